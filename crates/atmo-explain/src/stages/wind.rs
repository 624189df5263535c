//! The steady wind, profiled before the selection (part of stage 3).
//!
//! Drag acts on the velocity relative to the air, `v - w`. The rotor drag
//! is linear in it, so `k_r w` has linear columns; but the wind behind them
//! is `k_r w / k_r`, noise where the rotor drag is small (776 m/s was
//! printed on a real flight), and a wind that acts through the thrust lost
//! to axial inflow has no linear column at no wind at all. Selected at no
//! wind, a real wind's force was taken by the ground effect, the motor
//! lag, the inertia and the thrust scale (docs/explain.md). So the wind is
//! a nonlinear parameter, like the motor-lag time constant, profiled
//! before the selection:
//!
//! ```text
//! RSS(w) = min_theta |W_F (r - X_cal theta_c - X_drag(w) theta_d)|^2
//! ```
//!
//! - `X_drag(w)`: every drag column at the trial wind (rotor drag in the
//!   disc plane, thrust lost to axial inflow, quadratic body drag), their
//!   coefficients held inside their physical ranges. With the linear
//!   columns alone the wind of the plant's concealed drag + wind flight
//!   came out 6 % low: the body drag carries part of it there.
//! - `X_cal`: the calibration a flight always needs beside it (thrust scale
//!   and curve, the thrust axis: [`PROFILE_COMPANIONS`]). A constant
//!   sideways force is the thrust axis's, not a wind's.
//! - `W_F`: the force channels only. A steady wind acts through forces; the
//!   drag's torques hang on arm lengths and inertias that approximate robot
//!   files guess, and the differential rotor terms of a large trial wind
//!   then fit the torque model's errors.
//!
//! `RSS` is minimized on a polar grid (speeds to [`SEARCH_LIMIT`], past the
//! physical range, so that a fit at or beyond the bound is seen as such)
//! refined by a pattern search. The delete-a-fold jackknife of the wind
//! comes from the same profile restricted to the other folds, each
//! minimized on a local quadratic fit around the optimum (a fold whose
//! profile is not convex there gives an infinite deviation: not
//! identified). Each component is then tested alone: holding it at 0 (the
//! other profiled along its line) must cost [`MIN_AXIS_GAIN`] of the
//! residual left or of the wind's whole gain, whichever is smaller, and
//! its value must lie in its physical range; a component
//! that fails is held at 0 and the wind is the profile along the other
//! axis (a flight at one heading cannot tell a sideways wind from a
//! sideways thrust axis, and every fold agrees on that confusion). The
//! selection and the fit then build every drag column at the profiled
//! wind.

use nalgebra::{DMatrix, DVector, SMatrix, SVector};

use atmo_core::model::Input;

use crate::data::Prepared;
use crate::effects::{
    DRAG_WIDTH, DragColumns, Effect, Layout, WIND_AFFINE_DRAG, drag_columns_into,
};
use crate::recording::Recording;
use crate::selection::{self, FOLDS, Stats, fold_of};
use crate::stages::Residuals;

/// Most rows the profile uses (a long recording is profiled on evenly
/// spaced stretches of it: the wind is one steady vector).
const PROFILE_MAX_ROWS: usize = 15_000;
/// Rows of one such stretch.
const PROFILE_STRETCH_ROWS: usize = 1_500;
/// Largest trial wind speed (m/s): past the 15 m/s physical bound.
pub const SEARCH_LIMIT: f64 = 24.0;
/// The calibration profiled with the drag.
pub const PROFILE_COMPANIONS: [Effect; 3] =
    [Effect::ThrustScale, Effect::ThrustCurve, Effect::ThrustAxis];
