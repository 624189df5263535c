//! Stage 4b, accept: an effect the selection chose (it lowers the
//! held-out one-step residual) is *found* only if
//!
//! 1. every parameter lies inside its physical range ([`Param::range`], the
//!    table in docs/explain.md): a value beyond a bound by more than its
//!    uncertainty makes the effect "not identified"; a parameter at a bound
//!    within its uncertainty, or whose uncertainty exceeds its value, is
//!    reported as not identified (and an effect none of whose parameters is
//!    identified is not identified);
//! 2. it improves the held-out 0.5 s multi-step prediction: the velocity
//!    error at the horizon with the effects fitted without the start's fold
//!    must be at least [`PREDICTION_MARGIN`] lower with the effect than
//!    with the same model refitted without it;
//! 3. it is calibration, or physics no calibration explains as well
//!    ([`Fit::swaps_for`]): the calibration every flight pins down is the
//!    simpler account of what both explain.
//!
//! The rest is listed as rejected, with both numbers and the test that
//! decided. The fit is then redone with the accepted effects only, and
//! the tests are repeated on that reduced model: an effect that helped
//! only beside a rejected one (the prediction it is judged against is then
//! a model nobody will fly) is rejected in its turn, the worst first, until
//! every effect left improves the prediction of the effects left. So the
//! model reported is one whose every effect earns its place against the
//! others in it.

use atmo_core::RobotConfig;
use atmo_plant::PlantTemplate;
use atmo_plant::config::PlantConfig;

use crate::effects::Effect;
use crate::explanation::Decision;
use crate::parameter::Param;
use crate::physical::Physical;
use crate::recording::Recording;
use crate::replay::{self, StartError};
use crate::selection::{FOLDS, fold_of};
use crate::stages::fit::SWAP_RECOVERY;
use crate::stages::report::effect_parameters;
use crate::stages::{Fit, Residuals};
use crate::{HORIZON, Result};

/// Relative cut of the 0.5 s velocity error an effect must bring.
pub const PREDICTION_MARGIN: f64 = 0.01;

/// The physical range of each linear coefficient of `e`
/// ([`Param::range`]); unbounded where the coefficient is not a parameter
/// itself (the wind's `k_r w` products, the battery's loss per energy).
/// The fit holds every coefficient inside its range (`Stats::bounds`), so
/// an absurd value of one effect cannot stand in for another effect's
/// force during the selection.
pub fn coefficient_bounds(e: Effect) -> Vec<(f64, f64)> {
    (0..e.width())
        .map(|j| {
            Param::of_coefficient(e, j).map_or((f64::NEG_INFINITY, f64::INFINITY), Param::range)
        })
        .collect()
}

/// What the acceptance tests said about one parameter.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ParamStatus {
    Identified,
    /// At a bound (within its uncertainty) or uncertainty above |value|.
    NotIdentified,
    /// Beyond a bound by more than its uncertainty.
    OutOfRange,
}

/// The status of a value with standard deviation `std` in `range`.
pub fn param_status(value: f64, std: Option<f64>, range: Option<(f64, f64)>) -> ParamStatus {
    // A value that is not a number (a coefficient the fit does not have, a
    // quotient by a vanishing coefficient) is missing, not a finding.
    if !value.is_finite() {
        return ParamStatus::NotIdentified;
    }
    let sd = std.filter(|s| s.is_finite()).unwrap_or(0.0);
    if let Some((lo, hi)) = range {
        if value < lo - sd || value > hi + sd {
            return ParamStatus::OutOfRange;
        }
        if value <= lo || value >= hi {
            return ParamStatus::NotIdentified;
        }
    }
    // An uncertainty that is not a number (no fold estimate) says nothing
    // is pinned down.
    if std.is_some_and(|s| !s.is_finite())
        || (std.is_some() && sd.partial_cmp(&value.abs()) != Some(std::cmp::Ordering::Less))
    {
        return ParamStatus::NotIdentified;
    }
    ParamStatus::Identified
}

