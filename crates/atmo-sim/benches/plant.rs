//! Plant steps per second with every effect on.
//!
//! Each iteration runs 1000 steps (1 s of simulated time at dt = 1 ms) from
//! a fresh copy of the plant, so the robot does what the case says instead
//! of drifting for minutes: criterion's throughput line is steps per second,
//! and 1e6 steps/s is 1000x real time.

use std::hint::black_box;

use atmo_core::RobotConfig;
use atmo_core::model::{Input, Model, State, idx};
use atmo_sim::config::{PlantConfig, TerrainConfig};
use atmo_sim::plant::{Command, InitialState, Plant};
use criterion::{BatchSize, Criterion, Throughput, criterion_group, criterion_main};

const STEPS: u64 = 1000;

fn plant(config: &PlantConfig, height: f64, tilt: f64, on_ground: bool) -> Plant {
    let robot = RobotConfig::atmo();
    let mut x = State::zeros();
    if on_ground {
        // Wheels just touching flat ground at z = 0 (drive configuration).
        let body = Model::new(&robot).at_tilt(tilt);
        x[idx::Z] = -(body.rotor_position[0].z + robot.wheels.radius + 1e-4);
    } else {
        x[idx::Z] = -height;
    }
    let trim = Model::new(&robot).at_tilt(tilt).hover_trim();
    let initial = InitialState {
        state: x,
        tilt,
        thrust: if on_ground { Input::zeros() } else { trim },
    };
    let mut p = Plant::new(&robot, config, &TerrainConfig::flat(0.0), &initial, 1).unwrap();
    if on_ground {
        p.advance(&Command::idle(), 1.0).unwrap();
    }
    p
}

fn run(c: &mut Criterion, name: &str, template: &Plant, command: impl Fn(u64) -> Command) {
    let mut group = c.benchmark_group("atmo_sim_plant");
    group.throughput(Throughput::Elements(STEPS));
    group.bench_function(name, |b| {
        b.iter_batched(
            || template.clone(),
            |mut p| {
                for k in 0..STEPS {
                    p.step(black_box(&command(k))).unwrap();
                }
                p
            },
            BatchSize::SmallInput,
        );
    });
    group.finish();
}

fn bench(c: &mut Criterion) {
    let robot = RobotConfig::atmo();
    let full = PlantConfig::full();
    let trim = Model::new(&robot).at_tilt(0.0).hover_trim();

    // In the air at 1.5 m (ground effect, drag, wind, sensors... all on;
    // B is higher than any contact point reaches, so no contact is evaluated).
    let hover = plant(&full, 1.5, 0.0, false);
    run(c, "hover_1000_steps", &hover, |_| Command::rotors(trim));

    // Morphing near the ground: the tilt moves every step, so the composite
    // body is interpolated on the tilt grid and the ground-effect slice
    // recomputed every step.
    let low = plant(&full, 0.6, 0.3, false);
    let trim_low = Model::new(&robot).at_tilt(0.3).hover_trim();
    run(c, "morphing_1000_steps", &low, |k| {
        let mut cmd = Command::rotors(trim_low);
        cmd.tilt_rate = if k < STEPS / 2 { 0.39 } else { -0.39 };
        cmd
    });

    // Driving on four wheel contacts.
    let ground = plant(&full, 0.0, std::f64::consts::FRAC_PI_2, true);
    run(c, "driving_1000_steps", &ground, |_| {
        let mut cmd = Command::idle();
        cmd.wheel_rates.left = 4.0;
        cmd.wheel_rates.right = 4.0;
        cmd
    });

    // Reference: every effect off (atmo-core's RK4 inside the plant).
    let ideal = plant(&PlantConfig::ideal(), 1.5, 0.0, false);
    run(c, "ideal_1000_steps", &ideal, |_| Command::rotors(trim));
}

criterion_group!(benches, bench);
criterion_main!(benches);
