//! The daemon's control loop in simulation: a simulated [`Clock`] (the
//! plant's time) and a simulated [`TickIo`] whose sources are the plant's
//! sensors, the scenario's pilot script and the scenario's terrain.
//!
//! The tick itself is the daemon's [`ControlLoop`] (gather ->
//! `FlightStack::step` -> emit -> `prepare_next`, with its scheduler) and
//! the inputs are assembled by the daemon's [`InputLatch`], exactly as
//! onboard; only the sources differ:
//!
//! | input          | onboard (`OnboardIo`)              | simulation ([`SimIo`])                         |
//! |----------------|------------------------------------|------------------------------------------------|
//! | estimate       | ROS 2 odometry, age from acceptance | the plant's motion capture, age from publication |
//! | autopilot's estimate | ROS 2 PX4 `VehicleOdometry`, enabled beside a motion-capture estimate | with the scenario's `autopilot_estimate`: the plant's autopilot estimate (the motion capture's sample with its vertical-velocity error), not through the estimate faults |
//! | pilot          | ROS 2 `PilotInput`                 | the scenario's script at [`PILOT_RATE_HZ`]      |
//! | encoder        | iceoryx2 driver port               | the plant's encoder                            |
//! | contact        | iceoryx2 driver port               | the plant's contact signal                     |
//! | driver liveness| heartbeats                         | always alive (the simulated drivers answer)    |
//! | ground height  | ROS 2 `/atmo/ground` while fresh, else the config constant | the scenario's terrain map at the *estimated* position, with each estimate (same timeout) |
//! | ground normal  | ROS 2 `/atmo/ground_normal` while fresh, else level | the scenario's terrain plane's normal, with each height |
//!
//! The estimate reaches the latch through the scenario's fault injector
//! ([`crate::faults`]: a FIFO transport stamping each estimate with the
//! estimator's clock) and the ROS 2 node's order rule
//! ([`atmo_io::stamp_order`]: duplicates and reordered estimates dropped and
//! counted, a backward clock jump taken as a new clock). With faults, the
//! drivers can die (no liveness, no readings, nothing actuated) and the
//! MPC's solves can be cut as the time limit cuts them.
//!
//! A source's sample is "accepted" when the runner calls [`SimIo::sense`]
//! after a plant step; at the tick its age (plant time since acceptance)
//! stamps it on the tick's clock, as the onboard I/O does with its
//! `Instant`s. Nothing of the plant's truth reaches the flight stack.

use std::cell::Cell;
use std::time::Duration;

use atmo_core::model::{Input, idx};
use atmo_flight::control_loop::{Clock, ControlLoop, TickIo, TickTiming};
use atmo_flight::inputs::{InputLatch, InputSettings};
use atmo_flight::rc::{RcConfig, RcReading};
use atmo_flight::{Estimate, FlightStack, PilotInput, StepInputs, StepOutputs};
use atmo_plant::contact::Plane;
use atmo_plant::noise;
use atmo_plant::plant::{Command, Plant};
use rand_chacha::ChaCha8Rng;

use atmo_io::stamp_order::StampOrder;
use atmo_mpc::SolverCuts;

use crate::actuator_faults::ActuatorInjector;
use crate::faults::{FaultCounts, FaultInjector, FaultsConfig};
use crate::scenario::Scenario;

/// Rate of the scenario's pilot stream (a radio link's frame rate), Hz.
pub const PILOT_RATE_HZ: f64 = 50.0;

pub use crate::sim_time::time_ns;

/// The scenario's pilot inputs at `t`, as the flight stack reads them (the
/// one place a scenario's `[[pilot]]` becomes a pilot input: the in-process
/// runner and the SITL server both send this).
pub fn pilot_input(scenario: &Scenario, t: f64) -> PilotInput {
    scenario
        .pilot_at(t)
        .map_or(PilotInput::default(), |p| PilotInput {
            velocity: p.velocity,
            yaw_rate: p.yaw_rate,
            throttle: p.throttle,
            arm: p.arm,
            offboard: p.offboard,
            mpc_enabled: p.mpc,
        })
}

