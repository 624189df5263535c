//! The actuator side's faults (`[faults.actuators]`): the wheel landing
//! flown with one fault each, and what the flight stack does
//! (docs/faults.md, the actuator table): what the actuator monitor detects,
//! what the stack does, and the outcome (the landing where one can be made,
//! a safe failure where not).
#![allow(clippy::unwrap_used, reason = "test")]

use atmo_core::model::idx;
use atmo_flight::Mode;
use atmo_flight::actuator_monitor::Detected;
use atmo_sim::closed_loop::{ControllerConfig, TickRecord};

use super::faults::{Flight, assert_clean_landing, clean, fly_with};

fn rotor(onset: &str, rotor: usize, what: &str) -> Flight {
    fly_with(&format!(
        "[[faults.actuators.rotor]]\n{onset}\nrotor = {rotor}\n{what}"
    ))
}

#[test]
fn a_rotor_at_80_percent_is_taken_up_by_the_observer_and_the_landing_made() {
    for onset in ["t = 1.0", "mode = \"transition\""] {
        let f = rotor(onset, 2, "scale = 0.8");
        assert_clean_landing(&f, onset);
    }
}

/// The first tick whose status has `bit` of the actuator monitor set.
fn detected(f: &Flight, bit: u8) -> Option<&TickRecord> {
    f.ticks
        .iter()
        .find(|t| t.outputs.status.actuator_faults & bit != 0)
}

/// No controller here flies three rotors: above z* a failed rotor is
/// detected by the observer's torque at its limit and the thrust is cut
/// (Disarmed, the rotors stopped and the linkage held) before the robot
/// turns over. It falls: not a landing, and the test says so.
#[test]
fn a_rotor_failed_in_flight_is_detected_and_the_thrust_cut_before_a_flip() {
    for (n, what) in [(2, "scale = 0.6"), (2, "scale = 0.0"), (1, "stuck = true")] {
        let f = rotor("t = 1.0", n, what);
        let seen = detected(&f, Detected::ROTOR).unwrap_or_else(|| panic!("{what}"));
        assert!(seen.time > 1.0 && seen.time < 2.0, "{what}: {}", seen.time);
        assert_eq!(seen.outputs.status.mode, Mode::Disarmed, "{what}");
        assert_eq!(seen.outputs.thrust, [0.0; 4], "{what}");
        assert_eq!(seen.outputs.tilt_velocity, 0.0, "{what}");
        // Never armed again, never a take-off while the fault holds.
        let after: Vec<Mode> = f
            .ticks
            .iter()
            .filter(|t| t.time >= seen.time)
            .map(|t| t.outputs.status.mode)
            .collect();
        assert!(
            after
                .iter()
                .all(|m| matches!(m, Mode::Disarmed | Mode::Drive)),
            "{what}: {after:?}"
        );
        assert!(
            f.ticks
                .iter()
                .filter(|t| t.time >= seen.time)
                .all(|t| t.outputs.thrust == [0.0; 4])
        );
        // Cut, it falls; it does not turn over (until it is down).
        let tipped = f
            .ticks
            .iter()
            .filter(|t| t.time >= seen.time && t.truth_height > 0.3)
            .map(|t| {
                let s = &t.truth;
                (s[idx::ROLL].cos() * s[idx::PITCH].cos())
                    .acos()
                    .to_degrees()
            })
            .fold(0.0, f64::max);
        assert!(tipped < 90.0, "{what}: tipped {tipped} deg");
        assert!(!f.landed(), "{what}");
    }
}

/// In the transition the robot is already landing: the failed rotor is
/// detected and the landing goes on, onto the wheels below the crash speed.
#[test]
fn a_rotor_failed_in_the_transition_is_detected_and_landed_on_the_wheels() {
    for what in ["scale = 0.0", "scale = 0.6"] {
        let f = rotor("mode = \"transition\"", 2, what);
        let seen = detected(&f, Detected::ROTOR).unwrap_or_else(|| panic!("{what}"));
        assert_eq!(seen.outputs.status.mode, Mode::Transition, "{what}");
        assert!(f.summary.crash_reason.is_none(), "{what}: {:?}", f.summary);
        let impact = f.summary.impact_speed_mps.unwrap();
        assert!(impact < 1.5, "{what}: {impact}");
        assert!(f.summary.touchdown_tilt_deg.unwrap() > 45.0, "{what}");
        assert!(
            f.modes()
                .ends_with(&[Mode::Transition, Mode::Touchdown, Mode::Drive]),
            "{what}: {:?}",
            f.modes()
        );
    }
    let f = rotor("mode = \"transition\"", 1, "stuck = true");
    assert_clean_landing(&f, "stuck in the transition");
}

