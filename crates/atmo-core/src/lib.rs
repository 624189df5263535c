//! atmo-core: the physics of ATMO, as pure functions on fixed-size types.
//!
//! ATMO is a quadrotor whose two arms (each a wheel with two rotors) tilt
//! inward together by one angle varphi through a self-locking screw linkage:
//! varphi = 0 is a quadrotor, pi/2 a car.
//!
//! - [`config_file`]: the loading layer of every config file of the project
//!   ([`ConfigFile`]: strict TOML, errors with file, line and key; range checks).
//! - [`closed_stdout`]: the tests' check that a printing binary ends by
//!   SIGPIPE when its reader is gone.
//! - [`config`]: the robot file's layout, as data; [`validate`]: its physical
//!   checks (they build a linkage and a model).
//! - [`linkage`]: screw displacement x, tilt varphi and encoder counts.
//! - [`model`]: the 7-body dynamics `x_dot = f(x, u, varphi)` (composite rigid
//!   body at fixed tilt, see the module docs for the equations), analytic
//!   Jacobians, RK4 with exact sensitivities, hover trim.
//! - [`ground_effect`]: the model above a ground plane, rotor thrust times
//!   `1 + g(h_i, varphi)` with its exact Jacobians (the surface is a trait).
//! - [`ground_plane`]: the ground under the robot as a plane (a point and its
//!   unit normal), with the checks a ground input must pass.
//! - [`limits`]: critical angle `cos varphi_c = m g / T_max`, largest tilt for a
//!   thrust reserve, the tilt where the hover trim saturates.
//! - [`control`]: the paper's blending `alpha = f(h) cos varphi`, the tilt
//!   velocity law and differential-drive kinematics.
//!
//! Frames: NED world, FRD body, Euler ZYX; SI units, radians. Nothing here
//! allocates on the heap or does I/O (except reading a config file).

pub mod alloc_counter;
pub mod cli_numbers;
pub mod closed_stdout;
pub mod config;
pub mod config_file;
pub mod control;
pub mod error;
pub mod ground_effect;
pub mod ground_plane;
pub mod input_file;
pub mod limits;
pub mod linkage;
pub mod model;
pub mod params;
pub mod validate;

pub use config::RobotConfig;
pub use config_file::ConfigFile;
pub use error::{CoreError, Result};
pub use ground_plane::GroundPlane;
pub use linkage::Linkage;
pub use model::{Input, Model, NU, NX, State, TiltedBody};
