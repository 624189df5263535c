//! The plant side of software-in-the-loop: the peer of [`Ros2Node`].
//!
//! The SITL plant server runs the simulated robot and talks to the
//! unchanged `atmo-daemon` binary over ROS 2, using the same [`Ros2Config`]
//! as the daemon, so both sides agree on topic names and types:
//!
//! | topic | SITL side | daemon side |
//! | --- | --- | --- |
//! | `topics.estimate` | publishes the plant's state | [`Ros2Inputs::latest_estimate`](super::Ros2Inputs::latest_estimate) |
//! | `topics.autopilot_estimate` (when enabled) | publishes the autopilot's own estimate of the same instant (the same state unless given apart) | [`Ros2Inputs::latest_autopilot_estimate`](super::Ros2Inputs::latest_autopilot_estimate) |
//! | `topics.pilot` | publishes pilot inputs | [`Ros2Inputs::latest_pilot`](super::Ros2Inputs::latest_pilot) |
//! | `topics.esc_status` (when enabled) | publishes the rotors' RPM as PX4's `EscStatus` (four ESCs online, each its motor's) | [`Ros2Inputs::latest_esc`](super::Ros2Inputs::latest_esc) |
//! | `topics.status` | [`SitlInputs::latest_status`] | publishes one status per tick |
//!
//! Each estimate goes out on the estimate topic and, when enabled, the
//! autopilot's ([`SitlPublisher::try_publish_estimates`] gives the latter
//! its own state; it is the flight stack's fallback when the first is
//! lost: a test cuts the first and the daemon lands on the second), each
//! as the type the config names: `nav_msgs/Odometry` (converted to ENU/FLU by
//! [`state_to_odometry`]; the daemon converts it back to NED/FRD) or
//! `px4_msgs/VehicleOdometry` (NED/FRD, float32, by
//! [`state_to_vehicle_odometry`]; the stamp is sent in whole microseconds,
//! so the daemon sees `stamp_ns` rounded down to a microsecond). The
//! daemon drops estimates whose stamp does not increase: send increasing
//! stamps.
//!
//! As on the daemon side, a dedicated thread owns the DDS entities; the
//! plant's loop only touches bounded queues and never waits (a full queue
//! drops and counts, [`SitlCounters`]). The node is named
//! `<node_name>_sitl` in the config's namespace; the domain id comes from
//! [`Ros2StartOptions::domain_id`] or `ROS_DOMAIN_ID`. A disabled topic is
//! left out: its publishes are accepted and ignored, and
//! [`SitlInputs::latest_status`] then never returns a status.
//!
//! [`Ros2Node`]: super::Ros2Node

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, SyncSender, sync_channel};

use atmo_core::ConfigFile;
use atmo_core::model::State;
use ros2_client::{Node, Publisher, QosProfile, Subscription};

use super::dds::{
    DdsNode, count_publish, dds_node, domain_id, publish_queued, publisher, spawn_node_thread,
    stream_qos, subscription, take_burst, try_queue,
};
use super::{Ros2Config, Ros2StartOptions, Ros2Thread, TopicConfig};
use crate::error::Result;
use crate::msg::frames::{state_to_odometry, state_to_vehicle_odometry};
use crate::msg::{EscStatus, MpcStatus, Odometry, PilotInput, RosMessage, VehicleOdometry};

/// What the SITL node has seen and done so far (monotonic counters).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct SitlCounters {
    /// Messages handed to DDS (estimates and pilot inputs).
    pub published: u64,
    /// Records dropped because the publish queue was full.
    pub publish_dropped: u64,
    /// Publishes the DDS layer refused.
    pub publish_errors: u64,
    /// Statuses that decoded.
    pub status_received: u64,
    /// Payloads on the status topic that did not decode as `MpcStatus`.
    pub malformed: u64,
    /// Received statuses dropped because the reader's queue was full.
    pub inputs_dropped: u64,
}

#[derive(Default)]
struct Counters {
    published: AtomicU64,
    publish_dropped: AtomicU64,
    publish_errors: AtomicU64,
    status_received: AtomicU64,
    malformed: AtomicU64,
    inputs_dropped: AtomicU64,
}

impl Counters {
    fn snapshot(&self) -> SitlCounters {
        let g = |a: &AtomicU64| a.load(Ordering::Relaxed);
        SitlCounters {
            published: g(&self.published),
            publish_dropped: g(&self.publish_dropped),
            publish_errors: g(&self.publish_errors),
            status_received: g(&self.status_received),
            malformed: g(&self.malformed),
            inputs_dropped: g(&self.inputs_dropped),
        }
    }
}

