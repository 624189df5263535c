//! The dynamics must reproduce the ATMO authors' model: 60 evaluated points
//! to 1e-9 (relative, absolute floor 1e-9), the separate terms of their
//! equation at 10 points, and the hover trims of the reference README.

use atmo_core::RobotConfig;
use atmo_core::model::{Input, Model, State, rotation};
use nalgebra::{Matrix3, Matrix6, SMatrix, Vector3, Vector6};

fn model() -> Model {
    Model::new(&RobotConfig::atmo())
}

fn close(got: f64, want: f64) -> bool {
    (got - want).abs() <= 1e-9 * want.abs().max(1.0)
}

#[test]
fn reproduces_the_60_reference_points() {
    let text = include_str!("data/atmo_dynamics_reference.csv");
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    assert_eq!(header.len(), 29);
    assert_eq!(header[16], "varphi");
    let model = model();
    let mut rows = 0;
    let mut worst = 0.0_f64;
    for (row, line) in lines.enumerate() {
        let v: Vec<f64> = line.split(',').map(|s| s.parse().unwrap()).collect();
        let x = State::from_column_slice(&v[0..12]);
        let u = Input::from_column_slice(&v[12..16]);
        let xdot = model.dynamics(&x, &u, v[16]);
        for k in 0..12 {
            let want = v[17 + k];
            assert!(
                close(xdot[k], want),
                "row {row} xdot{k}: got {} want {want}",
                xdot[k]
            );
            worst = worst.max((xdot[k] - want).abs() / want.abs().max(1.0));
        }
        rows += 1;
    }
    assert_eq!(rows, 60);
    println!("worst relative error {worst:.2e}");
}

#[test]
fn reproduces_the_terms_of_the_equation_of_motion() {
    let json: serde_json::Value =
        serde_json::from_str(include_str!("data/atmo_model_terms_reference.json")).unwrap();
    let points = json["points"].as_array().unwrap();
    assert_eq!(points.len(), 10);
    let model = model();
    for (n, p) in points.iter().enumerate() {
        let x: Vec<f64> = p["x"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        let varphi = p["varphi"].as_f64().unwrap();
        let body = model.at_tilt(varphi);
        let r = rotation(x[3], x[4], x[5]);
        let w = Vector3::new(x[9], x[10], x[11]);
        // Their generalized velocities are (world velocity, body rates):
        // T = diag(R, I) maps our body-frame generalized forces to theirs.
        let mut t = Matrix6::zeros();
        t.fixed_view_mut::<3, 3>(0, 0).copy_from(&r);
        t.fixed_view_mut::<3, 3>(3, 3)
            .copy_from(&Matrix3::identity());
        let m_world = t * body.mass_matrix * t.transpose();
        let c = body.first_moment;
        let b_body = {
            let f = w.cross(&w.cross(&c));
            let tq = w.cross(&(body.inertia * w));
            Vector6::new(f.x, f.y, f.z, tq.x, tq.y, tq.z)
        };
        let g_world = {
            let g_b = r.transpose() * Vector3::new(0.0, 0.0, body.gravity);
            let tq = -c.cross(&g_b);
            Vector6::new(0.0, 0.0, -body.mass * body.gravity, tq.x, tq.y, tq.z)
        };
        let mut s_body = SMatrix::<f64, 6, 4>::zeros();
        s_body
            .fixed_view_mut::<3, 4>(0, 0)
            .copy_from(&body.thrust_force);
        s_body
            .fixed_view_mut::<3, 4>(3, 0)
            .copy_from(&body.thrust_torque);
        let s_world_t = t * s_body;
        for i in 0..6 {
            for j in 0..6 {
                let want = p["M"][i][j].as_f64().unwrap();
                assert!(
                    close(m_world[(i, j)], want),
                    "point {n} M[{i}][{j}] {} vs {want}",
                    m_world[(i, j)]
                );
            }
            let want_b = p["b"][i].as_f64().unwrap();
            let got_b = (t * b_body)[i];
            assert!(close(got_b, want_b), "point {n} b[{i}] {got_b} vs {want_b}");
            let want_g = p["g"][i].as_f64().unwrap();
            assert!(
                close(g_world[i], want_g),
                "point {n} g[{i}] {} vs {want_g}",
                g_world[i]
            );
            for k in 0..4 {
                let want = p["S"][k][i].as_f64().unwrap();
                assert!(
                    close(s_world_t[(i, k)], want),
                    "point {n} S[{k}][{i}] {} vs {want}",
                    s_world_t[(i, k)]
                );
            }
        }
    }
}

#[test]
fn hover_trims_match_the_reference_table() {
    let model = model();
    let table = [
        (0.0, [0.46948, 0.48677]),
        (20.0, [0.49923, 0.51839]),
        (40.0, [0.61173, 0.63657]),
        (50.0, [0.72838, 0.75929]),
        (60.0, [0.93494, 0.97758]),
    ];
    for (deg, [front, back]) in table {
        let body = model.at_tilt(f64::to_radians(deg));
        let u = body.hover_trim();
        let want = [front, back, front, back];
        for i in 0..4 {
            assert!(
                (u[i] - want[i]).abs() < 6e-6,
                "{deg} deg rotor {}: {} vs {}",
                i + 1,
                u[i],
                want[i]
            );
        }
        // The trim really is an equilibrium.
        let xdot = body.dynamics(&State::zeros(), &u);
        assert!(xdot.amax() < 1e-12, "{deg} deg: residual {}", xdot.amax());
    }
}
