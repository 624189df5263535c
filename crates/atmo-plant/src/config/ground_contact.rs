//! `[effects.ground_contact]`: the contact law's parameters and defaults.

use atmo_core::config_file::default_true;
use serde::Deserialize;

/// Largest contact stiffness the plant resolves at its largest step, N/m
/// (see the check in `super::EffectsConfig`'s validation).
pub const MAX_CONTACT_STIFFNESS: f64 = 1e6;

/// `[effects.ground_contact]`: compliant wheel contacts, wheel drive, and
/// crash detection (see [`crate::contact`] for the law).
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct GroundContactConfig {
    #[serde(default = "default_true")]
    pub enabled: bool,
    /// N/m, normal stiffness per contact point.
    #[serde(default = "GroundContactConfig::default_stiffness")]
    pub stiffness: f64,
    /// N s/m, normal damping per contact point.
    #[serde(default = "GroundContactConfig::default_damping")]
    pub damping: f64,
    /// Coulomb friction coefficient (body points, and wheels when rolling).
    #[serde(default = "GroundContactConfig::default_friction")]
    pub friction: f64,
    /// Coulomb friction coefficient of a wheel sliding sideways.
    #[serde(default = "GroundContactConfig::default_lateral_friction")]
    pub lateral_friction: f64,
    /// N/m, tangential (stiction) spring per contact point.
    #[serde(default = "GroundContactConfig::default_tangential_stiffness")]
    pub tangential_stiffness: f64,
    /// N s/m, tangential damping per contact point.
    #[serde(default = "GroundContactConfig::default_tangential_damping")]
    pub tangential_damping: f64,
    /// kg m^2, spin inertia of one side's drive (two wheels on a belt).
    #[serde(default = "GroundContactConfig::default_wheel_inertia")]
    pub wheel_inertia: f64,
    /// N m s/rad, proportional gain of each side's speed controller.
    #[serde(default = "GroundContactConfig::default_wheel_kp")]
    pub wheel_kp: f64,
    /// N m/rad, integral gain of each side's speed controller.
    #[serde(default = "GroundContactConfig::default_wheel_ki")]
    pub wheel_ki: f64,
    /// N m, torque limit of each side's drive motor.
    #[serde(default = "GroundContactConfig::default_wheel_torque_max")]
    pub wheel_torque_max: f64,
    /// m, the base box (body frame, relative to B): lower corner.
    #[serde(default = "GroundContactConfig::default_box_min")]
    pub base_box_min: [f64; 3],
    /// m, the base box: upper corner.
    #[serde(default = "GroundContactConfig::default_box_max")]
    pub base_box_max: [f64; 3],
    /// m/s, a wheel hitting the ground faster than this is a crash.
    #[serde(default = "GroundContactConfig::default_crash_speed")]
    pub crash_speed: f64,
    /// deg, tilt of the body z axis from the ground normal, while touching
    /// the ground, beyond which the robot has tipped over.
    #[serde(default = "GroundContactConfig::default_tip_over_deg")]
    pub tip_over_deg: f64,
}

impl GroundContactConfig {
    fn default_stiffness() -> f64 {
        20000.0
    }
    fn default_damping() -> f64 {
        200.0
    }
    fn default_friction() -> f64 {
        0.8
    }
    fn default_lateral_friction() -> f64 {
        0.45
    }
    fn default_tangential_stiffness() -> f64 {
        5000.0
    }
    fn default_tangential_damping() -> f64 {
        100.0
    }
    fn default_wheel_inertia() -> f64 {
        0.01
    }
    fn default_wheel_kp() -> f64 {
        0.5
    }
    fn default_wheel_ki() -> f64 {
        10.0
    }
    fn default_wheel_torque_max() -> f64 {
        3.0
    }
    fn default_box_min() -> [f64; 3] {
        [-0.10, -0.06, -0.05]
    }
    fn default_box_max() -> [f64; 3] {
        [0.10, 0.06, 0.06]
    }
    fn default_crash_speed() -> f64 {
        2.0
    }
    fn default_tip_over_deg() -> f64 {
        60.0
    }
}

impl Default for GroundContactConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            stiffness: Self::default_stiffness(),
            damping: Self::default_damping(),
            friction: Self::default_friction(),
            lateral_friction: Self::default_lateral_friction(),
            tangential_stiffness: Self::default_tangential_stiffness(),
            tangential_damping: Self::default_tangential_damping(),
            wheel_inertia: Self::default_wheel_inertia(),
            wheel_kp: Self::default_wheel_kp(),
            wheel_ki: Self::default_wheel_ki(),
            wheel_torque_max: Self::default_wheel_torque_max(),
            base_box_min: Self::default_box_min(),
            base_box_max: Self::default_box_max(),
            crash_speed: Self::default_crash_speed(),
            tip_over_deg: Self::default_tip_over_deg(),
        }
    }
}