/// The encoder stops counting while the tilt motor still obeys: the
/// commanded travel without a count is seen, the tilt is dead-reckoned
/// from the commands, and the landing is the clean one's within the
/// dead reckoning's error (one encoder step).
#[test]
fn a_stuck_tilt_encoder_is_detected_and_the_tilt_dead_reckoned_to_the_landing() {
    for onset in ["t = 1.0", "mode = \"morphing\"\ndelay = 0.2"] {
        let f = fly_with(&format!(
            "[[faults.actuators.tilt_encoder]]\n{onset}\nstuck = true"
        ));
        let seen = detected(&f, Detected::ENCODER_STUCK).unwrap_or_else(|| panic!("{onset}"));
        assert!(seen.outputs.status.mode == Mode::Morphing, "{onset}");
        assert_clean_landing(&f, onset);
        let worst = f
            .ticks
            .iter()
            .filter(|t| t.time >= seen.time)
            .map(|t| (t.outputs.status.tilt - t.truth_tilt).abs())
            .fold(0.0, f64::max);
        let step = ControllerConfig::atmo()
            .unwrap()
            .flight
            .monitor
            .encoder_step_deg;
        assert!(worst <= step.to_radians() + 1e-9, "{onset}: {worst}");
    }
}

/// The tilt motor turns (the encoder counts it) but the arms stay: the MPC
/// over-thrusts for the tilt it believes and the observer learns the lift
/// it did not predict. In morphing the arms are near 0 deg: no wheel
/// landing; a failsafe that hovers (the pilot disarms). In the transition
/// the arms are at the flight limit: failsafe, then a touchdown on the
/// wheels under the crash speed.
#[test]
fn a_slipping_tilt_motor_is_detected_by_the_lift_and_fails_safe() {
    let f = fly_with("[[faults.actuators.tilt_slip]]\nmode = \"morphing\"\ndelay = 0.2");
    let seen = detected(&f, Detected::TILT_MISMATCH).unwrap();
    assert_eq!(seen.outputs.status.mode, Mode::Failsafe);
    assert!(f.summary.crash_reason.is_none(), "{:?}", f.summary);
    let end = f.ticks.last().unwrap();
    assert_eq!(end.outputs.status.mode, Mode::Failsafe);
    assert!(end.truth_height > 0.3, "hovering: {}", end.truth_height);
    let f = fly_with("[[faults.actuators.tilt_slip]]\nmode = \"transition\"");
    let seen = detected(&f, Detected::TILT_MISMATCH).unwrap();
    assert_eq!(seen.outputs.status.mode, Mode::Failsafe);
    assert!(f.summary.crash_reason.is_none(), "{:?}", f.summary);
    assert!(f.summary.impact_speed_mps.unwrap() < 1.0, "{:?}", f.summary);
    assert!(
        f.modes()
            .ends_with(&[Mode::Failsafe, Mode::Touchdown, Mode::Drive])
    );
}

#[test]
fn a_tilt_encoder_jump_of_400_counts_is_flown_through() {
    let f = fly_with("[[faults.actuators.tilt_encoder]]\nt = 1.0\njump_counts = 400.0");
    assert_clean_landing(&f, "encoder jump");
}

/// A contact reported 1.5 m up cut the thrust (Flight -> Touchdown) and
/// crashed the robot: a contact is believed only where the fresh estimate
/// puts the base at most `takeoff_height` above the ground.
#[test]
fn a_false_ground_contact_in_flight_is_not_believed() {
    let f = fly_with("[[faults.actuators.contact]]\nt = 1.0\nduration = 0.3\nkind = \"false\"");
    let during: Vec<_> = f
        .ticks
        .iter()
        .filter(|t| (1.0..1.3).contains(&t.time))
        .collect();
    assert!(during.iter().any(|t| t.inputs.ground_contact));
    assert!(
        during
            .iter()
            .all(|t| t.outputs.status.mode != Mode::Touchdown)
    );
    assert_clean_landing(&f, "false contact");
    assert_eq!(f.summary.impact_speed_mps, clean().summary.impact_speed_mps);
}

