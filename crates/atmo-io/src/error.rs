//! The one error type of atmo-io.

use std::path::PathBuf;

/// Everything atmo-io can refuse. Each variant names what it was working on
/// (topic, field, file) so that a log line is enough to find the cause.
#[derive(Debug, thiserror::Error)]
pub enum IoError {
    /// A CDR payload could not be decoded as the expected type.
    #[error("topic `{topic}`: cannot decode {type_name}: {reason}")]
    Decode {
        topic: String,
        type_name: &'static str,
        reason: String,
    },
    /// A message could not be encoded (only for values CDR cannot express).
    #[error("cannot encode {type_name}: {reason}")]
    Encode {
        type_name: &'static str,
        reason: String,
    },
    /// A decoded message has a value the flight stack cannot use.
    #[error("topic `{topic}`: field `{field}`: {reason}")]
    InvalidField {
        topic: String,
        field: &'static str,
        reason: String,
    },
    /// A `.msg` definition refers to a type that is not known.
    #[error("message definition {type_name}: unknown field type `{field_type}`")]
    UnknownType {
        type_name: String,
        field_type: String,
    },
    /// Reading or writing a file failed.
    #[error("{file}: {cause}")]
    File {
        file: PathBuf,
        /// Said in the message, so not also a `source()` (an error says its
        /// cause or returns it, never both: a chain printed it twice).
        cause: std::io::Error,
    },
    /// The MCAP library refused a file or a record.
    #[error("{file}: MCAP: {cause}")]
    Mcap {
        file: PathBuf,
        /// Said in the message, not also a `source()`.
        cause: mcap::McapError,
    },
    /// A record of a log cannot be read (truncated, claims more bytes than
    /// the file holds, does not parse): reading stops there.
    #[error("{file}: MCAP record at byte {offset}: {reason}")]
    LogRecord {
        file: PathBuf,
        offset: usize,
        reason: String,
    },
    /// A log has corrupt chunks or messages (read with the `*_lossy` readers
    /// or `atmo-mcap recover` to keep the sound rest).
    #[error("{file}: corrupt log: {integrity}")]
    LogCorrupt { file: PathBuf, integrity: Integrity },
    /// A file given as an MCAP log is not one.
    #[error("{file}: not an MCAP file ({reason})")]
    NotMcap { file: PathBuf, reason: String },
    /// A log has a channel or schema this crate does not understand.
    #[error("{file}: channel `{topic}`: {reason}")]
    LogChannel {
        file: PathBuf,
        topic: String,
        reason: String,
    },
    /// A review output (figure, summary) could not be made or written.
    #[error("{0}")]
    Output(String),
    /// The logger was used wrongly (bad topic, too many channels, closed).
    #[error("MCAP logger: {0}")]
    Logger(String),
    /// A configuration file (topic names, ports) is invalid.
    #[error(transparent)]
    Config(#[from] atmo_core::CoreError),
    /// The DDS / ROS 2 layer refused an operation.
    #[error("ROS 2: {context}: {reason}")]
    Ros { context: String, reason: String },
    /// The iceoryx2 layer refused an operation.
    #[error("iceoryx2: service `{service}`: {reason}")]
    Iceoryx { service: String, reason: String },
}

/// Result alias for atmo-io.
pub type Result<T> = std::result::Result<T, IoError>;

/// What a read skipped because it was corrupt (0 everywhere for a sound log).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Integrity {
    /// Chunks whose CRC did not match or that did not decompress.
    pub corrupt_chunks: u64,
    /// Messages in those chunks, counted from their message indexes (a
    /// truncated log has none for its last chunk).
    pub messages_in_corrupt_chunks: u64,
    /// Messages whose payload did not decode as their schema's type.
    pub undecodable_messages: u64,
    /// The first corruption seen, for the error message.
    pub first_problem: Option<String>,
}

impl Integrity {
    /// Whether nothing was skipped.
    pub fn is_sound(&self) -> bool {
        self.corrupt_chunks == 0 && self.undecodable_messages == 0
    }

    pub(crate) fn note(&mut self, problem: impl FnOnce() -> String) {
        if self.first_problem.is_none() {
            self.first_problem = Some(problem());
        }
    }
}

impl std::fmt::Display for Integrity {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} corrupt chunk(s) skipped ({} messages), {} undecodable message(s) skipped",
            self.corrupt_chunks, self.messages_in_corrupt_chunks, self.undecodable_messages
        )?;
        if let Some(first) = &self.first_problem {
            write!(f, "; first: {first}")?;
        }
        Ok(())
    }
}
