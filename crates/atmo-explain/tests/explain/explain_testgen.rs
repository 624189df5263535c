//! The discrepancy finder on recordings of the independent generator
//! (`atmo-testgen`: its own rigid body, commands held over each sample, no
//! dither, motion-capture noise unlike the plant's), flown by two control
//! laws (a cascaded PID and a discrete LQR, both at the recording rate)
//! with each concealed effect in two forms (docs/testgen.md): the finder's
//! targets on recordings this project's simulator and controller did not
//! make, none of them chosen on one controller or one form alone.
#![allow(clippy::unwrap_used)] // reason: test code

use std::fmt::Write as _;
use std::path::Path;

use atmo_core::{ConfigFile as _, RobotConfig};
use atmo_explain::effects::Effect;
use atmo_explain::parameter::{Axis, Param};
use atmo_explain::recording::Recording;
use atmo_explain::{Explanation, Options, Parameter, explain};
use atmo_testgen::control::ControllerKind;
use atmo_testgen::flight::{FlightPlan, Row, fly, to_csv};
use atmo_testgen::robot::{RigidBody, RobotFile};
use atmo_testgen::sim::{ComOffset, Concealed, GroundEffect, MotorLag, ThrustCurve};
use atmo_testgen::{Form, concealed};

fn robot_path() -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/atmo.toml")
}

/// Every concealed-effect case is flown by both controllers in both forms.
const FLOWN: [(ControllerKind, Form); 4] = [
    (ControllerKind::Pid, Form::First),
    (ControllerKind::Lqr, Form::First),
    (ControllerKind::Pid, Form::Second),
    (ControllerKind::Lqr, Form::Second),
];

/// A generator flight of `duration` s with `fx` concealed.
fn generated(fx: &Concealed, seed: u64, duration: f64, controller: ControllerKind) -> Vec<Row> {
    let body = RigidBody::at_tilt(&RobotFile::load(&robot_path()).unwrap(), 0.0);
    let plan = FlightPlan {
        seed,
        duration,
        controller,
        ..FlightPlan::default()
    };
    fly(&body, fx, &plan)
}

/// `rows` read and analysed with ATMO's file, or the reader's refusal.
fn try_analyse_rows(rows: &[Row], what: String) -> Result<Explanation, atmo_explain::ExplainError> {
    let rec = Recording::from_csv_str(&to_csv(rows), what)?;
    let robot = RobotConfig::load(robot_path()).unwrap();
    explain(&rec, &robot, &Options::default())
}

/// The PID's default 48 s flight analysed, or the reader's refusal.
fn try_analyse(fx: &Concealed, seed: u64) -> Result<Explanation, atmo_explain::ExplainError> {
    let duration = FlightPlan::default().duration;
    let rows = generated(fx, seed, duration, ControllerKind::Pid);
    try_analyse_rows(&rows, format!("testgen seed {seed}, {duration} s"))
}

/// The drag + wind flights last 96 s, as the plant's do
/// (`explain_concealed`): four drag coefficients and a wind. The y area is
/// the least excited of them (the y sweep is slower): over seeds 1-20 of
/// the first form its spread is 9.0 % at 48 s and 6.1 % at 96 s
/// (docs/testgen.md).
const DRAG_AND_WIND_DURATION: f64 = 96.0;

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

fn near(v: f64, truth: f64) -> bool {
    ((v - truth) / truth).abs() <= 0.15
}

/// Parameter `name` within 15 % of `truth`.
fn within(ex: &Explanation, name: Param, truth: f64) -> Result<(), String> {
    let v = ex.parameter(name).unwrap_or(f64::NAN);
    if near(v, truth) {
        Ok(())
    } else {
        Err(format!("{}.{name} = {v}, truth {truth}", name.effect()))
    }
}

/// The concealed effects are the claimed ones and ranked first, nothing
/// else claimed (physics or calibration: an effect the selection proposed
/// and the acceptance refused is a decision, not a claim), and the
/// held-out 0.5 s velocity error at least halved.
fn named(ex: &Explanation, concealed: &[Effect]) -> Result<(), String> {
    let n = concealed.len();
    let top: Vec<Effect> = ex.effects[..n].iter().map(|e| e.name).collect();
    for c in concealed {
        if !top.contains(c) {
            return Err(format!("{c} not in the top {n}"));
        }
        if !ex.effects.iter().any(|e| e.name == *c && e.selected) {
            return Err(format!("{c} not found"));
        }
    }
    let others: Vec<Effect> = ex.effects[n..]
        .iter()
        .filter(|e| e.selected)
        .map(|e| e.name)
        .collect();
    if !others.is_empty() {
        return Err(format!("{others:?} claimed"));
    }
    let (b, a) = (
        ex.multistep_before.velocity_norm(),
        ex.multistep_after.velocity_norm(),
    );
    if ex.multistep_after.starts > 0 && a <= 0.5 * b {
        Ok(())
    } else {
        Err(format!("0.5 s velocity error {b} -> {a}"))
    }
}

