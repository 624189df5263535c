//! Analytic Jacobians and RK4 sensitivities against central differences.

use atmo_core::RobotConfig;
use atmo_core::model::{Input, Model, State};

/// Deterministic pseudo-random points (no RNG dependency in core tests).
fn lcg(seed: &mut u64) -> f64 {
    *seed = seed
        .wrapping_mul(6364136223846793005)
        .wrapping_add(1442695040888963407);
    ((*seed >> 11) as f64) / ((1u64 << 53) as f64)
}

fn random_point(seed: &mut u64) -> (State, Input, f64) {
    let mut x = State::zeros();
    for k in 0..12 {
        x[k] = 2.0 * lcg(seed) - 1.0;
    }
    x[3] *= 3.0; // yaw anywhere
    x[4] *= 1.2; // pitch within +-70 deg, away from the Euler singularity
    x[5] *= 1.5;
    for k in 9..12 {
        x[k] *= 3.0;
    }
    let u = Input::new(lcg(seed), lcg(seed), lcg(seed), lcg(seed));
    (x, u, lcg(seed) * std::f64::consts::FRAC_PI_2)
}

#[test]
fn dfdx_and_dfdu_match_central_differences() {
    let model = Model::new(&RobotConfig::atmo());
    let mut seed = 7;
    let h = 1e-6;
    for _ in 0..50 {
        let (x, u, varphi) = random_point(&mut seed);
        let body = model.at_tilt(varphi);
        let lin = body.linearize(&x, &u);
        assert_eq!(lin.xdot, body.dynamics(&x, &u));
        for j in 0..12 {
            let mut e = State::zeros();
            e[j] = h;
            let fd = (body.dynamics(&(x + e), &u) - body.dynamics(&(x - e), &u)) / (2.0 * h);
            for i in 0..12 {
                let err = (fd[i] - lin.dfdx[(i, j)]).abs();
                assert!(
                    err < 1e-6 * fd[i].abs().max(1.0),
                    "df{i}/dx{j}: analytic {} fd {}",
                    lin.dfdx[(i, j)],
                    fd[i]
                );
            }
        }
        for j in 0..4 {
            let mut e = Input::zeros();
            e[j] = h;
            let fd = (body.dynamics(&x, &(u + e)) - body.dynamics(&x, &(u - e))) / (2.0 * h);
            for i in 0..12 {
                let err = (fd[i] - lin.dfdu[(i, j)]).abs();
                assert!(
                    err < 1e-6 * fd[i].abs().max(1.0),
                    "df{i}/du{j}: analytic {} fd {}",
                    lin.dfdu[(i, j)],
                    fd[i]
                );
            }
        }
    }
}

#[test]
fn rk4_sensitivities_match_central_differences() {
    let model = Model::new(&RobotConfig::atmo());
    let mut seed = 11;
    let h = 1e-6;
    let dt = 0.1; // one MPC stage (1.0 s / 10)
    for _ in 0..20 {
        let (x, u, varphi) = random_point(&mut seed);
        let body = model.at_tilt(varphi);
        let s = body.rk4_step_sensitivity(&x, &u, dt);
        assert!((s.next - body.rk4_step(&x, &u, dt)).amax() < 1e-12);
        for j in 0..12 {
            let mut e = State::zeros();
            e[j] = h;
            let fd =
                (body.rk4_step(&(x + e), &u, dt) - body.rk4_step(&(x - e), &u, dt)) / (2.0 * h);
            for i in 0..12 {
                let err = (fd[i] - s.a[(i, j)]).abs();
                assert!(
                    err < 1e-6 * fd[i].abs().max(1.0),
                    "dx+{i}/dx{j}: {} vs fd {}",
                    s.a[(i, j)],
                    fd[i]
                );
            }
        }
        for j in 0..4 {
            let mut e = Input::zeros();
            e[j] = h;
            let fd =
                (body.rk4_step(&x, &(u + e), dt) - body.rk4_step(&x, &(u - e), dt)) / (2.0 * h);
            for i in 0..12 {
                let err = (fd[i] - s.b[(i, j)]).abs();
                assert!(
                    err < 1e-6 * fd[i].abs().max(1.0),
                    "dx+{i}/du{j}: {} vs fd {}",
                    s.b[(i, j)],
                    fd[i]
                );
            }
        }
    }
}

#[test]
fn rk4_is_fourth_order() {
    // Halving the step divides the one-step error by about 2^5 = 32.
    let model = Model::new(&RobotConfig::atmo());
    let mut seed = 3;
    let (x, u, varphi) = random_point(&mut seed);
    let body = model.at_tilt(varphi);
    let reference = {
        let mut y = x;
        for _ in 0..1000 {
            y = body.rk4_step(&y, &u, 0.1 / 1000.0);
        }
        y
    };
    let e1 = (body.rk4_step(&x, &u, 0.1) - reference).norm();
    let half = body.rk4_step(&body.rk4_step(&x, &u, 0.05), &u, 0.05);
    let e2 = (half - reference).norm();
    let ratio = e1 / e2;
    assert!(
        ratio > 12.0,
        "global error ratio {ratio} (two half steps vs one step; 16 for a 4th-order method)"
    );
}

#[test]
fn a_disturbance_wrench_shifts_the_accelerations_and_keeps_the_jacobians() {
    let model = Model::new(&RobotConfig::atmo());
    let mut seed = 5;
    let (x, u, varphi) = random_point(&mut seed);
    let body = model.at_tilt(varphi);
    let wrench = nalgebra::Vector6::new(1.0, -2.0, 3.0, 0.1, -0.2, 0.05);
    let disturbed = body.with_disturbance(wrench);
    // Same as passing the wrench as an extra wrench.
    let want = atmo_core::TiltedBody::state_derivative(&x, &body.accelerations(&x, &u, &wrench));
    assert!((disturbed.dynamics(&x, &u) - want).amax() < 1e-12);
    assert!((disturbed.dynamics(&x, &u) - body.dynamics(&x, &u)).amax() > 1e-3);
    let (a, b) = (body.linearize(&x, &u), disturbed.linearize(&x, &u));
    // df/du is exactly unchanged; df/dx changes only through R a in the
    // velocity rows (the disturbance changes a), which the FD check covers.
    assert_eq!(a.dfdu, b.dfdu);
    let h = 1e-6;
    for j in 0..12 {
        let mut e = State::zeros();
        e[j] = h;
        let fd = (disturbed.dynamics(&(x + e), &u) - disturbed.dynamics(&(x - e), &u)) / (2.0 * h);
        for i in 0..12 {
            assert!(
                (fd[i] - b.dfdx[(i, j)]).abs() < 1e-6 * fd[i].abs().max(1.0),
                "df{i}/dx{j}"
            );
        }
    }
}
