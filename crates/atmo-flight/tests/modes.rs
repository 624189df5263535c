//! One test per transition of the mode table, and the guards that must not fire.

use atmo_flight::Mode;
use atmo_flight::modes::{Conditions, TRANSITIONS, Thresholds, next_mode};

fn thresholds() -> Thresholds {
    Thresholds {
        takeoff_throttle: 0.5,
        takeoff_height: 0.3,
        morph_height: 1.2,
        morph_hysteresis: 0.1,
        transition_height: 0.45,
        transition_min_tilt: 45f64.to_radians(),
        thrust_cut_time: 0.3,
        touchdown_max_tip: 10f64.to_radians(),
        touchdown_level_timeout: 1.0,
        failsafe_recovery_time: 0.5,
        failsafe_recovery_tilt: 2f64.to_radians(),
    }
}

/// Healthy, armed, hovering at 2 m in the quadrotor configuration.
fn flying() -> Conditions {
    Conditions {
        armed: true,
        arming_ok: true,
        grounded: false,
        height: 2.0,
        throttle: 0.0,
        descent_commanded: false,
        estimate_fresh: true,
        mpc_failed: false,
        driver_lost: false,
        pilot_lost: false,
        tilt_unknown: false,
        rotor_failed: false,
        rotor_out: false,
        body_tip: 0.0,
        time_grounded: 0.0,
        tilt: 0.0,
        time_in_mode: 10.0,
    }
}

fn on_ground() -> Conditions {
    Conditions {
        grounded: true,
        height: 0.2,
        tilt: 1.1,
        ..flying()
    }
}

fn step(mode: Mode, c: Conditions) -> Mode {
    next_mode(mode, &c, &thresholds()).0
}

#[test]
fn disarm_from_every_armed_mode() {
    for mode in Mode::ALL {
        let c = Conditions {
            armed: false,
            ..flying()
        };
        assert_eq!(step(mode, c), Mode::Disarmed, "{mode:?}");
    }
}

#[test]
fn disarmed_to_drive_when_armed_on_the_ground() {
    assert_eq!(step(Mode::Disarmed, on_ground()), Mode::Drive);
    // Standing on its wheels before the contact signal rises: still the ground.
    assert_eq!(
        step(
            Mode::Disarmed,
            Conditions {
                grounded: false,
                ..on_ground()
            }
        ),
        Mode::Drive
    );
    assert_eq!(
        step(
            Mode::Disarmed,
            Conditions {
                armed: false,
                ..on_ground()
            }
        ),
        Mode::Disarmed
    );
    // Armed before any estimate, no contact: the height (0, no estimate's)
    // proves nothing, so it waits disarmed; contact alone is the ground.
    let unknown = Conditions {
        grounded: false,
        height: 0.0,
        estimate_fresh: false,
        ..on_ground()
    };
    assert_eq!(step(Mode::Disarmed, unknown), Mode::Disarmed);
    let touching = Conditions {
        grounded: true,
        ..unknown
    };
    assert_eq!(step(Mode::Disarmed, touching), Mode::Drive);
}

#[test]
fn disarmed_to_flight_when_armed_in_the_air_with_an_estimate() {
    assert_eq!(step(Mode::Disarmed, flying()), Mode::Flight);
    let stale = Conditions {
        estimate_fresh: false,
        ..flying()
    };
    assert_eq!(step(Mode::Disarmed, stale), Mode::Disarmed);
    let low = Conditions {
        height: 0.25,
        ..flying()
    };
    assert_eq!(step(Mode::Disarmed, low), Mode::Drive);
}

#[test]
fn flying_modes_to_failsafe_on_stale_estimate_or_mpc_failure() {
    for mode in [
        Mode::Takeoff,
        Mode::Flight,
        Mode::Morphing,
        Mode::Transition,
    ] {
        assert_eq!(
            step(
                mode,
                Conditions {
                    estimate_fresh: false,
                    ..flying()
                }
            ),
            Mode::Failsafe,
            "{mode:?}"
        );
        assert_eq!(
            step(
                mode,
                Conditions {
                    mpc_failed: true,
                    ..flying()
                }
            ),
            Mode::Failsafe,
            "{mode:?}"
        );
        assert_eq!(
            step(
                mode,
                Conditions {
                    driver_lost: true,
                    ..flying()
                }
            ),
            Mode::Failsafe,
            "{mode:?}"
        );
        assert_eq!(
            step(
                mode,
                Conditions {
                    pilot_lost: true,
                    ..flying()
                }
            ),
            Mode::Failsafe,
            "{mode:?}: radio lost"
        );
    }
    // Driving needs neither.
    assert_eq!(
        step(
            Mode::Drive,
            Conditions {
                estimate_fresh: false,
                mpc_failed: true,
                ..on_ground()
            }
        ),
        Mode::Drive
    );
}

