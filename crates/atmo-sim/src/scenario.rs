//! Scenario files (`config/scenarios/*.toml`): everything one simulated
//! flight needs.
//!
//! - `name`, `description`, `duration` (s), `seed`;
//! - `robot` and `plant`: robot and plant files, relative to the scenario
//!   file (defaults: the shipped ATMO parameters, every effect on);
//! - `[terrain]`: ground plane height and slope (at most 25 deg);
//! - `[initial]`: position (NED), Euler angles (deg), velocity, rates, tilt,
//!   initial rotor thrust, or `on_ground = true` to stand the robot on its
//!   wheels at the given x, y and yaw;
//! - `[effects.<name>]`: per-effect overrides of the plant file (a section
//!   here replaces the plant file's section of that name);
//! - `[[disturbances]]`: pushes (force in world axes, torque in body axes)
//!   over time intervals;
//! - what drives the robot, all piecewise constant from their time `t` on:
//!   `[[pilot]]` (what a flight stack reads from the pilot: arm, offboard and
//!   MPC switches, throttle, velocity command of at most 1 m/s, yaw rate),
//!   `[[reference]]` (position, yaw and tilt setpoints), and `[[open_loop]]`
//!   (actuator commands for open-loop runs: rotors, or a scale of the
//!   nominal hover trim at the current tilt, tilt rate, wheel rates).
//!
//! - `[faults]`: faults injected on the closed loop's input path (estimate
//!   dropouts, bursts, latency, duplicates, reordering, clock jumps, dead
//!   drivers, solver overruns: [`crate::faults`], docs/faults.md);
//! - `autopilot_estimate = true`: the autopilot's own estimate reaches the
//!   flight stack too, untouched by the estimate faults (what a failsafe
//!   flies on once the motion capture is lost).
//!
//! Loading is strict like every config of the project: unknown keys are
//! errors naming the file, line and key; values are range-checked and
//! errors name the key.

use std::path::{Path, PathBuf};

use atmo_core::config_file::{Checker, read_config_file};
use atmo_core::control::WheelRates;
use atmo_core::model::{Input, Model, State, idx, rotation};
use atmo_core::params::Params as _;
use atmo_core::{ConfigFile, CoreError, RobotConfig};
use nalgebra::Vector3;

use crate::error::{Result, SimError};
use crate::faults::FaultsConfig;
use atmo_plant::config::{EffectsConfig, PlantConfig, TerrainConfig};
use atmo_plant::contact::{Plane, rim_lowest_point};
use atmo_plant::plant::{Command, Event, InitialState, Plant};

/// Largest initial speed per axis, m/s (a robot of this class flies at a
/// few m/s; 1e6 m/s is a typo).
pub const MAX_INITIAL_SPEED: f64 = 30.0;
/// Largest initial body rate per axis, rad/s.
pub const MAX_INITIAL_RATE: f64 = 30.0;

/// NED z of the terrain plane below (x, y).
fn terrain_z_at(terrain: &TerrainConfig, x: f64, y: f64) -> f64 {
    let plane = Plane::new(terrain);
    let n = &plane.normal;
    plane.point.z - (n.x * (x - plane.point.x) + n.y * (y - plane.point.y)) / n.z
}

/// Largest pilot velocity command (m/s).
pub const MAX_PILOT_SPEED: f64 = 1.0;

