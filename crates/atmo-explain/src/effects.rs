//! The library of candidate effects: physical names, parameters and their
//! regressors (per unit parameter, the body-frame generalized acceleration
//! `M^-1 wrench` they add), built along a recording.
//!
//! | effect | parameters | wrench per unit parameter |
//! | --- | --- | --- |
//! | `ground_effect` | a surface over hub height and tilt: hat functions at {0.25, 0.35, 0.45, 0.6} m (0 at 0.75 m) times cubic B-splines in tilt (knots every 22.5 deg) | `sum_i phi(h_i, varphi) A e_i t_i` |
//! | `motor_lag` | time constant tau | `A (lag_tau(u) - u)` (profiled) |
//! | `drag` | rotor drag k_r (in the disc plane), axial k_a, body Cd A (x, y, z) | `-sum_i t_i P_i v_i`, `-sum_i t_i (1 - P_i) v_i` at the hubs, `-rho/2 \|v_k\| v_k` |
//! | `wind` | steady wind (x, y) | `k_r sum_i t_i P_i R^T e_j` |
//! | `thrust_scale` | s | `A t` |
//! | `thrust_curve` | f, thrust `(1 - f) t + f t^2` | `A (t^2 - t)` (per rotor) |
//! | `battery_sag` | thrust loss per energy | `-E(t) A t` |
//! | `com_offset` | d_x, d_y | first-order change of `M` and gravity torque |
//! | `thrust_axis` | turn about body x, y | `e_j x A_F t` at B |
//! | `inertia_error` | inertia scale - 1 | `-[0; I w_dot + w x I w]` |
//! | `mass_error` | mass scale - 1 | `[m g_b - m a - ...; c x (g_b - a)]` |
//!
//! `A` = `[A_F; A_T]` the nominal actuation, `t` the thrust (commands, or
//! lagged commands once motor lag is in the model), `P_i` the projection
//! onto rotor i's disc plane.

use atmo_core::model::{Input, TiltedBody, idx};
use nalgebra::{Matrix3, Matrix6x4, Vector3, Vector4, Vector6};

use crate::data::{Prepared, cross_matrix};
use crate::recording::{Recording, Sample};

/// Hub heights of the fitted ground-effect surface's height nodes (m); the
/// gain at the last is 0, below the first it is held.
pub const GE_HEIGHTS: [f64; 5] = [0.25, 0.35, 0.45, 0.6, 0.75];
/// Knot spacing of the surface's cubic B-splines in tilt (deg): a gain
/// smooth in tilt that can peak, and turn into suction, between knots.
pub const GE_TILT_KNOT_DEG: f64 = 22.5;
/// Cubic B-splines covering 0-90 deg (`90 / GE_TILT_KNOT_DEG + 3`).
pub const GE_TILT_SPLINES: usize = (90.0 / GE_TILT_KNOT_DEG) as usize + 3;
/// Coefficients of the surface: one per tilt spline and height node below
/// the last.
pub const GE_WIDTH: usize = GE_TILT_SPLINES * 4;
/// Drag coefficients: rotor drag, axial drag, body Cd A along x, y, z.
pub const DRAG_WIDTH: usize = 5;
/// The first drag columns, rotor and axial drag, are affine in the wind:
/// they act on `v_air + w x r_i`, linear in `v - wind` (the body drag's
/// `|v| v` is not).
pub const WIND_AFFINE_DRAG: usize = 2;
/// Air density used for body drag (kg/m^3).
pub const AIR_DENSITY: f64 = 1.225;

/// The candidate effects (in reports and `explain.json` by [`Effect::name`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Effect {
    GroundEffect,
    MotorLag,
    Drag,
    Wind,
    ThrustScale,
    ThrustCurve,
    BatterySag,
    ComOffset,
    ThrustAxis,
    InertiaError,
    MassError,
}

