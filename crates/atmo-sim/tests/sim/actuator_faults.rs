//! The actuator side's faults (`[faults.actuators]`): the wheel landing
//! flown with one fault each, and what the flight stack does
//! (docs/faults.md, the actuator table). Where the stack has no detection
//! the test pins the outcome, so a change to it is seen.
#![allow(clippy::unwrap_used, reason = "test")]

use atmo_flight::Mode;

use super::faults::{Flight, assert_clean_landing, clean, fly_with};

fn rotor(onset: &str, rotor: usize, what: &str) -> Flight {
    fly_with(&format!(
        "[[faults.actuators.rotor]]\n{onset}\nrotor = {rotor}\n{what}"
    ))
}

fn crash(f: &Flight) -> String {
    f.summary.crash_reason.clone().unwrap_or_default()
}

#[test]
fn a_rotor_at_80_percent_is_taken_up_by_the_observer_and_the_landing_made() {
    for onset in ["t = 1.0", "mode = \"transition\""] {
        let f = rotor(onset, 2, "scale = 0.8");
        assert_clean_landing(&f, onset);
    }
}

#[test]
fn a_rotor_stopped_or_at_60_percent_in_flight_is_not_detected_and_crashes() {
    for what in ["scale = 0.6", "scale = 0.0"] {
        let f = rotor("t = 1.0", 2, what);
        assert!(!f.landed(), "{what}");
        assert!(
            crash(&f).contains("BodyContact") || crash(&f).contains("HardImpact"),
            "{what}: {:?}",
            f.summary
        );
        assert!(
            !f.modes().contains(&Mode::Failsafe),
            "{what}: {:?}",
            f.modes()
        );
    }
}

#[test]
fn a_rotor_stopped_in_the_transition_touches_down_hard_without_a_crash() {
    let f = rotor("mode = \"transition\"", 2, "scale = 0.0");
    assert!(f.summary.crash_reason.is_none(), "{:?}", f.summary);
    let impact = f.summary.impact_speed_mps.unwrap();
    assert!(impact > 0.5 && impact < 1.5, "{impact}");
    assert!(f.modes().ends_with(&[Mode::Touchdown, Mode::Drive]));
}

#[test]
fn a_rotor_stuck_at_its_command_crashes_in_flight_and_is_landed_in_the_transition() {
    let f = rotor("t = 1.0", 1, "stuck = true");
    assert!(crash(&f).contains("BodyContact"), "{:?}", f.summary);
    let f = rotor("mode = \"transition\"", 1, "stuck = true");
    assert_clean_landing(&f, "stuck in the transition");
}

#[test]
fn a_stuck_tilt_encoder_keeps_morphing_from_the_transition_and_lands_too_fast() {
    for onset in ["t = 1.0", "mode = \"morphing\"\ndelay = 0.2"] {
        let f = fly_with(&format!(
            "[[faults.actuators.tilt_encoder]]\n{onset}\nstuck = true"
        ));
        assert!(f.summary.crash_reason.is_none(), "{onset}: {:?}", f.summary);
        assert!(
            !f.modes().contains(&Mode::Transition),
            "{onset}: {:?}",
            f.modes()
        );
        let impact = f.summary.impact_speed_mps.unwrap();
        assert!(impact > 0.5, "{onset}: {impact}");
    }
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

#[test]
fn a_missed_ground_contact_holds_the_transition_until_contact_returns() {
    let f = fly_with(
        "[[faults.actuators.contact]]\nmode = \"transition\"\nduration = 3.0\nkind = \"missed\"",
    );
    let entry = f.first_in(Mode::Transition, 0.0).unwrap().time;
    let touchdown = f.first_in(Mode::Touchdown, 0.0).unwrap().time;
    assert!(
        (touchdown - (entry + 3.0)).abs() < 0.02,
        "transition {entry}, touchdown {touchdown}"
    );
    assert!(f.summary.crash_reason.is_none());
    assert_eq!(f.summary.impact_speed_mps, clean().summary.impact_speed_mps);
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
