//! Every flight log committed under a `tests` folder of the repository
//! replays through today's flight stack bit for bit, its configuration
//! read as it was logged: keys added since it was flown take their
//! defaults (which reproduce what it flew), keys whose meaning changed are
//! migrated by the library (`atmo_flight::schema`). A config table with a
//! key added to it reads every logged configuration as before.
// Test code: an unwrap that fails is the failure report.
#![allow(clippy::unwrap_used)]

use std::path::{Path, PathBuf};

use atmo_core::config_file::parse_toml;
use atmo_core::params::Params as _;
use atmo_flight::flight_log::CONFIG_METADATA;
use atmo_flight::replay::{CutReplay, RecordedFlight, replay};
use atmo_flight::settings::{FlightSettings, ObserverConfig};
use atmo_io::mcap_log::read_extras;

/// The status topic of every flight log the daemon and the simulator write.
const STATUS_TOPIC: &str = "/atmo/status";

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// Every `*.mcap` below a `tests` folder (outside build output and
/// hidden folders).
fn committed_mcaps(dir: &Path, in_tests: bool, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        let name = path.file_name().unwrap().to_string_lossy().into_owned();
        if path.is_dir() {
            if !name.starts_with('.') && name != "target" {
                committed_mcaps(&path, in_tests || name == "tests", out);
            }
        } else if in_tests
            && path
                .extension()
                .is_some_and(|e| e.eq_ignore_ascii_case("mcap"))
        {
            out.push(path);
        }
    }
}

/// The committed flight logs: the MCAP files that hold a flight
/// configuration (the others are reader fixtures, not flights).
fn flight_logs() -> Vec<PathBuf> {
    let mut all = Vec::new();
    committed_mcaps(&repo(), false, &mut all);
    all.sort();
    all.into_iter()
        .filter(|p| {
            read_extras(p)
                .ok()
                .is_some_and(|e| e.metadata(CONFIG_METADATA).is_some())
        })
        .collect()
}

/// The declared keys of `FlightSettings` that `text` does not set.
fn keys_added_since(text: &str) -> Vec<String> {
    let doc: toml_edit::DocumentMut = text.parse().unwrap();
    FlightSettings::params()
        .into_iter()
        .map(|p| p.key)
        .filter(|key| {
            let mut item = doc.as_item();
            for part in key.split('.') {
                match item.get(part) {
                    Some(next) => item = next,
                    None => return true,
                }
            }
            false
        })
        .collect()
}

#[test]
fn every_committed_flight_log_replays_bit_for_bit_unpatched() {
    let logs = flight_logs();
    assert!(!logs.is_empty(), "no committed flight log found");
    let mut added_keys_seen = 0;
    for log in &logs {
        let flight = RecordedFlight::read(log, STATUS_TOPIC).unwrap();
        let config = RecordedFlight::config(&flight.files).unwrap();
        let report = replay(&flight, &config, CutReplay::AsLogged, |_| {}).unwrap();
        let added = keys_added_since(&flight.files.flight.text);
        println!(
            "{}: schema {}, {} ticks, identical {}, keys added since: {}",
            log.display(),
            flight.files.schema_version,
            report.ticks,
            report.identical(),
            added.join(", ")
        );
        assert!(report.ticks > 0);
        assert!(report.identical(), "{}: {report:?}", log.display());
        added_keys_seen += added.len();
    }
    // The logs predate keys declared today: the defaults are exercised.
    assert!(added_keys_seen > 0);
}

atmo_core::params! {
    /// `[observer]` with a key added after every committed log was flown.
    #[derive(Debug, Clone, PartialEq)]
    pub struct ObserverWithANewKey {
        pub enabled: bool;
        pub force_gain: f64, range 0.0..=1.0;
        pub torque_gain: f64, range 0.0..=1.0;
        pub max_force: f64, range 0.0..=200.0, unit "N";
        pub max_torque: f64, range 0.0..=20.0, unit "N m";
        pub min_interval: f64 = 0.0, range 0.0..=0.05, unit "s";
        /// The new key: 0 means what files without it flew.
        pub new_key: f64 = 0.0, range 0.0..=1.0;
    }
}

#[test]
fn a_key_added_with_its_default_reads_every_logged_config_as_before() {
    let logs = flight_logs();
    assert!(!logs.is_empty());
    for log in &logs {
        let flight = RecordedFlight::read(log, STATUS_TOPIC).unwrap();
        let doc: toml_edit::DocumentMut = flight.files.flight.text.parse().unwrap();
        let table = doc["observer"].as_table().unwrap().to_string();
        let file = Path::new("observer");
        let before: ObserverConfig = parse_toml(&table, file).unwrap();
        let after: ObserverWithANewKey = parse_toml(&table, file).unwrap();
        atmo_core::params::check_file(&after, file).unwrap();
        assert_eq!(after.new_key, 0.0);
        assert_eq!(
            (after.enabled, after.force_gain, after.torque_gain),
            (before.enabled, before.force_gain, before.torque_gain)
        );
        assert_eq!(
            (after.max_force, after.max_torque, after.min_interval),
            (before.max_force, before.max_torque, before.min_interval)
        );
    }
}
