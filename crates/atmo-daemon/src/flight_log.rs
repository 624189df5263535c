//! What a flight log holds so that the flight can be replayed: every tick's
//! inputs and outputs, and the configuration the flight stack was built from.
//!
//! - Per tick, two channels: [`INPUTS_TOPIC`] (`atmo_msgs/TickInputs`:
//!   every field of [`StepInputs`], the tick's clock value included) and the
//!   status topic (`atmo_msgs/MpcStatus`: the outputs). Both are fixed-size
//!   records copied into the logger's queue: no allocation on the control
//!   thread.
//! - At start, the configuration: the robot, flight and MPC files' texts as
//!   MCAP attachments (`config/robot`, `config/flight`, `config/mpc`, media
//!   type `application/toml`) and one metadata record [`CONFIG_METADATA`]
//!   with each file's source path and SHA-256, so that a replay rebuilds the
//!   same flight stack and notices an attachment that changed.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use atmo_core::ConfigFile as _;
use atmo_core::RobotConfig;
use atmo_io::mcap_log::{Channel, LogExtras, LoggerHandle};
use atmo_io::msg::{MpcStatus, TickInputs};
use atmo_mpc::{MpcFile, MpcSettings};
use sha2::{Digest, Sha256};

use crate::error::{DaemonError, Result};
use crate::flight_stack::{FlightStack, StepInputs, StepOutputs};
use crate::settings::FlightSettings;

/// Topic of the per-tick inputs.
pub const INPUTS_TOPIC: &str = "/atmo/tick_inputs";
/// Name of the metadata record that describes the configuration attachments.
pub const CONFIG_METADATA: &str = "atmo.config";
/// Media type of the configuration attachments.
pub const TOML_MEDIA_TYPE: &str = "application/toml";

/// The two per-tick channels of a flight log.
#[derive(Debug, Clone, Copy)]
pub struct TickChannels {
    pub status: Channel<MpcStatus>,
    pub inputs: Channel<TickInputs>,
}

impl TickChannels {
    /// Registers the status channel on `status_topic` and the inputs on
    /// [`INPUTS_TOPIC`] (start-up: allocates, may block).
    ///
    /// # Errors
    /// A topic the logger refuses.
    pub fn register(log: &LoggerHandle, status_topic: &str) -> atmo_io::Result<Self> {
        Ok(Self {
            status: log.channel(status_topic)?,
            inputs: log.channel(INPUTS_TOPIC)?,
        })
    }

    /// Queues one tick's inputs (with the solves the time limit cut,
    /// `outputs.status.solver_cuts`) and status, both stamped with the
    /// tick's clock. Never blocks, never allocates; a full queue drops and counts.
    pub fn log_tick(
        &self,
        log: &LoggerHandle,
        tick: u64,
        inputs: &StepInputs,
        outputs: &StepOutputs,
        status: &MpcStatus,
    ) {
        log.try_log(
            self.inputs,
            inputs.now_ns,
            &crate::telemetry::inputs_message(tick, inputs, &outputs.status.solver_cuts),
        );
        log.try_log(self.status, inputs.now_ns, status);
    }
}

/// One configuration file: where it came from and its exact text.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ConfigText {
    /// The path it was read from (as given), or a name for built-in texts.
    pub source: PathBuf,
    pub text: String,
}

impl ConfigText {
    /// SHA-256 of the text, lower-case hex.
    pub fn sha256(&self) -> String {
        use std::fmt::Write as _;
        let mut hex = String::with_capacity(64);
        for byte in Sha256::digest(self.text.as_bytes()) {
            let _ = write!(hex, "{byte:02x}");
        }
        hex
    }

    fn read(path: &Path) -> Result<Self> {
        Ok(Self {
            source: path.to_path_buf(),
            text: atmo_core::config_file::read_config_file(path)?,
        })
    }
}

/// The files a flight stack is built from: robot, flight settings, MPC
/// settings (the preset is the flight settings' `mpc_preset`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FlightConfigFiles {
    pub robot: ConfigText,
    pub flight: ConfigText,
    pub mpc: ConfigText,
}

/// A flight stack's configuration, parsed and validated.
#[derive(Debug, Clone, PartialEq)]
pub struct FlightConfig {
    pub robot: RobotConfig,
    pub flight: FlightSettings,
    pub mpc: MpcSettings,
}

impl FlightConfig {
    /// Builds the flight stack.
    ///
    /// # Errors
    /// Settings the flight stack refuses.
    pub fn stack(&self) -> Result<FlightStack> {
        FlightStack::new(&self.robot, self.mpc.clone(), self.flight.clone())
    }
}

const ROLES: [&str; 3] = ["robot", "flight", "mpc"];

impl FlightConfigFiles {
    /// Reads the three files.
    ///
    /// # Errors
    /// A file that cannot be read, named.
    pub fn read(robot: &Path, flight: &Path, mpc: &Path) -> Result<Self> {
        Ok(Self {
            robot: ConfigText::read(robot)?,
            flight: ConfigText::read(flight)?,
            mpc: ConfigText::read(mpc)?,
        })
    }

    /// The shipped config/atmo.toml, config/flight.toml and config/mpc.toml
    /// (the texts built into the binary, as `RobotConfig::atmo()` and friends).
    pub fn shipped() -> Self {
        let text = |source: &str, text: &str| ConfigText {
            source: PathBuf::from(source),
            text: text.to_string(),
        };
        Self {
            robot: text(
                "config/atmo.toml",
                include_str!("../../../config/atmo.toml"),
            ),
            flight: text(
                "config/flight.toml",
                include_str!("../../../config/flight.toml"),
            ),
            mpc: text("config/mpc.toml", include_str!("../../../config/mpc.toml")),
        }
    }

