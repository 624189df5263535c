//! `atmo-sim`: the command-line front of the simulator.

use std::path::PathBuf;

use anyhow::{Context, Result};
use atmo_core::limits::{
    critical_angle, max_tilt_for_reserve, thrust_to_weight, trim_saturation_angle,
};
use atmo_core::{ConfigFile, Linkage, Model, RobotConfig};
use clap::{Parser, Subcommand};

mod campaign_cmd;
mod fly;
#[cfg(feature = "sitl")]
mod serve_cmd;

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
    /// scenario), and PX4's estimate when the config enables
    /// `autopilot_estimate` (the plant's autopilot estimate: the motion
    /// capture's sample with its vertical-velocity error). Topics,
    /// services and the iceoryx2 prefix are read from the daemon's config
    /// file so both sides agree; ROS_DOMAIN_ID must match too. The plant
    /// waits, frozen at its initial state, until the daemon arms; then it
    /// runs the scenario's duration and writes OUT/summary.json (the
    /// landing judged on the plant's truth, and the server's counters).
    /// Exit status 0 when the scenario's success criteria are met.
    #[cfg(feature = "sitl")]
    Serve(serve_cmd::ServeArgs),
    /// Software in the loop: not in this build (atmo-sim's `sitl` feature).
    ///
    /// `atmo-sim serve` links the daemon's transports (ROS 2, iceoryx2) and
    /// the Roboclaw boards, which `fly`, `campaign` and `explain` do not
    /// need. Build it with: cargo build --release -p atmo-sim --features sitl
    #[cfg(not(feature = "sitl"))]
    Serve {
        /// Ignored: this build has no `serve`.
        #[arg(trailing_var_arg = true, allow_hyphen_values = true, hide = true)]
        args: Vec<std::ffi::OsString>,
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
        #[cfg(feature = "sitl")]
        Command::Serve(args) => serve_cmd::run(args),
        #[cfg(not(feature = "sitl"))]
        Command::Serve { .. } => anyhow::bail!(
            "this atmo-sim was built without its `sitl` feature, which `serve` needs: \
             cargo build --release -p atmo-sim --features sitl"
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
