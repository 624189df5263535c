//! Stage 5, validate: the fitted effects judged on data they were not
//! fitted on. Held-out residuals (each fold predicted by the fit on the
//! others) located and measured like the nominal ones; the fit written as
//! a plant file and checked by the plant's own loader; multi-step
//! prediction through the plant before and after (see [`crate::replay`]).

use atmo_core::ConfigFile as _;
use atmo_core::RobotConfig;
use atmo_plant::PlantTemplate;
use atmo_plant::config::PlantConfig;

use crate::effects::Effect;
use crate::explanation::RmsTable;
use crate::recording::Recording;
use crate::regions::{self, Location};
use crate::replay::{self, ReplayError};
use crate::selection::fold_of;
use crate::stages::locate::rms_table;
use crate::stages::{Fit, Mismatch, Residuals};
use crate::{ExplainError, HORIZON, Result};

/// How the fitted model does on held-out data.
#[derive(Debug, Clone)]
pub struct Validation {
    /// Held-out residual with the fitted effects, 6 per row.
    pub after: Vec<f64>,
    /// Where the held-out residual is still beyond the noise floor.
    pub location: Location,
    /// Its RMS, in the region located before the fit.
    pub rms: RmsTable,
    /// The plant file of the fit on all data (`fitted_effects.toml`).
    pub toml: String,
    pub multistep_before: ReplayError,
    pub multistep_after: ReplayError,
}

/// Validates the fit; `max_replay_starts` bounds the multi-step starts.
pub fn validate(
    rec: &Recording,
    robot: &RobotConfig,
    res: &Residuals,
    mismatch: &Mismatch,
    fit: &Fit,
    max_replay_starts: usize,
) -> Result<Validation> {
    let prep = &res.prep;
    let after = fit.heldout_residual(res);
    let location = regions::locate(prep, &after, &res.fit_rows);
    let rms = rms_table(
        prep,
        &after,
        &res.fit_rows,
        &mismatch.region,
        &mismatch.location.channels,
    );
    let (toml, fitted_cfg, fold_cfgs) = plant_files(rec, robot, fit)?;

    // Multi-step prediction before and after (held-out folds).
    let spacing = (res.duration() / max_replay_starts.max(1) as f64).max(HORIZON);
    let starts = replay::start_rows(prep, HORIZON, spacing);
    let mut nominal_cfg = PlantConfig::ideal();
    nominal_cfg.arm_inertia_convention = robot.arm.inertia_convention;
    let nominal = PlantTemplate::new(robot, &nominal_cfg).ok();
    let before_each = replay::replay_each(rec, prep, &starts, &|_| nominal.as_ref(), &|_| 0.0);
    let lag_on = fit.chosen.contains(&Effect::MotorLag);
    let tau = fit.knobs.tau;
    let fitted = PlantTemplate::new(robot, &fitted_cfg).ok();
    let folds: Vec<Option<PlantTemplate>> = fold_cfgs
        .iter()
        .map(|c| PlantTemplate::new(robot, c).ok())
        .collect();
    let after_each = replay::replay_each(
        rec,
        prep,
        &starts,
        &|k| res.seg_of[k].map_or(fitted.as_ref(), |s| folds[fold_of(s)].as_ref()),
        &|_| if lag_on { tau } else { 0.0 },
    );
    // Before and after over the same starts; the failures of each counted.
    let (multistep_before, multistep_after) = replay::paired(&before_each, &after_each);
    Ok(Validation {
        after,
        location,
        rms,
        toml,
        multistep_before,
        multistep_after,
    })
}

/// The plant file of the fit on all data (its text and the plant's reading
/// of it), and one per fold (a fold whose file the plant refuses falls back
/// to the fit on all data).
fn plant_files(
    rec: &Recording,
    robot: &RobotConfig,
    fit: &Fit,
) -> Result<(String, PlantConfig, Vec<PlantConfig>)> {
    let header = format!(
        "{} ({} rows), effects: {}",
        rec.source.display(),
        rec.samples.len(),
        if fit.chosen.is_empty() {
            "none".to_string()
        } else {
            fit.chosen
                .iter()
                .map(|e| e.name())
                .collect::<Vec<_>>()
                .join(", ")
        }
    );
    let convention = robot.arm.inertia_convention;
    let toml = fit.physical.toml(convention, &header);
    let fitted_cfg = PlantConfig::from_toml_str(&toml, "fitted_effects.toml")
        .map_err(|e| ExplainError::Fit(e.to_string()))?;
    let fold_cfgs = (0..fit.fold_theta.len())
        .map(|f| {
            PlantConfig::from_toml_str(
                &fit.fold_physical(f).toml(convention, "fold"),
                "fitted_effects.toml (fold)",
            )
            .unwrap_or_else(|_| fitted_cfg.clone())
        })
        .collect();
    Ok((toml, fitted_cfg, fold_cfgs))
}
