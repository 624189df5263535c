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
//! seeds give the same plants whichever controller flies them. A run's
//! record depends on the base seed and its index only (never on the thread
//! or the machine that flew it), so the report of runs flown in shards
//! ([`crate::campaign`]) equals the report of the same runs flown here.

use std::panic::AssertUnwindSafe;
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::closed_loop::{ControllerConfig, PredictedTouchdown, Summary, fly_within};
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

/// A run that did not succeed, for replay (`--runs 1 --seed SEED`).
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct Failure {
    pub run: usize,
    pub seed: u64,
    /// What went wrong, in words (the run's record has the numbers).
    pub reason: String,
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
    /// Runs at the wheel-landing target: no crash, touchdown tilt >=
    /// [`PAST_TILT_DEG`], impact speed <= [`PAST_IMPACT_MPS`].
    pub landed_past_64_deg: usize,
    pub crashes: usize,
    /// Runs that gave no flight: they panicked, ran past their time limit
    /// or were refused by the closed loop (`per_run[].error`).
    pub errors: usize,
    /// Each criterion's count with its Wilson 95 % interval: the
    /// scenario's success criteria, the wheel-landing target, no crash.
    pub criteria_met: CriteriaMet,
    pub failures: Vec<Failure>,
    /// The touchdown prediction at the decision against the flown one.
    pub prediction: Option<PredictionCheck>,
    /// Every run in order: its draws and its outcome.
    pub per_run: Vec<RunRecord>,
}

/// What one run drew: the plant's truth against the controller's model.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq, Default)]
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
/// runs that missed can be told apart from those that did not. Only what
/// the seed decides: no wall-clock time.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct RunRecord {
    pub run: usize,
    pub seed: u64,
    pub draws: Draws,
    pub success: bool,
    pub landed_past_64_deg: bool,
    pub crashed: bool,
    pub touchdown_tilt_deg: Option<f64>,
    pub impact_speed_mps: Option<f64>,
    /// Null for a run that gave no flight (`error`).
    pub max_mean_thrust: Option<f64>,
    pub drive_distance_m: Option<f64>,
    /// The touchdown the flight stack predicted at its decision.
    pub predicted_touchdown: Option<PredictedTouchdown>,
    pub crash_reason: Option<String>,
    pub mode_sequence: Vec<String>,
    /// Why the run gave no flight: a panic's message, its time limit, or
    /// the closed loop's refusal. Null for a flown run.
    pub error: Option<String>,
}

impl RunRecord {
    fn flown(run: usize, seed: u64, draws: Draws, criteria: &SuccessConfig, s: &Summary) -> Self {
        Self {
            run,
            seed,
            draws,
            success: criteria.met_by(s),
            landed_past_64_deg: landed_past_64_deg(s),
            crashed: s.crashed,
            touchdown_tilt_deg: s.touchdown_tilt_deg,
            impact_speed_mps: s.impact_speed_mps,
            max_mean_thrust: Some(s.max_mean_thrust),
            drive_distance_m: Some(s.drive_distance_m),
            predicted_touchdown: s.predicted_touchdown,
            crash_reason: s.crash_reason.clone(),
            mode_sequence: s.mode_sequence.clone(),
            error: None,
        }
    }

    fn errored(run: usize, seed: u64, draws: Draws, error: String) -> Self {
        Self {
            run,
            seed,
            draws,
            success: false,
            landed_past_64_deg: false,
            crashed: false,
            touchdown_tilt_deg: None,
            impact_speed_mps: None,
            max_mean_thrust: None,
            drive_distance_m: None,
            predicted_touchdown: None,
            crash_reason: None,
            mode_sequence: Vec::new(),
            error: Some(error),
        }
    }

