//! The flare at the end of a planned-tilt transition (docs/landing.md).
//!
//! Past about 62 deg the thrust that is left (`thrust_max`, ground effect
//! included) no longer holds the weight, so every degree beyond is bought
//! with fall speed. The flare spends it where it costs least: the descent
//! reference slows exponentially onto a hold clearance `c_hold` of the
//! wheels above the ground,
//!
//! ```text
//! d(t) = c(t) - c_hold,   d_dot = -min(v_desc, d / tau)
//! ```
//!
//! (a constant descent at `v_desc` until `d = v_desc tau`, then an
//! exponential), while the MPC tilts as far as its thrust holds the height;
//! until the commit the planned tilt only grows (a tilt given back to stop
//! the descent would have to be tilted again in the last centimetres, where
//! there is no time for it). The flare commits when a full-speed tilt-up
//! begun now is predicted to touch down at most at `impact_speed`
//! ([`predict_touchdown`]), or once the wheels are within `hold_band` above
//! the hold clearance and either slower than `commit_speed` or held there
//! `hold_time`, or when they sink `hold_band` below it. A hold that would
//! commit by time or slowness while the prediction says faster than
//! `lower_above_impact` lowers itself by `lower_step` instead (down to
//! `lowest_hold`) and the approach goes on: a robot the ground effect holds
//! at a high tilt would otherwise fall from there too fast. Then the flight
//! stack commands the tilt at the mechanism's full speed to the transition
//! limit, whatever the MPC's plan says, and the wheels meet the ground a few
//! centimetres later, at a tilt the robot could not have hovered at.
//!
//! The rotors' bound `thrust_max` (0.95) keeps a margin for the attitude
//! control. A robot that is weaker than its robot file spends it after the
//! commit: when the observer's vertical force at the commit exceeds
//! `weak_deficit` of the file's weight,
//!
//! ```text
//! deficit = F_z,observer / (m_file g) > weak_deficit  =>  u_i <= weak_thrust_max
//! ```
//!
//! until the touchdown ([`Flare::thrust_max`]). The deficit is taken once, at
//! the commit: during the tilt-up the observer also learns the ground
//! effect's error, and a bound that changed with it would change the
//! landing it is deciding.
//!
//! Two rules for the robots whose ground effect is stronger than the
//! model's (docs/landing.md "A ground-effect surplus not credited to the
//! tilt-up"):
//!
//! - **The force learned aloft as a floor.** Near the ground the observer
//!   learns the ground effect's error as a constant force, but the tilt-up
//!   carries the rotors through the surface's tilt range, where the gain
//!   falls from about +7 % at 60 deg to -7 % at 70 deg, and a surplus of
//!   lift at the hold turns into a deficit. The prediction therefore takes
//!   the observer's vertical force as at least the one learned aloft
//!   (before the transition, where the model's ground effect is below 1 %):
//!
//!   ```text
//!   F_z,predicted = max(F_z,observer, F_z,aloft)
//!   ```
//!
//!   A deficit learned near the ground is kept (a weak ground effect is not
//!   made stronger).
//! - **The margin spent late.** After the commit, while the wheels are
//!   within `late_window` of the ground (at the current tilt and attitude),
//!   the touchdown is predicted again from the current state, holding the
//!   measured roll and pitch with the axles turned by them (there within
//!   0.03 m/s of the impact on the landings measured; the level prediction
//!   was 0.1 m/s off), every rotor at
//!   `late_predicted_thrust`. A predicted impact above `late_impact_speed`
//!   spends the attitude margin as a weak robot does, from then on.

use atmo_core::ground_effect::{ThrustGainSurface, rk4_step_above_ground};
use atmo_core::model::{Input, State, idx};
use atmo_core::{GroundPlane, Model};
use atmo_mpc::{wheel_clearance, wheel_clearance_at_attitude};
use nalgebra::Vector6;
use serde::Deserialize;

