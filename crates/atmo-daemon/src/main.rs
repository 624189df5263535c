//! `atmo-daemon`: the onboard binary.

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};
use atmo_daemon::cli::DaemonConfigArg;
use atmo_daemon::onboard::{DaemonConfig, OnboardIo, OnboardSettings, OnboardShared};
use atmo_flight::Mode;
use atmo_flight::control_loop::ControlThread;
use atmo_flight::flight_log::{FlightConfig, FlightConfigFiles, TickChannels};
use atmo_io::mcap_log::McapLogger;
use atmo_io::msg::DiagnosticArray;
use atmo_io::msg::{RosMessage as _, VehicleOdometry};
use atmo_io::ros2::{Ros2Node, Ros2StartOptions};
use clap::{Parser, Subcommand};

/// ATMO onboard daemon: the flight stack (mode machine, RTI MPC, drive
/// controller, failsafes) at its control rate, talking ROS 2 to the robot
/// (estimate, pilot and drive commands in; status, diagnostics, optional
/// PX4 offboard out), iceoryx2 shared memory to its drivers (thrusters,
/// tilt, wheels, encoder, ground contact, heartbeats), and logging every
/// tick to MCAP.
#[derive(Parser)]
#[command(version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Fly the robot until SIGINT or SIGTERM.
    ///
    /// Then stop the control thread, finish the MCAP log (a valid file, every record accepted so far) and exit 0.
    /// ROS_DOMAIN_ID selects the DDS domain; RUST_LOG the log level
    /// (default `info,rustdds=off`; `rustdds=warn` shows the DDS layer).
    Run {
        #[command(flatten)]
        config: DaemonConfigArg,
        /// MCAP log file (overrides [log] path). An earlier flight's log
        /// there is never overwritten: this flight logs to the first free
        /// STEM.N.mcap beside it (flight.1.mcap, ...), and says so.
        #[arg(long)]
        log: Option<PathBuf>,
        /// Stop by itself after this many seconds (tests, bench runs; finite,
        /// at most one week).
        #[arg(long, value_parser = atmo_core::cli_numbers::run_duration_s)]
        duration: Option<f64>,
    },
    /// Validate every config file the daemon would use.
    ///
    /// Prints what it would run with, and exits (0: valid). With --params,
    /// prints every parameter of the robot, flight, MPC and daemon files
    /// (key, default, range, unit, doc) instead.
    Check {
        #[command(flatten)]
        config: DaemonConfigArg,
        /// Print the parameter reference (Markdown) and exit.
        #[arg(long)]
        params: bool,
    },
    /// Run the arming checks and a props-off tilt sweep; print a table.
    ///
    /// The checks run on the robot's transports (ROS 2 inputs, driver
    /// ports) for one check window, then a props-off tilt sweep
    /// (0 -> 50 -> 0 deg, the encoder against the command), and print a
    /// pass/fail table. The thrusters get 0 throughout. Exit 0: all passed;
    /// 1: a check failed. Not beside a running daemon: it owns the ports.
    Preflight {
        #[command(flatten)]
        config: DaemonConfigArg,
        /// The sweep's far end, deg (0..=90).
        #[arg(long, default_value_t = 50.0, value_parser = sweep_deg)]
        sweep_to_deg: f64,
        /// Only the checks, no tilt motion.
        #[arg(long)]
        no_sweep: bool,
    },
    /// Replay a flight log bit for bit, or a what-if with changed files.
    ///
    /// Rebuild the flight stack from the configuration stored in LOG, feed
    /// it the logged inputs tick by tick with the logged clock, and compare
    /// every output with the logged one bit for bit. Exit 0: identical; 1: a
    /// difference (the first is printed: tick, time, field, logged,
    /// replayed); 2: the log cannot be replayed.
    ///
    /// With --config (what-if) the inputs go through a changed flight stack
    /// and --out gets a per-tick comparison (whatif.csv, whatif.png) and the
    /// largest differences; that replay is open loop w.r.t. the plant.
    Replay {
        /// The flight log (`atmo-daemon run`, `atmo-sim fly`; a log cut by a
        /// crash after `atmo-mcap recover`).
        log: PathBuf,
        /// What-if: a config file replacing the logged file of the same name
        /// (e.g. mpc.toml), or a folder whose files replace those.
        #[arg(long, value_name = "DIR_OR_FILE")]
        config: Option<PathBuf>,
        /// Where a what-if writes its comparison.
        #[arg(long, value_name = "DIR", default_value = "whatif")]
        out: PathBuf,
        /// The status topic of the log (the daemon config's ros2.topics.status).
        #[arg(long, default_value = "/atmo/status")]
        status_topic: String,
    },
}

