//! Normal equations per segment, cross-validation over whole held-out
//! segments, forward-backward group selection, stability (inclusion
//! frequency over random halves of the segments) and delete-a-segment
//! jackknife uncertainties.
//!
//! Residuals and regressors are weighted by the channel noise floor, so one
//! unit of squared error is one noise-floor variance (and, in the second
//! pass, by the local excess variance: see `explain::entry_weights`). An effect enters the
//! model when adding it lowers the held-out squared error by at least
//! [`MIN_GAIN`] noise-floor variances per residual entry, and stays only if
//! removing it again would raise the held-out error by as much.

use nalgebra::{DMatrix, DVector};
use rand::SeedableRng;
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;

use crate::data::Prepared;
use crate::effects::{Effect, Layout};

/// Least held-out improvement for an effect, in noise-floor variances per
/// residual entry (2 %: a systematic RMS of about 0.14 of the noise floor
/// over the whole recording, or more in a part of it).
pub const MIN_GAIN: f64 = 0.02;
/// Number of cross-validation folds (segments are dealt round-robin).
pub const FOLDS: usize = 5;
/// Subsamples for the inclusion frequency.
pub const STABILITY_RUNS: usize = 24;

/// Sufficient statistics of the weighted least-squares problem, per segment.
#[derive(Debug, Clone)]
pub struct Stats {
    pub p: usize,
    pub g: Vec<DMatrix<f64>>,
    pub b: Vec<DVector<f64>>,
    pub yy: Vec<f64>,
    /// Residual entries (rows x 6) per segment.
    pub entries: Vec<usize>,
    /// Prior (penalty) matrix added to the normal equations of a fit.
    pub prior: DMatrix<f64>,
    /// Physical bounds of each column's coefficient (infinite for most):
    /// a fit that wants one beyond gets it at the bound (active set).
    pub bounds: Vec<(f64, f64)>,
}

/// Segments: contiguous stretches of about `max(2 s, T / 50)`; `seg_of[k]`
/// for fit rows.
pub fn segments(prep: &Prepared) -> (Vec<Option<usize>>, usize) {
    let t0 = prep.t[0];
    let total = prep.t[prep.n - 1] - t0;
    let len = (total / 50.0).max(2.0);
    let mut seg_of = vec![None; prep.n];
    let mut nseg = 0;
    for k in 0..prep.n {
        if prep.fit[k] {
            let s = ((prep.t[k] - t0) / len) as usize;
            seg_of[k] = Some(s);
            nseg = nseg.max(s + 1);
        }
    }
    (seg_of, nseg.max(1))
}

/// Fold of a segment.
pub fn fold_of(seg: usize) -> usize {
    seg % FOLDS
}

/// Most sweeps of the SVD fallback of [`bounded_solve`] (nalgebra's own
/// `pseudo_inverse` iterates until it converges: on a matrix with entries
/// near 1e200, from one finite but absurd cell such as `vx = 1e100`, it
/// never did).
const SVD_MAX_ITERATIONS: usize = 1000;

/// Solves `g theta = b` with a bounded cost: Cholesky (`g` is symmetric
/// and ridge-stabilized), else an SVD with at most [`SVD_MAX_ITERATIONS`]
/// sweeps and singular values below 1e-12 of the largest dropped. A system
/// with a non-finite entry, or whose SVD does not converge, has no solution
/// here: `theta = 0`, no correction (what an effect that explains nothing
/// is fitted to), so it cannot enter the model.
pub(crate) fn bounded_solve(g: DMatrix<f64>, b: &DVector<f64>) -> DVector<f64> {
    let q = b.len();
    if !g.iter().chain(b.iter()).all(|v| v.is_finite()) {
        return DVector::zeros(q);
    }
    if let Some(ch) = g.clone().cholesky() {
        let theta = ch.solve(b);
        if theta.iter().all(|v| v.is_finite()) {
            return theta;
        }
    }
    let Some(svd) = g.try_svd(true, true, f64::EPSILON, SVD_MAX_ITERATIONS) else {
        return DVector::zeros(q);
    };
    let largest = svd.singular_values.max();
    svd.solve(b, 1e-12 * largest)
        .ok()
        .filter(|theta| theta.iter().all(|v| v.is_finite()))
        .unwrap_or_else(|| DVector::zeros(q))
}

