//! The one error type of atmo-sim.

use atmo_core::CoreError;
use atmo_plant::PlantError;

/// Everything atmo-sim can refuse.
///
/// Configuration problems (plant file, scenario file) are reported through
/// atmo-core's [`CoreError`] (`ConfigRead`, `ConfigParse`, `ConfigValue`), so
/// every config error of the project names the file, the key and what was
/// expected in the same way.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    /// A configuration or robot-model error from atmo-core.
    #[error(transparent)]
    Core(#[from] CoreError),
    /// The plant refused a command or diverged.
    #[error(transparent)]
    Plant(PlantError),
    /// The flight stack or its MPC could not be built.
    #[error("closed loop: {0}")]
    Setup(String),
    /// A run went on past its wall-clock time limit (a Monte Carlo's
    /// per-run budget) and was stopped.
    #[error("stopped after its time limit of {limit_s:.0} s (at {sim_time_s:.2} s simulated)")]
    TimeLimit { limit_s: f64, sim_time_s: f64 },
    /// Writing an output (figure, summary, log) failed.
    #[error("output: {0}")]
    Output(String),
}

impl From<PlantError> for SimError {
    /// A plant config error stays a config error (`SimError::Core`), so
    /// plant and scenario files report alike.
    fn from(e: PlantError) -> Self {
        match e {
            PlantError::Core(core) => Self::Core(core),
            other => Self::Plant(other),
        }
    }
}

/// Result alias for atmo-sim.
pub type Result<T> = std::result::Result<T, SimError>;
