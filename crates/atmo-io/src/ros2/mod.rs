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
//! the DDS participant ([`DdsNode`] is the last field of the thread
//! structs), so RustDDS disposes every endpoint (SEDP) and the participant
//! while its event loop still runs, and a peer's graph forgets them at once
//! instead of after the 50 s participant lease.
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
//! commands need finite values.
//!
//! [`SitlNode`] is the other side for software-in-the-loop: the plant
//! server publishes the simulated estimate (as the configured estimate
//! type) and pilot inputs, and reads the daemon's status, on the topics of
//! the same [`Ros2Config`], so the daemon binary runs unchanged against it.

mod config;
mod sitl;

pub use config::{Ros2Config, TopicConfig, Topics};
pub use sitl::{SitlCounters, SitlInputs, SitlNode, SitlPublisher};

use std::net::Ipv4Addr;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, RecvTimeoutError, SyncSender, TrySendError, sync_channel};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use atmo_core::ConfigFile;
use atmo_core::model::State;
use ros2_client::dds::rustdds::DomainParticipantBuilder;
use ros2_client::{
    Context, MessageTypeName, Name, Node, NodeName, NodeOptions, Publisher, QosProfile,
    Subscription,
    qos::{History, WhenFull},
};
use serde::Serialize;
use serde::de::DeserializeOwned;

use crate::error::{IoError, Result};
use crate::msg::frames::{odometry_to_state, vehicle_odometry_to_state};
use crate::msg::{
    ActuatorMotors, DiagnosticArray, DiagnosticStatus, KeyValue, MpcStatus, Odometry,
    OffboardControlMode, PilotInput, RosMessage, Time, Twist, VehicleOdometry,
};

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

/// Whether a pilot input may be used: every number finite, throttle in [0, 1].
fn pilot_is_valid(p: &PilotInput) -> bool {
    p.velocity.iter().all(|v| v.is_finite())
        && p.yaw_rate.is_finite()
        && (0.0..=1.0).contains(&p.throttle)
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
    /// Estimates whose stamp did not increase.
    pub stamp_backwards: u64,
    pub drive_received: u64,
    pub drive_rejected: u64,
    /// Pilot inputs that decoded, whatever their values.
    pub pilot_received: u64,
    /// Pilot inputs with a non-finite number or a throttle outside [0, 1].
    pub pilot_rejected: u64,
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
    drive_received: AtomicU64,
    drive_rejected: AtomicU64,
    pilot_received: AtomicU64,
    pilot_rejected: AtomicU64,
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
            drive_received: g(&self.drive_received),
            drive_rejected: g(&self.drive_rejected),
            pilot_received: g(&self.pilot_received),
            pilot_rejected: g(&self.pilot_rejected),
            inputs_dropped: g(&self.inputs_dropped),
            published: g(&self.published),
            publish_dropped: g(&self.publish_dropped),
            publish_errors: g(&self.publish_errors),
        }
    }
}

fn bump(a: &AtomicU64) {
    a.fetch_add(1, Ordering::Relaxed);
}

/// Queues `message` for the node thread without blocking; a full queue
/// (or a stopped node) drops it and counts `dropped`.
fn try_queue<O>(tx: &SyncSender<O>, message: O, dropped: &AtomicU64) -> bool {
    match tx.try_send(message) {
        Ok(()) => true,
        Err(TrySendError::Full(_) | TrySendError::Disconnected(_)) => {
            bump(dropped);
            false
        }
    }
}

/// Node thread: waits up to 1 ms for an outgoing message, then publishes
/// every queued one.
fn publish_queued<O>(out_rx: &Receiver<O>, mut publish: impl FnMut(O)) {
    match out_rx.recv_timeout(Duration::from_millis(1)) {
        Ok(message) => {
            publish(message);
            while let Ok(message) = out_rx.try_recv() {
                publish(message);
            }
        }
        Err(RecvTimeoutError::Timeout) => {}
        // Every publisher handle dropped: keep serving the inputs.
        Err(RecvTimeoutError::Disconnected) => std::thread::sleep(Duration::from_millis(1)),
    }
}

