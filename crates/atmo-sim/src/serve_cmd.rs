//! `atmo-sim serve` (feature `sitl`): the plant behind the daemon's
//! transports, for the daemon binary to fly in real time.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use atmo_core::ConfigFile as _;
use atmo_daemon::cli::DaemonConfigArg;

/// The arguments of `atmo-sim serve` (its help is the doc comment of
/// `Command::Serve` in main.rs).
#[derive(clap::Args)]
pub struct ServeArgs {
    #[command(flatten)]
    scenario: crate::ScenarioArg,
    /// The daemon's config: its [ros2] topics and [drivers] ports are
    /// the ones served.
    #[command(flatten)]
    config: DaemonConfigArg,
    /// Output folder (summary.json, and the boards' logs while the
    /// flight runs): created with its marker file (.atmo-output) if
    /// absent, used again only if this tool made it (or it is empty); a
    /// file, a symbolic link, a device or a folder this tool did not
    /// write is refused before the plant starts.
    #[arg(long, default_value = "out/sitl")]
    out: PathBuf,
    /// Longest wait for the daemon to arm, s.
    #[arg(long, default_value_t = 60.0)]
    start_timeout: f64,
    /// Publish the motion capture on this topic instead of the daemon's
    /// estimate topic, for another ROS 2 node to play it to the daemon
    /// (scripts/ros2-peer.sh sitl: an rclpy relay).
    #[arg(long)]
    estimate_topic: Option<String>,
    /// Publish the pilot inputs on this topic instead of the daemon's
    /// pilot topic (the same relay then plays them too).
    #[arg(long)]
    pilot_topic: Option<String>,
    /// Fly the tilt through a real `atmo-roboclaw` process and a
    /// simulated Roboclaw board on a pseudo-terminal (this driver file,
    /// e.g. config/drivers/tilt.toml; its serial port is replaced by the
    /// pty) instead of playing the tilt driver. Needs --roboclaw-wheels.
    #[arg(long, requires = "roboclaw_wheels", value_name = "FILE")]
    roboclaw_tilt: Option<PathBuf>,
    /// The wheel board's driver file, likewise (config/drivers/wheels.toml).
    #[arg(long, requires = "roboclaw_tilt", value_name = "FILE")]
    roboclaw_wheels: Option<PathBuf>,
    /// The `atmo-roboclaw` binary (default: beside this one). The
    /// drivers' stderr goes to OUT/roboclaw-{tilt,wheels}.log.
    #[arg(long, value_name = "FILE")]
    roboclaw_bin: Option<PathBuf>,
    /// No progress bar.
    #[arg(long)]
    quiet: bool,
}

/// Serves one flight to the daemon and writes OUT/summary.json.
pub fn run(args: ServeArgs) -> Result<()> {
    use atmo_sim::sitl::{ServeOptions, serve};
    let scenario_path = &args.scenario.scenario;
    let out = args.out.as_path();
    let scenario = atmo_sim::Scenario::load(scenario_path)?;
    let mut daemon = args.config.load()?;
    let topics = &mut daemon.ros2.topics;
    if let Some(topic) = args.estimate_topic {
        topics.estimate.name = topic;
    }
    if let Some(topic) = args.pilot_topic {
        // Played to the daemon by another node (an RC relay, too, when the
        // daemon's own pilot topic is off): published whatever the file says.
        topics.pilot.name = topic;
        topics.pilot.enabled = true;
    }
    daemon
        .ros2
        .validate(Path::new("--estimate-topic/--pilot-topic"))
        .context("serve's topics")?;
    let esc = daemon
        .ros2
        .topics
        .esc_status
        .enabled
        .then_some(daemon.esc.full_speed_rpm);
    let mut options = ServeOptions::new(daemon.ros2, daemon.drivers);
    options.esc_full_speed_rpm = esc;
    options.start_timeout = std::time::Duration::from_secs_f64(args.start_timeout.max(0.0));
    // The boards' logs are written while the flight runs and kept whatever
    // its outcome, so the folder is added to, not staged whole.
    atmo_io::output_dir::open_shared(out)?;
    options.boards = args
        .roboclaw_tilt
        .zip(args.roboclaw_wheels)
        .map(|(tilt, wheels)| atmo_sim::boards::BoardFiles {
            tilt,
            wheels,
            driver_binary: args
                .roboclaw_bin
                .unwrap_or_else(|| beside_this_binary("atmo-roboclaw")),
            log_dir: Some(out.to_path_buf()),
        });
    let bar = if args.quiet {
        indicatif::ProgressBar::hidden()
    } else {
        indicatif::ProgressBar::new((scenario.file.duration * 1000.0) as u64)
    };
    bar.set_style(
        indicatif::ProgressStyle::with_template(
            "{spinner} sim {pos:>6}/{len} ms [{bar:30}] daemon: {msg}",
        )?
        .progress_chars("=> "),
    );
    bar.set_message("waiting for the daemon to arm");
    let mut progress = |t: f64, mode: Option<atmo_flight::Mode>| {
        bar.set_position((t * 1000.0) as u64);
        bar.set_message(mode.map_or("no status yet", atmo_flight::Mode::name));
    };
    let (summary, counters) = serve(&scenario, &options, &mut progress)?;
    bar.finish_and_clear();
    let ok = scenario.file.success.met_by(&summary);
    let json = serde_json::json!({
        "summary": summary,
        "succeeded": ok,
        "server": counters,
    });
    let path = out.join("summary.json");
    let mut files = atmo_io::output_dir::StagedFiles::new(out);
    files.write("summary.json", serde_json::to_string_pretty(&json)? + "\n")?;
    files.commit()?;
    println!("{}", serde_json::to_string_pretty(&json)?);
    if !ok {
        anyhow::bail!(
            "the flight did not meet the success criteria of {} (see {})",
            scenario_path.display(),
            path.display()
        );
    }
    Ok(())
}

/// `name` in the folder of the running binary (as cargo builds them).
fn beside_this_binary(name: &str) -> PathBuf {
    let file = format!("{name}{}", std::env::consts::EXE_SUFFIX);
    std::env::current_exe()
        .ok()
        .and_then(|exe| exe.parent().map(|dir| dir.join(&file)))
        .unwrap_or_else(|| PathBuf::from(file))
}
