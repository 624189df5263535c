//! `atmo_msgs`: the flight stack's own messages (`ros2/atmo_msgs/msg/`).

use serde::de::{Deserializer, Error as _};
use serde::{Deserialize, Serialize, Serializer};

use super::standard::Time;
use super::{Label, RosMessage};

/// The flight stack's mode: one type for the mode machine (atmo-flight's
/// `modes`), the `MpcStatus.MODE_*` code on the wire and the logs, and the
/// snake-case name in JSON summaries (stable codes: append only).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize)]
#[serde(rename_all = "snake_case")]
#[repr(u8)]
pub enum Mode {
    /// Outputs zero. Start-up state.
    #[default]
    Disarmed = 0,
    /// On the wheels; thrusters off; wheels follow the pilot.
    Drive = 1,
    /// Tilting back towards the flight configuration; thrusters start at or
    /// below the take-off tilt, then climb.
    Takeoff = 2,
    /// Free flight; the MPC tracks the pilot's velocity command.
    Flight = 3,
    /// Below z_varphi and descending: tilting at v_max up to the flight limit.
    Morphing = 4,
    /// Below z*: cost blended by alpha, tilt up to the transition limit,
    /// descent reference, wheels spun up before impact.
    Transition = 5,
    /// Grounded after a transition: thrust ramped to zero.
    Touchdown = 6,
    /// Something is wrong: tilt back to 0 and hold.
    Failsafe = 7,
}

impl Mode {
    pub const ALL: [Mode; 8] = [
        Mode::Disarmed,
        Mode::Drive,
        Mode::Takeoff,
        Mode::Flight,
        Mode::Morphing,
        Mode::Transition,
        Mode::Touchdown,
        Mode::Failsafe,
    ];

    pub fn code(self) -> u8 {
        self as u8
    }

    pub fn from_code(code: u8) -> Option<Self> {
        Self::ALL.get(usize::from(code)).copied()
    }

    pub fn name(self) -> &'static str {
        match self {
            Self::Disarmed => "disarmed",
            Self::Drive => "drive",
            Self::Takeoff => "takeoff",
            Self::Flight => "flight",
            Self::Morphing => "morphing",
            Self::Transition => "transition",
            Self::Touchdown => "touchdown",
            Self::Failsafe => "failsafe",
        }
    }

    /// Whether the MPC flies the thrusters in this mode.
    pub fn is_airborne_mode(self) -> bool {
        matches!(
            self,
            Mode::Takeoff | Mode::Flight | Mode::Morphing | Mode::Transition | Mode::Failsafe
        )
    }
}

/// How a tick's MPC solve ended: one type for the flight stack's status,
/// the `MpcStatus.SOLVER_*` code on the wire and the snake-case name in
/// JSON summaries (stable codes: append only).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize)]
#[serde(rename_all = "snake_case")]
#[repr(u8)]
pub enum SolverStatus {
    /// The MPC did not run this tick.
    #[default]
    Idle = 0,
    Solved = 1,
    Degraded = 2,
    Fallback = 3,
    Failed = 4,
}

impl SolverStatus {
    pub const ALL: [SolverStatus; 5] = [
        SolverStatus::Idle,
        SolverStatus::Solved,
        SolverStatus::Degraded,
        SolverStatus::Fallback,
        SolverStatus::Failed,
    ];

    pub fn code(self) -> u8 {
        self as u8
    }

    pub fn from_code(code: u8) -> Option<Self> {
        Self::ALL.get(usize::from(code)).copied()
    }

    pub fn name(self) -> &'static str {
        match self {
            Self::Idle => "idle",
            Self::Solved => "solved",
            Self::Degraded => "degraded",
            Self::Fallback => "fallback",
            Self::Failed => "failed",
        }
    }
}

/// The pilot's (or a scenario's) commands: the flight stack's pilot input
/// and the `atmo_msgs/msg/PilotInput` message, one type.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[allow(clippy::struct_excessive_bools)] // the pilot's three switches
pub struct PilotInput {
    /// NED world velocity command, m/s (the flight stack limits its norm).
    pub velocity: [f64; 3],
    /// rad/s, FRD (positive turns right).
    pub yaw_rate: f64,
    /// In [0, 1].
    pub throttle: f64,
    pub arm: bool,
    pub offboard: bool,
    pub mpc_enabled: bool,
}

