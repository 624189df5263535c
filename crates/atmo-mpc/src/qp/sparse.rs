//! Sparse multiple shooting: states and inputs as variables, block-sparse
//! equality constraints, diagonal Hessian.

use atmo_core::model::{NU as ATMO_NU, NX as ATMO_NX};
use clarabel::algebra::CscMatrix;
use clarabel::solver::SupportedConeT;
use nalgebra::SVector;

use super::solver::{CscBuilder, TimedSolver, solver_error};
use super::{LinearizedHorizon, QpSnapshot};
use crate::error::Result;
use crate::settings::SolverSettings;

/// Variables `z = (dx_0, du_0, dx_1, du_1, ..., dx_{N-1}, du_{N-1}, dx_N)`
/// (stage-interleaved, so the KKT matrix is banded). Rows: `12 (N+1)`
/// equalities (`dx_0 = e0`, then `dx_{k+1} - A_k dx_k - B_k du_k = defect_k`),
/// then `8N` bounds (`du <= 1 - ubar`, `-du <= ubar`). P is diagonal.
pub struct SparseQp<const NX: usize = ATMO_NX, const NU: usize = ATMO_NU> {
    steps: usize,
    pub(super) solver: TimedSolver,
    p_vals: Vec<f64>,
    q: Vec<f64>,
    a_vals: Vec<f64>,
    b: Vec<f64>,
    /// `0..NX`: the rows of b the feedback writes.
    e0_rows: Vec<usize>,
    /// Pattern copies for snapshots.
    p_pattern: CscMatrix<f64>,
    a_pattern: CscMatrix<f64>,
}

impl<const NX: usize, const NU: usize> SparseQp<NX, NU> {
    const STAGE: usize = NX + NU;

    fn x_offset(k: usize) -> usize {
        k * Self::STAGE
    }
    fn u_offset(k: usize) -> usize {
        k * Self::STAGE + NX
    }

    fn dims(steps: usize) -> (usize, usize, usize) {
        (steps * Self::STAGE + NX, NX * (steps + 1), 2 * NU * steps)
    }

    /// Walks A column by column in pattern order: `Some((row, value))` per
    /// entry, `None` at the end of each column.
    fn walk_a(lin: &LinearizedHorizon<NX, NU>, mut visit: impl FnMut(Option<(usize, f64)>)) {
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

    fn fill_vectors(
        lin: &LinearizedHorizon<NX, NU>,
        p_vals: &mut [f64],
        q: &mut [f64],
        b: &mut [f64],
    ) {
        let n = lin.steps();
        for k in 0..=n {
            let o = Self::x_offset(k);
            for i in 0..NX {
                p_vals[o + i] = lin.q_diag[k][i];
                q[o + i] = lin.q_diag[k][i] * lin.x_err[k][i];
            }
            if k < n {
                let o = Self::u_offset(k);
                for i in 0..NU {
                    p_vals[o + i] = lin.r_diag[i];
                    q[o + i] = lin.r_diag[i] * lin.u_err[k][i];
                }
                b[NX * (k + 1)..NX * (k + 2)].copy_from_slice(lin.defect[k].as_slice());
                let bound = NX * (n + 1) + 2 * NU * k;
                for i in 0..NU {
                    b[bound + i] = lin.u_hi[k][i] - lin.u_bar[k][i];
                    b[bound + NU + i] = lin.u_bar[k][i] - lin.u_lo[k][i];
                }
            }
        }
    }

    pub(super) fn new(lin: &LinearizedHorizon<NX, NU>, settings: &SolverSettings) -> Result<Self> {
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
            e0_rows: (0..NX).collect(),
            p_pattern,
            a_pattern,
        })
    }

    pub(super) fn load(&mut self, lin: &LinearizedHorizon<NX, NU>) -> Result<()> {
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

    pub(super) fn set_initial_deviation(&mut self, e0: &SVector<f64, NX>) -> Result<()> {
        self.b[..NX].copy_from_slice(e0.as_slice());
        // Only the first NX rows change: a selective update.
        self.solver
            .solver
            .update_b(&self.e0_rows.iter().zip(self.b[..NX].iter()))
            .map_err(solver_error)
    }

    pub(super) fn extract(&self, dx: &mut [SVector<f64, NX>], du: &mut [SVector<f64, NU>]) {
        let z = &self.solver.solver.solution.x;
        for k in 0..=self.steps {
            dx[k].copy_from_slice(&z[Self::x_offset(k)..Self::x_offset(k) + NX]);
            if k < self.steps {
                du[k].copy_from_slice(&z[Self::u_offset(k)..Self::u_offset(k) + NU]);
            }
        }
    }

    pub(super) fn snapshot(&self) -> QpSnapshot {
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
