//! RTI timing: one full tick, the feedback phase alone (the homotopy, and
//! its fallback to Clarabel), the transition with the tilt planned by the MPC, and the same QPs solved by Clarabel and (with
//! `--features osqp-compare`, needs cmake) OSQP in both formulations.
// Test, bench and example code: an unwrap that fails is the failure report.
#![allow(clippy::unwrap_used)]

#[path = "support/scenarios.rs"]
mod scenarios;

use std::hint::black_box;
use std::sync::Arc;
use std::time::{Duration, Instant};

use atmo_core::RobotConfig;
use atmo_core::ground_effect::table::GroundEffect;
use atmo_core::model::{Model, idx};
use atmo_mpc::{FeedbackMethod, Formulation, Mpc, Outcome, QpSnapshot, TiltPlan};
use clarabel::solver::IPSolver;
use criterion::{Criterion, criterion_group, criterion_main};
use scenarios::{NAMES, scenario};

/// Closed-loop estimates replayed by the timed ticks.
const RECORDED_TICKS: usize = 150;

fn formulation() -> Formulation {
    scenarios::settings(Formulation::Condensed)
        .solver
        .formulation
}

fn rti_tick(c: &mut Criterion) {
    let mut group = c.benchmark_group("rti_tick");
    for name in NAMES {
        let sc = scenario(name);
        let (mpc, estimates) = sc.warmed_up(formulation(), RECORDED_TICKS);
        time_full_ticks(&mut group, "rti_tick", name, &sc, mpc, &estimates);
    }
    group.finish();
}

/// Times `Mpc::tick` (preparation + feedback) over the replayed estimates.
fn time_full_ticks(
    group: &mut criterion::BenchmarkGroup<'_, criterion::measurement::WallTime>,
    group_name: &str,
    name: &str,
    sc: &scenarios::Scenario,
    mut mpc: Mpc,
    estimates: &[atmo_core::State],
) {
    let mut i = 0;
    let mut not_solved = 0;
    group.bench_function(name, |b| {
        b.iter(|| {
            sc.apply(&mut mpc);
            let out = mpc.tick(black_box(&estimates[i % RECORDED_TICKS])).unwrap();
            i += 1;
            not_solved += usize::from(out.outcome != Outcome::Solved);
            black_box(out.u)
        });
    });
    // Timing a solver that gave up early would flatter it: say so.
    eprintln!("{group_name}/{name}: {not_solved} of {i} ticks not Solved");
}

fn rti_feedback(c: &mut Criterion) {
    let mut group = c.benchmark_group("rti_feedback");
    for name in NAMES {
        let sc = scenario(name);
        let (mut mpc, estimates) = sc.warmed_up(formulation(), RECORDED_TICKS);
        let mut i = 0;
        let mut not_solved = 0;
        let mut fallbacks = 0;
        let mut changed = 0;
        group.bench_function(name, |b| {
            b.iter_custom(|iters| {
                let mut total = Duration::ZERO;
                for _ in 0..iters {
                    sc.apply(&mut mpc);
                    mpc.prepare().unwrap();
                    let x = estimates[i % RECORDED_TICKS];
                    i += 1;
                    let start = Instant::now();
                    let out = mpc.feedback(black_box(&x)).unwrap();
                    total += start.elapsed();
                    not_solved += usize::from(out.outcome != Outcome::Solved);
                    fallbacks += usize::from(out.path.is_fallback());
                    changed += usize::from(matches!(
                        out.path,
                        atmo_mpc::FeedbackPath::Homotopy { active_set_changes } if active_set_changes > 0
                    ));
                    black_box(out.u);
                }
                total
            });
        });
        eprintln!(
            "rti_feedback/{name}: {not_solved} of {i} ticks not Solved, {fallbacks} fell back to \
             Clarabel, {changed} changed the active set"
        );
    }
    group.finish();
}

/// `rti_tick` with the ground effect in the prediction model (the plant's
/// default surface, the ground 0.3 m under the start so that every hub is
/// inside the surface's 0.72 m reach): the preparation evaluates the surface
/// and its partials 16 times per stage.
fn rti_tick_ground_effect(c: &mut Criterion) {
    let mut group = c.benchmark_group("rti_tick_ground_effect");
    for name in NAMES {
        let sc = scenario(name);
        let settings = scenarios::settings(formulation());
        let mut mpc = Mpc::new(Model::new(&RobotConfig::atmo()), settings).unwrap();
        mpc.set_ground_effect(Some(Arc::new(GroundEffect::default_surface())));
        mpc.set_ground_height(sc.start[idx::Z] + 0.3).unwrap();
        let (mpc, estimates) = sc.warmed_up_from(mpc, RECORDED_TICKS);
        time_full_ticks(
            &mut group,
            "rti_tick_ground_effect",
            name,
            &sc,
            mpc,
            &estimates,
        );
    }
    group.finish();
}

