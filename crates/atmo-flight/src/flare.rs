//! The flare at the end of a planned-tilt transition: the touchdown
//! prediction and the one decision it feeds (docs/landing.md).
//!
//! Past about 62 deg the thrust that is left no longer holds the weight, so
//! every degree beyond is bought with fall speed. The flare spends it where
//! it costs least, in the last centimetres:
//!
//! 1. **Approach.** The descent reference slows exponentially onto a hold
//!    clearance `c_hold` of the wheels (measured as if the thrusters stood at
//!    the transition's tilt limit, the clearance a tilt-up ends at),
//!
//!    ```text
//!    d(t) = c(t) - c_hold,   d_dot = -min(v_desc, d / tau)
//!    ```
//!
//!    while the MPC tilts as far as its thrust holds the height; until the
//!    commit the planned tilt only grows.
//! 2. **Prediction.** Every preparation predicts the touchdown of a tilt-up
//!    at the mechanism's full speed begun now ([`predict_touchdown`]): the
//!    MPC's model with its ground-effect surface and the observer's wrench,
//!    the measured attitude held, every rotor reaching the MPC's bound less
//!    the attitude control's share through the motors' lag.
//! 3. **Decision.** The prediction has a spread, measured against the
//!    plant on runs it was not chosen on (docs/landing.md): `sigma_v` on the
//!    impact speed, `sigma_tilt` on the touchdown tilt. Committing now
//!    risks a landing too fast, waiting risks one too flat; the flare
//!    commits as soon as the first risk is no larger than the second,
//!
//!    ```text
//!    (v_max - v_hat) / sigma_v  >=  (tilt_hat - tilt_min) / sigma_tilt
//!    ```
//!
//!    which is where `P(v <= v_max) P(tilt >= tilt_min)` peaks as the
//!    approach goes down (both predictions fall as the commit is delayed).
//!    A robot predicted to land steeply waits for a soft landing; one
//!    predicted near `tilt_min` commits with the speed margin it has.
//!    When the approach is over (the hold reached, or the final approach
//!    no lower for a time constant) the flare commits too: waiting lowers
//!    neither risk.
//!
//! Then the flight stack commands the tilt at full speed to the transition
//! limit whatever the MPC's plan says, and the wheels meet the ground a few
//! centimetres later.

use atmo_core::ground_effect::{ThrustGainSurface, rk4_step_above_ground};
use atmo_core::model::{Input, State, idx};
use atmo_core::{GroundPlane, Model};
use atmo_mpc::wheel_clearance_at_attitude;
use nalgebra::Vector6;
use serde::Deserialize;

atmo_core::params! {
    /// The flare's settings (`[flare]` of `config/flight.toml`).
    #[derive(Debug, Clone, Copy, PartialEq)]
    pub struct FlareSettings {
        /// Wheels' clearance the descent slows onto, measured as if the
        /// thrusters stood at the transition's tilt limit.
        pub hold_clearance: f64, range -0.1..=0.5, unit "m";
        /// Time constant of the exponential approach.
        pub time_constant: f64, range 0.01..=5.0, unit "s";
        /// The landing target: impact speed at most this ...
        pub impact_speed_max: f64, range 0.01..=2.0, unit "m/s";
        /// ... at a touchdown tilt of at least this.
        pub touchdown_tilt_min_deg: f64, range 0.0..=90.0, unit "deg";
        /// The flown impact speed less the predicted one at the decision:
        /// its mean and standard deviation (each within 1 m/s, the spread
        /// above a thousandth of it).
        pub impact_speed_error: PredictionError, unit "m/s";
        /// The flown touchdown tilt less the predicted one at the
        /// decision: its mean and standard deviation (each within 20 deg,
        /// the spread above a thousandth of it).
        pub touchdown_tilt_error_deg: PredictionError, unit "deg";
    }
    check |_table, c, prefix| {
        let errors = [
            ("impact_speed_error", impact_speed_error, 1.0, "m/s"),
            ("touchdown_tilt_error_deg", touchdown_tilt_error_deg, 20.0, "deg"),
        ];
        for (name, e, limit, unit) in errors {
            let key = atmo_core::params::key(prefix, name);
            c.range(&format!("{key}.mean"), e.mean, -limit..=limit, unit)?;
            c.range(&format!("{key}.spread"), e.spread, limit * 1e-3..=limit, unit)?;
        }
        Ok(())
    }
}

