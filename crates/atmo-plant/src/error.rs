//! The one error type of atmo-plant.

use atmo_core::CoreError;

/// Everything the plant can refuse.
///
/// Configuration problems (plant file) are reported through atmo-core's
/// [`CoreError`] (`ConfigRead`, `ConfigParse`, `ConfigValue`), so every
/// config error of the project names the file, the key and what was
/// expected in the same way.
#[derive(Debug, thiserror::Error)]
pub enum PlantError {
    /// A configuration or robot-model error from atmo-core.
    #[error(transparent)]
    Core(#[from] CoreError),
    /// A command given to the plant is NaN or infinite.
    #[error("plant command `{name}` is not finite: {value}")]
    NonFiniteCommand { name: &'static str, value: f64 },
    /// The integration produced a non-finite state (the step is too large
    /// for the configured stiffnesses, or the inputs drove it there).
    #[error("the plant state became non-finite at t = {time} s")]
    Diverged { time: f64 },
}

/// Result alias for atmo-plant.
pub type Result<T> = std::result::Result<T, PlantError>;
