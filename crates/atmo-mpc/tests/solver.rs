//! The QP and its solver: in-place updates, the two formulations, RTI
//! against converged SQP, outcomes on bad input.
// Test, bench and example code: an unwrap that fails is the failure report.
#![allow(clippy::unwrap_used)]

mod common;

use atmo_core::RobotConfig;
use atmo_core::model::{Model, State, idx};
use atmo_mpc::{
    FailureCause, FeedbackMethod, FeedbackPath, Formulation, Mpc, MpcError, Outcome, wrap_angle,
};
use clarabel::solver::IPSolver;
use clarabel::solver::SolverStatus;
use common::{controller, hover_at, run, settings};

fn perturbed(height: f64) -> State {
    let mut x = hover_at(0.5, 0.0, height);
    x[idx::ROLL] = 20f64.to_radians();
    x[idx::VY] = 1.0;
    x
}

/// A few ticks into a recovery at 30 deg tilt, so that every block of the
/// QP (defects, active bounds, tilt-dependent Jacobians) is non-trivial.
fn mid_recovery(mpc: &mut Mpc, ticks: usize) -> State {
    let reference = hover_at(0.0, 0.0, 1.0);
    let trace = run(mpc, perturbed(1.0), ticks, |m, _, _| {
        m.set_reference_constant(&reference).unwrap();
        m.set_alpha(0.8).unwrap();
        m.set_tilt_ramp(30f64.to_radians(), 0.0, 0.0, 1.0).unwrap();
        30f64.to_radians()
    });
    *trace.last()
}

fn max_abs_diff(a: &[f64], b: &[f64]) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
}

fn updated_matches_fresh(formulation: Formulation, equilibrate: bool, tolerance: f64) {
    let mut s = settings(formulation);
    s.solver.equilibrate = equilibrate;
    // Clarabel's in-place updates are under test: its solution, not the homotopy's.
    s.feedback.method = FeedbackMethod::Clarabel;
    let mut mpc = Mpc::new(Model::new(&RobotConfig::atmo()), s.clone()).unwrap();
    let x = mid_recovery(&mut mpc, 20);
    let out = mpc.tick(&x).unwrap();
    assert_eq!(out.outcome, Outcome::Solved);
    let qp = mpc.qp_snapshot();
    let mut fresh = qp.fresh_solver(&s.solver).unwrap();
    fresh.solve();
    assert_eq!(
        fresh.solution.status,
        clarabel::solver::SolverStatus::Solved
    );
    let diff = max_abs_diff(&fresh.solution.x, mpc.qp_solution());
    eprintln!("{formulation:?} equilibrate={equilibrate}: |updated - fresh| = {diff:.3e}");
    assert!(diff < tolerance, "{diff}");
}

// Without equilibration an updated solver holds exactly the data a fresh one
// would: same numbers, same iterations.
#[test]
fn updated_solver_equals_fresh_without_equilibration_condensed() {
    updated_matches_fresh(Formulation::Condensed, false, 1e-12);
}

#[test]
fn updated_solver_equals_fresh_without_equilibration_sparse() {
    updated_matches_fresh(Formulation::Sparse, false, 1e-12);
}

// With equilibration the updated solver keeps the start-up scaling while a
// fresh one computes its own: both solve the same QP to the tolerances
// (1e-7), so they agree to well within what the actuators resolve.
#[test]
fn updated_solver_matches_fresh_with_equilibration_condensed() {
    updated_matches_fresh(Formulation::Condensed, true, 1e-6);
}

#[test]
fn updated_solver_matches_fresh_with_equilibration_sparse() {
    updated_matches_fresh(Formulation::Sparse, true, 1e-6);
}

/// A controller whose QPs are solved tightly: for tests that compare
/// algorithms (formulations, RTI vs SQP), not the flight tolerances.
fn precise(formulation: Formulation) -> Mpc {
    let mut s = settings(formulation);
    s.solver.tol_gap_abs = 1e-10;
    s.solver.tol_gap_rel = 1e-10;
    s.solver.tol_feas = 1e-10;
    s.solver.iterative_refinement = true;
    Mpc::new(Model::new(&RobotConfig::atmo()), s).unwrap()
}

