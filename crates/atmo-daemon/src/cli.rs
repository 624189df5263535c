//! Command-line argument groups shared by the binaries that read the
//! daemon's config: `atmo-daemon run|check` and `atmo-sim serve` (which must
//! agree with the daemon on topics, driver ports and the iceoryx2 prefix).
//! Behind the `cli` feature, so that the flight stack builds without clap.

use std::path::PathBuf;

use atmo_core::ConfigFile;

use crate::onboard::DaemonConfig;
use atmo_flight::error::Result;

/// `--config`: the daemon's config file.
#[derive(Debug, Clone, clap::Args)]
pub struct DaemonConfigArg {
    /// Daemon config (TOML): robot, flight and MPC files, ground height,
    /// input timeouts, `[log]`, `[ros2]` topics, `[drivers]` ports.
    #[arg(
        long = "config",
        value_name = "FILE",
        default_value = "config/daemon.toml"
    )]
    pub config: PathBuf,
}

impl DaemonConfigArg {
    /// Loads and validates the file (see [`DaemonConfig`]).
    ///
    /// # Errors
    /// A file that cannot be read, parsed or validated, named with the key.
    pub fn load(&self) -> Result<DaemonConfig> {
        DaemonConfig::load(&self.config)
    }
}