atmo_core::params! {
    /// `[initial]`.
    #[derive(Debug, Clone, PartialEq)]
    pub struct InitialConfig {
        /// NED position of B (z = -height). With `on_ground`, only x and y count.
        pub position: [f64; 3], range -1e4..=1e4, unit "m";
        /// (yaw, pitch, roll). With `on_ground`, only yaw counts.
        pub euler_deg: [f64; 3] = [0.0; 3], range Finite, unit "deg";
        /// World (NED) velocity of B.
        pub velocity: [f64; 3] = [0.0; 3],
            range -MAX_INITIAL_SPEED..=MAX_INITIAL_SPEED, unit "m/s";
        /// Body rates.
        pub rates: [f64; 3] = [0.0; 3], range -MAX_INITIAL_RATE..=MAX_INITIAL_RATE, unit "rad/s";
        /// Tilt (at most the robot's `limits.tilt_max_deg`, checked with the robot).
        pub tilt_deg: f64 = 0.0, range 0.0..=90.0, unit "deg";
        /// Normalized rotor thrust at t = 0 (matters with motor lag); default:
        /// the first open-loop rotor command.
        pub thrust: Option<[f64; 4]> = None, range 0.0..=1.0;
        /// Stand the robot on its wheels on the terrain, aligned with the slope.
        pub on_ground: bool = false;
    }
    check |init, c, prefix| {
        c.within(&atmo_core::params::key(prefix, "euler_deg[1]"), init.euler_deg[1], -89.0, 89.0)
    }
}

atmo_core::params! {
    /// `[[disturbances]]`: a push held from `t` to `t + duration`.
    #[derive(Debug, Clone, PartialEq)]
    pub struct DisturbanceConfig {
        /// Start (within the scenario's duration).
        pub t: f64, unit "s";
        /// Length.
        pub duration: f64, range 1e-3..=1e6, unit "s";
        /// Force at B, world frame.
        pub force: [f64; 3] = [0.0; 3], range -1000.0..=1000.0, unit "N";
        /// Torque, body frame.
        pub torque: [f64; 3] = [0.0; 3], range -100.0..=100.0, unit "N m";
    }
}

atmo_core::params! {
    /// `[[pilot]]`: the sticks and switches the scripted pilot holds from `t` on.
    #[derive(Debug, Clone, Default, PartialEq)]
    pub struct PilotSetpoint {
        /// From when (within the scenario, in order).
        pub t: f64, unit "s";
        /// Arm switch.
        pub arm: bool = false;
        /// Offboard switch.
        pub offboard: bool = false;
        /// MPC switch.
        pub mpc: bool = false;
        /// 0.5 = hold altitude; on the ground >= 0.5 starts a take-off.
        pub throttle: f64 = 0.0, range 0.0..=1.0;
        /// (forward, right, down) in the heading frame; norm at most
        /// `MAX_PILOT_SPEED`.
        pub velocity: [f64; 3] = [0.0; 3], range Finite, unit "m/s";
        /// FRD (positive turns right).
        pub yaw_rate: f64 = 0.0, range -3.0..=3.0, unit "rad/s";
    }
    check |pilot, c, prefix| {
        // hypot: a 1e300 component is reported as itself, not as an
        // overflowed inf.
        let [x, y, z] = pilot.velocity;
        let speed = x.hypot(y).hypot(z);
        if speed > MAX_PILOT_SPEED + 1e-12 {
            return Err(c.fail(
                &atmo_core::params::key(prefix, "velocity"),
                format!("a velocity command of at most {MAX_PILOT_SPEED} m/s"),
                speed,
            ));
        }
        Ok(())
    }
}

atmo_core::params! {
    /// `[[reference]]`: setpoints from `t` on.
    #[derive(Debug, Clone, PartialEq)]
    pub struct ReferenceInput {
        /// From when (within the scenario, in order).
        pub t: f64, unit "s";
        /// NED position.
        pub position: [f64; 3], range Finite, unit "m";
        /// Heading.
        pub yaw_deg: f64 = 0.0, range -360.0..=360.0, unit "deg";
        /// Tilt (at most the robot's limit); absent: the flight stack's
        /// tilt law decides.
        pub tilt_deg: Option<f64> = None, range 0.0..=90.0, unit "deg";
    }
}

