//! The plant file (`config/plant.toml`): integration step and effects.
//!
//! Every effect is a section `[effects.<name>]`. A section that is present
//! switches its effect on (with defaults for every key it leaves out), unless
//! it says `enabled = false`; an absent section leaves the effect off.
//! Unknown effect names and unknown keys are errors naming the file, the line
//! and the key path; values are range-checked and errors name the key.

use std::path::{Path, PathBuf};

use atmo_core::config::ArmInertiaConvention;
// The serde default of every `enabled` key: a present section is on.
use atmo_core::config_file::{Checker, ConfigFile, default_true};
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

/// The switchable effects. `None` = off.
#[derive(Debug, Clone, Default, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct EffectsConfig {
    pub ground_effect: Option<GroundEffectConfig>,
    pub motor_lag: Option<MotorLagConfig>,
    pub thrust_curve: Option<ThrustCurveConfig>,
    pub tilt_mechanism: Option<TiltMechanismConfig>,
    pub drag: Option<DragConfig>,
    pub wind: Option<WindConfig>,
    pub battery_sag: Option<BatterySagConfig>,
    pub com_offset: Option<ComOffsetConfig>,
    pub thrust_axis: Option<ThrustAxisConfig>,
    pub mass_error: Option<MassErrorConfig>,
    pub sensors: Option<SensorsConfig>,
    pub ground_contact: Option<GroundContactConfig>,
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

/// `[effects.motor_lag]`: first-order lag from command to thrust.
///
/// `tau t_dot = c(u) - t`, with the thrust curve `c(u) = (1 - f) u + f u^2`
/// (f = `curve`, 0 = linear as in the controller's model) and rotor thrust
/// `kT t`.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct MotorLagConfig {
    #[serde(default = "default_true")]
    pub enabled: bool,
    /// s.
    #[serde(default = "MotorLagConfig::default_time_constant")]
    pub time_constant: f64,
    /// Thrust-curve nonlinearity f in [0, 1].
    #[serde(default)]
    pub curve: f64,
}

impl MotorLagConfig {
    fn default_time_constant() -> f64 {
        0.03
    }
}

impl Default for MotorLagConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            time_constant: Self::default_time_constant(),
            curve: 0.0,
        }
    }
}

/// `[effects.tilt_mechanism]`: the self-locking screw linkage.
///
/// On: varphi integrates the commanded tilt velocity limited to `rate_max`
/// (default: the robot file's `limits.tilt_rate_max`), and the encoder
/// reports whole counts. Off: varphi integrates the command unlimited and
/// the encoder reports continuous counts. Either way loads never move the
/// tilt (the screw is self-locking) and it stays within [0, tilt_max].
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct TiltMechanismConfig {
    #[serde(default = "default_true")]
    pub enabled: bool,
    /// rad/s; `None` = the robot file's limit.
    pub rate_max: Option<f64>,
}

impl Default for TiltMechanismConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            rate_max: None,
        }
    }
}

/// `[effects.drag]`: rotor drag (linear) and body drag (quadratic).
///
/// Rotor i at hub velocity `v_i` relative to the air (body frame) feels
/// `-k_r t_i (v_i - (v_i . n_i) n_i) - k_a t_i (v_i . n_i) n_i` at its hub
/// (t_i its normalized thrust): the in-plane H-force and the thrust lost
/// to axial inflow (a rotor climbing into its own inflow, linearized);
/// the body feels `-1/2 rho CdA_k |v_k| v_k` per body axis k at B.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct DragConfig {
    #[serde(default = "default_true")]
    pub enabled: bool,
    /// N per (m/s) per rotor at full thrust.
    #[serde(default = "DragConfig::default_rotor")]
    pub rotor_drag: f64,
    /// N per (m/s) of axial inflow per rotor at full thrust: the thrust
    /// lost when the air comes through the disc against the thrust.
    #[serde(default)]
    pub axial_drag: f64,
    /// m^2, drag coefficient times area along body x, y, z.
    #[serde(default = "DragConfig::default_body")]
    pub body_cd_area: [f64; 3],
    /// kg/m^3.
    #[serde(default = "DragConfig::default_rho")]
    pub air_density: f64,
}

