//! The plant: atmo-core's 7-body dynamics plus the effects of the plant
//! config, integrated by classical RK4 at a fixed step.
//!
//! Continuous state (all integrated together by RK4): the 12 rigid-body
//! states, the normalized thrust of each rotor (motor lag), the spin rate and
//! speed-error integral of each side's wheel drive, the battery energy used,
//! and the tangential contact spring of each contact point. The tilt varphi
//! and the random processes (turbulence, ground-effect fluctuation) change
//! once per step: varphi moves by the rate-limited command times dt, the
//! composite body is taken at the mid-step tilt (atmo-core's exact body while
//! the tilt stands; while it moves, linear interpolation between exact bodies
//! on a 0.25 deg grid, within 1e-5 relative), and the noise is held over the
//! step. The rigid-body right-hand side is atmo-core's, evaluated with one set
//! of attitude sines and cosines (module `body`; bit-identical, tested).
//!
//! Rotor i produces the thrust `kT u_eff_i` along its axis, with
//! `u_eff_i = t_i s_batt (1 + g_i)`: `t_i` the lagged normalized thrust
//! (or the command when motor lag is off), `s_batt` the battery scale, and
//! `g_i` the ground-effect gain. Drag and contact wrenches enter
//! `TiltedBody::accelerations` as the extra body wrench.
//!
//! Wheels: each side's two wheels are belt-coupled (one spin rate per side,
//! positive = forward). A PI speed controller with a torque limit drives
//! each side: `J w_dot = tau_m + sum_wheels e . (r x F)`, with `e` the
//! forward spin axis, `r` the contact point from the wheel centre and `F` the
//! contact force. The body receives the contact wrench less its spin-axis
//! part (that part turns the wheel) and the motor reaction `-tau_m e`.

mod effects;
mod step;

use std::sync::Arc;

use atmo_core::config_file::{Checker, ConfigFile};
use atmo_core::control::WheelRates;
use atmo_core::model::{Input, Model, State, TiltedBody};
use atmo_core::{Linkage, RobotConfig};
use nalgebra::{SVector, Vector3};
use rand_chacha::ChaCha8Rng;

use crate::body::effective_body;
use crate::config::{
    BatterySagConfig, DragConfig, GroundContactConfig, PlantConfig, SensorsConfig, TerrainConfig,
};
use crate::contact::{ContactLaw, Plane, WheelLanes};
use crate::error::{PlantError, Result};
use crate::noise::{GaussMarkov, rng, stream};
use crate::sensors::{Estimate, Mocap};
use atmo_core::ground_effect::table::{GroundEffect, TiltSlice};
use effects::{Drive, Wind};

/// Contact points: the four wheels (rotor order), then the 8 base-box corners.
pub const N_CONTACTS: usize = 12;
pub(crate) const N_WHEELS: usize = 4;

const THRUST: usize = 12;
const WHEEL: usize = 16;
const WHEEL_INT: usize = 18;
const ENERGY: usize = 20;
const SPRING: usize = 21;
/// Length of the plant's continuous state.
pub const N_EXT: usize = SPRING + 3 * N_CONTACTS;
type Ext = SVector<f64, N_EXT>;

/// What the daemon sends: 4 rotor commands, the tilt velocity and the two
/// wheel rates.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Command {
    /// Normalized rotor commands, held to [0, 1].
    pub rotors: Input,
    /// rad/s, positive towards drive (larger varphi).
    pub tilt_rate: f64,
    /// rad/s, positive forward.
    pub wheel_rates: WheelRates,
}

impl Command {
    /// Rotors off, tilt held, wheels stopped.
    pub fn idle() -> Self {
        Self::rotors(Input::zeros())
    }

    /// These rotor commands, tilt held, wheels stopped.
    pub fn rotors(rotors: Input) -> Self {
        Self {
            rotors,
            tilt_rate: 0.0,
            wheel_rates: WheelRates {
                left: 0.0,
                right: 0.0,
            },
        }
    }
}

/// The plant's initial condition.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct InitialState {
    /// Rigid-body state (atmo-core order).
    pub state: State,
    /// rad.
    pub tilt: f64,
    /// Normalized thrust of each rotor at t = 0 (matters with motor lag).
    pub thrust: Input,
}