/// The per-fold plant files of the fit restricted to `set` (refitted on
/// the same regressors), the wind knob included.
fn fold_configs(fit: &Fit, set: &[Effect], robot: &RobotConfig) -> Vec<PlantConfig> {
    let idx = fit.columns_of(set);
    (0..FOLDS)
        .map(|f| {
            let theta = fit.stats.solve(&idx, &|s| fold_of(s) != f);
            let mut p = Physical::from_theta(&fit.layout, set, &idx, &theta, fit.knobs.tau);
            if let Some(w) = p.wind.as_mut() {
                w[0] += fit.knobs.wind[0];
                w[1] += fit.knobs.wind[1];
            }
            p.plant_config(robot.arm.inertia_convention)
        })
        .collect()
}

/// Held-out multi-step error of the effects `set` from each of the
/// `starts` (`None` where it could not be replayed).
fn heldout_multistep(
    rec: &Recording,
    robot: &RobotConfig,
    res: &Residuals,
    fit: &Fit,
    set: &[Effect],
    starts: &[(usize, usize)],
) -> Vec<Option<StartError>> {
    let plants: Vec<Option<PlantTemplate>> = fold_configs(fit, set, robot)
        .iter()
        .map(|c| PlantTemplate::new(robot, c).ok())
        .collect();
    let tau = if set.contains(&Effect::MotorLag) {
        fit.knobs.tau
    } else {
        0.0
    };
    replay::replay_each(
        rec,
        &res.prep,
        starts,
        &|k| plants[res.seg_of[k].map_or(0, fold_of)].as_ref(),
        &|_| tau,
    )
}