/// The flare's settings (`[flare]` of `config/flight.toml`).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FlareSettings {
    /// Whether a planned-tilt transition ends in the flare.
    pub enabled: bool,
    /// Wheels' clearance the descent slows onto, m, measured as if the
    /// thrusters stood at the transition's tilt limit (tilting lowers the
    /// hubs and swings the rims down: the clearance the tilt-up ends at).
    pub hold_clearance: f64,
    /// Time constant of the exponential approach, s.
    pub time_constant: f64,
    /// Distance around the hold clearance counted as holding, m.
    pub hold_band: f64,
    /// Vertical speed below which a hold commits at once, m/s.
    pub commit_speed: f64,
    /// Longest hold before the flare commits anyway, s.
    pub hold_time: f64,
    /// The impact speed aimed at, m/s: the approach commits as soon as a
    /// tilt-up begun now is predicted to touch down no faster.
    pub impact_speed: f64,
    /// Every rotor's command in that prediction (level, no motor lag: below
    /// the MPC's bound, for the attitude control and the lag it leaves out).
    pub predicted_thrust: f64,
    /// Thrust deficit (the observer's vertical force over the robot file's
    /// weight) at the commit above which the robot counts as weak.
    pub weak_deficit: f64,
    /// Each rotor's bound from the commit to the touchdown on a weak robot.
    pub weak_thrust_max: f64,
    /// Predicted impact speed (m/s) above which a hold that would commit by
    /// time or slowness is lowered instead.
    pub lower_above_impact: f64,
    /// How far such a hold is lowered each time, m (0: never).
    pub lower_step: f64,
    /// The lowest hold clearance it is lowered to, m.
    pub lowest_hold: f64,
    /// Whether the prediction takes the observer's vertical force as at
    /// least the one learned aloft (see the module docs).
    pub aloft_force_floor: bool,
    /// After the commit, within this clearance of the wheels (m, at the
    /// current tilt and attitude) the touchdown is predicted again (0: never).
    pub late_window: f64,
    /// Each rotor's command in that prediction.
    pub late_predicted_thrust: f64,
    /// Predicted impact speed above which the robot then spends its
    /// attitude margin (each rotor up to `weak_thrust_max`), m/s.
    pub late_impact_speed: f64,
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
    /// Every rotor's command during the fall (`predicted_thrust`).
    pub thrust: f64,
    /// Hold the state's roll and pitch (and turn the axles by them,
    /// [`wheel_clearance_at_attitude`]) instead of levelling the robot.
    pub hold_attitude: bool,
}

/// Touchdown tilt (rad) and vertical speed (m/s, down positive) if the
/// tilt-up began now from `state` at `tilt`: level (at the state's heading
/// and position, falling straight down; or at its roll and pitch with
/// `hold_attitude`), every rotor at
/// `thrust`, the tilt rising at full rate, integrated with RK4 in `dt` steps
/// until the wheels touch (at most `horizon` s; `None` if they do not).
/// Allocation-free; about 1 us per step.
pub fn predict_touchdown(
    m: &TouchdownModel<'_>,
    state: &State,
    tilt: f64,
    dt: f64,
    horizon: f64,
) -> Option<(f64, f64)> {
    let mut x = State::zeros();
    for i in [idx::X, idx::Y, idx::Z, idx::YAW, idx::VZ] {
        x[i] = state[i];
    }
    let clearance = if m.hold_attitude {
        x[idx::ROLL] = state[idx::ROLL];
        x[idx::PITCH] = state[idx::PITCH];
        wheel_clearance_at_attitude
    } else {
        wheel_clearance
    };
    let u = Input::from_element(m.thrust);
    let mut varphi = tilt;
    let mut t = 0.0;
    while t < horizon {
        if clearance(&m.model.at_tilt(varphi), &m.ground, &x, m.wheel_radius) <= 0.0 {
            return Some((varphi, x[idx::VZ]));
        }
        let next_tilt = (varphi + m.tilt_rate * dt).min(m.tilt_max);
        let body = m
            .model
            .at_tilt(0.5 * (varphi + next_tilt))
            .with_disturbance(m.disturbance);
        x = rk4_step_above_ground(body, m.surface, m.ground.point.z, &x, &u, dt);
        varphi = next_tilt;
        t += dt;
    }
    None
}

/// The observer's vertical body force (N, down positive) the prediction
/// takes: at least `aloft`, the one learned before the transition, with
/// `aloft_force_floor` (see the module docs).
pub fn predicted_vertical_force(s: &FlareSettings, observer: f64, aloft: Option<f64>) -> f64 {
    match aloft {
        Some(a) if s.aloft_force_floor => observer.max(a),
        _ => observer,
    }
}

/// Where the flare is.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Flare {
    /// Since when (ns) the wheels are within the hold band.
    holding_since: Option<u64>,
    /// The tilt-up has begun (it is never taken back in this transition).
    committed: bool,
    /// The thrust deficit of the last tick before the commit, then of the commit.
    deficit_at_commit: f64,
    /// How far the hold clearance has been lowered, m.
    lowered: f64,
    /// A late prediction after the commit said too fast (module docs).
    spends_late: bool,
}

impl Flare {
    /// Back to the approach (a new transition).
    pub fn reset(&mut self) {
        *self = Self::default();
    }

    /// Whether the tilt-up has begun.
    pub fn committed(&self) -> bool {
        self.committed
    }