#[test]
fn sparse_and_condensed_give_the_same_step() {
    let mut sparse = precise(Formulation::Sparse);
    let mut condensed = precise(Formulation::Condensed);
    let xs = mid_recovery(&mut sparse, 1);
    let xc = mid_recovery(&mut condensed, 1);
    assert!(max_abs_diff(xs.as_slice(), xc.as_slice()) < 1e-5);
    let os = sparse.tick(&xs).unwrap();
    let oc = condensed.tick(&xs).unwrap();
    let du = max_abs_diff(os.u.as_slice(), oc.u.as_slice());
    let plan = sparse
        .plan_states()
        .iter()
        .zip(condensed.plan_states())
        .map(|(a, b)| (a - b).amax())
        .fold(0.0, f64::max);
    eprintln!("sparse vs condensed: |du0| = {du:.2e}, |plan x| = {plan:.2e}");
    assert!(du < 1e-8 && plan < 1e-6);
}

/// At steady state one RTI iteration per tick has converged: iterating the
/// same problem to a full SQP solution changes nothing. Mid-transient it does.
#[test]
fn rti_agrees_with_converged_sqp_at_steady_state() {
    let cfg = RobotConfig::atmo();
    let reference = hover_at(0.3, -0.2, 1.5);
    let varphi = cfg.limits.tilt_flight_max();
    let setup = |m: &mut Mpc, _: usize, _: &State| {
        m.set_reference_constant(&reference).unwrap();
        m.set_alpha(varphi.cos()).unwrap();
        m.set_tilt_ramp(varphi, 0.0, 0.0, varphi).unwrap();
        varphi
    };
    let compare = |ticks: usize| {
        let mut mpc = precise(Formulation::Condensed);
        let trace = run(&mut mpc, perturbed(1.0), ticks, setup);
        let x = *trace.last();
        mpc.prepare().unwrap();
        let rti = mpc.feedback(&x).unwrap();
        let rti_plan: Vec<_> = mpc.plan_inputs().to_vec();
        let sqp = mpc.converge_sqp(&x, 50, 1e-10).unwrap();
        assert!(sqp.converged, "{sqp:?}");
        let du0 = max_abs_diff(rti.u.as_slice(), mpc.plan_inputs()[0].as_slice());
        let plan = rti_plan
            .iter()
            .zip(mpc.plan_inputs())
            .map(|(a, b)| (a - b).amax())
            .fold(0.0, f64::max);
        (du0, plan, sqp.iterations)
    };
    let (du0, plan, its) = compare(6 * 150);
    eprintln!("steady state: RTI vs SQP |du0| = {du0:.2e}, plan {plan:.2e}, SQP iterations {its}");
    assert!(du0 < 1e-6 && plan < 1e-6);
    let (du0_t, plan_t, its_t) = compare(10);
    eprintln!(
        "transient: RTI vs SQP |du0| = {du0_t:.2e}, plan {plan_t:.2e}, SQP iterations {its_t}"
    );
    assert!(
        plan_t > 1e-4,
        "the comparison must be able to tell a difference"
    );
}

#[test]
fn non_finite_estimate_flies_the_shifted_plan_then_fails() {
    let mut mpc = controller(Formulation::Condensed);
    let grace = mpc.settings().failure.grace_ticks;
    let x = hover_at(0.0, 0.0, 1.0);
    mpc.set_reference_constant(&x).unwrap();
    mpc.reset(&x).unwrap();
    let good = mpc.tick(&x).unwrap();
    assert_eq!(good.outcome, Outcome::Solved);
    let mut bad = x;
    bad[idx::VZ] = f64::NAN;
    for k in 1..=grace + 2 {
        let out = mpc.tick(&bad).unwrap();
        assert!(out.u.iter().all(|v| (0.0..=1.0).contains(v)));
        let cause = FailureCause::NonFiniteEstimate { entry: idx::VZ };
        if k <= grace {
            assert_eq!(
                out.outcome,
                Outcome::Fallback {
                    cause,
                    failed_ticks: k
                }
            );
            // Flying the previous plan: at hover that is the previous command.
            assert!((out.u - good.u).amax() < 1e-3);
        } else {
            assert_eq!(
                out.outcome,
                Outcome::Failed {
                    cause,
                    failed_ticks: k
                }
            );
        }
    }
    bad[idx::VZ] = f64::INFINITY;
    assert!(!mpc.tick(&bad).unwrap().outcome.is_fresh());
    let recovered = mpc.tick(&x).unwrap();
    assert_eq!(recovered.outcome, Outcome::Solved);
    assert_eq!(mpc.failed_ticks(), 0);
}

