//! Exact solution of a box-constrained convex QP by a parametric active-set
//! homotopy (the online active-set strategy of qpOASES, for simple bounds).
//!
//! # The problem
//!
//! ```text
//! min 1/2 z' H z + q' z   s.t.  lo <= z <= hi,     H symmetric positive definite (n x n)
//! ```
//!
//! A working set `W` fixes each variable free (`F`), at its lower bound or at
//! its upper bound (`A = L u U`). For a given `W` the stationary point is
//!
//! ```text
//! z_A = lo_L / hi_U,   H_FF z_F = -(q_F + H_FA z_A),   g = H z + q  (g_F = 0)
//! ```
//!
//! and it is the QP's solution iff it is primal feasible (`lo_F <= z_F <= hi_F`)
//! and dual feasible (`g_i >= 0` on `L`, `g_i <= 0` on `U`: `g_A` are the
//! bound multipliers).
//!
//! # The homotopy
//!
//! The point above is affine in the data `(q, lo, hi)`. Given the solution for
//! data `d_0` and the target data `d_1`, move along `d(s) = d_0 + s (d_1 - d_0)`:
//! with the target point `z^W(d_1)` of the current working set, the solution
//! moves on the segment from `z` to `z^W(d_1)` (and `g` likewise) until the first
//! breakpoint, where a free variable reaches a bound (it joins `A`) or a
//! multiplier reaches zero (its variable becomes free). There the working set
//! changes by one variable and the walk continues from the breakpoint to the
//! same `d_1`. When no breakpoint lies before the end the solution is
//! `z^W(d_1)` itself, computed from the factor: the result carries no round-off
//! accumulated along the path, only that of one solve.
//!
//! `H_FF = L L'` is kept as a Cholesky factor in the order variables became
//! free: freeing a variable appends a row (a forward solve); fixing one deletes
//! its row and column and restores the trailing block by a rank-one update
//! (Givens-like, always stable). Each change costs O(|F|^2), nothing allocates
//! after [`BoxHomotopy::new`].
//!
//! # Starting from a guess
//!
//! [`BoxHomotopy::solve_from_guess`] turns any working set into a solution: it
//! computes `z^W` for the real data, then relaxes the data so that `z^W` is
//! optimal (bounds of violated free variables moved to `z`, gradients of
//! wrong-signed multipliers shifted to zero) and walks the homotopy from that
//! auxiliary QP back to the real one. A good guess (an interior-point solution)
//! needs no step.

/// Where a variable sits in the working set.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Bound {
    Free,
    Lower,
    Upper,
}

/// Why a homotopy stopped before the target.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum HomotopyStop {
    /// More working-set changes than allowed.
    ChangeLimit,
    /// A pivot of the Cholesky factor of `H_FF` was too small (relative to the
    /// diagonal of `H`): the reduced Hessian is near singular.
    IllConditioned,
    /// A non-finite number in the data or the iterate.
    NonFinite,
}

/// A pivot `d` with `d^2 < PIVOT_TOLERANCE * H_ii` counts as ill-conditioned.
const PIVOT_TOLERANCE: f64 = 1e-12;

/// A slack or multiplier that ends the segment above `-ZERO_TOLERANCE`
/// (times the scale of `H` for multipliers) does not block. Without it a
/// degenerate variable (at its bound with a zero multiplier) whose end value
/// is a round-off `-1e-16` flips between fixed and free at zero step length.
const ZERO_TOLERANCE: f64 = 1e-11;

/// The homotopy's state: working set, factor, current point, current data.
pub struct BoxHomotopy {
    n: usize,
    bound: Vec<Bound>,
    /// Free variables in factor order (capacity n, never reallocated).
    free: Vec<usize>,
    /// Lower Cholesky factor of `H_FF` in `free` order, row-major, stride n.
    chol: Vec<f64>,
    /// Solution and gradient `H z + q` for the current data.
    z: Vec<f64>,
    grad: Vec<f64>,
    /// Current data.
    q: Vec<f64>,
    lo: Vec<f64>,
    hi: Vec<f64>,
    /// Target data of the walk in progress.
    q_end: Vec<f64>,
    lo_end: Vec<f64>,
    hi_end: Vec<f64>,
    /// Working-set point and gradient at the target data.
    z_w: Vec<f64>,
    grad_w: Vec<f64>,
    /// Work vector in factor order.
    work: Vec<f64>,
}

