//! atmo-explain: the discrepancy finder (`atmo-sim explain`). Where do a recording and the
//! nominal model disagree, which missing physics explains it, and how much
//! better does the model get with it.
//!
//! 1. **Residuals** ([`data`]): the nominal model (the robot file, nothing
//!    else) is evaluated at every recorded state with the recorded commands
//!    and tilt. Measured accelerations come from a Savitzky-Golay
//!    differentiator (window about 0.1 s from the data rate); the model
//!    side goes through the same filter (integrated, then differentiated),
//!    so the residual of a right model is noise. Multi-step prediction:
//!    atmo-plant's plant started from the recorded state and driven by the
//!    recorded commands for 0.5 s ([`replay`]).
//! 2. **Locate** ([`locate`]): channels x bins of hub height, tilt, speed,
//!    thrust, time, command rate and the (height, tilt) map, each tested
//!    against the noise floor (batch-means z tests, Bonferroni).
//! 3. **Name the physics** ([`effects`], [`select`]): nine candidate
//!    effects with physical parameters, linear in their coefficients
//!    (motor lag: time constant profiled by held-out error). Forward-backward
//!    selection on held-out whole segments (5 folds), inclusion frequency
//!    over random halves of the segments as confidence, delete-a-fold
//!    jackknife standard deviations, and a swap test for effects the data
//!    cannot tell apart.
//! 4. **Model it**: the fitted effects as a plant file
//!    (`fitted_effects.toml`, the plant's `[effects.<name>]` sections),
//!    replayed to compare held-out residual RMS and multi-step error before
//!    and after.
//! 5. **Outputs** ([`output`]): `report.md`, `fitted_effects.toml`,
//!    `explain.json`, PNG plots.
//!
//! Input format: docs/recording_format.md ([`recording`]).

pub mod cli;
pub mod data;
pub mod effects;
pub mod locate;
pub mod output;
pub mod recording;
pub mod replay;
pub mod select;
pub mod synth;

use std::fmt::Write as _;
use std::path::PathBuf;

use atmo_core::config::ArmInertiaConvention;
use atmo_core::{ConfigFile, RobotConfig};
use nalgebra::DVector;
use serde::Serialize;

use atmo_plant::config::PlantConfig;
use atmo_plant::ground_effect::{GroundEffect, GroundEffectConfig};
use data::{CHANNELS, Prepared};
use effects::{Effect, GE_HEIGHTS, GE_TILTS_DEG, Knobs, Layout, build_columns, lag_column};
use locate::Location;
use recording::Recording;
use replay::ReplayError;
use select::{Stats, fold_of};

