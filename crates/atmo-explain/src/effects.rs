//! The library of candidate effects: physical names, parameters and their
//! regressors (per unit parameter, the body-frame generalized acceleration
//! `M^-1 wrench` they add), built along a recording.
//!
//! | effect | parameters | wrench per unit parameter |
//! | --- | --- | --- |
//! | `ground_effect` | gain table over hub height {0.25, 0.35, 0.45, 0.6} m x tilt {40..70} deg (0 at 0.75 m), classical `R_p^2` below 30 deg | `sum_i phi(h_i, varphi) A e_i t_i` |
//! | `motor_lag` | time constant tau | `A (lag_tau(u) - u)` (profiled) |
//! | `drag` | rotor drag k_r, body Cd A (x, y, z) | `-sum_i t_i P_i v_i` at the hubs, `-rho/2 \|v_k\| v_k` |
//! | `wind` | steady wind (x, y) | `k_r sum_i t_i P_i R^T e_j` |
//! | `thrust_scale` | s | `A t` |
//! | `battery_sag` | thrust loss per energy | `-E(t) A t` |
//! | `com_offset` | d_x, d_y | first-order change of `M` and gravity torque |
//! | `inertia_error` | inertia scale - 1 | `-[0; I w_dot + w x I w]` |
//! | `mass_error` | mass scale - 1 | `[m g_b - m a - ...; c x (g_b - a)]` |
//!
//! `A` = `[A_F; A_T]` the nominal actuation, `t` the thrust (commands, or
//! lagged commands once motor lag is in the model), `P_i` the projection
//! onto rotor i's disc plane.

use atmo_core::model::{Input, idx};
use nalgebra::{Matrix3, Vector3, Vector4, Vector6};

use crate::data::{Prepared, cross_matrix};
use crate::recording::Recording;

/// Hub heights of the fitted ground-effect table (m); the last column is 0.
pub const GE_HEIGHTS: [f64; 5] = [0.25, 0.35, 0.45, 0.6, 0.75];
/// Tilts of the fitted ground-effect table rows (deg).
pub const GE_TILTS_DEG: [f64; 4] = [40.0, 50.0, 60.0, 70.0];
/// Below this tilt (deg) the classical law alone applies; blended up to 40.
pub const GE_CLASSICAL_BELOW_DEG: f64 = 30.0;
/// Air density used for body drag (kg/m^3).
pub const AIR_DENSITY: f64 = 1.225;

/// The candidate effects.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Effect {
    GroundEffect,
    MotorLag,
    Drag,
    Wind,
    ThrustScale,
    BatterySag,
    ComOffset,
    InertiaError,
    MassError,
}

