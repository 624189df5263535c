//! Closed loop: a scenario flown by the flight stack (FlightStack +
//! atmo-mpc) against the plant, tick by tick, with a summary of the landing.
//!
//! The flight stack runs in the daemon's own control loop
//! ([`atmo_flight::control_loop::ControlLoop`]) with a simulated clock and
//! a simulated `TickIo` ([`crate::sim_io`]): every input it sees comes
//! through the interface the onboard daemon uses.
//!
//! Timing: the plant steps at its fixed `dt` (1 ms); the flight stack ticks
//! at its control rate (150 Hz) on the plant's clock (tick k's deadline
//! `k T`, run at the first plant step at or after it). Its outputs are held
//! until the next tick. Deterministic: the flight stack's clock is the
//! plant's.

use std::time::Instant;

use atmo_core::RobotConfig;
use atmo_core::model::{State, idx};
use atmo_flight::control_loop::{TickTiming, tick_period};
use atmo_flight::flight_log::{FlightConfig, FlightConfigFiles, TickChannels};
use atmo_flight::inputs::InputSettings;
use atmo_flight::{FlightSettings, FlightStack, StepInputs, StepOutputs};
use atmo_io::msg::{MpcStatus, SimTruth};
use atmo_io::review::figure::FlightTrace;
use atmo_mpc::MpcSettings;
use atmo_mpc::settings::GroundEffectSource;

use crate::error::{Result, SimError};
use crate::scenario::{Scenario, SuccessConfig};
use crate::sim_io::{SimControl, SimIo, SimIoCounts, SimTick, terrain_z_below};
use atmo_plant::plant::Plant;

/// One control tick as the runner saw it (what is logged and plotted).
#[derive(Debug, Clone, Copy)]
pub struct TickRecord {
    pub time: f64,
    pub inputs: StepInputs,
    pub outputs: StepOutputs,
    /// The previous tick's timing (on the simulated clock).
    pub timing: TickTiming,
    /// The plant's true state and tilt at the tick.
    pub truth: State,
    pub truth_tilt: f64,
    /// True height of the base origin above the ground, m.
    pub truth_height: f64,
    /// The simulated I/O's counters (order rule, injected faults).
    pub io: SimIoCounts,
}

pub use atmo_io::review::landing::{LandingTracker, PredictedTouchdown, RunEnd, Summary};

impl SuccessConfig {
    /// Whether `summary` meets these `[success]` criteria: a wheel landing
    /// with no crash, enough tilt, a soft impact and a drive on; or, for a
    /// flight, no crash and no ground contact.
    pub fn met_by(&self, summary: &Summary) -> bool {
        let c = self;
        if c.landing {
            !summary.crashed
                && summary
                    .touchdown_tilt_deg
                    .is_some_and(|t| t >= c.min_touchdown_tilt_deg)
                && summary
                    .impact_speed_mps
                    .is_some_and(|v| v <= c.max_impact_speed)
                && summary.drive_distance_m >= c.min_drive_distance
        } else {
            !summary.crashed && summary.touchdown_time_s.is_none()
        }
    }
}

/// How a run of `scenario` on `plant` ended (for [`LandingTracker::summary`]).
pub fn run_end(scenario: &Scenario, plant: &Plant, wall_time_s: f64) -> RunEnd {
    RunEnd {
        scenario: scenario.file.name.clone(),
        seed: scenario.file.seed,
        crash_reason: plant
            .crash()
            .map(|e| format!("{:?} at t = {:.3} s", e.kind, e.time)),
        wall_time_s: Some(wall_time_s),
    }
}

/// The controller side of a closed-loop run: the robot model it believes
/// in (the plant may differ: see the scenario's robot and effects), its
/// flight settings and MPC settings.
#[derive(Debug, Clone)]
pub struct ControllerConfig {
    /// The texts `robot`, `flight` and `mpc` were parsed from (stored in a
    /// flight log, so that `atmo-daemon replay` rebuilds the same stack).
    pub files: FlightConfigFiles,
    pub robot: RobotConfig,
    pub flight: FlightSettings,
    pub mpc: MpcSettings,
    /// The daemon's input timeouts; its `ground_z` is replaced by the
    /// scenario's terrain under the start.
    pub inputs: InputSettings,
}

impl ControllerConfig {
    /// The shipped config/atmo.toml, config/flight.toml and config/mpc.toml.
    pub fn atmo() -> Result<Self> {
        let flight = FlightSettings::atmo();
        let mpc =
            MpcSettings::atmo(&flight.mpc_preset).map_err(|e| SimError::Setup(e.to_string()))?;
        let inputs = InputSettings::defaults(0.0, flight.failsafe.estimate_timeout);
        Ok(Self {
            files: FlightConfigFiles::shipped(),
            robot: RobotConfig::atmo(),
            flight,
            mpc,
            inputs,
        })
    }

