//! Fuzz targets for every parser of outside input.
//!
//! Each target takes arbitrary bytes and must neither panic, abort, hang
//! nor allocate without bound; where a parser documents a guarantee, the
//! target checks it too (a failed check is a crash):
//!
//! - [`recording_csv`]: the recording CSV reader of atmo-explain (its own
//!   format and Neural-Fly logs, chosen by the header as `Recording::load`
//!   does). Accepted rows are finite with strictly increasing time; errors
//!   name the file.
//! - [`config_toml`]: the TOML loaders through `ConfigFile::from_toml_str`
//!   (first byte picks robot, plant, flight, daemon or MPC; the rest is the
//!   file). Errors name the file.
//! - [`cdr_decode`]: `atmo_io::msg::decode` of every message type (first
//!   byte picks the type). A decoded message encodes, and its encoding
//!   decodes and encodes to the same bytes.
//! - [`mcap_read`]: the MCAP readers (`read_log`, the lossy readers,
//!   `read_topic` as atmo-explain uses it). A log `read_log` accepts reads
//!   the same through `read_log_lossy` with nothing skipped.
//! - [`mcap_recover`]: `recover`. What it writes is itself a log that
//!   `recover` copies whole.
//!
//! Where they run (docs/fuzzing.md): `cargo test` runs each on a bounded
//! number of mutated seeds (tests/mutated_seeds.rs, proptest: no coverage
//! guidance, shrinks a failure to the smallest mutation); the `fuzz/` crate
//! (its own workspace) builds them as cargo-afl binaries for coverage-guided
//! campaigns (scripts/fuzz.sh). Seeds: `fuzz/corpus/<target>/`
//! ([`corpus_dir`]).

use std::path::{Path, PathBuf};

use atmo_core::ConfigFile as _;
use atmo_io::mcap_log::{read_log, read_log_lossy, read_topic_lossy, recover};
use atmo_io::msg::{self, RosMessage};

/// A fuzz target: panics (or aborts) on a finding.
pub type Target = fn(&[u8]);

/// Every target by name (the binaries, the corpus folders, scripts/fuzz.sh).
pub const TARGETS: [(&str, Target); 5] = [
    ("recording_csv", recording_csv),
    ("config_toml", config_toml),
    ("cdr_decode", cdr_decode),
    ("mcap_read", mcap_read),
    ("mcap_recover", mcap_recover),
];

/// The file name the text targets give their input (errors must name it).
const INPUT_NAME: &str = "fuzz-input";

/// The committed seed folder of a target (the MCAP targets share one).
pub fn corpus_dir(target: &str) -> PathBuf {
    let folder = if target.starts_with("mcap_") {
        "mcap"
    } else {
        target
    };
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../fuzz/corpus")
        .join(folder)
}

/// The files of `paths`, folders expanded one level, sorted.
pub fn corpus_files(paths: &[PathBuf]) -> Vec<PathBuf> {
    let mut files = Vec::new();
    for path in paths {
        if path.is_dir() {
            let entries = std::fs::read_dir(path)
                .unwrap_or_else(|e| panic!("cannot list {}: {e}", path.display()));
            files.extend(
                entries
                    .filter_map(std::result::Result::ok)
                    .map(|e| e.path())
                    .filter(|p| p.is_file()),
            );
        } else {
            files.push(path.clone());
        }
    }
    files.sort();
    files
}

/// Asserts that an error message names the input file.
fn assert_names_input(error: &dyn std::fmt::Display) {
    let text = error.to_string();
    assert!(
        text.contains(INPUT_NAME),
        "error does not name the file: {text}"
    );
}

/// The recording CSV reader.
pub fn recording_csv(data: &[u8]) {
    use atmo_explain::recording::{Recording, contract, neural_fly};
    // Not UTF-8: `Recording::load` refuses it before parsing.
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let header = text.lines().find(|l| !l.trim().is_empty()).unwrap_or("");
    let read = if neural_fly::is_neural_fly_header(header) {
        neural_fly::from_neural_fly_str(text, INPUT_NAME)
    } else {
        Recording::from_csv_str(text, INPUT_NAME)
    };
    let rec = match read {
        Ok(rec) => rec,
        Err(e) => return assert_names_input(&e),
    };
    for s in &rec.samples {
        let values = [s.t, s.varphi, s.ground_z]
            .into_iter()
            .chain(s.x.iter().copied())
            .chain(s.u.iter().copied());
        for v in values {
            assert!(v.is_finite(), "accepted a non-finite value: {s:?}");
        }
    }
    for w in rec.samples.windows(2) {
        assert!(
            w[1].t > w[0].t,
            "time does not increase: {} {}",
            w[0].t,
            w[1].t
        );
    }
    // The reader contract (docs/input-contract.md) holds for what is accepted.
    assert_eq!(rec.at.len(), rec.samples.len(), "origins out of step");
    if let Err(e) = contract::check_time_axis(&rec) {
        panic!("accepted a time axis the contract refuses: {e}");
    }
    let bounds = contract::JumpBounds::of(&atmo_core::RobotConfig::atmo());
    let _ = contract::find_jumps(&rec, &bounds);
    let _ = rec.median_dt();
    let _ = rec.to_csv();
}

