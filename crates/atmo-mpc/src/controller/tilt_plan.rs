//! The tilt as a decision of the MPC (transition): the 13-state / 5-input
//! QP along the plan, and the landing objective.
//!
//! The plan carries the tilt `varphi_k` (a state) and the tilt rate
//! `omega_k` (an input, held over a stage, so `varphi_{k+1} = varphi_k + dt omega_k`
//! exactly). Bounds per stage, as boxes on the inputs so that the condensed
//! QP keeps its exact homotopy feedback:
//!
//! ```text
//! 0 <= u_k <= thrust_max
//! max(rate_min, (tilt_min - varphibar_k) / dt) <= omega_k <= min(rate_max, (tilt_max - varphibar_k) / dt)
//! ```
//!
//! (`thrust_max`: the plan's, or the settings' without one; the tilt limits enforced at the plan's tilt `varphibar_k`; the step of
//! the earlier stages' tilt in the same QP is not in them, RTI converges it
//! over the next ticks, and the flight stack clamps what it commands).
//!
//! The landing objective, "the largest tilt at touchdown for a bounded
//! impact speed": along the plan the wheels' clearance
//! `c_k = min_i [h_i(xbar_k, varphibar_k) - R_w sqrt(1 - (n . a_i)^2)]` (hub
//! heights above the ground plane along its normal `n` minus the rim's
//! reach towards it; `R_w sin(varphibar_k)` on level ground, see
//! [`wheel_clearance`]) predicts the
//! touchdown at the fractional stage `s*` where it crosses zero (the last
//! stage when it does not within the horizon). The cost adds
//!
//! ```text
//! sum_k  kappa_k [ |x_k - r_k|^2_Q + w_v (v_z,k - v_z,ref,k)^2 + w_tilt (varphi_k - varphi_max)^2 + w_level (pitch_k^2 + roll_k^2) ] + w_rate omega_k^2
//!   + sum_{k in {floor s*, ceil s*}} lambda_k [ W_tilt (varphi_k - varphi_max)^2 + W_v (v_z,k - v_td)^2 ]
//! kappa_k = clamp(1 - (k - s*), 0, 1)
//! ```
//!
//! with `lambda` the linear-interpolation weights of `s*` between its two
//! stages, `v_z,ref` the descent speed of the reference, `v_td` the
//! touchdown speed aimed at. `w_v` holds the descent slow (the paper's
//! transition cost, blended towards its L2 part, weighs no velocity), so
//! that there is time to tilt: the mechanism's speed, not the thrust, is
//! what limits the tilt of a fast descent. `w_level` keeps the attitude
//! level, so that the wheels touch together: the paper's cost, blended
//! towards its L2 part near the ground, weighs only the body rates, and
//! with every rotor at its bound in the tilt-up the ground effect's
//! fluctuating thrust rolled the robot by up to 10 deg, one side's wheels
//! touching early (docs/landing.md). The state cost fades
//! out past the touchdown (`kappa`): the plan ends on the wheels, and what
//! the model (which has no ground) predicts beyond is not penalized. Both
//! are continuous in `s*`, so the objective moves smoothly from tick to tick. The
//! optimizer trades the tilt at touchdown against the vertical speed there,
//! through the thrust it has left (rotor bound, ground effect of the model).

use std::f64::consts::FRAC_PI_2;

use atmo_core::GroundPlane;
use atmo_core::ground_effect::ThrustGainSurface;
use atmo_core::model::{Model, State, TiltedBody, idx, rk4_step_sensitivity, rotation, sin_cos};
use nalgebra::Vector3;

use super::{Mpc, check_finite, hover_reference, wrap_angle};
use crate::error::{MpcError, Result};
use crate::qp::{LinearizedHorizon, QpBackend};
use crate::settings::{MpcSettings, TiltPlanSettings};
use crate::tilt_model::{
    NUT, NXT, TILT, TiltInput, TiltState, TiltingBody, tilt_input, tilt_state,
};

