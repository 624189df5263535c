//! What the analysis found: the [`Explanation`] and its parts (serialized
//! into `explain.json` by [`crate::output`]).

use serde::Serialize;

use crate::HIGH_CONFIDENCE;
use crate::effects::Effect;
use crate::parameter::Param;
use crate::regions::{self, Location};
use crate::replay::ReplayError;
use crate::selection;

/// One parameter with its uncertainty.
#[derive(Debug, Clone, Serialize)]
pub struct Parameter {
    pub name: Param,
    pub value: f64,
    /// One standard deviation (delete-a-segment jackknife; null if unknown).
    pub std: Option<f64>,
    pub unit: String,
    /// Inside its physical range (not at a bound) with an uncertainty below
    /// its value (docs/explain.md, physical ranges); false: the value is
    /// not a finding.
    pub identified: bool,
}

/// Two parameters this data cannot separate (their jackknife estimates
/// correlate at least [`crate::stages::COMBINED_CORRELATION`]): neither is a
/// finding alone; the combination `first + weight * second`, the one with
/// the smallest variance, is.
#[derive(Debug, Clone, Serialize)]
pub struct CombinedFinding {
    /// The two (`effect.parameter` in `explain.json`).
    #[serde(serialize_with = "crate::parameter::serialize_qualified")]
    pub first: Param,
    #[serde(serialize_with = "crate::parameter::serialize_qualified")]
    pub second: Param,
    /// Correlation of their estimates.
    pub correlation: f64,
    /// `-cov / var(second)`, in first's units per second's.
    pub weight: f64,
    /// `first + weight * second`, in first's unit.
    pub value: f64,
    /// `sd(first) sqrt(1 - correlation^2)`.
    pub std: f64,
    pub unit: String,
}

impl CombinedFinding {
    /// `a + 0.123 b = 0.0204 +- 0.0011 N/(m/s) (correlation -0.95)`.
    pub fn describe(&self) -> String {
        format!(
            "{} {} {:.4} {} = {:.4} +- {:.4} {} (correlation {:.2})",
            self.first.qualified(),
            if self.weight < 0.0 { "-" } else { "+" },
            self.weight.abs(),
            self.second.qualified(),
            self.value,
            self.std,
            self.unit,
            self.correlation
        )
    }
}

/// A candidate effect's verdict.
#[derive(Debug, Clone, Serialize)]
pub struct EffectReport {
    pub name: Effect,
    pub physics: String,
    /// Claimed: selected and passed the acceptance.
    pub selected: bool,
    /// Of a claimed effect only: the inclusion frequency over random
    /// halves of the segments, in [0, 1]. `None` for an effect not claimed
    /// (rejected, not identified, not selected): its `decision` says why,
    /// with the numbers, and no confidence stands beside it to read as a
    /// claim.
    pub confidence: Option<f64>,
    /// How often the selection proposed the effect (inclusion frequency
    /// over the random halves), whatever the acceptance then decided: a
    /// diagnostic of the selection, not a confidence in the effect.
    pub selection_frequency: f64,
    /// The acceptance's decision with its numbers; `None` when the
    /// selection did not propose the effect.
    pub decision: Option<Decision>,
    /// Held-out improvement (noise-floor variances per residual entry) from
    /// adding it to the selected model (or lost by removing it).
    pub heldout_gain: f64,
    pub parameters: Vec<Parameter>,
    /// Effects this one cannot be told apart from with this data.
    pub indistinguishable_from: Vec<Effect>,
    /// Physics and calibration this data cannot tell apart, reported as
    /// one finding: on a claimed calibration, the physics it stands for as
    /// well; on that physics, the claimed calibration that carries it.
    pub same_finding_as: Vec<Effect>,
    /// Pairs of parameters (one of them this effect's) the data determine
    /// only in combination.
    pub combined: Vec<CombinedFinding>,
    /// Which test decided and its numbers (physical range and
    /// identifiability, held-out residual, 0.5 s prediction).
    pub decided_by: String,
    /// Part of the nominal calibration stage (thrust scale, thrust curve,
    /// inertia, mass, centre of mass), not physics.
    pub calibration: bool,
}

impl EffectReport {
    /// One of its parameters.
    pub fn parameter(&self, param: Param) -> Option<&Parameter> {
        self.parameters.iter().find(|p| p.name == param)
    }
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
    /// Rows dropped by the outlier rule (`recording::plausible`).
    pub outliers: crate::recording::plausible::Outliers,
    /// Rows skipped because their rotation matrix was not a rotation.
    pub skipped_rotation: usize,
    /// Rows dropped by the neighbour check (`recording::contract`).
    pub jumps: crate::recording::plausible::Outliers,
    pub contact_rows: usize,
    pub noise_floor: [f64; 6],
    /// The recorded velocity's band below 3 Hz, taken from the positions.
    pub velocity_from_positions: crate::velocity::VelocityCorrection,
    pub mismatch_found: bool,
    pub verdict: String,
    pub located: Vec<regions::Located>,
    pub located_channels: Vec<String>,
    pub effects: Vec<EffectReport>,
    pub selection_steps: Vec<selection::Step>,
    pub indistinguishable: Vec<(Effect, Effect)>,
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
    /// What the flight identifies about a claimed wind's speed.
    pub wind_speed: Option<WindSpeed>,
    /// Warnings about how far the results can be trusted.
    pub notes: Vec<String>,
}