impl BoxHomotopy {
    /// Buffers for `n` variables (the only allocations).
    pub fn new(n: usize) -> Self {
        Self {
            n,
            bound: vec![Bound::Free; n],
            free: Vec::with_capacity(n),
            chol: vec![0.0; n * n],
            z: vec![0.0; n],
            grad: vec![0.0; n],
            q: vec![0.0; n],
            lo: vec![0.0; n],
            hi: vec![0.0; n],
            q_end: vec![0.0; n],
            lo_end: vec![0.0; n],
            hi_end: vec![0.0; n],
            z_w: vec![0.0; n],
            grad_w: vec![0.0; n],
            work: vec![0.0; n],
        }
    }

    pub fn len(&self) -> usize {
        self.n
    }

    pub fn is_empty(&self) -> bool {
        self.n == 0
    }

    /// The current solution.
    pub fn solution(&self) -> &[f64] {
        &self.z
    }

    /// `H z + q` at the current solution: zero on free variables, the bound
    /// multipliers (signed) on the others.
    pub fn gradient(&self) -> &[f64] {
        &self.grad
    }

    /// The current working set.
    pub fn working_set(&self) -> &[Bound] {
        &self.bound
    }

    /// The target data: write `q`, `lo`, `hi` of the QP to solve next, then
    /// call [`Self::solve_from_guess`] or [`Self::walk_to_target`].
    pub fn target_mut(&mut self) -> (&mut [f64], &mut [f64], &mut [f64]) {
        (&mut self.q_end, &mut self.lo_end, &mut self.hi_end)
    }

    /// Solves the target QP from the working set `guess` (length n): factor
    /// `H_FF` afresh, relax the data until the guess is optimal, walk back.
    /// Returns the number of working-set changes.
    pub fn solve_from_guess(
        &mut self,
        h: &[f64],
        guess: &[Bound],
        max_changes: u32,
    ) -> Result<u32, HomotopyStop> {
        let n = self.n;
        debug_assert_eq!(h.len(), n * n);
        self.bound.copy_from_slice(guess);
        self.refactor(h)?;
        // z^W for the real data is the start; the relaxed data makes it optimal.
        self.working_set_point(h);
        self.q.copy_from_slice(&self.q_end);
        self.lo.copy_from_slice(&self.lo_end);
        self.hi.copy_from_slice(&self.hi_end);
        self.z.copy_from_slice(&self.z_w);
        self.grad.copy_from_slice(&self.grad_w);
        for i in 0..n {
            match self.bound[i] {
                Bound::Free => {
                    self.lo[i] = self.lo[i].min(self.z[i]);
                    self.hi[i] = self.hi[i].max(self.z[i]);
                }
                Bound::Lower if self.grad[i] < 0.0 => {
                    self.q[i] -= self.grad[i];
                    self.grad[i] = 0.0;
                }
                Bound::Upper if self.grad[i] > 0.0 => {
                    self.q[i] -= self.grad[i];
                    self.grad[i] = 0.0;
                }
                Bound::Lower | Bound::Upper => {}
            }
        }
        self.walk(h, max_changes)
    }

    /// Moves the current solution to the target data (set through
    /// [`Self::target_mut`]) along the straight line in the data.
    pub fn walk_to_target(&mut self, h: &[f64], max_changes: u32) -> Result<u32, HomotopyStop> {
        self.walk(h, max_changes)
    }