/// What the flight stack allows the tilt to do this tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TiltPlan {
    /// Tilt limits of the mode, rad.
    pub tilt_min: f64,
    pub tilt_max: f64,
    /// The mechanism's speed, rad/s (`rate_min <= 0 <= rate_max`).
    pub rate_min: f64,
    pub rate_max: f64,
    /// Wheel radius, m (the rim's reach below the hub at touchdown).
    pub wheel_radius: f64,
    /// Each rotor's upper bound this tick (`None`: the settings'
    /// `thrust_max`; the flight stack raises it once the landing's tilt-up
    /// has committed).
    pub thrust_max: Option<f64>,
}

/// The tilt-planning QP and its plan (allocated once, when `[tilt_plan]` is configured).
pub(super) struct TiltPlanner {
    pub(super) weights: TiltPlanSettings,
    /// The request in force; `None`: the tilt is the ramp parameter.
    pub(super) plan: Option<TiltPlan>,
    /// Planned tilt rate per stage, rad/s.
    pub(super) rate: Vec<f64>,
    pub(super) lin: LinearizedHorizon<NXT, NUT>,
    pub(super) qp: QpBackend<NXT, NUT>,
    pub(super) dx: Vec<TiltState>,
    pub(super) du: Vec<TiltInput>,
    /// The measured tilt for the next feedback, rad.
    pub(super) measured: f64,
    /// The last measured tilt and the rate commanded after it (the predictor's start).
    pub(super) last_applied: Option<(f64, f64)>,
    /// Fractional stage of the predicted touchdown in the last preparation.
    pub(super) touchdown_stage: f64,
    /// The last preparation built the tilt QP (the feedback solves it).
    pub(super) active: bool,
}

impl TiltPlanner {
    pub(super) fn new(
        model: &Model,
        settings: &MpcSettings,
        weights: TiltPlanSettings,
    ) -> Result<Self> {
        let steps = settings.horizon.steps;
        let mut lin = LinearizedHorizon::<NXT, NUT>::new(steps);
        // Start-up values of the same kind as the flight's (hover at 50 deg,
        // a small attitude), to build the solver from.
        let mut x = State::zeros();
        x[idx::PITCH] = 0.05;
        x[idx::ROLL] = -0.05;
        x[idx::WX] = 0.1;
        let varphi = 50f64.to_radians();
        let hover = hover_reference(&model.at_tilt(varphi));
        let f = TiltingBody {
            model,
            disturbance: nalgebra::Vector6::zeros(),
            surface: None,
            ground_z: 0.0,
        };
        let q = settings.weights.state_weight(1.0);
        let r = settings.weights.input_weight(1.0);
        let dt = settings.stage_dt();
        for k in 0..steps {
            let s = rk4_step_sensitivity(&f, &tilt_state(&x, varphi), &tilt_input(&hover, 0.0), dt);
            lin.a[k] = s.a;
            lin.b[k] = s.b;
            lin.q_diag[k] = tilt_state(&q, weights.tilt_weight);
            lin.u_bar[k] = tilt_input(&hover, 0.0);
            lin.u_lo[k] = tilt_input(&hover.map(|_| 0.0), -1.0);
            lin.u_hi[k] = tilt_input(&hover.map(|_| weights.thrust_max), 1.0);
        }
        lin.q_diag[steps] = tilt_state(&(q * settings.cost.terminal_scale), weights.tilt_weight);
        lin.r_diag = tilt_input(&r, weights.rate_weight);
        let qp = QpBackend::new(&lin, &settings.solver)?;
        Ok(Self {
            weights,
            plan: None,
            rate: vec![0.0; steps],
            lin,
            qp,
            dx: vec![TiltState::zeros(); steps + 1],
            du: vec![TiltInput::zeros(); steps],
            measured: 0.0,
            last_applied: None,
            touchdown_stage: steps as f64,
            active: false,
        })
    }
}

