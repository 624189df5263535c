//! Stage 3, select: the motor-lag time constant profiled by held-out
//! error, then forward-backward selection of the candidate effects in two
//! passes (the second with the fitted model's accelerations in the
//! mass-property columns and feasible-GLS weights), and the stability of
//! the choice over random halves of the segments (see [`crate::selection`]).

use nalgebra::DVector;

use crate::data::Prepared;
use crate::effects::{self, Columns, Effect, Knobs, Layout, build_columns, lag_column};
use crate::recording::Recording;
use crate::regions;
use crate::selection::{self, Stats, Step};
use crate::stages::Residuals;
use crate::stages::wind::WindProfile;

/// Motor-lag time constants of the profile (s): 4 ms x 1.4^i.
fn profile_taus() -> Vec<f64> {
    (0..12).map(|i| 0.004 * (1.4_f64).powi(i)).collect()
}

/// Every candidate but motor lag, at the nominal knobs: what the motor-lag
/// profile adds its column to.
#[derive(Debug, Clone)]
pub struct BaseRegressors {
    pub columns: Columns,
    /// Columns in `stats` (all but the motor-lag column).
    pub others: Vec<usize>,
    pub stats: Stats,
    /// Weight per residual entry (1 / noise floor).
    pub weights: Vec<f64>,
}

impl BaseRegressors {
    /// Builds the columns and their statistics.
    pub fn new(res: &Residuals, rec: &Recording) -> Self {
        let prep = &res.prep;
        let weights = res.floor_weights();
        let columns = build_columns(prep, rec, &Knobs::default(), &prep.nominal);
        let lag_c = columns.layout.columns(Effect::MotorLag).start;
        let others: Vec<usize> = (0..columns.layout.total).filter(|&c| c != lag_c).collect();
        let cols: Vec<&[f64]> = others.iter().map(|&c| columns.data[c].as_slice()).collect();
        let stats = Stats::build(&cols, &columns.resid, &weights, &res.seg_of, res.nseg);
        Self {
            columns,
            others,
            stats,
            weights,
        }
    }
}

/// Held-out error over the motor-lag time constant.
#[derive(Debug, Clone)]
pub struct LagProfile {
    /// (tau s, held-out squared error in noise-floor variances); tau 0 =
    /// no lag term.
    pub points: Vec<(f64, f64)>,
    /// The best time constant (parabolic refinement in log tau).
    pub tau: f64,
}

/// Profiles the motor-lag time constant: for each tau the lag column enters
/// with its coefficient fixed at 1, every other candidate free.
pub fn profile_motor_lag(res: &Residuals, base: &BaseRegressors) -> LagProfile {
    let prep = &res.prep;
    let (seg_of, nseg) = (&res.seg_of, res.nseg);
    let cols: Vec<&[f64]> = base
        .others
        .iter()
        .map(|&c| base.columns.data[c].as_slice())
        .collect();
    let all_idx: Vec<usize> = (0..base.others.len()).collect();
    let active = res.all_segments();
    let taus = profile_taus();
    let mut points = vec![(0.0, base.stats.cv(&all_idx, &active))];
    for &tau in &taus {
        let col = lag_column(prep, tau);
        // Cross products per segment in one flat buffer (segment-major).
        let p = cols.len();
        let mut flat = vec![0.0; nseg * p];
        let mut own = vec![0.0; nseg];
        let mut own_y = vec![0.0; nseg];
        for &k in &res.fit_rows {
            let Some(s) = seg_of[k] else { continue };
            let sums = &mut flat[s * p..(s + 1) * p];
            for c in 0..6 {
                let i = 6 * k + c;
                let w2 = base.weights[i] * base.weights[i];
                let l = col[i];
                if l == 0.0 {
                    continue;
                }
                own[s] += l * l * w2;
                own_y[s] += l * base.columns.resid[i] * w2;
                for (sum, cj) in sums.iter_mut().zip(&cols) {
                    *sum += l * cj[i] * w2;
                }
            }
        }
        let cross: Vec<DVector<f64>> = flat
            .chunks_exact(p.max(1))
            .map(DVector::from_column_slice)
            .collect();
        let st = base.stats.with_fixed_term(&cross, &own, &own_y);
        points.push((tau, st.cv(&all_idx, &active)));
    }
    let tau = best_tau(&points, taus[0]);
    LagProfile { points, tau }
}