/// Counts one publish: `Some(ok)` from a publisher, `None` for a disabled
/// topic.
fn count_publish(result: Option<bool>, published: &AtomicU64, errors: &AtomicU64) {
    match result {
        Some(true) => bump(published),
        Some(false) => bump(errors),
        None => {} // topic disabled
    }
}

/// Node thread: takes up to [`TAKE_BURST`] samples from `sub`. A payload
/// that does not decode counts `malformed`; a decoded one counts
/// `received` and goes through `accept` (which counts its own rejections
/// and returns `None` for them) into `tx`, where a full queue counts
/// `dropped`.
fn take_burst<M: 'static + DeserializeOwned, T>(
    sub: &Subscription<M>,
    malformed: &AtomicU64,
    received: &AtomicU64,
    dropped: &AtomicU64,
    tx: &SyncSender<T>,
    mut accept: impl FnMut(M) -> Option<T>,
) {
    for _ in 0..TAKE_BURST {
        match sub.take() {
            Ok(None) => return,
            Err(_) => bump(malformed),
            Ok(Some((message, _))) => {
                bump(received);
                if let Some(item) = accept(message)
                    && tx.try_send(item).is_err()
                {
                    bump(dropped);
                }
            }
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
    drive: Receiver<DriveCommand>,
    pilot: Receiver<PilotCommand>,
    counters: Arc<Counters>,
}

impl Ros2Inputs {
    /// The newest estimate accepted since the last call, if any. Never blocks.
    pub fn latest_estimate(&mut self) -> Option<RosEstimate> {
        self.estimates.try_iter().last()
    }

    /// The newest drive command accepted since the last call, if any.
    pub fn latest_drive(&mut self) -> Option<DriveCommand> {
        self.drive.try_iter().last()
    }

    /// The newest pilot input accepted since the last call, if any. Never blocks.
    pub fn latest_pilot(&mut self) -> Option<PilotCommand> {
        self.pilot.try_iter().last()
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

/// Resolves the domain id: the option, else `ROS_DOMAIN_ID`.
fn domain_id(options: Ros2StartOptions) -> Result<u16> {
    match options.domain_id {
        Some(id) => Ok(id),
        None => domain_id_from_env(),
    }
}

/// Starts a node thread: `build` makes the DDS entities on the new thread
/// (errors come back from here, not later), then `run` serves until `stop`.
fn spawn_node_thread<N: 'static>(
    thread_name: &str,
    stop: Arc<AtomicBool>,
    build: impl FnOnce() -> Result<N> + Send + 'static,
    run: fn(N),
) -> Result<Ros2Thread> {
    let (ready_tx, ready_rx) = sync_channel::<Result<()>>(1);
    // DDS entities are built on the thread that uses them.
    let join = std::thread::Builder::new()
        .name(thread_name.into())
        .spawn(move || match build() {
            Ok(node) => {
                let _ = ready_tx.send(Ok(()));
                run(node);
                Ok(())
            }
            Err(e) => {
                let text = e.to_string();
                let _ = ready_tx.send(Err(e));
                Err(IoError::Ros {
                    context: "start".into(),
                    reason: text,
                })
            }
        })
        .map_err(|e| ros_err("node thread", e))?;
    let thread = Ros2Thread {
        stop,
        join: Some(join),
    };
    match ready_rx.recv() {
        Ok(Ok(())) => Ok(thread),
        Ok(Err(e)) => Err(e),
        Err(_) => Err(ros_err("node thread", "ended before it was ready")),
    }
}

/// A node thread's ROS 2 node and DDS participant. Fields drop in order:
/// the node (its `ros_discovery_info` entry), then the participant. Keep it
/// the LAST field of a struct that also holds publishers and subscriptions,
/// so they are dropped (undeclared) while the participant still runs.
struct DdsNode {
    node: Node,
    _context: Context,
}

impl DdsNode {
    /// Drops `endpoints` (RustDDS undeclares them while its event loop
    /// runs), then the node and the participant (which disposes itself).
    /// No wait in between: a grace period of 250 ms changed nothing in a
    /// Fast DDS peer's graph, and it delayed the exit of the SITL server
    /// past the daemon's driver-liveness timeout.
    fn shut_down<E>(self, endpoints: E) {
        drop(endpoints);
        drop(self);
    }
}

/// A DDS participant on `domain` (127.0.0.1 only with `loopback_only`) and
/// a node named `node_name` in the config's namespace.
fn dds_node(config: &Ros2Config, domain: u16, node_name: &str) -> Result<DdsNode> {
    let mut builder = DomainParticipantBuilder::new(domain);
    if config.loopback_only {
        builder = builder
            .with_only_networks([Ipv4Addr::LOCALHOST])
            .same_host_loopback(true);
    }
    let participant = builder
        .build()
        .map_err(|e| ros_err(&format!("DDS participant on domain {domain}"), e))?;
    let context =
        Context::from_domain_participant(participant).map_err(|e| ros_err("context", e))?;
    let name = NodeName::new(&config.namespace, node_name)
        .map_err(|e| ros_err(&format!("node name `{node_name}`"), e))?;
    let node = context
        .new_node(name, NodeOptions::new().enable_rosout(false))
        .map_err(|e| ros_err("node", e))?;
    Ok(DdsNode {
        node,
        _context: context,
    })
}

/// Entry point: [`Ros2Node::start`].
pub struct Ros2Node;

/// Settings that are not in the config file.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Ros2StartOptions {
    /// Overrides `ROS_DOMAIN_ID` (tests run on their own domain).
    pub domain_id: Option<u16>,
}

fn ros_err(context: &str, e: impl std::fmt::Display) -> IoError {
    IoError::Ros {
        context: context.to_string(),
        reason: e.to_string(),
    }
}

/// `(namespace, base)` of an absolute topic name.
fn split_name(topic: &str) -> Result<Name> {
    let (ns, base) = topic.rsplit_once('/').unwrap_or(("", topic));
    let ns = if ns.is_empty() { "/" } else { ns };
    Name::new(ns, base).map_err(|e| ros_err(&format!("topic `{topic}`"), e))
}

fn type_name<M: RosMessage>() -> MessageTypeName {
    let mut parts = M::TYPE_NAME.split('/');
    let pkg = parts.next().unwrap_or_default();
    let name = parts.nth(1).unwrap_or_default();
    MessageTypeName::new(pkg, name)
}

/// Best effort, volatile, keep last 1: streams where a late sample is worth
/// nothing (inputs; PX4 outputs). As a subscription it matches reliable and
/// best-effort publishers.
fn stream_qos() -> QosProfile {
    QosProfile::subscription_default()
}

/// Depth of [`reliable_qos`], ROS 2's default (`rmw_qos_profile_default`).
const RELIABLE_DEPTH: usize = 10;

/// ROS 2's default profile (reliable, volatile, keep last 10), as offered by
/// a publisher that never waits for acknowledgements (`WhenFull::Fail`).
fn reliable_qos() -> QosProfile {
    QosProfile::subscription_default()
        .reliability_reliable(WhenFull::Fail)
        .history(History::KeepLast {
            depth: RELIABLE_DEPTH,
        })
}

fn publisher<M: RosMessage + Serialize>(
    node: &mut Node,
    topic: &TopicConfig,
    qos: &QosProfile,
) -> Result<Option<Publisher<M>>> {
    if !topic.enabled {
        return Ok(None);
    }
    let context = format!("publisher `{}`", topic.name);
    let t = node
        .create_topic(&split_name(&topic.name)?, type_name::<M>(), qos)
        .map_err(|e| ros_err(&context, e))?;
    node.create_publisher::<M>(&t, Some(qos.clone()))
        .map(Some)
        .map_err(|e| ros_err(&context, e))
}

fn subscription<M: RosMessage + DeserializeOwned>(
    node: &mut Node,
    topic: &TopicConfig,
) -> Result<Option<Subscription<M>>> {
    if !topic.enabled {
        return Ok(None);
    }
    let context = format!("subscription `{}`", topic.name);
    let t = node
        .create_topic(&split_name(&topic.name)?, type_name::<M>(), &stream_qos())
        .map_err(|e| ros_err(&context, e))?;
    node.create_subscription::<M>(&t, Some(stream_qos()))
        .map(Some)
        .map_err(|e| ros_err(&context, e))
}

enum EstimateSub {
    Odometry(Subscription<Odometry>),
    Px4(Subscription<VehicleOdometry>),
}

struct NodeThread {
    config: Ros2Config,
    status: Option<Publisher<MpcStatus>>,
    motors: Option<Publisher<ActuatorMotors>>,
    offboard: Option<Publisher<OffboardControlMode>>,
    diagnostics: Option<Publisher<DiagnosticArray>>,
    estimate: Option<EstimateSub>,
    drive: Option<Subscription<Twist>>,
    pilot: Option<Subscription<PilotInput>>,
    out_rx: Receiver<Outgoing>,
    estimate_tx: SyncSender<RosEstimate>,
    drive_tx: SyncSender<DriveCommand>,
    pilot_tx: SyncSender<PilotCommand>,
    counters: Arc<Counters>,
    stop: Arc<AtomicBool>,
    last_stamp: Option<u64>,
    started: Instant,
    /// `type_hash <topic>` = RIHS01 of each enabled topic's type.
    type_hashes: Vec<KeyValue>,
    /// Last: dropped after the endpoints above (see [`DdsNode`]).
    _dds: DdsNode,
}

/// `type_hash <topic>` = the RIHS01 hash of its type, for each enabled topic.
fn topic_type_hashes(topics: &Topics) -> Result<Vec<KeyValue>> {
    let all = [
        &topics.status,
        &topics.estimate,
        &topics.drive_command,
        &topics.pilot,
        &topics.actuator_motors,
        &topics.offboard_mode,
        &topics.diagnostics,
    ];
    all.into_iter()
        .filter(|t| t.enabled)
        .map(|t| {
            Ok(KeyValue {
                key: format!("type_hash {}", t.name),
                value: crate::msg::type_hash(&t.type_name)?,
            })
        })
        .collect()
}

/// At most this many samples are taken from one subscription per loop.
const TAKE_BURST: usize = 256;

impl Ros2Node {
    /// Creates the participant, node, publishers and subscriptions (errors
    /// are returned here, not later), then starts the node thread.
    pub fn start(
        config: &Ros2Config,
        options: Ros2StartOptions,
    ) -> Result<(Ros2Publisher, Ros2Inputs, Ros2Thread)> {
        config.validate(std::path::Path::new("(ros2 config)"))?;
        let domain = domain_id(options)?;
        let config = config.clone();
        let counters = Arc::new(Counters::default());
        let stop = Arc::new(AtomicBool::new(false));
        let (out_tx, out_rx) = sync_channel(config.publish_queue);
        let (estimate_tx, estimate_rx) = sync_channel(16);
        let (drive_tx, drive_rx) = sync_channel(16);
        let (pilot_tx, pilot_rx) = sync_channel(16);
        let channels = NodeChannels {
            out_rx,
            estimate_tx,
            drive_tx,
            pilot_tx,
        };
        let thread_counters = Arc::clone(&counters);
        let thread_stop = Arc::clone(&stop);
        let thread = spawn_node_thread(
            "ros2-node",
            stop,
            move || NodeThread::build(config, domain, channels, thread_counters, thread_stop),
            NodeThread::run,
        )?;
        Ok((
            Ros2Publisher {
                tx: out_tx,
                counters: Arc::clone(&counters),
            },
            Ros2Inputs {
                estimates: estimate_rx,
                drive: drive_rx,
                pilot: pilot_rx,
                counters,
            },
            thread,
        ))
    }
}

/// The node thread's ends of the channels to the control thread.
struct NodeChannels {
    out_rx: Receiver<Outgoing>,
    estimate_tx: SyncSender<RosEstimate>,
    drive_tx: SyncSender<DriveCommand>,
    pilot_tx: SyncSender<PilotCommand>,
}

impl NodeThread {
    fn build(
        config: Ros2Config,
        domain: u16,
        channels: NodeChannels,
        counters: Arc<Counters>,
        stop: Arc<AtomicBool>,
    ) -> Result<Self> {
        let mut dds = dds_node(&config, domain, &config.node_name)?;
        let node = &mut dds.node;
        let t = &config.topics;
        let status = publisher::<MpcStatus>(node, &t.status, &reliable_qos())?;
        let motors = publisher::<ActuatorMotors>(node, &t.actuator_motors, &stream_qos())?;
        let offboard = publisher::<OffboardControlMode>(node, &t.offboard_mode, &stream_qos())?;
        let diagnostics = publisher::<DiagnosticArray>(node, &t.diagnostics, &reliable_qos())?;
        let estimate = if t.estimate.type_name == VehicleOdometry::TYPE_NAME {
            subscription::<VehicleOdometry>(node, &t.estimate)?.map(EstimateSub::Px4)
        } else {
            subscription::<Odometry>(node, &t.estimate)?.map(EstimateSub::Odometry)
        };
        let drive = subscription::<Twist>(node, &t.drive_command)?;
        let pilot = subscription::<PilotInput>(node, &t.pilot)?;
        let type_hashes = topic_type_hashes(t)?;
        let NodeChannels {
            out_rx,
            estimate_tx,
            drive_tx,
            pilot_tx,
        } = channels;
        Ok(Self {
            config,
            status,
            motors,
            offboard,
            diagnostics,
            estimate,
            drive,
            pilot,
            out_rx,
            estimate_tx,
            drive_tx,
            pilot_tx,
            counters,
            stop,
            last_stamp: None,
            started: Instant::now(),
            type_hashes,
            _dds: dds,
        })
    }

    fn run(mut self) {
        let period = Duration::from_millis(self.config.diagnostics_period_ms);
        let mut next_diagnostics = Instant::now() + period;
        while !self.stop.load(Ordering::Relaxed) {
            publish_queued(&self.out_rx, |m| self.publish(m));
            self.take_estimates();
            self.take_drive();
            self.take_pilot();
            if Instant::now() >= next_diagnostics {
                self.publish(Outgoing::Diagnostics(Box::default()));
                next_diagnostics = Instant::now() + period;
            }
        }
        let Self {
            status,
            motors,
            offboard,
            diagnostics,
            estimate,
            drive,
            pilot,
            _dds: dds,
            ..
        } = self;
        dds.shut_down((
            status,
            motors,
            offboard,
            diagnostics,
            estimate,
            drive,
            pilot,
        ));
    }

    fn publish(&self, message: Outgoing) {
        let result = match message {
            Outgoing::Status(m) => self.status.as_ref().map(|p| p.publish(m).is_ok()),
            Outgoing::Motors(m) => self.motors.as_ref().map(|p| p.publish(m).is_ok()),
            Outgoing::Offboard(m) => self.offboard.as_ref().map(|p| p.publish(m).is_ok()),
            Outgoing::Diagnostics(mut m) => {
                m.status.push(self.own_diagnostics());
                if m.header.stamp == Time::default() {
                    m.header.stamp = Time::from_ns(crate::wall_clock_ns());
                }
                self.diagnostics.as_ref().map(|p| p.publish(*m).is_ok())
            }
        };
        count_publish(
            result,
            &self.counters.published,
            &self.counters.publish_errors,
        );
    }

    fn own_diagnostics(&self) -> DiagnosticStatus {
        let c = self.counters.snapshot();
        let rejected =
            c.malformed + c.invalid + c.stamp_backwards + c.drive_rejected + c.pilot_rejected;
        let pairs: [(&str, u64); 13] = [
            ("estimates_received", c.estimates_received),
            ("estimates_accepted", c.estimates_accepted),
            ("malformed", c.malformed),
            ("invalid", c.invalid),
            ("stamp_backwards", c.stamp_backwards),
            ("drive_received", c.drive_received),
            ("drive_rejected", c.drive_rejected),
            ("pilot_received", c.pilot_received),
            ("pilot_rejected", c.pilot_rejected),
            ("inputs_dropped", c.inputs_dropped),
            ("published", c.published),
            ("publish_dropped", c.publish_dropped),
            ("publish_errors", c.publish_errors),
        ];
        DiagnosticStatus {
            level: if rejected + c.publish_dropped + c.publish_errors > 0 {
                DiagnosticStatus::WARN
            } else {
                DiagnosticStatus::OK
            },
            name: "atmo/ros2".into(),
            message: if rejected > 0 {
                format!("{rejected} inputs rejected")
            } else {
                "ok".into()
            },
            hardware_id: self.config.node_name.clone(),
            values: pairs
                .iter()
                .map(|(k, v)| KeyValue {
                    key: (*k).to_string(),
                    value: v.to_string(),
                })
                .chain(std::iter::once(KeyValue {
                    key: "uptime_s".into(),
                    value: format!("{:.1}", self.started.elapsed().as_secs_f64()),
                }))
                .chain(self.type_hashes.iter().cloned())
                .collect(),
        }
    }

    fn take_estimates(&mut self) {
        let topic = self.config.topics.estimate.name.clone();
        for _ in 0..TAKE_BURST {
            let converted: Option<std::result::Result<(u64, State), IoError>> = match &self.estimate
            {
                None => return,
                Some(EstimateSub::Odometry(sub)) => match sub.take() {
                    Ok(None) => return,
                    Ok(Some((odom, _))) => Some(odom.header.stamp.to_ns().map_or_else(
                        || {
                            Err(IoError::InvalidField {
                                topic: topic.clone(),
                                field: "header.stamp",
                                reason: "negative or invalid time".into(),
                            })
                        },
                        |stamp| odometry_to_state(&topic, &odom).map(|x| (stamp, x)),
                    )),
                    Err(_) => None,
                },
                Some(EstimateSub::Px4(sub)) => match sub.take() {
                    Ok(None) => return,
                    Ok(Some((odom, _))) => Some(
                        vehicle_odometry_to_state(&topic, &odom)
                            .map(|x| (odom.timestamp_sample.saturating_mul(1000), x)),
                    ),
                    Err(_) => None,
                },
            };
            match converted {
                None => bump(&self.counters.malformed),
                Some(Err(_)) => {
                    bump(&self.counters.estimates_received);
                    bump(&self.counters.invalid);
                }
                Some(Ok((stamp_ns, state))) => {
                    bump(&self.counters.estimates_received);
                    if self.last_stamp.is_some_and(|last| stamp_ns <= last) {
                        bump(&self.counters.stamp_backwards);
                        continue;
                    }
                    self.last_stamp = Some(stamp_ns);
                    bump(&self.counters.estimates_accepted);
                    let estimate = RosEstimate {
                        stamp_ns,
                        received: Instant::now(),
                        state,
                    };
                    if self.estimate_tx.try_send(estimate).is_err() {
                        bump(&self.counters.inputs_dropped);
                    }
                }
            }
        }
    }

    fn take_drive(&self) {
        let Some(sub) = &self.drive else { return };
        let c = &self.counters;
        take_burst(
            sub,
            &c.malformed,
            &c.drive_received,
            &c.inputs_dropped,
            &self.drive_tx,
            |twist: Twist| {
                let (forward, yaw_rate) = (twist.linear.x, -twist.angular.z);
                if !forward.is_finite() || !yaw_rate.is_finite() {
                    bump(&c.drive_rejected);
                    return None;
                }
                Some(DriveCommand {
                    forward,
                    yaw_rate,
                    received: Instant::now(),
                })
            },
        );
    }

    fn take_pilot(&self) {
        let Some(sub) = &self.pilot else { return };
        let c = &self.counters;
        take_burst(
            sub,
            &c.malformed,
            &c.pilot_received,
            &c.inputs_dropped,
            &self.pilot_tx,
            |input: PilotInput| {
                if !pilot_is_valid(&input) {
                    bump(&c.pilot_rejected);
                    return None;
                }
                Some(PilotCommand {
                    input,
                    received: Instant::now(),
                })
            },
        );
    }
}