impl Stats {
    /// Accumulates the statistics of `cols` against `y` with a weight per
    /// residual entry (`6 k + channel`, 1 / standard deviation).
    pub fn build(
        cols: &[&[f64]],
        y: &[f64],
        weights: &[f64],
        seg_of: &[Option<usize>],
        nseg: usize,
    ) -> Self {
        let p = cols.len();
        let mut g = vec![DMatrix::zeros(p, p); nseg];
        let mut b = vec![DVector::zeros(p); nseg];
        let mut yy = vec![0.0; nseg];
        let mut entries = vec![0; nseg];
        let mut x = vec![0.0; p];
        for (k, seg) in seg_of.iter().enumerate() {
            let Some(s) = *seg else { continue };
            let gs = &mut g[s];
            let bs = &mut b[s];
            for c in 0..6 {
                let i = 6 * k + c;
                let w = weights[i];
                let yv = y[i] * w;
                let mut any = false;
                for (j, col) in cols.iter().enumerate() {
                    x[j] = col[i] * w;
                    any |= x[j] != 0.0;
                }
                yy[s] += yv * yv;
                entries[s] += 1;
                if !any {
                    continue;
                }
                for j in 0..p {
                    let xj = x[j];
                    if xj == 0.0 {
                        continue;
                    }
                    bs[j] += xj * yv;
                    for l in j..p {
                        gs[(j, l)] += xj * x[l];
                    }
                }
            }
        }
        for gs in &mut g {
            for j in 0..p {
                for l in 0..j {
                    gs[(j, l)] = gs[(l, j)];
                }
            }
        }
        Self {
            p,
            g,
            b,
            yy,
            entries,
            prior: DMatrix::zeros(p, p),
            bounds: vec![(f64::NEG_INFINITY, f64::INFINITY); p],
        }
    }

    /// The statistics with `y` replaced by `y - col` (a term with its
    /// coefficient fixed at 1), given the cross products of `col`.
    #[must_use]
    pub fn with_fixed_term(&self, cross: &[DVector<f64>], own: &[f64], own_y: &[f64]) -> Self {
        let mut out = self.clone();
        for s in 0..self.g.len() {
            out.yy[s] = self.yy[s] - 2.0 * own_y[s] + own[s];
            out.b[s] = &self.b[s] - &cross[s];
        }
        out
    }

    /// Number of segments.
    pub fn nseg(&self) -> usize {
        self.g.len()
    }

    /// Solves on the segments `use_seg` for the columns `idx`
    /// (ridge-stabilized) within the [`Stats::bounds`]: while a coefficient
    /// comes out beyond its bound, the farthest one (relative to its
    /// range's width, or its size for a one-sided range) is fixed at the
    /// bound and the rest solved again (at most one pass per column).
    pub fn solve(&self, idx: &[usize], use_seg: &dyn Fn(usize) -> bool) -> DVector<f64> {
        let mut fixed: Vec<Option<f64>> = vec![None; idx.len()];
        loop {
            let theta = self.solve_unconstrained(idx, &fixed, use_seg);
            let violation = |a: usize| {
                let (lo, hi) = self.bounds[idx[a]];
                let v = theta[a];
                let scale = if (hi - lo).is_finite() {
                    hi - lo
                } else {
                    v.abs().max(1e-300)
                };
                if v < lo {
                    Some(((lo - v) / scale, lo))
                } else if v > hi {
                    Some(((v - hi) / scale, hi))
                } else {
                    None
                }
            };
            let worst = (0..idx.len())
                .filter(|&a| fixed[a].is_none())
                .filter_map(|a| violation(a).map(|(d, b)| (a, d, b)))
                .max_by(|x, y| x.1.total_cmp(&y.1));
            match worst {
                Some((a, _, bound)) => fixed[a] = Some(bound),
                None => return theta,
            }
        }
    }

    /// The least-squares coefficients of the columns `all` with those of
    /// `fixed` held at their values.
    fn solve_unconstrained(
        &self,
        all: &[usize],
        fixed: &[Option<f64>],
        use_seg: &dyn Fn(usize) -> bool,
    ) -> DVector<f64> {
        let free: Vec<usize> = (0..all.len()).filter(|&a| fixed[a].is_none()).collect();
        let idx: Vec<usize> = free.iter().map(|&a| all[a]).collect();
        let held: Vec<(usize, f64)> = fixed
            .iter()
            .enumerate()
            .filter_map(|(a, v)| v.map(|v| (all[a], v)))
            .collect();
        let mut out = DVector::from_iterator(all.len(), fixed.iter().map(|v| v.unwrap_or(0.0)));
        let q = idx.len();
        if q == 0 {
            return out;
        }
        let mut g = DMatrix::zeros(q, q);
        let mut b = DVector::zeros(q);
        for s in 0..self.nseg() {
            if !use_seg(s) {
                continue;
            }
            for (a, &i) in idx.iter().enumerate() {
                b[a] += self.b[s][i];
                for (c, &j) in idx.iter().enumerate() {
                    g[(a, c)] += self.g[s][(i, j)];
                }
                for &(j, v) in &held {
                    b[a] -= self.g[s][(i, j)] * v;
                }
            }
        }
        for (a, &i) in idx.iter().enumerate() {
            for (c, &j) in idx.iter().enumerate() {
                g[(a, c)] += self.prior[(i, j)];
            }
            for &(j, v) in &held {
                b[a] -= self.prior[(i, j)] * v;
            }
        }
        let max_diag = (0..q).map(|a| g[(a, a)]).fold(0.0, f64::max).max(1e-300);
        for a in 0..q {
            g[(a, a)] += 1e-7 * max_diag + 1e-12;
        }
        for (pos, v) in bounded_solve(g, &b).iter().enumerate() {
            out[free[pos]] = *v;
        }
        out
    }

