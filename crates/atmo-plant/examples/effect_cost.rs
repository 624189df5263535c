//! What each plant effect costs while driving: 1000 plant steps (1 s
//! simulated) on four wheel contacts with ground contact alone, with one
//! more effect, and with every effect but one. Best of 30 runs each, in
//! microseconds per 1000 steps (1000 us = 1000x real time). Complements the
//! criterion bench `plant`, whose cases it shares:
//!
//! - `cargo run --release -p atmo-plant --example effect_cost`: the table above;
//! - `... -- cases`: the bench's four cases, best of 30 instead of a median
//!   (on a shared machine the fastest run is the least disturbed one);
//! - `... -- hover|morphing|driving|ideal`: one case alone, for a profiler;
//! - `... -- cases portable` (or a case name and `portable`): the same with
//!   the portable copy of the step code, for an A/B against the AVX2 copy
//!   this CPU picks (`Plant::uses_avx2`).

#[path = "../benches/support/cases.rs"]
mod cases;

use std::hint::black_box;
use std::time::Instant;

use atmo_plant::config::{EffectsConfig, PlantConfig};
use atmo_plant::plant::{Command, Plant};
use cases::{STEPS, cases, drive_command, plant};

/// Best of 30: microseconds for `STEPS` steps from a copy of `p`.
fn best_of_30(p: &Plant, command: &dyn Fn(u64) -> Command) -> f64 {
    (0..30)
        .map(|_| {
            let mut q = p.clone();
            let start = Instant::now();
            for k in 0..STEPS {
                q.step(black_box(&command(k))).expect("finite commands");
            }
            start.elapsed().as_secs_f64() * 1e6
        })
        .fold(f64::INFINITY, f64::min)
}

fn main() {
    let arg = std::env::args().nth(1);
    if let Some(arg) = arg.as_deref() {
        let portable = match std::env::args().nth(2).as_deref() {
            None => false,
            Some("portable") => true,
            Some(other) => {
                eprintln!("unknown second argument `{other}`: expected portable or nothing");
                std::process::exit(2);
            }
        };
        let mut chosen: Vec<_> = cases()
            .into_iter()
            .filter(|c| arg == "cases" || arg == c.name)
            .collect();
        if chosen.is_empty() {
            eprintln!(
                "unknown argument `{arg}`: expected cases, hover, morphing, driving or ideal"
            );
            std::process::exit(2);
        }
        let code = if portable {
            for case in &mut chosen {
                case.plant.use_portable_code();
            }
            "portable"
        } else if chosen[0].plant.uses_avx2() {
            "AVX2"
        } else {
            "portable (no AVX2 on this CPU)"
        };
        println!("| case | us per 1000 steps, best of 30, {code} step code |");
        println!("| --- | --- |");
        for case in &chosen {
            println!(
                "| {} | {:.0} |",
                case.name,
                best_of_30(&case.plant, &case.command)
            );
        }
        return;
    }

    let all = EffectsConfig::all();
    let config = |effects: EffectsConfig| PlantConfig {
        effects,
        ..PlantConfig::ideal()
    };
    let contact_only = EffectsConfig {
        ground_contact: all.ground_contact.clone(),
        ..EffectsConfig::default()
    };
    let drive = |_| drive_command();
    let time_drive = |e: EffectsConfig| {
        best_of_30(
            &plant(&config(e), 0.0, std::f64::consts::FRAC_PI_2, true),
            &drive,
        )
    };
    println!("| case | us per 1000 steps |");
    println!("| --- | --- |");
    for case in cases() {
        if case.name == "hover" || case.name == "ideal" {
            println!(
                "| {}, every effect {} | {:.0} |",
                case.name,
                if case.name == "hover" { "on" } else { "off" },
                best_of_30(&case.plant, &case.command)
            );
        }
    }
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
