//! Robot parameters: the TOML file layout, its loading and validation.
//!
//! Loading is strict: unknown keys, missing keys and wrong types are rejected
//! by serde (with the full key path and the line), and every value is then
//! checked against its physical range. Errors name the file, the key and what
//! was expected.

use std::path::{Path, PathBuf};

use nalgebra::{Matrix3, Vector3};
use serde::Deserialize;

use crate::error::{CoreError, Result};

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

/// Parses a TOML document of type `T` strictly, with errors that name `file`,
/// the line and the full key path. Shared by every config file of the project.
pub fn parse_toml<T: serde::de::DeserializeOwned>(text: &str, file: &Path) -> Result<T> {
    let deserializer = toml::Deserializer::new(text);
    serde_path_to_error::deserialize(deserializer).map_err(|err| {
        let key = err.path().to_string();
        let inner = err.into_inner();
        let line = inner.span().map_or(0, |span| {
            text[..span.start.min(text.len())].matches('\n').count() + 1
        });
        CoreError::ConfigParse {
            file: file.to_path_buf(),
            line,
            key: if key == "." { "(document)".into() } else { key },
            message: inner.message().to_string(),
        }
    })
}

/// Reads a whole file for a config loader, naming it on failure.
pub fn read_config_file(path: &Path) -> Result<String> {
    std::fs::read_to_string(path).map_err(|source| CoreError::ConfigRead {
        file: path.to_path_buf(),
        source,
    })
}

/// Collects value checks for one file so that each failure names its key.
pub struct Checker<'a> {
    file: &'a Path,
}

impl<'a> Checker<'a> {
    pub fn new(file: &'a Path) -> Self {
        Self { file }
    }

    pub fn fail(
        &self,
        key: &str,
        expected: impl Into<String>,
        got: impl std::fmt::Display,
    ) -> CoreError {
        CoreError::ConfigValue {
            file: self.file.to_path_buf(),
            key: key.to_string(),
            expected: expected.into(),
            got: got.to_string(),
        }
    }

    /// `value` must be finite and strictly positive.
    pub fn positive(&self, key: &str, value: f64) -> Result<()> {
        if value.is_finite() && value > 0.0 {
            Ok(())
        } else {
            Err(self.fail(key, "a finite value > 0", value))
        }
    }

    /// `value` must be finite and within `[min, max]`.
    pub fn within(&self, key: &str, value: f64, min: f64, max: f64) -> Result<()> {
        if value.is_finite() && (min..=max).contains(&value) {
            Ok(())
        } else {
            Err(self.fail(key, format!("a value in [{min}, {max}]"), value))
        }
    }

    /// Every entry must be finite.
    pub fn finite(&self, key: &str, values: &[f64]) -> Result<()> {
        match values.iter().find(|v| !v.is_finite()) {
            None => Ok(()),
            Some(v) => Err(self.fail(key, "finite numbers", v)),
        }
    }

    /// The tensor must be symmetric positive definite and satisfy the
    /// triangle inequalities of a physical body (principal moments).
    pub fn inertia(&self, key: &str, inertia: &Matrix3<f64>) -> Result<()> {
        self.finite(key, inertia.as_slice())?;
        let eig = inertia.symmetric_eigenvalues();
        let (a, b, c) = (eig[0], eig[1], eig[2]);
        if a <= 0.0 || b <= 0.0 || c <= 0.0 {
            return Err(self.fail(
                key,
                "a positive-definite inertia tensor",
                format!("principal moments ({a:.3e}, {b:.3e}, {c:.3e})"),
            ));
        }
        let tol = 1e-12 * (a + b + c);
        if a + b + tol < c || a + c + tol < b || b + c + tol < a {
            return Err(self.fail(
                key,
                "principal moments that satisfy the triangle inequality",
                format!("({a:.3e}, {b:.3e}, {c:.3e})"),
            ));
        }
        Ok(())
    }
}

impl RobotConfig {
    /// Loads and validates a robot file.
    pub fn load(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        Self::from_toml_str(&read_config_file(path)?, path)
    }

    /// Parses and validates robot parameters; `file` only names the origin in errors.
    pub fn from_toml_str(text: &str, file: impl Into<PathBuf>) -> Result<Self> {
        let file = file.into();
        let config: Self = parse_toml(text, &file)?;
        config.validate(&file)?;
        Ok(config)
    }

    /// The parameters the ATMO authors flew with (the file shipped in `config/atmo.toml`).
    pub fn atmo() -> Self {
        Self::from_toml_str(
            include_str!("../../../config/atmo.toml"),
            "config/atmo.toml",
        )
        .expect("the shipped config/atmo.toml is valid (tested)")
    }