/// What can stop the analysis.
#[derive(Debug, thiserror::Error)]
pub enum ExplainError {
    /// The recording cannot be used (names the file and what is wrong).
    #[error("{file}: {message}")]
    Input { file: PathBuf, message: String },
    /// The fitted effects do not make a valid plant file (a bug or an
    /// extreme fit; the message says which key).
    #[error("fitted effects: {0}")]
    Fit(String),
    /// Writing the outputs failed.
    #[error("output: {0}")]
    Output(String),
    /// The plant refused its file or a command while replaying or making a
    /// synthetic recording.
    #[error(transparent)]
    Plant(#[from] atmo_plant::PlantError),
    /// The synthetic recording's controller could not be built.
    #[error("synthetic flight: {0}")]
    Setup(String),
}

/// Result alias for atmo-explain.
pub type Result<T, E = ExplainError> = std::result::Result<T, E>;

/// Confidence at or above which an effect is "claimed with high confidence".
pub const HIGH_CONFIDENCE: f64 = 0.7;
/// Grid of the reported ground-effect gain: hub heights (m).
pub const GRID_HEIGHTS: [f64; 4] = [0.25, 0.35, 0.45, 0.6];
/// Grid of the reported ground-effect gain: tilts (deg).
pub const GRID_TILTS_DEG: [f64; 5] = [0.0, 40.0, 50.0, 60.0, 70.0];
/// Multi-step prediction horizon (s).
pub const HORIZON: f64 = 0.5;

/// Options of one analysis.
#[derive(Debug, Clone)]
pub struct Options {
    /// Seed of the stability subsampling.
    pub seed: u64,
    /// Show a progress bar.
    pub progress: bool,
    /// Most multi-step starts (spread over the recording).
    pub max_replay_starts: usize,
}

impl Default for Options {
    fn default() -> Self {
        Self {
            seed: 1,
            progress: false,
            max_replay_starts: 240,
        }
    }
}

/// One parameter with its uncertainty.
#[derive(Debug, Clone, Serialize)]
pub struct Parameter {
    pub name: String,
    pub value: f64,
    /// One standard deviation (delete-a-fold jackknife; null if unknown).
    pub std: Option<f64>,
    pub unit: String,
}

/// A candidate effect's verdict.
#[derive(Debug, Clone, Serialize)]
pub struct EffectReport {
    pub name: String,
    pub physics: String,
    pub selected: bool,
    /// Inclusion frequency over random halves of the segments, in [0, 1].
    pub confidence: f64,
    /// Held-out improvement (noise-floor variances per residual entry) from
    /// adding it to the selected model (or lost by removing it).
    pub heldout_gain: f64,
    pub parameters: Vec<Parameter>,
    /// Effects this one cannot be told apart from with this data.
    pub indistinguishable_from: Vec<String>,
}

/// One point of the ground-effect gain grid.
#[derive(Debug, Clone, Serialize)]
pub struct GridPoint {
    pub height_m: f64,
    pub varphi_deg: f64,
    pub gain: f64,
    pub std: f64,
    /// Whether the recording has data there (at least 0.5 s within
    /// +-0.05 m and +-3 deg).
    pub covered: bool,
}

/// RMS per channel, overall and in the located region.
#[derive(Debug, Clone, Serialize, Default)]
pub struct RmsTable {
    /// Per channel (a_x .. wdot_z), all held-out rows.
    pub per_channel: [f64; 6],
    /// Per channel, rows in the located region.
    pub located_per_channel: [f64; 6],
    /// RMS over the located channels in the located region, in units of
    /// their noise floors.
    pub located_normalized: f64,
    pub located_rows: usize,
}

/// One channel over time: recording, nominal model and fitted model.
#[derive(Debug, Clone, Default)]
pub struct Series {
    pub channel: usize,
    pub t: Vec<f64>,
    pub recording: Vec<f64>,
    pub nominal: Vec<f64>,
    pub fitted: Vec<f64>,
}

/// Everything the analysis found.
#[derive(Debug, Clone, Serialize)]
pub struct Explanation {
    pub source: String,
    pub rows: usize,
    pub rows_used: usize,
    pub rate_hz: f64,
    pub duration_s: f64,
    pub window_samples: usize,
    pub ignored_columns: Vec<String>,
    pub skipped_nonfinite: usize,
    pub skipped_time: usize,
    pub contact_rows: usize,
    pub noise_floor: [f64; 6],
    pub mismatch_found: bool,
    pub verdict: String,
    pub located: Vec<locate::Located>,
    pub located_channels: Vec<String>,
    pub effects: Vec<EffectReport>,
    pub selection_steps: Vec<select::Step>,
    pub indistinguishable: Vec<(String, String)>,
    pub heldout_rms_before: RmsTable,
    pub heldout_rms_after: RmsTable,
    pub multistep_before: ReplayError,
    pub multistep_after: ReplayError,
    pub ground_effect_gain_grid: Vec<GridPoint>,
    pub motor_lag_profile: Vec<(f64, f64)>,
    pub fitted_effects_toml: String,
    #[serde(skip)]
    pub location_before: Option<Location>,
    #[serde(skip)]
    pub location_after: Option<Location>,
    /// Series for the time-series plot: t, measured, nominal, fitted of the
    /// most affected channel.
    #[serde(skip)]
    pub series: Option<Series>,
    pub timings_s: Vec<(String, f64)>,
    /// Warnings about how far the results can be trusted.
    pub notes: Vec<String>,
}

struct Progress(Option<indicatif::ProgressBar>);

impl Progress {
    fn new(show: bool) -> Self {
        if !show {
            return Self(None);
        }
        let bar = indicatif::ProgressBar::new(8);
        bar.set_style(
            indicatif::ProgressStyle::with_template("{bar:30} {pos}/{len} {msg} [{elapsed}]")
                .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
        );
        Self(Some(bar))
    }
    fn step(&self, msg: &'static str) {
        if let Some(b) = &self.0 {
            b.set_message(msg);
            b.inc(1);
        }
    }
    fn finish(&self) {
        if let Some(b) = &self.0 {
            b.finish_and_clear();
        }
    }
}

fn convention_name(c: ArmInertiaConvention) -> &'static str {
    match c {
        ArmInertiaConvention::AuthorsModel => "authors_model",
        ArmInertiaConvention::AboutCom => "about_com",
    }
}

/// Physical parameters of the selected effects, from the coefficients.
#[derive(Debug, Clone, Default)]
struct Physical {
    ge: Option<Vec<f64>>,
    tau: Option<f64>,
    drag: Option<[f64; 4]>,
    wind: Option<[f64; 2]>,
    thrust_scale: Option<f64>,
    battery: Option<f64>,
    com: Option<[f64; 2]>,
    inertia: Option<f64>,
    mass: Option<f64>,
}

const BATTERY_CAPACITY_WH: f64 = 110.0;
const BATTERY_FULL_POWER_W: f64 = 560.0;

impl Physical {
    fn from_theta(
        layout: &Layout,
        set: &[Effect],
        idx: &[usize],
        theta: &DVector<f64>,
        tau: f64,
    ) -> Self {
        let get = |e: Effect| -> Vec<f64> {
            layout
                .columns(e)
                .map(|c| idx.iter().position(|i| *i == c).map_or(0.0, |p| theta[p]))
                .collect()
        };
        let mut out = Physical::default();
        for &e in set {
            let v = get(e);
            match e {
                Effect::GroundEffect => out.ge = Some(v),
                Effect::MotorLag => out.tau = Some(tau),
                Effect::Drag => out.drag = Some([v[0], v[1], v[2], v[3]]),
                Effect::Wind => {
                    let kr = get(Effect::Drag)[0];
                    out.wind = Some(if kr.abs() > 1e-3 {
                        [v[0] / kr, v[1] / kr]
                    } else {
                        [0.0, 0.0]
                    });
                }
                Effect::ThrustScale => out.thrust_scale = Some(v[0]),
                Effect::BatterySag => out.battery = Some(v[0]),
                Effect::ComOffset => out.com = Some([v[0], v[1]]),
                Effect::InertiaError => out.inertia = Some(v[0]),
                Effect::MassError => out.mass = Some(v[0]),
            }
        }
        out
    }

    fn ge_config(&self) -> Option<GroundEffectConfig> {
        let ge = self.ge.as_ref()?;
        let radius = ge[16].max(0.0).sqrt().clamp(0.01, 1.0);
        let gain: Vec<Vec<f64>> = (0..4)
            .map(|r| {
                let mut row: Vec<f64> = (0..4).map(|c| ge[r * 4 + c].clamp(-0.9, 5.0)).collect();
                row.push(0.0);
                row
            })
            .collect();
        Some(GroundEffectConfig {
            enabled: true,
            rotor_radius: radius,
            classical_below_deg: effects::GE_CLASSICAL_BELOW_DEG,
            correlation_time: 0.05,
            heights: GE_HEIGHTS.to_vec(),
            tilts_deg: GE_TILTS_DEG.to_vec(),
            gain,
            std: vec![vec![0.0; 5]; 4],
        })
    }

