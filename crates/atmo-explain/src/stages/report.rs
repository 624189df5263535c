//! Stage 6, report: every candidate's verdict with its parameters,
//! held-out gain and the effects it cannot be told apart from; the
//! ground-effect gain grid; the verdict; the time series to plot; the
//! notes on how far the results can be trusted. Assembled into the
//! [`Explanation`].

use atmo_core::ground_effect::table::GroundEffect;

use crate::data::CHANNELS;
use crate::effects::{self, Effect};
use crate::explanation::{
    CombinedFinding, EffectReport, Explanation, GridPoint, Parameter, Series, WindSpeed,
};
use crate::parameter::{Axis, Param};
use crate::physical::{BATTERY_CAPACITY_WH, BATTERY_FULL_POWER_W};
use crate::recording::Recording;
use crate::selection::{self, Step};
use crate::stages::{Decision, Fit, LagProfile, Mismatch, Residuals, Validation};
use crate::{GRID_HEIGHTS, GRID_TILTS_DEG, HIGH_CONFIDENCE};

/// Least |correlation| of two parameters' estimates at which they are
/// reported as one combined finding: a variance inflation of
/// `1 / (1 - 0.9^2)` = 5.3, the usual threshold for a pair a regression
/// cannot separate. The generator's axial drag and vertical area (-0.5 to
/// -0.6) stay apart; on the fan flights they correlate -0.86 to -0.97.
pub const COMBINED_CORRELATION: f64 = 0.9;

/// A parameter whose deviation is below this share of its physical range
/// is pinned down whatever it correlates with: the trade the correlation
/// describes moves it by less than a thousandth of what is possible, so a
/// pair of such parameters is two findings, not one combined. Chosen on
/// the generator's second form (a centre-of-mass offset known to 0.003 mm,
/// its two components correlating -0.91) and the L1 and indi flights
/// (combined pairs at 0.004-0.12 of their ranges); checked on the NF-C
/// flights and the generator's first form (docs/explain.md, held-out
/// table).
pub const COMBINED_RESOLUTION: f64 = 1e-3;

/// What the analysis found, stage by stage, before it is reported: what
/// [`report()`] is made of, and what a tool that scores the fitted model
/// on other data reads (`examples/neural_fly_fa`).
pub struct Analysis {
    /// The recording analysed: the reader contract's screening applied and
    /// the velocity's band below 3 Hz taken from the positions.
    pub rec: Recording,
    pub velocity_correction: crate::velocity::VelocityCorrection,
    /// The robot the replays ran: its tilt range cut to the tilts flown.
    pub replayed: atmo_core::RobotConfig,
    pub res: Residuals,
    pub mismatch: Mismatch,
    pub lag: LagProfile,
    pub steps: Vec<Step>,
    pub confidence: Vec<(Effect, f64)>,
    pub fit: Fit,
    /// The acceptance stage's decision on each effect the selection chose.
    pub decisions: Vec<(Effect, Decision)>,
    pub validation: Validation,
}

