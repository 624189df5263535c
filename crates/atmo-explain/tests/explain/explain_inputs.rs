//! The discrepancy finder's input handling and outputs: bad files give
//! clear errors naming the file and the problem (never a panic), odd rows
//! are skipped and counted, and the outputs are written and loadable.
// Helpers outside #[test] functions unwrap too (clippy.toml allows it in tests only).
#![allow(clippy::unwrap_used)]

use std::path::PathBuf;

use atmo_core::{ConfigFile, RobotConfig};
use atmo_explain::effects::Effect;
use atmo_explain::output::write_all;
use atmo_explain::recording::{REQUIRED_COLUMNS, Recording};
use atmo_explain::synth::{Flight, Profile, record};
use atmo_explain::{ExplainError, Options, explain};
use atmo_plant::config::{EffectsConfig, MotorLagConfig, PlantConfig, SensorsConfig};

fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("atmo_explain_{}_{name}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn header() -> String {
    REQUIRED_COLUMNS.join(",")
}

fn row(t: f64) -> String {
    let mut v = vec![format!("{t}")];
    v.extend((0..12).map(|i| {
        if i == 2 {
            "-1.5".to_string()
        } else {
            "0".to_string()
        }
    }));
    v.extend((0..4).map(|_| "0.48".to_string()));
    v.push("0".into());
    v.join(",")
}

/// The error of loading `path` (a test failure if it loads).
fn load_error(path: &std::path::Path) -> ExplainError {
    match Recording::load(path) {
        Ok(_) => panic!("{} loaded but should not", path.display()),
        Err(e) => e,
    }
}

fn message(e: &ExplainError) -> String {
    e.to_string()
}

#[test]
fn empty_file_is_an_error_naming_the_file() {
    let dir = temp_dir("empty");
    let path = dir.join("empty.csv");
    std::fs::write(&path, "").unwrap();
    let err = Recording::load(&path).unwrap_err();
    let msg = message(&err);
    assert!(msg.contains("empty.csv"), "{msg}");
    assert!(msg.contains("empty"), "{msg}");
}

#[test]
fn missing_file_is_an_error() {
    let err = Recording::load("/nonexistent/flight.csv").unwrap_err();
    let msg = message(&err);
    assert!(
        msg.contains("flight.csv") && msg.contains("cannot read"),
        "{msg}"
    );
}

#[test]
fn missing_columns_are_named() {
    let cols: Vec<&str> = REQUIRED_COLUMNS
        .iter()
        .copied()
        .filter(|c| *c != "wz" && *c != "varphi")
        .collect();
    let text = format!("{}\n1,2,3\n", cols.join(","));
    let err = Recording::from_csv_str(&text, "flight.csv").unwrap_err();
    let msg = message(&err);
    assert!(msg.contains("flight.csv"), "{msg}");
    assert!(msg.contains("`wz`") && msg.contains("`varphi`"), "{msg}");
    assert!(msg.contains("missing required columns"), "{msg}");
}

#[test]
fn header_only_is_an_error() {
    let err = Recording::from_csv_str(&format!("{}\n", header()), "h.csv").unwrap_err();
    assert!(
        message(&err).contains("no usable rows: the file holds no data rows"),
        "{}",
        message(&err)
    );
}

/// A recording whose time runs backwards kept one row and said only "too
/// short to analyse: 1 usable rows": the refusal says where the others went.
#[test]
fn a_recording_left_too_short_says_what_was_dropped() {
    let mut text = format!("{}\n", header());
    for k in (0..200).rev() {
        text += &(row(f64::from(k) / 100.0) + "\n");
    }
    let rec = Recording::from_csv_str(&text, "backwards.csv").unwrap();
    assert_eq!((rec.samples.len(), rec.skipped_time), (1, 199));
    let robot = RobotConfig::from_toml_str(
        include_str!("../../../../config/atmo.toml"),
        std::path::Path::new("atmo.toml"),
    )
    .unwrap();
    let Err(err) = atmo_explain::data::Prepared::new(&rec, &robot) else {
        panic!("1 row prepared for the analysis")
    };
    let msg = message(&err);
    assert!(
        msg.contains("too short to analyse: 1 usable rows")
            && msg.contains("dropped 199 not advancing in time"),
        "{msg}"
    );
    let nan = format!("{}\n{}\n", header(), row(f64::NAN));
    let msg = message(&Recording::from_csv_str(&nan, "nan.csv").unwrap_err());
    assert!(
        msg.contains("no usable rows (dropped 1 with a non-finite or missing value)"),
        "{msg}"
    );
}

