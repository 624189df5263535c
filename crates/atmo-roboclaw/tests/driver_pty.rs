//! The driver against the simulated Roboclaw over a real pseudo-terminal:
//! homing, velocity commands reaching the encoder, the two stops (the
//! driver's watchdog and the board's serial timeout), corrupt answers, a
//! silent board and a board reset, counted and reported.
#![allow(clippy::unwrap_used)]

mod common;

use atmo_core::ConfigFile;
use atmo_roboclaw::driver::{DriverCommand, Phase};
use atmo_roboclaw::protocol::Motor;
use atmo_roboclaw::sim::SimConfig;
use common::Rig;

/// The tilt board starting 3000 counts from home, homed.
fn homed_tilt() -> Rig {
    let mut rig = Rig::new(SimConfig::tilt(3000.0), "tilt.toml");
    assert!(
        rig.run_until(5.0, None, |r| r.driver.phase() == Phase::Running),
        "homing did not finish: {:?}, {}",
        rig.driver.phase(),
        rig.board.health()
    );
    rig
}

#[test]
fn homing_drives_to_the_switch_and_zeroes_the_counter() {
    let mut rig = Rig::new(SimConfig::tilt(3000.0), "tilt.toml");
    rig.tick(None);
    assert!(matches!(rig.driver.phase(), Phase::Homing { .. }));
    assert!(rig.driver.firmware().unwrap().as_str().contains("Roboclaw"));
    assert_eq!(rig.sim(|b| b.serial_timeout()), 5, "500 ms set at start");
    let start = rig.now();
    assert!(rig.run_until(5.0, None, |r| r.driver.phase() == Phase::Running));
    // 3000 counts at 2000 counts/s, with the 50 ms speed lag.
    let took = (rig.now() - start) as f64 * 1e-9;
    assert!((1.4..2.0).contains(&took), "homing took {took} s");
    assert!(rig.sim(|b| b.home_triggered()));
    assert_eq!(rig.sim(|b| b.encoder(Motor::M2)), 0);
    assert_eq!(rig.driver.counters().homings, 1);
    let out = rig.tick(None);
    assert_eq!(out.encoders[1], Some(0));
    assert!((out.tilt.unwrap().to_degrees() - 90.0).abs() < 1e-9);
    assert!(out.alive);
    assert!(out.watchdog_stop, "no command yet: zero speed");
    assert_eq!(out.speeds[1], Some(0));
    // The daemon's convention: the linkage model's counts at 90 deg.
    let robot = atmo_core::RobotConfig::load(common::repo_config("atmo.toml")).unwrap();
    let linkage = atmo_core::Linkage::from_config(&robot.linkage, robot.limits.tilt_max()).unwrap();
    let at_home = linkage.counts_from_tilt(90f64.to_radians()).unwrap();
    assert_eq!(out.tilt_counts, Some(at_home.round() as i64));
    assert_eq!(rig.board.health().failed, 0);
}

#[test]
fn homing_fails_without_a_switch_and_stops_the_motor() {
    let mut sim = SimConfig::tilt(3000.0);
    sim.home_switch = None;
    let mut rig = Rig::new(sim, "tilt.toml");
    let mut config = rig.driver.settings().clone();
    if let atmo_roboclaw::driver::Role::Tilt(t) = &mut config.role {
        t.homing_timeout_ns = 500_000_000;
    }
    rig.driver = atmo_roboclaw::driver::Driver::new(config);
    assert!(rig.run_until(2.0, None, |r| r.driver.phase() == Phase::Failed));
    assert_eq!(rig.driver.counters().homing_failures, 1);
    rig.tick(None);
    assert_eq!(rig.sim(|b| b.target(Motor::M2)), 0.0);
    assert!(!rig.tick(None).alive);
}

