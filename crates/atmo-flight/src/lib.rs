//! atmo-flight: ATMO's flight software as a library, with no transport.
//!
//! The robot (`atmo-daemon`), the simulator (`atmo-sim`) and the replay run
//! the same code: one tick path, the clock an input. Its normal dependency
//! tree has no ROS 2, iceoryx2, plotting or simulator plant (checked by
//! `tests/dependencies.rs`).
//!
//! - [`actuator_monitor`]: what the stack detects of actuators that do not
//!   do what it commands (rotor, tilt encoder and motor, ground contact).
//! - [`arming`]: the arming checks (estimate rate, radio, drivers, tilt
//!   encoder against the command, configuration) and their verdict.
//! - [`modes`]: the paper's mode state machine as an explicit transition table.
//! - [`flight_stack`]: `FlightStack::step(inputs)` (pure, deterministic, the
//!   clock is an input): input validation, mode machine, tilt law with limits,
//!   MPC feedback (thrusters), drive controller (wheels), failsafes, status;
//!   its inputs and outputs are the types of [`step_io`].
//! - [`flare`]: the landing decision: the touchdown prediction and when the
//!   tilt-up is committed.
//! - [`observer`]: disturbance observer that makes the MPC offset-free.
//! - [`ground_model`]: the ground-effect surface of the MPC's model, from its settings.
//! - [`control_loop`]: the one tick (gather -> step -> emit -> prepare)
//!   with absolute deadlines and per-tick timing, and the 150 Hz control
//!   thread that runs it.
//! - [`inputs`]: how a tick's inputs are made of what arrived (newest
//!   estimate, pilot with staleness, drive command, encoder, contact,
//!   driver liveness, ground height), shared by every `TickIo`.
//! - [`flight_log`]: what a flight log holds for a replay (per-tick inputs
//!   and status, the configuration files) and how it is written.
//! - [`replay`]: a flight log's inputs through a rebuilt flight stack,
//!   every output compared bit for bit with the logged one (and what-if).
//! - [`whatif`]: a what-if replay's per-tick comparison (CSV, largest
//!   differences).
//! - [`rc`]: the radio (PX4's `InputRc`) as a pilot source: channels,
//!   ranges, switches, kill latch.
//! - [`backup_control`]: the backup controller's level descent, on four
//!   rotors or on the three left with one stopped.
//! - [`esc`]: the ESCs' telemetry (PX4's `EscStatus`) as the rotors' speeds.
//! - [`telemetry`]: the tick's status as the `atmo_msgs/MpcStatus` message.
//! - [`settings`], read from `config/flight.toml`.

pub mod actuator_monitor;
pub mod arming;
pub mod backup_control;
pub mod control_loop;
pub mod error;
pub mod esc;
pub mod flare;
pub mod flight_log;
pub mod flight_stack;
pub mod ground_model;
pub mod inputs;
pub mod modes;
pub mod observer;
pub mod rc;
pub mod replay;
pub mod rotor_estimate;
pub mod schema;
pub mod settings;
pub mod step_io;
pub mod telemetry;
pub mod whatif;

pub use error::{FlightError, Result};
pub use flight_stack::{
    Estimate, FlightStack, PilotInput, RejectCounters, SolverStatus, Status, StepInputs,
    StepOutputs,
};
pub use modes::Mode;
pub use settings::FlightSettings;