#[test]
fn bad_rows_are_skipped_and_counted_and_extra_columns_listed() {
    let lines = [
        format!("{},ground_z,temperature", header()),
        format!("{},0,20", row(0.00)),
        format!("{},0,20", row(0.01)),
        format!("{},0,20", row(0.01)), // time does not increase
        format!("{},0,20", row(0.02).replace("-1.5", "NaN")), // non-finite
        format!("{},0,20", row(0.03).replace("-1.5", "abc")), // unparsable
        "0.04,1,2".to_string(),        // truncated row
        format!("{},0,20", row(0.05)),
    ];
    let text = lines.join("\n");
    let rec = Recording::from_csv_str(&text, "f.csv").unwrap();
    assert_eq!(rec.samples.len(), 3);
    assert_eq!(rec.skipped_time, 1);
    assert_eq!(rec.skipped_nonfinite, 3);
    assert_eq!(rec.ignored_columns, vec!["temperature".to_string()]);
}

#[test]
fn binary_and_mcap_inputs_are_errors_not_panics() {
    let dir = temp_dir("binary");
    // A corrupted MCAP (magic bytes then garbage).
    let mcap = dir.join("flight.mcap");
    std::fs::write(&mcap, b"\x89MCAP0\r\n\x01\x02\x03").unwrap();
    let msg = message(&Recording::load(&mcap).unwrap_err());
    assert!(msg.contains("flight.mcap") && msg.contains("MCAP"), "{msg}");
    // Binary garbage named .csv.
    let bin = dir.join("garbage.csv");
    std::fs::write(&bin, [0xff_u8, 0xfe, 0x00, 0x41, 0x80]).unwrap();
    let msg = message(&Recording::load(&bin).unwrap_err());
    assert!(
        msg.contains("garbage.csv") && msg.contains("UTF-8"),
        "{msg}"
    );
}

#[test]
fn too_short_recording_is_an_error() {
    let mut lines = vec![header()];
    lines.extend((0..10).map(|k| row(f64::from(k) * 0.01)));
    let text = lines.join("\n");
    let rec = Recording::from_csv_str(&text, "short.csv").unwrap();
    let err = explain(&rec, &RobotConfig::atmo(), &Options::default()).unwrap_err();
    assert!(message(&err).contains("too short"), "{}", message(&err));
}

/// The ideal plant with the motor lag and the sensors: the recordings the
/// output and MCAP tests write.
fn lagged_plant_with_sensors(robot: &RobotConfig) -> PlantConfig {
    let mut plant = PlantConfig::ideal();
    plant.arm_inertia_convention = robot.arm.inertia_convention;
    plant.effects = EffectsConfig {
        motor_lag: Some(MotorLagConfig::default()),
        sensors: Some(SensorsConfig::default()),
        ..EffectsConfig::none()
    };
    plant
}

