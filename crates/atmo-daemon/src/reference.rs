//! The parameter reference, `docs/parameters.md`: every key of the files
//! the onboard binary reads, as their `atmo_core::params!` declarations
//! say (`atmo-daemon check --params`).

use atmo_core::params::{Params, markdown_table};

use crate::onboard::DaemonConfig;

/// The reference: the robot, flight and MPC files, the ground-effect
/// surface the MPC may predict with (the files a flight log holds), and
/// the daemon file.
pub fn parameter_reference() -> String {
    let mut surface = Vec::new();
    atmo_core::ground_effect::GroundEffectConfig::list("effects.ground_effect", &mut surface);
    let tables = [
        markdown_table(
            "robot (config/atmo.toml)",
            &atmo_core::RobotConfig::params(),
        ),
        markdown_table(
            "flight (config/flight.toml)",
            &atmo_flight::settings::FlightSettings::params(),
        ),
        markdown_table("MPC (config/mpc.toml)", &atmo_mpc::MpcFile::params()),
        markdown_table(
            "ground-effect surface (a plant file's, when the MPC's model.ground_effect names one)",
            &surface,
        ),
        markdown_table("daemon (config/daemon.toml)", &DaemonConfig::params()),
    ];
    format!(
        "# Parameters\n\nGenerated from the declarations (`atmo_core::params!`) by \
         `cargo run -p atmo-daemon -- check --params > docs/parameters.md`; a test \
         checks it is current. A key with a default may be left out of a file; \
         `required` keys may not. Ranges are as declared (they may name other keys \
         of the table). The daemon file's `[ros2]` and `[drivers]` are atmo-io's \
         tables (docs/onboard.md); a topic's `type` is one its role takes.\n\n{}",
        tables.join("\n")
    )
}