/// Speeds of the coarse polar grid (m/s).
const COARSE_SPEED_STEP: f64 = 3.0;
/// Directions of the coarse polar grid.
const COARSE_DIRECTIONS: usize = 16;
/// First and last step of the pattern search (m/s).
const PATTERN_STEPS: (f64, f64) = (1.5, 0.005);
/// Directions of the two-dimensional pattern search (axes and diagonals).
const PATTERN_DIRECTIONS: [[f64; 2]; 8] = [
    [1.0, 0.0],
    [-1.0, 0.0],
    [0.0, 1.0],
    [0.0, -1.0],
    [1.0, 1.0],
    [1.0, -1.0],
    [-1.0, 1.0],
    [-1.0, -1.0],
];
/// Spacing of the local grid the jackknife's quadratics are fitted on (m/s).
const LOCAL_SPACING: f64 = 0.1;
/// Least share a wind component must gain ([`WindProfile::axis_gain`]) of
/// the smaller of two: the residual left at the optimum, and what the
/// wind as a whole gains. The selection's own least gain
/// ([`selection::MIN_GAIN`], in noise-floor variances) cannot judge this:
/// on a real flight the residual stays tens of noise floors, the model's
/// own errors, and a sideways wind trims them by a few percent whatever
/// the truth. A flight flown at one heading cannot tell a sideways wind
/// from a thrust axis turned sideways or from a drag law that is not quite
/// right, and every jackknife fold agrees on the same confusion: such a
/// confusion trims a few percent of the residual and of the wind's gain
/// alike, a real component at least a tenth of one of them. Against the
/// residual alone, a real but weak component (1 m/s beside 1.5 m/s with a
/// rotor drag of 0.02: 8 % of the residual, 26 % of the wind's gain) was
/// held at 0; against the wind's gain alone, a real cross wind under a
/// strong one would be. Measured (docs/explain.md, held-out table): on
/// the L1 and indi fan flights the sideways component gains at most 5.3 %
/// of the residual and 6.1 % of the wind's gain; the generator's real
/// components 19 % and more of one of them.
pub const MIN_AXIS_GAIN: f64 = 0.1;

/// The profiled wind.
#[derive(Debug, Clone)]
pub struct WindProfile {
    /// The wind of the least residual (NED x, y), m/s.
    pub wind: [f64; 2],
    /// Delete-a-fold jackknife deviation (infinite where a fold's profile
    /// has no minimum near the optimum).
    pub sd: [f64; 2],
    /// Residual sum of squares at the optimum and without wind (weighted).
    pub rss: f64,
    pub rss_no_wind: f64,
    /// What each component (x, y) of the two-dimensional optimum gains:
    /// the least residual with it held at 0 (the other profiled), less the
    /// residual at that optimum, relative to the smaller of that residual
    /// and the whole wind's gain. Below `MIN_AXIS_GAIN` the
    /// component is not identified, held at 0, and the wind is the profile
    /// along the other axis.
    pub axis_gain: [f64; 2],
    /// Whether each component is identified: its gain at least
    /// `MIN_AXIS_GAIN` and its value at the optimum inside its physical
    /// range. When exactly one is not, it is held at 0 and
    /// [`Self::wind`] is the profile along the other axis.
    pub identified: [bool; 2],
    /// Trial winds evaluated.
    pub evaluations: usize,
}

impl WindProfile {
    /// The optimum lies inside the search (not at its edge).
    pub fn is_interior(&self) -> bool {
        self.wind[0].hypot(self.wind[1]) < SEARCH_LIMIT - COARSE_SPEED_STEP / 2.0
    }
}

/// The selected effects' statistics with the drag columns rebuilt per
/// trial wind.
struct Profiler<'a> {
    prep: &'a Prepared,
    rec: &'a Recording,
    /// Rotor thrusts (commands lagged by the profiled motor lag).
    thrust: Vec<Input>,
    /// The stretches profiled, and the segment of each row used in them.
    stretches: Vec<(usize, usize)>,
    seg_of: Vec<Option<usize>>,
    fixed: Vec<&'a [f64]>,
    /// Bounds of the drag coefficients profiled.
    drag_bounds: [(f64, f64); DRAG_WIDTH],
    /// The fixed columns' statistics on the rows used.
    fixed_stats: Stats,
    resid: &'a [f64],
    weights: Vec<f64>,
    evaluations: usize,
    /// The drag columns before and after the filter, reused per trial
    /// wind (zeroed once: only the stretches' rows are ever written).
    drag: DragColumns,
    /// The [`WIND_AFFINE_DRAG`] columns, filtered, on the stretches' rows
    /// (in order): at no wind and their change per m/s of wind along x and
    /// y. The filter is linear, so a trial wind's columns are
    /// `at_rest + w_x per_x + w_y per_y`, without rebuilding or filtering
    /// them (two fifths of the filtering a trial wind took).
    affine: [[Vec<f64>; 3]; WIND_AFFINE_DRAG],
    /// Per segment, the fixed-by-drag cross products (`pf x DRAG_WIDTH`,
    /// row-major), summed here rather than in the segment's dense matrix:
    /// the same sums in the same order, without indexing it per entry.
    cross: Vec<f64>,
}

