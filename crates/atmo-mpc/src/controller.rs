//! The RTI controller: plan, preparation, feedback, fallback.

use std::f64::consts::{PI, TAU};
use std::time::{Duration, Instant};

use atmo_core::control::blending_alpha;
use atmo_core::model::{Input, Model, State, idx};
use clarabel::solver::SolverStatus;

use crate::error::{MpcError, Result};
use crate::homotopy::HomotopyStop;
use crate::qp::{LinearizedHorizon, QpBackend, QpSnapshot, SolveReport};
use crate::settings::{FeedbackMethod, Formulation, MpcSettings, Predictor};

/// Wraps an angle to (-pi, pi].
pub fn wrap_angle(a: f64) -> f64 {
    let w = a.rem_euclid(TAU);
    if w > PI { w - TAU } else { w }
}

/// Why a tick could not use a fresh solution.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FailureCause {
    /// The state estimate had a NaN or infinity (entry index).
    NonFiniteEstimate { entry: usize },
    /// The preparation phase failed (non-finite linearization, solver update).
    PreparationFailed,
    /// Clarabel ended without a usable solution.
    Solver(SolverStatus),
    /// Clarabel reported success but the solution was not finite.
    NonFiniteSolution,
}

/// Why a usable solution is less than fully solved.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DegradedCause {
    /// Clarabel's reduced tolerances were met (`AlmostSolved`).
    ReducedAccuracy,
    /// The iteration cap was hit with an iterate that meets the reduced
    /// tolerances; it is used. (Clarabel itself usually reports this as
    /// `AlmostSolved`.)
    IterationLimit,
    /// The time limit was hit with an iterate that meets the reduced
    /// tolerances; it is used. Limits hit earlier are a `Fallback`.
    TimeLimit,
}

/// How a tick ended.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Outcome {
    /// Fresh solution within the full tolerances.
    Solved,
    /// Fresh solution of reduced quality, still used.
    Degraded(DegradedCause),
    /// No fresh solution: flying the shifted previous plan, `failed_ticks`
    /// in a row (at most the configured grace).
    Fallback {
        cause: FailureCause,
        failed_ticks: u32,
    },
    /// More failed ticks in a row than the grace allows: the flight stack
    /// must act. The command is still the shifted previous plan.
    Failed {
        cause: FailureCause,
        failed_ticks: u32,
    },
}

impl Outcome {
    /// True when this tick's command comes from a fresh solve.
    pub fn is_fresh(&self) -> bool {
        matches!(self, Self::Solved | Self::Degraded(_))
    }
}

/// Wall-clock cost of one tick.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct TickTimings {
    /// The preparation that preceded this feedback (including its Clarabel
    /// solve at the predicted state).
    pub preparation: Duration,
    /// The Clarabel solve inside the preparation (zero without the homotopy).
    pub preparation_solve: Duration,
    pub preparation_solver_iterations: u32,
    /// Estimate in, command out.
    pub feedback: Duration,
    /// The Clarabel solve inside the feedback (zero when the homotopy gave
    /// the solution).
    pub solve: Duration,
    pub feedback_solver_iterations: u32,
    /// Interior-point iterations behind this tick's solution: the
    /// preparation's solve plus the feedback's (> 0 whenever a QP was solved).
    pub solver_iterations: u32,
}

/// Why the feedback fell back from the homotopy to a full Clarabel solve.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum HomotopyFallback {
    /// The preparation's correction of Clarabel's active set stopped.
    Preparation(HomotopyStop),
    /// The feedback's walk to the estimate stopped.
    Feedback(HomotopyStop),
}

/// How the feedback phase got the QP's solution.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FeedbackPath {
    /// The parametric active-set homotopy from the prepared solution: the
    /// exact QP solution, after `active_set_changes` working-set changes.
    Homotopy { active_set_changes: u32 },
    /// A full Clarabel solve at the estimate; `fallback` says why when the
    /// homotopy was configured (`None`: Clarabel is the configured method, or
    /// the sparse formulation).
    Clarabel { fallback: Option<HomotopyFallback> },
    /// No QP solved (non-finite estimate, failed preparation).
    NoSolve,
}

