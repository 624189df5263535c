//! What a claimed wind's flight identifies about its speed (part of the
//! report stage).
//!
//! A steady wind is the airspeed at which the drag vanishes. A flight
//! whose air-relative speed along the wind stays far from zero samples
//! the drag law only around that speed: there the law's force `F` and
//! its slope `F'` in the wind speed are what the data give, and the
//! speed follows from the law's shape. A linear law (rotor drag) puts
//! it at `F / F'`, a quadratic one (body drag) at `2 F / F'`; the fitted
//! mix of the two lies between. The mix is told by the law's curvature
//! and by how its parts scale with the thrust, which a fit reads
//! correctly only if its drag law is the air's.
//!
//! So the speed is reported as separated from the drag coefficients only
//! where the fitted model explains the disc-plane forces, through which
//! the wind acts, to within the noise: in each of them the held-out
//! residual after the fit is below [`LAW_MISFIT_FLOORS`] noise floors,
//! the RMS at which the model's misfit is as large as the noise itself.
//! Otherwise the report says the flight cannot separate them and gives
//! what it identifies: `F`, `F'` and the bracket the two laws put the
//! speed in.

use crate::effects::{Effect, mean_drag_force_along};
use crate::explanation::RmsTable;
use crate::explanation::WindSpeed;
use crate::recording::Recording;
use crate::stages::{Fit, Residuals};

/// The residual channels a steady wind's drag acts through: the force in
/// the disc plane (body x, y). The thrust axis's channel also carries the
/// thrust calibration (scale, curve), which a wind's speed does not rest
/// on.
pub const WIND_FORCE_CHANNELS: [usize; 2] = [0, 1];

/// Held-out RMS after the fit, in noise floors, at which the misfit's
/// variance equals the noise's (`sqrt 2`): above it in a disc-plane
/// channel the fitted drag law is not the air's. Checked in
/// docs/explain.md (held-out table, "wind speed separable").
pub const LAW_MISFIT_FLOORS: f64 = std::f64::consts::SQRT_2;

/// Wind-speed step of the slope's central difference (m/s).
const SLOPE_STEP: f64 = 0.1;

/// What the flight identifies about the fitted wind's speed; `None`
/// without a wind in the accepted fit (or without drag coefficients to
/// evaluate). `after`: the held-out residual's RMS with the fit.
pub fn wind_speed(
    res: &Residuals,
    rec: &Recording,
    fit: &Fit,
    after: &RmsTable,
) -> Option<WindSpeed> {
    if !fit.chosen.contains(&Effect::Wind) {
        return None;
    }
    let coefficients = fit.physical.drag?;
    let wind = fit.knobs.wind;
    let speed = wind[0].hypot(wind[1]);
    if speed <= 0.0 {
        return None;
    }
    let direction = wind.map(|w| w / speed);
    let prep = &res.prep;
    let thrust = crate::data::lagged_commands(&prep.t, &prep.u_eff, fit.knobs.tau);
    let force_at = |s: f64| {
        mean_drag_force_along(
            prep,
            rec,
            &thrust,
            &res.fit_rows,
            &coefficients,
            direction.map(|d| d * s),
            direction,
        )
    };
    let force_n = force_at(speed);
    let slope = (force_at(speed + SLOPE_STEP) - force_at(speed - SLOPE_STEP)) / (2.0 * SLOPE_STEP);
    let (speed_linear_law, speed_quadratic_law) = if slope > 0.0 {
        (force_n / slope, 2.0 * force_n / slope)
    } else {
        (f64::NAN, f64::NAN)
    };
    let misfit_floors = WIND_FORCE_CHANNELS
        .iter()
        .map(|&c| after.per_channel[c] / prep.floor[c])
        .fold(0.0, f64::max);
    Some(WindSpeed {
        speed,
        force_n,
        slope_n_per_mps: slope,
        speed_linear_law,
        speed_quadratic_law,
        misfit_floors,
        separable: misfit_floors < LAW_MISFIT_FLOORS,
    })
}
