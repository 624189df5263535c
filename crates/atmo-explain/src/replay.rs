//! Multi-step prediction: the plant (atmo-sim's, with a plant file's
//! effects) started from the recorded state and driven by the recorded
//! commands and tilt for a short horizon, against what was recorded.

use atmo_core::RobotConfig;
use atmo_core::control::WheelRates;
use atmo_core::model::{State, idx};

use crate::data::{Prepared, lagged_commands, sg_smoothing_taps};
use crate::recording::Recording;
use atmo_plant::PlantTemplate;
use atmo_plant::config::TerrainConfig;
use atmo_plant::plant::{Command, InitialState};

/// Prediction errors at the end of the horizon, RMS over the starts that
/// were replayed. With no start replayed every error is NaN (null in
/// `explain.json`): a missing prediction is not a zero error.
#[derive(Debug, Clone, Copy, serde::Serialize)]
pub struct ReplayError {
    /// Starts replayed to the horizon (the RMS is over these).
    pub starts: usize,
    /// Starts tried; `attempted - starts - skipped` could not be replayed.
    pub attempted: usize,
    /// Starts tried that could not be replayed (the plant refused its
    /// file, or the state left what the plant integrates).
    pub failed: usize,
    /// Starts left out because the model they are compared with failed
    /// there (see [`paired`]).
    pub unpaired: usize,
    pub horizon_s: f64,
    /// m, per axis x, y, z (NED).
    pub position: [f64; 3],
    /// rad, yaw, pitch, roll.
    pub attitude: [f64; 3],
    /// m/s.
    pub velocity: [f64; 3],
    /// rad/s.
    pub rate: [f64; 3],
}

impl ReplayError {
    /// Norm of the position error (m); NaN when no start was replayed.
    pub fn position_norm(&self) -> f64 {
        self.position.iter().map(|v| v * v).sum::<f64>().sqrt()
    }
    /// Norm of the velocity error (m/s); NaN when no start was replayed.
    pub fn velocity_norm(&self) -> f64 {
        self.velocity.iter().map(|v| v * v).sum::<f64>().sqrt()
    }
    /// The velocity error, or `None` when no start was replayed: the one
    /// accessor a comparison should use.
    pub fn velocity(&self) -> Option<f64> {
        (self.starts > 0).then(|| self.velocity_norm())
    }

    /// RMS over the replayed starts of `each` that `keep` admits (a start
    /// not admitted counts as unpaired, a failed one as failed).
    pub fn from_each(each: &[Option<StartError>], keep: &dyn Fn(usize) -> bool) -> Self {
        let mut sq = [[0.0; 3]; 4];
        let (mut count, mut failed, mut unpaired) = (0usize, 0usize, 0usize);
        let mut horizon_sum = 0.0;
        for (i, e) in each.iter().enumerate() {
            let Some(e) = e else {
                failed += 1;
                continue;
            };
            if !keep(i) {
                unpaired += 1;
                continue;
            }
            for a in 0..3 {
                sq[0][a] += e.position[a].powi(2);
                sq[1][a] += e.attitude[a].powi(2);
                sq[2][a] += e.velocity[a].powi(2);
                sq[3][a] += e.rate[a].powi(2);
            }
            horizon_sum += e.horizon_s;
            count += 1;
        }
        // No start: NaN, never the 0 an empty sum would give.
        let n = if count == 0 { f64::NAN } else { count as f64 };
        let r = |v: [f64; 3]| v.map(|s| (s / n).sqrt());
        ReplayError {
            starts: count,
            attempted: each.len(),
            failed,
            unpaired,
            horizon_s: horizon_sum / n,
            position: r(sq[0]),
            attitude: r(sq[1]),
            velocity: r(sq[2]),
            rate: r(sq[3]),
        }
    }
}

/// The errors of one start at the end of its horizon.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StartError {
    pub horizon_s: f64,
    pub position: [f64; 3],
    pub attitude: [f64; 3],
    pub velocity: [f64; 3],
    pub rate: [f64; 3],
}

/// Two models' errors over the same starts: those both replayed. An RMS
/// over different subsets of starts compares different flights, so a
/// start one model failed on is left out of the other's RMS too (and
/// counted as `unpaired` there, as `failed` in the one that failed).
pub fn paired(a: &[Option<StartError>], b: &[Option<StartError>]) -> (ReplayError, ReplayError) {
    let both =
        |i: usize| a.get(i).is_some_and(Option::is_some) && b.get(i).is_some_and(Option::is_some);
    (
        ReplayError::from_each(a, &both),
        ReplayError::from_each(b, &both),
    )
}

fn wrap(a: f64) -> f64 {
    let mut a = a % std::f64::consts::TAU;
    if a > std::f64::consts::PI {
        a -= std::f64::consts::TAU;
    } else if a < -std::f64::consts::PI {
        a += std::f64::consts::TAU;
    }
    a
}

/// The recorded state at row `k`, smoothed over the filter window
/// (angles unwrapped around row k).
pub fn smoothed_state(rec: &Recording, prep: &Prepared, k: usize) -> State {
    let h = prep.half;
    if k < h || k + h >= rec.samples.len() {
        return rec.samples[k].x;
    }
    let taps = sg_smoothing_taps(h);
    let center = rec.samples[k].x;
    let mut out = State::zeros();
    for (j, w) in taps.iter().enumerate() {
        let x = &rec.samples[k + j - h].x;
        for i in 0..12 {
            let d = if (idx::YAW..=idx::ROLL).contains(&i) {
                wrap(x[i] - center[i])
            } else {
                x[i] - center[i]
            };
            out[i] += w * d;
        }
    }
    center + out
}

