//! The fault campaign: the README's wheel landing flown in closed
//! loop (the daemon's own control loop on the plant's clock, deterministic)
//! with one fault of a scenario's `[faults]` table each, and the flight
//! stack's defined reaction to it (docs/faults.md lists them).
// Test, bench and example code: an unwrap that fails is the failure report.
#![allow(clippy::unwrap_used)]

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use atmo_flight::{Mode, SolverStatus};
use atmo_mpc::settings::FeedbackMethod;
use atmo_sim::closed_loop::{ControllerConfig, Summary, TickRecord, fly};
use atmo_sim::scenario::Scenario;

pub(crate) fn scenario_path() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/scenarios/wheel_landing.toml")
}

/// The wheel landing with `faults` (TOML of the `[faults]` table) added.
pub(crate) fn scenario(faults: &str) -> Scenario {
    let text = std::fs::read_to_string(scenario_path()).unwrap();
    Scenario::from_toml_str(&format!("{text}\n{faults}\n"), scenario_path())
        .unwrap_or_else(|e| panic!("{e}"))
}

pub(crate) struct Flight {
    pub(crate) summary: Summary,
    pub(crate) ticks: Vec<TickRecord>,
}

impl Flight {
    /// The modes in the order they were entered.
    pub(crate) fn modes(&self) -> Vec<Mode> {
        let mut modes: Vec<Mode> = Vec::new();
        for t in &self.ticks {
            let mode = t.outputs.status.mode;
            if modes.last() != Some(&mode) {
                modes.push(mode);
            }
        }
        modes
    }

    /// The first tick at or after `time` s in `mode`.
    pub(crate) fn first_in(&self, mode: Mode, after: f64) -> Option<&TickRecord> {
        self.ticks
            .iter()
            .find(|t| t.time >= after - 1e-9 && t.outputs.status.mode == mode)
    }

    fn last(&self) -> &TickRecord {
        self.ticks.last().unwrap()
    }

    pub(crate) fn landed(&self) -> bool {
        scenario("").file.success.met_by(&self.summary)
    }
}

pub(crate) fn fly_scenario(scenario: &Scenario) -> Flight {
    let controller = ControllerConfig::atmo().unwrap().deterministic();
    let mut ticks = Vec::new();
    let summary = fly(scenario, &controller, |r| ticks.push(*r)).unwrap();
    Flight { summary, ticks }
}

pub(crate) fn fly_with(faults: &str) -> Flight {
    fly_scenario(&scenario(faults))
}

/// The landing without faults, once per test process.
pub(crate) fn clean() -> &'static Flight {
    static CLEAN: OnceLock<Flight> = OnceLock::new();
    CLEAN.get_or_init(|| fly_with(""))
}

/// The summary without its wall-clock times (run time, MPC feedback
/// times): bit-identical flights compare equal.
fn flown(summary: &Summary) -> Summary {
    Summary {
        wall_time_s: None,
        feedback_time_median_s: 0.0,
        feedback_time_max_s: 0.0,
        ..summary.clone()
    }
}

/// Whether two flights commanded the same, tick for tick and bit for bit
/// (thrust, tilt velocity, wheels, mode; timings aside).
pub(crate) fn same_commands(a: &Flight, b: &Flight) -> bool {
    a.ticks.len() == b.ticks.len()
        && a.ticks.iter().zip(&b.ticks).all(|(x, y)| {
            let (x, y) = (&x.outputs, &y.outputs);
            x.thrust == y.thrust
                && x.tilt_velocity == y.tilt_velocity
                && x.wheel_rates == y.wheel_rates
                && x.status.mode == y.status.mode
        })
}

/// When the clean landing enters `mode`, s.
pub(crate) fn clean_entry(mode: Mode) -> f64 {
    clean().first_in(mode, 0.0).unwrap().time
}

const FLOWN: [Mode; 5] = [
    Mode::Flight,
    Mode::Morphing,
    Mode::Transition,
    Mode::Touchdown,
    Mode::Drive,
];

