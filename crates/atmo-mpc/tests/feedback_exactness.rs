//! The homotopy feedback gives the exact QP solution.
//!
//! Around plans recorded in the three benchmark situations (hover, morphing
//! at 50 deg, transition at 65 deg; `benches/support/scenarios.rs`), random
//! estimate perturbations are fed through the controller's QP path exactly as
//! a tick does: Clarabel at a predicted deviation plus the homotopy's
//! correction (preparation), then the homotopy to the actual deviation
//! (feedback). Each result is compared with a fresh Clarabel solve of the
//! same QP at the actual deviation with tight tolerances (1e-11, iterative
//! refinement), and checked against the QP's KKT conditions directly.
//!
//! What "equal to 1e-6" means here: the homotopy's solution is exact up to
//! the round-off of one Cholesky solve (its KKT residual is checked to 1e-9);
//! the interior-point reference is the one with the larger error (its
//! distance to the optimum scales with its tolerances), so the 1e-6 bound is
//! mostly a bound on the reference.
// Test, bench and example code: an unwrap that fails is the failure report.
#![allow(clippy::unwrap_used)]

mod common;
#[allow(dead_code)]
#[path = "../benches/support/scenarios.rs"]
mod scenarios;

use atmo_core::RobotConfig;
use atmo_core::model::{Model, NU, NX, State};
use atmo_mpc::qp::QpBackend;
use atmo_mpc::{Bound, CutWindow, Formulation, LinearizedHorizon, Mpc};
use clarabel::solver::SolverStatus;
use nalgebra::{DMatrix, DVector};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use scenarios::{NAMES, scenario};

/// Plans recorded per situation (one every `RECORD_EVERY` ticks of a closed loop).
const PLANS: usize = 12;
const RECORD_EVERY: usize = 10;
/// 3 situations x 12 plans x 280 = 10 080 cases.
const PERTURBATIONS_PER_PLAN: usize = 280;

/// Scale of one perturbation per state entry: x y z (m), yaw pitch roll
/// (rad), velocities (m/s), body rates (rad/s).
const SCALE: [f64; NX] = [
    0.05, 0.05, 0.05, 0.05, 0.05, 0.05, 0.2, 0.2, 0.2, 0.4, 0.4, 0.4,
];

/// Linearizations of `PLANS` preparations of a closed loop in the situation.
fn recorded_plans(name: &str) -> Vec<LinearizedHorizon> {
    let sc = scenario(name);
    let mut settings = scenarios::settings(Formulation::Condensed);
    settings.solver.time_limit = 1.0;
    let mut mpc = Mpc::new(Model::new(&RobotConfig::atmo()), settings).unwrap();
    sc.apply(&mut mpc);
    mpc.reset(&sc.start).unwrap();
    let h = mpc.settings().horizon.tick_period / 7.0;
    let body = mpc.model().at_tilt(sc.varphi);
    let mut x = sc.start;
    let mut plans = Vec::new();
    for tick in 0..PLANS * RECORD_EVERY {
        sc.apply(&mut mpc);
        mpc.prepare().unwrap();
        if tick % RECORD_EVERY == RECORD_EVERY - 1 {
            plans.push(mpc.linearization().clone());
        }
        let out = mpc.feedback(&x).unwrap();
        assert!(
            out.outcome.is_fresh(),
            "{name} tick {tick}: {:?}",
            out.outcome
        );
        for _ in 0..7 {
            x = body.rk4_step(&x, &out.u, h);
        }
    }
    plans
}

/// A perturbation of magnitude `size` (in units of `SCALE`).
fn perturbation(rng: &mut ChaCha8Rng, size: f64) -> State {
    State::from_fn(|i, _| size * SCALE[i] * rng.random_range(-1.0..=1.0))
}

/// Largest violation of the box QP's KKT conditions at `z`: bounds,
/// stationarity of free entries, signs of the bound multipliers. Relative to
/// the gradient's scale.
fn kkt_violation(h: &[f64], q: &[f64], hi: &[f64], ubar: &[f64], z: &[f64], ws: &[Bound]) -> f64 {
    let n = q.len();
    let scale = q.iter().fold(1.0_f64, |m, v| m.max(v.abs()));
    let mut worst: f64 = 0.0;
    for i in 0..n {
        let g: f64 = (0..n).map(|j| h[i * n + j] * z[j]).sum::<f64>() + q[i];
        let lo = -ubar[i];
        worst = worst.max(lo - z[i]).max(z[i] - hi[i]);
        let dual = match ws[i] {
            Bound::Free => g.abs(),
            Bound::Lower => (z[i] - lo).abs().max((-g).max(0.0)),
            Bound::Upper => (z[i] - hi[i]).abs().max(g.max(0.0)),
        };
        worst = worst.max(dual / scale);
    }
    worst
}

