//! The Neural-Fly importer on real flights (tests/data, 12 s of two flights
//! of O'Connell et al., Science Robotics 7(66), 2022; docs/neural_fly.md):
//! the conventions worked out from the data hold after conversion.

use std::path::{Path, PathBuf};

use atmo_core::model::{idx, rotation};
use atmo_core::{ConfigFile as _, RobotConfig};
use atmo_explain::effects::Effect;
use atmo_explain::parameter::{Axis, Param};
use atmo_explain::recording::Recording;
use atmo_explain::recording::neural_fly::split_row;
use nalgebra::Vector3;

fn data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data")
        .join(name)
}

fn robot() -> RobotConfig {
    RobotConfig::load(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/neural_fly_quadrotor.toml"),
    )
    .expect("config/neural_fly_quadrotor.toml")
}

const FLIGHTS: [&str; 2] = [
    "neural_fly_L1_nowind_12s.csv",
    "neural_fly_L1_100wind_12s.csv",
];

#[test]
fn detected_and_converted_to_ned() {
    for name in FLIGHTS {
        let rec = Recording::load(data(name)).unwrap();
        assert_eq!(rec.samples.len(), 600, "{name}");
        assert_eq!((rec.skipped_nonfinite, rec.skipped_time), (0, 0));
        for col in ["fa", "q", "T_sp", "hover_throttle"] {
            assert!(
                rec.ignored_columns.iter().any(|c| c == col),
                "{name}: {col}"
            );
        }
        // The figure 8 flies 1.4-3 m above their floor: NED z between -3.1 and
        // -1.3; pwm 800-1540 (100 % fan) over the full scale 2000.
        for s in &rec.samples {
            assert!(
                (-3.1..-1.3).contains(&s.x[idx::Z]),
                "{name}: z {}",
                s.x[idx::Z]
            );
            assert!(
                s.u.iter().all(|u| (0.3..0.85).contains(u)),
                "{name}: u {:?}",
                s.u
            );
        }
        assert!((rec.median_dt() - 0.02).abs() < 1e-4);
    }
}

#[test]
fn body_rates_agree_with_the_converted_attitude() {
    // vee(R^T dR/dt) in FRD from the converted Euler angles must match the
    // converted body rates (a wrong flip of either shows as ~200 % error).
    let rec = Recording::load(data(FLIGHTS[0])).unwrap();
    let rot = |k: usize| {
        let x = &rec.samples[k].x;
        rotation(x[idx::YAW], x[idx::PITCH], x[idx::ROLL])
    };
    let (mut err, mut norm) = (0.0, 0.0);
    for k in 1..rec.samples.len() - 1 {
        let h = rec.samples[k + 1].t - rec.samples[k - 1].t;
        let w_hat = rot(k).transpose() * (rot(k + 1) - rot(k - 1)) / h;
        let rebuilt = Vector3::new(w_hat[(2, 1)], w_hat[(0, 2)], w_hat[(1, 0)]);
        let x = &rec.samples[k].x;
        let w = Vector3::new(x[idx::WX], x[idx::WY], x[idx::WZ]);
        err += (rebuilt - w).norm_squared();
        norm += w.norm_squared();
    }
    let rel = (err / norm).sqrt();
    assert!(rel < 0.3, "relative body-rate mismatch {rel:.3}");
}

