//! The discrepancy finder on recordings of the independent generator
//! (`atmo-testgen`: its own rigid body, a cascaded PID at the recording
//! rate, commands held over each sample, no dither, motion-capture noise
//! unlike the plant's): the finder's targets on recordings this project's
//! simulator and controller did not make.
#![allow(clippy::unwrap_used)] // reason: test code

use std::fmt::Write as _;
use std::path::Path;

use atmo_core::{ConfigFile as _, RobotConfig};
use atmo_explain::effects::Effect;
use atmo_explain::parameter::{Axis, Param};
use atmo_explain::recording::Recording;
use atmo_explain::{Explanation, Options, Parameter, explain};
use atmo_testgen::flight::{FlightPlan, fly, to_csv};
use atmo_testgen::robot::{RigidBody, RobotFile};
use atmo_testgen::sim::Concealed;

fn robot_path() -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/atmo.toml")
}

/// The CSV of a generator flight of `duration` s with `fx` concealed.
fn generated_csv(fx: &Concealed, seed: u64, duration: f64) -> String {
    let body = RigidBody::at_tilt(&RobotFile::load(&robot_path()).unwrap(), 0.0);
    let plan = FlightPlan {
        seed,
        duration,
        ..FlightPlan::default()
    };
    to_csv(&fly(&body, fx, &plan))
}

/// [`generated_csv`] read and analysed with ATMO's file, or the reader's
/// refusal.
fn try_analyse_for(
    fx: &Concealed,
    seed: u64,
    duration: f64,
) -> Result<Explanation, atmo_explain::ExplainError> {
    let csv = generated_csv(fx, seed, duration);
    let rec = Recording::from_csv_str(&csv, format!("testgen seed {seed}, {duration} s"))?;
    let robot = RobotConfig::load(robot_path()).unwrap();
    explain(&rec, &robot, &Options::default())
}

/// [`try_analyse_for`] on the generator's default 48 s flight.
fn try_analyse(fx: &Concealed, seed: u64) -> Result<Explanation, atmo_explain::ExplainError> {
    try_analyse_for(fx, seed, FlightPlan::default().duration)
}

/// [`try_analyse`], which must not refuse.
fn analyse(fx: &Concealed, seed: u64) -> Explanation {
    try_analyse(fx, seed).unwrap()
}

/// The drag + wind flights last 96 s, as the plant's do
/// (`explain_concealed`): four drag coefficients and a wind. The y area is
/// the least excited of them (the wind blows along x, and the y sweep is
/// slower): over seeds 1-20 its spread is 9.0 % at 48 s and 6.1 % at 96 s
/// (docs/testgen.md).
const DRAG_AND_WIND_DURATION: f64 = 96.0;

/// [`try_analyse_for`] on a drag + wind flight of
/// [`DRAG_AND_WIND_DURATION`], which must not refuse.
fn analyse_drag_and_wind(fx: &Concealed, seed: u64) -> Explanation {
    try_analyse_for(fx, seed, DRAG_AND_WIND_DURATION).unwrap()
}

fn summary(ex: &Explanation) -> String {
    let mut s = format!("verdict: {}\n", ex.verdict);
    for e in ex
        .effects
        .iter()
        .filter(|e| e.selection_frequency > 0.0 || e.selected)
    {
        let p: Vec<String> = e
            .parameters
            .iter()
            .take(5)
            .map(|p| {
                let mark = if p.identified {
                    ""
                } else {
                    " (not identified)"
                };
                format!("{}={:.4}{mark}", p.name, p.value)
            })
            .collect();
        let _ = writeln!(
            s,
            "  {} sel={} conf={:?} freq={:.2} {} [{}]",
            e.name,
            e.selected,
            e.confidence,
            e.selection_frequency,
            p.join(" "),
            e.decided_by
        );
    }
    s
}

fn parameter(ex: &Explanation, name: Param) -> Option<&Parameter> {
    ex.effect(name.effect())?.parameter(name)
}

fn within(ex: &Explanation, name: Param, truth: f64) {
    let v = ex.parameter(name).unwrap_or(f64::NAN);
    assert!(
        ((v - truth) / truth).abs() <= 0.15,
        "{}.{name} = {v}, truth {truth}: {}",
        name.effect(),
        summary(ex)
    );
}