impl Effect {
    pub const ALL: [Effect; 9] = [
        Effect::GroundEffect,
        Effect::MotorLag,
        Effect::Drag,
        Effect::Wind,
        Effect::ThrustScale,
        Effect::BatterySag,
        Effect::ComOffset,
        Effect::InertiaError,
        Effect::MassError,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Effect::GroundEffect => "ground_effect",
            Effect::MotorLag => "motor_lag",
            Effect::Drag => "drag",
            Effect::Wind => "wind",
            Effect::ThrustScale => "thrust_scale",
            Effect::BatterySag => "battery_sag",
            Effect::ComOffset => "com_offset",
            Effect::InertiaError => "inertia_error",
            Effect::MassError => "mass_error",
        }
    }

    /// One line of physics for the report.
    pub fn physics(self) -> &'static str {
        match self {
            Effect::GroundEffect => "thrust gain T/T_inf - 1 over rotor hub height and tilt",
            Effect::MotorLag => "first-order lag from command to thrust",
            Effect::Drag => "linear rotor drag in the disc plane, quadratic body drag",
            Effect::Wind => "steady wind: drag acts on the air-relative velocity",
            Effect::ThrustScale => "thrust coefficient kT off by a constant factor",
            Effect::BatterySag => "thrust scale falling with the energy drawn",
            Effect::ComOffset => "centre of mass shifted in the body x-y plane",
            Effect::InertiaError => "inertia about B off by a factor",
            Effect::MassError => "mass (and first moment) off by a factor",
        }
    }

    /// Number of linear coefficients.
    pub fn width(self) -> usize {
        match self {
            Effect::GroundEffect => 17,
            Effect::Drag => 4,
            Effect::Wind | Effect::ComOffset => 2,
            _ => 1,
        }
    }

    /// Names of the coefficients.
    pub fn coefficient_names(self) -> Vec<String> {
        match self {
            Effect::GroundEffect => {
                let mut v = Vec::new();
                for tilt in GE_TILTS_DEG {
                    for h in &GE_HEIGHTS[..4] {
                        v.push(format!("gain(h={h:.2} m, varphi={tilt:.0} deg)"));
                    }
                }
                v.push("rotor_radius^2 (classical law), m^2".into());
                v
            }
            Effect::MotorLag => vec!["scale of the lag term (1 = lag as fitted)".into()],
            Effect::Drag => vec![
                "rotor_drag, N/(m/s)".into(),
                "body_cd_area_x, m^2".into(),
                "body_cd_area_y, m^2".into(),
                "body_cd_area_z, m^2".into(),
            ],
            Effect::Wind => vec!["rotor_drag * wind_x".into(), "rotor_drag * wind_y".into()],
            Effect::ThrustScale => vec!["thrust scale - 1".into()],
            Effect::BatterySag => vec!["thrust loss per unit energy, 1/s".into()],
            Effect::ComOffset => vec!["offset_x, m".into(), "offset_y, m".into()],
            Effect::InertiaError => vec!["inertia scale - 1".into()],
            Effect::MassError => vec!["mass scale - 1".into()],
        }
    }
}

/// Column layout: effect -> first column.
#[derive(Debug, Clone)]
pub struct Layout {
    pub effects: Vec<Effect>,
    pub offsets: Vec<usize>,
    pub total: usize,
}

impl Layout {
    pub fn all() -> Self {
        let mut offsets = Vec::new();
        let mut total = 0;
        for e in Effect::ALL {
            offsets.push(total);
            total += e.width();
        }
        Self {
            effects: Effect::ALL.to_vec(),
            offsets,
            total,
        }
    }

    pub fn columns(&self, e: Effect) -> std::ops::Range<usize> {
        let i = self.effects.iter().position(|x| *x == e).unwrap_or(0);
        self.offsets[i]..self.offsets[i] + e.width()
    }
}

/// Nonlinear settings the regressors depend on.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Knobs {
    /// Motor lag time constant (s), 0 = none.
    pub tau: f64,
    /// Steady wind (NED x, y, m/s) used in the drag regressors.
    pub wind: [f64; 2],
}

/// Weight of the classical law at tilt `varphi` (rad).
pub fn classical_weight(varphi: f64) -> f64 {
    let lo = GE_CLASSICAL_BELOW_DEG.to_radians();
    let hi = GE_TILTS_DEG[0].to_radians();
    if varphi <= lo {
        1.0
    } else if varphi >= hi {
        0.0
    } else {
        1.0 - (varphi - lo) / (hi - lo)
    }
}

fn bracket(xs: &[f64], x: f64) -> (usize, f64) {
    let n = xs.len();
    if x <= xs[0] {
        return (0, 0.0);
    }
    if x >= xs[n - 1] {
        return (n - 2, 1.0);
    }
    let mut i = 0;
    while xs[i + 1] < x {
        i += 1;
    }
    (i, (x - xs[i]) / (xs[i + 1] - xs[i]))
}