/// `check` on the analysis of `effects` (generator names) flown for
/// `duration` s at seed 1 by every controller in every form ([`FLOWN`]);
/// every flight that fails is named in one assertion.
fn on_every_flight(
    effects: &str,
    duration: f64,
    check: impl Fn(&Explanation, &Concealed, &[Row]) -> Result<(), String>,
) {
    let mut failed = Vec::new();
    for (controller, form) in FLOWN {
        let fx = concealed(effects, form).unwrap();
        let rows = generated(&fx, 1, duration, controller);
        let what = format!("testgen {effects}, {controller:?}, {form:?}");
        let outcome = try_analyse_rows(&rows, what.clone())
            .map_err(|e| e.to_string())
            .and_then(|ex| check(&ex, &fx, &rows).map_err(|e| format!("{e}: {}", summary(&ex))));
        if let Err(e) = outcome {
            failed.push(format!("{what}: {e}"));
        }
    }
    assert!(failed.is_empty(), "{failed:#?}");
}

fn lag_time_constant(fx: &Concealed) -> f64 {
    match fx.motor_lag {
        Some(MotorLag::Thrust(tau) | MotorLag::RotorSpeed(tau)) => tau,
        None => f64::NAN,
    }
}

#[test]
fn clean_flights_show_no_mismatch_on_at_least_nine_of_ten_seeds_under_each_controller() {
    for controller in [ControllerKind::Pid, ControllerKind::Lqr] {
        let verdicts: Vec<(u64, String)> = (1..=10)
            .map(|seed| {
                let rows = generated(&Concealed::default(), seed, 48.0, controller);
                let ex = try_analyse_rows(&rows, format!("clean seed {seed}")).unwrap();
                (seed, summary(&ex))
            })
            .collect();
        let clean = verdicts
            .iter()
            .filter(|(_, v)| v.starts_with("verdict: no significant mismatch"))
            .count();
        assert!(
            clean >= 9,
            "{controller:?}: {clean}/10 clean: {verdicts:#?}"
        );
    }
}

#[test]
fn ground_effect() {
    on_every_flight("ground_effect", 48.0, |ex, _, _| {
        named(ex, &[Effect::GroundEffect])
    });
}

#[test]
fn motor_lag() {
    on_every_flight("motor_lag", 48.0, |ex, fx, _| {
        named(ex, &[Effect::MotorLag])?;
        within(ex, Param::TimeConstant, lag_time_constant(fx))
    });
}

/// Drag and wind named; the wind's components that blow, the rotor drag
/// (N per (m/s) per N of thrust is `k_thrust` times that per unit
/// command in the finder's units) and the body drag
/// ([`body_drag_right`]) within 15 %.
fn drag_and_wind_right(ex: &Explanation, fx: &Concealed) -> Result<(), String> {
    named(ex, &[Effect::Drag, Effect::Wind])?;
    for axis in Axis::XY {
        let truth = fx.wind[axis as usize];
        if truth != 0.0 {
            within(ex, Param::SteadyWind(axis), truth)?;
        }
    }
    let (rotor_drag, areas) = fx.drag.unwrap();
    let k_thrust = RobotConfig::load(robot_path()).unwrap().rotor.k_thrust;
    within(ex, Param::RotorDrag, rotor_drag * k_thrust)?;
    // The generator's drag law is the finder's: the speed is separated,
    // and lies between the linear and the quadratic law's at the force
    // and slope identified (`stages::wind_speed`).
    let speed = ex.wind_speed.as_ref().ok_or("no wind speed")?;
    if !speed.separable
        || !(speed.speed_linear_law..=speed.speed_quadratic_law).contains(&speed.speed)
    {
        return Err(format!("wind speed {speed:?}"));
    }
    body_drag_right(ex, &areas)
}

#[test]
fn drag_and_wind() {
    on_every_flight("drag,wind", DRAG_AND_WIND_DURATION, |ex, fx, _| {
        drag_and_wind_right(ex, fx)
    });
}

