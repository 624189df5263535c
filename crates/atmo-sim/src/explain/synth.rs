//! Synthetic recordings: atmo-sim's plant (with whatever effects its config
//! switches on) flown in closed loop by a small scripted controller, logged
//! the way a real flight is: one row per motion-capture sample (noise,
//! latency, stamped with the instant it describes), with the rotor commands
//! and tilt in effect at that instant.
//!
//! The controller knows only the nominal model: position PD with
//! acceleration feed-forward through a reference pre-filter, geometric
//! attitude PD, and the nominal mass matrix and actuation to turn the
//! desired accelerations into the four rotor commands. A small PRBS dither
//! on the commands (system-identification excitation, 0.02 by default) can
//! be added. Used by the concealed-data tests, the benchmark and
//! `atmo-sim explain --demo`.

use atmo_core::RobotConfig;
use atmo_core::control::WheelRates;
use atmo_core::model::{Input, Model, State, idx};
use nalgebra::{Matrix3, Matrix4, Vector3, Vector4};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::recording::{Recording, Sample};
use crate::config::{PlantConfig, TerrainConfig};
use crate::error::Result;
use crate::plant::{Command, InitialState, Plant};

/// What the scripted flight does.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Profile {
    /// 12 s of lateral and vertical sweeps at 1.5 m (up to about 2 m/s),
    /// then low passes (rotor hubs from about 0.85 m down to 0.22 m and
    /// back, twice per tilt) at 0, 40, 50 and 55 deg, repeated until the
    /// duration is reached.
    Mixed,
    /// Hover at 1.5 m with the lateral sweeps only.
    Cruise,
    /// A wheel-landing approach: descend at 0.12 m/s from a hub height of
    /// 1.2 m to 0.22 m while moving forward at 0.3 m/s, tilt 50 deg rising
    /// to 55 deg.
    Landing,
}

/// One scripted flight.
#[derive(Debug, Clone)]
pub struct Flight {
    pub profile: Profile,
    /// s.
    pub duration: f64,
    pub seed: u64,
    /// Amplitude of the PRBS command dither (0 = none).
    pub dither: f64,
    /// Controller rate (Hz).
    pub control_rate: f64,
}

impl Flight {
    pub fn new(profile: Profile, duration: f64, seed: u64) -> Self {
        Self {
            profile,
            duration,
            seed,
            dither: 0.02,
            control_rate: 150.0,
        }
    }
}

/// Hub height minus base height (m) at tilt `varphi`, level attitude.
fn hub_offset(model: &Model, varphi: f64) -> f64 {
    let b = model.at_tilt(varphi);
    -b.rotor_position.iter().map(|r| r.z).sum::<f64>() / 4.0
}

/// Raw (unfiltered) reference: position (NED), yaw and tilt.
fn raw_reference(profile: Profile, model: &Model, t: f64) -> (Vector3<f64>, f64, f64) {
    let tau = std::f64::consts::TAU;
    let cruise = |t: f64| {
        let x = 2.0 * (1.0 - (tau * 2.0 / 12.0 * t).cos());
        let y = 1.5 * (1.0 - (tau / 12.0 * t).cos());
        let z = -1.5 - 0.3 * (tau * 3.0 / 12.0 * t).sin();
        Vector3::new(x, y, z)
    };
    let yaw = 0.5 * (0.2 * t).sin();
    match profile {
        Profile::Cruise => (cruise(t % 12.0), yaw, 0.0),
        Profile::Landing => {
            let tilt = if t < 3.0 {
                50.0
            } else {
                (50.0 + (t - 3.0) * 2.0).min(55.0)
            };
            let hub = (1.2 - 0.12 * t).max(0.22);
            let v = f64::to_radians(tilt);
            (
                Vector3::new(0.3 * t, 0.0, -(hub - hub_offset(model, v))),
                0.0,
                v,
            )
        }
        Profile::Mixed => {
            let cycle = 12.0 + 4.0 * 9.0;
            let tc = t % cycle;
            if tc < 12.0 {
                return (cruise(tc), yaw, 0.0);
            }
            let block = ((tc - 12.0) / 9.0) as usize;
            let tb = tc - 12.0 - block as f64 * 9.0;
            let tilt = [0.0_f64, 40.0, 50.0, 55.0][block.min(3)].to_radians();
            let hub = 0.51 + 0.40 * (tau * tb / 4.5).cos();
            let x = 0.6 * (0.5 * (tc - 12.0)).sin();
            let y = 0.4 * (0.35 * (tc - 12.0)).sin();
            (
                Vector3::new(x, y, -(hub - hub_offset(model, tilt))),
                yaw,
                tilt,
            )
        }
    }
}

/// Vee of a skew matrix.
fn vee(m: &Matrix3<f64>) -> Vector3<f64> {
    Vector3::new(m[(2, 1)], m[(0, 2)], m[(1, 0)])
}

