//! A bound on the rotors' mean thrust, written as a box in the rotors'
//! modes (`qp::rotor_modes`), gives the solution of the QP with that bound
//! as a general inequality: the condensed QP (Clarabel, and the homotopy's
//! preparation and feedback) against a reference Clarabel solve of the QP in
//! the rotor commands with the modes' rows written out.
// Test code: an unwrap that fails is the failure report.
#![allow(clippy::unwrap_used)]

mod common;
#[allow(dead_code)]
#[path = "../benches/support/scenarios.rs"]
mod scenarios;

use atmo_core::model::{NU, NX, State};
use atmo_mpc::qp::QpBackend;
use atmo_mpc::qp::rotor_modes::{ROTORS, mode_box, to_modes};
use atmo_mpc::{CutWindow, Formulation, LinearizedHorizon, SolverSettings};
use clarabel::algebra::CscMatrix;
use clarabel::solver::{DefaultSettings, DefaultSolver, IPSolver, SolverStatus, SupportedConeT};

/// A linearization of the 65 deg transition with every rotor allowed up to
/// `rotor_max` and the mean bounded by `mean_max` where the plan's mean is
/// above it (so that the bound is active on some stages and not on others).
fn transition_plan(rotor_max: f64, mean_max: f64) -> LinearizedHorizon {
    let sc = scenarios::scenario("transition_65deg");
    let (mpc, _) = sc.warmed_up(Formulation::Condensed, 30);
    let mut lin = mpc.linearization().clone();
    for k in 0..lin.steps() {
        for i in 0..ROTORS {
            lin.u_hi[k][i] = rotor_max;
        }
        lin.mean_thrust_max[k] = Some(mean_max);
    }
    lin
}

/// The reference: `min 1/2 du' H du + q' du` over the rotor commands, with
/// the rows `T (ubar_k + du_k)` in the modes' box written out per stage.
fn reference(lin: &LinearizedHorizon, e0: &State, settings: &SolverSettings) -> Vec<f64> {
    let mut plain = lin.clone();
    plain.mean_thrust_max.fill(None);
    let mut qp = QpBackend::new(&plain, settings).unwrap();
    qp.load(&plain).unwrap();
    qp.set_initial_deviation(e0).unwrap();
    let snap = qp.snapshot();
    let n = snap.q.len();
    // Rows 0..n: T du <= v_hi - vbar per stage; rows n..2n: -T du <= vbar - v_lo.
    let mut cols: Vec<Vec<(usize, f64)>> = vec![Vec::new(); n];
    let mut b = vec![0.0; 2 * n];
    for k in 0..lin.steps() {
        let (v_lo, v_hi) = mode_box(0.0, lin.u_hi[k][0], lin.mean_thrust_max[k].unwrap());
        let mut v_bar = [0.0; ROTORS];
        v_bar.copy_from_slice(&lin.u_bar[k].as_slice()[..ROTORS]);
        to_modes(&mut v_bar);
        for d in 0..ROTORS {
            let row = NU * k + d;
            // Row d of T: the columns of the stage's four rotors.
            let mut unit = [0.0; ROTORS];
            unit[d] = 1.0;
            to_modes(&mut unit);
            for (c, t) in unit.iter().enumerate() {
                cols[NU * k + c].push((row, *t));
                cols[NU * k + c].push((n + row, -*t));
            }
            b[row] = v_hi[d] - v_bar[d];
            b[n + row] = v_bar[d] - v_lo[d];
        }
    }
    let (mut colptr, mut rowval, mut nzval) = (vec![0], Vec::new(), Vec::new());
    for mut col in cols {
        col.sort_by_key(|(r, _)| *r);
        for (r, v) in col {
            rowval.push(r);
            nzval.push(v);
        }
        colptr.push(rowval.len());
    }
    let a = CscMatrix::new(2 * n, n, colptr, rowval, nzval);
    let clarabel = DefaultSettings {
        verbose: false,
        tol_gap_abs: 1e-11,
        tol_gap_rel: 1e-11,
        tol_feas: 1e-11,
        max_iter: 200,
        ..DefaultSettings::default()
    };
    let mut solver = DefaultSolver::new(
        &snap.p,
        &snap.q,
        &a,
        &b,
        &[SupportedConeT::NonnegativeConeT(2 * n)],
        clarabel,
    )
    .unwrap();
    solver.solve();
    assert_eq!(solver.solution.status, SolverStatus::Solved);
    solver.solution.x.clone()
}

