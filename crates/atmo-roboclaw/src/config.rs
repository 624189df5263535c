//! The driver's TOML file: one board, in tilt or wheel mode. Strict
//! (`deny_unknown_fields`), every value checked with its key, range and
//! unit through atmo-core's `ConfigFile`.

use std::path::{Path, PathBuf};

use atmo_core::config_file::{Checker, ConfigFile};
use atmo_core::{Linkage, RobotConfig};
use atmo_io::drivers::DriverPortsConfig;
use serde::Deserialize;

use crate::error::{Result, RoboclawError};
use crate::protocol::Motor;
use crate::sim::SwitchInput;
use crate::table::{Calibration, TiltCalibration, TiltTable};

/// What the board drives.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Mode {
    /// The tilt mechanism on M2: `tilt_velocity` in, `tilt_encoder` out.
    Tilt,
    /// The two wheel belt drives: `wheel_rates` in.
    Wheels,
}

/// A motor channel in the file: `"m1"` or `"m2"`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum MotorName {
    M1,
    M2,
}

impl From<MotorName> for Motor {
    fn from(m: MotorName) -> Self {
        match m {
            MotorName::M1 => Motor::M1,
            MotorName::M2 => Motor::M2,
        }
    }
}

/// The serial link.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SerialConfig {
    /// Device path (`/dev/ttyACM0`, or a simulated board's pty).
    pub port: String,
    /// Baud rate (the board's packet-serial setting).
    #[serde(default = "default_baud")]
    pub baud: u32,
    /// Packet-serial address, 128..=135 (0x80..=0x87).
    #[serde(default = "default_address")]
    pub address: u32,
    /// How long one attempt waits for its answer, ms.
    #[serde(default = "default_answer_timeout_ms")]
    pub answer_timeout_ms: u64,
    /// Attempts after the first, per transaction.
    #[serde(default = "default_retries")]
    pub retries: u32,
}

fn default_baud() -> u32 {
    115_200
}
fn default_address() -> u32 {
    0x80
}
fn default_answer_timeout_ms() -> u64 {
    10
}
fn default_retries() -> u32 {
    2
}

/// Timing and the two stops.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TimingConfig {
    /// Driver loop rate, Hz.
    pub rate_hz: f64,
    /// The driver's watchdog: motors to zero when no command for this long, ms.
    pub command_timeout_ms: u64,
    /// The board's own serial timeout (set at start), ms, a multiple of 100:
    /// the board stops both motors if the driver itself goes silent.
    pub board_serial_timeout_ms: u64,
    /// How often the board's settings are read back (reset detection), ms.
    pub health_check_period_ms: u64,
}

impl Default for TimingConfig {
    fn default() -> Self {
        Self {
            rate_hz: 100.0,
            command_timeout_ms: 200,
            board_serial_timeout_ms: 500,
            health_check_period_ms: 500,
        }
    }
}

/// Which calibration converts the tilt board's counts.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum CalibrationKind {
    Table,
    Linkage,
}

/// The home switch's input.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum SwitchName {
    S4,
    S5,
}

impl From<SwitchName> for SwitchInput {
    fn from(s: SwitchName) -> Self {
        match s {
            SwitchName::S4 => SwitchInput::S4,
            SwitchName::S5 => SwitchInput::S5,
        }
    }
}

/// Tilt mode.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TiltConfig {
    /// The robot file (relative to this file): its linkage model defines
    /// the counts the daemon reads on `tilt_encoder`.
    pub robot_file: PathBuf,
    pub calibration: CalibrationKind,
    /// Measured table: board counts (strictly increasing) ...
    #[serde(default)]
    pub table_counts: Vec<f64>,
    /// ... and the tilt at each, deg (strictly monotonic, 0..=90).
    #[serde(default)]
    pub table_tilt_deg: Vec<f64>,
    /// Linkage calibration: board counts per model count (+1 or -1).
    #[serde(default = "default_encoder_sign")]
    pub encoder_sign: f64,
    /// Tilt at the home switch (where the board's counter is 0), deg.
    #[serde(default = "default_home_tilt_deg")]
    pub home_tilt_deg: f64,
    /// No motion towards smaller tilt below this, deg (the authors' 1 deg).
    #[serde(default = "default_min_tilt_deg")]
    pub min_tilt_deg: f64,
    /// Speed limit of the tilt motor, counts/s.
    pub max_speed_counts_per_s: f64,
    /// Homing speed towards the switch, counts/s (a magnitude).
    pub homing_speed_counts_per_s: f64,
    /// Homing fails after this long, s.
    #[serde(default = "default_homing_timeout_s")]
    pub homing_timeout_s: f64,
    #[serde(default = "default_switch")]
    pub home_switch: SwitchName,
}

