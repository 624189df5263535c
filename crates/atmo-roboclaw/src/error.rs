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
    Link(LinkError),
    /// The simulated board's pseudo-terminal.
    #[error("pseudo-terminal: {what}: {cause}")]
    Pty {
        what: &'static str,
        /// Said in the message, so not also a `source()` (an error says its
        /// cause or returns it, never both).
        cause: std::io::Error,
    },
}

pub type Result<T> = std::result::Result<T, RoboclawError>;

/// By hand, not `#[from]` (which would also return it as `source()`): the
/// message says the link's error already.
impl From<LinkError> for RoboclawError {
    fn from(error: LinkError) -> Self {
        Self::Link(error)
    }
}
