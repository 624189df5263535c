//! Driver ports over iceoryx2 (zero-copy shared memory, publish-subscribe).
//!
//! Services (under a configurable prefix, default `atmo/drivers`):
//!
//! | service | payload | from -> to |
//! | --- | --- | --- |
//! | `<prefix>/thrusters` | [`ThrusterCommand`] | daemon -> thruster driver |
//! | `<prefix>/tilt_velocity` | [`TiltVelocityCommand`] | daemon -> tilt driver |
//! | `<prefix>/wheel_rates` | [`WheelRateCommand`] | daemon -> wheel driver |
//! | `<prefix>/tilt_encoder` | [`TiltEncoder`] | tilt driver -> daemon |
//! | `<prefix>/ground_contact` | [`GroundContact`] | contact sensor -> daemon |
//! | `<prefix>/heartbeat` | [`DriverHeartbeat`] | every driver -> daemon |
//! | `<prefix>/commands_sent` | event | daemon -> drivers: wakes drivers waiting for commands |
//!
//! Every sample carries a per-publisher sequence number and a
//! CLOCK_MONOTONIC stamp ([`monotonic_ns`]). Sending never blocks: a full
//! subscriber buffer loses its oldest sample (safe overflow).
//!
//! Liveness: the daemon side ([`FlightPorts`]) records when it last heard
//! from each driver (heartbeats, and the sensor streams themselves); a
//! driver not heard from within `liveness_timeout_ms` is reported dead in
//! [`DriverHealth`] (the flight stack's failsafe input), whether it stopped
//! publishing or its process died. Dead nodes' resources are then cleaned
//! so that a restarted driver reconnects. At start-up, [`cleanup_stale`]
//! removes what a crashed run left in `/tmp/iceoryx2` and `/dev/shm`.
//!
//! Ports of `ipc::Service` are not `Send`: open them on the thread that
//! uses them (the control thread).

mod payloads;

pub use payloads::{
    DriverHeartbeat, GroundContact, PortHeader, ThrusterCommand, TiltEncoder, TiltVelocityCommand,
    WheelRateCommand,
};

use std::fmt::Debug;
use std::path::Path;

use atmo_core::config_file::{Checker, ConfigFile};

use iceoryx2::node::{Node, NodeBuilder, NodeState};
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::{
    CallbackProgression, Config, FileName, LogLevel, NodeName, SemanticString, ServiceName,
    ZeroCopySend, set_log_level_from_env_or,
};
use iceoryx2::service::ipc;

use crate::error::{IoError, Result};

/// CLOCK_MONOTONIC in ns: the stamp clock of every driver-port sample.
pub fn monotonic_ns() -> u64 {
    let t = rustix::time::clock_gettime(rustix::time::ClockId::Monotonic);
    t.tv_sec as u64 * 1_000_000_000 + t.tv_nsec as u64
}

/// The drivers the daemon watches.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u32)]
pub enum DriverId {
    Thrusters = 0,
    Tilt = 1,
    Wheels = 2,
    GroundContact = 3,
}

impl DriverId {
    pub const ALL: [DriverId; 4] = [
        DriverId::Thrusters,
        DriverId::Tilt,
        DriverId::Wheels,
        DriverId::GroundContact,
    ];

    pub fn from_u32(v: u32) -> Option<Self> {
        Self::ALL.get(v as usize).copied()
    }

    pub fn name(self) -> &'static str {
        match self {
            Self::Thrusters => "thrusters",
            Self::Tilt => "tilt",
            Self::Wheels => "wheels",
            Self::GroundContact => "ground_contact",
        }
    }
}

atmo_core::params! {
    /// Driver-port settings (a `[drivers]`-style TOML table; all optional).
    #[derive(Debug, Clone, PartialEq, Eq)]
    pub struct DriverPortsConfig: Default {
        /// Service name prefix (letters, digits, `_ / -`).
        pub prefix: String = "atmo/drivers".into();
        /// A driver not heard from for this long is dead.
        pub liveness_timeout_ms: u64 = 100, range 1..=10_000, unit "ms";
        /// iceoryx2 file prefix (isolates runs: tests use their own), at
        /// most 32 letters, digits or `_`. Empty: iceoryx2's default.
        pub iceoryx_prefix: String = String::new();
        /// Drivers whose liveness is required (by name: thrusters, tilt,
        /// wheels, ground_contact).
        pub required: Vec<String> =
            DriverId::ALL.iter().map(|d| d.name().to_string()).collect();
    }
    check |ports, c, prefix| ports.check_names(c, prefix)
}