pub(crate) fn assert_clean_landing(flight: &Flight, what: &str) {
    assert!(flight.landed(), "{what}: {:#?}", flight.summary);
    assert_flown_through(flight, what);
}

/// Armed, it flew the clean landing's modes in order, no other.
pub(crate) fn assert_flown_through(flight: &Flight, what: &str) {
    let modes = flight.modes();
    let flown: Vec<Mode> = modes
        .iter()
        .copied()
        .skip_while(|m| *m == Mode::Disarmed)
        .collect();
    assert_eq!(flown, FLOWN, "{what}: modes {modes:?}");
}

#[test]
fn the_clean_landing_lands_and_its_timeline() {
    let c = clean();
    for mode in FLOWN {
        println!(
            "clean landing: {} at {:.3} s",
            mode.name(),
            clean_entry(mode)
        );
    }
    assert_clean_landing(c, "no fault");
    println!("clean landing: {:?}", c.summary);
    let io = c.last().io;
    assert_eq!((io.estimates_out_of_order, io.estimate_clock_jumps), (0, 0));
    assert!(io.drivers_alive);
    assert!(io.faults.estimates_published > 14 * 100, "{io:?}");
}

/// A dropout shorter than the estimate timeout (50 ms; 120 Hz motion
/// capture) is flown through on the last estimate. The stamps on either
/// side of a 30 ms dropout are at least 30 ms apart; the 150 Hz ticks see
/// the age grow to within one tick period of that gap.
#[test]
fn short_estimate_dropout_is_flown_through() {
    let t = clean_entry(Mode::Morphing) + 0.2;
    let f = fly_with(&format!(
        "[[faults.estimate_dropout]]\nt = {t}\nduration = 0.03"
    ));
    assert_clean_landing(&f, "30 ms dropout");
    assert!(f.last().io.faults.estimates_dropped >= 3);
    let max_age = f
        .ticks
        .iter()
        .map(|r| r.outputs.status.estimate_age)
        .fold(0.0, f64::max);
    // The estimates that reached the flight stack skip the dropout ...
    let stamps: Vec<u64> = f
        .ticks
        .iter()
        .filter_map(|r| r.inputs.estimate.map(|e| e.stamp_ns))
        .collect();
    let gap = stamps
        .windows(2)
        .map(|w| w[1].saturating_sub(w[0]) as f64 * 1e-9)
        .fold(0.0, f64::max);
    assert!(gap >= 0.03, "largest estimate gap {gap} s");
    // ... and the ticks fly on the last one, the timeout never reached.
    let tick = 1.0 / 150.0;
    assert!(
        max_age > 0.03 - tick && max_age <= 0.05,
        "oldest estimate flown {max_age} s"
    );
}

/// A dropout past the timeout: failsafe at the first tick the estimate is
/// stale (open-loop 0.95 x hover trim without an estimate, tilt back), back
/// to flight once the estimates are back and the failsafe is 0.5 s old
/// (`failsafe.recovery_time`) with the tilt back; then the landing again.
/// The landing meets the scenario's criteria (ended 0.5 s in, the morph
/// reaches z* before the flight limit and holds its height there until
/// tilted: `estimate_dropout_mid_morph_...`).
#[test]
fn estimate_dropout_past_the_timeout_fails_safe_then_recovers_and_lands() {
    for t in [0.3, 0.5] {
        let f = fly_with(&format!(
            "[[faults.estimate_dropout]]\nt = {t}\nduration = 0.3"
        ));
        let at = f
            .ticks
            .iter()
            .position(|r| r.time >= t && r.outputs.status.mode == Mode::Failsafe)
            .expect("no failsafe");
        let (before, failsafe) = (&f.ticks[at - 1], &f.ticks[at]);
        // The first tick whose estimate is stale, within the timeout of the dropout.
        assert!(before.outputs.status.estimate_age <= 0.05);
        assert!(failsafe.outputs.status.estimate_age > 0.05);
        assert!(
            failsafe.time > t && failsafe.time <= t + 0.05 + 1.0 / 150.0,
            "failsafe at {:.3} s, dropout from {t} s",
            failsafe.time
        );
        assert!(failsafe.outputs.tilt_velocity <= 0.0, "tilts back");
        let recovered = f
            .first_in(Mode::Flight, failsafe.time)
            .expect("no recovery");
        assert!(
            recovered.time >= failsafe.time + 0.5 - 1e-9 && recovered.time >= t + 0.3,
            "recovered at {:.3} s",
            recovered.time
        );
        let modes = f.modes();
        assert!(
            modes.ends_with(&[Mode::Transition, Mode::Touchdown, Mode::Drive]),
            "{modes:?}"
        );
        let s = &f.summary;
        println!(
            "dropout at {t} s: touchdown {:?} deg, {:?} m/s",
            s.touchdown_tilt_deg, s.impact_speed_mps
        );
        assert!(!s.crashed && s.impact_speed_mps.unwrap() <= 0.5, "{s:#?}");
        assert!(f.landed(), "{s:#?}");
    }
}

