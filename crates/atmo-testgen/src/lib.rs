//! atmo-testgen: recordings for the discrepancy finder made without the
//! flight stack (no atmo-core model, no atmo-plant, no atmo-mpc), so that
//! what `atmo-sim explain` finds on them is not an artefact shared by the
//! simulator and the analysis.
//!
//! - [`robot`]: the robot file read on its own; the seven bodies combined
//!   into one rigid body at a fixed tilt, about its centre of mass.
//! - [`sim`]: Newton-Euler about the centre of mass with a unit-quaternion
//!   attitude, RK4 sub-steps, commands held over each sample (zero-order
//!   hold), and the concealed effects (ground effect, motor lag, drag and
//!   wind, centre-of-mass offset, thrust scale, thrust curve), each its own
//!   implementation.
//! - [`control`]: cascaded PID (position, attitude, rate) computing at the
//!   recording rate from the noisy measurement, knowing only the file.
//! - [`flight`]: the system-identification reference, motion-capture noise
//!   (white position and attitude, white + Gauss-Markov velocity, white
//!   rates; no dither), the CSV of docs/recording_format.md.
//!
//! Simplification against the ATMO model: the tilt is fixed for a flight
//! (at a fixed tilt ATMO is one rigid body, which the nominal model of
//! atmo-core describes exactly; rotor gyroscopic terms are left out as in
//! atmo-core). `tests/reference.rs` checks the accelerations against
//! atmo-core's model, used there as the reference only.

pub mod control;
pub mod flight;
pub mod robot;
pub mod sim;

/// What can go wrong.
#[derive(Debug, thiserror::Error)]
pub enum GenError {
    #[error("{file}: {message}")]
    Robot { file: String, message: String },
    #[error("--effects: {0}")]
    Effects(String),
    #[error("writing {file}: {message}")]
    Output { file: String, message: String },
}

/// Concealed effects by name, at the values the tests use:
/// `ground_effect` (rotor radius 0.19 m), `motor_lag` (30 ms), `drag`
/// (rotor drag 0.03, Cd A 0.06 / 0.06 / 0.10 m^2) with `wind` (2 m/s north),
/// `com_offset` (8 mm forward, -5 mm right), `thrust_scale` (+8 %),
/// `thrust_curve` (b = 0.3), `none`.
pub fn concealed(list: &str) -> Result<sim::Concealed, GenError> {
    let mut fx = sim::Concealed::default();
    for name in list.split(',').map(str::trim).filter(|s| !s.is_empty()) {
        match name {
            "none" => {}
            "ground_effect" => fx.ground_effect_radius = Some(0.19),
            "motor_lag" => fx.motor_lag = Some(0.030),
            "drag" => fx.drag = Some((0.03, [0.06, 0.06, 0.10])),
            "wind" => fx.wind = [2.0, 0.0, 0.0],
            "com_offset" => fx.com_offset = Some([0.008, -0.005, 0.0]),
            "thrust_scale" => fx.thrust_scale = Some(0.08),
            "thrust_curve" => fx.thrust_curve = Some(0.3),
            other => {
                return Err(GenError::Effects(format!(
                    "unknown effect `{other}` (ground_effect, motor_lag, drag, wind, com_offset, \
                     thrust_scale, thrust_curve, none)"
                )));
            }
        }
    }
    if fx.wind != [0.0; 3] && fx.drag.is_none() {
        return Err(GenError::Effects(
            "`wind` is only felt through `drag`: give both".into(),
        ));
    }
    Ok(fx)
}
