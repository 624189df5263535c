//! A system-identification flight, its motion-capture recording and the
//! CSV writer (docs/recording_format.md).
//!
//! Reference (NED, repeating every 16 s): 10 s at 1.5 m altitude of two
//! frequency sweeps (x: 0.3 -> 1.5 rad/s, y at 0.7 of that, 1.5 m
//! amplitude: up to ~2 m/s), a small vertical sweep and a yaw swing; then a
//! 6 s low pass: down to `low_altitude` in 2 s (raised cosine), 2 s there
//! crossing at 0.4 m/s, 2 s back up. Velocity and acceleration of the
//! reference by central differences of the position.
//!
//! Motion-capture noise (not the plant's sensor model): white position
//! noise, white attitude noise (a small rotation vector), velocity noise
//! white plus first-order Gauss-Markov (0.1 s), white rate noise. The
//! recording is sampled at the controller's rate; each row's commands are
//! the ones held from that row's time to the next.

use nalgebra::{Rotation3, UnitQuaternion, Vector3};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

use crate::control::{Control, ControllerKind, Measured, Nominal, Reference};
use crate::lqr::{Lqr, Weights};
use crate::pid::{Gains, Pid};
use crate::robot::RigidBody;
use crate::sim::{Concealed, Truth};

/// Motion-capture noise standard deviations.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Noise {
    pub position: f64,
    pub attitude: f64,
    pub velocity_white: f64,
    pub velocity_markov: f64,
    pub velocity_markov_tau: f64,
    pub rate: f64,
}

impl Default for Noise {
    fn default() -> Self {
        Self {
            position: 0.0005,
            attitude: 0.002,
            velocity_white: 0.006,
            velocity_markov: 0.004,
            velocity_markov_tau: 0.1,
            rate: 0.008,
        }
    }
}

/// What to fly.
#[derive(Debug, Clone, PartialEq)]
pub struct FlightPlan {
    pub duration: f64,
    pub rate_hz: f64,
    /// RK4 sub-steps per sample.
    pub substeps: usize,
    /// Altitude of B in the low passes (m above the ground).
    pub low_altitude: f64,
    pub noise: Noise,
    pub controller: ControllerKind,
    /// The PID's gains ([`ControllerKind::Pid`]).
    pub gains: Gains,
    /// The LQR's weights ([`ControllerKind::Lqr`]).
    pub weights: Weights,
    pub seed: u64,
}

impl Default for FlightPlan {
    fn default() -> Self {
        Self {
            duration: 48.0,
            rate_hz: 150.0,
            substeps: 8,
            low_altitude: 0.16,
            noise: Noise::default(),
            controller: ControllerKind::default(),
            gains: Gains::default(),
            weights: Weights::default(),
            seed: 1,
        }
    }
}

/// One recorded row: time, base position (NED), Euler ZYX, world velocity,
/// body rates, held commands, tilt.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Row {
    pub t: f64,
    pub p: Vector3<f64>,
    pub yaw_pitch_roll: [f64; 3],
    pub v: Vector3<f64>,
    pub w: Vector3<f64>,
    pub u: [f64; 4],
    pub varphi: f64,
}

fn reference_position(t: f64, low_altitude: f64) -> (Vector3<f64>, f64) {
    const PERIOD: f64 = 16.0;
    const HIGH: f64 = 1.5;
    let cycle = (t / PERIOD).floor();
    let s = t - cycle * PERIOD;
    let smooth = |x: f64| 0.5 - 0.5 * (std::f64::consts::PI * x.clamp(0.0, 1.0)).cos();
    if s < 10.0 {
        // Sweeps: phase of a chirp 0.3 -> 1.5 rad/s over the 10 s; both
        // start at zero, and the squared fade (2.5 s) keeps the reference
        // acceleration continuous and within ~4 m/s^2.
        let phase = 0.3 * s + 0.06 * s * s;
        let fade = (smooth(s / 2.5) * smooth((10.0 - s) / 2.5)).powi(2);
        let x = 1.5 * fade * phase.sin();
        let y = 1.5 * fade * (0.7 * phase).sin();
        let z = -HIGH - 0.3 * fade * (0.5 * phase).sin();
        let yaw = 0.5 * fade * (0.35 * phase).sin();
        (Vector3::new(x, y, z), yaw)
    } else {
        let l = s - 10.0;
        let down = smooth(l / 2.0) - smooth((l - 4.0) / 2.0);
        let alt = HIGH - (HIGH - low_altitude) * down;
        let cross = 0.4 * (l - 3.0) * smooth(l / 2.0).min(1.0 - smooth((l - 4.0) / 2.0));
        (Vector3::new(cross, 0.0, -alt), 0.0)
    }
}

