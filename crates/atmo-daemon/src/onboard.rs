//! The onboard daemon: the flight stack on the control thread, wired to
//! the robot.
//!
//! ```text
//!  ROS 2 thread ──estimate, pilot, drive──▶ ┌──────────────────┐ ──thrust, tilt rate, wheels──▶ iceoryx2
//!  (atmo-io Ros2Node, bounded channels)     │  control thread  │ ◀──encoder, contact, heartbeats── drivers
//!                     ◀──MpcStatus────────  │  150 Hz, [`OnboardIo`] │ ──MpcStatus──▶ MCAP logger thread
//!                                           └──────────────────┘
//! ```
//!
//! Everything the control thread touches is non-blocking and
//! allocation-free after start-up: ROS 2 inputs are drained from bounded
//! channels, outputs go through `try_*` calls that drop and count when a
//! queue is full, and the driver ports are zero-copy iceoryx2 services
//! opened on the control thread itself (they are not `Send`).
//!
//! Clocks: the stack runs on its own monotonic clock (from 0 at start;
//! `MpcStatus.clock_ns`, `estimate_age`), and stamps its status with ROS
//! time read when the tick gathers its inputs (`MpcStatus.header.stamp`):
//! the wall clock, or with `[ros2] use_sim_time` the newest `/clock`
//! ([`atmo_io::ros2::Ros2Inputs::ros_time_ns`]).
//!
//! Input semantics (the shared [`atmo_flight::inputs::InputLatch`]): the estimate's
//! age is measured from when the ROS 2 thread accepted it (message stamps
//! come from another clock, ROS time; the node checks they increase); the
//! pilot stream goes stale after `pilot_timeout_ms`, a drive command counts
//! for `drive_timeout_ms`; a required driver not heard from within the
//! driver ports' liveness timeout sets `driver_lost`: failsafe in the air,
//! no take-off. The ground height comes from the ground topic
//! (`[ros2.topics] ground`, [`atmo_io::ros2::GroundHeight`]) while it is
//! younger than `ground_timeout_ms`, else from the config's `ground_z`; the
//! ground plane's normal from the ground-normal topic (`[ros2.topics]
//! ground_normal`, [`atmo_io::ros2::GroundNormal`]) by the same timeout,
//! else the ground is level.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU8, AtomicU64, Ordering};
use std::time::{Duration, Instant};

use atmo_core::config_file::ConfigFile;
use atmo_io::drivers::{DriverHealth, DriverPortsConfig, FlightPorts, monotonic_ns};
use atmo_io::mcap_log::{Compression, LoggerHandle, LoggerOptions};
use atmo_io::msg::{ActuatorMotors, IoHealth, OffboardControlMode};
use atmo_io::ros2::{Ros2Config, Ros2Inputs, Ros2Publisher};

use atmo_flight::arming::{ArmingMonitor, ArmingObservation, ArmingSettings};
use atmo_flight::control_loop::{TickIo, TickTiming};
use atmo_flight::error::{FlightError, Result};
use atmo_flight::esc::EscConfig;
use atmo_flight::flight_log::TickChannels;
use atmo_flight::flight_stack::{Estimate, StepInputs, StepOutputs};
use atmo_flight::inputs::{DriveCommand, InputLatch, InputSettings};
use atmo_flight::rc::{RcConfig, RcPilot};

