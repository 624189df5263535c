//! What one tick of the controller reports, and the alpha schedule.

use std::time::Duration;

use atmo_core::control::blending_alpha;
use atmo_core::model::Input;
use clarabel::solver::SolverStatus;

use crate::homotopy::HomotopyStop;

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
    /// The planned tilt rate to command now, rad/s, when the MPC plans the
    /// tilt ([`crate::Mpc::set_tilt_plan`]); `None`: the tilt is a parameter.
    pub tilt_rate: Option<f64>,
}

/// Result of `Mpc::converge_sqp`.
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