impl Effect {
    pub const ALL: [Effect; 11] = [
        Effect::GroundEffect,
        Effect::MotorLag,
        Effect::Drag,
        Effect::Wind,
        Effect::ThrustScale,
        Effect::ThrustCurve,
        Effect::BatterySag,
        Effect::ComOffset,
        Effect::ThrustAxis,
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
            Effect::ThrustCurve => "thrust_curve",
            Effect::BatterySag => "battery_sag",
            Effect::ComOffset => "com_offset",
            Effect::ThrustAxis => "thrust_axis",
            Effect::InertiaError => "inertia_error",
            Effect::MassError => "mass_error",
        }
    }

    /// One line of physics for the report.
    pub fn physics(self) -> &'static str {
        match self {
            Effect::GroundEffect => "thrust gain T/T_inf - 1 over rotor hub height and tilt",
            Effect::MotorLag => "first-order lag from command to thrust",
            Effect::Drag => {
                "linear rotor drag in the disc plane, thrust lost to axial inflow, quadratic body drag"
            }
            Effect::Wind => "steady wind: drag acts on the air-relative velocity",
            Effect::ThrustScale => "thrust coefficient kT off by a constant factor",
            Effect::ThrustCurve => {
                "command-to-thrust curve not linear: (1 - f) u + f u^2 of full thrust"
            }
            Effect::BatterySag => "thrust scale falling with the energy drawn",
            Effect::ComOffset => "centre of mass shifted in the body x-y plane",
            Effect::ThrustAxis => "thrust turned against the measured body frame",
            Effect::InertiaError => "inertia about B off by a factor",
            Effect::MassError => "mass (and first moment) off by a factor",
        }
    }

    /// Part of the nominal calibration of an approximate robot file (what
    /// every flight pins down: hover thrust, inertia, the command-to-thrust
    /// curve, mass, and the centre of mass, which every hover's rotor trim
    /// fixes and which no hand-built robot's file has to the millimetre,
    /// and the thrust axis against the measured body frame, which a
    /// motion-capture frame a degree off the rotor plane turns: in a hover
    /// at constant heading a steady sideways push that is not a wind),
    /// reported apart from the physics found after it.
    pub fn is_calibration(self) -> bool {
        matches!(
            self,
            Effect::ThrustScale
                | Effect::ThrustCurve
                | Effect::InertiaError
                | Effect::MassError
                | Effect::ComOffset
                | Effect::ThrustAxis
        )
    }

    /// Number of linear coefficients.
    pub fn width(self) -> usize {
        match self {
            Effect::GroundEffect => GE_WIDTH,
            Effect::Drag => DRAG_WIDTH,
            Effect::Wind | Effect::ComOffset | Effect::ThrustAxis => 2,
            _ => 1,
        }
    }

    /// Names of the coefficients.
    pub fn coefficient_names(self) -> Vec<String> {
        match self {
            Effect::GroundEffect => (0..GE_WIDTH)
                .map(|c| ge_coefficient_name(c % 4, c / 4))
                .collect(),
            Effect::MotorLag => vec!["scale of the lag term (1 = lag as fitted)".into()],
            Effect::Drag => vec![
                "rotor_drag, N/(m/s)".into(),
                "axial_drag, N/(m/s)".into(),
                "body_cd_area_x, m^2".into(),
                "body_cd_area_y, m^2".into(),
                "body_cd_area_z, m^2".into(),
            ],
            Effect::Wind => vec!["rotor_drag * wind_x".into(), "rotor_drag * wind_y".into()],
            Effect::ThrustScale => vec!["thrust scale - 1".into()],
            Effect::ThrustCurve => vec!["quadratic share f of the thrust curve".into()],
            Effect::BatterySag => vec!["thrust loss per unit energy, 1/s".into()],
            Effect::ComOffset => vec!["offset_x, m".into(), "offset_y, m".into()],
            Effect::ThrustAxis => vec!["tilt_x, rad".into(), "tilt_y, rad".into()],
            Effect::InertiaError => vec!["inertia scale - 1".into()],
            Effect::MassError => vec!["mass scale - 1".into()],
        }
    }
}

