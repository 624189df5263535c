//! The ROS 2 node (ros2-client over RustDDS), and its SITL peer.
//!
//! A dedicated thread owns the DDS participant, the publishers and the
//! subscriptions. The control thread talks to it only through bounded
//! channels: [`Ros2Publisher::try_publish_status`] (and the PX4 outputs)
//! copies a fixed-size record and returns at once (a full queue drops and
//! counts); [`Ros2Inputs::latest_estimate`], [`Ros2Inputs::latest_drive`]
//! and [`Ros2Inputs::latest_pilot`] drain the newest accepted input without
//! waiting. The domain id comes from `ROS_DOMAIN_ID` (default 0); with
//! `loopback_only` the participant uses 127.0.0.1 only.
//!
//! QoS per topic, as ROS 2 conventions expect (the README's topic table):
//! - status and diagnostics out: reliable, volatile, keep last 10 (ROS 2's
//!   default profile, what `ros2 topic echo`, rqt and diagnostic_aggregator
//!   subscribe with; best-effort subscribers match too). RustDDS makes a
//!   reliable writer wait while its window of 10 unacknowledged samples is
//!   full: the node uses `WhenFull::Fail`, so a slow reliable subscriber
//!   costs that sample (counted, `publish_errors`), never a wait of the node
//!   thread, and the control thread only ever touches its bounded queue.
//! - PX4 outputs: best effort, keep last 1 (what PX4's DDS bridge expects).
//! - Inputs: best effort, keep last 1, which matches reliable and
//!   best-effort publishers alike; a late sample is worth nothing.
//!
//! Shutdown: the endpoints are dropped before the node and the node before
//! the DDS participant (`dds::DdsNode` is the last field of the
//! thread structs), so RustDDS disposes every endpoint (SEDP) and the
//! participant while its event loop still runs. Fast DDS discards those
//! disposes (they carry no key hash, see `farewell`), so once the
//! participant has stopped the node sends its own SPDP dispose with the key
//! hash, and a Fast DDS peer's graph forgets the participant and all its
//! endpoints at once instead of after the 50 s participant lease.
//!
//! Type hashes: RustDDS 0.15 sends no endpoint USER_DATA, where an rmw puts
//! `typehash=RIHS01_...;` (peers see the hash as invalid; ROS 2 Kilted
//! matches anyway). The node publishes the RIHS01 hash of each of its
//! topic's types ([`crate::msg::type_hash`]) in its `atmo/ros2` diagnostics
//! (`type_hash <topic>`), so a peer can check them.
//!
//! Inputs are checked on the node thread and counted ([`Ros2Counters`],
//! also published on the diagnostics topic). Payloads that do not decode
//! (malformed CDR, another type on the topic) count as `malformed`.
//! Estimates are converted to NED/FRD here (ENU/FLU odometry); non-finite
//! fields and stamps that do not increase are rejected. Pilot inputs
//! (`atmo_msgs/msg/PilotInput`, NED velocity, FRD yaw rate) are accepted
//! only if every number is finite and the throttle is in [0, 1]. Drive
//! commands need finite values, ground heights (`geometry_msgs/PointStamped`,
//! ENU: `point.z` up, handed on as NED z) a finite `point.z`, ground normals
//! (`geometry_msgs/Vector3Stamped`, ENU, handed on as NED) finite components
//! (the flight stack checks the rest: length, slope).
//!
//! ROS time ([`Ros2Inputs::ros_time_ns`], the stamps of the status and the
//! diagnostics) is the wall clock, or with `use_sim_time` the newest
//! `rosgraph_msgs/Clock` on `topics.clock` (best effort, keep last 1, like
//! rclcpp's clock subscription; 0 until the first one, as in ROS 2; a clock
//! that jumps back, a restarted simulation, is followed).
//!
//! [`SitlNode`] is the other side for software-in-the-loop: the plant
//! server publishes the simulated estimate (as the configured estimate
//! type) and pilot inputs, and reads the daemon's status, on the topics of
//! the same [`Ros2Config`], so the daemon binary runs unchanged against it.

mod config;
mod dds;
mod farewell;
mod node;
mod sitl;

pub use config::{Ros2Config, TopicConfig, Topics};
pub use sitl::{SitlCounters, SitlInputs, SitlNode, SitlPublisher};

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, SyncSender};
use std::thread::JoinHandle;
use std::time::Instant;

use atmo_core::model::State;

use crate::error::{IoError, Result};
use crate::msg::{
    ActuatorMotors, DiagnosticArray, EscStatus, InputRc, MpcStatus, OffboardControlMode, PilotInput,
};
use dds::try_queue;

