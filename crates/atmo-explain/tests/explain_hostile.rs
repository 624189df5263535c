//! Hostile recordings (issue 21): one absurd but finite cell gives a
//! defined outcome in bounded time, never a hang.
#![allow(clippy::unwrap_used, reason = "test")]

use atmo_core::RobotConfig;
use atmo_explain::output::write_all;
use atmo_explain::recording::{Recording, Sample};
use atmo_explain::synth::{Flight, Profile, record};
use atmo_explain::{Explanation, Options, explain};
use atmo_plant::config::{EffectsConfig, MotorLagConfig, PlantConfig};

/// A 24 s cruise at 100 Hz (2400 rows) with a concealed motor lag, with
/// one cell (row 1002) changed by `poison`; explained, and every output
/// written. `None` if the analysis refused the recording.
fn explain_poisoned(name: &str, poison: impl FnOnce(&mut Sample)) -> Option<Explanation> {
    let robot = RobotConfig::atmo();
    let mut plant = PlantConfig::ideal();
    plant.arm_inertia_convention = robot.arm.inertia_convention;
    plant.effects = EffectsConfig {
        motor_lag: Some(MotorLagConfig::default()),
        ..EffectsConfig::none()
    };
    let mut rec: Recording =
        record(&robot, &plant, &Flight::new(Profile::Cruise, 24.0, 4)).unwrap();
    assert!(rec.samples.len() >= 2400, "{} rows", rec.samples.len());
    poison(&mut rec.samples[1001]);
    match explain(&rec, &robot, &Options::default()) {
        Ok(ex) => {
            for e in &ex.effects {
                assert!(e.confidence.is_finite(), "{}: {}", e.name, e.confidence);
            }
            eprintln!("{name}: verdict: {}", ex.verdict);
            let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join(name);
            if let Err(e) = write_all(&ex, &dir) {
                eprintln!("{name}: outputs refused: {e}");
            }
            Some(ex)
        }
        Err(e) => {
            eprintln!("{name}: refused: {e}");
            None
        }
    }
}

/// `vx = 1e100` in row 1002 of a 2400-row recording made `atmo-sim explain`
/// run forever, in nalgebra's `pseudo_inverse` after the Cholesky solve of
/// the selection failed (now `select::bounded_solve`: an SVD with at most
/// 1000 sweeps). The analysis ends, with an answer or an error.
#[test]
fn one_huge_velocity_cell_does_not_hang_the_analysis() {
    let _ = explain_poisoned("vx_1e100", |s| s.x[6] = 1e100);
}

/// `u1 = 1e200` panicked in plotters (colormaps.rs, unwrap on None) after
/// part of the outputs was written: a heat-map cell whose RMS overflowed to
/// NaN has no colour, and a series axis to 1e200 flattens the rest. Here
/// the analysis survives the cell; the figures are then drawn from numbers
/// made as bad as they can get (NaN cells, a 1e200 point): drawn, not a
/// panic.
#[test]
fn one_huge_rotor_command_does_not_panic_the_figures() {
    let mut ex = explain_poisoned("u1_1e200", |s| s.u[0] = 1e200).unwrap();
    let loc = ex.location_before.as_mut().unwrap();
    let mut poisoned = 0;
    for cell in loc.heat.iter_mut().flatten() {
        if cell[0].samples > 0 {
            for c in cell.iter_mut() {
                c.rms = f64::NAN;
            }
            poisoned += 1;
        }
    }
    assert!(poisoned > 0);
    let series = ex.series.as_mut().unwrap();
    series.recording[series.t.len() / 2] = 1e200;
    series.nominal[0] = f64::INFINITY;
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("figures_1e200");
    write_all(&ex, &dir).unwrap();
    for png in ["heatmap_before.png", "timeseries.png", "effects.png"] {
        assert!(dir.join(png).metadata().unwrap().len() > 1000, "{png}");
    }
}
