//! The plant file (`config/plant.toml`): integration step and effects.
//!
//! Every effect is a section `[effects.<name>]`. A section that is present
//! switches its effect on (with defaults for every key it leaves out), unless
//! it says `enabled = false`; an absent section leaves the effect off.
//! Unknown effect names and unknown keys are errors naming the file, the line
//! and the key path; values are range-checked and errors name the key.

use std::path::{Path, PathBuf};

use atmo_core::cli_numbers::{MAX_SAMPLE_RATE_HZ, MIN_SAMPLE_RATE_HZ};
use atmo_core::config::ArmInertiaConvention;
use atmo_core::config_file::{Checker, ConfigFile};
use serde::Deserialize;

use crate::error::{PlantError, Result};
pub use crate::motor::ThrustCurveConfig;
use atmo_core::ground_effect::GroundEffectConfig;
pub use ground_contact::{GroundContactConfig, MAX_CONTACT_STIFFNESS};

mod ground_contact;
fn default_dt() -> f64 {
    0.001
}
fn default_convention() -> ArmInertiaConvention {
    ArmInertiaConvention::AboutCom
}

/// The whole plant file.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct PlantConfig {
    /// s, fixed RK4 step, in (0, 0.001].
    #[serde(default = "default_dt")]
    pub dt: f64,
    /// How the plant reads the robot file's arm inertia. Default
    /// `"about_com"`: the physically consistent reading, the plant's truth
    /// (the controller's model keeps the authors' reading; see
    /// `atmo_core::config::ArmInertiaConvention`).
    #[serde(default = "default_convention")]
    pub arm_inertia_convention: ArmInertiaConvention,
    #[serde(default)]
    pub effects: EffectsConfig,
    /// Where the config came from (names it in errors found later, e.g. by
    /// the plant when it checks the mass properties).
    #[serde(skip)]
    pub source: PathBuf,
}

atmo_core::params! {
    /// The switchable effects. `None` = off.
    #[derive(Debug, Clone, PartialEq)]
    pub struct EffectsConfig: Default {
        /// `[effects.ground_effect]`: the thrust-gain surface as the truth.
        pub ground_effect: Option<GroundEffectConfig> = None;
        pub motor_lag: Option<MotorLagConfig> = None;
        pub thrust_curve: Option<ThrustCurveConfig> = None;
        pub tilt_mechanism: Option<TiltMechanismConfig> = None;
        pub drag: Option<DragConfig> = None;
        pub wind: Option<WindConfig> = None;
        pub battery_sag: Option<BatterySagConfig> = None;
        pub com_offset: Option<ComOffsetConfig> = None;
        pub thrust_axis: Option<ThrustAxisConfig> = None;
        pub mass_error: Option<MassErrorConfig> = None;
        pub sensors: Option<SensorsConfig> = None;
        pub ground_contact: Option<GroundContactConfig> = None;
    }
    check |effects, c, prefix| {
        // One thrust curve: with `[effects.thrust_curve]` the motor lag's
        // own curve must be 0.
        match (&effects.thrust_curve, &effects.motor_lag) {
            (Some(_), Some(lag)) if lag.curve != 0.0 => Err(c.fail(
                &atmo_core::params::key(prefix, "motor_lag.curve"),
                format!(
                    "0 when [{}] gives the curve",
                    atmo_core::params::key(prefix, "thrust_curve")
                ),
                lag.curve,
            )),
            _ => Ok(()),
        }
    }
}

/// Names of every effect, as written in `[effects.<name>]`.
pub const EFFECT_NAMES: [&str; 12] = [
    "ground_effect",
    "motor_lag",
    "thrust_curve",
    "tilt_mechanism",
    "drag",
    "wind",
    "battery_sag",
    "com_offset",
    "thrust_axis",
    "mass_error",
    "sensors",
    "ground_contact",
];

atmo_core::params! {
    /// `[effects.motor_lag]`: first-order lag from command to thrust.
    ///
    /// `tau t_dot = c(u) - t`, with the thrust curve `c(u) = (1 - f) u + f u^2`
    /// (f = `curve`, 0 = linear as in the controller's model) and rotor thrust
    /// `kT t`.
    #[derive(Debug, Clone, PartialEq)]
    pub struct MotorLagConfig: Default {
        /// Whether the effect is on (a present section is, unless it says
        /// false).
        pub enabled: bool = true;
        /// The lag's time constant tau.
        pub time_constant: f64 = 0.03, range 1e-4..=1.0, unit "s";
        /// Thrust-curve nonlinearity f (0 when `[effects.thrust_curve]`
        /// gives the curve).
        pub curve: f64 = 0.0, range 0.0..=1.0;
    }
}