    /// Lifts the MPC's wall-clock time limit (its iteration cap still
    /// bounds each solve) so that a simulated flight does not depend on how
    /// busy the machine is: same scenario and seed, same flight.
    #[must_use]
    pub fn deterministic(mut self) -> Self {
        self.mpc.solver.time_limit = 10.0;
        self
    }

    /// The MPC's ground-effect surface `source`, set in the MPC text a
    /// flight log stores (a named file's text is read and stored too) and
    /// in the settings parsed from it, so that a replay rebuilds the
    /// controller flown.
    ///
    /// # Errors
    /// A file that cannot be read.
    pub fn with_ground_effect(mut self, source: &GroundEffectSource) -> Result<Self> {
        self.files.set_ground_effect(source).map_err(setup)?;
        self.reparse_mpc()
    }

    /// `[tilt_plan] enabled`, in the MPC text and the settings.
    ///
    /// # Errors
    /// MPC settings without a `[tilt_plan]` when `enabled`.
    pub fn with_tilt_plan(mut self, enabled: bool) -> Result<Self> {
        if self.mpc.tilt_plan.is_none() {
            return if enabled {
                Err(SimError::Setup(format!(
                    "{}: the MPC settings have no [tilt_plan]",
                    self.files.mpc.source.display()
                )))
            } else {
                Ok(self)
            };
        }
        self.files
            .set_mpc_value("tilt_plan", "enabled", enabled)
            .map_err(setup)?;
        self.reparse_mpc()
    }

    /// Another MPC file (text stored in the log, settings parsed from it).
    ///
    /// # Errors
    /// A file that cannot be read or parsed.
    pub fn with_mpc_file(mut self, path: &std::path::Path) -> Result<Self> {
        self.files.set_mpc_file(path).map_err(setup)?;
        self.reparse_mpc()
    }

    /// The MPC settings parsed again from the (edited) text, keeping the
    /// time limit this config flies with (see [`Self::deterministic`]).
    fn reparse_mpc(mut self) -> Result<Self> {
        let time_limit = self.mpc.solver.time_limit;
        self.mpc = self.files.parse().map_err(setup)?.mpc;
        self.mpc.solver.time_limit = time_limit;
        Ok(self)
    }

    /// The flight stack (its ground-effect surface from the stored text).
    ///
    /// # Errors
    /// Settings the flight stack refuses.
    pub fn stack(&self) -> Result<FlightStack> {
        FlightConfig {
            robot: self.robot.clone(),
            flight: self.flight.clone(),
            mpc: self.mpc.clone(),
            ground_effect: self.files.ground_effect.clone(),
        }
        .stack()
        .map_err(|e| SimError::Setup(e.to_string()))
    }
}

/// The controllers a simulated flight can be flown with, by name.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize, clap::ValueEnum,
)]
#[serde(rename_all = "kebab-case")]
pub enum ControllerPreset {
    /// The MPC settings as given (config/mpc.toml, or `--mpc-config`).
    Config,
    /// No ground effect in the model, the tilt on the paper's law.
    Nominal,
    /// The ground-effect surface in the model, the tilt on the paper's law.
    GroundEffect,
    /// The ground-effect surface in the model and the tilt planned by the
    /// MPC in the transition (`[tilt_plan]`, enabled).
    PlannedTilt,
}

impl ControllerPreset {
    /// Its name, as on the command line and in output folders.
    pub fn name(self) -> &'static str {
        match self {
            Self::Config => "config",
            Self::Nominal => "nominal",
            Self::GroundEffect => "ground-effect",
            Self::PlannedTilt => "planned-tilt",
        }
    }

    /// `base` made into this controller; `surface` is the ground-effect
    /// surface of the presets that model it.
    ///
    /// # Errors
    /// A surface file that cannot be read, or MPC settings without the
    /// `[tilt_plan]` a preset needs.
    pub fn config(
        self,
        base: &ControllerConfig,
        surface: &GroundEffectSource,
    ) -> Result<ControllerConfig> {
        let with = |source: &GroundEffectSource, plans_tilt: bool| {
            base.clone()
                .with_ground_effect(source)?
                .with_tilt_plan(plans_tilt)
        };
        match self {
            Self::Config => Ok(base.clone()),
            Self::Nominal => with(&GroundEffectSource::None, false),
            Self::GroundEffect => with(surface, false),
            Self::PlannedTilt => with(surface, true),
        }
    }
}