impl Profiler<'_> {
    /// Statistics of `[fixed, drag(wind)]`.
    fn stats_at(&mut self, wind: [f64; 2]) -> Stats {
        self.evaluations += 1;
        self.drag_columns_at(wind, WIND_AFFINE_DRAG);
        for (column, [at_rest, per_x, per_y]) in self.drag.out.iter_mut().zip(&self.affine) {
            for (o, i) in stretch_entries(&self.stretches).enumerate() {
                column[i] = at_rest[o] + wind[0] * per_x[o] + wind[1] * per_y[o];
            }
        }
        let drag = &self.drag.out;
        let pf = self.fixed.len();
        let p = pf + DRAG_WIDTH;
        let nseg = self.fixed_stats.nseg();
        let mut out = Stats {
            p,
            g: vec![DMatrix::zeros(p, p); nseg],
            b: vec![DVector::zeros(p); nseg],
            yy: self.fixed_stats.yy.clone(),
            entries: self.fixed_stats.entries.clone(),
            prior: DMatrix::zeros(p, p),
            bounds: self
                .fixed_stats
                .bounds
                .iter()
                .copied()
                .chain(self.drag_bounds)
                .collect(),
        };
        out.prior
            .view_mut((0, 0), (pf, pf))
            .copy_from(&self.fixed_stats.prior);
        for s in 0..nseg {
            out.g[s]
                .view_mut((0, 0), (pf, pf))
                .copy_from(&self.fixed_stats.g[s]);
            out.b[s].rows_mut(0, pf).copy_from(&self.fixed_stats.b[s]);
        }
        let mut xf = vec![0.0; pf];
        let block = pf * DRAG_WIDTH;
        self.cross.clear();
        self.cross.resize(nseg * block, 0.0);
        for (k, seg) in self.seg_of.iter().enumerate() {
            let Some(s) = *seg else { continue };
            let mut gdd = SMatrix::<f64, DRAG_WIDTH, DRAG_WIDTH>::zeros();
            let mut bd = SVector::<f64, DRAG_WIDTH>::zeros();
            let (g, b) = (&mut out.g[s], &mut out.b[s]);
            let cross = &mut self.cross[s * block..(s + 1) * block];
            for c in 0..6 {
                let i = 6 * k + c;
                let w = self.weights[i];
                let xd: [f64; DRAG_WIDTH] = std::array::from_fn(|m| drag[m][i] * w);
                if xd.iter().all(|v| *v == 0.0) {
                    continue;
                }
                for (j, col) in self.fixed.iter().enumerate() {
                    xf[j] = col[i] * w;
                }
                let y = self.resid[i] * w;
                for m in 0..DRAG_WIDTH {
                    bd[m] += xd[m] * y;
                    for l in m..DRAG_WIDTH {
                        gdd[(m, l)] += xd[m] * xd[l];
                    }
                }
                for (x, sums) in xf.iter().zip(cross.chunks_exact_mut(DRAG_WIDTH)) {
                    for (sum, d) in sums.iter_mut().zip(&xd) {
                        *sum += x * d;
                    }
                }
            }
            for m in 0..DRAG_WIDTH {
                b[pf + m] += bd[m];
                for l in m..DRAG_WIDTH {
                    g[(pf + m, pf + l)] += gdd[(m, l)];
                    g[(pf + l, pf + m)] = g[(pf + m, pf + l)];
                }
            }
        }
        for (g, cross) in out.g.iter_mut().zip(self.cross.chunks_exact(block.max(1))) {
            for (j, sums) in cross.chunks_exact(DRAG_WIDTH).enumerate() {
                for (m, sum) in sums.iter().enumerate() {
                    g[(j, pf + m)] = *sum;
                    g[(pf + m, j)] = *sum;
                }
            }
        }
        out
    }

    /// The drag columns at `wind` into [`Profiler::drag`], filtered from
    /// column `first_filtered` on.
    fn drag_columns_at(&mut self, wind: [f64; 2], first_filtered: usize) {
        drag_columns_into(
            self.prep,
            self.rec,
            &self.thrust,
            wind,
            &self.stretches,
            &mut self.drag,
            first_filtered,
        );
    }

    /// [`Profiler::affine`]: the affine columns at no wind and at 1 m/s
    /// along x and along y, differenced.
    fn affine_drag_bases(&mut self) -> [[Vec<f64>; 3]; WIND_AFFINE_DRAG] {
        let mut at = |wind: [f64; 2]| -> [Vec<f64>; WIND_AFFINE_DRAG] {
            self.drag_columns_at(wind, 0);
            std::array::from_fn(|j| {
                let column = &self.drag.out[j];
                stretch_entries(&self.stretches)
                    .map(|i| column[i])
                    .collect()
            })
        };
        let (rest, x, y) = (at([0.0, 0.0]), at([1.0, 0.0]), at([0.0, 1.0]));
        let minus =
            |a: &[f64], b: &[f64]| -> Vec<f64> { a.iter().zip(b).map(|(a, b)| a - b).collect() };
        let mut bases = rest.map(|at_rest| [at_rest, Vec::new(), Vec::new()]);
        for (j, [at_rest, per_x, per_y]) in bases.iter_mut().enumerate() {
            *per_x = minus(&x[j], at_rest);
            *per_y = minus(&y[j], at_rest);
        }
        bases
    }

    /// Residual sums of squares at `wind`: on all segments, and per fold
    /// on the other folds (fitted and scored there).
    fn rss(&mut self, wind: [f64; 2]) -> (f64, [f64; FOLDS]) {
        let stats = self.stats_at(wind);
        let all: Vec<usize> = (0..stats.p).collect();
        let score = |use_seg: &dyn Fn(usize) -> bool| {
            let theta = stats.solve(&all, use_seg);
            (0..stats.nseg())
                .filter(|&s| use_seg(s))
                .map(|s| stats.sse(&all, &theta, s))
                .sum::<f64>()
        };
        let total = score(&|_| true);
        let folds = std::array::from_fn(|f| score(&|s| fold_of(s) != f));
        (total, folds)
    }

    /// Pattern search from `start` (a wind and its residual) along
    /// `directions` (steps halving from [`PATTERN_STEPS`]`.0` to `.1`,
    /// within [`SEARCH_LIMIT`]): the least residual found and where.
    fn pattern_search(
        &mut self,
        start: ([f64; 2], f64),
        directions: &[[f64; 2]],
    ) -> ([f64; 2], f64) {
        let mut best = start;
        let mut step = PATTERN_STEPS.0;
        while step >= PATTERN_STEPS.1 {
            let mut moved = false;
            for d in directions {
                let w = [best.0[0] + step * d[0], best.0[1] + step * d[1]];
                if w[0].hypot(w[1]) > SEARCH_LIMIT {
                    continue;
                }
                let r = self.rss(w).0;
                if r < best.1 {
                    best = (w, r);
                    moved = true;
                }
            }
            if !moved {
                step *= 0.5;
            }
        }
        best
    }

    /// The least residual with component `axis` of the wind held at 0, over
    /// the other component (from `start` along it): that component and the
    /// residual.
    fn line_minimum(&mut self, axis: usize, start: f64) -> (f64, f64) {
        let mut from = [0.0; 2];
        from[1 - axis] = start;
        let mut along = [0.0; 2];
        along[1 - axis] = 1.0;
        let start = (from, self.rss(from).0);
        let (w, rss) = self.pattern_search(start, &[along, along.map(|v| -v)]);
        (w[1 - axis], rss)
    }
}

