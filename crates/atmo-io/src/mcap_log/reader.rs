//! Decoding the project's own logs back into Rust types.

use std::path::Path;

use super::scan::{Integrity, scan};
use super::{MESSAGE_ENCODING, SCHEMA_ENCODING};
use crate::error::{IoError, Result};
use crate::msg::{
    ActuatorMotors, DiagnosticArray, MpcStatus, Odometry, OffboardControlMode, PilotInput,
    RosMessage, SimTruth, TickInputs, TickTiming, Twist, VehicleOdometry, decode,
};

/// A decoded message of any type this crate knows. Serializes (serde) as
/// the inner message, field for field as in its `.msg`.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
#[serde(untagged)]
pub enum AnyMessage {
    MpcStatus(MpcStatus),
    PilotInput(PilotInput),
    TickTiming(TickTiming),
    TickInputs(TickInputs),
    SimTruth(SimTruth),
    VehicleOdometry(VehicleOdometry),
    ActuatorMotors(ActuatorMotors),
    OffboardControlMode(OffboardControlMode),
    Twist(Twist),
    Odometry(Odometry),
    DiagnosticArray(DiagnosticArray),
}

/// One message of a log.
#[derive(Debug, Clone, PartialEq)]
pub struct LoggedMessage {
    pub topic: String,
    /// Schema name, `pkg/msg/Type`.
    pub type_name: String,
    pub sequence: u32,
    pub log_time_ns: u64,
    pub publish_time_ns: u64,
    pub message: AnyMessage,
}

/// Largest log read, bytes: a log is read whole, so its size is checked
/// before reading.
pub const MAX_LOG_BYTES: u64 = 4 << 30;

/// A flight log as an input file: read whole, so bounded.
const LOG: atmo_core::input_file::InputKind = atmo_core::input_file::InputKind {
    name: "a log",
    max_bytes: MAX_LOG_BYTES,
    advice: "",
};

/// Reads a log whole: a regular file of at most [`MAX_LOG_BYTES`]
/// ([`atmo_core::input_file`]).
pub(super) fn read_file(path: &Path) -> Result<Vec<u8>> {
    atmo_core::input_file::read(path, LOG).map_err(|cause| IoError::File {
        file: path.to_path_buf(),
        cause,
    })
}

fn decode_any(topic: &str, type_name: &str, data: &[u8]) -> Result<Option<AnyMessage>> {
    Ok(Some(match type_name {
        MpcStatus::TYPE_NAME => AnyMessage::MpcStatus(decode(topic, data)?),
        PilotInput::TYPE_NAME => AnyMessage::PilotInput(decode(topic, data)?),
        TickTiming::TYPE_NAME => AnyMessage::TickTiming(decode(topic, data)?),
        TickInputs::TYPE_NAME => AnyMessage::TickInputs(decode(topic, data)?),
        SimTruth::TYPE_NAME => AnyMessage::SimTruth(decode(topic, data)?),
        VehicleOdometry::TYPE_NAME => AnyMessage::VehicleOdometry(decode(topic, data)?),
        ActuatorMotors::TYPE_NAME => AnyMessage::ActuatorMotors(decode(topic, data)?),
        OffboardControlMode::TYPE_NAME => AnyMessage::OffboardControlMode(decode(topic, data)?),
        Twist::TYPE_NAME => AnyMessage::Twist(decode(topic, data)?),
        Odometry::TYPE_NAME => AnyMessage::Odometry(decode(topic, data)?),
        DiagnosticArray::TYPE_NAME => AnyMessage::DiagnosticArray(decode(topic, data)?),
        _ => return Ok(None),
    }))
}

/// Checks that `bytes` start with the MCAP magic, so that a file of random
/// bytes, CSV or nothing is refused by name rather than read as an empty log.
pub(super) fn check_magic(path: &Path, bytes: &[u8]) -> Result<()> {
    let reason = if bytes.is_empty() {
        "the file is empty".to_string()
    } else if bytes.len() < mcap::MAGIC.len() || !bytes.starts_with(mcap::MAGIC) {
        let head = &bytes[..bytes.len().min(8)];
        format!(
            "its first bytes {head:02x?} are not the MCAP magic {:02x?}",
            mcap::MAGIC
        )
    } else {
        return Ok(());
    };
    Err(IoError::NotMcap {
        file: path.to_path_buf(),
        reason,
    })
}

/// What a reader's visitor makes of one message.
enum Visit<T> {
    Skip,
    Keep(T),
    /// The payload does not decode: skipped and counted.
    Undecodable(IoError),
}