impl DriverPortsConfig {
    /// The prefixes' characters and the required drivers' names; errors
    /// name `prefix.<key>`.
    fn check_names(&self, c: &Checker<'_>, prefix: &str) -> atmo_core::Result<()> {
        let key = |name| atmo_core::params::key(prefix, name);
        if self.prefix.is_empty()
            || !self
                .prefix
                .chars()
                .all(|ch| ch.is_ascii_alphanumeric() || "_/-".contains(ch))
        {
            return Err(c.fail(
                &key("prefix"),
                "a service name prefix like atmo/drivers",
                &self.prefix,
            ));
        }
        if !self
            .iceoryx_prefix
            .chars()
            .all(|ch| ch.is_ascii_alphanumeric() || ch == '_')
            || self.iceoryx_prefix.len() > 32
        {
            return Err(c.fail(
                &key("iceoryx_prefix"),
                "at most 32 letters, digits or _",
                &self.iceoryx_prefix,
            ));
        }
        for (i, name) in self.required.iter().enumerate() {
            let at = format!("{}[{i}]", key("required"));
            if !DriverId::ALL.iter().any(|d| d.name() == name) {
                return Err(c.fail(&at, "thrusters, tilt, wheels or ground_contact", name));
            }
            // A name twice is a slip (another driver meant?), not a stricter rule.
            if self.required[..i].contains(name) {
                return Err(c.fail(&at, "each driver named once", format!("{name} again")));
            }
        }
        Ok(())
    }
}

impl ConfigFile for DriverPortsConfig {
    type Error = IoError;

    /// Checks the values; errors name `file` and the key.
    fn validate(&self, file: &Path) -> Result<()> {
        Ok(atmo_core::params::check_file(self, file)?)
    }
}

impl DriverPortsConfig {
    /// The iceoryx2 configuration of these ports.
    pub fn iceoryx_config(&self) -> Result<Config> {
        let mut config = Config::default();
        if !self.iceoryx_prefix.is_empty() {
            config.global.prefix =
                FileName::new(self.iceoryx_prefix.as_bytes()).map_err(|e| IoError::Iceoryx {
                    service: "(config)".into(),
                    reason: format!("prefix `{}`: {e:?}", self.iceoryx_prefix),
                })?;
        }
        Ok(config)
    }

    fn required_mask(&self) -> [bool; 4] {
        DriverId::ALL.map(|d| self.required.iter().any(|n| n == d.name()))
    }
}

fn iox_err(service: &str, e: impl Debug) -> IoError {
    IoError::Iceoryx {
        service: service.to_string(),
        reason: format!("{e:?}"),
    }
}

/// Removes the resources of dead nodes (a crashed earlier run) under
/// `config`'s iceoryx2 prefix; returns how many dead nodes were cleaned.
pub fn cleanup_stale(config: &DriverPortsConfig) -> Result<usize> {
    set_log_level_from_env_or(LogLevel::Error);
    let iox = config.iceoryx_config()?;
    let mut dead = Vec::new();
    Node::<ipc::Service>::list(&iox, |state| {
        if let NodeState::Dead(view) = state {
            dead.push(view);
        }
        CallbackProgression::Continue
    })
    .map_err(|e| iox_err("(node list)", e))?;
    let mut cleaned = 0;
    for view in dead {
        if view.try_remove_stale_resources().is_ok() {
            cleaned += 1;
        }
    }
    Ok(cleaned)
}

fn node(config: &DriverPortsConfig, name: &str) -> Result<Node<ipc::Service>> {
    set_log_level_from_env_or(LogLevel::Error);
    let iox = config.iceoryx_config()?;
    let node_name = NodeName::new(name).map_err(|e| iox_err(name, e))?;
    NodeBuilder::new()
        .name(&node_name)
        .config(&iox)
        .create::<ipc::Service>()
        .map_err(|e| iox_err(name, e))
}

type Pub<T> = Publisher<ipc::Service, T, ()>;
type Sub<T> = Subscriber<ipc::Service, T, ()>;

