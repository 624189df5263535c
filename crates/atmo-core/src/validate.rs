//! The physical checks of a robot file.
//!
//! They sit above [`crate::config`] (the data), [`crate::linkage`] and
//! [`crate::model`] because two of them build a linkage and a model: the
//! linkage must reach every tilt up to `limits.tilt_max_deg`, and the
//! composite inertia must stay positive definite up to
//! `limits.tilt_transition_max_deg`.

use std::path::Path;

use crate::config::RobotConfig;
use crate::config_file::{Checker, ConfigFile};
use crate::error::CoreError;
use crate::linkage::Linkage;
use crate::model::Model;

impl RobotConfig {
    /// The parameters the ATMO authors flew with (the file shipped in `config/atmo.toml`).
    pub fn atmo() -> Self {
        Self::from_toml_str(
            include_str!("../../../config/atmo.toml"),
            "config/atmo.toml",
        )
        .expect("the shipped config/atmo.toml is valid (tested)")
    }
}

impl ConfigFile for RobotConfig {
    type Error = CoreError;

    /// Checks every value against its physical range, then the whole
    /// robot (`physical`; here and not in the declaration, which would
    /// make the data module depend on the model built from it).
    fn validate(&self, file: &Path) -> Result<(), CoreError> {
        crate::params::check_file(self, file)?;
        physical(self, &Checker::new(file), "")
    }
}

/// The checks of a whole robot (after each value's range): the linkage
/// reaches every tilt up to the limit, the rotors carry the weight with
/// the reserve, the composite inertia is physical.
pub(crate) fn physical(
    config: &RobotConfig,
    c: &Checker<'_>,
    prefix: &str,
) -> Result<(), CoreError> {
    Linkage::from_config(&config.linkage, config.limits.tilt_max()).map_err(|e| {
        c.fail(
            &crate::params::key(prefix, "linkage"),
            "a linkage that reaches every tilt in [0, tilt_max_deg]",
            e,
        )
    })?;
    can_hover_with_reserve(config, c)?;
    composite_is_physical(config, c)
}

/// A robot the physics cannot fly is refused here, not found in flight:
/// the four rotors at full command must carry the weight with the flight
/// reserve, `4 kT / (m g) >= limits.thrust_reserve` (m of all seven bodies),
/// so that the in-flight tilt limit `acos(r m g / T_max)` exists.
fn can_hover_with_reserve(config: &RobotConfig, c: &Checker<'_>) -> Result<(), CoreError> {
    let mass = config.base.mass + 2.0 * config.arm.mass + 4.0 * config.rotor.mass;
    let weight = mass * config.environment.gravity;
    let ratio = 4.0 * config.rotor.k_thrust / weight;
    let reserve = config.limits.thrust_reserve;
    if ratio >= reserve {
        return Ok(());
    }
    Err(c.fail(
        "rotor.k_thrust",
        format!(
            "four rotors that carry the weight with limits.thrust_reserve = {reserve}: \
             4 k_thrust >= {:.2} N for a total mass of {mass:.3} kg \
             (base.mass + 2 arm.mass + 4 rotor.mass)",
            reserve * weight
        ),
        format!(
            "{} N: thrust-to-weight {ratio:.3}, the robot cannot fly",
            config.rotor.k_thrust
        ),
    ))
}

/// The composite body must have a positive-definite inertia wherever the
/// controller may fly (the authors' convention fails above ~86 deg).
fn composite_is_physical(config: &RobotConfig, c: &Checker<'_>) -> Result<(), CoreError> {
    let model = Model::new(config);
    let steps = 200;
    for i in 0..=steps {
        let varphi = config.limits.tilt_transition_max() * f64::from(i) / f64::from(steps);
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