/// The wheels' clearance above the ground plane `ground` of `body` (frozen
/// at its tilt) in state `x`: over the four wheels, the smallest distance of
/// a rim to the plane, each hub's signed height above the plane (along its
/// normal `n`) minus the rim's reach towards it, `R_w sqrt(1 - (n . a_i)^2)`
/// (a rim of radius `R_w` about the hub, in the plane normal to the wheel's
/// axle `a_i`, the rotor axis). The hubs are placed with the full attitude;
/// the axles with the heading only (the rim's reach at a level attitude, as
/// the level-ground clearance always took it: the landing is flown level).
/// On level ground this is, bit for bit, the lowest hub's height minus
/// `R_w sin(varphi)` (tested). Allocation-free.
pub fn wheel_clearance(
    body: &TiltedBody,
    ground: &GroundPlane,
    x: &State,
    wheel_radius: f64,
) -> f64 {
    clearance(body, ground, x, wheel_radius, Axles::Heading)
}

/// [`wheel_clearance`] with the axles turned by the full attitude too (the
/// plant's geometry: a rolled robot's lower rims reach further down). At a
/// level attitude the two are equal.
pub fn wheel_clearance_at_attitude(
    body: &TiltedBody,
    ground: &GroundPlane,
    x: &State,
    wheel_radius: f64,
) -> f64 {
    clearance(body, ground, x, wheel_radius, Axles::Attitude)
}

/// What turns the axles of [`clearance`].
#[derive(Clone, Copy, PartialEq)]
enum Axles {
    Heading,
    Attitude,
}

fn clearance(
    body: &TiltedBody,
    ground: &GroundPlane,
    x: &State,
    wheel_radius: f64,
    axles: Axles,
) -> f64 {
    let rot = rotation(x[idx::YAW], x[idx::PITCH], x[idx::ROLL]);
    let (sy, cy) = sin_cos(x[idx::YAW]);
    let n = &ground.normal;
    body.rotor_position
        .iter()
        .zip(&body.rotor_axis)
        .map(|(r, a)| {
            let hub = Vector3::new(
                x[idx::X] + rot.row(0).transpose().dot(r),
                x[idx::Y] + rot.row(1).transpose().dot(r),
                x[idx::Z] + rot[(2, 0)] * r.x + rot[(2, 1)] * r.y + rot[(2, 2)] * r.z,
            );
            let along = match axles {
                Axles::Heading => {
                    n.z * a.z + n.x * (cy * a.x - sy * a.y) + n.y * (sy * a.x + cy * a.y)
                }
                Axles::Attitude => n.dot(&(rot * a)),
            };
            let reach = wheel_radius * (1.0 - along * along).max(0.0).sqrt();
            ground.height(&hub) - reach
        })
        .fold(f64::INFINITY, f64::min)
}

/// Where the plan's wheels meet the ground: the fractional stage at which
/// the clearance `c_k` first crosses zero, or the last stage.
fn touchdown_stage(clearance: impl Iterator<Item = f64>, steps: usize) -> f64 {
    let mut previous: Option<f64> = None;
    for (k, c) in clearance.enumerate() {
        if c <= 0.0 {
            return match previous {
                Some(p) if p > 0.0 => (k - 1) as f64 + p / (p - c),
                _ => k as f64,
            };
        }
        previous = Some(c);
    }
    steps as f64
}