impl DragConfig {
    fn default_rotor() -> f64 {
        0.3
    }
    fn default_body() -> [f64; 3] {
        [0.03, 0.05, 0.10]
    }
    fn default_rho() -> f64 {
        1.225
    }
}

impl Default for DragConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            rotor_drag: Self::default_rotor(),
            axial_drag: 0.0,
            body_cd_area: Self::default_body(),
            air_density: Self::default_rho(),
        }
    }
}

/// One scripted gust: a 1 - cos pulse of peak `velocity` (NED, m/s) from
/// `t` to `t + duration`.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct GustConfig {
    pub t: f64,
    pub duration: f64,
    pub velocity: [f64; 3],
}

/// `[effects.wind]`: steady wind plus turbulence plus scripted gusts.
///
/// Wind (NED, m/s) = `steady` + first-order Gauss-Markov turbulence per axis
/// (standard deviation `turbulence_std`, correlation time
/// `turbulence_time`) + the scripted 1 - cos gusts.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct WindConfig {
    #[serde(default = "default_true")]
    pub enabled: bool,
    #[serde(default)]
    pub steady: [f64; 3],
    #[serde(default = "WindConfig::default_std")]
    pub turbulence_std: [f64; 3],
    #[serde(default = "WindConfig::default_time")]
    pub turbulence_time: f64,
    #[serde(default)]
    pub gusts: Vec<GustConfig>,
}

impl WindConfig {
    fn default_std() -> [f64; 3] {
        [0.3, 0.3, 0.1]
    }
    fn default_time() -> f64 {
        1.0
    }
}

impl Default for WindConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            steady: [0.0; 3],
            turbulence_std: Self::default_std(),
            turbulence_time: Self::default_time(),
            gusts: Vec::new(),
        }
    }
}

/// `[effects.battery_sag]`: thrust scale that falls with energy used.
///
/// Electrical power per rotor `P_full t_i^(3/2)` (momentum theory), energy
/// used `E`, thrust scale `1 - sag E / capacity` (held at or above 1 - sag).
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct BatterySagConfig {
    #[serde(default = "default_true")]
    pub enabled: bool,
    /// Wh.
    #[serde(default = "BatterySagConfig::default_capacity")]
    pub capacity_wh: f64,
    /// Wh already used at the start.
    #[serde(default)]
    pub used_wh: f64,
    /// W, electrical power of one rotor at full thrust.
    #[serde(default = "BatterySagConfig::default_power")]
    pub full_power_w: f64,
    /// Fraction of thrust lost when the battery is empty.
    #[serde(default = "BatterySagConfig::default_sag")]
    pub sag: f64,
}

impl BatterySagConfig {
    fn default_capacity() -> f64 {
        110.0
    }
    fn default_power() -> f64 {
        560.0
    }
    fn default_sag() -> f64 {
        0.15
    }
}

impl Default for BatterySagConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            capacity_wh: Self::default_capacity(),
            used_wh: 0.0,
            full_power_w: Self::default_power(),
            sag: Self::default_sag(),
        }
    }
}

/// `[effects.thrust_axis]`: the thrust turned by the small rotation
/// `tilt = (about body x, about body y)` (rad) against the body frame the
/// pose is measured in: the body feels `tilt x F_T` at B besides the
/// thrust `F_T`. What a motion-capture body frame a degree or two off the
/// rotor plane, or rotors mounted that much off, look like.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ThrustAxisConfig {
    #[serde(default = "default_true")]
    pub enabled: bool,
    /// rad, about body x and y.
    #[serde(default)]
    pub tilt: [f64; 2],
}

/// `[effects.com_offset]`: the real mass distribution shifted by `offset`
/// (m, body frame) against the model's.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ComOffsetConfig {
    #[serde(default = "default_true")]
    pub enabled: bool,
    #[serde(default = "ComOffsetConfig::default_offset")]
    pub offset: [f64; 3],
}

impl ComOffsetConfig {
    fn default_offset() -> [f64; 3] {
        [0.005, -0.003, 0.002]
    }
}

impl Default for ComOffsetConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            offset: Self::default_offset(),
        }
    }
}