/// The decision on every selected effect, and the fit redone with the
/// found ones.
pub fn accept_effects(
    rec: &Recording,
    robot: &RobotConfig,
    res: &Residuals,
    mut fit: Fit,
    max_replay_starts: usize,
) -> Result<(Fit, Vec<(Effect, Decision)>)> {
    let spacing = (res.duration() / max_replay_starts.max(1) as f64).max(HORIZON);
    let starts = replay::start_rows(&res.prep, HORIZON, spacing);
    let mut decisions = Vec::new();
    // Mass and thrust scale together: only thrust / mass is identified
    // (their columns differ only through the inertia); one combined
    // finding, carried by the thrust scale.
    if fit.chosen.contains(&Effect::ThrustScale) && fit.chosen.contains(&Effect::MassError) {
        let combination = match thrust_to_mass(&fit) {
            // Either held at a bound: the ratio of two bounds is not a
            // measurement (both at -0.5 read as "0.0000 +- 0.0000").
            Some(t) if t.at_bound => format!(
                "their combination thrust / mass - 1 is not identified either (thrust_scale = \
                 {:.4} and mass_error = {:.4} are held at bounds of their ranges)",
                t.scale, t.mass
            ),
            Some(t) => format!(
                "the identified combination is thrust / mass - 1 = {:.4} +- {:.4}, reported as \
                 thrust_scale",
                t.ratio, t.sd
            ),
            None => "their combination thrust / mass - 1 is not computed (the fit lacks a \
                     coefficient of the two)"
                .to_string(),
        };
        let kept: Vec<Effect> = fit
            .chosen
            .iter()
            .copied()
            .filter(|e| *e != Effect::MassError)
            .collect();
        fit.restrict(&kept);
        decisions.push((
            Effect::MassError,
            Decision::NotIdentified {
                reason: format!("not separable from thrust_scale: {combination}"),
            },
        ));
    }
    let chosen = fit.chosen.clone();
    // First round, on the whole selection's fit: every range, then the
    // prediction with each effect against the selection without it.
    let mut tested = Vec::new();
    for &e in &chosen {
        // Drag is part of a wind finding: judged with it.
        if rides_with_wind(e, &chosen) {
            continue;
        }
        match failure(&fit, e, &chosen, &chosen) {
            // (No calibration to swap in yet: the selection's are all in.)
            Some((d, _)) => decisions.push((e, d)),
            None => tested.push(e),
        }
    }
    decisions.extend(prediction_verdicts(
        rec, robot, res, &fit, &chosen, &tested, &starts, false,
    ));
    let mut kept: Vec<Effect> = chosen
        .iter()
        .copied()
        .filter(|&e| {
            let judged = if rides_with_wind(e, &chosen) {
                Effect::Wind
            } else {
                e
            };
            decisions
                .iter()
                .any(|(x, d)| *x == judged && matches!(d, Decision::Found { .. }))
        })
        .collect();
    // Later rounds, on the model left: the refit moves the kept effects'
    // values, so their ranges are checked again, and each must still
    // improve the prediction of the effects left (the worst one goes
    // first, then the rest are judged again without it). A physics
    // effect is only ever removed, a calibration only comes back in place
    // of one, so this ends.
    let mut settled = kept == chosen;
    while !settled {
        fit.restrict(&kept);
        if let Some((e, (d, swap))) = kept
            .iter()
            .find_map(|&e| failure(&fit, e, &kept, &chosen).map(|f| (e, f)))
        {
            let d = match d {
                Decision::NotIdentified { reason } => Decision::NotIdentified {
                    reason: format!("after the refit without the rejected effects, {reason}"),
                },
                d => d,
            };
            reject(&mut decisions, &mut kept, e, &d);
            if let Some(c) = swap.filter(|c| !kept.contains(c)) {
                kept.push(c);
            }
            continue;
        }
        let tested: Vec<Effect> = kept
            .iter()
            .copied()
            .filter(|e| !rides_with_wind(*e, &kept))
            .collect();
        let verdicts = prediction_verdicts(rec, robot, res, &fit, &kept, &tested, &starts, true);
        let worst = verdicts
            .iter()
            .filter(|(_, d)| !matches!(d, Decision::Found { .. }))
            .max_by(|a, b| {
                let (x, y) = (rejection_order(&a.1), rejection_order(&b.1));
                x.0.cmp(&y.0).then(x.1.total_cmp(&y.1))
            })
            .cloned();
        if let Some((e, d)) = worst {
            reject(&mut decisions, &mut kept, e, &d);
        } else {
            // Every effect left earns its place: its numbers are the
            // final model's.
            for (e, d) in verdicts {
                set_decision(&mut decisions, e, d);
            }
            settled = true;
        }
    }
    // Drag shares the wind's verdict.
    if let Some((_, d)) = decisions.iter().find(|(e, _)| *e == Effect::Wind) {
        let d = d.clone();
        set_decision(&mut decisions, Effect::Drag, d);
    }
    Ok((fit, decisions))
}

/// Why effect `e` of the fit of `model` is not a finding alone, if it is
/// not: out of range or not identified, a wind without a drag (both
/// [`Decision::NotIdentified`]), or a physics effect a calibration
/// explains as well ([`Decision::OneFindingWith`], with the best such
/// calibration the selection `proposed`, to take its place: one rejected
/// only because the physics did its work beside it).
fn failure(
    fit: &Fit,
    e: Effect,
    model: &[Effect],
    proposed: &[Effect],
) -> Option<(Decision, Option<Effect>)> {
    identification_failure(fit, e)
        .or_else(|| wind_failure(fit, e))
        .map(|reason| (Decision::NotIdentified { reason }, None))
        .or_else(|| {
            calibration_confusion(fit, e, model).map(|alike| {
                let swap = alike.iter().map(|(c, _)| *c).find(|c| proposed.contains(c));
                (
                    Decision::OneFindingWith {
                        recovery: alike[0].1,
                        calibrations: alike.into_iter().map(|(c, _)| c).collect(),
                    },
                    swap,
                )
            })
        })
}

/// Whether `e` is the drag of a wind finding in `model`: it is judged,
/// kept and rejected with the wind.
fn rides_with_wind(e: Effect, model: &[Effect]) -> bool {
    e == Effect::Drag && model.contains(&Effect::Wind)
}

