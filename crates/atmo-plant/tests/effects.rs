//! The remaining effects, each alone against its formula: sensors, wind and
//! drag, centre-of-mass offset, mass errors.

mod common;

use atmo_core::config::ArmInertiaConvention;
use atmo_core::model::{Input, Model, State, idx};
use atmo_plant::config::{
    ComOffsetConfig, DragConfig, EffectsConfig, GustConfig, MassErrorConfig, SensorsConfig,
    TerrainConfig, ThrustAxisConfig, WindConfig,
};
use atmo_plant::plant::{Command, InitialState, Plant};
use common::{level_at, plant_with, robot};

fn far_above() -> TerrainConfig {
    TerrainConfig::flat(-1000.0)
}

fn truth_model() -> Model {
    let mut cfg = robot();
    cfg.arm.inertia_convention = ArmInertiaConvention::AboutCom;
    Model::new(&cfg)
}

fn plant(effects: EffectsConfig, x: State, tilt: f64) -> Plant {
    Plant::new(
        &robot(),
        &plant_with(effects),
        &far_above(),
        &InitialState::at(x, tilt),
        42,
    )
    .expect("a valid plant")
}

#[test]
fn motion_capture_has_its_rate_latency_and_noise() {
    let quiet = SensorsConfig {
        position_std: 0.0,
        attitude_std: 0.0,
        velocity_std: 0.0,
        rate_std: 0.0,
        ..SensorsConfig::default()
    };
    let effects = EffectsConfig {
        sensors: Some(quiet),
        ..EffectsConfig::none()
    };
    // Falling: the state changes every step, so a stale sample shows.
    let mut p = plant(effects, level_at(0.0), 0.0);
    let mut truth = vec![p.state()];
    let mut published = 0;
    let mut last_seq = p.estimate().unwrap().sequence;
    for _ in 0..1000 {
        p.step(&Command::idle()).unwrap();
        truth.push(p.state());
        let e = p.estimate().unwrap();
        if e.sequence != last_seq {
            published += 1;
            last_seq = e.sequence;
            // 8 ms old: exactly the truth 8 steps ago.
            assert!((e.time - e.measured_at - 0.008).abs() < 1e-12);
            let k = (e.measured_at / p.dt()).round() as usize;
            assert_eq!(e.state, truth[k]);
            assert!((e.time - p.time()).abs() < 1e-12);
        }
    }
    // 120 Hz over 1 s (the sample at t = 0 was published at construction).
    assert_eq!(published, 120);

    // With noise: the position error has the configured spread.
    let effects = EffectsConfig {
        sensors: Some(SensorsConfig {
            latency: 0.0,
            ..SensorsConfig::default()
        }),
        ..EffectsConfig::none()
    };
    let x = level_at(5.0);
    let mut p = plant(effects, x, 0.0);
    let hover = truth_model().at_tilt(0.0).hover_trim();
    let mut sq = 0.0;
    let mut n = 0.0;
    let mut last_seq = u64::MAX;
    for _ in 0..20_000 {
        p.step(&Command::rotors(hover)).unwrap();
        let e = p.estimate().unwrap();
        if e.sequence != last_seq {
            last_seq = e.sequence;
            let err = e.state[idx::X] - p.state()[idx::X];
            sq += err * err;
            n += 1.0;
        }
    }
    let std = (sq / n).sqrt();
    // 2400 samples: the estimate of a 0.5 mm spread is within +-5 %.
    assert!((std - 0.0005).abs() < 0.05 * 0.0005, "position noise {std}");
}

/// The autopilot's estimate is the motion capture's sample of the same
/// instant with a Gauss-Markov error on its vertical velocity: of the
/// configured spread, correlated over the configured time, and drawn from
/// its own stream (the motion capture's samples do not change with it).
#[test]
fn the_autopilots_estimate_has_its_vertical_velocity_error() {
    let sensors = |std: f64| EffectsConfig {
        sensors: Some(SensorsConfig {
            autopilot_vz_error_std: std,
            autopilot_vz_error_time: 0.5,
            ..SensorsConfig::default()
        }),
        ..EffectsConfig::none()
    };
    let hover = truth_model().at_tilt(0.0).hover_trim();
    let mut with = plant(sensors(0.2), level_at(5.0), 0.0);
    let mut without = plant(sensors(0.0), level_at(5.0), 0.0);
    let mut errors = Vec::new();
    let mut last_seq = u64::MAX;
    for _ in 0..60_000 {
        with.step(&Command::rotors(hover)).unwrap();
        without.step(&Command::rotors(hover)).unwrap();
        let (e, a) = (with.estimate().unwrap(), with.autopilot_estimate().unwrap());
        assert_eq!(e, without.estimate().unwrap());
        assert_eq!(without.autopilot_estimate().unwrap(), e);
        if e.sequence != last_seq {
            last_seq = e.sequence;
            assert_eq!(
                (a.sequence, a.time, a.measured_at),
                (e.sequence, e.time, e.measured_at)
            );
            for i in (0..12).filter(|i| *i != idx::VZ) {
                assert_eq!(a.state[i], e.state[i], "component {i}");
            }
            errors.push(a.state[idx::VZ] - e.state[idx::VZ]);
        }
    }
    // 7200 samples over 60 s, 120 correlation times: the spread within
    // +-20 %, and one sample apart (1/120 s) the correlation exp(-1/60).
    let n = errors.len() as f64;
    let var = errors.iter().map(|x| x * x).sum::<f64>() / n;
    assert!((var.sqrt() - 0.2).abs() < 0.04, "spread {}", var.sqrt());
    let lag1 = errors.windows(2).map(|w| w[0] * w[1]).sum::<f64>() / (n - 1.0) / var;
    assert!(
        (lag1 - (-1.0_f64 / 60.0).exp()).abs() < 0.01,
        "correlation {lag1}"
    );
}