/// Every message of `path` that `visit` keeps, in file order, with what was
/// skipped as corrupt. Structural errors (truncation, a channel this crate
/// cannot read) are errors naming the file.
fn read_messages<T>(
    path: &Path,
    mut visit: impl FnMut(&mcap::Message<'_>) -> Result<Visit<T>>,
) -> Result<(Vec<T>, Integrity)> {
    let bytes = read_file(path)?;
    check_magic(path, &bytes)?;
    let mut out = Vec::new();
    let mut undecodable = 0u64;
    let mut first_undecodable = None;
    let end = scan(&bytes, false, |message| {
        match visit(&message)? {
            Visit::Skip => {}
            Visit::Keep(value) => out.push(value),
            Visit::Undecodable(e) => {
                undecodable += 1;
                first_undecodable.get_or_insert_with(|| {
                    format!(
                        "message {} at log time {} ns: {e}",
                        message.sequence, message.log_time
                    )
                });
            }
        }
        Ok::<(), IoError>(())
    })?;
    if let Some(stop) = end.stopped_by {
        return Err(IoError::LogRecord {
            file: path.to_path_buf(),
            offset: stop.offset,
            reason: stop.reason,
        });
    }
    let mut integrity = end.integrity;
    integrity.undecodable_messages = undecodable;
    if let Some(first) = first_undecodable {
        integrity.note(|| first);
    }
    Ok((out, integrity))
}

fn any_message(path: &Path, message: &mcap::Message<'_>) -> Result<Visit<LoggedMessage>> {
    let channel = &message.channel;
    let channel_error = |reason: String| IoError::LogChannel {
        file: path.to_path_buf(),
        topic: channel.topic.clone(),
        reason,
    };
    let Some(schema) = channel.schema.as_ref() else {
        return Err(channel_error("no schema".into()));
    };
    if schema.encoding != SCHEMA_ENCODING || channel.message_encoding != MESSAGE_ENCODING {
        return Err(channel_error(format!(
            "encodings {}/{}, expected {SCHEMA_ENCODING}/{MESSAGE_ENCODING}",
            schema.encoding, channel.message_encoding
        )));
    }
    Ok(
        match decode_any(&channel.topic, &schema.name, &message.data) {
            Ok(Some(decoded)) => Visit::Keep(LoggedMessage {
                topic: channel.topic.clone(),
                type_name: schema.name.clone(),
                sequence: message.sequence,
                log_time_ns: message.log_time,
                publish_time_ns: message.publish_time,
                message: decoded,
            }),
            Ok(None) => return Err(channel_error(format!("unknown schema {}", schema.name))),
            Err(e) => Visit::Undecodable(e),
        },
    )
}

fn sound<T>(path: &Path, read: (Vec<T>, Integrity)) -> Result<Vec<T>> {
    let (messages, integrity) = read;
    if integrity.is_sound() {
        Ok(messages)
    } else {
        Err(IoError::LogCorrupt {
            file: path.to_path_buf(),
            integrity,
        })
    }
}

/// Reads every message of a finished log, in file order, decoding each into
/// its Rust type. A channel that is not `ros2msg`/`cdr` or whose schema this
/// crate does not know is an error naming the file and topic (this reader is
/// for the project's own logs); a truncated log is an MCAP error (run
/// [`super::recover`] first); a corrupt chunk (CRC mismatch) or message is
/// [`IoError::LogCorrupt`] with the counts ([`read_log_lossy`] keeps the rest).
pub fn read_log(path: impl AsRef<Path>) -> Result<Vec<LoggedMessage>> {
    let path = path.as_ref();
    sound(path, read_log_lossy(path)?)
}

/// Like [`read_log`], but skips corrupt chunks and undecodable messages,
/// counting them in the returned [`Integrity`].
pub fn read_log_lossy(path: impl AsRef<Path>) -> Result<(Vec<LoggedMessage>, Integrity)> {
    let path = path.as_ref();
    read_messages(path, |message| any_message(path, message))
}

/// Reads the messages of one topic as type `M`: `(log_time_ns, message)` in
/// file order. The topic's schema must be `M`'s type. Corruption is an error
/// as in [`read_log`].
pub fn read_topic<M: RosMessage>(path: impl AsRef<Path>, topic: &str) -> Result<Vec<(u64, M)>> {
    let path = path.as_ref();
    sound(path, read_topic_lossy::<M>(path, topic)?)
}

/// Like [`read_topic`], skipping and counting corrupt chunks and messages.
pub fn read_topic_lossy<M: RosMessage>(
    path: impl AsRef<Path>,
    topic: &str,
) -> Result<(Vec<(u64, M)>, Integrity)> {
    let path = path.as_ref();
    read_messages(path, |message| {
        if message.channel.topic != topic {
            return Ok(Visit::Skip);
        }
        let schema_name = message
            .channel
            .schema
            .as_ref()
            .map_or("(none)", |s| s.name.as_str());
        if schema_name != M::TYPE_NAME {
            return Err(IoError::LogChannel {
                file: path.to_path_buf(),
                topic: topic.to_string(),
                reason: format!("schema {schema_name}, expected {}", M::TYPE_NAME),
            });
        }
        Ok(match decode::<M>(topic, &message.data) {
            Ok(decoded) => Visit::Keep((message.log_time, decoded)),
            Err(e) => Visit::Undecodable(e),
        })
    })
}
