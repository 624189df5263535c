//! Software in the loop: the plant as a server on the robot's real
//! transports, flown by the unmodified `atmo-daemon` binary.
//!
//! The server plays every driver on the iceoryx2 driver ports (it takes
//! thruster, tilt-velocity and wheel-rate commands; it publishes the tilt
//! encoder, the ground-contact signal and each driver's heartbeat) and the
//! motion-capture system and pilot on ROS 2 (`nav_msgs/Odometry` in
//! ENU/FLU, `atmo_msgs/PilotInput` from the scenario's script). Topic and
//! service names come from the same daemon config file as the daemon's.
//!
//! With [`ServeOptions::boards`] the tilt and wheel drivers are not played:
//! real `atmo-roboclaw` processes drive simulated Roboclaw boards on
//! pseudo-terminals, and the plant's tilt and wheels follow the boards
//! ([`crate::boards`]); the server still plays the thrusters, the ground
//! contact and the motion capture.
//!
//! Time: the plant steps in real time (wall clock, absolute 1 ms
//! deadlines). It is frozen at its initial state, with sensors and
//! heartbeats running, until the daemon reports an armed mode on its
//! status topic: a scenario that starts in the air does not fall while the
//! daemon starts. The landing is judged on the plant's truth (the same
//! [`LandingTracker`] as the in-process runner), with the daemon's modes
//! and counters read from its status topic.

use std::time::{Duration, Instant};

use atmo_core::model::Input;
use atmo_flight::Mode;
use atmo_io::drivers::{DriverEndpoint, DriverId, DriverPortsConfig};
use atmo_io::msg::{MpcStatus, PilotInput};
use atmo_io::ros2::{Ros2Config, Ros2StartOptions, SitlNode};
use atmo_io::wall_clock_ns;

use crate::boards::{BoardFiles, SimBoards};
use crate::closed_loop::{LandingTracker, Summary};
use crate::error::{Result, SimError};
use crate::scenario::Scenario;
use crate::sim_io::pilot_input;
use atmo_plant::plant::Command;

/// How the server runs.
#[derive(Debug, Clone)]
pub struct ServeOptions {
    pub ros2: Ros2Config,
    pub drivers: DriverPortsConfig,
    /// Longest wait for the daemon to arm before giving up.
    pub start_timeout: Duration,
    /// Rate of the encoder and contact streams, Hz.
    pub sensor_rate_hz: f64,
    /// Rate of the heartbeats and of the pilot stream, Hz.
    pub heartbeat_rate_hz: f64,
    /// Fly the tilt and the wheels through `atmo-roboclaw` processes and
    /// simulated boards on pseudo-terminals instead of playing their drivers.
    pub boards: Option<BoardFiles>,
    /// The rotors' RPM at full command (the daemon's `[esc]`), when
    /// `topics.esc_status` is enabled: the server publishes each rotor's
    /// speed at the sensor rate.
    pub esc_full_speed_rpm: Option<f64>,
}

impl ServeOptions {
    pub fn new(ros2: Ros2Config, drivers: DriverPortsConfig) -> Self {
        Self {
            ros2,
            drivers,
            start_timeout: Duration::from_secs(60),
            sensor_rate_hz: 200.0,
            heartbeat_rate_hz: 50.0,
            boards: None,
            esc_full_speed_rpm: None,
        }
    }
}

/// What the server counted (next to the landing summary).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct ServeCounters {
    pub status_received: u64,
    pub thrust_commands: u64,
    pub estimates_published: u64,
    /// Plant steps run more than 20 ms behind the wall clock (the server
    /// could not keep real time).
    pub late_steps: u64,
    /// Publishes the transports refused (full queue, iceoryx2 error).
    pub publish_failures: u64,
    /// Wall time waited for the daemon to arm, ms.
    pub waited_for_daemon_ms: u64,
    /// Wall clock (ns since the Unix epoch, the clock of the daemon's
    /// `header.stamp`) when the last plant step published: the drivers the
    /// server plays fell silent after it, and the daemon rightly sees them
    /// die from then on.
    pub served_until_ns: u64,
}

/// Progress callback: (plant time, daemon mode if known).
pub type Progress<'a> = &'a mut dyn FnMut(f64, Option<Mode>);

fn pilot_msg(scenario: &Scenario, t: f64) -> PilotInput {
    pilot_input(scenario, t)
}

#[allow(clippy::needless_pass_by_value)] // used as `map_err(ros_err)`
fn ros_err(e: atmo_io::IoError) -> SimError {
    SimError::Setup(e.to_string())
}

/// A periodic "is it due" check on a wall clock.
struct Every {
    period: Duration,
    next: Instant,
}

impl Every {
    fn new(rate_hz: f64) -> Self {
        Self {
            period: Duration::from_secs_f64(1.0 / rate_hz),
            next: Instant::now(),
        }
    }