/// Clarabel's solution made exact on its own active set (as OSQP's
/// "polishing" does): bounds within `near` of the solution are taken as
/// active, the free entries solve `H_FF z_F = -(q_F + H_FA z_A)` (nalgebra's
/// Cholesky, independent of the homotopy's factor updates).
fn polish(
    h: &[f64],
    q: &[f64],
    hi: &[f64],
    ubar: &[f64],
    z: &[f64],
    near: f64,
) -> (Vec<f64>, Vec<Bound>) {
    let n = q.len();
    let ws: Vec<Bound> = (0..n)
        .map(|i| {
            if (z[i] - hi[i]).abs() < near {
                Bound::Upper
            } else if (z[i] + ubar[i]).abs() < near {
                Bound::Lower
            } else {
                Bound::Free
            }
        })
        .collect();
    let mut out: Vec<f64> = (0..n)
        .map(|i| match ws[i] {
            Bound::Upper => hi[i],
            Bound::Lower => -ubar[i],
            Bound::Free => 0.0,
        })
        .collect();
    let free: Vec<usize> = (0..n).filter(|&i| ws[i] == Bound::Free).collect();
    let m = free.len();
    let hff = DMatrix::from_fn(m, m, |r, c| h[free[r] * n + free[c]]);
    let rhs = DVector::from_fn(m, |r, _| {
        -(q[free[r]] + (0..n).map(|j| h[free[r] * n + j] * out[j]).sum::<f64>())
    });
    let zf = hff
        .cholesky()
        .expect("H_FF is positive definite")
        .solve(&rhs);
    for (r, &i) in free.iter().enumerate() {
        out[i] = zf[r];
    }
    (out, ws)
}

#[derive(Default)]
struct Tally {
    cases: usize,
    changed: usize,
    most_changes: u32,
    fallbacks: usize,
    worst_vs_reference: f64,
    /// Against Clarabel's solution itself.
    worst_vs_raw: f64,
    raw_within: usize,
    /// Reference solutions no closeness threshold made a KKT point of.
    unpolished: usize,
    worst_kkt: f64,
    worst_fallback_vs_reference: f64,
}

