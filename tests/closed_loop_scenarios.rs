//! The flight stack (FlightStack + atmo-mpc) flies every scenario of
//! config/scenarios against the built-in plant (ground effect, motor lag,
//! sensor noise and latency, CoM offset, mass errors, wind turbulence, wheel
//! contact...) and meets the scenario's success criteria: for the landings,
//! no crash, touchdown tilt past the critical angle region, a soft impact
//! and a drive on.
// Test, bench and example code: an unwrap that fails is the failure report.
#![allow(clippy::unwrap_used)]

use std::path::PathBuf;

use atmo_sim::closed_loop::{ControllerConfig, Summary, fly};
use atmo_sim::monte_carlo;
use atmo_sim::scenario::Scenario;

fn scenario(name: &str) -> Scenario {
    let path: PathBuf = [
        env!("CARGO_MANIFEST_DIR"),
        "config",
        "scenarios",
        &format!("{name}.toml"),
    ]
    .iter()
    .collect();
    Scenario::load(&path).unwrap_or_else(|e| panic!("{e}"))
}

fn controller() -> ControllerConfig {
    ControllerConfig::atmo().unwrap().deterministic()
}

fn fly_checked(name: &str) -> Summary {
    let s = scenario(name);
    let summary = fly(&s, &controller(), |_| {}).unwrap();
    eprintln!("{name}: {summary:?}");
    assert!(
        !summary.crashed,
        "{name} crashed: {:?}",
        summary.crash_reason
    );
    assert!(
        s.file.success.met_by(&summary),
        "{name} missed its success criteria: {summary:#?}"
    );
    summary
}

fn assert_wheel_landing(s: &Summary, min_tilt: f64) {
    let tilt = s.touchdown_tilt_deg.expect("touched down");
    let impact = s.impact_speed_mps.expect("touched down");
    assert!(tilt >= min_tilt, "touchdown tilt {tilt:.1} deg");
    assert!(impact <= 0.5, "impact {impact:.2} m/s");
    let modes: Vec<&str> = s.mode_sequence.iter().map(String::as_str).collect();
    let landing = ["morphing", "transition", "touchdown", "drive"];
    assert!(modes.windows(4).any(|w| w == landing), "modes {modes:?}");
}

/// Past the critical angle (61.4 deg) the rotors cannot carry the weight:
/// a flat-ground transition ends at (nearly) full thrust.
fn assert_saturated_transition(s: &Summary) {
    assert!(
        s.max_mean_thrust > 0.9,
        "max mean thrust {:.2}",
        s.max_mean_thrust
    );
}