    /// Weighted squared error of `theta` (columns `idx`) on segment `s`.
    pub fn sse(&self, idx: &[usize], theta: &DVector<f64>, s: usize) -> f64 {
        let mut out = self.yy[s];
        for (a, &i) in idx.iter().enumerate() {
            out -= 2.0 * theta[a] * self.b[s][i];
            for (c, &j) in idx.iter().enumerate() {
                out += theta[a] * theta[c] * self.g[s][(i, j)];
            }
        }
        out
    }

    /// Held-out squared error: each fold predicted by a fit on the others,
    /// over the segments in `active`.
    pub fn cv(&self, idx: &[usize], active: &[bool]) -> f64 {
        let mut total = 0.0;
        for f in 0..FOLDS {
            let in_fold = |s: usize| active[s] && fold_of(s) == f;
            if !(0..self.nseg()).any(in_fold) {
                continue;
            }
            let theta = self.solve(idx, &|s| active[s] && fold_of(s) != f);
            for s in (0..self.nseg()).filter(|&s| in_fold(s)) {
                total += self.sse(idx, &theta, s);
            }
        }
        total
    }

    /// Residual entries in the active segments.
    pub fn entries_in(&self, active: &[bool]) -> usize {
        (0..self.nseg())
            .filter(|&s| active[s])
            .map(|s| self.entries[s])
            .sum()
    }
}

fn columns_of(layout: &Layout, set: &[Effect]) -> Vec<usize> {
    let mut idx = Vec::new();
    for e in set {
        idx.extend(layout.columns(*e));
    }
    idx
}

/// One step of the forward selection (for the report).
#[derive(Debug, Clone, serde::Serialize)]
pub struct Step {
    pub added: Effect,
    /// Held-out error before and after, noise-floor variances per entry.
    pub cv_before: f64,
    pub cv_after: f64,
}

/// Forward-backward selection over the active segments, all candidates
/// at once. (A two-stage selection, calibration candidates first and the
/// physics on top, was tried: on the independent generator's
/// centre-of-mass and drag + wind flights the calibration stage took thrust
/// scale, mass and inertia errors that the physics did not push out again,
/// and the result could not be replayed; the calibration is reported apart
/// instead, [`Effect::is_calibration`].)
pub fn select(
    stats: &Stats,
    layout: &Layout,
    candidates: &[Effect],
    active: &[bool],
) -> (Vec<Effect>, Vec<Step>) {
    select_from(stats, layout, candidates, &[], active)
}

/// Forward-backward selection among `candidates` starting from `base`.
fn select_from(
    stats: &Stats,
    layout: &Layout,
    candidates: &[Effect],
    base: &[Effect],
    active: &[bool],
) -> (Vec<Effect>, Vec<Step>) {
    let entries = stats.entries_in(active).max(1) as f64;
    let min_gain = MIN_GAIN * entries;
    let mut chosen: Vec<Effect> = base.to_vec();
    let mut steps = Vec::new();
    let mut current = stats.cv(&columns_of(layout, &chosen), active);
    loop {
        let mut best: Option<(Effect, f64)> = None;
        for &e in candidates {
            if chosen.contains(&e) {
                continue;
            }
            let mut set = chosen.clone();
            set.push(e);
            let cv = stats.cv(&columns_of(layout, &set), active);
            if best.is_none_or(|(_, b)| cv < b) {
                best = Some((e, cv));
            }
        }
        let Some((e, cv)) = best else { break };
        if current - cv < min_gain {
            break;
        }
        steps.push(Step {
            added: e,
            cv_before: current / entries,
            cv_after: cv / entries,
        });
        chosen.push(e);
        current = cv;
        // Backward: drop any effect the others now make unnecessary.
        loop {
            let mut dropped = false;
            for i in 0..chosen.len() {
                if chosen.len() < 2 {
                    break;
                }
                let mut set = chosen.clone();
                set.remove(i);
                let cv = stats.cv(&columns_of(layout, &set), active);
                if cv - current < min_gain {
                    chosen = set;
                    current = cv;
                    dropped = true;
                    break;
                }
            }
            if !dropped {
                break;
            }
        }
    }
    (chosen, steps)
}

