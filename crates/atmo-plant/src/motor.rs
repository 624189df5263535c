//! The motor model's command-to-thrust curve, `[effects.thrust_curve]`:
//! `c(u) = (1 - f) u + f u^2` of full thrust per rotor (f = `curve`, 0 =
//! linear as in the controller's model), applied with or without a motor
//! lag (with one it replaces `[effects.motor_lag].curve`, which must then
//! be 0). Off by default: real propellers are not linear in command, and
//! the discrepancy finder fits this curve (its `thrust_curve` effect).

use atmo_core::config_file::{Checker, default_true};
use serde::Deserialize;

use crate::error::Result;

/// `[effects.thrust_curve]`.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ThrustCurveConfig {
    #[serde(default = "default_true")]
    pub enabled: bool,
    /// f in [-1, 1] (the curve stays monotonic on [0, 1]).
    pub curve: f64,
}

impl ThrustCurveConfig {
    /// `c(u)`.
    pub fn thrust(f: f64, u: f64) -> f64 {
        (1.0 - f) * u + f * u * u
    }

    /// Range checks; with a motor lag (`lag_curve`: its
    /// `[effects.motor_lag].curve`) that curve must be 0 (one curve).
    pub(crate) fn validate(
        &self,
        c: &Checker<'_>,
        prefix: &str,
        lag_curve: Option<f64>,
    ) -> Result<()> {
        let p = format!("{prefix}.thrust_curve");
        c.within(&format!("{p}.curve"), self.curve, -1.0, 1.0)?;
        if let Some(curve) = lag_curve {
            c.within(
                &format!("{prefix}.motor_lag.curve (0 when [{p}] gives the curve)"),
                curve,
                0.0,
                0.0,
            )?;
        }
        Ok(())
    }
}