/// NED z of the terrain plane straight below (x, y).
pub fn terrain_z_below(plane: &Plane, x: f64, y: f64) -> f64 {
    let (n, p0) = (&plane.normal, &plane.point);
    p0.z - (n.x * (x - p0.x) + n.y * (y - p0.y)) / n.z
}

/// The plant's clock: time moves only when the plant steps. The runner
/// steps the plant up to a tick's deadline before it runs the tick, so
/// there is never anything to sleep for.
#[derive(Debug, Default)]
pub struct SimClock {
    now_ns: Cell<u64>,
}

impl SimClock {
    pub fn set(&self, now_ns: u64) {
        self.now_ns.set(now_ns);
    }
}

impl Clock for SimClock {
    fn now_ns(&self) -> u64 {
        self.now_ns.get()
    }

    fn sleep_until(&self, _deadline_ns: u64) {}
}

/// One tick as the simulated I/O saw it.
#[derive(Debug, Clone, Copy)]
pub struct SimTick {
    pub inputs: StepInputs,
    pub outputs: StepOutputs,
    /// The previous tick's timing (what the daemon logs with this tick).
    pub timing: TickTiming,
}

/// A sample accepted at `at_ns` (plant time), not yet handed to a tick.
#[derive(Debug, Clone, Copy)]
struct Arrived<T> {
    value: T,
    at_ns: u64,
}

/// The simulated [`TickIo`]: the plant's sensors and the scenario's pilot
/// and terrain in, the plant's command out.
#[derive(Debug)]
pub struct SimIo {
    latch: InputLatch,
    plane: Plane,
    now_ns: u64,
    estimate_sequence: Option<u64>,
    estimate: Option<Arrived<atmo_core::model::State>>,
    /// The autopilot's own estimate is delivered (`with_autopilot_estimate`).
    autopilot_enabled: bool,
    autopilot_estimate: Option<Arrived<atmo_core::model::State>>,
    pilot: Option<Arrived<PilotInput>>,
    pilot_period_ns: u64,
    next_pilot_ns: u64,
    command: Command,
    last: Option<SimTick>,
    faults: FaultInjector,
    actuators: ActuatorInjector,
    estimate_order: StampOrder,
    /// The rotors' true speeds at the last plant step (a fraction of full).
    rotor_speeds: [f64; 4],
    /// The ESCs' speed noise, a fraction of full, and its random stream.
    rotor_speed_noise: Option<(f64, ChaCha8Rng)>,
}

/// The simulated I/O's counters after a tick (what the onboard daemon
/// reports in `MpcStatus.io`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SimIoCounts {
    /// Estimates dropped by the order rule (duplicates, reordered).
    pub estimates_out_of_order: u64,
    /// Backward steps of the estimator's clock taken as a new clock.
    pub estimate_clock_jumps: u64,
    pub drivers_alive: bool,
    pub faults: FaultCounts,
}

impl SimIo {
    /// `settings` as the daemon's (timeouts; `ground_z` until the first
    /// estimate gives the terrain map a position).
    pub fn new(settings: InputSettings, plane: Plane) -> Self {
        Self {
            latch: InputLatch::new(settings),
            plane,
            now_ns: 0,
            estimate_sequence: None,
            estimate: None,
            autopilot_enabled: false,
            autopilot_estimate: None,
            pilot: None,
            pilot_period_ns: time_ns(1.0 / PILOT_RATE_HZ),
            next_pilot_ns: 0,
            command: Command::idle(),
            last: None,
            faults: FaultInjector::new(&FaultsConfig::default()),
            actuators: ActuatorInjector::default(),
            estimate_order: StampOrder::default(),
            rotor_speeds: [0.0; 4],
            rotor_speed_noise: None,
        }
    }

