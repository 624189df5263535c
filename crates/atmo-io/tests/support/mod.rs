//! Shared by the integration tests: sample messages and the interop folder.
// Test, bench and example code: an unwrap that fails is the failure report.
#![allow(clippy::unwrap_used)]
#![allow(dead_code)]

use std::path::PathBuf;

use atmo_core::model::State;
use atmo_io::mcap_log::{LoggedMessage, read_log};
use atmo_io::msg::{
    ActuatorMotors, DiagnosticArray, DiagnosticStatus, Header, IoHealth, KeyValue, Label, Mode,
    MpcStatus, OffboardControlMode, PilotInput, SolverStatus, TickTiming, Time, Twist, Vector3,
    VehicleOdometry, frames::state_to_odometry,
};

/// Where tests leave logs for the Python reference readers
/// (`tests/python/check_mcap.py`): `<target>/tmp/atmo-io-interop`.
pub fn interop_dir() -> PathBuf {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("atmo-io-interop");
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Writes `<log>.expected.json` next to a log: every message as read back
/// by the Rust reader (each test checks that this equals what it sent), for
/// the Python reader to compare field by field.
pub fn write_expected(log: &std::path::Path) -> Vec<LoggedMessage> {
    let messages = read_log(log).unwrap();
    let json: Vec<serde_json::Value> = messages
        .iter()
        .map(|m| {
            serde_json::json!({
                "topic": m.topic,
                "schema": m.type_name,
                "sequence": m.sequence,
                "log_time": m.log_time_ns,
                "publish_time": m.publish_time_ns,
                "message": serde_json::to_value(&m.message).unwrap(),
            })
        })
        .collect();
    let mut name = log.file_name().unwrap().to_os_string();
    name.push(".expected.json");
    std::fs::write(
        log.with_file_name(name),
        serde_json::to_string_pretty(&json).unwrap(),
    )
    .unwrap();
    messages
}

/// A status record that varies with `k` in every field.
pub fn status(k: u64) -> MpcStatus {
    let t = k as f64;
    let mut s = MpcStatus {
        stamp_ns: 1_000_000_000 + k * 6_666_667,
        ros_stamp_ns: 1_780_000_000_000_000_000 + k * 6_666_667,
        tick: k,
        mode: Mode::ALL[(k % 8) as usize],
        transition: if k.is_multiple_of(5) {
            Label::new("height below z*")
        } else {
            Label::EMPTY
        },
        solver_status: SolverStatus::ALL[(k % 5) as usize],
        solver_iterations: (k % 4) as u32,
        mpc_failed_ticks: (k % 3) as u32,
        mpc_failures_total: k / 3,
        feedback_fallbacks_total: k / 5,
        thrust: [0.1 + 1e-3 * t, 0.2, 0.3, 0.4 - 1e-4 * t],
        alpha: (t * 0.01).sin().abs(),
        varphi: 0.001 * t,
        tilt_limit: 1.2217,
        tilt_velocity: 0.39,
        drive_velocity: [0.5, -0.1],
        wheel_rates: [t * 0.01, -t * 0.01],
        height: 1.0 - 0.001 * t,
        ground_contact: k.is_multiple_of(2),
        estimate_age: if k == 3 { -1.0 } else { 0.004 },
        feedback_time: 1.1e-3,
        preparation_time: 2.2e-3,
        pilot: PilotInput {
            velocity: [0.0, 0.1, 0.3],
            yaw_rate: -0.1,
            throttle: 0.55,
            arm: true,
            offboard: k.is_multiple_of(3),
            mpc_enabled: true,
        },
        timing: TickTiming {
            tick: k,
            deadline_ns: k * 6_666_667,
            wake_latency: 2e-5,
            compute: 1.5e-3,
            overrun: k.is_multiple_of(7),
            overruns_total: k / 7,
            skipped_total: 0,
        },
        rejected_estimate: k,
        rejected_tilt: 2 * k,
        rejected_pilot: 3 * k,
        rejected_ground: 4 * k,
        io: IoHealth {
            malformed: k,
            invalid: k + 1,
            stamp_backwards: k + 2,
            inputs_dropped: k + 3,
            publish_dropped: k + 4,
            log_dropped: k + 5,
            drivers_alive: [k.is_multiple_of(2), true, k.is_multiple_of(3), true],
            driver_deaths: [k, 0, 1, 2],
        },
        ..MpcStatus::default()
    };
    for i in 0..12 {
        s.state[i] = t + i as f64 * 0.1;
        s.reference[i] = -t - i as f64;
        s.predicted_next[i] = t * 1e-3 + i as f64;
    }
    s
}

pub fn motors(k: u64) -> ActuatorMotors {
    let mut control = [f32::NAN; 12];
    for (i, c) in control.iter_mut().take(4).enumerate() {
        *c = 0.1 * (i as f32 + 1.0) + 1e-3 * k as f32;
    }
    ActuatorMotors {
        timestamp: k * 6667,
        timestamp_sample: (k * 6667).saturating_sub(10),
        reversible_flags: 0,
        control,
    }
}

pub fn px4_odometry(k: u64) -> VehicleOdometry {
    VehicleOdometry {
        timestamp: k * 10_000,
        timestamp_sample: k * 10_000,
        pose_frame: VehicleOdometry::POSE_FRAME_NED,
        position: [k as f32 * 0.1, 0.2, -1.5],
        q: [1.0, 0.0, 0.0, 0.0],
        velocity_frame: VehicleOdometry::VELOCITY_FRAME_NED,
        velocity: [0.1, 0.0, -0.2],
        angular_velocity: [0.0, 0.01, 0.0],
        position_variance: [1e-4; 3],
        orientation_variance: [1e-3; 3],
        velocity_variance: [1e-2; 3],
        reset_counter: 1,
        quality: 100,
    }
}

pub fn offboard(k: u64) -> OffboardControlMode {
    OffboardControlMode {
        timestamp: k * 10_000,
        direct_actuator: true,
        ..OffboardControlMode::default()
    }
}

pub fn drive(k: u64) -> Twist {
    Twist {
        linear: Vector3 {
            x: 0.5 + k as f64 * 0.01,
            y: 0.0,
            z: 0.0,
        },
        angular: Vector3 {
            x: 0.0,
            y: 0.0,
            z: -0.25,
        },
    }
}

pub fn mocap(k: u64) -> atmo_io::msg::Odometry {
    let mut x = State::zeros();
    x[0] = k as f64 * 0.01;
    x[2] = -1.0;
    x[3] = 0.3;
    x[4] = 0.05;
    x[5] = -0.02;
    x[6] = 0.2;
    x[11] = 0.1;
    state_to_odometry(&x, 2_000_000_000 + k * 10_000_000)
}

pub fn diagnostics(k: u64) -> DiagnosticArray {
    DiagnosticArray {
        header: Header {
            stamp: Time::from_ns(k * 1_000_000_000),
            frame_id: String::new(),
        },
        status: vec![
            DiagnosticStatus {
                level: DiagnosticStatus::OK,
                name: "atmo/ros2".into(),
                message: "ok".into(),
                hardware_id: "atmo".into(),
                values: vec![KeyValue {
                    key: "malformed".into(),
                    value: k.to_string(),
                }],
            },
            DiagnosticStatus {
                level: DiagnosticStatus::WARN,
                name: "atmo/drivers".into(),
                message: "thrusters stale".into(),
                hardware_id: String::new(),
                values: Vec::new(),
            },
        ],
    }
}
