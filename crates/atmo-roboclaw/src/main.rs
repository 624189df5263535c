//! `atmo-roboclaw`: one Roboclaw board on ATMO's iceoryx2 driver ports
//! (`run`), a simulated board on a pseudo-terminal (`sim`), and a check of
//! a driver file (`check`).

use std::io::Write;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use anyhow::{Context, Result, bail};
use atmo_core::ConfigFile;
use atmo_io::drivers::{DriverEndpoint, DriverId, monotonic_ns};
use atmo_roboclaw::config::{Mode, RoboclawConfig};
use atmo_roboclaw::driver::{Driver, DriverCommand, DriverSettings, Phase, Role};
use atmo_roboclaw::link::{Board, SerialTransport};
use atmo_roboclaw::pty::PtyServer;
use atmo_roboclaw::sim::{MonotonicClock, SimBoard, SimConfig};
use clap::{Parser, Subcommand, ValueEnum};

#[derive(Parser)]
#[command(
    name = "atmo-roboclaw",
    about = "Roboclaw driver of ATMO's tilt and wheel boards"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Clone, Copy, ValueEnum)]
enum SimMode {
    Tilt,
    Wheels,
}

#[derive(Subcommand)]
enum Command {
    /// Drive one board on the driver ports until SIGINT / SIGTERM.
    Run {
        /// The driver file (config/drivers/tilt.toml, wheels.toml).
        #[arg(long)]
        config: PathBuf,
        /// Serial port instead of the file's `serial.port`.
        #[arg(long)]
        port: Option<String>,
        /// Driver-port service prefix instead of the file's `ports.prefix`.
        #[arg(long)]
        ports_prefix: Option<String>,
        /// iceoryx2 file prefix instead of the file's `ports.iceoryx_prefix`
        /// (isolates a simulation's ports).
        #[arg(long)]
        iceoryx_prefix: Option<String>,
        /// The board's turnaround instead of the file's
        /// `serial.answer_timeout_ms` (1..=1000): a simulated board on a
        /// shared host answers when the scheduler runs it.
        #[arg(long)]
        answer_timeout_ms: Option<u64>,
    },
    /// A simulated board on a pseudo-terminal in real time; prints the
    /// pty's path on the first line, then a status line every second.
    Sim {
        #[arg(long, value_enum, default_value = "tilt")]
        mode: SimMode,
        /// Tilt board: counts between the start position and the home
        /// switch, in [0, 2147483647] (the board's 32-bit encoder).
        #[arg(long, default_value_t = 3000.0, value_parser = encoder_counts)]
        start_counts: f64,
        /// Also make this path a symbolic link to the pty (a stale link is
        /// replaced; a file, folder or device there is refused). Removed
        /// on exit if it still points to this board's pty.
        #[arg(long)]
        link: Option<PathBuf>,
    },
    /// Load and check a driver file; print what it resolves to.
    Check {
        #[arg(long)]
        config: PathBuf,
    },
}

fn main() -> Result<()> {
    match Cli::parse().command {
        Command::Run {
            config,
            port,
            ports_prefix,
            iceoryx_prefix,
            answer_timeout_ms,
        } => run(
            &config,
            port,
            ports_prefix,
            iceoryx_prefix,
            answer_timeout_ms,
        ),
        Command::Sim {
            mode,
            start_counts,
            link,
        } => sim(mode, start_counts, link.as_ref()),
        Command::Check { config } => check(&config),
    }
}

fn stop_flag() -> Result<Arc<AtomicBool>> {
    let stop = Arc::new(AtomicBool::new(false));
    for signal in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        signal_hook::flag::register(signal, Arc::clone(&stop))
            .context("installing the signal handler")?;
    }
    Ok(stop)
}

fn load(path: &PathBuf) -> Result<(RoboclawConfig, DriverSettings)> {
    let config = RoboclawConfig::load(path)?;
    let settings = DriverSettings::from_config(&config)?;
    Ok((config, settings))
}

