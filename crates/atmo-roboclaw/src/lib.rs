//! A driver for Basicmicro Roboclaw motor controllers on ATMO's iceoryx2
//! driver ports, and a simulated Roboclaw on a pseudo-terminal.
//!
//! ATMO has two boards (115200 baud, packet serial, address 0x80): the tilt
//! board drives the linkage's lead screw on M2 (quadrature encoder, home
//! switch in the drive configuration), the wheel board the two belt drives
//! on M1 and M2. One `atmo-roboclaw run` process drives one board.
//!
//! - [`protocol`]: the packet-serial subset as pure frame encode/decode;
//! - [`link`]: the serial transport and [`link::Board`] (deadlines,
//!   retries, [`link::BoardHealth`] counters);
//! - [`table`]: counts-to-tilt calibration (the measured table or the
//!   linkage model);
//! - [`config`]: the driver's TOML file;
//! - [`driver`]: the driver logic (start, homing, watchdog, reset
//!   detection, commands to speeds), pure and clocked from outside;
//! - [`sim`] and [`pty`]: the simulated board and its pseudo-terminal.

pub mod config;
pub mod driver;
pub mod error;
pub mod link;
pub mod protocol;
pub mod pty;
pub mod sim;
pub mod table;

pub use error::{Result, RoboclawError};
