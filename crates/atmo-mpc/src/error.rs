//! The one error type of atmo-mpc.
//!
//! How a solve ended is not an error: see [`crate::Outcome`]. Errors are
//! refused settings, refused parameters and calls out of order.

use atmo_core::CoreError;

/// Everything atmo-mpc can refuse.
#[derive(Debug, thiserror::Error)]
pub enum MpcError {
    /// The settings file could not be read, parsed or validated.
    #[error(transparent)]
    Config(#[from] CoreError),
    /// The requested cost preset is not in the settings file.
    #[error("unknown cost preset `{name}` (known: {known})")]
    UnknownPreset { name: String, known: String },
    /// A horizon parameter (reference, tilt, alpha) is not a finite number.
    #[error("{what} is not finite (stage {stage}, entry {entry})")]
    NonFiniteParameter {
        what: &'static str,
        stage: usize,
        entry: usize,
    },
    /// A parameter slice has the wrong length for the horizon.
    #[error("{what} has {got} entries, the horizon needs {expected}")]
    HorizonLength {
        what: &'static str,
        expected: usize,
        got: usize,
    },
    /// A parameter outside its range.
    #[error("{what} = {value} is outside [{min}, {max}]")]
    OutOfRange {
        what: &'static str,
        value: f64,
        min: f64,
        max: f64,
    },
    /// The linearization along the plan produced a non-finite number (the
    /// plan diverged). The following `feedback` flies the fallback and
    /// restarts the plan from its estimate.
    #[error(
        "linearization at stage {stage} is not finite; the plan restarts from the next estimate"
    )]
    NonFiniteLinearization { stage: usize },
    /// Clarabel refused the start-up QP or an in-place update.
    #[error("QP solver: {0}")]
    Solver(String),
    /// `feedback` was called without a `prepare` since the last feedback.
    #[error("feedback called before prepare")]
    NotPrepared,
}

/// Result alias for atmo-mpc.
pub type Result<T> = std::result::Result<T, MpcError>;
