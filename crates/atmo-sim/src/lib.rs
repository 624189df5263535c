//! atmo-sim: the simulator around the plant (atmo-plant).
//!
//! - [`scenario`]: TOML scenarios (config/scenarios/) with the initial
//!   state, terrain, effect overrides, disturbances, duration, seed, and
//!   what drives the robot.
//! - [`closed_loop`]: the flight stack (atmo-daemon) flown against the
//!   plant in the daemon's own control loop, with a simulated clock and a
//!   simulated `TickIo` ([`sim_io`]); [`monte_carlo`] runs many
//!   randomized landings; [`figure`] draws the paper's Fig. 5A;
//!   [`campaign`] sweeps them over conditions in shards that merge exactly.
//! - [`faults`]: a scenario's `[faults]`, injected on the closed loop's
//!   input path (docs/faults.md).
//! - `sitl` (feature `sitl`): `atmo-sim serve`, the plant behind the
//!   daemon's real transports (ROS 2 motion capture, iceoryx2 drivers) in
//!   real time; `boards`: its tilt and wheels through `atmo-roboclaw`
//!   processes and simulated Roboclaw boards on pseudo-terminals.
//!
//! The discrepancy finder is atmo-explain; the `atmo-sim explain`
//! subcommand is its CLI.

pub mod actuator_faults;
#[cfg(feature = "sitl")]
pub mod boards;
pub mod campaign;
pub mod closed_loop;
pub mod error;
pub mod faults;
/// Fig. 5A (shared with `atmo-mcap summary`: atmo-io's review module).
pub use atmo_io::review::figure;
pub mod monte_carlo;
pub mod scenario;
pub mod sim_io;
pub mod sim_time;
#[cfg(feature = "sitl")]
pub mod sitl;

pub use error::{Result, SimError};
pub use scenario::Scenario;
