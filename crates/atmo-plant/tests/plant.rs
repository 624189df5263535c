//! The plant against atmo-core and against closed-form physics.

mod common;

use atmo_core::config::ArmInertiaConvention;
use atmo_core::ground_effect::table::GroundEffectConfig;
use atmo_core::model::{Input, Model, State, idx};
use atmo_plant::config::{
    BatterySagConfig, EffectsConfig, GroundContactConfig, MotorLagConfig, PlantConfig,
    TerrainConfig, TiltMechanismConfig,
};
use atmo_plant::plant::{Command, InitialState, Plant};
use common::{level_at, plant_with, robot};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn far_above() -> TerrainConfig {
    TerrainConfig::flat(-1000.0)
}

/// atmo-core's model of the plant's truth (physical arm inertia).
fn truth_model() -> Model {
    let mut cfg = robot();
    cfg.arm.inertia_convention = ArmInertiaConvention::AboutCom;
    Model::new(&cfg)
}

#[test]
fn free_fall_follows_gravity_exactly() {
    // Every effect that does not touch a falling, unpowered body is on too.
    let effects = EffectsConfig {
        motor_lag: Some(MotorLagConfig::default()),
        tilt_mechanism: Some(TiltMechanismConfig::default()),
        ground_contact: Some(GroundContactConfig::default()),
        ..EffectsConfig::none()
    };
    let x0 = level_at(100.0);
    let mut plant = Plant::new(
        &robot(),
        &plant_with(effects),
        &TerrainConfig::flat(0.0),
        &InitialState::at(x0, 0.3),
        1,
    )
    .unwrap();
    plant.advance(&Command::idle(), 2.0).unwrap();
    let x = plant.state();
    let (g, t) = (9.81, 2.0);
    // RK4 integrates a constant acceleration exactly (to rounding).
    assert!(
        (x[idx::Z] - (-100.0 + 0.5 * g * t * t)).abs() < 1e-9,
        "z {}",
        x[idx::Z]
    );
    assert!((x[idx::VZ] - g * t).abs() < 1e-9, "vz {}", x[idx::VZ]);
    for i in [
        idx::X,
        idx::Y,
        idx::VX,
        idx::VY,
        idx::YAW,
        idx::PITCH,
        idx::ROLL,
        idx::WX,
        idx::WY,
        idx::WZ,
    ] {
        assert!(x[i].abs() < 1e-12, "state {i} = {}", x[i]);
    }
    assert!(plant.crash().is_none() && !plant.contact_signal());
}

#[test]
fn with_every_effect_off_the_plant_is_atmo_core() {
    let model = truth_model();
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    for case in 0..50 {
        let mut x = State::zeros();
        for i in 0..12 {
            x[i] = rng.random_range(-1.0..1.0);
        }
        x[idx::Z] = -5.0 - rng.random_range(0.0..3.0);
        let tilt = rng.random_range(0.0..1.5);
        let u = Input::from_fn(|_, _| rng.random_range(0.0..1.0));
        let mut plant = Plant::new(
            &robot(),
            &PlantConfig::ideal(),
            &far_above(),
            &InitialState::at(x, tilt),
            case,
        )
        .unwrap();
        let cmd = Command::rotors(u);
        let body = model.at_tilt(tilt);
        // The accelerations, bit for bit.
        assert_eq!(
            plant.body_derivative(&cmd).unwrap(),
            body.dynamics(&x, &u),
            "case {case}"
        );
        // And a step: the plant's RK4 is atmo-core's RK4.
        plant.step(&cmd).unwrap();
        assert_eq!(
            plant.state(),
            body.rk4_step(&x, &u, plant.dt()),
            "case {case}"
        );
    }
}