atmo_core::params! {
    /// `[effects.tilt_mechanism]`: the self-locking screw linkage.
    ///
    /// On: varphi integrates the commanded tilt velocity limited to `rate_max`
    /// (default: the robot file's `limits.tilt_rate_max`), and the encoder
    /// reports whole counts. Off: varphi integrates the command unlimited and
    /// the encoder reports continuous counts. Either way loads never move the
    /// tilt (the screw is self-locking) and it stays within [0, tilt_max].
    #[derive(Debug, Clone, PartialEq)]
    pub struct TiltMechanismConfig: Default {
        /// Whether the effect is on (a present section is, unless it says
        /// false).
        pub enabled: bool = true;
        /// The screw's largest tilt rate; absent: the robot file's limit.
        pub rate_max: Option<f64> = None, range 1e-3..=100.0, unit "rad/s";
    }
}

atmo_core::params! {
    /// `[effects.drag]`: rotor drag (linear) and body drag (quadratic).
    ///
    /// Rotor i at hub velocity `v_i` relative to the air (body frame) feels
    /// `-k_r t_i (v_i - (v_i . n_i) n_i) - k_a t_i (v_i . n_i) n_i` at its hub
    /// (t_i its normalized thrust): the in-plane H-force and the thrust lost
    /// to axial inflow (a rotor climbing into its own inflow, linearized);
    /// the body feels `-1/2 rho CdA_k |v_k| v_k` per body axis k at B.
    #[derive(Debug, Clone, PartialEq)]
    pub struct DragConfig: Default {
        /// Whether the effect is on (a present section is, unless it says
        /// false).
        pub enabled: bool = true;
        /// In-plane rotor drag per rotor at full thrust.
        pub rotor_drag: f64 = 0.3, range 0.0..=100.0, unit "N/(m/s)";
        /// Axial drag per rotor at full thrust: the thrust lost when the
        /// air comes through the disc against the thrust.
        pub axial_drag: f64 = 0.0, range 0.0..=100.0, unit "N/(m/s)";
        /// Drag coefficient times area along body x, y, z.
        pub body_cd_area: [f64; 3] = [0.03, 0.05, 0.10], range 0.0..=10.0, unit "m^2";
        /// Air density.
        pub air_density: f64 = 1.225, range 0.0..=10.0, unit "kg/m^3";
    }
}

atmo_core::params! {
    /// One scripted gust: a 1 - cos pulse of peak `velocity` (NED) from
    /// `t` to `t + duration`.
    #[derive(Debug, Clone, PartialEq)]
    pub struct GustConfig {
        /// Start.
        pub t: f64, range 0.0..=1e6, unit "s";
        /// Length of the pulse.
        pub duration: f64, range 1e-3..=1e6, unit "s";
        /// Peak wind of the pulse (NED).
        pub velocity: [f64; 3], range -50.0..=50.0, unit "m/s";
    }
}

atmo_core::params! {
    /// `[effects.wind]`: steady wind plus turbulence plus scripted gusts.
    ///
    /// Wind (NED, m/s) = `steady` + first-order Gauss-Markov turbulence per axis
    /// (standard deviation `turbulence_std`, correlation time
    /// `turbulence_time`) + the scripted 1 - cos gusts.
    #[derive(Debug, Clone, PartialEq)]
    pub struct WindConfig: Default {
        /// Whether the effect is on (a present section is, unless it says
        /// false).
        pub enabled: bool = true;
        /// Steady wind (NED).
        pub steady: [f64; 3] = [0.0; 3], range -50.0..=50.0, unit "m/s";
        /// Turbulence's standard deviation per axis.
        pub turbulence_std: [f64; 3] = [0.3, 0.3, 0.1], range 0.0..=20.0, unit "m/s";
        /// Turbulence's correlation time.
        pub turbulence_time: f64 = 1.0, range 1e-3..=1e4, unit "s";
        /// Scripted gusts (`[[effects.wind.gusts]]`).
        pub gusts: Vec<GustConfig> = Vec::new();
    }
}