impl FeedbackPath {
    /// True when the homotopy was configured and could not give the solution.
    pub fn is_fallback(&self) -> bool {
        matches!(self, Self::Clarabel { fallback: Some(_) })
    }
}

/// What one feedback phase returns.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TickOutput {
    /// Rotor commands to apply now, each in [0, 1].
    pub u: Input,
    pub outcome: Outcome,
    pub timings: TickTimings,
    pub path: FeedbackPath,
}

/// Result of [`Mpc::converge_sqp`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SqpReport {
    pub iterations: usize,
    /// Largest entry of the last step (dx, du).
    pub last_step: f64,
    pub converged: bool,
}

/// Refreshes alpha every `period` ticks, as the flight stack does.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AlphaSchedule {
    period: u32,
    ticks_left: u32,
    alpha: f64,
}

impl AlphaSchedule {
    pub fn new(period: u32) -> Self {
        Self {
            period: period.max(1),
            ticks_left: 0,
            alpha: 1.0,
        }
    }

    /// The alpha for this tick: `blending_alpha(height, varphi, z*)`
    /// recomputed on the first tick and then every `period` ticks, held in between.
    pub fn update(&mut self, height: f64, varphi: f64, transition_height: f64) -> f64 {
        if self.ticks_left == 0 {
            let fresh = blending_alpha(height, varphi, transition_height);
            if fresh.is_finite() {
                self.alpha = fresh;
            }
            self.ticks_left = self.period;
        }
        self.ticks_left -= 1;
        self.alpha
    }

    pub fn alpha(&self) -> f64 {
        self.alpha
    }
}

/// The RTI NMPC.
///
/// Per tick: [`Mpc::prepare`] (before the estimate arrives), then
/// [`Mpc::feedback`] with the estimate. Horizon parameters (reference,
/// tilt sequence, alpha) are set before `prepare`.
pub struct Mpc {
    model: Model,
    settings: MpcSettings,
    steps: usize,
    stage_dt: f64,
    /// Fraction of a stage the plan moves per tick.
    shift_fraction: f64,
    plan_x: Vec<State>,
    plan_u: Vec<Input>,
    x_ref: Vec<State>,
    u_ref: Vec<Input>,
    varphi: Vec<f64>,
    alpha: f64,
    lin: LinearizedHorizon,
    qp: QpBackend,
    dx: Vec<State>,
    du: Vec<Input>,
    prepared: bool,
    preparation_ok: bool,
    /// The last preparation met a non-finite linearization.
    plan_diverged: bool,
    preparation_time: Duration,
    preparation_solve: SolveReport,
    /// The `dx_0` the last preparation solved at.
    predicted_e0: State,
    /// The preparation's exact solution at the predicted state, when the
    /// homotopy is in use: `Ok` (ready) or why it is not.
    prepared_solution: Option<std::result::Result<(), HomotopyStop>>,
    /// The last finite estimate and the command flown after it (the model predictor's start).
    last_applied: Option<(State, Input)>,
    /// Feedback phases that fell back from the homotopy to Clarabel.
    homotopy_fallbacks: u64,
    failed_ticks: u32,
    /// Estimated disturbance wrench the predictions include (offset-free MPC).
    disturbance: nalgebra::Vector6<f64>,
}