/// Reads `ROS_DOMAIN_ID` (unset or empty: 0). Valid ids are 0..=232.
pub fn domain_id_from_env() -> Result<u16> {
    match std::env::var("ROS_DOMAIN_ID") {
        Err(_) => Ok(0),
        Ok(text) if text.trim().is_empty() => Ok(0),
        Ok(text) => match text.trim().parse::<u16>() {
            Ok(id) if id <= 232 => Ok(id),
            _ => Err(IoError::Ros {
                context: "ROS_DOMAIN_ID".into(),
                reason: format!("`{text}` is not a domain id in 0..=232"),
            }),
        },
    }
}

/// A state estimate accepted from ROS 2 (NED/FRD 12-state).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RosEstimate {
    /// The message's own stamp, ns (header stamp, or PX4 `timestamp_sample` in ns).
    pub stamp_ns: u64,
    /// When the node thread accepted it.
    pub received: Instant,
    pub state: State,
}

/// A drive command accepted from ROS 2 (FRD: positive yaw rate turns right).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DriveCommand {
    /// Forward speed, m/s.
    pub forward: f64,
    /// Yaw rate, rad/s, FRD (the ROS FLU angular.z negated).
    pub yaw_rate: f64,
    pub received: Instant,
}

/// A pilot input accepted from ROS 2 (`topics.pilot`): every number finite,
/// throttle in [0, 1]. Velocity NED, yaw rate FRD, as in the message.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PilotCommand {
    pub input: PilotInput,
    /// When the node thread accepted it.
    pub received: Instant,
}

/// A ground height accepted from ROS 2 (`topics.ground`): `point.z`
/// finite; NED, so the message's ENU `point.z` negated.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GroundHeight {
    /// NED z of the ground under the robot, m.
    pub z: f64,
    /// When the node thread accepted it.
    pub received: Instant,
}

/// A ground normal accepted from ROS 2 (`topics.ground_normal`): every
/// component finite; NED, so the message's ENU `(x, y, z)` as `(y, x, -z)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GroundNormal {
    /// The ground plane's normal under the robot, NED, out of the ground
    /// (not normalized here: the flight stack normalizes and checks it).
    pub normal: [f64; 3],
    /// When the node thread accepted it.
    pub received: Instant,
}

/// An RC frame accepted from ROS 2 (`topics.rc`, PX4's `InputRc`):
/// `channel_count` at most 18; the pulse widths as received (the daemon's
/// RC mapping checks them).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RcFrame {
    pub input: InputRc,
    /// When the node thread accepted it.
    pub received: Instant,
}

/// An ESC report accepted from ROS 2 (`topics.esc_status`, PX4's
/// `EscStatus`): at most 8 ESCs; the speeds as received (the daemon's
/// `[esc]` reads them).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EscFrame {
    pub status: EscStatus,
    /// When the node thread accepted it.
    pub received: Instant,
}

/// ROS time as the node keeps it: the wall clock, or with `use_sim_time`
/// the newest `/clock` (0 until one arrives, as ROS 2 does). Shared by the
/// node thread (which writes `/clock`) and the control thread (which reads
/// it without waiting).
struct RosClock {
    use_sim_time: bool,
    sim_ns: AtomicU64,
}

impl RosClock {
    fn now_ns(&self) -> u64 {
        if self.use_sim_time {
            self.sim_ns.load(Ordering::Relaxed)
        } else {
            crate::wall_clock_ns()
        }
    }
}