    fn due(&mut self, now: Instant) -> bool {
        if now < self.next {
            return false;
        }
        self.next += self.period;
        if self.next < now {
            self.next = now + self.period;
        }
        true
    }
}

/// The server's transports.
struct Links {
    drivers: DriverEndpoint,
    ros_out: atmo_io::ros2::SitlPublisher,
    ros_in: atmo_io::ros2::SitlInputs,
    sensors: Every,
    heartbeats: Every,
    counters: ServeCounters,
    last_status: Option<MpcStatus>,
    /// Sequence of the last estimate published.
    last_estimate: Option<u64>,
    /// The tilt and wheel drivers are real processes (no tilt encoder and
    /// no heartbeat of theirs from the server).
    boards: bool,
    /// The rotors' RPM at full command, when the ESCs are played.
    esc_full_speed_rpm: Option<f64>,
}

impl Links {
    fn count(&mut self, ok: bool) {
        if !ok {
            self.counters.publish_failures += 1;
        }
    }

    /// Sensor streams and heartbeats that are due; `stamp_ns` maps plant
    /// time to the estimate's ROS stamp.
    fn publish(
        &mut self,
        plant: &atmo_plant::Plant,
        pilot: &PilotInput,
        stamp_ns: impl Fn(f64) -> u64,
    ) {
        let now = Instant::now();
        if let Some(e) = plant.estimate()
            && self.last_estimate != Some(e.sequence)
        {
            self.last_estimate = Some(e.sequence);
            let autopilot = plant.autopilot_estimate().map_or(e.state, |a| a.state);
            let ok =
                self.ros_out
                    .try_publish_estimates(&e.state, &autopilot, stamp_ns(e.measured_at));
            self.count(ok);
            self.counters.estimates_published += u64::from(ok);
        }
        if self.sensors.due(now) {
            if !self.boards
                && let Ok(counts) = plant.encoder_counts()
            {
                let ok = self.drivers.publish_tilt_encoder(counts.round() as i64);
                self.count(ok);
            }
            let ok = self.drivers.publish_ground_contact(plant.contact_signal());
            self.count(ok);
            if let Some(full) = self.esc_full_speed_rpm {
                let rpm = plant.rotor_speeds().map(|s| (s * full).round() as i32);
                let ok = self.ros_out.try_publish_rotor_rpm(rpm);
                self.count(ok);
            }
        }
        if self.heartbeats.due(now) {
            for driver in DriverId::ALL {
                if self.boards && matches!(driver, DriverId::Tilt | DriverId::Wheels) {
                    continue;
                }
                let ok = self.drivers.publish_heartbeat(driver);
                self.count(ok);
            }
            let ok = self.ros_out.try_publish_pilot(pilot);
            self.count(ok);
        }
    }

    fn take_status(&mut self) -> Option<MpcStatus> {
        let mut newest = None;
        while let Some(s) = self.ros_in.latest_status() {
            self.counters.status_received += 1;
            newest = Some(s);
        }
        if newest.is_some() {
            self.last_status = newest;
        }
        newest
    }
}

/// Frozen until the daemon is armed: the initial state, freshly stamped,
/// sensors and heartbeats running. Only the tilt mechanism moves, as the
/// tilt driver (or the tilt board) commands it: a props-off preflight sweep
/// runs against the server, and the daemon commands none while disarmed.
fn wait_for_arming(
    plant: &mut atmo_plant::Plant,
    links: &mut Links,
    mut boards: Option<&mut SimBoards>,
    scenario: &Scenario,
    options: &ServeOptions,
    progress: Progress<'_>,
) -> Result<()> {
    let mode_of = |s: &MpcStatus| Mode::from_code(s.mode.code());
    let waiting = Instant::now();
    let initial_pilot = pilot_msg(scenario, 0.0);
    let mut republish = Every::new(100.0);
    let (mut tilt_rate, mut last) = (0.0, Instant::now());
    loop {
        let status = links.take_status();
        if status
            .as_ref()
            .and_then(mode_of)
            .is_some_and(|m| m != Mode::Disarmed)
        {
            return Ok(());
        }
        if waiting.elapsed() > options.start_timeout {
            return Err(SimError::Setup(format!(
                "no armed daemon on `{}` within {:.0} s ({} status messages seen)",
                options.ros2.topics.status.name,
                options.start_timeout.as_secs_f64(),
                links.counters.status_received
            )));
        }
        let received = links.drivers.receive();
        if let Some(boards) = boards.as_deref_mut() {
            boards.follow_tilt(plant.tilt());
            tilt_rate = boards.tilt_rate(plant.tilt());
            if let Some(exit) = boards.exited_driver() {
                return Err(SimError::Setup(exit));
            }
        } else if let Some(c) = received.tilt_velocity {
            tilt_rate = c.velocity;
        }
        let dt = last.elapsed().as_secs_f64();
        last = Instant::now();
        plant.place_tilt(plant.tilt() + tilt_rate * dt);
        let now = Instant::now();
        links.publish(plant, &initial_pilot, |_| wall_clock_ns());
        if republish.due(now) {
            // The plant publishes only as it steps: repeat the initial state.
            let ok = links
                .ros_out
                .try_publish_estimate(&plant.state(), wall_clock_ns());
            links.count(ok);
        }
        progress(0.0, links.last_status.as_ref().and_then(mode_of));
        std::thread::sleep(Duration::from_millis(2));
    }
}

