//! From a recording to accelerations: the Savitzky-Golay differentiator,
//! the composite body along the recording, the measured and nominal
//! accelerations, the residual, the envelope and the noise floor.
//!
//! Both sides of the residual go through the same linear operator `S`:
//! measured world velocity and body rates are differentiated with a
//! Savitzky-Golay filter (local quadratic fit, window about 0.1 s chosen
//! from the data rate); model accelerations and effect regressors are
//! first integrated along the recording (trapezoid) and then differentiated
//! with the same filter. So a model that is right gives a residual of pure
//! noise, however fast the commands change, and every linear effect stays
//! linear after filtering.

use atmo_core::RobotConfig;
use atmo_core::model::{Input, Model, TiltedBody, idx, rotation};
use nalgebra::{Matrix3, Matrix6x4, Vector3, Vector6};

use crate::ExplainError;
use crate::recording::{Recording, Sample};

/// Channels of the residual: body-frame linear acceleration of B and
/// angular acceleration.
pub const CHANNELS: [&str; 6] = ["a_x", "a_y", "a_z", "wdot_x", "wdot_y", "wdot_z"];
/// Units of the channels.
pub const CHANNEL_UNITS: [&str; 6] = ["m/s^2", "m/s^2", "m/s^2", "rad/s^2", "rad/s^2", "rad/s^2"];

/// Largest ratio of the noise floor to the white-noise floor.
const WHITE_FLOOR_BOUND: f64 = 2.0;

/// Composite bodies on a tilt grid, interpolated in between (as the plant does).
#[derive(Debug, Clone)]
pub struct BodyTable {
    step: f64,
    bodies: Vec<TiltedBody>,
}

impl BodyTable {
    pub fn new(model: &Model, tilt_max: f64) -> Self {
        let step = 0.25_f64.to_radians();
        let n = (tilt_max / step).ceil() as usize + 2;
        let bodies = (0..n).map(|k| model.at_tilt(k as f64 * step)).collect();
        Self { step, bodies }
    }

    /// The body at `varphi` (exact on the grid, linear in between).
    pub fn at(&self, varphi: f64) -> TiltedBody {
        let s = (varphi.max(0.0) / self.step).min((self.bodies.len() - 2) as f64);
        let k = s.floor() as usize;
        let w = s - k as f64;
        let (a, b) = (&self.bodies[k], &self.bodies[k + 1]);
        if w == 0.0 {
            return *a;
        }
        atmo_plant::lerp_body(a, b, w, varphi)
    }
}

/// Where the robot is in its flight envelope at one sample.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Envelope {
    /// m, mean rotor hub height above the ground plane.
    pub height: f64,
    /// rad.
    pub varphi: f64,
    /// m/s.
    pub speed: f64,
    /// Mean normalized rotor command.
    pub thrust: f64,
    /// s since the first sample.
    pub time: f64,
    /// 1/s, mean absolute rate of change of the rotor commands (smoothed).
    pub command_rate: f64,
}

/// The recording ready for fitting.
#[derive(Debug, Clone)]
pub struct Prepared {
    pub n: usize,
    pub t: Vec<f64>,
    pub dt: f64,
    /// Half window of the Savitzky-Golay filter (samples).
    pub half: usize,
    /// Derivative filter taps (per second), index `i + half` for offset i.
    pub taps: Vec<f64>,
    /// Contiguous usable runs `[start, end)`.
    pub runs: Vec<(usize, usize)>,
    /// Row is inside a run, away from its ends by the half window.
    pub fit: Vec<bool>,
    pub rot: Vec<Matrix3<f64>>,
    /// Measured (filtered) body-frame accelerations, 6 per row.
    pub meas: Vec<f64>,
    /// Nominal model accelerations through the same filter, 6 per row.
    pub nominal: Vec<f64>,
    /// Residual `meas - nominal`, 6 per row.
    pub resid: Vec<f64>,
    /// Noise floor of each channel (standard deviation of the filtered noise).
    pub floor: [f64; 6],
    pub env: Vec<Envelope>,
    /// Rows dropped because the wheels were at the ground.
    pub contact_rows: usize,
    /// Gaps in time (more than twice the median step) that split runs.
    pub gaps: usize,
    pub table: BodyTable,
    pub wheel_radius: f64,
    /// Per row: `M^-1 [A_F; A_T]`, the generalized acceleration per unit
    /// rotor command.
    pub act: Vec<Matrix6x4<f64>>,
    /// Per row: the commands the trapezoid evaluates the model with, the
    /// mean of the applied commands of the intervals before and after the
    /// row ([`effective_commands`]).
    pub u_eff: Vec<Input>,
}