/// What the node has seen and done so far (monotonic counters).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Ros2Counters {
    /// Estimates that decoded, whatever their values.
    pub estimates_received: u64,
    pub estimates_accepted: u64,
    /// Payloads on an input topic that did not decode as its type
    /// (malformed CDR or a message of another type).
    pub malformed: u64,
    /// Estimates with a non-finite or invalid field (NaN, bad quaternion, frame).
    pub invalid: u64,
    /// Estimates whose stamp did not increase (duplicates, reordered):
    /// dropped ([`crate::stamp_order`]).
    pub stamp_backwards: u64,
    /// Backward steps of the estimate stamps taken as a new estimator
    /// clock ([`crate::stamp_order`]).
    pub clock_jumps: u64,
    /// The autopilot's estimates (`topics.autopilot_estimate`) that
    /// decoded, whatever their values.
    pub autopilot_received: u64,
    /// The autopilot's estimates with a non-finite or invalid field.
    pub autopilot_rejected: u64,
    pub drive_received: u64,
    pub drive_rejected: u64,
    /// Pilot inputs that decoded, whatever their values.
    pub pilot_received: u64,
    /// Pilot inputs with a non-finite number or a throttle outside [0, 1].
    pub pilot_rejected: u64,
    /// RC frames (`InputRc`) that decoded, whatever their values.
    pub rc_received: u64,
    /// RC frames with more than 18 channels.
    pub rc_rejected: u64,
    /// ESC reports (`EscStatus`) that decoded, whatever their values.
    pub esc_received: u64,
    /// ESC reports with more than 8 ESCs.
    pub esc_rejected: u64,
    /// Ground heights that decoded, whatever their values.
    pub ground_received: u64,
    /// Ground heights with a non-finite `point.z`.
    pub ground_rejected: u64,
    /// Ground normals that decoded, whatever their values.
    pub ground_normal_received: u64,
    /// Ground normals with a non-finite component.
    pub ground_normal_rejected: u64,
    /// `/clock` messages that decoded (`use_sim_time` only).
    pub clock_received: u64,
    /// `/clock` messages with a negative or invalid time.
    pub clock_rejected: u64,
    /// Accepted inputs dropped because the control thread's queue was full.
    pub inputs_dropped: u64,
    pub published: u64,
    /// Records dropped because the publish queue was full.
    pub publish_dropped: u64,
    /// Publishes the DDS layer refused.
    pub publish_errors: u64,
}

#[derive(Default)]
struct Counters {
    estimates_received: AtomicU64,
    estimates_accepted: AtomicU64,
    malformed: AtomicU64,
    invalid: AtomicU64,
    stamp_backwards: AtomicU64,
    clock_jumps: AtomicU64,
    autopilot_received: AtomicU64,
    autopilot_rejected: AtomicU64,
    drive_received: AtomicU64,
    drive_rejected: AtomicU64,
    pilot_received: AtomicU64,
    pilot_rejected: AtomicU64,
    rc_received: AtomicU64,
    rc_rejected: AtomicU64,
    esc_received: AtomicU64,
    esc_rejected: AtomicU64,
    ground_received: AtomicU64,
    ground_rejected: AtomicU64,
    ground_normal_received: AtomicU64,
    ground_normal_rejected: AtomicU64,
    clock_received: AtomicU64,
    clock_rejected: AtomicU64,
    inputs_dropped: AtomicU64,
    published: AtomicU64,
    publish_dropped: AtomicU64,
    publish_errors: AtomicU64,
}

impl Counters {
    fn snapshot(&self) -> Ros2Counters {
        let g = |a: &AtomicU64| a.load(Ordering::Relaxed);
        Ros2Counters {
            estimates_received: g(&self.estimates_received),
            estimates_accepted: g(&self.estimates_accepted),
            malformed: g(&self.malformed),
            invalid: g(&self.invalid),
            stamp_backwards: g(&self.stamp_backwards),
            clock_jumps: g(&self.clock_jumps),
            autopilot_received: g(&self.autopilot_received),
            autopilot_rejected: g(&self.autopilot_rejected),
            drive_received: g(&self.drive_received),
            drive_rejected: g(&self.drive_rejected),
            pilot_received: g(&self.pilot_received),
            pilot_rejected: g(&self.pilot_rejected),
            rc_received: g(&self.rc_received),
            rc_rejected: g(&self.rc_rejected),
            esc_received: g(&self.esc_received),
            esc_rejected: g(&self.esc_rejected),
            ground_received: g(&self.ground_received),
            ground_rejected: g(&self.ground_rejected),
            ground_normal_received: g(&self.ground_normal_received),
            ground_normal_rejected: g(&self.ground_normal_rejected),
            clock_received: g(&self.clock_received),
            clock_rejected: g(&self.clock_rejected),
            inputs_dropped: g(&self.inputs_dropped),
            published: g(&self.published),
            publish_dropped: g(&self.publish_dropped),
            publish_errors: g(&self.publish_errors),
        }
    }
}

#[allow(clippy::large_enum_variant)] // inline on purpose: no allocation on the control thread
enum Outgoing {
    Status(MpcStatus),
    Motors(ActuatorMotors),
    Offboard(OffboardControlMode),
    Diagnostics(Box<DiagnosticArray>),
}

/// The control thread's sending side (`Clone + Send`; never blocks).
#[derive(Clone)]
pub struct Ros2Publisher {
    tx: SyncSender<Outgoing>,
    counters: Arc<Counters>,
}

impl Ros2Publisher {
    fn send(&self, message: Outgoing) -> bool {
        try_queue(&self.tx, message, &self.counters.publish_dropped)
    }

