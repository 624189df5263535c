//! atmo-sim: the built-in plant and the tools around it.
//!
//! Today it holds the `atmo-sim physics` command (what the physics of
//! atmo-core gives for a robot file). The plant with the effects the
//! controller leaves out, scenarios and the closed-loop runner are issue 3 and 5.
