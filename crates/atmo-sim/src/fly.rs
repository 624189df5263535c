//! `atmo-sim fly`: one closed-loop flight or a Monte Carlo, with outputs.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use atmo_mpc::settings::GroundEffectSource;
use atmo_sim::campaign::Plan;
use atmo_sim::campaign::shard::ShardSpec;
use atmo_sim::closed_loop::{ControllerConfig, ControllerPreset, TickRecord, fly_logged, trace_of};
use atmo_sim::figure::{Markers, TouchdownCloud, write_landing_figure, write_touchdown_figure};
use atmo_sim::monte_carlo::{self, MonteCarloReport};
use atmo_sim::scenario::Scenario;
use indicatif::{ProgressBar, ProgressStyle};

/// Which prediction model the MPC flies with (`--controller`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum ControllerChoice {
    /// config/mpc.toml's `[model] ground_effect`.
    Config,
    /// No ground effect in the model, the paper's tilt law.
    Nominal,
    /// The ground-effect surface in the model, the tilt on the paper's law.
    GroundEffect,
    /// The ground-effect surface in the model and the tilt planned by the
    /// MPC in the transition (`[tilt_plan]` of the MPC settings, enabled).
    PlannedTilt,
    /// Nominal and ground-effect, on the same scenario and seeds.
    Both,
    /// Nominal, ground-effect and planned-tilt, on the same scenario and seeds.
    All,
}

/// `--controller`, `--ground-surface`, `--mpc-config`.
#[derive(Debug, Clone)]
pub struct ControllerArgs {
    pub choice: ControllerChoice,
    pub surface: Option<PathBuf>,
    pub mpc_config: Option<PathBuf>,
}

/// `--runs`, `--seed`, `--jobs`, `--shard`.
#[derive(Debug, Clone, Copy)]
pub struct MonteCarloArgs {
    pub count: Option<usize>,
    pub seed: u64,
    pub jobs: Option<usize>,
    pub shard: Option<ShardSpec>,
}

impl ControllerChoice {
    /// The controllers flown, in order.
    fn presets(self) -> &'static [ControllerPreset] {
        use ControllerPreset as P;
        match self {
            Self::Config => &[P::Config],
            Self::Nominal => &[P::Nominal],
            Self::GroundEffect => &[P::GroundEffect],
            Self::PlannedTilt => &[P::PlannedTilt],
            Self::Both => &[P::Nominal, P::GroundEffect],
            Self::All => &[P::Nominal, P::GroundEffect, P::PlannedTilt],
        }
    }
}

pub fn run(
    scenario_path: &Path,
    out: &Path,
    runs: MonteCarloArgs,
    controller: &ControllerArgs,
) -> Result<()> {
    let scenario = Scenario::load(scenario_path).with_context(|| "loading the scenario")?;
    let base = ControllerConfig::atmo()?.deterministic();
    let base = match &controller.mpc_config {
        Some(path) => base
            .with_mpc_file(path)
            .with_context(|| format!("loading --mpc-config {}", path.display()))?,
        None => base,
    };
    let surface = controller
        .surface
        .clone()
        .map_or(GroundEffectSource::PlantDefault, GroundEffectSource::File);
    // Through the texts the flight log stores: a replay rebuilds this controller.
    let presets = controller.choice.presets();
    let controllers: Vec<(&str, ControllerConfig)> = presets
        .iter()
        .map(|p| {
            let name = if *p == ControllerPreset::Config {
                ""
            } else {
                p.name()
            };
            Ok((name, p.config(&base, &surface)?))
        })
        .collect::<Result<_>>()?;
    if let Some(shard) = runs.shard {
        let (Some(count), [preset]) = (runs.count, presets) else {
            bail!("--shard needs --runs and one controller (not `both` or `all`)");
        };
        let plan = Plan::monte_carlo(&scenario, *preset, count, runs.seed);
        return crate::campaign_cmd::fly_and_write_shard(
            &plan,
            &scenario,
            &controllers[0].1,
            shard,
            runs.jobs,
            &out.join(&scenario.file.name),
        );
    }
    let dir: PathBuf = out.join(&scenario.file.name);
    if runs.count == Some(0) {
        bail!("--runs must be at least 1");
    }
    let mut all_ok = true;
    let mut reports = Vec::new();
    // Staged: a run that fails leaves an earlier run's folder as it was.
    let staged = atmo_io::output_dir::StagedDir::new(&dir)?;
    for (name, controller) in &controllers {
        let dir = staged.path().join(name);
        std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
        if !name.is_empty() {
            println!("controller        {name}");
        }
        match runs.count {
            None => all_ok &= single(&scenario, controller, &dir)?,
            Some(n) => reports.push((*name, many(&scenario, controller, &dir, n, &runs)?)),
        }
    }
    if reports.len() > 1 {
        print_comparison(&reports);
    }
    // The results (monte_carlo.json) are committed whatever the figure does:
    // a flight without a touchdown has none to plot, and a figure that
    // fails is reported after the results are in place.
    let mut figure_error = None;
    if !reports.is_empty() {
        let touched_down = reports.iter().any(|(_, r)| {
            r.per_run
                .iter()
                .any(|run| run.touchdown_tilt_deg.zip(run.impact_speed_mps).is_some())
        });
        if touched_down {
            let path = staged.path().join("touchdown.png");
            match write_touchdowns(&path, &scenario.file.name, &reports) {
                Ok(()) => println!("touchdowns        touchdown.png"),
                Err(e) => figure_error = Some(e),
            }
        } else {
            println!("touchdowns        none (no run touched down): touchdown.png not drawn");
        }
    }
    let dir = staged.commit()?;
    println!("wrote             {}", dir.display());
    if let Some(e) = figure_error {
        return Err(e.context(format!(
            "the results are in {}, but touchdown.png could not be drawn",
            dir.display()
        )));
    }
    if !all_ok {
        std::process::exit(1);
    }
    Ok(())
}