atmo_core::params! {
    /// `config/daemon.toml`: what the onboard binary loads. Paths are relative
    /// to the folder of the file that names them.
    #[derive(Debug, Clone, PartialEq)]
    pub struct DaemonConfig {
        /// Robot parameters (config/atmo.toml).
        pub robot: PathBuf;
        /// Flight settings (config/flight.toml).
        pub flight: PathBuf;
        /// MPC settings (config/mpc.toml); the preset is the flight settings'.
        pub mpc: PathBuf;
        /// NED z of the (flat) ground under the robot when the ground topic
        /// is silent or stale: within the 10 km a recording's positions may
        /// span (a number like 1e300 is a typo, not a place).
        pub ground_z: f64 = 0.0, range -1e4..=1e4, unit "m";
        /// Age after which a ground height from the topic is replaced by
        /// `ground_z`.
        pub ground_timeout_ms: u64 = atmo_flight::inputs::DEFAULT_GROUND_TIMEOUT_MS,
            range 10..=60_000, unit "ms";
        /// Pilot stream silence after which its commands go to zero.
        pub pilot_timeout_ms: u64 = atmo_flight::inputs::DEFAULT_INPUT_TIMEOUT_MS,
            range 10..=10_000, unit "ms";
        /// Age after which a drive command is ignored.
        pub drive_timeout_ms: u64 = atmo_flight::inputs::DEFAULT_INPUT_TIMEOUT_MS,
            range 10..=10_000, unit "ms";
        /// Also send the thruster commands to PX4 (ActuatorMotors +
        /// OffboardControlMode on ROS 2), as the original ATMO did.
        pub px4_offboard: bool = false;
        pub log: LogConfig = LogConfig::default();
        /// The ROS 2 node: name, namespace, queue and topics (atmo-io).
        pub ros2: Ros2Config = Ros2Config::default();
        /// The iceoryx2 driver ports (atmo-io).
        pub drivers: DriverPortsConfig = DriverPortsConfig::default();
        /// The radio's mapping (used when `ros2.topics.rc` is enabled).
        pub rc: RcConfig = RcConfig::default();
        /// The ESCs' speeds' scale (used when `ros2.topics.esc_status` is
        /// enabled).
        pub esc: EscConfig = EscConfig::default();
        /// The arming checks' rates, windows and tolerances.
        pub arming: ArmingSettings = ArmingSettings::default();
    }
    check |daemon, c, _prefix| {
        let topics = &daemon.ros2.topics;
        if topics.esc_status.enabled && daemon.esc.full_speed_rpm <= 0.0 {
            return Err(c.fail(
                "esc.full_speed_rpm",
                "the rotors' RPM at full command while ros2.topics.esc_status is enabled",
                daemon.esc.full_speed_rpm,
            ));
        }
        if topics.rc.enabled && topics.pilot.enabled {
            return Err(c.fail(
                "ros2.topics.pilot.enabled",
                "false while ros2.topics.rc is enabled (one pilot source)",
                true,
            ));
        }
        Ok(())
    }
}

atmo_core::params! {
    /// `[log]`: the MCAP flight log.
    #[derive(Debug, Clone, PartialEq)]
    pub struct LogConfig: Default {
        /// Log file (relative to the working directory; not empty); `--log`
        /// overrides it.
        pub path: PathBuf = PathBuf::from("flight.mcap");
        /// Records queued before the logger drops (and counts).
        pub queue_capacity: usize = 4096, range 1..=1 << 20, unit "records";
        /// Longest time between two flushes (a killed daemon loses at most
        /// this much).
        pub flush_period_ms: u64 = 500, range 10..=1000, unit "ms";
        /// `zstd`, `lz4` or `none`.
        pub compression: String = "zstd".into();
    }
    check |log, c, prefix| {
        let key = |name| atmo_core::params::key(prefix, name);
        c.one_of(&key("compression"), &log.compression, &["zstd", "lz4", "none"])?;
        if log.path.as_os_str().is_empty() {
            return Err(c.fail(&key("path"), "a file path", "\"\""));
        }
        Ok(())
    }
}

impl LogConfig {
    /// The logger's options (validated values).
    pub fn options(&self) -> LoggerOptions {
        LoggerOptions {
            queue_capacity: self.queue_capacity,
            flush_period: Duration::from_millis(self.flush_period_ms),
            compression: match self.compression.as_str() {
                "lz4" => Compression::Lz4,
                "none" => Compression::None,
                _ => Compression::Zstd,
            },
            ..LoggerOptions::default()
        }
    }
}