    /// The plant file text.
    fn toml(&self, convention: ArmInertiaConvention, header: &str) -> String {
        let mut s = String::new();
        let _ = writeln!(s, "# Fitted by `atmo-sim explain`: {header}");
        let _ = writeln!(
            s,
            "# A plant file (config/plant.toml format): load it with PlantConfig::load.\n\
             # Effects are relative to the robot file the analysis was given; the arm\n\
             # inertia is read the way that robot file reads it."
        );
        let _ = writeln!(s, "dt = 0.001");
        let _ = writeln!(
            s,
            "arm_inertia_convention = \"{}\"",
            convention_name(convention)
        );
        let fmt = |v: &[f64]| {
            v.iter()
                .map(|x| format!("{x:.6}"))
                .collect::<Vec<_>>()
                .join(", ")
        };
        if let Some(ge) = self.ge_config() {
            let _ = writeln!(s, "\n[effects.ground_effect]");
            let _ = writeln!(
                s,
                "# Thrust gain T/T_inf - 1 by rotor hub height (m) and tilt (deg);\n# classical law with the fitted rotor radius below 30 deg."
            );
            let _ = writeln!(s, "rotor_radius = {:.6}", ge.rotor_radius);
            let _ = writeln!(s, "classical_below_deg = {:.1}", ge.classical_below_deg);
            let _ = writeln!(s, "correlation_time = {}", ge.correlation_time);
            let _ = writeln!(s, "heights = [{}]", fmt(&ge.heights));
            let _ = writeln!(s, "tilts_deg = [{}]", fmt(&ge.tilts_deg));
            let _ = writeln!(s, "gain = [");
            for row in &ge.gain {
                let _ = writeln!(s, "    [{}],", fmt(row));
            }
            let _ = writeln!(s, "]");
            let _ = writeln!(s, "std = [");
            for row in &ge.std {
                let _ = writeln!(s, "    [{}],", fmt(row));
            }
            let _ = writeln!(s, "]");
        }
        if let Some(tau) = self.tau {
            let _ = writeln!(
                s,
                "\n[effects.motor_lag]\ntime_constant = {:.6}\ncurve = 0.0",
                tau.clamp(1e-4, 1.0)
            );
        }
        if self.drag.is_some() || self.wind.is_some() {
            let d = self.drag.unwrap_or([0.0; 4]);
            let _ = writeln!(
                s,
                "\n[effects.drag]\nrotor_drag = {:.6}\nbody_cd_area = [{}]\nair_density = {}",
                d[0].clamp(0.0, 100.0),
                fmt(&[
                    d[1].clamp(0.0, 10.0),
                    d[2].clamp(0.0, 10.0),
                    d[3].clamp(0.0, 10.0)
                ]),
                effects::AIR_DENSITY
            );
        }
        if let Some(w) = self.wind {
            let _ = writeln!(
                s,
                "\n[effects.wind]\nsteady = [{}]\nturbulence_std = [0.0, 0.0, 0.0]",
                fmt(&[w[0].clamp(-50.0, 50.0), w[1].clamp(-50.0, 50.0), 0.0])
            );
        }
        if let Some(b) = self.battery {
            let sag = (b * 3600.0 * BATTERY_CAPACITY_WH / BATTERY_FULL_POWER_W).clamp(0.0, 0.9);
            let _ = writeln!(
                s,
                "\n[effects.battery_sag]\n# thrust x (1 - sag E / capacity), E the energy drawn\ncapacity_wh = {BATTERY_CAPACITY_WH}\nused_wh = 0.0\nfull_power_w = {BATTERY_FULL_POWER_W}\nsag = {sag:.6}"
            );
        }
        if let Some(c) = self.com {
            let _ = writeln!(
                s,
                "\n[effects.com_offset]\noffset = [{}]",
                fmt(&[c[0].clamp(-0.1, 0.1), c[1].clamp(-0.1, 0.1), 0.0])
            );
        }
        if self.thrust_scale.is_some() || self.mass.is_some() || self.inertia.is_some() {
            // A thrust scale (1 + s) acts on the rigid body exactly like mass,
            // first moment and inertia all divided by (1 + s).
            let s_t = 1.0 + self.thrust_scale.unwrap_or(0.0);
            let ms = (1.0 + self.mass.unwrap_or(0.0)) / s_t;
            let is = (1.0 + self.inertia.unwrap_or(0.0)) / s_t;
            let _ = writeln!(
                s,
                "\n[effects.mass_error]\n# mass_error {:.4}, inertia_error {:.4}, thrust_scale {:.4} (a thrust scale\n# 1 + s is written as mass and inertia scaled by 1 / (1 + s): the same dynamics)\nmass_scale = {:.6}\ninertia_scale = {:.6}",
                self.mass.unwrap_or(0.0),
                self.inertia.unwrap_or(0.0),
                self.thrust_scale.unwrap_or(0.0),
                ms.clamp(0.5, 2.0),
                is.clamp(0.5, 2.0)
            );
        }
        s
    }
}

