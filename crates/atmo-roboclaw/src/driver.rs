//! The driver's logic, pure: commands and the clock in, board transactions
//! and the outputs for the driver ports out. No iceoryx2 here (the binary
//! wires it), so tests run it against the simulated board tick by tick.
//!
//! Phases: `Starting` (firmware read, motors stopped, the board's serial
//! timeout set and read back; retried every tick until it succeeds) ->
//! tilt: `Homing` (M2 towards the home switch until the status word shows
//! it, then the counter set to 0) -> `Running`; a homing that takes longer
//! than `homing_timeout_s` ends in `Failed` (motors stopped). A board reset
//! seen while running (the serial timeout read back is not ours, or the
//! counter jumped back to 0 faster than the motor can move) is counted and
//! sends the driver back to `Starting` (tilt: and homing again: the
//! counter's zero is lost).
//!
//! The pilot's encoder reset (`rehome` on the tilt velocity port) sends a
//! running or failed tilt driver back to `Homing`.
//!
//! Watchdog: while running, a command older than `command_timeout_ms` (or
//! none yet) commands zero speed; each fall into that state is counted.
//!
//! After start-up, a tick allocates nothing: fixed buffers, `Copy` errors,
//! the calibration's tables read only.

use crate::config::{Mode, RoboclawConfig};
use crate::error::Result;
use crate::link::{Board, LinkError, Transport};
use crate::protocol::{Motor, Version};
use crate::sim::SwitchInput;
use crate::table::TiltCalibration;

/// Where the driver is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Phase {
    Starting,
    Homing {
        since_ns: u64,
    },
    Running,
    /// Homing failed: motors stopped, nothing published.
    Failed,
}

/// Tilt-mode settings, resolved from the file.
#[derive(Debug, Clone)]
pub struct TiltSettings {
    pub calibration: TiltCalibration,
    pub max_speed: f64,
    pub homing_speed: f64,
    pub homing_timeout_ns: u64,
    /// Tilt range the motor may drive in, rad.
    pub min_tilt: f64,
    pub max_tilt: f64,
    pub switch: SwitchInput,
}

/// Wheel-mode settings.
#[derive(Debug, Clone, Copy)]
pub struct WheelSettings {
    /// Motor of the left and right wheel.
    pub motors: [Motor; 2],
    /// Counts per rad, left and right (signed).
    pub counts_per_rad: [f64; 2],
    pub max_speed: f64,
}

/// What the board drives.
#[derive(Debug, Clone)]
pub enum Role {
    Tilt(TiltSettings),
    Wheels(WheelSettings),
}

/// Everything the driver needs, resolved and validated.
#[derive(Debug, Clone)]
pub struct DriverSettings {
    pub role: Role,
    pub command_timeout_ns: u64,
    /// The board's serial timeout, 100 ms units.
    pub board_serial_timeout: u8,
    pub health_check_period_ns: u64,
}

impl DriverSettings {
    /// From a loaded file (reads the robot file in tilt mode).
    pub fn from_config(config: &RoboclawConfig) -> Result<Self> {
        let role = match config.mode {
            Mode::Tilt => {
                // Validation guarantees [tilt] in tilt mode.
                let (Some(tilt), Some(calibration)) = (&config.tilt, config.tilt_calibration()?)
                else {
                    return Err(atmo_core::config_file::Checker::new(&config.file)
                        .fail("tilt", "a [tilt] table in tilt mode", "none")
                        .into());
                };
                let (lo, hi) = calibration.tilt_range();
                Role::Tilt(TiltSettings {
                    calibration,
                    max_speed: tilt.max_speed_counts_per_s,
                    homing_speed: tilt.homing_speed_counts_per_s,
                    homing_timeout_ns: (tilt.homing_timeout_s * 1e9) as u64,
                    min_tilt: tilt.min_tilt_deg.to_radians().max(lo),
                    max_tilt: tilt.home_tilt_deg.to_radians().min(hi),
                    switch: tilt.home_switch.into(),
                })
            }
            Mode::Wheels => {
                let Some(w) = &config.wheels else {
                    return Err(atmo_core::config_file::Checker::new(&config.file)
                        .fail("wheels", "a [wheels] table in wheels mode", "none")
                        .into());
                };
                let left: Motor = w.left_motor.into();
                let right = if left == Motor::M1 {
                    Motor::M2
                } else {
                    Motor::M1
                };
                Role::Wheels(WheelSettings {
                    motors: [left, right],
                    counts_per_rad: [w.left_counts_per_rad, w.right_counts_per_rad],
                    max_speed: w.max_speed_counts_per_s,
                })
            }
        };
        Ok(Self {
            role,
            command_timeout_ns: config.timing.command_timeout_ms * 1_000_000,
            board_serial_timeout: (config.timing.board_serial_timeout_ms / 100).min(255) as u8,
            health_check_period_ns: config.timing.health_check_period_ms * 1_000_000,
        })
    }
}