#[test]
fn velocity_commands_reach_the_encoder_counts() {
    let mut rig = homed_tilt();
    // Towards flight (tilt decreasing) at 0.1 rad/s for 2 s (near home the
    // table's slope is 62000 counts/rad: 0.1 rad/s is 6200 counts/s, under
    // the 8000 counts/s limit).
    let v = -0.1;
    let start_tilt = rig.tick(None).tilt.unwrap();
    for _ in 0..200 {
        rig.tick(Some(DriverCommand::TiltVelocity(v)));
    }
    let out = rig.last;
    let moved = out.tilt.unwrap() - start_tilt;
    // 0.4 rad less the lag of the board's speed loop (tau 50 ms: ~0.01 rad)
    // and the tick's hold of the table slope.
    assert!(
        (moved - 2.0 * v).abs() < 0.01,
        "moved {moved} rad, commanded {}",
        2.0 * v
    );
    // The counter grew (away from home), as the table says.
    let counts = rig.sim(|b| b.encoder(Motor::M2));
    assert_eq!(out.encoders[1], Some(counts));
    let table = atmo_roboclaw::table::TiltTable::authors();
    let expected = table.counts_from_tilt(start_tilt + moved);
    assert!(
        (f64::from(counts) - expected).abs() < 300.0,
        "counts {counts}, table at the tilt {expected}"
    );
    assert!(
        out.speeds[1].unwrap() > 0,
        "away from home = positive speed"
    );
    assert!(!out.watchdog_stop);
    // Towards drive again: the switch stops it at 90 deg.
    assert!(
        rig.run_until(5.0, Some(DriverCommand::TiltVelocity(0.3)), |r| {
            r.last.tilt.is_some_and(|t| t.to_degrees() >= 90.0 - 1e-9)
        })
    );
    assert_eq!(rig.board.health().failed, 0);
}

#[test]
fn watchdog_stops_the_motor_when_commands_stop() {
    let mut rig = homed_tilt();
    for _ in 0..50 {
        rig.tick(Some(DriverCommand::TiltVelocity(-0.1)));
    }
    assert!(rig.sim(|b| b.speed(Motor::M2)) > 1000.0);
    // Commands stop: 200 ms later the driver commands zero.
    let mut stopped_after = None;
    for i in 1..=80 {
        let out = rig.tick(None);
        if out.watchdog_stop && stopped_after.is_none() {
            stopped_after = Some(i * 10);
            assert_eq!(out.speeds[1], Some(0));
        }
    }
    let ms = stopped_after.unwrap();
    assert!((200..=220).contains(&ms), "stopped after {ms} ms");
    assert_eq!(rig.driver.counters().watchdog_stops, 1);
    assert!(rig.sim(|b| b.speed(Motor::M2)).abs() < 1.0);
    // The driver keeps reporting: the daemon still sees it alive.
    assert!(rig.last.alive);
}

#[test]
fn the_boards_serial_timeout_stops_the_motor_when_the_driver_dies() {
    let mut rig = homed_tilt();
    for _ in 0..50 {
        rig.tick(Some(DriverCommand::TiltVelocity(-0.2)));
    }
    // The driver process stops talking; the board's 500 ms timeout acts.
    let now = rig.clock.advance(1_500_000_000);
    rig.sim(|b| b.advance(now + 1));
    assert_eq!(rig.sim(|b| b.stats.serial_timeouts), 1);
    assert_eq!(rig.sim(|b| b.target(Motor::M2)), 0.0);
    assert!(rig.sim(|b| b.speed(Motor::M2)).abs() < 1.0);
}

#[test]
fn corrupt_answers_are_counted_and_retried() {
    let mut rig = homed_tilt();
    rig.tick(Some(DriverCommand::TiltVelocity(-0.1)));
    let before = *rig.board.health();
    // Two answers with a broken CRC (or a broken acknowledgement).
    rig.sim(|b| b.faults.corrupt_next = 2);
    for _ in 0..5 {
        rig.tick(Some(DriverCommand::TiltVelocity(-0.1)));
    }
    let h = *rig.board.health();
    assert_eq!(rig.sim(|b| b.stats.corrupted_answers), 2);
    assert_eq!(
        (h.crc_errors - before.crc_errors) + (h.bad_answers - before.bad_answers),
        2,
        "{h}"
    );
    assert!(
        h.crc_errors > before.crc_errors,
        "an encoder read was corrupted: {h}"
    );
    assert_eq!(h.retries - before.retries, 2);
    assert_eq!(h.failed, 0, "each retry succeeded");
    assert!(rig.last.alive);
    assert!(h.last_error.is_none());
}

