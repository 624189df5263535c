//! atmo-explain's integration tests, linked as one binary: each file is a
//! module (`cargo test -p atmo-explain --test explain -- explain_testgen::`).
//! As eight binaries they were 3-22 s of build apiece (cargo `--timings`,
//! 2026-12-03).

mod explain_closed_loop;
mod explain_concealed;
mod explain_contract;
mod explain_hostile;
mod explain_indistinguishable;
mod explain_inputs;
mod explain_neural_fly;
mod explain_other_robot;
mod explain_testgen;