/// Savitzky-Golay first-derivative taps of a local quadratic (= local
/// linear) fit over `2 half + 1` samples spaced `dt`.
pub fn sg_derivative_taps(half: usize, dt: f64) -> Vec<f64> {
    let m = half as f64;
    let denom = m * (m + 1.0) * (2.0 * m + 1.0) / 3.0 * dt;
    (0..=2 * half).map(|j| (j as f64 - m) / denom).collect()
}

/// Savitzky-Golay smoothing taps of a local quadratic fit.
pub fn sg_smoothing_taps(half: usize) -> Vec<f64> {
    let m = half as f64;
    let n = 2.0 * m + 1.0;
    let denom = n * (4.0 * m * m + 4.0 * m - 3.0);
    (0..=2 * half)
        .map(|j| {
            let i = j as f64 - m;
            3.0 * (3.0 * m * m + 3.0 * m - 1.0 - 5.0 * i * i) / denom
        })
        .collect()
}

/// The window half-width for a data rate: about 0.1 s, at least 2 samples.
pub fn half_window(dt: f64) -> usize {
    ((0.05 / dt).round() as usize).max(2)
}

fn skew(r: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -r.z, r.y, r.z, 0.0, -r.x, -r.y, r.x, 0.0)
}

impl Prepared {
    /// Applies `S` to per-row body-frame generalized accelerations `g`
    /// (6 per row): rotate the linear part to the world frame, integrate
    /// along each run, differentiate with the filter, rotate back. Rows
    /// outside `fit` get 0.
    pub fn smooth(&self, g: &[f64], out: &mut [f64]) {
        self.smooth_runs(g, out, &self.runs);
    }

    /// [`Prepared::smooth`] along the given stretches of runs only: inside
    /// a stretch, `half` rows or more from its ends, the result is the
    /// run's (the integral differs by a constant, which the derivative
    /// filter does not see).
    pub fn smooth_runs(&self, g: &[f64], out: &mut [f64], runs: &[(usize, usize)]) {
        out.fill(0.0);
        self.smooth_runs_in_place(g, out, runs);
    }

    /// [`Prepared::smooth_runs`] writing only the rows `half` or more from
    /// the stretches' ends: the others keep what `out` held. A caller that
    /// smooths many columns on the same stretches reuses one zeroed buffer
    /// (the wind profile: zeroing 90 000 rows per trial wind was a tenth
    /// of the finder's time).
    pub fn smooth_runs_in_place(&self, g: &[f64], out: &mut [f64], runs: &[(usize, usize)]) {
        let h = self.half;
        let mut integ: Vec<[f64; 6]> = Vec::new();
        for &(s, e) in runs {
            if e - s < 2 * h + 1 {
                continue;
            }
            self.integrate_run(g, s, e, &mut integ);
            self.differentiate_into(&integ, s, out);
        }
    }

