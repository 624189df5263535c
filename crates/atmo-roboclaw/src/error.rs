//! The one error type of atmo-roboclaw.

use atmo_core::CoreError;

use crate::link::{LinkError, SerialOpenError};

/// Everything atmo-roboclaw can refuse. Faults of a running board are not
/// errors: they are counted in [`crate::link::BoardHealth`].
#[derive(Debug, thiserror::Error)]
pub enum RoboclawError {
    /// A configuration file (reading, parsing, a value out of range), or the
    /// linkage model refused a value.
    #[error(transparent)]
    Core(#[from] CoreError),
    /// The iceoryx2 driver ports.
    #[error(transparent)]
    Ports(#[from] atmo_io::IoError),
    #[error(transparent)]
    SerialOpen(#[from] SerialOpenError),
    /// A transaction with the board failed (after its retries).
    #[error("board: {0}")]
    Link(#[from] LinkError),
    /// The simulated board's pseudo-terminal.
    #[error("pseudo-terminal: {what}: {source}")]
    Pty {
        what: &'static str,
        #[source]
        source: std::io::Error,
    },
}

pub type Result<T> = std::result::Result<T, RoboclawError>;
