//! SITL down to the serial bytes: the robot's two Roboclaw boards
//! simulated on pseudo-terminals (atmo-roboclaw's `SimBoard`), each driven
//! by a real `atmo-roboclaw run` process on the driver ports, with the
//! plant owning the mechanisms.
//!
//! ```text
//! daemon --tilt_velocity--> atmo-roboclaw (tilt) --packet serial--> SimBoard (pty) --M2 speed--> plant tilt rate
//!        <--tilt_encoder--                       <--encoder counts-          <--true position-- plant tilt
//! daemon --wheel_rates----> atmo-roboclaw (wheels) -------------> SimBoard (pty) --M1/M2 speeds--> plant wheel rates
//! ```
//!
//! Each plant step the tilt board's M2 is put at the plant's tilt (its
//! counts by the driver file's own calibration, so the driver reads the
//! plant's tilt back), and the plant's tilt rate is M2's speed (after the
//! board's first-order speed response) over the calibration's counts per
//! rad; the wheel rates are the wheel board's speeds over the driver
//! file's counts per rad.
//!
//! Bring-up: the tilt driver homes. Until then the board runs its own
//! motor model (the plant is frozen before the daemon arms); once the home
//! switch has triggered and M2 has rested for [`PLACE_AFTER`], the board's
//! mechanism is placed at the plant's tilt (the robot homed on the bench,
//! then set at the scenario's start) and from then on follows the plant.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::Arc;
use std::time::{Duration, Instant};

use atmo_core::ConfigFile;
use atmo_io::drivers::DriverPortsConfig;
use atmo_roboclaw::config::RoboclawConfig;
use atmo_roboclaw::driver::{DriverSettings, Role};
use atmo_roboclaw::protocol::Motor;
use atmo_roboclaw::pty::PtyServer;
use atmo_roboclaw::sim::{MonotonicClock, SimBoard, SimConfig};
use atmo_roboclaw::table::TiltCalibration;

use crate::error::{Result, SimError};

/// The homed tilt board is placed at the plant's tilt after M2 has rested
/// this long after the switch (the driver zeroes the counter and starts
/// running in that time).
pub const PLACE_AFTER: Duration = Duration::from_millis(500);

/// Counts between the tilt board's power-up position and its home switch.
const HOMING_TRAVEL_COUNTS: f64 = 2000.0;

/// The simulated boards' turnaround given to the drivers (their
/// `--answer-timeout-ms`), instead of the driver file's 10 ms for a real
/// board. A real Roboclaw answers within a millisecond of the request's
/// last byte; a simulated one answers when the host's scheduler runs its
/// thread, and on a shared 2-core host that takes 20-100 ms for one answer
/// in a few hundred (the drivers' `answer ms` histogram in their logs,
/// measured beside CPU-bound jobs). Late answers are matched, not misread
/// (`atmo_roboclaw::link`), but each one costs a retry.
pub const SIM_TURNAROUND_MS: u64 = 100;

/// What to fly the boards with.
#[derive(Debug, Clone)]
pub struct BoardFiles {
    /// The tilt board's driver file (config/drivers/tilt.toml).
    pub tilt: PathBuf,
    /// The wheel board's driver file (config/drivers/wheels.toml).
    pub wheels: PathBuf,
    /// The `atmo-roboclaw` binary.
    pub driver_binary: PathBuf,
    /// Where the drivers' stderr goes (`roboclaw-tilt.log`,
    /// `roboclaw-wheels.log`); `None`: discarded.
    pub log_dir: Option<PathBuf>,
}

/// Where the tilt board is in its bring-up.
#[derive(Debug, Clone, Copy, PartialEq)]
enum TiltPhase {
    /// Homing on its own motor model.
    Homing,
    /// The switch has triggered; placed once M2 rests until `at`.
    Homed { rest_since: Option<Instant> },
    /// Following the plant; board position = `offset` + board counts.
    Placed { offset: f64 },
}

/// The two simulated boards and their driver processes.
pub struct SimBoards {
    tilt: PtyServer,
    wheels: PtyServer,
    calibration: TiltCalibration,
    wheel_motors: [Motor; 2],
    wheel_counts_per_rad: [f64; 2],
    phase: TiltPhase,
    drivers: Vec<Child>,
}

fn setup(what: &str, e: impl std::fmt::Display) -> SimError {
    SimError::Setup(format!("{what}: {e}"))
}

fn load(path: &Path) -> Result<(RoboclawConfig, DriverSettings)> {
    let config = RoboclawConfig::load(path).map_err(|e| setup("driver file", e))?;
    let settings = DriverSettings::from_config(&config).map_err(|e| setup("driver file", e))?;
    Ok((config, settings))
}