    /// Trapezoid integral of `g` (body frame, 6 per row; the linear part
    /// rotated to the world frame first) along the run `[s, e)`, from 0.
    fn integrate_run(&self, g: &[f64], s: usize, e: usize, integ: &mut Vec<[f64; 6]>) {
        integ.clear();
        let mut acc = [0.0; 6];
        let mut prev = [0.0; 6];
        for k in s..e {
            let lin = self.rot[k] * Vector3::new(g[6 * k], g[6 * k + 1], g[6 * k + 2]);
            let cur = [
                lin.x,
                lin.y,
                lin.z,
                g[6 * k + 3],
                g[6 * k + 4],
                g[6 * k + 5],
            ];
            if k > s {
                let dt = self.t[k] - self.t[k - 1];
                for c in 0..6 {
                    acc[c] += 0.5 * dt * (prev[c] + cur[c]);
                }
            }
            prev = cur;
            integ.push(acc);
        }
    }

    /// Differentiates per-row world/body quantities `series` of run
    /// starting at `s` into `out` (linear part rotated to the body frame).
    fn differentiate_into(&self, series: &[[f64; 6]], s: usize, out: &mut [f64]) {
        let h = self.half;
        for (j, window) in series.windows(self.taps.len()).enumerate() {
            let mut d = [0.0; 6];
            for (tap, v) in self.taps.iter().zip(window) {
                for (dc, vc) in d.iter_mut().zip(v) {
                    *dc += tap * vc;
                }
            }
            let k = s + j + h;
            let lin = self.rot[k].transpose() * Vector3::new(d[0], d[1], d[2]);
            out[6 * k..6 * k + 6].copy_from_slice(&[lin.x, lin.y, lin.z, d[3], d[4], d[5]]);
        }
    }

    /// Builds everything from a recording and the robot model.
    pub fn new(rec: &Recording, robot: &RobotConfig) -> Result<Self, ExplainError> {
        let samples = &rec.samples;
        let n = samples.len();
        let dt = rec.median_dt();
        if n < 50 || dt <= 0.0 {
            return Err(ExplainError::Input {
                file: rec.source.clone(),
                message: format!(
                    "too short to analyse: {n} usable rows (at least 50, about 1 s, are needed){}",
                    rec.dropped_rows()
                        .map_or_else(String::new, |d| format!("; {d}"))
                ),
            });
        }
        let half = half_window(dt);
        let taps = sg_derivative_taps(half, dt);
        let model = Model::new(robot);
        let table = BodyTable::new(&model, robot.limits.tilt_max().max(0.1));
        let wheel_radius = robot.wheels.radius;
        let t: Vec<f64> = samples.iter().map(|s| s.t).collect();
        let rot: Vec<Matrix3<f64>> = samples
            .iter()
            .map(|s| rotation(s.x[idx::YAW], s.x[idx::PITCH], s.x[idx::ROLL]))
            .collect();
        let (env, usable, contact_rows) = envelope(samples, &t, &rot, &table, wheel_radius, half);
        let (runs, gaps) = runs_of(&t, &usable, dt);
        let fit = fit_mask(&runs, half, n);
        let u_eff = effective_commands(samples, &runs);
        let n_fit = fit.iter().filter(|f| **f).count();
        if n_fit < 20 {
            return Err(ExplainError::Input {
                file: rec.source.clone(),
                message: format!(
                    "no airborne stretch long enough to analyse ({contact_rows} of {n} rows are \
                     at the ground, {gaps} time gaps)"
                ),
            });
        }

        let mut prep = Self {
            n,
            t,
            dt,
            half,
            taps,
            runs,
            fit,
            rot,
            meas: vec![0.0; 6 * n],
            nominal: vec![0.0; 6 * n],
            resid: vec![0.0; 6 * n],
            floor: [0.0; 6],
            env,
            contact_rows,
            gaps,
            table,
            wheel_radius,
            act: Vec::with_capacity(n),
            u_eff,
        };
        let meas = prep.measured(samples);
        let (raw, nominal) = prep.nominal_model(samples);
        prep.resid = meas.iter().zip(&nominal).map(|(a, b)| a - b).collect();
        prep.meas = meas;
        prep.nominal = nominal;
        prep.floor = prep.noise_floor(samples, &raw);
        Ok(prep)
    }

