//! `atmo-daemon preflight`: the arming checks and a props-off tilt sweep,
//! run on the robot's transports instead of flying, with a pass/fail table.
//!
//! 1. Checks: for the longest arming window and half a second more, the
//!    daemon's input assembly ([`InputLatch`], the radio's mapping) and
//!    [`ArmingMonitor`] run at the control rate on the ROS 2 inputs and the
//!    driver ports, the tilt commanded to rest. Each arming check is a row,
//!    with what was measured.
//! 2. Tilt sweep (props off; the thrusters get 0 every tick): the tilt is
//!    driven to 0 deg, to `sweep_to_deg` and back to 0 at the robot's tilt
//!    rate limit (`limits.tilt_rate_max`), slowing near each target. A leg
//!    passes when the encoder arrives within [`ARRIVAL_DEG`] of its target
//!    in time (travel / rate + [`LEG_MARGIN_S`]) and the measured tilt never
//!    strays more than `arming.tilt_tolerance_deg` from the start of the
//!    leg plus the integral of the commanded tilt velocity.
//!
//! Preflight owns the driver ports for its run: do not run it beside a
//! running daemon.

use std::time::{Duration, Instant};

use atmo_core::{Linkage, RobotConfig};
use atmo_io::drivers::{DriverId, FlightPorts, monotonic_ns};
use atmo_io::ros2::Ros2Inputs;

use crate::onboard::{DaemonConfig, OnboardSettings};
use atmo_flight::arming::{ArmingCheck, ArmingMonitor, ArmingObservation};
use atmo_flight::error::{FlightError, Result};
use atmo_flight::flight_stack::Estimate;
use atmo_flight::inputs::{Assembled, InputLatch};
use atmo_flight::rc::RcPilot;

/// A sweep leg has arrived within this of its target, deg.
pub const ARRIVAL_DEG: f64 = 1.5;
/// Time a leg may take beyond travel / rate, s (start, slow-down, lag).
pub const LEG_MARGIN_S: f64 = 3.0;
/// Gain of the slow-down near a target, 1/s.
const APPROACH_GAIN: f64 = 4.0;

/// One line of the table.
#[derive(Debug, Clone, PartialEq)]
pub struct Row {
    pub check: String,
    pub pass: bool,
    pub detail: String,
}

/// Every row, in the order run.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Report {
    pub rows: Vec<Row>,
}

impl Report {
    pub fn passed(&self) -> bool {
        self.rows.iter().all(|r| r.pass)
    }
}

impl std::fmt::Display for Report {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let width = self.rows.iter().map(|r| r.check.len()).max().unwrap_or(5);
        writeln!(f, "{:width$}  result  detail", "check")?;
        for r in &self.rows {
            let verdict = if r.pass { "PASS" } else { "FAIL" };
            writeln!(f, "{:width$}  {verdict:6}  {}", r.check, r.detail)?;
        }
        let failed = self.rows.iter().filter(|r| !r.pass).count();
        if failed == 0 {
            write!(f, "preflight: all {} passed", self.rows.len())
        } else {
            write!(f, "preflight: {failed} of {} FAILED", self.rows.len())
        }
    }
}

/// The preflight's I/O: the daemon's inputs and the driver ports.
pub struct Preflight {
    ports: FlightPorts,
    ros_in: Ros2Inputs,
    latch: InputLatch,
    rc: Option<RcPilot>,
    monitor: ArmingMonitor,
    linkage: Linkage,
    problem: Option<&'static str>,
    window: Duration,
    tolerance: f64,
    tilt_rate: f64,
    period: Duration,
    start: Instant,
    next: Instant,
    tilt: Option<f64>,
    command: f64,
    last: Option<Assembled>,
}