#[test]
fn motor_lag_step_response_has_the_configured_time_constant() {
    for tau in [0.02, 0.05] {
        let effects = EffectsConfig {
            motor_lag: Some(MotorLagConfig {
                enabled: true,
                time_constant: tau,
                curve: 0.0,
            }),
            ..EffectsConfig::none()
        };
        let mut plant = Plant::new(
            &robot(),
            &plant_with(effects),
            &far_above(),
            &InitialState::at(level_at(0.0), 0.0),
            1,
        )
        .unwrap();
        let cmd = Command::rotors(Input::repeat(0.8));
        // Step until t = tau: the thrust must have covered 1 - 1/e of the step.
        let steps = (tau / plant.dt()).round() as usize;
        for _ in 0..steps {
            plant.step(&cmd).unwrap();
        }
        let reached = plant.thrust()[0] / 0.8;
        assert!(
            (reached - (1.0 - (-1.0_f64).exp())).abs() < 1e-6,
            "tau {tau}: {reached}"
        );
        // And 3 tau: 1 - e^-3.
        for _ in 0..2 * steps {
            plant.step(&cmd).unwrap();
        }
        let reached = plant.thrust()[0] / 0.8;
        assert!(
            (reached - (1.0 - (-3.0_f64).exp())).abs() < 1e-6,
            "tau {tau}: {reached}"
        );
        // The thrust acts: vertical acceleration follows the lagged thrust.
        let model = truth_model();
        let body = model.at_tilt(0.0);
        let expected = body.dynamics(&plant.state(), &plant.thrust());
        let got = plant.body_derivative(&cmd).unwrap();
        assert!((got - expected).norm() < 1e-12);
    }
}

#[test]
fn thrust_curve_bends_the_static_thrust() {
    let effects = EffectsConfig {
        motor_lag: Some(MotorLagConfig {
            enabled: true,
            time_constant: 0.01,
            curve: 0.5,
        }),
        ..EffectsConfig::none()
    };
    let mut plant = Plant::new(
        &robot(),
        &plant_with(effects),
        &far_above(),
        &InitialState::at(level_at(0.0), 0.0),
        1,
    )
    .unwrap();
    plant
        .advance(&Command::rotors(Input::repeat(0.4)), 0.5)
        .unwrap();
    // (1 - f) u + f u^2 = 0.5 * 0.4 + 0.5 * 0.16 = 0.28.
    assert!(
        (plant.thrust()[2] - 0.28).abs() < 1e-9,
        "{}",
        plant.thrust()[2]
    );
}

/// `place_tilt` moves the linkage (and the encoder) without a step: time
/// and the state stay, the range is enforced, a non-finite tilt is ignored.
#[test]
fn placing_the_tilt_moves_only_the_linkage() {
    let cfg = robot();
    let mut plant = Plant::new(
        &cfg,
        &PlantConfig::ideal(),
        &far_above(),
        &InitialState::at(level_at(0.0), 0.0),
        1,
    )
    .unwrap();
    let (time, state) = (plant.time(), plant.state());
    plant.place_tilt(0.5);
    assert_eq!(
        (plant.tilt(), plant.time(), plant.state()),
        (0.5, time, state)
    );
    let linkage = atmo_core::Linkage::from_config(&cfg.linkage, cfg.limits.tilt_max()).unwrap();
    let counts = plant.encoder_counts().unwrap();
    assert!((linkage.tilt_from_counts(counts).unwrap() - 0.5).abs() < 1e-9);
    plant.place_tilt(f64::NAN);
    assert_eq!(plant.tilt(), 0.5);
    plant.place_tilt(9.0);
    assert_eq!(plant.tilt(), cfg.limits.tilt_max());
    plant.place_tilt(-1.0);
    assert_eq!(plant.tilt(), 0.0);
}