    /// Measured accelerations: world velocity and body rates differentiated
    /// along each run.
    fn measured(&self, samples: &[Sample]) -> Vec<f64> {
        let half = self.half;
        let mut meas = vec![0.0; 6 * self.n];
        for &(s, e) in &self.runs {
            if e - s < 2 * half + 1 {
                continue;
            }
            let series = velocity_series(samples, s, e);
            self.differentiate_into(&series, s, &mut meas);
        }
        meas
    }

    /// The nominal model's accelerations per row and through `S`; fills
    /// `act` on the way.
    fn nominal_model(&mut self, samples: &[Sample]) -> (Vec<f64>, Vec<f64>) {
        let mut raw = vec![0.0; 6 * self.n];
        for (k, s) in samples.iter().enumerate() {
            let body = self.table.at(s.varphi);
            self.act.push(body.mass_matrix_inv * actuation(&body));
            let a = body.accelerations(&s.x, &self.u_eff[k], &Vector6::zeros());
            raw[6 * k..6 * k + 6].copy_from_slice(a.as_slice());
        }
        let mut nominal = vec![0.0; 6 * self.n];
        self.smooth(&raw, &mut nominal);
        (raw, nominal)
    }

    /// Noise floor: the noise of the recorded velocity and rates (white and
    /// Gauss-Markov, from the structure function of the velocity residual
    /// of the nominal model `raw`: [`crate::noise`]) through the filter,
    /// plus the command-timing term of the model side.
    fn noise_floor(&self, samples: &[Sample], raw: &[f64]) -> [f64; 6] {
        let n = self.n;
        let mut floor = [0.0; 6];
        let mut integ = Vec::new();
        let runs: Vec<Vec<[f64; 6]>> = self
            .runs
            .iter()
            .filter(|(s, e)| e - s > self.taps.len())
            .map(|&(s, e)| {
                self.integrate_run(raw, s, e, &mut integ);
                let v = velocity_series(samples, s, e);
                v.iter()
                    .zip(&integ)
                    .map(|(a, b)| std::array::from_fn(|c| a[c] - b[c]))
                    .collect()
            })
            .collect();
        let coloured = crate::noise::floor_from_velocity_residual(&runs, &self.taps, self.dt);
        let white = self.white_floor(samples);
        // The structure fit is believed between the white floor and twice
        // it: a large model error can take the noise's place (or pass for
        // correlated noise) in the fit.
        let sig: [f64; 6] =
            std::array::from_fn(|c| coloured[c].clamp(white[c], WHITE_FLOOR_BOUND * white[c]));
        // Command timing: the trapezoid of the effective commands leaves
        // the local error `h/4 G (applied_k - applied_{k-1})` in the
        // integrated model (not accumulated), seen through the taps.
        let tap_power: f64 = self.taps.iter().map(|h| h * h).sum();
        let mut cmd_var = [0.0; 6];
        let mut rows = 0usize;
        for k in 1..n {
            if !self.fit[k] {
                continue;
            }
            let h = self.t[k] - self.t[k - 1];
            let du = samples[k].applied - samples[k - 1].applied;
            let e = self.act[k] * du * (h / 4.0);
            for c in 0..6 {
                cmd_var[c] += e[c] * e[c];
            }
            rows += 1;
        }
        let rows = rows.max(1) as f64;
        // Linear channels are rotated world channels: pooled (in `sig`) and
        // their command terms too.
        let lin_cmd = (cmd_var[0] + cmd_var[1] + cmd_var[2]) / 3.0;
        for c in 0..6 {
            let cmd = if c < 3 { lin_cmd } else { cmd_var[c] };
            floor[c] = (sig[c].powi(2) + cmd / rows * tap_power).sqrt().max(1e-6);
        }
        floor
    }