    /// The ESCs' speed reports get white noise of `std` (a fraction of
    /// full speed; `[effects.sensors] rotor_speed_std`), drawn from the
    /// scenario `seed`'s own stream, one draw a rotor a tick.
    #[must_use]
    pub fn with_rotor_speed_noise(mut self, std: f64, seed: u64) -> Self {
        self.rotor_speed_noise =
            (std > 0.0).then(|| (std, noise::rng(seed, noise::stream::ROTOR_SPEEDS)));
        self
    }

    /// Injects the scenario's `[faults]` (validated with the scenario).
    #[must_use]
    pub fn with_faults(mut self, faults: &FaultsConfig) -> Self {
        self.faults = FaultInjector::new(faults);
        self.actuators = ActuatorInjector::new(&faults.actuators);
        if self.actuators.has_radio() {
            // The pilot comes as the radio, lost after the daemon's timeout.
            let mut settings = *self.latch.settings();
            settings.rc_timeout = Some(Duration::from_millis(RcConfig::default().timeout_ms));
            self.latch = InputLatch::new(settings);
        }
        self
    }

    /// Delivers the autopilot's own estimate too: the plant's
    /// ([`atmo_plant::Plant::autopilot_estimate`]), not through the
    /// estimate faults (its IMU and barometer do not go through the motion
    /// capture's link).
    #[must_use]
    pub fn with_autopilot_estimate(mut self, enabled: bool) -> Self {
        self.autopilot_enabled = enabled;
        self
    }

    pub fn counts(&self) -> SimIoCounts {
        SimIoCounts {
            estimates_out_of_order: self.estimate_order.out_of_order(),
            estimate_clock_jumps: self.estimate_order.clock_jumps(),
            drivers_alive: !self.faults.drivers_dead(self.now_ns),
            faults: self.faults.counts(),
        }
    }

    /// Accepts what the robot's sources deliver at the plant's current
    /// time: call once before the first tick and after every plant step.
    pub fn sense(&mut self, plant: &Plant, scenario: &Scenario) {
        self.now_ns = time_ns(plant.time());
        if let Some(e) = plant.estimate()
            && self.estimate_sequence != Some(e.sequence)
        {
            self.estimate_sequence = Some(e.sequence);
            self.faults
                .publish(self.now_ns, time_ns(e.measured_at), e.state);
            if self.autopilot_enabled
                && let Some(a) = plant.autopilot_estimate()
            {
                self.autopilot_estimate = Some(Arrived {
                    value: a.state,
                    at_ns: self.now_ns,
                });
            }
        }
        while let Some(e) = self.faults.next_delivery(self.now_ns) {
            if self.estimate_order.accept(e.stamp_ns) {
                self.estimate = Some(Arrived {
                    value: e.state,
                    at_ns: self.now_ns,
                });
            }
        }
        if self.now_ns >= self.next_pilot_ns {
            if !self.actuators.radio_silent(self.now_ns) {
                self.pilot = Some(Arrived {
                    value: pilot_input(scenario, plant.time()),
                    at_ns: self.now_ns,
                });
            }
            self.next_pilot_ns += self.pilot_period_ns;
        }
        if self.faults.drivers_dead(self.now_ns) {
            // Silent drivers: no heartbeat, no reading, nothing actuated.
            self.latch.drivers_alive(false);
            self.command = Command::idle();
            return;
        }
        let counts = match self
            .actuators
            .sense_slip(self.now_ns, plant.tilt(), plant.tilt_max())
        {
            Some(counted) => plant.encoder_counts_at(counted),
            None => plant.encoder_counts(),
        };
        if let Ok(counts) = counts {
            self.latch
                .tilt_counts(self.actuators.encoder(self.now_ns, counts));
        }
        self.latch
            .ground_contact(self.actuators.contact(self.now_ns, plant.contact_signal()));
        // The ESCs' speeds: after the motor's lag and any fault on it.
        self.rotor_speeds = plant.rotor_speeds();
    }

    /// The command the last tick left for the plant (held until the next).
    pub fn command(&self) -> &Command {
        &self.command
    }

    /// The last tick, once (`None` if no tick ran since the last call).
    pub fn take_tick(&mut self) -> Option<SimTick> {
        self.last.take()
    }

