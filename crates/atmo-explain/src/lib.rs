//! atmo-explain: the discrepancy finder (`atmo-sim explain`). Where do a recording and the
//! nominal model disagree, which missing physics explains it, and how much
//! better does the model get with it.
//!
//! 1. **Residuals** ([`data`]): the nominal model (the robot file, nothing
//!    else) is evaluated at every recorded state with the recorded commands
//!    and tilt. Measured accelerations come from a Savitzky-Golay
//!    differentiator (window about 0.1 s from the data rate) of the
//!    recorded velocity, its band below 3 Hz first taken from the positions
//!    ([`velocity`]: a velocity estimate's drift is not a force); the model
//!    side goes through the same filter (integrated, then differentiated),
//!    so the residual of a right model is noise. Multi-step prediction:
//!    atmo-plant's plant started from the recorded state and driven by the
//!    recorded commands for 0.5 s ([`replay`]).
//! 2. **Locate** ([`regions`]): channels x bins of hub height, tilt, speed,
//!    thrust, time, command rate and the (height, tilt) map, each tested
//!    against the noise floor (batch-means z tests, Bonferroni).
//! 3. **Name the physics** ([`effects`], [`selection`]): eleven candidate
//!    effects with physical parameters, linear in their coefficients, each
//!    held inside its physical range by an active set (motor lag: time
//!    constant profiled by held-out error; steady wind: profiled before the
//!    selection on the force channels with the drag and the thrust
//!    calibration, `stages::wind`). Forward-backward
//!    selection on held-out whole segments (5 folds), inclusion frequency
//!    over random halves of the segments as confidence, delete-a-segment
//!    jackknife covariances (two parameters correlated at |rho| >= 0.9 are
//!    one combined finding), and a swap test for effects the data cannot
//!    tell apart.
//! 4. **Fit and validate** ([`stages`]): the fitted effects as a plant file
//!    (`fitted_effects.toml`, the plant's `[effects.<name>]` sections),
//!    replayed to compare held-out residual RMS and multi-step error before
//!    and after.
//! 5. **Outputs** ([`output`]): `report.md`, `fitted_effects.toml`,
//!    `explain.json`, PNG plots.
//!
//! [`explain`] runs these as the [`stages`] residuals, locate, select, fit,
//! validate and report, each a function with its own input and output
//! types; progress goes to a callback ([`explain_with_progress`]), the
//! caller draws it.
//!
//! Input format: docs/recording_format.md ([`recording`]).

pub mod cli;
pub mod data;
pub mod effects;
mod explanation;
mod noise;
pub mod regions;

pub mod output;
pub mod parameter;
mod physical;
pub mod recording;
pub mod replay;
pub mod selection;
pub mod stages;
pub mod synth;
pub mod velocity;

use std::path::PathBuf;
use std::time::Instant;

use atmo_core::RobotConfig;

pub use explanation::{
    EffectReport, Explanation, GridPoint, Parameter, RmsTable, Series, WindSpeed,
};
use recording::{Recording, contract, plausible};
pub use stages::Analysis;
use stages::{
    BaseRegressors, Residuals, accept_effects, fit_effects, locate_mismatch, profile_motor_lag,
    report, select_effects, validate,
};

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
    /// The robot file cannot be read or is not valid (the message names
    /// the file, and the key or line).
    #[error(transparent)]
    Robot(#[from] atmo_core::CoreError),
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
    /// Most multi-step starts (spread over the recording).
    pub max_replay_starts: usize,
    /// Wall-clock budget of the whole analysis, s: when exceeded the
    /// analysis still finishes, and a note says by how much and which
    /// stage took longest.
    pub budget_s: f64,
}

/// Default [`Options::budget_s`]: about four times the analysis of a
/// recording at the row limit ([`recording::MAX_ROWS`]) on one core.
pub const DEFAULT_BUDGET_S: f64 = 300.0;