    /// The floor of white sensor noise alone: robust second differences of
    /// the recorded velocity and rates through the taps (linear channels
    /// pooled).
    fn white_floor(&self, samples: &[Sample]) -> [f64; 6] {
        let gain = self.taps.iter().map(|h| h * h).sum::<f64>().sqrt();
        let cols = [idx::VX, idx::VY, idx::VZ, idx::WX, idx::WY, idx::WZ];
        let mut sig = [0.0; 6];
        let mut d2: Vec<f64> = Vec::with_capacity(self.n);
        for (c, &col) in cols.iter().enumerate() {
            d2.clear();
            for &(s, e) in &self.runs {
                for k in s + 1..e.saturating_sub(1) {
                    let x = |j: usize| samples[j].x[col];
                    d2.push((x(k + 1) - 2.0 * x(k) + x(k - 1)).abs());
                }
            }
            if d2.is_empty() {
                continue;
            }
            let mid = d2.len() / 2;
            let (_, med, _) = d2.select_nth_unstable_by(mid, f64::total_cmp);
            sig[c] = 1.4826 * *med / 6.0_f64.sqrt() * gain;
        }
        let lin = ((sig[0] * sig[0] + sig[1] * sig[1] + sig[2] * sig[2]) / 3.0).sqrt();
        sig[..3].fill(lin);
        sig
    }

    /// Indices of the rows used for fitting.
    pub fn fit_rows(&self) -> impl Iterator<Item = usize> + '_ {
        (0..self.n).filter(|&k| self.fit[k])
    }
}

/// World velocity and body rates of the rows `[s, e)`.
fn velocity_series(samples: &[Sample], s: usize, e: usize) -> Vec<[f64; 6]> {
    (s..e)
        .map(|k| {
            let x = &samples[k].x;
            [
                x[idx::VX],
                x[idx::VY],
                x[idx::VZ],
                x[idx::WX],
                x[idx::WY],
                x[idx::WZ],
            ]
        })
        .collect()
}

/// `[A_F; A_T]`: the wrench per unit rotor command of a tilted body.
fn actuation(body: &TiltedBody) -> Matrix6x4<f64> {
    let mut a = Matrix6x4::zeros();
    a.fixed_view_mut::<3, 4>(0, 0).copy_from(&body.thrust_force);
    a.fixed_view_mut::<3, 4>(3, 0)
        .copy_from(&body.thrust_torque);
    a
}

/// Envelope per row, which rows are usable (wheels off the ground) and how
/// many are not; the command rate smoothed over the filter window.
fn envelope(
    samples: &[Sample],
    t: &[f64],
    rot: &[Matrix3<f64>],
    table: &BodyTable,
    wheel_radius: f64,
    half: usize,
) -> (Vec<Envelope>, Vec<bool>, usize) {
    let n = samples.len();
    let mut env = Vec::with_capacity(n);
    let mut usable = vec![true; n];
    let mut contact_rows = 0;
    let t0 = t[0];
    for (k, s) in samples.iter().enumerate() {
        let body = table.at(s.varphi);
        let p = Vector3::new(s.x[idx::X], s.x[idx::Y], s.x[idx::Z]);
        let r = &rot[k];
        let mut hsum = 0.0;
        let mut lowest = f64::INFINITY;
        for i in 0..4 {
            let hub = p + r * body.rotor_position[i];
            let h = s.ground_z - hub.z;
            hsum += h;
            let axis = r * body.rotor_axis[i];
            let reach = (1.0 - axis.z * axis.z).max(0.0).sqrt() * wheel_radius;
            lowest = lowest.min(h - reach);
        }
        if lowest < 0.03 {
            usable[k] = false;
            contact_rows += 1;
        }
        let v = Vector3::new(s.x[idx::VX], s.x[idx::VY], s.x[idx::VZ]);
        let du = if k > 0 {
            let d = t[k] - t[k - 1];
            (s.u - samples[k - 1].u).abs().sum() / 4.0 / d.max(1e-6)
        } else {
            0.0
        };
        env.push(Envelope {
            height: hsum / 4.0,
            varphi: s.varphi,
            speed: v.norm(),
            thrust: s.u.sum() / 4.0,
            time: s.t - t0,
            command_rate: du,
        });
    }
    // Smooth the command rate over the window (it is noisy per sample).
    let raw: Vec<f64> = env.iter().map(|e| e.command_rate).collect();
    let mut acc = 0.0;
    let mut prefix = vec![0.0; n + 1];
    for k in 0..n {
        acc += raw[k];
        prefix[k + 1] = acc;
    }
    for k in 0..n {
        let a = k.saturating_sub(half);
        let b = (k + half + 1).min(n);
        env[k].command_rate = (prefix[b] - prefix[a]) / (b - a) as f64;
    }
    (env, usable, contact_rows)
}

