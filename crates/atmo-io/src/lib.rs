//! atmo-io: the edges of the flight stack.
//!
//! Not built yet (issue 7). It will hold: ROS 2 messages and node
//! (ros2-client), zero-copy driver ports (iceoryx2), the MCAP logger and
//! reader, and CSV import of recordings.
