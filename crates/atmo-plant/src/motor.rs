//! The motor model's command-to-thrust curve, `[effects.thrust_curve]`:
//! `c(u) = (1 - f) u + f u^2` of full thrust per rotor (f = `curve`, 0 =
//! linear as in the controller's model), applied with or without a motor
//! lag (with one it replaces `[effects.motor_lag].curve`, which must then
//! be 0). Off by default: real propellers are not linear in command, and
//! the discrepancy finder fits this curve (its `thrust_curve` effect).

atmo_core::params! {
    /// `[effects.thrust_curve]`: the command-to-thrust curve
    /// `c(u) = (1 - f) u + f u^2`.
    #[derive(Debug, Clone, PartialEq)]
    pub struct ThrustCurveConfig {
        /// Whether the effect is on (a present section is, unless it says
        /// false).
        pub enabled: bool = true;
        /// f (the curve stays monotonic on [0, 1]).
        pub curve: f64, range -1.0..=1.0;
    }
}

impl ThrustCurveConfig {
    /// `c(u)`.
    pub fn thrust(f: f64, u: f64) -> f64 {
        (1.0 - f) * u + f * u * u
    }
}