impl InitialState {
    /// At rest at `state`, tilt `tilt`, rotors off.
    pub fn at(state: State, tilt: f64) -> Self {
        Self {
            state,
            tilt,
            thrust: Input::zeros(),
        }
    }
}

/// Why a crash was reported.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum CrashKind {
    /// A base-box corner (0..8) touched the ground.
    BodyContact { corner: usize },
    /// A wheel (rotor index 0..4) hit the ground faster than `crash_speed` (m/s).
    HardImpact { wheel: usize, speed: f64 },
    /// The body z axis left the ground normal by more than `tip_over_deg` while touching.
    TipOver { angle_deg: f64 },
}

/// Something that happened at the ground.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum EventKind {
    /// The wheels started carrying load (contact signal rose).
    Touchdown,
    /// The wheels stopped carrying load (contact signal fell).
    Liftoff,
    Crash(CrashKind),
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Event {
    pub time: f64,
    pub kind: EventKind,
}

/// Spacing of the exact bodies the moving tilt is interpolated between (rad).
const TILT_GRID: f64 = 0.25 * std::f64::consts::PI / 180.0;

/// Most events kept; later ones are counted in `events_dropped`.
const EVENT_CAPACITY: usize = 256;

/// Per-contact result of the last post-step evaluation.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ContactInfo {
    /// N (0 when open).
    pub normal_force: f64,
    /// m/s, speed towards the ground (0 for a base-box corner while the
    /// corners are out of the ground's reach).
    pub approach_speed: f64,
    pub touching: bool,
}

/// The truth plant.
// The flags are independent facts of the plant's state (encoder mode,
// contact signal, tip-over latch, interpolated body), not a mode in disguise.
#[allow(clippy::struct_excessive_bools)]
#[derive(Debug, Clone)]
pub struct Plant {
    model: Model,
    linkage: Linkage,
    dt: f64,
    tilt_max: f64,
    tilt_rate_max: f64,
    quantize_encoder: bool,
    wheel_rate_max: f64,
    wheel_radius: f64,
    plane: Plane,
    // Effects (None = off).
    ground_effect: Option<GroundEffect>,
    motor_lag: Option<(f64, f64)>,
    /// The thrust curve's f without a motor lag (with one it is in `motor_lag`).
    thrust_curve: Option<f64>,
    drag: Option<DragConfig>,
    wind: Option<Wind>,
    battery: Option<BatterySagConfig>,
    com_offset: Option<Vector3<f64>>,
    /// Rotation vector (body x, y) of the thrust against the body frame.
    thrust_axis: Option<Vector3<f64>>,
    mass_error: Option<(f64, f64)>,
    contact: Option<(ContactLaw, Drive, GroundContactConfig)>,
    corners: [Vector3<f64>; 8],
    /// m, farther from B than any contact point can be (at any tilt).
    reach: f64,
    /// m, farther from B than any base-box corner.
    corner_reach: f64,
    /// Cosine of the tip-over angle (the body z axis against the normal).
    tip_over_cos: f64,
    // Noise held over a step.
    ge_noise: [GaussMarkov; 4],
    ge_rng: ChaCha8Rng,
    wind_now: Vector3<f64>,
    /// External push: force (world frame, N) at B and torque (body frame, N m).
    external: (Vector3<f64>, Vector3<f64>),
    // State.
    steps: u64,
    ext: Ext,
    tilt: f64,
    body: TiltedBody,
    /// `body`'s wheels laid out for the four-lane loops, made on the first
    /// step near the ground after the body changes (None: not made yet).
    wheel_lanes: Option<WheelLanes>,
    /// Whether `body` is interpolated (the tilt was moving).
    body_interpolated: bool,
    /// Exact bodies every `TILT_GRID` from 0 to `tilt_max` (the last one at
    /// `tilt_max`), shared by clones.
    tilt_grid: Arc<[TiltedBody]>,
    ge_slice: TiltSlice,
    command: Command,
    mocap: Mocap,
    contacts: [ContactInfo; N_CONTACTS],
    grounded: bool,
    tipped: bool,
    crash: Option<Event>,
    events: Vec<Event>,
    events_dropped: usize,
    /// Steps run the copy of the step code compiled for AVX2 and FMA (the
    /// CPU has them); results are bit-identical to the portable copy.
    avx2: bool,
}

