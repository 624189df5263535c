//! Hostile recordings: one absurd but finite cell gives a
//! defined outcome in bounded time, never a hang.
#![allow(clippy::unwrap_used, reason = "test")]

use atmo_core::RobotConfig;
use atmo_explain::output::write_all;
use atmo_explain::recording::{Recording, Sample};
use atmo_explain::synth::{Flight, Profile, record};
use atmo_explain::{Explanation, Options, explain};
use atmo_plant::config::{EffectsConfig, MotorLagConfig, PlantConfig};

/// Changes a sample in place.
type Poison = fn(&mut Sample);

/// A 24 s cruise at 100 Hz (2400 rows) with a concealed motor lag.
pub(crate) fn cruise_with_motor_lag() -> Recording {
    let robot = RobotConfig::atmo();
    let mut plant = PlantConfig::ideal();
    plant.arm_inertia_convention = robot.arm.inertia_convention;
    plant.effects = EffectsConfig {
        motor_lag: Some(MotorLagConfig::default()),
        ..EffectsConfig::none()
    };
    let rec = record(&robot, &plant, &Flight::new(Profile::Cruise, 24.0, 4)).unwrap();
    assert!(rec.samples.len() >= 2400, "{} rows", rec.samples.len());
    rec
}

/// The names of the effects reported as found.
pub(crate) fn found(ex: &Explanation) -> Vec<&'static str> {
    ex.effects
        .iter()
        .filter(|e| e.selected)
        .map(|e| e.name.name())
        .collect()
}

/// [`cruise_with_motor_lag`] with one cell (row 1002) changed by `poison`;
/// explained, and every output written. `None` if the analysis refused the
/// recording.
fn explain_poisoned(name: &str, poison: impl FnOnce(&mut Sample)) -> Option<Explanation> {
    let robot = RobotConfig::atmo();
    let mut rec = cruise_with_motor_lag();
    poison(&mut rec.samples[1001]);
    match explain(&rec, &robot, &Options::default()) {
        Ok(ex) => {
            for e in &ex.effects {
                assert!(
                    e.confidence.is_none_or(f64::is_finite) && e.selection_frequency.is_finite(),
                    "{}: {:?} {}",
                    e.name,
                    e.confidence,
                    e.selection_frequency
                );
                assert_eq!(e.confidence.is_some(), e.selected, "{}", e.name);
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

/// One `u1 = 1e20` outlier in 2401 rows flipped the verdict to "no
/// significant mismatch" (the noise floor became 3.9e17 m/s^2, no note), and
/// `vx = 1e100` steered it. The outlier rule (`recording::plausible`) drops
/// the row and counts it, naming the column, the row and the value: the
/// verdict and the effects found are those of the clean recording. (The
/// `vx = 1e100` row also made `atmo-sim explain` run forever, in nalgebra's
/// `pseudo_inverse` after the Cholesky solve of the selection failed: the
/// solve is bounded now too, `select::bounded_solve`.)
#[test]
fn one_outlier_row_is_dropped_and_counted_and_the_verdict_stands() {
    let robot = RobotConfig::atmo();
    let clean = explain(&cruise_with_motor_lag(), &robot, &Options::default()).unwrap();
    assert!(clean.mismatch_found, "{}", clean.verdict);
    assert_eq!(clean.outliers.rows, 0);
    for (name, column, value, poison) in [
        (
            "outlier_u1_1e20",
            "u1",
            1e20,
            (|s: &mut Sample| s.u[0] = 1e20) as Poison,
        ),
        ("outlier_vx_1e100", "vx", 1e100, |s: &mut Sample| {
            s.x[6] = 1e100;
        }),
    ] {
        let ex = explain_poisoned(name, poison).unwrap();
        assert_eq!(ex.outliers.rows, 1, "{name}");
        assert_eq!(ex.outliers.columns.len(), 1, "{name}");
        let c = &ex.outliers.columns[0];
        assert_eq!((c.column, c.rows, c.first_value), (column, 1, value));
        assert_eq!(c.first_at, "row 1002");
        assert_eq!(ex.rows, clean.rows - 1, "{name}");
        assert_eq!(ex.verdict, clean.verdict, "{name}");
        assert_eq!(found(&ex), found(&clean), "{name}");
        for (k, (a, b)) in ex.noise_floor.iter().zip(clean.noise_floor).enumerate() {
            assert!(
                (a / b - 1.0).abs() < 0.05,
                "{name}: floor {k}: {a} vs clean {b}"
            );
        }
        let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join(name);
        let report = std::fs::read_to_string(dir.join("report.md")).unwrap();
        assert!(
            report.contains(&format!("Dropped rows: 1 with a cell outside its plausible range (docs/recording_format.md): {column} 1 (first at row 1002: {value:e})")),
            "{report}"
        );
    }
}

/// Rotor commands in PWM microseconds were "explained" as a thrust scale
/// of confidence 1.00, and `varphi = 100` was accepted: a whole column in a
/// wrong unit is refused, from a CSV file (naming the file, line, column and
/// value) and in memory.
#[test]
fn a_column_in_the_wrong_unit_is_refused_naming_it() {
    let robot = RobotConfig::atmo();
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("wrong_units");
    std::fs::create_dir_all(&dir).unwrap();
    let cases: [(&str, Poison, &str); 3] = [
        (
            "pwm",
            |s| {
                s.u = s.u.map(|u| 1000.0 + 1000.0 * u);
                s.applied = s.u;
            },
            "PWM",
        ),
        ("degrees", |s| s.varphi = 100.0, "not degrees"),
        (
            "rates_in_deg_s",
            |s| s.x[9] = s.x[9].to_degrees() + 200.0,
            "not deg/s",
        ),
    ];
    for (name, convert, hint) in cases {
        let mut rec = cruise_with_motor_lag();
        rec.samples.iter_mut().for_each(convert);
        let first = rec.samples[0];
        let column = match name {
            "pwm" => "u1",
            "degrees" => "varphi",
            _ => "wx",
        };
        let value = match name {
            "pwm" => first.u[0],
            "degrees" => first.varphi,
            _ => first.x[9],
        };
        let err = explain(&rec, &robot, &Options::default())
            .unwrap_err()
            .to_string();
        assert!(
            err.contains(&format!(
                "column {column}: {} of {} rows",
                rec.samples.len(),
                rec.samples.len()
            )) && err.contains(&format!("(first at row 1: {column} = {value})"))
                && err.contains(hint),
            "{name}: {err}"
        );
        let path = dir.join(format!("{name}.csv"));
        std::fs::write(&path, rec.to_csv()).unwrap();
        let err = Recording::load(&path).unwrap_err().to_string();
        assert!(
            err.contains(&path.display().to_string())
                && err.contains(&format!("column {column}:"))
                && err.contains(&format!("(first at line 2: {column} = "))
                && err.contains(hint),
            "{name}: {err}"
        );
    }
}

/// The analysis reports when it goes over its wall-clock budget (here a
/// budget no analysis can meet), naming the slowest stage; within budget
/// there is no such note.
#[test]
fn an_analysis_over_its_budget_says_so() {
    let robot = RobotConfig::atmo();
    let rec = cruise_with_motor_lag();
    let opts = Options {
        budget_s: 1e-6,
        ..Options::default()
    };
    let ex = explain(&rec, &robot, &opts).unwrap();
    let note = ex.notes.iter().find(|n| n.contains("wall-clock budget"));
    let note = note.unwrap_or_else(|| panic!("no budget note in {:?}", ex.notes));
    assert!(
        note.contains("over its wall-clock budget of 0.000001 s")
            && note.contains("slowest stage was `"),
        "{note}"
    );
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