/// The Monte Carlo's touchdowns, a cloud per controller (same seeds), with
/// the wheel-landing target's region.
fn write_touchdowns(
    path: &Path,
    scenario: &str,
    reports: &[(&str, MonteCarloReport)],
) -> Result<()> {
    let clouds: Vec<TouchdownCloud<'_>> = reports
        .iter()
        .map(|(name, r)| TouchdownCloud {
            label: if name.is_empty() { "controller" } else { name },
            points: r
                .per_run
                .iter()
                .filter_map(|run| run.touchdown_tilt_deg.zip(run.impact_speed_mps))
                .collect(),
            in_target: r.landed_past_64_deg,
        })
        .collect();
    let runs = reports.first().map_or(0, |(_, r)| r.runs);
    let seed = reports.first().map_or(0, |(_, r)| r.base_seed);
    write_touchdown_figure(
        path,
        &clouds,
        monte_carlo::PAST_TILT_DEG,
        monte_carlo::PAST_IMPACT_MPS,
        &format!("{scenario}: {runs} randomized runs from seed {seed}"),
    )?;
    Ok(())
}

/// One table, a column per controller, the same seeds.
fn print_comparison(reports: &[(&str, MonteCarloReport)]) {
    let row = |label: &str, cell: &dyn Fn(&MonteCarloReport) -> String| {
        let cells: Vec<String> = reports
            .iter()
            .map(|(_, r)| format!("{:>16}", cell(r)))
            .collect();
        println!("| {label:<34} |{} |", cells.join(" |"));
    };
    let names: Vec<String> = reports.iter().map(|(n, _)| format!("{n:>16}")).collect();
    println!("| {:<34} |{} |", "same seeds", names.join(" |"));
    let dist = |d: &Option<monte_carlo::Distribution>,
                f: &dyn Fn(&monte_carlo::Distribution) -> f64,
                p: usize| {
        d.as_ref()
            .map_or("-".to_string(), |d| format!("{:.p$}", f(d)))
    };
    row("success", &|r| format!("{}/{}", r.successes, r.runs));
    row("crashes", &|r| r.crashes.to_string());
    row("touchdown tilt median (deg)", &|r| {
        dist(&r.touchdown_tilt_deg, &|d| d.median, 1)
    });
    row("touchdown tilt p05 (deg)", &|r| {
        dist(&r.touchdown_tilt_deg, &|d| d.p05, 1)
    });
    row("impact speed median (m/s)", &|r| {
        dist(&r.impact_speed_mps, &|d| d.median, 2)
    });
    row("impact speed p95 (m/s)", &|r| {
        dist(&r.impact_speed_mps, &|d| d.p95, 2)
    });
    row("impact speed max (m/s)", &|r| {
        dist(&r.impact_speed_mps, &|d| d.max, 2)
    });
    row("max mean thrust median", &|r| {
        dist(&r.max_mean_thrust, &|d| d.median, 3)
    });
    row("tilt >= 64, impact <= 0.4, no crash", &|r| {
        format!("{}/{}", r.landed_past_64_deg, r.runs)
    });
}