/// A steady 4 m/s wind along x and the default body drag alone (no rotor
/// drag): on a robot at rest, the body drag force is
/// `1/2 rho CdA_x 16` along +x.
fn wind_of_4_mps_and_body_drag() -> (WindConfig, DragConfig) {
    let wind = WindConfig {
        steady: [4.0, 0.0, 0.0],
        turbulence_std: [0.0; 3],
        ..WindConfig::default()
    };
    let drag = DragConfig {
        rotor_drag: 0.0,
        ..DragConfig::default()
    };
    (wind, drag)
}

#[test]
fn steady_wind_drags_the_body_by_the_quadratic_law() {
    let (wind, drag) = wind_of_4_mps_and_body_drag();
    let effects = EffectsConfig {
        wind: Some(wind),
        drag: Some(drag.clone()),
        ..EffectsConfig::none()
    };
    let x = level_at(5.0);
    let p = plant(effects, x, 0.0);
    assert_eq!(p.wind(), nalgebra::Vector3::new(4.0, 0.0, 0.0));
    let u = Input::repeat(0.5);
    let got = p.body_derivative(&Command::rotors(u)).unwrap();
    let body = truth_model().at_tilt(0.0);
    let force = nalgebra::Vector3::new(
        0.5 * drag.air_density * drag.body_cd_area[0] * 16.0,
        0.0,
        0.0,
    );
    // Applied at the centre of mass: about B it carries the moment com x f.
    let torque = (body.first_moment / body.mass).cross(&force);
    assert!(
        torque.norm() > 1e-4,
        "ATMO's CoM is off B: the moment is felt"
    );
    let extra = nalgebra::Vector6::new(force.x, 0.0, 0.0, torque.x, torque.y, torque.z);
    let expected = TiltedBodyExt::with_extra(&body, &x, &u, &extra);
    assert!((got - expected).norm() < 1e-12, "{got} vs {expected}");
    assert!(got[idx::VX] > 0.0, "the wind pushes downwind");
}

#[test]
fn body_drag_acts_at_the_airframe_s_centre_not_at_a_shifted_mass() {
    // A CoM offset moves the mass, not the shape the air flows around: the
    // body drag's moment about B stays `c_nominal x f` (the law the
    // discrepancy finder fits, so a fitted file replays what was fitted).
    let (wind, drag) = wind_of_4_mps_and_body_drag();
    let offset = ComOffsetConfig {
        enabled: true,
        offset: [0.0, 0.0, 0.05],
    };
    let x = level_at(5.0);
    let with = plant(
        EffectsConfig {
            wind: Some(wind),
            drag: Some(drag.clone()),
            com_offset: Some(offset.clone()),
            ..EffectsConfig::none()
        },
        x,
        0.0,
    );
    let without = plant(
        EffectsConfig {
            com_offset: Some(offset),
            ..EffectsConfig::none()
        },
        x,
        0.0,
    );
    let u = Command::rotors(Input::repeat(0.5));
    let got = with.body_derivative(&u).unwrap() - without.body_derivative(&u).unwrap();
    let got = nalgebra::Vector6::from_iterator(
        (idx::VX..idx::VX + 3)
            .chain(idx::WX..idx::WX + 3)
            .map(|i| got[i]),
    );
    let shifted = with.body();
    let nominal = truth_model().at_tilt(0.0);
    let force = nalgebra::Vector3::new(
        0.5 * drag.air_density * drag.body_cd_area[0] * 16.0,
        0.0,
        0.0,
    );
    let wrench_at = |c: nalgebra::Vector3<f64>| {
        let t = c.cross(&force);
        shifted.mass_matrix_inv * nalgebra::Vector6::new(force.x, 0.0, 0.0, t.x, t.y, t.z)
    };
    let at_nominal = wrench_at(nominal.first_moment / nominal.mass);
    let at_shifted = wrench_at(shifted.first_moment / shifted.mass);
    assert!((got - at_nominal).norm() < 1e-9, "{got} vs {at_nominal}");
    assert!(
        (got - at_shifted).norm() > 1e-3,
        "the two points differ: {at_shifted}"
    );
}