atmo_core::params! {
    /// `[effects.battery_sag]`: thrust scale that falls with energy used.
    ///
    /// Electrical power per rotor `P_full t_i^(3/2)` (momentum theory), energy
    /// used `E`, thrust scale `1 - sag E / capacity` (held at or above 1 - sag).
    #[derive(Debug, Clone, PartialEq)]
    pub struct BatterySagConfig: Default {
        /// Whether the effect is on (a present section is, unless it says
        /// false).
        pub enabled: bool = true;
        /// The battery's capacity.
        pub capacity_wh: f64 = 110.0, range 1e-3..=1e6, unit "Wh";
        /// Energy already used at the start.
        pub used_wh: f64 = 0.0, range 0.0..=*capacity_wh, unit "Wh";
        /// Electrical power of one rotor at full thrust.
        pub full_power_w: f64 = 560.0, range 1e-3..=1e6, unit "W";
        /// Fraction of thrust lost when the battery is empty.
        pub sag: f64 = 0.15, range 0.0..=0.9;
    }
}

atmo_core::params! {
    /// `[effects.thrust_axis]`: the thrust turned by the small rotation
    /// `tilt = (about body x, about body y)` (rad) against the body frame the
    /// pose is measured in: the body feels `tilt x F_T` at B besides the
    /// thrust `F_T`. What a motion-capture body frame a degree or two off the
    /// rotor plane, or rotors mounted that much off, look like.
    #[derive(Debug, Clone, PartialEq)]
    pub struct ThrustAxisConfig: Default {
        /// Whether the effect is on (a present section is, unless it says
        /// false).
        pub enabled: bool = true;
        /// The rotation about body x and y.
        pub tilt: [f64; 2] = [0.0; 2], range -0.2..=0.2, unit "rad";
    }
}

atmo_core::params! {
    /// `[effects.com_offset]`: the real mass distribution shifted by `offset`
    /// (body frame) against the model's.
    #[derive(Debug, Clone, PartialEq)]
    pub struct ComOffsetConfig: Default {
        /// Whether the effect is on (a present section is, unless it says
        /// false).
        pub enabled: bool = true;
        /// The shift (body frame).
        pub offset: [f64; 3] = [0.005, -0.003, 0.002], range -0.1..=0.1, unit "m";
    }
}

atmo_core::params! {
    /// `[effects.mass_error]`: the real mass and inertia as scale factors of
    /// the model's (mass and first moment scale with `mass_scale`, the inertia
    /// about B with `inertia_scale`).
    #[derive(Debug, Clone, PartialEq)]
    pub struct MassErrorConfig: Default {
        /// Whether the effect is on (a present section is, unless it says
        /// false).
        pub enabled: bool = true;
        /// Real mass over the model's.
        pub mass_scale: f64 = 1.03, range 0.5..=2.0;
        /// Real inertia about B over the model's.
        pub inertia_scale: f64 = 1.08, range 0.5..=2.0;
    }
}

