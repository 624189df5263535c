//! The shipped scenarios load, validate and run open-loop, deterministically.

use atmo_core::model::idx;
use atmo_plant::config::PlantConfig;
use atmo_plant::plant::EventKind;
use atmo_sim::Scenario;

const NAMES: [&str; 5] = [
    "hover",
    "wheel_landing",
    "drive_takeoff_land",
    "landing_forward_velocity",
    "landing_slope_25deg",
];

fn path(name: &str) -> String {
    format!(
        "{}/../../config/scenarios/{name}.toml",
        env!("CARGO_MANIFEST_DIR")
    )
}

#[test]
fn every_scenario_loads_and_runs_open_loop_to_the_end() {
    for name in NAMES {
        let sc = Scenario::load(path(name)).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(sc.file.name, name);
        // The shipped plant file switches every effect on.
        assert_eq!(sc.plant.effects.enabled_names().len(), 10, "{name}");
        assert!(
            !sc.file.pilot.is_empty() && !sc.file.open_loop.is_empty(),
            "{name}"
        );
        let run = sc
            .run_open_loop(0.01)
            .unwrap_or_else(|e| panic!("{name}: {e}"));
        let last = run.samples.last().unwrap();
        assert!(
            (last.time - sc.file.duration).abs() < 1e-9,
            "{name}: ended at {}",
            last.time
        );
        assert_eq!(
            run.samples.len() as f64,
            (sc.file.duration / 0.01).round() + 1.0
        );
        assert!(
            run.samples
                .iter()
                .all(|s| s.state.iter().all(|v| v.is_finite()))
        );
    }
}

#[test]
fn the_same_scenario_and_seed_give_a_bit_identical_trajectory() {
    for name in ["wheel_landing", "landing_slope_25deg"] {
        let sc = Scenario::load(path(name)).unwrap();
        let a = sc.run_open_loop(0.001).unwrap();
        let b = sc.run_open_loop(0.001).unwrap();
        assert_eq!(a, b, "{name}: two runs differ");
        // The seed matters: another seed draws other noise.
        let mut other = sc.clone();
        other.file.seed += 1;
        let c = other.run_open_loop(0.001).unwrap();
        assert_ne!(a.samples, c.samples, "{name}: the seed changed nothing");
    }
}

#[test]
fn the_avx2_step_code_gives_the_portable_code_s_trajectory_bit_for_bit() {
    for name in NAMES {
        let sc = Scenario::load(path(name)).unwrap();
        let fast = sc.run_open_loop(0.001).unwrap();
        let mut plant = sc.build_plant().unwrap();
        if !plant.uses_avx2() {
            eprintln!("{name}: this CPU runs the portable code only");
        }
        plant.use_portable_code();
        assert!(!plant.uses_avx2());
        let portable = sc.run_plant_open_loop(plant, 0.001).unwrap();
        // Every step of every state, tilt, thrust, wheel rate and event.
        assert_eq!(fast, portable, "{name}");
        // Debug prints every f64 exactly (and tells -0.0 from 0.0).
        assert!(
            format!("{fast:?}") == format!("{portable:?}"),
            "{name}: differ in the sign of a zero"
        );
        assert!(fast.samples.len() > 1000, "{name}");
    }
}

#[test]
fn hover_trim_holds_position_in_the_ideal_plant() {
    let mut sc = Scenario::load(path("hover")).unwrap();
    sc.plant = PlantConfig::ideal();
    sc.file.disturbances.clear();
    let run = sc.run_open_loop(0.1).unwrap();
    let first = run.samples[0].state;
    let last = run.samples.last().unwrap().state;
    assert!(
        (last - first).norm() < 1e-9,
        "drifted by {}",
        (last - first).norm()
    );
    // The push alone moves it sideways (+y).
    let mut pushed = Scenario::load(path("hover")).unwrap();
    pushed.plant = PlantConfig::ideal();
    let run = pushed.run_open_loop(0.1).unwrap();
    // 2 N on 5.5 kg: 0.036 m/s sideways after the first 0.1 s of the push
    // (the push at B also tips the robot, which later drifts off: open loop).
    let before = &run.samples[50].state;
    let after = &run.samples[51].state;
    assert!(before[idx::VY].abs() < 1e-9, "{before}");
    let dv = after[idx::VY] - before[idx::VY];
    assert!((dv - 0.2 / 5.525).abs() < 0.1 * 0.2 / 5.525, "{dv}");
}

