//! Monte Carlo of a closed-loop scenario: N randomized copies flown in
//! parallel, success rate and distributions.
//!
//! Each run perturbs the truth (the plant), never the controller's model:
//! mass and inertia within +-5 % (`mass_error`), the rotors' thrust
//! coefficient within +-5 % (the plant's robot file), wind turbulence and a
//! random gust, sensor noise (the run's seed) and the initial state
//! (position +-0.1 m, velocity +-0.1 m/s, attitude +-2 deg), and the plant's
//! ground-effect surface: its table's mean gains scaled by a factor in
//! [0.7, 1.3] and its tilt axis shifted by up to +-3 deg, so that a
//! controller that models the ground effect never knows the truth exactly.
//! Run i uses seed `seed + i`, so any run can be replayed alone; the same
//! seeds give the same plants whichever controller flies them.

use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::Serialize;

use crate::closed_loop::{ControllerConfig, PredictedTouchdown, Summary, fly};
use crate::error::Result;
use crate::scenario::{Scenario, SuccessConfig};
use atmo_plant::config::{GustConfig, MassErrorConfig};

/// Order statistics of one quantity over the runs that have it.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct Distribution {
    pub count: usize,
    pub min: f64,
    pub p05: f64,
    pub median: f64,
    pub p95: f64,
    pub max: f64,
    pub mean: f64,
    pub values: Vec<f64>,
}

impl Distribution {
    pub fn of(mut values: Vec<f64>) -> Option<Self> {
        if values.is_empty() {
            return None;
        }
        values.sort_by(f64::total_cmp);
        let q = |p: f64| values[((values.len() - 1) as f64 * p).round() as usize];
        Some(Self {
            count: values.len(),
            min: values[0],
            p05: q(0.05),
            median: q(0.5),
            p95: q(0.95),
            max: values[values.len() - 1],
            mean: values.iter().sum::<f64>() / values.len() as f64,
            values,
        })
    }
}

/// The Wilson score interval at 95 % of `count` successes in `runs`
/// trials, as `[low, high]` (`[0, 1]` for no trial).
pub fn wilson_95(count: usize, runs: usize) -> [f64; 2] {
    if runs == 0 {
        return [0.0, 1.0];
    }
    let z = 1.959_963_984_540_054_f64;
    let n = runs as f64;
    let p = count as f64 / n;
    let z2n = z * z / n;
    let centre = (p + 0.5 * z2n) / (1.0 + z2n);
    let half = z / (1.0 + z2n) * (p * (1.0 - p) / n + 0.25 * z2n / n).sqrt();
    [(centre - half).max(0.0), (centre + half).min(1.0)]
}

/// A count of runs meeting a criterion, with its rate's Wilson 95 % interval.
#[derive(Debug, Clone, Copy, Serialize, PartialEq)]
pub struct Count {
    pub count: usize,
    pub runs: usize,
    pub rate: f64,
    pub wilson_95: [f64; 2],
}

impl Count {
    pub fn of(count: usize, runs: usize) -> Self {
        Self {
            count,
            runs,
            rate: if runs == 0 {
                0.0
            } else {
                count as f64 / runs as f64
            },
            wilson_95: wilson_95(count, runs),
        }
    }
}

impl std::fmt::Display for Count {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{}/{} ({:.1} %, 95 % {:.1}-{:.1} %)",
            self.count,
            self.runs,
            100.0 * self.rate,
            100.0 * self.wilson_95[0],
            100.0 * self.wilson_95[1]
        )
    }
}

/// [`MonteCarloReport::criteria_met`].
#[derive(Debug, Clone, Copy, Serialize, PartialEq)]
pub struct CriteriaMet {
    pub success: Count,
    /// Touchdown tilt >= [`PAST_TILT_DEG`], impact <= [`PAST_IMPACT_MPS`], no crash.
    pub wheel_landing_target: Count,
    pub no_crash: Count,
}

