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
//!   type `application/toml`; `config/ground_effect` too when the MPC
//!   predicts with a plant file's ground-effect surface) and one metadata record [`CONFIG_METADATA`]
//!   with each file's source path and SHA-256, so that a replay rebuilds the
//!   same flight stack and notices an attachment that changed, and the
//!   configuration's schema version ([`crate::schema`]), so that a replay
//!   migrates an older text and refuses a newer one.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use atmo_core::ConfigFile as _;
use atmo_core::RobotConfig;
use atmo_io::mcap_log::{Channel, LogExtras, LoggerHandle};
use atmo_io::msg::{MpcStatus, TickInputs};
use atmo_mpc::settings::GroundEffectSource;
use atmo_mpc::{MpcFile, MpcSettings};
use sha2::{Digest, Sha256};

use crate::error::{FlightError, Result};
use crate::flight_stack::{FlightStack, StepInputs, StepOutputs};
use crate::ground_model::{ground_surface, surface_from_text};
use crate::schema::{CONFIG_SCHEMA_VERSION, SCHEMA_VERSION_KEY, logged_version, migrate_flight};
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
/// settings (the preset is the flight settings' `mpc_preset`), and the
/// plant file whose ground-effect surface the MPC predicts with when its
/// `[model] ground_effect` names one.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FlightConfigFiles {
    pub robot: ConfigText,
    pub flight: ConfigText,
    pub mpc: ConfigText,
    pub ground_effect: Option<ConfigText>,
    /// The schema version the texts were written with
    /// ([`CONFIG_SCHEMA_VERSION`] unless read from an older log).
    pub schema_version: u32,
    /// What bringing an older log's texts to this build's schema changed
    /// (empty when nothing was changed).
    pub migrated: Vec<String>,
}

/// A flight stack's configuration, parsed and validated.
#[derive(Debug, Clone, PartialEq)]
pub struct FlightConfig {
    pub robot: RobotConfig,
    pub flight: FlightSettings,
    pub mpc: MpcSettings,
    /// The text of the plant file `mpc.model.ground_effect` names, if it names one.
    pub ground_effect: Option<ConfigText>,
}

impl FlightConfig {
    /// Builds the flight stack (a ground-effect surface from the stored
    /// text, never re-read from disk).
    ///
    /// # Errors
    /// Settings the flight stack refuses.
    pub fn stack(&self) -> Result<FlightStack> {
        let surface = match (&self.mpc.model.ground_effect, &self.ground_effect) {
            (GroundEffectSource::File(_), Some(file)) => {
                Some(surface_from_text(&file.text, &file.source)?)
            }
            (GroundEffectSource::File(path), None) => {
                return Err(FlightError::Setup(format!(
                    "model.ground_effect: {}: its text is not loaded",
                    path.display()
                )));
            }
            (source, _) => ground_surface(source)?,
        };
        FlightStack::with_ground_surface(
            &self.robot,
            self.mpc.clone(),
            self.flight.clone(),
            surface,
        )
    }
}

const ROBOT: &str = "robot";
const FLIGHT: &str = "flight";
const MPC: &str = "mpc";
const GROUND_EFFECT: &str = "ground_effect";