impl Default for Options {
    fn default() -> Self {
        Self {
            seed: 1,
            max_replay_starts: 240,
            budget_s: DEFAULT_BUDGET_S,
        }
    }
}

/// Where a running analysis is: `stage` started after `done` of `total`
/// stages finished (the last report has `done == total`, stage `"done"`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Progress {
    pub stage: &'static str,
    pub done: usize,
    pub total: usize,
}

/// The progress steps of [`explain_with_progress`], in order; also the
/// names of the timings in `explain.json`.
pub const STEPS: [&str; 10] = [
    "residuals",
    "locate",
    "regressors",
    "motor lag profile",
    "selection",
    "stability",
    "final fit",
    "acceptance",
    "validate",
    "report",
];

/// Reports each step to the caller and records when it ended.
struct Tracker<'a> {
    report: &'a mut dyn FnMut(Progress),
    clock: Instant,
    done: usize,
    timings: Vec<(String, f64)>,
}

impl<'a> Tracker<'a> {
    fn new(report: &'a mut dyn FnMut(Progress)) -> Self {
        Self {
            report,
            clock: Instant::now(),
            done: 0,
            timings: Vec::new(),
        }
    }

    /// Runs step `stage` (one of [`STEPS`]).
    fn step<T>(&mut self, stage: &'static str, run: impl FnOnce() -> T) -> T {
        (self.report)(Progress {
            stage,
            done: self.done,
            total: STEPS.len(),
        });
        let out = run();
        self.done += 1;
        self.lap(stage);
        out
    }

    fn lap(&mut self, name: &str) {
        self.timings
            .push((name.to_string(), self.clock.elapsed().as_secs_f64()));
    }
}

/// The note of an analysis whose `timings` (cumulative, the last one the
/// total) went over `budget_s`, naming the slowest stage.
fn over_budget(timings: &[(String, f64)], budget_s: f64) -> Option<String> {
    let total = timings.last()?.1;
    if total <= budget_s {
        return None;
    }
    let mut slowest = ("", 0.0);
    let mut before = 0.0;
    for (stage, at) in timings.iter().filter(|(s, _)| s != "total") {
        if at - before > slowest.1 {
            slowest = (stage.as_str(), at - before);
        }
        before = *at;
    }
    Some(format!(
        "the analysis took {total:.3} s, over its wall-clock budget of {budget_s} s \
         (--budget); its slowest stage was `{}` ({:.3} s)",
        slowest.0, slowest.1
    ))
}

/// Why the recorded velocity was analysed as it is.
fn velocity_note(c: &velocity::VelocityCorrection) -> String {
    format!(
        "velocity analysed as recorded: its band below {} Hz taken from the positions would \
         change it by {:.3} / {:.3} / {:.3} m/s RMS (x / y / z), more than a velocity sensor's \
         drift ({} m/s): the positions and the velocity disagree about the motion (another \
         frame, a jump, a time offset?)",
        c.below_hz,
        c.rms[0],
        c.rms[1],
        c.rms[2],
        velocity::MAX_CORRECTION_RMS
    )
}

/// The reader contract on a recording about to be analysed
/// (`recording::contract`): the time axis checked, the rows outside their
/// plausible ranges (in-memory recordings; the file readers already did) and
/// the neighbour check's glitches dropped and counted. `None` when nothing
/// was dropped (no copy made).
fn screen(rec: &Recording, robot: &RobotConfig) -> Result<Option<Recording>> {
    let fail = |message: String| ExplainError::Input {
        file: rec.source.clone(),
        message,
    };
    contract::check_time_axis(rec).map_err(&fail)?;
    let mut copy = None;
    if !rec.samples.iter().all(plausible::is_plausible) {
        let mut c = rec.clone();
        let (keep, dropped) =
            plausible::screen(&c.samples, |i| contract::label(rec, i)).map_err(&fail)?;
        contract::retain(&mut c, &keep);
        c.outliers.rows += dropped.rows;
        c.outliers.columns.extend(dropped.columns);
        copy = Some(c);
    }
    let bounds = contract::JumpBounds::of(robot);
    let current = copy.as_ref().unwrap_or(rec);
    if let Some((keep, found)) = contract::find_jumps(current, &bounds) {
        let mut c = copy.take().unwrap_or_else(|| rec.clone());
        contract::retain(&mut c, &keep);
        c.jumps.rows += found.rows;
        c.jumps.columns.extend(found.columns);
        copy = Some(c);
    }
    Ok(copy)
}