/// A burst (estimates held, then delivered at once): the newest of the
/// burst is flown, the older ones never reach a tick; a hold longer than
/// the timeout is a dropout (failsafe) first.
#[test]
fn estimate_burst_flies_the_newest_and_a_long_hold_fails_safe() {
    let t = clean_entry(Mode::Morphing) + 0.2;
    let short = fly_with(&format!(
        "[[faults.estimate_burst]]\nt = {t}\nduration = 0.04"
    ));
    assert_clean_landing(&short, "40 ms burst");
    assert!(short.last().io.faults.estimates_held >= 4);
    // The tick after the burst flies an estimate measured at its end.
    let after = short.ticks.iter().find(|r| r.time >= t + 0.04).unwrap();
    let age = after.outputs.status.estimate_age;
    assert!(age < 0.01, "estimate age after the burst {age} s");

    // Held 0.3 s: the flight of the same dropout (the burst's older
    // estimates are never flown, the newest is the first after the gap).
    let long = fly_with("[[faults.estimate_burst]]\nt = 0.3\nduration = 0.3");
    let dropout = fly_with("[[faults.estimate_dropout]]\nt = 0.3\nduration = 0.3");
    assert!(long.first_in(Mode::Failsafe, 0.3).is_some());
    assert!(same_commands(&long, &dropout));
    assert!(long.landed(), "{:#?}", long.summary);
}

/// A latency spike: ages are measured from arrival (onboard: acceptance by
/// the ROS 2 thread), so a delay is not seen as such; its onset is a gap,
/// flown through when shorter than the timeout and the delayed estimates
/// are flown. The landing holds with 30 ms extra latency for 1 s.
#[test]
fn latency_spike_below_the_timeout_is_flown_through() {
    let t = clean_entry(Mode::Morphing) + 0.1;
    let f = fly_with(&format!(
        "[[faults.estimate_latency]]\nt = {t}\nduration = 1.0\ndelay = 0.03"
    ));
    assert_clean_landing(&f, "30 ms latency for 1 s");
    assert!(f.last().io.faults.estimates_delayed >= 100);
}

/// The estimator's clock jumps: forward is simply newer; back by 5 s, two
/// estimates are dropped as out of order and the third (still increasing)
/// is taken as the new clock: no failsafe, the landing goes on.
#[test]
fn estimate_clock_jump_back_is_rebased_after_three_estimates() {
    let t = clean_entry(Mode::Morphing) + 0.2;
    let back = fly_with(&format!(
        "[[faults.estimate_clock_jump]]\nt = {t}\njump = -5.0"
    ));
    assert_clean_landing(&back, "clock 5 s back");
    let io = back.last().io;
    assert_eq!((io.estimates_out_of_order, io.estimate_clock_jumps), (2, 1));

    let forward = fly_with(&format!(
        "[[faults.estimate_clock_jump]]\nt = {t}\njump = 5.0"
    ));
    let io = forward.last().io;
    assert_eq!((io.estimates_out_of_order, io.estimate_clock_jumps), (0, 0));
    // Stamps are only ordered, never used as ages: the same flight.
    assert_eq!(flown(&forward.summary), flown(&clean().summary));
}

