//! The paper's control helpers, as pure functions.
//!
//! - Height factor and cost blending: `alpha(h, varphi) = f(h) cos varphi`
//!   with `f(h) = clamp(h / z*, 0, 1)` and h the height above ground. The MPC
//!   cost is `alpha L1 + (1 - alpha) L2`: far from the ground in the flight
//!   configuration it tracks everything (L1); close to the ground and tilted it
//!   keeps only attitude (L2) and lets the ground effect carry it down.
//!   (The paper gives the form `f(z) cos varphi`; the linear ramp to z* is
//!   our choice of f, a parameter of the flight stack.)
//! - Tilt-velocity reference law: in the air below z_varphi tilt at +v_max
//!   (towards drive); on the ground with throttle >= 0.5 tilt at -v_max
//!   (back towards flight, for take-off); otherwise hold.
//! - Differential drive: with FRD axes a positive yaw rate turns right, so
//!   the left wheel runs faster: `w_left = (V + omega l) / R`,
//!   `w_right = (V - omega l) / R`; and back, `V = R (w_l + w_r) / 2`,
//!   `omega = R (w_l - w_r) / (2 l)`.

use crate::config::Wheels;

/// `f(h) = clamp(h / z*, 0, 1)`.
pub fn height_factor(height: f64, transition_height: f64) -> f64 {
    (height / transition_height).clamp(0.0, 1.0)
}

/// `alpha = f(h) cos varphi`, in [0, 1] for varphi in [0, pi/2].
pub fn blending_alpha(height: f64, varphi: f64, transition_height: f64) -> f64 {
    (height_factor(height, transition_height) * varphi.cos()).clamp(0.0, 1.0)
}

/// Throttle at or above which a grounded ATMO tilts back to take off.
pub const TAKEOFF_THROTTLE: f64 = 0.5;

/// Commanded tilt velocity (rad/s, positive towards drive) from the paper's law.
pub fn tilt_velocity_reference(
    height: f64,
    grounded: bool,
    throttle: f64,
    morph_height: f64,
    v_max: f64,
) -> f64 {
    if grounded {
        if throttle >= TAKEOFF_THROTTLE {
            -v_max
        } else {
            0.0
        }
    } else if height < morph_height {
        v_max
    } else {
        0.0
    }
}

/// Wheel rates (rad/s) of a differential drive.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WheelRates {
    pub left: f64,
    pub right: f64,
}

/// Differential-drive kinematics of ATMO's wheels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DiffDrive {
    pub radius: f64,
    pub half_track: f64,
    pub max_rate: f64,
}

impl DiffDrive {
    pub fn new(wheels: &Wheels) -> Self {
        Self {
            radius: wheels.radius,
            half_track: wheels.half_track,
            max_rate: wheels.max_rate,
        }
    }

    /// Wheel rates for forward speed `v` (m/s) and yaw rate `omega` (rad/s,
    /// FRD: positive turns right), scaled down together when one wheel would
    /// exceed its limit, which keeps the turn radius `v / omega`.
    pub fn wheel_rates(&self, v: f64, omega: f64) -> WheelRates {
        let left = (v + omega * self.half_track) / self.radius;
        let right = (v - omega * self.half_track) / self.radius;
        let peak = left.abs().max(right.abs());
        let scale = if peak > self.max_rate {
            self.max_rate / peak
        } else {
            1.0
        };
        WheelRates {
            left: left * scale,
            right: right * scale,
        }
    }

    /// Forward speed and yaw rate from wheel rates.
    pub fn body_velocity(&self, rates: WheelRates) -> (f64, f64) {
        let v = self.radius * (rates.left + rates.right) / 2.0;
        let omega = self.radius * (rates.left - rates.right) / (2.0 * self.half_track);
        (v, omega)
    }
}