fn main() {
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                // RustDDS logs its own shutdown at WARN/ERROR: quiet unless asked.
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info,rustdds=off")),
        )
        .with_writer(std::io::stderr)
        .init();
    let cli = Cli::parse();
    if matches!(cli.command, Command::Check { .. } | Command::Replay { .. }) {
        // The commands that only print end when their reader does
        // (`| head`), as a C tool does, instead of panicking in println!.
        // `run` and `preflight` drive the robot: a closed pipe must not
        // kill them.
        sigpipe::reset();
    }
    let result = match cli.command {
        Command::Run {
            config,
            log,
            duration,
        } => run(&config, log, duration),
        Command::Check { params: true, .. } => {
            print!("{}", atmo_daemon::reference::parameter_reference());
            Ok(())
        }
        Command::Check { config, .. } => check(&config),
        Command::Preflight {
            config,
            sweep_to_deg,
            no_sweep,
        } => match preflight(&config, (!no_sweep).then_some(sweep_to_deg)) {
            Ok(true) => Ok(()),
            Ok(false) => std::process::exit(1),
            Err(e) => Err(e),
        },
        Command::Replay {
            log,
            config,
            out,
            status_topic,
        } => match replay_command(&log, config.as_deref(), &out, &status_topic) {
            Ok(true) => Ok(()),
            Ok(false) => std::process::exit(1),
            Err(e) => Err(e),
        },
    };
    if let Err(e) = result {
        eprintln!("atmo-daemon: {e:#}");
        std::process::exit(2);
    }
}

/// `replay`: true when every output is identical.
fn replay_command(
    log: &std::path::Path,
    what_if: Option<&std::path::Path>,
    out: &std::path::Path,
    status_topic: &str,
) -> Result<bool> {
    use atmo_flight::replay::{CutReplay, RecordedFlight, replay};
    let flight = RecordedFlight::read(log, status_topic)?;
    println!(
        "{}: configuration schema version {} (this build's: {})",
        log.display(),
        flight.files.schema_version,
        atmo_flight::schema::CONFIG_SCHEMA_VERSION
    );
    for change in &flight.files.migrated {
        println!("  migrated: {change}");
    }
    // A what-if's folder is staged, refused up front if it is not one this
    // tool may replace (a file, someone's folder), and moved into place
    // whole at the end (atmo_io::output_dir).
    let staged = what_if
        .map(|_| atmo_io::output_dir::StagedDir::new(out))
        .transpose()?;
    let mut files = flight.files.clone();
    if let Some(path) = what_if {
        for replaced in files.override_with(path)? {
            println!("what-if: {}", replaced.display());
        }
    }
    let config = RecordedFlight::config(&files)
        .with_context(|| format!("the configuration to replay {} with", log.display()))?;
    let started = Instant::now();
    let mut table = atmo_flight::whatif::WhatIfTable::default();
    // A what-if's solves are other solves: none is cut (see `CutReplay`).
    let cuts = if what_if.is_some() {
        CutReplay::None
    } else {
        CutReplay::AsLogged
    };
    let report = replay(&flight, &config, cuts, |pair| {
        if what_if.is_some() {
            table.push(pair);
        }
    })?;
    let wall = started.elapsed().as_secs_f64();
    println!(
        "{}: {} ticks ({:.2} s of flight) replayed in {:.3} s ({:.0}x real time)",
        log.display(),
        report.ticks,
        report.duration_s,
        wall,
        report.duration_s / wall.max(1e-9)
    );
    let (inputs_left, status_left) = flight.incomplete_tail;
    if inputs_left + status_left > 0 {
        println!(
            "  the log ends mid-tick: replayed to its last complete tick ({inputs_left} inputs and {status_left} status records after it)"
        );
    }
    if report.cuts_replayed > 0 {
        println!(
            "  {} solves the time limit cut in flight were cut again at their logged iteration",
            report.cuts_replayed
        );
    }
    if report.cut_overflow_ticks > 0 {
        println!(
            "  {} ticks had more time-limit cuts than the log records: they cannot be reproduced",
            report.cut_overflow_ticks
        );
    }
    match &report.first_difference {
        None => println!("identical: every output of every tick, bit for bit"),
        Some(d) => println!(
            "{} of {} ticks differ; first: {d}",
            report.differing_ticks, report.ticks
        ),
    }
    if let Some(staged) = staged {
        table.write(staged.path())?;
        write_whatif_figure(&table, staged.path())?;
        let written = staged.commit()?;
        println!("{}", atmo_flight::whatif::OPEN_LOOP_NOTE);
        for line in table.largest_differences() {
            println!("  {line}");
        }
        println!("wrote {}", written.display());
    }
    Ok(report.identical())
}