/// Every estimate of the descent delivered twice: the copies are dropped by
/// the order rule (counted), the flight is the clean one bit for bit.
#[test]
fn duplicated_estimates_are_dropped_and_counted_and_change_nothing() {
    let f = fly_with("[[faults.estimate_duplicate]]\nt = 0.0\nduration = 8.0");
    let io = f.last().io;
    assert!(io.faults.estimates_duplicated > 900, "{io:?}");
    assert_eq!(io.estimates_out_of_order, io.faults.estimates_duplicated);
    assert_eq!(flown(&f.summary), flown(&clean().summary));
    assert!(same_commands(&f, clean()));
}

/// Estimates reordered in pairs through the descent: the overtaken one is
/// dropped (counted), the stream thins to 60 Hz, the landing holds.
#[test]
fn reordered_estimates_older_ones_dropped_and_counted_landing_holds() {
    let f = fly_with("[[faults.estimate_reorder]]\nt = 0.5\nduration = 6.0");
    assert_clean_landing(&f, "reordered pairs");
    let io = f.last().io;
    assert!(io.faults.estimates_reordered > 300, "{io:?}");
    assert_eq!(io.estimates_out_of_order, io.faults.estimates_reordered);
    // The flight stack saw only increasing stamps: nothing rejected there.
    assert_eq!(f.summary.rejected_inputs, [0; 5]);
}

/// Every driver dies 50 ms into the transition (no heartbeats, no encoder
/// or contact, nothing actuated): failsafe at the first tick after, never a
/// flying or driving mode again while they are dead, no panic.
#[test]
fn drivers_dying_mid_transition_fail_safe_and_stay_there() {
    let f = fly_with("[faults.driver_death]\nmode = \"transition\"\ndelay = 0.05");
    let transition = f.first_in(Mode::Transition, 0.0).unwrap().time;
    let dead = f
        .ticks
        .iter()
        .find(|r| r.inputs.driver_lost)
        .expect("driver loss never reached the flight stack");
    assert!(
        dead.time >= transition + 0.05 - 1e-9 && dead.time <= transition + 0.05 + 0.01,
        "driver loss at {:.3} s, transition at {transition:.3} s",
        dead.time
    );
    assert_eq!(
        dead.outputs.status.mode,
        Mode::Failsafe,
        "{:?}",
        dead.outputs.status.transition
    );
    for r in f.ticks.iter().filter(|r| r.time >= dead.time) {
        assert!(r.inputs.driver_lost);
        assert_eq!(r.outputs.status.mode, Mode::Failsafe, "at {:.3} s", r.time);
    }
    println!(
        "drivers dead mid-transition: plant {:?}, touchdown {:?} m/s",
        f.summary.crash_reason, f.summary.impact_speed_mps
    );
}

fn ticks_with_cuts(f: &Flight) -> usize {
    f.ticks
        .iter()
        .filter(|r| r.outputs.status.solver_cuts.count > 0)
        .count()
}