/// Runs the analysis's stages on a recording (no report).
pub fn analyse(rec: &Recording, robot: &RobotConfig, opts: &Options) -> Result<Analysis> {
    analyse_tracked(rec, robot, opts, &mut Tracker::new(&mut |_| {}))
}

/// The stages, each timed and announced by `t`.
fn analyse_tracked(
    rec: &Recording,
    robot: &RobotConfig,
    opts: &Options,
    t: &mut Tracker,
) -> Result<Analysis> {
    if rec.samples.len() > recording::MAX_ROWS {
        return Err(ExplainError::Input {
            file: rec.source.clone(),
            message: recording::row_limit_error(&format!("{} rows", rec.samples.len())),
        });
    }
    let screened = screen(rec, robot)?;
    let rec = screened.as_ref().unwrap_or(rec);
    let (corrected, velocity_correction) = velocity::from_positions(rec);
    let rec = corrected.into_owned();
    let res = t.step("residuals", || Residuals::new(&rec, robot))?;
    let mismatch = t.step("locate", || locate_mismatch(&res));
    let base = t.step("regressors", || BaseRegressors::new(&res, &rec));
    let lag = t.step("motor lag profile", || profile_motor_lag(&res, &base));
    drop(base);
    let selection = t.step("selection", || select_effects(&res, &rec, lag.tau));
    let steps = selection.steps.clone();
    let confidence = t.step("stability", || selection.stability(opts.seed));
    let fit = t.step("final fit", || fit_effects(&res, &rec, selection));
    let replayed = replay::within_flown_tilts(robot, &rec);
    let (fit, decisions) = t.step("acceptance", || {
        accept_effects(&rec, &replayed, &res, fit, opts.max_replay_starts)
    })?;
    let validation = t.step("validate", || {
        validate(
            &rec,
            &replayed,
            &res,
            &mismatch,
            &fit,
            opts.max_replay_starts,
        )
    })?;
    Ok(Analysis {
        rec,
        velocity_correction,
        replayed,
        res,
        mismatch,
        lag,
        steps,
        confidence,
        fit,
        decisions,
        validation,
    })
}

/// Runs the whole analysis and reports it.
pub fn explain(rec: &Recording, robot: &RobotConfig, opts: &Options) -> Result<Explanation> {
    explain_with_progress(rec, robot, opts, &mut |_| {})
}

/// Runs the whole analysis, telling `progress` when each step starts.
pub fn explain_with_progress(
    rec: &Recording,
    robot: &RobotConfig,
    opts: &Options,
    progress: &mut dyn FnMut(Progress),
) -> Result<Explanation> {
    let mut t = Tracker::new(progress);
    let a = analyse_tracked(rec, robot, opts, &mut t)?;
    let mut ex = t.step("report", || report(&a));
    ex.velocity_from_positions = a.velocity_correction;
    if !a.velocity_correction.applied {
        ex.notes.push(velocity_note(&a.velocity_correction));
    }
    t.lap("total");
    (t.report)(Progress {
        stage: "done",
        done: t.done,
        total: STEPS.len(),
    });
    if let Some(note) = over_budget(&t.timings, opts.budget_s) {
        ex.notes.push(note);
    }
    ex.timings_s = t.timings;
    Ok(ex)
}