fn rms_table(
    prep: &Prepared,
    resid: &[f64],
    rows: &[usize],
    region: &[bool],
    channels: &[usize],
) -> RmsTable {
    let mut sq = [0.0; 6];
    let mut sq_in = [0.0; 6];
    let mut n_in = 0usize;
    let mut norm = 0.0;
    for &k in rows {
        for c in 0..6 {
            let r = resid[6 * k + c];
            sq[c] += r * r;
            if region[k] {
                sq_in[c] += r * r;
            }
        }
        if region[k] {
            n_in += 1;
            for &c in channels {
                let r = resid[6 * k + c] / prep.floor[c];
                norm += r * r;
            }
        }
    }
    let n = rows.len().max(1) as f64;
    let ni = n_in.max(1) as f64;
    RmsTable {
        per_channel: sq.map(|s| (s / n).sqrt()),
        located_per_channel: sq_in.map(|s| (s / ni).sqrt()),
        located_normalized: (norm / (ni * channels.len().max(1) as f64)).sqrt(),
        located_rows: n_in,
    }
}

/// Statistics of every column with the ground-effect smoothness prior.
fn stats_of(
    columns: &effects::Columns,
    weights: &[f64],
    seg_of: &[Option<usize>],
    nseg: usize,
) -> Stats {
    let cols: Vec<&[f64]> = columns.data.iter().map(Vec::as_slice).collect();
    let mut stats = Stats::build(&cols, &columns.resid, weights, seg_of, nseg);
    let ge = columns.layout.columns(Effect::GroundEffect);
    let mut diag: Vec<f64> = ge
        .clone()
        .map(|c| stats.g.iter().map(|g| g[(c, c)]).sum::<f64>())
        .filter(|d| *d > 0.0)
        .collect();
    diag.sort_by(f64::total_cmp);
    let scale = diag.get(diag.len() / 2).copied().unwrap_or(0.0) * 1e-3;
    let prior = effects::ge_smoothness();
    for (a, i) in ge.clone().enumerate() {
        for (b, j) in ge.clone().enumerate() {
            stats.prior[(i, j)] = prior[a][b] * scale;
        }
    }
    stats
}

/// Least rows in a (height, tilt) cell for its own variance estimate.
const MIN_CELL_ROWS: usize = 50;

/// Weights per residual entry for the second selection pass (feasible
/// generalized least squares): 1 / noise floor of the channel, divided by
/// the RMS (in noise floors) that the pass-1 fit leaves in the row's
/// (height, tilt) cell when that exceeds 1.
///
/// Why: near the ground the rotor thrust is unsteady (the paper measures
/// strong fluctuation), so the residual there is noisier than the sensor
/// floor. In closed loop the controller answers those random torques, so
/// any regressor built from the flown commands correlates with them; left
/// at full weight they would let, for example, an inertia error "explain"
/// part of the noise. Down-weighting noisy cells (never up-weighting) keeps
/// the selection about the systematic part.
fn entry_weights(
    prep: &Prepared,
    channel_weights: &[f64; 6],
    columns: &effects::Columns,
    idx: &[usize],
    theta: &DVector<f64>,
    fit_rows: &[usize],
) -> Vec<f64> {
    let cell = |k: usize| {
        let e = &prep.env[k];
        let h = locate::HEIGHT_EDGES
            .windows(2)
            .position(|w| e.height >= w[0] && e.height < w[1]);
        let v = locate::VARPHI_EDGES
            .windows(2)
            .position(|w| e.varphi.to_degrees() >= w[0] && e.varphi.to_degrees() < w[1]);
        h.zip(v)
            .map(|(h, v)| h * (locate::VARPHI_EDGES.len() - 1) + v)
    };
    let cells = (locate::HEIGHT_EDGES.len() - 1) * (locate::VARPHI_EDGES.len() - 1);
    let mut sq = vec![[0.0; 6]; cells];
    let mut rows = vec![0usize; cells];
    for &k in fit_rows {
        let Some(c) = cell(k) else { continue };
        rows[c] += 1;
        for ch in 0..6 {
            let i = 6 * k + ch;
            let fitted: f64 = idx
                .iter()
                .enumerate()
                .map(|(a, &j)| theta[a] * columns.data[j][i])
                .sum();
            let r = (columns.resid[i] - fitted) * channel_weights[ch];
            sq[c][ch] += r * r;
        }
    }
    let mut weights: Vec<f64> = (0..6 * prep.n).map(|i| channel_weights[i % 6]).collect();
    for &k in fit_rows {
        let Some(c) = cell(k) else { continue };
        if rows[c] < MIN_CELL_ROWS {
            continue;
        }
        for ch in 0..6 {
            let rms = (sq[c][ch] / rows[c] as f64).sqrt();
            weights[6 * k + ch] /= rms.max(1.0);
        }
    }
    weights
}

