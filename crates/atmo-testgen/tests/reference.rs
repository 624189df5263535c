//! The generator's dynamics against atmo-core's ATMO model (the reference
//! only: the generator itself shares no code with the flight stack). With
//! nothing concealed the two must agree far below the recording noise, or
//! the "clean" flights would not be clean for the discrepancy finder.

use atmo_core::model::{Input, Model, State, idx, rotation};
use atmo_core::{ConfigFile as _, RobotConfig};
use atmo_testgen::robot::{RigidBody, RobotFile};
use atmo_testgen::sim::{Concealed, Truth};
use nalgebra::{Rotation3, UnitQuaternion, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

const ROBOTS: [&str; 3] = ["atmo.toml", "quadrotor.toml", "neural_fly_quadrotor.toml"];

fn path(name: &str) -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../config")
        .join(name)
}

struct Case {
    x: State,
    u: [f64; 4],
}

fn random_case(rng: &mut ChaCha8Rng) -> Case {
    let mut x = State::zeros();
    for i in 0..3 {
        x[idx::X + i] = rng.random_range(-2.0..2.0);
        x[idx::VX + i] = rng.random_range(-3.0..3.0);
        x[idx::WX + i] = rng.random_range(-2.0..2.0);
    }
    x[idx::YAW] = rng.random_range(-3.0..3.0);
    x[idx::PITCH] = rng.random_range(-0.6..0.6);
    x[idx::ROLL] = rng.random_range(-0.6..0.6);
    Case {
        x,
        u: [(); 4].map(|()| rng.random_range(0.2..0.8)),
    }
}

fn truth_state(truth: &Truth, c: &Case) -> atmo_testgen::sim::Body {
    let x = &c.x;
    let r = rotation(x[idx::YAW], x[idx::PITCH], x[idx::ROLL]);
    let q = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(r));
    truth.from_base(
        Vector3::new(x[idx::X], x[idx::Y], x[idx::Z]),
        Vector3::new(x[idx::VX], x[idx::VY], x[idx::VZ]),
        q,
        Vector3::new(x[idx::WX], x[idx::WY], x[idx::WZ]),
        &c.u,
    )
}

#[test]
fn accelerations_match_atmo_core_at_every_tilt() {
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    for name in ROBOTS {
        let file = RobotFile::load(&path(name)).unwrap();
        let model = Model::new(&RobotConfig::load(path(name)).unwrap());
        for tilt_deg in [0.0, 20.0, 40.0, 55.0, 70.0] {
            let varphi = f64::to_radians(tilt_deg);
            let truth = Truth::new(RigidBody::at_tilt(&file, varphi), Concealed::default());
            let body = model.at_tilt(varphi);
            for _ in 0..50 {
                let c = random_case(&mut rng);
                let (a_world, w_dot) = truth.base_accelerations(&truth_state(&truth, &c), &c.u);
                let xdot = body.dynamics(&c.x, &Input::from(c.u));
                let a_ref = Vector3::new(xdot[idx::VX], xdot[idx::VY], xdot[idx::VZ]);
                let w_ref = Vector3::new(xdot[idx::WX], xdot[idx::WY], xdot[idx::WZ]);
                let (ea, ew) = ((a_world - a_ref).norm(), (w_dot - w_ref).norm());
                assert!(
                    ea < 1e-9 * (1.0 + a_ref.norm()) && ew < 1e-9 * (1.0 + w_ref.norm()),
                    "{name} at {tilt_deg} deg: |da| = {ea:.3e}, |dw'| = {ew:.3e}"
                );
            }
        }
    }
}

#[test]
fn one_held_sample_matches_atmo_core_far_below_the_noise() {
    // 150 Hz, commands held over the sample: the generator's RK4 sub-steps
    // against atmo-core's RK4 on the same interval. The recording noise is
    // 0.5 mm / 6 mm/s / 8 mrad/s; the difference must be orders below it.
    let dt = 1.0 / 150.0;
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    for name in ROBOTS {
        let file = RobotFile::load(&path(name)).unwrap();
        let model = Model::new(&RobotConfig::load(path(name)).unwrap());
        let truth = Truth::new(RigidBody::at_tilt(&file, 0.0), Concealed::default());
        let body = model.at_tilt(0.0);
        for _ in 0..20 {
            let c = random_case(&mut rng);
            let mut s = truth_state(&truth, &c);
            for _ in 0..8 {
                s = truth.step(&s, &c.u, dt / 8.0);
            }
            let mut x = c.x;
            for _ in 0..8 {
                x = body.rk4_step(&x, &Input::from(c.u), dt / 8.0);
            }
            let (p, v) = truth.base(&s);
            let dp = (p - Vector3::new(x[idx::X], x[idx::Y], x[idx::Z])).norm();
            let dv = (v - Vector3::new(x[idx::VX], x[idx::VY], x[idx::VZ])).norm();
            let dw = (s.w - Vector3::new(x[idx::WX], x[idx::WY], x[idx::WZ])).norm();
            assert!(
                dp < 1e-8 && dv < 1e-6 && dw < 1e-6,
                "{name}: dp {dp:.2e} m, dv {dv:.2e} m/s, dw {dw:.2e} rad/s"
            );
        }
    }
}