/// The residual entries (6 per row) of the stretches' rows, in order: the
/// layout of [`Profiler::affine`].
fn stretch_entries(stretches: &[(usize, usize)]) -> impl Iterator<Item = usize> + '_ {
    stretches.iter().flat_map(|&(s, e)| 6 * s..6 * e)
}

/// Profiles the wind with the linear drag and [`PROFILE_COMPANIONS`],
/// given the columns and statistics built at no wind.
pub fn profile_wind(
    res: &Residuals,
    rec: &Recording,
    tau: f64,
    layout: &Layout,
    columns: &[Vec<f64>],
    stats: &Stats,
    weights: &[f64],
) -> WindProfile {
    let (prep, seg_of) = (&res.prep, res.seg_of.as_slice());
    let rest = PROFILE_COMPANIONS;
    let fixed_idx = selection::columns_for(layout, &rest);
    let weights: Vec<f64> = weights
        .iter()
        .enumerate()
        .map(|(i, w)| if i % 6 < 3 { *w } else { 0.0 })
        .collect();
    let (stretches, seg_of) = stretches(prep, seg_of);
    let fixed: Vec<&[f64]> = fixed_idx.iter().map(|&j| columns[j].as_slice()).collect();
    let mut fixed_stats = Stats::build(&fixed, &prep.resid, &weights, &seg_of, stats.nseg());
    fixed_stats.prior = stats
        .prior
        .select_rows(&fixed_idx)
        .select_columns(&fixed_idx);
    fixed_stats.bounds = fixed_idx.iter().map(|&j| stats.bounds[j]).collect();
    let drag = layout.columns(Effect::Drag).start;
    let drag_bounds = std::array::from_fn(|m| stats.bounds[drag + m]);
    let mut prof = Profiler {
        prep,
        rec,
        thrust: crate::data::lagged_commands(&prep.t, &prep.u_eff, tau),
        stretches,
        seg_of,
        fixed,
        drag_bounds,
        fixed_stats,
        resid: &prep.resid,
        weights,
        evaluations: 0,
        drag: DragColumns::zeroed(prep.n),
        affine: Default::default(),
        cross: Vec::new(),
    };
    prof.affine = prof.affine_drag_bases();
    // Coarse polar grid.
    let rss_no_wind = prof.rss([0.0; 2]).0;
    let mut best = ([0.0; 2], rss_no_wind);
    let mut speed = COARSE_SPEED_STEP;
    while speed <= SEARCH_LIMIT + 1e-9 {
        for d in 0..COARSE_DIRECTIONS {
            let a = std::f64::consts::TAU * d as f64 / COARSE_DIRECTIONS as f64;
            let w = [speed * a.cos(), speed * a.sin()];
            let r = prof.rss(w).0;
            if r < best.1 {
                best = (w, r);
            }
        }
        speed += COARSE_SPEED_STEP;
    }
    let mut best = prof.pattern_search(best, &PATTERN_DIRECTIONS);
    // Each component's gain: the profile along the other with it held at 0.
    // That line passes through no wind, so neither gains more than the wind
    // as a whole: below the least gain, neither is identified, and the
    // lines need not be searched.
    let relative = |rss: f64| (rss - best.1).max(0.0) / best.1.max(f64::MIN_POSITIVE);
    let whole_wind_counts = relative(rss_no_wind) >= MIN_AXIS_GAIN;
    let held: [(f64, f64); 2] = if whole_wind_counts {
        std::array::from_fn(|axis| prof.line_minimum(axis, best.0[1 - axis]))
    } else {
        [(0.0, rss_no_wind); 2]
    };
    // Against the smaller of the residual left and the wind's whole gain
    // (a wind that does not count as a whole leaves no component).
    let scale = best.1.min(rss_no_wind - best.1).max(f64::MIN_POSITIVE);
    let axis_gain = held.map(|(_, rss)| {
        if whole_wind_counts {
            (rss - best.1).max(0.0) / scale
        } else {
            relative(rss)
        }
    });
    // A component beyond its physical range is not identified either (the
    // finder's rule for every parameter).
    let identified: [bool; 2] = std::array::from_fn(|axis| {
        let (lo, hi) =
            crate::parameter::Param::SteadyWind(crate::parameter::Axis::XY[axis]).range();
        axis_gain[axis] >= MIN_AXIS_GAIN && (lo..=hi).contains(&best.0[axis])
    });
    // One component not identified: it is held at 0 and the wind is the
    // profile along the other axis.
    let free = match identified {
        [true, false] => {
            best = ([held[1].0, 0.0], held[1].1);
            Some(0)
        }
        [false, true] => {
            best = ([0.0, held[0].0], held[0].1);
            Some(1)
        }
        _ => None,
    };
    // Jackknife: each fold's profile on a local grid (5 x 5, or 5 points
    // along the free axis), its quadratic's minimum.
    let offsets: Vec<[f64; 2]> = match free {
        None => (-2..=2)
            .flat_map(|i| (-2..=2).map(move |j| [f64::from(i), f64::from(j)]))
            .map(|d| d.map(|v| LOCAL_SPACING * v))
            .collect(),
        Some(axis) => (-2..=2)
            .map(|i| {
                let mut d = [0.0; 2];
                d[axis] = LOCAL_SPACING * f64::from(i);
                d
            })
            .collect(),
    };
    let points: Vec<([f64; 2], [f64; FOLDS])> = offsets
        .iter()
        .map(|d| (*d, prof.rss([best.0[0] + d[0], best.0[1] + d[1]]).1))
        .collect();
    let fold_winds: Vec<Option<[f64; 2]>> = (0..FOLDS)
        .map(|f| {
            let pts: Vec<([f64; 2], f64)> = points.iter().map(|(d, r)| (*d, r[f])).collect();
            let d = match free {
                None => quadratic_minimum(&pts),
                Some(axis) => line_quadratic_minimum(&pts, axis),
            };
            d.map(|d| [best.0[0] + d[0], best.0[1] + d[1]])
        })
        .collect();
    let mut sd = jackknife_sd(&fold_winds);
    // A component not identified has no deviation to report.
    for axis in 0..2 {
        if !identified[axis] {
            sd[axis] = f64::INFINITY;
        }
    }
    WindProfile {
        wind: best.0,
        sd,
        rss: best.1,
        rss_no_wind,
        axis_gain,
        identified,
        evaluations: prof.evaluations,
    }
}

