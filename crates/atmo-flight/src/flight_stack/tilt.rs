//! The tilt command: the limit in force in each mode, the velocity each
//! mode asks for, and the limits that velocity is held to.

use super::FlightStack;
use crate::modes::Mode;

impl FlightStack {
    /// Tilt limit in force in `mode`, rad.
    pub(super) fn tilt_limit(&self, mode: Mode) -> f64 {
        match mode {
            Mode::Transition if self.plans_tilt => self.transition_tilt_max,
            Mode::Transition => self.transition_limit,
            Mode::Failsafe if self.failsafe_descends() => self.descent_tilt(),
            Mode::Takeoff | Mode::Flight | Mode::Morphing | Mode::Failsafe => self.flight_limit(),
            Mode::Disarmed | Mode::Drive | Mode::Touchdown => self.tilt_max,
        }
    }

    /// The transition's tilt limit at `height`: from the flight limit at z*
    /// to the transition limit at `transition_full_tilt_height`, linear in
    /// between. Tilting past the critical angle while still high would make
    /// ATMO fall the rest of the way; this keeps the tilt in step with the
    /// descent so that the wheels meet the ground as the thrust runs out.
    pub(super) fn transition_schedule(&self, height: f64) -> f64 {
        let top = self.thresholds.transition_height;
        let bottom = self.settings.modes.transition_full_tilt_height;
        let progress = ((top - height) / (top - bottom)).clamp(0.0, 1.0);
        let flight = self.flight_limit();
        flight + (self.transition_tilt_max - flight) * progress
    }

    /// The tilt velocity the mode asks for, before limits.
    /// On the ground a take-off tilts back only to the take-off tilt, where
    /// the thrusters start: folding further before lift-off would put the
    /// body on the ground (the wheels stop holding it up below ~35 deg).
    pub(super) fn tilt_velocity_wanted(&self, mode: Mode, grounded: bool, tilt: f64) -> f64 {
        let v = self.tilt_rate_max;
        let takeoff_tilt = self.settings.modes.takeoff_max_tilt_deg.to_radians();
        match mode {
            // Disarmed, the pilot's lever moves the arms (on the bench or
            // on the ground: the rotors are off).
            Mode::Disarmed => self.tilt_lever * v,
            Mode::Drive | Mode::Touchdown => 0.0,
            Mode::Takeoff if grounded && tilt <= takeoff_tilt => 0.0,
            // A failsafe descent: to its tilt (the limit), from either side.
            Mode::Failsafe if self.failsafe_descends() => v,
            Mode::Takeoff | Mode::Flight | Mode::Failsafe => -v,
            // Held until the MPC's plan says otherwise (see `step`).
            Mode::Transition if self.plans_tilt => 0.0,
            Mode::Morphing | Mode::Transition => v,
        }
    }

    /// Enforces `[0, limit]` on the tilt whatever is wanted: never move
    /// further out, come back at full speed when outside, never overshoot.
    pub(super) fn limit_tilt_velocity(&self, wanted: f64, tilt: f64, limit: f64) -> f64 {
        let dt = self.period();
        let v = self.tilt_rate_max;
        if tilt > limit {
            return -v;
        }
        wanted.clamp(-v, v).clamp(-tilt / dt, (limit - tilt) / dt)
    }
}