/// The concealed effects are the selected ones, ranked first, nothing
/// else at confidence >= 0.5, and the held-out 0.5 s velocity error at
/// least halved.
fn assert_named(ex: &Explanation, concealed: &[Effect]) {
    let n = concealed.len();
    let top: Vec<Effect> = ex.effects[..n].iter().map(|e| e.name).collect();
    for c in concealed {
        assert!(top.contains(c), "{c} not in the top {n}: {}", summary(ex));
        assert!(
            ex.effects.iter().any(|e| e.name == *c && e.selected),
            "{c} not found: {}",
            summary(ex)
        );
    }
    let others: Vec<Effect> = ex.effects[n..]
        .iter()
        .filter(|e| e.selected || e.selection_frequency >= 0.5)
        .map(|e| e.name)
        .collect();
    assert!(others.is_empty(), "{others:?} claimed: {}", summary(ex));
    let (b, a) = (
        ex.multistep_before.velocity_norm(),
        ex.multistep_after.velocity_norm(),
    );
    assert!(
        ex.multistep_after.starts > 0 && a <= 0.5 * b,
        "0.5 s velocity error {b} -> {a}: {}",
        summary(ex)
    );
}

#[test]
fn clean_flights_show_no_mismatch_on_at_least_nine_of_ten_seeds() {
    let verdicts: Vec<(u64, String)> = (1..=10)
        .map(|seed| (seed, analyse(&Concealed::default(), seed)))
        .map(|(seed, ex)| (seed, summary(&ex)))
        .collect();
    let clean = verdicts
        .iter()
        .filter(|(_, v)| v.starts_with("verdict: no significant mismatch"))
        .count();
    assert!(clean >= 9, "{clean}/10 clean: {verdicts:#?}");
}

#[test]
fn ground_effect() {
    let fx = Concealed {
        ground_effect_radius: Some(0.19),
        ..Concealed::default()
    };
    assert_named(&analyse(&fx, 1), &[Effect::GroundEffect]);
}

#[test]
fn motor_lag() {
    let fx = Concealed {
        motor_lag: Some(0.03),
        ..Concealed::default()
    };
    let ex = analyse(&fx, 1);
    assert_named(&ex, &[Effect::MotorLag]);
    within(&ex, Param::TimeConstant, 0.03);
}

/// The generator's drag + wind (rotor drag 0.03 N per (m/s) per N of
/// thrust, body drag at the centre of mass, 2 m/s wind north).
fn drag_and_wind_fx() -> Concealed {
    Concealed {
        drag: Some((0.03, [0.06, 0.06, 0.10])),
        wind: [2.0, 0.0, 0.0],
        ..Concealed::default()
    }
}

/// Rotor drag 0.03 N per (m/s) per N of thrust is 0.03 x k_thrust per unit
/// command in the finder's units. Seed 1: drag and wind named, every
/// scalar within 15 %: the wind, the rotor drag, the x and y areas and the
/// vertical law ([`body_drag_right`]).
#[test]
fn drag_and_wind() {
    let ex = analyse_drag_and_wind(&drag_and_wind_fx(), 1);
    assert_named(&ex, &[Effect::Drag, Effect::Wind]);
    within(&ex, Param::SteadyWind(Axis::X), 2.0);
    let k_thrust = RobotConfig::load(robot_path()).unwrap().rotor.k_thrust;
    within(&ex, Param::RotorDrag, 0.03 * k_thrust);
    if let Err(missed) = body_drag_right(&ex) {
        panic!("{missed}: {}", summary(&ex));
    }
}