/// The TOML loaders; the first byte picks the file kind.
pub fn config_toml(data: &[u8]) {
    let Some((&kind, rest)) = data.split_first() else {
        return;
    };
    let Ok(text) = std::str::from_utf8(rest) else {
        return;
    };
    let file = Path::new(INPUT_NAME);
    let error = match kind % 5 {
        0 => atmo_core::RobotConfig::from_toml_str(text, file)
            .err()
            .map(|e| e.to_string()),
        1 => atmo_plant::PlantConfig::from_toml_str(text, file)
            .err()
            .map(|e| e.to_string()),
        2 => atmo_flight::FlightSettings::from_toml_str(text, file)
            .err()
            .map(|e| e.to_string()),
        3 => atmo_daemon::onboard::DaemonConfig::from_toml_str(text, file)
            .err()
            .map(|e| e.to_string()),
        _ => match atmo_mpc::MpcFile::from_toml_str(text, file) {
            Ok(mpc) => {
                // Every preset becomes settings or a named error.
                for name in mpc.presets.keys() {
                    let _ = mpc.settings(name);
                }
                None
            }
            Err(e) => Some(e.to_string()),
        },
    };
    if let Some(e) = error {
        assert_names_input(&e);
    }
}

/// Decodes as `M`; a decoded message must round-trip.
fn cdr_round_trip<M: RosMessage>(payload: &[u8]) -> Option<M> {
    let message = msg::decode::<M>("/fuzz", payload).ok()?;
    let bytes = msg::encode_to_vec(&message)
        .unwrap_or_else(|e| panic!("a decoded {} does not encode: {e}", M::TYPE_NAME));
    let again = msg::decode::<M>("/fuzz", &bytes)
        .unwrap_or_else(|e| panic!("an encoded {} does not decode: {e}", M::TYPE_NAME));
    let bytes_again = msg::encode_to_vec(&again).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(bytes, bytes_again, "{} does not round-trip", M::TYPE_NAME);
    Some(message)
}

/// The CDR decoders; the first byte picks the message type.
pub fn cdr_decode(data: &[u8]) {
    use atmo_io::msg::frames;
    let Some((&kind, payload)) = data.split_first() else {
        return;
    };
    match kind % 20 {
        0 => drop(cdr_round_trip::<msg::MpcStatus>(payload)),
        1 => drop(cdr_round_trip::<msg::PilotInput>(payload)),
        2 => drop(cdr_round_trip::<msg::TickTiming>(payload)),
        3 => drop(cdr_round_trip::<msg::IoHealth>(payload)),
        4 => {
            if let Some(odom) = cdr_round_trip::<msg::VehicleOdometry>(payload) {
                let _ = frames::vehicle_odometry_to_state("/fuzz", &odom);
            }
        }
        5 => drop(cdr_round_trip::<msg::ActuatorMotors>(payload)),
        6 => drop(cdr_round_trip::<msg::OffboardControlMode>(payload)),
        7 => drop(cdr_round_trip::<msg::Twist>(payload)),
        8 => {
            if let Some(odom) = cdr_round_trip::<msg::Odometry>(payload) {
                let _ = frames::odometry_to_state("/fuzz", &odom);
            }
        }
        9 => drop(cdr_round_trip::<msg::DiagnosticArray>(payload)),
        10 => drop(cdr_round_trip::<msg::DiagnosticStatus>(payload)),
        11 => drop(cdr_round_trip::<msg::KeyValue>(payload)),
        12 => drop(cdr_round_trip::<msg::Header>(payload)),
        13 => drop(cdr_round_trip::<msg::Time>(payload)),
        14 => drop(cdr_round_trip::<msg::Vector3>(payload)),
        15 => drop(cdr_round_trip::<msg::Point>(payload)),
        16 => drop(cdr_round_trip::<msg::Quaternion>(payload)),
        17 => drop(cdr_round_trip::<msg::Pose>(payload)),
        18 => drop(cdr_round_trip::<msg::PoseWithCovariance>(payload)),
        _ => drop(cdr_round_trip::<msg::TwistWithCovariance>(payload)),
    }
}

/// A scratch file of this process and thread (the readers take paths;
/// `cargo test` runs targets on several threads at once).
fn scratch(name: &str) -> PathBuf {
    let thread = format!("{:?}", std::thread::current().id());
    let thread: String = thread.chars().filter(char::is_ascii_digit).collect();
    let dir = std::env::temp_dir().join(format!("atmo-fuzz-{}-{thread}", std::process::id()));
    std::fs::create_dir_all(&dir)
        .unwrap_or_else(|e| panic!("cannot create {}: {e}", dir.display()));
    dir.join(name)
}

fn write_input(data: &[u8]) -> PathBuf {
    let path = scratch("input.mcap");
    std::fs::write(&path, data).unwrap_or_else(|e| panic!("cannot write {}: {e}", path.display()));
    path
}

/// The MCAP readers.
pub fn mcap_read(data: &[u8]) {
    let path = write_input(data);
    let lossy = read_log_lossy(&path);
    if let Ok(strict) = read_log(&path) {
        let Ok((messages, integrity)) = &lossy else {
            panic!("read_log accepts what read_log_lossy refuses: {lossy:?}");
        };
        assert!(integrity.is_sound(), "read_log accepted {integrity}");
        assert_eq!(
            strict.len(),
            messages.len(),
            "read_log and read_log_lossy differ"
        );
    }
    let _ = read_topic_lossy::<msg::MpcStatus>(&path, atmo_explain::recording::STATUS_TOPIC);
    let _ = atmo_explain::recording::Recording::from_mcap(&path);
}

/// `recover`, and `recover` of what it wrote.
pub fn mcap_recover(data: &[u8]) {
    let input = write_input(data);
    let first = scratch("recovered.mcap");
    let Ok(report) = recover(&input, &first) else {
        return;
    };
    let second = scratch("recovered-again.mcap");
    let again = recover(&first, &second)
        .unwrap_or_else(|e| panic!("recover's own output does not recover: {e}"));
    assert_eq!(
        (again.messages, again.channels, again.stopped_by.as_deref()),
        (report.messages, report.channels, None),
        "recover's output is not copied whole"
    );
    let _ = read_log_lossy(&first);
}