/// A run that did not succeed, for replay.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct Failure {
    pub run: usize,
    pub seed: u64,
    pub summary: Summary,
}

/// `monte_carlo.json`.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct MonteCarloReport {
    pub scenario: String,
    pub base_seed: u64,
    pub runs: usize,
    pub successes: usize,
    pub success_rate: f64,
    pub criteria: SuccessConfig,
    pub touchdown_tilt_deg: Option<Distribution>,
    pub impact_speed_mps: Option<Distribution>,
    pub drive_distance_m: Option<Distribution>,
    pub max_mean_thrust: Option<Distribution>,
    /// Runs that landed past the paper: no crash, touchdown tilt >= 64 deg,
    /// impact speed <= 0.4 m/s (issue 17's Monte Carlo criterion).
    pub landed_past_64_deg: usize,
    pub crashes: usize,
    /// Each criterion's count with its Wilson 95 % interval: the
    /// scenario's success criteria, the wheel-landing target, no crash.
    pub criteria_met: CriteriaMet,
    pub failures: Vec<Failure>,
    /// The touchdown prediction at the decision against the flown one.
    pub prediction: Option<PredictionCheck>,
    /// Every run in order: its draws and its outcome.
    pub per_run: Vec<RunRecord>,
    pub wall_time_s: f64,
    pub threads: usize,
}

/// What one run drew: the plant's truth against the controller's model.
#[derive(Debug, Clone, Copy, Serialize, PartialEq, Default)]
pub struct Draws {
    /// Mass and inertia against the robot file's (1 = as the file says).
    pub mass_scale: f64,
    pub inertia_scale: f64,
    /// The rotors' thrust coefficient against the robot file's.
    pub thrust_scale: f64,
    /// The plant's ground-effect gains against its table's (1 when the
    /// scenario has no ground effect) and the shift of its tilt axis.
    pub ground_effect_scale: f64,
    pub ground_effect_shift_deg: f64,
    /// The gust: start (s), duration (s), velocity (m/s, NED).
    pub gust_t: f64,
    pub gust_duration: f64,
    pub gust_velocity: [f64; 3],
}

/// One run of the Monte Carlo: what it drew and how it flew, so that the
/// runs that missed can be told apart from those that did not.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct RunRecord {
    pub run: usize,
    pub seed: u64,
    pub draws: Draws,
    pub success: bool,
    pub landed_past_64_deg: bool,
    pub crashed: bool,
    pub touchdown_tilt_deg: Option<f64>,
    pub impact_speed_mps: Option<f64>,
    pub max_mean_thrust: f64,
    /// The touchdown the flight stack predicted at its decision.
    pub predicted_touchdown: Option<PredictedTouchdown>,
}

/// The flown touchdown against the one predicted at the decision, over
/// the runs that decided and touched down: mean (bias) and standard
/// deviation (spread) of flown minus predicted.
#[derive(Debug, Clone, Copy, Serialize, PartialEq)]
pub struct PredictionCheck {
    pub runs: usize,
    pub impact_speed_bias_mps: f64,
    pub impact_speed_spread_mps: f64,
    pub touchdown_tilt_bias_deg: f64,
    pub touchdown_tilt_spread_deg: f64,
}

impl PredictionCheck {
    /// Over `records`; `None` if no run decided and touched down.
    pub fn of(records: &[RunRecord]) -> Option<Self> {
        let pairs: Vec<(f64, f64)> = records
            .iter()
            .filter_map(|r| {
                let p = r.predicted_touchdown?;
                Some((
                    r.impact_speed_mps? - p.impact_speed_mps,
                    r.touchdown_tilt_deg? - p.tilt_deg,
                ))
            })
            .collect();
        if pairs.is_empty() {
            return None;
        }
        let n = pairs.len() as f64;
        let mean = |f: fn(&(f64, f64)) -> f64| pairs.iter().map(f).sum::<f64>() / n;
        let (v, t) = (mean(|p| p.0), mean(|p| p.1));
        let spread = |f: fn(&(f64, f64)) -> f64, m: f64| {
            (pairs.iter().map(|p| (f(p) - m).powi(2)).sum::<f64>() / n).sqrt()
        };
        Some(Self {
            runs: pairs.len(),
            impact_speed_bias_mps: v,
            impact_speed_spread_mps: spread(|p| p.0, v),
            touchdown_tilt_bias_deg: t,
            touchdown_tilt_spread_deg: spread(|p| p.1, t),
        })
    }
}

