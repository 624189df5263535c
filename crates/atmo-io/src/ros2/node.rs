//! The daemon's node thread: builds the publishers and subscriptions of
//! [`Ros2Config`], publishes what the control thread queues, and checks,
//! converts and counts every input before it reaches the control thread.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, SyncSender, sync_channel};
use std::time::{Duration, Instant};

use atmo_core::ConfigFile;
use atmo_core::model::State;
use ros2_client::{Publisher, Subscription};
use serde::de::DeserializeOwned;

use super::dds::{
    DdsNode, TAKE_BURST, bump, count_publish, dds_node, domain_id, publish_queued, publisher,
    reliable_qos, spawn_node_thread, stream_qos, subscription, take_burst,
};
use super::{
    Counters, DriveCommand, EscFrame, GroundHeight, GroundNormal, Outgoing, PilotCommand, RcFrame,
    Ros2Config, Ros2Inputs, Ros2Node, Ros2Publisher, Ros2StartOptions, Ros2Thread, RosClock,
    RosEstimate,
};
use crate::error::{IoError, Result};
use crate::msg::frames::{odometry_to_state, vehicle_odometry_to_state};
use crate::msg::{
    ActuatorMotors, Clock, DiagnosticArray, DiagnosticStatus, EscStatus, InputRc, KeyValue,
    MpcStatus, Odometry, OffboardControlMode, PilotInput, PointStamped, RosMessage, Time, Twist,
    Vector3Stamped, VehicleOdometry,
};
use crate::stamp_order::StampOrder;

/// Whether a pilot input may be used: every number finite, throttle in [0, 1].
fn pilot_is_valid(p: &PilotInput) -> bool {
    p.velocity.iter().all(|v| v.is_finite())
        && p.yaw_rate.is_finite()
        && (0.0..=1.0).contains(&p.throttle)
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
    autopilot_estimate: Option<Subscription<VehicleOdometry>>,
    drive: Option<Subscription<Twist>>,
    pilot: Option<Subscription<PilotInput>>,
    rc: Option<Subscription<InputRc>>,
    esc: Option<Subscription<EscStatus>>,
    ground: Option<Subscription<PointStamped>>,
    ground_normal: Option<Subscription<Vector3Stamped>>,
    /// `topics.clock`, with `use_sim_time` only.
    clock_sub: Option<Subscription<Clock>>,
    out_rx: Receiver<Outgoing>,
    estimate_tx: SyncSender<RosEstimate>,
    autopilot_tx: SyncSender<RosEstimate>,
    drive_tx: SyncSender<DriveCommand>,
    pilot_tx: SyncSender<PilotCommand>,
    rc_tx: SyncSender<RcFrame>,
    esc_tx: SyncSender<EscFrame>,
    ground_tx: SyncSender<GroundHeight>,
    ground_normal_tx: SyncSender<GroundNormal>,
    clock: Arc<RosClock>,
    counters: Arc<Counters>,
    stop: Arc<AtomicBool>,
    /// The estimate stamps' order rule (duplicates, reordering, clock jumps).
    estimate_order: StampOrder,
    started: Instant,
    /// `type_hash <topic>` = RIHS01 of each enabled topic's type.
    type_hashes: Vec<KeyValue>,
    /// Last: dropped after the endpoints above (see [`DdsNode`]).
    _dds: DdsNode,
}

