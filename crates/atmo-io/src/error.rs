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
    #[error("{file}: {source}")]
    File {
        file: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// The MCAP library refused a file or a record.
    #[error("{file}: MCAP: {source}")]
    Mcap {
        file: PathBuf,
        #[source]
        source: mcap::McapError,
    },
    /// A log has corrupt chunks or messages (read with the `*_lossy` readers
    /// or `atmo-mcap recover` to keep the sound rest).
    #[error("{file}: corrupt log: {integrity}")]
    LogCorrupt {
        file: PathBuf,
        integrity: crate::mcap_log::Integrity,
    },
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