/// Candidates' verdicts, sorted (claimed first; then by confidence, by
/// selection frequency and by held-out gain), and the pairs of effects the
/// data cannot tell apart.
pub fn effect_reports(
    fit: &Fit,
    confidence: &[(Effect, f64)],
    decisions: &[(Effect, Decision)],
) -> (Vec<EffectReport>, Vec<(Effect, Effect)>) {
    let active = vec![true; fit.stats.nseg()];
    let (stats, chosen) = (&fit.stats, &fit.chosen);
    let cv = |set: &[Effect]| stats.cv(&fit.columns_of(set), &active);
    let entries = stats.entries_in(&active).max(1) as f64;
    let cv_sel = stats.cv(&fit.idx, &active);
    let mut reports = Vec::new();
    let mut pairs: Vec<(Effect, Effect)> = Vec::new();
    for &e in &Effect::ALL {
        let selected = chosen.contains(&e);
        // A profiled wind is the knob of the drag's columns: one finding
        // with the drag, whose inclusion frequency is its confidence.
        let of = if e == Effect::Wind && fit.wind.is_some() {
            Effect::Drag
        } else {
            e
        };
        // A confidence is what a claim carries; an effect not claimed
        // carries its decision instead.
        let frequency = confidence.iter().find(|c| c.0 == of).map(|c| c.1);
        let conf = frequency.filter(|_| selected);
        let decision = decisions.iter().find(|d| d.0 == e).map(|d| d.1.clone());
        let gain = if selected {
            let rest: Vec<Effect> = chosen.iter().copied().filter(|x| *x != e).collect();
            (cv(&rest) - cv_sel) / entries
        } else {
            let mut more = chosen.clone();
            more.push(e);
            (cv_sel - cv(&more)) / entries
        };
        let indist: Vec<Effect> = fit.swaps_for(e);
        pairs.extend(indist.iter().map(|&f| (e, f)));
        let decided_by = decisions.iter().find(|d| d.0 == e).map_or_else(
            || {
                "not selected: adding it lowers the held-out residual by less than the threshold"
                    .into()
            },
            |d| d.1.describe(),
        );
        // A rejected effect's parameters are those of the fit it was
        // rejected from (what it would have claimed).
        reports.push(EffectReport {
            name: e,
            physics: e.physics().into(),
            decided_by,
            calibration: e.is_calibration(),
            selected,
            confidence: conf,
            // Not computed (no stability run) reads as never proposed.
            selection_frequency: frequency.unwrap_or(0.0),
            decision,
            heldout_gain: gain,
            parameters: effect_parameters(fit, e, selected)
                .into_iter()
                .map(|mut p| {
                    p.identified =
                        crate::stages::param_status(p.value, p.std, Some(p.name.range()))
                            == crate::stages::ParamStatus::Identified;
                    p
                })
                .collect(),
            indistinguishable_from: indist,
            same_finding_as: Vec::new(),
            combined: Vec::new(),
        });
    }
    link_physics_and_calibration(fit, decisions, &mut reports);
    combine_inseparable(fit, &mut reports);
    reports.sort_by(|a, b| {
        b.selected
            .cmp(&a.selected)
            .then(
                b.confidence
                    .unwrap_or(-1.0)
                    .total_cmp(&a.confidence.unwrap_or(-1.0)),
            )
            .then(b.selection_frequency.total_cmp(&a.selection_frequency))
            .then(b.heldout_gain.total_cmp(&a.heldout_gain))
    });
    (reports, pairs)
}

/// Physics and a claimed calibration that explain the same thing are one
/// finding (the selection's swap test either way, or the acceptance's
/// [`Decision::OneFindingWith`]): each names the other in
/// `same_finding_as`, so neither is silently preferred.
fn link_physics_and_calibration(
    fit: &Fit,
    decisions: &[(Effect, Decision)],
    reports: &mut [EffectReport],
) {
    let mut pairs: Vec<(Effect, Effect)> = Vec::new();
    for &c in fit.chosen.iter().filter(|c| c.is_calibration()) {
        for p in fit.swaps_for(c).into_iter().filter(|p| !p.is_calibration()) {
            pairs.push((p, c));
        }
        for (p, d) in decisions {
            if let Decision::OneFindingWith { calibrations, .. } = d
                && calibrations.contains(&c)
                && !pairs.contains(&(*p, c))
            {
                pairs.push((*p, c));
            }
        }
    }
    for r in reports.iter_mut() {
        for (p, c) in &pairs {
            let other = if r.name == *p {
                c
            } else if r.name == *c {
                p
            } else {
                continue;
            };
            r.same_finding_as.push(*other);
        }
        if matches!(r.decision, Some(Decision::OneFindingWith { .. }))
            && r.same_finding_as.is_empty()
        {
            r.decided_by
                .push_str("; that calibration was not claimed either (see its decision)");
        }
    }
}

/// The selected effects' parameters that are their linear coefficients
/// one to one (`effect`, parameter index, column): the wind's, the motor
/// lag's, the ground effect's and the battery sag's are not (a knob, a
/// profiled time constant, a surface reported as a grid, a scaled
/// coefficient).
fn linear_parameters(fit: &Fit) -> Vec<(Effect, usize, usize)> {
    fit.chosen
        .iter()
        .filter(|e| {
            !matches!(
                e,
                Effect::Wind | Effect::MotorLag | Effect::GroundEffect | Effect::BatterySag
            )
        })
        .flat_map(|&e| {
            fit.layout
                .columns(e)
                .enumerate()
                .map(move |(j, c)| (e, j, c))
        })
        .collect()
}

