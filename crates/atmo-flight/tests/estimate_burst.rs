//! The SITL flight that fell (CI, 2026-12-04; reproduced the same day under
//! three busy loops on 2 cores): two motion-capture estimates accepted
//! 39 us apart, the disturbance observer differenced them over that `dt`,
//! its force estimate jumped to its limits, the MPC cut the thrust to zero
//! at 0.78 m and ATMO hit the ground at 2.6 m/s. The fixture
//! (`tests/data/sitl_estimate_burst.mcap`) is that flight's log, written by
//! the daemon of fc7d04b (`atmo-sim` test
//! `sitl::the_daemon_binary_lands_on_the_wheels_against_the_plant_server`).
//!
//! The log predates the observer's `min_interval` and the flare's present
//! design (configuration schema 1). It is replayed as it is: the library
//! migrates its `[flare]` to schema 2 (the flight fell at 0.78 m, before
//! any flare could act) and `min_interval` takes its default, 0, the rule
//! the flight flew with; the replay is the logged flight bit for bit,
//! collapse included. With the shipped `min_interval` set on the parsed
//! settings (the only change), the thrust after the burst stays near
//! hover (0.52 a rotor against the logged 0.02).
// Test code: an unwrap that fails is the failure report.
#![allow(clippy::unwrap_used)]

use std::path::Path;

use atmo_flight::replay::{CutReplay, RecordedFlight, replay};
use atmo_flight::settings::FlightSettings;

/// The burst: tick 356 took the estimate accepted 39 us after tick 355's.
const BURST_TICK: u64 = 356;

fn flight() -> RecordedFlight {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/sitl_estimate_burst.mcap");
    RecordedFlight::read(path, "/atmo/status").unwrap()
}

/// Mean rotor command of the five ticks after the burst (their estimates
/// still show the robot descending at 0.3 m/s as commanded: the fall it
/// caused starts later), as logged and as replayed with the observer's
/// `min_interval` as logged (`None`) or set to a value.
fn thrust_after_the_burst(min_interval: Option<f64>) -> (f64, f64, bool) {
    let flight = flight();
    let mut config = RecordedFlight::config(&flight.files).unwrap();
    if let Some(interval) = min_interval {
        config.flight.observer.min_interval = interval;
    }
    let (mut logged, mut replayed, mut n) = (0.0, 0.0, 0.0);
    let report = replay(&flight, &config, CutReplay::AsLogged, |pair| {
        if (BURST_TICK + 1..=BURST_TICK + 5).contains(&pair.tick) {
            logged += pair.logged.thrust.iter().sum::<f64>() / 4.0;
            replayed += pair.replayed.thrust.iter().sum::<f64>() / 4.0;
            n += 1.0;
        }
    })
    .unwrap();
    assert_eq!(n, 5.0);
    (logged / n, replayed / n, report.identical())
}

/// The log records no schema version and has the hold-and-commit flare:
/// schema 1, migrated by the library; the key added since reads as its
/// default.
#[test]
fn the_fixture_is_read_as_schema_1_and_migrated_by_the_library() {
    let flight = flight();
    assert_eq!(flight.files.schema_version, 1);
    assert_eq!(
        flight.files.migrated.len(),
        1,
        "{:?}",
        flight.files.migrated
    );
    assert!(flight.files.migrated[0].starts_with("[flare] of schema 1"));
    assert!(!flight.files.flight.text.contains("min_interval"));
    let config = RecordedFlight::config(&flight.files).unwrap();
    assert_eq!(config.flight.observer.min_interval, 0.0);
    assert!(FlightSettings::atmo().observer.min_interval > 0.0);
}

#[test]
fn the_logged_config_replays_the_fall_bit_for_bit() {
    let (logged, replayed, identical) = thrust_after_the_burst(None);
    assert!(identical, "the fixture no longer replays as logged");
    assert_eq!(logged.to_bits(), replayed.to_bits());
    // What fell: the rotors near zero after the burst.
    assert!(
        logged < 0.1,
        "logged mean thrust after the burst {logged:.3}"
    );
}

#[test]
fn with_min_interval_the_burst_leaves_the_thrust_at_hover() {
    let shipped = FlightSettings::atmo().observer.min_interval;
    let (logged, replayed, identical) = thrust_after_the_burst(Some(shipped));
    assert!(!identical);
    println!(
        "mean rotor command after the burst: logged {logged:.3}, with min_interval {replayed:.3}"
    );
    // Hover at 31 deg of tilt is about 0.57 a rotor (the ticks before).
    assert!(
        (0.45..0.75).contains(&replayed),
        "replayed mean thrust after the burst {replayed:.3}"
    );
}