atmo_core::params! {
    /// `[effects.sensors]`: what the controller sees.
    ///
    /// A motion-capture estimate of the full state at `rate_hz`, each sample the
    /// true state `latency` s old plus white Gaussian noise; the autopilot's
    /// own estimate, the same sample with a correlated vertical-velocity
    /// error; and a ground-contact
    /// signal, true while the wheels carry more than `contact_threshold` N.
    /// Off: the estimate is the true state at every plant step.
    #[derive(Debug, Clone, PartialEq)]
    pub struct SensorsConfig: Default {
        /// Whether the effect is on (a present section is, unless it says
        /// false).
        pub enabled: bool = true;
        /// Estimate rate.
        pub rate_hz: f64 = 120.0, range MIN_SAMPLE_RATE_HZ..=MAX_SAMPLE_RATE_HZ, unit "Hz";
        /// Age of each estimate.
        pub latency: f64 = 0.008, range 0.0..=0.5, unit "s";
        /// Position noise (standard deviation).
        pub position_std: f64 = 0.0005, range 0.0..=1.0, unit "m";
        /// Attitude noise (standard deviation).
        pub attitude_std: f64 = 0.002, range 0.0..=1.0, unit "rad";
        /// Velocity noise (standard deviation).
        pub velocity_std: f64 = 0.01, range 0.0..=10.0, unit "m/s";
        /// Body-rate noise (standard deviation).
        pub rate_std: f64 = 0.02, range 0.0..=10.0, unit "rad/s";
        /// Total wheel normal force above which the robot reports ground
        /// contact.
        pub contact_threshold: f64 = 5.0, range 0.0..=1000.0, unit "N";
        /// The autopilot's own estimate (PX4's EKF on its IMU and
        /// barometer, the flight stack's fallback when the motion capture
        /// is lost) is each motion-capture sample with an error on its
        /// vertical velocity: a first-order Gauss-Markov process of this
        /// standard deviation (the barometer's drift, the rotors' wash on
        /// its pressure). 0: the motion capture's sample as it is.
        pub autopilot_vz_error_std: f64 = 0.0, range 0.0..=2.0, unit "m/s";
        /// The correlation time of that error.
        pub autopilot_vz_error_time: f64 = 1.0, range 0.01..=1000.0, unit "s";
        /// The ESCs' speed reports (what PX4's `esc_status` carries): each
        /// rotor's speed (the square root of its thrust state, a fraction
        /// of full) plus white noise of this standard deviation, one draw a
        /// control tick; 0: exact. Drawn by the simulator's I/O
        /// (`atmo_sim::sim_io`), not by the plant's step.
        pub rotor_speed_std: f64 = 0.0, range 0.0..=0.5;
    }
}

/// Largest slope the plant models (deg).
pub const MAX_SLOPE_DEG: f64 = 25.0;

atmo_core::params! {
    /// The ground: a plane through height `height` (m, up) above the world
    /// origin, rising at `slope_deg` towards the compass direction
    /// `slope_azimuth_deg` (0 = north = +x, 90 = east = +y).
    #[derive(Debug, Clone, Copy, PartialEq)]
    pub struct TerrainConfig: Default {
        /// Height of the plane at the origin (up).
        pub height: f64 = 0.0, range -1000.0..=10000.0, unit "m";
        /// The plane's slope.
        pub slope_deg: f64 = 0.0, range 0.0..=MAX_SLOPE_DEG, unit "deg";
        /// The compass direction the plane rises towards.
        pub slope_azimuth_deg: f64 = 0.0, range -360.0..=360.0, unit "deg";
    }
}

impl TerrainConfig {
    pub fn flat(height: f64) -> Self {
        Self {
            height,
            slope_deg: 0.0,
            slope_azimuth_deg: 0.0,
        }
    }

    /// Range checks; keys are named `{prefix}.<key>`.
    pub fn validate(&self, c: &Checker<'_>, prefix: &str) -> Result<()> {
        Ok(atmo_core::params::Params::check(self, c, prefix)?)
    }
}

impl EffectsConfig {
    /// Every effect off.
    pub fn none() -> Self {
        Self::default()
    }

    /// The thrust axis's rotation vector (body x, y, 0), when it is on.
    pub fn thrust_axis_rotation(&self) -> Option<[f64; 3]> {
        self.thrust_axis
            .as_ref()
            .filter(|e| e.enabled)
            .map(|e| [e.tilt[0], e.tilt[1], 0.0])
    }

    /// The centre of mass's offset (body frame, m), when it is on.
    pub fn com_offset_vector(&self) -> Option<nalgebra::Vector3<f64>> {
        self.com_offset
            .as_ref()
            .filter(|e| e.enabled)
            .map(|e| nalgebra::Vector3::from(e.offset))
    }

    /// The mass and inertia scales, when the mass error is on.
    pub fn mass_error_scales(&self) -> Option<(f64, f64)> {
        self.mass_error
            .as_ref()
            .filter(|e| e.enabled)
            .map(|e| (e.mass_scale, e.inertia_scale))
    }

    /// Every effect on with its default parameters.
    pub fn all() -> Self {
        Self {
            ground_effect: Some(GroundEffectConfig::default()),
            motor_lag: Some(MotorLagConfig::default()),
            thrust_curve: None,
            tilt_mechanism: Some(TiltMechanismConfig::default()),
            drag: Some(DragConfig::default()),
            wind: Some(WindConfig::default()),
            battery_sag: Some(BatterySagConfig::default()),
            com_offset: Some(ComOffsetConfig::default()),
            thrust_axis: None,
            mass_error: Some(MassErrorConfig::default()),
            sensors: Some(SensorsConfig::default()),
            ground_contact: Some(GroundContactConfig::default()),
        }
    }