/// Inclusion frequency of each candidate over random halves of the segments.
pub fn stability(
    stats: &Stats,
    layout: &Layout,
    candidates: &[Effect],
    seed: u64,
) -> Vec<(Effect, f64)> {
    let nseg = stats.nseg();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut counts = vec![0usize; candidates.len()];
    let mut order: Vec<usize> = (0..nseg).collect();
    for _ in 0..STABILITY_RUNS {
        order.shuffle(&mut rng);
        let mut active = vec![false; nseg];
        for &s in &order[..nseg.div_ceil(2)] {
            active[s] = true;
        }
        let (chosen, _) = select(stats, layout, candidates, &active);
        for (i, e) in candidates.iter().enumerate() {
            if chosen.contains(e) {
                counts[i] += 1;
            }
        }
    }
    candidates
        .iter()
        .zip(counts)
        .map(|(e, c)| (*e, c as f64 / STABILITY_RUNS as f64))
        .collect()
}

/// Coefficients on all data and their delete-a-segment jackknife
/// covariance, for the columns of `set`.
pub fn fit_with_uncertainty(
    stats: &Stats,
    layout: &Layout,
    set: &[Effect],
) -> (Vec<usize>, DVector<f64>, DMatrix<f64>) {
    fit_with_uncertainty_of(stats, columns_of(layout, set))
}

/// [`fit_with_uncertainty`] for the columns `idx`. The jackknife leaves out
/// one segment at a time (about 50 of them), not one of the [`FOLDS`]: five
/// replicates give a deviation with four degrees of freedom, which on the
/// plant's drag flights scattered by a factor of two between seeds.
pub fn fit_with_uncertainty_of(
    stats: &Stats,
    idx: Vec<usize>,
) -> (Vec<usize>, DVector<f64>, DMatrix<f64>) {
    let theta = stats.solve(&idx, &|_| true);
    let replicates: Vec<DVector<f64>> = (0..stats.nseg())
        .filter(|&d| stats.entries[d] > 0)
        .map(|d| stats.solve(&idx, &|s| s != d))
        .collect();
    let cov = jackknife_covariance(idx.len(), &replicates);
    (idx, theta, cov)
}

/// Delete-one jackknife covariance of `p` coefficients from their
/// replicates (`(k-1)/k sum (t_i - mean)(t_i - mean)^T`; zero with fewer
/// than two).
fn jackknife_covariance(p: usize, replicates: &[DVector<f64>]) -> DMatrix<f64> {
    let k = replicates.len() as f64;
    if k < 2.0 {
        return DMatrix::zeros(p, p);
    }
    let mean = replicates.iter().fold(DVector::zeros(p), |a, t| a + t) / k;
    let mut sum = DMatrix::zeros(p, p);
    for t in replicates {
        let d = t - &mean;
        sum += &d * d.transpose();
    }
    sum * ((k - 1.0) / k)
}

/// Standard deviations: the square roots of a covariance's diagonal.
pub fn deviations(cov: &DMatrix<f64>) -> DVector<f64> {
    cov.diagonal().map(|v| v.max(0.0).sqrt())
}

/// Columns of a set of effects.
pub fn columns_for(layout: &Layout, set: &[Effect]) -> Vec<usize> {
    columns_of(layout, set)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bounded_solve_solves_a_sound_system_and_refuses_absurd_ones() {
        let g = DMatrix::from_row_slice(2, 2, &[4.0, 1.0, 1.0, 3.0]);
        let b = DVector::from_row_slice(&[1.0, 2.0]);
        let theta = bounded_solve(g.clone(), &b);
        assert!((&g * &theta - &b).norm() < 1e-12, "{theta}");
        // Singular (Cholesky fails): the SVD's least-norm solution.
        let singular = DMatrix::from_row_slice(2, 2, &[1.0, 1.0, 1.0, 1.0]);
        let theta = bounded_solve(singular, &DVector::from_row_slice(&[2.0, 2.0]));
        assert!(
            (theta[0] - 1.0).abs() < 1e-9 && (theta[1] - 1.0).abs() < 1e-9,
            "{theta}"
        );
        // What one `vx = 1e100` cell makes of the normal equations: entries
        // of 1e200 next to ordinary ones, and overflow to inf or NaN.
        let huge = DMatrix::from_row_slice(2, 2, &[1e200, -1e200, -1e200, 1e-3]);
        let theta = bounded_solve(huge, &DVector::from_row_slice(&[1e100, 1.0]));
        assert!(theta.iter().all(|v| v.is_finite()), "{theta}");
        for bad in [f64::INFINITY, f64::NAN] {
            let g = DMatrix::from_row_slice(2, 2, &[bad, 0.0, 0.0, 1.0]);
            assert_eq!(bounded_solve(g, &b), DVector::zeros(2));
        }
    }
}