/// The profile's minimum, refined by a parabola in log tau through its
/// neighbours; `smallest` when the minimum is at tau = 0.
fn best_tau(profile: &[(f64, f64)], smallest: f64) -> f64 {
    let best = profile
        .iter()
        .copied()
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .unwrap_or((0.0, 0.0));
    let mut tau_star = best.0;
    if let Some(i) = profile.iter().position(|p| p.0 == best.0)
        && i >= 2
        && i + 1 < profile.len()
    {
        let (x0, x1, x2) = (
            profile[i - 1].0.ln(),
            profile[i].0.ln(),
            profile[i + 1].0.ln(),
        );
        let (y0, y1, y2) = (profile[i - 1].1, profile[i].1, profile[i + 1].1);
        let d = (x0 - x1) * (x0 - x2) * (x1 - x2);
        let a = (x2 * (y1 - y0) + x1 * (y0 - y2) + x0 * (y2 - y1)) / d;
        let b = (x2 * x2 * (y0 - y1) + x1 * x1 * (y2 - y0) + x0 * x0 * (y1 - y2)) / d;
        if a > 0.0 {
            tau_star = (-b / (2.0 * a)).clamp(x0, x2).exp();
        }
    }
    if tau_star == 0.0 {
        tau_star = smallest;
    }
    tau_star
}

/// [`best_tau`] with the profile's smallest time constant, for the tests.
#[cfg(test)]
pub(crate) fn best_tau_for_test(profile: &[(f64, f64)]) -> f64 {
    best_tau(profile, profile.get(1).map_or(0.0, |p| p.0))
}

/// The selected effects and what they were selected on.
#[derive(Debug, Clone)]
pub struct Selection {
    pub layout: Layout,
    /// The regressors' nonlinear settings (tau and the wind from their
    /// profiles).
    pub knobs: Knobs,
    /// The wind's profile, when its optimum lies inside the search.
    pub wind: Option<WindProfile>,
    /// Filtered accelerations the mass-property columns use: the nominal
    /// model's, plus the pass-1 fit when anything was selected.
    pub accel: Vec<f64>,
    /// Weight per residual entry of the final pass.
    pub weights: Vec<f64>,
    pub columns: Columns,
    pub stats: Stats,
    /// Selected effects, in the order they were added.
    pub chosen: Vec<Effect>,
    pub steps: Vec<Step>,
    /// The effects the selection could choose: all but the wind when its
    /// profile identified no component.
    pub candidates: Vec<Effect>,
}

/// Selects among all candidates with the lag column at `tau`: pass 1 on
/// the nominal accelerations and floor weights, and, when it selected
/// anything, pass 2 on the pass-1 model's accelerations and weights.
pub fn select_effects(res: &Residuals, rec: &Recording, tau: f64) -> Selection {
    let prep = &res.prep;
    let active = res.all_segments();
    let mut knobs = Knobs {
        tau,
        wind: [0.0; 2],
    };
    let layout = Layout::all();
    let mut weights = res.floor_weights();
    // Two passes: the mass-property columns need the acceleration the
    // fitted model predicts (pass 1 uses the nominal model's).
    let mut accel = prep.nominal.clone();
    let mut columns = build_columns(prep, rec, &knobs, &accel);
    let mut stats = stats_of(&columns, &weights, &res.seg_of, res.nseg);
    // The drag candidate on the air-relative velocity, at the profiled
    // wind (stages::wind): the wind's columns at no wind carry only the
    // in-plane rotor drag's `k_r w`, and without the rest of the wind's
    // force other candidates took it.
    // The profile is the wind's test: a wind none of whose components it
    // identified is no wind, for the drag columns and for the selection,
    // which could otherwise claim one through the wind's linear columns
    // on the few percent a wind trims from any residual.
    let pre =
        crate::stages::wind::profile_wind(res, rec, tau, &layout, &columns.data, &stats, &weights);
    let wind = (pre.is_interior() && pre.identified.contains(&true)).then(|| {
        knobs.wind = pre.wind;
        columns = build_columns(prep, rec, &knobs, &accel);
        stats = stats_of(&columns, &weights, &res.seg_of, res.nseg);
        pre
    });
    let candidates: Vec<Effect> = Effect::ALL
        .into_iter()
        .filter(|e| wind.is_some() || *e != Effect::Wind)
        .collect();
    let (mut chosen, mut steps) = selection::select(&stats, &layout, &candidates, &active);
    if !chosen.is_empty() {
        let idx = selection::columns_for(&layout, &chosen);
        let theta = stats.solve(&idx, &|_| true);
        for k in 0..prep.n {
            if !prep.fit[k] {
                continue;
            }
            for c in 0..6 {
                let i = 6 * k + c;
                accel[i] += idx
                    .iter()
                    .enumerate()
                    .map(|(a, &j)| theta[a] * columns.data[j][i])
                    .sum::<f64>();
            }
        }
        weights = entry_weights(
            prep,
            &res.channel_weights,
            &columns,
            &idx,
            &theta,
            &res.fit_rows,
        );
        drop(columns);
        columns = build_columns(prep, rec, &knobs, &accel);
        stats = stats_of(&columns, &weights, &res.seg_of, res.nseg);
        (chosen, steps) = selection::select(&stats, &layout, &candidates, &active);
    }
    Selection {
        layout,
        knobs,
        wind,
        accel,
        weights,
        columns,
        stats,
        chosen,
        steps,
        candidates,
    }
}

