//! The actuator monitor on fault-free flights: its signals' largest values
//! and every detection, over randomized wheel landings (the Monte Carlo's
//! randomization, `atmo-sim fly --runs N --seed S`). A measurement, not a
//! check (ignored): docs/faults.md ("False positives") gives its numbers.
//!
//! `MONITOR_SEEDS=1,1001 MONITOR_RUNS=200 cargo test -p atmo-sim --test sim
//! -- --ignored monitor_margins --nocapture`
#![allow(clippy::unwrap_used, reason = "measurement")]

use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};

use atmo_flight::Mode;
use atmo_sim::closed_loop::{ControllerConfig, fly};
use atmo_sim::monte_carlo::{randomized_with_draws, wilson_95};

use super::faults::scenario;

struct Run {
    seed: u64,
    /// Largest observer roll or pitch torque while it learns, N m.
    torque: f64,
    /// Largest observer body-z force while it learns, N.
    force: f64,
    /// Largest commanded tilt travel without 0.5 deg of tilt movement, deg.
    travel: f64,
    /// Smallest fraction of its command a rotor's thrust followed between
    /// two speed reports (the stopped-rotor detector's signal), flying.
    followed: f64,
    /// What was detected, and the first detection.
    detected: u8,
    first: String,
    landed: bool,
}

fn fly_one(seed: u64, controller: &ControllerConfig) -> Run {
    let base = scenario("");
    let (flown, _) = randomized_with_draws(&base, seed);
    let step = controller.flight.monitor.encoder_step_deg.to_radians();
    let mut run = Run {
        seed,
        torque: 0.0,
        force: 0.0,
        travel: 0.0,
        followed: f64::INFINITY,
        detected: 0,
        first: String::new(),
        landed: false,
    };
    let (mut anchor, mut travel) = (0.0f64, 0.0f64);
    let mut previous: Option<(f64, f64)> = None;
    let tau = controller.robot.rotor.time_constant;
    // The last tick's time, speeds and commands sent.
    let mut last_report: Option<(f64, [f64; 4], [f64; 4])> = None;
    let summary = fly(&flown, controller, |r| {
        let s = &r.outputs.status;
        if let (Some((t, before, sent)), Some(now)) = (last_report, r.inputs.rotor_speeds)
            && matches!(
                s.mode,
                Mode::Flight | Mode::Morphing | Mode::Transition | Mode::Failsafe
            )
        {
            let follow = 1.0 - (-(r.time - t) / tau).exp();
            for k in (0..4).filter(|&k| sent[k] >= 0.05) {
                let (t0, t1) = (before[k] * before[k], now[k] * now[k]);
                run.followed = run.followed.min((t0 + (t1 - t0) / follow) / sent[k]);
            }
        }
        last_report = r
            .inputs
            .rotor_speeds
            .map(|speeds| (r.time, speeds, r.outputs.thrust));
        if matches!(s.mode, Mode::Flight | Mode::Morphing | Mode::Transition) {
            run.torque = run
                .torque
                .max(s.disturbance[3].abs())
                .max(s.disturbance[4].abs());
            run.force = run.force.max(s.disturbance[2].abs());
        }
        if s.actuator_faults != 0 && run.first.is_empty() {
            run.first = format!(
                "{} at {:.2} s in {}",
                s.actuator_faults,
                r.time,
                s.mode.name()
            );
        }
        run.detected |= s.actuator_faults;
        if let Some((t, v)) = previous {
            travel += v * (r.time - t);
        }
        if (s.tilt - anchor).abs() >= step {
            anchor = s.tilt;
            travel = 0.0;
        }
        run.travel = run.travel.max(travel.abs().to_degrees());
        previous = Some((r.time, r.outputs.tilt_velocity));
    })
    .unwrap();
    run.landed = base.file.success.met_by(&summary);
    run
}

#[test]
#[ignore = "a measurement: minutes of flights"]
fn monitor_margins() {
    let seeds: Vec<u64> = std::env::var("MONITOR_SEEDS")
        .unwrap_or_else(|_| "1".into())
        .split(',')
        .map(|s| s.trim().parse().unwrap())
        .collect();
    let runs: u64 = std::env::var("MONITOR_RUNS").map_or(200, |r| r.parse().unwrap());
    let controller = ControllerConfig::atmo().unwrap().deterministic();
    let jobs: Vec<u64> = seeds
        .iter()
        .flat_map(|s| (0..runs).map(move |k| s + k))
        .collect();
    let next = AtomicUsize::new(0);
    let results = Mutex::new(Vec::new());
    std::thread::scope(|scope| {
        for _ in 0..2 {
            scope.spawn(|| {
                while let Some(&seed) = jobs.get(next.fetch_add(1, Ordering::Relaxed)) {
                    let run = fly_one(seed, &controller);
                    results.lock().unwrap().push(run);
                }
            });
        }
    });
    let mut runs = results.into_inner().unwrap();
    runs.sort_by_key(|r| r.seed);
    let n = runs.len();
    let trips = runs.iter().filter(|r| r.detected != 0).count();
    let landed = runs.iter().filter(|r| r.landed).count();
    let [lo, hi] = wilson_95(trips, n);
    let largest = |f: fn(&Run) -> f64| runs.iter().map(f).fold(0.0, f64::max);
    let percentile = |f: fn(&Run) -> f64, p: usize| {
        let mut v: Vec<f64> = runs.iter().map(f).collect();
        v.sort_by(f64::total_cmp);
        v[(n * p / 100).min(n - 1)]
    };
    println!(
        "{n} runs (seeds {seeds:?} + 0..{}): {trips} with a detection (Wilson 95 % {:.2}-{:.2} %), {landed} landed",
        runs_per(&seeds, n),
        lo * 100.0,
        hi * 100.0
    );
    println!(
        "torque max {:.3} N m (p99 {:.3}); body-z force max {:.2} N (p99 {:.2}); encoder lag max {:.2} deg",
        largest(|r| r.torque),
        percentile(|r| r.torque, 99),
        largest(|r| r.force),
        percentile(|r| r.force, 99),
        largest(|r| r.travel)
    );
    let smallest = runs
        .iter()
        .map(|r| r.followed)
        .fold(f64::INFINITY, f64::min);
    println!(
        "a rotor's thrust followed at least {smallest:.3} of its command (stopped under {}; p1 of the runs' smallest {:.3})",
        controller.flight.monitor.rotor_stopped_ratio,
        {
            let mut v: Vec<f64> = runs.iter().map(|r| r.followed).collect();
            v.sort_by(f64::total_cmp);
            v[n / 100]
        }
    );
    for r in runs.iter().filter(|r| r.detected != 0 || !r.landed) {
        println!(
            "  seed {}: detected {}, landed {}",
            r.seed, r.first, r.landed
        );
    }
}

fn runs_per(seeds: &[u64], n: usize) -> usize {
    n / seeds.len().max(1)
}
