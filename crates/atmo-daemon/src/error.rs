//! The one error type of atmo-daemon's library.

/// What the flight stack can refuse at start-up. Nothing in `step` returns
/// an error: bad inputs are rejected, counted and reported in the status.
#[derive(Debug, thiserror::Error)]
pub enum DaemonError {
    #[error(transparent)]
    Config(#[from] atmo_core::CoreError),
    #[error(transparent)]
    Mpc(#[from] atmo_mpc::MpcError),
    #[error("{0}")]
    Setup(String),
}

pub type Result<T> = std::result::Result<T, DaemonError>;