/// Capping the interior-point iterations of a Clarabel feedback (the
/// homotopy's fallback): an iterate that is still far from the optimum is not
/// flown (fallback to the shifted plan); one that meets the reduced
/// tolerances is (degraded); enough iterations solve.
#[test]
fn iteration_cap_falls_back_early_and_degrades_late() {
    let solve_with_cap = |cap: u32| {
        let mut s = settings(Formulation::Condensed);
        s.feedback.method = FeedbackMethod::Clarabel;
        s.solver.max_iter = cap;
        let mut mpc = Mpc::new(Model::new(&RobotConfig::atmo()), s).unwrap();
        mpc.set_reference_constant(&hover_at(0.0, 0.0, 1.0))
            .unwrap();
        let x = perturbed(1.0);
        mpc.reset(&x).unwrap();
        let out = mpc.tick(&x).unwrap();
        assert!(out.u.iter().all(|v| (0.0..=1.0).contains(v)));
        out
    };
    let solved = solve_with_cap(40);
    assert_eq!(solved.outcome, Outcome::Solved);
    let needed = solved.timings.solver_iterations;
    let early = solve_with_cap(1);
    assert_eq!(
        early.outcome,
        Outcome::Fallback {
            cause: FailureCause::Solver(SolverStatus::MaxIterations),
            failed_ticks: 1
        }
    );
    let mut degraded = 0;
    for cap in 1..needed {
        let out = solve_with_cap(cap);
        eprintln!(
            "cap {cap}: {:?}, |u - u_solved| = {:.1e}",
            out.outcome,
            (out.u - solved.u).amax()
        );
        if let Outcome::Degraded(_) = out.outcome {
            degraded += 1;
            assert!(
                (out.u - solved.u).amax() < 1e-2,
                "a degraded command must be close to the solution"
            );
        }
    }
    assert!(degraded > 0, "no cap gave a usable iterate");
}

/// With the homotopy, Clarabel's solution in the preparation only seeds the
/// active set: an iterate cut off after one or two iterations still ends in
/// the exact solution (the correction walks from its active set), the same
/// command as with an uncapped Clarabel.
#[test]
fn homotopy_is_exact_whatever_clarabel_gave_in_the_preparation() {
    let solve_with_cap = |cap: u32| {
        let mut s = settings(Formulation::Condensed);
        s.solver.max_iter = cap;
        let mut mpc = Mpc::new(Model::new(&RobotConfig::atmo()), s).unwrap();
        mpc.set_reference_constant(&hover_at(0.0, 0.0, 1.0))
            .unwrap();
        let x = perturbed(1.0);
        mpc.reset(&x).unwrap();
        mpc.tick(&x).unwrap()
    };
    let full = solve_with_cap(40);
    assert!(
        matches!(full.path, FeedbackPath::Homotopy { .. }),
        "{:?}",
        full.path
    );
    for cap in [1, 2] {
        let out = solve_with_cap(cap);
        assert_eq!(out.outcome, Outcome::Solved);
        assert!(
            matches!(out.path, FeedbackPath::Homotopy { .. }),
            "{:?}",
            out.path
        );
        assert!(
            (out.u - full.u).amax() < 1e-9,
            "cap {cap}: {:.2e}",
            (out.u - full.u).amax()
        );
    }
}

#[test]
fn time_limit_hit_early_flies_the_shifted_plan() {
    let mut s = settings(Formulation::Sparse);
    s.solver.time_limit = 1e-5;
    let mut mpc = Mpc::new(Model::new(&RobotConfig::atmo()), s).unwrap();
    mpc.set_reference_constant(&hover_at(0.0, 0.0, 1.0))
        .unwrap();
    let x = perturbed(1.0);
    mpc.reset(&x).unwrap();
    let plan_u0 = mpc.plan_inputs()[0];
    let out = mpc.tick(&x).unwrap();
    assert_eq!(
        out.outcome,
        Outcome::Fallback {
            cause: FailureCause::Solver(SolverStatus::CallbackTerminated),
            failed_ticks: 1
        }
    );
    // The plan after reset holds the hover trim, so the shifted plan does too.
    assert!((out.u - plan_u0).amax() < 1e-12);
}