fn setup(e: impl std::fmt::Display) -> SimError {
    SimError::Setup(e.to_string())
}

/// The record of `tick`, with the plant's truth at it.
fn record(tick: &SimTick, plant: &Plant, io: SimIoCounts) -> TickRecord {
    let truth = plant.state();
    let ground = terrain_z_below(plant.plane(), truth[idx::X], truth[idx::Y]);
    TickRecord {
        time: plant.time(),
        inputs: tick.inputs,
        outputs: tick.outputs,
        timing: tick.timing,
        truth,
        truth_tilt: plant.tilt(),
        truth_height: ground - truth[idx::Z],
        io,
    }
}

/// Flies `scenario` in closed loop; `on_tick` sees every tick (for logs).
pub fn fly(
    scenario: &Scenario,
    controller: &ControllerConfig,
    on_tick: impl FnMut(&TickRecord),
) -> Result<Summary> {
    fly_observed(scenario, controller, on_tick, |_| {})
}

/// [`fly`] without observers, stopped with [`SimError::TimeLimit`] once the
/// wall clock passes `deadline` (checked every control tick).
pub fn fly_within(
    scenario: &Scenario,
    controller: &ControllerConfig,
    deadline: Option<Instant>,
) -> Result<Summary> {
    fly_until(scenario, controller, deadline, |_| {}, |_| {})
}

/// The plant's truth now, as logged.
pub fn truth_of(plant: &Plant) -> SimTruth {
    let state = plant.state();
    SimTruth {
        time: plant.time(),
        state: MpcStatus::array(&state),
        tilt: plant.tilt(),
        height: terrain_z_below(plant.plane(), state[idx::X], state[idx::Y]) - state[idx::Z],
        contact: plant.contact_signal(),
    }
}

/// [`fly`], with `on_plant` seeing the plant's truth at the start and after
/// every plant step.
pub fn fly_observed(
    scenario: &Scenario,
    controller: &ControllerConfig,
    on_tick: impl FnMut(&TickRecord),
    on_plant: impl FnMut(&SimTruth),
) -> Result<Summary> {
    fly_until(scenario, controller, None, on_tick, on_plant)
}

fn fly_until(
    scenario: &Scenario,
    controller: &ControllerConfig,
    deadline: Option<Instant>,
    mut on_tick: impl FnMut(&TickRecord),
    mut on_plant: impl FnMut(&SimTruth),
) -> Result<Summary> {
    let wall = Instant::now();
    let mut plant = scenario.build_plant()?;
    let mut stack = controller.stack()?;
    let duration = scenario.file.duration;
    let mut tracker = LandingTracker::new((duration / stack.period()) as usize + 2);
    // The daemon's constant ground height: the terrain under the start.
    let start = plant.state();
    let inputs = InputSettings {
        ground_z: terrain_z_below(plant.plane(), start[idx::X], start[idx::Y]),
        ..controller.inputs
    };
    let io = SimIo::new(inputs, *plant.plane())
        .with_faults(&scenario.file.faults)
        .with_autopilot_estimate(scenario.file.autopilot_estimate)
        .with_rotor_speed_noise(
            scenario
                .plant
                .effects
                .sensors
                .as_ref()
                .filter(|s| s.enabled)
                .map_or(0.0, |s| s.rotor_speed_std),
            scenario.file.seed,
        );
    let mut control = SimControl::new(tick_period(stack.period()), io);
    control.io.sense(&plant, scenario);
    on_plant(&truth_of(&plant));

    while plant.time() < duration - 1e-9 {
        if let Some(tick) = control.tick_if_due(&plant, &mut stack) {
            let s = &tick.outputs.status;
            tracker.on_control_tick(
                s.mode,
                &tick.outputs.thrust,
                (s.solver != atmo_flight::SolverStatus::Idle).then_some(s.feedback_time),
                s.mpc_failures_total,
                s.rejected.counts(),
            );
            if let Some((d, p)) = stack
                .flare_decision()
                .and_then(|d| d.predicted.map(|p| (d, p)))
            {
                tracker.on_decision(PredictedTouchdown {
                    decided_at_s: d.now_ns as f64 * 1e-9,
                    tilt_deg: p.tilt.to_degrees(),
                    impact_speed_mps: p.impact_speed,
                    time_to_touchdown_s: p.time,
                });
            }
            on_tick(&record(&tick, &plant, control.io.counts()));
            if deadline.is_some_and(|d| Instant::now() > d) {
                return Err(SimError::TimeLimit {
                    limit_s: deadline.map_or(0.0, |d| (d - wall).as_secs_f64()),
                    sim_time_s: plant.time(),
                });
            }
        }
        let (force, torque) = scenario.disturbance_at(plant.time());
        plant.set_external_wrench(force, torque)?;
        let was_grounded = plant.contact_signal();
        plant.step(control.io.command())?;
        control.io.sense(&plant, scenario);
        let truth = truth_of(&plant);
        on_plant(&truth);
        tracker.after_plant_step(&truth, was_grounded);
        if plant.crash().is_some() {
            break;
        }
    }
    Ok(tracker.summary(&run_end(scenario, &plant, wall.elapsed().as_secs_f64())))
}