/// Whether a drag + wind analysis has the body drag right: the x and y
/// areas within 15 %, and the vertical law: its area within 15 %, or, where
/// the flight cannot tell it from the axial drag (0 in the generator), the
/// combination the report gives instead within 15 % of the truth's
/// (`weight x 0.10`). `Err` says what missed.
fn body_drag_right(ex: &Explanation) -> Result<(), String> {
    let near = |v: f64, truth: f64| ((v - truth) / truth).abs() <= 0.15;
    let area = |axis: Axis| parameter(ex, Param::BodyCdArea(axis));
    for axis in Axis::XY {
        let a = area(axis).ok_or(format!("no {axis:?} area"))?;
        if !(a.identified && near(a.value, 0.06)) {
            return Err(format!("{} area {:.4}", axis.suffix(), a.value));
        }
    }
    let z = area(Axis::Z).ok_or("no vertical area")?;
    if z.identified {
        return if near(z.value, 0.10) {
            Ok(())
        } else {
            Err(format!("vertical area {:.4}", z.value))
        };
    }
    let drag = ex
        .effects
        .iter()
        .find(|e| e.name == Effect::Drag)
        .ok_or("no drag")?;
    let pair = drag
        .combined
        .iter()
        .find(|c| c.first == Param::AxialDrag && c.second == Param::BodyCdArea(Axis::Z))
        .ok_or(format!(
            "vertical area not identified, no combination: {:?}",
            drag.combined
        ))?;
    if near(pair.value, pair.weight * 0.10) {
        Ok(())
    } else {
        Err(format!(
            "{} against {:.4}",
            pair.describe(),
            pair.weight * 0.10
        ))
    }
}

/// The body drag areas over ten seeds, counted as the clean flights are
/// (at least nine of ten). Measured (docs/testgen.md): on 96 s flights 20
/// of seeds 1-20 (the y area 0.0524-0.0647); on 48 s
/// flights 19 of 20 (seed 1's y area 18 % low).
#[test]
fn drag_and_wind_areas_within_15_percent_on_at_least_nine_of_ten_seeds() {
    let outcomes: Vec<(u64, Result<(), String>)> = (1..=10)
        .map(|seed| {
            let ex = analyse_drag_and_wind(&drag_and_wind_fx(), seed);
            (seed, body_drag_right(&ex))
        })
        .collect();
    let right = outcomes.iter().filter(|(_, r)| r.is_ok()).count();
    assert!(right >= 9, "{right}/10 right: {outcomes:#?}");
}

/// A wind with two real components (2 m/s north, 1.5 m/s west): the
/// per-component test of the wind profile (`stages::wind::MIN_AXIS_GAIN`,
/// set on the real fan flights, where the sideways component was a thrust
/// axis in disguise) must not hold a real component at 0. On this flight a
/// 1 m/s cross component costs 19 % of the residual and is kept; one of
/// 0.5 m/s beside 3 m/s costs 4.6 % and is not identified
/// (docs/explain.md).
#[test]
fn a_wind_with_two_real_components_is_named_in_both() {
    let fx = Concealed {
        drag: Some((0.03, [0.06, 0.06, 0.10])),
        wind: [2.0, -1.5, 0.0],
        ..Concealed::default()
    };
    let ex = analyse(&fx, 1);
    assert_named(&ex, &[Effect::Drag, Effect::Wind]);
    within(&ex, Param::SteadyWind(Axis::X), 2.0);
    within(&ex, Param::SteadyWind(Axis::Y), -1.5);
}

#[test]
fn centre_of_mass_offset() {
    let fx = Concealed {
        com_offset: Some([0.008, -0.005, 0.0]),
        ..Concealed::default()
    };
    let ex = analyse(&fx, 1);
    assert_named(&ex, &[Effect::ComOffset]);
    within(&ex, Param::ComOffset(Axis::X), 0.008);
    within(&ex, Param::ComOffset(Axis::Y), -0.005);
}

#[test]
fn thrust_scale() {
    let fx = Concealed {
        thrust_scale: Some(0.08),
        ..Concealed::default()
    };
    let ex = analyse(&fx, 1);
    assert_named(&ex, &[Effect::ThrustScale]);
    within(&ex, Param::ThrustScaleMinusOne, 0.08);
}

#[test]
fn thrust_curve() {
    let fx = Concealed {
        thrust_curve: Some(0.3),
        ..Concealed::default()
    };
    let ex = analyse(&fx, 1);
    assert_named(&ex, &[Effect::ThrustCurve]);
    within(&ex, Param::QuadraticShare, 0.3);
}

#[test]
fn ground_effect_and_motor_lag() {
    let fx = Concealed {
        ground_effect_radius: Some(0.19),
        motor_lag: Some(0.03),
        ..Concealed::default()
    };
    let ex = analyse(&fx, 1);
    assert_named(&ex, &[Effect::GroundEffect, Effect::MotorLag]);
    within(&ex, Param::TimeConstant, 0.03);
}