    /// The hold clearance now, m (`hold_clearance`, less what a too fast
    /// prediction lowered it by).
    pub fn hold_clearance(&self, s: &FlareSettings) -> f64 {
        s.hold_clearance - self.lowered
    }

    /// Each rotor's bound after the commit of a weak robot (`None`: the
    /// MPC's own `thrust_max`; see the module docs).
    pub fn thrust_max(&self, s: &FlareSettings) -> Option<f64> {
        let weak = self.deficit_at_commit > s.weak_deficit;
        (self.committed && (weak || self.spends_late)).then_some(s.weak_thrust_max)
    }

    /// Whether a late prediction after the commit is due: committed, not yet
    /// spending the margin, the wheels within `late_window` (m) of the ground
    /// at the current tilt and attitude (`clearance`, evaluated only then).
    pub fn late_prediction_due(&self, s: &FlareSettings, clearance: impl FnOnce() -> f64) -> bool {
        self.committed && !self.spends_late && s.late_window > 0.0 && clearance() < s.late_window
    }

    /// Takes a late prediction's impact speed (m/s): too fast spends the
    /// attitude margin until the touchdown.
    pub fn late_prediction(&mut self, s: &FlareSettings, predicted_impact: Option<f64>) {
        self.spends_late |= predicted_impact.is_some_and(|v| v > s.late_impact_speed);
    }

    /// One tick of the flare's logic: `clearance` of the wheels (m),
    /// vertical speed `vz` (m/s, down positive), at time `now_ns`;
    /// `predicted_impact`: [`predict_touchdown`]'s speed for a tilt-up now;
    /// `deficit`: the observer's vertical force over the file's weight.
    pub fn update(
        &mut self,
        s: &FlareSettings,
        now_ns: u64,
        clearance: f64,
        vz: f64,
        predicted_impact: Option<f64>,
        deficit: f64,
    ) -> bool {
        if self.committed {
            return true;
        }
        // Kept from the tick that commits on (`update` returns above).
        self.deficit_at_commit = deficit;
        if predicted_impact.is_some_and(|v| v <= s.impact_speed) {
            self.committed = true;
            return true;
        }
        let hold = self.hold_clearance(s);
        if clearance > hold + s.hold_band {
            self.holding_since = None;
            return false;
        }
        let since = *self.holding_since.get_or_insert(now_ns);
        let held = now_ns.saturating_sub(since) as f64 * 1e-9;
        // Sinking through the hold: the thrust cannot hold this tilt here,
        // waiting would only land lower.
        let sinking = clearance < hold - s.hold_band;
        let holding_done = vz.abs() <= s.commit_speed || held >= s.hold_time;
        // Held up here (a strong ground effect) but predicted to fall too
        // fast from here: go lower first.
        let too_fast = predicted_impact.is_some_and(|v| v > s.lower_above_impact);
        if holding_done
            && !sinking
            && too_fast
            && s.lower_step > 0.0
            && hold - s.lower_step >= s.lowest_hold - 1e-12
        {
            self.lowered += s.lower_step;
            self.holding_since = None;
            return false;
        }
        self.committed = holding_done || sinking;
        self.committed
    }

    /// The reference's clearance and descent speed (down positive) `t`
    /// seconds ahead of a clearance `c0`, descending at most at `v_desc`
    /// onto the hold clearance as it is now ([`Flare::hold_clearance`]; see
    /// the module docs). Below the hold the reference is the hold.
    pub fn approach(&self, s: &FlareSettings, v_desc: f64, c0: f64, t: f64) -> (f64, f64) {
        let hold = self.hold_clearance(s);
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
        enabled: true,
        hold_clearance: 0.03,
        time_constant: 0.2,
        hold_band: 0.01,
        commit_speed: 0.03,
        hold_time: 0.3,
        impact_speed: 0.3,
        predicted_thrust: 0.9,
        weak_deficit: 0.06,
        weak_thrust_max: 1.0,
        lower_above_impact: 0.4,
        lower_step: 0.01,
        lowest_hold: 0.01,
        aloft_force_floor: true,
        late_window: 0.03,
        late_predicted_thrust: 0.95,
        late_impact_speed: 0.4,
    };