/// `whatif.png` in `out`: altitude, tilt, mean thrust and mode, logged
/// against what-if.
fn write_whatif_figure(
    table: &atmo_flight::whatif::WhatIfTable,
    out: &std::path::Path,
) -> Result<()> {
    use atmo_flight::whatif::mean_thrust;
    use atmo_io::review::figure::{Overlay, OverlayPanel, write_overlay_figure};
    let panel = |label: &'static str, (logged, replayed): (Vec<f64>, Vec<f64>)| OverlayPanel {
        label,
        logged,
        replayed,
    };
    let overlay = Overlay {
        title: "what-if replay (open loop w.r.t. the plant): logged vs what-if",
        time: table.time().to_vec(),
        panels: vec![
            panel("altitude [m]", table.series(|s| s.height)),
            panel("tilt varphi [deg]", table.series(|s| s.varphi.to_degrees())),
            panel("mean thrust (normalized)", table.series(mean_thrust)),
            panel("mode (code)", table.series(|s| f64::from(s.mode.code()))),
        ],
    };
    write_overlay_figure(&out.join("whatif.png"), &overlay)?;
    Ok(())
}

/// Everything loaded and validated before anything starts.
struct Loaded {
    config: DaemonConfig,
    /// The exact texts the flight stack is built from (logged at start).
    files: FlightConfigFiles,
    /// Parsed from `files`: the flight stack is built from these texts only.
    parsed: FlightConfig,
}

fn load(arg: &DaemonConfigArg) -> Result<Loaded> {
    let config = arg.load()?;
    let files = FlightConfigFiles::read(&config.robot, &config.flight, &config.mpc)?;
    let parsed = files.parse()?;
    Ok(Loaded {
        config,
        files,
        parsed,
    })
}

fn check(arg: &DaemonConfigArg) -> Result<()> {
    let l = load(arg)?;
    let path = &arg.config;
    l.parsed.stack()?;
    println!("{}: valid", path.display());
    println!("  robot  {}", l.config.robot.display());
    println!(
        "  flight {} ({} Hz, MPC preset `{}`)",
        l.config.flight.display(),
        l.parsed.flight.control_loop.rate_hz,
        l.parsed.flight.mpc_preset
    );
    println!("  mpc    {}", l.config.mpc.display());
    println!("  log    {}", l.config.log.path.display());
    let t = &l.config.ros2.topics;
    println!(
        "  ros2   status {}, estimate {} ({}), pilot {}, drive {}",
        t.status.name, t.estimate.name, t.estimate.type_name, t.pilot.name, t.drive_command.name
    );
    println!(
        "  drivers prefix {}, liveness {} ms",
        l.config.drivers.prefix, l.config.drivers.liveness_timeout_ms
    );
    // What a failsafe flies once the estimate is lost for good.
    if t.autopilot_estimate.enabled {
        println!(
            "  estimate lost: level descent on the autopilot's estimate {}",
            t.autopilot_estimate.name
        );
    } else if t.estimate.type_name != VehicleOdometry::TYPE_NAME {
        println!(
            "  estimate lost: open-loop trim, no attitude held (with PX4 on board, enable ros2.topics.autopilot_estimate; docs/faults.md)"
        );
    }
    if t.rc.enabled {
        let (rc, s) = (&l.config.rc, &l.config.rc.switches);
        println!(
            "  radio  {} ({}..{}..{} us; offboard ch {}, MPC ch {}, kill ch {}; lost after {} ms)",
            t.rc.name,
            rc.min_us,
            rc.center_us,
            rc.max_us,
            s.offboard.channel,
            s.mpc.channel,
            s.kill.channel,
            rc.timeout_ms
        );
    }
    match l.config.flight_problem() {
        None => println!("  arming configuration check: can fly"),
        Some(problem) => println!("  arming configuration check FAILS: {problem}"),
    }
    Ok(())
}