/// The stretches of the runs the profile uses and the segment of each row
/// in them: every run up to [`PROFILE_MAX_ROWS`] rows in all; past that,
/// evenly spaced stretches of [`PROFILE_STRETCH_ROWS`], each row at least
/// the filter's half window from a stretch's ends (where its filtered
/// columns equal the whole run's).
fn stretches(
    prep: &Prepared,
    seg_of: &[Option<usize>],
) -> (Vec<(usize, usize)>, Vec<Option<usize>>) {
    let total: usize = prep.runs.iter().map(|(s, e)| e - s).sum();
    if total <= PROFILE_MAX_ROWS {
        return (prep.runs.clone(), seg_of.to_vec());
    }
    let pieces: Vec<(usize, usize)> = prep
        .runs
        .iter()
        .flat_map(|&(s, e)| {
            (s..e)
                .step_by(PROFILE_STRETCH_ROWS)
                .map(move |a| (a, (a + PROFILE_STRETCH_ROWS).min(e)))
        })
        .filter(|(a, b)| b - a > 2 * prep.half + 1)
        .collect();
    let keep = (pieces.len() * PROFILE_STRETCH_ROWS)
        .div_ceil(PROFILE_MAX_ROWS)
        .max(1);
    let chosen: Vec<(usize, usize)> = pieces.into_iter().step_by(keep).collect();
    let mut used = vec![None; seg_of.len()];
    for &(a, b) in &chosen {
        let inner = a + prep.half..b - prep.half;
        used[inner.clone()].copy_from_slice(&seg_of[inner]);
    }
    (chosen, used)
}