/// Whether this CPU runs the step's AVX2 copy: x86-64 with AVX2 and FMA.
fn cpu_has_avx2() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// A robot and a plant config checked once, with what a plant takes from
/// them alone: the model, the linkage, the exact bodies of the tilt grid
/// and the contact points' reaches. [`PlantTemplate::start`] builds a
/// [`Plant`] from it for a terrain, an initial condition and a seed, the
/// same plant [`Plant::new`] builds, without redoing that work (the
/// discrepancy finder starts one plant per 0.5 s stretch it replays).
#[derive(Debug, Clone)]
pub struct PlantTemplate {
    robot: RobotConfig,
    config: PlantConfig,
    model: Model,
    linkage: Linkage,
    tilt_max: f64,
    tilt_grid: Arc<[TiltedBody]>,
    corners: [Vector3<f64>; 8],
    reach: f64,
    corner_reach: f64,
}

impl PlantTemplate {
    /// Checks the plant config against the robot and builds what every
    /// plant of the pair shares.
    pub fn new(robot: &RobotConfig, config: &PlantConfig) -> Result<Self> {
        config.validate(&config.source)?;
        let checker = Checker::new(&config.source);
        let fx = &config.effects;
        let mut truth = robot.clone();
        truth.arm.inertia_convention = config.arm_inertia_convention;
        let model = Model::new(&truth);
        let tilt_max = robot.limits.tilt_max();
        let linkage = Linkage::from_config(&robot.linkage, tilt_max)?;
        let com_offset = fx.com_offset_vector();
        let mass_error = fx.mass_error_scales();
        let tilt_grid = tilt_grid(&model, tilt_max, mass_error, com_offset, &checker)?;
        let (lo, hi) = fx
            .ground_contact
            .as_ref()
            .filter(|e| e.enabled)
            .map_or_else(
                || {
                    let d = GroundContactConfig::default();
                    (d.base_box_min, d.base_box_max)
                },
                |c| (c.base_box_min, c.base_box_max),
            );
        let corners = box_corners(lo, hi);
        let (reach, corner_reach) = reaches(&model, robot, tilt_max, &corners);
        Ok(Self {
            robot: robot.clone(),
            config: config.clone(),
            model,
            linkage,
            tilt_max,
            tilt_grid: tilt_grid.into(),
            corners,
            reach,
            corner_reach,
        })
    }