#[test]
fn rotor_drag_opposes_the_in_plane_air_velocity() {
    let drag = DragConfig {
        body_cd_area: [0.0; 3],
        ..DragConfig::default()
    };
    let effects = EffectsConfig {
        drag: Some(drag.clone()),
        ..EffectsConfig::none()
    };
    let mut x = level_at(5.0);
    x[idx::VY] = 2.0;
    let p = plant(effects, x, 0.0);
    let u = Input::repeat(0.5);
    let got = p.body_derivative(&Command::rotors(u)).unwrap();
    let body = truth_model().at_tilt(0.0);
    // Level rotors, axes vertical: all of v is in the rotor planes.
    let f = -drag.rotor_drag * 0.5 * 2.0;
    let mut extra = nalgebra::Vector6::new(0.0, 4.0 * f, 0.0, 0.0, 0.0, 0.0);
    let mut torque = nalgebra::Vector3::zeros();
    for r in &body.rotor_position {
        torque += r.cross(&nalgebra::Vector3::new(0.0, f, 0.0));
    }
    extra.fixed_rows_mut::<3>(3).copy_from(&torque);
    let expected = TiltedBodyExt::with_extra(&body, &x, &u, &extra);
    assert!((got - expected).norm() < 1e-12, "{got} vs {expected}");
}

#[test]
fn axial_inflow_takes_thrust_along_the_rotor_axes_only() {
    let drag = DragConfig {
        rotor_drag: 0.0,
        axial_drag: 0.8,
        body_cd_area: [0.0; 3],
        ..DragConfig::default()
    };
    let effects = EffectsConfig {
        drag: Some(drag.clone()),
        ..EffectsConfig::none()
    };
    // Climbing at 1.5 m/s (NED z up is negative) with a 2 m/s sideways
    // velocity: level rotors see the climb as axial inflow, the sideways
    // velocity in their planes (no in-plane drag here).
    let mut x = level_at(5.0);
    x[idx::VZ] = -1.5;
    x[idx::VY] = 2.0;
    let p = plant(effects, x, 0.0);
    let u = Input::repeat(0.5);
    let got = p.body_derivative(&Command::rotors(u)).unwrap();
    let body = truth_model().at_tilt(0.0);
    let mut force = nalgebra::Vector3::zeros();
    let mut torque = nalgebra::Vector3::zeros();
    for (n, r) in body.rotor_axis.iter().zip(&body.rotor_position) {
        let v = nalgebra::Vector3::new(0.0, 2.0, -1.5);
        let f = -n * n.dot(&v) * drag.axial_drag * 0.5;
        force += f;
        torque += r.cross(&f);
    }
    assert!(force.y.abs() < 1e-12, "no in-plane force: {force}");
    // The rotors push up (-z); climbing into their inflow loses thrust: +z.
    assert!(force.z > 0.0, "a climb loses thrust: {force}");
    let extra = nalgebra::Vector6::new(force.x, force.y, force.z, torque.x, torque.y, torque.z);
    let expected = TiltedBodyExt::with_extra(&body, &x, &u, &extra);
    assert!((got - expected).norm() < 1e-12, "{got} vs {expected}");
}

#[test]
fn a_turned_thrust_axis_pushes_sideways_by_the_rotation_times_the_thrust() {
    let tilt = [0.02, -0.03];
    let effects = EffectsConfig {
        thrust_axis: Some(ThrustAxisConfig {
            enabled: true,
            tilt,
        }),
        ..EffectsConfig::none()
    };
    let x = level_at(5.0);
    let p = plant(effects, x, 0.0);
    let u = Input::repeat(0.5);
    let got = p.body_derivative(&Command::rotors(u)).unwrap();
    let body = truth_model().at_tilt(0.0);
    let thrust = body.thrust_force * u;
    let f = nalgebra::Vector3::new(tilt[0], tilt[1], 0.0).cross(&thrust);
    // Level rotors push along -z: about +x the thrust turns towards +y,
    // about +y towards -x.
    assert!(f.y > 0.0 && f.x > 0.0, "{f}");
    let extra = nalgebra::Vector6::new(f.x, f.y, f.z, 0.0, 0.0, 0.0);
    let expected = TiltedBodyExt::with_extra(&body, &x, &u, &extra);
    assert!((got - expected).norm() < 1e-12, "{got} vs {expected}");
}

