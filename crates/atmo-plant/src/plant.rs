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
//! of attitude sines and cosines (module `rigid`; bit-identical, tested).
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

use std::borrow::Cow;
use std::sync::Arc;

use atmo_core::control::WheelRates;
use atmo_core::model::{Input, Model, State, TiltedBody, idx};
use atmo_core::{Linkage, RobotConfig};
use nalgebra::{Cholesky, Matrix3, SVector, U6, Vector3, Vector6};
use rand_chacha::ChaCha8Rng;

use crate::config::{
    BatterySagConfig, DragConfig, GroundContactConfig, PlantConfig, SensorsConfig, TerrainConfig,
    WindConfig,
};
use crate::contact::{ContactLaw, Plane};
use crate::error::{PlantError, Result};
use crate::ground_effect::{GroundEffect, TiltSlice};
use crate::noise::{GaussMarkov, rng, stream};
use crate::rigid::{Attitude, accelerations, lerp_body, state_derivative};
use crate::sensors::{Estimate, Mocap};

/// Contact points: the four wheels (rotor order), then the 8 base-box corners.
pub const N_CONTACTS: usize = 12;
const N_WHEELS: usize = 4;

const THRUST: usize = 12;
const WHEEL: usize = 16;
const WHEEL_INT: usize = 18;
const ENERGY: usize = 20;
const SPRING: usize = 21;
/// Length of the plant's continuous state.
pub const N_EXT: usize = SPRING + 3 * N_CONTACTS;
type Ext = SVector<f64, N_EXT>;

/// Which contact points a step has to consider (see `Plant::reachable`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Reach {
    Nothing,
    Wheels,
    Everything,
}

impl Reach {
    /// How many leading entries of the continuous state can change.
    fn state_len(self) -> usize {
        match self {
            Self::Nothing => SPRING,
            Self::Wheels => SPRING + 3 * N_WHEELS,
            Self::Everything => N_EXT,
        }
    }
}

/// The four wheels' body-frame geometry, `[component][wheel]` (rotor
/// order), the layout the four-lane contact kernel reads.
#[derive(Debug, Clone, Copy, Default)]
struct WheelLanes {
    hub: [[f64; 4]; 3],
    axle: [[f64; 4]; 3],
    /// Forward spin axis: the axle times `SPIN_SIGN`.
    spin_axis: [[f64; 4]; 3],
}

impl WheelLanes {
    #[inline(always)]
    fn of(body: &TiltedBody) -> Self {
        Self {
            hub: std::array::from_fn(|k| std::array::from_fn(|j| body.rotor_position[j][k])),
            axle: std::array::from_fn(|k| std::array::from_fn(|j| body.rotor_axis[j][k])),
            spin_axis: std::array::from_fn(|k| {
                std::array::from_fn(|j| body.rotor_axis[j][k] * SPIN_SIGN[j])
            }),
        }
    }
}

/// Wheel j's lowest rim point towards unit `down` (body frame), as the
/// four-wheel loops compute it: `c + R d_p / |d_p|` and the sideways
/// direction `l_p / |l_p|`, with d_p = d - a (a.d) and l_p = a - d (a.d).
/// For unit a and d both have the length sqrt(1 - (a.d)^2), so one square
/// root serves both. A wheel lying flat (|d_p| <= 1e-6) touches at its hub
/// and has no sideways direction (`upright` false).
#[derive(Debug, Clone, Copy)]
struct Rim {
    upright: bool,
    /// From the hub to the point.
    offset: [f64; 3],
    point: [f64; 3],
    /// Sideways (along the axle, in the ground plane); body frame.
    lateral: [f64; 3],
}

#[inline(always)]
fn rim(g: &WheelLanes, j: usize, down: &Vector3<f64>, radius: f64) -> Rim {
    let c = [g.hub[0][j], g.hub[1][j], g.hub[2][j]];
    let a = [g.axle[0][j], g.axle[1][j], g.axle[2][j]];
    let ad = a[0] * down.x + a[1] * down.y + a[2] * down.z;
    let len_sq = 1.0 - ad * ad;
    let upright = len_sq > 1e-12;
    let inv = 1.0 / len_sq.max(1e-12).sqrt();
    let reach = if upright { radius * inv } else { 0.0 };
    let offset: [f64; 3] = std::array::from_fn(|i| (down[i] - a[i] * ad) * reach);
    Rim {
        upright,
        offset,
        point: std::array::from_fn(|i| c[i] + offset[i]),
        lateral: std::array::from_fn(|i| (a[i] - down[i] * ad) * inv),
    }
}

/// The post-step pass at the four wheels, `[component][wheel]`.
#[derive(Debug, Clone, Copy, Default)]
struct WheelReport {
    touching: [bool; 4],
    normal_force: [f64; 4],
    approach_speed: [f64; 4],
    /// Tangential spring held at the friction limit (zero when open).
    spring: [[f64; 4]; 3],
}

/// The contact law's result at the four wheels, `[component][wheel]`
/// (body frame); only wheels with `touching` count.
#[derive(Debug, Clone, Copy, Default)]
struct WheelForces {
    touching: [bool; 4],
    force: [[f64; 4]; 3],
    /// Torque about B without the spin-axis part.
    torque: [[f64; 4]; 3],
    /// Torque about the spin axis (turns the wheel).
    axial: [f64; 4],
    /// Tangential spring rate (world frame).
    spring_rate: [[f64; 4]; 3],
}

/// Which side each rotor's wheel is on (0 = left, 1 = right), PX4 quad-x:
/// rotors 1 and 4 on the right arm, 2 and 3 on the left.
const WHEEL_SIDE: [usize; 4] = [1, 0, 0, 1];
/// Sign from the rotor axis to the forward spin axis: at varphi = 90 deg the
/// right rotors' axes point +y and the left ones' -y; forward rolling is a
/// spin about -y for both.
const SPIN_SIGN: [f64; 4] = [-1.0, 1.0, 1.0, -1.0];

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

#[derive(Debug, Clone, Copy)]
struct Drive {
    inertia: f64,
    kp: f64,
    ki: f64,
    torque_max: f64,
}

#[derive(Debug, Clone)]
struct Wind {
    config: WindConfig,
    turbulence: [GaussMarkov; 3],
    rng: ChaCha8Rng,
}

