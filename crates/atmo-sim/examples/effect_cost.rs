//! What each plant effect costs while driving: 1000 plant steps (1 s
//! simulated) on four wheel contacts with ground contact alone, with one
//! more effect, and with every effect but one. Best of 30 runs each, in
//! microseconds per 1000 steps (1000 us = 1000x real time). Complements the
//! criterion bench `plant` (which times the four whole cases).
//! `cargo run --release -p atmo-sim --example effect_cost`

use std::hint::black_box;
use std::time::Instant;

use atmo_core::RobotConfig;
use atmo_core::model::{Input, Model, State, idx};
use atmo_sim::config::{EffectsConfig, PlantConfig, TerrainConfig};
use atmo_sim::plant::{Command, InitialState, Plant};

const DRIVE_TILT: f64 = std::f64::consts::FRAC_PI_2;

/// A plant parked on its wheels (after 1 s of settling) or at 1.5 m.
fn plant(config: &PlantConfig, on_ground: bool) -> Plant {
    let robot = RobotConfig::atmo();
    let tilt = if on_ground { DRIVE_TILT } else { 0.0 };
    let mut x = State::zeros();
    x[idx::Z] = if on_ground {
        let body = Model::new(&robot).at_tilt(tilt);
        -(body.rotor_position[0].z + robot.wheels.radius + 1e-4)
    } else {
        -1.5
    };
    let initial = InitialState {
        state: x,
        tilt,
        thrust: if on_ground {
            Input::zeros()
        } else {
            Model::new(&robot).at_tilt(tilt).hover_trim()
        },
    };
    let mut p = Plant::new(&robot, config, &TerrainConfig::flat(0.0), &initial, 1)
        .expect("built-in configs are valid");
    if on_ground {
        p.advance(&Command::idle(), 1.0).expect("settles");
    }
    p
}

/// Best of 30: microseconds for 1000 steps from a copy of `p`.
fn micros_per_1000_steps(p: &Plant, cmd: &Command) -> f64 {
    (0..30)
        .map(|_| {
            let mut q = p.clone();
            let start = Instant::now();
            for _ in 0..1000 {
                q.step(black_box(cmd)).expect("finite commands");
            }
            start.elapsed().as_secs_f64() * 1e6
        })
        .fold(f64::INFINITY, f64::min)
}

/// The bench's morphing case, best of 30: at 0.6 m and 0.3 rad, tilting up
/// at (pi/2)/4 rad/s for 0.5 s, then back down, rotors at trim.
fn morphing_micros(full: &PlantConfig) -> f64 {
    let robot = RobotConfig::atmo();
    let mut x = State::zeros();
    x[idx::Z] = -0.6;
    let tilt = 0.3;
    let initial = InitialState {
        state: x,
        tilt,
        thrust: Model::new(&robot).at_tilt(tilt).hover_trim(),
    };
    let low = Plant::new(&robot, full, &TerrainConfig::flat(0.0), &initial, 1).expect("valid");
    let trim_low = Command::rotors(Model::new(&robot).at_tilt(tilt).hover_trim());
    (0..30)
        .map(|_| {
            let mut q = low.clone();
            let start = Instant::now();
            for k in 0..1000 {
                let mut cmd = trim_low;
                cmd.tilt_rate = if k < 500 { 0.39 } else { -0.39 };
                q.step(black_box(&cmd)).expect("finite commands");
            }
            start.elapsed().as_secs_f64() * 1e6
        })
        .fold(f64::INFINITY, f64::min)
}

/// The criterion bench's four cases, best of 30 instead of a median (on a
/// shared machine the fastest run is the least disturbed one).
fn print_bench_cases(all: &EffectsConfig, drive: &Command, hover: &Command) {
    let full = PlantConfig {
        effects: all.clone(),
        ..PlantConfig::ideal()
    };
    let morphing = morphing_micros(&full);
    println!("| case | us per 1000 steps, best of 30 |");
    println!("| --- | --- |");
    println!(
        "| hover | {:.0} |",
        micros_per_1000_steps(&plant(&full, false), hover)
    );
    println!("| morphing | {morphing:.0} |");
    println!(
        "| driving | {:.0} |",
        micros_per_1000_steps(&plant(&full, true), drive)
    );
    let ideal = PlantConfig::ideal();
    println!(
        "| ideal | {:.0} |",
        micros_per_1000_steps(&plant(&ideal, false), hover)
    );
}

fn main() {
    let all = EffectsConfig::all();
    let config = |effects: EffectsConfig| PlantConfig {
        effects,
        ..PlantConfig::ideal()
    };
    let mut drive = Command::idle();
    drive.wheel_rates.left = 4.0;
    drive.wheel_rates.right = 4.0;
    let hover = Command::rotors(Model::new(&RobotConfig::atmo()).at_tilt(0.0).hover_trim());
    let contact_only = EffectsConfig {
        ground_contact: all.ground_contact.clone(),
        ..EffectsConfig::default()
    };
    let time_drive = |e: EffectsConfig| micros_per_1000_steps(&plant(&config(e), true), &drive);
    // One case alone, for a profiler.
    let full = config(all.clone());
    match std::env::args().nth(1).as_deref() {
        Some("hover") => {
            let t = micros_per_1000_steps(&plant(&full, false), &hover);
            println!("| hover | {t:.0} |");
            return;
        }
        Some("morphing") => {
            println!("| morphing | {:.0} |", morphing_micros(&full));
            return;
        }
        Some("driving") => {
            let t = micros_per_1000_steps(&plant(&full, true), &drive);
            println!("| driving | {t:.0} |");
            return;
        }
        _ => {}
    }
    if std::env::args().nth(1).as_deref() == Some("cases") {
        print_bench_cases(&all, &drive, &hover);
        return;
    }

    println!("| case | us per 1000 steps |");
    println!("| --- | --- |");
    let ideal = micros_per_1000_steps(&plant(&config(EffectsConfig::default()), false), &hover);
    println!("| hover, every effect off | {ideal:.0} |");
    let full = micros_per_1000_steps(&plant(&config(all.clone()), false), &hover);
    println!("| hover, every effect on | {full:.0} |");
    println!(
        "| driving, ground contact only | {:.0} |",
        time_drive(contact_only.clone())
    );
    println!(
        "| driving, every effect on | {:.0} |",
        time_drive(all.clone())
    );
    macro_rules! effect {
        ($field:ident) => {{
            let mut with = contact_only.clone();
            with.$field = all.$field.clone();
            let mut without = all.clone();
            without.$field = None;
            println!(
                "| driving, contact + {0} / every effect but {0} | {1:.0} / {2:.0} |",
                stringify!($field),
                time_drive(with),
                time_drive(without)
            );
        }};
    }
    effect!(ground_effect);
    effect!(motor_lag);
    effect!(tilt_mechanism);
    effect!(drag);
    effect!(wind);
    effect!(battery_sag);
    effect!(com_offset);
    effect!(mass_error);
    effect!(sensors);
}