/// Every service with the same settings on both sides (a mismatch would
/// make the second side fail to open it).
fn service<T: Debug + ZeroCopySend + Copy + 'static>(
    node: &Node<ipc::Service>,
    config: &DriverPortsConfig,
    leaf: &str,
) -> Result<(
    String,
    iceoryx2::service::port_factory::publish_subscribe::PortFactory<ipc::Service, T, ()>,
)> {
    let name = format!("{}/{leaf}", config.prefix);
    let service_name = ServiceName::new(&name).map_err(|e| iox_err(&name, e))?;
    let factory = node
        .service_builder(&service_name)
        .publish_subscribe::<T>()
        .max_publishers(8)
        .max_subscribers(8)
        .max_nodes(16)
        .subscriber_max_buffer_size(8)
        .history_size(0)
        .enable_safe_overflow(true)
        .open_or_create()
        .map_err(|e| iox_err(&name, e))?;
    Ok((name, factory))
}

/// The event service that wakes drivers when commands were sent (same
/// settings on both sides).
fn command_event(
    node: &Node<ipc::Service>,
    config: &DriverPortsConfig,
) -> Result<(
    String,
    iceoryx2::service::port_factory::event::PortFactory<ipc::Service>,
)> {
    let name = format!("{}/commands_sent", config.prefix);
    let service_name = ServiceName::new(&name).map_err(|e| iox_err(&name, e))?;
    let factory = node
        .service_builder(&service_name)
        .event()
        .max_notifiers(8)
        .max_listeners(8)
        .max_nodes(16)
        .open_or_create()
        .map_err(|e| iox_err(&name, e))?;
    Ok((name, factory))
}

fn publisher<T: Debug + ZeroCopySend + Copy + 'static>(
    node: &Node<ipc::Service>,
    config: &DriverPortsConfig,
    leaf: &str,
) -> Result<Sender<T>> {
    let (name, factory) = service::<T>(node, config, leaf)?;
    let port = factory
        .publisher_builder()
        .create()
        .map_err(|e| iox_err(&name, e))?;
    Ok(Sender {
        port,
        sequence: 0,
        errors: 0,
    })
}

fn subscriber<T: Debug + ZeroCopySend + Copy + 'static>(
    node: &Node<ipc::Service>,
    config: &DriverPortsConfig,
    leaf: &str,
) -> Result<Receiver<T>> {
    let (name, factory) = service::<T>(node, config, leaf)?;
    let port = factory
        .subscriber_builder()
        .create()
        .map_err(|e| iox_err(&name, e))?;
    Ok(Receiver {
        port,
        last_sequence: None,
        counters: StreamCounters::default(),
    })
}

struct Sender<T: Debug + ZeroCopySend + 'static> {
    port: Pub<T>,
    sequence: u64,
    errors: u64,
}

impl<T: Debug + ZeroCopySend + Copy + 'static> Sender<T> {
    /// Stamps and sends one sample; false (counted) if iceoryx2 refused.
    fn send(&mut self, make: impl FnOnce(PortHeader) -> T) -> bool {
        let header = PortHeader {
            sequence: self.sequence,
            stamp_ns: monotonic_ns(),
        };
        self.sequence += 1;
        let value = make(header);
        if let Ok(sample) = self.port.loan_uninit()
            && sample.write_payload(value).send().is_ok()
        {
            return true;
        }
        self.errors += 1;
        false
    }
}

/// Per-stream receive counters.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct StreamCounters {
    pub received: u64,
    /// Samples missing between two received (sequence gaps).
    pub lost: u64,
    /// A sequence number that did not increase (the publisher restarted).
    pub restarts: u64,
    pub receive_errors: u64,
}

struct Receiver<T: Debug + ZeroCopySend + 'static> {
    port: Sub<T>,
    last_sequence: Option<u64>,
    counters: StreamCounters,
}

impl<T: Debug + ZeroCopySend + Copy + 'static> Receiver<T> {
    /// Takes every waiting sample; returns the newest. `header` reads a
    /// sample's header (to count gaps and restarts).
    fn drain(&mut self, header: impl Fn(&T) -> PortHeader) -> Option<T> {
        let mut newest = None;
        for _ in 0..64 {
            match self.port.receive() {
                Ok(Some(sample)) => {
                    let value = *sample;
                    let seq = header(&value).sequence;
                    self.counters.received += 1;
                    match self.last_sequence {
                        Some(last) if seq > last + 1 => self.counters.lost += seq - last - 1,
                        Some(last) if seq <= last => self.counters.restarts += 1,
                        _ => {}
                    }
                    self.last_sequence = Some(seq);
                    newest = Some(value);
                }
                Ok(None) => break,
                Err(_) => {
                    self.counters.receive_errors += 1;
                    break;
                }
            }
        }
        newest
    }
}