/// The minimum of the least-squares quadratic through `(d, r)` points, if
/// the quadratic is convex.
fn quadratic_minimum(points: &[([f64; 2], f64)]) -> Option<[f64; 2]> {
    let n = points.len();
    let x = DMatrix::from_fn(n, 6, |i, j| {
        let [a, b] = points[i].0;
        [1.0, a, b, a * a, a * b, b * b][j]
    });
    let y = DVector::from_iterator(n, points.iter().map(|p| p.1));
    let c = (x.transpose() * &x).cholesky()?.solve(&(x.transpose() * y));
    // r = c0 + c1 a + c2 b + c3 a^2 + c4 ab + c5 b^2: gradient 0 at H d = -g.
    let h = nalgebra::Matrix2::new(2.0 * c[3], c[4], c[4], 2.0 * c[5]);
    if h[(0, 0)] <= 0.0 || h.determinant() <= 0.0 {
        return None;
    }
    let d = h.try_inverse()? * nalgebra::Vector2::new(-c[1], -c[2]);
    d.iter().all(|v| v.is_finite()).then(|| [d[0], d[1]])
}

/// The minimum of the least-squares parabola through `(d, r)` points that
/// differ along `axis` only, if it is convex.
fn line_quadratic_minimum(points: &[([f64; 2], f64)], axis: usize) -> Option<[f64; 2]> {
    let n = points.len();
    let x = DMatrix::from_fn(n, 3, |i, j| points[i].0[axis].powi(j as i32));
    let y = DVector::from_iterator(n, points.iter().map(|p| p.1));
    let c = (x.transpose() * &x).cholesky()?.solve(&(x.transpose() * y));
    if c[2] <= 0.0 {
        return None;
    }
    let mut d = [0.0; 2];
    d[axis] = -c[1] / (2.0 * c[2]);
    d[axis].is_finite().then_some(d)
}

