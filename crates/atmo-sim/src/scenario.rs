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
//!   drivers, solver overruns: [`crate::faults`], docs/faults.md).
//!
//! Loading is strict like every config of the project: unknown keys are
//! errors naming the file, line and key; values are range-checked and
//! errors name the key.

use std::path::{Path, PathBuf};

use atmo_core::config_file::{Checker, read_config_file};
use atmo_core::control::WheelRates;
use atmo_core::model::{Input, Model, State, idx, rotation};
use atmo_core::{ConfigFile, CoreError, RobotConfig};
use nalgebra::Vector3;
use serde::Deserialize;

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

/// `[initial]`.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct InitialConfig {
    /// m, NED position of B (z = -height). With `on_ground`, only x and y count.
    pub position: [f64; 3],
    /// deg, (yaw, pitch, roll). With `on_ground`, only yaw counts.
    #[serde(default)]
    pub euler_deg: [f64; 3],
    /// m/s, world (NED) velocity of B.
    #[serde(default)]
    pub velocity: [f64; 3],
    /// rad/s, body rates.
    #[serde(default)]
    pub rates: [f64; 3],
    /// deg.
    #[serde(default)]
    pub tilt_deg: f64,
    /// Normalized rotor thrust at t = 0 (matters with motor lag); default:
    /// the first open-loop rotor command.
    pub thrust: Option<[f64; 4]>,
    /// Stand the robot on its wheels on the terrain, aligned with the slope.
    #[serde(default)]
    pub on_ground: bool,
}

/// `[[disturbances]]`: a push held from `t` to `t + duration`.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct DisturbanceConfig {
    pub t: f64,
    pub duration: f64,
    /// N, world frame, at B.
    #[serde(default)]
    pub force: [f64; 3],
    /// N m, body frame.
    #[serde(default)]
    pub torque: [f64; 3],
}

/// `[[pilot]]`: the sticks and switches the scripted pilot holds from `t` on.
#[derive(Debug, Clone, Default, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct PilotSetpoint {
    pub t: f64,
    #[serde(default)]
    pub arm: bool,
    #[serde(default)]
    pub offboard: bool,
    #[serde(default)]
    pub mpc: bool,
    /// 0..1 (0.5 = hold altitude; on the ground >= 0.5 starts a take-off).
    #[serde(default)]
    pub throttle: f64,
    /// m/s, (forward, right, down) in the heading frame; norm <= 1.
    #[serde(default)]
    pub velocity: [f64; 3],
    /// rad/s, FRD (positive turns right).
    #[serde(default)]
    pub yaw_rate: f64,
}

/// `[[reference]]`: setpoints from `t` on.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ReferenceInput {
    pub t: f64,
    /// m, NED.
    pub position: [f64; 3],
    #[serde(default)]
    pub yaw_deg: f64,
    /// deg; None = the flight stack's tilt law decides.
    pub tilt_deg: Option<f64>,
}

/// `[[open_loop]]`: actuator commands from `t` on. Exactly one of `rotors`
/// and `trim_scale`.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct OpenLoopInput {
    pub t: f64,
    /// Normalized rotor commands.
    pub rotors: Option<[f64; 4]>,
    /// Rotors = this times the nominal model's level hover trim at the
    /// current tilt (each held to [0, 1]).
    pub trim_scale: Option<f64>,
    /// rad/s, positive towards drive.
    #[serde(default)]
    pub tilt_rate: f64,
    /// rad/s, (left, right), positive forward.
    #[serde(default)]
    pub wheel_rates: [f64; 2],
}

/// The scenario file as written.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ScenarioFile {
    pub name: String,
    #[serde(default)]
    pub description: String,
    /// s.
    pub duration: f64,
    pub seed: u64,
    /// Robot file, relative to the scenario file.
    pub robot: Option<String>,
    /// Plant file, relative to the scenario file.
    pub plant: Option<String>,
    #[serde(default)]
    pub terrain: TerrainConfig,
    pub initial: InitialConfig,
    #[serde(default)]
    pub effects: EffectsConfig,
    #[serde(default)]
    pub disturbances: Vec<DisturbanceConfig>,
    #[serde(default)]
    pub pilot: Vec<PilotSetpoint>,
    #[serde(default)]
    pub reference: Vec<ReferenceInput>,
    #[serde(default)]
    pub open_loop: Vec<OpenLoopInput>,
    /// What a closed-loop run of this scenario must achieve.
    #[serde(default)]
    pub success: SuccessConfig,
    /// Faults injected on the closed loop's input path ([`crate::faults`]).
    #[serde(default)]
    pub faults: FaultsConfig,
}

/// `[success]`: the closed-loop pass criteria of a scenario.
#[derive(Debug, Clone, Copy, Deserialize, serde::Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct SuccessConfig {
    /// true: a wheel landing (touchdown tilt, impact speed, drive on);
    /// false: a flight that must not touch the ground.
    #[serde(default = "atmo_core::config_file::default_true")]
    pub landing: bool,
    #[serde(default = "SuccessConfig::default_tilt")]
    pub min_touchdown_tilt_deg: f64,
    /// m/s, vertical speed at first wheel contact.
    #[serde(default = "SuccessConfig::default_impact")]
    pub max_impact_speed: f64,
    /// m driven after touchdown.
    #[serde(default = "SuccessConfig::default_drive")]
    pub min_drive_distance: f64,
}

impl SuccessConfig {
    fn default_tilt() -> f64 {
        60.0
    }
    fn default_impact() -> f64 {
        0.5
    }
    fn default_drive() -> f64 {
        1.0
    }
}