/// Two parameters whose estimates correlate at least
/// [`COMBINED_CORRELATION`] (over the jackknife) are not findings alone.
/// Both are marked not identified (unless both are [`pinned`]), and the
/// combination `a + w b` with the
/// least variance (`w = -cov_ab / var_b`, deviation `sd_a sqrt(1 - rho^2)`)
/// is reported on the effects they belong to.
fn combine_inseparable(fit: &Fit, reports: &mut [EffectReport]) {
    let params = linear_parameters(fit);
    let pos = |c: usize| fit.idx.iter().position(|&i| i == c);
    for (n, &(ea, ja, ca)) in params.iter().enumerate() {
        for &(eb, jb, cb) in &params[n + 1..] {
            let (Some(a), Some(b)) = (pos(ca), pos(cb)) else {
                continue;
            };
            let (vaa, vbb, vab) = (fit.cov[(a, a)], fit.cov[(b, b)], fit.cov[(a, b)]);
            if !(vaa > 0.0 && vbb > 0.0) {
                continue;
            }
            let rho = vab / (vaa * vbb).sqrt();
            if rho.abs() < COMBINED_CORRELATION
                || (pinned(reports, ea, ja) && pinned(reports, eb, jb))
            {
                continue;
            }
            let name_of = |e: Effect, j: usize| -> Option<(Param, String)> {
                let r = reports.iter().find(|r| r.name == e)?;
                let p = r.parameters.get(j)?;
                Some((p.name, p.unit.clone()))
            };
            let (Some((first, unit)), Some((second, _))) = (name_of(ea, ja), name_of(eb, jb))
            else {
                continue;
            };
            let weight = -vab / vbb;
            let finding = CombinedFinding {
                first,
                second,
                correlation: rho,
                weight,
                value: fit.theta[a] + weight * fit.theta[b],
                std: vaa.sqrt() * (1.0 - rho * rho).max(0.0).sqrt(),
                unit,
            };
            for r in reports.iter_mut().filter(|r| r.name == ea || r.name == eb) {
                for (e, j) in [(ea, ja), (eb, jb)] {
                    if r.name != e {
                        continue;
                    }
                    if let Some(p) = r.parameters.get_mut(j) {
                        p.identified = false;
                    }
                }
                // Once per effect concerned (once when both are its own).
                r.combined.push(finding.clone());
            }
        }
    }
}

/// Whether parameter `j` of effect `e` is known to within
/// [`COMBINED_RESOLUTION`] of its physical range.
fn pinned(reports: &[EffectReport], e: Effect, j: usize) -> bool {
    reports
        .iter()
        .find(|r| r.name == e)
        .and_then(|r| r.parameters.get(j))
        .is_some_and(|p| {
            let (lo, hi) = p.name.range();
            p.std
                .is_some_and(|sd| sd.is_finite() && sd < COMBINED_RESOLUTION * (hi - lo))
        })
}