#[test]
fn robot_file_hover_thrust_and_mass_match_the_flight() {
    // No wind: the mean thrust the robot file gives for the recorded
    // commands is the weight (the flight stays at one height on average);
    // and the authors' fa obeys fa_xy = m a_xy in the body frame for the
    // file's mass (thrust is along body z).
    let robot = robot();
    let model = atmo_core::model::Model::new(&robot);
    let rec = Recording::load(data(FLIGHTS[0])).unwrap();
    let mean_thrust = rec
        .samples
        .iter()
        .map(|s| s.u.sum() * robot.rotor.k_thrust)
        .sum::<f64>()
        / rec.samples.len() as f64;
    let weight = model.weight();
    assert!(
        (mean_thrust / weight - 1.0).abs() < 0.05,
        "mean thrust {mean_thrust:.2} N against weight {weight:.2} N"
    );
    let text = std::fs::read_to_string(data(FLIGHTS[1])).unwrap();
    let rec = Recording::load(data(FLIGHTS[1])).unwrap();
    let column = split_row(text.lines().next().unwrap())
        .iter()
        .position(|c| *c == "fa")
        .unwrap();
    let fa: Vec<Vector3<f64>> = text
        .lines()
        .skip(1)
        .map(|l| {
            let v: Vec<f64> = serde_json::from_str(split_row(l)[column]).unwrap();
            // z-up world to NED.
            Vector3::new(v[0], -v[1], -v[2])
        })
        .collect();
    let (mut sxy, mut sxx) = (0.0, 0.0);
    for k in 1..rec.samples.len() - 1 {
        let (a, b) = (&rec.samples[k - 1], &rec.samples[k + 1]);
        let dv = Vector3::new(
            b.x[idx::VX] - a.x[idx::VX],
            b.x[idx::VY] - a.x[idx::VY],
            b.x[idx::VZ] - a.x[idx::VZ],
        ) / (b.t - a.t);
        let x = &rec.samples[k].x;
        let rt = rotation(x[idx::YAW], x[idx::PITCH], x[idx::ROLL]).transpose();
        let acc_b = rt * (dv - Vector3::new(0.0, 0.0, robot.environment.gravity));
        let fa_b = rt * fa[k];
        for i in 0..2 {
            sxy += acc_b[i] * fa_b[i];
            sxx += acc_b[i] * acc_b[i];
        }
    }
    let mass = sxy / sxx;
    assert!(
        (mass / model.mass() - 1.0).abs() < 0.02,
        "fa_xy / a_xy = {mass:.3} kg against the file's {:.3} kg",
        model.mass()
    );
}

/// The analysis of the committed 12 s of the 100 % fan flight, run once for
/// the tests that read it.
fn fan_flight_explained() -> &'static atmo_explain::Explanation {
    static EX: std::sync::OnceLock<atmo_explain::Explanation> = std::sync::OnceLock::new();
    EX.get_or_init(|| {
        let rec = Recording::load(data(FLIGHTS[1])).expect("the committed fan flight loads");
        atmo_explain::explain(&rec, &robot(), &atmo_explain::Options::default())
            .expect("the fan flight is analysed")
    })
}

/// The selected effect `name` of a report (fails the test if not selected).
fn selected(ex: &atmo_explain::Explanation, name: Effect) -> &atmo_explain::EffectReport {
    ex.effects
        .iter()
        .find(|e| e.name == name && e.selected)
        .unwrap_or_else(|| panic!("{name} not selected: {}", ex.verdict))
}

/// Parameter `name` of an effect's report.
fn parameter(e: &atmo_explain::EffectReport, name: Param) -> &atmo_explain::Parameter {
    e.parameter(name)
        .unwrap_or_else(|| panic!("{} has no {name}", e.name))
}

#[test]
fn the_fan_wind_is_named_along_the_fan_and_no_sideways_wind_is_claimed() {
    // 12 s of the 100 % fan flight (12.1 m/s at the fan, blowing along their
    // x, our NED x). The flight holds one heading, so a sideways wind
    // cannot be told from a thrust axis turned sideways: its component is
    // not identified (`stages::wind::MIN_AXIS_GAIN`), the wind is profiled
    // along x alone.
    let ex = fan_flight_explained();
    let wind = selected(ex, Effect::Wind);
    assert!(
        wind.confidence.is_some_and(|c| c >= 0.5),
        "{:?}",
        wind.confidence
    );
    let param = |a: Axis| parameter(wind, Param::SteadyWind(a));
    let (x, y) = (param(Axis::X), param(Axis::Y));
    assert!(x.identified && (-15.0..-8.0).contains(&x.value), "{x:?}");
    assert!(!y.identified && y.value == 0.0, "{y:?}");
}