/// The MPC's time limit hit by every solve for 0.5 s (each cut after its
/// first interior-point iteration). With the shipped homotopy feedback the
/// cut is the preparation's Clarabel solve: the homotopy corrects it from
/// the last working set to the exact QP solution, so the flight is the
/// clean one bit for bit, every cut logged (`solver_cuts`, replayed). With
/// the Clarabel feedback the feedback solve is cut too: the shifted plan
/// is flown (`Fallback`, counted) for the grace of 15 ticks, then the MPC
/// has failed: failsafe, recovery once the solves are whole again.
#[test]
fn solver_time_limit_hit_repeatedly_cuts_counted_then_failsafe_past_the_grace() {
    let overrun = "[[faults.solver_overrun]]\nt = 0.3\nduration = 0.5\niteration = 1";
    let homotopy = fly_with(overrun);
    assert!(
        ticks_with_cuts(&homotopy) >= 74,
        "{}",
        ticks_with_cuts(&homotopy)
    );
    assert_eq!(flown(&homotopy.summary), flown(&clean().summary));
    assert!(same_commands(&homotopy, clean()));

    let mut controller = ControllerConfig::atmo().unwrap().deterministic();
    controller.mpc.feedback.method = FeedbackMethod::Clarabel;
    let mut ticks = Vec::new();
    let summary = fly(&scenario(overrun), &controller, |r| ticks.push(*r)).unwrap();
    let clarabel = Flight { summary, ticks };
    let fallbacks: Vec<&TickRecord> = clarabel
        .ticks
        .iter()
        .filter(|r| r.outputs.status.solver == SolverStatus::Fallback)
        .collect();
    assert!(fallbacks.len() >= 15, "{} fallback ticks", fallbacks.len());
    assert!(fallbacks[0].time >= 0.3 && fallbacks[0].time < 0.32);
    let failsafe = clarabel.first_in(Mode::Failsafe, 0.3).expect("no failsafe");
    let grace_end = fallbacks[0].time + 15.0 / 150.0;
    assert!(
        failsafe.time >= grace_end - 1e-6 && failsafe.time <= grace_end + 0.02,
        "failsafe at {:.3} s, grace over at {grace_end:.3} s",
        failsafe.time
    );
    assert!(clarabel.summary.mpc_failures >= 15);
    assert!(
        clarabel.first_in(Mode::Flight, 0.8).is_some(),
        "no recovery"
    );
    println!(
        "Clarabel feedback, solves cut for 0.5 s: {:?}",
        clarabel.summary
    );
}

/// The MPC fails for good in the morph (every solve cut, with the Clarabel
/// feedback, from 1.5 s to the end): past the grace the failsafe flies the
/// backup controller's level descent, not the failed MPC's last plan
/// (which hovered and then climbed away to 7 m and turned over), tilts to
/// the landing tilt that puts the wheels under the base, and comes down
/// level and slowly on its wheels.
#[test]
fn the_mpc_failed_for_good_the_backup_lands_level_on_the_wheels() {
    let overrun = "[[faults.solver_overrun]]\nt = 1.5\nduration = 30.0\niteration = 1";
    let mut controller = ControllerConfig::atmo().unwrap().deterministic();
    controller.mpc.feedback.method = FeedbackMethod::Clarabel;
    let mut ticks = Vec::new();
    let summary = fly(&scenario(overrun), &controller, |r| ticks.push(*r)).unwrap();
    let f = Flight { summary, ticks };
    let airborne = assert_level_descent_onto_the_wheels(&f, 1.5);
    assert!(
        airborne
            .iter()
            .all(|t| t.outputs.status.solver == SolverStatus::Failed),
        "the solves came back"
    );
    println!("the MPC failed for good: {:?}", f.summary);
}

/// The failsafe from `after` s on came down as the backup controller
/// lands: never climbing, leaning under 5 deg, on the wheels (over 30 deg
/// of tilt) under 0.35 m/s, no crash. Returns its airborne ticks.
fn assert_level_descent_onto_the_wheels(f: &Flight, after: f64) -> Vec<&TickRecord> {
    let failsafe = f.first_in(Mode::Failsafe, after).expect("no failsafe");
    let airborne: Vec<&TickRecord> = f
        .ticks
        .iter()
        .filter(|t| t.time >= failsafe.time && t.outputs.status.mode == Mode::Failsafe)
        .collect();
    let highest = airborne.iter().map(|t| t.truth_height).fold(0.0, f64::max);
    assert!(
        highest < failsafe.truth_height + 0.05,
        "climbed from {:.2} to {highest:.2} m",
        failsafe.truth_height
    );
    let leaned = airborne
        .iter()
        .map(|t| {
            let s = &t.truth;
            s[atmo_core::model::idx::ROLL]
                .abs()
                .max(s[atmo_core::model::idx::PITCH].abs())
        })
        .fold(0.0, f64::max);
    assert!(leaned.to_degrees() < 5.0, "{:.1} deg", leaned.to_degrees());
    let s = &f.summary;
    assert!(s.crash_reason.is_none(), "{s:?}");
    assert!(s.touchdown_tilt_deg.unwrap() > 30.0, "{s:?}");
    assert!(s.impact_speed_mps.unwrap() < 0.35, "{s:?}");
    airborne
}

