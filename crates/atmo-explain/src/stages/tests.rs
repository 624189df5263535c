//! One focused test per stage, on two small synthetic recordings (20 s at
//! 100 Hz of an open-loop hover with zero-mean command dither, flown by
//! the plant without a controller): the nominal robot, and the robot with
//! mass and inertia 5 % heavier than its file says (flown at 1.05 times
//! the nominal hover trim). Open loop, only the first seconds stay
//! analysable (two 2 s segments); on the nominal flight the selection
//! still picks an effect (not asserted; locate finds nothing there).

use std::sync::OnceLock;

use atmo_core::control::WheelRates;
use atmo_core::model::{Input, Model, State, idx};
use atmo_core::{ConfigFile as _, RobotConfig};
use atmo_plant::config::{EffectsConfig, MassErrorConfig, PlantConfig, TerrainConfig};
use atmo_plant::plant::{Command, InitialState, Plant};
use nalgebra::Vector4;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::select as select_stage;
use super::*;
use crate::Explanation;
use crate::effects::Effect;
use crate::recording::{Recording, Sample};
use crate::selection;

const MASS_SCALE: f64 = 1.05;
const SECONDS: f64 = 20.0;
/// Half-width of the uniform noise on recorded velocities (m/s) and rates (rad/s).
const NOISE: f64 = 0.004;

/// An open-loop hover at 3 m with a multi-sine dither of 0.03 on each rotor,
/// recorded at 100 Hz with uniform noise on the velocities and rates.
fn hover(mass_scale: f64) -> (RobotConfig, Recording) {
    let robot = RobotConfig::atmo();
    let mut cfg = PlantConfig::ideal();
    cfg.arm_inertia_convention = robot.arm.inertia_convention;
    cfg.effects = EffectsConfig {
        mass_error: (mass_scale != 1.0).then_some(MassErrorConfig {
            enabled: true,
            mass_scale,
            inertia_scale: mass_scale,
        }),
        ..EffectsConfig::none()
    };
    let trim = Model::new(&robot).at_tilt(0.0).hover_trim() * mass_scale;
    let mut x0 = State::zeros();
    x0[idx::Z] = -3.0;
    let initial = InitialState {
        state: x0,
        tilt: 0.0,
        thrust: trim,
    };
    let mut plant = Plant::new(&robot, &cfg, &TerrainConfig::flat(0.0), &initial, 1).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let freq = [1.3, 2.1, 3.4, 4.7];
    let phase = [0.0, 1.0, 2.0, 3.0];
    let command = |t: f64| {
        Vector4::from_fn(|i, _| {
            let dither = 0.03 * (std::f64::consts::TAU * freq[i] * t + phase[i]).sin();
            (trim[i] + dither).clamp(0.0, 1.0)
        })
    };
    let every = (0.01 / plant.dt()).round() as usize;
    let steps = (SECONDS / plant.dt()).round() as usize;
    let mut samples: Vec<Sample> = Vec::new();
    let mut applied_sum = Input::zeros();
    for step in 0..steps {
        let t = plant.time();
        let u = command(t);
        if step % every == 0 {
            // The previous row's commands: the mean of what its steps applied.
            if let Some(last) = samples.last_mut() {
                last.applied = applied_sum / every as f64;
            }
            applied_sum = Input::zeros();
            let mut x = plant.state();
            for i in [idx::VX, idx::VY, idx::VZ, idx::WX, idx::WY, idx::WZ] {
                x[i] += rng.random_range(-NOISE..NOISE);
            }
            samples.push(Sample {
                t,
                x,
                u,
                applied: u,
                varphi: plant.tilt(),
                ground_z: 0.0,
                battery_v: None,
            });
        }
        let cmd = Command {
            rotors: u,
            tilt_rate: 0.0,
            wheel_rates: WheelRates {
                left: 0.0,
                right: 0.0,
            },
        };
        plant.step(&cmd).unwrap();
        applied_sum += u;
    }
    (robot, Recording::from_samples("open-loop hover", samples))
}

/// Every stage's output for one recording, with what the selection chose
/// before the acceptance and the report.
struct Run {
    analysis: Analysis,
    chosen_by_selection: Vec<Effect>,
    explanation: Explanation,
}

impl std::ops::Deref for Run {
    type Target = Analysis;
    fn deref(&self) -> &Analysis {
        &self.analysis
    }
}

