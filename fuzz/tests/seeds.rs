//! The seeds reach past the parsers' first checks (a seed refused at its
//! first byte gives the fuzzer nothing to start from), and every committed
//! input, findings included, runs through its target without a crash.
#![allow(clippy::unwrap_used, reason = "test")]

use std::path::{Path, PathBuf};

use atmo_core::ConfigFile as _;

fn corpus(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("corpus")
        .join(name)
}

#[test]
fn every_committed_input_runs_without_a_crash() {
    for (name, target) in atmo_fuzz::TARGETS {
        let dir = corpus(if name.starts_with("mcap_") {
            "mcap"
        } else {
            name
        });
        let files = atmo_fuzz::corpus_files(&[dir]);
        assert!(!files.is_empty(), "{name}: no seeds");
        for file in files {
            target(&std::fs::read(&file).unwrap());
        }
    }
}

#[test]
fn the_text_seeds_are_accepted() {
    for file in atmo_fuzz::corpus_files(&[corpus("config_toml")]) {
        let data = std::fs::read(&file).unwrap();
        let text = std::str::from_utf8(&data[1..]).unwrap();
        let ok = match data[0] {
            0 => atmo_core::RobotConfig::from_toml_str(text, &file).is_ok(),
            1 => atmo_plant::PlantConfig::from_toml_str(text, &file).is_ok(),
            2 => atmo_daemon::FlightSettings::from_toml_str(text, &file).is_ok(),
            3 => atmo_daemon::onboard::DaemonConfig::from_toml_str(text, &file).is_ok(),
            _ => atmo_mpc::MpcFile::from_toml_str(text, &file).is_ok(),
        };
        assert!(ok, "{} is refused", file.display());
    }
    for name in ["own_format.csv", "optional_columns.csv", "neural_fly.csv"] {
        let path = corpus("recording_csv").join(name);
        let rec = atmo_explain::recording::Recording::load(&path).unwrap();
        assert!(
            rec.samples.len() >= 2,
            "{name}: {} samples",
            rec.samples.len()
        );
    }
}

#[test]
fn the_mcap_seeds_hold_messages() {
    let dir = corpus("mcap");
    for name in ["plain.mcap", "zstd.mcap", "lz4.mcap"] {
        let messages = atmo_io::mcap_log::read_log(dir.join(name)).unwrap();
        assert!(messages.len() >= 7, "{name}: {} messages", messages.len());
    }
    let out = std::env::temp_dir().join("atmo-fuzz-seed-recovered.mcap");
    let report = atmo_io::mcap_log::recover(dir.join("truncated.mcap"), &out).unwrap();
    assert!(
        report.messages >= 1 && report.stopped_by.is_some(),
        "{report:?}"
    );
}