#[test]
fn drive_scenario_starts_standing_on_its_wheels() {
    let sc = Scenario::load(path("drive_takeoff_land")).unwrap();
    let run = sc.run_open_loop(0.01).unwrap();
    // Standing: the contact signal rises within the first steps, no crash
    // while it drives the first 4 s at 0.5 m/s.
    assert!(run.samples[10..400].iter().all(|s| s.grounded));
    assert!(
        run.events
            .iter()
            .all(|e| e.time > 4.0 || !matches!(e.kind, EventKind::Crash(_)))
    );
    let at4 = &run.samples[400];
    assert!(
        (at4.state[idx::X] - 2.0).abs() < 0.1,
        "x at 4 s: {}",
        at4.state[idx::X]
    );
}

#[test]
fn pilot_and_reference_inputs_are_piecewise_constant() {
    let sc = Scenario::load(path("wheel_landing")).unwrap();
    assert!(sc.pilot_at(0.0).unwrap().mpc);
    assert_eq!(sc.pilot_at(7.999).unwrap().throttle, 0.35);
    assert_eq!(sc.pilot_at(8.0).unwrap().throttle, 0.0);
    assert_eq!(sc.reference_at(0.5).unwrap().tilt_deg, Some(0.0));
    assert_eq!(sc.reference_at(1.5).unwrap().tilt_deg, Some(70.0));
}

#[test]
fn on_ground_stands_the_robot_on_a_slope_in_any_heading() {
    for (azimuth, yaw) in [(0.0, 0.0), (90.0, 0.0), (30.0, 120.0)] {
        let text = format!(
            r#"
name = "parked"
duration = 3.0
seed = 1
[terrain]
slope_deg = 20.0
slope_azimuth_deg = {azimuth}
[initial]
position = [1.0, -2.0, 0.0]
euler_deg = [{yaw}, 0.0, 0.0]
tilt_deg = 90.0
on_ground = true
[effects.ground_effect]
enabled = false
[effects.wind]
enabled = false
[effects.sensors]
enabled = false
[[open_loop]]
t = 0.0
rotors = [0.0, 0.0, 0.0, 0.0]
"#
        );
        let sc = Scenario::from_toml_str(&text, path("parked")).unwrap();
        let run = sc.run_open_loop(0.01).unwrap();
        assert!(
            run.crash.is_none(),
            "azimuth {azimuth}, yaw {yaw}: {:?}",
            run.crash
        );
        let first = run.samples[0].state;
        let last = run.samples.last().unwrap().state;
        assert!(
            run.samples[5..].iter().all(|s| s.grounded),
            "azimuth {azimuth}, yaw {yaw}"
        );
        // Settled where it was put (the wheel drives hold it): within 5 cm,
        // heading kept, at rest.
        let moved = ((last[idx::X] - first[idx::X]).powi(2)
            + (last[idx::Y] - first[idx::Y]).powi(2))
        .sqrt();
        assert!(
            moved < 0.05,
            "azimuth {azimuth}, yaw {yaw}: moved {moved} m"
        );
        assert!(
            (last[idx::YAW] - first[idx::YAW]).abs() < 0.02,
            "azimuth {azimuth}, yaw {yaw}"
        );
        let speed = (last[idx::VX].powi(2) + last[idx::VY].powi(2) + last[idx::VZ].powi(2)).sqrt();
        assert!(speed < 1e-3, "azimuth {azimuth}, yaw {yaw}: {speed} m/s");
    }
}