#[derive(Clone, Copy)]
enum Outgoing {
    Estimate {
        state: State,
        autopilot: State,
        stamp_ns: u64,
    },
    Pilot(PilotInput),
    /// The four rotors' RPM (the node thread makes the `EscStatus`).
    RotorRpm([i32; 4]),
}

/// The plant's sending side (`Clone + Send`; never blocks, never allocates).
#[derive(Clone)]
pub struct SitlPublisher {
    tx: SyncSender<Outgoing>,
    counters: Arc<Counters>,
}

impl SitlPublisher {
    fn send(&self, message: Outgoing) -> bool {
        try_queue(&self.tx, message, &self.counters.publish_dropped)
    }

    /// Queues the plant's state (NED/FRD 12-state) for `topics.estimate`
    /// and, when enabled, `topics.autopilot_estimate`, stamped `stamp_ns`;
    /// false if dropped (counted). The node thread converts it to each
    /// topic's type (see the module docs).
    pub fn try_publish_estimate(&self, state: &State, stamp_ns: u64) -> bool {
        self.try_publish_estimates(state, state, stamp_ns)
    }

    /// As [`Self::try_publish_estimate`], with the autopilot's own estimate
    /// of the same instant (its errors differ from the motion capture's)
    /// for `topics.autopilot_estimate`.
    pub fn try_publish_estimates(&self, state: &State, autopilot: &State, stamp_ns: u64) -> bool {
        self.send(Outgoing::Estimate {
            state: *state,
            autopilot: *autopilot,
            stamp_ns,
        })
    }

    /// Queues the four rotors' RPM (the robot file's rotor order) for
    /// `topics.esc_status` as PX4 publishes it: four ESCs, online and
    /// armed, ESC k driving motor k + 1; false if dropped (counted).
    pub fn try_publish_rotor_rpm(&self, rpm: [i32; 4]) -> bool {
        self.send(Outgoing::RotorRpm(rpm))
    }

    /// Queues one pilot input for `topics.pilot`; false if dropped (counted).
    /// Sent as given: the daemon's node rejects non-finite numbers and a
    /// throttle outside [0, 1].
    pub fn try_publish_pilot(&self, input: &PilotInput) -> bool {
        self.send(Outgoing::Pilot(*input))
    }

    pub fn counters(&self) -> SitlCounters {
        self.counters.snapshot()
    }
}

/// The plant's receiving side (`Send`, one owner).
pub struct SitlInputs {
    status: Receiver<MpcStatus>,
    counters: Arc<Counters>,
}

impl SitlInputs {
    /// The newest daemon status received since the last call, if any.
    /// Never blocks.
    pub fn latest_status(&mut self) -> Option<MpcStatus> {
        self.status.try_iter().last()
    }

    pub fn counters(&self) -> SitlCounters {
        self.counters.snapshot()
    }
}

/// Entry point: [`SitlNode::start`].
pub struct SitlNode;

impl SitlNode {
    /// The SITL node's ROS 2 name: `<node_name>_sitl`.
    pub fn node_name(config: &Ros2Config) -> String {
        format!("{}_sitl", config.node_name.trim_end_matches('_'))
    }

    /// Validates `config` (the daemon's), creates the participant, node,
    /// publishers and subscription (errors are returned here, not later),
    /// then starts the node thread. Stop it with [`Ros2Thread::stop`].
    pub fn start(
        config: &Ros2Config,
        options: Ros2StartOptions,
    ) -> Result<(SitlPublisher, SitlInputs, Ros2Thread)> {
        config.validate(std::path::Path::new("(ros2 config)"))?;
        let domain = domain_id(options)?;
        let config = config.clone();
        let counters = Arc::new(Counters::default());
        let stop = Arc::new(AtomicBool::new(false));
        let (out_tx, out_rx) = sync_channel(config.publish_queue);
        let (status_tx, status_rx) = sync_channel(16);
        let thread_counters = Arc::clone(&counters);
        let thread_stop = Arc::clone(&stop);
        let thread = spawn_node_thread(
            "ros2-sitl",
            stop,
            move || {
                SitlThread::build(
                    &config,
                    domain,
                    out_rx,
                    status_tx,
                    thread_counters,
                    thread_stop,
                )
            },
            SitlThread::run,
        )?;
        Ok((
            SitlPublisher {
                tx: out_tx,
                counters: Arc::clone(&counters),
            },
            SitlInputs {
                status: status_rx,
                counters,
            },
            thread,
        ))
    }
}

enum EstimatePub {
    Odometry(Publisher<Odometry>),
    Px4(Publisher<VehicleOdometry>),
}