/// Delete-a-fold jackknife deviation of the fold estimates (infinite if any
/// fold has none).
fn jackknife_sd(folds: &[Option<[f64; 2]>]) -> [f64; 2] {
    let Some(w): Option<Vec<[f64; 2]>> = folds.iter().copied().collect() else {
        return [f64::INFINITY; 2];
    };
    let k = w.len() as f64;
    if k < 2.0 {
        return [f64::INFINITY; 2];
    }
    std::array::from_fn(|j| {
        let mean = w.iter().map(|x| x[j]).sum::<f64>() / k;
        ((k - 1.0) / k * w.iter().map(|x| (x[j] - mean).powi(2)).sum::<f64>()).sqrt()
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_quadratic_minimum_of_a_bowl_is_its_centre_and_a_saddle_has_none() {
        let bowl: Vec<([f64; 2], f64)> = (-2..=2)
            .flat_map(|i| (-2..=2).map(move |j| [0.5 * f64::from(i), 0.5 * f64::from(j)]))
            .map(|d| (d, 3.0 + 2.0 * (d[0] - 0.3).powi(2) + (d[1] + 0.7).powi(2)))
            .collect();
        let m = quadratic_minimum(&bowl).expect("a bowl has a minimum");
        assert!(
            (m[0] - 0.3).abs() < 1e-9 && (m[1] + 0.7).abs() < 1e-9,
            "{m:?}"
        );
        let saddle: Vec<([f64; 2], f64)> = bowl
            .iter()
            .map(|(d, _)| (*d, d[0] * d[0] - d[1] * d[1]))
            .collect();
        assert!(quadratic_minimum(&saddle).is_none());
    }

    #[test]
    fn the_parabola_along_an_axis_has_its_vertex_and_a_cap_has_none() {
        let line: Vec<([f64; 2], f64)> = (-2..=2)
            .map(|i| [0.0, 0.1 * f64::from(i)])
            .map(|d| (d, 5.0 + 3.0 * (d[1] - 0.04).powi(2)))
            .collect();
        let m = line_quadratic_minimum(&line, 1).expect("a parabola has a vertex");
        assert!(m[0] == 0.0 && (m[1] - 0.04).abs() < 1e-9, "{m:?}");
        let cap: Vec<([f64; 2], f64)> = line.iter().map(|(d, r)| (*d, -r)).collect();
        assert!(line_quadratic_minimum(&cap, 1).is_none());
    }

    #[test]
    fn a_fold_without_a_minimum_makes_the_deviation_infinite() {
        let sd = jackknife_sd(&[Some([1.0, 2.0]), None, Some([1.0, 2.0])]);
        assert!(sd.iter().all(|s| s.is_infinite()));
        let sd = jackknife_sd(&[Some([1.0, 0.0]), Some([3.0, 0.0])]);
        assert!((sd[0] - 1.0).abs() < 1e-12 && sd[1] == 0.0, "{sd:?}");
    }
}
