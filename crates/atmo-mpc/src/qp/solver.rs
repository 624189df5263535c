//! Clarabel built once with a fixed pattern, and our own per-solve time limit.

use std::sync::Arc;
use std::sync::atomic::{AtomicU32, AtomicU64, Ordering};
use std::time::{Duration, Instant};

use clarabel::algebra::CscMatrix;
use clarabel::solver::{DefaultInfo, DefaultSettings, DefaultSolver, IPSolver, SupportedConeT};

use super::SolveReport;
use super::cuts::CutWindow;
use crate::error::{MpcError, Result};
use crate::settings::SolverSettings;

/// Creates a Clarabel solver without its own time limit. Clarabel 0.11
/// compares `time_limit` with the sum of its top-level timers, which include
/// the set-up and a "post-process" timer that is never reset: after about
/// 10^4 solves (a minute at 150 Hz) every solve would end at iteration 0 with
/// `MaxTime`. [`TimedSolver`] enforces the limit with its own clock instead.
pub fn build_solver(
    p: &CscMatrix<f64>,
    q: &[f64],
    a: &CscMatrix<f64>,
    b: &[f64],
    cones: &[SupportedConeT<f64>],
    settings: &SolverSettings,
) -> Result<DefaultSolver<f64>> {
    let mut clarabel = clarabel_settings(settings);
    clarabel.time_limit = f64::INFINITY;
    DefaultSolver::new(p, q, a, b, cones, clarabel).map_err(solver_error)
}

/// Clarabel with a per-solve wall-clock limit measured by us: a termination
/// callback (checked once per interior-point iteration) compares a monotonic
/// clock with the deadline set just before the solve. In a replay the
/// callback instead ends a scripted solve at its recorded iteration
/// ([`super::cuts`]). The window that numbers the solves and records the cuts
/// is passed to each solve: it belongs to the controller, which owns several
/// QPs (nominal and tilt-planning) whose solves one window must number.
pub struct TimedSolver {
    pub solver: DefaultSolver<f64>,
    epoch: Instant,
    /// Nanoseconds after `epoch`; shared with the callback.
    deadline: Arc<AtomicU64>,
    /// Iteration a replayed solve ends at ([`NOT_SCRIPTED`]: none); shared
    /// with the callback.
    scripted_cut: Arc<AtomicU32>,
    limit: Duration,
}

const NOT_SCRIPTED: u32 = u32::MAX;

impl TimedSolver {
    pub fn new(
        p: &CscMatrix<f64>,
        q: &[f64],
        a: &CscMatrix<f64>,
        b: &[f64],
        cones: &[SupportedConeT<f64>],
        settings: &SolverSettings,
    ) -> Result<Self> {
        let mut solver = build_solver(p, q, a, b, cones, settings)?;
        let epoch = Instant::now();
        let deadline = Arc::new(AtomicU64::new(u64::MAX));
        let scripted_cut = Arc::new(AtomicU32::new(NOT_SCRIPTED));
        let (deadline_seen, cut_seen) = (Arc::clone(&deadline), Arc::clone(&scripted_cut));
        solver.set_termination_callback(move |info: &DefaultInfo<f64>| {
            match cut_seen.load(Ordering::Relaxed) {
                NOT_SCRIPTED => nanos_since(epoch) > deadline_seen.load(Ordering::Relaxed),
                cut => info.iterations >= cut,
            }
        });
        Ok(Self {
            solver,
            epoch,
            deadline,
            scripted_cut,
            limit: Duration::from_secs_f64(settings.time_limit),
        })
    }

    /// Solves as the next solve of `window`; `CallbackTerminated` means the
    /// time limit was hit (recorded in `window`) or, in a replay, the
    /// window's scripted cut was reached.
    pub fn solve(&mut self, window: &mut CutWindow) -> SolveReport {
        let start = Instant::now();
        let (ordinal, script) = window.next_solve();
        let limit = u64::try_from(self.limit.as_nanos()).unwrap_or(u64::MAX);
        let deadline = match script {
            // A replay: only the recorded cuts end a solve early.
            Some(_) => u64::MAX,
            None => nanos_since(self.epoch).saturating_add(limit),
        };
        self.deadline.store(deadline, Ordering::Relaxed);
        let cut = script.flatten().unwrap_or(NOT_SCRIPTED);
        self.scripted_cut.store(cut, Ordering::Relaxed);
        self.solver.solve();
        let report = SolveReport {
            status: self.solver.solution.status,
            iterations: self.solver.solution.iterations,
            solve_time: start.elapsed().as_secs_f64(),
        };
        if report.status == clarabel::solver::SolverStatus::CallbackTerminated {
            window.record(ordinal, report.iterations);
        }
        report
    }
}

impl TimedSolver {
    /// Whether the last iterate meets Clarabel's reduced ("almost solved")
    /// tolerances: the same test Clarabel applies before it turns an
    /// iteration or time limit into `AlmostSolved`, which it does not do for
    /// a callback termination.
    pub fn iterate_meets_reduced_tolerances(&self) -> bool {
        let info = &self.solver.info;
        let s = self.solver.settings();
        info.ktratio <= 1.0
            && (info.gap_abs < s.reduced_tol_gap_abs || info.gap_rel < s.reduced_tol_gap_rel)
            && info.res_primal < s.reduced_tol_feas
            && info.res_dual < s.reduced_tol_feas
    }
}

fn nanos_since(epoch: Instant) -> u64 {
    u64::try_from(epoch.elapsed().as_nanos()).unwrap_or(u64::MAX)
}

