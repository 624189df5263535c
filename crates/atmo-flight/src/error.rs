//! The one error type of atmo-daemon's library.

/// What the flight stack can refuse at start-up. Nothing in `step` returns
/// an error: bad inputs are rejected, counted and reported in the status.
#[derive(Debug, thiserror::Error)]
pub enum FlightError {
    #[error(transparent)]
    Config(#[from] atmo_core::CoreError),
    #[error(transparent)]
    Mpc(#[from] atmo_mpc::MpcError),
    #[error("{0}")]
    Setup(String),
    #[error(transparent)]
    Io(#[from] atmo_io::IoError),
    /// A flight log that cannot be replayed; names the file and what is
    /// missing or wrong (channel, tick, attachment).
    #[error("{file}: {reason}")]
    Log {
        file: std::path::PathBuf,
        reason: String,
    },
}

pub type Result<T> = std::result::Result<T, FlightError>;