/// The i-th randomized copy of `base`.
pub fn randomized(base: &Scenario, seed: u64) -> Scenario {
    randomized_with_draws(base, seed).0
}

/// The i-th randomized copy of `base` and what was drawn for it.
pub fn randomized_with_draws(base: &Scenario, seed: u64) -> (Scenario, Draws) {
    let mut s = base.clone();
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x4d43_5f41_544d_4f00);
    let mut within = |half: f64| rng.random_range(-half..=half);
    s.file.seed = seed;
    let fx = &mut s.plant.effects;
    let mass = fx.mass_error.clone().unwrap_or(MassErrorConfig {
        enabled: true,
        mass_scale: 1.0,
        inertia_scale: 1.0,
    });
    let mut draws = Draws {
        ground_effect_scale: 1.0,
        ..Draws::default()
    };
    draws.mass_scale = mass.mass_scale * (1.0 + within(0.05));
    draws.inertia_scale = mass.inertia_scale * (1.0 + within(0.05));
    fx.mass_error = Some(MassErrorConfig {
        enabled: true,
        mass_scale: draws.mass_scale,
        inertia_scale: draws.inertia_scale,
    });
    draws.thrust_scale = 1.0 + within(0.05);
    s.robot.rotor.k_thrust *= draws.thrust_scale;
    let mut wind = fx.wind.clone().unwrap_or_default();
    wind.enabled = true;
    draws.gust_t = within(0.5 * s.file.duration).abs();
    draws.gust_duration = 1.0 + within(0.5);
    draws.gust_velocity = [within(1.5), within(1.5), within(0.3)];
    wind.gusts.push(GustConfig {
        t: draws.gust_t,
        duration: draws.gust_duration,
        velocity: draws.gust_velocity,
    });
    fx.wind = Some(wind);
    let init = &mut s.file.initial;
    for k in 0..3 {
        init.position[k] += within(0.1);
        init.velocity[k] += within(0.1);
        init.euler_deg[k] += within(2.0);
    }
    if init.on_ground {
        // A robot on its wheels starts on the ground, whatever the spread says.
        init.position = base.file.initial.position;
        init.velocity = base.file.initial.velocity;
        init.euler_deg = base.file.initial.euler_deg;
    }
    // Drawn last, so that the draws above stay those of the runs before.
    if let Some(ge) = s.plant.effects.ground_effect.as_mut() {
        draws.ground_effect_scale = 1.0 + within(0.3);
        draws.ground_effect_shift_deg = within(3.0);
        *ge = ge.perturbed(draws.ground_effect_scale, draws.ground_effect_shift_deg);
    }
    (s, draws)
}

/// Issue 17's Monte Carlo criterion on the touchdown tilt (deg, at least)
/// and the impact speed (m/s, at most).
pub const PAST_TILT_DEG: f64 = 64.0;
pub const PAST_IMPACT_MPS: f64 = 0.4;

/// Issue 17's Monte Carlo criterion: no crash, touchdown tilt >=
/// [`PAST_TILT_DEG`], impact speed <= [`PAST_IMPACT_MPS`].
pub fn landed_past_64_deg(s: &Summary) -> bool {
    !s.crashed
        && s.touchdown_tilt_deg.is_some_and(|t| t >= PAST_TILT_DEG)
        && s.impact_speed_mps.is_some_and(|v| v <= PAST_IMPACT_MPS)
}

/// A run as a worker thread hands it back: (run, seed, draws, how it flew).
type Flown = (usize, u64, Draws, Result<Summary>);

