//! The physical checks of a robot file.
//!
//! They sit above [`crate::config`] (the data), [`crate::linkage`] and
//! [`crate::model`] because two of them build a linkage and a model: the
//! linkage must reach every tilt up to `limits.tilt_max_deg`, and the
//! composite inertia must stay positive definite up to
//! `limits.tilt_transition_max_deg`.

use std::path::Path;

use nalgebra::{Matrix3, Vector3};

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

    /// Checks every value against its physical range.
    fn validate(&self, file: &Path) -> Result<(), CoreError> {
        let c = Checker::new(file);
        c.range(
            "environment.gravity",
            self.environment.gravity,
            0.1..=100.0,
            "m/s^2",
        )?;

        c.range("base.mass", self.base.mass, 1e-3..=1e3, "kg")?;
        c.inertia("base.inertia", &self.base.inertia.matrix())?;

        c.range("arm.mass", self.arm.mass, 1e-4..=1e3, "kg")?;
        c.inertia("arm.inertia", &self.arm.inertia.matrix())?;
        c.finite("arm.base_to_hinge", &self.arm.base_to_hinge)?;
        c.finite("arm.hinge_to_com", &self.arm.hinge_to_com)?;
        c.finite("arm.hinge_to_rotor1", &self.arm.hinge_to_rotor1)?;

        c.range("rotor.mass", self.rotor.mass, 1e-5..=1e2, "kg")?;
        let [ixx, iyy, izz] = self.rotor.inertia;
        c.inertia(
            "rotor.inertia",
            &Matrix3::from_diagonal(&Vector3::new(ixx, iyy, izz)),
        )?;
        c.range("rotor.k_thrust", self.rotor.k_thrust, 1e-3..=1e5, "N")?;
        c.range("rotor.k_moment", self.rotor.k_moment, 0.0..=1.0, "m")?;
        c.range(
            "rotor.time_constant",
            self.rotor.time_constant,
            0.0..=1.0,
            "s",
        )?;
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
        Linkage::from_config(l, self.limits.tilt_max()).map_err(|e| {
            c.fail(
                "linkage",
                "a linkage that reaches every tilt in [0, tilt_max_deg]",
                e,
            )
        })?;

        let lim = &self.limits;
        c.positive("limits.tilt_rate_max", lim.tilt_rate_max)?;
        c.range("limits.tilt_max_deg", lim.tilt_max_deg, 1.0..=90.0, "deg")?;
        c.range(
            "limits.tilt_flight_max_deg",
            lim.tilt_flight_max_deg,
            0.0..=lim.tilt_max_deg,
            "deg",
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
        c.range("limits.thrust_reserve", lim.thrust_reserve, 1.0..=10.0, "")?;
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
        can_hover_with_reserve(self, &c)?;
        composite_is_physical(self, &c)
    }
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
