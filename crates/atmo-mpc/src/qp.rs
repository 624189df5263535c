//! The RTI quadratic program in its two forms, and Clarabel updated in place.
//!
//! Both forms are in deviations from the plan (`dx_k = x_k - xbar_k`,
//! `du_k = u_k - ubar_k`) and are filled from one [`LinearizedHorizon`].
//! Each builds its sparsity pattern once; every later tick writes values into
//! the same pattern (`update_P/q/A/b`), so the solver's symbolic
//! factorization is reused and nothing is allocated by our code.

use atmo_core::model::{Input, InputJacobian, NU, NX, State, StateJacobian};
use clarabel::algebra::CscMatrix;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

use clarabel::solver::{
    DefaultInfo, DefaultSettings, DefaultSolver, IPSolver, SolverStatus, SupportedConeT,
};
use nalgebra::{SMatrix, SVector};

use crate::error::{MpcError, Result};
use crate::homotopy::{Bound, BoxHomotopy, HomotopyStop};
use crate::settings::{Formulation, SolverSettings};

/// Everything the QP needs from one linearization along the plan.
/// Stages `k = 0..N` for states, `0..N-1` for inputs.
#[derive(Debug, Clone)]
pub struct LinearizedHorizon {
    /// `dx_{k+1} = A_k dx_k + B_k du_k + defect_k`.
    pub a: Vec<StateJacobian>,
    pub b: Vec<InputJacobian>,
    /// `RK4(xbar_k, ubar_k) - xbar_{k+1}`: the multiple-shooting gap.
    pub defect: Vec<State>,
    /// Diagonal of the state weight per stage (index N: terminal).
    pub q_diag: Vec<State>,
    /// Diagonal of the input weight.
    pub r_diag: Input,
    /// `xbar_k - x_ref_k`, yaw entry wrapped to (-pi, pi].
    pub x_err: Vec<State>,
    /// `ubar_k - u_ref_k`.
    pub u_err: Vec<Input>,
    /// `ubar_k`: bounds are `-ubar <= du <= 1 - ubar`.
    pub u_bar: Vec<Input>,
}

impl LinearizedHorizon {
    pub fn new(steps: usize) -> Self {
        Self {
            a: vec![StateJacobian::identity(); steps],
            b: vec![InputJacobian::zeros(); steps],
            defect: vec![State::zeros(); steps],
            q_diag: vec![State::from_element(1.0); steps + 1],
            r_diag: Input::from_element(1.0),
            x_err: vec![State::zeros(); steps + 1],
            u_err: vec![Input::zeros(); steps],
            u_bar: vec![Input::from_element(0.5); steps],
        }
    }

    pub fn steps(&self) -> usize {
        self.a.len()
    }
}

/// How one QP solve ended, in Clarabel's words.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SolveReport {
    pub status: SolverStatus,
    pub iterations: u32,
    /// s, wall clock around the solve call (Clarabel's own figure includes
    /// its set-up time).
    pub solve_time: f64,
}

/// A QP in Clarabel's standard form `min 1/2 z'Pz + q'z  s.t.  Az + s = b`,
/// `s` in `{0}^zero_rows x R+^nonneg_rows` (zero rows first). A copy for
/// tests and benchmarks (allocates).
#[derive(Debug, Clone)]
pub struct QpSnapshot {
    /// Upper triangle.
    pub p: CscMatrix<f64>,
    pub q: Vec<f64>,
    pub a: CscMatrix<f64>,
    pub b: Vec<f64>,
    pub zero_rows: usize,
    pub nonneg_rows: usize,
}

impl QpSnapshot {
    pub fn cones(&self) -> Vec<SupportedConeT<f64>> {
        let mut cones = Vec::new();
        if self.zero_rows > 0 {
            cones.push(SupportedConeT::ZeroConeT(self.zero_rows));
        }
        cones.push(SupportedConeT::NonnegativeConeT(self.nonneg_rows));
        cones
    }