/// `--sweep-to-deg`: a tilt in 0..=90 deg.
fn sweep_deg(text: &str) -> std::result::Result<f64, String> {
    match text.parse::<f64>() {
        Ok(v) if (0.0..=90.0).contains(&v) => Ok(v),
        _ => Err(format!("`{text}` is not a tilt in 0..=90 deg")),
    }
}

/// `preflight`: true when every row passed.
fn preflight(arg: &DaemonConfigArg, sweep_to_deg: Option<f64>) -> Result<bool> {
    let l = load(arg)?;
    let (_ros_out, ros_in, ros_thread) =
        Ros2Node::start(&l.config.ros2, Ros2StartOptions::default()).context("ROS 2 node")?;
    let mut preflight = atmo_daemon::preflight::Preflight::open(
        &l.config,
        &l.parsed.robot,
        ros_in,
        l.parsed.flight.control_loop.rate_hz,
        l.parsed.flight.failsafe.estimate_timeout,
    )?;
    println!(
        "preflight {}: arming checks, then {}",
        arg.config.display(),
        sweep_to_deg.map_or("no sweep".to_string(), |d| format!(
            "a props-off tilt sweep 0 -> {d} -> 0 deg"
        ))
    );
    let report = preflight.run(sweep_to_deg);
    drop(preflight);
    ros_thread.stop().context("stopping the ROS 2 node")?;
    println!("{report}");
    Ok(report.passed())
}