/// Ground-effect basis at hub height `h` and tilt `varphi`: adds
/// `scale * phi_j` into `out[j]` for the 17 coefficients.
pub fn ge_basis(h: f64, varphi: f64, scale: f64, out: &mut [f64]) {
    let wc = classical_weight(varphi);
    if wc > 0.0 {
        // Classical law to first order: (R / 4 z)^2 with z along the slipstream.
        let z = (h / varphi.cos().max(0.05)).max(0.05);
        out[16] += scale * wc / (16.0 * z * z);
    }
    if wc < 1.0 {
        let tilts: Vec<f64> = GE_TILTS_DEG.iter().map(|d| d.to_radians()).collect();
        let (i, wt) = bracket(&tilts, varphi);
        let (j, wh) = bracket(&GE_HEIGHTS, h);
        let s = scale * (1.0 - wc);
        for (ri, rw) in [(i, 1.0 - wt), (i + 1, wt)] {
            for (cj, cw) in [(j, 1.0 - wh), (j + 1, wh)] {
                if cj < 4 {
                    out[ri * 4 + cj] += s * rw * cw;
                }
            }
        }
    }
}

/// The ground-effect gain of coefficients `theta` (17) at (h, varphi).
pub fn ge_gain(theta: &[f64], h: f64, varphi: f64) -> f64 {
    let mut phi = [0.0; 17];
    ge_basis(h, varphi, 1.0, &mut phi);
    phi.iter().zip(theta).map(|(a, b)| a * b).sum()
}

/// Regressor columns, each `6 n` values (body-frame generalized
/// accelerations per unit coefficient, filtered like the measurement).
#[derive(Debug, Clone)]
pub struct Columns {
    pub layout: Layout,
    pub data: Vec<Vec<f64>>,
    /// Residual of the nominal model (measured - nominal).
    pub resid: Vec<f64>,
}

/// The body-frame "air" velocity direction derivative etc. per row.
fn push6(buf: &mut [f64], k: usize, v: &Vector6<f64>) {
    for c in 0..6 {
        buf[6 * k + c] += v[c];
    }
}

fn wrench(f: &Vector3<f64>, t: &Vector3<f64>) -> Vector6<f64> {
    Vector6::new(f.x, f.y, f.z, t.x, t.y, t.z)
}