impl Mpc {
    /// In the next preparations the MPC plans the tilt within `plan` (see
    /// [`crate::controller`]'s tilt-plan docs); [`Mpc::set_tilt_ramp`] or
    /// [`Mpc::set_tilt_sequence`] hand the tilt back to the parameter.
    /// Errors when `[tilt_plan]` is not configured or the plan is malformed.
    pub fn set_tilt_plan(&mut self, plan: &TiltPlan) -> Result<()> {
        check_finite(
            "tilt plan",
            0,
            &[
                plan.tilt_min,
                plan.tilt_max,
                plan.rate_min,
                plan.rate_max,
                plan.wheel_radius,
                plan.thrust_max.unwrap_or(0.0),
            ],
        )?;
        for (what, v, max) in [
            ("tilt plan tilt_min", plan.tilt_min, plan.tilt_max),
            ("tilt plan tilt_max", plan.tilt_max, FRAC_PI_2),
            ("tilt plan rate_min", plan.rate_min, 0.0),
            ("tilt plan wheel_radius", plan.wheel_radius, 1.0),
            // A rotor command is a fraction of its full thrust.
            ("tilt plan thrust_max", plan.thrust_max.unwrap_or(1.0), 1.0),
        ] {
            let min = if what.ends_with("rate_min") {
                f64::MIN
            } else {
                0.0
            };
            if !(min..=max + 1e-9).contains(&v) {
                return Err(MpcError::OutOfRange {
                    what,
                    value: v,
                    min,
                    max,
                });
            }
        }
        if plan.rate_max < 0.0 {
            return Err(MpcError::OutOfRange {
                what: "tilt plan rate_max",
                value: plan.rate_max,
                min: 0.0,
                max: f64::MAX,
            });
        }
        let dt = self.stage_dt;
        let Some(tilt) = self.tilt.as_deref_mut() else {
            return Err(MpcError::Solver(
                "set_tilt_plan: no [tilt_plan] in the MPC settings".into(),
            ));
        };
        if tilt.plan.is_none() {
            // Taking over from the parameter: the plan continues its sequence.
            for k in 0..self.steps {
                tilt.rate[k] = ((self.varphi[k + 1] - self.varphi[k]) / dt)
                    .clamp(plan.rate_min, plan.rate_max);
            }
        }
        tilt.plan = Some(*plan);
        Ok(())
    }

    /// The measured tilt the next feedback starts the tilt plan from, rad.
    pub fn set_measured_tilt(&mut self, varphi: f64) -> Result<()> {
        check_finite("measured tilt", 0, &[varphi])?;
        if let Some(tilt) = self.tilt.as_deref_mut() {
            tilt.measured = varphi;
        }
        Ok(())
    }

    /// Whether the MPC plans the tilt (a [`TiltPlan`] is in force).
    pub fn plans_tilt(&self) -> bool {
        self.tilt.as_ref().is_some_and(|t| t.plan.is_some())
    }

    /// The planned tilt rate per stage (empty unless the tilt is planned).
    pub fn planned_tilt_rates(&self) -> &[f64] {
        match self.tilt.as_deref() {
            Some(t) if t.plan.is_some() => &t.rate,
            _ => &[],
        }
    }

    /// The predicted touchdown of the last tilt-planning preparation, as a
    /// fractional stage (N: not within the horizon).
    pub fn predicted_touchdown_stage(&self) -> Option<f64> {
        self.tilt
            .as_deref()
            .filter(|t| t.active)
            .map(|t| t.touchdown_stage)
    }

    /// Back to the tilt as a parameter (the ramp setters call this).
    pub(super) fn stop_planning_tilt(&mut self) {
        if let Some(tilt) = self.tilt.as_deref_mut() {
            tilt.plan = None;
            tilt.active = false;
            tilt.last_applied = None;
        }
    }