fn run(arg: &DaemonConfigArg, log_path: Option<PathBuf>, duration: Option<f64>) -> Result<()> {
    let l = load(arg)?;
    let path = &arg.config;
    let stack = l.parsed.stack()?;
    let period = atmo_flight::control_loop::tick_period(stack.period());

    // SIGINT/SIGTERM only set a flag: the main thread shuts down in order.
    let terminate = Arc::new(AtomicBool::new(false));
    for signal in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        signal_hook::flag::register(signal, Arc::clone(&terminate))
            .with_context(|| format!("installing the handler of signal {signal}"))?;
    }

    let named = log_path.unwrap_or_else(|| l.config.log.path.clone());
    if let Some(dir) = named.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("creating the log folder {}", dir.display()))?;
    }
    // An earlier flight's log is never overwritten.
    let log_path = atmo_io::mcap_log::unused_log_path(&named)?;
    if log_path != named {
        tracing::info!(
            exists = %named.display(),
            log = %log_path.display(),
            "an earlier flight's log is there: this flight logs beside it"
        );
    }
    let (log, log_thread) = McapLogger::spawn(&log_path, l.config.log.options())
        .with_context(|| format!("opening the log {}", log_path.display()))?;
    let channels = TickChannels::register(&log, &l.config.ros2.topics.status.name)?;
    l.files
        .log_to(&log, 0)
        .context("storing the configuration in the log")?;
    let (ros_out, ros_in, ros_thread) =
        Ros2Node::start(&l.config.ros2, Ros2StartOptions::default()).context("ROS 2 node")?;

    let shared = Arc::new(OnboardShared::default());
    let settings = OnboardSettings::new(&l.config, l.parsed.flight.failsafe.estimate_timeout);
    let drivers = l.config.drivers.clone();
    let (thread_shared, thread_log, thread_ros_out) =
        (Arc::clone(&shared), log.clone(), ros_out.clone());
    let control = ControlThread::spawn_with(stack, period, move |_| {
        OnboardIo::open(
            &drivers,
            ros_in,
            thread_ros_out,
            thread_log,
            channels,
            settings,
            thread_shared,
        )
    })
    .context("starting the control thread")?;
    tracing::info!(
        config = %path.display(),
        log = %log_path.display(),
        rate_hz = l.parsed.flight.control_loop.rate_hz,
        "atmo-daemon running"
    );

    let started = Instant::now();
    let flight_problem = l.config.flight_problem();
    if let Some(problem) = flight_problem {
        tracing::warn!(problem, "this configuration cannot arm");
    }
    let diagnostics_period = Duration::from_millis(l.config.ros2.diagnostics_period_ms);
    let mut next_diagnostics = Instant::now();
    let mut reported_arming = u8::MAX;
    let mut reported_mode = Mode::Disarmed.code();
    let mut reported_deaths = 0;
    let mut panicked = false;
    let mut log_failure_reported = false;
    while !terminate.load(Ordering::Relaxed) {
        if !control.is_running() {
            panicked = true;
            break;
        }
        if duration.is_some_and(|d| started.elapsed().as_secs_f64() >= d) {
            break;
        }
        std::thread::sleep(Duration::from_millis(20));
        let mode = shared.mode.load(Ordering::Relaxed);
        if mode != reported_mode {
            reported_mode = mode;
            tracing::info!(mode = Mode::from_code(mode).map_or("?", Mode::name), "mode");
        }
        if !log_failure_reported && log.failed() {
            // The control thread flies on; its records are dropped and
            // counted (`io.log_dropped` in every status).
            log_failure_reported = true;
            tracing::error!(
                log = %log_path.display(),
                error = log.failure().unwrap_or_default(),
                "the log cannot be written: flying on, its records dropped and counted"
            );
        }
        let arming = shared.arming_failures.load(Ordering::Relaxed);
        if shared.started.load(Ordering::Relaxed) && arming != reported_arming {
            reported_arming = arming;
            let status = atmo_flight::arming::diagnostics(arming, flight_problem);
            tracing::info!(verdict = %status.message, "arming checks");
        }
        if Instant::now() >= next_diagnostics {
            next_diagnostics = Instant::now() + diagnostics_period;
            let mut status = atmo_flight::arming::diagnostics(arming, flight_problem);
            status
                .values
                .extend(shared.counts().map(|(key, value)| atmo_io::msg::KeyValue {
                    key: key.into(),
                    value: value.to_string(),
                }));
            ros_out.try_publish_diagnostics(DiagnosticArray {
                status: vec![status],
                ..DiagnosticArray::default()
            });
        }
        let deaths = shared.driver_deaths.load(Ordering::Relaxed);
        if deaths != reported_deaths {
            reported_deaths = deaths;
            tracing::warn!(
                alive_bits = shared.drivers_alive.load(Ordering::Relaxed),
                deaths,
                "a driver stopped talking"
            );
        }
    }

    // Shut down in order: no tick after this, then the log, then ROS 2.
    let ticks = control.counters().ticks.load(Ordering::Relaxed);
    let stack = control.stop();
    log.finish();
    let written = log_thread.join();
    ros_thread.stop().context("stopping the ROS 2 node")?;
    // The counters first: a log that failed is when they matter most.
    tracing::info!(
        ticks,
        log = %log_path.display(),
        counters = %shared
            .counts()
            .map(|(key, value)| format!("{key}={value}"))
            .join(" "),
        "atmo-daemon stopped"
    );
    let written = written.with_context(|| format!("writing the log {}", log_path.display()))?;
    tracing::info!(
        records = written.written,
        dropped = written.dropped,
        "log written"
    );
    if panicked || stack.is_err() {
        bail!(
            "the control thread panicked; the log up to then is in {}",
            log_path.display()
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// clap's own consistency checks (unique argument ids, defaults that parse).
    #[test]
    fn the_command_line_is_consistent() {
        use clap::CommandFactory as _;
        Cli::command().debug_assert();
    }

    /// `run --duration nan|inf|1e300` must not run until killed.
    #[test]
    fn run_refuses_a_duration_that_never_ends() {
        for value in ["nan", "inf", "1e300", "-1", "0"] {
            let flag = format!("--duration={value}");
            let err = Cli::try_parse_from(["atmo-daemon", "run", flag.as_str()])
                .err()
                .unwrap_or_else(|| panic!("--duration {value} accepted"));
            let text = err.to_string();
            assert!(
                text.contains("--duration") && text.contains(value),
                "{text}"
            );
        }
        assert!(Cli::try_parse_from(["atmo-daemon", "run", "--duration", "2.5"]).is_ok());
    }
}
