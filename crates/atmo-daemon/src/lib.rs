//! atmo-daemon: the flight stack and the onboard binary.
//!
//! Not built yet (issue 5). It will hold: `FlightStack` (mode state machine,
//! reference generation, tilt and drive control, failsafes) with a pure
//! `step(inputs, now)`, and the 150 Hz control loop that wires it to atmo-io.
