//! atmo-sim's real-time tests: the unmodified daemon binary flying
//! against `atmo-sim serve` (and, in `sitl_boards`, real `atmo-roboclaw`
//! drivers on simulated boards behind pseudo-terminals), on the wall clock.
//!
//! A binary of their own, not modules of `tests/sim`, for the cost of one
//! more link (20-30 s): cargo runs test binaries one after the other, so
//! these flights never share the machine with the rest of the suite. A
//! pseudo-terminal's bytes reach the other side only when a kernel worker
//! thread runs; with both cores of a 2-core machine busy (the other tests
//! of one binary run two at a time), that took up to 2 s, measured with a
//! pty echo round trip beside two busy loops (p99 155 ms; a pipe: 0.14 ms),
//! and the flight through the boards lost its serial link for that long.
//! The tests also take [`sitl::serial`]: one flight at a time.

mod sitl;
mod sitl_boards;
mod sitl_preflight;