impl Default for SuccessConfig {
    fn default() -> Self {
        Self {
            landing: true,
            min_touchdown_tilt_deg: Self::default_tilt(),
            max_impact_speed: Self::default_impact(),
            min_drive_distance: Self::default_drive(),
        }
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
    /// The initial state's position (bounded, above the terrain unless
    /// standing on it), velocity and rates; errors name the key.
    fn validate_initial_state(&self, c: &Checker<'_>) -> Result<()> {
        let init = &self.initial;
        for (k, v) in init.position.iter().enumerate() {
            c.range(&format!("initial.position[{k}]"), *v, -1e4..=1e4, "m")?;
        }
        for (k, v) in init.velocity.iter().enumerate() {
            c.range(
                &format!("initial.velocity[{k}]"),
                *v,
                -MAX_INITIAL_SPEED..=MAX_INITIAL_SPEED,
                "m/s",
            )?;
        }
        for (k, v) in init.rates.iter().enumerate() {
            c.range(
                &format!("initial.rates[{k}]"),
                *v,
                -MAX_INITIAL_RATE..=MAX_INITIAL_RATE,
                "rad/s",
            )?;
        }
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
        Ok(())
    }

    /// Range checks, tilts up to `tilt_max_deg`; errors name `file` and the key.
    pub fn validate_with_tilt_max(&self, file: &Path, tilt_max_deg: f64) -> Result<()> {
        let c = Checker::new(file);
        if self.name.trim().is_empty() {
            return Err(c.fail("name", "a non-empty name", "\"\"").into());
        }
        c.within("duration", self.duration, 1e-3, 3600.0)?;
        self.terrain.validate(&c, "terrain")?;
        self.effects.validate(&c, "effects")?;

        self.validate_initial_state(&c)?;
        let init = &self.initial;
        c.finite("initial.euler_deg", &init.euler_deg)?;
        c.within("initial.euler_deg[1]", init.euler_deg[1], -89.0, 89.0)?;
        c.within("initial.tilt_deg", init.tilt_deg, 0.0, tilt_max_deg)?;
        if let Some(thrust) = init.thrust {
            for u in thrust {
                c.within("initial.thrust", u, 0.0, 1.0)?;
            }
        }

        for (i, d) in self.disturbances.iter().enumerate() {
            let k = format!("disturbances[{i}]");
            c.within(&format!("{k}.t"), d.t, 0.0, self.duration)?;
            c.positive(&format!("{k}.duration"), d.duration)?;
            for v in d.force {
                c.within(&format!("{k}.force"), v, -1000.0, 1000.0)?;
            }
            for v in d.torque {
                c.within(&format!("{k}.torque"), v, -100.0, 100.0)?;
            }
        }

        c.within(
            "success.min_touchdown_tilt_deg",
            self.success.min_touchdown_tilt_deg,
            0.0,
            90.0,
        )?;
        c.within(
            "success.max_impact_speed",
            self.success.max_impact_speed,
            0.0,
            10.0,
        )?;
        c.within(
            "success.min_drive_distance",
            self.success.min_drive_distance,
            0.0,
            1000.0,
        )?;
        self.faults.validate(file, self.duration)?;
        check_times(&c, "pilot", self.pilot.iter().map(|p| p.t), self.duration)?;
        for (i, p) in self.pilot.iter().enumerate() {
            let k = format!("pilot[{i}]");
            c.within(&format!("{k}.throttle"), p.throttle, 0.0, 1.0)?;
            c.finite(&format!("{k}.velocity"), &p.velocity)?;
            let speed = Vector3::from(p.velocity).norm();
            if speed > MAX_PILOT_SPEED + 1e-12 {
                return Err(c
                    .fail(
                        &format!("{k}.velocity"),
                        format!("a velocity command of at most {MAX_PILOT_SPEED} m/s"),
                        speed,
                    )
                    .into());
            }
            c.within(&format!("{k}.yaw_rate"), p.yaw_rate, -3.0, 3.0)?;
        }

        check_times(
            &c,
            "reference",
            self.reference.iter().map(|r| r.t),
            self.duration,
        )?;
        for (i, r) in self.reference.iter().enumerate() {
            let k = format!("reference[{i}]");
            c.finite(&format!("{k}.position"), &r.position)?;
            c.within(&format!("{k}.yaw_deg"), r.yaw_deg, -360.0, 360.0)?;
            if let Some(tilt) = r.tilt_deg {
                c.within(&format!("{k}.tilt_deg"), tilt, 0.0, tilt_max_deg)?;
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
        for (i, o) in self.open_loop.iter().enumerate() {
            let k = format!("open_loop[{i}]");
            match (&o.rotors, o.trim_scale) {
                (Some(rotors), None) => {
                    for u in rotors {
                        c.within(&format!("{k}.rotors"), *u, 0.0, 1.0)?;
                    }
                }
                (None, Some(scale)) => c.within(&format!("{k}.trim_scale"), scale, 0.0, 2.0)?,
                _ => {
                    return Err(c
                        .fail(
                            &format!("{k}.rotors"),
                            "exactly one of `rotors` and `trim_scale`",
                            "both or neither",
                        )
                        .into());
                }
            }
            c.within(&format!("{k}.tilt_rate"), o.tilt_rate, -10.0, 10.0)?;
            for v in o.wheel_rates {
                c.within(&format!("{k}.wheel_rates"), v, -100.0, 100.0)?;
            }
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