/// The reference at `t` (position, velocity, acceleration, yaw).
pub fn reference(t: f64, low_altitude: f64) -> Reference {
    let h = 1e-3;
    let (p0, yaw) = reference_position(t, low_altitude);
    let (pm, _) = reference_position(t - h, low_altitude);
    let (pp, _) = reference_position(t + h, low_altitude);
    Reference {
        p: p0,
        v: (pp - pm) / (2.0 * h),
        a: (pp - p0 * 2.0 + pm) / (h * h),
        yaw,
    }
}

/// Euler ZYX (yaw, pitch, roll) of a body-to-world rotation.
pub fn euler_zyx(r: &Rotation3<f64>) -> [f64; 3] {
    let m = r.matrix();
    [
        m[(1, 0)].atan2(m[(0, 0)]),
        (-m[(2, 0)]).clamp(-1.0, 1.0).asin(),
        m[(2, 1)].atan2(m[(2, 2)]),
    ]
}

/// Flies `plan` with the true robot (`nominal` plus `fx`) under the plan's
/// controller, which knows only `nominal`; returns the recording.
pub fn fly(nominal: &RigidBody, fx: &Concealed, plan: &FlightPlan) -> Vec<Row> {
    let truth = Truth::new(nominal.clone(), fx.clone());
    let dt = 1.0 / plan.rate_hz;
    let known = Nominal::new(nominal);
    let hover_command = known.hover_command();
    let mut ctl: Box<dyn Control> = match plan.controller {
        ControllerKind::Pid => Box::new(Pid::new(known, plan.gains)),
        ControllerKind::Lqr => Box::new(Lqr::new(known, plan.weights, dt)),
    };
    let h = dt / plan.substeps as f64;
    let mut rng = ChaCha8Rng::seed_from_u64(plan.seed);
    let mut gauss = |sigma: f64| -> Vector3<f64> {
        let mut z = || -> f64 { StandardNormal.sample(&mut rng) };
        Vector3::new(z(), z(), z()) * sigma
    };
    let start = reference(0.0, plan.low_altitude);
    let hover = truth.steady_thrust(hover_command);
    let mut state = truth.at(start.p, hover);
    let n = (plan.duration * plan.rate_hz).round() as usize;
    let decay = (-dt / plan.noise.velocity_markov_tau).exp();
    let mut markov = Vector3::zeros();
    let mut rows = Vec::with_capacity(n);
    for k in 0..n {
        let t = k as f64 * dt;
        let (p, v) = truth.base(&state);
        let nz = &plan.noise;
        markov = markov * decay + gauss(nz.velocity_markov * (1.0 - decay * decay).sqrt());
        let r_meas =
            UnitQuaternion::from_scaled_axis(gauss(nz.attitude)) * state.q.to_rotation_matrix();
        let meas = Measured {
            p: p + gauss(nz.position),
            v: v + gauss(nz.velocity_white) + markov,
            r: r_meas.to_rotation_matrix(),
            w: state.w + gauss(nz.rate),
        };
        let u = ctl.command(&meas, &reference(t, plan.low_altitude), dt);
        rows.push(Row {
            t,
            p: meas.p,
            yaw_pitch_roll: euler_zyx(&meas.r),
            v: meas.v,
            w: meas.w,
            u,
            varphi: nominal.varphi,
        });
        for _ in 0..plan.substeps {
            state = truth.step(&state, &u, h);
        }
    }
    rows
}

/// The rows as a recording CSV (docs/recording_format.md).
pub fn to_csv(rows: &[Row]) -> String {
    use std::fmt::Write as _;
    let mut out =
        String::from("t,x,y,z,yaw,pitch,roll,vx,vy,vz,wx,wy,wz,u1,u2,u3,u4,varphi,ground_z\n");
    for r in rows {
        let _ = write!(out, "{:.6}", r.t);
        for v in
            r.p.iter()
                .chain(&r.yaw_pitch_roll)
                .chain(r.v.iter())
                .chain(r.w.iter())
        {
            let _ = write!(out, ",{v:.9}");
        }
        for u in &r.u {
            let _ = write!(out, ",{u:.9}");
        }
        let _ = writeln!(out, ",{:.9},0.0", r.varphi);
    }
    out
}