impl SimBoards {
    /// Opens both boards on pseudo-terminals and starts one
    /// `atmo-roboclaw run` per board on `ports`.
    pub fn start(files: &BoardFiles, ports: &DriverPortsConfig) -> Result<Self> {
        let (_, tilt_settings) = load(&files.tilt)?;
        let (_, wheel_settings) = load(&files.wheels)?;
        let Role::Tilt(tilt) = tilt_settings.role else {
            return Err(setup(&files.tilt.display().to_string(), "not a tilt board"));
        };
        let Role::Wheels(wheels) = wheel_settings.role else {
            return Err(setup(
                &files.wheels.display().to_string(),
                "not a wheel board",
            ));
        };
        let clock = Arc::new(MonotonicClock);
        let tilt_board = PtyServer::spawn(
            SimBoard::new(SimConfig::tilt(HOMING_TRAVEL_COUNTS)),
            clock.clone(),
        )
        .map_err(|e| setup("tilt board pty", e))?;
        let wheel_board = PtyServer::spawn(SimBoard::new(SimConfig::wheels()), clock)
            .map_err(|e| setup("wheel board pty", e))?;
        let mut boards = Self {
            tilt: tilt_board,
            wheels: wheel_board,
            calibration: tilt.calibration,
            wheel_motors: wheels.motors,
            wheel_counts_per_rad: wheels.counts_per_rad,
            phase: TiltPhase::Homing,
            drivers: Vec::new(),
        };
        for (name, file, pty) in [
            ("tilt", &files.tilt, boards.tilt.path().to_path_buf()),
            ("wheels", &files.wheels, boards.wheels.path().to_path_buf()),
        ] {
            let stderr = match &files.log_dir {
                Some(dir) => std::fs::File::create(dir.join(format!("roboclaw-{name}.log")))
                    .map(Stdio::from)
                    .map_err(|e| setup("driver log", e))?,
                None => Stdio::null(),
            };
            let child = Command::new(&files.driver_binary)
                .arg("run")
                .arg("--config")
                .arg(file)
                .arg("--port")
                .arg(&pty)
                .args(["--ports-prefix", &ports.prefix])
                .args(["--iceoryx-prefix", &ports.iceoryx_prefix])
                .args(["--answer-timeout-ms", &SIM_TURNAROUND_MS.to_string()])
                .stdout(Stdio::null())
                .stderr(stderr)
                .spawn()
                .map_err(|e| setup(&files.driver_binary.display().to_string(), e))?;
            boards.drivers.push(child);
        }
        Ok(boards)
    }

    /// Whether the tilt board follows the plant (homed and placed).
    pub fn placed(&self) -> bool {
        matches!(self.phase, TiltPhase::Placed { .. })
    }

    /// A driver process that has exited, with its status.
    pub fn exited_driver(&mut self) -> Option<String> {
        self.drivers.iter_mut().find_map(|c| {
            c.try_wait()
                .ok()
                .flatten()
                .map(|status| format!("atmo-roboclaw (pid {}) exited: {status}", c.id()))
        })
    }

    /// Bring-up and coupling, called every server iteration with the
    /// plant's tilt (rad): homes, then places and holds M2 at that tilt.
    pub fn follow_tilt(&mut self, plant_tilt: f64) {
        let target = self.calibration.board_counts(plant_tilt);
        let phase = self.phase;
        let next = self.tilt.with_board(|b| match phase {
            TiltPhase::Homing if b.home_triggered() => TiltPhase::Homed { rest_since: None },
            TiltPhase::Homing => phase,
            TiltPhase::Homed { rest_since } => {
                let resting = b.target(Motor::M2) == 0.0 && b.speed(Motor::M2).abs() < 1.0;
                match (resting, rest_since) {
                    (false, _) => TiltPhase::Homed { rest_since: None },
                    (true, None) => TiltPhase::Homed {
                        rest_since: Some(Instant::now()),
                    },
                    (true, Some(since)) if since.elapsed() >= PLACE_AFTER => {
                        // The counter reads position - offset.
                        let offset = b.position(Motor::M2) - f64::from(b.encoder(Motor::M2));
                        b.set_position(Motor::M2, offset + target);
                        TiltPhase::Placed { offset }
                    }
                    (true, Some(_)) => phase,
                }
            }
            TiltPhase::Placed { offset } => {
                b.set_position(Motor::M2, offset + target);
                phase
            }
        });
        if let Some(next) = next {
            self.phase = next;
        }
    }

    /// The plant's tilt rate: M2's speed over the counts per rad at
    /// `plant_tilt` (0 before the board follows the plant).
    pub fn tilt_rate(&self, plant_tilt: f64) -> f64 {
        if !self.placed() {
            return 0.0;
        }
        let per_rad = self.calibration.counts_per_rad(plant_tilt);
        let speed = self.tilt.with_board(|b| b.speed(Motor::M2)).unwrap_or(0.0);
        if per_rad.abs() > f64::EPSILON {
            speed / per_rad
        } else {
            0.0
        }
    }

    /// The wheel rates (rad/s, left and right): each motor's speed over its
    /// counts per rad.
    pub fn wheel_rates(&self) -> [f64; 2] {
        let speeds = self
            .wheels
            .with_board(|b| self.wheel_motors.map(|m| b.speed(m)))
            .unwrap_or([0.0; 2]);
        [
            speeds[0] / self.wheel_counts_per_rad[0],
            speeds[1] / self.wheel_counts_per_rad[1],
        ]
    }
}

impl Drop for SimBoards {
    /// SIGTERM to each driver (it stops its motors and leaves the ports),
    /// then waits for it; SIGKILL after 2 s.
    fn drop(&mut self) {
        for child in &mut self.drivers {
            // std's Child sends only SIGKILL; SIGTERM lets the driver stop
            // its motors and close its ports.
            let _ = Command::new("kill")
                .args(["-TERM", &child.id().to_string()])
                .status();
        }
        let deadline = Instant::now() + Duration::from_secs(2);
        for child in &mut self.drivers {
            while Instant::now() < deadline {
                if let Ok(Some(_)) = child.try_wait() {
                    break;
                }
                std::thread::sleep(Duration::from_millis(20));
            }
            let _ = child.kill();
            let _ = child.wait();
        }
    }
}
