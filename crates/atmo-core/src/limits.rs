//! Thrust limits of a tilting quadrotor.
//!
//! With all four rotors at full thrust `T_max = 4 kT`, the vertical thrust
//! at tilt varphi is `T_max cos varphi`. The critical angle, past which the
//! rotors can no longer carry the weight, is `cos varphi_c = m g / T_max`.
//! Flight keeps a reserve r: `T_max cos varphi_max / (m g) = r`, so
//! `cos varphi_max = r m g / T_max` (ATMO: r = 1.35 gives about 50 deg).

use crate::error::{CoreError, Result};
use crate::model::Model;

/// Thrust-to-weight ratio `T_max / (m g)`.
pub fn thrust_to_weight(model: &Model) -> f64 {
    model.max_total_thrust() / model.weight()
}

/// `acos(r m g / T_max)`: the largest tilt that keeps a thrust reserve `r`.
pub fn max_tilt_for_reserve(model: &Model, reserve: f64) -> Result<f64> {
    let cos = reserve / thrust_to_weight(model);
    if !(reserve.is_finite() && reserve > 0.0 && cos <= 1.0) {
        return Err(CoreError::OutOfRange {
            quantity: "thrust reserve (must not exceed the thrust-to-weight ratio)",
            value: reserve,
            min: 0.0,
            max: thrust_to_weight(model),
        });
    }
    Ok(cos.acos())
}

/// The critical angle `acos(m g / T_max)`, rad.
pub fn critical_angle(model: &Model) -> Result<f64> {
    max_tilt_for_reserve(model, 1.0)
}

/// The tilt (rad) at which the level hover trim first needs a rotor at full
/// command, found by bisection on `[0, upper]`. Slightly below the critical
/// angle because the rotors do not share the load equally (the centre of
/// mass is not under the rotor centroid).
pub fn trim_saturation_angle(model: &Model, upper: f64) -> Result<f64> {
    let peak = |varphi: f64| model.at_tilt(varphi).hover_trim().max();
    if peak(0.0) >= 1.0 {
        return Err(CoreError::OutOfRange {
            quantity: "hover trim at varphi = 0 (the robot cannot hover)",
            value: peak(0.0),
            min: 0.0,
            max: 1.0,
        });
    }
    if peak(upper) < 1.0 {
        return Ok(upper);
    }
    let (mut lo, mut hi) = (0.0, upper);
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if peak(mid) < 1.0 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    Ok(0.5 * (lo + hi))
}
