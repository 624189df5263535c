//! The condensed QP: states eliminated, 4N inputs, a dense Hessian and box
//! constraints only, so that the feedback can walk the exact homotopy.

use atmo_core::model::{NU as ATMO_NU, NX as ATMO_NX};
use clarabel::algebra::CscMatrix;
use clarabel::solver::{SolverStatus, SupportedConeT};
use nalgebra::{SMatrix, SVector};

use super::cuts::CutWindow;
use super::solver::{CscBuilder, TimedSolver, solver_error};
use super::{LinearizedHorizon, QpSnapshot, SolveReport};
use crate::error::Result;
use crate::homotopy::{Bound, BoxHomotopy, HomotopyStop};
use crate::settings::SolverSettings;

/// Variables `du` (4N). With `dx_k = Phi_k e0 + sum_{j<k} G_{k,j} du_j + w_k`
/// the cost becomes `1/2 du' H du + (g0 + M e0)' du`; constraints are the box
/// `-ubar <= du <= 1 - ubar` only, so A = [I; -I] never changes.
pub struct CondensedQp<const NX: usize = ATMO_NX, const NU: usize = ATMO_NU> {
    steps: usize,
    pub(super) solver: TimedSolver,
    /// Dense Hessian, column-major n x n (both triangles).
    hessian: Vec<f64>,
    p_vals: Vec<f64>,
    /// `g0` (no e0 term) and the feedback gradient `g0 + M e0`.
    g0: Vec<f64>,
    q: Vec<f64>,
    b: Vec<f64>,
    /// `M_i = B_i' S_{i+1} Phi_{i+1}`, rows 4i..4i+4 of M.
    m: Vec<SMatrix<f64, NU, NX>>,
    // Work arrays of the condensing recursions.
    phi: Vec<SMatrix<f64, NX, NX>>,
    w: Vec<SVector<f64, NX>>,
    /// `G_{k,j}`, k = 1..N, j < k, at `k (k - 1) / 2 + j`.
    g: Vec<SMatrix<f64, NX, NU>>,
    s: Vec<SMatrix<f64, NX, NX>>,
    lambda: Vec<SVector<f64, NX>>,
    p_pattern: CscMatrix<f64>,
    a_pattern: CscMatrix<f64>,
    /// The exact solution, moved from the predicted to the actual `e0`.
    homotopy: BoxHomotopy,
    /// Working set read off Clarabel's solution.
    guess: Vec<Bound>,
    /// Where the current solution comes from.
    pub(super) solved_by: SolvedBy,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum SolvedBy {
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

impl<const NX: usize, const NU: usize> CondensedQp<NX, NU> {
    pub(super) fn new(lin: &LinearizedHorizon<NX, NU>, settings: &SolverSettings) -> Result<Self> {
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
            m: vec![SMatrix::<f64, NU, NX>::zeros(); steps],
            phi: vec![SMatrix::<f64, NX, NX>::identity(); steps + 1],
            w: vec![SVector::<f64, NX>::zeros(); steps + 1],
            g: vec![SMatrix::<f64, NX, NU>::zeros(); steps * (steps + 1) / 2],
            s: vec![SMatrix::<f64, NX, NX>::zeros(); steps + 1],
            lambda: vec![SVector::<f64, NX>::zeros(); steps + 1],
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
    fn condense(&mut self, lin: &LinearizedHorizon<NX, NU>) {
        let n = self.steps;
        let nu_total = NU * n;
        // Forward: Phi, w, G.
        self.phi[0] = SMatrix::<f64, NX, NX>::identity();
        self.w[0] = SVector::<f64, NX>::zeros();
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
        self.s[n] = SMatrix::<f64, NX, NX>::from_diagonal(&lin.q_diag[n]);
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
            let t: SMatrix<f64, NU, NX> = lin.b[i].transpose() * self.s[i + 1];
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
                self.b[NU * k + i] = lin.u_hi[k][i] - lin.u_bar[k][i];
                self.b[nu_total + NU * k + i] = lin.u_bar[k][i] - lin.u_lo[k][i];
            }
        }
    }

    pub(super) fn load(&mut self, lin: &LinearizedHorizon<NX, NU>) -> Result<()> {
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
    fn gradient_at(&mut self, e0: &SVector<f64, NX>) {
        for i in 0..self.steps {
            let gi = self.m[i] * e0;
            for d in 0..NU {
                self.q[NU * i + d] = self.g0[NU * i + d] + gi[d];
            }
        }
    }

    pub(super) fn set_initial_deviation(&mut self, e0: &SVector<f64, NX>) -> Result<()> {
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
    /// The Clarabel solve is the next of `window` ([`super::cuts`]): a cut
    /// there changes the homotopy's starting guess, and so the rounding of
    /// its exact solution, which a replay must repeat.
    pub fn prepare_solution(
        &mut self,
        e0_predicted: &SVector<f64, NX>,
        max_changes: u32,
        window: &mut CutWindow,
    ) -> Result<PreparedSolution> {
        self.set_initial_deviation(e0_predicted)?;
        let clarabel = self.solver.solve(window);
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
        e0: &SVector<f64, NX>,
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

    pub(super) fn extract(
        &self,
        lin: &LinearizedHorizon<NX, NU>,
        e0: &SVector<f64, NX>,
        dx: &mut [SVector<f64, NX>],
        du: &mut [SVector<f64, NU>],
    ) {
        let z = self.raw_solution();
        dx[0] = *e0;
        for k in 0..self.steps {
            du[k] = SVector::<f64, NU>::from_column_slice(&z[NU * k..NU * (k + 1)]);
            dx[k + 1] = lin.a[k] * dx[k] + lin.b[k] * du[k] + lin.defect[k];
        }
    }

    pub(super) fn snapshot(&self) -> QpSnapshot {
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
