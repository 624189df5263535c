//! `px4_msgs` types for flying through PX4 offboard (PX4 v1.15 layouts).

use serde::{Deserialize, Serialize};

use super::RosMessage;

/// `px4_msgs/msg/VehicleOdometry` (NED world, FRD body).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct VehicleOdometry {
    /// us since PX4 boot.
    pub timestamp: u64,
    pub timestamp_sample: u64,
    pub pose_frame: u8,
    pub position: [f32; 3],
    /// Hamilton quaternion (w, x, y, z), FRD body to `pose_frame`.
    pub q: [f32; 4],
    pub velocity_frame: u8,
    pub velocity: [f32; 3],
    pub angular_velocity: [f32; 3],
    pub position_variance: [f32; 3],
    pub orientation_variance: [f32; 3],
    pub velocity_variance: [f32; 3],
    pub reset_counter: u8,
    pub quality: i8,
}

impl VehicleOdometry {
    pub const POSE_FRAME_UNKNOWN: u8 = 0;
    pub const POSE_FRAME_NED: u8 = 1;
    pub const POSE_FRAME_FRD: u8 = 2;
    pub const VELOCITY_FRAME_UNKNOWN: u8 = 0;
    pub const VELOCITY_FRAME_NED: u8 = 1;
    pub const VELOCITY_FRAME_FRD: u8 = 2;
    pub const VELOCITY_FRAME_BODY_FRD: u8 = 3;
}

/// `px4_msgs/msg/ActuatorMotors`: normalized motor commands (first four used,
/// rotors 1..4 in PX4 quad-x order; NaN = disarmed).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct ActuatorMotors {
    /// us since PX4 boot.
    pub timestamp: u64,
    pub timestamp_sample: u64,
    pub reversible_flags: u16,
    pub control: [f32; 12],
}

impl ActuatorMotors {
    pub const ACTUATOR_FUNCTION_MOTOR1: u8 = 101;
    pub const NUM_CONTROLS: u8 = 12;

    /// Four thruster commands in [0, 1] (rotors 1..4) for PX4: the other
    /// eight controls NaN (disarmed), `timestamp_us` in both stamps.
    pub fn from_thrust(timestamp_us: u64, thrust: [f64; 4]) -> Self {
        let mut control = [f32::NAN; 12];
        for (c, t) in control.iter_mut().zip(thrust) {
            *c = t as f32;
        }
        Self {
            timestamp: timestamp_us,
            timestamp_sample: timestamp_us,
            reversible_flags: 0,
            control,
        }
    }
}

/// `px4_msgs/msg/OffboardControlMode`: which setpoint PX4 follows.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[allow(clippy::struct_excessive_bools)] // mirrors the PX4 message field for field
pub struct OffboardControlMode {
    /// us since PX4 boot.
    pub timestamp: u64,
    pub position: bool,
    pub velocity: bool,
    pub acceleration: bool,
    pub attitude: bool,
    pub body_rate: bool,
    pub thrust_and_torque: bool,
    pub direct_actuator: bool,
}

impl OffboardControlMode {
    /// The heartbeat for direct actuator control (what the thrusters need).
    pub fn direct_actuator(timestamp_us: u64) -> Self {
        Self {
            timestamp: timestamp_us,
            direct_actuator: true,
            ..Self::default()
        }
    }
}

impl RosMessage for VehicleOdometry {
    const TYPE_NAME: &'static str = "px4_msgs/msg/VehicleOdometry";
}
impl RosMessage for ActuatorMotors {
    const TYPE_NAME: &'static str = "px4_msgs/msg/ActuatorMotors";
}
impl RosMessage for OffboardControlMode {
    const TYPE_NAME: &'static str = "px4_msgs/msg/OffboardControlMode";
}

/// `px4_msgs/msg/InputRc`: the receiver's raw channels as PX4 publishes
/// them (`/fmu/out/input_rc` over uXRCE-DDS). Pulse widths in us; what
/// they mean (sticks, switches) is the reader's mapping.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct InputRc {
    /// us since PX4 boot.
    pub timestamp: u64,
    /// Last valid reception, us since PX4 boot.
    pub timestamp_last_signal: u64,
    /// Channels the receiver delivers (the first `channel_count` of `values`).
    pub channel_count: u8,
    /// < 0 undefined, 0 no signal, 100 full reception.
    pub rssi: i32,
    /// The receiver's own failsafe flag (true is reliable, false is not).
    pub rc_failsafe: bool,
    /// No frame within the expected time.
    pub rc_lost: bool,
    pub rc_lost_frame_count: u16,
    pub rc_total_frame_count: u16,
    pub rc_ppm_frame_length: u16,
    pub input_source: u8,
    /// Pulse width of each channel, us (channel 1 is `values[0]`).
    pub values: [u16; 18],
    /// 0..100 %, -1 invalid.
    pub link_quality: i8,
    /// dBm, NaN invalid.
    pub rssi_dbm: f32,
}

impl InputRc {
    pub const RC_INPUT_MAX_CHANNELS: u8 = 18;
}

impl RosMessage for InputRc {
    const TYPE_NAME: &'static str = "px4_msgs/msg/InputRc";
}

/// `px4_msgs/msg/EscReport`: one ESC's telemetry, as in PX4's `EscStatus`.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct EscReport {
    /// us since PX4 boot.
    pub timestamp: u64,
    pub esc_errorcount: u32,
    /// Motor speed, RPM (negative: reverse rotation).
    pub esc_rpm: i32,
    /// V.
    pub esc_voltage: f32,
    /// A.
    pub esc_current: f32,
    /// deg C.
    pub esc_temperature: f32,
    pub esc_address: u8,
    pub esc_cmdcount: u8,
    pub esc_state: u8,
    /// The output function the ESC drives (PX4's Motor1 = 101, Motor2 =
    /// 102, ...); 0: not set.
    pub actuator_function: u8,
    /// Bits of the ESC's own failures (over current, motor stuck, ...).
    pub failures: u16,
    /// Applied power, 0-100 %.
    pub esc_power: i8,
}

/// `px4_msgs/msg/EscStatus`: the ESCs' telemetry as PX4 publishes it
/// (`/fmu/out/esc_status` over uXRCE-DDS).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct EscStatus {
    /// us since PX4 boot.
    pub timestamp: u64,
    /// Incremented by PX4 at each new report.
    pub counter: u16,
    /// ESCs connected (the first `esc_count` of `esc`).
    pub esc_count: u8,
    pub esc_connectiontype: u8,
    /// Bit i: ESC i is online.
    pub esc_online_flags: u8,
    /// Bit i: ESC i is armed.
    pub esc_armed_flags: u8,
    pub esc: [EscReport; 8],
}

impl EscStatus {
    pub const CONNECTED_ESC_MAX: u8 = 8;
    /// PX4's output function of motor 1 (`actuator_function`); motor k is
    /// this plus k - 1.
    pub const ACTUATOR_FUNCTION_MOTOR1: u8 = 101;
}

impl RosMessage for EscReport {
    const TYPE_NAME: &'static str = "px4_msgs/msg/EscReport";
}
impl RosMessage for EscStatus {
    const TYPE_NAME: &'static str = "px4_msgs/msg/EscStatus";
}
