//! atmo-io: the edges of the flight stack.
//!
//! - [`msg`]: ROS 2 message types (`atmo_msgs`, standard and `px4_msgs`
//!   types) with CDR (de)serialization, `.msg` schemas, and the ENU/FLU <->
//!   NED/FRD conversion done at the ROS 2 edge only.
//! - [`mcap_log`]: the MCAP logger (own thread, bounded channel, never
//!   blocks the tick), the reader for the project's logs, and `recover`.
//! - [`drivers`]: zero-copy iceoryx2 driver ports (thrusters, tilt, wheels,
//!   ground contact) with sequence numbers, stamps and driver liveness.
//! - [`ros2`]: the ROS 2 node (status out, estimates, drive commands and
//!   pilot inputs in, PX4 offboard outputs, diagnostics), never blocking the
//!   control thread, and its SITL peer for the plant server.
//! - [`output_dir`]: output folders written whole or not at all.
//! - [`review`] (feature `review`): a flight's landing summary and Fig. 5A,
//!   as the simulator makes them and from any log.
//!
//! Conventions: NED world, FRD body, Euler ZYX, the 12-state order of
//! `atmo_core::model::idx`; time in u64 nanoseconds.

#[cfg(feature = "drivers")]
pub mod drivers;
pub mod error;
pub mod mcap_log;
pub mod msg;
pub mod output_dir;
#[cfg(feature = "review")]
pub mod review;
#[cfg(feature = "ros2")]
pub mod ros2;
pub mod stamp_order;

pub use error::{IoError, Result};

/// Wall-clock time in ns since the Unix epoch (ROS 2 header stamps, MCAP
/// metadata); 0 if the clock reads before 1970.
pub fn wall_clock_ns() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX))
}