/// How a predicted quantity's flown value scatters about it: the
/// prediction's measured bias and spread (docs/landing.md).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PredictionError {
    pub mean: f64,
    pub spread: f64,
}

/// Each rotor's command bound from the commit to the touchdown: full
/// thrust. The MPC's lower bound keeps a margin for the attitude control
/// through the approach, which the slow-down onto the hold needs; in the
/// tilt-up the margin that is left buys tilt (docs/landing.md).
pub const COMMITTED_THRUST_MAX: f64 = 1.0;

/// A predicted touchdown.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Touchdown {
    /// Tilt when the wheels touch, rad.
    pub tilt: f64,
    /// Vertical speed then, m/s (down positive).
    pub impact_speed: f64,
    /// Time from now, s.
    pub time: f64,
}

impl FlareSettings {
    /// `p` of [`predict_touchdown`] with the prediction's measured mean
    /// error added: the touchdown expected on average.
    pub fn expected(&self, p: &Touchdown) -> Touchdown {
        Touchdown {
            tilt: p.tilt + self.touchdown_tilt_error_deg.mean.to_radians(),
            impact_speed: p.impact_speed + self.impact_speed_error.mean,
            time: p.time,
        }
    }

    /// The speed and tilt margins of an expected touchdown `p`, each in
    /// its spread.
    pub fn margins(&self, p: &Touchdown) -> (f64, f64) {
        (
            (self.impact_speed_max - p.impact_speed) / self.impact_speed_error.spread,
            (p.tilt.to_degrees() - self.touchdown_tilt_min_deg)
                / self.touchdown_tilt_error_deg.spread,
        )
    }

    /// Whether a tilt-up predicted to touch down as `p` is due now: its
    /// risk of a landing too fast is no larger than waiting's risk of one
    /// too flat (module docs).
    pub fn commits(&self, p: &Touchdown) -> bool {
        let (speed, tilt) = self.margins(p);
        speed >= tilt
    }
}

/// What the robot and the MPC's model know, for [`predict_touchdown`].
#[derive(Clone, Copy)]
pub struct TouchdownModel<'a> {
    pub model: &'a Model,
    /// The MPC's thrust-gain surface (`None`: the nominal model).
    pub surface: Option<&'a dyn ThrustGainSurface>,
    /// The ground plane (the wheels touch it; the ground effect is measured
    /// from the horizontal plane through its point).
    pub ground: GroundPlane,
    /// The observer's body wrench (what the model leaves out).
    pub disturbance: Vector6<f64>,
    pub wheel_radius: f64,
    /// The tilt-up: rate (rad/s) up to the limit (rad).
    pub tilt_rate: f64,
    pub tilt_max: f64,
    /// Every rotor's command the fall tends to, and the commands now.
    pub thrust: f64,
    pub thrust_now: Input,
    /// The motors' time constant, s (0: the thrust follows at once).
    pub motor_time_constant: f64,
}

