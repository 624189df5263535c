//! The RTI quadratic program in its two forms, and Clarabel updated in place.
//!
//! Both forms are in deviations from the plan (`dx_k = x_k - xbar_k`,
//! `du_k = u_k - ubar_k`) and are filled from one [`LinearizedHorizon`].
//! Each builds its sparsity pattern once; every later tick writes values into
//! the same pattern (`update_P/q/A/b`), so the solver's symbolic
//! factorization is reused and nothing is allocated by our code.

mod condensed;
pub mod cuts;
mod solver;
mod sparse;

use atmo_core::model::{NU as ATMO_NU, NX as ATMO_NX};
use clarabel::algebra::CscMatrix;
use clarabel::solver::{DefaultSolver, SolverStatus, SupportedConeT};
use nalgebra::{SMatrix, SVector};

use crate::error::Result;
use crate::settings::{Formulation, SolverSettings};

use condensed::SolvedBy;
pub use condensed::{CondensedQp, PreparedSolution};
pub use solver::{TimedSolver, build_solver, clarabel_settings};
pub use sparse::SparseQp;

/// Everything the QP needs from one linearization along the plan.
/// Stages `k = 0..N` for states, `0..N-1` for inputs.
#[derive(Debug, Clone)]
pub struct LinearizedHorizon<const NX: usize = ATMO_NX, const NU: usize = ATMO_NU> {
    /// `dx_{k+1} = A_k dx_k + B_k du_k + defect_k`.
    pub a: Vec<SMatrix<f64, NX, NX>>,
    pub b: Vec<SMatrix<f64, NX, NU>>,
    /// `RK4(xbar_k, ubar_k) - xbar_{k+1}`: the multiple-shooting gap.
    pub defect: Vec<SVector<f64, NX>>,
    /// Diagonal of the state weight per stage (index N: terminal).
    pub q_diag: Vec<SVector<f64, NX>>,
    /// Diagonal of the input weight.
    pub r_diag: SVector<f64, NU>,
    /// `xbar_k - x_ref_k`, yaw entry wrapped to (-pi, pi].
    pub x_err: Vec<SVector<f64, NX>>,
    /// `ubar_k - u_ref_k`.
    pub u_err: Vec<SVector<f64, NU>>,
    /// `ubar_k`: bounds are `u_lo - ubar <= du <= u_hi - ubar`.
    pub u_bar: Vec<SVector<f64, NU>>,
    /// Input bounds per stage (0 and 1 for the rotor commands).
    pub u_lo: Vec<SVector<f64, NU>>,
    pub u_hi: Vec<SVector<f64, NU>>,
}

impl<const NX: usize, const NU: usize> LinearizedHorizon<NX, NU> {
    pub fn new(steps: usize) -> Self {
        Self {
            a: vec![SMatrix::<f64, NX, NX>::identity(); steps],
            b: vec![SMatrix::<f64, NX, NU>::zeros(); steps],
            defect: vec![SVector::<f64, NX>::zeros(); steps],
            q_diag: vec![SVector::<f64, NX>::from_element(1.0); steps + 1],
            r_diag: SVector::<f64, NU>::from_element(1.0),
            x_err: vec![SVector::<f64, NX>::zeros(); steps + 1],
            u_err: vec![SVector::<f64, NU>::zeros(); steps],
            u_bar: vec![SVector::<f64, NU>::from_element(0.5); steps],
            u_lo: vec![SVector::<f64, NU>::zeros(); steps],
            u_hi: vec![SVector::<f64, NU>::from_element(1.0); steps],
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

/// The RTI QP and its solver, in the chosen formulation.
pub enum QpBackend<const NX: usize = ATMO_NX, const NU: usize = ATMO_NU> {
    Sparse(Box<SparseQp<NX, NU>>),
    Condensed(Box<CondensedQp<NX, NU>>),
}

impl<const NX: usize, const NU: usize> QpBackend<NX, NU> {
    /// Builds the pattern from `lin` and creates Clarabel once.
    pub fn new(lin: &LinearizedHorizon<NX, NU>, settings: &SolverSettings) -> Result<Self> {
        Ok(match settings.formulation {
            Formulation::Sparse => Self::Sparse(Box::new(SparseQp::new(lin, settings)?)),
            Formulation::Condensed => Self::Condensed(Box::new(CondensedQp::new(lin, settings)?)),
        })
    }

    /// Preparation: write the new linearization into the solver.
    pub fn load(&mut self, lin: &LinearizedHorizon<NX, NU>) -> Result<()> {
        match self {
            Self::Sparse(qp) => qp.load(lin),
            Self::Condensed(qp) => qp.load(lin),
        }
    }

    /// Feedback: insert `dx_0 = x_est - xbar_0`.
    pub fn set_initial_deviation(&mut self, e0: &SVector<f64, NX>) -> Result<()> {
        match self {
            Self::Sparse(qp) => qp.set_initial_deviation(e0),
            Self::Condensed(qp) => qp.set_initial_deviation(e0),
        }
    }

    /// Clarabel on the QP as loaded in it, as the next solve of `window`
    /// (which records a time-limit cut, or repeats a replay's; see [`cuts`]).
    pub fn solve(&mut self, window: &mut cuts::CutWindow) -> SolveReport {
        match self {
            Self::Sparse(qp) => qp.solver.solve(window),
            Self::Condensed(qp) => {
                qp.solved_by = SolvedBy::Clarabel;
                qp.solver.solve(window)
            }
        }
    }

    /// The solution as plan deviations (states by forward simulation of the
    /// linear model in the condensed form).
    pub fn extract(
        &self,
        lin: &LinearizedHorizon<NX, NU>,
        e0: &SVector<f64, NX>,
        dx: &mut [SVector<f64, NX>],
        du: &mut [SVector<f64, NU>],
    ) {
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
    pub fn condensed_mut(&mut self) -> Option<&mut CondensedQp<NX, NU>> {
        match self {
            Self::Sparse(_) => None,
            Self::Condensed(qp) => Some(qp),
        }
    }
}