#[test]
fn tilt_mechanism_limits_the_rate_holds_and_reports_whole_counts() {
    let effects = EffectsConfig {
        tilt_mechanism: Some(TiltMechanismConfig::default()),
        ..EffectsConfig::none()
    };
    let cfg = robot();
    let mut plant = Plant::new(
        &cfg,
        &plant_with(effects),
        &far_above(),
        &InitialState::at(level_at(0.0), 0.0),
        1,
    )
    .unwrap();
    let mut cmd = Command::idle();
    cmd.tilt_rate = 10.0; // far above the mechanism's speed
    plant.advance(&cmd, 1.0).unwrap();
    let rate = cfg.limits.tilt_rate_max;
    assert!((plant.tilt() - rate).abs() < 1e-12, "tilt {}", plant.tilt());
    let counts = plant.encoder_counts().unwrap();
    assert_eq!(counts, counts.round());
    let linkage = atmo_core::Linkage::from_config(&cfg.linkage, cfg.limits.tilt_max()).unwrap();
    assert!((linkage.tilt_from_counts(counts).unwrap() - plant.tilt()).abs() < 1e-3);
    // Not commanded: the tilt holds, whatever the rotors do.
    let held = plant.tilt();
    plant
        .advance(&Command::rotors(Input::new(1.0, 0.0, 1.0, 0.0)), 0.5)
        .unwrap();
    assert_eq!(plant.tilt(), held);
    // It stops at the end stop (4 s of full rate covers the 90 deg travel).
    cmd.tilt_rate = 1.0;
    plant.advance(&cmd, 4.0).unwrap();
    assert_eq!(plant.tilt(), cfg.limits.tilt_max());
    // Without the effect: the command is integrated unlimited, counts continuous.
    let mut ideal = Plant::new(
        &cfg,
        &PlantConfig::ideal(),
        &far_above(),
        &InitialState::at(level_at(0.0), 0.0),
        1,
    )
    .unwrap();
    cmd.tilt_rate = 1.0;
    ideal.advance(&cmd, 0.5).unwrap();
    assert!((ideal.tilt() - 0.5).abs() < 1e-12);
}

#[test]
fn ground_effect_scales_the_thrust_by_the_documented_surface() {
    // Noise-free table for the check.
    let mut ge = GroundEffectConfig::default();
    for row in &mut ge.std {
        row.fill(0.0);
    }
    let effects = EffectsConfig {
        ground_effect: Some(ge.clone()),
        ..EffectsConfig::none()
    };
    let surface = atmo_core::ground_effect::table::GroundEffect::new(&ge);
    let model = truth_model();
    for tilt_deg in [0.0_f64, 40.0, 50.0, 70.0] {
        let tilt = tilt_deg.to_radians();
        let body = model.at_tilt(tilt);
        // Rotor hubs 0.3 m above the ground (level attitude).
        let hub_z = body.rotor_position[0].z;
        let x = level_at(0.3 + hub_z);
        let plant = Plant::new(
            &robot(),
            &plant_with(effects.clone()),
            &TerrainConfig::flat(0.0),
            &InitialState::at(x, tilt),
            1,
        )
        .unwrap();
        let u = Input::repeat(0.6);
        let g = surface.gain(0.3, tilt).mean;
        let expected = body.dynamics(&x, &(u * (1.0 + g)));
        let got = plant.body_derivative(&Command::rotors(u)).unwrap();
        assert!(
            (got - expected).norm() < 1e-9,
            "tilt {tilt_deg}: {got} vs {expected}"
        );
        assert!(
            g.abs() > 1e-3,
            "gain at {tilt_deg} deg should not vanish at 0.3 m: {g}"
        );
    }
}

#[test]
fn battery_sag_lowers_thrust_as_energy_is_used() {
    let effects = EffectsConfig {
        battery_sag: Some(BatterySagConfig {
            capacity_wh: 1.0, // tiny, so that seconds matter
            ..BatterySagConfig::default()
        }),
        ..EffectsConfig::none()
    };
    let u = Input::repeat(0.5);
    let mut plant = Plant::new(
        &robot(),
        &plant_with(effects),
        &far_above(),
        &InitialState::at(level_at(0.0), 0.0),
        1,
    )
    .unwrap();
    let first = plant.body_derivative(&Command::rotors(u)).unwrap()[idx::VZ];
    plant.advance(&Command::rotors(u), 1.0).unwrap();
    // Power 4 * 560 W * 0.5^1.5 for 1 s.
    let energy = 4.0 * 560.0 * 0.5_f64.powf(1.5);
    assert!(
        (plant.energy_used() - energy).abs() < 1e-6,
        "{}",
        plant.energy_used()
    );
    let now = plant.body_derivative(&Command::rotors(u)).unwrap()[idx::VZ];
    // Less thrust: the plant's acceleration is the model's at the scaled command.
    let scale = 1.0 - 0.15 * energy / 3600.0;
    let body = truth_model().at_tilt(0.0);
    assert!((first - body.dynamics(&level_at(0.0), &u)[idx::VZ]).abs() < 1e-9);
    let expected = body.dynamics(&plant.state(), &(u * scale))[idx::VZ];
    assert!((now - expected).abs() < 1e-9, "{now} vs {expected}");
    let unscaled = body.dynamics(&plant.state(), &u)[idx::VZ];
    assert!(
        now > unscaled + 1e-3,
        "sag must weaken the thrust: {now} vs {unscaled}"
    );
}