/// A command from the daemon.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum DriverCommand {
    /// rad/s, positive towards drive.
    TiltVelocity(f64),
    /// rad/s, left and right.
    WheelRates([f64; 2]),
}

/// What one tick produced.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct TickOutput {
    /// Tilt mode, running: the linkage model's counts (publish on `tilt_encoder`).
    pub tilt_counts: Option<i64>,
    /// The tilt it stands for, rad.
    pub tilt: Option<f64>,
    /// The board's counters this tick (per motor, if read).
    pub encoders: [Option<i32>; 2],
    /// Speeds sent this tick, counts/s.
    pub speeds: [Option<i32>; 2],
    /// The driver is running and its board answers: send a heartbeat.
    pub alive: bool,
    /// The watchdog holds the motors at zero.
    pub watchdog_stop: bool,
}

/// Driver counters (the link's are in [`crate::link::BoardHealth`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct DriverCounters {
    pub ticks: u64,
    /// Times the watchdog stopped the motors (falls into stale commands).
    pub watchdog_stops: u64,
    pub homings: u64,
    pub homing_failures: u64,
    /// Commands refused (not finite, or of the other mode).
    pub bad_commands: u64,
    /// Encoder readings outside the calibration table.
    pub outside_table: u64,
    /// Completed start sequences.
    pub starts: u64,
    /// Homings the pilot asked for (the encoder reset switch's rising edges
    /// that started one).
    pub rehome_requests: u64,
}

/// Failed transactions in a row after which the driver stops sending
/// heartbeats (the daemon then sees it dead).
const MAX_CONSECUTIVE_FAILURES: u32 = 3;

/// The driver of one board.
#[derive(Debug, Clone)]
pub struct Driver {
    settings: DriverSettings,
    phase: Phase,
    last_command: Option<(DriverCommand, u64)>,
    stale: bool,
    /// The pilot's rehome request as last received (edges start a homing).
    rehome_held: bool,
    last_encoder: [Option<(i32, u64)>; 2],
    last_health_check_ns: u64,
    firmware: Option<Version>,
    last_status: u32,
    counters: DriverCounters,
}

impl Driver {
    pub fn new(settings: DriverSettings) -> Self {
        Self {
            settings,
            phase: Phase::Starting,
            last_command: None,
            stale: true,
            rehome_held: false,
            last_encoder: [None; 2],
            last_health_check_ns: 0,
            firmware: None,
            last_status: 0,
            counters: DriverCounters::default(),
        }
    }

    pub fn phase(&self) -> Phase {
        self.phase
    }

    pub fn counters(&self) -> DriverCounters {
        self.counters
    }

    pub fn firmware(&self) -> Option<&Version> {
        self.firmware.as_ref()
    }

    pub fn last_status(&self) -> u32 {
        self.last_status
    }

    pub fn settings(&self) -> &DriverSettings {
        &self.settings
    }

    /// Records a command received at `now_ns`.
    pub fn command(&mut self, command: DriverCommand, now_ns: u64) {
        let ok = match (command, &self.settings.role) {
            (DriverCommand::TiltVelocity(v), Role::Tilt(_)) => v.is_finite(),
            (DriverCommand::WheelRates(r), Role::Wheels(_)) => r.iter().all(|v| v.is_finite()),
            _ => false,
        };
        if ok {
            self.last_command = Some((command, now_ns));
        } else {
            self.counters.bad_commands += 1;
        }
    }

    /// The pilot's request to home again, as received with each command:
    /// its rising edge starts a homing of a running tilt driver, or retries
    /// a failed one (the counter's zero is found again on the switch). A
    /// request held on does not repeat it.
    pub fn rehome_request(&mut self, requested: bool, now_ns: u64) {
        let rising = requested && !self.rehome_held;
        self.rehome_held = requested;
        if rising
            && matches!(self.settings.role, Role::Tilt(_))
            && matches!(self.phase, Phase::Running | Phase::Failed)
        {
            self.counters.rehome_requests += 1;
            self.last_encoder = [None; 2];
            self.phase = Phase::Homing { since_ns: now_ns };
        }
    }

