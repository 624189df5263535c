//! Writes the seed inputs of `fuzz/corpus/`: `config_toml` (the shipped
//! `config/` files behind their selector byte), `cdr_decode` and `mcap`
//! (generated; the recording CSV seeds are written by hand):
//! `cargo run -p atmo-fuzz --example write_seeds`.
#![allow(
    clippy::unwrap_used,
    reason = "a one-off generator: a failure is a bug to see"
)]

use std::path::Path;

use atmo_core::model::State;
use atmo_io::mcap_log::{Compression, LoggerOptions, McapLogger};
use atmo_io::msg::{self, RosMessage, frames};

fn state() -> State {
    State::from_column_slice(&[
        0.1, -0.2, -1.5, 0.3, 0.02, -0.01, 0.5, 0.1, -0.05, 0.01, 0.02, -0.03,
    ])
}

fn header() -> msg::Header {
    msg::Header {
        stamp: msg::Time::from_ns(1_500_000_000),
        frame_id: "map".into(),
    }
}

fn diagnostics() -> msg::DiagnosticArray {
    msg::DiagnosticArray {
        header: header(),
        status: vec![msg::DiagnosticStatus {
            level: msg::DiagnosticStatus::WARN,
            name: "atmo/logger".into(),
            message: "dropped".into(),
            hardware_id: "fc".into(),
            values: vec![msg::KeyValue {
                key: "dropped".into(),
                value: "3".into(),
            }],
        }],
    }
}

/// Writes `corpus/cdr_decode/NN_Type.bin`: the selector byte of
/// `atmo_fuzz::cdr_decode`, then the CDR payload with its header.
fn cdr_seed<M: RosMessage>(dir: &Path, selector: u8, message: &M) {
    let mut bytes = vec![selector];
    bytes.extend(msg::encode_to_vec(message).unwrap());
    let name = M::TYPE_NAME.rsplit('/').next().unwrap();
    std::fs::write(dir.join(format!("{selector:02}_{name}.bin")), bytes).unwrap();
}

fn cdr_seeds(dir: &Path) {
    std::fs::create_dir_all(dir).unwrap();
    let odom = frames::state_to_odometry(&state(), 1_500_000_000);
    let px4_odom = frames::state_to_vehicle_odometry(&state(), 1_500_000);
    let status = msg::MpcStatus {
        transition: msg::Label::new("hover"),
        ..msg::MpcStatus::default()
    };
    cdr_seed(dir, 0, &status);
    cdr_seed(dir, 1, &msg::PilotInput::default());
    cdr_seed(dir, 2, &msg::TickTiming::default());
    cdr_seed(dir, 3, &msg::IoHealth::default());
    cdr_seed(dir, 4, &px4_odom);
    cdr_seed(
        dir,
        5,
        &msg::ActuatorMotors::from_thrust(1_500_000, [0.4, 0.41, 0.39, 0.4]),
    );
    cdr_seed(
        dir,
        6,
        &msg::OffboardControlMode::direct_actuator(1_500_000),
    );
    cdr_seed(dir, 7, &odom.twist.twist);
    cdr_seed(dir, 8, &odom);
    cdr_seed(dir, 9, &diagnostics());
    cdr_seed(dir, 10, &diagnostics().status[0]);
    cdr_seed(dir, 11, &diagnostics().status[0].values[0]);
    cdr_seed(dir, 12, &header());
    cdr_seed(dir, 13, &header().stamp);
    cdr_seed(dir, 14, &odom.twist.twist.linear);
    cdr_seed(dir, 15, &odom.pose.pose.position);
    cdr_seed(dir, 16, &odom.pose.pose.orientation);
    cdr_seed(dir, 17, &odom.pose.pose);
    cdr_seed(dir, 18, &odom.pose);
    cdr_seed(dir, 19, &odom.twist);
}

/// A small log of the flight stack's kind: status, odometry, diagnostics.
fn write_log(path: &Path, compression: Compression) {
    let options = LoggerOptions {
        compression,
        ..LoggerOptions::default()
    };
    let (log, thread) = McapLogger::spawn(path, options).unwrap();
    let status_ch = log
        .channel::<msg::MpcStatus>(atmo_explain::recording::STATUS_TOPIC)
        .unwrap();
    let odom_ch = log.channel::<msg::Odometry>("/atmo/mocap/odom").unwrap();
    let diag_ch = log.channel::<msg::DiagnosticArray>("/diagnostics").unwrap();
    for k in 0..3u64 {
        let t = 1_000_000_000 + k * 6_666_667;
        let status = msg::MpcStatus {
            stamp_ns: t,
            tick: k,
            state: msg::MpcStatus::array(&state()),
            thrust: [12.0; 4],
            ..msg::MpcStatus::default()
        };
        assert!(log.try_log(status_ch, t, &status));
        assert!(log.try_log(odom_ch, t, &frames::state_to_odometry(&state(), t)));
    }
    assert!(log.try_log(diag_ch, 1_020_000_000, &diagnostics()));
    log.finish();
    thread.join().unwrap();
}

fn mcap_seeds(dir: &Path) {
    std::fs::create_dir_all(dir).unwrap();
    write_log(&dir.join("plain.mcap"), Compression::None);
    write_log(&dir.join("zstd.mcap"), Compression::Zstd);
    write_log(&dir.join("lz4.mcap"), Compression::Lz4);
    // A killed writer: the log cut inside its chunk, after some messages
    // (what `recover` is for): the longest such cut.
    let plain = std::fs::read(dir.join("plain.mcap")).unwrap();
    let truncated = dir.join("truncated.mcap");
    let scratch = std::env::temp_dir().join("atmo-fuzz-seed-scratch.mcap");
    for len in (0..plain.len()).rev().step_by(16) {
        std::fs::write(&truncated, &plain[..len]).unwrap();
        let report = atmo_io::mcap_log::recover(&truncated, &scratch).unwrap();
        if report.stopped_by.is_some() && report.messages >= 1 {
            break;
        }
    }
}

/// `corpus/config_toml/K_name.toml`: the selector byte `K` of
/// `atmo_fuzz::config_toml` (0 robot, 1 plant, 2 flight, 3 daemon, 4 MPC),
/// then the shipped file.
fn config_seeds(dir: &Path, config: &Path) {
    std::fs::create_dir_all(dir).unwrap();
    let files = [
        (0, "atmo.toml"),
        (0, "quadrotor.toml"),
        (1, "plant.toml"),
        (2, "flight.toml"),
        (3, "daemon.toml"),
        (4, "mpc.toml"),
    ];
    for (selector, name) in files {
        let mut bytes = vec![selector];
        bytes.extend(std::fs::read(config.join(name)).unwrap());
        std::fs::write(dir.join(format!("{selector}_{name}")), bytes).unwrap();
    }
}

fn main() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let corpus = root.join("fuzz/corpus");
    config_seeds(&corpus.join("config_toml"), &root.join("config"));
    cdr_seeds(&corpus.join("cdr_decode"));
    // One folder for both MCAP targets.
    mcap_seeds(&corpus.join("mcap"));
    println!("seeds written under {}", corpus.display());
}