/// The fallback path: the homotopy may change no bound and each estimate is
/// jolted by +-2 rad/s in roll and pitch rate, so the walk stops at its first
/// breakpoint and Clarabel solves at the estimate. Only the ticks that fell
/// back are timed.
fn rti_feedback_fallback(c: &mut Criterion) {
    let mut group = c.benchmark_group("rti_feedback_fallback");
    for name in NAMES {
        let sc = scenario(name);
        let mut settings = scenarios::settings(formulation());
        settings.feedback.max_active_set_changes = 0;
        assert_eq!(settings.feedback.method, FeedbackMethod::Homotopy);
        let (_, estimates) = sc.warmed_up(formulation(), RECORDED_TICKS);
        let mut mpc = Mpc::new(Model::new(&RobotConfig::atmo()), settings).unwrap();
        sc.apply(&mut mpc);
        mpc.reset(&sc.start).unwrap();
        let mut i = 0;
        let mut tried = 0;
        group.bench_function(name, |b| {
            b.iter_custom(|iters| {
                let mut total = Duration::ZERO;
                let mut timed = 0;
                while timed < iters {
                    sc.apply(&mut mpc);
                    mpc.prepare().unwrap();
                    let mut x = estimates[i % RECORDED_TICKS];
                    let jolt = if i % 2 == 0 { 2.0 } else { -2.0 };
                    x[idx::WX] += jolt;
                    x[idx::WY] -= jolt;
                    i += 1;
                    tried += 1;
                    let start = Instant::now();
                    let out = mpc.feedback(black_box(&x)).unwrap();
                    let took = start.elapsed();
                    if out.path.is_fallback() {
                        total += took;
                        timed += 1;
                    }
                    black_box(out.u);
                }
                total
            });
        });
        eprintln!(
            "rti_feedback_fallback/{name}: {} fallbacks timed of {tried} ticks",
            mpc.homotopy_fallbacks()
        );
    }
    group.finish();
}

/// Full ticks in both formulations: the measurement behind the default.
fn formulation_compare(c: &mut Criterion) {
    let mut group = c.benchmark_group("formulation_compare");
    for (label, formulation) in [
        ("condensed", Formulation::Condensed),
        ("sparse", Formulation::Sparse),
    ] {
        for name in NAMES {
            let sc = scenario(name);
            let (mut mpc, estimates) = sc.warmed_up(formulation, RECORDED_TICKS);
            let mut i = 0;
            let mut not_solved = 0;
            group.bench_function(format!("{label}/{name}"), |b| {
                b.iter(|| {
                    sc.apply(&mut mpc);
                    let out = mpc.tick(black_box(&estimates[i % RECORDED_TICKS])).unwrap();
                    i += 1;
                    not_solved += usize::from(out.outcome != Outcome::Solved);
                    black_box(out.u)
                });
            });
            eprintln!("formulation_compare/{label}/{name}: {not_solved} of {i} ticks not Solved");
        }
    }
    group.finish();
}

/// The QP of one morphing_50deg tick, in one formulation.
fn morphing_qp(formulation: Formulation) -> (QpSnapshot, Mpc) {
    let sc = scenario("morphing_50deg");
    let (mut mpc, estimates) = sc.warmed_up(formulation, RECORDED_TICKS);
    sc.apply(&mut mpc);
    mpc.tick(&estimates[RECORDED_TICKS - 1]).unwrap();
    (mpc.qp_snapshot(), mpc)
}

#[cfg(feature = "osqp-compare")]
/// OSQP's `l <= A z <= u` from Clarabel's `A z + s = b`, `s` in {0}^m0 x R+.
fn osqp_problem(qp: &QpSnapshot, eps: f64) -> osqp::Problem {
    let to_osqp = |m: &clarabel::algebra::CscMatrix<f64>| osqp::CscMatrix {
        nrows: m.m,
        ncols: m.n,
        indptr: m.colptr.clone().into(),
        indices: m.rowval.clone().into(),
        data: m.nzval.clone().into(),
    };
    let lower: Vec<f64> = (0..qp.b.len())
        .map(|r| {
            if r < qp.zero_rows {
                qp.b[r]
            } else {
                f64::NEG_INFINITY
            }
        })
        .collect();
    let settings = osqp::Settings::default()
        .verbose(false)
        .eps_abs(eps)
        .eps_rel(eps)
        .warm_start(false)
        .polish(true)
        .max_iter(20_000);
    osqp::Problem::new(
        to_osqp(&qp.p),
        &qp.q,
        to_osqp(&qp.a),
        &lower,
        &qp.b,
        &settings,
    )
    .unwrap()
}