/// The effects that stand or fall with `e` in `model`: the wind and its
/// drag together, any other effect alone.
fn finding_of(e: Effect, model: &[Effect]) -> Vec<Effect> {
    if e == Effect::Wind || rides_with_wind(e, model) {
        vec![Effect::Wind, Effect::Drag]
    } else {
        vec![e]
    }
}

/// Record `d` as the decision on `e`, replacing an earlier one.
fn set_decision(decisions: &mut Vec<(Effect, Decision)>, e: Effect, d: Decision) {
    match decisions.iter_mut().find(|x| x.0 == e) {
        Some(x) => x.1 = d,
        None => decisions.push((e, d)),
    }
}

/// Reject `e` (with the drag, when `e` is the wind or the drag of a wind
/// finding) from the model `kept`, with the decision `d`.
fn reject(
    decisions: &mut Vec<(Effect, Decision)>,
    kept: &mut Vec<Effect>,
    e: Effect,
    d: &Decision,
) {
    let gone = finding_of(e, kept);
    for g in &gone {
        set_decision(decisions, *g, d.clone());
    }
    kept.retain(|k| !gone.contains(k));
}

/// The order in which failed effects leave the model, worst first: one
/// whose prediction could not be compared (or not identified) before any
/// measured one, which go by how much the effect worsens the prediction
/// (with / without, over the same starts). The class is explicit, so no
/// missing number stands in for a large one.
fn rejection_order(d: &Decision) -> (u8, f64) {
    match d {
        Decision::RejectedByPrediction { with, without, .. } => (0, with / without),
        _ => (1, 0.0),
    }
}

/// The 0.5 s prediction test of one effect from the per-start errors with
/// and without it: compared over the starts both models replayed, never
/// against a missing prediction. A model with the effect that fails on
/// more starts than the one without it does not earn the effect.
pub(crate) fn prediction_decision(
    with: &[Option<StartError>],
    without: &[Option<StartError>],
    reduced: bool,
) -> Decision {
    let (w, wo) = replay::paired(with, without);
    let failed = Decision::PredictionFailed {
        attempted: with.len(),
        with_failed: w.failed,
        without_failed: wo.failed,
        reduced,
    };
    let (Some(a), Some(b)) = (w.velocity(), wo.velocity()) else {
        return failed;
    };
    if w.failed > wo.failed {
        return failed;
    }
    if a < (1.0 - PREDICTION_MARGIN) * b {
        Decision::Found {
            with: Some(a),
            without: Some(b),
        }
    } else {
        Decision::RejectedByPrediction {
            with: a,
            without: b,
            reduced,
        }
    }
}

/// The 0.5 s prediction test of each effect of `tested` in the model
/// `set`: the held-out velocity error with `set` against `set` without the
/// effect (without the drag too, for the wind), refitted on the same
/// regressors. `reduced` marks a model left after other rejections.
#[allow(clippy::too_many_arguments)] // reason: the stage's inputs, passed through
fn prediction_verdicts(
    rec: &Recording,
    robot: &RobotConfig,
    res: &Residuals,
    fit: &Fit,
    set: &[Effect],
    tested: &[Effect],
    starts: &[(usize, usize)],
    reduced: bool,
) -> Vec<(Effect, Decision)> {
    // No 0.5 s stretch in the recording: the residual test alone decides
    // (said so in the report). Starts that exist but fail are not this.
    if starts.is_empty() || set.is_empty() {
        return tested
            .iter()
            .map(|&e| {
                (
                    e,
                    Decision::Found {
                        with: None,
                        without: None,
                    },
                )
            })
            .collect();
    }
    let with = heldout_multistep(rec, robot, res, fit, set, starts);
    tested
        .iter()
        .map(|&e| {
            let gone = finding_of(e, set);
            let rest: Vec<Effect> = set.iter().copied().filter(|x| !gone.contains(x)).collect();
            let without = heldout_multistep(rec, robot, res, fit, &rest, starts);
            (e, prediction_decision(&with, &without, reduced))
        })
        .collect()
}