#[test]
fn bad_parameters_are_refused_not_panicked_on() {
    let mut mpc = controller(Formulation::Sparse);
    let x = hover_at(0.0, 0.0, 1.0);
    assert!(matches!(mpc.feedback(&x), Err(MpcError::NotPrepared)));
    let mut nan_ref = x;
    nan_ref[idx::YAW] = f64::NAN;
    assert!(matches!(
        mpc.set_reference_constant(&nan_ref),
        Err(MpcError::NonFiniteParameter { entry: 3, .. })
    ));
    assert!(matches!(
        mpc.set_reference(&[x; 3]),
        Err(MpcError::HorizonLength {
            expected: 11,
            got: 3,
            ..
        })
    ));
    assert!(mpc.set_alpha(1.5).is_err());
    assert!(mpc.set_alpha(f64::NAN).is_err());
    assert!(mpc.set_tilt_ramp(f64::NAN, 0.0, 0.0, 1.0).is_err());
    assert!(
        mpc.set_tilt_sequence(&[0.0; 11].map(|v: f64| v - 1.0))
            .is_err()
    );
    assert!(mpc.reset(&nan_ref).is_err());
    // A valid ramp is clamped at its limit.
    mpc.set_tilt_ramp(1.0, 0.5, 0.0, 1.1).unwrap();
    let seq = mpc.tilt_sequence();
    assert_eq!(seq[0], 1.0);
    assert!((seq[1] - 1.05).abs() < 1e-12);
    assert_eq!(seq[10], 1.1);
}

#[test]
fn yaw_error_is_the_wrapped_difference() {
    let mut mpc = controller(Formulation::Condensed);
    let mut reference = hover_at(0.0, 0.0, 1.0);
    reference[idx::YAW] = 179f64.to_radians();
    let mut x0 = reference;
    x0[idx::YAW] = -179f64.to_radians();
    let trace = run(&mut mpc, x0, 3 * 150, |m, _, _| {
        m.set_reference_constant(&reference).unwrap();
        m.set_alpha(1.0).unwrap();
        m.set_tilt_ramp(0.0, 0.0, 0.0, 0.0).unwrap();
        0.0
    });
    // The short way is 2 deg across +-180; the long way would pass through 0.
    let worst = trace
        .states
        .iter()
        .map(|s| wrap_angle(s[idx::YAW] - reference[idx::YAW]).abs())
        .fold(0.0, f64::max);
    assert!(worst < 3f64.to_radians(), "yaw went the long way: {worst}");
    let last = wrap_angle(trace.last()[idx::YAW] - reference[idx::YAW]);
    assert!(last.abs() < 0.2f64.to_radians(), "{last}");
}

/// Past the critical angle near the ground (65 deg, alpha about 0.2) the
/// robot cannot hold altitude; the controller must still solve every tick,
/// keep the rotors in [0, 1] and keep the attitude level.
#[test]
fn transition_past_critical_angle_stays_solved_and_level() {
    let mut mpc = controller(Formulation::Condensed);
    let cfg = RobotConfig::atmo();
    let varphi = 65f64.to_radians();
    assert!(varphi > atmo_core::limits::critical_angle(mpc.model()).unwrap());
    let height = 0.2;
    let alpha = atmo_core::control::blending_alpha(height, varphi, cfg.limits.transition_height);
    assert!((alpha - 0.2).abs() < 0.03, "{alpha}");
    let reference = hover_at(0.0, 0.0, 0.0);
    let trace = run(&mut mpc, hover_at(0.0, 0.0, height), 60, |m, _, _| {
        m.set_reference_constant(&reference).unwrap();
        m.set_alpha(alpha).unwrap();
        m.set_tilt_ramp(varphi, 0.0, 0.0, varphi).unwrap();
        varphi
    });
    assert!(trace.inputs_within_bounds());
    assert_eq!(trace.fresh_fraction(), 1.0);
    let worst_tilt = trace
        .states
        .iter()
        .map(|s| s[idx::PITCH].abs().max(s[idx::ROLL].abs()))
        .fold(0.0, f64::max);
    assert!(worst_tilt < 2f64.to_radians(), "{worst_tilt}");
}