#[test]
fn a_moving_tilt_uses_a_body_within_1e_5_of_the_exact_one_and_the_exact_one_at_rest() {
    let effects = EffectsConfig {
        tilt_mechanism: Some(TiltMechanismConfig::default()),
        ..EffectsConfig::none()
    };
    let model = truth_model();
    let mut plant = Plant::new(
        &robot(),
        &plant_with(effects),
        &far_above(),
        &InitialState::at(level_at(0.0), 0.1),
        1,
    )
    .unwrap();
    let mut cmd = Command::idle();
    cmd.tilt_rate = 0.3;
    for _ in 0..2000 {
        plant.step(&cmd).unwrap();
        let b = plant.body();
        let exact = model.at_tilt(b.varphi);
        let rel = |a: f64, e: f64, scale: f64| (a - e).abs() / scale;
        assert!(rel(b.mass, exact.mass, exact.mass) < 1e-12);
        assert!((b.first_moment - exact.first_moment).norm() / exact.first_moment.norm() < 1e-5);
        assert!((b.inertia - exact.inertia).norm() / exact.inertia.norm() < 1e-5);
        assert!(
            (b.mass_matrix_inv - exact.mass_matrix_inv).norm() / exact.mass_matrix_inv.norm()
                < 1e-5
        );
        assert!((b.thrust_torque - exact.thrust_torque).norm() / exact.thrust_torque.norm() < 1e-5);
    }
    // Stopped: the exact body again, so the plant is atmo-core bit for bit.
    plant.step(&Command::idle()).unwrap();
    let tilt = plant.tilt();
    assert_eq!(*plant.body(), model.at_tilt(tilt));
    let u = Input::repeat(0.5);
    assert_eq!(
        plant.body_derivative(&Command::rotors(u)).unwrap(),
        model.at_tilt(tilt).dynamics(&plant.state(), &u)
    );
}

/// A template's plants are `Plant::new`'s, bit for bit, and independent of
/// each other: a plant stepped through a morph (the tilt grid in use) and
/// the ground effect leaves the next plant of the same template unchanged.
#[test]
fn a_template_starts_the_plant_new_builds_every_time() {
    let effects = EffectsConfig {
        ground_effect: Some(GroundEffectConfig::default()),
        motor_lag: Some(MotorLagConfig::default()),
        tilt_mechanism: Some(TiltMechanismConfig::default()),
        ground_contact: Some(GroundContactConfig::default()),
        ..EffectsConfig::all()
    };
    let (robot, config) = (robot(), plant_with(effects));
    let terrain = TerrainConfig::flat(0.0);
    let initial = InitialState::at(level_at(0.4), 0.5);
    let command = Command {
        tilt_rate: 0.6,
        ..Command::rotors(Input::repeat(0.45))
    };
    let flown = |mut plant: Plant| {
        plant.advance(&command, 1.0).unwrap();
        (plant.state(), plant.tilt(), plant.steps())
    };
    let template = atmo_plant::PlantTemplate::new(&robot, &config).unwrap();
    let first = flown(template.start(&terrain, &initial, 7).unwrap());
    let second = flown(template.start(&terrain, &initial, 7).unwrap());
    let built = flown(Plant::new(&robot, &config, &terrain, &initial, 7).unwrap());
    assert!(
        first.1 > 0.8,
        "the tilt moved through the grid: {}",
        first.1
    );
    assert_eq!(first, second);
    assert_eq!(first, built);
    let other_seed = flown(template.start(&terrain, &initial, 8).unwrap());
    assert_ne!(first.0, other_seed.0, "the seed drives the noise");
}