    fn walk(&mut self, h: &[f64], max_changes: u32) -> Result<u32, HomotopyStop> {
        let n = self.n;
        let mut changes = 0;
        let h_scale = (0..n).fold(1.0_f64, |m, i| m.max(h[i * n + i].abs()));
        let (slack_tol, multiplier_tol) = (ZERO_TOLERANCE, ZERO_TOLERANCE * h_scale);
        loop {
            self.working_set_point(h);
            // First breakpoint on the segment s in [0, 1].
            let mut step = 1.0;
            let mut blocking = None;
            // A quantity that is >= 0 now and `end` at the segment's end.
            let mut consider = |now: f64, end: f64, tol: f64, i: usize, to: Bound| {
                if end < -tol {
                    let now = now.max(0.0);
                    let s = now / (now - end);
                    if s < step {
                        step = s;
                        blocking = Some((i, to));
                    }
                }
            };
            for i in 0..n {
                match self.bound[i] {
                    Bound::Free => {
                        let (z, z_w) = (self.z[i], self.z_w[i]);
                        let tol = slack_tol;
                        consider(z - self.lo[i], z_w - self.lo_end[i], tol, i, Bound::Lower);
                        consider(self.hi[i] - z, self.hi_end[i] - z_w, tol, i, Bound::Upper);
                    }
                    Bound::Lower => {
                        consider(self.grad[i], self.grad_w[i], multiplier_tol, i, Bound::Free);
                    }
                    Bound::Upper => {
                        consider(
                            -self.grad[i],
                            -self.grad_w[i],
                            multiplier_tol,
                            i,
                            Bound::Free,
                        );
                    }
                }
            }
            let Some((i, to)) = blocking else {
                if !self.z_w.iter().all(|v| v.is_finite()) {
                    return Err(HomotopyStop::NonFinite);
                }
                self.z.copy_from_slice(&self.z_w);
                self.grad.copy_from_slice(&self.grad_w);
                self.q.copy_from_slice(&self.q_end);
                self.lo.copy_from_slice(&self.lo_end);
                self.hi.copy_from_slice(&self.hi_end);
                return Ok(changes);
            };
            if changes >= max_changes {
                return Err(HomotopyStop::ChangeLimit);
            }
            changes += 1;
            for k in 0..n {
                self.z[k] += step * (self.z_w[k] - self.z[k]);
                self.grad[k] += step * (self.grad_w[k] - self.grad[k]);
                self.q[k] += step * (self.q_end[k] - self.q[k]);
                self.lo[k] += step * (self.lo_end[k] - self.lo[k]);
                self.hi[k] += step * (self.hi_end[k] - self.hi[k]);
            }
            if !step.is_finite() {
                return Err(HomotopyStop::NonFinite);
            }
            match to {
                Bound::Lower | Bound::Upper => {
                    self.z[i] = if to == Bound::Lower {
                        self.lo[i]
                    } else {
                        self.hi[i]
                    };
                    self.bound[i] = to;
                    self.fix(i);
                }
                Bound::Free => {
                    self.grad[i] = 0.0;
                    self.bound[i] = Bound::Free;
                    self.release(h, i)?;
                }
            }
        }
    }

    /// `z_w`, `grad_w`: the working set's stationary point for the target data.
    fn working_set_point(&mut self, h: &[f64]) {
        let n = self.n;
        for i in 0..n {
            self.z_w[i] = match self.bound[i] {
                Bound::Free => 0.0,
                Bound::Lower => self.lo_end[i],
                Bound::Upper => self.hi_end[i],
            };
        }
        // Right-hand side -(q_F + H_FA z_A) in factor order.
        let m = self.free.len();
        for (r, &i) in self.free.iter().enumerate() {
            let row = &h[i * n..(i + 1) * n];
            let mut acc = self.q_end[i];
            for (j, &zj) in self.z_w.iter().enumerate() {
                acc += row[j] * zj;
            }
            self.work[r] = -acc;
        }
        self.solve_factor(m);
        for (r, &i) in self.free.iter().enumerate() {
            self.z_w[i] = self.work[r];
        }
        for i in 0..n {
            self.grad_w[i] = if self.bound[i] == Bound::Free {
                0.0
            } else {
                let row = &h[i * n..(i + 1) * n];
                row.iter().zip(&self.z_w).map(|(a, b)| a * b).sum::<f64>() + self.q_end[i]
            };
        }
    }

