//! Stage 4, fit: the selected effects' coefficients on all data, their
//! delete-a-segment jackknife covariance and the per-fold fits (for
//! held-out predictions), at the wind profiled before the selection
//! ([`super::wind`]).

use nalgebra::{DMatrix, DVector};

use crate::effects::{Columns, Effect, Knobs, Layout, build_columns};
use crate::physical::Physical;
use crate::recording::Recording;
use crate::selection::{self, Stats, fold_of};
use crate::stages::select::stats_of;
use crate::stages::wind::WindProfile;
use crate::stages::{Residuals, Selection};

/// Gauss-Newton steps of the wind on the rotor-drag columns when no wind
/// was profiled.
const WIND_REFINEMENTS: usize = 3;

/// Share of what an effect explains that another must recover, swapped
/// in for it, for the data to be unable to tell them apart.
pub const SWAP_RECOVERY: f64 = 0.9;

/// The fitted model.
#[derive(Debug, Clone)]
pub struct Fit {
    pub layout: Layout,
    /// The effects in the model (drag added when wind was selected), sorted.
    pub chosen: Vec<Effect>,
    /// Regressor settings: motor-lag tau and the profiled wind.
    pub knobs: Knobs,
    /// The wind's profile (before the selection), when wind was selected
    /// at it: the wind is the knob, not a linear coefficient (its columns
    /// stay out of the fit).
    pub wind: Option<WindProfile>,
    pub columns: Columns,
    pub stats: Stats,
    /// Columns of `chosen`, their coefficients on all data and their
    /// jackknife covariance.
    pub idx: Vec<usize>,
    pub theta: DVector<f64>,
    pub cov: DMatrix<f64>,
    /// Coefficients fitted without each fold (`selection::FOLDS` of them).
    pub fold_theta: Vec<DVector<f64>>,
    /// Physical parameters of the fit on all data (wind included).
    pub(crate) physical: Physical,
}

impl Fit {
    /// Physical parameters of the fit without fold `f`, the wind knob
    /// included.
    pub(crate) fn fold_physical(&self, f: usize) -> Physical {
        let mut p = Physical::from_theta(
            &self.layout,
            &self.chosen,
            &self.idx,
            &self.fold_theta[f],
            self.knobs.tau,
        );
        if let Some(w) = p.wind.as_mut() {
            w[0] += self.knobs.wind[0];
            w[1] += self.knobs.wind[1];
        }
        p
    }

    /// Jackknife standard deviations of `theta`.
    pub fn sd(&self) -> DVector<f64> {
        selection::deviations(&self.cov)
    }

    /// The fit redone with the effects `kept` only (same regressors and
    /// knobs).
    pub fn restrict(&mut self, kept: &[Effect]) {
        let mut chosen = kept.to_vec();
        chosen.sort();
        if !chosen.contains(&Effect::Wind) {
            self.wind = None;
        }
        let (idx, theta, cov) =
            selection::fit_with_uncertainty_of(&self.stats, self.columns_of(&chosen));
        let mut physical =
            Physical::from_theta(&self.layout, &chosen, &idx, &theta, self.knobs.tau);
        if let Some(w) = physical.wind.as_mut() {
            w[0] += self.knobs.wind[0];
            w[1] += self.knobs.wind[1];
        }
        self.fold_theta = (0..selection::FOLDS)
            .map(|f| self.stats.solve(&idx, &|s| fold_of(s) != f))
            .collect();
        self.chosen = chosen;
        self.idx = idx;
        self.theta = theta;
        self.cov = cov;
        self.physical = physical;
    }

    /// The effects outside the model that the data cannot tell apart from
    /// its effect `e`: swapping `e` for one of them recovers at least
    /// `SWAP_RECOVERY` of what `e` explains of the cross-validated
    /// residual. The best swap first.
    pub fn swaps_for(&self, e: Effect) -> Vec<Effect> {
        self.swaps_with_recovery(e, |_| true)
            .into_iter()
            .map(|(f, _)| f)
            .collect()
    }

    /// [`Fit::swaps_for`] among the effects `among` admits, each with the
    /// share of `e`'s cross-validated gain it recovers.
    pub fn swaps_with_recovery(
        &self,
        e: Effect,
        among: impl Fn(Effect) -> bool,
    ) -> Vec<(Effect, f64)> {
        if !self.chosen.contains(&e) {
            return Vec::new();
        }
        let active = vec![true; self.stats.nseg()];
        let cv = |set: &[Effect]| self.stats.cv(&self.columns_of(set), &active);
        let with = self.stats.cv(&self.idx, &active);
        let rest: Vec<Effect> = self.chosen.iter().copied().filter(|x| *x != e).collect();
        let without = cv(&rest);
        if without - with <= 0.0 {
            return Vec::new();
        }
        let mut swaps: Vec<(Effect, f64)> = Effect::ALL
            .iter()
            .copied()
            .filter(|&f| !self.chosen.contains(&f) && among(f))
            .map(|f| {
                let mut swapped = rest.clone();
                swapped.push(f);
                (f, (without - cv(&swapped)) / (without - with))
            })
            .filter(|(_, recovery)| *recovery >= SWAP_RECOVERY)
            .collect();
        swaps.sort_by(|a, b| b.1.total_cmp(&a.1));
        swaps
    }

