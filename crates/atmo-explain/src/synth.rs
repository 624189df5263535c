//! Synthetic recordings: atmo-plant's plant (with whatever effects its config
//! switches on) flown in closed loop by the flight stack's controller,
//! logged the way a real flight is: one row per motion-capture sample
//! (noise, latency, stamped with the instant it describes), with the rotor
//! commands and tilt in effect at that instant.
//!
//! The controller is atmo-mpc's RTI MPC with the shipped `default` preset,
//! which knows only the nominal model. It tracks a scripted reference (a
//! system-identification flight: sweeps at altitude, low passes at fixed
//! tilts) through a critically damped pre-filter, with the reference
//! previewed over its horizon and the tilt ramped at the mechanism's speed
//! towards the scripted tilt. A PRBS dither on the rotor commands
//! (system-identification excitation, 0.03 by default, switched every
//! third tick) can be added, as a test pilot's injected doublets would be.
//! Used by the concealed-data tests, the benchmark and
//! `atmo-sim explain --demo`.

use atmo_core::RobotConfig;
use atmo_core::control::WheelRates;
use atmo_core::model::{Input, Model, State, idx};
use atmo_mpc::{Mpc, MpcSettings};
use nalgebra::{Vector3, Vector4};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::recording::{Recording, Sample};
use crate::{ExplainError, Result};
use atmo_plant::config::{PlantConfig, TerrainConfig};
use atmo_plant::plant::{Command, InitialState, Plant};

/// What the scripted flight does.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Profile {
    /// 12 s of lateral and vertical sweeps at 1.5 m (up to about 3 m/s),
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
            dither: 0.03,
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
        let x = 3.0 * (1.0 - (tau * 2.0 / 12.0 * t).cos());
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

/// The reference after a critically damped pre-filter (3 rad/s per axis),
/// one entry per control tick from t = 0: position, velocity, yaw, tilt.
/// Precomputed so that the controller sees it over its whole horizon.
struct FilteredReference {
    period: f64,
    points: Vec<(Vector3<f64>, Vector3<f64>, f64, f64)>,
}

impl FilteredReference {
    fn new(profile: Profile, model: &Model, period: f64, until: f64) -> Self {
        let wf = 3.0;
        let (mut rp, _, _) = raw_reference(profile, model, 0.0);
        let mut rv = Vector3::zeros();
        let ticks = (until / period).ceil() as usize + 1;
        let mut points = Vec::with_capacity(ticks);
        for i in 0..ticks {
            let (raw, yaw, tilt) = raw_reference(profile, model, i as f64 * period);
            points.push((rp, rv, yaw, tilt));
            let ra = (raw - rp) * (wf * wf) - rv * (2.0 * wf);
            rv += ra * period;
            rp += rv * period;
        }
        Self { period, points }
    }

    /// The state reference at time `t` (attitude level at the reference
    /// yaw, rates zero) and the tilt reference.
    fn at(&self, t: f64) -> (State, f64) {
        let i = ((t / self.period).round().max(0.0) as usize).min(self.points.len() - 1);
        let (p, v, yaw, tilt) = self.points[i];
        let mut x = State::zeros();
        x[idx::X] = p.x;
        x[idx::Y] = p.y;
        x[idx::Z] = p.z;
        x[idx::YAW] = yaw;
        x[idx::VX] = v.x;
        x[idx::VY] = v.y;
        x[idx::VZ] = v.z;
        (x, tilt)
    }
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
    let setup =
        |e: atmo_mpc::MpcError| ExplainError::Setup(format!("synthetic flight controller: {e}"));
    // Offline: no wall-clock limit on a solve, so that a recording does not
    // depend on how busy the machine is.
    let mut settings = MpcSettings::atmo("default").map_err(setup)?;
    settings.solver.time_limit = 10.0;
    let mut mpc = Mpc::new(model.clone(), settings).map_err(setup)?;
    mpc.reset(&x0).map_err(setup)?;
    let mut rng = ChaCha8Rng::seed_from_u64(flight.seed ^ 0x5eed);
    let dt = plant.dt();
    let period = 1.0 / flight.control_rate;
    let steps = (flight.duration / dt).round() as usize;
    let horizon = mpc.stage_dt() * mpc.steps() as f64;
    let reference =
        FilteredReference::new(flight.profile, &model, period, flight.duration + horizon);
    let mut x_ref = vec![State::zeros(); mpc.steps() + 1];
    let tilt_rate_max = robot.limits.tilt_rate_max;
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
    let mut steps_at: Vec<usize> = Vec::new();
    let mut tilt_rate = 0.0;
    for _ in 0..steps {
        let t = plant.time();
        if t + 1e-9 >= next_tick {
            tick += 1;
            next_tick = tick as f64 * period;
            let Some(est) = plant.estimate().copied() else {
                continue;
            };
            let (_, tilt_ref) = reference.at(t);
            for (k, r) in x_ref.iter_mut().enumerate() {
                *r = reference.at(t + k as f64 * mpc.stage_dt()).0;
            }
            let tilt = plant.tilt();
            tilt_rate = ((tilt_ref - tilt) * 3.0).clamp(-tilt_rate_max, tilt_rate_max);
            let (lo, hi) = if tilt_rate >= 0.0 {
                (tilt, tilt_ref.max(tilt))
            } else {
                (tilt_ref.min(tilt), tilt)
            };
            mpc.set_reference(&x_ref).map_err(setup)?;
            mpc.set_tilt_ramp(tilt, tilt_rate, lo, hi).map_err(setup)?;
            mpc.prepare().map_err(setup)?;
            let out = mpc.feedback(&est.state).map_err(setup)?;
            if tick.is_multiple_of(3) && flight.dither > 0.0 {
                dither = Vector4::from_fn(|_, _| {
                    if rng.random::<bool>() {
                        flight.dither
                    } else {
                        -flight.dither
                    }
                });
            }
            u = (out.u + dither).map(|v| v.clamp(0.0, 1.0));
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
        if let Some(est) = plant.estimate()
            && last_seq != Some(est.sequence)
        {
            last_seq = Some(est.sequence);
            let at = ((est.measured_at / dt).round().max(0.0) as usize).min(cmd_hist.len() - 1);
            // The command applied over the step that starts at `at`.
            let cmd_at = cmd_hist[(at + 1).min(cmd_hist.len() - 1)];
            steps_at.push(at);
            samples.push(Sample {
                t: est.measured_at,
                x: est.state,
                u: cmd_at,
                applied: cmd_at,
                varphi: tilt_hist[at],
                ground_z: 0.0,
                battery_v: None,
            });
        }
    }
    // The commands applied over each row's interval: the mean of the plant
    // steps' commands from this row's step to the next row's.
    for k in 0..samples.len().saturating_sub(1) {
        let (a, b) = (steps_at[k] + 1, steps_at[k + 1] + 1);
        if b > a && b <= cmd_hist.len() {
            samples[k].applied = cmd_hist[a..b].iter().sum::<Input>() / (b - a) as f64;
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