/// Contiguous usable runs `[start, end)`, split at time gaps (more than
/// twice the median step `dt`) and at unusable rows; and the gap count.
fn runs_of(t: &[f64], usable: &[bool], dt: f64) -> (Vec<(usize, usize)>, usize) {
    let n = t.len();
    let mut runs = Vec::new();
    let mut gaps = 0;
    let mut start: Option<usize> = None;
    for k in 0..n {
        let gap = k > 0 && t[k] - t[k - 1] > 2.0 * dt;
        if gap {
            gaps += 1;
        }
        if let Some(s0) = start
            && (gap || !usable[k])
        {
            runs.push((s0, k));
            start = None;
        }
        if start.is_none() && usable[k] {
            start = Some(k);
        }
    }
    if let Some(s0) = start {
        runs.push((s0, n));
    }
    (runs, gaps)
}

/// Rows inside a run, away from its ends by the half window.
fn fit_mask(runs: &[(usize, usize)], half: usize, n: usize) -> Vec<bool> {
    let mut fit = vec![false; n];
    for &(s, e) in runs {
        if e - s > 2 * half {
            for f in &mut fit[s + half..e - half] {
                *f = true;
            }
        }
    }
    fit
}

/// The commands to evaluate the model with at each row so that the
/// trapezoid integrates the applied commands exactly:
/// `(applied_{k-1} + applied_k) / 2`, with `applied_k` the mean command over
/// `[t_k, t_{k+1})` (the row's own commands when held). For a model
/// `g_k = G_k u`, the trapezoid `sum h/2 (g_{k-1} + g_k)` of these equals the
/// integral of the held commands `sum h/2 (G_{k-1} + G_k) applied_{k-1}` up to
/// the local term `h/4 G_k (applied_k - applied_{k-1})` (it does not
/// accumulate: no delay). Evaluating the row's own commands instead shifts
/// every command half a sample early, which reads as a motor lag of `h/2`.
/// At the start of a run the row's own applied commands are used.
pub fn effective_commands(samples: &[Sample], runs: &[(usize, usize)]) -> Vec<Input> {
    let mut out: Vec<Input> = samples.iter().map(|s| s.applied).collect();
    for &(s, e) in runs {
        for k in s + 1..e {
            out[k] = (samples[k - 1].applied + samples[k].applied) * 0.5;
        }
    }
    out
}

/// Cross-product matrix `[r]x`.
pub(crate) fn cross_matrix(r: &Vector3<f64>) -> Matrix3<f64> {
    skew(r)
}

/// First-order lag of the rotor commands with time constant `tau` (s),
/// exact for commands that move linearly between samples (the same
/// first-order hold the trapezoid integration of the model assumes);
/// `tau <= 0` returns the commands.
pub fn lagged_commands(t: &[f64], u: &[Input], tau: f64) -> Vec<Input> {
    if tau <= 0.0 {
        return u.to_vec();
    }
    let mut out = Vec::with_capacity(u.len());
    let mut state = u.first().copied().unwrap_or_else(Input::zeros);
    for k in 0..u.len() {
        if k > 0 {
            let h = (t[k] - t[k - 1]).max(1e-9);
            let a = 1.0 - (-h / tau).exp();
            let b = 1.0 - tau * a / h;
            state = state * (1.0 - a) + u[k - 1] * a + (u[k] - u[k - 1]) * b;
        }
        out.push(state);
    }
    out
}