/// `type_hash <topic>` = the RIHS01 hash of its type, for each topic the
/// node uses.
fn topic_type_hashes(config: &Ros2Config) -> Result<Vec<KeyValue>> {
    let topics = &config.topics;
    let all = [
        &topics.status,
        &topics.estimate,
        &topics.drive_command,
        &topics.pilot,
        &topics.actuator_motors,
        &topics.offboard_mode,
        &topics.diagnostics,
        &topics.ground,
        &topics.ground_normal,
        &topics.rc,
        &topics.esc_status,
        &topics.autopilot_estimate,
    ];
    let clock = config.use_sim_time.then_some(&topics.clock);
    all.into_iter()
        .chain(clock)
        .filter(|t| t.enabled)
        .map(|t| {
            Ok(KeyValue {
                key: format!("type_hash {}", t.name),
                value: crate::msg::type_hash(&t.type_name)?,
            })
        })
        .collect()
}

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
        let (autopilot_tx, autopilot_rx) = sync_channel(16);
        let (drive_tx, drive_rx) = sync_channel(16);
        let (pilot_tx, pilot_rx) = sync_channel(16);
        let (rc_tx, rc_rx) = sync_channel(16);
        let (esc_tx, esc_rx) = sync_channel(16);
        let (ground_tx, ground_rx) = sync_channel(16);
        let (ground_normal_tx, ground_normal_rx) = sync_channel(16);
        let clock = Arc::new(RosClock {
            use_sim_time: config.use_sim_time,
            sim_ns: 0.into(),
        });
        let channels = NodeChannels {
            out_rx,
            estimate_tx,
            autopilot_tx,
            drive_tx,
            pilot_tx,
            rc_tx,
            esc_tx,
            ground_tx,
            ground_normal_tx,
            clock: Arc::clone(&clock),
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
                autopilot_estimates: autopilot_rx,
                drive: drive_rx,
                pilot: pilot_rx,
                rc: rc_rx,
                esc: esc_rx,
                ground: ground_rx,
                ground_normal: ground_normal_rx,
                clock,
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
    autopilot_tx: SyncSender<RosEstimate>,
    drive_tx: SyncSender<DriveCommand>,
    pilot_tx: SyncSender<PilotCommand>,
    rc_tx: SyncSender<RcFrame>,
    esc_tx: SyncSender<EscFrame>,
    ground_tx: SyncSender<GroundHeight>,
    ground_normal_tx: SyncSender<GroundNormal>,
    clock: Arc<RosClock>,
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
        let autopilot_estimate = subscription::<VehicleOdometry>(node, &t.autopilot_estimate)?;
        let drive = subscription::<Twist>(node, &t.drive_command)?;
        let pilot = subscription::<PilotInput>(node, &t.pilot)?;
        let rc = subscription::<InputRc>(node, &t.rc)?;
        let esc = subscription::<EscStatus>(node, &t.esc_status)?;
        let ground = subscription::<PointStamped>(node, &t.ground)?;
        let ground_normal = subscription::<Vector3Stamped>(node, &t.ground_normal)?;
        let clock_sub = if config.use_sim_time {
            subscription::<Clock>(node, &t.clock)?
        } else {
            None
        };
        let type_hashes = topic_type_hashes(&config)?;
        let NodeChannels {
            out_rx,
            estimate_tx,
            autopilot_tx,
            drive_tx,
            pilot_tx,
            rc_tx,
            esc_tx,
            ground_tx,
            ground_normal_tx,
            clock,
        } = channels;
        Ok(Self {
            config,
            status,
            motors,
            offboard,
            diagnostics,
            estimate,
            autopilot_estimate,
            drive,
            pilot,
            rc,
            esc,
            ground,
            ground_normal,
            clock_sub,
            out_rx,
            estimate_tx,
            autopilot_tx,
            drive_tx,
            pilot_tx,
            rc_tx,
            esc_tx,
            ground_tx,
            ground_normal_tx,
            clock,
            counters,
            stop,
            estimate_order: StampOrder::default(),
            started: Instant::now(),
            type_hashes,
            _dds: dds,
        })
    }

    fn run(mut self) -> Result<()> {
        let period = Duration::from_millis(self.config.diagnostics_period_ms);
        let mut next_diagnostics = Instant::now() + period;
        while !self.stop.load(Ordering::Relaxed) {
            publish_queued(&self.out_rx, |m| self.publish(m));
            self.take_estimates();
            self.take_autopilot_estimates();
            self.take_drive();
            self.take_pilot();
            self.take_rc();
            self.take_esc();
            self.take_ground();
            self.take_ground_normal();
            self.take_clock();
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
            autopilot_estimate,
            drive,
            pilot,
            rc,
            esc,
            ground,
            ground_normal,
            clock_sub,
            _dds: dds,
            ..
        } = self;
        dds.shut_down((
            status,
            motors,
            offboard,
            diagnostics,
            estimate,
            autopilot_estimate,
            drive,
            pilot,
            rc,
            esc,
            ground,
            ground_normal,
            clock_sub,
        ))
    }

    fn publish(&self, message: Outgoing) {
        let result = match message {
            Outgoing::Status(m) => self.status.as_ref().map(|p| p.publish(m).is_ok()),
            Outgoing::Motors(m) => self.motors.as_ref().map(|p| p.publish(m).is_ok()),
            Outgoing::Offboard(m) => self.offboard.as_ref().map(|p| p.publish(m).is_ok()),
            Outgoing::Diagnostics(mut m) => {
                m.status.push(self.own_diagnostics());
                if m.header.stamp == Time::default() {
                    m.header.stamp = Time::from_ns(self.clock.now_ns());
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
        let rejected = c.malformed
            + c.invalid
            + c.stamp_backwards
            + c.drive_rejected
            + c.pilot_rejected
            + c.rc_rejected
            + c.esc_rejected
            + c.ground_rejected
            + c.ground_normal_rejected
            + c.autopilot_rejected
            + c.clock_rejected;
        let pairs: [(&str, u64); 26] = [
            ("estimates_received", c.estimates_received),
            ("estimates_accepted", c.estimates_accepted),
            ("malformed", c.malformed),
            ("invalid", c.invalid),
            ("stamp_backwards", c.stamp_backwards),
            ("clock_jumps", c.clock_jumps),
            ("autopilot_received", c.autopilot_received),
            ("autopilot_rejected", c.autopilot_rejected),
            ("drive_received", c.drive_received),
            ("drive_rejected", c.drive_rejected),
            ("pilot_received", c.pilot_received),
            ("pilot_rejected", c.pilot_rejected),
            ("rc_received", c.rc_received),
            ("rc_rejected", c.rc_rejected),
            ("esc_received", c.esc_received),
            ("esc_rejected", c.esc_rejected),
            ("ground_received", c.ground_received),
            ("ground_rejected", c.ground_rejected),
            ("ground_normal_received", c.ground_normal_received),
            ("ground_normal_rejected", c.ground_normal_rejected),
            ("clock_received", c.clock_received),
            ("clock_rejected", c.clock_rejected),
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
                    let jumps = self.estimate_order.clock_jumps();
                    if !self.estimate_order.accept(stamp_ns) {
                        bump(&self.counters.stamp_backwards);
                        continue;
                    }
                    if self.estimate_order.clock_jumps() > jumps {
                        bump(&self.counters.clock_jumps);
                    }
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

    /// Takes a burst from the input subscription `sub` (if enabled): each
    /// decoded message counts `received`, and `check` turns it into what the
    /// control thread gets, or `None` for a rejected one (counted in
    /// `rejected`).
    fn take_input<M: 'static + DeserializeOwned, T>(
        &self,
        sub: Option<&Subscription<M>>,
        received: &AtomicU64,
        rejected: &AtomicU64,
        tx: &SyncSender<T>,
        check: impl Fn(M) -> Option<T>,
    ) {
        let Some(sub) = sub else { return };
        let c = &self.counters;
        take_burst(sub, &c.malformed, received, &c.inputs_dropped, tx, |m| {
            let accepted = check(m);
            if accepted.is_none() {
                bump(rejected);
            }
            accepted
        });
    }

    fn take_drive(&self) {
        let c = &self.counters;
        self.take_input(
            self.drive.as_ref(),
            &c.drive_received,
            &c.drive_rejected,
            &self.drive_tx,
            |twist: Twist| {
                let (forward, yaw_rate) = (twist.linear.x, -twist.angular.z);
                (forward.is_finite() && yaw_rate.is_finite()).then(|| DriveCommand {
                    forward,
                    yaw_rate,
                    received: Instant::now(),
                })
            },
        );
    }

    fn take_pilot(&self) {
        let c = &self.counters;
        self.take_input(
            self.pilot.as_ref(),
            &c.pilot_received,
            &c.pilot_rejected,
            &self.pilot_tx,
            |input: PilotInput| {
                pilot_is_valid(&input).then(|| PilotCommand {
                    input,
                    received: Instant::now(),
                })
            },
        );
    }

    fn take_rc(&self) {
        let c = &self.counters;
        self.take_input(
            self.rc.as_ref(),
            &c.rc_received,
            &c.rc_rejected,
            &self.rc_tx,
            |input: InputRc| {
                (input.channel_count <= InputRc::RC_INPUT_MAX_CHANNELS).then(|| RcFrame {
                    input,
                    received: Instant::now(),
                })
            },
        );
    }

    /// ESC reports: at most [`EscStatus::CONNECTED_ESC_MAX`] ESCs, else
    /// rejected; their speeds are the daemon's to read (its `[esc]`).
    fn take_esc(&self) {
        let c = &self.counters;
        self.take_input(
            self.esc.as_ref(),
            &c.esc_received,
            &c.esc_rejected,
            &self.esc_tx,
            |status: EscStatus| {
                (status.esc_count <= EscStatus::CONNECTED_ESC_MAX).then(|| EscFrame {
                    status,
                    received: Instant::now(),
                })
            },
        );
    }

    fn take_ground(&self) {
        let c = &self.counters;
        self.take_input(
            self.ground.as_ref(),
            &c.ground_received,
            &c.ground_rejected,
            &self.ground_tx,
            |ground: PointStamped| {
                ground.point.z.is_finite().then(|| GroundHeight {
                    z: -ground.point.z,
                    received: Instant::now(),
                })
            },
        );
    }

    /// The autopilot's estimates: converted as PX4's odometry `estimate`
    /// is, an invalid one counted in `autopilot_rejected`. No order rule:
    /// the flight stack refuses one stamped before the last, and it ages
    /// from acceptance here.
    fn take_autopilot_estimates(&self) {
        let c = &self.counters;
        let topic = &self.config.topics.autopilot_estimate.name;
        self.take_input(
            self.autopilot_estimate.as_ref(),
            &c.autopilot_received,
            &c.autopilot_rejected,
            &self.autopilot_tx,
            |odom: VehicleOdometry| {
                vehicle_odometry_to_state(topic, &odom)
                    .ok()
                    .map(|state| RosEstimate {
                        stamp_ns: odom.timestamp_sample.saturating_mul(1000),
                        received: Instant::now(),
                        state,
                    })
            },
        );
    }

    fn take_ground_normal(&self) {
        let c = &self.counters;
        self.take_input(
            self.ground_normal.as_ref(),
            &c.ground_normal_received,
            &c.ground_normal_rejected,
            &self.ground_normal_tx,
            |normal: Vector3Stamped| {
                let v = normal.vector;
                // ENU to NED: (east, north, up) -> (north, east, down).
                let ned = [v.y, v.x, -v.z];
                ned.iter().all(|c| c.is_finite()).then(|| GroundNormal {
                    normal: ned,
                    received: Instant::now(),
                })
            },
        );
    }

    /// `use_sim_time`: the newest valid `/clock` is ROS time from now on.
    fn take_clock(&self) {
        let Some(sub) = &self.clock_sub else { return };
        let c = &self.counters;
        for _ in 0..TAKE_BURST {
            match sub.take() {
                Ok(None) => return,
                Err(_) => bump(&c.malformed),
                Ok(Some((message, _))) => {
                    bump(&c.clock_received);
                    match message.clock.to_ns() {
                        Some(ns) => self.clock.sim_ns.store(ns, Ordering::Relaxed),
                        None => bump(&c.clock_rejected),
                    }
                }
            }
        }
    }
}
