//! What one tick of the flight stack reads and writes: the inputs of
//! [`crate::FlightStack::step`] and its outputs with the tick's status (the
//! records the flight log stores and a replay compares).

use atmo_core::control::WheelRates;
use atmo_core::model::State;
use atmo_mpc::SolverCuts;

use crate::modes::Mode;

/// A state estimate and the time it was measured.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Estimate {
    pub stamp_ns: u64,
    pub state: State,
}

impl Estimate {
    /// Its age at `now_ns` on the same clock, s (0 if stamped later).
    pub fn age(&self, now_ns: u64) -> f64 {
        now_ns.saturating_sub(self.stamp_ns) as f64 * 1e-9
    }
}

pub use atmo_io::msg::{PilotInput, SolverStatus};

/// Everything one tick sees.
#[derive(Debug, Clone, Copy, PartialEq)]
#[allow(clippy::struct_excessive_bools)] // independent signals, as on the wire (TickInputs)
pub struct StepInputs {
    /// The flight stack's clock, ns.
    pub now_ns: u64,
    /// Latest estimate received (possibly old, possibly the same as last tick).
    pub estimate: Option<Estimate>,
    /// Tilt encoder counts (continuous), if a reading arrived.
    pub tilt_counts: Option<f64>,
    pub pilot: PilotInput,
    /// Wheel contact signal.
    pub ground_contact: bool,
    /// NED z of the ground plane under the robot (its base origin), m.
    pub ground_z: f64,
    /// Unit normal of the ground plane through that point, NED, pointing
    /// out of the ground (level: `[0, 0, -1]`); `None`: level ground. A
    /// normal that is not finite, shorter than 1e-6 or steeper than
    /// [`atmo_core::ground_plane::MAX_GROUND_SLOPE_DEG`] is rejected with
    /// the plane (see [`RejectCounters::ground`]).
    pub ground_normal: Option<[f64; 3]>,
    /// A required driver stopped talking (the I/O layer's liveness check;
    /// always false in simulation): fly the failsafe, do not take off.
    pub driver_lost: bool,
    /// The pilot's radio is lost (PX4's `rc_lost`, or silent longer than
    /// the RC timeout; only with the radio as the pilot source): fly the
    /// failsafe, do not take off.
    pub pilot_lost: bool,
    /// Arming checks that fail (bits of [`crate::arming::ArmingCheck`];
    /// 0: all pass): the stack does not arm while any is set.
    pub arming_failures: u8,
    /// The pilot's manual tilt lever, -1..1 (positive towards the drive
    /// configuration): while disarmed, the tilt velocity as a fraction of
    /// the mechanism's speed (the authors' manual mode). 0 without a radio.
    pub tilt_lever: f64,
    /// The pilot's encoder reset switch: home the tilt driver again
    /// (passed on only while disarmed).
    pub rehome_tilt: bool,
    /// The autopilot's own estimate (PX4's, from its IMU and barometer),
    /// when the daemon takes `estimate` from elsewhere (the motion capture
    /// straight over ROS 2). Only its attitude, body rates and vertical
    /// speed are flown on, and only in a failsafe whose `estimate` is
    /// stale (the backup controller's level descent): without the motion
    /// capture its horizontal position and velocity drift.
    pub autopilot_estimate: Option<Estimate>,
    /// Each rotor's speed as its ESC reports it (PX4's `esc_status`), as a
    /// fraction of its speed at full command (the thrust goes with its
    /// square); `None`: no report young enough (no ESC telemetry, or older
    /// than the estimate timeout). The actuator monitor tells a stopped
    /// rotor by it within a few ticks.
    pub rotor_speeds: Option<[f64; 4]>,
}

/// Inputs rejected so far, by kind.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct RejectCounters {
    /// Non-finite entries, stamps in the future or going backwards.
    pub estimate: u64,
    /// Non-finite or out-of-range encoder counts.
    pub tilt: u64,
    /// Non-finite or out-of-range pilot inputs.
    pub pilot: u64,
    /// Ground planes: a non-finite height, or a normal that is not finite,
    /// shorter than 1e-6 or steeper than 35 deg (the last good plane holds).
    pub ground: u64,
    /// ESC speed reports with a speed not finite or outside [0, 2] of full
    /// (the tick flies without speeds).
    pub rotor_speeds: u64,
}

impl RejectCounters {
    /// The counters in the order of the log's `MpcStatus::rejected_inputs`.
    pub fn counts(&self) -> [u64; 5] {
        [
            self.estimate,
            self.tilt,
            self.pilot,
            self.ground,
            self.rotor_speeds,
        ]
    }
}

/// The status record of one tick (fixed size, copied into logs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Status {
    pub now_ns: u64,
    pub mode: Mode,
    /// Reason of the transition taken this tick, if any.
    pub transition: Option<&'static str>,
    pub alpha: f64,
    /// Tilt used this tick, rad.
    pub tilt: f64,
    /// Tilt limit in force this tick, rad.
    pub tilt_limit: f64,
    /// Height of the base origin above the ground, m.
    pub height: f64,
    /// Age of the estimate used, s (infinite if none).
    pub estimate_age: f64,
    /// State used (the last good estimate).
    pub state: State,
    /// MPC reference for stage 0 (or the drive reference).
    pub reference: State,
    /// Predicted state at the next MPC stage.
    pub predicted_next: State,
    pub solver: SolverStatus,
    pub mpc_failed_ticks: u32,
    pub mpc_failures_total: u64,
    /// Feedbacks that fell back from the homotopy to a full Clarabel solve, since start.
    pub feedback_fallbacks_total: u64,
    /// MPC feedback and preparation times, s (preparation: of the previous `prepare_next`).
    pub feedback_time: f64,
    pub preparation_time: f64,
    pub solver_iterations: u32,
    /// QP solves this tick: 1, or more when a mode change re-planned or
    /// warmed the MPC up (its preparation solves once with the homotopy feedback).
    pub qp_solves: u32,
    /// Drive reference: forward speed m/s and yaw rate rad/s.
    pub drive_velocity: [f64; 2],
    /// Disturbance wrench the MPC predicts with (body force N, torque N m).
    pub disturbance: [f64; 6],
    pub rejected: RejectCounters,
    /// Solves the wall-clock time limit cut since the last
    /// [`crate::FlightStack::open_cut_window`] (the preparation before this tick
    /// and this tick's feedback): logged so that a replay cuts them again.
    pub solver_cuts: SolverCuts,
    /// What the actuator monitor has detected (bits of
    /// [`crate::actuator_monitor::Detected`]; 0: nothing).
    pub actuator_faults: u8,
}

/// What one tick commands.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepOutputs {
    /// Normalized thruster commands, each in [0, 1].
    pub thrust: [f64; 4],
    /// Tilt velocity, rad/s, positive towards drive.
    pub tilt_velocity: f64,
    /// Home the tilt driver again (only ever set while disarmed).
    pub rehome_tilt: bool,
    pub wheel_rates: WheelRates,
    pub status: Status,
}