impl ConfigFile for DaemonConfig {
    type Error = FlightError;

    /// The robot, flight and MPC paths are relative to the folder of `file`.
    fn locate(&mut self, file: &Path) {
        let dir = file.parent().unwrap_or(Path::new("."));
        for path in [&mut self.robot, &mut self.flight, &mut self.mpc] {
            if path.is_relative() {
                *path = dir.join(&*path);
            }
        }
    }

    /// Checks the values; errors name `file` and the key.
    fn validate(&self, file: &Path) -> Result<()> {
        atmo_core::params::check_file(self, file)?;
        Ok(())
    }
}

impl DaemonConfig {
    /// Why this configuration cannot fly, if it cannot (the arming checks'
    /// configuration check: a valid file the daemon runs with, which
    /// nevertheless could not arm safely).
    pub fn flight_problem(&self) -> Option<&'static str> {
        let t = &self.ros2.topics;
        let required = |name: &str| self.drivers.required.iter().any(|r| r == name);
        if !t.pilot.enabled && !t.rc.enabled {
            Some("no pilot source: ros2.topics.pilot and ros2.topics.rc are both disabled")
        } else if !t.estimate.enabled {
            Some("no estimate: ros2.topics.estimate is disabled")
        } else if !required("tilt") {
            Some("drivers.required lacks \"tilt\": the encoder check needs its liveness")
        } else if !self.px4_offboard && !required("thrusters") {
            Some("no thruster path: px4_offboard is off and drivers.required lacks \"thrusters\"")
        } else {
            None
        }
    }
}

/// What the control thread shares with the rest of the daemon (atomics:
/// read by the main thread for diagnostics and the exit report).
#[derive(Debug, Default)]
pub struct OnboardShared {
    /// Current mode (`Mode::code`).
    pub mode: AtomicU8,
    /// Drivers alive (bit i: [`atmo_io::drivers::DriverId`] i).
    pub drivers_alive: AtomicU8,
    /// Alive -> dead transitions, all drivers.
    pub driver_deaths: AtomicU64,
    /// Ticks run with the pilot stream silent.
    pub pilot_stale_ticks: AtomicU64,
    /// Ticks run with the radio lost (radio as the pilot source only).
    pub pilot_lost_ticks: AtomicU64,
    /// Radio frames the mapping refused (a mapped channel missing or no
    /// servo pulse).
    pub rc_rejected: AtomicU64,
    /// ESC reports that gave no speeds (a rotor's ESC missing or offline).
    pub esc_rejected: AtomicU64,
    /// Ticks with no estimate fresh enough to fly on (age > timeout).
    pub estimates_stale_ticks: AtomicU64,
    /// Ticks on the configured ground height because the ground topic had
    /// spoken but was older than its timeout.
    pub ground_stale_ticks: AtomicU64,
    /// Driver-port sends refused.
    pub port_send_errors: AtomicU64,
    /// Status records the logger dropped (queue full).
    pub log_dropped: AtomicU64,
    /// Arming checks failing now (bits of [`atmo_flight::arming::ArmingCheck`]).
    pub arming_failures: AtomicU8,
    /// Set once the first tick has run.
    pub started: AtomicBool,
}