    /// A fresh Clarabel solver for this QP with the same settings as the controller.
    pub fn fresh_solver(&self, settings: &SolverSettings) -> Result<DefaultSolver<f64>> {
        build_solver(&self.p, &self.q, &self.a, &self.b, &self.cones(), settings)
    }
}

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
/// clock with the deadline set just before the solve.
pub struct TimedSolver {
    pub solver: DefaultSolver<f64>,
    epoch: Instant,
    /// Nanoseconds after `epoch`; shared with the callback.
    deadline: Arc<AtomicU64>,
    limit: Duration,
}

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
        let shared = Arc::clone(&deadline);
        solver.set_termination_callback(move |_info: &DefaultInfo<f64>| {
            nanos_since(epoch) > shared.load(Ordering::Relaxed)
        });
        Ok(Self {
            solver,
            epoch,
            deadline,
            limit: Duration::from_secs_f64(settings.time_limit),
        })
    }

    /// Solves; `CallbackTerminated` means the time limit was hit.
    pub fn solve(&mut self) -> SolveReport {
        let start = Instant::now();
        let limit = u64::try_from(self.limit.as_nanos()).unwrap_or(u64::MAX);
        self.deadline.store(
            nanos_since(self.epoch).saturating_add(limit),
            Ordering::Relaxed,
        );
        self.solver.solve();
        SolveReport {
            status: self.solver.solution.status,
            iterations: self.solver.solution.iterations,
            solve_time: start.elapsed().as_secs_f64(),
        }
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
struct CscBuilder {
    rows: usize,
    colptr: Vec<usize>,
    rowval: Vec<usize>,
    nzval: Vec<f64>,
}

impl CscBuilder {
    fn new(rows: usize) -> Self {
        Self {
            rows,
            colptr: vec![0],
            rowval: Vec::new(),
            nzval: Vec::new(),
        }
    }
    fn push(&mut self, row: usize, value: f64) {
        self.rowval.push(row);
        self.nzval.push(value);
    }
    fn end_column(&mut self) {
        self.colptr.push(self.rowval.len());
    }
    fn finish(self) -> CscMatrix<f64> {
        let cols = self.colptr.len() - 1;
        CscMatrix::new(self.rows, cols, self.colptr, self.rowval, self.nzval)
    }
}

fn solver_error(e: impl std::fmt::Display) -> MpcError {
    MpcError::Solver(e.to_string())
}

/// The RTI QP and its solver, in the chosen formulation.
pub enum QpBackend {
    Sparse(Box<SparseQp>),
    Condensed(Box<CondensedQp>),
}

impl QpBackend {
    /// Builds the pattern from `lin` and creates Clarabel once.
    pub fn new(lin: &LinearizedHorizon, settings: &SolverSettings) -> Result<Self> {
        Ok(match settings.formulation {
            Formulation::Sparse => Self::Sparse(Box::new(SparseQp::new(lin, settings)?)),
            Formulation::Condensed => Self::Condensed(Box::new(CondensedQp::new(lin, settings)?)),
        })
    }

    /// Preparation: write the new linearization into the solver.
    pub fn load(&mut self, lin: &LinearizedHorizon) -> Result<()> {
        match self {
            Self::Sparse(qp) => qp.load(lin),
            Self::Condensed(qp) => qp.load(lin),
        }
    }

    /// Feedback: insert `dx_0 = x_est - xbar_0`.
    pub fn set_initial_deviation(&mut self, e0: &State) -> Result<()> {
        match self {
            Self::Sparse(qp) => qp.set_initial_deviation(e0),
            Self::Condensed(qp) => qp.set_initial_deviation(e0),
        }
    }

    /// Clarabel on the QP as loaded in it.
    pub fn solve(&mut self) -> SolveReport {
        match self {
            Self::Sparse(qp) => qp.solver.solve(),
            Self::Condensed(qp) => {
                qp.solved_by = SolvedBy::Clarabel;
                qp.solver.solve()
            }
        }
    }

    /// The solution as plan deviations (states by forward simulation of the
    /// linear model in the condensed form).
    pub fn extract(&self, lin: &LinearizedHorizon, e0: &State, dx: &mut [State], du: &mut [Input]) {
        match self {
            Self::Sparse(qp) => qp.extract(dx, du),
            Self::Condensed(qp) => qp.extract(lin, e0, dx, du),
        }
    }

    pub fn snapshot(&self) -> QpSnapshot {
        match self {
            Self::Sparse(qp) => qp.snapshot(),
            Self::Condensed(qp) => qp.snapshot(),
        }
    }

    /// See [`TimedSolver::iterate_meets_reduced_tolerances`].
    pub fn iterate_usable(&self) -> bool {
        match self {
            Self::Sparse(qp) => qp.solver.iterate_meets_reduced_tolerances(),
            Self::Condensed(qp) => qp.solver.iterate_meets_reduced_tolerances(),
        }
    }

    pub fn formulation(&self) -> Formulation {
        match self {
            Self::Sparse(_) => Formulation::Sparse,
            Self::Condensed(_) => Formulation::Condensed,
        }
    }

    /// Primal solution vector of the last solve (layout of the formulation).
    pub fn raw_solution(&self) -> &[f64] {
        match self {
            Self::Sparse(qp) => &qp.solver.solver.solution.x,
            Self::Condensed(qp) => qp.raw_solution(),
        }
    }

    /// The condensed QP, whose box-only constraints allow the homotopy.
    pub fn condensed_mut(&mut self) -> Option<&mut CondensedQp> {
        match self {
            Self::Sparse(_) => None,
            Self::Condensed(qp) => Some(qp),
        }
    }
}

// ---------------------------------------------------------------------------
// Sparse multiple shooting.

/// Variables `z = (dx_0, du_0, dx_1, du_1, ..., dx_{N-1}, du_{N-1}, dx_N)`
/// (stage-interleaved, so the KKT matrix is banded). Rows: `12 (N+1)`
/// equalities (`dx_0 = e0`, then `dx_{k+1} - A_k dx_k - B_k du_k = defect_k`),
/// then `8N` bounds (`du <= 1 - ubar`, `-du <= ubar`). P is diagonal.
pub struct SparseQp {
    steps: usize,
    solver: TimedSolver,
    p_vals: Vec<f64>,
    q: Vec<f64>,
    a_vals: Vec<f64>,
    b: Vec<f64>,
    /// Pattern copies for snapshots.
    p_pattern: CscMatrix<f64>,
    a_pattern: CscMatrix<f64>,
}

const STAGE: usize = NX + NU;

fn x_offset(k: usize) -> usize {
    k * STAGE
}
fn u_offset(k: usize) -> usize {
    k * STAGE + NX
}

impl SparseQp {
    fn dims(steps: usize) -> (usize, usize, usize) {
        (steps * STAGE + NX, NX * (steps + 1), 2 * NU * steps)
    }

    /// Walks A column by column in pattern order: `Some((row, value))` per
    /// entry, `None` at the end of each column.
    fn walk_a(lin: &LinearizedHorizon, mut visit: impl FnMut(Option<(usize, f64)>)) {
        let n = lin.steps();
        let bound_base = NX * (n + 1);
        for k in 0..=n {
            for j in 0..NX {
                visit(Some((NX * k + j, 1.0)));
                if k < n {
                    for i in 0..NX {
                        visit(Some((NX * (k + 1) + i, -lin.a[k][(i, j)])));
                    }
                }
                visit(None);
            }
            if k < n {
                for j in 0..NU {
                    for i in 0..NX {
                        visit(Some((NX * (k + 1) + i, -lin.b[k][(i, j)])));
                    }
                    visit(Some((bound_base + 2 * NU * k + j, 1.0)));
                    visit(Some((bound_base + 2 * NU * k + NU + j, -1.0)));
                    visit(None);
                }
            }
        }
    }

    fn fill_vectors(lin: &LinearizedHorizon, p_vals: &mut [f64], q: &mut [f64], b: &mut [f64]) {
        let n = lin.steps();
        for k in 0..=n {
            let o = x_offset(k);
            for i in 0..NX {
                p_vals[o + i] = lin.q_diag[k][i];
                q[o + i] = lin.q_diag[k][i] * lin.x_err[k][i];
            }
            if k < n {
                let o = u_offset(k);
                for i in 0..NU {
                    p_vals[o + i] = lin.r_diag[i];
                    q[o + i] = lin.r_diag[i] * lin.u_err[k][i];
                }
                b[NX * (k + 1)..NX * (k + 2)].copy_from_slice(lin.defect[k].as_slice());
                let bound = NX * (n + 1) + 2 * NU * k;
                for i in 0..NU {
                    b[bound + i] = 1.0 - lin.u_bar[k][i];
                    b[bound + NU + i] = lin.u_bar[k][i];
                }
            }
        }
    }

    fn new(lin: &LinearizedHorizon, settings: &SolverSettings) -> Result<Self> {
        let steps = lin.steps();
        let (nz, rows_eq, rows_box) = Self::dims(steps);
        let mut a = CscBuilder::new(rows_eq + rows_box);
        Self::walk_a(lin, |entry| match entry {
            Some((row, value)) => a.push(row, value),
            None => a.end_column(),
        });
        let a_pattern = a.finish();
        let mut p = CscBuilder::new(nz);
        for c in 0..nz {
            p.push(c, 1.0);
            p.end_column();
        }
        let mut p_pattern = p.finish();
        let mut q = vec![0.0; nz];
        let mut b = vec![0.0; rows_eq + rows_box];
        Self::fill_vectors(lin, &mut p_pattern.nzval, &mut q, &mut b);
        let cones = [
            SupportedConeT::ZeroConeT(rows_eq),
            SupportedConeT::NonnegativeConeT(rows_box),
        ];
        let solver = TimedSolver::new(&p_pattern, &q, &a_pattern, &b, &cones, settings)?;
        Ok(Self {
            steps,
            solver,
            p_vals: p_pattern.nzval.clone(),
            q,
            a_vals: a_pattern.nzval.clone(),
            b,
            p_pattern,
            a_pattern,
        })
    }

    fn load(&mut self, lin: &LinearizedHorizon) -> Result<()> {
        let mut pos = 0;
        let vals = &mut self.a_vals;
        Self::walk_a(lin, |entry| {
            if let Some((_, value)) = entry {
                vals[pos] = value;
                pos += 1;
            }
        });
        Self::fill_vectors(lin, &mut self.p_vals, &mut self.q, &mut self.b);
        self.solver
            .solver
            .update_P(&self.p_vals)
            .map_err(solver_error)?;
        self.solver
            .solver
            .update_A(&self.a_vals)
            .map_err(solver_error)?;
        self.solver.solver.update_q(&self.q).map_err(solver_error)?;
        // b without e0 yet: feedback writes the first NX rows.
        self.solver.solver.update_b(&self.b).map_err(solver_error)
    }

    fn set_initial_deviation(&mut self, e0: &State) -> Result<()> {
        self.b[..NX].copy_from_slice(e0.as_slice());
        // Only the first NX rows change: a selective update.
        let rows: &[usize; NX] = &[0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11];
        self.solver
            .solver
            .update_b(&rows.iter().zip(self.b[..NX].iter()))
            .map_err(solver_error)
    }

    fn extract(&self, dx: &mut [State], du: &mut [Input]) {
        let z = &self.solver.solver.solution.x;
        for k in 0..=self.steps {
            dx[k].copy_from_slice(&z[x_offset(k)..x_offset(k) + NX]);
            if k < self.steps {
                du[k].copy_from_slice(&z[u_offset(k)..u_offset(k) + NU]);
            }
        }
    }

    fn snapshot(&self) -> QpSnapshot {
        let mut p = self.p_pattern.clone();
        p.nzval.copy_from_slice(&self.p_vals);
        let mut a = self.a_pattern.clone();
        a.nzval.copy_from_slice(&self.a_vals);
        let (_, rows_eq, rows_box) = Self::dims(self.steps);
        QpSnapshot {
            p,
            q: self.q.clone(),
            a,
            b: self.b.clone(),
            zero_rows: rows_eq,
            nonneg_rows: rows_box,
        }
    }
}

// ---------------------------------------------------------------------------
// Condensed.

type Gain = SMatrix<f64, NU, NX>;

/// Variables `du` (4N). With `dx_k = Phi_k e0 + sum_{j<k} G_{k,j} du_j + w_k`
/// the cost becomes `1/2 du' H du + (g0 + M e0)' du`; constraints are the box
/// `-ubar <= du <= 1 - ubar` only, so A = [I; -I] never changes.
pub struct CondensedQp {
    steps: usize,
    solver: TimedSolver,
    /// Dense Hessian, column-major n x n (both triangles).
    hessian: Vec<f64>,
    p_vals: Vec<f64>,
    /// `g0` (no e0 term) and the feedback gradient `g0 + M e0`.
    g0: Vec<f64>,
    q: Vec<f64>,
    b: Vec<f64>,
    /// `M_i = B_i' S_{i+1} Phi_{i+1}`, rows 4i..4i+4 of M.
    m: Vec<Gain>,
    // Work arrays of the condensing recursions.
    phi: Vec<StateJacobian>,
    w: Vec<State>,
    /// `G_{k,j}`, k = 1..N, j < k, at `k (k - 1) / 2 + j`.
    g: Vec<InputJacobian>,
    s: Vec<StateJacobian>,
    lambda: Vec<State>,
    p_pattern: CscMatrix<f64>,
    a_pattern: CscMatrix<f64>,
    /// The exact solution, moved from the predicted to the actual `e0`.
    homotopy: BoxHomotopy,
    /// Working set read off Clarabel's solution.
    guess: Vec<Bound>,
    /// Where the current solution comes from.
    solved_by: SolvedBy,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum SolvedBy {
    Clarabel,
    Homotopy,
}

/// What the preparation's solve at the predicted state gave.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PreparedSolution {
    /// Clarabel at the predicted state.
    pub clarabel: SolveReport,
    /// The walk from Clarabel's active set to the exact solution: working-set
    /// changes, or why it stopped (then the feedback must use Clarabel).
    pub correction: std::result::Result<u32, HomotopyStop>,
}

fn g_index(k: usize, j: usize) -> usize {
    k * (k - 1) / 2 + j
}

impl CondensedQp {
    fn new(lin: &LinearizedHorizon, settings: &SolverSettings) -> Result<Self> {
        let steps = lin.steps();
        let n = NU * steps;
        let mut p = CscBuilder::new(n);
        for c in 0..n {
            for r in 0..=c {
                p.push(r, if r == c { 1.0 } else { 0.0 });
            }
            p.end_column();
        }
        let p_pattern = p.finish();
        let mut a = CscBuilder::new(2 * n);
        for c in 0..n {
            a.push(c, 1.0);
            a.push(n + c, -1.0);
            a.end_column();
        }
        let a_pattern = a.finish();
        let mut qp = Self {
            steps,
            // Placeholder identity QP, replaced right below once values exist.
            solver: TimedSolver::new(
                &p_pattern,
                &vec![0.0; n],
                &a_pattern,
                &vec![1.0; 2 * n],
                &[SupportedConeT::NonnegativeConeT(2 * n)],
                settings,
            )?,
            hessian: vec![0.0; n * n],
            p_vals: p_pattern.nzval.clone(),
            g0: vec![0.0; n],
            q: vec![0.0; n],
            b: vec![0.0; 2 * n],
            m: vec![Gain::zeros(); steps],
            phi: vec![StateJacobian::identity(); steps + 1],
            w: vec![State::zeros(); steps + 1],
            g: vec![InputJacobian::zeros(); steps * (steps + 1) / 2],
            s: vec![StateJacobian::zeros(); steps + 1],
            lambda: vec![State::zeros(); steps + 1],
            p_pattern,
            a_pattern,
            homotopy: BoxHomotopy::new(n),
            guess: vec![Bound::Free; n],
            solved_by: SolvedBy::Clarabel,
        };
        // Build the real solver from the real start-up values, so that its
        // equilibration matches the problem it will see.
        qp.condense(lin);
        qp.q.copy_from_slice(&qp.g0);
        let mut p_now = qp.p_pattern.clone();
        p_now.nzval.copy_from_slice(&qp.p_vals);
        qp.solver = TimedSolver::new(
            &p_now,
            &qp.q,
            &qp.a_pattern,
            &qp.b,
            &[SupportedConeT::NonnegativeConeT(2 * n)],
            settings,
        )?;
        Ok(qp)
    }

    /// The condensing recursions (see the crate docs).
    fn condense(&mut self, lin: &LinearizedHorizon) {
        let n = self.steps;
        let nu_total = NU * n;
        // Forward: Phi, w, G.
        self.phi[0] = StateJacobian::identity();
        self.w[0] = State::zeros();
        for k in 0..n {
            self.phi[k + 1] = lin.a[k] * self.phi[k];
            self.w[k + 1] = lin.a[k] * self.w[k] + lin.defect[k];
            for j in 0..k {
                self.g[g_index(k + 1, j)] = lin.a[k] * self.g[g_index(k, j)];
            }
            self.g[g_index(k + 1, k)] = lin.b[k];
        }
        // Backward: S_k = Q_k + A_k' S_{k+1} A_k, lambda_k = Q_k c_k + A_k' lambda_{k+1},
        // with c_k = w_k + xbar_k - x_ref_k.
        let c_n = self.w[n] + lin.x_err[n];
        self.s[n] = StateJacobian::from_diagonal(&lin.q_diag[n]);
        self.lambda[n] = lin.q_diag[n].component_mul(&c_n);
        for k in (1..n).rev() {
            let c_k = self.w[k] + lin.x_err[k];
            let at = lin.a[k].transpose();
            let mut s = at * self.s[k + 1] * lin.a[k];
            for i in 0..NX {
                s[(i, i)] += lin.q_diag[k][i];
            }
            // Symmetrize against round-off growth.
            self.s[k] = (s + s.transpose()) * 0.5;
            self.lambda[k] = lin.q_diag[k].component_mul(&c_k) + at * self.lambda[k + 1];
        }
        // Rows of H, M and g0.
        for i in 0..n {
            let t: Gain = lin.b[i].transpose() * self.s[i + 1];
            self.m[i] = t * self.phi[i + 1];
            let g_i =
                lin.b[i].transpose() * self.lambda[i + 1] + lin.r_diag.component_mul(&lin.u_err[i]);
            self.g0[NU * i..NU * (i + 1)].copy_from_slice(g_i.as_slice());
            for j in 0..=i {
                let mut block: SMatrix<f64, NU, NU> = t * self.g[g_index(i + 1, j)];
                if j == i {
                    block = (block + block.transpose()) * 0.5;
                    for d in 0..NU {
                        block[(d, d)] += lin.r_diag[d];
                    }
                }
                for c in 0..NU {
                    for r in 0..NU {
                        // H[4i + r, 4j + c] and its mirror.
                        self.hessian[(NU * j + c) * nu_total + NU * i + r] = block[(r, c)];
                        self.hessian[(NU * i + r) * nu_total + NU * j + c] = block[(r, c)];
                    }
                }
            }
        }
        let mut pos = 0;
        for c in 0..nu_total {
            for r in 0..=c {
                self.p_vals[pos] = self.hessian[c * nu_total + r];
                pos += 1;
            }
        }
        for k in 0..n {
            for i in 0..NU {
                self.b[NU * k + i] = 1.0 - lin.u_bar[k][i];
                self.b[nu_total + NU * k + i] = lin.u_bar[k][i];
            }
        }
    }

    fn load(&mut self, lin: &LinearizedHorizon) -> Result<()> {
        self.condense(lin);
        self.q.copy_from_slice(&self.g0);
        self.solver
            .solver
            .update_P(&self.p_vals)
            .map_err(solver_error)?;
        self.solver.solver.update_b(&self.b).map_err(solver_error)?;
        self.solver.solver.update_q(&self.q).map_err(solver_error)
    }

    /// `q = g0 + M e0`.
    fn gradient_at(&mut self, e0: &State) {
        for i in 0..self.steps {
            let gi = self.m[i] * e0;
            for d in 0..NU {
                self.q[NU * i + d] = self.g0[NU * i + d] + gi[d];
            }
        }
    }

    fn set_initial_deviation(&mut self, e0: &State) -> Result<()> {
        self.gradient_at(e0);
        self.solved_by = SolvedBy::Clarabel;
        self.solver.solver.update_q(&self.q).map_err(solver_error)
    }

    /// The homotopy's target: the current `q` and the box.
    fn set_homotopy_target(&mut self) {
        let n = NU * self.steps;
        let (q, lo, hi) = self.homotopy.target_mut();
        q.copy_from_slice(&self.q);
        hi.copy_from_slice(&self.b[..n]);
        for (l, ubar) in lo.iter_mut().zip(&self.b[n..]) {
            *l = -ubar;
        }
    }

    /// Preparation: Clarabel solves at the predicted `e0`; the working set
    /// read off its solution (a bound is active where its slack is below its
    /// multiplier) is corrected by the homotopy into the exact solution there.
    pub fn prepare_solution(
        &mut self,
        e0_predicted: &State,
        max_changes: u32,
    ) -> Result<PreparedSolution> {
        self.set_initial_deviation(e0_predicted)?;
        let clarabel = self.solver.solve();
        let n = NU * self.steps;
        let sol = &self.solver.solver.solution;
        if matches!(
            clarabel.status,
            SolverStatus::Solved | SolverStatus::AlmostSolved
        ) {
            for i in 0..n {
                // Rows 0..n: du <= hi (slack s_i), rows n..2n: -du <= -lo.
                let (s_hi, y_hi) = (sol.s[i], sol.z[i]);
                let (s_lo, y_lo) = (sol.s[n + i], sol.z[n + i]);
                self.guess[i] = if s_hi < y_hi {
                    Bound::Upper
                } else if s_lo < y_lo {
                    Bound::Lower
                } else {
                    Bound::Free
                };
            }
        } else {
            // An iterate cut short (time or iteration limit) guesses badly
            // (measured: more than 80 changes from it); the last tick's
            // working set is closer.
            self.guess.copy_from_slice(self.homotopy.working_set());
        }
        self.set_homotopy_target();
        let correction = self
            .homotopy
            .solve_from_guess(&self.hessian, &self.guess, max_changes);
        if correction.is_ok() {
            self.solved_by = SolvedBy::Homotopy;
        }
        Ok(PreparedSolution {
            clarabel,
            correction,
        })
    }

    /// Feedback: moves the prepared exact solution to `e0` (only `q` changes).
    /// On `Err` the solution is unusable; solve with Clarabel instead.
    pub fn feedback_solution(
        &mut self,
        e0: &State,
        max_changes: u32,
    ) -> std::result::Result<u32, HomotopyStop> {
        self.gradient_at(e0);
        self.set_homotopy_target();
        let walked = self.homotopy.walk_to_target(&self.hessian, max_changes);
        self.solved_by = if walked.is_ok() {
            SolvedBy::Homotopy
        } else {
            SolvedBy::Clarabel
        };
        walked
    }

    /// The dense Hessian `H` (n x n, symmetric).
    pub fn hessian(&self) -> &[f64] {
        &self.hessian
    }

    /// The homotopy's working set after the last preparation or feedback.
    pub fn working_set(&self) -> &[Bound] {
        self.homotopy.working_set()
    }

    /// Primal solution of the last solve (Clarabel's or the homotopy's).
    pub fn raw_solution(&self) -> &[f64] {
        match self.solved_by {
            SolvedBy::Clarabel => &self.solver.solver.solution.x,
            SolvedBy::Homotopy => self.homotopy.solution(),
        }
    }

    fn extract(&self, lin: &LinearizedHorizon, e0: &State, dx: &mut [State], du: &mut [Input]) {
        let z = self.raw_solution();
        dx[0] = *e0;
        for k in 0..self.steps {
            du[k] = SVector::<f64, NU>::from_column_slice(&z[NU * k..NU * (k + 1)]);
            dx[k + 1] = lin.a[k] * dx[k] + lin.b[k] * du[k] + lin.defect[k];
        }
    }

    fn snapshot(&self) -> QpSnapshot {
        let mut p = self.p_pattern.clone();
        p.nzval.copy_from_slice(&self.p_vals);
        QpSnapshot {
            p,
            q: self.q.clone(),
            a: self.a_pattern.clone(),
            b: self.b.clone(),
            zero_rows: 0,
            nonneg_rows: 2 * NU * self.steps,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::settings::MpcSettings;

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
        let clarabel_clock = |s: &TimedSolver| s.solver.timers.as_ref().unwrap().total_time();
        solver.solve();
        let first = clarabel_clock(&solver);
        let limit = Duration::from_secs_f64(settings.time_limit);
        let mut stalled = 0;
        for k in 0..20_000 {
            let start = std::time::Instant::now();
            let report = solver.solve();
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
    fn time_limit_stops_a_solve() {
        let mut settings = MpcSettings::atmo("default").unwrap().solver;
        settings.time_limit = 0.0;
        let mut solver = tiny(&settings);
        assert_eq!(solver.solve().status, SolverStatus::CallbackTerminated);
    }
}
