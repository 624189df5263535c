//! `atmo-sim`: the command-line front of the simulator.

use std::path::PathBuf;

use anyhow::{Context, Result};
use atmo_core::limits::{
    critical_angle, max_tilt_for_reserve, thrust_to_weight, trim_saturation_angle,
};
use atmo_core::{ConfigFile, Linkage, Model, RobotConfig};
use atmo_daemon::cli::DaemonConfigArg;
use clap::{Parser, Subcommand};

mod campaign_cmd;
mod fly;

/// ATMO simulator: the built-in plant, scenarios and analysis tools.
#[derive(Parser)]
#[command(version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Print what the physics of a robot file gives.
    ///
    /// Mass, thrust-to-weight, critical angle, in-flight tilt limit, hover
    /// trims and linkage travel.
    Physics {
        /// Robot parameter file (TOML, see config/atmo.toml).
        #[arg(long, default_value = "config/atmo.toml")]
        robot: PathBuf,
    },
    /// Fly a scenario in closed loop, once or as a Monte Carlo.
    ///
    /// The flight stack (mode machine + RTI MPC) against the built-in plant (ground effect, motor lag, sensor
    /// noise, wheel contact...). Writes into OUT/<scenario name>/:
    /// summary.json (touchdown tilt, impact speed, max mean thrust, crash,
    /// drive distance, mode sequence, MPC failures, times) and figure.png (the
    /// paper's Fig. 5A for this flight). With --runs N: a Monte Carlo of N
    /// randomized copies (mass, inertia, thrust +-5 %, gusts, sensor noise,
    /// initial spread, the plant's ground-effect surface) in parallel,
    /// written to monte_carlo.json: distributions, and under `per_run` each
    /// run's seed, draws and outcome (replay one with --runs 1 --seed S),
    /// and OUT/<scenario name>/touchdown.png: impact speed against touchdown
    /// tilt of every run, a cloud per controller (--controller all: the same
    /// seeds), the wheel-landing target (>= 64 deg, <= 0.4 m/s) shaded.
    /// With --shard K/N: only the runs g with g % N == K, written to
    /// OUT/<scenario name>/shards/ for `atmo-sim campaign merge`.
    /// The exit status is 0 when the flight (or every Monte Carlo run) met
    /// the success criteria: no crash, touchdown tilt >= 60 deg, impact speed
    /// <= 0.5 m/s, >= 1 m driven after touchdown.
    Fly {
        #[command(flatten)]
        scenario: ScenarioArg,
        /// Output folder; results go to OUT/<scenario name>/.
        #[arg(long, default_value = "out")]
        out: PathBuf,
        /// Monte Carlo: fly this many randomized copies instead of one flight
        /// (1 to 100000).
        #[arg(long, value_parser = atmo_core::cli_numbers::run_count)]
        runs: Option<usize>,
        /// Seed of the first Monte Carlo run (run i uses seed + i).
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Threads for the Monte Carlo (default: all cores; at most 1024).
        #[arg(long, value_parser = atmo_core::cli_numbers::job_count)]
        jobs: Option<usize>,
        /// Fly only shard K of N (0-based) of the --runs Monte Carlo and
        /// write its partial result; `atmo-sim campaign merge` joins the N
        /// into the monte_carlo.json one process would write.
        #[arg(long, requires = "runs")]
        shard: Option<atmo_sim::campaign::shard::ShardSpec>,
        /// The MPC's prediction model: `nominal` (no ground effect),
        /// `ground-effect` (the plant's documented default surface, the tilt
        /// on the paper's law), `planned-tilt` (the ground-effect model and
        /// the MPC deciding the tilt in the transition, config/mpc.toml's
        /// [tilt_plan]), `both` (nominal and ground-effect) or `all` (the
        /// three; fly each on the same scenario and seeds, into OUT/<scenario
        /// name>/<controller>/, and print one table), or `config` (what
        /// config/mpc.toml says).
        #[arg(long, value_enum, default_value_t = fly::ControllerChoice::Config)]
        controller: fly::ControllerChoice,
        /// With `--controller ground-effect` or `both`: the surface from
        /// `[effects.ground_effect]` of this plant file instead (e.g. the
        /// fitted_effects.toml of `atmo-sim explain`).
        #[arg(long)]
        ground_surface: Option<PathBuf>,
        /// Fly with this MPC settings file instead of the shipped
        /// config/mpc.toml (same layout; the flight settings' preset is used).
        #[arg(long)]
        mpc_config: Option<PathBuf>,
    },
    /// Landing campaigns: Monte Carlo sweeps in shards, merged exactly,
    /// with a success map; Slurm array jobs (docs/campaigns.md).
    Campaign {
        #[command(subcommand)]
        command: campaign_cmd::CampaignCommand,
    },
    // The help text is the doc comment of `atmo_explain::cli::Args` (a doc
    // comment here would replace it).
    Explain(atmo_explain::cli::Args),
    /// Software in the loop: the plant in real time for `atmo-daemon run`.
    ///
    /// Runs the plant on the robot's transports, for the unmodified daemon
    /// to fly.
    /// Plays every driver on the iceoryx2 driver ports (takes thruster,
    /// tilt-velocity and wheel-rate commands; publishes the tilt encoder,
    /// ground contact and heartbeats) and the motion-capture system and
    /// pilot on ROS 2 (nav_msgs/Odometry, atmo_msgs/PilotInput from the
    /// scenario). Topics, services and the iceoryx2 prefix are read from
    /// the daemon's config file so both sides agree; ROS_DOMAIN_ID must match
    /// too. The plant waits, frozen at its initial state, until the daemon
    /// arms; then it runs the scenario's duration and writes
    /// OUT/summary.json (the landing judged on the plant's truth, and the
    /// server's counters). Exit status 0 when the scenario's success
    /// criteria are met.
    Serve {
        #[command(flatten)]
        scenario: ScenarioArg,
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
    },
}