impl Mpc {
    /// Builds the controller and its solver (the only allocations), with the
    /// plan at hover at the origin, level, varphi = 0.
    pub fn new(model: Model, settings: MpcSettings) -> Result<Self> {
        let steps = settings.horizon.steps;
        let stage_dt = settings.stage_dt();
        let shift_fraction = settings.horizon.tick_period / stage_dt;
        let hover = model.at_tilt(0.0).hover_trim().map(|u| u.clamp(0.0, 1.0));
        let mut lin = LinearizedHorizon::new(steps);
        Self::start_up_linearization(&model, &settings, &hover, &mut lin);
        let qp = QpBackend::new(&lin, &settings.solver)?;
        Ok(Self {
            model,
            steps,
            stage_dt,
            shift_fraction,
            plan_x: vec![State::zeros(); steps + 1],
            plan_u: vec![hover; steps],
            x_ref: vec![State::zeros(); steps + 1],
            u_ref: vec![hover; steps],
            varphi: vec![0.0; steps + 1],
            alpha: 1.0,
            lin,
            qp,
            dx: vec![State::zeros(); steps + 1],
            du: vec![Input::zeros(); steps],
            prepared: false,
            preparation_ok: false,
            plan_diverged: false,
            preparation_time: Duration::ZERO,
            preparation_solve: SolveReport {
                status: SolverStatus::Unsolved,
                iterations: 0,
                solve_time: 0.0,
            },
            prepared_solution: None,
            predicted_e0: State::zeros(),
            last_applied: None,
            homotopy_fallbacks: 0,
            failed_ticks: 0,
            disturbance: nalgebra::Vector6::zeros(),
            settings,
        })
    }

    /// A representative linearization (hover at varphi = 0, with a small
    /// attitude and rate so that no Jacobian entry is accidentally zero) to
    /// build the solver and its equilibration from.
    fn start_up_linearization(
        model: &Model,
        settings: &MpcSettings,
        hover: &Input,
        lin: &mut LinearizedHorizon,
    ) {
        let body = model.at_tilt(0.0);
        let mut x = State::zeros();
        x[idx::PITCH] = 0.05;
        x[idx::ROLL] = -0.05;
        x[idx::WX] = 0.1;
        x[idx::WY] = -0.1;
        x[idx::WZ] = 0.05;
        let dt = settings.stage_dt();
        let q = settings.weights.state_weight(1.0);
        for k in 0..settings.horizon.steps {
            let s = body.rk4_step_sensitivity(&x, hover, dt);
            lin.a[k] = s.a;
            lin.b[k] = s.b;
            lin.defect[k] = State::zeros();
            lin.q_diag[k] = q;
            lin.u_bar[k] = *hover;
            lin.u_err[k] = Input::zeros();
        }
        lin.q_diag[settings.horizon.steps] = q * settings.cost.terminal_scale;
        lin.r_diag = settings.weights.input_weight(1.0);
    }

    pub fn settings(&self) -> &MpcSettings {
        &self.settings
    }

    pub fn model(&self) -> &Model {
        &self.model
    }

    pub fn formulation(&self) -> Formulation {
        self.qp.formulation()
    }

    /// N.
    pub fn steps(&self) -> usize {
        self.steps
    }

    pub fn stage_dt(&self) -> f64 {
        self.stage_dt
    }

    /// The linearization along the plan of the last preparation.
    pub fn linearization(&self) -> &LinearizedHorizon {
        &self.lin
    }

    /// Predicted states `x_0..x_N` of the current plan.
    pub fn plan_states(&self) -> &[State] {
        &self.plan_x
    }

    /// Planned inputs `u_0..u_{N-1}`.
    pub fn plan_inputs(&self) -> &[Input] {
        &self.plan_u
    }

    /// Input reference per stage (hover trim at the stage tilt, clamped to [0, 1]).
    pub fn input_reference(&self) -> &[Input] {
        &self.u_ref
    }

    pub fn alpha(&self) -> f64 {
        self.alpha
    }

    pub fn tilt_sequence(&self) -> &[f64] {
        &self.varphi
    }

    /// Consecutive ticks without a fresh solution.
    pub fn failed_ticks(&self) -> u32 {
        self.failed_ticks
    }

    /// Feedback phases so far that fell back from the homotopy to a full
    /// Clarabel solve ([`FeedbackPath::is_fallback`]).
    pub fn homotopy_fallbacks(&self) -> u64 {
        self.homotopy_fallbacks
    }

    /// The deviation `x_pred - xbar_0` the last preparation solved the QP at
    /// (zero without the homotopy).
    pub fn predicted_deviation_of_last_preparation(&self) -> State {
        self.predicted_e0
    }