fn run(mass_scale: f64) -> Run {
    let (robot, rec) = hover(mass_scale);
    let res = Residuals::new(&rec, &robot).unwrap();
    let mismatch = locate_mismatch(&res);
    let base = BaseRegressors::new(&res, &rec);
    let lag = profile_motor_lag(&res, &base);
    let sel = select_effects(&res, &rec, lag.tau);
    let chosen_by_selection = sel.chosen.clone();
    let steps = sel.steps.clone();
    let confidence = sel.stability(1);
    let fit = fit_effects(&res, &rec, sel);
    let (fit, decisions) = super::accept_effects(&rec, &robot, &res, fit, 240).unwrap();
    let validation = validate(&rec, &robot, &res, &mismatch, &fit, 240).unwrap();
    let analysis = Analysis {
        rec,
        velocity_correction: crate::velocity::VelocityCorrection::default(),
        replayed: robot,
        res,
        mismatch,
        lag,
        steps,
        confidence,
        fit,
        decisions,
        validation,
    };
    let explanation = report(&analysis);
    Run {
        analysis,
        chosen_by_selection,
        explanation,
    }
}

fn nominal() -> &'static Run {
    static RUN: OnceLock<Run> = OnceLock::new();
    RUN.get_or_init(|| run(1.0))
}

fn heavy() -> &'static Run {
    static RUN: OnceLock<Run> = OnceLock::new();
    RUN.get_or_init(|| run(MASS_SCALE))
}

fn mean_over_fit_rows(res: &Residuals, resid: &[f64], channel: usize) -> f64 {
    res.fit_rows
        .iter()
        .map(|&k| resid[6 * k + channel])
        .sum::<f64>()
        / res.fit_rows.len() as f64
}

#[test]
fn residuals_of_the_heavy_robot_are_the_missing_thrust_per_mass() {
    // Flown at 1.05 x trim, the heavy robot hovers; the nominal model
    // predicts an upward (-z) acceleration of 0.05 g for those commands,
    // so the residual a_z = measured - nominal is +0.05 g.
    let heavy = heavy();
    let g = 9.81;
    let a_z = mean_over_fit_rows(&heavy.res, &heavy.res.prep.resid, 2);
    assert!(
        (a_z - 0.05 * g).abs() < 0.1 * 0.05 * g,
        "mean a_z residual {a_z}"
    );
    // The nominal robot's residual is noise around 0.
    let nominal = nominal();
    let a_z = mean_over_fit_rows(&nominal.res, &nominal.res.prep.resid, 2);
    assert!(
        a_z.abs() < 0.3 * nominal.res.prep.floor[2],
        "mean a_z residual {a_z}, floor {}",
        nominal.res.prep.floor[2]
    );
    // Rows within the half window of the ends are not fitted.
    assert!(!heavy.res.prep.fit[0] && !heavy.res.prep.fit[heavy.res.prep.n - 1]);
    // Open loop, the flight leaves the analysable envelope after a few
    // seconds; at least two 2 s segments stay usable.
    assert!(heavy.res.nseg >= 2, "{} segments", heavy.res.nseg);
}

#[test]
fn locate_flags_a_z_of_the_heavy_robot_and_nothing_of_the_nominal_one() {
    let heavy = heavy();
    assert!(
        heavy.mismatch.location.channels.contains(&2),
        "{:?}",
        heavy.mismatch.location.channels
    );
    assert!(heavy.mismatch.rms.located_normalized > 2.0);
    assert!(heavy.mismatch.region.iter().any(|r| *r));
    let nominal = nominal();
    assert!(
        nominal.mismatch.location.located.is_empty(),
        "{:?}",
        nominal.mismatch.location.located
    );
}

#[test]
fn best_tau_is_the_vertex_of_a_parabola_in_log_tau() {
    let tau0: f64 = 0.02;
    let mut profile = vec![(0.0, 10.0)];
    profile.extend((0..12).map(|i| {
        let tau = 0.004 * 1.4_f64.powi(i);
        (tau, (tau.ln() - tau0.ln()).powi(2))
    }));
    let tau = select_stage::best_tau_for_test(&profile);
    assert!((tau / tau0 - 1.0).abs() < 1e-9, "{tau}");
    // A profile without a minimum past tau = 0 falls back to the smallest tau.
    let flat = [(0.0, 0.0), (0.004, 1.0), (0.0056, 2.0)];
    assert_eq!(select_stage::best_tau_for_test(&flat), 0.004);
}

