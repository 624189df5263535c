//! The one error type of atmo-sim.

use atmo_core::CoreError;

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
    /// A command given to the plant is NaN or infinite.
    #[error("plant command `{name}` is not finite: {value}")]
    NonFiniteCommand { name: &'static str, value: f64 },
    /// The integration produced a non-finite state (the step is too large
    /// for the configured stiffnesses, or the inputs drove it there).
    #[error("the plant state became non-finite at t = {time} s")]
    Diverged { time: f64 },
    /// The flight stack or its MPC could not be built.
    #[error("closed loop: {0}")]
    Setup(String),
    /// Writing an output (figure, summary, log) failed.
    #[error("output: {0}")]
    Output(String),
}

/// Result alias for atmo-sim.
pub type Result<T> = std::result::Result<T, SimError>;
