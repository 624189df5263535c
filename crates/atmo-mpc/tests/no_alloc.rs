//! The tick allocates nothing in our code. A counting global allocator
//! (`atmo_core::alloc_counter`, this test binary only) counts heap
//! allocations made on the test's own thread; the bare Clarabel solve is counted
//! separately so that its share, if any, is reported on its own.
// Test, bench and example code: an unwrap that fails is the failure report.
#![allow(clippy::unwrap_used)]

mod common;

use atmo_core::RobotConfig;
use atmo_core::alloc_counter::count;
use atmo_core::model::{Model, State, idx};
use atmo_mpc::{FeedbackPath, Formulation, Mpc, Outcome, TiltPlan};
use common::{SUBSTEPS, hover_at};

#[global_allocator]
static GLOBAL: atmo_core::alloc_counter::CountingAllocator =
    atmo_core::alloc_counter::CountingAllocator;

const TICKS: usize = 200;
const MEASURED_TICKS: usize = 180;

#[derive(Default, Debug)]
struct Counts {
    parameters_and_prepare: usize,
    feedback: usize,
    bare_solve: usize,
    /// Feedback phases by path.
    homotopy_ticks: usize,
    clarabel_ticks: usize,
    fallback: usize,
}

/// How the feedback is asked to run.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Feedback {
    /// The shipped settings (homotopy in the condensed formulation).
    Shipped,
    /// No working-set change allowed and the estimate jolted by +-2 rad/s in
    /// roll and pitch rate each tick: the
    /// homotopy falls back to Clarabel whenever the active set moves.
    ForcedFallback,
    /// The shipped settings with the tilt planned by the MPC (13/5 QP,
    /// landing objective), from 50 deg, the planned rate integrated.
    TiltPlanned,
}

fn measure(formulation: Formulation, feedback: Feedback) -> Counts {
    let mut settings = common::settings(formulation);
    if feedback == Feedback::ForcedFallback {
        settings.feedback.max_active_set_changes = 0;
    }
    let mut mpc = Mpc::new(Model::new(&RobotConfig::atmo()), settings).unwrap();
    let tick_period = mpc.settings().horizon.tick_period;
    let h = tick_period / SUBSTEPS as f64;
    let reference = hover_at(0.0, 0.0, 1.5);
    let mut x = hover_at(0.4, -0.3, 1.0);
    x[idx::ROLL] = 0.3;
    x[idx::VX] = 0.8;
    mpc.set_reference_constant(&reference).unwrap();
    mpc.reset(&x).unwrap();
    let mut counts = Counts::default();
    let warm_up = TICKS - MEASURED_TICKS;
    let rate = std::f64::consts::FRAC_PI_2 / 4.0;
    let robot = RobotConfig::atmo();
    let plan = TiltPlan {
        tilt_min: 0.0,
        tilt_max: robot.limits.tilt_transition_max(),
        rate_min: -rate,
        rate_max: rate,
        wheel_radius: robot.wheels.radius,
        thrust_max: None,
    };
    let mut planned_tilt = 50f64.to_radians();
    if feedback == Feedback::TiltPlanned {
        mpc.set_tilt_ramp(planned_tilt, 0.0, 0.0, plan.tilt_max)
            .unwrap();
        mpc.set_ground_height(0.0).unwrap();
    }
    for tick in 0..TICKS {
        let varphi = if feedback == Feedback::TiltPlanned {
            planned_tilt
        } else {
            (rate * tick_period * tick as f64).min(50f64.to_radians())
        };
        let warm = tick < warm_up;
        let (prep, n_prep) = count(|| {
            mpc.set_reference_constant(&reference).unwrap();
            mpc.set_alpha(varphi.cos()).unwrap();
            if feedback == Feedback::TiltPlanned {
                // The second half with the committed tilt-up's raised rotor
                // bound on even ticks.
                let bound = (tick >= TICKS / 2 && tick % 2 == 0).then_some(1.0);
                mpc.set_tilt_plan(&TiltPlan {
                    thrust_max: bound,
                    ..plan
                })
                .unwrap();
                mpc.set_measured_tilt(varphi).unwrap();
            } else {
                mpc.set_tilt_ramp(varphi, rate, 0.0, 50f64.to_radians())
                    .unwrap();
            }
            mpc.prepare()
        });
        prep.unwrap();
        let mut estimate = x;
        if feedback == Feedback::ForcedFallback {
            let jolt = if tick % 2 == 0 { 2.0 } else { -2.0 };
            estimate[idx::WX] += jolt;
            estimate[idx::WY] -= jolt;
        }
        let (out, n_fb) = count(|| mpc.feedback(&estimate));
        let out = out.unwrap();
        assert!(out.outcome.is_fresh(), "{:?}", out.outcome);
        let (_, n_solve) = count(|| mpc.resolve_loaded_qp());
        if !warm {
            counts.parameters_and_prepare += n_prep;
            counts.feedback += n_fb;
            counts.bare_solve += n_solve;
            match out.path {
                FeedbackPath::Homotopy { .. } => counts.homotopy_ticks += 1,
                FeedbackPath::Clarabel { .. } => counts.clarabel_ticks += 1,
                FeedbackPath::NoSolve => {}
            }
        }
        let body = mpc.model().at_tilt(varphi);
        for _ in 0..SUBSTEPS {
            x = body.rk4_step(&x, &out.u, h);
        }
        if feedback == Feedback::TiltPlanned {
            assert!(mpc.plans_tilt());
            planned_tilt += out.tilt_rate.unwrap() * tick_period;
        }
    }
    // The failure path: a non-finite estimate.
    let mut bad: State = x;
    bad[idx::WX] = f64::NAN;
    for _ in 0..5 {
        // The preparation (with its Clarabel solve) is counted above.
        mpc.prepare().unwrap();
        let (out, n) = count(|| mpc.feedback(&bad).unwrap());
        assert!(matches!(out.outcome, Outcome::Fallback { .. }));
        counts.fallback += n;
    }
    counts
}