impl FlightConfigFiles {
    /// Reads the three files, and the ground-effect file the MPC file names.
    ///
    /// # Errors
    /// A file that cannot be read, named; texts that do not parse.
    pub fn read(robot: &Path, flight: &Path, mpc: &Path) -> Result<Self> {
        let mut files = Self {
            robot: ConfigText::read(robot)?,
            flight: ConfigText::read(flight)?,
            mpc: ConfigText::read(mpc)?,
            ground_effect: None,
            schema_version: CONFIG_SCHEMA_VERSION,
            migrated: Vec::new(),
        };
        files.read_ground_effect()?;
        Ok(files)
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
            ground_effect: None,
            schema_version: CONFIG_SCHEMA_VERSION,
            migrated: Vec::new(),
        }
    }

    /// `(role, file)` of every file present.
    fn files(&self) -> Vec<(&'static str, &ConfigText)> {
        let mut files = vec![
            (ROBOT, &self.robot),
            (FLIGHT, &self.flight),
            (MPC, &self.mpc),
        ];
        files.extend(self.ground_effect.as_ref().map(|g| (GROUND_EFFECT, g)));
        files
    }

    fn files_mut(&mut self) -> Vec<&mut ConfigText> {
        let mut files = vec![&mut self.robot, &mut self.flight, &mut self.mpc];
        files.extend(self.ground_effect.as_mut());
        files
    }

    fn mpc_settings(&self) -> Result<(FlightSettings, MpcSettings)> {
        let flight = FlightSettings::from_toml_str(&self.flight.text, &self.flight.source)?;
        let mpc = MpcFile::from_toml_str(&self.mpc.text, &self.mpc.source)?
            .settings(&flight.mpc_preset)
            .map_err(|e| {
                FlightError::Setup(format!(
                    "{}: preset `{}` of {}: {e}",
                    self.mpc.source.display(),
                    flight.mpc_preset,
                    self.flight.source.display()
                ))
            })?;
        Ok((flight, mpc))
    }

    fn ground_effect_source(&self) -> Result<GroundEffectSource> {
        Ok(self.mpc_settings()?.1.model.ground_effect)
    }

    /// Reads the plant file the MPC text names as its ground-effect surface
    /// (none if it names none).
    fn read_ground_effect(&mut self) -> Result<()> {
        self.ground_effect = match self.ground_effect_source()? {
            GroundEffectSource::File(path) => Some(ConfigText::read(&path)?),
            _ => None,
        };
        Ok(())
    }

    /// Sets the MPC's `[model] ground_effect` in the MPC text (comments and
    /// layout kept) and reads the file it names, so that the texts stay
    /// the exact description of the flight stack flown (and logged).
    ///
    /// # Errors
    /// An MPC text that is not TOML, a file that cannot be read.
    pub fn set_ground_effect(&mut self, source: &GroundEffectSource) -> Result<()> {
        let value = match source {
            GroundEffectSource::None => "none".to_string(),
            GroundEffectSource::PlantDefault => "default".to_string(),
            GroundEffectSource::File(path) => path.display().to_string(),
        };
        self.set_mpc_value("model", "ground_effect", value)?;
        self.read_ground_effect()
    }

    /// Sets `key` of `[table]` in the MPC text (comments and layout kept),
    /// so that a setting changed for a flight is in the text its log stores.
    ///
    /// # Errors
    /// An MPC text that is not TOML.
    pub fn set_mpc_value(
        &mut self,
        table: &str,
        key: &str,
        value: impl Into<toml_edit::Value>,
    ) -> Result<()> {
        let mut doc: toml_edit::DocumentMut = self
            .mpc
            .text
            .parse()
            .map_err(|e| FlightError::Setup(format!("{}: {e}", self.mpc.source.display())))?;
        doc[table][key] = toml_edit::value(value);
        self.mpc.text = doc.to_string();
        Ok(())
    }

    /// Replaces the MPC file (and the ground-effect file it names).
    ///
    /// # Errors
    /// A file that cannot be read.
    pub fn set_mpc_file(&mut self, path: &Path) -> Result<()> {
        self.mpc = ConfigText::read(path)?;
        self.read_ground_effect()
    }

    /// Parses and validates the texts (errors name the source file, line, key).
    ///
    /// # Errors
    /// Bad TOML or values, an unknown MPC preset, a ground-effect file named
    /// but not held.
    pub fn parse(&self) -> Result<FlightConfig> {
        let robot = RobotConfig::from_toml_str(&self.robot.text, &self.robot.source)?;
        let (flight, mpc) = self.mpc_settings()?;
        if let (GroundEffectSource::File(path), None) =
            (&mpc.model.ground_effect, &self.ground_effect)
        {
            return Err(FlightError::Setup(format!(
                "{}: model.ground_effect names {}, whose text is missing",
                self.mpc.source.display(),
                path.display()
            )));
        }
        Ok(FlightConfig {
            robot,
            flight,
            mpc,
            ground_effect: self.ground_effect.clone(),
        })
    }

    /// Stores the texts in the log (attachments `config/<role>`) with the
    /// [`CONFIG_METADATA`] record (`<role>.source`, `<role>.sha256`,
    /// `schema_version`).
    /// Start-up only: allocates and may block.
    ///
    /// # Errors
    /// The logger has stopped.
    pub fn log_to(&self, log: &LoggerHandle, log_time_ns: u64) -> atmo_io::Result<()> {
        for (role, file) in self.files() {
            log.attach(
                &format!("config/{role}"),
                TOML_MEDIA_TYPE,
                log_time_ns,
                file.text.as_bytes().to_vec(),
            )?;
        }
        log.metadata(CONFIG_METADATA, self.metadata_entries())
    }

    /// The [`CONFIG_METADATA`] record's entries.
    fn metadata_entries(&self) -> BTreeMap<String, String> {
        let mut entries = BTreeMap::new();
        for (role, file) in self.files() {
            entries.insert(format!("{role}.source"), file.source.display().to_string());
            entries.insert(format!("{role}.sha256"), file.sha256());
        }
        let version = self.schema_version.to_string();
        entries.insert(SCHEMA_VERSION_KEY.to_string(), version);
        entries
    }

    /// The configuration stored in a log by [`Self::log_to`]; `file` names
    /// the log in errors. Each attachment's text must match its recorded hash.
    /// A log of an older schema version has its flight settings migrated
    /// ([`crate::schema`]; what changed is in `migrated`). The texts are
    /// not parsed here ([`Self::parse`] does that).
    ///
    /// # Errors
    /// No [`CONFIG_METADATA`] record, a missing attachment, text that is not
    /// UTF-8 or whose SHA-256 differs from the recorded one, a schema
    /// version newer than this build's.
    pub fn from_log(extras: &LogExtras, file: &Path) -> Result<Self> {
        let fail = |reason: String| FlightError::Log {
            file: file.to_path_buf(),
            reason,
        };
        let meta = extras.metadata(CONFIG_METADATA).ok_or_else(|| {
            fail(format!(
                "no `{CONFIG_METADATA}` metadata record: the log does not hold the configuration it was flown with"
            ))
        })?;
        let role = |role: &str| -> Result<ConfigText> {
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
            Ok(config)
        };
        let mut flight = role(FLIGHT)?;
        let schema_version = logged_version(
            meta.get(SCHEMA_VERSION_KEY).map(String::as_str),
            &flight.text,
        )
        .map_err(|e| fail(e.to_string()))?;
        let (text, migrated) =
            migrate_flight(&flight.text, schema_version).map_err(|e| fail(e.to_string()))?;
        flight.text = text;
        let files = Self {
            robot: role(ROBOT)?,
            flight,
            mpc: role(MPC)?,
            ground_effect: meta
                .contains_key(&format!("{GROUND_EFFECT}.sha256"))
                .then(|| role(GROUND_EFFECT))
                .transpose()?,
            schema_version,
            migrated,
        };
        Ok(files)
    }

    /// What-if: replaces every file whose name (the last path component of
    /// its source) is `path`'s, or, for a folder, is present in it; a new
    /// MPC file that names another ground-effect file reads that one.
    /// Returns the sources replaced.
    ///
    /// # Errors
    /// A path that is neither, a file that cannot be read, or one that
    /// replaces nothing (named, with the names that would match).
    pub fn override_with(&mut self, path: &Path) -> Result<Vec<PathBuf>> {
        let source_before = self.ground_effect_source()?;
        let mut replaced = Vec::new();
        let names: Vec<String> = self
            .files()
            .iter()
            .map(|(_, f)| file_name(&f.source))
            .collect();
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
            return Err(FlightError::Setup(format!(
                "--config {}: replaces none of the logged files ({})",
                path.display(),
                names.join(", ")
            )));
        }
        if self.ground_effect_source()? != source_before {
            self.read_ground_effect()?;
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

    /// What [`FlightConfigFiles::log_to`] stores, with the schema version
    /// `version` (`None`: a log written before versions were recorded).
    fn extras(files: &FlightConfigFiles, version: Option<&str>) -> atmo_io::mcap_log::LogExtras {
        let mut meta = files.metadata_entries();
        match version {
            Some(v) => meta.insert(SCHEMA_VERSION_KEY.to_string(), v.to_string()),
            None => meta.remove(SCHEMA_VERSION_KEY),
        };
        let attachments = files
            .files()
            .into_iter()
            .map(|(role, f)| atmo_io::mcap_log::LogAttachment {
                name: format!("config/{role}"),
                media_type: TOML_MEDIA_TYPE.to_string(),
                log_time_ns: 0,
                data: f.text.as_bytes().to_vec(),
            })
            .collect();
        atmo_io::mcap_log::LogExtras {
            attachments,
            metadata: vec![(CONFIG_METADATA.to_string(), meta)],
        }
    }

    #[test]
    fn a_log_records_its_schema_and_one_of_a_newer_schema_is_refused() {
        let files = FlightConfigFiles::shipped();
        let log = Path::new("f.mcap");
        let current = CONFIG_SCHEMA_VERSION.to_string();
        assert_eq!(
            FlightConfigFiles::from_log(&extras(&files, Some(&current)), log).unwrap(),
            files
        );
        // Unrecorded: the shipped flare is of the current schema.
        assert_eq!(
            FlightConfigFiles::from_log(&extras(&files, None), log).unwrap(),
            files
        );
        let newer = (CONFIG_SCHEMA_VERSION + 1).to_string();
        let e = FlightConfigFiles::from_log(&extras(&files, Some(&newer)), log)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("f.mcap")
                && e.contains(&format!(
                    "schema version {newer}, newer than this build's {current}"
                )),
            "{e}"
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