    /// The plant of this robot and config on `terrain` from `initial`;
    /// `seed` drives every random process.
    pub fn start(
        &self,
        terrain: &TerrainConfig,
        initial: &InitialState,
        seed: u64,
    ) -> Result<Plant> {
        let (robot, config) = (&self.robot, &self.config);
        let checker = Checker::new(&config.source);
        terrain.validate(&checker, "terrain")?;
        let fx = &config.effects;
        let model = self.model.clone();
        let tilt_max = self.tilt_max;
        let linkage = self.linkage;
        let dt = config.dt;

        let tilt_mech = fx.tilt_mechanism.as_ref().filter(|e| e.enabled);
        let tilt_rate_max = tilt_mech.map_or(f64::INFINITY, |e| {
            e.rate_max.unwrap_or(robot.limits.tilt_rate_max)
        });
        let ground_effect = fx
            .ground_effect
            .as_ref()
            .filter(|e| e.enabled)
            .map(GroundEffect::new);
        let curve = fx
            .thrust_curve
            .as_ref()
            .filter(|e| e.enabled)
            .map(|e| e.curve);
        let motor_lag = fx
            .motor_lag
            .as_ref()
            .filter(|e| e.enabled)
            .map(|e| (e.time_constant, curve.unwrap_or(e.curve)));
        let thrust_curve = curve.filter(|_| motor_lag.is_none());
        let drag = fx.drag.clone().filter(|e| e.enabled);
        let battery = fx.battery_sag.clone().filter(|e| e.enabled);
        let com_offset = fx.com_offset_vector();
        let mass_error = fx.mass_error_scales();
        let sensors: Option<SensorsConfig> = fx.sensors.clone().filter(|e| e.enabled);
        let contact_cfg = fx.ground_contact.clone().filter(|e| e.enabled);

        let c = &initial.state;
        checker.finite("initial.state", c.as_slice())?;
        checker.within("initial.tilt", initial.tilt, 0.0, tilt_max)?;
        for u in &initial.thrust {
            checker.within("initial.thrust", *u, 0.0, 1.0)?;
        }

        let mut ge_rng = rng(seed, stream::GROUND_EFFECT);
        let tau_ge = ground_effect.as_ref().map_or(1.0, |g| g.correlation_time);
        let ge_noise = std::array::from_fn(|_| GaussMarkov::new(tau_ge, dt, &mut ge_rng));
        let wind = fx.wind.clone().filter(|e| e.enabled).map(|config| {
            let mut rng = rng(seed, stream::WIND);
            let turbulence =
                std::array::from_fn(|_| GaussMarkov::new(config.turbulence_time, dt, &mut rng));
            Wind {
                config,
                turbulence,
                rng,
            }
        });
        let contact = contact_cfg.map(|c| {
            (
                ContactLaw::new(&c),
                Drive {
                    inertia: c.wheel_inertia,
                    kp: c.wheel_kp,
                    ki: c.wheel_ki,
                    torque_max: c.wheel_torque_max,
                },
                c,
            )
        });
        let (corners, reach, corner_reach) = (self.corners, self.reach, self.corner_reach);
        let tip_over_cos = contact
            .as_ref()
            .map_or(-1.0, |(_, _, c)| c.tip_over_deg.to_radians().cos());

        let mut ext = Ext::zeros();
        ext.fixed_rows_mut::<12>(0).copy_from(&initial.state);
        ext.fixed_rows_mut::<4>(THRUST).copy_from(&initial.thrust);
        let tilt = initial.tilt;
        let body = effective_body(&model, tilt, mass_error, com_offset)
            .expect("checked at every tilt above");
        let ge_slice = ground_effect.as_ref().map_or_else(
            || GroundEffect::default_surface().slice(tilt),
            |g| g.slice(tilt),
        );
        let mut plant = Plant {
            linkage,
            dt,
            tilt_max,
            tilt_rate_max,
            quantize_encoder: tilt_mech.is_some(),
            wheel_rate_max: robot.wheels.max_rate,
            wheel_radius: robot.wheels.radius,
            plane: Plane::new(terrain),
            ground_effect,
            motor_lag,
            thrust_curve,
            drag,
            wind,
            battery,
            com_offset,
            thrust_axis: fx.thrust_axis_rotation().map(Vector3::from),
            mass_error,
            contact,
            corners,
            reach,
            corner_reach,
            tip_over_cos,
            ge_noise,
            ge_rng,
            wind_now: Vector3::zeros(),
            external: (Vector3::zeros(), Vector3::zeros()),
            steps: 0,
            ext,
            tilt,
            ge_slice,
            body,
            wheel_lanes: None,
            body_interpolated: false,
            tilt_grid: Arc::clone(&self.tilt_grid),
            command: Command::rotors(initial.thrust),
            mocap: Mocap::new(sensors, dt, seed),
            contacts: [ContactInfo::default(); N_CONTACTS],
            grounded: false,
            tipped: false,
            crash: None,
            events: Vec::with_capacity(EVENT_CAPACITY),
            events_dropped: 0,
            avx2: cpu_has_avx2(),
            model,
        };
        if let Some(w) = &plant.wind {
            plant.wind_now = w.at(0.0);
        }
        plant.observe();
        plant.grounded = plant.contact_signal();
        Ok(plant)
    }
}

impl Plant {
    /// Builds the plant for a robot, a validated plant config, the terrain
    /// and the initial condition; `seed` drives every random process.
    pub fn new(
        robot: &RobotConfig,
        config: &PlantConfig,
        terrain: &TerrainConfig,
        initial: &InitialState,
        seed: u64,
    ) -> Result<Self> {
        PlantTemplate::new(robot, config)?.start(terrain, initial, seed)
    }

    /// Whether steps run the copy of the step code compiled for AVX2 and FMA
    /// (chosen at construction from what the CPU reports).
    pub fn uses_avx2(&self) -> bool {
        self.avx2
    }

    /// Runs the portable (baseline x86-64 or other target) copy of the step
    /// code from now on, for tests and A/B timing. Results are bit-identical
    /// to the AVX2 copy: Rust never fuses a multiply and an add on its own,
    /// and vectorizing does not reorder floating-point sums.
    pub fn use_portable_code(&mut self) {
        self.avx2 = false;
    }

    /// s, fixed step.
    pub fn dt(&self) -> f64 {
        self.dt
    }