    fn files(&self) -> [&ConfigText; 3] {
        [&self.robot, &self.flight, &self.mpc]
    }

    fn files_mut(&mut self) -> [&mut ConfigText; 3] {
        [&mut self.robot, &mut self.flight, &mut self.mpc]
    }

    /// Parses and validates the texts (errors name the source file, line, key).
    ///
    /// # Errors
    /// Bad TOML or values, an unknown MPC preset.
    pub fn parse(&self) -> Result<FlightConfig> {
        let robot = RobotConfig::from_toml_str(&self.robot.text, &self.robot.source)?;
        let flight = FlightSettings::from_toml_str(&self.flight.text, &self.flight.source)?;
        let mpc = MpcFile::from_toml_str(&self.mpc.text, &self.mpc.source)?
            .settings(&flight.mpc_preset)
            .map_err(|e| {
                DaemonError::Setup(format!(
                    "{}: preset `{}` of {}: {e}",
                    self.mpc.source.display(),
                    flight.mpc_preset,
                    self.flight.source.display()
                ))
            })?;
        Ok(FlightConfig { robot, flight, mpc })
    }

    /// Stores the texts in the log (attachments `config/<role>`) with the
    /// [`CONFIG_METADATA`] record (`<role>.source`, `<role>.sha256`).
    /// Start-up only: allocates and may block.
    ///
    /// # Errors
    /// The logger has stopped.
    pub fn log_to(&self, log: &LoggerHandle, log_time_ns: u64) -> atmo_io::Result<()> {
        let mut entries = BTreeMap::new();
        for (role, file) in ROLES.iter().zip(self.files()) {
            log.attach(
                &format!("config/{role}"),
                TOML_MEDIA_TYPE,
                log_time_ns,
                file.text.as_bytes().to_vec(),
            )?;
            entries.insert(format!("{role}.source"), file.source.display().to_string());
            entries.insert(format!("{role}.sha256"), file.sha256());
        }
        log.metadata(CONFIG_METADATA, entries)
    }

    /// The configuration stored in a log by [`Self::log_to`]; `file` names
    /// the log in errors. Each attachment's text must match its recorded hash.
    ///
    /// # Errors
    /// No [`CONFIG_METADATA`] record, a missing attachment, text that is not
    /// UTF-8 or whose SHA-256 differs from the recorded one.
    pub fn from_log(extras: &LogExtras, file: &Path) -> Result<Self> {
        let fail = |reason: String| DaemonError::Log {
            file: file.to_path_buf(),
            reason,
        };
        let meta = extras.metadata(CONFIG_METADATA).ok_or_else(|| {
            fail(format!(
                "no `{CONFIG_METADATA}` metadata record: the log does not hold the configuration it was flown with"
            ))
        })?;
        let mut texts = Vec::with_capacity(3);
        for role in ROLES {
            let name = format!("config/{role}");
            let attachment = extras
                .attachment(&name)
                .ok_or_else(|| fail(format!("attachment `{name}` is missing")))?;
            let text = String::from_utf8(attachment.data.clone())
                .map_err(|e| fail(format!("attachment `{name}`: not UTF-8 text ({e})")))?;
            let entry = |key: &str| {
                meta.get(&format!("{role}.{key}")).ok_or_else(|| {
                    fail(format!(
                        "metadata `{CONFIG_METADATA}` has no key `{role}.{key}`"
                    ))
                })
            };
            let config = ConfigText {
                source: PathBuf::from(entry("source")?),
                text,
            };
            let recorded = entry("sha256")?;
            let actual = config.sha256();
            if *recorded != actual {
                return Err(fail(format!(
                    "attachment `{name}` is corrupt: SHA-256 {actual}, recorded {recorded}"
                )));
            }
            texts.push(config);
        }
        let mut texts = texts.into_iter();
        let mut next = || {
            texts
                .next()
                .ok_or_else(|| fail("internal: role count".into()))
        };
        Ok(Self {
            robot: next()?,
            flight: next()?,
            mpc: next()?,
        })
    }

    /// What-if: replaces every file whose name (the last path component of
    /// its source) is `path`'s, or, for a folder, is present in it. Returns
    /// the sources replaced.
    ///
    /// # Errors
    /// A path that is neither, a file that cannot be read, or one that
    /// replaces nothing (named, with the names that would match).
    pub fn override_with(&mut self, path: &Path) -> Result<Vec<PathBuf>> {
        let mut replaced = Vec::new();
        let names: Vec<String> = self.files().iter().map(|f| file_name(&f.source)).collect();
        for (file, name) in self.files_mut().into_iter().zip(&names) {
            let candidate = if path.is_dir() {
                path.join(name)
            } else if file_name(path) == *name {
                path.to_path_buf()
            } else {
                continue;
            };
            if candidate.is_file() {
                *file = ConfigText::read(&candidate)?;
                replaced.push(candidate);
            }
        }
        if replaced.is_empty() {
            return Err(DaemonError::Setup(format!(
                "--config {}: replaces none of the logged files ({})",
                path.display(),
                names.join(", ")
            )));
        }
        Ok(replaced)
    }
}

fn file_name(path: &Path) -> String {
    path.file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shipped_files_parse_to_the_built_in_settings() {
        let parsed = FlightConfigFiles::shipped().parse().unwrap();
        assert_eq!(parsed.robot, RobotConfig::atmo());
        assert_eq!(parsed.flight, FlightSettings::atmo());
        assert_eq!(
            parsed.mpc,
            MpcSettings::atmo(&parsed.flight.mpc_preset).unwrap()
        );
    }

    #[test]
    fn hash_is_sha256_hex() {
        let t = ConfigText {
            source: "x".into(),
            text: "abc".into(),
        };
        assert_eq!(
            t.sha256(),
            "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
        );
    }
}