    fn tilting_body(&self) -> TiltingBody<'_> {
        TiltingBody {
            model: &self.model,
            disturbance: self.disturbance,
            surface: self
                .ground_effect
                .as_deref()
                .map(|s| s as &dyn ThrustGainSurface),
            ground_z: self.ground_z,
        }
    }

    /// Shifts the tilt plan as `shift_plan` shifts the states and inputs.
    pub(super) fn shift_tilt_plan(&mut self) {
        let s = self.shift_fraction;
        let n = self.steps;
        let dt = self.stage_dt;
        let Some(tilt) = self.tilt.as_deref_mut().filter(|t| t.plan.is_some()) else {
            return;
        };
        let last = self.varphi[n] + tilt.rate[n - 1] * dt;
        for k in 0..n {
            self.varphi[k] = self.varphi[k] * (1.0 - s) + self.varphi[k + 1] * s;
        }
        self.varphi[n] = self.varphi[n] * (1.0 - s) + last * s;
        for k in 0..n - 1 {
            tilt.rate[k] = tilt.rate[k] * (1.0 - s) + tilt.rate[k + 1] * s;
        }
    }

    /// The wheels' clearance above the ground plane at a plan stage, m.
    fn clearance(&self, x: &State, varphi: f64, wheel_radius: f64) -> f64 {
        wheel_clearance(&self.model.at_tilt(varphi), &self.ground, x, wheel_radius)
    }

    /// The preparation's linearization for the tilt-planning QP: the
    /// 13/5 sensitivities along the plan, the weights with the landing
    /// objective, the bounds; loaded into the solver.
    pub(super) fn linearize_tilt_plan(&mut self) -> Result<()> {
        // Taken out for the borrow of the model beside it (moves the box, no allocation).
        let Some(mut tilt) = self.tilt.take() else {
            return Err(MpcError::NotPrepared);
        };
        let result = self.fill_tilt_linearization(&mut tilt);
        self.tilt = Some(tilt);
        result
    }

    fn fill_tilt_linearization(&mut self, tilt: &mut TiltPlanner) -> Result<()> {
        let Some(plan) = tilt.plan else {
            return Err(MpcError::NotPrepared);
        };
        let n = self.steps;
        let dt = self.stage_dt;
        let w = tilt.weights;
        let q = self.state_weight_now();
        let r = self.settings.weights.input_weight(self.alpha);
        for k in 0..n {
            self.u_ref[k] = self.rotor_reference(hover_reference(&self.stage_body(self.varphi[k])));
        }
        let failed = {
            let f = self.tilting_body();
            let lin = &mut tilt.lin;
            let mut failed = None;
            for k in 0..n {
                let v = tilt_input(&self.plan_u[k], tilt.rate[k]);
                let s =
                    rk4_step_sensitivity(&f, &tilt_state(&self.plan_x[k], self.varphi[k]), &v, dt);
                let defect = s.next - tilt_state(&self.plan_x[k + 1], self.varphi[k + 1]);
                if !(s.a.iter().all(|v| v.is_finite())
                    && s.b.iter().all(|v| v.is_finite())
                    && defect.iter().all(|v| v.is_finite()))
                {
                    failed = Some(k);
                    break;
                }
                lin.a[k] = s.a;
                lin.b[k] = s.b;
                lin.defect[k] = defect;
                lin.q_diag[k] = tilt_state(&q, w.tilt_weight);
                lin.u_err[k] = tilt_input(&(self.plan_u[k] - self.u_ref[k]), tilt.rate[k]);
                lin.u_bar[k] = v;
                let lo = plan.rate_min.max((plan.tilt_min - self.varphi[k]) / dt);
                let hi = plan.rate_max.min((plan.tilt_max - self.varphi[k]) / dt);
                lin.u_lo[k] = tilt_input(&self.rotor_min, lo.min(hi));
                let rotor_max = plan.thrust_max.unwrap_or(w.thrust_max);
                let top = self
                    .rotor_max
                    .zip_map(&self.rotor_min, |m, lo| m.min(rotor_max).max(lo));
                lin.u_hi[k] = tilt_input(&top, hi);
            }
            failed
        };
        if let Some(stage) = failed {
            self.plan_diverged = true;
            return Err(MpcError::NonFiniteLinearization { stage });
        }
        let lin = &mut tilt.lin;
        lin.q_diag[n] = tilt_state(&(q * self.settings.cost.terminal_scale), w.tilt_weight);
        for q_k in &mut lin.q_diag {
            q_k[idx::VZ] += w.descent_speed_weight;
            q_k[idx::PITCH] += w.level_weight;
            q_k[idx::ROLL] += w.level_weight;
        }
        lin.r_diag = tilt_input(&r, w.rate_weight);
        for k in 0..=n {
            let mut e = self.plan_x[k] - self.x_ref[k];
            e[idx::YAW] = wrap_angle(e[idx::YAW]);
            lin.x_err[k] = tilt_state(&e, self.varphi[k] - plan.tilt_max);
        }
        // The landing objective at the predicted touchdown; the plan ends
        // there (past it the model, without the ground, is fiction).
        let touchdown = touchdown_stage(
            (0..=n).map(|k| self.clearance(&self.plan_x[k], self.varphi[k], plan.wheel_radius)),
            n,
        );
        tilt.touchdown_stage = touchdown;
        for k in 0..=n {
            let kept = (1.0 - (k as f64 - touchdown)).clamp(0.0, 1.0);
            if kept < 1.0 {
                lin.q_diag[k] *= kept;
            }
        }
        let below = touchdown.floor() as usize;
        let frac = touchdown - below as f64;
        for (k, lambda) in [(below, 1.0 - frac), (below + 1, frac)] {
            if k <= n && lambda > 0.0 {
                lin.q_diag[k][TILT] += lambda * w.touchdown_tilt_weight;
                lin.q_diag[k][idx::VZ] += lambda * w.touchdown_speed_weight;
                lin.x_err[k][idx::VZ] = self.plan_x[k][idx::VZ] - w.touchdown_speed;
            }
        }
        tilt.qp.load(&tilt.lin)?;
        tilt.active = true;
        Ok(())
    }

    /// `varphi_pred - varphibar_0` for the measured tilt the preparation
    /// expects (as [`Mpc::predicted_deviation`] for the states).
    pub(super) fn predicted_tilt_deviation(&self, shifted: bool) -> f64 {
        let Some(tilt) = self.tilt.as_deref() else {
            return 0.0;
        };
        let Some((varphi, rate)) = tilt.last_applied else {
            return 0.0;
        };
        let predicted = match (shifted, self.settings.feedback.predictor) {
            (false, _) => varphi,
            (true, crate::settings::Predictor::Plan) => return 0.0,
            (true, crate::settings::Predictor::Model) => {
                varphi + rate * self.settings.horizon.tick_period
            }
        };
        let e = predicted - self.varphi[0];
        if e.is_finite() { e } else { 0.0 }
    }
}