/// Flies `flight` against a plant built from `robot` and `plant_cfg` on
/// flat ground at height 0 and records it.
pub fn record(robot: &RobotConfig, plant_cfg: &PlantConfig, flight: &Flight) -> Result<Recording> {
    let model = Model::new(robot);
    let (p0, yaw0, tilt0) = raw_reference(flight.profile, &model, 0.0);
    let mut x0 = State::zeros();
    x0[idx::X] = p0.x;
    x0[idx::Y] = p0.y;
    x0[idx::Z] = p0.z;
    x0[idx::YAW] = yaw0;
    let body0 = model.at_tilt(tilt0);
    let initial = InitialState {
        state: x0,
        tilt: tilt0,
        thrust: body0.hover_trim().map(|v| v.clamp(0.0, 1.0)),
    };
    let mut plant = Plant::new(
        robot,
        plant_cfg,
        &TerrainConfig::flat(0.0),
        &initial,
        flight.seed,
    )?;
    let mut rng = ChaCha8Rng::seed_from_u64(flight.seed ^ 0x5eed);
    let dt = plant.dt();
    let period = 1.0 / flight.control_rate;
    let steps = (flight.duration / dt).round() as usize;
    // Reference pre-filter (critically damped, 3 rad/s) per axis.
    let wf = 3.0;
    let mut rp = p0;
    let mut rv = Vector3::zeros();
    let mut u = initial.thrust;
    let mut dither = Vector4::zeros();
    let mut next_tick = 0.0;
    let mut tick = 0u64;
    // Command and tilt history per plant step (to log what was in effect).
    let mut cmd_hist: Vec<Input> = Vec::with_capacity(steps + 1);
    let mut tilt_hist: Vec<f64> = Vec::with_capacity(steps + 1);
    cmd_hist.push(u);
    tilt_hist.push(plant.tilt());
    let mut samples = Vec::with_capacity((flight.duration * 200.0) as usize);
    let mut last_seq = None;
    let mut tilt_rate = 0.0;
    let mut body = body0;
    let mut body_tilt = tilt0;
    for _ in 0..steps {
        let t = plant.time();
        if t + 1e-9 >= next_tick {
            tick += 1;
            next_tick = tick as f64 * period;
            let (raw, yaw_ref, tilt_ref) = raw_reference(flight.profile, &model, t);
            let ra = (raw - rp) * (wf * wf) - rv * (2.0 * wf);
            rv += ra * period;
            rp += rv * period;
            let Some(est) = plant.estimate().copied() else {
                continue;
            };
            let x = est.state;
            let tilt = plant.tilt();
            if (tilt - body_tilt).abs() > 0.002 {
                body = model.at_tilt(tilt);
                body_tilt = tilt;
            }
            tilt_rate = (tilt_ref - tilt) * 3.0;
            let p = Vector3::new(x[idx::X], x[idx::Y], x[idx::Z]);
            let v = Vector3::new(x[idx::VX], x[idx::VY], x[idx::VZ]);
            let w = Vector3::new(x[idx::WX], x[idx::WY], x[idx::WZ]);
            let r = atmo_core::model::rotation(x[idx::YAW], x[idx::PITCH], x[idx::ROLL]);
            let g = model.gravity;
            let a_d = ra + (rp - p) * 4.0 + (rv - v) * 4.0;
            let mut f = a_d - Vector3::new(0.0, 0.0, g);
            // Keep the thrust direction within 35 deg of vertical.
            let horiz = (f.x * f.x + f.y * f.y).sqrt();
            let max_h = -f.z * 0.7;
            if horiz > max_h && horiz > 0.0 {
                f.x *= max_h / horiz;
                f.y *= max_h / horiz;
            }
            let b3 = -f / f.norm();
            let b1c = Vector3::new(yaw_ref.cos(), yaw_ref.sin(), 0.0);
            let b2 = b3.cross(&b1c).normalize();
            let b1 = b2.cross(&b3);
            let rd = Matrix3::from_columns(&[b1, b2, b3]);
            let e_r = vee(&(rd.transpose() * r - r.transpose() * rd)) * 0.5;
            let wd = -e_r * 150.0 - w * 20.0;
            let a_b = r.transpose() * (a_d);
            let g_b = r.transpose() * Vector3::new(0.0, 0.0, g);
            let c = body.first_moment;
            let lin = a_b * body.mass - c.cross(&wd) - g_b * body.mass + w.cross(&w.cross(&c));
            let ang =
                body.inertia * wd + c.cross(&a_b) - c.cross(&g_b) + w.cross(&(body.inertia * w));
            let mut a4 = Matrix4::zeros();
            a4.set_row(0, &body.thrust_force.row(2));
            for k in 0..3 {
                a4.set_row(k + 1, &body.thrust_torque.row(k));
            }
            let rhs = Vector4::new(lin.z, ang.x, ang.y, ang.z);
            if let Some(sol) = a4.lu().solve(&rhs) {
                if tick % 3 == 0 && flight.dither > 0.0 {
                    dither = Vector4::from_fn(|_, _| {
                        if rng.random::<bool>() {
                            flight.dither
                        } else {
                            -flight.dither
                        }
                    });
                }
                u = (sol + dither).map(|v| v.clamp(0.0, 1.0));
            }
        }
        let cmd = Command {
            rotors: u,
            tilt_rate,
            wheel_rates: WheelRates {
                left: 0.0,
                right: 0.0,
            },
        };
        plant.step(&cmd)?;
        cmd_hist.push(u);
        tilt_hist.push(plant.tilt());
        if let Some(est) = plant.estimate() {
            if last_seq != Some(est.sequence) {
                last_seq = Some(est.sequence);
                let at = ((est.measured_at / dt).round().max(0.0) as usize).min(cmd_hist.len() - 1);
                // The command applied over the step that starts at `at`.
                let cmd_at = cmd_hist[(at + 1).min(cmd_hist.len() - 1)];
                samples.push(Sample {
                    t: est.measured_at,
                    x: est.state,
                    u: cmd_at,
                    varphi: tilt_hist[at],
                    ground_z: 0.0,
                    battery_v: None,
                });
            }
        }
    }
    // Samples can share an instant at the start (latency not yet filled).
    samples.dedup_by(|b, a| b.t <= a.t);
    Ok(Recording::from_samples(
        format!(
            "synthetic {:?} flight, seed {}",
            flight.profile, flight.seed
        ),
        samples,
    ))
}