fn rotor_deviations(qp: &QpBackend, lin: &LinearizedHorizon, e0: &State) -> Vec<f64> {
    let mut dx = vec![State::zeros(); lin.steps() + 1];
    let mut du = vec![nalgebra::SVector::<f64, NU>::zeros(); lin.steps()];
    qp.extract(lin, e0, &mut dx, &mut du);
    du.iter().flat_map(|u| u.iter().copied()).collect()
}

#[test]
fn the_mean_bound_in_the_rotors_modes_solves_the_qp_with_the_general_inequality() {
    let shipped = scenarios::settings(Formulation::Condensed).solver;
    let settings = common::reference_settings(&shipped);
    // Below the plan's mean (about 0.6 at 65 deg), so that it binds.
    let lin = transition_plan(0.7, 0.58);
    let mut e0 = State::zeros();
    e0[2] = 0.02;
    e0[5] = 0.03;
    e0[9] = 0.2;
    let want = reference(&lin, &e0, &settings);

    let mut qp = QpBackend::new(&lin, &settings).unwrap();
    qp.load(&lin).unwrap();
    qp.set_initial_deviation(&e0).unwrap();
    let report = qp.solve(&mut CutWindow::default());
    assert_eq!(report.status, SolverStatus::Solved);
    let by_clarabel = rotor_deviations(&qp, &lin, &e0);
    // The homotopy: prepared at another deviation, fed back to e0.
    let condensed = qp.condensed_mut().unwrap();
    let prepared = condensed
        .prepare_solution(&(e0 * 0.5), 200, &mut CutWindow::default())
        .unwrap();
    assert!(prepared.correction.is_ok(), "{prepared:?}");
    condensed.feedback_solution(&e0, 200).unwrap();
    let by_homotopy = rotor_deviations(&qp, &lin, &e0);

    let mut binding = 0;
    for k in 0..lin.steps() {
        let u: Vec<f64> = (0..ROTORS)
            .map(|i| lin.u_bar[k][i] + by_homotopy[NU * k + i])
            .collect();
        let mean = u.iter().sum::<f64>() / 4.0;
        assert!(mean <= 0.58 + 1e-9, "stage {k}: mean {mean}");
        assert!(
            u.iter().all(|&r| (-1e-9..=0.7 + 1e-9).contains(&r)),
            "stage {k}: {u:?}"
        );
        binding += usize::from(mean > 0.58 - 1e-6);
    }
    assert!(
        binding > 0,
        "the mean bound binds nowhere: the test tests nothing"
    );
    for (name, got) in [("clarabel", &by_clarabel), ("homotopy", &by_homotopy)] {
        let worst = got
            .iter()
            .zip(&want)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        assert!(worst < 1e-6, "{name}: {worst:e} from the reference");
    }
    let _ = NX;
}

/// The sparse form has no general rows: it bounds every rotor by the
/// mean's bound, a subset of what the modes allow.
#[test]
fn the_sparse_form_bounds_every_rotor_by_the_mean_s_bound() {
    let settings = common::reference_settings(&scenarios::settings(Formulation::Sparse).solver);
    let lin = transition_plan(0.7, 0.58);
    let mut e0 = State::zeros();
    e0[2] = 0.02;
    let mut qp = QpBackend::new(&lin, &settings).unwrap();
    qp.load(&lin).unwrap();
    qp.set_initial_deviation(&e0).unwrap();
    assert_eq!(
        qp.solve(&mut CutWindow::default()).status,
        SolverStatus::Solved
    );
    let du = rotor_deviations(&qp, &lin, &e0);
    let mut at_bound = 0;
    for k in 0..lin.steps() {
        for i in 0..ROTORS {
            let u = lin.u_bar[k][i] + du[NU * k + i];
            assert!(u <= 0.58 + 1e-6, "stage {k} rotor {i}: {u}");
            at_bound += usize::from(u > 0.58 - 1e-4);
        }
    }
    assert!(
        at_bound > 0,
        "no rotor at the bound: the test tests nothing"
    );
}