    #[test]
    fn the_approach_descends_at_the_speed_then_slows_onto_the_hold_clearance() {
        // 0.5 m above the hold at 0.2 m/s: constant until 4 cm above it.
        let (c, v) = Flare::default().approach(&S, 0.2, 0.53, 1.0);
        assert!((c - 0.33).abs() < 1e-12 && (v - 0.2).abs() < 1e-12);
        // Continuous at the knee, and the speed is the distance over tau after it.
        let t_knee = (0.5 - 0.04) / 0.2;
        let (c1, v1) = Flare::default().approach(&S, 0.2, 0.53, t_knee + 1e-9);
        assert!((c1 - 0.07).abs() < 1e-6 && (v1 - 0.2).abs() < 1e-6);
        let (c2, v2) = Flare::default().approach(&S, 0.2, 0.53, t_knee + 0.4);
        assert!(((c2 - 0.03) / 0.2 - v2).abs() < 1e-12);
        assert!(c2 > 0.03 && c2 < 0.04);
        // Below the hold: back to it.
        assert_eq!(Flare::default().approach(&S, 0.2, 0.01, 0.5), (0.03, 0.0));
    }

    #[test]
    fn the_flare_commits_when_slow_in_the_band_or_after_the_hold_time() {
        let mut f = Flare::default();
        assert!(!f.update(&S, 0, 0.2, 0.0, None, 0.0), "high: no commit");
        assert!(
            !f.update(&S, 1, 0.035, 0.1, None, 0.0),
            "in the band, still descending"
        );
        assert!(f.update(&S, 2, 0.035, 0.01, None, 0.0), "slow in the band");
        assert!(
            f.update(&S, 3, 0.5, 0.2, None, 0.0),
            "committed stays committed"
        );
        let mut f = Flare::default();
        assert!(!f.update(&S, 0, 0.035, 0.1, None, 0.0));
        assert!(!f.update(&S, 200_000_000, 0.035, 0.1, None, 0.0));
        assert!(
            f.update(&S, 300_000_000, 0.035, 0.1, None, 0.0),
            "the hold time ran out"
        );
        let mut f = Flare::default();
        assert!(!f.update(&S, 0, 0.035, 0.1, None, 0.0));
        assert!(
            f.update(&S, 1, 0.019, 0.1, None, 0.0),
            "sinking through the hold"
        );
        let mut f = Flare::default();
        assert!(!f.update(&S, 0, 0.2, 0.2, Some(0.31), 0.0));
        assert!(
            f.update(&S, 1, 0.2, 0.2, Some(0.29), 0.0),
            "predicted to land slowly enough"
        );
        f.reset();
        assert!(!f.committed());
    }

    #[test]
    fn a_hold_predicted_to_land_too_fast_is_lowered_before_it_commits() {
        let mut f = Flare::default();
        // Held slowly at the hold (0.03 m), but predicted at 0.45 m/s: lower.
        assert!(!f.update(&S, 0, 0.035, 0.01, Some(0.45), 0.0));
        assert!((f.hold_clearance(&S) - 0.02).abs() < 1e-12);
        // The approach's reference now slows onto the lowered hold.
        let (c, v) = f.approach(&S, 0.2, 0.019, 0.5);
        assert!((c - 0.02).abs() < 1e-12 && v == 0.0, "{c} {v}");
        let (c, _) = f.approach(&S, 0.2, 0.1, 10.0);
        assert!((c - 0.02).abs() < 1e-6, "{c}");
        // The old hold is now above the band: approach on.
        assert!(!f.update(&S, 1, 0.035, 0.01, Some(0.45), 0.0));
        // At the new hold, still too fast: down to the lowest hold, 0.01 m.
        assert!(!f.update(&S, 2, 0.025, 0.01, Some(0.45), 0.0));
        assert!((f.hold_clearance(&S) - 0.01).abs() < 1e-12);
        // Not below the lowest hold: commits there whatever the prediction.
        assert!(f.update(&S, 3, 0.012, 0.01, Some(0.45), 0.0));
        // Predicted slow enough for the aim: commits at once as before; not
        // too fast for the hold: commits by slowness at the first hold.
        let mut f = Flare::default();
        assert!(f.update(&S, 0, 0.035, 0.01, Some(0.35), 0.0));
        assert!((f.hold_clearance(&S) - 0.03).abs() < 1e-12);
        // Sinking through the hold commits, too fast or not.
        let mut f = Flare::default();
        assert!(f.update(&S, 0, 0.015, 0.1, Some(0.45), 0.0));
        f.reset();
        assert!((f.hold_clearance(&S) - 0.03).abs() < 1e-12);
    }

