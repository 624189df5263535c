//! atmo-daemon: the onboard binary around atmo-flight's control loop.
//!
//! - [`onboard`]: the onboard binary's I/O (ROS 2, iceoryx2 driver ports,
//!   MCAP logger thread) around the control thread, and `config/daemon.toml`.
//! - [`preflight`]: the arming checks and a props-off tilt sweep on the
//!   robot's transports, as a pass/fail table (`atmo-daemon preflight`).
//! - [`reference`](mod@reference): the parameter reference (`atmo-daemon check --params`).
//! - `cli` (feature `cli-args`): the command-line argument groups the
//!   binaries share (`atmo-sim serve` reads the same daemon config).
//!
//! The flight software itself (flight stack, mode machine, landing
//! decision, control loop, replay) is the `atmo-flight` library; the
//! binary's own dependencies (clap, signal-hook, tracing, anyhow) are the
//! default `cli` feature.

#[cfg(feature = "cli-args")]
pub mod cli;
pub mod onboard;
pub mod preflight;
pub mod reference;