impl Preflight {
    /// Opens the driver ports (on the calling thread, which then runs the
    /// preflight) for `config`, with the robot's linkage and limits.
    pub fn open(
        config: &DaemonConfig,
        robot: &RobotConfig,
        ros_in: Ros2Inputs,
        rate_hz: f64,
        estimate_timeout: f64,
    ) -> Result<Self> {
        let ports = FlightPorts::open(&config.drivers)
            .map_err(|e| FlightError::Setup(format!("driver ports: {e}")))?;
        let settings = OnboardSettings::new(config, estimate_timeout);
        let linkage = Linkage::from_config(&robot.linkage, robot.limits.tilt_max())?;
        let a = config.arming;
        let now = Instant::now();
        Ok(Self {
            ports,
            ros_in,
            latch: InputLatch::new(settings.inputs()),
            rc: settings.rc.map(RcPilot::new),
            monitor: ArmingMonitor::new(a, settings.configuration_ok),
            linkage,
            problem: config.flight_problem(),
            window: Duration::from_millis(a.estimate_window_ms.max(a.tilt_window_ms) + 500),
            tolerance: a.tilt_tolerance_deg.to_radians(),
            tilt_rate: robot.limits.tilt_rate_max,
            period: Duration::from_secs_f64(1.0 / rate_hz),
            start: now,
            next: now,
            tilt: None,
            command: 0.0,
            last: None,
        })
    }

    fn now_ns(&self) -> u64 {
        u64::try_from(self.start.elapsed().as_nanos()).unwrap_or(u64::MAX)
    }

    /// One tick: send the commands (thrust 0, `tilt_velocity`, wheels 0),
    /// wait for the next deadline, gather the inputs, run the checks.
    fn tick(&mut self, tilt_velocity: f64) -> u8 {
        self.ports.send_thrust([0.0; 4]);
        self.ports.send_tilt_velocity(tilt_velocity, false);
        self.ports.send_wheel_rates([0.0; 2]);
        self.ports.notify_drivers();
        self.command = tilt_velocity;
        self.next += self.period;
        if let Some(wait) = self.next.checked_duration_since(Instant::now()) {
            std::thread::sleep(wait);
        }
        let now_ns = self.now_ns();
        let stamp = |received: Instant| now_ns.saturating_sub(received.elapsed().as_nanos() as u64);
        while let Some(e) = self.ros_in.latest_estimate() {
            self.latch.estimate(Estimate {
                stamp_ns: stamp(e.received),
                state: e.state,
            });
        }
        while let Some(p) = self.ros_in.latest_pilot() {
            self.latch.pilot(p.input, stamp(p.received));
        }
        if let Some(frame) = self.ros_in.latest_rc()
            && let Some(rc) = &mut self.rc
            && let Ok(reading) = rc.map(&frame.input)
        {
            self.latch.radio(reading, stamp(frame.received));
        }
        let drivers = self.ports.poll(monotonic_ns());
        if let Some(encoder) = drivers.tilt_encoder {
            self.tilt = self.linkage.tilt_from_counts(encoder.counts as f64).ok();
        }
        self.latch
            .drivers_alive(drivers.health.all_required_alive());
        let assembled = self.latch.assemble(now_ns);
        self.last = Some(assembled);
        self.monitor.observe(&ArmingObservation {
            now_ns,
            estimates_total: self.ros_in.counters().estimates_accepted,
            pilot_lost: assembled.inputs.pilot_lost,
            driver_lost: assembled.inputs.driver_lost,
            tilt: self.tilt,
            tilt_velocity: self.command,
        })
    }