impl std::fmt::Display for Effect {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// The effects' names joined by `sep` (`a, b, c`).
pub fn join(effects: &[Effect], sep: &str) -> String {
    effects
        .iter()
        .map(|e| e.name())
        .collect::<Vec<_>>()
        .join(sep)
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

/// Uniform cubic B-spline of unit knot spacing, support [0, 4).
fn cubic_bspline(x: f64) -> f64 {
    if !(0.0..4.0).contains(&x) {
        0.0
    } else if x < 1.0 {
        x.powi(3) / 6.0
    } else if x < 2.0 {
        let u = x - 1.0;
        (((-3.0 * u + 3.0) * u + 3.0) * u + 1.0) / 6.0
    } else if x < 3.0 {
        let u = x - 2.0;
        ((3.0 * u - 6.0) * u * u + 4.0) / 6.0
    } else {
        (4.0 - x).powi(3) / 6.0
    }
}

/// Tilt (deg) where tilt spline `j` peaks (outside 0-90 deg for the end
/// ones, whose peaks lie beyond the range).
pub fn ge_spline_peak_deg(j: usize) -> f64 {
    (j as f64 - 1.0) * GE_TILT_KNOT_DEG
}

/// Name of the surface's coefficient at height node `height` and tilt
/// spline `spline`.
pub fn ge_coefficient_name(height: usize, spline: usize) -> String {
    format!(
        "gain(h={:.2} m, spline peaking at {:.1} deg)",
        GE_HEIGHTS[height],
        ge_spline_peak_deg(spline)
    )
}

/// Ground-effect basis at hub height `h` and tilt `varphi`: adds
/// `scale * phi_j` into `out[j]` for the [`GE_WIDTH`] coefficients
/// (`out[4 s + c]`: tilt spline s, height node c).
pub fn ge_basis(h: f64, varphi: f64, scale: f64, out: &mut [f64]) {
    let last = (GE_TILT_SPLINES - 3) as f64;
    let x = (varphi.to_degrees() / GE_TILT_KNOT_DEG).clamp(0.0, last - 1e-9);
    let (c, wh) = atmo_core::ground_effect::table::bracket(&GE_HEIGHTS, h);
    let first = x.floor() as usize;
    for spline in first..(first + 4).min(GE_TILT_SPLINES) {
        let b = scale * cubic_bspline(x - spline as f64 + 3.0);
        for (node, w) in [(c, 1.0 - wh), (c + 1, wh)] {
            if node < 4 {
                out[spline * 4 + node] += b * w;
            }
        }
    }
}

/// The ground-effect gain of coefficients `theta` ([`GE_WIDTH`]) at
/// (h, varphi).
pub fn ge_gain(theta: &[f64], h: f64, varphi: f64) -> f64 {
    let mut phi = [0.0; GE_WIDTH];
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

/// First column of each candidate in the [`Layout`].
struct Starts {
    ge: usize,
    lag: usize,
    drag: usize,
    wind: usize,
    thrust_scale: usize,
    thrust_curve: usize,
    battery: usize,
    com: usize,
    thrust_axis: usize,
    inertia: usize,
    mass: usize,
}

impl Starts {
    fn of(layout: &Layout) -> Self {
        let at = |e: Effect| layout.columns(e).start;
        Self {
            ge: at(Effect::GroundEffect),
            lag: at(Effect::MotorLag),
            drag: at(Effect::Drag),
            wind: at(Effect::Wind),
            thrust_scale: at(Effect::ThrustScale),
            thrust_curve: at(Effect::ThrustCurve),
            battery: at(Effect::BatterySag),
            com: at(Effect::ComOffset),
            thrust_axis: at(Effect::ThrustAxis),
            inertia: at(Effect::InertiaError),
            mass: at(Effect::MassError),
        }
    }
}

/// What the regressors of one row are built from.
struct Row<'a> {
    k: usize,
    sample: &'a Sample,
    /// Thrust (commands, lagged by the knobs' tau).
    thrust: &'a Input,
    /// The commands the model is evaluated with ([`Prepared::u_eff`]).
    command: &'a Input,
    body: TiltedBody,
    /// `M^-1 [A_F; A_T]` of the row.
    act: &'a Matrix6x4<f64>,
    rot: &'a Matrix3<f64>,
}

impl<'a> Row<'a> {
    /// Row `k` of the recording, with the rotor thrusts `thrust`.
    fn at(prep: &'a Prepared, rec: &'a Recording, thrust: &'a [Input], k: usize) -> Self {
        let sample = &rec.samples[k];
        Row {
            k,
            sample,
            thrust: &thrust[k],
            command: &prep.u_eff[k],
            body: prep.table.at(sample.varphi),
            act: &prep.act[k],
            rot: &prep.rot[k],
        }
    }

    fn position(&self) -> Vector3<f64> {
        let x = &self.sample.x;
        Vector3::new(x[idx::X], x[idx::Y], x[idx::Z])
    }
    fn velocity(&self) -> Vector3<f64> {
        let x = &self.sample.x;
        Vector3::new(x[idx::VX], x[idx::VY], x[idx::VZ])
    }
    fn rates(&self) -> Vector3<f64> {
        let x = &self.sample.x;
        Vector3::new(x[idx::WX], x[idx::WY], x[idx::WZ])
    }
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
    let thrust = crate::data::lagged_commands(&prep.t, &prep.u_eff, knobs.tau);
    // Smoothed part (through S) and direct part (already filtered).
    let mut raw: Vec<Vec<f64>> = vec![vec![0.0; 6 * n]; layout.total];
    // Direct parts of the 4 mass-property columns (mass, inertia, com x, com y).
    let mut direct: Vec<Vec<f64>> = vec![vec![0.0; 6 * n]; 4];
    let mut lag_raw = vec![0.0; 6 * n];
    let mut energy = 0.0;
    let at = Starts::of(&layout);
    let wind = Vector3::new(knobs.wind[0], knobs.wind[1], 0.0);
    for k in 0..n {
        if k > 0 {
            let dt = prep.t[k] - prep.t[k - 1];
            energy += dt
                * thrust[k - 1]
                    .iter()
                    .map(|v| v.max(0.0).powf(1.5))
                    .sum::<f64>();
        }
        let row = Row::at(prep, rec, &thrust, k);
        push_thrust_terms(&mut raw, &mut lag_raw, &at, &row, energy);
        push_ground_effect(&mut raw, &at, &row);
        push_drag_and_wind(&mut raw, &at, &row, &wind);
        push_mass_properties(&mut raw, &mut direct, &at, &row, accel);
    }
    filter_columns(prep, &layout, &at, raw, &lag_raw, &direct)
}

/// Thrust scale, thrust curve, battery sag (thrust times the energy drawn so far),
/// motor lag (difference of thrust and command) for the current tau, and
/// the thrust axis turned.
fn push_thrust_terms(
    raw: &mut [Vec<f64>],
    lag_raw: &mut [f64],
    at: &Starts,
    row: &Row,
    energy: f64,
) {
    let bt = row.act * row.thrust;
    push6(&mut raw[at.thrust_scale], row.k, &bt);
    let curve = row.thrust.map(|t| t * t - t);
    push6(&mut raw[at.thrust_curve], row.k, &(row.act * curve));
    push6(&mut raw[at.battery], row.k, &(-bt * energy));
    push6(lag_raw, row.k, &(row.act * (row.thrust - row.command)));
    let thrust = row.body.thrust_force * row.thrust;
    for j in 0..2 {
        let f = Vector3::ith(j, 1.0).cross(&thrust);
        push6(
            &mut raw[at.thrust_axis + j],
            row.k,
            &(row.body.mass_matrix_inv * wrench(&f, &Vector3::zeros())),
        );
    }
}

/// Ground effect: each rotor's basis at its hub height, times its thrust.
fn push_ground_effect(raw: &mut [Vec<f64>], at: &Starts, row: &Row) {
    let (s, t, r, p) = (row.sample, row.thrust, row.rot, row.position());
    let mut per_rotor = [[0.0; GE_WIDTH]; 4];
    for i in 0..4 {
        let hub = p + r * row.body.rotor_position[i];
        let h = s.ground_z - hub.z;
        ge_basis(h, s.varphi, 1.0, &mut per_rotor[i]);
    }
    for j in 0..GE_WIDTH {
        let weights = Vector4::new(
            per_rotor[0][j] * t[0],
            per_rotor[1][j] * t[1],
            per_rotor[2][j] * t[2],
            per_rotor[3][j] * t[3],
        );
        if weights != Vector4::zeros() {
            push6(&mut raw[at.ge + j], row.k, &(row.act * weights));
        }
    }
}

/// The drag wrenches of one row about B (body frame, per unit
/// coefficient): rotor drag in the disc planes, thrust lost to axial
/// inflow, and quadratic body drag along body x, y, z acting at the centre
/// of mass, on the velocity relative to the air (`wind`, NED).
fn drag_wrenches(row: &Row, wind: &Vector3<f64>) -> [Vector6<f64>; DRAG_WIDTH] {
    let (t, r, body) = (row.thrust, row.rot, &row.body);
    let w = row.rates();
    let v_air = r.transpose() * (row.velocity() - wind);
    let mut out = [Vector6::zeros(); DRAG_WIDTH];
    for i in 0..4 {
        let n_i = &body.rotor_axis[i];
        let r_i = &body.rotor_position[i];
        let vi = v_air + w.cross(r_i);
        let axial = n_i * vi.dot(n_i);
        let f = -(vi - axial) * t[i].max(0.0);
        out[0] += wrench(&f, &r_i.cross(&f));
        let f = -axial * t[i].max(0.0);
        out[1] += wrench(&f, &r_i.cross(&f));
    }
    // The body drag acts at the centre of mass (the usual rigid-body
    // model: a force without a moment about the CoM), so about B it carries
    // the moment `com x f`; ATMO's CoM moves with the tilt. It is the robot
    // file's CoM: a fitted CoM offset moves the mass, not the airframe the
    // air flows around (the plant's `drag_wrench` does the same).
    let com = body.first_moment / body.mass;
    for axis in 0..3 {
        let mut f = Vector3::zeros();
        f[axis] = -0.5 * AIR_DENSITY * v_air[axis].abs() * v_air[axis];
        out[2 + axis] = wrench(&f, &com.cross(&f));
    }
    out
}

/// The drag columns of one row: [`drag_wrenches`] as body-frame
/// generalized accelerations (before filtering).
fn drag_terms(row: &Row, wind: &Vector3<f64>) -> [Vector6<f64>; DRAG_WIDTH] {
    drag_wrenches(row, wind).map(|w| row.body.mass_matrix_inv * w)
}

/// The mean drag force (N) along the horizontal unit `direction` (NED x,
/// y) over `rows`, for the drag `coefficients` and the rotor thrusts
/// `thrust` in a steady `wind`: what the drag law of a fit says the air
/// pushes the robot with where it flew.
pub fn mean_drag_force_along(
    prep: &Prepared,
    rec: &Recording,
    thrust: &[Input],
    rows: &[usize],
    coefficients: &[f64; DRAG_WIDTH],
    wind: [f64; 2],
    direction: [f64; 2],
) -> f64 {
    let wind = Vector3::new(wind[0], wind[1], 0.0);
    let direction = Vector3::new(direction[0], direction[1], 0.0);
    let total: f64 = rows
        .iter()
        .map(|&k| {
            let row = Row::at(prep, rec, thrust, k);
            let force: Vector3<f64> = drag_wrenches(&row, &wind)
                .iter()
                .zip(coefficients)
                .map(|(w, c)| w.fixed_rows::<3>(0) * *c)
                .sum();
            (row.rot * force).dot(&direction)
        })
        .sum();
    total / rows.len().max(1) as f64
}

/// Drag on the air-relative velocity (`wind` the current wind knob), and
/// the wind columns (rotor drag per unit wind along world x and y).
fn push_drag_and_wind(raw: &mut [Vec<f64>], at: &Starts, row: &Row, wind: &Vector3<f64>) {
    let (t, r, body, k) = (row.thrust, row.rot, &row.body, row.k);
    for (j, term) in drag_terms(row, wind).iter().enumerate() {
        push6(&mut raw[at.drag + j], k, term);
    }
    let mut wind_cols = [Vector6::zeros(); 2];
    let wind_dirs = [
        r.transpose().column(0).into_owned(),
        r.transpose().column(1).into_owned(),
    ];
    for i in 0..4 {
        let n_i = &body.rotor_axis[i];
        let r_i = &body.rotor_position[i];
        let ti = t[i].max(0.0);
        for (jw, dir) in wind_dirs.iter().enumerate() {
            let fw = (dir - n_i * dir.dot(n_i)) * ti;
            wind_cols[jw] += wrench(&fw, &r_i.cross(&fw));
        }
    }
    for jw in 0..2 {
        push6(
            &mut raw[at.wind + jw],
            k,
            &(body.mass_matrix_inv * wind_cols[jw]),
        );
    }
}

/// The drag columns of `n` rows before (`raw`) and after (`out`) the
/// measurement's filter: `6 n` values each, zeroed once and reused.
pub struct DragColumns {
    pub raw: [Vec<f64>; DRAG_WIDTH],
    pub out: [Vec<f64>; DRAG_WIDTH],
}

impl DragColumns {
    pub fn zeroed(n: usize) -> Self {
        Self {
            raw: std::array::from_fn(|_| vec![0.0; 6 * n]),
            out: std::array::from_fn(|_| vec![0.0; 6 * n]),
        }
    }
}

/// The drag columns alone (filtered like the measurement) for the rotor
/// thrusts `thrust` and a wind, on the stretches `runs`: what the wind
/// profile rebuilds per trial wind instead of every column. Only the
/// stretches' rows are written (in `out`, those `half` or more from a
/// stretch's ends), so buffers zeroed once and reused on the same
/// stretches give 0 elsewhere. Only the columns from `first_filtered` on
/// are filtered into `out` (the wind profile combines the
/// [`WIND_AFFINE_DRAG`] ones from filtered bases).
pub fn drag_columns_into(
    prep: &Prepared,
    rec: &Recording,
    thrust: &[Input],
    wind: [f64; 2],
    runs: &[(usize, usize)],
    columns: &mut DragColumns,
    first_filtered: usize,
) {
    let DragColumns { raw, out } = columns;
    let wind = Vector3::new(wind[0], wind[1], 0.0);
    for &(s, e) in runs {
        for k in s..e {
            let row = Row::at(prep, rec, thrust, k);
            // Only the columns filtered here are needed raw.
            let terms = drag_terms(&row, &wind);
            for (r, term) in raw.iter_mut().zip(&terms).skip(first_filtered) {
                r[6 * k..6 * k + 6].copy_from_slice(term.as_slice());
            }
        }
    }
    for (r, o) in raw.iter().zip(out.iter_mut()).skip(first_filtered) {
        prep.smooth_runs_in_place(r, o, runs);
    }
}

/// Mass properties (mass, inertia, centre-of-mass offset): the change of
/// the gravity and gyroscopic wrench goes through `S`; the change of the
/// mass matrix times `accel` (already filtered) enters `direct`.
fn push_mass_properties(
    raw: &mut [Vec<f64>],
    direct: &mut [Vec<f64>],
    at: &Starts,
    row: &Row,
    accel: &[f64],
) {
    let (r, body, k) = (row.rot, &row.body, row.k);
    let minv = &body.mass_matrix_inv;
    let w = row.rates();
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
    push6(&mut raw[at.mass], k, &(minv * dw));
    let dma = wrench(&(a_meas * m - c.cross(&wd_meas)), &c.cross(&a_meas));
    push6(&mut direct[0], k, &(-(minv * dma)));
    // inertia_error.
    let gyro = wrench(&Vector3::zeros(), &(-w.cross(&(inertia * w))));
    push6(&mut raw[at.inertia], k, &(minv * gyro));
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
        let di = Matrix3::identity() * (2.0 * c.dot(&d)) - c * d.transpose() - d * c.transpose();
        let dw = dw - wrench(&Vector3::zeros(), &w.cross(&(di * w)));
        push6(&mut raw[at.com + j], k, &(minv * dw));
        let dma = wrench(
            &(-(cross_matrix(&md) * wd_meas)),
            &(md.cross(&a_meas) + di * wd_meas),
        );
        push6(&mut direct[2 + j], k, &(-(minv * dma)));
    }
}

/// Every column through `S` (the lag column from `lag_raw`), plus the
/// direct parts of the mass-property columns on the fit rows.
fn filter_columns(
    prep: &Prepared,
    layout: &Layout,
    at: &Starts,
    mut raw: Vec<Vec<f64>>,
    lag_raw: &[f64],
    direct: &[Vec<f64>],
) -> Columns {
    let n = prep.n;
    let mut buf = vec![0.0; 6 * n];
    for j in 0..layout.total {
        if j == at.lag {
            prep.smooth(lag_raw, &mut buf);
        } else if raw[j].iter().any(|v| *v != 0.0) {
            prep.smooth(&raw[j], &mut buf);
        } else {
            buf.fill(0.0);
        }
        let d = match j {
            _ if j == at.mass => Some(&direct[0]),
            _ if j == at.inertia => Some(&direct[1]),
            _ if j == at.com => Some(&direct[2]),
            _ if j == at.com + 1 => Some(&direct[3]),
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
        layout: layout.clone(),
        data: raw,
        resid: prep.resid.clone(),
    }
}

/// The motor-lag column alone for a time constant (commands as thrust).
pub fn lag_column(prep: &Prepared, tau: f64) -> Vec<f64> {
    let n = prep.n;
    let u = &prep.u_eff;
    let thrust = crate::data::lagged_commands(&prep.t, u, tau);
    let mut raw = vec![0.0; 6 * n];
    for k in 0..n {
        let g = prep.act[k] * (thrust[k] - u[k]);
        raw[6 * k..6 * k + 6].copy_from_slice(g.as_slice());
    }
    let mut out = vec![0.0; 6 * n];
    prep.smooth(&raw, &mut out);
    out
}

/// Smoothness prior of the ground-effect surface: first differences of
/// its coefficients along height (including towards the fixed 0 at 0.75
/// m) and along the tilt splines, as a [`GE_WIDTH`] square matrix `D^T D`
/// on the effect's columns. Scaled by the caller to a small fraction of
/// the data's weight, it leaves well-measured coefficients alone and makes
/// those of tilts and heights without data follow their neighbours.
pub fn ge_smoothness() -> Vec<Vec<f64>> {
    let mut rows: Vec<Vec<f64>> = Vec::new();
    for r in 0..GE_TILT_SPLINES {
        for c in 0..4 {
            let mut d = vec![0.0; GE_WIDTH];
            d[r * 4 + c] = 1.0;
            if c < 3 {
                d[r * 4 + c + 1] = -1.0;
            }
            rows.push(d);
            if r + 1 < GE_TILT_SPLINES {
                let mut d = vec![0.0; GE_WIDTH];
                d[r * 4 + c] = 1.0;
                d[(r + 1) * 4 + c] = -1.0;
                rows.push(d);
            }
        }
    }
    let mut out = vec![vec![0.0; GE_WIDTH]; GE_WIDTH];
    for d in &rows {
        for i in 0..GE_WIDTH {
            for j in 0..GE_WIDTH {
                out[i][j] += d[i] * d[j];
            }
        }
    }
    out
}