fn qp_solver_compare(c: &mut Criterion) {
    let mut group = c.benchmark_group("qp_solver_compare");
    for (label, formulation) in [
        ("condensed", Formulation::Condensed),
        ("sparse", Formulation::Sparse),
    ] {
        let (qp, mpc) = morphing_qp(formulation);
        let mut clarabel = qp.fresh_solver(&mpc.settings().solver).unwrap();
        clarabel.solve();
        assert_eq!(
            clarabel.solution.status,
            clarabel::solver::SolverStatus::Solved
        );
        #[cfg(feature = "osqp-compare")]
        let reference = clarabel.solution.x.clone();
        group.bench_function(format!("clarabel_{label}"), |b| {
            b.iter(|| {
                clarabel.solve();
                black_box(clarabel.solution.iterations)
            });
        });
        #[cfg(feature = "osqp-compare")]
        for eps in [1e-4, 1e-6] {
            let mut problem = osqp_problem(&qp, eps);
            let (iterations, deviation) = {
                let status = problem.solve();
                let x = status.x().expect("OSQP solves the RTI QP");
                let dev = x
                    .iter()
                    .zip(&reference)
                    .map(|(a, b)| (a - b).abs())
                    .fold(0.0, f64::max);
                (status.iter(), dev)
            };
            eprintln!(
                "qp_solver_compare/osqp_{label}_eps{eps:e}: {iterations} ADMM iterations, \
                 max |x_osqp - x_clarabel| = {deviation:.2e} (Clarabel: {} IPM iterations)",
                clarabel.solution.iterations
            );
            group.bench_function(format!("osqp_{label}_eps{eps:e}"), |b| {
                b.iter(|| black_box(problem.solve().iter()));
            });
        }
    }
    group.finish();
}

/// The transition with the tilt planned by the MPC (13/5 QP, the default
/// ground-effect surface, the landing objective): 60 deg at 0.25 m,
/// descending at 0.2 m/s. `tick`: preparation + feedback; `feedback`: the
/// feedback phase alone. The estimates come from a closed loop of the
/// atmo-core model with the planned tilt rate integrated.
fn rti_tilt_plan(c: &mut Criterion) {
    let mut group = c.benchmark_group("rti_tilt_plan");
    let robot = RobotConfig::atmo();
    let mut settings = scenarios::settings(formulation());
    settings.model.ground_effect = atmo_mpc::settings::GroundEffectSource::PlantDefault;
    let plan = TiltPlan {
        tilt_min: 0.0,
        tilt_max: robot.limits.tilt_transition_max(),
        rate_min: -robot.limits.tilt_rate_max,
        rate_max: robot.limits.tilt_rate_max,
        wheel_radius: robot.wheels.radius,
        thrust_max: None,
    };
    let make = || {
        let model = Model::new(&robot);
        let mut mpc = Mpc::new(model, settings.clone()).unwrap();
        mpc.set_ground_effect(Some(Arc::new(GroundEffect::default_surface())));
        mpc.set_ground_height(0.0).unwrap();
        let mut reference = atmo_core::State::zeros();
        reference[idx::VZ] = 0.2;
        mpc.set_reference_constant(&reference).unwrap();
        mpc.set_alpha(0.2).unwrap();
        mpc.set_tilt_ramp(60f64.to_radians(), 0.0, 0.0, plan.tilt_max)
            .unwrap();
        mpc.set_tilt_plan(&plan).unwrap();
        mpc
    };
    // Record the closed loop once.
    let mut mpc = make();
    let mut x = atmo_core::State::zeros();
    x[idx::Z] = -0.25;
    x[idx::VZ] = 0.1;
    let mut varphi = 60f64.to_radians();
    mpc.reset(&x).unwrap();
    let period = mpc.settings().horizon.tick_period;
    let mut recorded = Vec::with_capacity(RECORDED_TICKS);
    for _ in 0..RECORDED_TICKS {
        recorded.push((x, varphi));
        mpc.set_measured_tilt(varphi).unwrap();
        let out = mpc.tick(&x).unwrap();
        let body = mpc.model().at_tilt(varphi);
        for _ in 0..7 {
            x = body.rk4_step(&x, &out.u, period / 7.0);
        }
        varphi += out.tilt_rate.unwrap() * period;
        // Hold the height band of a landing (the model has no ground).
        if x[idx::Z] > -0.15 {
            x[idx::Z] = -0.25;
        }
    }
    let timed = |group: &mut criterion::BenchmarkGroup<'_, _>, label: &str, feedback_only: bool| {
        let mut mpc = make();
        mpc.reset(&recorded[0].0).unwrap();
        let mut i = 0;
        let mut not_solved = 0;
        group.bench_function(label, |b| {
            b.iter_custom(|iters| {
                let mut total = Duration::ZERO;
                for _ in 0..iters {
                    let (x, varphi) = recorded[i % RECORDED_TICKS];
                    i += 1;
                    mpc.set_tilt_plan(&plan).unwrap();
                    mpc.set_measured_tilt(varphi).unwrap();
                    let start = Instant::now();
                    mpc.prepare().unwrap();
                    let fb = Instant::now();
                    let out = mpc.feedback(black_box(&x)).unwrap();
                    total += if feedback_only {
                        fb.elapsed()
                    } else {
                        start.elapsed()
                    };
                    not_solved += usize::from(out.outcome != Outcome::Solved);
                    black_box(out.u);
                }
                total
            });
        });
        eprintln!("rti_tilt_plan/{label}: {not_solved} of {i} ticks not Solved");
    };
    timed(&mut group, "tick", false);
    timed(&mut group, "feedback", true);
    group.finish();
}

criterion_group!(
    benches,
    rti_tick,
    rti_tilt_plan,
    rti_tick_ground_effect,
    rti_feedback,
    rti_feedback_fallback,
    formulation_compare,
    qp_solver_compare
);
criterion_main!(benches);