/// `r = (1 + s) / (1 + m) - 1` of the thrust scale s and mass error m of
/// the fit, with its deviation from the fit's jackknife covariance (first
/// order: `g^T C g`, `g = (1 / (1 + m), -(1 + s) / (1 + m)^2)`).
fn thrust_to_mass(fit: &Fit) -> Option<ThrustToMass> {
    let s_col = fit.layout.columns(Effect::ThrustScale).start;
    let m_col = fit.layout.columns(Effect::MassError).start;
    let pos = |c: usize| fit.idx.iter().position(|i| *i == c);
    let (ps, pm) = (pos(s_col)?, pos(m_col)?);
    let (s, m) = (fit.theta[ps], fit.theta[pm]);
    let (gs, gm) = (1.0 / (1.0 + m), -(1.0 + s) / (1.0 + m).powi(2));
    let c = &fit.cov;
    let var = gs * gs * c[(ps, ps)] + 2.0 * gs * gm * c[(ps, pm)] + gm * gm * c[(pm, pm)];
    let at_bound = |v: f64, e: Effect| {
        coefficient_bounds(e)
            .first()
            .is_some_and(|&(lo, hi)| v <= lo || v >= hi)
    };
    Some(ThrustToMass {
        ratio: (1.0 + s) / (1.0 + m) - 1.0,
        sd: var.max(0.0).sqrt(),
        scale: s,
        mass: m,
        at_bound: at_bound(s, Effect::ThrustScale) || at_bound(m, Effect::MassError),
    })
}

/// Thrust per mass from the thrust scale and mass error of a fit.
struct ThrustToMass {
    ratio: f64,
    sd: f64,
    scale: f64,
    mass: f64,
    /// Either coefficient held at a bound of its range.
    at_bound: bool,
}

impl Decision {
    /// One line for the report: which test decided, with the numbers.
    pub fn describe(&self) -> String {
        match self {
            Decision::Found {
                with: Some(w),
                without: Some(wo),
            } => format!(
                "found: lowers the held-out residual and the 0.5 s velocity error ({wo:.4} -> {w:.4} m/s)"
            ),
            Decision::PredictionFailed {
                attempted,
                with_failed,
                without_failed,
                reduced,
            } => format!(
                "not claimed: the 0.5 s prediction{} could not be compared (of {attempted} starts, \
                 {with_failed} could not be replayed with it and {without_failed} without it{})",
                if *reduced {
                    " of the model left after the other rejections"
                } else {
                    ""
                },
                if with_failed > without_failed && with_failed < attempted {
                    "; it fails where the model without it does not"
                } else {
                    ""
                }
            ),
            Decision::Found { .. } => {
                "found by the held-out residual alone (no 0.5 s stretch to predict)".into()
            }
            Decision::NotIdentified { reason } => format!("not identified: {reason}"),
            Decision::OneFindingWith {
                calibrations,
                recovery,
            } => format!(
                "one finding with {}: this data cannot tell it apart from that calibration of the \
                 robot file (swapped in for it, the calibration explains {:.2}x as much, {}x or \
                 more making them one); the model carries the calibration, and no physics is \
                 claimed alone",
                crate::effects::join(calibrations, ", "),
                recovery,
                SWAP_RECOVERY
            ),
            Decision::RejectedByPrediction {
                with,
                without,
                reduced,
            } => format!(
                "rejected by the 0.5 s prediction{}: lowers the held-out residual, but the \
                 velocity error is {with:.4} m/s with it against {without:.4} m/s without",
                if *reduced {
                    " of the model left after the other rejections"
                } else {
                    ""
                }
            ),
        }
    }
}