fn default_encoder_sign() -> f64 {
    -1.0
}
fn default_home_tilt_deg() -> f64 {
    90.0
}
fn default_min_tilt_deg() -> f64 {
    1.0
}
fn default_homing_timeout_s() -> f64 {
    30.0
}
fn default_switch() -> SwitchName {
    SwitchName::S5
}

/// Wheel mode.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WheelsConfig {
    /// The left wheel's motor; the right wheel is on the other.
    pub left_motor: MotorName,
    /// Board counts per rad of wheel rotation, signed (the sign turns a
    /// motor wired backwards).
    pub left_counts_per_rad: f64,
    pub right_counts_per_rad: f64,
    /// Speed limit of each motor, counts/s.
    pub max_speed_counts_per_s: f64,
}

/// One board's driver file.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RoboclawConfig {
    pub mode: Mode,
    pub serial: SerialConfig,
    #[serde(default)]
    pub timing: TimingConfig,
    /// The iceoryx2 driver ports (atmo-io's keys).
    #[serde(default)]
    pub ports: DriverPortsConfig,
    pub tilt: Option<TiltConfig>,
    pub wheels: Option<WheelsConfig>,
    /// Where the file was read from (relative paths resolve against it).
    #[serde(skip)]
    pub file: PathBuf,
}

impl ConfigFile for RoboclawConfig {
    type Error = RoboclawError;

    fn locate(&mut self, file: &Path) {
        self.file = file.to_path_buf();
        if let Some(tilt) = &mut self.tilt
            && tilt.robot_file.is_relative()
            && let Some(dir) = file.parent()
        {
            tilt.robot_file = dir.join(&tilt.robot_file);
        }
    }

    fn validate(&self, file: &Path) -> Result<()> {
        let c = Checker::new(file);
        let s = &self.serial;
        if s.port.is_empty() {
            return Err(c.fail("serial.port", "a device path", "\"\"").into());
        }
        c.range("serial.baud", u64::from(s.baud), 2400..=460_800, "baud")?;
        c.range("serial.address", u64::from(s.address), 0x80..=0x87, "")?;
        c.range(
            "serial.answer_timeout_ms",
            s.answer_timeout_ms,
            1..=1000,
            "ms",
        )?;
        c.range("serial.retries", u64::from(s.retries), 0..=10, "")?;
        let t = &self.timing;
        c.range("timing.rate_hz", t.rate_hz, 1.0..=1000.0, "Hz")?;
        c.range(
            "timing.command_timeout_ms",
            t.command_timeout_ms,
            10..=10_000,
            "ms",
        )?;
        c.range(
            "timing.board_serial_timeout_ms",
            t.board_serial_timeout_ms,
            100..=25_500,
            "ms",
        )?;
        if t.board_serial_timeout_ms % 100 != 0 {
            return Err(c
                .fail(
                    "timing.board_serial_timeout_ms",
                    "a multiple of 100 ms (the board counts tenths of a second)",
                    t.board_serial_timeout_ms,
                )
                .into());
        }
        c.range(
            "timing.health_check_period_ms",
            t.health_check_period_ms,
            10..=60_000,
            "ms",
        )?;
        // atmo-io names its keys from the table's root: say `ports.`.
        self.ports.validate(file).map_err(|e| match e {
            atmo_io::IoError::Config(atmo_core::CoreError::ConfigValue {
                file,
                key,
                expected,
                got,
            }) => RoboclawError::Core(atmo_core::CoreError::ConfigValue {
                file,
                key: format!("ports.{key}"),
                expected,
                got,
            }),
            other => other.into(),
        })?;
        match self.mode {
            Mode::Tilt => {
                let Some(tilt) = &self.tilt else {
                    return Err(c.fail("tilt", "a [tilt] table in tilt mode", "none").into());
                };
                if self.wheels.is_some() {
                    return Err(c
                        .fail("wheels", "no [wheels] table in tilt mode", "one")
                        .into());
                }
                validate_tilt(&c, tilt, file)?;
            }
            Mode::Wheels => {
                let Some(w) = &self.wheels else {
                    return Err(c
                        .fail("wheels", "a [wheels] table in wheels mode", "none")
                        .into());
                };
                if self.tilt.is_some() {
                    return Err(c
                        .fail("tilt", "no [tilt] table in wheels mode", "one")
                        .into());
                }
                for (key, v) in [
                    ("wheels.left_counts_per_rad", w.left_counts_per_rad),
                    ("wheels.right_counts_per_rad", w.right_counts_per_rad),
                ] {
                    c.range(key, v.abs(), 1.0..=1.0e6, "counts/rad (magnitude)")?;
                }
                c.range(
                    "wheels.max_speed_counts_per_s",
                    w.max_speed_counts_per_s,
                    1.0..=1.0e7,
                    "counts/s",
                )?;
            }
        }
        Ok(())
    }
}

