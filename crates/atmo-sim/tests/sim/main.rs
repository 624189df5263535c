//! atmo-sim's integration tests, linked as one binary: each file is a
//! module (`cargo test -p atmo-sim --test sim -- faults::`). As six
//! binaries each re-instantiated and linked the whole flight stack, 21-32 s
//! of build apiece (cargo `--timings`, 2026-12-03). The real-time SITL
//! flights are the one exception: `tests/sitl`, a binary of their own.

mod actuator_faults;
mod campaign;
mod closed_loop_identification;
mod config_errors;
mod faults;
mod hostile;
mod monitor_margins;
mod replay;
mod rotor_out_bound;
mod scenarios;
