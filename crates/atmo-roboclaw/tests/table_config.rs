//! The counts-to-tilt table (interpolation, inversion, validation) and the
//! driver file's strict loading.
#![allow(clippy::unwrap_used)]

mod common;

use std::path::Path;

use atmo_core::ConfigFile;
use atmo_roboclaw::RoboclawError;
use atmo_roboclaw::config::{Mode, RoboclawConfig};
use atmo_roboclaw::table::{AUTHORS_TABLE_COUNTS, AUTHORS_TABLE_TILT_DEG, TiltTable};

fn err_text(e: &RoboclawError) -> String {
    e.to_string()
}

#[test]
fn the_authors_table_interpolates_like_numpy_interp() {
    let t = TiltTable::authors();
    let deg = |c: f64| t.tilt_from_counts(c).0.to_degrees();
    assert!((deg(0.0) - 90.0).abs() < 1e-12);
    assert!((deg(26325.0) - 0.8).abs() < 1e-12);
    // Halfway between 3696 (86.6 deg) and 5551 (84.0 deg).
    assert!((deg(f64::midpoint(3696.0, 5551.0)) - 85.3).abs() < 1e-9);
    // Every point exactly.
    for (c, a) in AUTHORS_TABLE_COUNTS.iter().zip(AUTHORS_TABLE_TILT_DEG) {
        assert!((deg(*c) - a).abs() < 1e-9, "{c}");
    }
    // Outside: held at the end value and flagged.
    assert_eq!(t.tilt_from_counts(-10.0), (90f64.to_radians(), true));
    assert_eq!(t.tilt_from_counts(30000.0), (0.8f64.to_radians(), true));
    assert!(t.tilt_from_counts(f64::NAN).1);
    assert!(!t.tilt_from_counts(100.0).1);
}

#[test]
fn the_table_inverts_and_its_slope_is_the_segments() {
    let t = TiltTable::authors();
    for i in 0..=1000 {
        let c = 26325.0 * f64::from(i) / 1000.0;
        let (tilt, _) = t.tilt_from_counts(c);
        assert!((t.counts_from_tilt(tilt) - c).abs() < 1e-6, "{c}");
    }
    // Between 0 and 3696 counts the tilt falls 3.4 deg.
    let slope = t.counts_per_rad(88f64.to_radians());
    assert!(
        (slope + 3696.0 / 3.4f64.to_radians()).abs() < 1e-6,
        "{slope}"
    );
    // Monotone: more counts, less tilt, everywhere.
    assert!((1..=89).all(|d| t.counts_per_rad(f64::from(d).to_radians()) < 0.0));
    assert_eq!(t.tilt_range().0, 0.8f64.to_radians());
}

fn table_error(counts: &[f64], tilt: &[f64]) -> String {
    err_text(&TiltTable::new(counts, tilt, Path::new("tilt.toml"), "tilt.").unwrap_err())
}

#[test]
fn table_validation_names_file_key_and_point() {
    let e = table_error(&[0.0, 10.0, 10.0], &[90.0, 50.0, 10.0]);
    assert!(
        e.starts_with("tilt.toml: key `tilt.table_counts[2]`"),
        "{e}"
    );
    assert!(e.contains("strictly increasing"), "{e}");
    let e = table_error(&[0.0, 10.0, 20.0], &[95.0, 50.0, 10.0]);
    assert!(
        e.contains("`tilt.table_tilt_deg[0]`") && e.contains("[0, 90] deg"),
        "{e}"
    );
    let e = table_error(&[0.0, 10.0, 20.0], &[90.0, 50.0, 60.0]);
    assert!(
        e.contains("`tilt.table_tilt_deg[2]`") && e.contains("falling"),
        "{e}"
    );
    let e = table_error(&[0.0, 10.0, 20.0], &[90.0, 90.0, 60.0]);
    assert!(e.contains("`tilt.table_tilt_deg[1]`"), "{e}");
    let e = table_error(&[0.0, 10.0], &[90.0, 50.0, 10.0]);
    assert!(
        e.contains("`tilt.table_tilt_deg`") && e.contains("as many points"),
        "{e}"
    );
    let e = table_error(&[0.0], &[90.0]);
    assert!(e.contains("at least 2 points"), "{e}");
    let e = table_error(&[0.0, f64::NAN], &[90.0, 10.0]);
    assert!(e.contains("`tilt.table_counts[1]`"), "{e}");
    // Rising angles are fine (an encoder counting the other way).
    assert!(TiltTable::new(&[0.0, 5.0], &[10.0, 80.0], Path::new("t"), "").is_ok());
}

#[test]
fn the_example_files_load() {
    let tilt = RoboclawConfig::load(common::repo_config("drivers/tilt.toml")).unwrap();
    assert_eq!(tilt.mode, Mode::Tilt);
    assert!(
        tilt.tilt
            .as_ref()
            .unwrap()
            .robot_file
            .ends_with("drivers/../atmo.toml")
    );
    let settings = atmo_roboclaw::driver::DriverSettings::from_config(&tilt).unwrap();
    assert_eq!(settings.board_serial_timeout, 5);
    let wheels = RoboclawConfig::load(common::repo_config("drivers/wheels.toml")).unwrap();
    assert_eq!(wheels.mode, Mode::Wheels);
}

fn load_error(edit: impl Fn(String) -> String) -> String {
    let path = common::repo_config("drivers/tilt.toml");
    let text = edit(std::fs::read_to_string(&path).unwrap());
    err_text(&RoboclawConfig::from_toml_str(&text, "tilt.toml").unwrap_err())
}