/// What the flight identifies about a claimed wind's speed.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct WindSpeed {
    /// The fitted wind's speed (m/s).
    pub speed: f64,
    /// The fitted drag law's mean force along the wind where the robot
    /// flew (N), and its slope in the wind's speed (N per m/s): what any
    /// drag law that fits the flight shares.
    pub force_n: f64,
    pub slope_n_per_mps: f64,
    /// The speed a linear drag law (`F / F'`) and a quadratic one
    /// (`2 F / F'`) put at that force and slope (m/s; NaN without a
    /// positive slope).
    pub speed_linear_law: f64,
    pub speed_quadratic_law: f64,
    /// The larger held-out RMS after the fit of the disc-plane force
    /// channels, in noise floors.
    pub misfit_floors: f64,
    /// The speed is separated from the drag coefficients: the misfit
    /// below `stages::LAW_MISFIT_FLOORS`.
    pub separable: bool,
}

impl WindSpeed {
    /// The report's note when the speed is not separated.
    pub fn note(&self) -> Option<String> {
        (!self.separable).then(|| {
            format!(
                "the wind's speed ({:.1} m/s) is not separated from the drag coefficients: \
                 the fitted drag law leaves {:.1} noise floors of held-out residual in the \
                 disc-plane force, a misfit larger than the noise, so the law's shape, which \
                 places the speed, is not established; identified: the drag force along the \
                 wind where the robot flew, {:.2} N, and its slope, {:.3} N per m/s of wind; \
                 a linear drag law puts the speed at {:.1} m/s, a quadratic one at {:.1} m/s",
                self.speed,
                self.misfit_floors,
                self.force_n,
                self.slope_n_per_mps,
                self.speed_linear_law,
                self.speed_quadratic_law
            )
        })
    }
}

impl Explanation {
    /// The report of an effect.
    pub fn effect(&self, effect: Effect) -> Option<&EffectReport> {
        self.effects.iter().find(|e| e.name == effect)
    }

    /// A parameter's value, from its effect's report.
    pub fn parameter(&self, param: Param) -> Option<f64> {
        self.effect(param.effect())?
            .parameter(param)
            .map(|p| p.value)
    }

    /// Selected effects in rank order.
    pub fn selected(&self) -> Vec<Effect> {
        self.effects
            .iter()
            .filter(|e| e.selected)
            .map(|e| e.name)
            .collect()
    }

    /// Effects other than `expected` that are selected with high confidence
    /// (>= [`HIGH_CONFIDENCE`]), in rank order.
    pub fn confidently_claimed_besides(&self, expected: &[Effect]) -> Vec<Effect> {
        self.effects
            .iter()
            .filter(|e| e.selected && e.confidence.is_some_and(|c| c >= HIGH_CONFIDENCE))
            .map(|e| e.name)
            .filter(|n| !expected.contains(n))
            .collect()
    }
}

/// Which test decided an effect's verdict (in `explain.json` as
/// `decision`, tagged by `kind`, with its numbers).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Decision {
    /// Passed both tests (multi-step velocity error at the horizon with
    /// and without it, m/s; `None` when no 0.5 s stretch exists).
    Found {
        with: Option<f64>,
        without: Option<f64>,
    },
    /// A parameter outside its physical range, or none identified.
    NotIdentified { reason: String },
    /// Physics a calibration of the robot file explains as well (swapped
    /// in for it, at least the acceptance's `SWAP_RECOVERY` of its held-out
    /// gain): with those calibrations one finding, which the model carries
    /// as the calibration (the simpler account) and the report names as
    /// both. `recovery`: the share of the physics' cross-validated gain the
    /// best of them recovers, swapped in for it.
    OneFindingWith {
        calibrations: Vec<Effect>,
        recovery: f64,
    },
    /// Lowers the one-step residual but not the 0.5 s prediction;
    /// `reduced` when judged on the model left after other rejections.
    /// Both errors are over the same starts (those both models replayed).
    RejectedByPrediction {
        with: f64,
        without: f64,
        reduced: bool,
    },
    /// The 0.5 s prediction test could not be made: of `attempted` starts
    /// the model with the effect failed on `with_failed` and the model
    /// without it on `without_failed`, leaving no start both replayed, or
    /// the model with the effect failed on more starts than without it.
    /// Not claimed: a missing prediction is not a zero error.
    PredictionFailed {
        attempted: usize,
        with_failed: usize,
        without_failed: usize,
        reduced: bool,
    },
}