/// Liveness of each driver at one instant.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DriverHealth {
    /// Indexed by [`DriverId`] as usize.
    pub alive: [bool; 4],
    /// Time since last heard from, ns (`None`: never).
    pub age_ns: [Option<u64>; 4],
    /// Which drivers are required (config).
    pub required: [bool; 4],
}

impl DriverHealth {
    pub fn is_alive(&self, driver: DriverId) -> bool {
        self.alive[driver as usize]
    }

    /// Every required driver is alive (false: the failsafe should act).
    pub fn all_required_alive(&self) -> bool {
        self.alive
            .iter()
            .zip(self.required)
            .all(|(alive, required)| *alive || !required)
    }
}

/// What [`FlightPorts::poll`] read this tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DriverInputs {
    /// Newest encoder sample since the last poll.
    pub tilt_encoder: Option<TiltEncoder>,
    /// Newest contact sample since the last poll.
    pub ground_contact: Option<GroundContact>,
    /// Newest heartbeat per driver since the last poll.
    pub heartbeats: [Option<DriverHeartbeat>; 4],
    pub health: DriverHealth,
}

/// Counters of the daemon side.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct FlightPortsCounters {
    pub send_errors: u64,
    pub tilt_encoder: StreamCounters,
    pub ground_contact: StreamCounters,
    pub heartbeat: StreamCounters,
    /// Heartbeats naming an unknown driver.
    pub bad_heartbeats: u64,
    /// Transitions alive -> dead, per driver.
    pub deaths: [u64; 4],
    /// Dead nodes whose resources were cleaned (start-up and after deaths).
    pub cleaned_nodes: u64,
}

/// The daemon's side of the driver ports.
pub struct FlightPorts {
    node: Node<ipc::Service>,
    config: DriverPortsConfig,
    thrusters: Sender<ThrusterCommand>,
    tilt_velocity: Sender<TiltVelocityCommand>,
    wheel_rates: Sender<WheelRateCommand>,
    tilt_encoder: Receiver<TiltEncoder>,
    ground_contact: Receiver<GroundContact>,
    heartbeat: Receiver<DriverHeartbeat>,
    notifier: Notifier<ipc::Service>,
    notify_errors: u64,
    last_heard_ns: [Option<u64>; 4],
    was_alive: [bool; 4],
    bad_heartbeats: u64,
    deaths: [u64; 4],
    cleaned_nodes: u64,
}

impl FlightPorts {
    /// Cleans what a crashed run left, then opens every service. Call on
    /// the thread that will use the ports.
    pub fn open(config: &DriverPortsConfig) -> Result<Self> {
        config.validate(std::path::Path::new("(driver ports config)"))?;
        let cleaned = cleanup_stale(config)?;
        let node = node(config, "atmo_daemon")?;
        let (event_name, event) = command_event(&node, config)?;
        let notifier = event
            .notifier_builder()
            .create()
            .map_err(|e| iox_err(&event_name, e))?;
        Ok(Self {
            notifier,
            notify_errors: 0,
            thrusters: publisher(&node, config, "thrusters")?,
            tilt_velocity: publisher(&node, config, "tilt_velocity")?,
            wheel_rates: publisher(&node, config, "wheel_rates")?,
            tilt_encoder: subscriber(&node, config, "tilt_encoder")?,
            ground_contact: subscriber(&node, config, "ground_contact")?,
            heartbeat: subscriber(&node, config, "heartbeat")?,
            node,
            config: config.clone(),
            last_heard_ns: [None; 4],
            was_alive: [false; 4],
            bad_heartbeats: 0,
            deaths: [0; 4],
            cleaned_nodes: cleaned as u64,
        })
    }

    /// Sends thruster commands (never blocks; false if refused, counted).
    /// Call [`Self::notify_drivers`] after the tick's sends.
    pub fn send_thrust(&mut self, thrust: [f64; 4]) -> bool {
        self.thrusters
            .send(|header| ThrusterCommand { header, thrust })
    }