fn check(path: &PathBuf) -> Result<()> {
    let (config, settings) = load(path)?;
    println!(
        "{}: mode {:?}, port {} at {} baud, address {:#04x}",
        path.display(),
        config.mode,
        config.serial.port,
        config.serial.baud,
        config.serial.address
    );
    println!(
        "watchdog {} ms, board serial timeout {} x 100 ms, loop {} Hz",
        config.timing.command_timeout_ms, settings.board_serial_timeout, config.timing.rate_hz
    );
    match &settings.role {
        Role::Tilt(t) => {
            let (lo, hi) = t.calibration.tilt_range();
            println!(
                "tilt: calibrated {:.1}..{:.1} deg, driven {:.1}..{:.1} deg, home switch bit {:#010x}",
                lo.to_degrees(),
                hi.to_degrees(),
                t.min_tilt.to_degrees(),
                t.max_tilt.to_degrees(),
                t.switch.status_bit()
            );
            println!("board counts -> tilt -> counts published on tilt_encoder (linkage model):");
            for counts in (0..=26_000).step_by(2_000) {
                let r = t.calibration.read(f64::from(counts));
                println!(
                    "  {counts:>6} -> {:>5.1} deg -> {:>8.1}{}",
                    r.tilt.to_degrees(),
                    r.model_counts,
                    if r.outside { " (outside)" } else { "" }
                );
            }
            if let Some(cmp) = config.table_vs_linkage()? {
                println!("the table against the linkage model (board counts as model counts):");
                for p in &cmp.points {
                    match p.model_tilt {
                        Some(m) => println!(
                            "  {:>6.0}: table {:>5.1} deg, model {:>5.1} deg, difference {:>+6.1} deg",
                            p.counts,
                            p.table_tilt.to_degrees(),
                            m.to_degrees(),
                            (p.table_tilt - m).to_degrees()
                        ),
                        None => println!(
                            "  {:>6.0}: table {:>5.1} deg, beyond the model's counts",
                            p.counts,
                            p.table_tilt.to_degrees()
                        ),
                    }
                }
                if let Some((worst, at)) = cmp.max_abs() {
                    println!(
                        "largest disagreement {:.1} deg at {at:.0} counts; {} points beyond the model",
                        worst.to_degrees(),
                        cmp.beyond_model()
                    );
                }
            }
        }
        Role::Wheels(w) => println!(
            "wheels: left on {}, right on {}, {:?} counts/rad, limit {} counts/s",
            w.motors[0].name(),
            w.motors[1].name(),
            w.counts_per_rad,
            w.max_speed
        ),
    }
    Ok(())
}

fn run(
    path: &PathBuf,
    port: Option<String>,
    ports_prefix: Option<String>,
    iceoryx_prefix: Option<String>,
    answer_timeout_ms: Option<u64>,
) -> Result<()> {
    let (mut config, settings) = load(path)?;
    if let Some(ms) = answer_timeout_ms {
        anyhow::ensure!(
            (1..=1000).contains(&ms),
            "--answer-timeout-ms {ms}: expected 1..=1000 ms (the file's serial.answer_timeout_ms range)"
        );
        config.serial.answer_timeout_ms = ms;
    }
    if let Some(port) = port {
        config.serial.port = port;
    }
    if let Some(prefix) = ports_prefix {
        config.ports.prefix = prefix;
    }
    if let Some(prefix) = iceoryx_prefix {
        config.ports.iceoryx_prefix = prefix;
    }
    config
        .ports
        .validate(path)
        .context("--ports-prefix / --iceoryx-prefix")?;
    let stop = stop_flag()?;
    let transport = SerialTransport::open(&config.serial.port, config.serial.baud)?;
    let mut board = Board::new(transport, config.link());
    let (id, node) = match config.mode {
        Mode::Tilt => (DriverId::Tilt, "atmo_roboclaw_tilt"),
        Mode::Wheels => (DriverId::Wheels, "atmo_roboclaw_wheels"),
    };
    let mut endpoint = DriverEndpoint::open(&config.ports, node)?;
    let mut driver = Driver::new(settings);
    let period_ns = (1e9 / config.timing.rate_hz) as u64;
    let mut next_ns = monotonic_ns();
    let mut last_report = next_ns;
    let mut ticks_at_report = 0;
    let mut port_errors = 0u64;
    eprintln!(
        "atmo-roboclaw: {} board on {} ({} Hz)",
        node, config.serial.port, config.timing.rate_hz
    );
    while !stop.load(Ordering::SeqCst) {
        // Wakes on the daemon's tick (commands_sent) or at the next
        // deadline of the own rate: the watchdog and the heartbeat go on
        // without a daemon.
        // At or past the deadline the wait is zero: it takes what is there.
        let wait = Duration::from_nanos(next_ns.saturating_sub(monotonic_ns()));
        let commands = endpoint.wait_for_commands(wait).unwrap_or_else(|_| {
            // SIGINT/SIGTERM interrupt the wait: not a port error.
            if !stop.load(Ordering::SeqCst) {
                port_errors += 1;
            }
            endpoint.receive()
        });
        let now = monotonic_ns();
        match config.mode {
            Mode::Tilt => {
                if let Some(c) = commands.tilt_velocity {
                    driver.command(DriverCommand::TiltVelocity(c.velocity), now);
                    driver.rehome_request(c.rehome, now);
                }
            }
            Mode::Wheels => {
                if let Some(c) = commands.wheel_rates {
                    driver.command(DriverCommand::WheelRates(c.rates), now);
                }
            }
        }
        let out = driver.tick(&mut board, now);
        if now >= next_ns {
            // Deadlines on a fixed grid; after an overrun, from now.
            next_ns = (next_ns + period_ns).max(now);
        }
        if let Some(counts) = out.tilt_counts
            && !endpoint.publish_tilt_encoder(counts)
        {
            port_errors += 1;
        }
        if out.alive && !endpoint.publish_heartbeat(id) {
            port_errors += 1;
        }
        if now.saturating_sub(last_report) >= 1_000_000_000 {
            let ticks = driver.counters().ticks;
            let rate = (ticks - ticks_at_report) as f64 * 1e9 / (now - last_report) as f64;
            last_report = now;
            ticks_at_report = ticks;
            report(&driver, &board, port_errors, rate);
        }
    }
    // Leave the motors stopped (the board's serial timeout would too).
    let stopped = board.stop();
    report(&driver, &board, port_errors, 0.0);
    eprintln!(
        "atmo-roboclaw: stopped ({})",
        if stopped.is_ok() {
            "motors at 0"
        } else {
            "board did not answer the stop"
        }
    );
    Ok(())
}