atmo_core::params! {
    /// `[[open_loop]]`: actuator commands from `t` on. Exactly one of `rotors`
    /// and `trim_scale`.
    #[derive(Debug, Clone, PartialEq)]
    pub struct OpenLoopInput {
        /// From when (the first at 0, in order).
        pub t: f64, unit "s";
        /// Normalized rotor commands.
        pub rotors: Option<[f64; 4]> = None, range 0.0..=1.0;
        /// Rotors = this times the nominal model's level hover trim at the
        /// current tilt (each held to [0, 1]).
        pub trim_scale: Option<f64> = None, range 0.0..=2.0;
        /// Tilt rate, positive towards drive.
        pub tilt_rate: f64 = 0.0, range -10.0..=10.0, unit "rad/s";
        /// (left, right), positive forward.
        pub wheel_rates: [f64; 2] = [0.0; 2], range -100.0..=100.0, unit "rad/s";
    }
    check |input, c, prefix| {
        if input.rotors.is_some() == input.trim_scale.is_some() {
            return Err(c.fail(
                &atmo_core::params::key(prefix, "rotors"),
                "exactly one of `rotors` and `trim_scale`",
                "both or neither",
            ));
        }
        Ok(())
    }
}

atmo_core::params! {
    /// The scenario file as written.
    #[derive(Debug, Clone, PartialEq)]
    pub struct ScenarioFile {
        /// The scenario's name (its output folder).
        pub name: String;
        /// One line on what it flies.
        pub description: String = String::new();
        /// Simulated time.
        pub duration: f64, range 1e-3..=3600.0, unit "s";
        /// Seed of the plant's noise and turbulence.
        pub seed: u64;
        /// Robot file, relative to the scenario file; absent: the shipped
        /// ATMO parameters.
        pub robot: Option<String> = None;
        /// Plant file, relative to the scenario file; absent: every effect on.
        pub plant: Option<String> = None;
        /// The ground plane.
        pub terrain: TerrainConfig = TerrainConfig::default();
        /// The initial state.
        pub initial: InitialConfig;
        /// Per-effect overrides of the plant file.
        pub effects: EffectsConfig = EffectsConfig::default();
        /// Pushes over time intervals.
        pub disturbances: Vec<DisturbanceConfig> = Vec::new();
        /// The scripted pilot.
        pub pilot: Vec<PilotSetpoint> = Vec::new();
        /// Setpoints.
        pub reference: Vec<ReferenceInput> = Vec::new();
        /// Actuator commands of an open-loop run.
        pub open_loop: Vec<OpenLoopInput> = Vec::new();
        /// What a closed-loop run of this scenario must achieve.
        pub success: SuccessConfig = SuccessConfig::default();
        /// Faults injected on the closed loop's input path ([`crate::faults`]).
        pub faults: FaultsConfig = FaultsConfig::default();
        /// The autopilot's own estimate (PX4's, from its IMU and barometer;
        /// the plant's `[effects.sensors] autopilot_vz_error_std`) reaches
        /// the flight stack beside the motion capture's, as the daemon's
        /// `ros2.topics.autopilot_estimate` when enabled; the estimate
        /// faults act on the motion capture's only.
        pub autopilot_estimate: bool = false;
    }
}

atmo_core::params! {
    /// `[success]`: the closed-loop pass criteria of a scenario.
    #[derive(Debug, Clone, Copy, serde::Serialize, PartialEq)]
    pub struct SuccessConfig: Default {
        /// true: a wheel landing (touchdown tilt, impact speed, drive on);
        /// false: a flight that must not touch the ground.
        pub landing: bool = true;
        /// Least tilt at the first wheel contact.
        pub min_touchdown_tilt_deg: f64 = 60.0, range 0.0..=90.0, unit "deg";
        /// Largest vertical speed at the first wheel contact.
        pub max_impact_speed: f64 = 0.5, range 0.0..=10.0, unit "m/s";
        /// Least distance driven after touchdown.
        pub min_drive_distance: f64 = 1.0, range 0.0..=1000.0, unit "m";
    }
}

/// A loaded, validated scenario with its robot and (merged) plant config.
#[derive(Debug, Clone)]
pub struct Scenario {
    pub file: ScenarioFile,
    pub path: PathBuf,
    pub robot: RobotConfig,
    /// The plant file with the scenario's effect overrides applied.
    pub plant: PlantConfig,
}

/// One recorded sample of an open-loop run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    pub time: f64,
    pub state: State,
    pub tilt: f64,
    pub thrust: Input,
    pub wheel_rates: WheelRates,
    pub grounded: bool,
}