#[test]
fn csv_round_trip_and_outputs_are_written_and_loadable() {
    let robot = RobotConfig::atmo();
    let plant = lagged_plant_with_sensors(&robot);
    let rec = record(&robot, &plant, &Flight::new(Profile::Cruise, 24.0, 3)).unwrap();
    let dir = temp_dir("outputs");
    let csv = dir.join("recording.csv");
    std::fs::write(&csv, rec.to_csv()).unwrap();
    let back = Recording::load(&csv).unwrap();
    assert_eq!(back.samples.len(), rec.samples.len());
    assert_eq!(back.skipped_nonfinite + back.skipped_time, 0);
    let ex = explain(&back, &robot, &Options::default()).unwrap();
    assert_eq!(ex.selected(), vec![Effect::MotorLag]);
    write_all(&ex, &dir).unwrap();
    for f in [
        "report.md",
        "explain.json",
        "fitted_effects.toml",
        "heatmap_before.png",
        "heatmap_after.png",
        "timeseries.png",
        "effects.png",
    ] {
        let meta = std::fs::metadata(dir.join(f)).unwrap_or_else(|_| panic!("{f} missing"));
        assert!(meta.len() > 100, "{f} is nearly empty");
    }
    // The plant loads the fitted file and has the effect in it.
    let cfg = PlantConfig::load(dir.join("fitted_effects.toml")).unwrap();
    assert_eq!(cfg.effects.enabled_names(), vec!["motor_lag"]);
    // explain.json has the keys a report promises.
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("explain.json")).unwrap()).unwrap();
    for key in [
        "mismatch_found",
        "located",
        "effects",
        "heldout_rms_before",
        "heldout_rms_after",
        "ground_effect_gain_grid",
    ] {
        assert!(json.get(key).is_some(), "explain.json lacks {key}");
    }
    assert_eq!(json["mismatch_found"], serde_json::Value::Bool(true));
    let effect = &json["effects"][0];
    assert_eq!(effect["name"], "motor_lag");
    assert!(effect["confidence"].as_f64().unwrap() > 0.9);
    assert!(
        effect["parameters"]
            .as_array()
            .is_some_and(|p| !p.is_empty())
    );
    assert_eq!(
        json["ground_effect_gain_grid"].as_array().unwrap().len(),
        20
    );
    let report = std::fs::read_to_string(dir.join("report.md")).unwrap();
    assert!(report.contains("motor_lag") && report.contains("heatmap_before.png"));
}

/// Writes `rec` as the flight stack's MCAP log (one `/atmo/status` per row,
/// estimate age 0, and one tick halfway to the next row that repeats the
/// row's estimate with the commands that make the interval's mean the
/// recording's applied commands: the log carries the command timing the
/// simulator had) and returns the path.
pub(crate) fn write_mcap(rec: &Recording, path: &std::path::Path) {
    use atmo_io::mcap_log::{LoggerOptions, McapLogger};
    use atmo_io::msg::MpcStatus;
    let (log, thread) = McapLogger::spawn(path, LoggerOptions::default()).unwrap();
    let ch = log.channel::<MpcStatus>("/atmo/status").unwrap();
    for (k, s) in rec.samples.iter().enumerate() {
        let stamp_ns = (s.t * 1e9).round() as u64;
        let mut state = [0.0; 12];
        state.copy_from_slice(s.x.as_slice());
        let msg = MpcStatus {
            stamp_ns,
            tick: k as u64,
            state,
            thrust: [s.u[0], s.u[1], s.u[2], s.u[3]],
            varphi: s.varphi,
            height: s.ground_z - s.x[2],
            estimate_age: 0.0,
            ..MpcStatus::default()
        };
        // The logger's queue is bounded: retry until accepted.
        while !log.try_log(ch, stamp_ns, &msg) {
            std::thread::sleep(std::time::Duration::from_millis(1));
        }
        let Some(next) = rec.samples.get(k + 1) else {
            continue;
        };
        let mid_ns = (f64::midpoint(s.t, next.t) * 1e9).round() as u64;
        let second_half = s.applied * 2.0 - s.u;
        let mid = MpcStatus {
            stamp_ns: mid_ns,
            thrust: [
                second_half[0],
                second_half[1],
                second_half[2],
                second_half[3],
            ],
            estimate_age: (mid_ns - stamp_ns) as f64 * 1e-9,
            ..msg
        };
        while !log.try_log(ch, mid_ns, &mid) {
            std::thread::sleep(std::time::Duration::from_millis(1));
        }
    }
    log.finish();
    thread.join().unwrap();
}