/// One status line on stderr (once a second, off the tick).
fn report(driver: &Driver, board: &Board<SerialTransport>, port_errors: u64, rate_hz: f64) {
    let c = driver.counters();
    let phase = match driver.phase() {
        Phase::Starting => "starting",
        Phase::Homing { .. } => "homing",
        Phase::Running => "running",
        Phase::Failed => "FAILED (homing)",
    };
    let mut err = std::io::stderr().lock();
    let _ = write!(
        err,
        "atmo-roboclaw: {phase}, {rate_hz:.0} ticks/s, status {:#010x}, watchdog stops {}, homings {}, rehome requests {}, port errors {port_errors}, board: {}",
        driver.last_status(),
        c.watchdog_stops,
        c.homings,
        c.rehome_requests,
        board.health()
    );
    if let Some(e) = board.health().last_error {
        let _ = write!(err, ", last error: {e}");
    }
    let _ = writeln!(err);
}

fn sim(mode: SimMode, start_counts: f64, link: Option<&PathBuf>) -> Result<()> {
    let config = match mode {
        SimMode::Tilt => SimConfig::tilt(start_counts),
        SimMode::Wheels => SimConfig::wheels(),
    };
    // Refused before the board starts: only a stale link is replaced.
    if let Some(link) = link
        && std::fs::symlink_metadata(link).is_ok_and(|m| !m.file_type().is_symlink())
    {
        bail!(
            "--link {}: exists and is not a symbolic link; nothing was replaced (name a new path)",
            link.display()
        );
    }
    let stop = stop_flag()?;
    let server = PtyServer::spawn(SimBoard::new(config), Arc::new(MonotonicClock))?;
    println!("{}", server.path().display());
    std::io::stdout().flush()?;
    if let Some(link) = link {
        if std::fs::symlink_metadata(link).is_ok() {
            std::fs::remove_file(link)
                .with_context(|| format!("--link {}: removing the stale link", link.display()))?;
        }
        std::os::unix::fs::symlink(server.path(), link)
            .with_context(|| format!("--link {}: linking it to the pty", link.display()))?;
    }
    let mut ticks = 0u64;
    while !stop.load(Ordering::SeqCst) {
        std::thread::sleep(Duration::from_millis(50));
        ticks += 1;
        if ticks.is_multiple_of(20) {
            server.with_board(|b| {
                eprintln!(
                    "sim: M1 {} counts {:.0} counts/s, M2 {} counts {:.0} counts/s, home {}, serial timeout {} x 100 ms, {}",
                    b.encoder(atmo_roboclaw::protocol::Motor::M1),
                    b.speed(atmo_roboclaw::protocol::Motor::M1),
                    b.encoder(atmo_roboclaw::protocol::Motor::M2),
                    b.speed(atmo_roboclaw::protocol::Motor::M2),
                    b.home_triggered(),
                    b.serial_timeout(),
                    b.stats
                );
            });
        }
    }
    // Only our own link: another board may have taken the name since.
    if let Some(link) = link.filter(|l| std::fs::read_link(l).is_ok_and(|t| t == server.path())) {
        let _ = std::fs::remove_file(link);
    }
    Ok(())
}

/// `--start-counts`: a finite count the board's 32-bit encoder can hold.
fn encoder_counts(text: &str) -> std::result::Result<f64, String> {
    match text.trim().parse::<f64>() {
        Ok(v) if v.is_finite() && (0.0..=f64::from(i32::MAX)).contains(&v) => Ok(v),
        _ => Err(format!(
            "{text} is not a finite number of counts in [0, {}]",
            i32::MAX
        )),
    }
}