/// The log's disk is full (`/dev/full`: every write fails with ENOSPC):
/// the flight is the clean one bit for bit (logging never blocks the
/// control path), every record after the failure is dropped and counted,
/// and the writer's error names the file and the cause.
#[cfg(target_os = "linux")]
#[test]
fn log_disk_full_flight_unaffected_records_dropped_and_counted() {
    use atmo_flight::flight_log::TickChannels;
    use atmo_io::mcap_log::{LoggerOptions, McapLogger};
    let (log, thread) = McapLogger::spawn("/dev/full", LoggerOptions::default()).unwrap();
    let channels = TickChannels::register(&log, "/atmo/status").unwrap();
    let controller = ControllerConfig::atmo().unwrap().deterministic();
    let mut ticks = Vec::new();
    let summary = fly(&scenario(""), &controller, |r| {
        let status =
            atmo_flight::telemetry::status_message(r.timing.tick, &r.inputs, &r.outputs, &r.timing);
        channels.log_tick(&log, r.timing.tick, &r.inputs, &r.outputs, &status);
        ticks.push(*r);
    })
    .unwrap();
    assert_eq!(flown(&summary), flown(&clean().summary));
    let logged = Flight { summary, ticks };
    assert!(same_commands(&logged, clean()));
    let ticks = logged.ticks;
    // The writer fails at its first write to the file (at start-up or at
    // a flush): after the finish, everything logged is counted as dropped
    // or was lost with the failed write.
    log.finish();
    let error = thread.join().unwrap_err().to_string();
    assert!(
        error.contains("/dev/full") && error.contains("No space left"),
        "{error}"
    );
    assert!(log.failed());
    assert_eq!(log.failure().as_deref(), Some(error.as_str()));
    assert!(log.dropped() > 0, "nothing counted as dropped");
    // After the failure every record is refused at once and counted.
    let before = log.dropped();
    channels.log_tick(
        &log,
        0,
        &ticks[0].inputs,
        &ticks[0].outputs,
        &atmo_io::msg::MpcStatus::default(),
    );
    assert_eq!(log.dropped(), before + 2);
}

/// A `[faults]` table is checked like every config: the error names the
/// scenario file and the key.
#[test]
fn a_bad_faults_table_is_refused_naming_the_file_and_the_key() {
    let text = std::fs::read_to_string(scenario_path()).unwrap();
    for (faults, key) in [
        (
            "[[faults.estimate_dropout]]\nt = 1.0\nduration = -0.1",
            "faults.estimate_dropout[0].duration",
        ),
        (
            "[[faults.estimate_latency]]\nt = 1.0\nduration = 0.5\ndelay = nan",
            "faults.estimate_latency[0].delay",
        ),
        (
            "[[faults.estimate_clock_jump]]\nt = 1.0\njump = -2000.0",
            "faults.estimate_clock_jump[0].jump",
        ),
        (
            "[faults.driver_death]\nmode = \"hover\"",
            "faults.driver_death.mode",
        ),
        ("[faults.driver_death]\ndelay = 0.1", "faults.driver_death"),
        (
            "[[faults.solver_overrun]]\nt = 20.0\nduration = 0.1",
            "faults.solver_overrun[0].t",
        ),
        ("[faults]\nestimate_dropouts = []", "estimate_dropouts"),
    ] {
        let err = Scenario::from_toml_str(&format!("{text}\n{faults}\n"), scenario_path())
            .err()
            .unwrap_or_else(|| panic!("accepted: {faults}"))
            .to_string();
        assert!(
            err.contains("wheel_landing.toml") && err.contains(key),
            "{faults}: {err}"
        );
    }
}