/// Runs `scenario` in real time against a daemon on the transports of
/// `options`; returns the landing summary and the server's counters.
pub fn serve(
    scenario: &Scenario,
    options: &ServeOptions,
    progress: Progress<'_>,
) -> Result<(Summary, ServeCounters)> {
    let mut plant = scenario.build_plant()?;
    let drivers = DriverEndpoint::open(&options.drivers, "atmo_sitl_plant").map_err(ros_err)?;
    let (ros_out, ros_in, ros_thread) =
        SitlNode::start(&options.ros2, Ros2StartOptions::default()).map_err(ros_err)?;
    let mut links = Links {
        drivers,
        ros_out,
        ros_in,
        sensors: Every::new(options.sensor_rate_hz),
        heartbeats: Every::new(options.heartbeat_rate_hz),
        counters: ServeCounters::default(),
        last_status: None,
        last_estimate: None,
        boards: options.boards.is_some(),
        esc_full_speed_rpm: options.esc_full_speed_rpm,
    };
    let mut boards = match &options.boards {
        Some(files) => Some(SimBoards::start(files, &options.drivers)?),
        None => None,
    };
    let mode_of = |s: &MpcStatus| Mode::from_code(s.mode.code());

    let waiting = Instant::now();
    wait_for_arming(
        &mut plant,
        &mut links,
        boards.as_mut(),
        scenario,
        options,
        progress,
    )?;
    links.counters.waited_for_daemon_ms =
        u64::try_from(waiting.elapsed().as_millis()).unwrap_or(u64::MAX);

    let start = Instant::now();
    let start_wall_ns = wall_clock_ns();
    let stamp = move |t: f64| start_wall_ns + (t.max(0.0) * 1e9).round() as u64;
    // Sized for 150 Hz status; more only reallocates.
    let mut tracker = LandingTracker::new((scenario.file.duration * 150.0) as usize + 2);
    let mut command = Command::idle();
    let dt = plant.dt();
    let mut step: u64 = 0;
    while plant.time() < scenario.file.duration - 1e-9 && plant.crash().is_none() {
        // Real time: plant step k at start + k dt (absolute deadlines).
        let deadline = start + Duration::from_secs_f64(step as f64 * dt);
        let now = Instant::now();
        if deadline > now {
            std::thread::sleep(deadline - now);
        } else if now - deadline > Duration::from_millis(20) {
            links.counters.late_steps += 1;
        }
        let received = links.drivers.receive();
        if let Some(c) = received.thrust {
            command.rotors = Input::from(c.thrust);
            links.counters.thrust_commands += 1;
        }
        if let Some(boards) = &mut boards {
            boards.follow_tilt(plant.tilt());
            command.tilt_rate = boards.tilt_rate(plant.tilt());
            let [left, right] = boards.wheel_rates();
            command.wheel_rates = atmo_core::control::WheelRates { left, right };
        } else {
            if let Some(c) = received.tilt_velocity {
                command.tilt_rate = c.velocity;
            }
            if let Some(c) = received.wheel_rates {
                command.wheel_rates = atmo_core::control::WheelRates {
                    left: c.rates[0],
                    right: c.rates[1],
                };
            }
        }
        if let Some(s) = links.take_status() {
            tracker.on_control_tick(
                s.mode,
                &s.thrust,
                (s.solver_iterations > 0).then_some(s.feedback_time),
                s.mpc_failures_total,
                s.rejected_inputs(),
            );
        }
        let t = plant.time();
        let (force, torque) = scenario.disturbance_at(t);
        plant.set_external_wrench(force, torque)?;
        let was_grounded = plant.contact_signal();
        plant.step(&command)?;
        tracker.after_plant_step(&crate::closed_loop::truth_of(&plant), was_grounded);
        links.publish(&plant, &pilot_msg(scenario, plant.time()), stamp);
        step += 1;
        if step.is_multiple_of(50) {
            progress(plant.time(), links.last_status.as_ref().and_then(mode_of));
        }
    }
    links.counters.served_until_ns = wall_clock_ns();
    drop(ros_thread);
    let summary = tracker.summary(&crate::closed_loop::run_end(
        scenario,
        &plant,
        start.elapsed().as_secs_f64(),
    ));
    Ok((summary, links.counters))
}