    /// True when the feedback uses the homotopy (configured, condensed QP).
    pub fn uses_homotopy(&self) -> bool {
        self.settings.feedback.method == FeedbackMethod::Homotopy
            && self.formulation() == Formulation::Condensed
    }

    /// Starts the plan at `x0` (held over the horizon) with hover-trim
    /// inputs at the current tilt sequence. Call once before the first tick
    /// and after a `NonFiniteLinearization`.
    pub fn reset(&mut self, x0: &State) -> Result<()> {
        check_finite("reset state", 0, x0.as_slice())?;
        self.restart_plan(x0);
        self.failed_ticks = 0;
        self.prepared = false;
        self.last_applied = None;
        Ok(())
    }

    /// Plan held at `x0` with hover-trim inputs at the stage tilts.
    fn restart_plan(&mut self, x0: &State) {
        self.refresh_input_reference();
        for x in &mut self.plan_x {
            *x = *x0;
        }
        self.plan_u.copy_from_slice(&self.u_ref);
        self.plan_diverged = false;
    }

    /// Sets the same state reference for every stage.
    pub fn set_reference_constant(&mut self, x_ref: &State) -> Result<()> {
        check_finite("state reference", 0, x_ref.as_slice())?;
        for r in &mut self.x_ref {
            *r = *x_ref;
        }
        Ok(())
    }

    /// Sets the state reference per stage (N + 1 entries).
    pub fn set_reference(&mut self, x_ref: &[State]) -> Result<()> {
        check_len("state reference", self.steps + 1, x_ref.len())?;
        for (k, r) in x_ref.iter().enumerate() {
            check_finite("state reference", k, r.as_slice())?;
        }
        self.x_ref.copy_from_slice(x_ref);
        Ok(())
    }

    /// Sets the tilt per stage (N + 1 entries, rad).
    pub fn set_tilt_sequence(&mut self, varphi: &[f64]) -> Result<()> {
        check_len("tilt sequence", self.steps + 1, varphi.len())?;
        for (k, v) in varphi.iter().enumerate() {
            check_finite("tilt sequence", k, &[*v])?;
            check_tilt(*v)?;
        }
        self.varphi.copy_from_slice(varphi);
        Ok(())
    }

    /// The paper's tilt parameter: `varphi_k = clamp(varphi_now + rate t_k, min, max)`
    /// with `t_k = k T / N`.
    pub fn set_tilt_ramp(&mut self, varphi_now: f64, rate: f64, min: f64, max: f64) -> Result<()> {
        for (what, v) in [
            ("tilt", varphi_now),
            ("tilt rate", rate),
            ("tilt min", min),
            ("tilt max", max),
        ] {
            check_finite(what, 0, &[v])?;
        }
        check_tilt(min)?;
        check_tilt(max)?;
        if min > max {
            return Err(MpcError::OutOfRange {
                what: "tilt min",
                value: min,
                min: 0.0,
                max,
            });
        }
        for (k, v) in self.varphi.iter_mut().enumerate() {
            *v = (varphi_now + rate * self.stage_dt * k as f64).clamp(min, max);
        }
        Ok(())
    }

    /// Sets the cost blend alpha (in [0, 1]) for the next preparations.
    pub fn set_alpha(&mut self, alpha: f64) -> Result<()> {
        if !(alpha.is_finite() && (0.0..=1.0).contains(&alpha)) {
            return Err(MpcError::OutOfRange {
                what: "alpha",
                value: alpha,
                min: 0.0,
                max: 1.0,
            });
        }
        self.alpha = alpha;
        Ok(())
    }

    /// Sets the disturbance wrench (body force, torque about B) that the
    /// predictions and the input reference include from the next preparation.
    pub fn set_disturbance(&mut self, wrench: &nalgebra::Vector6<f64>) -> Result<()> {
        if let Some(bad) = wrench.iter().find(|v| !v.is_finite()) {
            return Err(MpcError::OutOfRange {
                what: "disturbance wrench",
                value: *bad,
                min: f64::MIN,
                max: f64::MAX,
            });
        }
        self.disturbance = *wrench;
        Ok(())
    }