#[test]
fn mcap_logs_are_read_and_truncated_ones_are_clear_errors() {
    let robot = RobotConfig::atmo();
    let plant = lagged_plant_with_sensors(&robot);
    let rec = record(&robot, &plant, &Flight::new(Profile::Cruise, 24.0, 4)).unwrap();
    let dir = temp_dir("mcap");
    let path = dir.join("flight.mcap");
    write_mcap(&rec, &path);
    let back = Recording::load(&path).unwrap();
    assert_eq!(back.samples.len(), rec.samples.len());
    for (a, b) in back.samples.iter().zip(&rec.samples) {
        assert!((a.t - b.t).abs() < 1e-8);
        assert_eq!(a.u, b.u);
        assert!((a.x - b.x).norm() < 1e-12);
        assert!((a.varphi - b.varphi).abs() < 1e-12);
        assert!((a.ground_z - b.ground_z).abs() < 1e-9);
    }
    // Read from the log, the concealed lag is what the tool names: the top
    // effect, and nothing else claimed with high confidence (the finder's
    // criterion; on this short 24 s cruise an inertia error of about 5 %
    // can enter at low confidence, 0.3-0.6, depending on the seed).
    let ex = explain(&back, &robot, &Options::default()).unwrap();
    assert_eq!(ex.effects[0].name, Effect::MotorLag);
    assert!(ex.effects[0].selected);
    let others = ex.confidently_claimed_besides(&[Effect::MotorLag]);
    assert!(others.is_empty(), "{others:?} claimed: {}", ex.verdict);

    // Cut short (a killed writer without recovery): a clear error, no panic.
    let bytes = std::fs::read(&path).unwrap();
    let cut = dir.join("cut.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    let msg = message(&load_error(&cut));
    assert!(msg.contains("cut.mcap") && msg.contains("MCAP"), "{msg}");
    // Corrupted: the magic bytes overwritten.
    let mut bad = bytes.clone();
    for b in &mut bad[..8] {
        *b ^= 0x5a;
    }
    let corrupt = dir.join("corrupt.mcap");
    std::fs::write(&corrupt, &bad).unwrap();
    let msg = message(&load_error(&corrupt));
    assert!(
        msg.contains("corrupt.mcap") && msg.contains("MCAP"),
        "{msg}"
    );
    // Empty.
    let empty = dir.join("empty.mcap");
    std::fs::write(&empty, b"").unwrap();
    let msg = message(&load_error(&empty));
    assert!(msg.contains("empty.mcap"), "{msg}");
}

/// A 10-million-row CSV was killed by the kernel at 24 GB
/// resident. A recording past the row limit is refused at the line where
/// the limit was passed, and a file past the size limit before it is read
/// (a sparse file here: nothing is allocated for it).
#[test]
fn recordings_over_the_row_or_file_limit_are_refused() {
    use atmo_explain::recording::{MAX_FILE_BYTES, MAX_ROWS};
    let mut text = header();
    text.push('\n');
    for i in 0..=MAX_ROWS {
        text.push_str(&row(i as f64 * 0.01));
        text.push('\n');
    }
    let err = Recording::from_csv_str(&text, "long.csv")
        .unwrap_err()
        .to_string();
    assert!(
        err.starts_with(&format!(
            "long.csv: line {}: more than {MAX_ROWS} rows",
            MAX_ROWS + 2
        )),
        "{err}"
    );
    drop(text);

    let path = temp_dir("limit").join("huge.csv");
    std::fs::File::create(&path)
        .unwrap()
        .set_len(MAX_FILE_BYTES + 1)
        .unwrap();
    let err = message(&load_error(&path));
    assert!(
        err.contains(&format!(
            "{} bytes, over the {MAX_FILE_BYTES}-byte limit",
            MAX_FILE_BYTES + 1
        )),
        "{err}"
    );
    std::fs::remove_file(&path).unwrap();
}
