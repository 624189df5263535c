//! ROS 2 messages: Rust types, CDR (de)serialization and `.msg` schemas.
//!
//! Every type implements [`RosMessage`]: its ROS 2 name (`pkg/msg/Type`),
//! serde (de)serialization in field order, which the CDR (XCDR1) codec of
//! RustDDS turns into the bytes ROS 2 puts on the wire (little endian,
//! alignment relative to the start of the body; fixed arrays without
//! length, sequences and strings with a `u32` length, strings with their
//! NUL). [`encode`] and [`decode`] add and check the 4-byte encapsulation
//! header (`00 01 00 00` = CDR little endian) used on the wire and in MCAP.
//!
//! The `.msg` texts are the ones shipped in `ros2/atmo_msgs/msg/` (our
//! package) and `crates/atmo-io/msg/` (copies of the standard definitions of
//! the ROS 2 and PX4 packages, for MCAP schemas). [`schema_text`] assembles a
//! `ros2msg` schema with every dependency, as Foxglove and the reference
//! readers expect.

mod atmo;
mod big_array;
mod definitions;
pub mod frames;
mod label;
mod px4;
mod standard;
mod type_hash;

pub use atmo::{
    IoHealth, Mode, MpcStatus, PilotInput, SimTruth, SolverStatus, TickInputs, TickTiming,
};
pub use definitions::{definition, schema_text};
pub use label::Label;
pub use px4::{
    ActuatorMotors, EscReport, EscStatus, InputRc, OffboardControlMode, VehicleOdometry,
};
pub use standard::{
    Clock, DiagnosticArray, DiagnosticStatus, Header, KeyValue, Odometry, Point, PointStamped,
    Pose, PoseWithCovariance, Quaternion, Time, Twist, TwistWithCovariance, Vector3,
    Vector3Stamped,
};
pub use type_hash::{hashed_description, type_hash};

use byteorder::{BigEndian, LittleEndian};
use serde::Serialize;
use serde::de::DeserializeOwned;

use crate::error::{IoError, Result};

/// Encapsulation header of a little-endian classic CDR payload.
pub const CDR_LE_HEADER: [u8; 4] = [0x00, 0x01, 0x00, 0x00];
/// Encapsulation header of a big-endian classic CDR payload.
pub const CDR_BE_HEADER: [u8; 4] = [0x00, 0x00, 0x00, 0x00];

/// A ROS 2 message type with its CDR mapping and `.msg` definition.
pub trait RosMessage:
    Serialize + DeserializeOwned + Clone + std::fmt::Debug + Send + 'static
{
    /// ROS 2 name, `pkg/msg/Type` (also the MCAP schema name).
    const TYPE_NAME: &'static str;

    /// DDS type name as ROS 2 puts it on the wire: `pkg::msg::dds_::Type_`.
    fn dds_type_name() -> String {
        let mut parts = Self::TYPE_NAME.split('/');
        let pkg = parts.next().unwrap_or_default();
        let _msg = parts.next();
        let name = parts.next().unwrap_or_default();
        format!("{pkg}::msg::dds_::{name}_")
    }
}

/// Appends `message` to `out` as a CDR payload with its encapsulation header
/// (little endian). `out` is cleared first; reuse it to avoid allocation.
pub fn encode<M: RosMessage>(message: &M, out: &mut Vec<u8>) -> Result<()> {
    out.clear();
    out.extend_from_slice(&CDR_LE_HEADER);
    encode_body(message, out)
}

/// Appends the CDR body (no encapsulation header) of `message` to `out`.
/// Alignment is relative to where the body starts.
pub fn encode_body<M: Serialize + RosMessage>(message: &M, out: &mut Vec<u8>) -> Result<()> {
    // The serializer counts alignment from its own start, not from the
    // start of `out`: write into `out` after the header through a writer.
    cdr_encoding::to_writer::<M, LittleEndian, _>(&mut *out, message).map_err(|e| IoError::Encode {
        type_name: M::TYPE_NAME,
        reason: e.to_string(),
    })
}

/// Encodes `message` into a new buffer (header included).
pub fn encode_to_vec<M: RosMessage>(message: &M) -> Result<Vec<u8>> {
    let mut out = Vec::with_capacity(64);
    encode(message, &mut out)?;
    Ok(out)
}

/// Decodes a CDR payload with its encapsulation header (little or big
/// endian). `topic` only names the origin in errors. Trailing bytes beyond
/// 3 bytes of padding are an error (a message of another, longer type).
pub fn decode<M: RosMessage>(topic: &str, payload: &[u8]) -> Result<M> {
    let fail = |reason: String| IoError::Decode {
        topic: topic.to_string(),
        type_name: M::TYPE_NAME,
        reason,
    };
    if payload.len() < 4 {
        return Err(fail(format!(
            "{} bytes, shorter than the 4-byte encapsulation header",
            payload.len()
        )));
    }
    let (header, body) = payload.split_at(4);
    let decoded = match [header[0], header[1]] {
        [0x00, 0x01] => cdr_encoding::from_bytes::<M, LittleEndian>(body),
        [0x00, 0x00] => cdr_encoding::from_bytes::<M, BigEndian>(body),
        other => {
            return Err(fail(format!(
                "encapsulation {other:02x?} is not classic CDR (00 00 or 00 01)"
            )));
        }
    };
    let (message, used) = decoded.map_err(|e| fail(e.to_string()))?;
    if body.len() > used + 3 {
        return Err(fail(format!(
            "{} bytes left over after the message ({} used): wrong type?",
            body.len() - used,
            used
        )));
    }
    Ok(message)
}

#[cfg(test)]
mod tests;