    /// The disturbance wrench in use.
    pub fn disturbance(&self) -> nalgebra::Vector6<f64> {
        self.disturbance
    }

    fn refresh_input_reference(&mut self) {
        for k in 0..self.steps {
            self.u_ref[k] = self
                .model
                .at_tilt(self.varphi[k])
                .with_disturbance(self.disturbance)
                .hover_trim()
                .map(|u| u.clamp(0.0, 1.0));
        }
    }

    /// Preparation phase: shift the plan by one tick, linearize along it
    /// (RK4 sensitivities), build the QP. Needs no estimate.
    pub fn prepare(&mut self) -> Result<Duration> {
        self.prepare_inner(true)
    }

    fn prepare_inner(&mut self, shift: bool) -> Result<Duration> {
        let start = Instant::now();
        self.prepared = true;
        self.preparation_ok = false;
        if shift {
            self.shift_plan();
        }
        self.rewrap_plan_yaw();
        let weights = &self.settings.weights;
        let q = weights.state_weight(self.alpha);
        let r = weights.input_weight(self.alpha);
        let dt = self.stage_dt;
        for k in 0..self.steps {
            let body = self
                .model
                .at_tilt(self.varphi[k])
                .with_disturbance(self.disturbance);
            self.u_ref[k] = body.hover_trim().map(|u| u.clamp(0.0, 1.0));
            let s = body.rk4_step_sensitivity(&self.plan_x[k], &self.plan_u[k], dt);
            let defect = s.next - self.plan_x[k + 1];
            if !(s.a.iter().all(|v| v.is_finite())
                && s.b.iter().all(|v| v.is_finite())
                && defect.iter().all(|v| v.is_finite()))
            {
                self.preparation_time = start.elapsed();
                self.plan_diverged = true;
                return Err(MpcError::NonFiniteLinearization { stage: k });
            }
            self.lin.a[k] = s.a;
            self.lin.b[k] = s.b;
            self.lin.defect[k] = defect;
            self.lin.q_diag[k] = q;
            self.lin.u_err[k] = self.plan_u[k] - self.u_ref[k];
            self.lin.u_bar[k] = self.plan_u[k];
        }
        self.lin.q_diag[self.steps] = q * self.settings.cost.terminal_scale;
        self.lin.r_diag = r;
        for k in 0..=self.steps {
            let mut e = self.plan_x[k] - self.x_ref[k];
            e[idx::YAW] = wrap_angle(e[idx::YAW]);
            self.lin.x_err[k] = e;
        }
        self.qp.load(&self.lin)?;
        self.prepared_solution = None;
        self.preparation_solve.solve_time = 0.0;
        self.preparation_solve.iterations = 0;
        if self.uses_homotopy() {
            let e0 = self.predicted_deviation(shift);
            self.predicted_e0 = e0;
            let max_changes = self.settings.feedback.max_preparation_changes;
            if let Some(qp) = self.qp.condensed_mut() {
                let prepared = qp.prepare_solution(&e0, max_changes)?;
                self.preparation_solve = prepared.clarabel;
                self.prepared_solution = Some(prepared.correction.map(|_| ()));
            }
        }
        self.preparation_ok = true;
        self.preparation_time = start.elapsed();
        Ok(self.preparation_time)
    }

    /// `x_pred - xbar_0` for the estimate the preparation expects (see
    /// [`Predictor`]); zero (the shifted plan) when there is no last estimate.
    /// Without a shift (re-planning at the same time) the last estimate itself.
    fn predicted_deviation(&self, shifted: bool) -> State {
        let Some((x, u)) = self.last_applied else {
            return State::zeros();
        };
        let predicted = match (shifted, self.settings.feedback.predictor) {
            (false, _) => x,
            (true, Predictor::Plan) => return State::zeros(),
            (true, Predictor::Model) => self
                .model
                .at_tilt(self.varphi[0])
                .with_disturbance(self.disturbance)
                .rk4_step(&x, &u, self.settings.horizon.tick_period),
        };
        let mut e0 = predicted - self.plan_x[0];
        e0[idx::YAW] = wrap_angle(e0[idx::YAW]);
        if e0.iter().all(|v| v.is_finite()) {
            e0
        } else {
            State::zeros()
        }
    }