impl Wind {
    fn at(&self, time: f64) -> Vector3<f64> {
        let c = &self.config;
        let mut w = Vector3::from(c.steady);
        for k in 0..3 {
            w[k] += c.turbulence_std[k] * self.turbulence[k].value;
        }
        for g in &c.gusts {
            if time >= g.t && time < g.t + g.duration {
                let shape =
                    0.5 * (1.0 - (2.0 * std::f64::consts::PI * (time - g.t) / g.duration).cos());
                w += Vector3::from(g.velocity) * shape;
            }
        }
        w
    }
}

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
    drag: Option<DragConfig>,
    wind: Option<Wind>,
    battery: Option<BatterySagConfig>,
    com_offset: Option<Vector3<f64>>,
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

/// The 12 rigid-body states at the head of the plant's state (a plain copy;
/// nalgebra's `into_owned` goes through a generic iterator).
#[inline(always)]
fn body_state(ext: &Ext) -> State {
    State::from_column_slice(&ext.as_slice()[..12])
}

fn skew(r: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -r.z, r.y, r.z, 0.0, -r.x, -r.y, r.x, 0.0)
}

/// The composite body at `tilt` with the mass-property errors applied:
/// mass and first moment scaled by `ms`, inertia about B by `is`, then the
/// whole mass distribution shifted by `d` (body frame):
/// `c' = c + m d`, `I' = I + m (|d|^2 1 - d d^T) + 2 (c . d) 1 - c d^T - d c^T`.
fn effective_body(
    model: &Model,
    tilt: f64,
    mass_error: Option<(f64, f64)>,
    com_offset: Option<Vector3<f64>>,
) -> Option<TiltedBody> {
    let mut b = model.at_tilt(tilt);
    if mass_error.is_none() && com_offset.is_none() {
        return Some(b);
    }
    if let Some((ms, is)) = mass_error {
        b.mass *= ms;
        b.first_moment *= ms;
        b.inertia *= is;
    }
    if let Some(d) = com_offset {
        let (m, c) = (b.mass, b.first_moment);
        b.inertia += (Matrix3::identity() * d.norm_squared() - d * d.transpose()) * m
            + Matrix3::identity() * (2.0 * c.dot(&d))
            - c * d.transpose()
            - d * c.transpose();
        b.first_moment = c + d * m;
    }
    let mut mm = b.mass_matrix;
    mm.fixed_view_mut::<3, 3>(0, 0).fill_with_identity();
    mm.fixed_view_mut::<3, 3>(0, 0).scale_mut(b.mass);
    mm.fixed_view_mut::<3, 3>(0, 3)
        .copy_from(&(-skew(&b.first_moment)));
    mm.fixed_view_mut::<3, 3>(3, 0)
        .copy_from(&skew(&b.first_moment));
    mm.fixed_view_mut::<3, 3>(3, 3).copy_from(&b.inertia);
    b.mass_matrix = mm;
    b.mass_matrix_inv = Cholesky::<f64, U6>::new(mm)?.inverse();
    Some(b)
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
        config.validate()?;
        let checker = atmo_core::config::Checker::new(&config.source);
        terrain.validate(&checker, "terrain")?;
        let fx = &config.effects;
        let mut truth = robot.clone();
        truth.arm.inertia_convention = config.arm_inertia_convention;
        let model = Model::new(&truth);
        let tilt_max = robot.limits.tilt_max();
        let linkage = Linkage::from_config(&robot.linkage, tilt_max)?;
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
        let motor_lag = fx
            .motor_lag
            .as_ref()
            .filter(|e| e.enabled)
            .map(|e| (e.time_constant, e.curve));
        let drag = fx.drag.clone().filter(|e| e.enabled);
        let battery = fx.battery_sag.clone().filter(|e| e.enabled);
        let com_offset = fx
            .com_offset
            .as_ref()
            .filter(|e| e.enabled)
            .map(|e| Vector3::from(e.offset));
        let mass_error = fx
            .mass_error
            .as_ref()
            .filter(|e| e.enabled)
            .map(|e| (e.mass_scale, e.inertia_scale));
        let sensors: Option<SensorsConfig> = fx.sensors.clone().filter(|e| e.enabled);
        let contact_cfg = fx.ground_contact.clone().filter(|e| e.enabled);

        // Every exact body the moving tilt is interpolated between, built
        // once; this also checks that the perturbed mass properties stay
        // physical at every tilt.
        let cells = (tilt_max / TILT_GRID).ceil().max(1.0) as usize;
        let mut tilt_grid = Vec::with_capacity(cells + 1);
        for k in 0..=cells {
            let tilt = (k as f64 * TILT_GRID).min(tilt_max);
            let Some(body) = effective_body(&model, tilt, mass_error, com_offset) else {
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
        let (lo, hi) = contact.as_ref().map_or(
            (
                GroundContactConfig::default().base_box_min,
                GroundContactConfig::default().base_box_max,
            ),
            |(_, _, c)| (c.base_box_min, c.base_box_max),
        );
        let corners = std::array::from_fn(|k| {
            Vector3::new(
                if k & 1 == 0 { lo[0] } else { hi[0] },
                if k & 2 == 0 { lo[1] } else { hi[1] },
                if k & 4 == 0 { lo[2] } else { hi[2] },
            )
        });

        // Farthest contact point from B at any tilt, plus a margin that no
        // point can cover in one step.
        let corner_reach = corners.iter().map(Vector3::norm).fold(0.0, f64::max);
        let mut reach = corner_reach;
        for k in 0..=90 {
            let body = model.at_tilt(tilt_max * f64::from(k) / 90.0);
            for c in &body.rotor_position {
                reach = reach.max(c.norm() + robot.wheels.radius);
            }
        }
        // 5 cm: no point covers that in one step below 50 m/s.
        let (reach, corner_reach) = (reach + 0.05, corner_reach + 0.05);

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
        let mut plant = Self {
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
            drag,
            wind,
            battery,
            com_offset,
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
            tilt_grid: tilt_grid.into(),
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

    /// s, simulated time (step count times dt).
    pub fn time(&self) -> f64 {
        self.steps as f64 * self.dt
    }

    /// Steps taken.
    pub fn steps(&self) -> u64 {
        self.steps
    }

    /// The true rigid-body state.
    pub fn state(&self) -> State {
        body_state(&self.ext)
    }

    /// rad, the true tilt.
    pub fn tilt(&self) -> f64 {
        self.tilt
    }

    /// The tilt encoder: counts via the linkage, whole counts when the tilt
    /// mechanism effect is on.
    pub fn encoder_counts(&self) -> Result<f64> {
        let counts = self.linkage.counts_from_tilt(self.tilt)?;
        Ok(if self.quantize_encoder {
            counts.round()
        } else {
            counts
        })
    }

    /// Normalized thrust of each rotor (after the motor lag and curve).
    pub fn thrust(&self) -> Input {
        if self.motor_lag.is_some() {
            self.ext.fixed_rows::<4>(THRUST).into_owned()
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

    /// The ground-contact signal the robot reports.
    pub fn contact_signal(&self) -> bool {
        let wheel_force: f64 = self.contacts[..N_WHEELS]
            .iter()
            .map(|c| c.normal_force)
            .sum();
        self.mocap.contact_signal(wheel_force)
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

    /// `x_dot` of the rigid body now under `command` (with every effect;
    /// ground-effect and wind noise as held for the current step).
    pub fn body_derivative(&self, command: &Command) -> Result<State> {
        let cmd = self.sanitize(command)?;
        let d = self.derivative(&self.ext, &cmd, self.reachable());
        Ok(d.fixed_rows::<12>(0).into_owned())
    }

    #[inline(always)]
    fn sanitize(&self, command: &Command) -> Result<Command> {
        for (i, u) in command.rotors.iter().enumerate() {
            if !u.is_finite() {
                const NAMES: [&str; 4] = ["rotors[0]", "rotors[1]", "rotors[2]", "rotors[3]"];
                return Err(PlantError::NonFiniteCommand {
                    name: NAMES[i],
                    value: *u,
                });
            }
        }
        for (name, v) in [
            ("tilt_rate", command.tilt_rate),
            ("wheel_rates.left", command.wheel_rates.left),
            ("wheel_rates.right", command.wheel_rates.right),
        ] {
            if !v.is_finite() {
                return Err(PlantError::NonFiniteCommand { name, value: v });
            }
        }
        let wmax = self.wheel_rate_max;
        Ok(Command {
            rotors: Input::new(
                command.rotors[0].clamp(0.0, 1.0),
                command.rotors[1].clamp(0.0, 1.0),
                command.rotors[2].clamp(0.0, 1.0),
                command.rotors[3].clamp(0.0, 1.0),
            ),
            tilt_rate: command
                .tilt_rate
                .clamp(-self.tilt_rate_max, self.tilt_rate_max),
            wheel_rates: WheelRates {
                left: command.wheel_rates.left.clamp(-wmax, wmax),
                right: command.wheel_rates.right.clamp(-wmax, wmax),
            },
        })
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

    /// The step; it and everything it calls per step are `inline(always)`
    /// so that both copies of `step` contain all of it.
    #[inline(always)]
    fn step_kernel(&mut self, command: &Command) -> Result<()> {
        let cmd = self.sanitize(command)?;
        self.command = cmd;
        let dt = self.dt;

        // Tilt: self-locking screw, moves only by the (limited) command.
        let new_tilt = (self.tilt + cmd.tilt_rate * dt).clamp(0.0, self.tilt_max);
        self.update_body(0.5 * (self.tilt + new_tilt), new_tilt != self.tilt);

        // Random processes, held over the step.
        if self.ground_effect.is_some() {
            for n in &mut self.ge_noise {
                n.advance(&mut self.ge_rng);
            }
        }
        let mid_time = self.time() + 0.5 * dt;
        if let Some(w) = &mut self.wind {
            for n in &mut w.turbulence {
                n.advance(&mut w.rng);
            }
            self.wind_now = w.at(mid_time);
        }

        // RK4 over the states that can change in this step: the contact
        // springs of points that cannot reach the ground are zero (reset
        // when a contact opens) and their derivatives are zero, so they are
        // left out, exactly (same operations, element by element, on the rest).
        let reach = self.reachable();
        let n = reach.state_len();
        self.prepare_wheel_lanes(reach);
        // One call site for the four stages (the derivative is inlined, once):
        // stage s+1 is evaluated at x + k_s h_s, and the weighted sum
        // k1 + 2 k2 + 2 k3 + k4 is accumulated in that order. Only the first
        // n entries are touched: no copies of the whole state.
        let x = &self.ext;
        let half = 0.5 * dt;
        let stage_step = [half, half, dt];
        let weight = [1.0, 2.0, 2.0, 1.0];
        let mut stage = *x;
        let mut k = Ext::from([0.0; N_EXT]);
        let mut sum = [0.0; N_EXT];
        // Slices of the live length: bounds checked once, so the loops vectorize.
        let x = &x.as_slice()[..n];
        for s in 0..4 {
            self.derivative_into(&stage, &cmd, reach, &mut k);
            let k = &k.as_slice()[..n];
            if s == 0 {
                sum[..n].copy_from_slice(k);
            } else {
                for (sum, k) in sum[..n].iter_mut().zip(k) {
                    *sum += k * weight[s];
                }
            }
            if s < 3 {
                let h = stage_step[s];
                for ((st, x), k) in stage.as_mut_slice()[..n].iter_mut().zip(x).zip(k) {
                    *st = x + k * h;
                }
            }
        }
        let sixth = dt / 6.0;
        let next = &mut stage.as_mut_slice()[..n];
        for ((next, x), sum) in next.iter_mut().zip(x).zip(&sum[..n]) {
            *next = x + sum * sixth;
        }
        if !next.iter().all(|v| v.is_finite()) {
            return Err(PlantError::Diverged {
                time: self.time() + dt,
            });
        }
        self.ext.as_mut_slice()[..n].copy_from_slice(next);
        self.tilt = new_tilt;
        self.steps += 1;
        self.observe();
        Ok(())
    }

    /// Sets the composite body for a step whose mid-step tilt is `mid`:
    /// exact (atmo-core's `at_tilt` with the mass errors) while the tilt
    /// stands still; while it moves, interpolated between the exact bodies
    /// of the 0.25 deg grid built at start-up, so that morphing does not
    /// rebuild and refactor the body every step.
    #[inline(always)]
    fn update_body(&mut self, mid: f64, moving: bool) {
        if moving {
            let cells = self.tilt_grid.len() - 1;
            let k = ((mid / TILT_GRID).floor().max(0.0) as usize).min(cells - 1);
            let (lo, hi) = (&self.tilt_grid[k], &self.tilt_grid[k + 1]);
            let w = ((mid - lo.varphi) / (hi.varphi - lo.varphi)).clamp(0.0, 1.0);
            self.body = lerp_body(lo, hi, w, mid);
            self.body_interpolated = true;
        } else if mid != self.body.varphi || self.body_interpolated {
            if let Some(b) = effective_body(&self.model, mid, self.mass_error, self.com_offset) {
                self.body = b;
                self.body_interpolated = false;
            }
        } else {
            return; // the same body: the ground-effect slice and wheel lanes stand too
        }
        self.wheel_lanes = None;
        if let Some(ge) = &self.ground_effect {
            self.ge_slice = ge.slice(self.body.varphi);
        }
    }

    /// Steps until `duration` more seconds have passed (rounded to whole steps).
    pub fn advance(&mut self, command: &Command, duration: f64) -> Result<()> {
        let n = (duration / self.dt).round().max(0.0) as u64;
        for _ in 0..n {
            self.step(command)?;
        }
        Ok(())
    }

    /// After a step: contact springs, drive integrators, contact report,
    /// events, sensors.
    #[inline(always)]
    fn observe(&mut self) {
        let mut report = [ContactInfo::default(); N_CONTACTS];
        // Far above the ground nothing touches: skip the contact pass.
        let reach = self.reachable();
        let near = reach != Reach::Nothing;
        let rot = if near {
            let x = body_state(&self.ext);
            Attitude::of(&x).r
        } else {
            Matrix3::identity()
        };
        let mut wheel_springs = [[0.0; 4]; 3];
        self.prepare_wheel_lanes(reach);
        if near {
            (report, wheel_springs) = self.contact_report(&rot, reach == Reach::Everything);
        }
        let time = self.time();
        let mut new_events: [Option<EventKind>; N_CONTACTS + 1] = [None; N_CONTACTS + 1];
        if let Some((law, drive, cfg)) = &self.contact {
            let n = self.plane.normal;
            // Out of reach nothing touches: the springs only need zeroing if
            // something touched a step ago (they stay zero otherwise).
            if near || self.contacts.iter().any(|c| c.touching) {
                for j in 0..N_WHEELS {
                    for k in 0..3 {
                        self.ext[SPRING + 3 * j + k] = wheel_springs[k][j];
                    }
                }
                for (j, info) in report.iter().enumerate().skip(N_WHEELS) {
                    let s = if info.touching {
                        let s = Vector3::new(
                            self.ext[SPRING + 3 * j],
                            self.ext[SPRING + 3 * j + 1],
                            self.ext[SPRING + 3 * j + 2],
                        );
                        law.limit_spring(&n, &s, info.normal_force, None)
                    } else {
                        Vector3::zeros()
                    };
                    self.ext.fixed_rows_mut::<3>(SPRING + 3 * j).copy_from(&s);
                }
            }
            if drive.ki > 0.0 {
                let limit = drive.torque_max / drive.ki;
                for side in 0..2 {
                    self.ext[WHEEL_INT + side] = self.ext[WHEEL_INT + side].clamp(-limit, limit);
                }
            }
            // Crash reports (a touchdown needs a touching point: only when near).
            if near {
                let crash_speed = cfg.crash_speed;
                for j in 0..N_CONTACTS {
                    let was = self.contacts[j].touching;
                    let now = &report[j];
                    if now.touching && !was {
                        // The speed just before contact: the first touching step
                        // has already been slowed by the contact force.
                        let speed = now.approach_speed.max(self.contacts[j].approach_speed);
                        if j < N_WHEELS {
                            if speed > crash_speed {
                                new_events[j] = Some(EventKind::Crash(CrashKind::HardImpact {
                                    wheel: j,
                                    speed,
                                }));
                            }
                        } else {
                            new_events[j] = Some(EventKind::Crash(CrashKind::BodyContact {
                                corner: j - N_WHEELS,
                            }));
                        }
                    }
                }
            }
            if !self.tipped && report.iter().any(|c| c.touching) {
                let body_down = rot.column(2).into_owned();
                let cos_angle = (-body_down.dot(&n)).clamp(-1.0, 1.0);
                // Compare cosines (acos only when it tips: once per run).
                if cos_angle < self.tip_over_cos {
                    let angle = cos_angle.acos().to_degrees();
                    self.tipped = true;
                    new_events[N_CONTACTS] =
                        Some(EventKind::Crash(CrashKind::TipOver { angle_deg: angle }));
                }
            }
        }
        for kind in new_events.into_iter().flatten() {
            self.push_event(Event { time, kind });
        }
        self.contacts = report;
        let grounded = self.contact_signal();
        if grounded != self.grounded {
            self.grounded = grounded;
            let kind = if grounded {
                EventKind::Touchdown
            } else {
                EventKind::Liftoff
            };
            self.push_event(Event { time, kind });
        }
        let x = self.state();
        self.mocap.record(self.steps, &x);
    }

    fn push_event(&mut self, event: Event) {
        if matches!(event.kind, EventKind::Crash(_)) && self.crash.is_none() {
            self.crash = Some(event);
        }
        if self.events.len() < EVENT_CAPACITY {
            self.events.push(event);
        } else {
            self.events_dropped += 1;
        }
    }

    /// Makes the current body's wheel lanes if a wheel may reach the ground
    /// and they are not made yet (the body changed since).
    #[inline(always)]
    fn prepare_wheel_lanes(&mut self, reach: Reach) {
        if reach != Reach::Nothing && self.wheel_lanes.is_none() {
            self.wheel_lanes = Some(WheelLanes::of(&self.body));
        }
    }

    /// The current body's wheel lanes; made here only if they were not
    /// prepared (`body_derivative` right after the body changed).
    #[inline(always)]
    fn wheel_lanes(&self) -> Cow<'_, WheelLanes> {
        self.wheel_lanes
            .as_ref()
            .map_or_else(|| Cow::Owned(WheelLanes::of(&self.body)), Cow::Borrowed)
    }

    /// Which contact points can touch the ground during the coming step,
    /// from where B is now: `reach` and `corner_reach` carry a 5 cm margin
    /// that no point covers in one step below 50 m/s.
    #[inline(always)]
    fn reachable(&self) -> Reach {
        if self.contact.is_none() {
            return Reach::Nothing;
        }
        let height = self.plane.height(&Vector3::new(
            self.ext[idx::X],
            self.ext[idx::Y],
            self.ext[idx::Z],
        ));
        if height > self.reach {
            Reach::Nothing
        } else if height > self.corner_reach {
            Reach::Wheels
        } else {
            Reach::Everything
        }
    }

    /// `max_k down_b . c_k` over the base-box corners (body frame): the
    /// support function of the axis-aligned box, one term per axis.
    #[inline(always)]
    fn box_support(&self, down_b: &Vector3<f64>) -> f64 {
        let (lo, hi) = (&self.corners[0], &self.corners[7]);
        (0..3)
            .map(|i| (down_b[i] * lo[i]).max(down_b[i] * hi[i]))
            .sum()
    }

    /// Where each contact point is after a step: touching or not, its speed
    /// towards the ground and its normal force (the contact law's normal
    /// part; wheel spin moves the rim point along the ground, not into it);
    /// and the wheels' tangential springs held at the friction limit. The
    /// corners are left out (not touching) unless `corners_in_reach`.
    #[inline(always)]
    fn contact_report(
        &self,
        r: &Matrix3<f64>,
        corners_in_reach: bool,
    ) -> ([ContactInfo; N_CONTACTS], [[f64; 4]; 3]) {
        let mut report = [ContactInfo::default(); N_CONTACTS];
        let Some((law, _, _)) = &self.contact else {
            return (report, [[0.0; 4]; 3]);
        };
        let ext = &self.ext;
        let p = Vector3::new(ext[idx::X], ext[idx::Y], ext[idx::Z]);
        let v = Vector3::new(ext[idx::VX], ext[idx::VY], ext[idx::VZ]);
        let w = Vector3::new(ext[idx::WX], ext[idx::WY], ext[idx::WZ]);
        let n = self.plane.normal;
        let down_b = -(r.transpose() * n);
        let height = self.plane.height(&p);
        let v_n_b = v.dot(&n);
        let wheels = self.wheel_report(r, &down_b, height, v_n_b, &w, law);
        for (j, info) in report[..N_WHEELS].iter_mut().enumerate() {
            *info = ContactInfo {
                normal_force: wheels.normal_force[j],
                approach_speed: wheels.approach_speed[j],
                touching: wheels.touching[j],
            };
        }
        if !corners_in_reach {
            return (report, wheels.spring);
        }
        // The corners in plain arrays first (a loop that vectorizes), then
        // into the report.
        let mut depth = [0.0; 8];
        let mut v_n = [0.0; 8];
        // (v + R (w x c)) . n = v . n - down_b . (w x c) = v . n - c . (down_b x w),
        // with R^T n = -down_b.
        let down_x_w = down_b.cross(&w);
        for (k, c) in self.corners.iter().enumerate() {
            depth[k] = down_b.dot(c) - height;
            v_n[k] = v_n_b - c.dot(&down_x_w);
        }
        for (k, info) in report[N_WHEELS..].iter_mut().enumerate() {
            info.approach_speed = -v_n[k];
            if depth[k] > 0.0 {
                info.touching = true;
                info.normal_force = law.normal_force(depth[k], v_n[k]);
            }
        }
        (report, wheels.spring)
    }

    /// `contact_report` at the four wheels at once, in one branch-free loop
    /// like `wheel_forces`, with the springs held as `ContactLaw::limit_spring`
    /// holds them.
    #[inline(always)]
    fn wheel_report(
        &self,
        r: &Matrix3<f64>,
        down: &Vector3<f64>,
        height: f64,
        v_n_b: f64,
        w: &Vector3<f64>,
        law: &ContactLaw,
    ) -> WheelReport {
        let g = &*self.wheel_lanes();
        let n = &self.plane.normal;
        let kt = law.tangential_stiffness;
        let mut out = WheelReport::default();
        for j in 0..N_WHEELS {
            let rim = rim(g, j, down, self.wheel_radius);
            let pt = rim.point;
            let depth = down.x * pt[0] + down.y * pt[1] + down.z * pt[2] - height;
            // (v + R (w x p)) . n, with R^T n = -down.
            let w_x_p = [
                w.y * pt[2] - w.z * pt[1],
                w.z * pt[0] - w.x * pt[2],
                w.x * pt[1] - w.y * pt[0],
            ];
            let v_n = v_n_b - (down.x * w_x_p[0] + down.y * w_x_p[1] + down.z * w_x_p[2]);
            let touching = depth > 0.0;
            let f_n = if touching {
                law.normal_force(depth, v_n)
            } else {
                0.0
            };
            // The spring's tangential part, held at the friction limit.
            let lat: [f64; 3] = std::array::from_fn(|i| {
                r[(i, 0)] * rim.lateral[0] + r[(i, 1)] * rim.lateral[1] + r[(i, 2)] * rim.lateral[2]
            });
            let s: [f64; 3] = std::array::from_fn(|k| self.ext[SPRING + 3 * j + k]);
            let s_n = s[0] * n.x + s[1] * n.y + s[2] * n.z;
            let f: [f64; 3] = std::array::from_fn(|i| (s[i] - n[i] * s_n) * kt);
            let held = touching && f_n > 0.0;
            let scale = if held {
                1.0 / (law.limit_divisor(&f, f_n, &lat, rim.upright) * kt)
            } else {
                0.0
            };
            for i in 0..3 {
                out.spring[i][j] = f[i] * scale;
            }
            out.touching[j] = touching;
            out.normal_force[j] = f_n;
            out.approach_speed[j] = -v_n;
        }
        out
    }

    /// Contact wrench on the body (body force, torque about B) and the
    /// derivatives of the contact springs and wheel drives, written into `d`.
    /// Skips the contact points when B is farther from the ground than any
    /// point of the robot can reach.
    #[inline(always)]
    fn contact_terms(
        &self,
        ext: &Ext,
        r: &Matrix3<f64>,
        cmd: &Command,
        reach: Reach,
        d: &mut Ext,
    ) -> Vector6<f64> {
        let Some((law, drive, _)) = &self.contact else {
            return Vector6::zeros();
        };
        let body = &self.body;
        let p = Vector3::new(ext[idx::X], ext[idx::Y], ext[idx::Z]);
        let v = Vector3::new(ext[idx::VX], ext[idx::VY], ext[idx::VZ]);
        let w = Vector3::new(ext[idx::WX], ext[idx::WY], ext[idx::WZ]);
        let height = self.plane.height(&p);
        let rt = r.transpose();
        let n = self.plane.normal;
        let down_b = -(rt * n);
        let mut force = Vector3::zeros();
        let mut torque = Vector3::zeros();
        let mut wheel_torque = [0.0; 2];
        let spin = [ext[WHEEL], ext[WHEEL + 1]];
        // A rim point is at most the radius below its hub: while every hub
        // is higher than that, no wheel touches (the usual case in flight).
        let wheel_may_touch = reach != Reach::Nothing
            && body
                .rotor_position
                .iter()
                .any(|c| down_b.dot(c) + self.wheel_radius > height);
        if wheel_may_touch {
            let wheels = self.wheel_forces(ext, r, &down_b, height, &w, &v, law);
            for j in 0..N_WHEELS {
                if !wheels.touching[j] {
                    continue;
                }
                for k in 0..3 {
                    d[SPRING + 3 * j + k] = wheels.spring_rate[k][j];
                }
                force += Vector3::new(wheels.force[0][j], wheels.force[1][j], wheels.force[2][j]);
                torque += Vector3::new(
                    wheels.torque[0][j],
                    wheels.torque[1][j],
                    wheels.torque[2][j],
                );
                wheel_torque[WHEEL_SIDE[j]] += wheels.axial[j];
            }
        }
        // The base-box corners: none touches while the box's support along
        // down_b is below B (a point c is `height - down_b . c` above ground).
        if reach == Reach::Everything && self.box_support(&down_b) > height {
            for (k, point) in self.corners.iter().enumerate() {
                let j = N_WHEELS + k;
                let depth = down_b.dot(point) - height;
                if depth <= 0.0 {
                    continue;
                }
                let v_point = v + r * w.cross(point);
                let s = Vector3::new(
                    ext[SPRING + 3 * j],
                    ext[SPRING + 3 * j + 1],
                    ext[SPRING + 3 * j + 2],
                );
                let (f_world, _, s_dot) = law.force(&n, depth, &v_point, &s, None);
                d.fixed_rows_mut::<3>(SPRING + 3 * j).copy_from(&s_dot);
                let f_b = rt * f_world;
                force += f_b;
                torque += point.cross(&f_b);
            }
        }
        // Wheel drives: PI speed control with a torque limit; the
        // motor reaction acts on the body about the side's spin axis.
        let cmd_rates = [cmd.wheel_rates.left, cmd.wheel_rates.right];
        let side_axis = [
            body.rotor_axis[1] * SPIN_SIGN[1],
            body.rotor_axis[0] * SPIN_SIGN[0],
        ];
        for side in 0..2 {
            let err = cmd_rates[side] - spin[side];
            let tau = (drive.kp * err + drive.ki * ext[WHEEL_INT + side])
                .clamp(-drive.torque_max, drive.torque_max);
            d[WHEEL + side] = (tau + wheel_torque[side]) / drive.inertia;
            d[WHEEL_INT + side] = err;
            torque -= side_axis[side] * tau;
        }
        Vector6::new(force.x, force.y, force.z, torque.x, torque.y, torque.z)
    }

    /// The contact law at the four wheels at once: one loop over the wheels
    /// with straight-line arithmetic and selects (no branches), which the
    /// compiler turns into 4-wide vector code (2-wide in the portable copy).
    /// The law is `ContactLaw::force` at each wheel's lowest rim point
    /// (`rim`); the rim point moves with the body and with the wheel's spin.
    #[inline(always)]
    #[allow(clippy::too_many_arguments, clippy::similar_names)]
    fn wheel_forces(
        &self,
        ext: &Ext,
        r: &Matrix3<f64>,
        down: &Vector3<f64>,
        height: f64,
        w: &Vector3<f64>,
        v: &Vector3<f64>,
        law: &ContactLaw,
    ) -> WheelForces {
        let g = &*self.wheel_lanes();
        let radius = self.wheel_radius;
        let n = &self.plane.normal;
        let spin_side = [ext[WHEEL], ext[WHEEL + 1]];
        let spin: [f64; 4] = std::array::from_fn(|j| spin_side[WHEEL_SIDE[j]]);
        let spring: [[f64; 4]; 3] =
            std::array::from_fn(|k| std::array::from_fn(|j| ext[SPRING + 3 * j + k]));
        let mut out = WheelForces::default();
        for j in 0..N_WHEELS {
            let c = [g.hub[0][j], g.hub[1][j], g.hub[2][j]];
            let e = [g.spin_axis[0][j], g.spin_axis[1][j], g.spin_axis[2][j]];
            let Rim {
                upright,
                offset: rim,
                point: pt,
                lateral: lat_b,
            } = rim(g, j, down, radius);
            let depth = down.x * pt[0] + down.y * pt[1] + down.z * pt[2] - height;
            // Velocity of the rim point: body motion plus wheel spin (body frame).
            let vl = [
                w.y * pt[2] - w.z * pt[1] + (e[1] * rim[2] - e[2] * rim[1]) * spin[j],
                w.z * pt[0] - w.x * pt[2] + (e[2] * rim[0] - e[0] * rim[2]) * spin[j],
                w.x * pt[1] - w.y * pt[0] + (e[0] * rim[1] - e[1] * rim[0]) * spin[j],
            ];
            let vp: [f64; 3] = std::array::from_fn(|i| {
                v[i] + r[(i, 0)] * vl[0] + r[(i, 1)] * vl[1] + r[(i, 2)] * vl[2]
            });
            let lat: [f64; 3] = std::array::from_fn(|i| {
                r[(i, 0)] * lat_b[0] + r[(i, 1)] * lat_b[1] + r[(i, 2)] * lat_b[2]
            });
            // Normal spring-damper, tangential spring-damper (world frame).
            let v_n = vp[0] * n.x + vp[1] * n.y + vp[2] * n.z;
            let f_n = law.normal_force(depth, v_n);
            let v_t = [vp[0] - n.x * v_n, vp[1] - n.y * v_n, vp[2] - n.z * v_n];
            let f_t: [f64; 3] = std::array::from_fn(|i| {
                -(spring[i][j] * law.tangential_stiffness) - v_t[i] * law.tangential_damping
            });
            // Coulomb cap: an ellipse (rolling / sideways), a circle when flat.
            let scale = if f_n <= 0.0 {
                0.0
            } else {
                1.0 / law.limit_divisor(&f_t, f_n, &lat, upright)
            };
            let f_w: [f64; 3] = std::array::from_fn(|i| n[i] * f_n + f_t[i] * scale);
            // Into the body frame; torque about B less the spin-axis part,
            // which turns the wheel instead.
            let f_b: [f64; 3] = std::array::from_fn(|i| {
                r[(0, i)] * f_w[0] + r[(1, i)] * f_w[1] + r[(2, i)] * f_w[2]
            });
            let rim_x_f = [
                rim[1] * f_b[2] - rim[2] * f_b[1],
                rim[2] * f_b[0] - rim[0] * f_b[2],
                rim[0] * f_b[1] - rim[1] * f_b[0],
            ];
            let axial = e[0] * rim_x_f[0] + e[1] * rim_x_f[1] + e[2] * rim_x_f[2];
            let tq = [
                pt[1] * f_b[2] - pt[2] * f_b[1] - e[0] * axial,
                pt[2] * f_b[0] - pt[0] * f_b[2] - e[1] * axial,
                pt[0] * f_b[1] - pt[1] * f_b[0] - e[2] * axial,
            ];
            // A rim point is at most the radius below its hub.
            let hub_low = down.x * c[0] + down.y * c[1] + down.z * c[2] + radius > height;
            let touching = hub_low && depth > 0.0;
            out.touching[j] = touching;
            for i in 0..3 {
                out.force[i][j] = f_b[i];
                out.torque[i][j] = tq[i];
                out.spring_rate[i][j] = v_t[i];
            }
            out.axial[j] = axial;
        }
        out
    }

    /// The derivative of the continuous state.
    fn derivative(&self, ext: &Ext, cmd: &Command, reach: Reach) -> Ext {
        let mut d = Ext::zeros();
        self.derivative_into(ext, cmd, reach, &mut d);
        d
    }

    /// The derivative of the continuous state, written into the first
    /// `reach.state_len()` entries of `d` (the only ones that can be
    /// nonzero; the rest is left as it is).
    #[inline(always)]
    fn derivative_into(&self, ext: &Ext, cmd: &Command, reach: Reach, d: &mut Ext) {
        let body = &self.body;
        let x = body_state(ext);
        let att = Attitude::of(&x);
        d.as_mut_slice()[..reach.state_len()].fill(0.0);

        // Rotor thrust: motor lag and curve, battery, ground effect.
        let mut t = cmd.rotors;
        if let Some((tau, f)) = self.motor_lag {
            for i in 0..4 {
                let u = cmd.rotors[i];
                let target = (1.0 - f) * u + f * u * u;
                t[i] = ext[THRUST + i];
                d[THRUST + i] = (target - t[i]) / tau;
            }
        }
        let mut u_eff = t;
        if let Some(b) = &self.battery {
            let used = b.used_wh * 3600.0 + ext[ENERGY];
            let scale = 1.0 - b.sag * (used / (b.capacity_wh * 3600.0)).min(1.0);
            u_eff *= scale;
            d[ENERGY] = t
                .iter()
                .map(|ti| {
                    let ti = ti.max(0.0);
                    b.full_power_w * ti * ti.sqrt()
                })
                .sum();
        }

        let pushed = self.external.0 != Vector3::zeros() || self.external.1 != Vector3::zeros();
        let needs_pose =
            pushed || self.ground_effect.is_some() || self.drag.is_some() || self.contact.is_some();
        let mut extra = Vector6::zeros();
        if needs_pose {
            let r = att.r;
            if pushed {
                let f = r.transpose() * self.external.0;
                let t = &self.external.1;
                extra += Vector6::new(f.x, f.y, f.z, t.x, t.y, t.z);
            }
            let p = Vector3::new(x[idx::X], x[idx::Y], x[idx::Z]);
            let v = Vector3::new(x[idx::VX], x[idx::VY], x[idx::VZ]);
            let w = Vector3::new(x[idx::WX], x[idx::WY], x[idx::WZ]);

            if let Some(ge) = &self.ground_effect {
                for i in 0..4 {
                    // No thrust, no gain to apply (the common case on the ground).
                    if u_eff[i] == 0.0 {
                        continue;
                    }
                    let hub = p + r * body.rotor_position[i];
                    let h = self.plane.height(&hub);
                    u_eff[i] *= 1.0 + ge.sample(&self.ge_slice, h, self.ge_noise[i].value);
                }
            }

            if let Some(drag) = &self.drag {
                let v_air = r.transpose() * (v - self.wind_now);
                let q = 0.5 * drag.air_density;
                let mut force = -Vector3::new(
                    q * drag.body_cd_area[0] * v_air.x.abs() * v_air.x,
                    q * drag.body_cd_area[1] * v_air.y.abs() * v_air.y,
                    q * drag.body_cd_area[2] * v_air.z.abs() * v_air.z,
                );
                let mut torque = Vector3::zeros();
                for i in 0..4 {
                    if t[i] <= 0.0 {
                        continue; // rotor drag scales with thrust
                    }
                    let n = &body.rotor_axis[i];
                    let vi = v_air + w.cross(&body.rotor_position[i]);
                    let fi = -(vi - n * vi.dot(n)) * (drag.rotor_drag * t[i].max(0.0));
                    force += fi;
                    torque += body.rotor_position[i].cross(&fi);
                }
                extra += Vector6::new(force.x, force.y, force.z, torque.x, torque.y, torque.z);
            }

            if self.contact.is_some() {
                extra += self.contact_terms(ext, &r, cmd, reach, d);
            }
        }

        let acc = accelerations(body, &x, &att, &u_eff, &extra);
        d.fixed_rows_mut::<12>(0)
            .copy_from(&state_derivative(&x, &att, &acc));
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::contact::{rim_lowest_point, wheel_lateral};
    use rand::{Rng, SeedableRng};

    /// The four-lane wheel kernels against the scalar law they restate
    /// (`rim_lowest_point`, `wheel_lateral`, `ContactLaw::force` and
    /// `ContactLaw::limit_spring`, one wheel at a time), at
    /// random poses, velocities, spins and springs on flat and sloped
    /// ground, with the wheels upright (90 deg), tilted (45 deg) and flat
    /// (0 deg), sticking and sliding.
    #[test]
    fn the_wheel_kernels_are_the_scalar_contact_law() {
        let robot = RobotConfig::atmo();
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let (mut touching, mut sliding, mut flat) = (0, 0, 0);
        for (tilt_deg, slope_deg) in [(90.0, 0.0), (90.0, 20.0), (45.0, 10.0), (0.0, 0.0)] {
            let tilt = f64::to_radians(tilt_deg);
            let terrain = TerrainConfig {
                height: 0.0,
                slope_deg,
                slope_azimuth_deg: 30.0,
            };
            let initial = InitialState::at(State::zeros(), tilt);
            let mut plant =
                Plant::new(&robot, &PlantConfig::full(), &terrain, &initial, 1).unwrap();
            let Some((law, _, _)) = plant.contact else {
                panic!("the full plant has ground contact");
            };
            // Level at 0 deg, the wheels lie flat: the hub is the lowest point.
            let lying_flat = tilt_deg == 0.0;
            let rest =
                plant.body.rotor_position[0].z + if lying_flat { 0.0 } else { robot.wheels.radius };
            for _ in 0..200 {
                let mut ext = Ext::zeros();
                ext[idx::X] = rng.random_range(-1.0..1.0);
                ext[idx::Y] = rng.random_range(-1.0..1.0);
                let ground_z = -plant
                    .plane
                    .height(&Vector3::new(ext[idx::X], ext[idx::Y], 0.0))
                    / plant.plane.normal.z.abs();
                ext[idx::Z] = ground_z - rest + rng.random_range(-0.02..0.03);
                if !lying_flat {
                    for i in [idx::YAW, idx::PITCH, idx::ROLL] {
                        ext[i] = rng.random_range(-0.4..0.4);
                    }
                }
                for i in [idx::VX, idx::VY, idx::VZ, idx::WX, idx::WY, idx::WZ] {
                    ext[i] = rng.random_range(-1.5..1.5);
                }
                ext[WHEEL] = rng.random_range(-20.0..20.0);
                ext[WHEEL + 1] = rng.random_range(-20.0..20.0);
                let spring_scale = if rng.random_bool(0.5) { 1e-4 } else { 0.05 };
                for j in 0..3 * N_WHEELS {
                    ext[SPRING + j] = rng.random_range(-spring_scale..spring_scale);
                }
                let x = body_state(&ext);
                let r = Attitude::of(&x).r;
                let rt = r.transpose();
                let n = plant.plane.normal;
                let down_b = -(rt * n);
                let p = Vector3::new(x[idx::X], x[idx::Y], x[idx::Z]);
                let v = Vector3::new(x[idx::VX], x[idx::VY], x[idx::VZ]);
                let w = Vector3::new(x[idx::WX], x[idx::WY], x[idx::WZ]);
                let height = plant.plane.height(&p);
                let lanes = plant.wheel_forces(&ext, &r, &down_b, height, &w, &v, &law);
                plant.ext = ext;
                let report = plant.wheel_report(&r, &down_b, height, v.dot(&n), &w, &law);
                let close = |a: f64, b: f64, j: usize, what: &str| {
                    assert!(
                        (a - b).abs() <= 1e-12 * (1.0 + b.abs()),
                        "{tilt_deg} deg, wheel {j}, {what}: kernel {a}, law {b}"
                    );
                };
                for j in 0..N_WHEELS {
                    let c = plant.body.rotor_position[j];
                    let axle = plant.body.rotor_axis[j];
                    let pt = rim_lowest_point(&c, &axle, &down_b, robot.wheels.radius);
                    let lateral = wheel_lateral(&(r * axle), &n);
                    let depth = down_b.dot(&pt) - height;
                    assert_eq!(lanes.touching[j], depth > 0.0, "wheel {j} depth {depth}");
                    // The post-step report (no spin: it moves the point along the ground).
                    let v_n = (v + r * w.cross(&pt)).dot(&n);
                    assert_eq!(report.touching[j], depth > 0.0);
                    close(report.approach_speed[j], -v_n, j, "approach speed");
                    let s = Vector3::new(
                        ext[SPRING + 3 * j],
                        ext[SPRING + 3 * j + 1],
                        ext[SPRING + 3 * j + 2],
                    );
                    if depth <= 0.0 {
                        assert_eq!(report.normal_force[j], 0.0);
                        assert!((0..3).all(|i| report.spring[i][j] == 0.0));
                        continue;
                    }
                    let f_n = law.normal_force(depth, v_n);
                    close(report.normal_force[j], f_n, j, "report normal force");
                    let held = law.limit_spring(&n, &s, f_n, lateral.as_ref());
                    for i in 0..3 {
                        close(report.spring[i][j], held[i], j, "held spring");
                    }
                    touching += 1;
                    flat += usize::from(lateral.is_none());
                    let spin_axis = axle * SPIN_SIGN[j];
                    let rim = pt - c;
                    let spin = ext[WHEEL + WHEEL_SIDE[j]];
                    let v_point = v + r * (w.cross(&pt) + spin_axis.cross(&rim) * spin);
                    let (f_world, f_n, s_dot) =
                        law.force(&n, depth, &v_point, &s, lateral.as_ref());
                    let f_t = f_world - n * f_n;
                    let unlimited =
                        -(s * law.tangential_stiffness) - s_dot * law.tangential_damping;
                    sliding += usize::from((f_t - unlimited).norm() > 1e-9 * unlimited.norm());
                    let f_b = rt * f_world;
                    let axial = spin_axis.dot(&rim.cross(&f_b));
                    let tq = pt.cross(&f_b) - spin_axis * axial;
                    for i in 0..3 {
                        close(lanes.force[i][j], f_b[i], j, "force");
                        close(lanes.torque[i][j], tq[i], j, "torque");
                        close(lanes.spring_rate[i][j], s_dot[i], j, "spring rate");
                    }
                    close(lanes.axial[j], axial, j, "axial torque");
                }
            }
        }
        // Every branch of the law was compared, many times.
        assert!(touching > 500, "{touching} touching wheels");
        assert!(sliding > 50, "{sliding} sliding wheels");
        assert!(flat > 50, "{flat} flat wheels");
    }
}