    /// `work[..m] <- (L L')^{-1} work[..m]`.
    fn solve_factor(&mut self, m: usize) {
        let n = self.n;
        let l = &self.chol;
        let x = &mut self.work[..m];
        for i in 0..m {
            let row = &l[i * n..i * n + i];
            let mut acc = x[i];
            for (a, b) in row.iter().zip(&x[..i]) {
                acc -= a * b;
            }
            x[i] = acc / l[i * n + i];
        }
        for i in (0..m).rev() {
            x[i] /= l[i * n + i];
            let xi = x[i];
            let row = &l[i * n..i * n + i];
            for (xj, a) in x[..i].iter_mut().zip(row) {
                *xj -= a * xi;
            }
        }
    }

    /// Factor of `H_FF` from scratch, free variables in index order.
    fn refactor(&mut self, h: &[f64]) -> Result<(), HomotopyStop> {
        self.free.clear();
        for i in 0..self.n {
            if self.bound[i] == Bound::Free {
                self.release(h, i)?;
            }
        }
        Ok(())
    }

    /// Variable `i` becomes free: a new last row of the factor.
    fn release(&mut self, h: &[f64], i: usize) -> Result<(), HomotopyStop> {
        let n = self.n;
        let m = self.free.len();
        for (r, &j) in self.free.iter().enumerate() {
            self.work[r] = h[j * n + i];
        }
        // Forward solve L l = H_F,i into row m.
        let mut norm2 = 0.0;
        for r in 0..m {
            let mut acc = self.work[r];
            for c in 0..r {
                acc -= self.chol[r * n + c] * self.chol[m * n + c];
            }
            let v = acc / self.chol[r * n + r];
            self.chol[m * n + r] = v;
            norm2 += v * v;
        }
        let pivot = h[i * n + i] - norm2;
        if !pivot.is_finite() {
            return Err(HomotopyStop::NonFinite);
        }
        if pivot <= PIVOT_TOLERANCE * h[i * n + i].abs() {
            return Err(HomotopyStop::IllConditioned);
        }
        self.chol[m * n + m] = pivot.sqrt();
        self.free.push(i);
        Ok(())
    }

