//! `atmo-sim fly`: one closed-loop flight or a Monte Carlo, with outputs.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use atmo_sim::closed_loop::{ControllerConfig, TickRecord, fly_logged, trace_of};
use atmo_sim::figure::{Markers, write_landing_figure};
use atmo_sim::monte_carlo;
use atmo_sim::scenario::Scenario;
use indicatif::{ProgressBar, ProgressStyle};

pub fn run(
    scenario_path: &Path,
    out: &Path,
    runs: Option<usize>,
    seed: u64,
    jobs: Option<usize>,
) -> Result<()> {
    let scenario = Scenario::load(scenario_path).with_context(|| "loading the scenario")?;
    let controller = ControllerConfig::atmo()?.deterministic();
    let dir: PathBuf = out.join(&scenario.file.name);
    // Staged: a run that fails leaves an earlier run's folder as it was.
    let staged = atmo_io::output_dir::StagedDir::new(&dir)?;
    let succeeded = match runs {
        None => single(&scenario, &controller, staged.path())?,
        Some(0) => bail!("--runs must be at least 1"),
        Some(n) => many(&scenario, &controller, staged.path(), n, seed, jobs)?,
    };
    let dir = staged.commit()?;
    println!("wrote             {}", dir.display());
    if !succeeded {
        std::process::exit(1);
    }
    Ok(())
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
    seed: u64,
    jobs: Option<usize>,
) -> Result<bool> {
    let threads = jobs
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, std::num::NonZero::get));
    let bar = ProgressBar::new(runs as u64);
    bar.set_style(
        ProgressStyle::with_template("{bar:40} {pos}/{len} runs  {elapsed_precise} (eta {eta})")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let report = monte_carlo::run(scenario, controller, runs, seed, threads, &|n| {
        bar.set_position(n as u64);
    })?;
    bar.finish_and_clear();
    let path = dir.join("monte_carlo.json");
    std::fs::write(&path, serde_json::to_string_pretty(&report)? + "\n")
        .with_context(|| format!("writing {}", path.display()))?;
    println!(
        "{}: {}/{} successful ({:.1} %), {} crashes, {:.0} s on {} threads",
        report.scenario,
        report.successes,
        report.runs,
        100.0 * report.success_rate,
        report.crashes,
        report.wall_time_s,
        report.threads
    );
    if let (Some(t), Some(v)) = (&report.touchdown_tilt_deg, &report.impact_speed_mps) {
        println!(
            "touchdown tilt  median {:.1} deg (p05 {:.1}, p95 {:.1}); impact speed median {:.2} m/s (p95 {:.2}, max {:.2})",
            t.median, t.p05, t.p95, v.median, v.p95, v.max
        );
    }
    for f in report.failures.iter().take(10) {
        println!(
            "  failed run {} (seed {}): tilt {:?}, impact {:?}, crash {:?}",
            f.run,
            f.seed,
            f.summary.touchdown_tilt_deg,
            f.summary.impact_speed_mps,
            f.summary.crash_reason
        );
    }
    println!("outputs           monte_carlo.json");
    Ok(true)
}