impl Selection {
    /// Inclusion frequency of every effect over random halves of the
    /// segments (`seed` picks the halves); 0 for one that was no candidate.
    pub fn stability(&self, seed: u64) -> Vec<(Effect, f64)> {
        let mut out = selection::stability(&self.stats, &self.layout, &self.candidates, seed);
        out.extend(
            Effect::ALL
                .into_iter()
                .filter(|e| !self.candidates.contains(e))
                .map(|e| (e, 0.0)),
        );
        out
    }
}

/// Statistics of every column with the ground-effect smoothness prior.
pub(crate) fn stats_of(
    columns: &effects::Columns,
    weights: &[f64],
    seg_of: &[Option<usize>],
    nseg: usize,
) -> Stats {
    let cols: Vec<&[f64]> = columns.data.iter().map(Vec::as_slice).collect();
    let mut stats = Stats::build(&cols, &columns.resid, weights, seg_of, nseg);
    for e in Effect::ALL {
        let bounds = crate::stages::coefficient_bounds(e);
        for (j, b) in columns.layout.columns(e).zip(bounds) {
            stats.bounds[j] = b;
        }
    }
    let ge = columns.layout.columns(Effect::GroundEffect);
    let mut diag: Vec<f64> = ge
        .clone()
        .map(|c| stats.g.iter().map(|g| g[(c, c)]).sum::<f64>())
        .filter(|d| *d > 0.0)
        .collect();
    diag.sort_by(f64::total_cmp);
    let scale = diag.get(diag.len() / 2).copied().unwrap_or(0.0) * 1e-3;
    let prior = effects::ge_smoothness();
    for (a, i) in ge.clone().enumerate() {
        for (b, j) in ge.clone().enumerate() {
            stats.prior[(i, j)] = prior[a][b] * scale;
        }
    }
    stats
}

/// Least rows in a (height, tilt) cell for its own variance estimate.
const MIN_CELL_ROWS: usize = 50;

/// Weights per residual entry for the second selection pass (feasible
/// generalized least squares): 1 / noise floor of the channel, divided by
/// the RMS (in noise floors) that the pass-1 fit leaves in the row's
/// (height, tilt) cell when that exceeds 1.
///
/// Why: near the ground the rotor thrust is unsteady (the paper measures
/// strong fluctuation), so the residual there is noisier than the sensor
/// floor. In closed loop the controller answers those random torques, so
/// any regressor built from the flown commands correlates with them; left
/// at full weight they would let, for example, an inertia error "explain"
/// part of the noise. Down-weighting noisy cells (never up-weighting) keeps
/// the selection about the systematic part.
fn entry_weights(
    prep: &Prepared,
    channel_weights: &[f64; 6],
    columns: &effects::Columns,
    idx: &[usize],
    theta: &DVector<f64>,
    fit_rows: &[usize],
) -> Vec<f64> {
    let cell = |k: usize| {
        let e = &prep.env[k];
        let h = regions::HEIGHT_EDGES
            .windows(2)
            .position(|w| e.height >= w[0] && e.height < w[1]);
        let v = regions::VARPHI_EDGES
            .windows(2)
            .position(|w| e.varphi.to_degrees() >= w[0] && e.varphi.to_degrees() < w[1]);
        h.zip(v)
            .map(|(h, v)| h * (regions::VARPHI_EDGES.len() - 1) + v)
    };
    let cells = (regions::HEIGHT_EDGES.len() - 1) * (regions::VARPHI_EDGES.len() - 1);
    let mut sq = vec![[0.0; 6]; cells];
    let mut rows = vec![0usize; cells];
    for &k in fit_rows {
        let Some(c) = cell(k) else { continue };
        rows[c] += 1;
        for ch in 0..6 {
            let i = 6 * k + ch;
            let fitted: f64 = idx
                .iter()
                .enumerate()
                .map(|(a, &j)| theta[a] * columns.data[j][i])
                .sum();
            let r = (columns.resid[i] - fitted) * channel_weights[ch];
            sq[c][ch] += r * r;
        }
    }
    let mut weights: Vec<f64> = (0..6 * prep.n).map(|i| channel_weights[i % 6]).collect();
    for &k in fit_rows {
        let Some(c) = cell(k) else { continue };
        if rows[c] < MIN_CELL_ROWS {
            continue;
        }
        for ch in 0..6 {
            let rms = (sq[c][ch] / rows[c] as f64).sqrt();
            weights[6 * k + ch] /= rms.max(1.0);
        }
    }
    weights
}
