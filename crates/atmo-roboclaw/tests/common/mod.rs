//! The driver against the simulated board over a real pseudo-terminal, on
//! one hand-set clock shared by both (deterministic dynamics; only the
//! answer timeouts run on the wall clock).
#![allow(dead_code, clippy::unwrap_used)]

use std::path::{Path, PathBuf};
use std::sync::Arc;

use atmo_core::config_file::ConfigFile;
use atmo_roboclaw::config::RoboclawConfig;
use atmo_roboclaw::driver::{Driver, DriverCommand, DriverSettings, TickOutput};
use atmo_roboclaw::link::{Board, SerialTransport};
use atmo_roboclaw::pty::PtyServer;
use atmo_roboclaw::sim::{Clock, ManualClock, SimBoard, SimConfig};

pub fn repo_config(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../config")
        .join(name)
}

/// The example file `config/drivers/<name>` with its port replaced;
/// `name` may end in `+linkage`: the tilt file with the linkage calibration.
pub fn example_config(name: &str, port: &str) -> RoboclawConfig {
    let (file, linkage) = match name.strip_suffix("+linkage") {
        Some(file) => (file, true),
        None => (name, false),
    };
    let path = repo_config(&format!("drivers/{file}"));
    let mut text = std::fs::read_to_string(&path).unwrap();
    if linkage {
        text = text
            .replace("calibration = \"table\"", "calibration = \"linkage\"")
            .lines()
            .filter(|l| !l.starts_with("table_"))
            .collect::<Vec<_>>()
            .join("\n");
    }
    let text = text
        .lines()
        .map(|l| {
            if l.starts_with("port = ") {
                format!("port = \"{port}\"")
            } else {
                l.to_string()
            }
        })
        .collect::<Vec<_>>()
        .join("\n");
    RoboclawConfig::from_toml_str(&text, &path).unwrap()
}

pub const TICK_NS: u64 = 10_000_000;

/// Answer timeout of the tests' links, ms.
pub const ANSWER_TIMEOUT_MS: u64 = 100;

pub struct Rig {
    pub clock: Arc<ManualClock>,
    pub server: PtyServer,
    pub board: Board<SerialTransport>,
    pub driver: Driver,
    pub config: RoboclawConfig,
    pub last: TickOutput,
}

impl Rig {
    /// A simulated board (`sim`) and the example driver file `file`.
    pub fn new(sim: SimConfig, file: &str) -> Self {
        let clock = Arc::new(ManualClock::new(1_000_000_000));
        let server = PtyServer::spawn(SimBoard::new(sim), clock.clone() as Arc<dyn Clock>).unwrap();
        let port = server.path().to_str().unwrap().to_string();
        let mut config = example_config(file, &port);
        // The answer timeout is wall-clock time: generous, so that a busy
        // machine (the whole workspace's tests on 2 cores) does not turn a
        // late answer into a counted fault the test did not inject.
        config.serial.answer_timeout_ms = ANSWER_TIMEOUT_MS;
        let board = Board::new(
            SerialTransport::open(&port, config.serial.baud).unwrap(),
            config.link(),
        );
        let driver = Driver::new(DriverSettings::from_config(&config).unwrap());
        Self {
            clock,
            server,
            board,
            driver,
            config,
            last: TickOutput::default(),
        }
    }

    pub fn now(&self) -> u64 {
        self.clock.now_ns()
    }

    /// One 10 ms tick, with `command` received just before it.
    pub fn tick(&mut self, command: Option<DriverCommand>) -> TickOutput {
        let now = self.clock.advance(TICK_NS);
        if let Some(c) = command {
            self.driver.command(c, now);
        }
        self.last = self.driver.tick(&mut self.board, now);
        self.last
    }

    /// Ticks until `done` (at most `max_s` of simulated time); true if done.
    pub fn run_until(
        &mut self,
        max_s: f64,
        command: Option<DriverCommand>,
        mut done: impl FnMut(&Rig) -> bool,
    ) -> bool {
        let ticks = (max_s * 1e9 / TICK_NS as f64) as usize;
        for _ in 0..ticks {
            self.tick(command);
            if done(self) {
                return true;
            }
        }
        false
    }

    pub fn sim<R>(&self, f: impl FnOnce(&mut SimBoard) -> R) -> R {
        self.server.with_board(f).unwrap()
    }
}