/// The result of an open-loop run.
#[derive(Debug, Clone, PartialEq)]
pub struct Run {
    pub samples: Vec<Sample>,
    pub events: Vec<Event>,
    pub crash: Option<Event>,
    pub steps: u64,
}

/// Index of the entry in force at `t` in a list sorted by time.
fn active<T>(items: &[T], t: f64, time: impl Fn(&T) -> f64) -> Option<&T> {
    let n = items.partition_point(|item| time(item) <= t + 1e-12);
    n.checked_sub(1).map(|i| &items[i])
}

fn check_times<'a>(
    c: &Checker<'_>,
    key: &str,
    times: impl Iterator<Item = f64> + 'a,
    duration: f64,
) -> Result<()> {
    let mut last = f64::NEG_INFINITY;
    for (i, t) in times.enumerate() {
        let k = format!("{key}[{i}].t");
        c.within(&k, t, 0.0, duration)?;
        if t < last {
            return Err(c.fail(&k, format!("times in order (>= {last})"), t).into());
        }
        last = t;
    }
    Ok(())
}

impl ConfigFile for ScenarioFile {
    type Error = SimError;

    /// Range checks with tilts up to 90 deg; [`Scenario`] checks them again
    /// against the robot's `limits.tilt_max_deg` once it has the robot.
    fn validate(&self, file: &Path) -> Result<()> {
        self.validate_with_tilt_max(file, 90.0)
    }
}

impl ScenarioFile {
    /// Range checks, tilts up to `tilt_max_deg`; errors name `file` and the key.
    pub fn validate_with_tilt_max(&self, file: &Path, tilt_max_deg: f64) -> Result<()> {
        let c = Checker::new(file);
        if self.name.trim().is_empty() {
            return Err(c.fail("name", "a non-empty name", "\"\"").into());
        }
        self.check(&c, "")?;
        // What the declarations cannot say: the robot's tilt limit, times
        // within the scenario and in order, B above the terrain.
        let init = &self.initial;
        if !init.on_ground {
            let ground = terrain_z_at(&self.terrain, init.position[0], init.position[1]);
            if init.position[2] > ground {
                return Err(c
                    .fail(
                        "initial.position[2]",
                        format!(
                            "B above the terrain (NED z <= {ground} m at this x, y; z is down), \
                             or on_ground = true"
                        ),
                        init.position[2],
                    )
                    .into());
            }
        }
        c.within("initial.tilt_deg", init.tilt_deg, 0.0, tilt_max_deg)?;
        for (i, d) in self.disturbances.iter().enumerate() {
            c.within(&format!("disturbances[{i}].t"), d.t, 0.0, self.duration)?;
        }
        self.faults.validate(file, self.duration)?;
        check_times(&c, "pilot", self.pilot.iter().map(|p| p.t), self.duration)?;
        check_times(
            &c,
            "reference",
            self.reference.iter().map(|r| r.t),
            self.duration,
        )?;
        for (i, r) in self.reference.iter().enumerate() {
            if let Some(tilt) = r.tilt_deg {
                c.within(&format!("reference[{i}].tilt_deg"), tilt, 0.0, tilt_max_deg)?;
            }
        }
        check_times(
            &c,
            "open_loop",
            self.open_loop.iter().map(|o| o.t),
            self.duration,
        )?;
        if let Some(first) = self.open_loop.first().filter(|o| o.t != 0.0) {
            return Err(c
                .fail(
                    "open_loop[0].t",
                    "0 (the script must say what happens from the start)",
                    first.t,
                )
                .into());
        }
        Ok(())
    }
}

impl Scenario {
    /// Loads a scenario file with the robot and plant files it names.
    pub fn load(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        Self::from_toml_str(&read_config_file(path)?, path)
    }