    /// Steps taken.
    pub fn steps(&self) -> u64 {
        self.steps
    }

    /// The mechanical end stop, rad.
    pub fn tilt_max(&self) -> f64 {
        self.tilt_max
    }

    /// rad, the true tilt.
    pub fn tilt(&self) -> f64 {
        self.tilt
    }

    /// Moves the linkage to `tilt` (clamped to its range) without a step:
    /// the tilt mechanism driven while the rest of the plant is held (SITL
    /// before the flight, a props-off tilt sweep). The body's inertia and
    /// geometry follow; time, state and contacts do not change.
    pub fn place_tilt(&mut self, tilt: f64) {
        if !tilt.is_finite() {
            return;
        }
        let tilt = tilt.clamp(0.0, self.tilt_max);
        self.update_body(tilt, false);
        self.tilt = tilt;
    }

    /// The tilt encoder: counts via the linkage, whole counts when the tilt
    /// mechanism effect is on.
    pub fn encoder_counts(&self) -> Result<f64> {
        self.encoder_counts_at(self.tilt)
    }

    /// What the encoder reads at `tilt` (rad): a motor that slips turns
    /// its encoder while the arms stay.
    pub fn encoder_counts_at(&self, tilt: f64) -> Result<f64> {
        let counts = self.linkage.counts_from_tilt(tilt)?;
        Ok(if self.quantize_encoder {
            counts.round()
        } else {
            counts
        })
    }

    /// Each rotor's speed, a fraction of its speed at full: what its ESC
    /// would report (thrust goes with the speed squared).
    pub fn rotor_speeds(&self) -> [f64; 4] {
        let t = self.thrust().map(|t| t.max(0.0).sqrt());
        [t[0], t[1], t[2], t[3]]
    }

    /// Normalized thrust of each rotor (after the motor lag and curve).
    pub fn thrust(&self) -> Input {
        if self.motor_lag.is_some() {
            self.ext.fixed_rows::<4>(THRUST).into_owned()
        } else if let Some(f) = self.thrust_curve {
            self.command
                .rotors
                .map(|u| crate::motor::ThrustCurveConfig::thrust(f, u))
        } else {
            self.command.rotors
        }
    }

    /// rad/s, wheel spin rate per side (positive forward).
    pub fn wheel_rates(&self) -> WheelRates {
        if self.contact.is_some() {
            WheelRates {
                left: self.ext[WHEEL],
                right: self.ext[WHEEL + 1],
            }
        } else {
            self.command.wheel_rates
        }
    }

    /// J, battery energy used since the start.
    pub fn energy_used(&self) -> f64 {
        self.ext[ENERGY]
    }

    /// Wind at the current step (NED, m/s).
    pub fn wind(&self) -> Vector3<f64> {
        self.wind_now
    }

    /// Sets the external disturbance held from now on: a force at B (world
    /// frame, N) and a torque (body frame, N m). Non-finite values are refused.
    pub fn set_external_wrench(
        &mut self,
        force_world: Vector3<f64>,
        torque_body: Vector3<f64>,
    ) -> Result<()> {
        for (name, v) in [
            ("external force", force_world),
            ("external torque", torque_body),
        ] {
            if let Some(bad) = v.iter().find(|x| !x.is_finite()) {
                return Err(PlantError::NonFiniteCommand { name, value: *bad });
            }
        }
        self.external = (force_world, torque_body);
        Ok(())
    }

    /// The composite body in use (with mass-property errors).
    pub fn body(&self) -> &TiltedBody {
        &self.body
    }

    /// The nominal model (what the controller knows).
    pub fn model(&self) -> &Model {
        &self.model
    }

    /// The terrain plane.
    pub fn plane(&self) -> &Plane {
        &self.plane
    }

    /// The latest published state estimate.
    pub fn estimate(&self) -> Option<&Estimate> {
        self.mocap.latest.as_ref()
    }

    /// The autopilot's own estimate of the same instant (same time and
    /// sequence as [`Plant::estimate`]; `[effects.sensors]
    /// autopilot_vz_error_std`).
    pub fn autopilot_estimate(&self) -> Option<&Estimate> {
        self.mocap.autopilot.as_ref()
    }

    /// Contact state after the last step (wheels in rotor order, then corners).
    pub fn contacts(&self) -> &[ContactInfo; N_CONTACTS] {
        &self.contacts
    }