#[cfg(test)]
mod tests {
    use super::{
        GroundPlane, State, Vector3, idx, rotation, sin_cos, touchdown_stage, wheel_clearance,
        wheel_clearance_at_attitude,
    };
    use atmo_core::{Model, RobotConfig};

    #[test]
    fn clearance_on_a_slope_is_the_lowest_rim_towards_the_plane() {
        // Hand-computed: hubs at (+-0.2, +-0.15, 0.05) m (body), the wheels'
        // axles (+-sin 70, 0, -cos 70) (the sign of the hub's x), base 0.5 m
        // above the origin, level, yaw 0; the ground a 25 deg slope through
        // the origin rising to +x, n = (-sin 25, 0, -cos 25). Uphill hubs:
        // n . p = 0.2 (-sin 25) + 0.45 cos 25 = 0.3233149 m, reach
        // 0.125 sqrt(1 - cos(95 deg)^2) = 0.1245243 m; downhill:
        // 0.4923622 m and 0.125 sqrt(1 - cos(45 deg)^2) = 0.0883883 m.
        let phi = 70f64.to_radians();
        let mut body = Model::new(&RobotConfig::atmo()).at_tilt(phi);
        for (i, (x, y)) in [(0.2, 0.15), (0.2, -0.15), (-0.2, 0.15), (-0.2, -0.15)]
            .into_iter()
            .enumerate()
        {
            body.rotor_position[i] = Vector3::new(x, y, 0.05);
            body.rotor_axis[i] = Vector3::new(f64::signum(x) * phi.sin(), 0.0, -phi.cos());
        }
        let s = 25f64.to_radians();
        let slope =
            GroundPlane::new(Vector3::zeros(), Vector3::new(-s.sin(), 0.0, -s.cos())).unwrap();
        let mut x = State::zeros();
        x[idx::Z] = -0.5;
        let c = wheel_clearance(&body, &slope, &x, 0.125);
        assert!((c - 0.198_790_514_556_884).abs() < 1e-12, "{c}");
        // The level ground measures hub heights minus R sin(70 deg): 0.45 - 0.1174616.
        let level = wheel_clearance(&body, &GroundPlane::level(0.0), &x, 0.125);
        assert!(
            (level - (0.45 - 0.125 * phi.sin())).abs() < 1e-12,
            "{level}"
        );
        // Facing east (yaw 90 deg) the hubs lie across the slope: the
        // highest-ground hubs are those at world x = +0.15.
        x[idx::YAW] = std::f64::consts::FRAC_PI_2;
        let across = wheel_clearance(&body, &slope, &x, 0.125);
        let reach = 0.125 * (1.0 - (s.cos() * phi.cos()).powi(2)).sqrt();
        let expected = -0.15 * s.sin() + 0.45 * s.cos() - reach;
        assert!((across - expected).abs() < 1e-12, "{across} {expected}");
    }

