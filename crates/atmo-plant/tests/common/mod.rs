//! Helpers shared by the plant tests.
#![allow(dead_code)]

use atmo_core::RobotConfig;
use atmo_core::model::{Model, State, idx};
use atmo_plant::config::{EffectsConfig, GroundContactConfig, PlantConfig};

pub fn robot() -> RobotConfig {
    RobotConfig::atmo()
}

/// A plant config with only the given effects.
pub fn plant_with(effects: EffectsConfig) -> PlantConfig {
    PlantConfig {
        effects,
        ..PlantConfig::ideal()
    }
}

/// Only ground contact.
pub fn contact_only() -> PlantConfig {
    plant_with(EffectsConfig {
        ground_contact: Some(GroundContactConfig::default()),
        ..EffectsConfig::none()
    })
}

/// Distance (m) from B down to the lowest wheel rim point at `tilt`, level.
pub fn wheel_drop(tilt: f64) -> f64 {
    let body = Model::new(&robot()).at_tilt(tilt);
    let r = robot().wheels.radius;
    (0..4)
        .map(|i| {
            let c = body.rotor_position[i];
            let a = body.rotor_axis[i];
            let down = nalgebra::Vector3::new(0.0, 0.0, 1.0);
            let dp = down - a * down.dot(&a);
            let n = dp.norm();
            if n > 1e-9 { c.z + r * dp.z / n } else { c.z }
        })
        .fold(f64::NEG_INFINITY, f64::max)
}

/// A level state with B at `height` m above the NED origin plane.
pub fn level_at(height: f64) -> State {
    let mut x = State::zeros();
    x[idx::Z] = -height;
    x
}