#[test]
fn failsafe_to_touchdown_when_grounded() {
    assert_eq!(
        step(
            Mode::Failsafe,
            Conditions {
                estimate_fresh: false,
                ..on_ground()
            }
        ),
        Mode::Touchdown
    );
}

#[test]
fn failsafe_to_flight_only_when_healthy_tilted_back_and_after_the_recovery_time() {
    assert_eq!(step(Mode::Failsafe, flying()), Mode::Flight);
    assert_eq!(
        step(
            Mode::Failsafe,
            Conditions {
                time_in_mode: 0.2,
                ..flying()
            }
        ),
        Mode::Failsafe
    );
    assert_eq!(
        step(
            Mode::Failsafe,
            Conditions {
                tilt: 0.3,
                ..flying()
            }
        ),
        Mode::Failsafe
    );
    assert_eq!(
        step(
            Mode::Failsafe,
            Conditions {
                mpc_failed: true,
                ..flying()
            }
        ),
        Mode::Failsafe
    );
    assert_eq!(
        step(
            Mode::Failsafe,
            Conditions {
                estimate_fresh: false,
                ..flying()
            }
        ),
        Mode::Failsafe
    );
    assert_eq!(
        step(
            Mode::Failsafe,
            Conditions {
                driver_lost: true,
                ..flying()
            }
        ),
        Mode::Failsafe
    );
    assert_eq!(
        step(
            Mode::Failsafe,
            Conditions {
                pilot_lost: true,
                ..flying()
            }
        ),
        Mode::Failsafe,
        "radio still lost"
    );
}

#[test]
fn drive_to_takeoff_at_half_throttle() {
    assert_eq!(
        step(
            Mode::Drive,
            Conditions {
                throttle: 0.5,
                ..on_ground()
            }
        ),
        Mode::Takeoff
    );
    assert_eq!(
        step(
            Mode::Drive,
            Conditions {
                throttle: 0.49,
                ..on_ground()
            }
        ),
        Mode::Drive
    );
    // No take-off with a dead driver.
    assert_eq!(
        step(
            Mode::Drive,
            Conditions {
                throttle: 0.9,
                driver_lost: true,
                ..on_ground()
            }
        ),
        Mode::Drive
    );
    // Nor with the radio lost.
    assert_eq!(
        step(
            Mode::Drive,
            Conditions {
                throttle: 0.9,
                pilot_lost: true,
                ..on_ground()
            }
        ),
        Mode::Drive
    );
}

#[test]
fn takeoff_to_drive_when_aborted_on_the_ground() {
    assert_eq!(
        step(
            Mode::Takeoff,
            Conditions {
                throttle: 0.2,
                ..on_ground()
            }
        ),
        Mode::Drive
    );
    assert_eq!(
        step(
            Mode::Takeoff,
            Conditions {
                throttle: 0.7,
                ..on_ground()
            }
        ),
        Mode::Takeoff
    );
}

#[test]
fn takeoff_to_flight_when_airborne_above_the_takeoff_height() {
    assert_eq!(
        step(
            Mode::Takeoff,
            Conditions {
                height: 0.35,
                throttle: 0.7,
                ..flying()
            }
        ),
        Mode::Flight
    );
    assert_eq!(
        step(
            Mode::Takeoff,
            Conditions {
                height: 0.25,
                throttle: 0.7,
                ..flying()
            }
        ),
        Mode::Takeoff
    );
}

#[test]
fn flight_to_morphing_below_z_varphi_when_descending() {
    let low = Conditions {
        height: 1.0,
        descent_commanded: true,
        ..flying()
    };
    assert_eq!(step(Mode::Flight, low), Mode::Morphing);
    assert_eq!(
        step(
            Mode::Flight,
            Conditions {
                descent_commanded: false,
                ..low
            }
        ),
        Mode::Flight
    );
    assert_eq!(
        step(Mode::Flight, Conditions { height: 1.5, ..low }),
        Mode::Flight
    );
}