/// A dropout past the timeout in the middle of the morph (0.9 m up, 20 deg
/// of tilt): the failsafe tilts back before handing over, so the robot
/// reaches z* folded; morphing then holds its height below z* until tilted
/// near the flight limit, and the transition lands on the wheels. (Before,
/// the transition began folded at z* and the body hit the ground.)
#[test]
fn estimate_dropout_mid_morph_fails_safe_then_holds_below_z_star_until_tilted_and_lands() {
    let t = 2.0;
    let f = fly_with(&format!(
        "[[faults.estimate_dropout]]\nt = {t}\nduration = 0.3"
    ));
    let modes = f.modes();
    println!("mid-morph dropout: {modes:?}\n{:#?}", f.summary);
    assert!(f.first_in(Mode::Failsafe, t).is_some(), "{modes:?}");
    let transition = f.first_in(Mode::Transition, t).expect("no transition");
    assert!(transition.outputs.status.tilt >= 45f64.to_radians());
    assert!(
        modes.ends_with(&[Mode::Transition, Mode::Touchdown, Mode::Drive]),
        "{modes:?}"
    );
    assert!(f.landed(), "{:#?}", f.summary);
}

/// The injected cuts are logged like wall-clock ones: the flight log of a
/// landing whose Clarabel feedback solves are cut for 0.5 s replays bit for
/// bit with its logged cuts (`atmo-daemon replay`), and differs without them.
#[test]
fn injected_solver_cuts_are_logged_and_a_replay_repeats_them() {
    use atmo_flight::replay::{CutReplay, RecordedFlight, replay};
    use atmo_sim::closed_loop::{STATUS_TOPIC, fly_logged};
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("sim-faults");
    std::fs::create_dir_all(&dir).unwrap();
    let mut controller = ControllerConfig::atmo().unwrap().deterministic();
    controller
        .files
        .set_mpc_value("feedback", "method", "clarabel")
        .unwrap();
    let mpc = dir.join("mpc_clarabel_feedback.toml");
    std::fs::write(&mpc, &controller.files.mpc.text).unwrap();
    let controller = controller.with_mpc_file(&mpc).unwrap();
    assert_eq!(controller.mpc.feedback.method, FeedbackMethod::Clarabel);
    let log = dir.join("solver_overrun.mcap");
    let overrun = "[[faults.solver_overrun]]\nt = 0.3\nduration = 0.5\niteration = 1";
    let (summary, _) = fly_logged(&scenario(overrun), &controller, &log, |_| {}).unwrap();
    assert!(summary.mpc_failures >= 15, "{summary:?}");

    let flight = RecordedFlight::read(&log, STATUS_TOPIC).unwrap();
    let config = RecordedFlight::config(&flight.files).unwrap();
    let report = replay(&flight, &config, CutReplay::AsLogged, |_| {}).unwrap();
    assert_eq!(report.first_difference, None, "{report:?}");
    assert_eq!(report.ticks, 2100);
    let uncut = replay(&flight, &config, CutReplay::None, |_| {}).unwrap();
    assert!(uncut.first_difference.is_some(), "the cuts changed nothing");
}

