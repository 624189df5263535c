//! The one error type of atmo-core.

use std::path::PathBuf;

/// Everything atmo-core can refuse.
#[derive(Debug, thiserror::Error)]
pub enum CoreError {
    /// The configuration file could not be read.
    #[error("{file}: cannot read: {cause}")]
    ConfigRead {
        file: PathBuf,
        /// Said in the message, so not also a `source()` (an error says its
        /// cause or returns it, never both: a chain printed it twice).
        cause: std::io::Error,
    },
    /// The configuration is not valid TOML or does not have the expected
    /// shape (unknown key, missing key, wrong type).
    #[error("{file}:{line}: key `{key}`: {message}")]
    ConfigParse {
        file: PathBuf,
        /// 1-based line, 0 when the parser could not tell.
        line: usize,
        key: String,
        message: String,
    },
    /// A value has the right type but is physically meaningless.
    #[error("{file}: key `{key}`: expected {expected}, got {got}")]
    ConfigValue {
        file: PathBuf,
        key: String,
        expected: String,
        got: String,
    },
    /// An argument outside the domain of a function (linkage, limits...).
    #[error("{quantity} = {value} is outside [{min}, {max}]")]
    OutOfRange {
        quantity: &'static str,
        value: f64,
        min: f64,
        max: f64,
    },
}

/// Result alias for atmo-core.
pub type Result<T> = std::result::Result<T, CoreError>;