/// The scenario to fly (positional).
#[derive(clap::Args)]
struct ScenarioArg {
    /// Scenario file (see config/scenarios/).
    #[arg(
        value_name = "SCENARIO",
        default_value = "config/scenarios/wheel_landing.toml"
    )]
    scenario: PathBuf,
}

fn main() -> Result<()> {
    let cli = Cli::parse();
    if !matches!(cli.command, Command::Serve { .. }) {
        // A command that prints ends when its reader does (`| head`), as a
        // C tool does, instead of panicking in println!. The SITL plant
        // server is left to Rust's default: it serves a flight.
        sigpipe::reset();
    }
    match cli.command {
        Command::Physics { robot } => physics(&robot),
        Command::Fly {
            scenario,
            out,
            runs,
            seed,
            jobs,
            shard,
            controller,
            ground_surface,
            mpc_config,
        } => fly::run(
            &scenario.scenario,
            &out,
            fly::MonteCarloArgs {
                count: runs,
                seed,
                jobs,
                shard,
            },
            &fly::ControllerArgs {
                choice: controller,
                surface: ground_surface,
                mpc_config,
            },
        ),
        Command::Campaign { command } => campaign_cmd::run(command),
        Command::Serve {
            scenario,
            config,
            out,
            start_timeout,
            estimate_topic,
            pilot_topic,
            roboclaw_tilt,
            roboclaw_wheels,
            roboclaw_bin,
            quiet,
        } => serve(
            &scenario.scenario,
            &config,
            &out,
            start_timeout,
            [estimate_topic, pilot_topic],
            roboclaw_tilt.zip(roboclaw_wheels).map(|(tilt, wheels)| {
                (
                    tilt,
                    wheels,
                    roboclaw_bin.unwrap_or_else(|| beside_this_binary("atmo-roboclaw")),
                )
            }),
            quiet,
        ),
        Command::Explain(args) => explain(&args),
    }
}