#[test]
fn select_finds_a_mass_property_or_thrust_effect_only_when_there_is_one() {
    let heavy = heavy();
    let found = &heavy.chosen_by_selection;
    assert!(
        found.iter().any(|e| matches!(
            e,
            Effect::ThrustScale | Effect::MassError | Effect::InertiaError
        )),
        "{found:?}"
    );
    assert!(!heavy.steps.is_empty());
    assert!(heavy.lag.points.len() == 13 && heavy.lag.tau > 0.0);
    // Two segments only: random halves hold one segment, too few to select
    // on, so the confidences are 0 here.
    assert_eq!(heavy.confidence.len(), Effect::ALL.len());
}

#[test]
fn fit_recovers_the_thrust_per_unit_mass() {
    let fit = &heavy().fit;
    assert_eq!(fit.fold_theta.len(), selection::FOLDS);
    assert!(fit.sd().iter().all(|s| s.is_finite()));
    // However it is written, thrust per unit mass is 1 / 1.05 of the model's.
    let p = &fit.physical;
    let per_mass = (1.0 + p.thrust_scale.unwrap_or(0.0)) / (1.0 + p.mass.unwrap_or(0.0));
    assert!(
        (per_mass * MASS_SCALE - 1.0).abs() < 0.01,
        "thrust per mass {per_mass}: {p:?}"
    );
}

#[test]
fn validation_shows_the_fit_better_on_held_out_data() {
    let run = heavy();
    let v = &run.validation;
    let before = mean_over_fit_rows(&run.res, &run.res.prep.resid, 2);
    let after = mean_over_fit_rows(&run.res, &v.after, 2);
    assert!(after.abs() < 0.1 * before.abs(), "{before} -> {after}");
    assert!(v.rms.located_normalized < 0.5 * run.mismatch.rms.located_normalized);
    assert!(
        v.multistep_after.position_norm() < 0.5 * v.multistep_before.position_norm(),
        "{:?} -> {:?}",
        v.multistep_before,
        v.multistep_after
    );
    let cfg = PlantConfig::from_toml_str(&v.toml, "fitted").unwrap();
    assert!(cfg.effects.mass_error.is_some(), "{}", v.toml);
}

#[test]
fn report_states_the_verdict_and_ranks_selected_effects_first() {
    let ex = &heavy().explanation;
    assert!(ex.mismatch_found);
    assert!(
        ex.verdict.starts_with("mismatch found; explained by"),
        "{}",
        ex.verdict
    );
    let first_rejected = ex
        .effects
        .iter()
        .position(|e| !e.selected)
        .unwrap_or(Effect::ALL.len());
    assert!(ex.effects[first_rejected..].iter().all(|e| !e.selected));
    assert_eq!(ex.effects.len(), Effect::ALL.len());
    assert_eq!(ex.ground_effect_gain_grid.len(), 20);
}

#[test]
fn only_a_claimed_effect_carries_a_confidence() {
    for run in [heavy(), nominal()] {
        let json = crate::output::json(&run.explanation);
        for (e, j) in run
            .explanation
            .effects
            .iter()
            .zip(json["effects"].as_array().unwrap())
        {
            assert_eq!(e.confidence.is_some(), e.selected, "{}", e.name);
            assert_eq!(j["confidence"].is_null(), !e.selected, "{j}");
            // What the acceptance judged carries its decision, claimed or not.
            assert_eq!(j["decision"].is_null(), e.decision.is_none(), "{j}");
            if e.selected {
                assert_eq!(j["decision"]["kind"], "found", "{j}");
            }
        }
    }
}