#[test]
fn the_fan_winds_speed_is_not_separated_from_the_drag_and_the_force_is_given() {
    // The airspeed along the fan stays far from zero, where a linear and a
    // quadratic drag law with the same force and slope put the wind at
    // F / F' and 2 F / F'; the fitted law leaves a misfit larger than the
    // noise in the disc-plane force (`stages::LAW_MISFIT_FLOORS`), so the
    // speed is not claimed as separated: the report says so and gives the
    // force and slope it identifies. The fan's measured 12.1 m/s lies
    // between the two laws' speeds.
    let ex = fan_flight_explained();
    let speed = ex
        .wind_speed
        .as_ref()
        .expect("a claimed wind has its speed");
    assert!(!speed.separable, "{speed:?}");
    assert!(speed.misfit_floors >= atmo_explain::stages::LAW_MISFIT_FLOORS);
    assert!(
        speed.force_n > 0.0 && speed.slope_n_per_mps > 0.0,
        "{speed:?}"
    );
    assert!(
        (speed.speed_linear_law..=speed.speed_quadratic_law).contains(&12.1),
        "{speed:?}"
    );
    assert!(
        ex.notes
            .iter()
            .any(|n| n.contains("not separated from the drag")),
        "{:?}",
        ex.notes
    );
}

#[test]
fn rotor_drag_and_body_drag_at_one_airspeed_are_one_combined_finding() {
    // In 12 s of the 100 % fan flight the airspeed stays
    // near 14 m/s, where the linear rotor drag and the quadratic body drag
    // along x are nearly the same line: neither is a finding alone, their
    // best-determined combination is, with a deviation far below the
    // separate ones.
    let ex = fan_flight_explained();
    let drag = selected(ex, Effect::Drag);
    let (rotor, area_x) = (
        parameter(drag, Param::RotorDrag),
        parameter(drag, Param::BodyCdArea(Axis::X)),
    );
    assert!(
        !rotor.identified && !area_x.identified,
        "{rotor:?} {area_x:?}"
    );
    let pair = drag
        .combined
        .iter()
        .find(|c| c.first == Param::RotorDrag && c.second == Param::BodyCdArea(Axis::X))
        .unwrap_or_else(|| panic!("no combined finding: {:?}", drag.combined));
    assert!(pair.correlation <= -0.9, "{pair:?}");
    // The combination is determined where its parts are not.
    assert!(pair.std < 0.1 * rotor.std.unwrap(), "{pair:?} {rotor:?}");
    assert!(pair.value > 10.0 * pair.std, "{pair:?}");
    // explain.json carries it.
    let json = atmo_explain::output::json(ex);
    let drag_json = json["effects"]
        .as_array()
        .and_then(|a| a.iter().find(|e| e["name"] == "drag"))
        .unwrap();
    assert!(
        drag_json["combined"]
            .as_array()
            .is_some_and(|c| c.iter().any(|c| c["second"] == "drag.body_cd_area_x")),
        "{drag_json}"
    );
    // Its value is what the fit says: rotor drag plus weight times area.
    let expect = rotor.value + pair.weight * area_x.value;
    assert!(
        (pair.value - expect).abs() < 1e-9 * expect.abs().max(1.0),
        "{pair:?}"
    );
}