/// Timing of one control tick: the control loop's record and the
/// `atmo_msgs/msg/TickTiming` message, one type.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct TickTiming {
    /// Tick number since start.
    pub tick: u64,
    /// The deadline this tick was scheduled for, ns.
    pub deadline_ns: u64,
    /// Wake-up minus deadline, s (the period jitter; >= 0).
    pub wake_latency: f64,
    /// Time spent in the tick body, s.
    pub compute: f64,
    /// The body ran past the next deadline.
    pub overrun: bool,
    pub overruns_total: u64,
    /// Deadlines skipped because the loop fell behind.
    pub skipped_total: u64,
}

/// `atmo_msgs/msg/TickInputs`: everything one tick of the flight stack
/// consumed (see the `.msg`). `Copy` and allocation-free: built on the
/// control thread, serialized elsewhere.
///
/// Logs written before the ground normal was logged end after
/// `solver_cut_overflow`; they decode with `has_ground_normal = false`
/// (level ground, what those flight stacks assumed), and logs written
/// before `pilot_lost` end after the normal and decode with the radio
/// present and every arming check passed; logs before the lever, or before
/// the autopilot's estimate, decode with the lever at rest and without
/// that estimate, so that old flight logs still replay.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
#[allow(clippy::struct_excessive_bools)] // the wire layout: presence flags and two signals
pub struct TickInputs {
    pub tick: u64,
    /// The tick's clock value, ns.
    pub clock_ns: u64,
    pub has_estimate: bool,
    /// When the estimate was accepted, ns on the tick's clock.
    pub estimate_received_ns: u64,
    pub estimate: [f64; 12],
    pub has_tilt_counts: bool,
    pub tilt_counts: f64,
    pub pilot: PilotInput,
    pub ground_contact: bool,
    /// NED z of the ground, m.
    pub ground_z: f64,
    pub driver_lost: bool,
    /// Time-limit cuts of the tick's solves (see the `.msg`).
    pub solver_cut_count: u8,
    pub solver_cut_solve: [u8; 12],
    pub solver_cut_iteration: [u32; 12],
    pub solver_cut_overflow: u32,
    /// Whether the tick had a ground normal (else: level ground).
    pub has_ground_normal: bool,
    /// The ground plane's unit normal, NED, out of the ground.
    pub ground_normal: [f64; 3],
    /// The pilot's radio is lost (a failsafe input).
    pub pilot_lost: bool,
    /// Arming checks that failed (bit set; 0: all pass).
    pub arming_failures: u8,
    /// The pilot's manual tilt lever, -1..1 (positive: towards the drive
    /// configuration; 0 without a radio).
    pub tilt_lever: f64,
    /// The pilot asks the tilt driver to home again (the encoder reset
    /// switch).
    pub rehome_tilt: bool,
    /// Whether the tick had the autopilot's own estimate.
    pub has_autopilot_estimate: bool,
    /// When the autopilot's estimate was accepted, ns on the tick's clock.
    pub autopilot_estimate_received_ns: u64,
    /// The autopilot's estimate, 12-state order.
    pub autopilot_estimate: [f64; 12],
    /// Whether the tick had the rotors' ESC speeds.
    pub has_rotor_speeds: bool,
    /// Each rotor's speed, a fraction of its speed at full command.
    pub rotor_speeds: [f64; 4],
}

/// The fields of `TickInputs` in wire order (its .msg definition's, checked
/// by the message tests).
pub(super) const TICK_INPUTS_FIELDS: &[&str] = &[
    "tick",
    "clock_ns",
    "has_estimate",
    "estimate_received_ns",
    "estimate",
    "has_tilt_counts",
    "tilt_counts",
    "pilot",
    "ground_contact",
    "ground_z",
    "driver_lost",
    "solver_cut_count",
    "solver_cut_solve",
    "solver_cut_iteration",
    "solver_cut_overflow",
    "has_ground_normal",
    "ground_normal",
    "pilot_lost",
    "arming_failures",
    "tilt_lever",
    "rehome_tilt",
    "has_autopilot_estimate",
    "autopilot_estimate_received_ns",
    "autopilot_estimate",
    "has_rotor_speeds",
    "rotor_speeds",
];

impl<'de> Deserialize<'de> for TickInputs {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        deserializer.deserialize_struct("TickInputs", TICK_INPUTS_FIELDS, TickInputsVisitor)
    }
}

/// Field order as in the `.msg`; the ground normal's fields may be absent
/// (a log written before them).
struct TickInputsVisitor;

impl<'de> serde::de::Visitor<'de> for TickInputsVisitor {
    type Value = TickInputs;

    fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("atmo_msgs/msg/TickInputs")
    }

    fn visit_seq<A: serde::de::SeqAccess<'de>>(self, mut seq: A) -> Result<TickInputs, A::Error> {
        fn next<'de, A: serde::de::SeqAccess<'de>, T: Deserialize<'de>>(
            seq: &mut A,
            field: &'static str,
        ) -> Result<T, A::Error> {
            seq.next_element()?
                .ok_or_else(|| A::Error::missing_field(field))
        }
        let mut m = TickInputs {
            tick: next(&mut seq, "tick")?,
            clock_ns: next(&mut seq, "clock_ns")?,
            has_estimate: next(&mut seq, "has_estimate")?,
            estimate_received_ns: next(&mut seq, "estimate_received_ns")?,
            estimate: next(&mut seq, "estimate")?,
            has_tilt_counts: next(&mut seq, "has_tilt_counts")?,
            tilt_counts: next(&mut seq, "tilt_counts")?,
            pilot: next(&mut seq, "pilot")?,
            ground_contact: next(&mut seq, "ground_contact")?,
            ground_z: next(&mut seq, "ground_z")?,
            driver_lost: next(&mut seq, "driver_lost")?,
            solver_cut_count: next(&mut seq, "solver_cut_count")?,
            solver_cut_solve: next(&mut seq, "solver_cut_solve")?,
            solver_cut_iteration: next(&mut seq, "solver_cut_iteration")?,
            solver_cut_overflow: next(&mut seq, "solver_cut_overflow")?,
            has_ground_normal: false,
            ground_normal: [0.0; 3],
            pilot_lost: false,
            arming_failures: 0,
            tilt_lever: 0.0,
            rehome_tilt: false,
            has_autopilot_estimate: false,
            autopilot_estimate_received_ns: 0,
            autopilot_estimate: [0.0; 12],
            has_rotor_speeds: false,
            rotor_speeds: [0.0; 4],
        };
        // A log before the ground normal ends here: the payload is used up,
        // reading on fails, and the message is the old one (level ground).
        // Anything else left over is refused by `decode`'s length check.
        if let Ok(Some(has)) = seq.next_element::<bool>() {
            m.has_ground_normal = has;
            m.ground_normal = next(&mut seq, "ground_normal")?;
            // Likewise a log before the pilot's radio ends after the normal.
            if let Ok(Some(lost)) = seq.next_element::<bool>() {
                m.pilot_lost = lost;
                m.arming_failures = next(&mut seq, "arming_failures")?;
                // And a log before the manual tilt lever after the checks.
                if let Ok(Some(lever)) = seq.next_element::<f64>() {
                    m.tilt_lever = lever;
                    m.rehome_tilt = next(&mut seq, "rehome_tilt")?;
                    // And a log before the autopilot's estimate after the lever.
                    if let Ok(Some(has)) = seq.next_element::<bool>() {
                        m.has_autopilot_estimate = has;
                        m.autopilot_estimate_received_ns =
                            next(&mut seq, "autopilot_estimate_received_ns")?;
                        m.autopilot_estimate = next(&mut seq, "autopilot_estimate")?;
                        // And a log before the ESC speeds after it.
                        if let Ok(Some(has)) = seq.next_element::<bool>() {
                            m.has_rotor_speeds = has;
                            m.rotor_speeds = next(&mut seq, "rotor_speeds")?;
                        }
                    }
                }
            }
        }
        Ok(m)
    }
}

/// `atmo_msgs/msg/SimTruth`: the simulator's truth after a plant step.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct SimTruth {
    /// Plant time, s.
    pub time: f64,
    pub state: [f64; 12],
    /// rad.
    pub tilt: f64,
    /// Above the terrain, m.
    pub height: f64,
    pub contact: bool,
}

/// `atmo_msgs/msg/IoHealth`: counters of the edges (see the `.msg`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct IoHealth {
    pub malformed: u64,
    pub invalid: u64,
    pub stamp_backwards: u64,
    pub inputs_dropped: u64,
    pub publish_dropped: u64,
    pub log_dropped: u64,
    /// Thrusters, tilt, wheels, ground contact.
    pub drivers_alive: [bool; 4],
    pub driver_deaths: [u64; 4],
}

