//! The two phases of a tick (preparation, feedback), the fallback, and the
//! re-planning and SQP diagnostics built on them.

use std::f64::consts::{FRAC_PI_2, PI, TAU};
use std::time::{Duration, Instant};

use atmo_core::model::{NU, NX, State, idx};
use clarabel::solver::SolverStatus;
use nalgebra::SVector;

use super::outcome::{
    DegradedCause, FailureCause, FeedbackPath, HomotopyFallback, Outcome, SqpReport, TickOutput,
    TickTimings,
};
use super::{Mpc, hover_reference, wrap_angle};
use crate::error::{MpcError, Result};
use crate::homotopy::HomotopyStop;
use crate::qp::cuts::CutWindow;
use crate::qp::{QpBackend, QpSnapshot, SolveReport};
use crate::settings::Predictor;
use crate::tilt_model::{TILT, TILT_RATE, tilt_state};

impl Mpc {
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
            self.shift_tilt_plan();
        }
        self.rewrap_plan_yaw();
        let planning = self.plans_tilt();
        if let Some(tilt) = self.tilt.as_deref_mut() {
            tilt.active = false;
        }
        let linearized = if planning {
            self.linearize_tilt_plan()
        } else {
            self.linearize_nominal()
        };
        if let Err(e) = linearized {
            self.preparation_time = start.elapsed();
            return Err(e);
        }
        self.prepared_solution = None;
        self.preparation_solve.solve_time = 0.0;
        self.preparation_solve.iterations = 0;
        if self.uses_homotopy() {
            let e0 = self.predicted_deviation(shift);
            self.predicted_e0 = e0;
            let max_changes = self.settings.feedback.max_preparation_changes;
            let prepared = if planning {
                let e0_tilt = tilt_state(&e0, self.predicted_tilt_deviation(shift));
                match self.tilt.as_deref_mut().and_then(|t| t.qp.condensed_mut()) {
                    Some(qp) => {
                        Some(qp.prepare_solution(&e0_tilt, max_changes, &mut self.cut_window)?)
                    }
                    None => None,
                }
            } else {
                match self.qp.condensed_mut() {
                    Some(qp) => {
                        Some(qp.prepare_solution(&e0, max_changes, &mut self.cut_window)?)
                    }
                    None => None,
                }
            };
            if let Some(prepared) = prepared {
                self.preparation_solve = prepared.clarabel;
                self.prepared_solution = Some(prepared.correction.map(|_| ()));
            }
        }
        self.preparation_ok = true;
        self.preparation_time = start.elapsed();
        Ok(self.preparation_time)
    }

    /// The preparation's linearization with the tilt as a parameter, loaded
    /// into the 12/4 QP.
    fn linearize_nominal(&mut self) -> Result<()> {
        let q = self.state_weight_now();
        let r = self.settings.weights.input_weight(self.alpha);
        let dt = self.stage_dt;
        for k in 0..self.steps {
            let body = self.stage_body(self.varphi[k]);
            self.u_ref[k] = self.rotor_reference(hover_reference(&body));
            let s = self.step_sensitivity(&body, &self.plan_x[k], &self.plan_u[k], dt);
            let defect = s.next - self.plan_x[k + 1];
            if !(s.a.iter().all(|v| v.is_finite())
                && s.b.iter().all(|v| v.is_finite())
                && defect.iter().all(|v| v.is_finite()))
            {
                self.plan_diverged = true;
                return Err(MpcError::NonFiniteLinearization { stage: k });
            }
            self.lin.a[k] = s.a;
            self.lin.b[k] = s.b;
            self.lin.defect[k] = defect;
            self.lin.q_diag[k] = q;
            self.lin.u_err[k] = self.plan_u[k] - self.u_ref[k];
            self.lin.u_bar[k] = self.plan_u[k];
            self.lin.u_lo[k] = self.rotor_min;
            self.lin.u_hi[k] = self.rotor_max;
        }
        self.lin.q_diag[self.steps] = q * self.settings.cost.terminal_scale;
        self.lin.r_diag = r;
        for k in 0..=self.steps {
            let mut e = self.plan_x[k] - self.x_ref[k];
            e[idx::YAW] = wrap_angle(e[idx::YAW]);
            self.lin.x_err[k] = e;
        }
        self.qp.load(&self.lin)
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
            (true, Predictor::Model) => self.step(
                &self.stage_body(self.varphi[0]),
                &x,
                &u,
                self.settings.horizon.tick_period,
            ),
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
        let last = self.step(
            &self.stage_body(self.varphi[n]),
            &self.plan_x[n],
            &self.plan_u[n - 1],
            self.stage_dt,
        );
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
        if let Some(tilt) = self.tilt.as_deref_mut() {
            tilt.last_applied = out.tilt_rate.map(|rate| (tilt.measured, rate));
        }
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
        let prepared = self.prepared_solution;
        let planning = self.tilt.as_deref().is_some_and(|t| t.active);
        let solved = if planning {
            let Some(tilt) = self.tilt.as_deref_mut() else {
                return Err(MpcError::NotPrepared);
            };
            let e0_tilt = tilt_state(&e0, tilt.measured - self.varphi[0]);
            let solved = solve_at(
                &mut tilt.qp,
                prepared,
                &e0_tilt,
                max_changes,
                &mut self.cut_window,
                &mut timings,
            );
            if solved.is_ok() {
                tilt.qp
                    .extract(&tilt.lin, &e0_tilt, &mut tilt.dx, &mut tilt.du);
            }
            solved
        } else {
            let solved = solve_at(
                &mut self.qp,
                prepared,
                &e0,
                max_changes,
                &mut self.cut_window,
                &mut timings,
            );
            if solved.is_ok() {
                self.qp.extract(&self.lin, &e0, &mut self.dx, &mut self.du);
            }
            solved
        };
        let (outcome, path) = match solved {
            Ok(done) => done,
            Err((path, cause)) => {
                if path.is_fallback() {
                    self.homotopy_fallbacks += 1;
                }
                return Ok(self.fail_on(path, cause, timings, start));
            }
        };
        if path.is_fallback() {
            self.homotopy_fallbacks += 1;
        }
        if planning {
            self.split_tilt_solution();
        }
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
            self.plan_u[k] = (self.plan_u[k] + self.du[k]).zip_zip_map(
                &self.rotor_min,
                &self.rotor_max,
                f64::clamp,
            );
        }
        let tilt_rate = self.apply_tilt_solution();
        self.failed_ticks = 0;
        timings.feedback = start.elapsed();
        Ok(TickOutput {
            u: self.plan_u[0],
            outcome,
            timings,
            path,
            tilt_rate,
        })
    }

    /// The 12/4 parts of the tilt QP's step into `dx`, `du`.
    fn split_tilt_solution(&mut self) {
        if let Some(tilt) = self.tilt.as_deref() {
            for (dx, t) in self.dx.iter_mut().zip(&tilt.dx) {
                *dx = t.fixed_rows::<NX>(0).into_owned();
            }
            for (du, t) in self.du.iter_mut().zip(&tilt.du) {
                *du = t.fixed_rows::<NU>(0).into_owned();
            }
        }
    }

    /// The tilt QP's step applied to the tilt plan (after a finite
    /// solution); the rate to command now.
    fn apply_tilt_solution(&mut self) -> Option<f64> {
        let tilt = self.tilt.as_deref_mut().filter(|t| t.active)?;
        for (varphi, dx) in self.varphi.iter_mut().zip(&tilt.dx) {
            *varphi = (*varphi + dx[TILT]).clamp(0.0, FRAC_PI_2);
        }
        for k in 0..self.steps {
            let (lo, hi) = (tilt.lin.u_lo[k][TILT_RATE], tilt.lin.u_hi[k][TILT_RATE]);
            tilt.rate[k] = (tilt.rate[k] + tilt.du[k][TILT_RATE]).clamp(lo, hi.max(lo));
        }
        Some(tilt.rate[0])
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
        let tilt_rate = self
            .tilt
            .as_deref()
            .filter(|t| t.plan.is_some())
            .map(|t| t.rate[0]);
        TickOutput {
            u: u.zip_zip_map(&self.rotor_min, &self.rotor_max, f64::clamp),
            outcome,
            timings,
            path: FeedbackPath::NoSolve,
            tilt_rate,
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
    /// touching nothing else. For measuring the bare solver call: outside
    /// the flight's window of solves, so a cut in it is not recorded.
    pub fn resolve_loaded_qp(&mut self) -> SolveReport {
        let mut window = CutWindow::default();
        match self.tilt.as_deref_mut().filter(|t| t.active) {
            Some(tilt) => tilt.qp.solve(&mut window),
            None => self.qp.solve(&mut window),
        }
    }

    /// A copy of the nominal (12/4) QP last loaded in the solver (allocates).
    pub fn qp_snapshot(&self) -> QpSnapshot {
        self.qp.snapshot()
    }

    /// The primal solution of the last solve, in the formulation's layout.
    pub fn qp_solution(&self) -> &[f64] {
        self.qp.raw_solution()
    }
}

/// The QP's solution at `e0`: the homotopy from the prepared solution when
/// it is ready, else Clarabel; how it ended, or the failure (with the path
/// tried). Generic in the QP's size (nominal 12/4, tilt planning 13/5).
fn solve_at<const NX_: usize, const NU_: usize>(
    qp: &mut QpBackend<NX_, NU_>,
    prepared: Option<std::result::Result<(), HomotopyStop>>,
    e0: &SVector<f64, NX_>,
    max_changes: u32,
    window: &mut CutWindow,
    timings: &mut TickTimings,
) -> std::result::Result<(Outcome, FeedbackPath), (FeedbackPath, FailureCause)> {
    let mut fallback = None;
    let walked = match (prepared, qp.condensed_mut()) {
        (Some(Ok(())), Some(condensed)) => match condensed.feedback_solution(e0, max_changes) {
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
    if let Some(active_set_changes) = walked {
        timings.solver_iterations = timings.preparation_solver_iterations;
        return Ok((
            Outcome::Solved,
            FeedbackPath::Homotopy { active_set_changes },
        ));
    }
    let path = FeedbackPath::Clarabel { fallback };
    if qp.set_initial_deviation(e0).is_err() {
        return Err((path, FailureCause::PreparationFailed));
    }
    let report: SolveReport = qp.solve(window);
    timings.solve = Duration::from_secs_f64(report.solve_time.max(0.0));
    timings.feedback_solver_iterations = report.iterations;
    timings.solver_iterations = timings.preparation_solver_iterations + report.iterations;
    let outcome = match report.status {
        SolverStatus::Solved => Outcome::Solved,
        SolverStatus::AlmostSolved => Outcome::Degraded(DegradedCause::ReducedAccuracy),
        // A limit hit early leaves an iterate far from the optimum (up to
        // 0.27 in u after 0-2 iterations, measured): fly the shifted plan
        // unless the iterate already meets the reduced tolerances.
        SolverStatus::MaxIterations if qp.iterate_usable() => {
            Outcome::Degraded(DegradedCause::IterationLimit)
        }
        // Our per-solve clock ends a solve through the termination callback.
        SolverStatus::MaxTime | SolverStatus::CallbackTerminated if qp.iterate_usable() => {
            Outcome::Degraded(DegradedCause::TimeLimit)
        }
        other => return Err((path, FailureCause::Solver(other))),
    };
    Ok((outcome, path))
}