/// The touchdown if the tilt-up began now from `state` at `tilt`: the
/// state's roll and pitch held (the axles turned by them,
/// [`wheel_clearance_at_attitude`]), every rotor going from its command now
/// to `thrust` with the motors' lag, the tilt rising at full rate,
/// integrated with RK4 in `dt` steps until the wheels touch (at most
/// `horizon` s; `None` if they do not). Allocation-free (bench
/// `flare/predict_touchdown`).
pub fn predict_touchdown(
    m: &TouchdownModel<'_>,
    state: &State,
    tilt: f64,
    dt: f64,
    horizon: f64,
) -> Option<Touchdown> {
    let mut x = State::zeros();
    for i in [
        idx::X,
        idx::Y,
        idx::Z,
        idx::ROLL,
        idx::PITCH,
        idx::YAW,
        idx::VZ,
    ] {
        x[i] = state[i];
    }
    let target = Input::from_element(m.thrust);
    let mut varphi = tilt;
    let mut t = 0.0;
    while t < horizon {
        let body = m.model.at_tilt(varphi);
        if wheel_clearance_at_attitude(&body, &m.ground, &x, m.wheel_radius) <= 0.0 {
            return Some(Touchdown {
                tilt: varphi,
                impact_speed: x[idx::VZ],
                time: t,
            });
        }
        let u = if m.motor_time_constant > 0.0 {
            target + (m.thrust_now - target) * (-(t + 0.5 * dt) / m.motor_time_constant).exp()
        } else {
            target
        };
        let next_tilt = (varphi + m.tilt_rate * dt).min(m.tilt_max);
        let body = m
            .model
            .at_tilt(0.5 * (varphi + next_tilt))
            .with_disturbance(m.disturbance);
        x = rk4_step_above_ground(body, m.surface, m.ground.point.z, &x, &u, dt);
        // The attitude control holds the attitude: no rotation builds up.
        for i in [idx::WX, idx::WY, idx::WZ] {
            x[i] = 0.0;
        }
        x[idx::ROLL] = state[idx::ROLL];
        x[idx::PITCH] = state[idx::PITCH];
        varphi = next_tilt;
        t += dt;
    }
    None
}

/// The observer's vertical body force (N, down positive) the prediction
/// takes: at least `aloft`, the one learned before the transition. Near
/// the ground the observer learns the ground effect's error at the hold's
/// tilt as a constant force, but the tilt-up carries the rotors through the
/// surface's tilt range, where a surplus at the hold turns into a deficit:
/// a surplus learned near the ground is not credited to the tilt-up, a
/// deficit is kept.
pub fn predicted_vertical_force(observer: f64, aloft: Option<f64>) -> f64 {
    aloft.map_or(observer, |a| observer.max(a))
}

/// The decision, as it was taken (for the record and the validation of
/// the prediction against the flown touchdown).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Decision {
    /// When, ns on the flight stack's clock.
    pub now_ns: u64,
    /// The touchdown expected then ([`FlareSettings::expected`]; `None`
    /// when the approach reached its hold without a prediction).
    pub predicted: Option<Touchdown>,
    /// The tilt (rad) and the wheels' clearance at the tilt limit (m) then.
    pub tilt: f64,
    pub clearance: f64,
}

/// The final approach: the flare predicts (and may decide) while the
/// wheels are within this of the ground at the transition's tilt limit, m.
pub const PREDICTION_RANGE: f64 = 0.17;

/// Where the flare is.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Flare {
    /// The tilt-up has begun (it is never taken back in this transition).
    decision: Option<Decision>,
    /// The lowest clearance of the final approach so far (m) and when it
    /// was reached (ns): the approach has stalled when it has not gone
    /// lower for a time constant.
    lowest: Option<(f64, u64)>,
}

impl Flare {
    /// Back to the approach (a new transition).
    pub fn reset(&mut self) {
        *self = Self::default();
    }

    /// Whether the tilt-up has begun.
    pub fn committed(&self) -> bool {
        self.decision.is_some()
    }

    /// The decision taken in this transition, if any.
    pub fn decision(&self) -> Option<Decision> {
        self.decision
    }

    /// One tick of the approach: commits when `predicted` (a tilt-up begun
    /// at the last preparation, [`predict_touchdown`]), expected with the
    /// prediction's mean error, says so ([`FlareSettings::commits`]), or
    /// when the approach has stopped descending: the wheels' `clearance`
    /// (m, at the tilt limit) has reached the hold, or in the final
    /// approach ([`PREDICTION_RANGE`]) it has not gone lower for the
    /// approach's time constant (a robot whose MPC holds it a little above
    /// the hold, short of thrust to tilt further). There waiting longer
    /// lowers neither risk. Returns whether the tilt-up has begun.
    pub fn update(
        &mut self,
        s: &FlareSettings,
        now_ns: u64,
        tilt: f64,
        clearance: f64,
        predicted: Option<Touchdown>,
    ) -> bool {
        if self.decision.is_some() {
            return true;
        }
        let expected = predicted.map(|p| s.expected(&p));
        let final_approach = clearance < PREDICTION_RANGE;
        if final_approach && self.lowest.is_none_or(|(c, _)| clearance < c) {
            self.lowest = Some((clearance, now_ns));
        }
        // Risen out of the final approach, it is no stall to tilt up from.
        let stalled = final_approach
            && self.lowest.is_some_and(|(_, since)| {
                now_ns.saturating_sub(since) as f64 * 1e-9 >= s.time_constant
            });
        if expected.is_some_and(|e| s.commits(&e)) || clearance <= s.hold_clearance || stalled {
            self.decision = Some(Decision {
                now_ns,
                predicted: expected,
                tilt,
                clearance,
            });
        }
        self.committed()
    }