/// Whether a drag + wind analysis has the body drag `areas` right: the x
/// and y areas within 15 %, and the vertical law: its area within 15 %,
/// or, where the flight cannot tell it from the axial drag (0 in the
/// generator), the combination the report gives instead within 15 % of
/// the truth's (`weight x area`). `Err` says what missed.
fn body_drag_right(ex: &Explanation, areas: &[f64; 3]) -> Result<(), String> {
    let area = |axis: Axis| parameter(ex, Param::BodyCdArea(axis));
    for axis in Axis::XY {
        let a = area(axis).ok_or(format!("no {axis:?} area"))?;
        if !(a.identified && near(a.value, areas[axis as usize])) {
            return Err(format!("{} area {:.4}", axis.suffix(), a.value));
        }
    }
    let z = area(Axis::Z).ok_or("no vertical area")?;
    if z.identified {
        return if near(z.value, areas[2]) {
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
    if near(pair.value, pair.weight * areas[2]) {
        Ok(())
    } else {
        Err(format!(
            "{} against {:.4}",
            pair.describe(),
            pair.weight * areas[2]
        ))
    }
}

/// The body drag areas over ten seeds of the first form, counted as the
/// clean flights are (at least nine of ten). Measured (docs/testgen.md):
/// on 96 s flights 20 of seeds 1-20 (the y area 0.0524-0.0647); on 48 s
/// flights 19 of 20 (seed 1's y area 18 % low).
#[test]
fn drag_and_wind_areas_within_15_percent_on_at_least_nine_of_ten_seeds() {
    let fx = concealed("drag,wind", Form::First).unwrap();
    let areas = fx.drag.unwrap().1;
    let outcomes: Vec<(u64, Result<(), String>)> = (1..=10)
        .map(|seed| {
            let rows = generated(&fx, seed, DRAG_AND_WIND_DURATION, ControllerKind::Pid);
            let ex = try_analyse_rows(&rows, format!("drag, wind seed {seed}")).unwrap();
            (seed, body_drag_right(&ex, &areas))
        })
        .collect();
    let right = outcomes.iter().filter(|(_, r)| r.is_ok()).count();
    assert!(right >= 9, "{right}/10 right: {outcomes:#?}");
}

/// A wind with two real components (2 m/s north, 1.5 m/s west): the
/// per-component test of the wind profile (`stages::wind::MIN_AXIS_GAIN`,
/// set on the real fan flights, where the sideways component was a thrust
/// axis in disguise) must not hold a real component at 0. The second
/// form's wind (1.5, 1.0) m/s is the weaker case (`drag_and_wind`).
#[test]
fn a_wind_with_two_real_components_is_named_in_both() {
    let fx = Concealed {
        wind: [2.0, -1.5, 0.0],
        ..concealed("drag", Form::First).unwrap()
    };
    let rows = generated(&fx, 1, 48.0, ControllerKind::Pid);
    let ex = try_analyse_rows(&rows, "two-component wind".into()).unwrap();
    let outcome = named(&ex, &[Effect::Drag, Effect::Wind])
        .and_then(|()| within(&ex, Param::SteadyWind(Axis::X), 2.0))
        .and_then(|()| within(&ex, Param::SteadyWind(Axis::Y), -1.5));
    assert!(outcome.is_ok(), "{outcome:?}: {}", summary(&ex));
}

#[test]
fn centre_of_mass_offset() {
    on_every_flight("com_offset", 48.0, |ex, fx, _| {
        named(ex, &[Effect::ComOffset])?;
        let Some(ComOffset::MovedCentre(d) | ComOffset::Composite(d)) = fx.com_offset else {
            return Err("no offset concealed".into());
        };
        within(ex, Param::ComOffset(Axis::X), d[0])?;
        within(ex, Param::ComOffset(Axis::Y), d[1])
    });
}

#[test]
fn thrust_scale() {
    on_every_flight("thrust_scale", 48.0, |ex, fx, _| {
        named(ex, &[Effect::ThrustScale])?;
        within(ex, Param::ThrustScaleMinusOne, fx.thrust_scale.unwrap())
    });
}

/// The quadratic share f of the finder's curve `(1 - f) u + f u^2`: the
/// generator's own for its quadratic form; for its power law `u^e` the
/// least-squares share over the commands the flight held (the truth as
/// the finder's family can carry it).
fn quadratic_share(curve: ThrustCurve, rows: &[Row]) -> f64 {
    match curve {
        ThrustCurve::Quadratic(b) => b,
        ThrustCurve::Power(e) => {
            let (mut num, mut den) = (0.0, 0.0);
            for u in rows.iter().flat_map(|r| r.u) {
                let x = u * u - u;
                num += x * (u.powf(e) - u);
                den += x * x;
            }
            num / den
        }
    }
}

#[test]
fn thrust_curve() {
    on_every_flight("thrust_curve", 48.0, |ex, fx, rows| {
        named(ex, &[Effect::ThrustCurve])?;
        let truth = quadratic_share(fx.thrust_curve.unwrap(), rows);
        within(ex, Param::QuadraticShare, truth)
    });
}

#[test]
fn ground_effect_and_motor_lag() {
    on_every_flight("ground_effect,motor_lag", 48.0, |ex, fx, _| {
        named(ex, &[Effect::GroundEffect, Effect::MotorLag])?;
        within(ex, Param::TimeConstant, lag_time_constant(fx))
    });
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
            thrust_curve: Some(ThrustCurve::Quadratic(0.9)),
            ..Concealed::default()
        },
        Concealed {
            com_offset: Some(ComOffset::MovedCentre([0.09, 0.0, 0.0])),
            ..Concealed::default()
        },
        Concealed {
            motor_lag: Some(MotorLag::Thrust(0.4)),
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
            ground_effect: Some(GroundEffect::CheesemanBennett(0.9)),
            ..Concealed::default()
        },
    ];
    let mut analysed = 0;
    for fx in &cases {
        let ex = match try_analyse(fx, 2) {
            Ok(ex) => ex,
            Err(e) => {
                let fastest = generated(fx, 2, FlightPlan::default().duration, ControllerKind::Pid)
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