/// Builds every candidate's columns for the knobs.
///
/// `accel` (6 per row, filtered body-frame accelerations) is what the
/// mass-property columns multiply their change of the mass matrix with:
/// the nominal model's first, then the fitted model's (never the measured
/// one, whose noise these columns would then fit).
pub fn build_columns(prep: &Prepared, rec: &Recording, knobs: &Knobs, accel: &[f64]) -> Columns {
    let layout = Layout::all();
    let n = prep.n;
    let samples = &rec.samples;
    let u: Vec<Input> = samples.iter().map(|s| s.u).collect();
    let thrust = crate::data::lagged_commands(&prep.t, &u, knobs.tau);
    // Smoothed part (through S) and direct part (already filtered).
    let mut raw: Vec<Vec<f64>> = vec![vec![0.0; 6 * n]; layout.total];
    // Direct parts of the 4 mass-property columns (mass, inertia, com x, com y).
    let mut direct: Vec<Vec<f64>> = vec![vec![0.0; 6 * n]; 4];
    let mut lag_raw = vec![0.0; 6 * n];
    let mut energy = 0.0;
    let c_ge = layout.columns(Effect::GroundEffect).start;
    let c_lag = layout.columns(Effect::MotorLag).start;
    let c_drag = layout.columns(Effect::Drag).start;
    let c_wind = layout.columns(Effect::Wind).start;
    let c_ts = layout.columns(Effect::ThrustScale).start;
    let c_bat = layout.columns(Effect::BatterySag).start;
    let c_com = layout.columns(Effect::ComOffset).start;
    let c_in = layout.columns(Effect::InertiaError).start;
    let c_m = layout.columns(Effect::MassError).start;
    let wind_w = Vector3::new(knobs.wind[0], knobs.wind[1], 0.0);
    let mut ge = [0.0; 17];
    for k in 0..n {
        let s = &samples[k];
        let t = &thrust[k];
        if k > 0 {
            let dt = prep.t[k] - prep.t[k - 1];
            energy += dt
                * thrust[k - 1]
                    .iter()
                    .map(|v| v.max(0.0).powf(1.5))
                    .sum::<f64>();
        }
        let body = prep.table.at(s.varphi);
        let minv = &body.mass_matrix_inv;
        let b = &prep.act[k];
        let r = &prep.rot[k];
        let x = &s.x;
        let p = Vector3::new(x[idx::X], x[idx::Y], x[idx::Z]);
        let v = Vector3::new(x[idx::VX], x[idx::VY], x[idx::VZ]);
        let w = Vector3::new(x[idx::WX], x[idx::WY], x[idx::WZ]);
        let bt = b * t;
        // Thrust scale and battery.
        push6(&mut raw[c_ts], k, &bt);
        push6(&mut raw[c_bat], k, &(-bt * energy));
        // Motor lag (difference of thrust and command) for the current tau.
        push6(&mut lag_raw, k, &(b * (t - s.u)));
        // Ground effect.
        ge.fill(0.0);
        let mut per_rotor = [[0.0; 17]; 4];
        for i in 0..4 {
            let hub = p + r * body.rotor_position[i];
            let h = s.ground_z - hub.z;
            ge_basis(h, s.varphi, 1.0, &mut per_rotor[i]);
        }
        for j in 0..17 {
            let weights = Vector4::new(
                per_rotor[0][j] * t[0],
                per_rotor[1][j] * t[1],
                per_rotor[2][j] * t[2],
                per_rotor[3][j] * t[3],
            );
            if weights != Vector4::zeros() {
                push6(&mut raw[c_ge + j], k, &(b * weights));
            }
        }
        // Drag and wind.
        let v_air = r.transpose() * (v - wind_w);
        let mut rotor_w = Vector6::zeros();
        let mut wind_cols = [Vector6::zeros(); 2];
        let wind_dirs = [
            r.transpose().column(0).into_owned(),
            r.transpose().column(1).into_owned(),
        ];
        for i in 0..4 {
            let n_i = &body.rotor_axis[i];
            let r_i = &body.rotor_position[i];
            let ti = t[i].max(0.0);
            let vi = v_air + w.cross(r_i);
            let f = -(vi - n_i * vi.dot(n_i)) * ti;
            rotor_w += wrench(&f, &r_i.cross(&f));
            for (jw, dir) in wind_dirs.iter().enumerate() {
                let fw = (dir - n_i * dir.dot(n_i)) * ti;
                wind_cols[jw] += wrench(&fw, &r_i.cross(&fw));
            }
        }
        push6(&mut raw[c_drag], k, &(minv * rotor_w));
        for axis in 0..3 {
            let mut f = Vector3::zeros();
            f[axis] = -0.5 * AIR_DENSITY * v_air[axis].abs() * v_air[axis];
            push6(
                &mut raw[c_drag + 1 + axis],
                k,
                &(minv * wrench(&f, &Vector3::zeros())),
            );
        }
        for jw in 0..2 {
            push6(&mut raw[c_wind + jw], k, &(minv * wind_cols[jw]));
        }
        // Mass properties: measured accelerations enter directly.
        let g_b = r.transpose() * Vector3::new(0.0, 0.0, body.gravity);
        // The change of the mass matrix acts on the true acceleration; to
        // first order that is the nominal model's (filtered) one. Using the
        // measured one would let these columns fit the measurement noise.
        let a_meas = Vector3::new(accel[6 * k], accel[6 * k + 1], accel[6 * k + 2]);
        let wd_meas = Vector3::new(accel[6 * k + 3], accel[6 * k + 4], accel[6 * k + 5]);
        let m = body.mass;
        let c = body.first_moment;
        let inertia = body.inertia;
        // mass_error: M' = M + d [[m I, -[c]x], [[c]x, 0]], W' = W + d [m g_b - w x (w x c); c x g_b].
        let dw = wrench(&(g_b * m - w.cross(&w.cross(&c))), &c.cross(&g_b));
        push6(&mut raw[c_m], k, &(minv * dw));
        let dma = wrench(&(a_meas * m - c.cross(&wd_meas)), &c.cross(&a_meas));
        push6(&mut direct[0], k, &(-(minv * dma)));
        // inertia_error.
        let gyro = wrench(&Vector3::zeros(), &(-w.cross(&(inertia * w))));
        push6(&mut raw[c_in], k, &(minv * gyro));
        push6(
            &mut direct[1],
            k,
            &(-(minv * wrench(&Vector3::zeros(), &(inertia * wd_meas)))),
        );
        // com_offset along body x and y (first order).
        for j in 0..2 {
            let mut d = Vector3::zeros();
            d[j] = 1.0;
            let md = d * m;
            let dw = wrench(&(-w.cross(&w.cross(&md))), &md.cross(&g_b));
            let di =
                Matrix3::identity() * (2.0 * c.dot(&d)) - c * d.transpose() - d * c.transpose();
            let dw = dw - wrench(&Vector3::zeros(), &w.cross(&(di * w)));
            push6(&mut raw[c_com + j], k, &(minv * dw));
            let di =
                Matrix3::identity() * (2.0 * c.dot(&d)) - c * d.transpose() - d * c.transpose();
            let dma = wrench(
                &(-(cross_matrix(&md) * wd_meas)),
                &(md.cross(&a_meas) + di * wd_meas),
            );
            push6(&mut direct[2 + j], k, &(-(minv * dma)));
        }
    }
    let mut buf = vec![0.0; 6 * n];
    for j in 0..layout.total {
        if j == c_lag {
            prep.smooth(&lag_raw, &mut buf);
        } else if raw[j].iter().any(|v| *v != 0.0) {
            prep.smooth(&raw[j], &mut buf);
        } else {
            buf.fill(0.0);
        }
        let d = match j {
            _ if j == c_m => Some(&direct[0]),
            _ if j == c_in => Some(&direct[1]),
            _ if j == c_com => Some(&direct[2]),
            _ if j == c_com + 1 => Some(&direct[3]),
            _ => None,
        };
        if let Some(d) = d {
            for k in 0..n {
                if prep.fit[k] {
                    for c in 0..6 {
                        buf[6 * k + c] += d[6 * k + c];
                    }
                }
            }
        }
        std::mem::swap(&mut raw[j], &mut buf);
    }
    Columns {
        layout,
        data: raw,
        resid: prep.resid.clone(),
    }
}