    /// The first crash, if any.
    pub fn crash(&self) -> Option<&Event> {
        self.crash.as_ref()
    }

    /// Events so far (at most 256 kept).
    pub fn events(&self) -> &[Event] {
        &self.events
    }

    /// Events not kept because the list was full.
    pub fn events_dropped(&self) -> usize {
        self.events_dropped
    }

    /// Advances one step of `dt` under `command` (rotors held to [0, 1],
    /// tilt rate and wheel rates to their limits; non-finite commands are
    /// refused and leave the plant unchanged).
    ///
    /// The step code is compiled twice, portable and for AVX2 with FMA (the
    /// whole step inlined into each copy); the CPU picks at construction.
    pub fn step(&mut self, command: &Command) -> Result<()> {
        #[cfg(target_arch = "x86_64")]
        if self.avx2 {
            // SAFETY: `avx2` is set only when the CPU reports AVX2 and FMA.
            #[allow(unsafe_code)]
            return unsafe { self.step_avx2(command) };
        }
        self.step_kernel(command)
    }

    /// `step_kernel` compiled for AVX2 and FMA: 10-15 % faster in flight and
    /// while morphing (BENCHMARKS.md).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    fn step_avx2(&mut self, command: &Command) -> Result<()> {
        self.step_kernel(command)
    }

    /// Steps until `duration` more seconds have passed (rounded to whole steps).
    pub fn advance(&mut self, command: &Command, duration: f64) -> Result<()> {
        let n = (duration / self.dt).round().max(0.0) as u64;
        for _ in 0..n {
            self.step(command)?;
        }
        Ok(())
    }
}

/// Every exact body the moving tilt is interpolated between: one every
/// `TILT_GRID` from 0 to `tilt_max` (the last one at `tilt_max`), built once.
/// This also checks that the perturbed mass properties stay physical at
/// every tilt.
fn tilt_grid(
    model: &Model,
    tilt_max: f64,
    mass_error: Option<(f64, f64)>,
    com_offset: Option<Vector3<f64>>,
    checker: &Checker,
) -> Result<Vec<TiltedBody>> {
    let cells = (tilt_max / TILT_GRID).ceil().max(1.0) as usize;
    let mut tilt_grid = Vec::with_capacity(cells + 1);
    for k in 0..=cells {
        let tilt = (k as f64 * TILT_GRID).min(tilt_max);
        let Some(body) = effective_body(model, tilt, mass_error, com_offset) else {
            let key = if mass_error.is_some() {
                "effects.mass_error.inertia_scale"
            } else {
                "effects.com_offset.offset"
            };
            return Err(checker
                .fail(
                    key,
                    "mass properties with a positive-definite mass matrix at every tilt",
                    format!("not at {:.2} deg", tilt.to_degrees()),
                )
                .into());
        };
        tilt_grid.push(body);
    }
    Ok(tilt_grid)
}

/// The 8 corners of the base box `lo`..`hi` (body frame); corner k takes
/// `hi` along axis i where bit i of k is set (corner 0 is `lo`, 7 is `hi`).
fn box_corners(lo: [f64; 3], hi: [f64; 3]) -> [Vector3<f64>; 8] {
    std::array::from_fn(|k| {
        Vector3::new(
            if k & 1 == 0 { lo[0] } else { hi[0] },
            if k & 2 == 0 { lo[1] } else { hi[1] },
            if k & 4 == 0 { lo[2] } else { hi[2] },
        )
    })
}

/// (farthest any contact point gets from B at any tilt, farthest a base-box
/// corner gets), m, each plus a margin that no point covers in one step.
fn reaches(
    model: &Model,
    robot: &RobotConfig,
    tilt_max: f64,
    corners: &[Vector3<f64>; 8],
) -> (f64, f64) {
    let corner_reach = corners.iter().map(Vector3::norm).fold(0.0, f64::max);
    let mut reach = corner_reach;
    for k in 0..=90 {
        let body = model.at_tilt(tilt_max * f64::from(k) / 90.0);
        for c in &body.rotor_position {
            reach = reach.max(c.norm() + robot.wheels.radius);
        }
    }
    // 5 cm: no point covers that in one step below 50 m/s.
    (reach + 0.05, corner_reach + 0.05)
}