/// `atmo_msgs/msg/MpcStatus`: one control tick (see the `.msg` for units
/// and frames). `Copy` and allocation-free: built on the control thread,
/// serialized elsewhere. On the wire the header's frame id is empty and
/// `mode_name` / `solver_status_name` are derived from the codes.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct MpcStatus {
    /// Flight-stack clock at the start of the tick, ns since the stack
    /// started (`clock_ns`; monotonic, the clock of `estimate_age`).
    pub stamp_ns: u64,
    /// ROS time at the start of the tick, ns since the Unix epoch
    /// (`header.stamp`): the wall clock on the robot, the simulated clock in
    /// a simulation.
    pub ros_stamp_ns: u64,
    pub tick: u64,
    pub mode: Mode,
    /// Reason of the transition taken this tick, or why arming was refused
    /// ("arming refused: ..."); empty if neither.
    pub transition: Label,
    pub solver_status: SolverStatus,
    pub solver_iterations: u32,
    pub mpc_failed_ticks: u32,
    pub mpc_failures_total: u64,
    /// Feedbacks that fell back from the homotopy to a full Clarabel solve.
    pub feedback_fallbacks_total: u64,
    pub state: [f64; 12],
    pub reference: [f64; 12],
    pub predicted_next: [f64; 12],
    pub thrust: [f64; 4],
    pub alpha: f64,
    pub varphi: f64,
    pub tilt_limit: f64,
    pub tilt_velocity: f64,
    pub drive_velocity: [f64; 2],
    pub wheel_rates: [f64; 2],
    pub height: f64,
    pub ground_contact: bool,
    /// Age of the estimate used, s; -1 if there is none yet.
    pub estimate_age: f64,
    pub feedback_time: f64,
    pub preparation_time: f64,
    pub pilot: PilotInput,
    pub timing: TickTiming,
    pub rejected_estimate: u64,
    pub rejected_tilt: u64,
    pub rejected_pilot: u64,
    pub rejected_ground: u64,
    /// ROS 2, log and driver health (filled by the daemon from atmo-io's counters).
    pub io: IoHealth,
    /// What the flight stack's actuator monitor has detected, bits (1:
    /// tilt encoder stuck, 2: tilt not where believed, 4: a rotor failed,
    /// 8: contact inferred, 16: a rotor stopped by its ESC's speed; 0:
    /// nothing). Logs written before it decode with 0.
    pub actuator_faults: u8,
    /// ESC speed reports refused (a speed not finite or outside [0, 2] of
    /// full). Logs written before it decode with 0.
    pub rejected_rotor_speeds: u64,
}

impl MpcStatus {
    /// The inputs the flight stack refused, in the order of
    /// `review::Summary::rejected_inputs` (estimate, tilt, pilot, ground,
    /// rotor speeds).
    pub fn rejected_inputs(&self) -> [u64; 5] {
        [
            self.rejected_estimate,
            self.rejected_tilt,
            self.rejected_pilot,
            self.rejected_ground,
            self.rejected_rotor_speeds,
        ]
    }

    /// A 12-state as the message's array (state, reference, predicted_next).
    pub fn array(x: &atmo_core::model::State) -> [f64; 12] {
        let mut out = [0.0; 12];
        out.copy_from_slice(x.as_slice());
        out
    }
}

/// The wire layout of `MpcStatus.msg`, field for field; `S` is `&str` when
/// writing (no allocation) and `String` when reading.
#[derive(Serialize, Deserialize)]
struct WireHeader<S> {
    stamp: Time,
    frame_id: S,
}

#[derive(Serialize, Deserialize)]
struct Wire<S> {
    header: WireHeader<S>,
    tick: u64,
    clock_ns: u64,
    mode: u8,
    mode_name: S,
    transition: S,
    solver_status: u8,
    solver_status_name: S,
    solver_iterations: u32,
    mpc_failed_ticks: u32,
    mpc_failures_total: u64,
    feedback_fallbacks_total: u64,
    state: [f64; 12],
    reference: [f64; 12],
    predicted_next: [f64; 12],
    thrust: [f64; 4],
    alpha: f64,
    varphi: f64,
    tilt_limit: f64,
    tilt_velocity: f64,
    drive_velocity: [f64; 2],
    wheel_rates: [f64; 2],
    height: f64,
    ground_contact: bool,
    estimate_age: f64,
    feedback_time: f64,
    preparation_time: f64,
    pilot: PilotInput,
    timing: TickTiming,
    rejected_estimate: u64,
    rejected_tilt: u64,
    rejected_pilot: u64,
    rejected_ground: u64,
    io: IoHealth,
    actuator_faults: Trailing<u8>,
    rejected_rotor_speeds: Trailing<u64>,
}

/// One of the message's last fields, which logs written before them lack:
/// read as 0 when the payload ends before it (the reader fails at the end
/// of the payload; nothing follows it to misread).
#[derive(Serialize)]
#[serde(transparent)]
struct Trailing<T>(T);

impl<'de, T: Deserialize<'de> + Default> Deserialize<'de> for Trailing<T> {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        Ok(Self(T::deserialize(deserializer).unwrap_or_default()))
    }
}