    /// Variable `i` leaves the free set: delete its row and column of the
    /// factor, then `L33 L33' + v v'` (v: the deleted column below the
    /// diagonal) is refactored by a rank-one update.
    fn fix(&mut self, i: usize) {
        let n = self.n;
        let m = self.free.len();
        let Some(p) = self.free.iter().position(|&j| j == i) else {
            return;
        };
        self.free.remove(p);
        let l = &mut self.chol;
        // Shift rows p+1.. up by one, dropping column p; keep the dropped
        // entries in `work`.
        for r in p + 1..m {
            self.work[r - 1] = l[r * n + p];
            for c in 0..r {
                let from = if c < p { c } else { c + 1 };
                if from <= r {
                    l[(r - 1) * n + c] = l[r * n + from];
                }
            }
        }
        // Rank-one update of the trailing block (rows/cols p..m-1 of the new factor).
        for k in p..m - 1 {
            let lkk = l[k * n + k];
            let vk = self.work[k];
            let r = lkk.hypot(vk);
            let c = r / lkk;
            let s = vk / lkk;
            l[k * n + k] = r;
            for row in k + 1..m - 1 {
                let lik = (l[row * n + k] + s * self.work[row]) / c;
                self.work[row] = c * self.work[row] - s * lik;
                l[row * n + k] = lik;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A random SPD matrix and data, deterministic (LCG).
    struct Lcg(u64);
    impl Lcg {
        fn next(&mut self) -> f64 {
            self.0 = self
                .0
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            ((self.0 >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
        }
    }

    fn spd(n: usize, rng: &mut Lcg) -> Vec<f64> {
        let b: Vec<f64> = (0..n * n).map(|_| rng.next()).collect();
        let mut h = vec![0.0; n * n];
        for i in 0..n {
            for j in 0..n {
                h[i * n + j] = (0..n).map(|k| b[i * n + k] * b[j * n + k]).sum::<f64>();
            }
            h[i * n + i] += 0.1;
        }
        h
    }

    /// Max violation of the KKT conditions of the box QP at `z`.
    fn kkt_violation(h: &[f64], q: &[f64], lo: &[f64], hi: &[f64], z: &[f64]) -> f64 {
        let n = q.len();
        let mut worst: f64 = 0.0;
        for i in 0..n {
            let g: f64 = (0..n).map(|j| h[i * n + j] * z[j]).sum::<f64>() + q[i];
            worst = worst.max(lo[i] - z[i]).max(z[i] - hi[i]);
            let at_lo = (z[i] - lo[i]).abs() < 1e-12;
            let at_hi = (z[i] - hi[i]).abs() < 1e-12;
            let dual = if at_lo {
                (-g).max(0.0)
            } else if at_hi {
                g.max(0.0)
            } else {
                g.abs()
            };
            worst = worst.max(dual);
        }
        worst
    }

    fn random_box(n: usize, rng: &mut Lcg, h: &[f64]) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
        let q: Vec<f64> = (0..n).map(|_| 3.0 * rng.next()).collect();
        let lo: Vec<f64> = (0..n).map(|_| -0.2 - 0.3 * rng.next().abs()).collect();
        let hi: Vec<f64> = (0..n).map(|_| 0.2 + 0.3 * rng.next().abs()).collect();
        let _ = h;
        (q, lo, hi)
    }

    #[test]
    fn from_any_guess_and_along_the_line_the_kkt_conditions_hold() {
        let mut rng = Lcg(7);
        let mut changed = 0;
        for trial in 0..300 {
            let n = 1 + trial % 17;
            let h = spd(n, &mut rng);
            let (q, lo, hi) = random_box(n, &mut rng, &h);
            let mut hom = BoxHomotopy::new(n);
            let (tq, tlo, thi) = hom.target_mut();
            tq.copy_from_slice(&q);
            tlo.copy_from_slice(&lo);
            thi.copy_from_slice(&hi);
            let guess: Vec<Bound> = (0..n)
                .map(|i| [Bound::Free, Bound::Lower, Bound::Upper][(trial + i) % 3])
                .collect();
            hom.solve_from_guess(&h, &guess, 10 * n as u32).unwrap();
            let v = kkt_violation(&h, &q, &lo, &hi, hom.solution());
            assert!(v < 1e-10, "trial {trial}: KKT violation {v}");
            // Then a new gradient along the line.
            let q2: Vec<f64> = q.iter().map(|v| v + 2.0 * rng.next()).collect();
            hom.target_mut().0.copy_from_slice(&q2);
            let k = hom.walk_to_target(&h, 10 * n as u32).unwrap();
            changed += usize::from(k > 0);
            let v = kkt_violation(&h, &q2, &lo, &hi, hom.solution());
            assert!(
                v < 1e-10,
                "trial {trial}: KKT violation {v} after {k} changes"
            );
        }
        assert!(
            changed > 100,
            "only {changed} walks changed the working set"
        );
    }

    #[test]
    fn the_change_limit_stops_a_walk() {
        let mut rng = Lcg(3);
        let n = 12;
        let h = spd(n, &mut rng);
        let (q, lo, hi) = random_box(n, &mut rng, &h);
        let mut hom = BoxHomotopy::new(n);
        let (tq, tlo, thi) = hom.target_mut();
        tq.copy_from_slice(&q);
        tlo.copy_from_slice(&lo);
        thi.copy_from_slice(&hi);
        let needed = hom
            .solve_from_guess(&h, &vec![Bound::Free; n], 100)
            .unwrap();
        assert!(needed > 1, "{needed}");
        let mut again = BoxHomotopy::new(n);
        let (tq, tlo, thi) = again.target_mut();
        tq.copy_from_slice(&q);
        tlo.copy_from_slice(&lo);
        thi.copy_from_slice(&hi);
        assert_eq!(
            again.solve_from_guess(&h, &vec![Bound::Free; n], needed - 1),
            Err(HomotopyStop::ChangeLimit)
        );
    }

    #[test]
    fn a_singular_reduced_hessian_is_reported() {
        // Rank one: H = v v'.
        let n = 3;
        let v = [1.0, 2.0, -1.0];
        let h: Vec<f64> = (0..n * n).map(|k| v[k / n] * v[k % n]).collect();
        let mut hom = BoxHomotopy::new(n);
        assert_eq!(
            hom.solve_from_guess(&h, &[Bound::Free; 3], 10),
            Err(HomotopyStop::IllConditioned)
        );
    }
}