/// Runs the whole analysis.
pub fn explain(
    rec: &Recording,
    robot: &RobotConfig,
    opts: &Options,
) -> Result<Explanation, ExplainError> {
    let clock = std::time::Instant::now();
    let mut timings = Vec::new();
    let lap = |name: &str, timings: &mut Vec<(String, f64)>| {
        timings.push((name.to_string(), clock.elapsed().as_secs_f64()));
    };
    let progress = Progress::new(opts.progress);
    progress.step("residuals");
    let prep = Prepared::new(rec, robot)?;
    let channel_weights = prep.floor.map(|f| 1.0 / f);
    let mut weights: Vec<f64> = (0..6 * prep.n).map(|i| channel_weights[i % 6]).collect();
    let (seg_of, nseg) = select::segments(&prep);
    let fit_rows: Vec<usize> = prep.fit_rows().collect();
    lap("residuals", &mut timings);

    // Motor lag: profile the time constant by held-out error with every
    // other candidate in the model.
    progress.step("regressors");
    let base = build_columns(&prep, rec, &Knobs::default(), &prep.nominal);
    let layout = base.layout.clone();
    let lag_c = layout.columns(Effect::MotorLag).start;
    let others: Vec<usize> = (0..layout.total).filter(|&c| c != lag_c).collect();
    let cols: Vec<&[f64]> = others.iter().map(|&c| base.data[c].as_slice()).collect();
    let base_stats = Stats::build(&cols, &base.resid, &weights, &seg_of, nseg);
    let all_idx: Vec<usize> = (0..others.len()).collect();
    let active = vec![true; nseg];
    lap("regressors", &mut timings);
    progress.step("motor lag profile");
    let taus: Vec<f64> = (0..12).map(|i| 0.004 * (1.4_f64).powi(i)).collect();
    let mut profile = vec![(0.0, base_stats.cv(&all_idx, &active))];
    for &tau in &taus {
        let col = lag_column(&prep, rec, tau);
        let mut cross = vec![DVector::zeros(others.len()); nseg];
        let mut own = vec![0.0; nseg];
        let mut own_y = vec![0.0; nseg];
        for &k in &fit_rows {
            let Some(s) = seg_of[k] else { continue };
            for c in 0..6 {
                let i = 6 * k + c;
                let w2 = weights[i] * weights[i];
                let l = col[i];
                if l == 0.0 {
                    continue;
                }
                own[s] += l * l * w2;
                own_y[s] += l * base.resid[i] * w2;
                for (j, cj) in cols.iter().enumerate() {
                    cross[s][j] += l * cj[i] * w2;
                }
            }
        }
        let st = base_stats.with_fixed_term(&cross, &own, &own_y);
        profile.push((tau, st.cv(&all_idx, &active)));
    }
    drop(cols);
    drop(base);
    let best = profile
        .iter()
        .copied()
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .unwrap_or((0.0, 0.0));
    // Parabolic refinement in log tau around the best grid point.
    let mut tau_star = best.0;
    if let Some(i) = profile.iter().position(|p| p.0 == best.0) {
        if i >= 2 && i + 1 < profile.len() {
            let (x0, x1, x2) = (
                profile[i - 1].0.ln(),
                profile[i].0.ln(),
                profile[i + 1].0.ln(),
            );
            let (y0, y1, y2) = (profile[i - 1].1, profile[i].1, profile[i + 1].1);
            let d = (x0 - x1) * (x0 - x2) * (x1 - x2);
            let a = (x2 * (y1 - y0) + x1 * (y0 - y2) + x0 * (y2 - y1)) / d;
            let b = (x2 * x2 * (y0 - y1) + x1 * x1 * (y2 - y0) + x0 * x0 * (y1 - y2)) / d;
            if a > 0.0 {
                tau_star = (-b / (2.0 * a)).clamp(x0, x2).exp();
            }
        }
    }
    if tau_star == 0.0 {
        tau_star = taus[0];
    }
    lap("motor lag profile", &mut timings);

    // All candidates with the lag column at tau*.
    progress.step("selection");
    let mut knobs = Knobs {
        tau: tau_star,
        wind: [0.0; 2],
    };
    // Two passes: the mass-property columns need the acceleration the
    // fitted model predicts (pass 1 uses the nominal model's).
    let mut accel = prep.nominal.clone();
    let mut columns = build_columns(&prep, rec, &knobs, &accel);
    let mut stats = stats_of(&columns, &weights, &seg_of, nseg);
    let candidates = Effect::ALL.to_vec();
    let (mut chosen, mut steps) = select::select(&stats, &layout, &candidates, &active);
    if !chosen.is_empty() {
        let idx = select::columns_for(&layout, &chosen);
        let theta = stats.solve(&idx, &|_| true);
        for k in 0..prep.n {
            if !prep.fit[k] {
                continue;
            }
            for c in 0..6 {
                let i = 6 * k + c;
                accel[i] += idx
                    .iter()
                    .enumerate()
                    .map(|(a, &j)| theta[a] * columns.data[j][i])
                    .sum::<f64>();
            }
        }
        weights = entry_weights(&prep, &channel_weights, &columns, &idx, &theta, &fit_rows);
        drop(columns);
        columns = build_columns(&prep, rec, &knobs, &accel);
        stats = stats_of(&columns, &weights, &seg_of, nseg);
        (chosen, steps) = select::select(&stats, &layout, &candidates, &active);
    }
    lap("selection", &mut timings);
    progress.step("stability");
    let confidence = select::stability(&stats, &layout, &candidates, opts.seed);
    lap("stability", &mut timings);

    // Wind is defined relative to drag.
    if chosen.contains(&Effect::Wind) && !chosen.contains(&Effect::Drag) {
        chosen.push(Effect::Drag);
    }
    chosen.sort();
    // Refine the wind in the drag regressors (body drag is quadratic in it).
    progress.step("final fit");
    if chosen.contains(&Effect::Wind) {
        for _ in 0..3 {
            let (idx, theta, _) = select::fit_with_uncertainty(&stats, &layout, &chosen);
            let phys = Physical::from_theta(&layout, &chosen, &idx, &theta, tau_star);
            let w = phys.wind.unwrap_or([0.0; 2]);
            let kr = phys.drag.map_or(0.0, |d| d[0]);
            if kr <= 1e-3 {
                break;
            }
            knobs.wind = [knobs.wind[0] + w[0], knobs.wind[1] + w[1]];
            drop(columns);
            columns = build_columns(&prep, rec, &knobs, &accel);
            stats = stats_of(&columns, &weights, &seg_of, nseg);
        }
    }
    let (idx, theta, sd) = select::fit_with_uncertainty(&stats, &layout, &chosen);
    let mut phys = Physical::from_theta(&layout, &chosen, &idx, &theta, tau_star);
    if let Some(w) = phys.wind.as_mut() {
        w[0] += knobs.wind[0];
        w[1] += knobs.wind[1];
    }
    lap("final fit", &mut timings);

    // Held-out residuals: each fold predicted by the fit on the others.
    let entries = stats.entries_in(&active).max(1) as f64;
    let mut after = columns.resid.clone();
    let mut fold_theta = Vec::new();
    for f in 0..select::FOLDS {
        let th = stats.solve(&idx, &|s| fold_of(s) != f);
        fold_theta.push(th);
    }
    for &k in &fit_rows {
        let Some(s) = seg_of[k] else { continue };
        let th = &fold_theta[fold_of(s)];
        for c in 0..6 {
            let i = 6 * k + c;
            let mut pred = 0.0;
            for (a, &j) in idx.iter().enumerate() {
                pred += th[a] * columns.data[j][i];
            }
            after[i] -= pred;
        }
    }

    // Locate before and after.
    progress.step("locate");
    let loc_before = locate::locate(&prep, &prep.resid, &fit_rows);
    let loc_after = locate::locate(&prep, &after, &fit_rows);
    let region = loc_before.region_mask(&prep);
    let rms_before = rms_table(&prep, &prep.resid, &fit_rows, &region, &loc_before.channels);
    let rms_after = rms_table(&prep, &after, &fit_rows, &region, &loc_before.channels);
    lap("locate", &mut timings);

    // Effect reports: parameters, confidence, gains, indistinguishable pairs.
    let cv_sel = stats.cv(&idx, &active);
    let mut reports = Vec::new();
    let mut pairs: Vec<(String, String)> = Vec::new();
    for &e in &candidates {
        let selected = chosen.contains(&e);
        let conf = confidence.iter().find(|c| c.0 == e).map_or(0.0, |c| c.1);
        let gain = if selected {
            let rest: Vec<Effect> = chosen.iter().copied().filter(|x| *x != e).collect();
            (stats.cv(&select::columns_for(&layout, &rest), &active) - cv_sel) / entries
        } else {
            let mut more = chosen.clone();
            more.push(e);
            (cv_sel - stats.cv(&select::columns_for(&layout, &more), &active)) / entries
        };
        let mut indist = Vec::new();
        if selected {
            let rest: Vec<Effect> = chosen.iter().copied().filter(|x| *x != e).collect();
            let without = stats.cv(&select::columns_for(&layout, &rest), &active);
            for &f in &candidates {
                if chosen.contains(&f) {
                    continue;
                }
                let mut swapped = rest.clone();
                swapped.push(f);
                let cv_swap = stats.cv(&select::columns_for(&layout, &swapped), &active);
                // The swap recovers at least 90 % of what e explains.
                if without - cv_swap >= 0.9 * (without - cv_sel) && without - cv_sel > 0.0 {
                    indist.push(f.name().to_string());
                    pairs.push((e.name().to_string(), f.name().to_string()));
                }
            }
        }
        // Parameters: for selected effects from the final fit; for rejected
        // ones, what a fit with them added would give (for the record).
        let (pidx, ptheta, psd) = if selected {
            (idx.clone(), theta.clone(), sd.clone())
        } else {
            let mut more = chosen.clone();
            more.push(e);
            select::fit_with_uncertainty(&stats, &layout, &more)
        };
        let coef = |c: usize| -> (f64, f64) {
            pidx.iter()
                .position(|i| *i == c)
                .map_or((0.0, 0.0), |p| (ptheta[p], psd[p]))
        };
        let cols = layout.columns(e);
        let names = e.coefficient_names();
        let mut parameters = Vec::new();
        match e {
            Effect::MotorLag => {
                let (c, cs) = coef(cols.start);
                parameters.push(Parameter {
                    name: "time_constant".into(),
                    value: tau_star,
                    std: None,
                    unit: "s".into(),
                });
                parameters.push(Parameter {
                    name: "lag_term_scale".into(),
                    value: c,
                    std: Some(cs),
                    unit: "1 (1 = consistent)".into(),
                });
            }
            Effect::Wind => {
                let kr = coef(layout.columns(Effect::Drag).start).0;
                for (j, axis) in ["x", "y"].iter().enumerate() {
                    let (c, cs) = coef(cols.start + j);
                    let (v, s) = if kr.abs() > 1e-3 {
                        (
                            c / kr + knobs.wind[j] * f64::from(u8::from(selected)),
                            cs / kr.abs(),
                        )
                    } else {
                        (0.0, f64::NAN)
                    };
                    parameters.push(Parameter {
                        name: format!("steady_{axis}"),
                        value: v,
                        std: s.is_finite().then_some(s),
                        unit: "m/s (NED)".into(),
                    });
                }
            }
            Effect::BatterySag => {
                let (c, cs) = coef(cols.start);
                let k = 3600.0 * BATTERY_CAPACITY_WH / BATTERY_FULL_POWER_W;
                parameters.push(Parameter {
                    name: "sag".into(),
                    value: c * k,
                    std: Some(cs * k),
                    unit: format!("thrust fraction at {BATTERY_CAPACITY_WH} Wh drawn at {BATTERY_FULL_POWER_W} W per rotor"),
                });
            }
            Effect::GroundEffect => {
                for (j, c) in cols.clone().enumerate() {
                    let (v, s) = coef(c);
                    parameters.push(Parameter {
                        name: names[j].clone(),
                        value: v,
                        std: Some(s),
                        unit: if j == 16 { "m^2".into() } else { "1".into() },
                    });
                }
            }
            _ => {
                let units = match e {
                    Effect::Drag => vec!["N/(m/s)", "m^2", "m^2", "m^2"],
                    Effect::ComOffset => vec!["m", "m"],
                    _ => vec!["1"],
                };
                let pnames: Vec<String> = match e {
                    Effect::Drag => vec![
                        "rotor_drag".into(),
                        "body_cd_area_x".into(),
                        "body_cd_area_y".into(),
                        "body_cd_area_z".into(),
                    ],
                    Effect::ComOffset => vec!["offset_x".into(), "offset_y".into()],
                    Effect::ThrustScale => vec!["scale_minus_one".into()],
                    Effect::InertiaError => vec!["inertia_scale_minus_one".into()],
                    Effect::MassError => vec!["mass_scale_minus_one".into()],
                    _ => names.clone(),
                };
                for (j, c) in cols.clone().enumerate() {
                    let (v, s) = coef(c);
                    parameters.push(Parameter {
                        name: pnames[j].clone(),
                        value: v,
                        std: Some(s),
                        unit: units[j].into(),
                    });
                }
            }
        }
        reports.push(EffectReport {
            name: e.name().into(),
            physics: e.physics().into(),
            selected,
            confidence: conf,
            heldout_gain: gain,
            parameters,
            indistinguishable_from: indist,
        });
    }
    reports.sort_by(|a, b| {
        b.selected
            .cmp(&a.selected)
            .then(b.confidence.total_cmp(&a.confidence))
            .then(b.heldout_gain.total_cmp(&a.heldout_gain))
    });

    // Ground-effect grid (the plant's surface of the fitted file).
    let mut grid = Vec::new();
    let ge_fold: Vec<Option<GroundEffect>> = (0..select::FOLDS)
        .map(|f| {
            Physical::from_theta(&layout, &chosen, &idx, &fold_theta[f], tau_star)
                .ge_config()
                .map(|c| GroundEffect::new(&c))
        })
        .collect();
    let ge_all = phys.ge_config().map(|c| GroundEffect::new(&c));
    let min_rows = (0.5 / prep.dt).ceil() as usize;
    for &vd in &GRID_TILTS_DEG {
        for &h in &GRID_HEIGHTS {
            let count = fit_rows
                .iter()
                .filter(|&&k| {
                    (prep.env[k].height - h).abs() <= 0.05
                        && (prep.env[k].varphi.to_degrees() - vd).abs() <= 3.0
                })
                .count();
            let v = vd.to_radians();
            let gain = ge_all.as_ref().map_or(0.0, |g| g.gain(h, v).mean);
            let folds: Vec<f64> = ge_fold
                .iter()
                .map(|g| g.as_ref().map_or(0.0, |g| g.gain(h, v).mean))
                .collect();
            let k = folds.len() as f64;
            let mean = folds.iter().sum::<f64>() / k;
            let std =
                ((k - 1.0) / k * folds.iter().map(|x| (x - mean).powi(2)).sum::<f64>()).sqrt();
            grid.push(GridPoint {
                height_m: h,
                varphi_deg: vd,
                gain,
                std,
                covered: count >= min_rows,
            });
        }
    }

    // The plant file, checked by the plant's own loader.
    let header = format!(
        "{} ({} rows), effects: {}",
        rec.source.display(),
        rec.samples.len(),
        if chosen.is_empty() {
            "none".to_string()
        } else {
            chosen
                .iter()
                .map(|e| e.name())
                .collect::<Vec<_>>()
                .join(", ")
        }
    );
    let convention = robot.arm.inertia_convention;
    let toml_text = phys.toml(convention, &header);
    let fitted_cfg = PlantConfig::from_toml_str(&toml_text, "fitted_effects.toml")
        .map_err(|e| ExplainError::Fit(e.to_string()))?;
    let fold_cfgs: Vec<PlantConfig> = fold_theta
        .iter()
        .map(|th| {
            let mut p = Physical::from_theta(&layout, &chosen, &idx, th, tau_star);
            if let Some(w) = p.wind.as_mut() {
                w[0] += knobs.wind[0];
                w[1] += knobs.wind[1];
            }
            PlantConfig::from_toml_str(&p.toml(convention, "fold"), "fitted_effects.toml (fold)")
                .unwrap_or_else(|_| fitted_cfg.clone())
        })
        .collect();

    // Multi-step prediction before and after (held-out folds).
    progress.step("replay");
    let duration = prep.t[prep.n - 1] - prep.t[0];
    let spacing = (duration / opts.max_replay_starts.max(1) as f64).max(HORIZON);
    let starts = replay::start_rows(&prep, HORIZON, spacing);
    let mut nominal_cfg = PlantConfig::ideal();
    nominal_cfg.arm_inertia_convention = convention;
    let multistep_before = replay::replay(
        rec,
        &prep,
        robot,
        &starts,
        &|_| nominal_cfg.clone(),
        &|_| 0.0,
    );
    let lag_on = chosen.contains(&Effect::MotorLag);
    let multistep_after = replay::replay(
        rec,
        &prep,
        robot,
        &starts,
        &|k| seg_of[k].map_or_else(|| fitted_cfg.clone(), |s| fold_cfgs[fold_of(s)].clone()),
        &|_| if lag_on { tau_star } else { 0.0 },
    );
    lap("replay", &mut timings);

    // Verdict.
    let high: Vec<&EffectReport> = reports
        .iter()
        .filter(|r| r.selected && r.confidence >= HIGH_CONFIDENCE)
        .collect();
    let mismatch_found = !chosen.is_empty() || !loc_before.located.is_empty();
    let verdict = if !mismatch_found {
        "no significant mismatch: the nominal model explains the recording to its noise floor"
            .to_string()
    } else if chosen.is_empty() {
        "mismatch located, but no candidate effect explains it (see the located regions)"
            .to_string()
    } else {
        format!(
            "mismatch found; explained by {}{}",
            reports
                .iter()
                .filter(|r| r.selected)
                .map(|r| {
                    if r.indistinguishable_from.is_empty() {
                        format!("{} (confidence {:.2})", r.name, r.confidence)
                    } else {
                        format!(
                            "{} (confidence {:.2}; this data cannot tell it apart from {})",
                            r.name,
                            r.confidence,
                            r.indistinguishable_from.join(", ")
                        )
                    }
                })
                .collect::<Vec<_>>()
                .join(", "),
            if high.is_empty() {
                "; no effect with high confidence"
            } else {
                ""
            }
        )
    };

    // Series for the time-series plot: the channel with the largest located excess.
    let ch = loc_before
        .located
        .iter()
        .max_by(|a, b| a.rms_ratio.total_cmp(&b.rms_ratio))
        .and_then(|l| CHANNELS.iter().position(|c| *c == l.channel))
        .unwrap_or(2);
    // A 20 s window where the nominal residual of that channel is largest
    // (the whole recording when it is shorter than 30 s).
    let (w0, w1) = if duration > 30.0 {
        let t0 = prep.t[0];
        let nb = duration.ceil() as usize + 1;
        let mut per_s = vec![0.0; nb];
        for &k in &fit_rows {
            let r = prep.resid[6 * k + ch];
            per_s[((prep.t[k] - t0) as usize).min(nb - 1)] += r * r;
        }
        let best = (0..nb.saturating_sub(20))
            .max_by(|&a, &b| {
                per_s[a..a + 20]
                    .iter()
                    .sum::<f64>()
                    .total_cmp(&per_s[b..b + 20].iter().sum::<f64>())
            })
            .unwrap_or(0);
        (t0 + best as f64, t0 + best as f64 + 20.0)
    } else {
        (f64::NEG_INFINITY, f64::INFINITY)
    };
    let mut ts = Vec::new();
    let (mut sm, mut sn, mut sf) = (Vec::new(), Vec::new(), Vec::new());
    for &k in fit_rows
        .iter()
        .filter(|&&k| prep.t[k] >= w0 && prep.t[k] <= w1)
    {
        ts.push(prep.t[k]);
        sm.push(prep.meas[6 * k + ch]);
        sn.push(prep.nominal[6 * k + ch]);
        sf.push(prep.meas[6 * k + ch] - after[6 * k + ch]);
    }
    let mut notes = Vec::new();
    let used_segments = (0..nseg).filter(|&s| stats.entries[s] > 0).count();
    if used_segments < 10 {
        notes.push(format!(
            "only {used_segments} segments of airborne data (about {:.0} s): held-out \
             scores and confidences rest on few segments; record longer for firm answers",
            fit_rows.len() as f64 * prep.dt
        ));
    }
    if prep.contact_rows > 0 {
        notes.push(format!(
            "{} rows at the ground left out (ground contact is not a candidate effect)",
            prep.contact_rows
        ));
    }
    progress.finish();
    lap("total", &mut timings);
    Ok(Explanation {
        source: rec.source.display().to_string(),
        rows: rec.samples.len(),
        rows_used: fit_rows.len(),
        rate_hz: 1.0 / prep.dt,
        duration_s: duration,
        window_samples: 2 * prep.half + 1,
        ignored_columns: rec.ignored_columns.clone(),
        skipped_nonfinite: rec.skipped_nonfinite,
        skipped_time: rec.skipped_time,
        contact_rows: prep.contact_rows,
        noise_floor: prep.floor,
        mismatch_found,
        verdict,
        located: loc_before.located.clone(),
        located_channels: loc_before
            .channels
            .iter()
            .map(|&c| CHANNELS[c].to_string())
            .collect(),
        effects: reports,
        selection_steps: steps,
        indistinguishable: pairs,
        heldout_rms_before: rms_before,
        heldout_rms_after: rms_after,
        multistep_before,
        multistep_after,
        ground_effect_gain_grid: grid,
        motor_lag_profile: profile.iter().map(|(t, c)| (*t, c / entries)).collect(),
        fitted_effects_toml: toml_text,
        location_before: Some(loc_before),
        location_after: Some(loc_after),
        series: Some(Series {
            channel: ch,
            t: ts,
            recording: sm,
            nominal: sn,
            fitted: sf,
        }),
        timings_s: timings,
        notes,
    })
}

impl Explanation {
    /// The report of an effect by name.
    pub fn effect(&self, name: &str) -> Option<&EffectReport> {
        self.effects.iter().find(|e| e.name == name)
    }

    /// A parameter of an effect by name.
    pub fn parameter(&self, effect: &str, name: &str) -> Option<f64> {
        self.effect(effect)?
            .parameters
            .iter()
            .find(|p| p.name == name)
            .map(|p| p.value)
    }

    /// Selected effects in rank order.
    pub fn selected(&self) -> Vec<&str> {
        self.effects
            .iter()
            .filter(|e| e.selected)
            .map(|e| e.name.as_str())
            .collect()
    }

    /// Effects other than `expected` that are selected with high confidence
    /// (>= [`HIGH_CONFIDENCE`]), in rank order.
    pub fn confidently_claimed_besides(&self, expected: &[&str]) -> Vec<&str> {
        self.effects
            .iter()
            .filter(|e| e.selected && e.confidence >= HIGH_CONFIDENCE)
            .map(|e| e.name.as_str())
            .filter(|n| !expected.contains(n))
            .collect()
    }
}