    /// The tick's clock stamp of a sample accepted at `at_ns` (its age at
    /// the tick counted back from the deadline, as onboard).
    fn stamp(&self, deadline_ns: u64, at_ns: u64) -> u64 {
        deadline_ns.saturating_sub(self.now_ns.saturating_sub(at_ns))
    }
}

impl TickIo for SimIo {
    fn gather(&mut self, deadline_ns: u64) -> Option<StepInputs> {
        if let Some(e) = self.estimate.take() {
            self.latch.estimate(Estimate {
                stamp_ns: self.stamp(deadline_ns, e.at_ns),
                state: e.value,
            });
            // The terrain map, looked up where the robot believes it is:
            // the plane's height there and its normal.
            let z = terrain_z_below(&self.plane, e.value[idx::X], e.value[idx::Y]);
            let stamp = self.stamp(deadline_ns, e.at_ns);
            self.latch.ground_plane(z, self.plane.normal.into(), stamp);
        }
        if let Some(e) = self.autopilot_estimate.take() {
            self.latch.autopilot_estimate(Estimate {
                stamp_ns: self.stamp(deadline_ns, e.at_ns),
                state: e.value,
            });
        }
        if let Some(p) = self.pilot.take() {
            let at = self.stamp(deadline_ns, p.at_ns);
            if self.actuators.has_radio() {
                let reading = RcReading {
                    pilot: p.value,
                    tilt_lever: 0.0,
                    rehome_tilt: false,
                    lost: false,
                };
                self.latch.radio(reading, at);
            } else {
                self.latch.pilot(p.value, at);
            }
        }
        // The ESCs report through PX4, not the drivers: heard whatever the
        // drivers do.
        let mut speeds = self.rotor_speeds;
        if let Some((std, rng)) = &mut self.rotor_speed_noise {
            for s in &mut speeds {
                *s = (*s + *std * noise::normal(rng)).max(0.0);
            }
        }
        self.latch.rotor_speeds(speeds, deadline_ns);
        Some(self.latch.assemble(deadline_ns).inputs)
    }

    fn emit(&mut self, inputs: &StepInputs, outputs: &StepOutputs, timing: &TickTiming) {
        self.faults.on_mode(outputs.status.mode, self.now_ns);
        self.actuators.on_mode(outputs.status.mode, self.now_ns);
        self.command = if self.faults.drivers_dead(self.now_ns) {
            Command::idle()
        } else {
            Command {
                rotors: self
                    .actuators
                    .rotors(self.now_ns, Input::from(outputs.thrust)),
                tilt_rate: self.actuators.tilt_rate(self.now_ns, outputs.tilt_velocity),
                wheel_rates: outputs.wheel_rates,
            }
        };
        self.latch.mode(outputs.status.mode);
        self.last = Some(SimTick {
            inputs: *inputs,
            outputs: *outputs,
            timing: *timing,
        });
    }

    fn cut_script(&mut self) -> Option<SolverCuts> {
        self.faults.cut_script(self.now_ns)
    }
}

/// The daemon's control loop on the plant's clock.
#[derive(Debug)]
pub struct SimControl {
    pub clock: SimClock,
    pub io: SimIo,
    control: ControlLoop,
}

impl SimControl {
    /// Ticks every `period` (the daemon's control period), the first at t = 0.
    pub fn new(period: Duration, io: SimIo) -> Self {
        Self {
            clock: SimClock::default(),
            io,
            control: ControlLoop::new(period, 0),
        }
    }

    /// Runs the control tick if its deadline has come at the plant's
    /// current time (the first plant step at or after it) and returns it.
    pub fn tick_if_due(&mut self, plant: &Plant, stack: &mut FlightStack) -> Option<SimTick> {
        let now = time_ns(plant.time());
        if now < self.control.next_deadline_ns() {
            return None;
        }
        self.clock.set(now);
        self.control.tick(&self.clock, stack, &mut self.io);
        self.io.take_tick()
    }
}
