//! The generator's flights: tracked, unsaturated, stable with every
//! concealed effect (a flight that falls over is no test of anything).

use atmo_testgen::control::ControllerKind;
use atmo_testgen::flight::{FlightPlan, fly, reference, to_csv};
use atmo_testgen::robot::{RigidBody, RobotFile};
use atmo_testgen::{Form, concealed};

fn atmo() -> RigidBody {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/atmo.toml");
    RigidBody::at_tilt(&RobotFile::load(&path).expect("config/atmo.toml"), 0.0)
}

#[test]
fn every_case_tracks_the_reference_without_saturating_under_both_controllers() {
    for controller in [ControllerKind::Pid, ControllerKind::Lqr] {
        for form in [Form::First, Form::Second] {
            tracks_without_saturating(controller, form);
        }
    }
}

fn tracks_without_saturating(controller: ControllerKind, form: Form) {
    let body = atmo();
    let plan = FlightPlan {
        duration: 32.0,
        controller,
        ..FlightPlan::default()
    };
    for case in [
        "none",
        "ground_effect",
        "motor_lag",
        "drag,wind",
        "com_offset",
        "thrust_scale",
        "thrust_curve",
        "ground_effect,motor_lag",
    ] {
        let rows = fly(&body, &concealed(case, form).expect("a known case"), &plan);
        let case = format!("{controller:?}, {form:?} {case}");
        let mut sq = 0.0;
        let mut saturated = 0;
        let mut lowest = f64::INFINITY;
        for r in &rows {
            let e = r.p - reference(r.t, plan.low_altitude).p;
            sq += e.norm_squared();
            saturated += r.u.iter().filter(|u| **u <= 0.0 || **u >= 1.0).count();
            lowest = lowest.min(-r.p.z);
        }
        let rms = (sq / rows.len() as f64).sqrt();
        let sat = saturated as f64 / (4 * rows.len()) as f64;
        println!(
            "{case}: RMS {rms:.3} m, saturated {:.3} %, lowest {lowest:.3} m",
            sat * 100.0
        );
        assert!(rms < 0.15, "{case}: position RMS error {rms:.3} m");
        assert!(
            sat < 0.005,
            "{case}: {:.2} % of commands saturated",
            sat * 100.0
        );
        assert!(lowest > 0.08, "{case}: B down to {lowest:.3} m");
    }
}

#[test]
fn csv_has_the_recording_format_header_and_a_row_per_sample() {
    let plan = FlightPlan {
        duration: 1.0,
        ..FlightPlan::default()
    };
    let rows = fly(
        &atmo(),
        &concealed("none", Form::First).expect("none"),
        &plan,
    );
    let csv = to_csv(&rows);
    let mut lines = csv.lines();
    assert_eq!(
        lines.next(),
        Some("t,x,y,z,yaw,pitch,roll,vx,vy,vz,wx,wy,wz,u1,u2,u3,u4,varphi,ground_z")
    );
    assert_eq!(lines.count(), 150);
    assert!(concealed("wind", Form::First).is_err());
    assert!(concealed("sparkles", Form::Second).is_err());
}
