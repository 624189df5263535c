//! The mode state machine of the paper, as an explicit transition table.
//!
//! ```text
//!            armed & grounded            throttle >= 0.5             airborne & h > h_takeoff
//! Disarmed ----------------> Drive ------------------------> Takeoff -------------------------> Flight
//!    |                        ^  ^      throttle < 0.5 & grounded |                               |
//!    | armed & airborne       |  +--------------------------------+          h < z_varphi & descent command
//!    +------------------------|----------------------------------------------------------> Flight  v
//!                             |                                                               Morphing
//!                    thrust cut complete                      h > z_varphi + hysteresis  <----+  |
//!                             |                                                                  | h < z*
//!                        Touchdown <------------------- grounded ------------------------- Transition
//!                                                              (h < z* once tilted near the flight limit)
//!
//! Failsafe: from Takeoff/Flight/Morphing/Transition on a stale estimate, an
//! MPC failure past its grace, a lost driver or a lost radio, or a tilt not
//! where it is believed, or (but from Transition) a rotor out; back to
//! Flight once healthy and tilted back (never with a rotor out); to
//! Touchdown when grounded. With a rotor failed, a contact from
//! Flight/Morphing/Transition is a touchdown only with the body level
//! (`modes.touchdown_max_tip_deg`): touching on one wheel tipped, the
//! flight goes on, for at most `modes.touchdown_level_timeout` of contact.
//! Any mode -> Disarmed when the arm switch drops.
//! ```
//!
//! Rows are checked in order; the first whose `from` contains the current
//! mode and whose guard holds fires. At most one transition per tick.

/// The flight stack's modes (atmo-io's type: the same codes on the wire
/// and in the logs).
pub use atmo_io::msg::Mode;

/// Everything the guards look at, computed by the flight stack each tick.
// The guards read switches and signals that are booleans by nature.
#[allow(clippy::struct_excessive_bools)]
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Conditions {
    pub armed: bool,
    /// Every arming check passes (only arming looks at it).
    pub arming_ok: bool,
    /// Wheel contact reported by the ground-contact signal.
    pub grounded: bool,
    /// Height of the base origin above the ground, m.
    pub height: f64,
    pub throttle: f64,
    /// Pilot commands a descent (downward velocity above a threshold).
    pub descent_commanded: bool,
    /// The state estimate is recent enough to fly on.
    pub estimate_fresh: bool,
    /// The MPC has failed for longer than its grace period.
    pub mpc_failed: bool,
    /// A required driver (thrusters, tilt, wheels, contact sensor) stopped
    /// talking: what is commanded may not happen.
    pub driver_lost: bool,
    /// The pilot's radio is lost (only with the radio as the pilot source).
    pub pilot_lost: bool,
    /// The tilt is not where it is believed (the actuator monitor: a
    /// slipping tilt motor, a jammed linkage): no wheel landing to plan.
    pub tilt_unknown: bool,
    /// A rotor does not deliver its command (the actuator monitor).
    pub rotor_failed: bool,
    /// ... and delivers too little to fly the wheel landing on
    /// (`monitor.rotor_out_effectiveness`): descend (`Mode::Failsafe`).
    pub rotor_out: bool,
    /// The body's tilt from level (the angle between its z axis and the
    /// vertical), rad.
    pub body_tip: f64,
    /// Seconds the ground contact has lasted (0 without one).
    pub time_grounded: f64,
    /// Measured tilt, rad.
    pub tilt: f64,
    /// Seconds since the current mode was entered.
    pub time_in_mode: f64,
}