    /// The fresh command, if any (the watchdog's view).
    fn fresh_command(&mut self, now_ns: u64) -> Option<DriverCommand> {
        let fresh = self.last_command.and_then(|(c, t)| {
            (now_ns.saturating_sub(t) <= self.settings.command_timeout_ns).then_some(c)
        });
        let stale = fresh.is_none();
        if stale && !self.stale && self.last_command.is_some() {
            self.counters.watchdog_stops += 1;
        }
        self.stale = stale;
        fresh
    }

    /// One tick at `now_ns`: the phase's transactions with the board.
    pub fn tick<T: Transport>(&mut self, board: &mut Board<T>, now_ns: u64) -> TickOutput {
        self.counters.ticks += 1;
        let mut out = TickOutput::default();
        match self.phase {
            Phase::Starting => {
                if self.start(board).is_ok() {
                    self.counters.starts += 1;
                    self.last_health_check_ns = now_ns;
                    self.last_encoder = [None; 2];
                    self.phase = match self.settings.role {
                        Role::Tilt(_) => Phase::Homing { since_ns: now_ns },
                        Role::Wheels(_) => Phase::Running,
                    };
                }
            }
            Phase::Homing { since_ns } => self.home(board, now_ns, since_ns),
            Phase::Running => {
                // Errors are counted in the board's health; the tick goes on.
                let _ = self.run(board, now_ns, &mut out);
                out.alive = self.phase == Phase::Running
                    && board.health().consecutive_failures < MAX_CONSECUTIVE_FAILURES;
            }
            Phase::Failed => {
                let _ = board.stop();
            }
        }
        out
    }

    /// The start sequence; the first failure ends it (retried next tick).
    fn start<T: Transport>(&mut self, board: &mut Board<T>) -> std::result::Result<(), LinkError> {
        self.firmware = Some(board.read_firmware_version()?);
        board.stop()?;
        board.set_serial_timeout(self.settings.board_serial_timeout)?;
        let read_back = board.read_serial_timeout()?;
        if read_back != self.settings.board_serial_timeout {
            // A board that does not keep the setting: treat like no answer.
            return Err(LinkError::Unexpected {
                command: crate::protocol::Command::ReadSerialTimeout,
                reply: crate::protocol::Reply::SerialTimeout(read_back),
            });
        }
        self.last_status = board.read_status()?;
        Ok(())
    }

    fn home<T: Transport>(&mut self, board: &mut Board<T>, now_ns: u64, since_ns: u64) {
        let Role::Tilt(tilt) = &self.settings.role else {
            self.phase = Phase::Running;
            return;
        };
        let (switch, speed, timeout) = (
            tilt.switch.status_bit(),
            tilt.homing_speed,
            tilt.homing_timeout_ns,
        );
        let Ok(status) = board.read_status() else {
            return;
        };
        self.last_status = status;
        if status & switch != 0 {
            // At home: stop there and make sure the counter reads 0 (the
            // board's Home mode does it too; a board without it needs it).
            if board.set_speed(Motor::M2, 0).is_ok() && board.set_encoder(Motor::M2, 0).is_ok() {
                self.counters.homings += 1;
                self.last_encoder = [None; 2];
                self.phase = Phase::Running;
            }
            return;
        }
        if now_ns.saturating_sub(since_ns) > timeout {
            self.counters.homing_failures += 1;
            let _ = board.stop();
            self.phase = Phase::Failed;
            return;
        }
        // The counter grows away from home: home is towards negative speed.
        let _ = board.set_speed(Motor::M2, -(speed.round() as i32));
    }

    /// A board reset: counted, and the start (and homing) again.
    fn board_reset<T: Transport>(&mut self, board: &mut Board<T>) {
        board.health_mut().resets += 1;
        let _ = board.stop();
        self.phase = Phase::Starting;
    }

    /// True if `count` of `motor` at `now_ns` is back near the counter's
    /// power-up value, reached faster than the motor can move.
    fn encoder_jumped_to_zero(
        &self,
        motor: Motor,
        count: i32,
        now_ns: u64,
        max_speed: f64,
    ) -> bool {
        let Some((previous, t)) = self.last_encoder[motor.index()] else {
            return false;
        };
        let dt = now_ns.saturating_sub(t) as f64 * 1e-9;
        // Twice the speed limit and a margin of 50 counts: only a jump the
        // motor cannot make, and one that lands where a counter starts
        // (0, plus what the coasting rotor turned since).
        let reach = 2.0 * max_speed * dt + 50.0;
        let jump = (f64::from(count) - f64::from(previous)).abs();
        jump > reach && f64::from(count).abs() <= reach
    }