    /// Parses and validates a scenario; `path` names it in errors and is the
    /// base of its relative `robot` and `plant` paths.
    pub fn from_toml_str(text: &str, path: impl Into<PathBuf>) -> Result<Self> {
        let path = path.into();
        let file = ScenarioFile::from_toml_str(text, &path)?;
        let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
        let robot = match &file.robot {
            Some(rel) => RobotConfig::load(dir.join(rel))?,
            None => RobotConfig::atmo(),
        };
        let base = match &file.plant {
            Some(rel) => PlantConfig::load(dir.join(rel))?,
            None => PlantConfig::full(),
        };
        file.validate_with_tilt_max(&path, robot.limits.tilt_max_deg)?;
        let plant = PlantConfig {
            effects: base.effects.overridden_by(&file.effects),
            source: path.clone(),
            ..base
        };
        plant.validate(&path)?;
        Ok(Self {
            file,
            path,
            robot,
            plant,
        })
    }

    /// The plant's initial condition.
    pub fn initial_state(&self) -> Result<InitialState> {
        let init = &self.file.initial;
        let tilt = init.tilt_deg.to_radians();
        let [yaw, pitch, roll] = init.euler_deg.map(f64::to_radians);
        let mut x = State::zeros();
        x[idx::YAW] = yaw;
        x[idx::PITCH] = pitch;
        x[idx::ROLL] = roll;
        for k in 0..3 {
            x[idx::X + k] = init.position[k];
            x[idx::VX + k] = init.velocity[k];
            x[idx::WX + k] = init.rates[k];
        }
        if init.on_ground {
            self.stand_on_ground(&mut x, tilt)?;
        }
        let thrust = match (init.thrust, self.file.open_loop.first()) {
            (Some(t), _) => Input::from(t),
            (None, Some(first)) => self.rotor_command(first, tilt),
            (None, None) => Input::zeros(),
        };
        Ok(InitialState {
            state: x,
            tilt,
            thrust: thrust.map(|u| u.clamp(0.0, 1.0)),
        })
    }

    /// Puts B where the robot stands on its wheels with the body aligned
    /// with the terrain, keeping x, y and yaw.
    fn stand_on_ground(&self, x: &mut State, tilt: f64) -> Result<()> {
        let terrain = &self.file.terrain;
        let plane = Plane::new(terrain);
        let slope = terrain.slope_deg.to_radians();
        // Body attitude on the slope: pitch and roll from the slope seen
        // along the heading (small-angle exact for pure pitch or roll).
        let rel = terrain.slope_azimuth_deg.to_radians() - x[idx::YAW];
        let pitch = (slope.tan() * rel.cos()).atan();
        let roll = -(slope.tan() * rel.sin() * pitch.cos()).atan();
        x[idx::PITCH] = pitch;
        x[idx::ROLL] = roll;
        let r = rotation(x[idx::YAW], pitch, roll);
        let body = Model::new(&self.robot).at_tilt(tilt);
        let down_b = -(r.transpose() * plane.normal);
        let drop = (0..4)
            .map(|i| {
                let p = rim_lowest_point(
                    &body.rotor_position[i],
                    &body.rotor_axis[i],
                    &down_b,
                    self.robot.wheels.radius,
                );
                p.dot(&down_b)
            })
            .fold(f64::NEG_INFINITY, f64::max);
        // The ground point below (x, y), then B `drop` above it along the normal.
        let n = &plane.normal;
        let (px, py) = (x[idx::X], x[idx::Y]);
        let z = plane.point.z - (n.x * (px - plane.point.x) + n.y * (py - plane.point.y)) / n.z;
        let b = Vector3::new(px, py, z) + n * (drop + 1e-4);
        if !b.iter().all(|v| v.is_finite()) {
            return Err(CoreError::ConfigValue {
                file: self.path.clone(),
                key: "initial.on_ground".into(),
                expected: "a terrain the robot can stand on".into(),
                got: format!("{b:?}"),
            }
            .into());
        }
        x[idx::X] = b.x;
        x[idx::Y] = b.y;
        x[idx::Z] = b.z;
        for k in 0..3 {
            x[idx::VX + k] = 0.0;
            x[idx::WX + k] = 0.0;
        }
        Ok(())
    }