/// No contact reported though the wheels are down: the estimate says the
/// wheels rest on the ground (clearance, vertical speed, for a time) and
/// that is the contact; the touchdown is the clean landing's.
#[test]
fn a_missed_ground_contact_is_inferred_from_the_estimate_and_landed() {
    let f = fly_with(
        "[[faults.actuators.contact]]\nmode = \"transition\"\nduration = 3.0\nkind = \"missed\"",
    );
    let entry = f.first_in(Mode::Transition, 0.0).unwrap().time;
    let touchdown = f.first_in(Mode::Touchdown, 0.0).unwrap();
    assert!(
        touchdown.time < entry + 3.0,
        "transition {entry}, touchdown {}",
        touchdown.time
    );
    assert!(!touchdown.inputs.ground_contact);
    assert!(touchdown.outputs.status.actuator_faults & Detected::CONTACT_INFERRED != 0);
    // The wheels settle, then the estimate must rest for `contact_time`.
    let clean_touchdown = clean().first_in(Mode::Touchdown, 0.0).unwrap().time;
    let settle = ControllerConfig::atmo()
        .unwrap()
        .flight
        .monitor
        .contact_time;
    assert!(
        touchdown.time - clean_touchdown >= settle && touchdown.time - clean_touchdown < 0.5,
        "{} s after the clean touchdown",
        touchdown.time - clean_touchdown
    );
    assert_clean_landing(&f, "missed contact");
    assert_eq!(f.summary.impact_speed_mps, clean().summary.impact_speed_mps);
}

/// The radio goes silent: after the daemon's RC timeout the radio is lost,
/// a failsafe that holds (no recovery while lost); once it is back and the
/// failsafe is old enough, flight again and the landing.
#[test]
fn a_lost_radio_fails_safe_and_the_landing_follows_its_return() {
    for onset in ["t = 1.0", "mode = \"transition\""] {
        let f = fly_with(&format!(
            "[[faults.actuators.radio]]\n{onset}\nduration = 1.0"
        ));
        let lost = f.ticks.iter().find(|t| t.inputs.pilot_lost).unwrap();
        let failsafe = f.first_in(Mode::Failsafe, 0.0).unwrap();
        assert!((failsafe.time - lost.time).abs() < 0.02, "{onset}");
        let back = f
            .ticks
            .iter()
            .find(|t| t.time > lost.time && !t.inputs.pilot_lost)
            .unwrap();
        assert!(
            f.ticks
                .iter()
                .filter(|t| t.time >= failsafe.time && t.time < back.time)
                .all(|t| t.outputs.status.mode == Mode::Failsafe),
            "{onset}"
        );
        assert!(f.landed(), "{onset}: {:?}", f.summary);
        assert!(
            f.modes()
                .ends_with(&[Mode::Transition, Mode::Touchdown, Mode::Drive])
        );
    }
}

#[test]
fn a_bad_actuator_fault_is_refused_naming_the_key() {
    for (faults, key) in [
        (
            "[[faults.actuators.rotor]]\nt = 1.0\nrotor = 5",
            "faults.actuators.rotor[0].rotor",
        ),
        (
            "[[faults.actuators.rotor]]\nt = 1.0\nrotor = 1\nscale = 1.5",
            "faults.actuators.rotor[0].scale",
        ),
        (
            "[[faults.actuators.contact]]\nt = 1.0\nduration = 0.1\nkind = \"maybe\"",
            "faults.actuators.contact[0].kind",
        ),
        (
            "[[faults.actuators.tilt_encoder]]\nstuck = true",
            "faults.actuators.tilt_encoder[0]",
        ),
    ] {
        let path = super::faults::scenario_path();
        let text = std::fs::read_to_string(&path).unwrap();
        let err = atmo_sim::Scenario::from_toml_str(&format!("{text}\n{faults}\n"), &path)
            .unwrap_err()
            .to_string();
        assert!(err.contains(&format!("`{key}")), "{faults}: {err}");
    }
}