#[test]
fn wheel_landing_of_fig5_lands_past_66_deg_softly_and_drives_on() {
    let s = fly_checked("wheel_landing");
    let s = {
        // The same flight through the MCAP logger: every tick is in the log.
        let dir = std::env::temp_dir().join(format!("atmo-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("flight.mcap");
        let mut ticks = 0u64;
        let (logged, log) = atmo_sim::closed_loop::fly_logged(
            &scenario("wheel_landing"),
            &controller(),
            &path,
            |_| ticks += 1,
        )
        .unwrap();
        let mut a = logged.clone();
        let mut b = s;
        for x in [&mut a, &mut b] {
            x.wall_time_s = None;
            x.feedback_time_median_s = 0.0;
            x.feedback_time_max_s = 0.0;
        }
        assert_eq!(a, b, "logging changed the flight");
        assert_eq!(log.dropped, 0);
        let status: Vec<(u64, atmo_io::msg::MpcStatus)> =
            atmo_io::mcap_log::read_topic(&path, atmo_sim::closed_loop::STATUS_TOPIC).unwrap();
        assert_eq!(status.len() as u64, ticks);
        let mut modes: Vec<&str> = Vec::new();
        for (_, m) in &status {
            if modes.last() != Some(&m.mode.name()) {
                modes.push(m.mode.name());
            }
        }
        assert_eq!(
            modes,
            logged
                .mode_sequence
                .iter()
                .map(String::as_str)
                .collect::<Vec<_>>()
        );
        std::fs::remove_dir_all(&dir).unwrap();
        logged
    };
    assert_wheel_landing(&s, 60.0);
    assert_saturated_transition(&s);
    // Issue 17's targets for this landing (the flare, docs/landing.md):
    // past the paper's 65 deg, soft, the thrust not saturated.
    let tilt = s.touchdown_tilt_deg.unwrap_or(0.0);
    let impact = s.impact_speed_mps.unwrap_or(f64::INFINITY);
    assert!(
        tilt >= 66.0,
        "touchdown tilt {tilt:.2} deg, issue 17 wants >= 66"
    );
    assert!(
        impact <= 0.35,
        "impact {impact:.3} m/s, issue 17 wants <= 0.35"
    );
    assert!(
        s.max_mean_thrust <= 0.95 + 1e-9,
        "max mean thrust {:.3}",
        s.max_mean_thrust
    );
    assert!(
        s.drive_distance_m >= 1.0,
        "drove {:.2} m",
        s.drive_distance_m
    );
    assert_eq!(s.mpc_failures, 0);
}

#[test]
fn landing_with_forward_velocity_of_fig6c() {
    let s = fly_checked("landing_forward_velocity");
    // Issue 17: Fig. 6C lands past 64 deg (the flare, docs/landing.md).
    assert_wheel_landing(&s, 64.0);
    assert_saturated_transition(&s);
    assert!(
        s.drive_distance_m >= 1.0,
        "drove {:.2} m",
        s.drive_distance_m
    );
}

#[test]
fn drive_takeoff_fly_land_of_fig6ab() {
    let s = fly_checked("drive_takeoff_land");
    let modes: Vec<&str> = s.mode_sequence.iter().map(String::as_str).collect();
    assert_eq!(&modes[..3], ["drive", "takeoff", "flight"], "{modes:?}");
    // Issue 17: Fig. 6A/B lands past 64 deg (paper: 58 deg for 6B).
    assert_wheel_landing(&s, 64.0);
    assert!(
        s.drive_distance_m >= 1.0,
        "drove {:.2} m",
        s.drive_distance_m
    );
}

#[test]
fn landing_on_a_25_deg_slope_of_fig6d() {
    let s = fly_checked("landing_slope_25deg");
    // Issue 17: at least 60 deg on the slope too. The flight stack measures
    // the wheels' clearance against the ground plane (height and normal
    // from the terrain); measured 64.59 deg at 0.25 m/s (docs/landing.md).
    assert_wheel_landing(&s, 60.0);
}

#[test]
fn hover_holds_through_a_lateral_push() {
    let s = fly_checked("hover");
    assert_eq!(s.mode_sequence, ["flight"]);
    assert_eq!(s.mpc_failures, 0);
}

#[test]
fn a_flight_is_deterministic() {
    let s = scenario("wheel_landing");
    let c = controller();
    let mut a = fly(&s, &c, |_| {}).unwrap();
    let mut b = fly(&s, &c, |_| {}).unwrap();
    for x in [&mut a, &mut b] {
        x.wall_time_s = None;
        x.feedback_time_median_s = 0.0;
        x.feedback_time_max_s = 0.0;
    }
    assert_eq!(a, b);
}

#[test]
fn monte_carlo_of_the_wheel_landing() {
    // The 200-run figure is in README.md (`atmo-sim fly --runs 200`); the test
    // flies 40 randomized copies (mass, inertia and thrust +-5 %, gusts,
    // sensor noise, initial spread) on the cores there are.
    let runs = 40;
    let threads = std::thread::available_parallelism().map_or(1, std::num::NonZero::get);
    let report = monte_carlo::run(
        &scenario("wheel_landing"),
        &controller(),
        runs,
        1,
        threads,
        &|_| {},
    )
    .unwrap();
    eprintln!(
        "monte carlo: {}/{} in {:.1} s",
        report.successes, report.runs, report.wall_time_s
    );
    for f in &report.failures {
        eprintln!("  failed run {} seed {}: {:?}", f.run, f.seed, f.summary);
    }
    assert_eq!(report.runs, runs);
    assert_eq!(report.crashes, 0);
    // The per-run records: in run order, agreeing with the counts, and each
    // run's draws those its seed gives again (so a miss can be replayed).
    assert_eq!(report.per_run.len(), runs);
    assert!(
        report
            .per_run
            .iter()
            .enumerate()
            .all(|(i, r)| r.run == i && r.seed == 1 + i as u64)
    );
    assert_eq!(
        report.per_run.iter().filter(|r| r.success).count(),
        report.successes
    );
    assert_eq!(
        report
            .per_run
            .iter()
            .filter(|r| r.landed_past_64_deg)
            .count(),
        report.landed_past_64_deg
    );
    let base = scenario("wheel_landing");
    let again = monte_carlo::randomized_with_draws(&base, 7);
    assert_eq!(again.1, report.per_run[6].draws);
    let mass = again.0.plant.effects.mass_error.as_ref().unwrap();
    assert_eq!(mass.mass_scale, again.1.mass_scale);
    assert_eq!(
        again.0.robot.rotor.k_thrust,
        base.robot.rotor.k_thrust * again.1.thrust_scale
    );
    assert!((0.7..=1.3).contains(&again.1.ground_effect_scale));
    assert!(
        report.success_rate >= 0.95,
        "success rate {}",
        report.success_rate
    );
}

fn tilt(s: &Summary) -> f64 {
    s.touchdown_tilt_deg.expect("touched down")
}

fn impact(s: &Summary) -> f64 {
    s.impact_speed_mps.expect("touched down")
}

/// Issue 17's Monte Carlo criterion (>= 64 deg, <= 0.4 m/s, no crash).
fn assert_landed_past_64_deg(s: &Summary) {
    assert!(
        monte_carlo::landed_past_64_deg(s),
        "issue 17's criterion missed: {:.2} deg at {:.3} m/s",
        tilt(s),
        impact(s)
    );
}

/// Run `seed` of the wheel landing's Monte Carlo flown with a rule of the
/// flare (`with`) and without it (`without`): neither crashes, and only the
/// flight with the rule meets issue 17's criterion. Returns both summaries.
fn with_and_without(
    seed: u64,
    with: &ControllerConfig,
    without: &ControllerConfig,
    rule: &str,
) -> (Summary, Summary) {
    let run = monte_carlo::randomized(&scenario("wheel_landing"), seed);
    let a = fly(&run, with, |_| {}).unwrap();
    let b = fly(&run, without, |_| {}).unwrap();
    eprintln!("run {seed} with {rule}: {a:?}\nwithout: {b:?}");
    assert!(!a.crashed && !b.crashed);
    assert!(
        !monte_carlo::landed_past_64_deg(&b),
        "without {rule} issue 17's criterion was met too: {:.2} deg at {:.3} m/s",
        tilt(&b),
        impact(&b)
    );
    assert_landed_past_64_deg(&a);
    (a, b)
}

#[test]
fn a_robot_weaker_than_its_file_spends_its_attitude_margin_after_the_flare_commits() {
    // Run 21 of `fly --runs 200 --seed 1`: thrust over weight 0.935 of the
    // file's (docs/landing.md "A weak robot spends its margin"). The same
    // robot and seed flown with the rotors held to the MPC's 0.95 after the
    // commit as well: the margin spent buys impact speed at the same tilt
    // or more (measured 64.8 deg at 0.32 m/s against 64.4 deg at 0.41 m/s;
    // before the level weight, 65.1 deg at 0.33 against 63.8 at 0.38).
    let mut keeping_margin = controller();
    keeping_margin.flight.flare.weak_thrust_max = keeping_margin
        .mpc
        .tilt_plan
        .as_ref()
        .expect("the shipped MPC plans the tilt")
        .thrust_max;
    let (spending, keeping) =
        with_and_without(21, &controller(), &keeping_margin, "spending the margin");
    assert!(
        spending.max_mean_thrust > 0.96,
        "the margin was not spent: max mean thrust {:.3}",
        spending.max_mean_thrust
    );
    assert!(keeping.max_mean_thrust <= 0.95 + 1e-9);
    assert!(
        tilt(&spending) >= tilt(&keeping),
        "touchdown tilt {:.2} deg spending the margin, {:.2} keeping it",
        tilt(&spending),
        tilt(&keeping)
    );
    assert!(
        impact(&spending) <= impact(&keeping) - 0.05,
        "impact {:.3} m/s spending the margin, {:.3} keeping it",
        impact(&spending),
        impact(&keeping)
    );
}

#[test]
fn a_ground_effect_surplus_learned_at_the_hold_is_not_credited_to_the_tilt_up() {
    // Run 197 of `fly --runs 200 --seed 1`: a ground effect 23 % stronger
    // than the MPC's surface holds the robot at the hold at about 60 deg, and
    // the observer learns the surplus as lift; the tilt-up to 67 deg carries
    // the rotors to where the surface's gain is negative. Crediting that lift
    // to the prediction commits too early (docs/landing.md "A ground-effect
    // surplus not credited to the tilt-up"). Measured: 66.28 deg at
    // 0.315 m/s not crediting it, 67.09 deg at 0.409 m/s crediting it.
    let mut crediting = controller();
    crediting.flight.flare.aloft_force_floor = false;
    crediting.flight.flare.late_window = 0.0;
    let mut floored = controller();
    floored.flight.flare.late_window = 0.0;
    let (not_credited, credited) = with_and_without(197, &floored, &crediting, "the force floor");
    assert!(
        impact(&not_credited) <= impact(&credited) - 0.05,
        "impact {:.3} m/s not crediting the surplus, {:.3} crediting it",
        impact(&not_credited),
        impact(&credited)
    );
}

#[test]
fn a_tilt_up_predicted_fast_near_the_ground_spends_the_attitude_margin() {
    // Run 1118 of `fly --runs 200 --seed 1001`: a strong robot (not weak at
    // its commit) whose tilt-up, predicted again within 3 cm of the ground
    // with its attitude held, is faster than 0.4 m/s. Measured: 66.90 deg
    // at 0.386 m/s spending the margin from there (max mean thrust 0.998),
    // 66.88 deg at 0.403 m/s without the late prediction.
    let mut never = controller();
    never.flight.flare.late_window = 0.0;
    let (late, kept) = with_and_without(1118, &controller(), &never, "the late prediction");
    assert!(
        late.max_mean_thrust > 0.96,
        "the margin was not spent: max mean thrust {:.3}",
        late.max_mean_thrust
    );
    assert!(kept.max_mean_thrust <= 0.95 + 1e-9);
    assert!(
        impact(&late) < impact(&kept),
        "impact {:.3} m/s with the late prediction, {:.3} without",
        impact(&late),
        impact(&kept)
    );
}

/// The larger of roll and pitch (deg, the plant's truth) on the last tick of
/// the transition, as the wheels touch.
fn attitude_at_the_touchdown(scenario: &Scenario, controller: &ControllerConfig) -> (Summary, f64) {
    use atmo_core::model::idx;
    let mut last = f64::NAN;
    let summary = fly(scenario, controller, |tick| {
        if tick.outputs.status.mode == atmo_daemon::Mode::Transition {
            let angle = tick.truth[idx::ROLL]
                .abs()
                .max(tick.truth[idx::PITCH].abs());
            last = angle.to_degrees();
        }
    })
    .unwrap();
    (summary, last)
}

#[test]
fn the_planned_tilt_keeps_the_robot_level_so_that_its_wheels_touch_together() {
    // Seed 126 of `fly --runs 200 --seed 1` (docs/landing.md "Level
    // wheels"): a strong ground effect whose fluctuating thrust rolled the
    // robot by about 10 deg while every rotor stood at its bound, and one
    // side's wheels touched early, at 63.6 deg and 0.17 m/s. With the
    // level weight the MPC spends differential thrust on the roll
    // (measured: 3.8 deg at the touchdown against 7.6, 65.5 deg at
    // 0.29 m/s). Both arms keep the flare's hold where it is (no "hold
    // lowered", docs/landing.md), as when this was measured: with it, the
    // robot without the level weight lowers its hold and touches down
    // rolled 4.8 deg, and the comparison is no longer the weight's alone
    // (the level robot: 4.2 deg).
    let robot = monte_carlo::randomized(&scenario("wheel_landing"), 126);
    let mut levelled = controller();
    levelled.flight.flare.lower_step = 0.0;
    let (level, level_angle) = attitude_at_the_touchdown(&robot, &levelled);
    let mut unlevelled = levelled.clone();
    unlevelled
        .mpc
        .tilt_plan
        .as_mut()
        .expect("the shipped MPC plans the tilt")
        .level_weight = 0.0;
    let (rolled, rolled_angle) = attitude_at_the_touchdown(&robot, &unlevelled);
    eprintln!(
        "level: {level_angle:.2} deg at the touchdown, {level:?}\nno level weight: {rolled_angle:.2} deg, {rolled:?}"
    );
    assert!(!level.crashed && !rolled.crashed);
    assert!(
        level_angle + 2.0 <= rolled_angle,
        "attitude at the touchdown: {level_angle:.2} deg with the level weight, {rolled_angle:.2} without"
    );
    assert!(
        tilt(&level) >= tilt(&rolled) + 1.0,
        "touchdown tilt {:.2} deg level, {:.2} deg rolled",
        tilt(&level),
        tilt(&rolled)
    );
    assert_landed_past_64_deg(&level);
}