#[test]
fn gusts_follow_their_one_minus_cosine_profile() {
    let wind = WindConfig {
        turbulence_std: [0.0; 3],
        gusts: vec![GustConfig {
            t: 1.0,
            duration: 1.0,
            velocity: [0.0, 3.0, 0.0],
        }],
        ..WindConfig::default()
    };
    let effects = EffectsConfig {
        wind: Some(wind),
        ..EffectsConfig::none()
    };
    let mut p = plant(effects, level_at(5.0), 0.0);
    p.advance(&Command::idle(), 1.5).unwrap();
    // The wind of the last step is taken at its middle, t = 1.4995 s.
    let shape = 0.5 * (1.0 - (2.0 * std::f64::consts::PI * 0.4995).cos());
    assert!((p.wind().y - 3.0 * shape).abs() < 1e-9, "{}", p.wind().y);
    p.advance(&Command::idle(), 1.0).unwrap();
    assert_eq!(p.wind().y, 0.0);
}

#[test]
fn turbulence_has_its_spread() {
    let wind = WindConfig {
        turbulence_std: [0.5, 0.0, 0.0],
        turbulence_time: 0.05,
        ..WindConfig::default()
    };
    let effects = EffectsConfig {
        wind: Some(wind),
        ..EffectsConfig::none()
    };
    let mut p = plant(effects, level_at(5.0), 0.0);
    let (mut sum, mut sq, mut n) = (0.0, 0.0, 0.0);
    for _ in 0..50_000 {
        p.step(&Command::idle()).unwrap();
        let w = p.wind().x;
        sum += w;
        sq += w * w;
        n += 1.0;
    }
    let mean = sum / n;
    let std = (sq / n - mean * mean).sqrt();
    // 50 s of a 0.05 s process: ~500 independent samples, +-10 % on the spread.
    assert!(
        mean.abs() < 0.1 && (std - 0.5).abs() < 0.05,
        "mean {mean}, std {std}"
    );
}

#[test]
fn a_forward_centre_of_mass_pitches_the_trimmed_robot_nose_down() {
    let effects = EffectsConfig {
        com_offset: Some(ComOffsetConfig {
            enabled: true,
            offset: [0.005, 0.0, 0.0],
        }),
        ..EffectsConfig::none()
    };
    let x = level_at(5.0);
    let p = plant(effects, x, 0.0);
    let body = truth_model().at_tilt(0.0);
    let trim = body.hover_trim();
    let got = p.body_derivative(&Command::rotors(trim)).unwrap();
    // The nominal trim balances the nominal body exactly.
    assert!(body.dynamics(&x, &trim).fixed_rows::<3>(idx::WX).norm() < 1e-9);
    // Shifted 5 mm forward: gravity's torque about B is -m g d about y.
    assert!(got[idx::WY] < -0.1, "pitch acceleration {}", got[idx::WY]);
    assert!(
        got[idx::WX].abs() < 0.1 * got[idx::WY].abs(),
        "roll couples in only through the products of inertia"
    );
    let p_body = p.body();
    assert!((p_body.first_moment.x - (body.first_moment.x + body.mass * 0.005)).abs() < 1e-12);
}

#[test]
fn mass_and_inertia_errors_scale_the_body() {
    let effects = EffectsConfig {
        mass_error: Some(MassErrorConfig {
            enabled: true,
            mass_scale: 1.1,
            inertia_scale: 1.2,
        }),
        ..EffectsConfig::none()
    };
    let p = plant(effects, level_at(5.0), 0.7);
    let nominal = truth_model().at_tilt(0.7);
    let b = p.body();
    assert!((b.mass - 1.1 * nominal.mass).abs() < 1e-12);
    assert!((b.first_moment - nominal.first_moment * 1.1).norm() < 1e-12);
    assert!((b.inertia - nominal.inertia * 1.2).norm() < 1e-12);
    assert!((b.mass_matrix * b.mass_matrix_inv - nalgebra::Matrix6::identity()).norm() < 1e-9);
    // Heavier: the same command lifts less.
    let u = Input::repeat(0.6);
    let got = p.body_derivative(&Command::rotors(u)).unwrap()[idx::VZ];
    assert!(got > nominal.dynamics(&level_at(5.0), &u)[idx::VZ]);
}

/// atmo-core's `x_dot` with an extra body wrench.
struct TiltedBodyExt;

impl TiltedBodyExt {
    fn with_extra(
        body: &atmo_core::TiltedBody,
        x: &State,
        u: &Input,
        extra: &nalgebra::Vector6<f64>,
    ) -> State {
        atmo_core::TiltedBody::state_derivative(x, &body.accelerations(x, u, extra))
    }
}