    /// Moves the plan forward by one controller period: linear interpolation
    /// between stages (the tick is a fraction of a stage), the last state
    /// continued by one RK4 step with the last input.
    fn shift_plan(&mut self) {
        let s = self.shift_fraction;
        let n = self.steps;
        let last = self
            .model
            .at_tilt(self.varphi[n])
            .with_disturbance(self.disturbance)
            .rk4_step(&self.plan_x[n], &self.plan_u[n - 1], self.stage_dt);
        for k in 0..n {
            self.plan_x[k] = self.plan_x[k] * (1.0 - s) + self.plan_x[k + 1] * s;
        }
        self.plan_x[n] = self.plan_x[n] * (1.0 - s) + last * s;
        for k in 0..n - 1 {
            self.plan_u[k] = self.plan_u[k] * (1.0 - s) + self.plan_u[k + 1] * s;
        }
    }

    /// Keeps the plan's yaw near (-pi, pi] by whole turns (the dynamics are
    /// 2 pi periodic in yaw, so this changes nothing physical).
    fn rewrap_plan_yaw(&mut self) {
        let yaw0 = self.plan_x[0][idx::YAW];
        if yaw0.is_finite() && yaw0.abs() > PI {
            let turns = (yaw0 / TAU).round() * TAU;
            for x in &mut self.plan_x {
                x[idx::YAW] -= turns;
            }
        }
    }

    /// Feedback phase: the QP's solution at the estimate (the homotopy from
    /// the prepared solution, or Clarabel), applied to the plan; returns the
    /// command. Never panics on bad numbers: a non-finite estimate or a failed
    /// solve gives the shifted previous plan and a `Fallback`/`Failed` outcome.
    pub fn feedback(&mut self, x_est: &State) -> Result<TickOutput> {
        let out = self.feedback_inner(x_est)?;
        self.last_applied = x_est
            .iter()
            .all(|v| v.is_finite())
            .then_some((*x_est, out.u));
        Ok(out)
    }