/// Parameters of `e`: for a selected effect from the final fit; for a
/// rejected one, what a fit with it added would give (for the record).
pub(crate) fn effect_parameters(fit: &Fit, e: Effect, selected: bool) -> Vec<Parameter> {
    let layout = &fit.layout;
    let (pidx, ptheta, psd) = if selected {
        (fit.idx.clone(), fit.theta.clone(), fit.sd())
    } else {
        let mut more = fit.chosen.clone();
        more.push(e);
        let (idx, theta, cov) = selection::fit_with_uncertainty(&fit.stats, layout, &more);
        (idx, theta, selection::deviations(&cov))
    };
    // A coefficient the fit does not have is missing (NaN, not
    // identified), not a zero.
    let coef = |c: usize| -> (f64, f64) {
        pidx.iter()
            .position(|i| *i == c)
            .map_or((f64::NAN, f64::NAN), |p| (ptheta[p], psd[p]))
    };
    let param = |name: Param, value: f64, std: Option<f64>| Parameter {
        identified: true,
        name,
        value,
        std,
        unit: name.unit().into_owned(),
    };
    let cols = layout.columns(e);
    match e {
        Effect::MotorLag => {
            let (c, cs) = coef(cols.start);
            vec![
                param(Param::TimeConstant, fit.knobs.tau, None),
                param(Param::LagTermScale, c, Some(cs)),
            ]
        }
        Effect::Wind if selected && fit.wind.is_some() => {
            // Infinite for a component the profile did not identify
            // (`WindProfile::identified`).
            let sd = fit.wind.as_ref().map_or([f64::NAN; 2], |p| p.sd);
            Axis::XY
                .iter()
                .enumerate()
                .map(|(j, &axis)| param(Param::SteadyWind(axis), fit.knobs.wind[j], Some(sd[j])))
                .collect()
        }
        Effect::Wind => {
            let kr = coef(layout.columns(Effect::Drag).start).0;
            Axis::XY
                .iter()
                .enumerate()
                .map(|(j, &axis)| {
                    let (c, cs) = coef(cols.start + j);
                    let (v, s) = if kr.abs() > 1e-3 {
                        (
                            c / kr + fit.knobs.wind[j] * f64::from(u8::from(selected)),
                            cs / kr.abs(),
                        )
                    } else {
                        // No rotor drag to divide by: the wind is not
                        // measured, and not a zero wind either.
                        (f64::NAN, f64::NAN)
                    };
                    param(Param::SteadyWind(axis), v, s.is_finite().then_some(s))
                })
                .collect()
        }
        Effect::BatterySag => {
            let (c, cs) = coef(cols.start);
            let k = 3600.0 * BATTERY_CAPACITY_WH / BATTERY_FULL_POWER_W;
            vec![param(Param::Sag, c * k, Some(cs * k))]
        }
        _ => cols
            .enumerate()
            .filter_map(|(j, c)| {
                let (v, s) = coef(c);
                Param::of_coefficient(e, j).map(|p| param(p, v, Some(s)))
            })
            .collect(),
    }
}

/// The ground-effect gain of the fitted plant file on the report grid, its
/// spread over the folds (jackknife) and whether the recording covers each
/// point (at least 0.5 s within +-0.05 m and +-3 deg).
pub fn gain_grid(res: &Residuals, fit: &Fit) -> Vec<GridPoint> {
    let prep = &res.prep;
    let ge_fold: Vec<Option<GroundEffect>> = (0..selection::FOLDS)
        .map(|f| {
            fit.fold_physical(f)
                .ge_config()
                .map(|c| GroundEffect::new(&c))
        })
        .collect();
    let ge_all = fit.physical.ge_config().map(|c| GroundEffect::new(&c));
    let min_rows = (0.5 / prep.dt).ceil() as usize;
    let mut grid = Vec::new();
    for &vd in &GRID_TILTS_DEG {
        for &h in &GRID_HEIGHTS {
            let count = res
                .fit_rows
                .iter()
                .filter(|&&k| {
                    (prep.env[k].height - h).abs() <= 0.05
                        && (prep.env[k].varphi.to_degrees() - vd).abs() <= 3.0
                })
                .count();
            let v = vd.to_radians();
            let gain = ge_all.as_ref().map_or(0.0, |g| g.gain(h, v).mean);
            let folds: Vec<f64> = ge_fold
                .iter()
                .map(|g| g.as_ref().map_or(0.0, |g| g.gain(h, v).mean))
                .collect();
            let k = folds.len() as f64;
            let mean = folds.iter().sum::<f64>() / k;
            let std =
                ((k - 1.0) / k * folds.iter().map(|x| (x - mean).powi(2)).sum::<f64>()).sqrt();
            grid.push(GridPoint {
                height_m: h,
                varphi_deg: vd,
                gain,
                std,
                covered: count >= min_rows,
            });
        }
    }
    grid
}