    /// Checks every value against its physical range.
    pub fn validate(&self, file: &Path) -> Result<()> {
        let c = Checker::new(file);
        c.within("environment.gravity", self.environment.gravity, 0.1, 100.0)?;

        c.positive("base.mass", self.base.mass)?;
        c.inertia("base.inertia", &self.base.inertia.matrix())?;

        c.positive("arm.mass", self.arm.mass)?;
        c.inertia("arm.inertia", &self.arm.inertia.matrix())?;
        c.finite("arm.base_to_hinge", &self.arm.base_to_hinge)?;
        c.finite("arm.hinge_to_com", &self.arm.hinge_to_com)?;
        c.finite("arm.hinge_to_rotor1", &self.arm.hinge_to_rotor1)?;

        c.positive("rotor.mass", self.rotor.mass)?;
        let [ixx, iyy, izz] = self.rotor.inertia;
        c.inertia(
            "rotor.inertia",
            &Matrix3::from_diagonal(&Vector3::new(ixx, iyy, izz)),
        )?;
        c.positive("rotor.k_thrust", self.rotor.k_thrust)?;
        c.within("rotor.k_moment", self.rotor.k_moment, 0.0, 1.0)?;
        for (i, s) in self.rotor.yaw_sign.iter().enumerate() {
            if *s != 1.0 && *s != -1.0 {
                return Err(c.fail(&format!("rotor.yaw_sign[{i}]"), "+1 or -1", s));
            }
        }

        c.positive("wheels.radius", self.wheels.radius)?;
        c.positive("wheels.half_track", self.wheels.half_track)?;
        c.positive("wheels.max_rate", self.wheels.max_rate)?;

        let l = &self.linkage;
        c.positive("linkage.h", l.h)?;
        c.positive("linkage.d1", l.d1)?;
        c.positive("linkage.d2", l.d2)?;
        c.finite("linkage.d", &l.d)?;
        c.positive("linkage.thread_pitch", l.thread_pitch)?;
        c.positive("linkage.counts_per_rev", l.counts_per_rev)?;
        crate::linkage::Linkage::from_config(l, self.limits.tilt_max()).map_err(|e| {
            c.fail(
                "linkage",
                "a linkage that reaches every tilt in [0, tilt_max_deg]",
                e,
            )
        })?;

        let lim = &self.limits;
        c.positive("limits.tilt_rate_max", lim.tilt_rate_max)?;
        c.within("limits.tilt_max_deg", lim.tilt_max_deg, 1.0, 90.0)?;
        c.within(
            "limits.tilt_flight_max_deg",
            lim.tilt_flight_max_deg,
            0.0,
            lim.tilt_max_deg,
        )?;
        if lim.tilt_transition_max_deg < lim.tilt_flight_max_deg
            || lim.tilt_transition_max_deg > lim.tilt_max_deg
        {
            return Err(c.fail(
                "limits.tilt_transition_max_deg",
                format!(
                    "tilt limits in order: tilt_flight_max_deg ({}) <= tilt_transition_max_deg <= tilt_max_deg ({})",
                    lim.tilt_flight_max_deg, lim.tilt_max_deg
                ),
                lim.tilt_transition_max_deg,
            ));
        }
        c.within("limits.thrust_reserve", lim.thrust_reserve, 1.0, 10.0)?;
        c.positive("limits.transition_height", lim.transition_height)?;
        if !(lim.morph_height.is_finite() && lim.morph_height > lim.transition_height) {
            return Err(c.fail(
                "limits.morph_height",
                format!(
                    "a height above limits.transition_height ({} m)",
                    lim.transition_height
                ),
                lim.morph_height,
            ));
        }
        // The composite body must have a positive-definite inertia wherever
        // the controller may fly (the authors' convention fails above ~86 deg).
        let model = crate::model::Model::new(self);
        let steps = 200;
        for i in 0..=steps {
            let varphi = lim.tilt_transition_max() * f64::from(i) / f64::from(steps);
            if !model.composite_is_physical(varphi) {
                return Err(c.fail(
                    "arm.inertia",
                    "a composite inertia that is positive definite up to limits.tilt_transition_max_deg",
                    format!("an indefinite inertia at {:.1} deg", varphi.to_degrees()),
                ));
            }
        }
        // The composite body must have a positive-definite inertia wherever
        // the controller may fly (the authors' convention fails above ~86 deg).
        let model = crate::model::Model::new(self);
        let steps = 200;
        for i in 0..=steps {
            let varphi = lim.tilt_transition_max() * f64::from(i) / f64::from(steps);
            if !model.composite_is_physical(varphi) {
                return Err(c.fail(
                    "arm.inertia",
                    "a composite inertia that is positive definite up to limits.tilt_transition_max_deg",
                    format!("an indefinite inertia at {:.1} deg", varphi.to_degrees()),
                ));
            }
        }
        Ok(())
    }
}