    fn run<T: Transport>(
        &mut self,
        board: &mut Board<T>,
        now_ns: u64,
        out: &mut TickOutput,
    ) -> std::result::Result<(), LinkError> {
        if now_ns.saturating_sub(self.last_health_check_ns) >= self.settings.health_check_period_ns
        {
            self.last_health_check_ns = now_ns;
            // After a reset the board has its stored timeout, not ours. A
            // failed read is counted in the board's health and must not
            // keep this tick from commanding the motors.
            if let Ok(timeout) = board.read_serial_timeout()
                && timeout != self.settings.board_serial_timeout
            {
                self.board_reset(board);
                return Ok(());
            }
            if let Ok(status) = board.read_status() {
                self.last_status = status;
            }
        }
        let command = self.fresh_command(now_ns);
        out.watchdog_stop = command.is_none();
        match self.settings.role.clone_kind() {
            RoleKind::Tilt => self.run_tilt(board, now_ns, command, out),
            RoleKind::Wheels => self.run_wheels(board, now_ns, command, out),
        }
    }

    fn run_tilt<T: Transport>(
        &mut self,
        board: &mut Board<T>,
        now_ns: u64,
        command: Option<DriverCommand>,
        out: &mut TickOutput,
    ) -> std::result::Result<(), LinkError> {
        let Role::Tilt(tilt) = &self.settings.role else {
            return Ok(());
        };
        let max_speed = tilt.max_speed;
        let (count, _) = board.read_encoder(Motor::M2)?;
        if self.encoder_jumped_to_zero(Motor::M2, count, now_ns, max_speed) {
            self.board_reset(board);
            return Ok(());
        }
        let Role::Tilt(tilt) = &self.settings.role else {
            return Ok(());
        };
        self.last_encoder[Motor::M2.index()] = Some((count, now_ns));
        out.encoders[Motor::M2.index()] = Some(count);
        let reading = tilt.calibration.read(f64::from(count));
        out.tilt = Some(reading.tilt);
        out.tilt_counts = Some(reading.model_counts.round() as i64);
        let mut velocity = match command {
            Some(DriverCommand::TiltVelocity(v)) => v,
            _ => 0.0,
        };
        // Stay inside the calibrated range: the table says nothing beyond.
        if (reading.tilt <= tilt.min_tilt && velocity < 0.0)
            || (reading.tilt >= tilt.max_tilt && velocity > 0.0)
        {
            velocity = 0.0;
        }
        let speed = (velocity * tilt.calibration.counts_per_rad(reading.tilt))
            .clamp(-max_speed, max_speed)
            .round() as i32;
        if reading.outside {
            self.counters.outside_table += 1;
        }
        out.speeds[Motor::M2.index()] = Some(speed);
        board.set_speed(Motor::M2, speed)
    }

    fn run_wheels<T: Transport>(
        &mut self,
        board: &mut Board<T>,
        now_ns: u64,
        command: Option<DriverCommand>,
        out: &mut TickOutput,
    ) -> std::result::Result<(), LinkError> {
        let Role::Wheels(w) = &self.settings.role else {
            return Ok(());
        };
        let w = *w;
        let rates = match command {
            Some(DriverCommand::WheelRates(r)) => r,
            _ => [0.0; 2],
        };
        for motor in [Motor::M1, Motor::M2] {
            let (count, _) = board.read_encoder(motor)?;
            if self.encoder_jumped_to_zero(motor, count, now_ns, w.max_speed) {
                self.board_reset(board);
                return Ok(());
            }
            self.last_encoder[motor.index()] = Some((count, now_ns));
            out.encoders[motor.index()] = Some(count);
        }
        let mut result = Ok(());
        for side in 0..2 {
            let motor = w.motors[side];
            let speed = (rates[side] * w.counts_per_rad[side])
                .clamp(-w.max_speed, w.max_speed)
                .round() as i32;
            out.speeds[motor.index()] = Some(speed);
            // Both motors are commanded even if one transaction fails.
            result = result.and(board.set_speed(motor, speed));
        }
        result
    }
}

/// The role without its data (to dispatch without borrowing it).
enum RoleKind {
    Tilt,
    Wheels,
}

impl Role {
    fn clone_kind(&self) -> RoleKind {
        match self {
            Self::Tilt(_) => RoleKind::Tilt,
            Self::Wheels(_) => RoleKind::Wheels,
        }
    }
}
