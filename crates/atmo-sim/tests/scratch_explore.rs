#![allow(clippy::unwrap_used)]
use std::path::{Path, PathBuf};
use atmo_daemon::SolverState;
use atmo_sim::closed_loop::{ControllerConfig, fly};
use atmo_sim::scenario::Scenario;
fn scenario_path() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/scenarios/wheel_landing.toml")
}
fn run(faults: &str) {
    let text = std::fs::read_to_string(scenario_path()).unwrap();
    let sc = Scenario::from_toml_str(&format!("{text}\n{faults}\n"), scenario_path()).unwrap();
    let controller = ControllerConfig::atmo().unwrap().deterministic();
    let mut ticks = Vec::new();
    let s = fly(&sc, &controller, |r| ticks.push(*r)).unwrap();
    let mut modes = Vec::new();
    for t in &ticks { let m = t.outputs.status.mode; if modes.last().map(|(x, _)| *x) != Some(m) { modes.push((m, t.time)); } }
    let cuts: usize = ticks.iter().filter(|r| r.outputs.status.solver_cuts.count > 0).count();
    let fb = ticks.iter().filter(|r| r.outputs.status.solver == SolverState::Fallback).count();
    let failed = ticks.iter().filter(|r| r.outputs.status.solver == SolverState::Failed).count();
    let fallbacks = ticks.last().unwrap().outputs.status.feedback_fallbacks_total;
    println!("== {faults}\n  modes {:?}\n  tilt {:?} impact {:?} crashed {} {:?} drive {:.2} mpc_failures {} cuts {cuts} fallback {fb} failed {failed} homotopy_fallbacks {fallbacks} io {:?}",
        modes.iter().map(|(m, t)| format!("{}@{:.3}", m.name(), t)).collect::<Vec<_>>(),
        s.touchdown_tilt_deg, s.impact_speed_mps, s.crashed, s.crash_reason, s.drive_distance_m, s.mpc_failures, ticks.last().unwrap().io);
}
#[test]
fn explore() {
    for f in [
        "[[faults.estimate_dropout]]\nt = 0.5\nduration = 0.3",
        "[[faults.estimate_dropout]]\nt = 0.3\nduration = 0.3",
        "[[faults.estimate_dropout]]\nt = 2.0\nduration = 0.3",
        "[[faults.estimate_burst]]\nt = 0.5\nduration = 0.3",
        "[[faults.estimate_burst]]\nt = 0.3\nduration = 0.3",
        "[[faults.solver_overrun]]\nt = 1.15\nduration = 0.05\niteration = 1",
        "[[faults.solver_overrun]]\nt = 1.15\nduration = 0.05\niteration = 0",
        "[[faults.solver_overrun]]\nt = 0.5\nduration = 0.5\niteration = 1",
        "[[faults.solver_overrun]]\nt = 0.5\nduration = 0.5\niteration = 0",
        "[[faults.solver_overrun]]\nt = 3.0\nduration = 1.0\niteration = 0",
        "[faults.driver_death]\nmode = \"transition\"\ndelay = 0.05",
    ] { run(f); }
}