/// Thresholds the guards use (from the flight settings and robot limits).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Thresholds {
    pub takeoff_throttle: f64,
    pub takeoff_height: f64,
    /// z_varphi, m.
    pub morph_height: f64,
    pub morph_hysteresis: f64,
    /// z*, m.
    pub transition_height: f64,
    /// Tilt below which morphing does not hand over to the transition even
    /// below z* (it holds its height instead), rad: a robot that reaches
    /// z* with its arms folded (after a failsafe near the ground) cannot
    /// tilt to the wheel-landing angle in the height left.
    pub transition_min_tilt: f64,
    /// Seconds the thrust takes to ramp to zero after touchdown.
    pub thrust_cut_time: f64,
    /// With a rotor failed, the most the body may be tipped from level at
    /// a wheel contact for it to be a touchdown, rad.
    pub touchdown_max_tip: f64,
    /// The longest the flight goes on tipped on a lasting contact, s.
    pub touchdown_level_timeout: f64,
    /// Minimum time in failsafe before recovering, s.
    pub failsafe_recovery_time: f64,
    /// Tilt below which a failsafe may hand back to flight, rad.
    pub failsafe_recovery_tilt: f64,
}

type Guard = fn(&Conditions, &Thresholds) -> bool;

/// One row of the transition table.
#[derive(Clone, Copy)]
pub struct Transition {
    pub from: &'static [Mode],
    pub to: Mode,
    pub guard: Guard,
    /// Why, for logs and the architecture drawing.
    pub reason: &'static str,
}

/// Every mode but `Disarmed` (the first of `Mode::ALL`).
const ARMED_MODES: &[Mode] = Mode::ALL.split_at(1).1;
const FLYING: &[Mode] = &[
    Mode::Takeoff,
    Mode::Flight,
    Mode::Morphing,
    Mode::Transition,
];

/// The table, in priority order.
pub const TRANSITIONS: &[Transition] = &[
    Transition {
        from: ARMED_MODES,
        to: Mode::Disarmed,
        guard: |c, _| !c.armed,
        reason: "arm switch off",
    },
    Transition {
        // Out (too little thrust left for the wheel landing's tilts) above
        // z*: down at a set speed, the heading let go, the arms tilted to
        // put the wheels under the base. A transition under way is already
        // landing and lands.
        from: &[Mode::Takeoff, Mode::Flight, Mode::Morphing],
        to: Mode::Failsafe,
        guard: |c, _| c.rotor_out,
        reason: "a rotor out: descend",
    },
    Transition {
        from: &[Mode::Disarmed],
        to: Mode::Drive,
        // The height says "ground" only from a fresh estimate: armed before
        // the first one arrives, a missing estimate's zero height would put
        // a flying robot in Drive, its thrusters off (seen in SITL on a
        // loaded machine). Without contact or an estimate it stays disarmed.
        guard: |c, t| {
            c.armed
                && c.arming_ok
                && (c.grounded || (c.estimate_fresh && c.height <= t.takeoff_height))
        },
        reason: "armed on the ground",
    },
    Transition {
        from: &[Mode::Disarmed],
        to: Mode::Flight,
        guard: |c, t| {
            c.armed
                && c.arming_ok
                && !c.grounded
                && c.height > t.takeoff_height
                && c.estimate_fresh
                && !c.rotor_failed
        },
        reason: "armed in the air",
    },
    Transition {
        from: FLYING,
        to: Mode::Failsafe,
        guard: |c, _| {
            !c.estimate_fresh || c.mpc_failed || c.driver_lost || c.pilot_lost || c.tilt_unknown
        },
        reason: "estimate stale, MPC failed, or a driver, radio or actuator lost",
    },
    Transition {
        from: &[Mode::Failsafe],
        to: Mode::Touchdown,
        guard: contact_believed,
        reason: "grounded in failsafe",
    },
    Transition {
        from: &[Mode::Failsafe],
        to: Mode::Flight,
        guard: |c, t| {
            c.estimate_fresh
                && !c.mpc_failed
                && !c.driver_lost
                && !c.pilot_lost
                && !c.tilt_unknown
                && !c.rotor_out
                && c.time_in_mode >= t.failsafe_recovery_time
                && c.tilt <= t.failsafe_recovery_tilt
        },
        reason: "healthy again and tilted back",
    },
    Transition {
        from: &[Mode::Transition, Mode::Morphing, Mode::Flight],
        to: Mode::Touchdown,
        guard: |c, t| {
            contact_believed(c, t)
                && !(c.rotor_failed
                    && c.body_tip > t.touchdown_max_tip
                    && c.time_grounded < t.touchdown_level_timeout)
        },
        reason: "wheels on the ground",
    },
    Transition {
        from: &[Mode::Drive],
        to: Mode::Takeoff,
        guard: |c, t| {
            c.throttle >= t.takeoff_throttle
                && !c.driver_lost
                && !c.pilot_lost
                && !c.tilt_unknown
                && !c.rotor_failed
        },
        reason: "throttle up on the ground, every driver and the radio alive",
    },
    Transition {
        from: &[Mode::Takeoff],
        to: Mode::Drive,
        guard: |c, t| c.grounded && c.throttle < t.takeoff_throttle,
        reason: "take-off aborted",
    },
    Transition {
        from: &[Mode::Takeoff],
        to: Mode::Flight,
        guard: |c, t| !c.grounded && c.height > t.takeoff_height,
        reason: "airborne",
    },
    Transition {
        from: &[Mode::Flight],
        to: Mode::Morphing,
        guard: |c, t| c.height < t.morph_height && c.descent_commanded,
        reason: "descending below z_varphi",
    },
    Transition {
        from: &[Mode::Morphing],
        to: Mode::Flight,
        guard: |c, t| c.height > t.morph_height + t.morph_hysteresis,
        reason: "climbed back above z_varphi",
    },
    Transition {
        from: &[Mode::Morphing],
        to: Mode::Transition,
        guard: |c, t| c.height < t.transition_height && c.tilt >= t.transition_min_tilt,
        reason: "below z* and tilted",
    },
    Transition {
        from: &[Mode::Touchdown],
        to: Mode::Drive,
        guard: |c, t| c.time_in_mode >= t.thrust_cut_time,
        reason: "thrust cut complete",
    },
];