#[test]
fn tick_does_not_allocate_in_our_code() {
    for (formulation, feedback) in [
        (Formulation::Condensed, Feedback::Shipped),
        (Formulation::Condensed, Feedback::ForcedFallback),
        (Formulation::Condensed, Feedback::TiltPlanned),
        (Formulation::Sparse, Feedback::Shipped),
    ] {
        let c = measure(formulation, feedback);
        let case = format!("{formulation:?}, {feedback:?}");
        eprintln!(
            "{case}, {MEASURED_TICKS} ticks ({} homotopy, {} Clarabel feedbacks): parameters+prepare \
             {} allocations, feedback {}, bare Clarabel solve {} (same QP again), failure path {}",
            c.homotopy_ticks,
            c.clarabel_ticks,
            c.parameters_and_prepare,
            c.feedback,
            c.bare_solve,
            c.fallback
        );
        // Whatever a phase allocates beyond Clarabel's own per-solve block
        // (one per solve it runs, counted in the bare solve) is ours.
        let (prepare_solves, feedback_solves) = match (formulation, feedback) {
            (Formulation::Sparse, _) => (0, MEASURED_TICKS),
            (Formulation::Condensed, _) => (MEASURED_TICKS, c.clarabel_ticks),
        };
        let per_solve = c.bare_solve.div_ceil(MEASURED_TICKS);
        assert!(
            c.parameters_and_prepare <= per_solve * prepare_solves,
            "{case}: preparation allocates {} in {prepare_solves} Clarabel solves",
            c.parameters_and_prepare
        );
        assert!(
            c.feedback <= per_solve * feedback_solves,
            "{case}: feedback allocates {} in {feedback_solves} Clarabel solves",
            c.feedback
        );
        assert_eq!(c.fallback, 0, "{case}: the failure path allocates");
        match (formulation, feedback) {
            (Formulation::Condensed, Feedback::Shipped | Feedback::TiltPlanned) => {
                assert_eq!(c.clarabel_ticks, 0, "{case}: the homotopy fell back");
                assert_eq!(c.feedback, 0, "{case}: the homotopy feedback allocates");
            }
            (Formulation::Condensed, Feedback::ForcedFallback) => {
                assert!(c.clarabel_ticks > 0, "{case}: no fallback was forced");
            }
            (Formulation::Sparse, _) => assert_eq!(c.homotopy_ticks, 0),
        }
    }
}

/// Clarabel's own allocations inside `solve`, measured: one heap block
/// (about 400 bytes) per solve, from its internal timers
/// (`Timers::start_as_current` re-creates a sub-timer HashMap after the
/// per-solve reset). Not ours to remove; pinned here so a change shows up.
#[test]
fn clarabel_solve_allocates_once_per_solve_in_its_timers() {
    for formulation in [Formulation::Condensed, Formulation::Sparse] {
        let c = measure(formulation, Feedback::Shipped);
        assert!(
            c.bare_solve <= MEASURED_TICKS,
            "{formulation:?}: Clarabel's solve allocated {} times in {MEASURED_TICKS} solves",
            c.bare_solve
        );
    }
}