/// The window of solves covers both of the MPC's QPs. In transition the tilt
/// is planned by a second QP whose Clarabel solves (the homotopy's starting
/// guess in each preparation) were once outside the window: a busy machine
/// cut them unrecorded and the replay of a real SITL flight differed from
/// the transition on, by one ulp (CI, 2026-12-03). Here every solve of the
/// transition's first half second is cut at iteration 1: each of those
/// ticks logs its cut, the log replays bit for bit, and without the cuts it
/// does not.
#[test]
fn the_tilt_planning_solves_are_in_the_window_and_their_cuts_replay() {
    use atmo_flight::replay::{CutReplay, RecordedFlight, replay};
    use atmo_sim::closed_loop::{STATUS_TOPIC, fly_logged};
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("sim-faults");
    std::fs::create_dir_all(&dir).unwrap();
    let controller = ControllerConfig::atmo().unwrap().deterministic();
    let start = clean().first_in(Mode::Transition, 0.0).unwrap().time;
    let overrun = format!(
        "[[faults.solver_overrun]]\nt = {:.3}\nduration = 0.5\niteration = 1",
        start + 0.05
    );
    let log = dir.join("tilt_planning_overrun.mcap");
    fly_logged(&scenario(&overrun), &controller, &log, |_| {}).unwrap();

    let flight = RecordedFlight::read(&log, STATUS_TOPIC).unwrap();
    let in_overrun = |t: f64| t > start + 0.06 && t < start + 0.54;
    let planning: Vec<_> = flight
        .inputs
        .iter()
        .zip(&flight.status)
        .filter(|(i, s)| in_overrun(i.clock_ns as f64 * 1e-9) && s.mode.name() == "transition")
        .collect();
    assert!(planning.len() >= 60, "{} transition ticks", planning.len());
    let uncut = planning
        .iter()
        .filter(|(i, _)| i.solver_cut_count == 0)
        .count();
    assert_eq!(uncut, 0, "transition ticks without a logged cut");

    let config = RecordedFlight::config(&flight.files).unwrap();
    let report = replay(&flight, &config, CutReplay::AsLogged, |_| {}).unwrap();
    println!("replayed with the cuts: {report:?}");
    assert_eq!(report.first_difference, None, "{report:?}");
    let without = replay(&flight, &config, CutReplay::None, |_| {}).unwrap();
    println!(
        "without them, first difference: {:?}",
        without.first_difference
    );
    assert!(
        without.first_difference.is_some(),
        "the cuts changed nothing"
    );
}

/// The motion capture lost for good at 1.5 s (in the morph, 1.1 m up),
/// the autopilot's own estimate still arriving (`autopilot_estimate`,
/// with config/plant.toml's vertical-velocity error on it): the
/// failsafe flies the backup controller on that estimate's attitude,
/// body rates and vertical speed, the arms to the landing tilt, and comes
/// down level and slowly on its wheels; the log carries that estimate and
/// replays bit for bit. Without it the open-loop trim tips over and
/// crashes (docs/faults.md).
#[test]
fn the_estimate_lost_for_good_lands_on_the_autopilots_estimate() {
    use atmo_flight::replay::{CutReplay, RecordedFlight, replay};
    use atmo_sim::closed_loop::{STATUS_TOPIC, fly_logged};
    let lost = "[[faults.estimate_dropout]]\nt = 1.5\nduration = 60.0";
    let controller = ControllerConfig::atmo().unwrap().deterministic();
    let mut with_autopilot = scenario(lost);
    with_autopilot.file.autopilot_estimate = true;
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("faults-autopilot");
    std::fs::create_dir_all(&dir).unwrap();
    let log = dir.join(format!("estimate_lost_{}.mcap", std::process::id()));
    let mut ticks = Vec::new();
    let (summary, _) = fly_logged(&with_autopilot, &controller, &log, |r| {
        ticks.push(*r);
    })
    .unwrap();
    let f = Flight { summary, ticks };
    let failsafe = f.first_in(Mode::Failsafe, 1.5).expect("no failsafe");
    assert!(failsafe.time < 1.6, "failsafe at {:.3} s", failsafe.time);
    assert_level_descent_onto_the_wheels(&f, 1.5);
    let s = &f.summary;

    let mut flight = RecordedFlight::read(&log, STATUS_TOPIC).unwrap();
    let config = RecordedFlight::config(&flight.files).unwrap();
    let replayed =
        |flight: &RecordedFlight| replay(flight, &config, CutReplay::AsLogged, |_| {}).unwrap();
    assert_eq!(replayed(&flight).first_difference, None);
    // Without the autopilot's estimate (a log before it) the failsafe
    // flies the open-loop trim: the replay tells.
    for i in &mut flight.inputs {
        i.has_autopilot_estimate = false;
    }
    assert!(replayed(&flight).first_difference.is_some());

    let without = fly_with(lost);
    assert!(
        without.summary.crash_reason.is_some(),
        "{:?}",
        without.summary
    );
    println!("the estimate lost for good: {s:?}");
}