    fn feedback_inner(&mut self, x_est: &State) -> Result<TickOutput> {
        if !self.prepared {
            return Err(MpcError::NotPrepared);
        }
        self.prepared = false;
        let start = Instant::now();
        let mut timings = TickTimings {
            preparation: self.preparation_time,
            preparation_solve: Duration::from_secs_f64(self.preparation_solve.solve_time.max(0.0)),
            preparation_solver_iterations: self.preparation_solve.iterations,
            ..TickTimings::default()
        };
        if let Some(entry) = x_est.iter().position(|v| !v.is_finite()) {
            return Ok(self.fail(FailureCause::NonFiniteEstimate { entry }, timings, start));
        }
        if !self.preparation_ok {
            let out = self.fail(FailureCause::PreparationFailed, timings, start);
            // A plan that could not be linearized (it diverged) is useless
            // from now on: restart it from the estimate so the next tick can solve.
            if self.plan_diverged {
                self.restart_plan(x_est);
            }
            return Ok(out);
        }
        let mut e0 = x_est - self.plan_x[0];
        e0[idx::YAW] = wrap_angle(e0[idx::YAW]);
        let max_changes = self.settings.feedback.max_active_set_changes;
        let mut fallback = None;
        let walked = match (self.prepared_solution, self.qp.condensed_mut()) {
            (Some(Ok(())), Some(qp)) => match qp.feedback_solution(&e0, max_changes) {
                Ok(changes) => Some(changes),
                Err(stop) => {
                    fallback = Some(HomotopyFallback::Feedback(stop));
                    None
                }
            },
            (Some(Err(stop)), _) => {
                fallback = Some(HomotopyFallback::Preparation(stop));
                None
            }
            _ => None,
        };
        let (outcome, path) = if let Some(active_set_changes) = walked {
            timings.solver_iterations = timings.preparation_solver_iterations;
            (
                Outcome::Solved,
                FeedbackPath::Homotopy { active_set_changes },
            )
        } else {
            if fallback.is_some() {
                self.homotopy_fallbacks += 1;
            }
            let path = FeedbackPath::Clarabel { fallback };
            if self.qp.set_initial_deviation(&e0).is_err() {
                return Ok(self.fail_on(path, FailureCause::PreparationFailed, timings, start));
            }
            let report: SolveReport = self.qp.solve();
            timings.solve = Duration::from_secs_f64(report.solve_time.max(0.0));
            timings.feedback_solver_iterations = report.iterations;
            timings.solver_iterations = timings.preparation_solver_iterations + report.iterations;
            let outcome = match report.status {
                SolverStatus::Solved => Outcome::Solved,
                SolverStatus::AlmostSolved => Outcome::Degraded(DegradedCause::ReducedAccuracy),
                // A limit hit early leaves an iterate far from the optimum (up to
                // 0.27 in u after 0-2 iterations, measured): fly the shifted plan
                // unless the iterate already meets the reduced tolerances.
                SolverStatus::MaxIterations if self.qp.iterate_usable() => {
                    Outcome::Degraded(DegradedCause::IterationLimit)
                }
                // Our per-solve clock ends a solve through the termination callback.
                SolverStatus::MaxTime | SolverStatus::CallbackTerminated
                    if self.qp.iterate_usable() =>
                {
                    Outcome::Degraded(DegradedCause::TimeLimit)
                }
                other => {
                    return Ok(self.fail_on(path, FailureCause::Solver(other), timings, start));
                }
            };
            (outcome, path)
        };
        self.qp.extract(&self.lin, &e0, &mut self.dx, &mut self.du);
        let finite = self.dx.iter().all(|x| x.iter().all(|v| v.is_finite()))
            && self.du.iter().all(|u| u.iter().all(|v| v.is_finite()));
        if !finite {
            return Ok(self.fail_on(path, FailureCause::NonFiniteSolution, timings, start));
        }
        for k in 0..=self.steps {
            self.plan_x[k] += self.dx[k];
        }
        for k in 0..self.steps {
            // The solver meets the box to its tolerance; the actuators need it exactly.
            self.plan_u[k] = (self.plan_u[k] + self.du[k]).map(|u| u.clamp(0.0, 1.0));
        }
        self.failed_ticks = 0;
        timings.feedback = start.elapsed();
        Ok(TickOutput {
            u: self.plan_u[0],
            outcome,
            timings,
            path,
        })
    }

    /// [`Self::fail`] after a solve was attempted on `path`.
    fn fail_on(
        &mut self,
        path: FeedbackPath,
        cause: FailureCause,
        timings: TickTimings,
        start: Instant,
    ) -> TickOutput {
        TickOutput {
            path,
            ..self.fail(cause, timings, start)
        }
    }

    fn fail(
        &mut self,
        cause: FailureCause,
        mut timings: TickTimings,
        start: Instant,
    ) -> TickOutput {
        self.failed_ticks = self.failed_ticks.saturating_add(1);
        let planned = self.plan_u[0];
        let u = if planned.iter().all(|v| v.is_finite()) {
            planned
        } else {
            self.u_ref[0]
        };
        let failed_ticks = self.failed_ticks;
        let outcome = if failed_ticks <= self.settings.failure.grace_ticks {
            Outcome::Fallback {
                cause,
                failed_ticks,
            }
        } else {
            Outcome::Failed {
                cause,
                failed_ticks,
            }
        };
        timings.feedback = start.elapsed();
        TickOutput {
            u: u.map(|v| v.clamp(0.0, 1.0)),
            outcome,
            timings,
            path: FeedbackPath::NoSolve,
        }
    }

