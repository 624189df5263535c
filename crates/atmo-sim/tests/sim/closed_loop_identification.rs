//! The loop closed: a system-identification flight with the
//! ground effect concealed from the controller (atmo-explain's synthetic
//! flight, flown by the nominal MPC against atmo-plant with the default
//! surface and realistic sensors), the discrepancy finder on its recording,
//! its `fitted_effects.toml` loaded into the MPC's model with the tilt
//! planned in the transition, and the wheel landing flown on the same
//! randomized seeds by that controller and by the nominal MPC (today's
//! default: no ground effect in the model, the paper's tilt law). The
//! numbers are printed; the fitted controller must touch down steeper with
//! an impact that is not worse (medians over the seeds).
//!
//! Seconds (5.7 s measured in release on main of 2026-12-02 at load 8; the
//! workspace's test profile is optimized too, so it runs with `cargo test`):
//! `cargo test -p atmo-sim --test sim -- closed_loop_identification --nocapture`.
//! Measured in release: ground_effect selected (confidence 1.00); over seeds 1-8
//! the median touchdown went from 62.61 deg at 0.40 m/s (nominal MPC) to
//! 63.54 deg at 0.37 m/s (fitted surface, planned tilt).
// Test, bench and example code: an unwrap that fails is the failure report.
#![allow(clippy::unwrap_used)]

use std::path::PathBuf;

use atmo_core::RobotConfig;
use atmo_core::ground_effect::table::GroundEffectConfig;
use atmo_explain::synth::{Flight, Profile, record};
use atmo_explain::{Options, explain};
use atmo_mpc::settings::GroundEffectSource;
use atmo_plant::config::{PlantConfig, SensorsConfig};
use atmo_sim::closed_loop::{ControllerConfig, fly};
use atmo_sim::monte_carlo::randomized;
use atmo_sim::scenario::Scenario;

const SEEDS: u64 = 8;

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

#[test]
fn fitted_ground_effect_in_the_mpc_lands_steeper_than_the_nominal_mpc() {
    let robot = RobotConfig::atmo();
    let mut plant = PlantConfig::ideal();
    plant.arm_inertia_convention = robot.arm.inertia_convention;
    plant.effects.ground_effect = Some(GroundEffectConfig::default());
    plant.effects.sensors = Some(SensorsConfig::default());
    let rec = record(&robot, &plant, &Flight::new(Profile::Mixed, 48.0, 7)).unwrap();
    let ex = explain(&rec, &robot, &Options::default()).unwrap();
    let found = ex
        .effect(atmo_explain::effects::Effect::GroundEffect)
        .unwrap();
    eprintln!(
        "explain: ground_effect selected={} confidence={:?}",
        found.selected, found.confidence
    );
    assert!(found.selected, "the ground effect was not identified");
    let dir = std::env::temp_dir().join(format!("atmo-sysid-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let fitted: PathBuf = dir.join("fitted_effects.toml");
    std::fs::write(&fitted, &ex.fitted_effects_toml).unwrap();

    let base = ControllerConfig::atmo().unwrap().deterministic();
    let nominal = base
        .clone()
        .with_ground_effect(&GroundEffectSource::None)
        .unwrap()
        .with_tilt_plan(false)
        .unwrap();
    let informed = base
        .with_ground_effect(&GroundEffectSource::File(fitted))
        .unwrap()
        .with_tilt_plan(true)
        .unwrap();

    let path: PathBuf = [
        env!("CARGO_MANIFEST_DIR"),
        "..",
        "..",
        "config",
        "scenarios",
        "wheel_landing.toml",
    ]
    .iter()
    .collect();
    let scenario = Scenario::load(&path).unwrap();
    let mut rows = Vec::new();
    for seed in 1..=SEEDS {
        let s = randomized(&scenario, seed);
        let a = fly(&s, &nominal, |_| {}).unwrap();
        let b = fly(&s, &informed, |_| {}).unwrap();
        assert!(!a.crashed && !b.crashed, "seed {seed}: {a:?} {b:?}");
        let row = (
            a.touchdown_tilt_deg.unwrap(),
            a.impact_speed_mps.unwrap(),
            b.touchdown_tilt_deg.unwrap(),
            b.impact_speed_mps.unwrap(),
        );
        eprintln!(
            "seed {seed}: nominal {:.2} deg {:.2} m/s | fitted + planned tilt {:.2} deg {:.2} m/s",
            row.0, row.1, row.2, row.3
        );
        rows.push(row);
    }
    let tilt_nominal = median(rows.iter().map(|r| r.0).collect());
    let impact_nominal = median(rows.iter().map(|r| r.1).collect());
    let tilt_fitted = median(rows.iter().map(|r| r.2).collect());
    let impact_fitted = median(rows.iter().map(|r| r.3).collect());
    eprintln!(
        "medians over {SEEDS} seeds: nominal {tilt_nominal:.2} deg {impact_nominal:.2} m/s, \
         fitted + planned tilt {tilt_fitted:.2} deg {impact_fitted:.2} m/s"
    );
    assert!(tilt_fitted > tilt_nominal, "touchdown tilt not up");
    assert!(impact_fitted <= impact_nominal, "impact speed worse");
}