/// `atmo-sim explain`: the analysis with its progress bar on stderr.
fn explain(args: &atmo_explain::cli::Args) -> Result<()> {
    let bar = if args.quiet {
        indicatif::ProgressBar::hidden()
    } else {
        indicatif::ProgressBar::new(atmo_explain::STEPS.len() as u64)
    };
    bar.set_style(indicatif::ProgressStyle::with_template(
        "{bar:30} {pos}/{len} {msg} [{elapsed}]",
    )?);
    let mut progress = |p: atmo_explain::Progress| {
        bar.set_length(p.total as u64);
        bar.set_position(p.done as u64);
        bar.set_message(p.stage);
    };
    let summary = atmo_explain::cli::run(args, &mut progress);
    bar.finish_and_clear();
    print!("{}", summary?);
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

fn serve(
    scenario_path: &std::path::Path,
    config: &DaemonConfigArg,
    out: &std::path::Path,
    start_timeout: f64,
    [estimate_topic, pilot_topic]: [Option<String>; 2],
    roboclaw: Option<(PathBuf, PathBuf, PathBuf)>,
    quiet: bool,
) -> Result<()> {
    use atmo_sim::sitl::{ServeOptions, serve};
    let scenario = atmo_sim::Scenario::load(scenario_path)?;
    let mut daemon = config.load()?;
    let topics = &mut daemon.ros2.topics;
    if let Some(topic) = estimate_topic {
        topics.estimate.name = topic;
    }
    if let Some(topic) = pilot_topic {
        // Played to the daemon by another node (an RC relay, too, when the
        // daemon's own pilot topic is off): published whatever the file says.
        topics.pilot.name = topic;
        topics.pilot.enabled = true;
    }
    daemon
        .ros2
        .validate(std::path::Path::new("--estimate-topic/--pilot-topic"))
        .context("serve's topics")?;
    let mut options = ServeOptions::new(daemon.ros2, daemon.drivers);
    options.start_timeout = std::time::Duration::from_secs_f64(start_timeout.max(0.0));
    // The boards' logs are written while the flight runs and kept whatever
    // its outcome, so the folder is added to, not staged whole.
    atmo_io::output_dir::open_shared(out)?;
    options.boards = roboclaw.map(
        |(tilt, wheels, driver_binary)| atmo_sim::boards::BoardFiles {
            tilt,
            wheels,
            driver_binary,
            log_dir: Some(out.to_path_buf()),
        },
    );
    let bar = if quiet {
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

fn physics(robot: &PathBuf) -> Result<()> {
    let cfg = RobotConfig::load(robot).with_context(|| "loading the robot file")?;
    let model = Model::new(&cfg);
    let reserve = cfg.limits.thrust_reserve;
    println!("robot file            {}", robot.display());
    println!("total mass            {:.3} kg", model.mass());
    println!("weight                {:.3} N", model.weight());
    println!(
        "max total thrust      {:.2} N (4 x kT)",
        model.max_total_thrust()
    );
    println!("thrust-to-weight      {:.3}", thrust_to_weight(&model));
    println!(
        "critical angle        {:.2} deg   (cos varphi_c = m g / T_max)",
        critical_angle(&model)?.to_degrees()
    );
    println!(
        "trim saturates at     {:.2} deg   (first rotor at full command in level hover)",
        trim_saturation_angle(&model, cfg.limits.tilt_max())?.to_degrees()
    );
    println!(
        "in-flight tilt limit  {:.2} deg   (thrust reserve {reserve}: T_max cos varphi / (m g) = {reserve})",
        max_tilt_for_reserve(&model, reserve)?.to_degrees()
    );
    println!("\nlevel hover trim (rotors 1 FR, 2 BL, 3 FL, 4 BR)");
    println!("  varphi      u1       u2       u3       u4");
    for deg in [0.0_f64, 20.0, 40.0, 50.0, 60.0] {
        let u = model.at_tilt(deg.to_radians()).hover_trim();
        println!(
            "  {deg:>4.0} deg  {:.5}  {:.5}  {:.5}  {:.5}",
            u[0], u[1], u[2], u[3]
        );
    }
    let link = Linkage::from_config(&cfg.linkage, cfg.limits.tilt_max())?;
    let (x0, x1) = link.screw_range();
    let (_, counts) = link.counts_range();
    println!(
        "\nlinkage               screw x from {:.2} mm to {:.2} mm ({:.1} revolutions, {:.0} encoder counts) over 0..{:.0} deg",
        x0 * 1e3,
        x1 * 1e3,
        (x1 - x0) / cfg.linkage.thread_pitch,
        counts,
        cfg.limits.tilt_max_deg
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    /// clap's own consistency checks (unique argument ids, defaults that parse).
    #[test]
    fn the_command_line_is_consistent() {
        use clap::CommandFactory as _;
        super::Cli::command().debug_assert();
    }
}