/// The robot the replays run: its tilt range cut to the tilts the
/// recording flew (1 deg at the least). The plant checks a file's mass
/// properties at every tilt of its range; the finder measured them at the
/// flown tilts only, so a fitted mass property is replayed where it was
/// measured and not refused for tilts the recording never reached.
pub fn within_flown_tilts(robot: &RobotConfig, rec: &Recording) -> RobotConfig {
    let flown = rec
        .samples
        .iter()
        .map(|s| s.varphi.to_degrees())
        .fold(0.0, f64::max);
    let mut cut = robot.clone();
    let limits = &mut cut.limits;
    let top = (flown + 1.0).clamp(1.0, limits.tilt_max_deg);
    limits.tilt_max_deg = top;
    limits.tilt_flight_max_deg = limits.tilt_flight_max_deg.min(top);
    limits.tilt_transition_max_deg = limits.tilt_transition_max_deg.min(top);
    cut
}

/// Start rows: fit rows whose next `horizon` seconds stay in one run,
/// spaced at least `spacing` s.
pub fn start_rows(prep: &Prepared, horizon: f64, spacing: f64) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    for &(s, e) in &prep.runs {
        let mut next_t = f64::NEG_INFINITY;
        for k in s..e {
            if !prep.fit[k] || prep.t[k] < next_t {
                continue;
            }
            let end_t = prep.t[k] + horizon;
            let Some(j) = (k..e).find(|&j| prep.t[j] >= end_t - 1e-9) else {
                break;
            };
            out.push((k, j));
            next_t = prep.t[k] + spacing;
        }
    }
    out
}

/// Runs the plant from each start for the horizon and returns the RMS
/// error at the end over the starts replayed, with the failed ones
/// counted ([`replay_each`]).
pub fn replay<'t>(
    rec: &Recording,
    prep: &Prepared,
    starts: &[(usize, usize)],
    plant_for: &dyn Fn(usize) -> Option<&'t PlantTemplate>,
    lag_tau: &dyn Fn(usize) -> f64,
) -> ReplayError {
    ReplayError::from_each(&replay_each(rec, prep, starts, plant_for, lag_tau), &|_| {
        true
    })
}

/// Runs the plant from each start for the horizon: the error at its end
/// per start, `None` where it could not be replayed. `plant_for(k)` picks
/// the plant (robot and plant file, checked once) for the start row k
/// (held-out fits), `None` where the plant refused its file.
pub fn replay_each<'t>(
    rec: &Recording,
    prep: &Prepared,
    starts: &[(usize, usize)],
    plant_for: &dyn Fn(usize) -> Option<&'t PlantTemplate>,
    lag_tau: &dyn Fn(usize) -> f64,
) -> Vec<Option<StartError>> {
    let u = &prep.u_eff;
    let mut out = Vec::with_capacity(starts.len());
    for &(k, j) in starts {
        let Some(template) = plant_for(k) else {
            out.push(None);
            continue;
        };
        let tau = lag_tau(k);
        let s = &rec.samples[k];
        let thrust = if tau > 0.0 {
            let from = k.saturating_sub(((5.0 * tau) / prep.dt) as usize + 2);
            lagged_commands(&prep.t[from..=k], &u[from..=k], tau)[k - from]
        } else {
            u[k]
        };
        let initial = InitialState {
            state: smoothed_state(rec, prep, k),
            tilt: s.varphi.max(0.0),
            thrust: thrust.map(|v| v.clamp(0.0, 1.0)),
        };
        let terrain = TerrainConfig::flat(-s.ground_z);
        let Ok(mut plant) = template.start(&terrain, &initial, 1) else {
            out.push(None);
            continue;
        };
        let t_end = prep.t[j];
        let mut row = k;
        let mut ok = true;
        while plant.time() + prep.t[k] < t_end - 1e-9 {
            let now = prep.t[k] + plant.time();
            while row + 1 < j && prep.t[row + 1] <= now + 1e-9 {
                row += 1;
            }
            let next = (row + 1).min(rec.samples.len() - 1);
            let dtr = (prep.t[next] - prep.t[row]).max(1e-6);
            let tilt_rate = (rec.samples[next].varphi - rec.samples[row].varphi) / dtr;
            let cmd = Command {
                rotors: rec.samples[row].applied,
                tilt_rate,
                wheel_rates: WheelRates {
                    left: 0.0,
                    right: 0.0,
                },
            };
            if plant.step(&cmd).is_err() {
                ok = false;
                break;
            }
        }
        let x = plant.state();
        let y = &rec.samples[j].x;
        let e = StartError {
            horizon_s: t_end - prep.t[k],
            position: std::array::from_fn(|a| x[idx::X + a] - y[idx::X + a]),
            attitude: std::array::from_fn(|a| wrap(x[idx::YAW + a] - y[idx::YAW + a])),
            velocity: std::array::from_fn(|a| x[idx::VX + a] - y[idx::VX + a]),
            rate: std::array::from_fn(|a| x[idx::WX + a] - y[idx::WX + a]),
        };
        // A state that is not a number is a failed replay, not an error.
        let finite = [e.position, e.attitude, e.velocity, e.rate]
            .iter()
            .all(|v| v.iter().all(|c| c.is_finite()));
        out.push((ok && finite).then_some(e));
    }
    out
}
