//! Robot parameters: the layout of the TOML robot file, as data.
//!
//! Loading goes through [`crate::config_file::ConfigFile`] (strict parsing,
//! errors with file, line and key path); the physical checks, which need the
//! linkage and the model, live in [`crate::validate`].

use nalgebra::Matrix3;
use serde::Deserialize;

crate::params! {
    /// The whole robot file (`config/atmo.toml`). Besides each value's
    /// range, the physical checks of [`crate::validate`]: the linkage
    /// reaches every tilt, the rotors carry the weight with the reserve,
    /// the composite inertia is physical.
    #[derive(Debug, Clone, PartialEq)]
    pub struct RobotConfig {
        pub environment: Environment;
        pub base: Base;
        pub arm: Arm;
        pub rotor: Rotor;
        pub wheels: Wheels;
        pub linkage: LinkageConfig;
        pub limits: Limits;
    }
}

crate::params! {
    /// `[environment]`.
    #[derive(Debug, Clone, PartialEq)]
    pub struct Environment {
        /// Gravitational acceleration.
        pub gravity: f64, range 0.1..=100.0, unit "m/s^2";
    }
}

crate::params! {
    /// A symmetric inertia tensor by its six entries (positive definite,
    /// principal moments that satisfy the triangle inequality).
    #[derive(Debug, Clone, Copy, PartialEq)]
    pub struct Inertia {
        /// Moment about x.
        pub xx: f64, unit "kg m^2";
        /// Moment about y.
        pub yy: f64, unit "kg m^2";
        /// Moment about z.
        pub zz: f64, unit "kg m^2";
        /// Product of inertia xy.
        pub xy: f64, unit "kg m^2";
        /// Product of inertia xz.
        pub xz: f64, unit "kg m^2";
        /// Product of inertia yz.
        pub yz: f64, unit "kg m^2";
    }
    check |inertia, c, prefix| c.inertia(prefix, &inertia.matrix())
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

crate::params! {
    /// `[base]`: the central body.
    #[derive(Debug, Clone, PartialEq)]
    pub struct Base {
        /// Mass; its centre of mass is the base origin B.
        pub mass: f64, range 1e-3..=1e3, unit "kg";
        /// About B, body frame.
        pub inertia: Inertia;
    }
}

crate::params! {
    /// `[arm]`: the right arm (the left one mirrors it).
    #[derive(Debug, Clone, PartialEq)]
    pub struct Arm {
        /// Mass of one arm (with its two rotors' mounts).
        pub mass: f64, range 1e-4..=1e3, unit "kg";
        pub inertia: Inertia;
        /// How `inertia` is used; see [`ArmInertiaConvention`].
        pub inertia_convention: ArmInertiaConvention;
        /// Base origin B to the right hinge A, body frame.
        pub base_to_hinge: [f64; 3], range Finite, unit "m";
        /// Hinge A to the right arm's centre of mass, arm frame.
        pub hinge_to_com: [f64; 3], range Finite, unit "m";
        /// Hinge A to rotor 1, arm frame.
        pub hinge_to_rotor1: [f64; 3], range Finite, unit "m";
    }
}

/// How the listed arm inertia enters the model.
///
/// The listed tensor (Ixx 0.0087, Iyy 0.037, Izz 0.044 kg m^2 for a 1.54 kg
/// arm whose CoM is 0.17 m from the hinge) can only be a tensor about the
/// arm's own centre of mass: about the hinge, Ixx would be at least
/// m |r_AG|^2 = 0.044. The authors' model nevertheless treats it as the tensor
/// about the hinge (subtracting `m [r_AG]x^T [r_AG]x`), with the xz and yz
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

crate::params! {
    /// `[rotor]`: each of the four rotors.
    #[derive(Debug, Clone, PartialEq)]
    pub struct Rotor {
        /// Mass of one rotor.
        pub mass: f64, range 1e-5..=1e2, unit "kg";
        /// Principal (xx, yy, zz) in the rotor frame.
        pub inertia: [f64; 3], unit "kg m^2";
        /// Thrust at full command.
        pub k_thrust: f64, range 1e-3..=1e5, unit "N";
        /// Reaction moment per unit thrust.
        pub k_moment: f64, range 0.0..=1.0, unit "m";
        /// Reaction-moment sign per rotor, each +1 or -1.
        pub yaw_sign: [f64; 4];
        /// Time constant of the thrust's first-order response to a command
        /// (0: immediate, the MPC's model and what a robot file without it
        /// flew).
        pub time_constant: f64 = 0.0, range 0.0..=1.0, unit "s";
    }
    check |_table, c, prefix| {
        let [ixx, iyy, izz] = *inertia;
        c.inertia(
            &crate::params::key(prefix, "inertia"),
            &nalgebra::Matrix3::from_diagonal(&nalgebra::Vector3::new(ixx, iyy, izz)),
        )?;
        for (i, s) in yaw_sign.iter().enumerate() {
            if *s != 1.0 && *s != -1.0 {
                return Err(c.fail(&format!("{}[{i}]", crate::params::key(prefix, "yaw_sign")), "+1 or -1", s));
            }
        }
        Ok(())
    }
}

crate::params! {
    /// `[wheels]`.
    #[derive(Debug, Clone, PartialEq)]
    pub struct Wheels {
        /// Wheel radius.
        pub radius: f64, range 1e-3..=10.0, unit "m";
        /// Half the distance between the left and right wheels.
        pub half_track: f64, range 1e-3..=10.0, unit "m";
        /// Wheel motor limit.
        pub max_rate: f64, range 1e-2..=1e4, unit "rad/s";
    }
}

crate::params! {
    /// `[linkage]`: the tilt mechanism's geometry (it must reach every
    /// tilt up to `limits.tilt_max_deg`).
    #[derive(Debug, Clone, PartialEq)]
    pub struct LinkageConfig {
        /// Linkage offset h.
        pub h: f64, range 1e-4..=10.0, unit "m";
        /// Link length d1.
        pub d1: f64, range 1e-4..=10.0, unit "m";
        /// Link length d2.
        pub d2: f64, range 1e-4..=10.0, unit "m";
        /// The fixed pivot D = (Dx, Dy).
        pub d: [f64; 2], range Finite, unit "m";
        /// Screw travel per revolution.
        pub thread_pitch: f64, range 1e-5..=1.0, unit "m";
        /// Encoder counts per output revolution.
        pub counts_per_rev: f64, range 1.0..=1e9, unit "counts";
    }
}

crate::params! {
    /// `[limits]`: the tilt and thrust limits and the mode heights.
    #[derive(Debug, Clone, PartialEq)]
    pub struct Limits {
        /// The tilt mechanism's speed.
        pub tilt_rate_max: f64, range 1e-3..=100.0, unit "rad/s";
        /// Mechanical end stop (the drive configuration).
        pub tilt_max_deg: f64, range 1.0..=90.0, unit "deg";
        /// Tilt limit in free flight.
        pub tilt_flight_max_deg: f64, range 0.0..=*tilt_max_deg, unit "deg";
        /// Between `tilt_flight_max_deg` and `tilt_max_deg`.
        pub tilt_transition_max_deg: f64, unit "deg";
        /// Full thrust over the weight the robot must keep.
        pub thrust_reserve: f64, range 1.0..=10.0;
        /// z* (> 0).
        pub transition_height: f64, range 1e-2..=100.0, unit "m";
        /// z_varphi, above `transition_height`.
        pub morph_height: f64, unit "m";
    }
    check |_table, c, prefix| {
        let key = |name| crate::params::key(prefix, name);
        if tilt_transition_max_deg < tilt_flight_max_deg || tilt_transition_max_deg > tilt_max_deg {
            return Err(c.fail(
                &key("tilt_transition_max_deg"),
                format!(
                    "tilt limits in order: tilt_flight_max_deg ({tilt_flight_max_deg}) <= tilt_transition_max_deg <= tilt_max_deg ({tilt_max_deg})"
                ),
                tilt_transition_max_deg,
            ));
        }
        if !(morph_height.is_finite() && morph_height > transition_height) {
            return Err(c.fail(
                &key("morph_height"),
                format!("a height above {} ({transition_height} m)", key("transition_height")),
                morph_height,
            ));
        }
        Ok(())
    }
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
