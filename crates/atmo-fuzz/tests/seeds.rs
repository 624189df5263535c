//! The seeds reach past the parsers' first checks (a seed refused at its
//! first byte gives the fuzzer nothing to start from), and every committed
//! input, findings included, runs through its target without a crash.
#![allow(clippy::unwrap_used, reason = "test")]

use std::path::PathBuf;

use atmo_core::ConfigFile as _;
use atmo_fuzz::corpus_dir as corpus;

#[test]
fn every_committed_input_runs_without_a_crash() {
    for (name, target) in atmo_fuzz::TARGETS {
        let files = atmo_fuzz::corpus_files(&[corpus(name)]);
        assert!(!files.is_empty(), "{name}: no seeds");
        for file in files {
            target(&std::fs::read(&file).unwrap());
        }
    }
}

/// The TOML seeds are the shipped config files behind their selector byte
/// (`cargo run -p atmo-fuzz --example write_seeds` copies them): a seed of
/// an older format is refused at once and gives the fuzzer nothing.
#[test]
fn the_config_seeds_are_the_shipped_config_files() {
    let config = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../config");
    for file in atmo_fuzz::corpus_files(&[corpus("config_toml")]) {
        let name = file.file_name().unwrap().to_str().unwrap();
        let shipped = config.join(&name[2..]);
        let seed = std::fs::read(&file).unwrap();
        assert!(
            seed[1..] == std::fs::read(&shipped).unwrap()[..],
            "{name} is not {} any more: run `cargo run -p atmo-fuzz --example write_seeds`",
            shipped.display()
        );
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
            2 => atmo_flight::FlightSettings::from_toml_str(text, &file).is_ok(),
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

/// The hostile reproductions committed as seeds end as the reader contract
/// says: counted skips or an error naming the line.
#[test]
fn the_hostile_seeds_end_in_counted_skips_or_named_errors() {
    use atmo_explain::recording::Recording;
    let dir = corpus("recording_csv");
    let load = |name: &str| Recording::load(dir.join(name));
    let rec = load("hostile_nf_t_1e300.csv").unwrap();
    assert_eq!((rec.samples.len(), rec.skipped_time), (2, 1));
    for name in ["hostile_nf_r_zero.csv", "hostile_nf_r_reflection.csv"] {
        let rec = load(name).unwrap();
        assert_eq!((rec.samples.len(), rec.skipped_rotation), (1, 1), "{name}");
    }
    let rec = load("hostile_t_1e300.csv").unwrap();
    assert_eq!((rec.samples.len(), rec.skipped_time), (5, 1));
    let err = load("hostile_t_ms.csv").unwrap_err().to_string();
    assert!(
        err.contains("column t") && err.contains("milliseconds"),
        "{err}"
    );
    let err = load("hostile_duplicate_column.csv")
        .unwrap_err()
        .to_string();
    assert!(err.contains("column `c7` appears twice"), "{err}");
    // The glitch row is within the plausible ranges: the reader keeps it,
    // the analysis's neighbour check (which knows the robot) drops it.
    let rec = load("hostile_glitch.csv").unwrap();
    let bounds = atmo_explain::recording::contract::JumpBounds::of(&atmo_core::RobotConfig::atmo());
    let (_, jumps) = atmo_explain::recording::contract::find_jumps(&rec, &bounds).unwrap();
    assert_eq!(jumps.rows, 1);
    assert_eq!(
        jumps.describe(),
        "vx 1 (first at line 4: 9.9e1), wx 1 (first at line 4: 9.9e1)"
    );

    // Configs: an array longer than its fixed size is refused naming the key.
    let robot = std::fs::read_to_string(
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../config/atmo.toml"),
    )
    .unwrap();
    let long = robot.replacen(
        "yaw_sign = [1.0, 1.0, -1.0, -1.0]",
        "yaw_sign = [1.0, 1.0, -1.0, -1.0, 1.0, \"x\"]",
        1,
    );
    let mut input = vec![0u8];
    input.extend_from_slice(long.as_bytes());
    atmo_fuzz::config_toml(&input);
    let err = atmo_core::RobotConfig::from_toml_str(&long, "r.toml")
        .unwrap_err()
        .to_string();
    assert!(err.contains("rotor.yaw_sign"), "{err}");
}