    /// Sends the tilt velocity, with `rehome` (the pilot's encoder reset,
    /// only while disarmed).
    pub fn send_tilt_velocity(&mut self, velocity: f64, rehome: bool) -> bool {
        self.tilt_velocity.send(|header| TiltVelocityCommand {
            header,
            velocity,
            rehome,
        })
    }

    pub fn send_wheel_rates(&mut self, rates: [f64; 2]) -> bool {
        self.wheel_rates
            .send(|header| WheelRateCommand { header, rates })
    }

    /// Wakes drivers blocked in [`DriverEndpoint::wait_for_commands`] (one
    /// iceoryx2 event per tick, after the sends; never blocks). Drivers that
    /// poll do not need it.
    pub fn notify_drivers(&mut self) -> bool {
        if self.notifier.notify().is_ok() {
            true
        } else {
            self.notify_errors += 1;
            false
        }
    }

    /// Reads every waiting sample and updates liveness at `now_ns`
    /// (CLOCK_MONOTONIC, [`monotonic_ns`]).
    pub fn poll(&mut self, now_ns: u64) -> DriverInputs {
        let tilt_encoder = self.tilt_encoder.drain(|s| s.header);
        let ground_contact = self.ground_contact.drain(|s| s.header);
        if tilt_encoder.is_some() {
            self.last_heard_ns[DriverId::Tilt as usize] = Some(now_ns);
        }
        if ground_contact.is_some() {
            self.last_heard_ns[DriverId::GroundContact as usize] = Some(now_ns);
        }
        let mut heartbeats = [None; 4];
        for _ in 0..64 {
            let Some(beat) = self.heartbeat.drain_one() else {
                break;
            };
            match DriverId::from_u32(beat.driver) {
                Some(id) => {
                    self.last_heard_ns[id as usize] = Some(now_ns);
                    heartbeats[id as usize] = Some(beat);
                }
                None => self.bad_heartbeats += 1,
            }
        }
        let timeout = self.config.liveness_timeout_ms * 1_000_000;
        let mut alive = [false; 4];
        let mut age_ns = [None; 4];
        let mut someone_died = false;
        for i in 0..4 {
            age_ns[i] = self.last_heard_ns[i].map(|t| now_ns.saturating_sub(t));
            alive[i] = age_ns[i].is_some_and(|age| age <= timeout);
            if self.was_alive[i] && !alive[i] {
                self.deaths[i] += 1;
                someone_died = true;
            }
            self.was_alive[i] = alive[i];
        }
        if someone_died {
            // Free the dead process's ports so that a restarted driver can
            // connect (iceoryx2 keeps them until cleaned).
            self.cleaned_nodes += self.cleanup_dead_nodes();
        }
        DriverInputs {
            tilt_encoder,
            ground_contact,
            heartbeats,
            health: DriverHealth {
                alive,
                age_ns,
                required: self.config.required_mask(),
            },
        }
    }

    fn cleanup_dead_nodes(&self) -> u64 {
        let state = self.node.try_cleanup_dead_nodes();
        state.cleanups
    }

    pub fn counters(&self) -> FlightPortsCounters {
        FlightPortsCounters {
            send_errors: self.thrusters.errors
                + self.tilt_velocity.errors
                + self.wheel_rates.errors
                + self.notify_errors,
            tilt_encoder: self.tilt_encoder.counters,
            ground_contact: self.ground_contact.counters,
            heartbeat: self.heartbeat.counters,
            bad_heartbeats: self.bad_heartbeats,
            deaths: self.deaths,
            cleaned_nodes: self.cleaned_nodes,
        }
    }
}

impl Receiver<DriverHeartbeat> {
    /// One heartbeat (every driver's matters, not only the newest).
    fn drain_one(&mut self) -> Option<DriverHeartbeat> {
        match self.port.receive() {
            Ok(Some(sample)) => {
                let beat = *sample;
                self.counters.received += 1;
                Some(beat)
            }
            Ok(None) => None,
            Err(_) => {
                self.counters.receive_errors += 1;
                None
            }
        }
    }
}

/// What a driver process (or the SITL plant server) received.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct DriverCommands {
    pub thrust: Option<ThrusterCommand>,
    pub tilt_velocity: Option<TiltVelocityCommand>,
    pub wheel_rates: Option<WheelRateCommand>,
}