#[test]
fn morphing_to_flight_when_climbing_back_past_the_hysteresis() {
    assert_eq!(
        step(
            Mode::Morphing,
            Conditions {
                height: 1.35,
                ..flying()
            }
        ),
        Mode::Flight
    );
    assert_eq!(
        step(
            Mode::Morphing,
            Conditions {
                height: 1.25,
                ..flying()
            }
        ),
        Mode::Morphing
    );
}

#[test]
fn morphing_to_transition_below_z_star_once_tilted() {
    let tilted = 46f64.to_radians();
    assert_eq!(
        step(
            Mode::Morphing,
            Conditions {
                height: 0.44,
                tilt: tilted,
                ..flying()
            }
        ),
        Mode::Transition
    );
    assert_eq!(
        step(
            Mode::Morphing,
            Conditions {
                height: 0.46,
                tilt: tilted,
                ..flying()
            }
        ),
        Mode::Morphing
    );
    // Folded (after a failsafe near the ground): morphing holds on.
    assert_eq!(
        step(
            Mode::Morphing,
            Conditions {
                height: 0.3,
                tilt: 44f64.to_radians(),
                ..flying()
            }
        ),
        Mode::Morphing
    );
}

#[test]
fn transition_to_touchdown_on_contact() {
    for mode in [Mode::Transition, Mode::Morphing, Mode::Flight] {
        assert_eq!(step(mode, on_ground()), Mode::Touchdown, "{mode:?}");
    }
    assert_eq!(
        step(
            Mode::Transition,
            Conditions {
                height: 0.1,
                ..flying()
            }
        ),
        Mode::Transition
    );
}

/// With a rotor failed, a contact with the body tipped past
/// `touchdown_max_tip` is one wheel touching: the flight goes on (the
/// touchdown's thrust ramp would drop the body onto its other wheels); level
/// it is a touchdown, and tipped too once the contact has lasted
/// `touchdown_level_timeout` (resting on something). Without a rotor fault
/// a tipped contact is one too (a slope).
#[test]
fn with_a_rotor_failed_a_contact_is_a_touchdown_only_level() {
    let tipped = 25f64.to_radians();
    for mode in [Mode::Transition, Mode::Morphing, Mode::Flight] {
        let failed = Conditions {
            rotor_failed: true,
            body_tip: tipped,
            ..on_ground()
        };
        assert_ne!(step(mode, failed), Mode::Touchdown, "{mode:?} tipped");
        let resting = Conditions {
            time_grounded: 1.0,
            ..failed
        };
        assert_eq!(
            step(mode, resting),
            Mode::Touchdown,
            "{mode:?} resting tipped"
        );
        let level = Conditions {
            body_tip: 5f64.to_radians(),
            ..failed
        };
        assert_eq!(step(mode, level), Mode::Touchdown, "{mode:?} level");
        let healthy = Conditions {
            body_tip: tipped,
            ..on_ground()
        };
        assert_eq!(step(mode, healthy), Mode::Touchdown, "{mode:?} healthy");
    }
}

/// A contact reported while the fresh estimate puts the robot 1.5 m up is
/// a false one (a sensor fault): believing it cut the thrust in flight and
/// crashed the robot. Not believed with a fresh estimate; believed without
/// one (the estimate cannot say otherwise) and at the ground.
#[test]
fn a_contact_reported_high_above_the_ground_is_not_believed() {
    let false_contact = Conditions {
        grounded: true,
        height: 1.5,
        ..flying()
    };
    for mode in [
        Mode::Transition,
        Mode::Morphing,
        Mode::Flight,
        Mode::Failsafe,
    ] {
        assert_ne!(step(mode, false_contact), Mode::Touchdown, "{mode:?}");
    }
    assert_eq!(step(Mode::Flight, false_contact), Mode::Flight);
    let stale = Conditions {
        estimate_fresh: false,
        ..false_contact
    };
    assert_eq!(step(Mode::Failsafe, stale), Mode::Touchdown);
    let at_takeoff_height = Conditions {
        height: 0.3,
        ..false_contact
    };
    assert_eq!(step(Mode::Transition, at_takeoff_height), Mode::Touchdown);
}

#[test]
fn touchdown_to_drive_once_the_thrust_is_cut() {
    assert_eq!(
        step(
            Mode::Touchdown,
            Conditions {
                time_in_mode: 0.31,
                ..on_ground()
            }
        ),
        Mode::Drive
    );
    assert_eq!(
        step(
            Mode::Touchdown,
            Conditions {
                time_in_mode: 0.1,
                ..on_ground()
            }
        ),
        Mode::Touchdown
    );
}