/// Recordings built to push a parameter beyond its physical range
/// (docs/explain.md): a thrust 80 % above the file's, a thrust curve with
/// f = 0.9, a centre of mass 9 cm off, a 0.4 s motor lag, a rotor drag of
/// 0.3 N per (m/s) per N of thrust (8.4 per unit command, range 5), body
/// drag areas of 2 m^2 (range 1) in a 2 m/s wind, a 20 m/s wind (range 15),
/// a classical ground effect of a 0.9 m rotor (gains past 3 at the low
/// pass). None of these is printed as a finding: no selected effect
/// carries a parameter beyond its range by more than its deviation, nor
/// one outside it that is marked identified. A value held at a bound is
/// not identified; what is fitted beside it is not judged here (the 2 m^2
/// areas, held at 1, leave a 2.9 m/s wind where the truth has 2:
/// docs/explain.md, "Acceptance").
/// The generator has no drag and its controller cannot hold every such
/// robot: a flight that runs away past 100 m/s (the 9 cm offset) is refused
/// by the reader's plausible ranges (docs/recording_format.md), naming the
/// velocity column, which is also no finding; the test checks from the
/// generated rows that the flight really ran away.
#[test]
fn no_parameter_outside_its_physical_range_is_a_finding() {
    let cases = [
        Concealed {
            thrust_scale: Some(0.8),
            ..Concealed::default()
        },
        Concealed {
            thrust_curve: Some(0.9),
            ..Concealed::default()
        },
        Concealed {
            com_offset: Some([0.09, 0.0, 0.0]),
            ..Concealed::default()
        },
        Concealed {
            motor_lag: Some(0.4),
            ..Concealed::default()
        },
        Concealed {
            drag: Some((0.3, [0.0; 3])),
            ..Concealed::default()
        },
        Concealed {
            drag: Some((0.0, [2.0, 2.0, 2.0])),
            wind: [2.0, 0.0, 0.0],
            ..Concealed::default()
        },
        Concealed {
            drag: Some((0.005, [0.06, 0.06, 0.10])),
            wind: [20.0, 0.0, 0.0],
            ..Concealed::default()
        },
        Concealed {
            ground_effect_radius: Some(0.9),
            ..Concealed::default()
        },
    ];
    let mut analysed = 0;
    for fx in &cases {
        let ex = match try_analyse(fx, 2) {
            Ok(ex) => ex,
            Err(e) => {
                let body = RigidBody::at_tilt(&RobotFile::load(&robot_path()).unwrap(), 0.0);
                let plan = FlightPlan {
                    seed: 2,
                    ..FlightPlan::default()
                };
                let fastest = fly(&body, fx, &plan)
                    .iter()
                    .map(|r| r.v.amax())
                    .fold(0.0, f64::max);
                let e = e.to_string();
                assert!(
                    fastest > 100.0 && e.contains("column v") && e.contains("plausible range"),
                    "{fx:?}: refused ({e}) but its fastest velocity is {fastest} m/s"
                );
                eprintln!("{fx:?}: refused, the flight ran away ({fastest:.0} m/s): {e}");
                continue;
            }
        };
        analysed += 1;
        eprintln!("{fx:?}: {}", summary(&ex));
        for e in ex.effects.iter().filter(|e| e.selected) {
            for p in &e.parameters {
                {
                    let (lo, hi) = p.name.range();
                    assert!(
                        (lo..=hi).contains(&p.value) || !p.identified,
                        "{fx:?}: {}.{} = {} outside [{lo}, {hi}] printed as found: {}",
                        e.name,
                        p.name,
                        p.value,
                        summary(&ex)
                    );
                    assert!(
                        p.value >= lo - p.std.unwrap_or(0.0)
                            && p.value <= hi + p.std.unwrap_or(0.0),
                        "{fx:?}: {}.{} = {} beyond [{lo}, {hi}] in a found effect: {}",
                        e.name,
                        p.name,
                        p.value,
                        summary(&ex)
                    );
                }
            }
        }
    }
    assert!(
        analysed >= 6,
        "only {analysed} of the flights were analysed"
    );
}