#[test]
fn a_silent_board_is_counted_and_the_heartbeat_stops() {
    let mut rig = homed_tilt();
    rig.tick(Some(DriverCommand::TiltVelocity(-0.1)));
    assert!(rig.last.alive);
    rig.sim(|b| b.faults.silent = true);
    let t0 = std::time::Instant::now();
    for _ in 0..3 {
        rig.tick(Some(DriverCommand::TiltVelocity(-0.1)));
    }
    let h = *rig.board.health();
    assert!(!rig.last.alive, "no heartbeat from a silent board");
    assert_eq!(h.no_answer, 9, "{h}");
    assert_eq!(h.failed, 3, "{h}");
    let e = h.last_error.unwrap().to_string();
    assert!(e.contains("no answer within 100 ms, 3 attempts"), "{e}");
    // A tick stops at its first failed transaction: 3 attempts of 100 ms.
    let took = t0.elapsed().as_millis();
    assert!((900..2000).contains(&took), "{took} ms");
    rig.sim(|b| b.faults.silent = false);
    rig.tick(Some(DriverCommand::TiltVelocity(-0.1)));
    assert!(rig.last.alive, "back when it answers again");
    assert_eq!(rig.driver.phase(), Phase::Running);
}

#[test]
fn the_driver_starts_once_a_silent_board_answers() {
    let mut sim = SimConfig::tilt(0.0);
    sim.firmware = "USB Roboclaw 2x15a v4.2.8".into();
    let mut rig = Rig::new(sim, "tilt.toml");
    rig.sim(|b| b.faults.silent = true);
    for _ in 0..3 {
        rig.tick(None);
    }
    assert_eq!(rig.driver.phase(), Phase::Starting);
    assert_eq!(rig.board.health().no_answer, 9);
    rig.sim(|b| b.faults.silent = false);
    assert!(rig.run_until(1.0, None, |r| r.driver.phase() == Phase::Running));
    assert_eq!(rig.driver.counters().starts, 1);
}

#[test]
fn a_board_reset_is_detected_counted_and_homed_again() {
    let mut rig = homed_tilt();
    // To about 60 deg.
    assert!(
        rig.run_until(3.0, Some(DriverCommand::TiltVelocity(-0.3)), |r| {
            r.last.tilt.is_some_and(|t| t.to_degrees() < 60.0)
        })
    );
    let true_position = rig.sim(|b| b.position(Motor::M2));
    rig.sim(atmo_roboclaw::sim::SimBoard::reset);
    assert_eq!(rig.sim(|b| b.encoder(Motor::M2)), 0);
    // Detected at the next encoder read (a jump back to the power-up 0).
    rig.tick(Some(DriverCommand::TiltVelocity(-0.3)));
    assert_eq!(rig.board.health().resets, 1);
    assert_eq!(rig.driver.phase(), Phase::Starting);
    assert!(!rig.last.alive);
    // Started and homed again: the counter means the tilt again.
    assert!(rig.run_until(10.0, None, |r| r.driver.phase() == Phase::Running));
    assert_eq!(rig.driver.counters().homings, 2);
    assert_eq!(rig.driver.counters().starts, 2);
    assert_eq!(
        rig.sim(|b| b.serial_timeout()),
        5,
        "set again after the reset"
    );
    let out = rig.tick(None);
    assert!((out.tilt.unwrap().to_degrees() - 90.0).abs() < 1e-9);
    assert!(rig.sim(|b| b.position(Motor::M2)) < true_position);
}

#[test]
fn a_reset_at_standstill_is_found_by_the_serial_timeout_read_back() {
    let mut rig = homed_tilt();
    // Standing at home, the counter is 0 before and after: only the
    // board's settings show the reset.
    for _ in 0..10 {
        rig.tick(None);
    }
    rig.sim(atmo_roboclaw::sim::SimBoard::reset);
    assert!(rig.run_until(1.0, None, |r| r.board.health().resets == 1));
    assert!(rig.run_until(5.0, None, |r| r.driver.phase() == Phase::Running));
    assert_eq!(rig.sim(|b| b.serial_timeout()), 5);
}

#[test]
fn wheel_rates_reach_both_motors() {
    let mut rig = Rig::new(SimConfig::wheels(), "wheels.toml");
    assert!(rig.run_until(0.5, None, |r| r.driver.phase() == Phase::Running));
    // Left 2 rad/s, right 1 rad/s for 1 s: left on M2 (+300 counts/rad),
    // right on M1 (-300 counts/rad).
    for _ in 0..100 {
        rig.tick(Some(DriverCommand::WheelRates([2.0, 1.0])));
    }
    let out = rig.last;
    assert_eq!(out.speeds, [Some(-300), Some(600)]);
    let (m1, m2) = rig.sim(|b| (b.encoder(Motor::M1), b.encoder(Motor::M2)));
    // 1 s less the 50 ms lag.
    assert!((f64::from(m2) - 570.0).abs() < 20.0, "M2 {m2}");
    assert!((f64::from(m1) + 285.0).abs() < 20.0, "M1 {m1}");
    assert!(out.alive);
    // Rates stop: the watchdog stops both.
    assert!(rig.run_until(1.0, None, |r| r.last.watchdog_stop));
    let out = rig.tick(None);
    assert_eq!(out.speeds, [Some(0), Some(0)]);
    assert_eq!(rig.board.health().failed, 0);
}