    /// Queues one status for the status topic; false if dropped (counted).
    pub fn try_publish_status(&self, status: &MpcStatus) -> bool {
        self.send(Outgoing::Status(*status))
    }

    /// Queues thruster commands (ignored if the topic is disabled).
    pub fn try_publish_motors(&self, motors: &ActuatorMotors) -> bool {
        self.send(Outgoing::Motors(*motors))
    }

    /// Queues the PX4 offboard heartbeat (ignored if the topic is disabled).
    pub fn try_publish_offboard(&self, mode: &OffboardControlMode) -> bool {
        self.send(Outgoing::Offboard(*mode))
    }

    /// Queues extra diagnostics (allocates: not for the control thread). The
    /// node adds its own `atmo/ros2` status to each array it publishes.
    pub fn try_publish_diagnostics(&self, diagnostics: DiagnosticArray) -> bool {
        self.send(Outgoing::Diagnostics(Box::new(diagnostics)))
    }

    pub fn counters(&self) -> Ros2Counters {
        self.counters.snapshot()
    }
}

/// The control thread's receiving side (`Send`, one owner).
pub struct Ros2Inputs {
    estimates: Receiver<RosEstimate>,
    autopilot_estimates: Receiver<RosEstimate>,
    drive: Receiver<DriveCommand>,
    pilot: Receiver<PilotCommand>,
    rc: Receiver<RcFrame>,
    esc: Receiver<EscFrame>,
    ground: Receiver<GroundHeight>,
    ground_normal: Receiver<GroundNormal>,
    clock: Arc<RosClock>,
    counters: Arc<Counters>,
}

impl Ros2Inputs {
    /// The newest estimate accepted since the last call, if any. Never blocks.
    pub fn latest_estimate(&mut self) -> Option<RosEstimate> {
        self.estimates.try_iter().last()
    }

    /// The newest autopilot's estimate accepted since the last call, if
    /// any (`topics.autopilot_estimate`). Never blocks.
    pub fn latest_autopilot_estimate(&mut self) -> Option<RosEstimate> {
        self.autopilot_estimates.try_iter().last()
    }

    /// The newest drive command accepted since the last call, if any.
    pub fn latest_drive(&mut self) -> Option<DriveCommand> {
        self.drive.try_iter().last()
    }

    /// The newest pilot input accepted since the last call, if any. Never blocks.
    pub fn latest_pilot(&mut self) -> Option<PilotCommand> {
        self.pilot.try_iter().last()
    }

    /// The newest RC frame accepted since the last call, if any. Never blocks.
    pub fn latest_rc(&mut self) -> Option<RcFrame> {
        self.rc.try_iter().last()
    }

    /// The newest ESC report accepted since the last call, if any. Never
    /// blocks.
    pub fn latest_esc(&mut self) -> Option<EscFrame> {
        self.esc.try_iter().last()
    }

    /// The newest ground height accepted since the last call, if any.
    pub fn latest_ground(&mut self) -> Option<GroundHeight> {
        self.ground.try_iter().last()
    }

    /// The newest ground normal accepted since the last call, if any.
    pub fn latest_ground_normal(&mut self) -> Option<GroundNormal> {
        self.ground_normal.try_iter().last()
    }

    /// ROS time now, ns since the epoch: the wall clock, or with
    /// `use_sim_time` the newest `/clock` (0 before the first). An atomic
    /// read: never blocks, never allocates.
    pub fn ros_time_ns(&self) -> u64 {
        self.clock.now_ns()
    }

    pub fn counters(&self) -> Ros2Counters {
        self.counters.snapshot()
    }
}

/// The node thread; stop it with [`Ros2Thread::stop`].
pub struct Ros2Thread {
    stop: Arc<AtomicBool>,
    join: Option<JoinHandle<Result<()>>>,
}

impl Ros2Thread {
    /// Stops the node thread and returns how it ended.
    pub fn stop(mut self) -> Result<()> {
        self.stop.store(true, Ordering::SeqCst);
        match self.join.take() {
            Some(join) => join.join().unwrap_or_else(|_| {
                Err(IoError::Ros {
                    context: "node thread".into(),
                    reason: "panicked".into(),
                })
            }),
            None => Ok(()),
        }
    }
}

impl Drop for Ros2Thread {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
        if let Some(join) = self.join.take() {
            let _ = join.join();
        }
    }
}

/// Entry point: [`Ros2Node::start`].
pub struct Ros2Node;

/// Settings that are not in the config file.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Ros2StartOptions {
    /// Overrides `ROS_DOMAIN_ID` (tests run on their own domain).
    pub domain_id: Option<u16>,
}