/// Flies `runs` randomized copies on `threads` threads; `progress` is
/// called after each run with the number finished.
pub fn run(
    base: &Scenario,
    controller: &ControllerConfig,
    runs: usize,
    base_seed: u64,
    threads: usize,
    progress: &(dyn Fn(usize) + Sync),
) -> Result<MonteCarloReport> {
    let wall = std::time::Instant::now();
    let criteria = base.file.success;
    let next = AtomicUsize::new(0);
    let done = AtomicUsize::new(0);
    let results: Mutex<Vec<Flown>> = Mutex::new(Vec::with_capacity(runs));
    let threads = threads.clamp(1, runs.max(1));
    std::thread::scope(|scope| {
        for _ in 0..threads {
            scope.spawn(|| {
                loop {
                    let i = next.fetch_add(1, Ordering::Relaxed);
                    if i >= runs {
                        break;
                    }
                    let seed = base_seed.wrapping_add(i as u64);
                    let (scenario, draws) = randomized_with_draws(base, seed);
                    let summary = fly(&scenario, controller, |_| {});
                    results
                        .lock()
                        .unwrap_or_else(std::sync::PoisonError::into_inner)
                        .push((i, seed, draws, summary));
                    progress(done.fetch_add(1, Ordering::Relaxed) + 1);
                }
            });
        }
    });
    let mut results = results
        .into_inner()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    results.sort_by_key(|r| r.0);
    let mut summaries = Vec::with_capacity(runs);
    let mut per_run = Vec::with_capacity(runs);
    for (i, seed, draws, r) in results {
        let s = r?;
        per_run.push(RunRecord {
            run: i,
            seed,
            draws,
            success: criteria.met_by(&s),
            landed_past_64_deg: landed_past_64_deg(&s),
            crashed: s.crashed,
            touchdown_tilt_deg: s.touchdown_tilt_deg,
            impact_speed_mps: s.impact_speed_mps,
            max_mean_thrust: s.max_mean_thrust,
            predicted_touchdown: s.predicted_touchdown,
        });
        summaries.push((i, seed, s));
    }
    let successes = summaries
        .iter()
        .filter(|(_, _, s)| criteria.met_by(s))
        .count();
    let failures = summaries
        .iter()
        .filter(|(_, _, s)| !criteria.met_by(s))
        .map(|(i, seed, s)| Failure {
            run: *i,
            seed: *seed,
            summary: s.clone(),
        })
        .collect();
    let landed = summaries
        .iter()
        .filter(|(_, _, s)| landed_past_64_deg(s))
        .count();
    let crashes = summaries.iter().filter(|(_, _, s)| s.crashed).count();
    Ok(MonteCarloReport {
        scenario: base.file.name.clone(),
        base_seed,
        runs,
        successes,
        success_rate: if runs == 0 {
            0.0
        } else {
            successes as f64 / runs as f64
        },
        criteria,
        touchdown_tilt_deg: Distribution::of(
            summaries
                .iter()
                .filter_map(|(_, _, s)| s.touchdown_tilt_deg)
                .collect(),
        ),
        impact_speed_mps: Distribution::of(
            summaries
                .iter()
                .filter_map(|(_, _, s)| s.impact_speed_mps)
                .collect(),
        ),
        drive_distance_m: Distribution::of(
            summaries
                .iter()
                .map(|(_, _, s)| s.drive_distance_m)
                .collect(),
        ),
        max_mean_thrust: Distribution::of(
            summaries
                .iter()
                .map(|(_, _, s)| s.max_mean_thrust)
                .collect(),
        ),
        landed_past_64_deg: landed,
        crashes,
        criteria_met: CriteriaMet {
            success: Count::of(successes, runs),
            wheel_landing_target: Count::of(landed, runs),
            no_crash: Count::of(runs - crashes, runs),
        },
        failures,
        prediction: PredictionCheck::of(&per_run),
        per_run,
        wall_time_s: wall.elapsed().as_secs_f64(),
        threads,
    })
}