/// Clarabel settings for RTI: presolve off (it would forbid in-place
/// updates), no printing, our tolerances and caps.
pub fn clarabel_settings(s: &SolverSettings) -> DefaultSettings<f64> {
    DefaultSettings {
        presolve_enable: false,
        verbose: false,
        input_sparse_dropzeros: false,
        max_iter: s.max_iter,
        time_limit: s.time_limit,
        tol_gap_abs: s.tol_gap_abs,
        tol_gap_rel: s.tol_gap_rel,
        tol_feas: s.tol_feas,
        equilibrate_enable: s.equilibrate,
        iterative_refinement_enable: s.iterative_refinement,
        max_step_fraction: s.max_step_fraction,
        ..DefaultSettings::default()
    }
}

/// A CSC pattern built by walking the entries column by column.
pub(super) struct CscBuilder {
    rows: usize,
    colptr: Vec<usize>,
    rowval: Vec<usize>,
    nzval: Vec<f64>,
}

impl CscBuilder {
    pub(super) fn new(rows: usize) -> Self {
        Self {
            rows,
            colptr: vec![0],
            rowval: Vec::new(),
            nzval: Vec::new(),
        }
    }
    pub(super) fn push(&mut self, row: usize, value: f64) {
        self.rowval.push(row);
        self.nzval.push(value);
    }
    pub(super) fn end_column(&mut self) {
        self.colptr.push(self.rowval.len());
    }
    pub(super) fn finish(self) -> CscMatrix<f64> {
        let cols = self.colptr.len() - 1;
        CscMatrix::new(self.rows, cols, self.colptr, self.rowval, self.nzval)
    }
}

pub(super) fn solver_error(e: impl std::fmt::Display) -> MpcError {
    MpcError::Solver(e.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::qp::cuts::SolverCuts;
    use crate::settings::MpcSettings;
    use clarabel::solver::SolverStatus;

    /// min (x - 1)^2 s.t. x <= 2: a QP Clarabel solves in a few microseconds.
    fn tiny(settings: &SolverSettings) -> TimedSolver {
        let p = CscMatrix::new(1, 1, vec![0, 1], vec![0], vec![2.0]);
        let a = CscMatrix::new(1, 1, vec![0, 1], vec![0], vec![1.0]);
        TimedSolver::new(
            &p,
            &[-2.0],
            &a,
            &[2.0],
            &[SupportedConeT::NonnegativeConeT(1)],
            settings,
        )
        .unwrap()
    }

    // Clarabel's own time-limit clock drifts (it counts the set-up and an
    // accumulating post-process timer); ours restarts with every solve.
    #[test]
    fn time_limit_holds_over_many_solves() {
        let mut settings = MpcSettings::atmo("default").unwrap().solver;
        settings.time_limit = 0.02;
        let mut solver = tiny(&settings);
        let mut window = CutWindow::default();
        let clarabel_clock = |s: &TimedSolver| s.solver.timers.as_ref().unwrap().total_time();
        solver.solve(&mut window);
        let first = clarabel_clock(&solver);
        let limit = Duration::from_secs_f64(settings.time_limit);
        let mut stalled = 0;
        for k in 0..20_000 {
            let start = std::time::Instant::now();
            let report = solver.solve(&mut window);
            let took = start.elapsed();
            // A loaded machine can stall one solve past the limit (seen in
            // CI); that solve may be stopped. Any other stop would mean the
            // clock is not per solve.
            if report.status == SolverStatus::CallbackTerminated && took >= limit {
                stalled += 1;
                continue;
            }
            assert_eq!(report.status, SolverStatus::Solved, "solve {k} ({took:?})");
            assert!(report.iterations > 0);
        }
        assert!(stalled < 100, "{stalled} solves stalled past the limit");
        assert!((solver.solver.solution.x[0] - 1.0).abs() < 1e-6);
        let drift = clarabel_clock(&solver).saturating_sub(first);
        eprintln!("Clarabel's time-limit clock drifted by {drift:?} over 20000 solves");
        assert!(drift > Duration::from_micros(100), "{drift:?}");
    }

    #[test]
    fn a_scripted_window_cuts_where_the_recorded_one_did() {
        let settings = MpcSettings::atmo("default").unwrap().solver;
        let mut solver = tiny(&settings);
        let mut window = CutWindow::default();
        let full = solver.solve(&mut window);
        assert_eq!(full.status, SolverStatus::Solved);
        assert!(full.iterations >= 3, "{full:?}");
        let mut script = SolverCuts::default();
        script.record(1, 2);
        window.open(Some(script));
        assert_eq!(solver.solve(&mut window).status, SolverStatus::Solved);
        let cut = solver.solve(&mut window);
        assert_eq!(
            (cut.status, cut.iterations),
            (SolverStatus::CallbackTerminated, 2)
        );
        assert_eq!(solver.solve(&mut window).status, SolverStatus::Solved);
        assert_eq!(window.cuts(), script);
        // Back in flight: the wall clock, nothing scripted.
        window.open(None);
        assert_eq!(solver.solve(&mut window).status, SolverStatus::Solved);
        assert!(window.cuts().is_empty());
    }

    #[test]
    fn time_limit_stops_a_solve() {
        let mut settings = MpcSettings::atmo("default").unwrap().solver;
        settings.time_limit = 0.0;
        let mut solver = tiny(&settings);
        let mut window = CutWindow::default();
        let cut = solver.solve(&mut window);
        assert_eq!(cut.status, SolverStatus::CallbackTerminated);
        // Recorded, as solve 0 of the window, for a replay.
        assert_eq!(window.cuts().cut_of(0), Some(cut.iterations));
    }
}
