//! The driver's TOML file: one board, in tilt or wheel mode. Its tables
//! are declared with `atmo_core::params!` (each key once, with doc,
//! default, range and unit); the file itself stays a strict serde derive
//! (`deny_unknown_fields`) because it keeps the path it was read from,
//! and checks what spans tables (the mode against `[tilt]`/`[wheels]`,
//! the tilt calibration's form).

use std::path::{Path, PathBuf};

use atmo_core::config_file::{Checker, ConfigFile};
use atmo_core::params::Params as _;
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

atmo_core::params! {
    /// The serial link.
    #[derive(Debug, Clone, PartialEq)]
    pub struct SerialConfig {
        /// Device path (`/dev/ttyACM0`, or a simulated board's pty).
        pub port: String;
        /// Baud rate (the board's packet-serial setting).
        pub baud: u32 = 115_200, range 2400..=460_800, unit "baud";
        /// Packet-serial address, 128..=135 (0x80..=0x87).
        pub address: u32 = 0x80, range 0x80..=0x87;
        /// How long one attempt waits for its answer.
        pub answer_timeout_ms: u64 = 10, range 1..=1000, unit "ms";
        /// Attempts after the first, per transaction.
        pub retries: u32 = 2, range 0..=10;
    }
    check |serial, c, prefix| {
        if serial.port.is_empty() {
            return Err(c.fail(&atmo_core::params::key(prefix, "port"), "a device path", "\"\""));
        }
        Ok(())
    }
}

atmo_core::params! {
    /// Timing and the two stops.
    #[derive(Debug, Clone, PartialEq)]
    pub struct TimingConfig: Default {
        /// Driver loop rate.
        pub rate_hz: f64 = 100.0, range 1.0..=1000.0, unit "Hz";
        /// The driver's watchdog: motors to zero when no command for this long.
        pub command_timeout_ms: u64 = 200, range 10..=10_000, unit "ms";
        /// The board's own serial timeout (set at start), a multiple of 100:
        /// the board stops both motors if the driver itself goes silent.
        pub board_serial_timeout_ms: u64 = 500, range 100..=25_500, unit "ms";
        /// How often the board's settings are read back (reset detection).
        pub health_check_period_ms: u64 = 500, range 10..=60_000, unit "ms";
    }
    check |timing, c, prefix| {
        if !timing.board_serial_timeout_ms.is_multiple_of(100) {
            return Err(c.fail(
                &atmo_core::params::key(prefix, "board_serial_timeout_ms"),
                "a multiple of 100 ms (the board counts tenths of a second)",
                timing.board_serial_timeout_ms,
            ));
        }
        Ok(())
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

atmo_core::params! {
    /// Tilt mode.
    #[derive(Debug, Clone, PartialEq)]
    pub struct TiltConfig {
        /// The robot file (relative to this file): its linkage model defines
        /// the counts the daemon reads on `tilt_encoder`.
        pub robot_file: PathBuf;
        /// `table` or `linkage`.
        pub calibration: CalibrationKind;
        /// Measured table: board counts (strictly increasing) ...
        pub table_counts: Vec<f64> = Vec::new();
        /// ... and the tilt at each (strictly monotonic, 0..=90).
        pub table_tilt_deg: Vec<f64> = Vec::new(), unit "deg";
        /// Linkage calibration: board counts per model count (+1 or -1).
        pub encoder_sign: f64 = -1.0;
        /// Tilt at the home switch (where the board's counter is 0).
        pub home_tilt_deg: f64 = 90.0, range 0.0..=90.0, unit "deg";
        /// No motion towards smaller tilt below this (the authors' 1 deg).
        pub min_tilt_deg: f64 = 1.0, range 0.0..=90.0, unit "deg";
        /// Speed limit of the tilt motor.
        pub max_speed_counts_per_s: f64, range 1.0..=1.0e7, unit "counts/s";
        /// Homing speed towards the switch (a magnitude, at most
        /// `max_speed_counts_per_s`).
        pub homing_speed_counts_per_s: f64,
            range 1.0..=max_speed_counts_per_s.max(1.0), unit "counts/s";
        /// Homing fails after this long.
        pub homing_timeout_s: f64 = 30.0, range 0.1..=600.0, unit "s";
        /// The home switch's input.
        pub home_switch: SwitchName = SwitchName::S5;
    }
}

atmo_core::params! {
    /// Wheel mode.
    #[derive(Debug, Clone, PartialEq)]
    pub struct WheelsConfig {
        /// The left wheel's motor; the right wheel is on the other.
        pub left_motor: MotorName;
        /// Board counts per rad of wheel rotation, signed (the sign turns a
        /// motor wired backwards); magnitude 1 to 1e6.
        pub left_counts_per_rad: f64, unit "counts/rad";
        /// The same for the right wheel.
        pub right_counts_per_rad: f64, unit "counts/rad";
        /// Speed limit of each motor.
        pub max_speed_counts_per_s: f64, range 1.0..=1.0e7, unit "counts/s";
    }
    check |wheels, c, prefix| {
        for (name, v) in [
            ("left_counts_per_rad", wheels.left_counts_per_rad),
            ("right_counts_per_rad", wheels.right_counts_per_rad),
        ] {
            c.range(
                &atmo_core::params::key(prefix, name),
                v.abs(),
                1.0..=1.0e6,
                "counts/rad (magnitude)",
            )?;
        }
        Ok(())
    }
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
        self.serial.check(&c, "serial")?;
        self.timing.check(&c, "timing")?;
        self.ports.check(&c, "ports")?;
        self.tilt.check(&c, "tilt")?;
        self.wheels.check(&c, "wheels")?;
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
                if self.wheels.is_none() {
                    return Err(c
                        .fail("wheels", "a [wheels] table in wheels mode", "none")
                        .into());
                }
                if self.tilt.is_some() {
                    return Err(c
                        .fail("tilt", "no [tilt] table in wheels mode", "one")
                        .into());
                }
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
