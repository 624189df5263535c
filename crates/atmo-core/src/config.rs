//! Robot parameters: the layout of the TOML robot file, as data.
//!
//! Loading goes through [`crate::config_file::ConfigFile`] (strict parsing,
//! errors with file, line and key path); the physical checks, which need the
//! linkage and the model, live in [`crate::validate`].

use nalgebra::Matrix3;
use serde::Deserialize;

/// The whole robot file (`config/atmo.toml`).
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct RobotConfig {
    pub environment: Environment,
    pub base: Base,
    pub arm: Arm,
    pub rotor: Rotor,
    pub wheels: Wheels,
    pub linkage: LinkageConfig,
    pub limits: Limits,
}

#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Environment {
    /// m/s^2.
    pub gravity: f64,
}

/// A symmetric inertia tensor by its six entries (kg m^2).
#[derive(Debug, Clone, Copy, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Inertia {
    pub xx: f64,
    pub yy: f64,
    pub zz: f64,
    pub xy: f64,
    pub xz: f64,
    pub yz: f64,
}

impl Inertia {
    /// The tensor as a matrix, entries placed as written.
    pub fn matrix(&self) -> Matrix3<f64> {
        Matrix3::new(
            self.xx, self.xy, self.xz, //
            self.xy, self.yy, self.yz, //
            self.xz, self.yz, self.zz,
        )
    }
}

#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Base {
    /// kg.
    pub mass: f64,
    pub inertia: Inertia,
}

#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Arm {
    /// kg.
    pub mass: f64,
    pub inertia: Inertia,
    /// How `inertia` is used; see [`ArmInertiaConvention`].
    pub inertia_convention: ArmInertiaConvention,
    /// m, base origin B to the right hinge A, body frame.
    pub base_to_hinge: [f64; 3],
    /// m, hinge A to the right arm's centre of mass, arm frame.
    pub hinge_to_com: [f64; 3],
    /// m, hinge A to rotor 1, arm frame.
    pub hinge_to_rotor1: [f64; 3],
}

/// How the listed arm inertia enters the model.
///
/// The listed tensor (Ixx 0.0087, Iyy 0.037, Izz 0.044 kg m^2 for a 1.54 kg
/// arm whose CoM is 0.17 m from the hinge) can only be a tensor about the
/// arm's own centre of mass: about the hinge, Ixx would be at least
/// m |r_AG|^2 = 0.044. The authors' model nevertheless treats it as the tensor
/// about the hinge (subtracting m [r_AG]x^T [r_AG]x), with the xz and yz
/// products negated on the right arm. That under-estimates the roll and yaw
/// inertia by about 0.088 kg m^2 and makes the composite inertia indefinite
/// above about 86 deg of tilt.
#[derive(Debug, Clone, Copy, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum ArmInertiaConvention {
    /// As in the authors' model (reproduces their reference data to 1e-14).
    /// The controller's model.
    AuthorsModel,
    /// Physical: the listed tensor is the right arm's about its CoM in the
    /// arm frame; the left arm is its mirror image. The plant's truth.
    AboutCom,
}

#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Rotor {
    /// kg.
    pub mass: f64,
    /// kg m^2, principal (xx, yy, zz) in the rotor frame.
    pub inertia: [f64; 3],
    /// N, thrust at full command.
    pub k_thrust: f64,
    /// m, reaction moment per unit thrust.
    pub k_moment: f64,
    /// Reaction-moment sign per rotor, each +1 or -1.
    pub yaw_sign: [f64; 4],
    /// s, time constant of the thrust's first-order response to a command
    /// (0: immediate, the MPC's model; a robot file without it reads 0).
    #[serde(default)]
    pub time_constant: f64,
}

#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Wheels {
    /// m.
    pub radius: f64,
    /// m, half the distance between the left and right wheels.
    pub half_track: f64,
    /// rad/s.
    pub max_rate: f64,
}

#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct LinkageConfig {
    pub h: f64,
    pub d1: f64,
    pub d2: f64,
    /// m, the fixed pivot D = (Dx, Dy).
    pub d: [f64; 2],
    /// m of screw travel per revolution.
    pub thread_pitch: f64,
    /// Encoder counts per output revolution.
    pub counts_per_rev: f64,
}

#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Limits {
    /// rad/s.
    pub tilt_rate_max: f64,
    pub tilt_max_deg: f64,
    pub tilt_flight_max_deg: f64,
    pub tilt_transition_max_deg: f64,
    pub thrust_reserve: f64,
    /// m, z*.
    pub transition_height: f64,
    /// m, z_varphi.
    pub morph_height: f64,
}

impl Limits {
    pub fn tilt_max(&self) -> f64 {
        self.tilt_max_deg.to_radians()
    }
    pub fn tilt_flight_max(&self) -> f64 {
        self.tilt_flight_max_deg.to_radians()
    }
    pub fn tilt_transition_max(&self) -> f64 {
        self.tilt_transition_max_deg.to_radians()
    }
}