    /// Why a run that did not succeed missed, in words.
    fn failure_reason(&self) -> String {
        if let Some(e) = &self.error {
            return e.clone();
        }
        if let Some(c) = &self.crash_reason {
            return format!("crashed: {c}");
        }
        let fmt =
            |v: Option<f64>, unit: &str| v.map_or("none".to_string(), |v| format!("{v:.3} {unit}"));
        format!(
            "touchdown tilt {}, impact {}, driven {}, modes {}",
            fmt(self.touchdown_tilt_deg, "deg"),
            fmt(self.impact_speed_mps, "m/s"),
            fmt(self.drive_distance_m, "m"),
            self.mode_sequence.join(" -> ")
        )
    }
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

/// The wheel-landing target: the touchdown tilt (deg, at least) and the
/// impact speed (m/s, at most), past the paper's 65 deg landing's margin.
pub const PAST_TILT_DEG: f64 = 64.0;
pub const PAST_IMPACT_MPS: f64 = 0.4;

/// The wheel-landing target: no crash, touchdown tilt >= [`PAST_TILT_DEG`],
/// impact speed <= [`PAST_IMPACT_MPS`].
pub fn landed_past_64_deg(s: &Summary) -> bool {
    !s.crashed
        && s.touchdown_tilt_deg.is_some_and(|t| t >= PAST_TILT_DEG)
        && s.impact_speed_mps.is_some_and(|v| v <= PAST_IMPACT_MPS)
}

/// Each run's wall-clock budget unless told otherwise (a normal run of the
/// shipped scenarios takes well under a second in a release build).
pub const RUN_TIME_LIMIT: Duration = Duration::from_secs(120);

/// Run `index` of the Monte Carlo from `base_seed`: its seed is
/// `base_seed + index`; a panic, a run past `time_limit` or a refusal of the
/// closed loop is recorded as the run's `error`, never lost.
pub fn fly_run(
    base: &Scenario,
    controller: &ControllerConfig,
    base_seed: u64,
    index: usize,
    time_limit: Duration,
) -> RunRecord {
    let seed = base_seed.wrapping_add(index as u64);
    let (scenario, draws) = randomized_with_draws(base, seed);
    let deadline = Instant::now() + time_limit;
    let flown = std::panic::catch_unwind(AssertUnwindSafe(|| {
        fly_within(&scenario, controller, Some(deadline))
    }));
    match flown {
        Ok(Ok(summary)) => RunRecord::flown(index, seed, draws, &base.file.success, &summary),
        Ok(Err(e)) => RunRecord::errored(index, seed, draws, e.to_string()),
        Err(panic) => {
            let message = panic
                .downcast_ref::<&str>()
                .map(|m| (*m).to_string())
                .or_else(|| panic.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "a panic without a message".to_string());
            RunRecord::errored(index, seed, draws, format!("panicked: {message}"))
        }
    }
}

/// Flies the runs `indices` of the Monte Carlo from `base_seed` on
/// `threads` threads; the records come back in the order of `indices`.
/// `progress` is called after each run with the number finished.
pub fn fly_runs(
    base: &Scenario,
    controller: &ControllerConfig,
    indices: &[usize],
    base_seed: u64,
    threads: usize,
    time_limit: Duration,
    progress: &(dyn Fn(usize) + Sync),
) -> Vec<RunRecord> {
    let next = AtomicUsize::new(0);
    let done = AtomicUsize::new(0);
    let results: Mutex<Vec<(usize, RunRecord)>> = Mutex::new(Vec::with_capacity(indices.len()));
    let threads = threads.clamp(1, indices.len().max(1));
    std::thread::scope(|scope| {
        for _ in 0..threads {
            scope.spawn(|| {
                loop {
                    let k = next.fetch_add(1, Ordering::Relaxed);
                    let Some(&index) = indices.get(k) else {
                        break;
                    };
                    let record = fly_run(base, controller, base_seed, index, time_limit);
                    results
                        .lock()
                        .unwrap_or_else(std::sync::PoisonError::into_inner)
                        .push((k, record));
                    progress(done.fetch_add(1, Ordering::Relaxed) + 1);
                }
            });
        }
    });
    let mut results = results
        .into_inner()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    results.sort_by_key(|r| r.0);
    results.into_iter().map(|(_, r)| r).collect()
}

/// Flies `runs` randomized copies on `threads` threads and reports them;
/// `progress` is called after each run with the number finished.
pub fn run(
    base: &Scenario,
    controller: &ControllerConfig,
    runs: usize,
    base_seed: u64,
    threads: usize,
    progress: &(dyn Fn(usize) + Sync),
) -> MonteCarloReport {
    let indices: Vec<usize> = (0..runs).collect();
    let records = fly_runs(
        base,
        controller,
        &indices,
        base_seed,
        threads,
        RUN_TIME_LIMIT,
        progress,
    );
    report(&base.file.name, base_seed, base.file.success, records)
}

/// The report of the runs `per_run` (in run order) of the Monte Carlo of
/// `scenario` from `base_seed`: a pure function of the records, so runs
/// flown anywhere and merged give the report of runs flown here.
pub fn report(
    scenario: &str,
    base_seed: u64,
    criteria: SuccessConfig,
    per_run: Vec<RunRecord>,
) -> MonteCarloReport {
    let runs = per_run.len();
    let count = |f: &dyn Fn(&RunRecord) -> bool| per_run.iter().filter(|r| f(r)).count();
    let successes = count(&|r| r.success);
    let landed = count(&|r| r.landed_past_64_deg);
    let crashes = count(&|r| r.crashed);
    let errors = count(&|r| r.error.is_some());
    let values = |f: &dyn Fn(&RunRecord) -> Option<f64>| {
        Distribution::of(per_run.iter().filter_map(f).collect())
    };
    MonteCarloReport {
        scenario: scenario.to_string(),
        base_seed,
        runs,
        successes,
        success_rate: if runs == 0 {
            0.0
        } else {
            successes as f64 / runs as f64
        },
        criteria,
        touchdown_tilt_deg: values(&|r| r.touchdown_tilt_deg),
        impact_speed_mps: values(&|r| r.impact_speed_mps),
        drive_distance_m: values(&|r| r.drive_distance_m),
        max_mean_thrust: values(&|r| r.max_mean_thrust),
        landed_past_64_deg: landed,
        crashes,
        errors,
        criteria_met: CriteriaMet {
            success: Count::of(successes, runs),
            wheel_landing_target: Count::of(landed, runs),
            no_crash: Count::of(runs - crashes, runs),
        },
        failures: per_run
            .iter()
            .filter(|r| !r.success)
            .map(|r| Failure {
                run: r.run,
                seed: r.seed,
                reason: r.failure_reason(),
            })
            .collect(),
        prediction: PredictionCheck::of(&per_run),
        per_run,
    }
}