    /// Each rotor's bound (`None`: the MPC's own): from the commit to the
    /// touchdown the rotors may use their full range.
    pub fn thrust_max(&self) -> Option<f64> {
        self.committed().then_some(COMMITTED_THRUST_MAX)
    }

    /// The reference's clearance and descent speed (down positive) `t`
    /// seconds ahead of a clearance `c0`, descending at most at `v_desc`
    /// onto the hold clearance (see the module docs). Below the hold the
    /// reference is the hold.
    pub fn approach(s: &FlareSettings, v_desc: f64, c0: f64, t: f64) -> (f64, f64) {
        let hold = s.hold_clearance;
        let d0 = c0 - hold;
        if d0 <= 0.0 {
            return (hold, 0.0);
        }
        let tau = s.time_constant;
        let knee = v_desc * tau;
        let (d_knee, t_exp) = if d0 > knee {
            let t_knee = (d0 - knee) / v_desc;
            if t < t_knee {
                return (c0 - v_desc * t, v_desc);
            }
            (knee, t - t_knee)
        } else {
            (d0, t)
        };
        let d = d_knee * (-t_exp / tau).exp();
        (hold + d, d / tau)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const S: FlareSettings = FlareSettings {
        hold_clearance: 0.03,
        time_constant: 0.2,
        impact_speed_max: 0.4,
        touchdown_tilt_min_deg: 64.0,
        impact_speed_error: PredictionError {
            mean: 0.0,
            spread: 0.05,
        },
        touchdown_tilt_error_deg: PredictionError {
            mean: 0.0,
            spread: 1.0,
        },
    };

    fn touchdown(tilt_deg: f64, impact_speed: f64) -> Touchdown {
        Touchdown {
            tilt: tilt_deg.to_radians(),
            impact_speed,
            time: 0.3,
        }
    }

    #[test]
    fn the_rotors_may_use_their_full_range_from_the_commit_on() {
        let mut f = Flare::default();
        assert!(!f.update(&S, 0, 1.0, 0.1, Some(touchdown(67.0, 0.30))));
        assert_eq!(f.thrust_max(), None, "not before the commit");
        assert!(f.update(&S, 1, 1.0, 0.1, Some(touchdown(66.0, 0.30))));
        assert_eq!(f.thrust_max(), Some(COMMITTED_THRUST_MAX));
        f.reset();
        assert_eq!(f.thrust_max(), None);
    }

    #[test]
    fn the_decision_records_the_touchdown_expected_with_the_mean_error() {
        let s = FlareSettings {
            impact_speed_error: PredictionError {
                mean: -0.05,
                spread: 0.05,
            },
            touchdown_tilt_error_deg: PredictionError {
                mean: 0.5,
                spread: 1.0,
            },
            ..S
        };
        // Predicted 66 deg at 0.35 m/s: expected 66.5 deg at 0.30 m/s,
        // 2 spreads of speed against 2.5 of tilt: waits.
        let mut f = Flare::default();
        assert!(!f.update(&s, 0, 1.0, 0.1, Some(touchdown(66.0, 0.35))));
        // 65.5 deg at 0.35: expected 66 deg at 0.30, due.
        assert!(f.update(&s, 1, 1.0, 0.1, Some(touchdown(65.5, 0.35))));
        let d = f.decision().unwrap().predicted.unwrap();
        assert!((d.impact_speed - 0.30).abs() < 1e-12);
        assert!((d.tilt.to_degrees() - 66.0).abs() < 1e-9);
    }

    #[test]
    fn the_approach_descends_at_the_speed_then_slows_onto_the_hold_clearance() {
        // 0.5 m above the hold at 0.2 m/s: constant until 4 cm above it.
        let (c, v) = Flare::approach(&S, 0.2, 0.53, 1.0);
        assert!((c - 0.33).abs() < 1e-12 && (v - 0.2).abs() < 1e-12);
        // Continuous at the knee, and the speed is the distance over tau after it.
        let t_knee = (0.5 - 0.04) / 0.2;
        let (c1, v1) = Flare::approach(&S, 0.2, 0.53, t_knee + 1e-9);
        assert!((c1 - 0.07).abs() < 1e-6 && (v1 - 0.2).abs() < 1e-6);
        let (c2, v2) = Flare::approach(&S, 0.2, 0.53, t_knee + 0.4);
        assert!(((c2 - 0.03) / 0.2 - v2).abs() < 1e-12);
        assert!(c2 > 0.03 && c2 < 0.04);
        // Below the hold: back to it.
        assert_eq!(Flare::approach(&S, 0.2, 0.01, 0.5), (0.03, 0.0));
    }

    #[test]
    fn the_flare_commits_when_the_risk_of_a_fast_landing_is_no_larger_than_a_flat_ones() {
        let mut f = Flare::default();
        assert!(!f.update(&S, 0, 1.0, 0.1, None), "no prediction: no commit");
        // 0.30 m/s at 66 deg: two spreads of speed, two of tilt.
        assert!(f.update(&S, 1, 1.0, 0.1, Some(touchdown(66.0, 0.30))));
        let d = f.decision().unwrap();
        assert_eq!((d.now_ns, d.predicted), (1, Some(touchdown(66.0, 0.30))));
        // Committed stays committed, the decision as taken.
        assert!(f.update(&S, 2, 1.0, 0.1, None));
        assert_eq!(f.decision().unwrap().now_ns, 1);
        f.reset();
        assert!(!f.committed());
        // A steep landing predicted too fast waits ...
        assert!(!f.update(&S, 3, 1.0, 0.1, Some(touchdown(67.0, 0.30))));
        // ... one predicted near the tilt target commits with less margin ...
        assert!(f.update(&S, 4, 1.0, 0.1, Some(touchdown(64.5, 0.37))));
        // ... and one predicted below it commits as soon as the speed is no
        // further over its limit than the tilt is under its own.
        let mut f = Flare::default();
        assert!(!f.update(&S, 5, 1.0, 0.1, Some(touchdown(63.0, 0.46))));
        assert!(f.update(&S, 6, 1.0, 0.1, Some(touchdown(63.0, 0.45))));
        // At the hold (0.03 m) the approach is over: commits, with or
        // without a prediction.
        let mut f = Flare::default();
        assert!(!f.update(&S, 7, 1.0, 0.031, Some(touchdown(67.0, 0.30))));
        assert!(f.update(&S, 8, 1.0, 0.03, Some(touchdown(67.0, 0.30))));
        let mut f = Flare::default();
        assert!(f.update(&S, 9, 1.0, 0.02, None));
        assert_eq!(f.decision().unwrap().predicted, None);
    }

    #[test]
    fn a_final_approach_that_stops_going_lower_for_a_time_constant_commits() {
        let ns = |seconds: f64| (seconds * 1e9) as u64;
        // Held 2-4 cm above the hold (0.03 m), no touchdown predicted: the
        // lowest clearance (0.05 m at 0.05 s) is not beaten for tau = 0.2 s.
        let mut f = Flare::default();
        let held = [0.06, 0.05, 0.07, 0.06, 0.055];
        for (k, c) in (0u32..).zip(held) {
            assert!(!f.update(&S, ns(0.05 * f64::from(k)), 1.0, c, None), "{k}");
        }
        assert!(!f.update(&S, ns(0.24), 1.0, 0.06, None));
        assert!(f.update(&S, ns(0.25), 1.0, 0.06, None));
        assert_eq!(f.decision().unwrap().predicted, None);
        // Still descending, however slowly: no commit.
        let mut f = Flare::default();
        for k in 0..100 {
            let c = 0.1 - 0.0005 * f64::from(k);
            assert!(!f.update(&S, ns(0.01 * f64::from(k)), 1.0, c, None), "{k}");
        }
        // Stalled above the final approach (the prediction's range): no
        // tilt-up from there ...
        let mut f = Flare::default();
        for k in 0..100 {
            let c = PREDICTION_RANGE + 0.01;
            assert!(!f.update(&S, ns(0.01 * f64::from(k)), 1.0, c, None), "{k}");
        }
        // ... nor after it entered the final approach and rose out of it.
        let mut f = Flare::default();
        assert!(!f.update(&S, 0, 1.0, PREDICTION_RANGE - 0.01, None));
        for k in 1..100 {
            let c = PREDICTION_RANGE + 0.05;
            assert!(!f.update(&S, ns(0.01 * f64::from(k)), 1.0, c, None), "{k}");
        }
    }

    #[test]
    fn the_prediction_does_not_credit_a_surplus_learned_near_the_ground() {
        // Learned aloft: 2 N of missing lift; at the hold the observer reads
        // 1 N of extra lift (a ground effect stronger than the model's).
        assert_eq!(predicted_vertical_force(-1.0, Some(2.0)), 2.0);
        // A deficit grown near the ground is kept.
        assert_eq!(predicted_vertical_force(3.0, Some(2.0)), 3.0);
        assert_eq!(predicted_vertical_force(-1.0, None), -1.0);
    }

    fn touchdown_model(model: &Model) -> TouchdownModel<'_> {
        TouchdownModel {
            model,
            surface: None,
            ground: GroundPlane::level(0.0),
            disturbance: Vector6::zeros(),
            wheel_radius: 0.125,
            tilt_rate: 22.5f64.to_radians(),
            tilt_max: 70f64.to_radians(),
            thrust: 0.9,
            thrust_now: Input::from_element(0.9),
            motor_time_constant: 0.0,
        }
    }