    /// The arming checks over one window, the tilt at rest.
    pub fn checks(&mut self) -> Vec<Row> {
        let started = Instant::now();
        let estimates_before = self.ros_in.counters().estimates_accepted;
        let mut failures = 0;
        while started.elapsed() < self.window {
            failures = self.tick(0.0);
        }
        let seconds = started.elapsed().as_secs_f64();
        let rate = (self.ros_in.counters().estimates_accepted - estimates_before) as f64 / seconds;
        let health = self.ports.poll(monotonic_ns()).health;
        let silent: Vec<&str> = DriverId::ALL
            .into_iter()
            .filter(|d| health.required[*d as usize] && !health.is_alive(*d))
            .map(DriverId::name)
            .collect();
        let radio = match (&self.rc, self.last.map(|a| a.inputs.pilot_lost)) {
            (None, _) => "no radio configured (atmo_msgs/PilotInput)".to_string(),
            (Some(_), Some(true)) => "lost (rc_lost, or silent)".to_string(),
            (Some(_), _) => "present".to_string(),
        };
        ArmingCheck::ALL
            .into_iter()
            .map(|check| Row {
                check: format!("arming: {}", check.name()),
                pass: failures & check.bit() == 0,
                detail: match check {
                    ArmingCheck::Configuration => self.problem.unwrap_or("can fly").to_string(),
                    ArmingCheck::EstimateRate => {
                        format!("{rate:.1} Hz accepted over {seconds:.1} s")
                    }
                    ArmingCheck::Radio => radio.clone(),
                    ArmingCheck::Drivers if silent.is_empty() => {
                        "every required driver alive".into()
                    }
                    ArmingCheck::Drivers => format!("silent: {}", silent.join(", ")),
                    ArmingCheck::TiltEncoder => match self.tilt {
                        Some(t) => format!("{:.1} deg, at rest as commanded", t.to_degrees()),
                        None => "no encoder reading".into(),
                    },
                },
            })
            .collect()
    }

    /// One sweep leg to `target` (rad): arrival and agreement with the
    /// integrated command.
    fn leg(&mut self, target: f64) -> Row {
        let name = format!("tilt sweep to {:.0} deg", target.to_degrees());
        let Some(start_tilt) = self.tilt else {
            return Row {
                check: name,
                pass: false,
                detail: "no encoder reading".into(),
            };
        };
        let limit =
            Duration::from_secs_f64((target - start_tilt).abs() / self.tilt_rate + LEG_MARGIN_S);
        let started = Instant::now();
        let (mut commanded, mut worst, mut last_ns) = (0.0_f64, 0.0_f64, self.now_ns());
        let mut tilt = start_tilt;
        while (target - tilt).abs() > ARRIVAL_DEG.to_radians() && started.elapsed() < limit {
            let v = (APPROACH_GAIN * (target - tilt)).clamp(-self.tilt_rate, self.tilt_rate);
            self.tick(v);
            let now_ns = self.now_ns();
            commanded += v * now_ns.saturating_sub(last_ns) as f64 * 1e-9;
            last_ns = now_ns;
            tilt = self.tilt.unwrap_or(tilt);
            worst = worst.max(((tilt - start_tilt) - commanded).abs());
        }
        // Settle: the command at rest, the encoder should stay.
        for _ in 0..10 {
            self.tick(0.0);
        }
        let arrived = (target - tilt).abs() <= ARRIVAL_DEG.to_radians();
        let agrees = worst <= self.tolerance;
        Row {
            check: name,
            pass: arrived && agrees,
            detail: format!(
                "{:.1} -> {:.1} deg in {:.1} s (limit {:.1} s); encoder vs command at most {:.2} deg (tolerance {:.1})",
                start_tilt.to_degrees(),
                tilt.to_degrees(),
                started.elapsed().as_secs_f64(),
                limit.as_secs_f64(),
                worst.to_degrees(),
                self.tolerance.to_degrees()
            ),
        }
    }

    /// The props-off sweep: 0 deg, `to_deg`, 0 deg; one row per leg.
    pub fn sweep(&mut self, to_deg: f64) -> Vec<Row> {
        [0.0, to_deg, 0.0]
            .into_iter()
            .map(|deg| self.leg(deg.to_radians()))
            .collect()
    }

    /// Both parts, into one report (the sweep only if `sweep_to_deg` is set).
    pub fn run(&mut self, sweep_to_deg: Option<f64>) -> Report {
        let mut rows = self.checks();
        if let Some(to) = sweep_to_deg {
            rows.extend(self.sweep(to));
        }
        // Leave the tilt at rest.
        self.tick(0.0);
        Report { rows }
    }
}