    #[test]
    fn a_robot_weaker_than_its_file_at_the_commit_spends_the_attitude_margin() {
        let mut f = Flare::default();
        assert!(!f.update(&S, 0, 0.2, 0.2, None, 0.1));
        assert_eq!(f.thrust_max(&S), None, "not before the commit");
        assert!(f.update(&S, 1, 0.2, 0.2, Some(0.2), 0.1));
        assert_eq!(f.thrust_max(&S), Some(1.0));
        // Taken at the commit: what the observer learns later does not move it.
        f.update(&S, 2, 0.1, 0.3, None, 0.0);
        assert_eq!(f.thrust_max(&S), Some(1.0));
        let mut f = Flare::default();
        assert!(f.update(&S, 0, 0.2, 0.2, Some(0.2), 0.03));
        assert_eq!(f.thrust_max(&S), None, "as strong as its file");
        f.update(&S, 1, 0.1, 0.3, None, 0.2);
        assert_eq!(f.thrust_max(&S), None, "weaker only after the commit");
        f.reset();
        assert_eq!(f.thrust_max(&S), None);
    }

    #[test]
    fn a_late_prediction_too_fast_spends_the_margin_until_the_touchdown() {
        let mut f = Flare::default();
        assert!(!f.late_prediction_due(&S, || 0.01), "not before the commit");
        assert!(f.update(&S, 0, 0.2, 0.2, Some(0.2), 0.0));
        assert_eq!(f.thrust_max(&S), None, "as strong as its file");
        assert!(!f.late_prediction_due(&S, || 0.05), "outside the window");
        assert!(f.late_prediction_due(&S, || 0.02));
        f.late_prediction(&S, Some(0.39));
        assert_eq!(f.thrust_max(&S), None, "predicted slow enough");
        f.late_prediction(&S, None);
        assert_eq!(f.thrust_max(&S), None, "no touchdown predicted");
        f.late_prediction(&S, Some(0.41));
        assert_eq!(f.thrust_max(&S), Some(1.0));
        assert!(!f.late_prediction_due(&S, || 0.02), "decided once");
        f.reset();
        assert_eq!(f.thrust_max(&S), None);
        let off = FlareSettings {
            late_window: 0.0,
            ..S
        };
        assert!(f.update(&off, 0, 0.2, 0.2, Some(0.2), 0.0));
        assert!(!f.late_prediction_due(&off, || 0.0));
    }

    #[test]
    fn the_prediction_does_not_credit_a_surplus_learned_near_the_ground() {
        // Learned aloft: 2 N of missing lift; at the hold the observer reads
        // 1 N of extra lift (a ground effect stronger than the model's).
        assert_eq!(predicted_vertical_force(&S, -1.0, Some(2.0)), 2.0);
        // A deficit grown near the ground is kept.
        assert_eq!(predicted_vertical_force(&S, 3.0, Some(2.0)), 3.0);
        assert_eq!(predicted_vertical_force(&S, -1.0, None), -1.0);
        let off = FlareSettings {
            aloft_force_floor: false,
            ..S
        };
        assert_eq!(predicted_vertical_force(&off, -1.0, Some(2.0)), -1.0);
    }

    #[test]
    fn the_prediction_holding_the_attitude_touches_down_earlier_when_rolled() {
        use atmo_core::RobotConfig;
        let model = Model::new(&RobotConfig::atmo());
        let tilt = 60f64.to_radians();
        let ground = GroundPlane::level(0.0);
        // Level, the wheels 4 cm above the ground (the clearance grows
        // one-for-one with the height), falling at 0.1 m/s; then rolled.
        let mut state = State::zeros();
        state[idx::Z] = wheel_clearance(&model.at_tilt(tilt), &ground, &state, 0.125) - 0.04;
        state[idx::VZ] = 0.1;
        state[idx::ROLL] = 4f64.to_radians();
        let mut m = TouchdownModel {
            model: &model,
            surface: None,
            ground,
            disturbance: Vector6::zeros(),
            wheel_radius: 0.125,
            tilt_rate: 22.5f64.to_radians(),
            tilt_max: 70f64.to_radians(),
            thrust: 0.9,
            hold_attitude: false,
        };
        let (level_tilt, level_v) = predict_touchdown(&m, &state, tilt, 0.005, 1.0).unwrap();
        m.hold_attitude = true;
        let (rolled_tilt, rolled_v) = predict_touchdown(&m, &state, tilt, 0.005, 1.0).unwrap();
        // The rolled robot's low side (hub and rim) is nearer the ground.
        assert!(rolled_tilt < level_tilt, "{rolled_tilt} {level_tilt}");
        assert!(rolled_v > 0.0 && level_v > 0.0);
        // At a level state the two are the same prediction.
        state[idx::ROLL] = 0.0;
        let held = predict_touchdown(&m, &state, tilt, 0.005, 1.0);
        m.hold_attitude = false;
        assert_eq!(held, predict_touchdown(&m, &state, tilt, 0.005, 1.0));
    }
}