/// Wind without an identified drag: the wind speed is only known through
/// a drag coefficient (no airspeed variation to separate them), so what is
/// identified is the steady force, not the wind behind it.
fn wind_failure(fit: &Fit, e: Effect) -> Option<String> {
    if e != Effect::Wind {
        return None;
    }
    let drag = effect_parameters(fit, Effect::Drag, true);
    let identified = |p: &crate::explanation::Parameter| {
        param_status(p.value, p.std, Some(p.name.range())) == ParamStatus::Identified
    };
    if drag.iter().any(identified) {
        return None;
    }
    let listed: Vec<String> = drag
        .iter()
        .map(|p| {
            format!(
                "{} = {:.4} +- {:.4}",
                p.name,
                p.value,
                p.std.unwrap_or(f64::NAN)
            )
        })
        .collect();
    Some(format!(
        "drag and wind not separable (no drag coefficient identified: {}): the steady \
         force is identified, not the wind speed behind it",
        listed.join(", ")
    ))
}

/// A physics effect the data cannot tell apart from a calibration of the
/// robot file: a calibration that every flight
/// pins down, swapped in for it, explains nearly as much, so it is the
/// simpler account and no physics is claimed. On a flight at one heading,
/// a steady wind and a centre of mass or thrust axis off the file push
/// alike. With those calibrations, the best first.
///
/// A wind is judged by its own columns' swaps. A wind whose force the
/// drag's columns carry (built at the profiled or refined wind) has
/// nothing of its own to swap and is not judged here: the drag's swaps
/// are not used, because on the fan flights an inertia or mass error swaps
/// for the drag of a 4-9 m/s fan (docs/explain.md, "Acceptance"; the
/// measurements: docs/decisions/2026-12-05-explain-history.md).
fn calibration_confusion(fit: &Fit, e: Effect, model: &[Effect]) -> Option<Vec<(Effect, f64)>> {
    if e.is_calibration() || rides_with_wind(e, model) {
        return None;
    }
    let calibrations = fit.swaps_with_recovery(e, Effect::is_calibration);
    (!calibrations.is_empty()).then_some(calibrations)
}

/// Why effect `e` of the fit is not identified, if it is not.
fn identification_failure(fit: &Fit, e: Effect) -> Option<String> {
    let params = effect_parameters(fit, e, true);
    let mut any_identified = false;
    for p in &params {
        let (lo, hi) = p.name.range();
        match param_status(p.value, p.std, Some((lo, hi))) {
            ParamStatus::OutOfRange => {
                return Some(format!(
                    "{} = {:.4} +- {:.4} {} is outside its physical range [{lo}, {hi}]",
                    p.name,
                    p.value,
                    p.std.unwrap_or(0.0),
                    p.unit
                ));
            }
            ParamStatus::Identified => any_identified = true,
            ParamStatus::NotIdentified => {}
        }
    }
    (!any_identified).then(|| {
        "no parameter identified (each at a bound of its range or with an uncertainty above \
         its value)"
            .to_string()
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parameter_status_follows_range_and_uncertainty() {
        let r = Some((-0.5, 0.5));
        assert_eq!(param_status(0.1, Some(0.01), r), ParamStatus::Identified);
        assert_eq!(param_status(0.1, Some(0.2), r), ParamStatus::NotIdentified);
        assert_eq!(
            param_status(0.1, Some(f64::INFINITY), r),
            ParamStatus::NotIdentified
        );
        assert_eq!(
            param_status(0.1, Some(f64::NAN), r),
            ParamStatus::NotIdentified
        );
        assert_eq!(
            param_status(0.9, Some(f64::INFINITY), r),
            ParamStatus::OutOfRange
        );
        assert_eq!(param_status(0.5, Some(0.01), r), ParamStatus::NotIdentified);
        assert_eq!(param_status(-0.95, Some(0.3), r), ParamStatus::OutOfRange);
        assert_eq!(
            param_status(54.6, Some(1.0), Some((-15.0, 15.0))),
            ParamStatus::OutOfRange
        );
        assert_eq!(
            coefficient_bounds(Effect::GroundEffect)[0],
            Param::Gain { height: 0, tilt: 0 }.range()
        );
        assert_eq!(
            coefficient_bounds(Effect::Wind),
            vec![(f64::NEG_INFINITY, f64::INFINITY); 2]
        );
    }
}
