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
//!   implementation, in two forms ([`Form`]).
//! - [`control`]: what the controllers share; [`pid`] (cascaded PID:
//!   position, attitude, rate) and [`lqr`] (a discrete LQR on the full
//!   state), both computing at the recording rate from the noisy
//!   measurement, knowing only the file.
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
pub mod lqr;
pub mod pid;
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

/// Which implementation and values of each concealed effect
/// [`concealed`] builds: two forms, so that a finder rule chosen on one can
/// be checked on the other.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum Form {
    /// Cheeseman-Bennett ground effect (R 0.19 m); thrust lag 30 ms; rotor
    /// drag 0.03, `Cd A` 0.06 / 0.06 / 0.10 m^2, wind 2 m/s north; the
    /// centre of mass moved (8, -5) mm, inertia unchanged; thrust +8 %;
    /// thrust curve `0.7 u + 0.3 u^2`.
    #[default]
    First,
    /// A ground-effect gain continuous in height and tilt, with suction
    /// at high tilt ([`sim::GroundEffect::Continuous`]); rotor-speed lag
    /// 45 ms; rotor drag 0.02, `Cd A` 0.04 / 0.08 / 0.13 m^2, wind (1.5,
    /// 1.0) m/s; a battery slid so the centre of mass moves (-6, 9) mm,
    /// inertia and moment arms following; thrust -6 %; thrust curve
    /// `u^1.2`.
    Second,
}

/// Concealed effects by name (`ground_effect`, `motor_lag`, `drag`,
/// `wind`, `com_offset`, `thrust_scale`, `thrust_curve`, `none`), in the
/// given [`Form`].
pub fn concealed(list: &str, form: Form) -> Result<sim::Concealed, GenError> {
    use sim::{ComOffset, GroundEffect, MotorLag, ThrustCurve};
    let first = form == Form::First;
    let mut fx = sim::Concealed::default();
    for name in list.split(',').map(str::trim).filter(|s| !s.is_empty()) {
        match name {
            "none" => {}
            "ground_effect" if first => {
                fx.ground_effect = Some(GroundEffect::CheesemanBennett(0.19));
            }
            "ground_effect" => fx.ground_effect = Some(GroundEffect::Continuous),
            "motor_lag" if first => fx.motor_lag = Some(MotorLag::Thrust(0.030)),
            "motor_lag" => fx.motor_lag = Some(MotorLag::RotorSpeed(0.045)),
            "drag" if first => fx.drag = Some((0.03, [0.06, 0.06, 0.10])),
            "drag" => fx.drag = Some((0.02, [0.04, 0.08, 0.13])),
            "wind" if first => fx.wind = [2.0, 0.0, 0.0],
            "wind" => fx.wind = [1.5, 1.0, 0.0],
            "com_offset" if first => {
                fx.com_offset = Some(ComOffset::MovedCentre([0.008, -0.005, 0.0]));
            }
            "com_offset" => fx.com_offset = Some(ComOffset::Composite([-0.006, 0.009, 0.0])),
            "thrust_scale" if first => fx.thrust_scale = Some(0.08),
            "thrust_scale" => fx.thrust_scale = Some(-0.06),
            "thrust_curve" if first => fx.thrust_curve = Some(ThrustCurve::Quadratic(0.3)),
            "thrust_curve" => fx.thrust_curve = Some(ThrustCurve::Power(1.2)),
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