    #[test]
    fn level_clearance_is_the_lowest_hub_minus_the_rim_reach_of_the_tilt() {
        // The model's own body (any tilt and attitude) on level ground: bit
        // for bit the clearance before the ground plane, hub heights with the
        // attitude minus R_w sin(varphi) (the reach at a level attitude).
        let model = Model::new(&RobotConfig::atmo());
        let mut x = State::zeros();
        x[idx::Z] = -0.4;
        x[idx::YAW] = 0.7;
        for (pitch, roll) in [(0.0, 0.0), (0.05, -0.03), (-0.1, 0.08)] {
            x[idx::PITCH] = pitch;
            x[idx::ROLL] = roll;
            let (sp, cp) = sin_cos(pitch);
            let (sr, cr) = sin_cos(roll);
            for deg in [0.0, 30.0, 50.0, 62.0, 70.0, 90.0] {
                let body = model.at_tilt(f64::to_radians(deg));
                let lowest = body
                    .rotor_position
                    .iter()
                    .map(|r| -0.1 - (x[idx::Z] - sp * r.x + cp * sr * r.y + cp * cr * r.z))
                    .fold(f64::INFINITY, f64::min);
                let expected = lowest - 0.125 * sin_cos(body.varphi).0;
                let c = wheel_clearance(&body, &GroundPlane::level(-0.1), &x, 0.125);
                assert_eq!(c, expected, "{deg} deg, pitch {pitch}, roll {roll}");
            }
        }
    }

    #[test]
    fn clearance_at_attitude_turns_the_axles_with_the_body() {
        // Level: the same as the heading-only clearance, bit for bit.
        let model = Model::new(&RobotConfig::atmo());
        let body = model.at_tilt(66f64.to_radians());
        let ground = GroundPlane::level(0.0);
        let mut x = State::zeros();
        x[idx::Z] = -0.2;
        x[idx::YAW] = 0.4;
        assert_eq!(
            wheel_clearance_at_attitude(&body, &ground, &x, 0.125),
            wheel_clearance(&body, &ground, &x, 0.125)
        );
        // Rolled by 3 deg: each rim reaches down by R_w sqrt(1 - (z . R a_i)^2)
        // (the axle turned by the whole rotation), computed here per wheel.
        x[idx::ROLL] = 3f64.to_radians();
        let rot = rotation(x[idx::YAW], x[idx::PITCH], x[idx::ROLL]);
        let expected = body
            .rotor_position
            .iter()
            .zip(&body.rotor_axis)
            .map(|(r, a)| {
                let hub_z = x[idx::Z] + (rot * r).z;
                let along = (rot * a).z;
                -hub_z - 0.125 * (1.0 - along * along).sqrt()
            })
            .fold(f64::INFINITY, f64::min);
        let c = wheel_clearance_at_attitude(&body, &ground, &x, 0.125);
        assert!((c - expected).abs() < 1e-12, "{c} {expected}");
        // The heading-only clearance differs there by millimetres.
        let level_axles = wheel_clearance(&body, &ground, &x, 0.125);
        assert!((level_axles - c).abs() > 1e-3, "{level_axles} {c}");
    }

    #[test]
    fn touchdown_is_interpolated_where_the_clearance_crosses_zero() {
        assert!((touchdown_stage([0.3, 0.2, 0.1, -0.1, -0.3].into_iter(), 4) - 2.5).abs() < 1e-12);
        assert_eq!(touchdown_stage([0.3, 0.2].into_iter(), 1), 1.0);
        assert_eq!(touchdown_stage([-0.1, -0.2].into_iter(), 1), 0.0);
    }
}