impl EstimatePub {
    /// The publisher of `topic` (None when disabled), of the type it names.
    fn new(node: &mut Node, topic: &TopicConfig, qos: &QosProfile) -> Result<Option<Self>> {
        Ok(if topic.type_name == VehicleOdometry::TYPE_NAME {
            publisher::<VehicleOdometry>(node, topic, qos)?.map(Self::Px4)
        } else {
            publisher::<Odometry>(node, topic, qos)?.map(Self::Odometry)
        })
    }

    /// Publishes `state` (see the module docs for the conversions).
    fn publish(&self, state: &State, stamp_ns: u64) -> bool {
        match self {
            Self::Odometry(p) => p.publish(state_to_odometry(state, stamp_ns)).is_ok(),
            Self::Px4(p) => p
                .publish(state_to_vehicle_odometry(state, stamp_ns / 1000))
                .is_ok(),
        }
    }
}

struct SitlThread {
    estimate: Option<EstimatePub>,
    autopilot_estimate: Option<EstimatePub>,
    pilot: Option<Publisher<PilotInput>>,
    esc: Option<Publisher<EscStatus>>,
    status: Option<Subscription<MpcStatus>>,
    out_rx: Receiver<Outgoing>,
    status_tx: SyncSender<MpcStatus>,
    counters: Arc<Counters>,
    stop: Arc<AtomicBool>,
    /// Last: dropped after the endpoints above (see [`DdsNode`]).
    _dds: DdsNode,
}

impl SitlThread {
    fn build(
        config: &Ros2Config,
        domain: u16,
        out_rx: Receiver<Outgoing>,
        status_tx: SyncSender<MpcStatus>,
        counters: Arc<Counters>,
        stop: Arc<AtomicBool>,
    ) -> Result<Self> {
        let mut dds = dds_node(config, domain, &SitlNode::node_name(config))?;
        let node = &mut dds.node;
        let t = &config.topics;
        // Sensor-style streams, as a motion-capture system and a radio send.
        let qos = stream_qos();
        let estimate = EstimatePub::new(node, &t.estimate, &qos)?;
        let autopilot_estimate = EstimatePub::new(node, &t.autopilot_estimate, &qos)?;
        let pilot = publisher::<PilotInput>(node, &t.pilot, &qos)?;
        let esc = publisher::<EscStatus>(node, &t.esc_status, &qos)?;
        let status = subscription::<MpcStatus>(node, &t.status)?;
        Ok(Self {
            estimate,
            autopilot_estimate,
            pilot,
            esc,
            status,
            out_rx,
            status_tx,
            counters,
            stop,
            _dds: dds,
        })
    }

    fn run(self) -> Result<()> {
        while !self.stop.load(Ordering::Relaxed) {
            publish_queued(&self.out_rx, |m| self.publish(m));
            self.take_status();
        }
        let Self {
            estimate,
            autopilot_estimate,
            pilot,
            esc,
            status,
            _dds: dds,
            ..
        } = self;
        dds.shut_down((estimate, autopilot_estimate, pilot, esc, status))
    }

    fn publish(&self, message: Outgoing) {
        let count = |result| {
            count_publish(
                result,
                &self.counters.published,
                &self.counters.publish_errors,
            );
        };
        match message {
            Outgoing::Estimate {
                state,
                autopilot,
                stamp_ns,
            } => {
                for (topic, state) in [
                    (&self.estimate, &state),
                    (&self.autopilot_estimate, &autopilot),
                ] {
                    count(topic.as_ref().map(|p| p.publish(state, stamp_ns)));
                }
            }
            Outgoing::Pilot(m) => count(self.pilot.as_ref().map(|p| p.publish(m).is_ok())),
            Outgoing::RotorRpm(rpm) => {
                let mut status = EscStatus {
                    esc_count: 4,
                    esc_online_flags: 0b1111,
                    esc_armed_flags: 0b1111,
                    ..EscStatus::default()
                };
                for (k, (report, rpm)) in status.esc.iter_mut().zip(rpm).enumerate() {
                    report.esc_rpm = rpm;
                    report.actuator_function = EscStatus::ACTUATOR_FUNCTION_MOTOR1 + k as u8;
                }
                count(self.esc.as_ref().map(|p| p.publish(status).is_ok()));
            }
        }
    }

    fn take_status(&self) {
        let Some(sub) = &self.status else { return };
        let c = &self.counters;
        take_burst(
            sub,
            &c.malformed,
            &c.status_received,
            &c.inputs_dropped,
            &self.status_tx,
            Some,
        );
    }
}