/// `[effects.mass_error]`: the real mass and inertia as scale factors of
/// the model's (mass and first moment scale with `mass_scale`, the inertia
/// about B with `inertia_scale`).
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct MassErrorConfig {
    #[serde(default = "default_true")]
    pub enabled: bool,
    #[serde(default = "MassErrorConfig::default_mass")]
    pub mass_scale: f64,
    #[serde(default = "MassErrorConfig::default_inertia")]
    pub inertia_scale: f64,
}

impl MassErrorConfig {
    fn default_mass() -> f64 {
        1.03
    }
    fn default_inertia() -> f64 {
        1.08
    }
}

impl Default for MassErrorConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            mass_scale: Self::default_mass(),
            inertia_scale: Self::default_inertia(),
        }
    }
}

/// `[effects.sensors]`: what the controller sees.
///
/// A motion-capture estimate of the full state at `rate_hz`, each sample the
/// true state `latency` s old plus white Gaussian noise; and a ground-contact
/// signal, true while the wheels carry more than `contact_threshold` N.
/// Off: the estimate is the true state at every plant step.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct SensorsConfig {
    #[serde(default = "default_true")]
    pub enabled: bool,
    /// Hz.
    #[serde(default = "SensorsConfig::default_rate")]
    pub rate_hz: f64,
    /// s.
    #[serde(default = "SensorsConfig::default_latency")]
    pub latency: f64,
    /// m.
    #[serde(default = "SensorsConfig::default_position_std")]
    pub position_std: f64,
    /// rad.
    #[serde(default = "SensorsConfig::default_attitude_std")]
    pub attitude_std: f64,
    /// m/s.
    #[serde(default = "SensorsConfig::default_velocity_std")]
    pub velocity_std: f64,
    /// rad/s.
    #[serde(default = "SensorsConfig::default_rate_std")]
    pub rate_std: f64,
    /// N, total wheel normal force above which the robot reports ground contact.
    #[serde(default = "SensorsConfig::default_contact_threshold")]
    pub contact_threshold: f64,
}

impl SensorsConfig {
    fn default_rate() -> f64 {
        120.0
    }
    fn default_latency() -> f64 {
        0.008
    }
    fn default_position_std() -> f64 {
        0.0005
    }
    fn default_attitude_std() -> f64 {
        0.002
    }
    fn default_velocity_std() -> f64 {
        0.01
    }
    fn default_rate_std() -> f64 {
        0.02
    }
    fn default_contact_threshold() -> f64 {
        5.0
    }
}

impl Default for SensorsConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            rate_hz: Self::default_rate(),
            latency: Self::default_latency(),
            position_std: Self::default_position_std(),
            attitude_std: Self::default_attitude_std(),
            velocity_std: Self::default_velocity_std(),
            rate_std: Self::default_rate_std(),
            contact_threshold: Self::default_contact_threshold(),
        }
    }
}

/// The ground: a plane through height `height` (m, up) above the world
/// origin, rising at `slope_deg` towards the compass direction
/// `slope_azimuth_deg` (0 = north = +x, 90 = east = +y).
#[derive(Debug, Clone, Copy, Default, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct TerrainConfig {
    #[serde(default)]
    pub height: f64,
    #[serde(default)]
    pub slope_deg: f64,
    #[serde(default)]
    pub slope_azimuth_deg: f64,
}

/// Largest slope the plant models (deg).
pub const MAX_SLOPE_DEG: f64 = 25.0;

impl TerrainConfig {
    pub fn flat(height: f64) -> Self {
        Self {
            height,
            slope_deg: 0.0,
            slope_azimuth_deg: 0.0,
        }
    }