/// A contact report that can be true: the estimate (while fresh) puts the
/// base at most `takeoff_height` above the ground. A contact reported
/// higher up is a false one (a sensor fault): believing it cut the thrust
/// of a robot 1.5 m up. Without a fresh estimate the contact is believed.
fn contact_believed(c: &Conditions, t: &Thresholds) -> bool {
    c.grounded && (!c.estimate_fresh || c.height <= t.takeoff_height)
}

/// The next mode: the first matching row of [`TRANSITIONS`], or `mode`.
pub fn next_mode(mode: Mode, c: &Conditions, t: &Thresholds) -> (Mode, Option<&'static str>) {
    for row in TRANSITIONS {
        if row.from.contains(&mode) && (row.guard)(c, t) {
            return (row.to, Some(row.reason));
        }
    }
    (mode, None)
}

#[cfg(test)]
mod tests {
    use super::{ARMED_MODES, Mode};

    /// The status carries a transition's reason in a `Label`: a longer one
    /// would be cut there (it was: "...the radio " lost its "or an actuator").
    #[test]
    fn every_reason_fits_the_status_label_whole() {
        for row in super::TRANSITIONS {
            assert!(
                row.reason.len() <= atmo_io::msg::Label::CAPACITY,
                "{} bytes: {}",
                row.reason.len(),
                row.reason
            );
        }
    }

    #[test]
    fn the_armed_modes_are_every_mode_but_disarmed() {
        assert_eq!(ARMED_MODES.len(), Mode::ALL.len() - 1);
        assert!(!ARMED_MODES.contains(&Mode::Disarmed));
        assert!(
            Mode::ALL
                .iter()
                .all(|m| *m == Mode::Disarmed || ARMED_MODES.contains(m))
        );
    }
}