#[test]
fn horizon_length_and_preset_are_configurable() {
    for (steps, preset) in [(5, "fig5"), (20, "default")] {
        let mut s = atmo_mpc::MpcSettings::atmo(preset).unwrap();
        s.horizon.steps = steps;
        s.solver.time_limit = 1.0;
        let mut mpc = Mpc::new(Model::new(&RobotConfig::atmo()), s).unwrap();
        assert_eq!(mpc.steps(), steps);
        assert!((mpc.stage_dt() - 1.0 / steps as f64).abs() < 1e-15);
        let reference = hover_at(0.0, 0.0, 1.0);
        let trace = run(&mut mpc, perturbed(1.0), 3 * 150, |m, _, _| {
            m.set_reference_constant(&reference).unwrap();
            m.set_alpha(1.0).unwrap();
            m.set_tilt_ramp(0.0, 0.0, 0.0, 0.0).unwrap();
            0.0
        });
        assert_eq!(mpc.plan_states().len(), steps + 1);
        assert_eq!(mpc.plan_inputs().len(), steps);
        assert!(trace.inputs_within_bounds());
        let err = (trace.last().fixed_rows::<3>(idx::X) - reference.fixed_rows::<3>(idx::X)).norm();
        assert!(err < 0.05, "N = {steps}, {preset}: {err} m off after 3 s");
    }
}

#[test]
fn alpha_is_refreshed_every_period_and_held_in_between() {
    let mut schedule = atmo_mpc::AlphaSchedule::new(10);
    let z_star = 0.45;
    // First tick computes; the next nine hold even though the height changed.
    let first = schedule.update(0.45, 0.0, z_star);
    assert_eq!(first, 1.0);
    for _ in 0..9 {
        assert_eq!(schedule.update(0.0, 1.0, z_star), 1.0);
    }
    // Tick 11 refreshes: on the ground alpha is 0.
    assert_eq!(schedule.update(0.0, 1.0, z_star), 0.0);
    // Half the transition height at 60 deg: 0.5 * cos(60 deg) = 0.25.
    let mut schedule = atmo_mpc::AlphaSchedule::new(1);
    assert!((schedule.update(0.225, 60f64.to_radians(), z_star) - 0.25).abs() < 1e-12);
}

/// The flight stack moves the controller into its control thread.
#[test]
fn controller_can_move_to_the_control_thread() {
    fn assert_send<T: Send>() {}
    assert_send::<Mpc>();
    let mut mpc = controller(Formulation::Condensed);
    let x = hover_at(0.0, 0.0, 1.0);
    let handle = std::thread::spawn(move || {
        mpc.set_reference_constant(&x).unwrap();
        mpc.reset(&x).unwrap();
        mpc.tick(&x).unwrap().outcome
    });
    assert_eq!(handle.join().unwrap(), Outcome::Solved);
}

/// A plan that blows up (here: started at an absurd speed) fails one tick
/// with a bounded fallback command and is restarted from the estimate.
#[test]
fn diverged_plan_is_restarted_from_the_estimate() {
    let mut mpc = controller(Formulation::Condensed);
    let x = hover_at(0.0, 0.0, 1.0);
    mpc.set_reference_constant(&x).unwrap();
    let mut absurd = x;
    absurd[idx::WX] = 1e300;
    mpc.reset(&absurd).unwrap();
    assert!(matches!(
        mpc.prepare(),
        Err(MpcError::NonFiniteLinearization { .. })
    ));
    let out = mpc.feedback(&x).unwrap();
    assert!(matches!(
        out.outcome,
        Outcome::Fallback {
            cause: FailureCause::PreparationFailed,
            failed_ticks: 1
        }
    ));
    assert!(out.u.iter().all(|v| (0.0..=1.0).contains(v)));
    let next = mpc.tick(&x).unwrap();
    assert_eq!(next.outcome, Outcome::Solved);
    assert_eq!(mpc.failed_ticks(), 0);
}