#[test]
fn the_model_fitted_on_the_flight_s_start_predicts_its_end() {
    // Held-out data: the whole analysis on the first 12 s of the
    // 100 % fan flight, its model scored on 12 s from 36 s on, which it
    // never saw (the linear acceleration's residual, which carries the
    // fan's force; the authors' `fa` cut on the whole flights is in
    // docs/explain.md).
    use atmo_explain::effects::Effect;
    use atmo_explain::stages::{
        BaseRegressors, Residuals, accept_effects, fit_effects, profile_motor_lag, select_effects,
    };
    let robot = robot();
    // As `explain` reads a recording: the velocity's slow band from the
    // positions.
    let load = |name: &str| {
        atmo_explain::velocity::from_positions(&Recording::load(data(name)).unwrap())
            .0
            .into_owned()
    };
    let start = load(FLIGHTS[1]);
    let res = Residuals::new(&start, &robot).unwrap();
    let base = BaseRegressors::new(&res, &start);
    let lag = profile_motor_lag(&res, &base);
    drop(base);
    let fit = fit_effects(&res, &start, select_effects(&res, &start, lag.tau));
    let starts = atmo_explain::Options::default().max_replay_starts;
    let (fit, _) = accept_effects(&start, &robot, &res, fit, starts).unwrap();
    assert!(fit.chosen.contains(&Effect::Wind), "{:?}", fit.chosen);

    let end = load("neural_fly_L1_100wind_36s_12s.csv");
    let unseen = Residuals::new(&end, &robot).unwrap();
    let after = fit.residual_on_unseen(&unseen, &end);
    let mean_square = |r: &[f64]| {
        let rows = &unseen.fit_rows;
        let sum: f64 = rows
            .iter()
            .flat_map(|&k| (0..3).map(move |c| r[6 * k + c].powi(2)))
            .sum();
        sum / (3 * rows.len()) as f64
    };
    let (before, after) = (mean_square(&unseen.prep.resid), mean_square(&after));
    let cut = 1.0 - after / before;
    println!(
        "unseen 12 s: {} rows, effects {:?}, linear residual {before:.3} -> {after:.3} (m/s^2)^2, cut {:.1} %",
        unseen.fit_rows.len(),
        fit.chosen,
        100.0 * cut
    );
    assert!(cut >= 0.8, "cut {:.1} %", 100.0 * cut);
}

/// On a no-wind piece of a real flight: no effect is claimed as
/// physics (not calibration) with confidence >= 0.5, and the model
/// reported predicts the 0.5 s velocity no worse than the robot file.
fn no_physics_claimed_and_prediction_no_worse(name: &str) {
    let rec = Recording::load(data(name)).expect("the committed flight loads");
    let ex = atmo_explain::explain(&rec, &robot(), &atmo_explain::Options::default())
        .expect("the flight is analysed");
    let claimed: Vec<String> = ex
        .effects
        .iter()
        .filter(|e| {
            e.selected
                && !e.calibration
                && e.confidence.is_some_and(|c| c >= 0.5)
                && e.decided_by.starts_with("found")
        })
        .map(|e| format!("{} ({:?}): {}", e.name, e.confidence, e.decided_by))
        .collect();
    assert!(claimed.is_empty(), "physics claimed: {claimed:?}");
    // Physics left as one finding with a calibration carries the share of
    // its gain that calibration recovers: the number that decided it.
    for e in &ex.effects {
        if let Some(atmo_explain::stages::Decision::OneFindingWith { recovery, .. }) = &e.decision {
            assert!(
                *recovery >= atmo_explain::stages::SWAP_RECOVERY
                    && e.decided_by.contains(&format!("{recovery:.2}x")),
                "{}: {recovery} {}",
                e.name,
                e.decided_by
            );
        }
    }
    let (before, after) = (
        ex.multistep_before.velocity_norm(),
        ex.multistep_after.velocity_norm(),
    );
    assert!(
        after <= before,
        "0.5 s velocity error {before:.3} -> {after:.3} m/s"
    );
}

#[test]
fn a_no_wind_flight_at_one_heading_claims_no_wind() {
    // 18 s of the no-wind flight. It holds one heading, so a steady wind
    // pushes as a centre of mass off the file does: before the acceptance
    // preferred the calibration, the finder named a wind of 1.0 m/s here
    // at confidence 1.00 (2.4 m/s once the rounds were repeated).
    no_physics_claimed_and_prediction_no_worse("neural_fly_L1_nowind_18s_18s.csv");
}

#[test]
fn every_effect_kept_improves_the_prediction_of_the_model_it_is_kept_in() {
    // The flight's last 11 s: the selection chose a thrust axis with
    // effects the acceptance then rejected. Judged only beside them, the
    // axis was kept, and the model reported predicted the 0.5 s velocity
    // worse than the robot file alone (0.717 -> 0.804 m/s). Judged again
    // in the model left, it goes too.
    no_physics_claimed_and_prediction_no_worse("neural_fly_L1_nowind_39s_11s.csv");
}