#[test]
fn every_row_of_the_table_is_exercised_above() {
    // A new row without a test shows up here: each (from, to) pair must be one
    // of the pairs the tests above cover.
    let covered = [
        (Mode::Drive, Mode::Disarmed),
        (Mode::Flight, Mode::Disarmed),
        (Mode::Disarmed, Mode::Drive),
        (Mode::Disarmed, Mode::Flight),
        (Mode::Flight, Mode::Failsafe),
        (Mode::Failsafe, Mode::Touchdown),
        (Mode::Failsafe, Mode::Flight),
        (Mode::Drive, Mode::Takeoff),
        (Mode::Takeoff, Mode::Drive),
        (Mode::Takeoff, Mode::Flight),
        (Mode::Flight, Mode::Morphing),
        (Mode::Morphing, Mode::Flight),
        (Mode::Morphing, Mode::Transition),
        (Mode::Transition, Mode::Touchdown),
        (Mode::Touchdown, Mode::Drive),
    ];
    for row in TRANSITIONS {
        assert!(
            covered
                .iter()
                .any(|(from, to)| row.from.contains(from) && row.to == *to),
            "untested row to {:?} ({})",
            row.to,
            row.reason
        );
    }
}

#[test]
fn a_failed_arming_check_keeps_it_disarmed_on_the_ground_and_in_the_air() {
    for c in [on_ground(), flying()] {
        let refused = Conditions {
            arming_ok: false,
            ..c
        };
        assert_eq!(step(Mode::Disarmed, refused), Mode::Disarmed);
        assert_ne!(step(Mode::Disarmed, c), Mode::Disarmed);
    }
    // Once armed the checks do not disarm: the failsafes act instead.
    let flying_refused = Conditions {
        arming_ok: false,
        ..flying()
    };
    assert_eq!(step(Mode::Flight, flying_refused), Mode::Flight);
}

#[test]
fn a_tilt_not_where_believed_fails_safe_and_holds_until_disarmed() {
    for mode in [
        Mode::Takeoff,
        Mode::Flight,
        Mode::Morphing,
        Mode::Transition,
    ] {
        let c = Conditions {
            tilt_unknown: true,
            ..flying()
        };
        assert_eq!(step(mode, c), Mode::Failsafe, "{mode:?}");
    }
    let c = Conditions {
        tilt_unknown: true,
        ..flying()
    };
    assert_eq!(step(Mode::Failsafe, c), Mode::Failsafe, "no recovery");
    let c = Conditions {
        tilt_unknown: true,
        throttle: 1.0,
        ..on_ground()
    };
    assert_eq!(step(Mode::Drive, c), Mode::Drive, "no take-off");
}

#[test]
fn a_reduced_rotor_flies_on_and_a_rotor_out_descends_in_failsafe_until_grounded() {
    // Reduced (its effectiveness is in the MPC): the flight goes on.
    let c = Conditions {
        rotor_failed: true,
        ..flying()
    };
    for mode in [Mode::Flight, Mode::Transition] {
        assert_eq!(step(mode, c), mode, "{mode:?}");
    }
    let low = Conditions { height: 0.8, ..c };
    assert_eq!(step(Mode::Morphing, low), Mode::Morphing);
    let out = Conditions {
        rotor_out: true,
        ..c
    };
    for mode in [Mode::Takeoff, Mode::Flight, Mode::Morphing] {
        assert_eq!(step(mode, out), Mode::Failsafe, "{mode:?}");
    }
    assert_eq!(step(Mode::Transition, out), Mode::Transition, "it lands");
    assert_eq!(step(Mode::Failsafe, out), Mode::Failsafe, "no recovery");
    let down = Conditions {
        grounded: true,
        height: 0.2,
        ..out
    };
    assert_eq!(step(Mode::Failsafe, down), Mode::Touchdown);
    assert_eq!(
        step(Mode::Disarmed, c),
        Mode::Disarmed,
        "not armed in the air again"
    );
    let c = Conditions {
        rotor_failed: true,
        throttle: 1.0,
        ..on_ground()
    };
    assert_eq!(step(Mode::Disarmed, c), Mode::Drive);
    assert_eq!(step(Mode::Drive, c), Mode::Drive, "no take-off");
}