impl OnboardShared {
    /// Every counter, named: what the diagnostics publish and the exit
    /// report prints (whatever the tick dropped or refused is told here).
    pub fn counts(&self) -> [(&'static str, u64); 9] {
        let g = |c: &AtomicU64| c.load(Ordering::Relaxed);
        [
            ("driver_deaths", g(&self.driver_deaths)),
            ("pilot_stale_ticks", g(&self.pilot_stale_ticks)),
            ("pilot_lost_ticks", g(&self.pilot_lost_ticks)),
            ("rc_rejected", g(&self.rc_rejected)),
            ("esc_rejected", g(&self.esc_rejected)),
            ("estimates_stale_ticks", g(&self.estimates_stale_ticks)),
            ("ground_stale_ticks", g(&self.ground_stale_ticks)),
            ("port_send_errors", g(&self.port_send_errors)),
            ("log_dropped", g(&self.log_dropped)),
        ]
    }
}

/// `result`'s value, or none with the refusal counted in `rejected`.
fn counted<T, E>(result: std::result::Result<T, E>, rejected: &AtomicU64) -> Option<T> {
    result
        .map_err(|_| rejected.fetch_add(1, Ordering::Relaxed))
        .ok()
}

/// Settings the tick uses (from [`DaemonConfig`]).
#[derive(Debug, Clone, Copy)]
pub struct OnboardSettings {
    pub ground_z: f64,
    pub ground_timeout: Duration,
    pub pilot_timeout: Duration,
    pub drive_timeout: Duration,
    pub px4_offboard: bool,
    /// The flight stack's estimate timeout, s (for the stale counter).
    pub estimate_timeout: f64,
    /// The radio's mapping, when it is the pilot source.
    pub rc: Option<RcConfig>,
    /// The ESCs' speeds' scale, when their telemetry is an input.
    pub esc: Option<EscConfig>,
    pub arming: ArmingSettings,
    /// The configuration check's verdict ([`DaemonConfig::flight_problem`]
    /// is `None`).
    pub configuration_ok: bool,
}

impl OnboardSettings {
    /// The input assembly's part.
    pub fn inputs(&self) -> InputSettings {
        InputSettings {
            ground_z: self.ground_z,
            ground_timeout: self.ground_timeout,
            pilot_timeout: self.pilot_timeout,
            drive_timeout: self.drive_timeout,
            estimate_timeout: self.estimate_timeout,
            rc_timeout: self.rc.map(|rc| Duration::from_millis(rc.timeout_ms)),
        }
    }

    pub fn new(config: &DaemonConfig, estimate_timeout: f64) -> Self {
        Self {
            ground_z: config.ground_z,
            ground_timeout: Duration::from_millis(config.ground_timeout_ms),
            pilot_timeout: Duration::from_millis(config.pilot_timeout_ms),
            drive_timeout: Duration::from_millis(config.drive_timeout_ms),
            px4_offboard: config.px4_offboard,
            estimate_timeout,
            rc: config.ros2.topics.rc.enabled.then_some(config.rc),
            esc: config.ros2.topics.esc_status.enabled.then_some(config.esc),
            arming: config.arming,
            configuration_ok: config.flight_problem().is_none(),
        }
    }
}

/// The control thread's I/O on the robot: ROS 2 in and out, driver ports,
/// MCAP log. Built on the control thread ([`OnboardIo::open`]).
pub struct OnboardIo {
    ports: FlightPorts,
    ros_in: Ros2Inputs,
    ros_out: Ros2Publisher,
    log: LoggerHandle,
    channels: TickChannels,
    px4_offboard: bool,
    shared: Arc<OnboardShared>,
    started: Instant,
    latch: InputLatch,
    /// The radio's mapping, when it is the pilot source.
    rc: Option<RcPilot>,
    /// The ESCs' speeds' scale, when their telemetry is an input.
    esc: Option<EscConfig>,
    arming: ArmingMonitor,
    /// The last tick's measured tilt (if an encoder reading had arrived)
    /// and commanded tilt velocity, for the arming checks.
    last_tilt: (Option<f64>, f64),
    health: Option<DriverHealth>,
    tick: u64,
    /// ROS time (the wall clock, or `/clock` with `use_sim_time`) when this
    /// tick's inputs were gathered: the status's header stamp (ROS tools
    /// show real dates, and a peer can compare it with its own clock).
    tick_ros_ns: u64,
}

/// The tick's clock stamp of something accepted at `received`: its age
/// now, counted back from the tick's deadline.
fn stamp_on_tick_clock(deadline_ns: u64, received: Instant) -> u64 {
    let age = u64::try_from(received.elapsed().as_nanos()).unwrap_or(u64::MAX);
    deadline_ns.saturating_sub(age)
}

impl OnboardIo {
    /// Opens the driver ports (cleaning what a crashed run left) on the
    /// calling thread, which must be the control thread.
    pub fn open(
        drivers: &DriverPortsConfig,
        ros_in: Ros2Inputs,
        ros_out: Ros2Publisher,
        log: LoggerHandle,
        channels: TickChannels,
        settings: OnboardSettings,
        shared: Arc<OnboardShared>,
    ) -> atmo_io::Result<Self> {
        Ok(Self {
            ports: FlightPorts::open(drivers)?,
            ros_in,
            ros_out,
            log,
            channels,
            px4_offboard: settings.px4_offboard,
            shared,
            started: Instant::now(),
            latch: InputLatch::new(settings.inputs()),
            rc: settings.rc.map(RcPilot::new),
            esc: settings.esc,
            arming: ArmingMonitor::new(settings.arming, settings.configuration_ok),
            last_tilt: (None, 0.0),
            health: None,
            tick: 0,
            tick_ros_ns: 0,
        })
    }

