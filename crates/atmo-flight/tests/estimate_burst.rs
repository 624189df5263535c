//! The SITL flight that fell (CI, 2026-12-04; reproduced the same day under
//! three busy loops on 2 cores): two motion-capture estimates accepted
//! 39 us apart, the disturbance observer differenced them over that `dt`,
//! its force estimate jumped to its limits, the MPC cut the thrust to zero
//! at 0.78 m and ATMO hit the ground at 2.6 m/s. The fixture
//! (`tests/data/sitl_estimate_burst.mcap`) is that flight's log, written by
//! the daemon of fc7d04b (`atmo-sim` test
//! `sitl::the_daemon_binary_lands_on_the_wheels_against_the_plant_server`).
//!
//! Replayed open loop with its own configuration plus the observer's
//! `min_interval` (the only change), the thrust after the burst stays near
//! hover (0.52 a rotor against the logged 0.02); with `min_interval = 0`
//! (the old rule) the replay is the logged flight bit for bit, collapse
//! included.
// Test code: an unwrap that fails is the failure report.
#![allow(clippy::unwrap_used)]

use std::path::Path;

use atmo_flight::replay::{CutReplay, RecordedFlight, replay};

/// The burst: tick 356 took the estimate accepted 39 us after tick 355's.
const BURST_TICK: u64 = 356;

/// The fixture. Its logged flight.toml predates `min_interval` and the
/// flare's present keys, which the current parser requires: the tests add
/// `min_interval` and take the shipped `[flare]` (the flight fell at
/// 0.78 m, before any flare could act).
fn flight() -> RecordedFlight {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/sitl_estimate_burst.mcap");
    RecordedFlight::read(path, "/atmo/status").unwrap()
}

/// Adds `keys` (TOML lines) to the logged `text` after its first `anchor`.
fn add_keys_after(text: &mut String, anchor: &str, keys: &str) {
    assert!(text.contains(anchor), "the logged flight.toml changed");
    *text = text.replacen(anchor, &format!("{anchor}\n{keys}"), 1);
}

/// The byte range of the table `header` in a TOML `text`: from its header
/// line up to the next table's (or the end).
fn section_range(text: &str, header: &str) -> Option<std::ops::Range<usize>> {
    let a = text.find(&format!("\n{header}\n"))? + 1;
    let b = text[a + 1..]
        .find("\n[")
        .map_or(text.len(), |i| a + 1 + i + 1);
    Some(a..b)
}

/// The shipped config/flight.toml's table `header`, alone.
fn shipped_section(header: &str) -> String {
    let shipped = include_str!("../../../config/flight.toml");
    let range = section_range(shipped, header).expect("shipped section");
    shipped[range].to_string()
}

/// Replaces the logged `text`'s table `header` with `section`.
fn replace_section(text: &mut String, header: &str, section: &str) {
    let range = section_range(text, header).expect("the logged flight.toml changed");
    text.replace_range(range, section);
}

/// Mean rotor command of the five ticks after the burst (their estimates
/// still show the robot descending at 0.3 m/s as commanded: the fall it
/// caused starts later), as logged and as replayed with the observer's
/// `min_interval` set to `min_interval`.
fn thrust_after_the_burst(min_interval: &str) -> (f64, f64, bool) {
    let flight = flight();
    let mut files = flight.files.clone();
    let text = &mut files.flight.text;
    add_keys_after(
        text,
        "max_torque = 1.0",
        &format!("min_interval = {min_interval}"),
    );
    // The shipped [flare] table alone: the tables after it in today's file
    // (the actuator monitor's) are not this log's.
    replace_section(text, "[flare]", &shipped_section("[flare]"));
    let config = RecordedFlight::config(&files).unwrap();
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

/// A log flown before a required key is read; only parsing its
/// configuration refuses it, naming the key.
#[test]
fn the_fixture_is_read_and_its_config_refused_for_the_missing_key() {
    let e = RecordedFlight::config(&flight().files)
        .expect_err("the logged flight.toml lacks min_interval")
        .to_string();
    assert!(e.contains("min_interval"), "{e}");
}

#[test]
fn the_old_rule_replays_the_fall_bit_for_bit() {
    let (logged, replayed, identical) = thrust_after_the_burst("0.0");
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
    let (logged, replayed, identical) = thrust_after_the_burst("0.004");
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