/// The drivers' side of the ports: command subscribers, sensor and
/// heartbeat publishers. One process may play several drivers.
pub struct DriverEndpoint {
    _node: Node<ipc::Service>,
    thrusters: Receiver<ThrusterCommand>,
    tilt_velocity: Receiver<TiltVelocityCommand>,
    wheel_rates: Receiver<WheelRateCommand>,
    tilt_encoder: Sender<TiltEncoder>,
    ground_contact: Sender<GroundContact>,
    heartbeat: Sender<DriverHeartbeat>,
    listener: Listener<ipc::Service>,
    last_command: [(u64, u64, u64); 3],
}

impl DriverEndpoint {
    /// Opens every service as a driver; `name` is the iceoryx2 node name.
    pub fn open(config: &DriverPortsConfig, name: &str) -> Result<Self> {
        config.validate(std::path::Path::new("(driver ports config)"))?;
        let node = node(config, name)?;
        let (event_name, event) = command_event(&node, config)?;
        let listener = event
            .listener_builder()
            .create()
            .map_err(|e| iox_err(&event_name, e))?;
        Ok(Self {
            listener,
            thrusters: subscriber(&node, config, "thrusters")?,
            tilt_velocity: subscriber(&node, config, "tilt_velocity")?,
            wheel_rates: subscriber(&node, config, "wheel_rates")?,
            tilt_encoder: publisher(&node, config, "tilt_encoder")?,
            ground_contact: publisher(&node, config, "ground_contact")?,
            heartbeat: publisher(&node, config, "heartbeat")?,
            _node: node,
            last_command: [(0, 0, 0); 3],
        })
    }

    /// Sleeps until the daemon signals new commands
    /// ([`FlightPorts::notify_drivers`]) or `timeout` passes, then returns
    /// what [`Self::receive`] returns. A timeout under 1 us does not sleep:
    /// iceoryx2 0.10 waits on a socket whose timeout is a `timeval` in whole
    /// microseconds, and 0 there means "no timeout" (blocked until the next
    /// signal, for good without a daemon); it takes the pending signals and
    /// returns at once.
    pub fn wait_for_commands(&mut self, timeout: std::time::Duration) -> Result<DriverCommands> {
        if timeout < std::time::Duration::from_micros(1) {
            self.listener
                .try_wait(|_| {})
                .map_err(|e| iox_err("commands_sent", e))?;
        } else {
            self.listener
                .timed_wait(|_| {}, timeout)
                .map_err(|e| iox_err("commands_sent", e))?;
        }
        Ok(self.receive())
    }

    /// The newest command of each kind since the last call.
    pub fn receive(&mut self) -> DriverCommands {
        let commands = DriverCommands {
            thrust: self.thrusters.drain(|s| s.header),
            tilt_velocity: self.tilt_velocity.drain(|s| s.header),
            wheel_rates: self.wheel_rates.drain(|s| s.header),
        };
        // After the samples were taken: never before a sample's own stamp.
        let now = monotonic_ns();
        let headers = [
            commands.thrust.map(|c| c.header),
            commands.tilt_velocity.map(|c| c.header),
            commands.wheel_rates.map(|c| c.header),
        ];
        for (slot, header) in self.last_command.iter_mut().zip(headers) {
            if let Some(h) = header {
                *slot = (h.sequence, h.stamp_ns, now);
            }
        }
        commands
    }

    pub fn publish_tilt_encoder(&mut self, counts: i64) -> bool {
        self.tilt_encoder
            .send(|header| TiltEncoder { header, counts })
    }

    pub fn publish_ground_contact(&mut self, contact: bool) -> bool {
        self.ground_contact.send(|header| GroundContact {
            header,
            contact: u8::from(contact),
            reserved: [0; 7],
        })
    }

    /// Heartbeat of `driver`, echoing the last command of its kind (the
    /// contact sensor has none).
    pub fn publish_heartbeat(&mut self, driver: DriverId) -> bool {
        let (sequence, stamp, received) = match driver {
            DriverId::Thrusters => self.last_command[0],
            DriverId::Tilt => self.last_command[1],
            DriverId::Wheels => self.last_command[2],
            DriverId::GroundContact => (0, 0, 0),
        };
        self.heartbeat.send(|header| DriverHeartbeat {
            header,
            driver: driver as u32,
            reserved: 0,
            last_command_sequence: sequence,
            last_command_stamp_ns: stamp,
            last_command_received_ns: received,
        })
    }
}
