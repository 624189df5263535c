//! atmo-plant: the truth physics of the ATMO simulator.
//!
//! The plant is everything the controller's model leaves out, on top of
//! atmo-core's 7-body dynamics. It depends on atmo-core only (no flight
//! stack, no transports), so the discrepancy finder (atmo-explain) and the
//! simulator (atmo-sim) both replay recordings through it.
//!
//! # The plant ([`plant::Plant`])
//!
//! atmo-core's 7-body dynamics (composite rigid body at the current tilt,
//! `M_b (a, w_dot) = A u_eff + gravity + Coriolis + extra wrench`),
//! integrated by classical RK4 at a fixed step `dt <= 1 ms` (default 1 ms),
//! driven by the daemon's commands: 4 rotor commands in [0, 1], the tilt
//! velocity and the two wheel rates. Every effect below is a named section
//! `[effects.<name>]` of the plant file ([`config::PlantConfig`]); with every
//! effect off the plant's accelerations are atmo-core's, bit for bit.
//!
//! - `ground_effect` (atmo-core's [`atmo_core::ground_effect::GroundEffect`], the
//!   controller's surface used as the truth): rotor i's thrust is multiplied by
//!   `1 + g(h_i, varphi) + sigma(h_i, varphi) n_i(t)`, h_i the hub height
//!   above the ground plane. Classical Cheeseman-Bennett law
//!   `T/T_inf = 1 / (1 - (R_p / 4z)^2)` below 30 deg (z = h / cos varphi),
//!   a table after the paper's Fig. 3C for 40-70 deg (largest at 50 deg,
//!   +19 % at 0.25 m; suction at 70 deg with a 8 % standard deviation),
//!   linear blend in between; n_i a unit Gauss-Markov process. See
//!   docs/ground_effect.md.
//! - `motor_lag`: `tau t_dot = (1 - f) u + f u^2 - t`, thrust `kT t`.
//! - `tilt_mechanism`: `varphi_dot = clamp(cmd, +-rate_max)`, varphi in
//!   [0, tilt_max], never back-driven (self-locking screw); encoder counts
//!   from atmo-core's linkage, rounded to whole counts.
//! - `drag`: rotor drag `-k_r t_i (v_i - (v_i . n_i) n_i)` at each hub
//!   (v_i the hub's air velocity), body drag `-1/2 rho CdA_k |v_k| v_k` per
//!   body axis.
//! - `wind`: steady + per-axis Gauss-Markov turbulence + scripted 1 - cos
//!   gusts; drag acts on the air-relative velocity.
//! - `battery_sag`: energy `E = int sum P_full t_i^1.5 dt`, thrust scale
//!   `1 - sag E / capacity`.
//! - `com_offset`, `mass_error`: the true mass distribution shifted by an
//!   offset and scaled (mass and first moment by one factor, inertia about B
//!   by another), so the controller's model is wrong the way a real one is.
//! - `sensors` ([`sensors`]): motion-capture estimate at 100-200 Hz with
//!   latency and Gaussian noise; ground-contact signal from the wheel load.
//! - `ground_contact` ([`contact`]): each rotor shroud is a wheel (circle
//!   of radius 0.125 m at the hub, normal to the rotor axis) touching the
//!   plane at its lowest rim point; spring-damper normal force, tangential
//!   spring with a Coulomb cap (true stiction), belt-coupled wheels per side
//!   driven by a torque-limited PI speed controller. Base-box corners on
//!   the ground, wheel impacts above `crash_speed` and tip-over are
//!   reported as crashes. Terrain: a plane of any height and slope up to
//!   25 deg.
//!
//! Randomness ([`noise`]): one ChaCha8 stream per component from the
//! scenario seed; no global state, so a scenario and seed give a
//! bit-identical trajectory.
//!

// Everything `Plant::step` calls per step is `inline(always)`: the step is
// compiled twice, portable and AVX2, and only code inlined into it gets the
// AVX2 copy (the rule, and the test that checks it: module `plant::step`).
#![allow(clippy::inline_always)]

mod body;
pub mod config;
pub mod contact;
pub mod error;
pub mod motor;
pub mod noise;
pub mod plant;
pub mod sensors;

pub use body::lerp_body;
pub use config::{EffectsConfig, PlantConfig, TerrainConfig};
pub use error::{PlantError, Result};
pub use plant::{Command, CrashKind, Event, EventKind, InitialState, Plant, PlantTemplate};