#[test]
fn the_driver_file_is_strict() {
    let e = load_error(|t| t.replace("retries = 2", "retries = 2\nretry = 3"));
    assert!(e.contains("tilt.toml") && e.contains("serial.retry"), "{e}");
    let e = load_error(|t| {
        t.replace(
            "board_serial_timeout_ms = 500",
            "board_serial_timeout_ms = 250",
        )
    });
    assert!(
        e.contains("`timing.board_serial_timeout_ms`") && e.contains("multiple of 100"),
        "{e}"
    );
    let e = load_error(|t| t.replace("required = [\"tilt\"]", "required = [\"tilts\"]"));
    assert!(e.contains("tilt.toml: key `ports.required[0]`"), "{e}");
    let e = load_error(|t| t.replace("address = 128", "address = 7"));
    assert!(e.contains("`serial.address`"), "{e}");
    let e = load_error(|t| t.replace("mode = \"tilt\"", "mode = \"wheels\""));
    assert!(e.contains("`wheels`"), "{e}");
    let e = load_error(|t| t.replace("mode = \"tilt\"", "mode = \"tilted\""));
    assert!(e.contains("`mode`"), "{e}");
    let e = load_error(|t| {
        t.replace(
            "homing_speed_counts_per_s = 2000.0",
            "homing_speed_counts_per_s = 9000.0",
        )
    });
    assert!(e.contains("`tilt.homing_speed_counts_per_s`"), "{e}");
    let e = load_error(|t| t.replace("[0, 3696, 5551,", "[0, 3696, 3000,"));
    assert!(e.contains("`tilt.table_counts[2]`"), "{e}");
    let e = load_error(|t| t.replace("calibration = \"table\"", "calibration = \"linkage\""));
    assert!(e.contains("no table with calibration = \"linkage\""), "{e}");
}

#[test]
fn the_linkage_calibration_follows_the_model() {
    let path = common::repo_config("drivers/tilt.toml");
    let text = std::fs::read_to_string(&path)
        .unwrap()
        .replace("calibration = \"table\"", "calibration = \"linkage\"")
        .lines()
        .filter(|l| !l.starts_with("table_"))
        .collect::<Vec<_>>()
        .join("\n");
    let config = RoboclawConfig::from_toml_str(&text, &path).unwrap();
    let cal = config.tilt_calibration().unwrap().unwrap();
    // Board 0 at home (90 deg); counting up towards 0 deg.
    let home = cal.read(0.0);
    assert!((home.tilt.to_degrees() - 90.0).abs() < 1e-6);
    let at_45 = cal.read(home.model_counts / 2.0);
    assert!(at_45.tilt > 0.0 && at_45.tilt < 90f64.to_radians());
    let far = cal.read(home.model_counts + 1.0);
    assert!(far.outside && far.tilt.abs() < 1e-9);
    assert!(cal.counts_per_rad(0.5) < 0.0);
    board_counts_invert_the_reading(&cal);
}

/// `board_counts` is the inverse of `read` over the calibrated range.
fn board_counts_invert_the_reading(cal: &atmo_roboclaw::table::TiltCalibration) {
    let (lo, hi) = cal.tilt_range();
    for i in 0..=40 {
        let tilt = lo + (hi - lo) * f64::from(i) / 40.0;
        let back = cal.read(cal.board_counts(tilt)).tilt;
        assert!((back - tilt).abs() < 1e-9, "{tilt} -> {back}");
    }
}

#[test]
fn board_counts_invert_the_table_calibration() {
    let config = RoboclawConfig::load(common::repo_config("drivers/tilt.toml")).unwrap();
    let cal = config.tilt_calibration().unwrap().unwrap();
    board_counts_invert_the_reading(&cal);
    // Below the table's last point (0.8 deg) the counts hold its end.
    assert_eq!(cal.board_counts(0.0), 26325.0);
}

#[test]
fn the_table_against_the_linkage_model() {
    let robot = atmo_core::RobotConfig::load(common::repo_config("atmo.toml")).unwrap();
    let linkage = atmo_core::Linkage::from_config(&robot.linkage, robot.limits.tilt_max()).unwrap();
    let home = 90f64.to_radians();
    // A table made from the model itself agrees with it.
    let model_home = linkage.counts_from_tilt(home).unwrap();
    let tilt_deg: Vec<f64> = (0..=18).rev().map(|i| f64::from(i) * 5.0).collect();
    let counts: Vec<f64> = tilt_deg
        .iter()
        .map(|d| model_home - linkage.counts_from_tilt(d.to_radians()).unwrap())
        .collect();
    let own = TiltTable::new(&counts, &tilt_deg, Path::new("t"), "").unwrap();
    let cmp = own.compare_with_linkage(&linkage, -1.0, home).unwrap();
    assert_eq!(cmp.beyond_model(), 0);
    assert!(cmp.max_abs().unwrap().0 < 1e-9);
    // The authors' table does not: their counter is not the model's
    // encoder (26325 counts over the travel, against the model's 19929).
    let cmp = TiltTable::authors()
        .compare_with_linkage(&linkage, -1.0, home)
        .unwrap();
    let (worst, at) = cmp.max_abs().unwrap();
    assert!(
        (worst.to_degrees() - 28.3).abs() < 0.1,
        "{}",
        worst.to_degrees()
    );
    assert_eq!(at, 19645.0);
    assert_eq!(cmp.beyond_model(), 10);
    // The example file gives the same through its keys.
    let config = RoboclawConfig::load(common::repo_config("drivers/tilt.toml")).unwrap();
    assert_eq!(config.table_vs_linkage().unwrap().unwrap(), cmp);
}