/// Whether anything disagrees, and the one-line verdict.
pub fn verdict(reports: &[EffectReport], chosen: &[Effect], mismatch: &Mismatch) -> (bool, String) {
    let high = reports
        .iter()
        .any(|r| r.selected && r.confidence.is_some_and(|c| c >= HIGH_CONFIDENCE));
    let mismatch_found = !chosen.is_empty() || !mismatch.location.located.is_empty();
    let verdict = if !mismatch_found {
        "no significant mismatch: the nominal model explains the recording to its noise floor"
            .to_string()
    } else if chosen.is_empty() {
        "mismatch located, but no candidate effect explains it (see the located regions)"
            .to_string()
    } else {
        let describe = |r: &EffectReport| {
            let conf = r.confidence.map_or_else(
                || "confidence not computed".into(),
                |c| format!("confidence {c:.2}"),
            );
            if r.indistinguishable_from.is_empty() {
                format!("{} ({conf}; {})", r.name, r.decided_by)
            } else {
                format!(
                    "{} ({conf}; this data cannot tell it apart from {})",
                    r.name,
                    effects::join(&r.indistinguishable_from, ", ")
                )
            }
        };
        // Physics, then what physics or a calibration explains alike (one
        // finding, carried by the calibration), then calibration alone.
        let group = |r: &EffectReport| match (r.calibration, r.same_finding_as.is_empty()) {
            (false, _) => 0,
            (true, false) => 1,
            (true, true) => 2,
        };
        let list = |g: u8| {
            reports
                .iter()
                .filter(|r| r.selected && group(r) == g)
                .map(|r| {
                    if g == 1 {
                        format!(
                            "{} or {} (one finding, carried by the calibration {}; {})",
                            r.name,
                            effects::join(&r.same_finding_as, " or "),
                            r.name,
                            describe(r)
                        )
                    } else {
                        describe(r)
                    }
                })
                .collect::<Vec<_>>()
                .join(", ")
        };
        let parts: Vec<String> = [
            (list(0), ""),
            (list(1), "physics or calibration: "),
            (list(2), "nominal calibration: "),
        ]
        .into_iter()
        .filter(|(l, _)| !l.is_empty())
        .map(|(l, head)| format!("{head}{l}"))
        .collect();
        let explained = if parts.len() == 1 && list(0).is_empty() && list(1).is_empty() {
            format!("the nominal calibration alone: {}", list(2))
        } else {
            parts.join("; ")
        };
        format!(
            "mismatch found; explained by {explained}{}",
            if high {
                ""
            } else {
                "; no effect with high confidence"
            }
        )
    };
    // Physics the acceptance made one finding with a claimed calibration
    // is listed with it above, not as rejected; physics refused for its
    // own reasons stays listed with them.
    let rejected: Vec<String> = reports
        .iter()
        .filter(|r| !r.selected && !r.decided_by.starts_with("not selected"))
        .filter(|r| {
            !matches!(r.decision, Some(Decision::OneFindingWith { .. }))
                || r.same_finding_as.is_empty()
        })
        .map(|r| format!("{} ({})", r.name, r.decided_by))
        .collect();
    let verdict = if rejected.is_empty() {
        verdict
    } else {
        format!("{verdict}; rejected: {}", rejected.join("; "))
    };
    (mismatch_found, verdict)
}

/// The time series to plot: the channel with the largest located excess
/// (a_z when nothing is located) over a 20 s window where its nominal
/// residual is largest (the whole recording when it is shorter than 30 s).
pub fn plot_series(res: &Residuals, mismatch: &Mismatch, after: &[f64]) -> Series {
    let prep = &res.prep;
    let ch = mismatch
        .location
        .located
        .iter()
        .max_by(|a, b| a.rms_ratio.total_cmp(&b.rms_ratio))
        .and_then(|l| CHANNELS.iter().position(|c| *c == l.channel))
        .unwrap_or(2);
    let duration = res.duration();
    // The per-second bins are sized from the time axis, which the reader
    // contract bounds (`recording::contract::MAX_DURATION_S`); a longer or
    // non-finite span is plotted whole rather than trusted.
    let bounded = duration.is_finite() && duration <= crate::recording::contract::MAX_DURATION_S;
    let (w0, w1) = if duration > 30.0 && bounded {
        let t0 = prep.t[0];
        let nb = duration.ceil() as usize + 1;
        let mut per_s = vec![0.0; nb];
        for &k in &res.fit_rows {
            let r = prep.resid[6 * k + ch];
            let bin = (prep.t[k] - t0).max(0.0) as usize;
            per_s[bin.min(nb - 1)] += r * r;
        }
        let best = (0..nb.saturating_sub(20))
            .max_by(|&a, &b| {
                per_s[a..a + 20]
                    .iter()
                    .sum::<f64>()
                    .total_cmp(&per_s[b..b + 20].iter().sum::<f64>())
            })
            .unwrap_or(0);
        (t0 + best as f64, t0 + best as f64 + 20.0)
    } else {
        (f64::NEG_INFINITY, f64::INFINITY)
    };
    let mut series = Series {
        channel: ch,
        ..Series::default()
    };
    for &k in res
        .fit_rows
        .iter()
        .filter(|&&k| prep.t[k] >= w0 && prep.t[k] <= w1)
    {
        series.t.push(prep.t[k]);
        series.recording.push(prep.meas[6 * k + ch]);
        series.nominal.push(prep.nominal[6 * k + ch]);
        series
            .fitted
            .push(prep.meas[6 * k + ch] - after[6 * k + ch]);
    }
    series
}

