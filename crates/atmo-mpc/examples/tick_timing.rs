//! Per-tick timing distribution (p50, p99, max) of the RTI controller in
//! the three benchmark situations: condensed with the homotopy feedback (the
//! shipped setting), condensed with a Clarabel feedback, sparse. Criterion
//! gives medians; this gives the tail. Run with
//! `cargo run --release -p atmo-mpc --example tick_timing [ticks]`.
// Test, bench and example code: an unwrap that fails is the failure report.
#![allow(clippy::unwrap_used)]

#[allow(dead_code)]
#[path = "../benches/support/scenarios.rs"]
mod scenarios;

use std::time::{Duration, Instant};

use atmo_mpc::{FeedbackMethod, FeedbackPath, Formulation};
use scenarios::{NAMES, scenario};

fn percentile(sorted: &[Duration], p: f64) -> Duration {
    let i = ((sorted.len() - 1) as f64 * p).round() as usize;
    sorted[i]
}

fn micros(d: Duration) -> f64 {
    d.as_secs_f64() * 1e6
}

fn main() {
    let ticks: usize = std::env::args()
        .nth(1)
        .and_then(|a| a.parse().ok())
        .unwrap_or(3000);
    let recorded = 150;
    println!(
        "| configuration | scenario | phase | p50 (us) | p99 (us) | max (us) | IPM iterations p50 (prepare + feedback) |"
    );
    println!("| --- | --- | --- | --- | --- | --- | --- |");
    for (label, formulation, method) in [
        (
            "condensed/homotopy",
            Formulation::Condensed,
            FeedbackMethod::Homotopy,
        ),
        (
            "condensed/clarabel",
            Formulation::Condensed,
            FeedbackMethod::Clarabel,
        ),
        ("sparse", Formulation::Sparse, FeedbackMethod::Clarabel),
    ] {
        for name in NAMES {
            let sc = scenario(name);
            let mut settings = scenarios::settings(formulation);
            settings.feedback.method = method;
            let (mut mpc, estimates) = sc.warmed_up_with(settings, recorded);
            let fallbacks_before = mpc.homotopy_fallbacks();
            let mut changed = 0;
            let mut prepare = Vec::with_capacity(ticks);
            let mut feedback = Vec::with_capacity(ticks);
            let mut tick = Vec::with_capacity(ticks);
            let mut iterations = Vec::with_capacity(ticks);
            let mut not_solved = 0;
            for i in 0..ticks {
                sc.apply(&mut mpc);
                let start = Instant::now();
                mpc.prepare().unwrap();
                let mid = Instant::now();
                let out = mpc.feedback(&estimates[i % recorded]).unwrap();
                let end = Instant::now();
                prepare.push(mid - start);
                feedback.push(end - mid);
                tick.push(end - start);
                iterations.push(out.timings.solver_iterations);
                changed += usize::from(matches!(
                    out.path,
                    FeedbackPath::Homotopy { active_set_changes } if active_set_changes > 0
                ));
                if out.outcome != atmo_mpc::Outcome::Solved {
                    if not_solved < 5 {
                        eprintln!(
                            "{label} {name}: tick {i}: outcome not Solved: {:?} after {} iterations",
                            out.outcome, out.timings.solver_iterations
                        );
                    }
                    not_solved += 1;
                }
            }
            iterations.sort_unstable();
            for (phase, samples) in [
                ("tick", &mut tick),
                ("prepare", &mut prepare),
                ("feedback", &mut feedback),
            ] {
                samples.sort_unstable();
                println!(
                    "| {label} | {name} | {phase} | {:.1} | {:.1} | {:.0} | {} |",
                    micros(percentile(samples, 0.5)),
                    micros(percentile(samples, 0.99)),
                    micros(*samples.last().unwrap()),
                    iterations[iterations.len() / 2],
                );
            }
            if not_solved > 0 {
                println!("| {label} | {name} | ticks not Solved | {not_solved} of {ticks} | | | |");
            }
            if mpc.uses_homotopy() {
                println!(
                    "| {label} | {name} | homotopy: ticks with active-set changes / fallbacks to Clarabel | {changed} / {} of {ticks} | | | |",
                    mpc.homotopy_fallbacks() - fallbacks_before
                );
            }
        }
    }
}
