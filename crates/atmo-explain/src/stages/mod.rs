//! The stages of [`crate::explain`], each a function from the previous
//! stages' outputs to its own:
//!
//! | stage | function | output |
//! | --- | --- | --- |
//! | residuals | [`Residuals::new`] | [`Residuals`]: the prepared recording, weights, segments |
//! | locate | [`locate_mismatch`] | [`Mismatch`]: located bins, region, RMS of the nominal model |
//! | select | [`BaseRegressors::new`], [`profile_motor_lag`], [`select_effects`], [`Selection::stability`] | [`LagProfile`], [`Selection`], confidences |
//! | fit | [`fit_effects`] | [`Fit`]: coefficients, jackknife deviations, fold fits |
//! | accept | [`accept_effects`] | the [`Fit`] of the found effects, a [`Decision`] per selected effect (physical range, identifiability, 0.5 s prediction) |
//! | validate | [`validate()`] | [`Validation`]: held-out residuals, plant file, multi-step errors |
//! | report | [`report()`] | [`crate::Explanation`] |

mod accept;
mod fit;
mod locate;
mod report;
mod residuals;
mod select;
mod validate;
pub(crate) mod wind;
mod wind_speed;

#[cfg(test)]
mod tests;

pub use crate::explanation::Decision;
pub use accept::{ParamStatus, accept_effects, coefficient_bounds, param_status};
pub use fit::{Fit, SWAP_RECOVERY, fit_effects};
pub use locate::{Mismatch, locate_mismatch, rms_table};
pub use report::{
    Analysis, COMBINED_CORRELATION, effect_reports, gain_grid, notes, plot_series, report, verdict,
};
pub use residuals::Residuals;
pub use select::{BaseRegressors, LagProfile, Selection, profile_motor_lag, select_effects};
pub use validate::{Validation, validate};
pub use wind::WindProfile;
pub use wind_speed::{LAW_MISFIT_FLOORS, WIND_FORCE_CHANNELS, wind_speed};