    /// One full tick: `prepare` then `feedback`. A failed preparation still
    /// gives a command (the fallback), with the error reported as the outcome.
    pub fn tick(&mut self, x_est: &State) -> Result<TickOutput> {
        match self.prepare() {
            Ok(_) | Err(MpcError::NonFiniteLinearization { .. } | MpcError::Solver(_)) => {}
            Err(e) => return Err(e),
        }
        self.feedback(x_est)
    }

    /// Runs Gauss-Newton SQP on the current problem (no shift, same
    /// estimate and parameters) until the step is below `tol`: the fully
    /// converged solution that one RTI iteration approximates. Diagnostic.
    /// Re-plans at the current time when the problem changed a lot (a new
    /// flight mode): up to `iterations` Gauss-Newton iterations without
    /// shifting, each ending in a feedback with `x_est`; returns the last
    /// feedback (stops early at the first one without a fresh solution).
    /// A one-off cost of `iterations` feedback phases.
    pub fn replan(&mut self, x_est: &State, iterations: usize) -> Result<TickOutput> {
        let mut out = None;
        for _ in 0..iterations.max(1) {
            self.prepare_inner(false)?;
            let tick = self.feedback(x_est)?;
            let fresh = tick.outcome.is_fresh();
            out = Some(tick);
            if !fresh {
                break;
            }
        }
        out.ok_or(MpcError::NotPrepared)
    }

    pub fn converge_sqp(&mut self, x_est: &State, max_iter: usize, tol: f64) -> Result<SqpReport> {
        let mut last_step = f64::INFINITY;
        for it in 1..=max_iter {
            self.prepare_inner(false)?;
            let out = self.feedback(x_est)?;
            if !out.outcome.is_fresh() {
                return Err(MpcError::Solver(format!(
                    "SQP iteration {it}: {:?}",
                    out.outcome
                )));
            }
            // The first step of dx is the estimate insertion, not an SQP step.
            let dx_step = self.dx[1..]
                .iter()
                .map(nalgebra::Matrix::amax)
                .fold(0.0, f64::max);
            let du_step = self
                .du
                .iter()
                .map(nalgebra::Matrix::amax)
                .fold(0.0, f64::max);
            last_step = dx_step.max(du_step);
            if last_step < tol {
                return Ok(SqpReport {
                    iterations: it,
                    last_step,
                    converged: true,
                });
            }
        }
        Ok(SqpReport {
            iterations: max_iter,
            last_step,
            converged: false,
        })
    }

    /// Re-solves the QP currently loaded (after a `prepare` and a `feedback`),
    /// touching nothing else. For measuring the bare solver call.
    pub fn resolve_loaded_qp(&mut self) -> SolveReport {
        self.qp.solve()
    }

    /// A copy of the QP currently loaded in the solver (allocates).
    pub fn qp_snapshot(&self) -> QpSnapshot {
        self.qp.snapshot()
    }

    /// The primal solution of the last solve, in the formulation's layout.
    pub fn qp_solution(&self) -> &[f64] {
        self.qp.raw_solution()
    }
}

fn check_finite(what: &'static str, stage: usize, values: &[f64]) -> Result<()> {
    match values.iter().position(|v| !v.is_finite()) {
        None => Ok(()),
        Some(entry) => Err(MpcError::NonFiniteParameter { what, stage, entry }),
    }
}

fn check_len(what: &'static str, expected: usize, got: usize) -> Result<()> {
    if expected == got {
        Ok(())
    } else {
        Err(MpcError::HorizonLength {
            what,
            expected,
            got,
        })
    }
}

fn check_tilt(v: f64) -> Result<()> {
    if (0.0..=std::f64::consts::FRAC_PI_2 + 1e-9).contains(&v) {
        Ok(())
    } else {
        Err(MpcError::OutOfRange {
            what: "tilt",
            value: v,
            min: 0.0,
            max: std::f64::consts::FRAC_PI_2,
        })
    }
}