    fn io_health(&self) -> IoHealth {
        let ros = self.ros_out.counters();
        let ports = self.ports.counters();
        IoHealth {
            malformed: ros.malformed,
            invalid: ros.invalid,
            stamp_backwards: ros.stamp_backwards,
            inputs_dropped: ros.inputs_dropped,
            publish_dropped: ros.publish_dropped,
            log_dropped: self.log.dropped(),
            drivers_alive: self.health.map_or([false; 4], |h| h.alive),
            driver_deaths: ports.deaths,
        }
    }
}

impl TickIo for OnboardIo {
    fn gather(&mut self, deadline_ns: u64) -> Option<StepInputs> {
        self.tick_ros_ns = self.ros_in.ros_time_ns();
        while let Some(e) = self.ros_in.latest_estimate() {
            // Age from acceptance (see the module doc), on the tick's clock.
            self.latch.estimate(Estimate {
                stamp_ns: stamp_on_tick_clock(deadline_ns, e.received),
                state: e.state,
            });
        }
        if let Some(e) = self.ros_in.latest_autopilot_estimate() {
            self.latch.autopilot_estimate(Estimate {
                stamp_ns: stamp_on_tick_clock(deadline_ns, e.received),
                state: e.state,
            });
        }
        if let Some(g) = self.ros_in.latest_ground() {
            let received = stamp_on_tick_clock(deadline_ns, g.received);
            self.latch.ground_z(g.z, received);
        }
        if let Some(n) = self.ros_in.latest_ground_normal() {
            let received = stamp_on_tick_clock(deadline_ns, n.received);
            self.latch.ground_normal(n.normal, received);
        }
        while let Some(p) = self.ros_in.latest_pilot() {
            let received = stamp_on_tick_clock(deadline_ns, p.received);
            self.latch.pilot(p.input, received);
        }
        if let Some(frame) = self.ros_in.latest_rc()
            && let Some(rc) = &mut self.rc
            && let Some(reading) = counted(rc.map(&frame.input), &self.shared.rc_rejected)
        {
            let received = stamp_on_tick_clock(deadline_ns, frame.received);
            self.latch.radio(reading, received);
        }
        if let Some(frame) = self.ros_in.latest_esc()
            && let Some(esc) = &self.esc
            && let Some(speeds) =
                counted(esc.rotor_speeds(&frame.status), &self.shared.esc_rejected)
        {
            let received = stamp_on_tick_clock(deadline_ns, frame.received);
            self.latch.rotor_speeds(speeds, received);
        }
        while let Some(d) = self.ros_in.latest_drive() {
            self.latch.drive(DriveCommand {
                forward: d.forward,
                yaw_rate: d.yaw_rate,
                received_ns: stamp_on_tick_clock(deadline_ns, d.received),
            });
        }
        let drivers = self.ports.poll(monotonic_ns());
        if let Some(encoder) = drivers.tilt_encoder {
            self.latch.tilt_counts(encoder.counts as f64);
        }
        if let Some(contact) = drivers.ground_contact {
            self.latch.ground_contact(contact.contact != 0);
        }
        self.latch
            .drivers_alive(drivers.health.all_required_alive());
        self.health = Some(drivers.health);
        let mut assembled = self.latch.assemble(deadline_ns);
        let (tilt, tilt_velocity) = self.last_tilt;
        let arming_failures = self.arming.observe(&ArmingObservation {
            now_ns: deadline_ns,
            estimates_total: self.ros_in.counters().estimates_accepted,
            pilot_lost: assembled.inputs.pilot_lost,
            driver_lost: assembled.inputs.driver_lost,
            tilt,
            tilt_velocity,
        });
        assembled.inputs.arming_failures = arming_failures;
        self.shared
            .arming_failures
            .store(arming_failures, Ordering::Relaxed);
        if assembled.pilot_stale {
            self.shared
                .pilot_stale_ticks
                .fetch_add(1, Ordering::Relaxed);
        }
        if assembled.inputs.pilot_lost {
            self.shared.pilot_lost_ticks.fetch_add(1, Ordering::Relaxed);
        }
        if assembled.estimate_stale {
            self.shared
                .estimates_stale_ticks
                .fetch_add(1, Ordering::Relaxed);
        }
        if assembled.ground_stale {
            self.shared
                .ground_stale_ticks
                .fetch_add(1, Ordering::Relaxed);
        }
        Some(assembled.inputs)
    }

