//! Decoding the project's own logs back into Rust types.

use std::path::Path;

use super::{MESSAGE_ENCODING, SCHEMA_ENCODING};
use crate::error::{IoError, Result};
use crate::msg::{
    ActuatorMotors, DiagnosticArray, MpcStatus, Odometry, OffboardControlMode, PilotInput,
    RosMessage, TickTiming, Twist, VehicleOdometry, decode,
};

/// A decoded message of any type this crate knows. Serializes (serde) as
/// the inner message, field for field as in its `.msg`.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
#[serde(untagged)]
pub enum AnyMessage {
    MpcStatus(MpcStatus),
    PilotInput(PilotInput),
    TickTiming(TickTiming),
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

fn read_file(path: &Path) -> Result<Vec<u8>> {
    std::fs::read(path).map_err(|source| IoError::File {
        file: path.to_path_buf(),
        source,
    })
}

fn decode_any(topic: &str, type_name: &str, data: &[u8]) -> Result<Option<AnyMessage>> {
    Ok(Some(match type_name {
        MpcStatus::TYPE_NAME => AnyMessage::MpcStatus(decode(topic, data)?),
        PilotInput::TYPE_NAME => AnyMessage::PilotInput(decode(topic, data)?),
        TickTiming::TYPE_NAME => AnyMessage::TickTiming(decode(topic, data)?),
        VehicleOdometry::TYPE_NAME => AnyMessage::VehicleOdometry(decode(topic, data)?),
        ActuatorMotors::TYPE_NAME => AnyMessage::ActuatorMotors(decode(topic, data)?),
        OffboardControlMode::TYPE_NAME => AnyMessage::OffboardControlMode(decode(topic, data)?),
        Twist::TYPE_NAME => AnyMessage::Twist(decode(topic, data)?),
        Odometry::TYPE_NAME => AnyMessage::Odometry(decode(topic, data)?),
        DiagnosticArray::TYPE_NAME => AnyMessage::DiagnosticArray(decode(topic, data)?),
        _ => return Ok(None),
    }))
}

/// Reads every message of a finished log, in file order, decoding each into
/// its Rust type. A channel that is not `ros2msg`/`cdr` or whose schema this
/// crate does not know is an error naming the file and topic (this reader is
/// for the project's own logs); a truncated log is an MCAP error (run
/// [`super::recover`] first).
pub fn read_log(path: impl AsRef<Path>) -> Result<Vec<LoggedMessage>> {
    let path = path.as_ref();
    let bytes = read_file(path)?;
    let stream = mcap::MessageStream::new(&bytes).map_err(|source| IoError::Mcap {
        file: path.to_path_buf(),
        source,
    })?;
    let mut out = Vec::new();
    for message in stream {
        let message = message.map_err(|source| IoError::Mcap {
            file: path.to_path_buf(),
            source,
        })?;
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
        let decoded = decode_any(&channel.topic, &schema.name, &message.data)?
            .ok_or_else(|| channel_error(format!("unknown schema {}", schema.name)))?;
        out.push(LoggedMessage {
            topic: channel.topic.clone(),
            type_name: schema.name.clone(),
            sequence: message.sequence,
            log_time_ns: message.log_time,
            publish_time_ns: message.publish_time,
            message: decoded,
        });
    }
    Ok(out)
}

/// Reads the messages of one topic as type `M`: `(log_time_ns, message)` in
/// file order. The topic's schema must be `M`'s type.
pub fn read_topic<M: RosMessage>(path: impl AsRef<Path>, topic: &str) -> Result<Vec<(u64, M)>> {
    let path = path.as_ref();
    let bytes = read_file(path)?;
    let stream = mcap::MessageStream::new(&bytes).map_err(|source| IoError::Mcap {
        file: path.to_path_buf(),
        source,
    })?;
    let mut out = Vec::new();
    for message in stream {
        let message = message.map_err(|source| IoError::Mcap {
            file: path.to_path_buf(),
            source,
        })?;
        if message.channel.topic != topic {
            continue;
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
        out.push((message.log_time, decode::<M>(topic, &message.data)?));
    }
    Ok(out)
}