#[test]
fn acceptance_never_compares_against_a_prediction_that_failed() {
    use crate::replay::{self, ReplayError};
    let (robot, rec) = hover(MASS_SCALE);
    let res = &heavy().res;
    let starts = replay::start_rows(&res.prep, crate::HORIZON, crate::HORIZON);
    assert!(starts.len() >= 4, "{} starts", starts.len());
    let mut cfg = PlantConfig::ideal();
    cfg.arm_inertia_convention = robot.arm.inertia_convention;
    let nominal = atmo_plant::PlantTemplate::new(&robot, &cfg).unwrap();
    let replayed = replay::replay_each(&rec, &res.prep, &starts, &|_| Some(&nominal), &|_| 0.0);
    assert!(replayed.iter().all(Option::is_some));
    // A model whose plant file the plant refuses: no start replays.
    let failed = replay::replay_each(&rec, &res.prep, &starts, &|_| None, &|_| 0.0);
    assert!(failed.iter().all(Option::is_none));
    let e = ReplayError::from_each(&failed, &|_| true);
    assert_eq!(
        (e.starts, e.failed, e.attempted),
        (0, starts.len(), starts.len())
    );
    assert_eq!(e.velocity(), None);
    assert!(e.velocity_norm().is_nan(), "a missing error read as {e:?}");

    // Without the effect, nothing replays: no verdict reads that as 0 m/s.
    for (with, without) in [(&replayed, &failed), (&failed, &replayed)] {
        let d = super::accept::prediction_decision(with, without, false);
        assert!(
            matches!(d, Decision::PredictionFailed { attempted, .. } if attempted == starts.len()),
            "{d:?}"
        );
        assert!(!d.describe().contains("0.0000"), "{}", d.describe());
    }

    // Half the starts fail without the effect: both errors are over the
    // starts both replayed, not the one over all and the other over half.
    let half: Vec<_> = (0..starts.len())
        .map(|i| replayed[i].filter(|_| i % 2 == 0))
        .collect();
    let on_half = ReplayError::from_each(&replayed, &|i| i % 2 == 0);
    let (w, wo) = replay::paired(&replayed, &half);
    assert_eq!(
        (w.starts, w.unpaired, wo.failed),
        (on_half.starts, starts.len() / 2, starts.len() / 2)
    );
    assert_eq!(w.velocity(), on_half.velocity());
    match super::accept::prediction_decision(&replayed, &half, false) {
        Decision::RejectedByPrediction { with, without, .. } => {
            assert_eq!(Some(with), on_half.velocity());
            assert_eq!(with, without, "the same model over the same starts");
        }
        d => panic!("{d:?}"),
    }
    // More failures with the effect than without it: not claimed.
    let d = super::accept::prediction_decision(&half, &replayed, false);
    assert!(matches!(d, Decision::PredictionFailed { .. }), "{d:?}");
}

#[test]
fn physics_a_claimed_calibration_explains_alike_is_one_finding_not_a_rejection() {
    let run = heavy();
    let report = |name: Effect, calibration: bool, selected: bool, other: Effect, d: Decision| {
        crate::EffectReport {
            name,
            physics: String::new(),
            selected,
            confidence: selected.then_some(1.0),
            selection_frequency: 1.0,
            decided_by: d.describe(),
            decision: Some(d),
            heldout_gain: 0.1,
            parameters: Vec::new(),
            indistinguishable_from: Vec::new(),
            same_finding_as: vec![other],
            combined: Vec::new(),
            calibration,
        }
    };
    let found = Decision::Found {
        with: Some(0.5),
        without: Some(0.6),
    };
    let alike = Decision::OneFindingWith {
        calibrations: vec![Effect::ThrustAxis],
        recovery: 0.95,
    };
    let reports = [
        report(Effect::ThrustAxis, true, true, Effect::Wind, found),
        report(Effect::Wind, false, false, Effect::ThrustAxis, alike),
    ];
    let (_, v) = verdict(&reports, &[Effect::ThrustAxis], &run.mismatch);
    assert!(
        v.contains("physics or calibration: thrust_axis or wind (one finding"),
        "{v}"
    );
    assert!(!v.contains("rejected"), "{v}");
    assert!(!v.contains("nominal calibration alone"), "{v}");
}

/// Mass properties are measured at the tilts a recording flew (this hover:
/// 0 deg). A mass scale with the inertia about B as filed is physical
/// there but leaves no positive-definite mass matrix at the robot's
/// largest tilts: the replays run it on the flown tilts instead of
/// refusing it for tilts never reached.
#[test]
fn a_fitted_mass_property_is_replayed_on_the_tilts_flown() {
    let (robot, rec) = hover(MASS_SCALE);
    let mut cfg = PlantConfig::ideal();
    cfg.arm_inertia_convention = robot.arm.inertia_convention;
    cfg.effects.mass_error = Some(MassErrorConfig {
        enabled: true,
        mass_scale: 1.6,
        inertia_scale: 1.0,
    });
    assert!(atmo_plant::PlantTemplate::new(&robot, &cfg).is_err());
    let cut = crate::replay::within_flown_tilts(&robot, &rec);
    assert!(cut.limits.tilt_max_deg <= 1.0, "{:?}", cut.limits);
    assert!(atmo_plant::PlantTemplate::new(&cut, &cfg).is_ok());
}