/// The per-tick series of the paper's Fig. 5A (the plant's truth height
/// and tilt, the flight stack's mode, alpha and thrust).
pub fn trace_of(records: &[TickRecord]) -> FlightTrace {
    let mut trace = FlightTrace::default();
    for r in records {
        let s = &r.outputs.status;
        trace.push(
            r.time,
            r.truth_height,
            r.truth_tilt,
            s.mode,
            s.alpha,
            &r.outputs.thrust,
        );
    }
    trace
}

/// The topic of the per-tick status in the flight log.
pub const STATUS_TOPIC: &str = "/atmo/status";
pub use atmo_io::review::log::{SIM_METADATA, TRUTH_TOPIC};

impl ControllerConfig {
    /// Whether the controller's settings are the ones its files parse to
    /// (up to the MPC time limit, which [`Self::deterministic`] lifts and a
    /// replay lifts too): then a replay rebuilds the same flight stack.
    pub fn matches_files(&self) -> bool {
        self.files.parse().is_ok_and(|parsed| {
            let mut mpc = parsed.mpc;
            mpc.solver.time_limit = self.mpc.solver.time_limit;
            parsed.robot == self.robot && parsed.flight == self.flight && mpc == self.mpc
        })
    }
}

/// Flies `scenario` and logs every tick's `atmo_msgs/MpcStatus` to the MCAP
/// file `path` (ROS 2 profile: Foxglove plots every field). Errors if the
/// logger dropped anything: a simulation has no excuse to lose records.
pub fn fly_logged(
    scenario: &Scenario,
    controller: &ControllerConfig,
    path: &std::path::Path,
    mut on_tick: impl FnMut(&TickRecord),
) -> Result<(Summary, atmo_io::mcap_log::LogSummary)> {
    use atmo_io::mcap_log::{LoggerOptions, McapLogger};
    let io = |e: atmo_io::IoError| SimError::Output(e.to_string());
    // A simulation runs ~50x faster than real time: a deep queue.
    let options = LoggerOptions {
        queue_capacity: 1 << 16,
        ..LoggerOptions::default()
    };
    let (log, thread) = McapLogger::spawn(path, options).map_err(io)?;
    let channels = TickChannels::register(&log, STATUS_TOPIC).map_err(io)?;
    let truth = log.channel::<SimTruth>(TRUTH_TOPIC).map_err(io)?;
    controller.files.log_to(&log, 0).map_err(io)?;
    let mut tick = 0;
    let mut crash = None;
    let summary = fly_observed(
        scenario,
        controller,
        |r| {
            let message =
                atmo_flight::telemetry::status_message(tick, &r.inputs, &r.outputs, &r.timing);
            // Counted if dropped (queue full): reported as an error below.
            channels.log_tick(&log, tick, &r.inputs, &r.outputs, &message);
            tick += 1;
            on_tick(r);
        },
        |t| {
            // One record per plant step (1000 per simulated second at the
            // default dt, a million at the smallest): the simulation waits
            // for the writer rather than drop them.
            log.log_waiting(truth, (t.time * 1e9).round() as u64, t);
        },
    );
    if let Ok(s) = &summary {
        crash.clone_from(&s.crash_reason);
    }
    let mut meta = std::collections::BTreeMap::new();
    meta.insert("scenario".to_string(), scenario.file.name.clone());
    meta.insert("seed".to_string(), scenario.file.seed.to_string());
    meta.insert("crash".to_string(), crash.unwrap_or_default());
    meta.insert(
        "controller_matches_files".to_string(),
        controller.matches_files().to_string(),
    );
    log.metadata(SIM_METADATA, meta).map_err(io)?;
    log.finish();
    let written = thread.join().map_err(io)?;
    let summary = summary?;
    if written.dropped > 0 {
        return Err(SimError::Output(format!(
            "{}: the logger dropped {} records",
            path.display(),
            written.dropped
        )));
    }
    Ok((summary, written))
}