/// The motor-lag column alone for a time constant (commands as thrust).
pub fn lag_column(prep: &Prepared, rec: &Recording, tau: f64) -> Vec<f64> {
    let n = prep.n;
    let u: Vec<Input> = rec.samples.iter().map(|s| s.u).collect();
    let thrust = crate::data::lagged_commands(&prep.t, &u, tau);
    let mut raw = vec![0.0; 6 * n];
    for k in 0..n {
        let g = prep.act[k] * (thrust[k] - u[k]);
        raw[6 * k..6 * k + 6].copy_from_slice(g.as_slice());
    }
    let mut out = vec![0.0; 6 * n];
    prep.smooth(&raw, &mut out);
    out
}

/// Smoothness prior of the ground-effect table: first differences along
/// height (including towards the fixed 0 at 0.75 m) and along tilt, as a
/// 17 x 17 matrix `D^T D` on the effect's columns. Scaled by the caller to
/// a small fraction of the data's weight, it leaves well-measured entries
/// alone and makes entries without data follow their neighbours.
pub fn ge_smoothness() -> Vec<Vec<f64>> {
    let mut rows: Vec<Vec<f64>> = Vec::new();
    for r in 0..4 {
        for c in 0..4 {
            let mut d = vec![0.0; 17];
            d[r * 4 + c] = 1.0;
            if c < 3 {
                d[r * 4 + c + 1] = -1.0;
            }
            rows.push(d);
        }
    }
    for r in 0..3 {
        for c in 0..4 {
            let mut d = vec![0.0; 17];
            d[r * 4 + c] = 1.0;
            d[(r + 1) * 4 + c] = -1.0;
            rows.push(d);
        }
    }
    let mut out = vec![vec![0.0; 17]; 17];
    for d in &rows {
        for i in 0..17 {
            for j in 0..17 {
                out[i][j] += d[i] * d[j];
            }
        }
    }
    out
}