    /// Builds the plant at the initial condition with the scenario's seed.
    pub fn build_plant(&self) -> Result<Plant> {
        Ok(Plant::new(
            &self.robot,
            &self.plant,
            &self.file.terrain,
            &self.initial_state()?,
            self.file.seed,
        )?)
    }

    /// The pilot input in force at `t`.
    pub fn pilot_at(&self, t: f64) -> Option<&PilotSetpoint> {
        active(&self.file.pilot, t, |p| p.t)
    }

    /// The reference in force at `t`.
    pub fn reference_at(&self, t: f64) -> Option<&ReferenceInput> {
        active(&self.file.reference, t, |r| r.t)
    }

    /// The disturbance (world force, body torque) at `t`.
    pub fn disturbance_at(&self, t: f64) -> (Vector3<f64>, Vector3<f64>) {
        let mut force = Vector3::zeros();
        let mut torque = Vector3::zeros();
        for d in &self.file.disturbances {
            if t >= d.t && t < d.t + d.duration {
                force += Vector3::from(d.force);
                torque += Vector3::from(d.torque);
            }
        }
        (force, torque)
    }

    fn rotor_command(&self, o: &OpenLoopInput, tilt: f64) -> Input {
        match (o.rotors, o.trim_scale) {
            (Some(u), _) => Input::from(u),
            (None, Some(scale)) => {
                let trim = Model::new(&self.robot).at_tilt(tilt).hover_trim();
                (trim * scale).map(|u| u.clamp(0.0, 1.0))
            }
            (None, None) => Input::zeros(),
        }
    }

    /// The open-loop actuator command at `t` for a robot at `tilt`.
    pub fn open_loop_command(&self, t: f64, model: &Model, tilt: f64) -> Command {
        let Some(o) = active(&self.file.open_loop, t, |o| o.t) else {
            return Command::idle();
        };
        let rotors = match (o.rotors, o.trim_scale) {
            (Some(u), _) => Input::from(u),
            (None, Some(scale)) => {
                (model.at_tilt(tilt).hover_trim() * scale).map(|u| u.clamp(0.0, 1.0))
            }
            (None, None) => Input::zeros(),
        };
        Command {
            rotors,
            tilt_rate: o.tilt_rate,
            wheel_rates: WheelRates {
                left: o.wheel_rates[0],
                right: o.wheel_rates[1],
            },
        }
    }

    /// Runs the scenario open-loop (the `[[open_loop]]` script and the
    /// disturbances) for its duration, recording a sample every
    /// `record_period` s.
    pub fn run_open_loop(&self, record_period: f64) -> Result<Run> {
        self.run_plant_open_loop(self.build_plant()?, record_period)
    }

    /// `run_open_loop` on a plant built by `build_plant` and then adjusted
    /// (for example to run its portable step code).
    pub fn run_plant_open_loop(&self, mut plant: Plant, record_period: f64) -> Result<Run> {
        // The nominal model: what a pilot's trim would be computed from.
        let model = Model::new(&self.robot);
        let steps = (self.file.duration / plant.dt()).round() as u64;
        let every = ((record_period / plant.dt()).round() as u64).max(1);
        let mut samples = Vec::with_capacity((steps / every + 2) as usize);
        let sample = |plant: &Plant| Sample {
            time: plant.time(),
            state: plant.state(),
            tilt: plant.tilt(),
            thrust: plant.thrust(),
            wheel_rates: plant.wheel_rates(),
            grounded: plant.contact_signal(),
        };
        samples.push(sample(&plant));
        for k in 0..steps {
            let t = plant.time();
            let (force, torque) = self.disturbance_at(t);
            plant.set_external_wrench(force, torque)?;
            let cmd = self.open_loop_command(t, &model, plant.tilt());
            plant.step(&cmd)?;
            if (k + 1) % every == 0 {
                samples.push(sample(&plant));
            }
        }
        Ok(Run {
            samples,
            events: plant.events().to_vec(),
            crash: plant.crash().copied(),
            steps,
        })
    }
}