/// One flight, its outputs written into `dir`; whether it succeeded.
fn single(scenario: &Scenario, controller: &ControllerConfig, dir: &Path) -> Result<bool> {
    let mut records: Vec<TickRecord> = Vec::new();
    let log_path = dir.join("flight.mcap");
    let (summary, log) = fly_logged(scenario, controller, &log_path, |r| records.push(*r))?;
    let summary_path = dir.join("summary.json");
    std::fs::write(
        &summary_path,
        serde_json::to_string_pretty(&summary)? + "\n",
    )
    .with_context(|| format!("writing {}", summary_path.display()))?;
    let lim = &controller.robot.limits;
    let markers = Markers {
        morph_height: lim.morph_height,
        transition_height: lim.transition_height,
        touchdown: summary.touchdown_time_s,
    };
    let figure_path = dir.join("figure.png");
    write_landing_figure(
        &figure_path,
        &trace_of(&records),
        &markers,
        &format!(
            "ATMO {} (simulated, seed {})",
            scenario.file.name, scenario.file.seed
        ),
    )?;
    let ok = scenario.file.success.met_by(&summary);
    let fmt = |v: Option<f64>, unit: &str| v.map_or("-".to_string(), |v| format!("{v:.2} {unit}"));
    println!("scenario          {}", scenario.file.name);
    println!("modes             {}", summary.mode_sequence.join(" -> "));
    println!(
        "touchdown tilt    {}",
        fmt(summary.touchdown_tilt_deg, "deg")
    );
    println!("impact speed      {}", fmt(summary.impact_speed_mps, "m/s"));
    println!("max mean thrust   {:.3}", summary.max_mean_thrust);
    println!(
        "crashed           {}",
        summary.crash_reason.as_deref().unwrap_or("no")
    );
    println!("driven            {:.2} m", summary.drive_distance_m);
    println!("MPC failures      {}", summary.mpc_failures);
    println!(
        "time              {:.1} s simulated in {:.2} s ({:.0}x real time)",
        summary.sim_time_s,
        summary.wall_time_s.unwrap_or(0.0),
        summary.sim_time_s / summary.wall_time_s.unwrap_or(0.0).max(1e-9)
    );
    println!(
        "outputs           summary.json, figure.png and flight.mcap ({} messages)",
        log.written
    );
    println!(
        "result            {}",
        if ok { "SUCCESS" } else { "FAILED" }
    );
    Ok(ok)
}

fn many(
    scenario: &Scenario,
    controller: &ControllerConfig,
    dir: &Path,
    runs: usize,
    opts: &MonteCarloArgs,
) -> Result<MonteCarloReport> {
    let seed = opts.seed;
    let threads = opts
        .jobs
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, std::num::NonZero::get));
    let bar = ProgressBar::new(runs as u64);
    bar.set_style(
        ProgressStyle::with_template("{bar:40} {pos}/{len} runs  {elapsed_precise} (eta {eta})")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let wall = std::time::Instant::now();
    let report = monte_carlo::run(scenario, controller, runs, seed, threads, &|n| {
        bar.set_position(n as u64);
    });
    bar.finish_and_clear();
    let wall_time_s = wall.elapsed().as_secs_f64();
    let path = dir.join("monte_carlo.json");
    std::fs::write(&path, serde_json::to_string_pretty(&report)? + "\n")
        .with_context(|| format!("writing {}", path.display()))?;
    println!(
        "{}: {}/{} successful ({:.1} %), {} crashes, {} runs without a flight, {:.0} s on {} threads",
        report.scenario,
        report.successes,
        report.runs,
        100.0 * report.success_rate,
        report.crashes,
        report.errors,
        wall_time_s,
        threads.min(runs)
    );
    if let (Some(t), Some(v)) = (&report.touchdown_tilt_deg, &report.impact_speed_mps) {
        println!(
            "touchdown tilt  median {:.1} deg (p05 {:.1}, p95 {:.1}); impact speed median {:.2} m/s (p95 {:.2}, max {:.2})",
            t.median, t.p05, t.p95, v.median, v.p95, v.max
        );
    }
    let c = &report.criteria_met;
    println!("success           {}", c.success);
    println!(
        "target            {} (>= {} deg, <= {} m/s)",
        c.wheel_landing_target,
        monte_carlo::PAST_TILT_DEG,
        monte_carlo::PAST_IMPACT_MPS
    );
    println!("no crash          {}", c.no_crash);
    if let Some(p) = &report.prediction {
        println!(
            "prediction        flown - predicted at the decision over {} runs: impact {:+.3} m/s (spread {:.3}), tilt {:+.2} deg (spread {:.2})",
            p.runs,
            p.impact_speed_bias_mps,
            p.impact_speed_spread_mps,
            p.touchdown_tilt_bias_deg,
            p.touchdown_tilt_spread_deg
        );
    }
    for f in report.failures.iter().take(10) {
        println!("  failed run {} (seed {}): {}", f.run, f.seed, f.reason);
    }
    println!("outputs           monte_carlo.json");
    Ok(report)
}