#[test]
fn homotopy_feedback_equals_a_tight_clarabel_solve() {
    let mut shipped = scenarios::settings(Formulation::Condensed);
    // Numbers are under test, not the machine's load: no wall-clock limit.
    shipped.solver.time_limit = 1.0;
    let feedback = shipped.feedback;
    let tight = common::reference_settings(&shipped.solver);
    let mut rng = ChaCha8Rng::seed_from_u64(18);
    let mut total = Tally::default();
    for name in NAMES {
        let mut tally = Tally::default();
        for lin in recorded_plans(name) {
            let mut under_test = QpBackend::new(&lin, &shipped.solver).unwrap();
            under_test.load(&lin).unwrap();
            let mut reference = QpBackend::new(&lin, &tight).unwrap();
            reference.load(&lin).unwrap();
            for _ in 0..PERTURBATIONS_PER_PLAN {
                // The prediction misses by a tenth of a typical error; the
                // estimate is off the plan by up to three.
                let predicted = perturbation(&mut rng, 0.1);
                let size = [0.3, 1.0, 3.0][rng.random_range(0..3)];
                let actual = perturbation(&mut rng, size);
                let qp = under_test.condensed_mut().unwrap();
                let prepared = qp
                    .prepare_solution(
                        &predicted,
                        feedback.max_preparation_changes,
                        &mut CutWindow::default(),
                    )
                    .unwrap();
                let walked = match prepared.correction {
                    Ok(_) => qp.feedback_solution(&actual, feedback.max_active_set_changes),
                    Err(stop) => Err(stop),
                };
                reference.set_initial_deviation(&actual).unwrap();
                let report = reference.solve(&mut CutWindow::default());
                assert_eq!(report.status, SolverStatus::Solved, "{name}: reference");
                tally.cases += 1;
                let deviation = |a: &[f64], b: &[f64]| {
                    a.iter()
                        .zip(b)
                        .map(|(x, y)| (x - y).abs())
                        .fold(0.0, f64::max)
                };
                if let Ok(changes) = walked {
                    tally.changed += usize::from(changes > 0);
                    tally.most_changes = tally.most_changes.max(changes);
                    let snap = under_test.snapshot();
                    let n = NU * lin.steps();
                    let (hi, ubar) = (&snap.b[..n], &snap.b[n..]);
                    let qp = under_test.condensed_mut().unwrap();
                    let h = qp.hessian();
                    let v =
                        kkt_violation(h, &snap.q, hi, ubar, qp.raw_solution(), qp.working_set());
                    assert!(v <= 1e-9, "{name}: KKT violation {v:.3e}");
                    tally.worst_kkt = tally.worst_kkt.max(v);
                    let raw = reference.raw_solution();
                    let d_raw = deviation(qp.raw_solution(), raw);
                    tally.raw_within += usize::from(d_raw <= 1e-6);
                    tally.worst_vs_raw = tally.worst_vs_raw.max(d_raw);
                    // The first closeness that gives a KKT point: the
                    // raw solution is off by up to ~1e-5 where a bound's
                    // multiplier is nearly zero.
                    let polished = [1e-7, 1e-6, 1e-5, 1e-4, 1e-8, 1e-9]
                        .iter()
                        .find_map(|&near| {
                            let (z, ws) = polish(h, &snap.q, hi, ubar, raw, near);
                            (kkt_violation(h, &snap.q, hi, ubar, &z, &ws) <= 1e-9).then_some(z)
                        });
                    let Some(polished) = polished else {
                        // Not counted as agreement: reported.
                        tally.unpolished += 1;
                        eprintln!(
                            "{name}: Clarabel's solution could not be polished (raw deviation {d_raw:.2e})"
                        );
                        continue;
                    };
                    let d = deviation(qp.raw_solution(), &polished);
                    assert!(
                        d <= 1e-6,
                        "{name}: homotopy vs polished reference {d:.3e} after {changes} changes \
                             (raw reference {d_raw:.3e})"
                    );
                    tally.worst_vs_reference = tally.worst_vs_reference.max(d);
                } else {
                    // The controller then solves with Clarabel at the
                    // shipped tolerances: that is what it would fly.
                    tally.fallbacks += 1;
                    under_test.set_initial_deviation(&actual).unwrap();
                    under_test.solve(&mut CutWindow::default());
                    let d = deviation(under_test.raw_solution(), reference.raw_solution());
                    tally.worst_fallback_vs_reference = tally.worst_fallback_vs_reference.max(d);
                }
            }
        }
        let solved = tally.cases - tally.fallbacks;
        eprintln!(
            "{name}: {} cases, {:.1} % needed active-set changes (at most {}), {:.2} % fell back \
             to Clarabel; max |homotopy - polished reference| = {:.2e}, max KKT residual {:.2e}; \
             raw Clarabel 1e-11 within 1e-6 in {} of {solved} (max {:.2e}), {} references not \
             polishable; fallbacks (Clarabel at the shipped 1e-6) vs reference {:.2e}",
            tally.cases,
            100.0 * tally.changed as f64 / tally.cases as f64,
            tally.most_changes,
            100.0 * tally.fallbacks as f64 / tally.cases as f64,
            tally.worst_vs_reference,
            tally.worst_kkt,
            tally.raw_within,
            tally.worst_vs_raw,
            tally.unpolished,
            tally.worst_fallback_vs_reference,
        );
        total.cases += tally.cases;
        total.changed += tally.changed;
        total.fallbacks += tally.fallbacks;
        total.unpolished += tally.unpolished;
    }
    assert_eq!(total.unpolished, 0, "references that could not be polished");
    eprintln!(
        "all: {} cases, {:.1} % with active-set changes, {:.2} % fallbacks",
        total.cases,
        100.0 * total.changed as f64 / total.cases as f64,
        100.0 * total.fallbacks as f64 / total.cases as f64
    );
    assert!(total.cases >= 10_000);
    // The perturbations must exercise the homotopy, not only its first segment.
    assert!(
        total.changed * 5 >= total.cases,
        "only {} of {} cases changed the active set",
        total.changed,
        total.cases
    );
    assert!(
        total.fallbacks * 100 <= total.cases,
        "{} of {} cases fell back",
        total.fallbacks,
        total.cases
    );
}