fn validate_tilt(c: &Checker<'_>, tilt: &TiltConfig, file: &Path) -> Result<()> {
    match tilt.calibration {
        CalibrationKind::Table => {
            TiltTable::new(&tilt.table_counts, &tilt.table_tilt_deg, file, "tilt.")?;
        }
        CalibrationKind::Linkage => {
            if tilt.encoder_sign != 1.0 && tilt.encoder_sign != -1.0 {
                return Err(c
                    .fail("tilt.encoder_sign", "1 or -1", tilt.encoder_sign)
                    .into());
            }
            if !tilt.table_counts.is_empty() || !tilt.table_tilt_deg.is_empty() {
                return Err(c
                    .fail(
                        "tilt.table_counts",
                        "no table with calibration = \"linkage\"",
                        "a table",
                    )
                    .into());
            }
        }
    }
    c.range("tilt.home_tilt_deg", tilt.home_tilt_deg, 0.0..=90.0, "deg")?;
    c.range("tilt.min_tilt_deg", tilt.min_tilt_deg, 0.0..=90.0, "deg")?;
    c.range(
        "tilt.max_speed_counts_per_s",
        tilt.max_speed_counts_per_s,
        1.0..=1.0e7,
        "counts/s",
    )?;
    c.range(
        "tilt.homing_speed_counts_per_s",
        tilt.homing_speed_counts_per_s,
        1.0..=tilt.max_speed_counts_per_s.max(1.0),
        "counts/s (at most tilt.max_speed_counts_per_s)",
    )?;
    c.range(
        "tilt.homing_timeout_s",
        tilt.homing_timeout_s,
        0.1..=600.0,
        "s",
    )?;
    Ok(())
}

impl RoboclawConfig {
    /// The link settings.
    pub fn link(&self) -> crate::link::LinkSettings {
        crate::link::LinkSettings {
            address: self.serial.address as u8,
            baud: self.serial.baud,
            answer_timeout: std::time::Duration::from_millis(self.serial.answer_timeout_ms),
            retries: self.serial.retries,
        }
    }

    /// Tilt mode with a table: the table against the robot file's linkage
    /// model (with `tilt.encoder_sign` and `tilt.home_tilt_deg`).
    pub fn table_vs_linkage(&self) -> Result<Option<crate::table::LinkageComparison>> {
        let Some(tilt) = &self.tilt else {
            return Ok(None);
        };
        if tilt.calibration != CalibrationKind::Table {
            return Ok(None);
        }
        let robot = RobotConfig::load(&tilt.robot_file)?;
        let linkage = Linkage::from_config(&robot.linkage, robot.limits.tilt_max())?;
        let table = TiltTable::new(
            &tilt.table_counts,
            &tilt.table_tilt_deg,
            &self.file,
            "tilt.",
        )?;
        table
            .compare_with_linkage(&linkage, tilt.encoder_sign, tilt.home_tilt_deg.to_radians())
            .map(Some)
    }

    /// Loads the robot file and builds the tilt calibration (tilt mode).
    pub fn tilt_calibration(&self) -> Result<Option<TiltCalibration>> {
        let Some(tilt) = &self.tilt else {
            return Ok(None);
        };
        let robot = RobotConfig::load(&tilt.robot_file)?;
        let linkage = Linkage::from_config(&robot.linkage, robot.limits.tilt_max())?;
        let calibration = match tilt.calibration {
            CalibrationKind::Table => Calibration::Table(TiltTable::new(
                &tilt.table_counts,
                &tilt.table_tilt_deg,
                &self.file,
                "tilt.",
            )?),
            CalibrationKind::Linkage => Calibration::Linkage {
                sign: tilt.encoder_sign,
                home_counts: 0.0,
            },
        };
        TiltCalibration::new(calibration, linkage, tilt.home_tilt_deg.to_radians()).map(Some)
    }
}
