//! MCAP logging for Foxglove and the reference readers, and reading back.
//!
//! - [`McapLogger`]: a writer thread behind a bounded channel. The control
//!   thread calls [`LoggerHandle::try_log`], which copies a fixed-size record
//!   into the channel and returns at once (no lock, no allocation; a full
//!   channel drops the record and counts it). The writer thread owns the
//!   `mcap::Writer`: `ros2` profile, `ros2msg` schemas with every dependency,
//!   `cdr` messages with the encapsulation header, zstd chunks compressed on
//!   that thread (compression threads 0), and a flush (chunk closed, file
//!   flushed) at least every `flush_period` (<= 1 s), so a killed process
//!   loses at most that much. Drops are written to the log itself on
//!   [`LOGGER_TOPIC`] as a `diagnostic_msgs/DiagnosticArray`.
//! - [`LoggerHandle::attach`] / [`LoggerHandle::metadata`] store files (the
//!   configuration) and string maps at start-up; [`read_extras`] reads them
//!   back, from truncated logs too, and `recover` keeps them.
//! - [`recover`]: turns a truncated log (killed writer) into a valid one.
//! - [`read_log`] / [`read_topic`]: decode a log back into Rust types. Every
//!   chunk's CRC is checked before its messages are used; a corrupt chunk or
//!   an undecodable message is skipped and counted ([`Integrity`]), an error
//!   for the strict readers, a count for the `*_lossy` ones and `recover`.
//!   Every length a record claims is checked against the bytes there before
//!   anything is allocated, so a hostile file takes at most its own size plus
//!   one chunk of memory (records.rs).

mod attachments;
mod logger;
mod reader;
mod records;
mod recover;
mod scan;

pub use attachments::{LogAttachment, LogExtras, read_extras};
pub use logger::{
    Channel, Compression, LOGGER_TOPIC, LogPayload, LogSummary, Loggable, LoggerHandle,
    LoggerOptions, LoggerThread, McapLogger, unused_log_path,
};
pub use reader::{
    AnyMessage, LoggedMessage, read_log, read_log_lossy, read_topic, read_topic_lossy,
};
pub use recover::{RecoverReport, recover};
pub use scan::Integrity;

/// MCAP profile of every log.
pub const PROFILE: &str = "ros2";
/// Schema encoding of every channel.
pub const SCHEMA_ENCODING: &str = "ros2msg";
/// Message encoding of every channel.
pub const MESSAGE_ENCODING: &str = "cdr";