    fn emit(&mut self, inputs: &StepInputs, outputs: &StepOutputs, timing: &TickTiming) {
        let mut sent = self.ports.send_thrust(outputs.thrust);
        sent &= self
            .ports
            .send_tilt_velocity(outputs.tilt_velocity, outputs.rehome_tilt);
        sent &= self
            .ports
            .send_wheel_rates([outputs.wheel_rates.left, outputs.wheel_rates.right]);
        sent &= self.ports.notify_drivers();
        if !sent {
            self.shared.port_send_errors.fetch_add(1, Ordering::Relaxed);
        }
        if self.px4_offboard {
            let us = u64::try_from(self.started.elapsed().as_micros()).unwrap_or(u64::MAX);
            self.ros_out
                .try_publish_offboard(&OffboardControlMode::direct_actuator(us));
            self.ros_out
                .try_publish_motors(&ActuatorMotors::from_thrust(us, outputs.thrust));
        }
        let mut status = atmo_flight::telemetry::status_message(self.tick, inputs, outputs, timing);
        status.io = self.io_health();
        status.ros_stamp_ns = self.tick_ros_ns;
        // Both drop and count when full; neither blocks.
        self.ros_out.try_publish_status(&status);
        self.channels
            .log_tick(&self.log, self.tick, inputs, outputs, &status);
        self.latch.mode(outputs.status.mode);
        self.last_tilt = (
            inputs.tilt_counts.map(|_| outputs.status.tilt),
            outputs.tilt_velocity,
        );
        self.tick += 1;
        let alive = status
            .io
            .drivers_alive
            .iter()
            .enumerate()
            .fold(0u8, |bits, (i, a)| bits | (u8::from(*a) << i));
        let s = &self.shared;
        s.mode.store(outputs.status.mode.code(), Ordering::Relaxed);
        s.drivers_alive.store(alive, Ordering::Relaxed);
        s.driver_deaths
            .store(status.io.driver_deaths.iter().sum(), Ordering::Relaxed);
        s.log_dropped
            .store(status.io.log_dropped, Ordering::Relaxed);
        s.started.store(true, Ordering::Relaxed);
    }
}