    /// These effects with every section that `over` has replaced by `over`'s.
    #[must_use]
    pub fn overridden_by(&self, over: &Self) -> Self {
        fn pick<T: Clone>(base: Option<&T>, over: Option<&T>) -> Option<T> {
            over.or(base).cloned()
        }
        Self {
            ground_effect: pick(self.ground_effect.as_ref(), over.ground_effect.as_ref()),
            motor_lag: pick(self.motor_lag.as_ref(), over.motor_lag.as_ref()),
            thrust_curve: pick(self.thrust_curve.as_ref(), over.thrust_curve.as_ref()),
            tilt_mechanism: pick(self.tilt_mechanism.as_ref(), over.tilt_mechanism.as_ref()),
            drag: pick(self.drag.as_ref(), over.drag.as_ref()),
            wind: pick(self.wind.as_ref(), over.wind.as_ref()),
            battery_sag: pick(self.battery_sag.as_ref(), over.battery_sag.as_ref()),
            com_offset: pick(self.com_offset.as_ref(), over.com_offset.as_ref()),
            thrust_axis: pick(self.thrust_axis.as_ref(), over.thrust_axis.as_ref()),
            mass_error: pick(self.mass_error.as_ref(), over.mass_error.as_ref()),
            sensors: pick(self.sensors.as_ref(), over.sensors.as_ref()),
            ground_contact: pick(self.ground_contact.as_ref(), over.ground_contact.as_ref()),
        }
    }

    /// The names of the effects that are on.
    pub fn enabled_names(&self) -> Vec<&'static str> {
        let on = [
            self.ground_effect.as_ref().is_some_and(|e| e.enabled),
            self.motor_lag.as_ref().is_some_and(|e| e.enabled),
            self.thrust_curve.as_ref().is_some_and(|e| e.enabled),
            self.tilt_mechanism.as_ref().is_some_and(|e| e.enabled),
            self.drag.as_ref().is_some_and(|e| e.enabled),
            self.wind.as_ref().is_some_and(|e| e.enabled),
            self.battery_sag.as_ref().is_some_and(|e| e.enabled),
            self.com_offset.as_ref().is_some_and(|e| e.enabled),
            self.thrust_axis.as_ref().is_some_and(|e| e.enabled),
            self.mass_error.as_ref().is_some_and(|e| e.enabled),
            self.sensors.as_ref().is_some_and(|e| e.enabled),
            self.ground_contact.as_ref().is_some_and(|e| e.enabled),
        ];
        EFFECT_NAMES
            .iter()
            .zip(on)
            .filter(|(_, on)| *on)
            .map(|(n, _)| *n)
            .collect()
    }

    /// Range checks of every present section; keys are named `{prefix}.<effect>.<key>`.
    pub fn validate(&self, c: &Checker<'_>, prefix: &str) -> Result<()> {
        Ok(atmo_core::params::Params::check(self, c, prefix)?)
    }
}

impl PlantConfig {
    /// Every effect off: the plant is atmo-core's model integrated by RK4.
    pub fn ideal() -> Self {
        Self {
            dt: default_dt(),
            arm_inertia_convention: default_convention(),
            effects: EffectsConfig::none(),
            source: PathBuf::from("(built-in ideal plant)"),
        }
    }

    /// Every effect on with its defaults.
    pub fn full() -> Self {
        Self {
            dt: default_dt(),
            arm_inertia_convention: default_convention(),
            effects: EffectsConfig::all(),
            source: PathBuf::from("(built-in full plant)"),
        }
    }
}

impl ConfigFile for PlantConfig {
    type Error = PlantError;

    /// Remembers the file: the plant names it in errors it finds later.
    fn locate(&mut self, file: &Path) {
        self.source = file.to_path_buf();
    }

    /// Range checks; errors name `file` and the key.
    fn validate(&self, file: &Path) -> Result<()> {
        let c = Checker::new(file);
        c.range("dt", self.dt, 1e-6..=0.001, "s")?;
        self.effects.validate(&c, "effects")
    }
}