impl Serialize for MpcStatus {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        Wire::<&str> {
            header: WireHeader {
                stamp: Time::from_ns(self.ros_stamp_ns),
                frame_id: "",
            },
            tick: self.tick,
            clock_ns: self.stamp_ns,
            mode: self.mode.code(),
            mode_name: self.mode.name(),
            transition: self.transition.as_str(),
            solver_status: self.solver_status.code(),
            solver_status_name: self.solver_status.name(),
            solver_iterations: self.solver_iterations,
            mpc_failed_ticks: self.mpc_failed_ticks,
            mpc_failures_total: self.mpc_failures_total,
            feedback_fallbacks_total: self.feedback_fallbacks_total,
            state: self.state,
            reference: self.reference,
            predicted_next: self.predicted_next,
            thrust: self.thrust,
            alpha: self.alpha,
            varphi: self.varphi,
            tilt_limit: self.tilt_limit,
            tilt_velocity: self.tilt_velocity,
            drive_velocity: self.drive_velocity,
            wheel_rates: self.wheel_rates,
            height: self.height,
            ground_contact: self.ground_contact,
            estimate_age: self.estimate_age,
            feedback_time: self.feedback_time,
            preparation_time: self.preparation_time,
            pilot: self.pilot,
            timing: self.timing,
            rejected_estimate: self.rejected_estimate,
            rejected_tilt: self.rejected_tilt,
            rejected_pilot: self.rejected_pilot,
            rejected_ground: self.rejected_ground,
            io: self.io,
            actuator_faults: Trailing(self.actuator_faults),
            rejected_rotor_speeds: Trailing(self.rejected_rotor_speeds),
        }
        .serialize(serializer)
    }
}

impl<'de> Deserialize<'de> for MpcStatus {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        let w = Wire::<String>::deserialize(deserializer)?;
        let ros_stamp_ns = w.header.stamp.to_ns().ok_or_else(|| {
            D::Error::custom(format!(
                "field `header.stamp`: {:?} is not a valid time",
                w.header.stamp
            ))
        })?;
        let mode = Mode::from_code(w.mode)
            .ok_or_else(|| D::Error::custom(format!("field `mode`: unknown code {}", w.mode)))?;
        let solver_status = SolverStatus::from_code(w.solver_status).ok_or_else(|| {
            D::Error::custom(format!(
                "field `solver_status`: unknown code {}",
                w.solver_status
            ))
        })?;
        Ok(Self {
            stamp_ns: w.clock_ns,
            ros_stamp_ns,
            tick: w.tick,
            mode,
            transition: Label::new(&w.transition),
            solver_status,
            solver_iterations: w.solver_iterations,
            mpc_failed_ticks: w.mpc_failed_ticks,
            mpc_failures_total: w.mpc_failures_total,
            feedback_fallbacks_total: w.feedback_fallbacks_total,
            state: w.state,
            reference: w.reference,
            predicted_next: w.predicted_next,
            thrust: w.thrust,
            alpha: w.alpha,
            varphi: w.varphi,
            tilt_limit: w.tilt_limit,
            tilt_velocity: w.tilt_velocity,
            drive_velocity: w.drive_velocity,
            wheel_rates: w.wheel_rates,
            height: w.height,
            ground_contact: w.ground_contact,
            estimate_age: w.estimate_age,
            feedback_time: w.feedback_time,
            preparation_time: w.preparation_time,
            pilot: w.pilot,
            timing: w.timing,
            rejected_estimate: w.rejected_estimate,
            rejected_tilt: w.rejected_tilt,
            rejected_pilot: w.rejected_pilot,
            rejected_ground: w.rejected_ground,
            io: w.io,
            actuator_faults: w.actuator_faults.0,
            rejected_rotor_speeds: w.rejected_rotor_speeds.0,
        })
    }
}

impl RosMessage for PilotInput {
    const TYPE_NAME: &'static str = "atmo_msgs/msg/PilotInput";
}
impl RosMessage for SimTruth {
    const TYPE_NAME: &'static str = "atmo_msgs/msg/SimTruth";
}
impl RosMessage for TickInputs {
    const TYPE_NAME: &'static str = "atmo_msgs/msg/TickInputs";
}
impl RosMessage for TickTiming {
    const TYPE_NAME: &'static str = "atmo_msgs/msg/TickTiming";
}
impl RosMessage for IoHealth {
    const TYPE_NAME: &'static str = "atmo_msgs/msg/IoHealth";
}
impl RosMessage for MpcStatus {
    const TYPE_NAME: &'static str = "atmo_msgs/msg/MpcStatus";
}