    /// The fit's columns of the effects `set`: the wind, when profiled, is
    /// the knob and has none.
    pub fn columns_of(&self, set: &[Effect]) -> Vec<usize> {
        model_columns(&self.layout, set, self.wind.is_some())
    }

    /// The held-out prediction of the fitted effects: entry `i` of the
    /// residual predicted by the fit on the folds other than row `k`'s.
    pub fn heldout_residual(&self, res: &Residuals) -> Vec<f64> {
        let mut after = self.columns.resid.clone();
        for &k in &res.fit_rows {
            let Some(s) = res.seg_of[k] else { continue };
            let th = &self.fold_theta[fold_of(s)];
            for c in 0..6 {
                let i = 6 * k + c;
                let mut pred = 0.0;
                for (a, &j) in self.idx.iter().enumerate() {
                    pred += th[a] * self.columns.data[j][i];
                }
                after[i] -= pred;
            }
        }
        after
    }

    /// The residual this model leaves on a recording it was not fitted on
    /// (`res` of `rec`): the regressors at the fit's knobs, built as the
    /// selection builds them, once on the nominal accelerations and again
    /// on the model's (the mass-property columns need the model's
    /// acceleration), times the coefficients fitted on all data. Battery
    /// sag's energy counts from `rec`'s start.
    pub fn residual_on_unseen(&self, res: &Residuals, rec: &Recording) -> Vec<f64> {
        let prep = &res.prep;
        let predict = |data: &[Vec<f64>], i: usize| -> f64 {
            self.idx
                .iter()
                .enumerate()
                .map(|(a, &j)| self.theta[a] * data[j][i])
                .sum()
        };
        let mut accel = prep.nominal.clone();
        let columns = build_columns(prep, rec, &self.knobs, &accel);
        for (i, a) in accel.iter_mut().enumerate() {
            *a += predict(&columns.data, i);
        }
        drop(columns);
        let columns = build_columns(prep, rec, &self.knobs, &accel);
        let mut after = columns.resid.clone();
        for (i, r) in after.iter_mut().enumerate() {
            *r -= predict(&columns.data, i);
        }
        after
    }
}

/// Fits the selected effects.
pub fn fit_effects(res: &Residuals, rec: &Recording, sel: Selection) -> Fit {
    let Selection {
        layout,
        mut knobs,
        accel,
        weights,
        mut columns,
        mut stats,
        mut chosen,
        wind: wind_profile,
        ..
    } = sel;
    let prep = &res.prep;
    // Wind is defined relative to drag, and drag at a wind claims it.
    if chosen.contains(&Effect::Wind) && !chosen.contains(&Effect::Drag) {
        chosen.push(Effect::Drag);
    }
    if chosen.contains(&Effect::Drag) && !chosen.contains(&Effect::Wind) && knobs.wind != [0.0; 2] {
        chosen.push(Effect::Wind);
    }
    chosen.sort();
    // The wind profiled before the selection is the wind of the fit (its
    // drag columns were built at it). Without one, the rotor drag's linear
    // wind columns are fed back (Gauss-Newton on `k_r w`).
    let wind = if chosen.contains(&Effect::Wind) {
        if wind_profile.is_none() {
            for _ in 0..WIND_REFINEMENTS {
                let idx = selection::columns_for(&layout, &chosen);
                let theta = stats.solve(&idx, &|_| true);
                let phys = Physical::from_theta(&layout, &chosen, &idx, &theta, knobs.tau);
                let w = phys.wind.unwrap_or([0.0; 2]);
                let kr = phys.drag.map_or(0.0, |d| d[0]);
                if kr <= 1e-3 {
                    break;
                }
                knobs.wind = [knobs.wind[0] + w[0], knobs.wind[1] + w[1]];
                drop(columns);
                columns = build_columns(prep, rec, &knobs, &accel);
                stats = stats_of(&columns, &weights, &res.seg_of, res.nseg);
            }
        }
        wind_profile
    } else {
        None
    };
    let idx = model_columns(&layout, &chosen, wind.is_some());
    let (idx, theta, cov) = selection::fit_with_uncertainty_of(&stats, idx);
    let mut physical = Physical::from_theta(&layout, &chosen, &idx, &theta, knobs.tau);
    if let Some(w) = physical.wind.as_mut() {
        w[0] += knobs.wind[0];
        w[1] += knobs.wind[1];
    }
    let fold_theta = (0..selection::FOLDS)
        .map(|f| stats.solve(&idx, &|s| fold_of(s) != f))
        .collect();
    Fit {
        layout,
        chosen,
        knobs,
        wind,
        columns,
        stats,
        idx,
        theta,
        cov,
        fold_theta,
        physical,
    }
}

/// Columns of the effects `set`, without the wind's when it is profiled.
fn model_columns(layout: &Layout, set: &[Effect], wind_profiled: bool) -> Vec<usize> {
    let set: Vec<Effect> = set
        .iter()
        .copied()
        .filter(|e| !(wind_profiled && *e == Effect::Wind))
        .collect();
    selection::columns_for(layout, &set)
}