#[test]
fn the_linkage_calibration_drives_and_reports_the_same_way() {
    let mut rig = Rig::new(SimConfig::tilt(0.0), "tilt.toml+linkage");
    assert!(rig.run_until(1.0, None, |r| r.driver.phase() == Phase::Running));
    let home = rig.tick(None);
    assert!((home.tilt.unwrap().to_degrees() - 90.0).abs() < 1e-6);
    assert_eq!(home.tilt_counts, Some(19929));
    // Near 90 deg the model's counts per rad grow without bound (the
    // linkage's singular end): the 8000 counts/s limit holds the tilt
    // speed there. Away from it, 0.1 rad/s for 1 s is 0.1 rad.
    assert!(
        rig.run_until(3.0, Some(DriverCommand::TiltVelocity(-0.2)), |r| {
            r.last.tilt.is_some_and(|t| t.to_degrees() < 75.0)
        })
    );
    let start = rig.last.tilt.unwrap();
    for _ in 0..100 {
        rig.tick(Some(DriverCommand::TiltVelocity(-0.1)));
    }
    let out = rig.last;
    let moved = out.tilt.unwrap() - start;
    assert!((moved + 0.1).abs() < 0.01, "moved {moved} rad");
    // The board's counter grew; the model's counts fell with the tilt.
    assert!(out.encoders[1].unwrap() > 0);
    assert!(out.tilt_counts.unwrap() < 19929);
    assert_eq!(
        out.tilt_counts.unwrap(),
        19929 - i64::from(out.encoders[1].unwrap()),
        "board counts are model counts, signed"
    );
}

#[test]
fn a_wheel_board_reset_is_detected_and_the_wheels_run_on() {
    let mut rig = Rig::new(SimConfig::wheels(), "wheels.toml");
    let rates = Some(DriverCommand::WheelRates([5.0, 5.0]));
    assert!(rig.run_until(0.5, rates, |r| r.driver.phase() == Phase::Running));
    for _ in 0..100 {
        rig.tick(rates);
    }
    rig.sim(atmo_roboclaw::sim::SimBoard::reset);
    rig.tick(rates);
    assert_eq!(rig.board.health().resets, 1);
    assert!(rig.run_until(0.5, rates, |r| r.driver.phase() == Phase::Running));
    assert_eq!(rig.driver.counters().starts, 2);
    for _ in 0..50 {
        rig.tick(rates);
    }
    assert_eq!(rig.last.speeds, [Some(-1500), Some(1500)]);
    assert!(rig.sim(|b| b.speed(Motor::M2)) > 1400.0);
    assert_eq!(rig.sim(|b| b.serial_timeout()), 5);
}

#[test]
fn the_pilots_encoder_reset_homes_again_once_per_flip() {
    let mut rig = homed_tilt();
    // To about 60 deg, then the switch flipped (and held).
    assert!(
        rig.run_until(3.0, Some(DriverCommand::TiltVelocity(-0.3)), |r| {
            r.last.tilt.is_some_and(|t| t.to_degrees() < 60.0)
        })
    );
    let now = rig.now();
    rig.driver.rehome_request(true, now);
    assert!(matches!(rig.driver.phase(), Phase::Homing { .. }));
    assert!(rig.run_until(10.0, None, |r| r.driver.phase() == Phase::Running));
    assert_eq!(rig.driver.counters().homings, 2);
    assert_eq!(rig.driver.counters().rehome_requests, 1);
    let out = rig.tick(None);
    assert!((out.tilt.unwrap().to_degrees() - 90.0).abs() < 1e-9);
    assert_eq!(rig.sim(|b| b.encoder(Motor::M2)), 0);
    // Held on: no second homing; off and on again: one more.
    let now = rig.now();
    rig.driver.rehome_request(true, now);
    assert_eq!(rig.driver.phase(), Phase::Running);
    rig.driver.rehome_request(false, now);
    rig.driver.rehome_request(true, now);
    assert!(matches!(rig.driver.phase(), Phase::Homing { .. }));
    assert_eq!(rig.driver.counters().rehome_requests, 2);
    assert_eq!(rig.board.health().failed, 0);
}
