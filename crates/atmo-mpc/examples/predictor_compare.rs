//! Which prediction of the next estimate serves the homotopy better: the
//! shifted plan's first state or one RK4 step of the model from the last
//! estimate with the applied command. Closed loops in the three benchmark
//! situations against the atmo-core model (7 RK4 substeps per tick), the
//! estimate = true state + uniform noise (1 cm, 0.5 deg, 2 cm/s, 0.02 rad/s
//! standard deviations), the same noise sequence for both predictors.
//! Reports the prediction error (largest entry over the noise scale), the
//! share of ticks whose feedback changed the active set and the feedback time.
//! `cargo run --release -p atmo-mpc --example predictor_compare [ticks]`
// Test, bench and example code: an unwrap that fails is the failure report.
#![allow(clippy::unwrap_used)]

#[allow(dead_code)]
#[path = "../benches/support/scenarios.rs"]
mod scenarios;

use std::time::Duration;

use atmo_core::RobotConfig;
use atmo_core::model::{Model, NX, State, idx};
use atmo_mpc::{FeedbackMethod, FeedbackPath, Formulation, Mpc, Predictor, wrap_angle};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use scenarios::{NAMES, scenario};

/// Noise standard deviation per state entry.
const NOISE: [f64; NX] = [
    0.01, 0.01, 0.01, 0.0087, 0.0087, 0.0087, 0.02, 0.02, 0.02, 0.02, 0.02, 0.02,
];

fn main() {
    let ticks: usize = std::env::args()
        .nth(1)
        .and_then(|a| a.parse().ok())
        .unwrap_or(1500);
    println!(
        "| scenario | predictor / feedback | prediction error p50 / p99 (noise sd) | ticks with active-set changes | changes p99 | fallbacks | diverged preparations | feedback p50 / p99 (us) | final position error (m) |"
    );
    println!("| --- | --- | --- | --- | --- | --- | --- | --- | --- |");
    for name in NAMES {
        for (predictor, method) in [
            (Predictor::Plan, FeedbackMethod::Homotopy),
            (Predictor::Model, FeedbackMethod::Homotopy),
            (Predictor::Model, FeedbackMethod::Clarabel),
        ] {
            let sc = scenario(name);
            let mut settings = scenarios::settings(Formulation::Condensed);
            settings.feedback.predictor = predictor;
            settings.feedback.method = method;
            settings.solver.time_limit = 1.0;
            let mut mpc = Mpc::new(Model::new(&RobotConfig::atmo()), settings).unwrap();
            sc.apply(&mut mpc);
            mpc.reset(&sc.start).unwrap();
            let h = mpc.settings().horizon.tick_period / 7.0;
            let body = mpc.model().at_tilt(sc.varphi);
            let mut rng = ChaCha8Rng::seed_from_u64(5);
            let mut x = sc.start;
            let mut errors = Vec::with_capacity(ticks);
            let mut changes = Vec::with_capacity(ticks);
            let mut feedback: Vec<Duration> = Vec::with_capacity(ticks);
            let mut diverged = 0;
            for _ in 0..ticks {
                let estimate = State::from_fn(|i, _| {
                    x[i] + NOISE[i] * 3f64.sqrt() * rng.random_range(-1.0..=1.0)
                });
                sc.apply(&mut mpc);
                // A diverged plan is restarted by the feedback (counted below).
                if mpc.prepare().is_err() {
                    diverged += 1;
                }
                let mut e0 = estimate - mpc.plan_states()[0];
                e0[idx::YAW] = wrap_angle(e0[idx::YAW]);
                let miss = e0 - mpc.predicted_deviation_of_last_preparation();
                errors.push(
                    (0..NX)
                        .map(|i| miss[i].abs() / NOISE[i])
                        .fold(0.0, f64::max),
                );
                let out = mpc.feedback(&estimate).unwrap();
                feedback.push(out.timings.feedback);
                changes.push(match out.path {
                    FeedbackPath::Homotopy { active_set_changes } => active_set_changes,
                    FeedbackPath::Clarabel { fallback: None } | FeedbackPath::NoSolve => 0,
                    FeedbackPath::Clarabel { fallback: Some(_) } => u32::MAX,
                });
                for _ in 0..7 {
                    x = body.rk4_step(&x, &out.u, h);
                }
            }
            errors.sort_by(f64::total_cmp);
            feedback.sort_unstable();
            let changed = changes.iter().filter(|&&c| c > 0 && c != u32::MAX).count();
            let fallbacks = changes.iter().filter(|&&c| c == u32::MAX).count();
            changes.sort_unstable();
            let p = |n: usize, q: f64| ((n - 1) as f64 * q).round() as usize;
            println!(
                "| {name} | {predictor:?} / {method:?} | {:.2} / {:.2} | {:.1} % | {} | {fallbacks} | {diverged} | {:.1} / {:.1} | {:.3} |",
                errors[p(ticks, 0.5)],
                errors[p(ticks, 0.99)],
                100.0 * changed as f64 / ticks as f64,
                changes[p(ticks, 0.99)],
                feedback[p(ticks, 0.5)].as_secs_f64() * 1e6,
                feedback[p(ticks, 0.99)].as_secs_f64() * 1e6,
                (x.fixed_rows::<3>(0) - sc.reference.fixed_rows::<3>(0)).norm(),
            );
        }
    }
}