/// Warnings about how far the results can be trusted.
pub fn notes(res: &Residuals, fit: &Fit, decisions: &[(Effect, Decision)]) -> Vec<String> {
    let mut notes = Vec::new();
    let unjudged: Vec<&str> = decisions
        .iter()
        .filter(|(_, d)| matches!(d, Decision::PredictionFailed { .. }))
        .map(|(e, _)| e.name())
        .collect();
    if !unjudged.is_empty() {
        notes.push(format!(
            "{} selected effect(s) not claimed because a 0.5 s prediction they were judged by \
             could not be replayed ({}): a missing prediction is not compared",
            unjudged.len(),
            unjudged.join(", ")
        ));
    }
    let used_segments = (0..res.nseg).filter(|&s| fit.stats.entries[s] > 0).count();
    if used_segments < 10 {
        notes.push(format!(
            "only {used_segments} segments of airborne data (about {:.0} s): held-out \
             scores and confidences rest on few segments; record longer for firm answers",
            res.fit_rows.len() as f64 * res.prep.dt
        ));
    }
    if res.prep.contact_rows > 0 {
        notes.push(format!(
            "{} rows at the ground left out (ground contact is not a candidate effect)",
            res.prep.contact_rows
        ));
    }
    notes
}

/// The explanation of the findings (without timings: [`crate::explain`]
/// adds them).
pub fn report(f: &Analysis) -> Explanation {
    let (rec, res, fit, val) = (&f.rec, &f.res, &f.fit, &f.validation);
    let prep = &res.prep;
    let (effects, indistinguishable) = effect_reports(fit, &f.confidence, &f.decisions);
    let (mismatch_found, verdict) = verdict(&effects, &fit.chosen, &f.mismatch);
    let entries = fit.stats.entries_in(&vec![true; fit.stats.nseg()]).max(1) as f64;
    let before = &f.mismatch.location;
    let wind_speed = super::wind_speed::wind_speed(res, rec, fit, &val.rms);
    let mut notes = notes(res, fit, &f.decisions);
    notes.extend(wind_speed.as_ref().and_then(WindSpeed::note));
    Explanation {
        source: rec.source.display().to_string(),
        rows: rec.samples.len(),
        rows_used: res.fit_rows.len(),
        rate_hz: 1.0 / prep.dt,
        duration_s: res.duration(),
        window_samples: 2 * prep.half + 1,
        ignored_columns: rec.ignored_columns.clone(),
        skipped_nonfinite: rec.skipped_nonfinite,
        skipped_time: rec.skipped_time,
        outliers: rec.outliers.clone(),
        skipped_rotation: rec.skipped_rotation,
        jumps: rec.jumps.clone(),
        contact_rows: prep.contact_rows,
        noise_floor: prep.floor,
        velocity_from_positions: crate::velocity::VelocityCorrection::default(),
        mismatch_found,
        verdict,
        located: before.located.clone(),
        located_channels: before
            .channels
            .iter()
            .map(|&c| CHANNELS[c].to_string())
            .collect(),
        effects,
        selection_steps: f.steps.clone(),
        indistinguishable,
        heldout_rms_before: f.mismatch.rms.clone(),
        heldout_rms_after: val.rms.clone(),
        multistep_before: val.multistep_before,
        multistep_after: val.multistep_after,
        ground_effect_gain_grid: gain_grid(res, fit),
        motor_lag_profile: f
            .lag
            .points
            .iter()
            .map(|(t, c)| (*t, c / entries))
            .collect(),
        fitted_effects_toml: val.toml.clone(),
        location_before: Some(before.clone()),
        location_after: Some(val.location.clone()),
        series: Some(plot_series(res, &f.mismatch, &val.after)),
        timings_s: Vec::new(),
        wind_speed,
        notes,
    }
}