    pub fn validate(&self, c: &Checker<'_>, prefix: &str) -> Result<()> {
        c.within(&format!("{prefix}.height"), self.height, -1000.0, 10000.0)?;
        c.within(
            &format!("{prefix}.slope_deg"),
            self.slope_deg,
            0.0,
            MAX_SLOPE_DEG,
        )?;
        c.within(
            &format!("{prefix}.slope_azimuth_deg"),
            self.slope_azimuth_deg,
            -360.0,
            360.0,
        )?;
        Ok(())
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
        if let Some(e) = &self.ground_effect {
            e.validate(c, &format!("{prefix}.ground_effect"))?;
        }
        if let Some(e) = &self.motor_lag {
            let p = format!("{prefix}.motor_lag");
            c.within(&format!("{p}.time_constant"), e.time_constant, 1e-4, 1.0)?;
            c.within(&format!("{p}.curve"), e.curve, 0.0, 1.0)?;
        }
        if let Some(e) = &self.thrust_curve {
            e.validate(c, prefix, self.motor_lag.as_ref().map(|m| m.curve))?;
        }
        if let Some(rate) = self.tilt_mechanism.as_ref().and_then(|e| e.rate_max) {
            c.positive(&format!("{prefix}.tilt_mechanism.rate_max"), rate)?;
        }
        if let Some(e) = &self.drag {
            let p = format!("{prefix}.drag");
            c.within(&format!("{p}.rotor_drag"), e.rotor_drag, 0.0, 100.0)?;
            c.within(&format!("{p}.axial_drag"), e.axial_drag, 0.0, 100.0)?;
            for v in e.body_cd_area {
                c.within(&format!("{p}.body_cd_area"), v, 0.0, 10.0)?;
            }
            c.within(&format!("{p}.air_density"), e.air_density, 0.0, 10.0)?;
        }
        if let Some(e) = &self.wind {
            let p = format!("{prefix}.wind");
            for v in e.steady {
                c.within(&format!("{p}.steady"), v, -50.0, 50.0)?;
            }
            for v in e.turbulence_std {
                c.within(&format!("{p}.turbulence_std"), v, 0.0, 20.0)?;
            }
            c.positive(&format!("{p}.turbulence_time"), e.turbulence_time)?;
            for (i, g) in e.gusts.iter().enumerate() {
                let q = format!("{p}.gusts[{i}]");
                c.within(&format!("{q}.t"), g.t, 0.0, 1e6)?;
                c.positive(&format!("{q}.duration"), g.duration)?;
                for v in g.velocity {
                    c.within(&format!("{q}.velocity"), v, -50.0, 50.0)?;
                }
            }
        }
        if let Some(e) = &self.battery_sag {
            let p = format!("{prefix}.battery_sag");
            c.positive(&format!("{p}.capacity_wh"), e.capacity_wh)?;
            c.within(&format!("{p}.used_wh"), e.used_wh, 0.0, e.capacity_wh)?;
            c.positive(&format!("{p}.full_power_w"), e.full_power_w)?;
            c.within(&format!("{p}.sag"), e.sag, 0.0, 0.9)?;
        }
        if let Some(e) = &self.thrust_axis {
            for v in e.tilt {
                c.within(&format!("{prefix}.thrust_axis.tilt"), v, -0.2, 0.2)?;
            }
        }
        if let Some(e) = &self.com_offset {
            for v in e.offset {
                c.within(&format!("{prefix}.com_offset.offset"), v, -0.1, 0.1)?;
            }
        }
        if let Some(e) = &self.mass_error {
            let p = format!("{prefix}.mass_error");
            c.within(&format!("{p}.mass_scale"), e.mass_scale, 0.5, 2.0)?;
            c.within(&format!("{p}.inertia_scale"), e.inertia_scale, 0.5, 2.0)?;
        }
        if let Some(e) = &self.sensors {
            let p = format!("{prefix}.sensors");
            c.within(&format!("{p}.rate_hz"), e.rate_hz, 1.0, 1000.0)?;
            c.within(&format!("{p}.latency"), e.latency, 0.0, 0.5)?;
            c.within(&format!("{p}.position_std"), e.position_std, 0.0, 1.0)?;
            c.within(&format!("{p}.attitude_std"), e.attitude_std, 0.0, 1.0)?;
            c.within(&format!("{p}.velocity_std"), e.velocity_std, 0.0, 10.0)?;
            c.within(&format!("{p}.rate_std"), e.rate_std, 0.0, 10.0)?;
            c.within(
                &format!("{p}.contact_threshold"),
                e.contact_threshold,
                0.0,
                1000.0,
            )?;
        }
        if let Some(e) = &self.ground_contact {
            atmo_core::params::Params::check(e, c, &format!("{prefix}.ground_contact"))?;
        }
        Ok(())
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