    /// A level state with the wheels `clearance` m above the ground at
    /// `tilt`, falling at `vz`.
    fn state_above(model: &Model, tilt: f64, clearance: f64, vz: f64) -> State {
        let mut state = State::zeros();
        let ground = GroundPlane::level(0.0);
        state[idx::Z] =
            wheel_clearance_at_attitude(&model.at_tilt(tilt), &ground, &state, 0.125) - clearance;
        state[idx::VZ] = vz;
        state
    }

    #[test]
    fn the_prediction_touches_down_earlier_when_rolled_and_later_with_more_thrust() {
        use atmo_core::RobotConfig;
        let model = Model::new(&RobotConfig::atmo());
        let tilt = 60f64.to_radians();
        let mut state = state_above(&model, tilt, 0.04, 0.1);
        let m = touchdown_model(&model);
        let level = predict_touchdown(&m, &state, tilt, 0.005, 1.0).unwrap();
        assert!(level.impact_speed > 0.1 && level.tilt > tilt && level.time > 0.0);
        // The rolled robot's low side (hub and rim) is nearer the ground.
        state[idx::ROLL] = 4f64.to_radians();
        let rolled = predict_touchdown(&m, &state, tilt, 0.005, 1.0).unwrap();
        assert!(rolled.tilt < level.tilt, "{rolled:?} {level:?}");
        // Rotors spinning up from a lower command through a lag fall faster.
        state[idx::ROLL] = 0.0;
        let lagged = TouchdownModel {
            thrust_now: Input::from_element(0.7),
            motor_time_constant: 0.05,
            ..m
        };
        let slow = predict_touchdown(&lagged, &state, tilt, 0.005, 1.0).unwrap();
        assert!(slow.impact_speed > level.impact_speed, "{slow:?} {level:?}");
        // And no touchdown within a horizon too short.
        assert_eq!(predict_touchdown(&m, &state, tilt, 0.005, 0.01), None);
    }
}
