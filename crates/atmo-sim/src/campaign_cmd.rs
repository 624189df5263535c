//! `atmo-sim campaign`: plan, fly, merge and submit landing campaigns
//! (docs/campaigns.md), and the shard of `atmo-sim fly --shard`.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use atmo_io::output_dir::{StagedFiles, open_shared};
use atmo_io::review::success_map::{MapAxis, MapCell, write_success_map};
use atmo_sim::campaign::shard::{self, BuildIdentity, Merged, ShardFile, ShardSpec};
use atmo_sim::campaign::{CampaignFile, Plan, Target, slurm};
use atmo_sim::closed_loop::{ControllerConfig, ControllerPreset};
use atmo_sim::monte_carlo::{self, Count, MonteCarloReport};
use atmo_sim::scenario::Scenario;
use serde::Serialize;

/// `atmo-sim campaign ...`.
#[derive(clap::Subcommand)]
pub enum CampaignCommand {
    /// Expand a campaign file: print its cells, runs and shards, and the
    /// command each shard runs; write OUT/plan.json.
    Plan {
        /// Campaign file (TOML, see config/campaigns/).
        campaign: PathBuf,
        #[command(flatten)]
        controller: ControllerOverride,
        #[command(flatten)]
        out: CampaignFolder,
    },
    /// Fly a campaign: one shard (--shard K/N, writes
    /// OUT/shards/shard-K-of-N.json for `merge`), or all of it in this
    /// process (then merged into OUT at once), or one run alone
    /// (--run-index G: prints its record).
    Run {
        campaign: PathBuf,
        #[command(flatten)]
        controller: ControllerOverride,
        /// Fly only shard K of N (0-based): the global runs g with g % N == K.
        #[arg(long)]
        shard: Option<ShardSpec>,
        /// Fly only global run G (cell G / runs_per_cell, seed base_seed +
        /// G % runs_per_cell) and print its record: a failed run again.
        #[arg(long, conflicts_with = "shard")]
        run_index: Option<usize>,
        /// Threads (default: all cores; at most 1024).
        #[arg(long, value_parser = atmo_core::cli_numbers::job_count)]
        jobs: Option<usize>,
        #[command(flatten)]
        out: CampaignFolder,
    },
    /// Merge shards (shard files or folders of them) into OUT: a plain
    /// Monte Carlo's monte_carlo.json (the one `fly --runs N` writes, byte
    /// for byte), or a sweep's campaign.json, cells.md and map.png. A
    /// missing or repeated shard, or one flown by another build, is refused.
    Merge {
        #[arg(required = true)]
        shards: Vec<PathBuf>,
        #[command(flatten)]
        out: CampaignFolder,
    },
    /// Write OUT/campaign.sbatch: a Slurm array job, one task per shard of
    /// the campaign file's `shards`, with its `[slurm]` resources; submit
    /// it with `sbatch`, then `merge OUT/shards`.
    Slurm {
        campaign: PathBuf,
        #[command(flatten)]
        controller: ControllerOverride,
        #[command(flatten)]
        out: CampaignFolder,
        /// The atmo-sim each task runs (default: this one). It must be
        /// reachable at this path from every node.
        #[arg(long)]
        binary: Option<PathBuf>,
    },
}

/// `--out`: the folder every command of one campaign shares.
#[derive(clap::Args, Clone)]
pub struct CampaignFolder {
    /// The campaign folder: created with its marker file (.atmo-output) if
    /// absent, and used again only if this tool made it (or it is empty);
    /// a file, a symbolic link, a device or a folder this tool did not
    /// write is refused before anything is written or flown. Each file a
    /// command adds appears whole (written under a temporary name, then
    /// renamed into place).
    #[arg(long = "out", value_name = "OUT", default_value = "out/campaign")]
    path: PathBuf,
}

/// `--controller`: fly the campaign with another controller than its file
/// names (the same cells and seeds).
#[derive(clap::Args, Clone, Copy)]
pub struct ControllerOverride {
    #[arg(long, value_enum)]
    controller: Option<ControllerPreset>,
}

pub fn run(command: CampaignCommand) -> Result<()> {
    match command {
        CampaignCommand::Plan {
            campaign,
            controller,
            out,
        } => plan(&campaign, controller, &out.path),
        CampaignCommand::Run {
            campaign,
            controller,
            shard,
            run_index,
            jobs,
            out,
        } => run_campaign(&campaign, controller, shard, run_index, jobs, &out.path),
        CampaignCommand::Merge { shards, out } => merge(&shards, &out.path),
        CampaignCommand::Slurm {
            campaign,
            controller,
            out,
            binary,
        } => write_slurm(&campaign, controller, &out.path, binary),
    }
}

/// The campaign file, its scenario (relative to the file) and controller.
fn load(
    path: &Path,
    controller: ControllerOverride,
) -> Result<(CampaignFile, Scenario, ControllerConfig, Plan)> {
    let mut file = CampaignFile::load(path)?;
    if let Some(c) = controller.controller {
        file.controller = c;
    }
    let scenario_path = path
        .parent()
        .unwrap_or_else(|| Path::new("."))
        .join(&file.scenario);
    let scenario = Scenario::load(&scenario_path)
        .with_context(|| format!("{}: key `scenario`", path.display()))?;
    let base = ControllerConfig::atmo()?.deterministic();
    let controller = file
        .controller
        .config(&base, &atmo_mpc::settings::GroundEffectSource::PlantDefault)?;
    let plan = Plan::of(&file, &scenario);
    Ok((file, scenario, controller, plan))
}

fn threads(jobs: Option<usize>) -> usize {
    jobs.unwrap_or_else(|| std::thread::available_parallelism().map_or(1, std::num::NonZero::get))
}

/// What flew: this executable and the parsed scenario and controller.
fn build_identity(scenario: &Scenario, controller: &ControllerConfig) -> Result<BuildIdentity> {
    let exe = std::env::current_exe().context("locating this executable")?;
    let binary = std::fs::read(&exe).with_context(|| format!("reading {}", exe.display()))?;
    let config = format!(
        "{:?}\n{:?}\n{:?}\n{:?}\n{:?}\n{:?}\n{:?}",
        scenario.file,
        scenario.robot,
        scenario.plant,
        controller.robot,
        controller.flight,
        controller.mpc,
        controller.inputs
    );
    Ok(BuildIdentity::of(&binary, &config))
}

/// Writes `value` as pretty JSON to `path` in a folder [`open_shared`]
/// opened, through a temporary file, so a reader never sees half a file.
fn write_json(path: &Path, value: &impl Serialize) -> Result<()> {
    let name = path
        .file_name()
        .with_context(|| format!("{}: not a file name", path.display()))?;
    let mut files = StagedFiles::new(path.parent().unwrap_or_else(|| Path::new(".")));
    files.write(name, serde_json::to_string_pretty(value)? + "\n")?;
    files.commit()?;
    Ok(())
}

/// Opens the campaign folder `out` ([`open_shared`]: created and marked,
/// or one this tool wrote) and its `shards/` folder, before any run flies.
pub fn open_campaign_folder(out: &Path) -> Result<PathBuf> {
    open_shared(out)?;
    let shards = out.join("shards");
    std::fs::create_dir_all(&shards).with_context(|| format!("creating {}", shards.display()))?;
    Ok(shards)
}

/// Flies `shard` of `plan` and writes it into the campaign folder `out`'s
/// `shards/`, with progress lines on stderr (a batch job's log: at most
/// one per 5 % or per 30 s). The folder is checked before the first run.
pub fn fly_and_write_shard(
    plan: &Plan,
    scenario: &Scenario,
    controller: &ControllerConfig,
    shard: ShardSpec,
    jobs: Option<usize>,
    out: &Path,
) -> Result<()> {
    let dir = open_campaign_folder(out)?;
    let build = build_identity(scenario, controller)?;
    let start = Instant::now();
    let last = Mutex::new((0usize, Instant::now()));
    let total = shard.runs(plan.total_runs()).len();
    eprintln!(
        "shard {shard}: {total} runs of {} on {} threads",
        plan.total_runs(),
        threads(jobs)
    );
    let file = shard::fly_shard(
        plan,
        scenario,
        controller,
        shard,
        threads(jobs),
        build,
        &|n, of| {
            let mut last = last
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner);
            let step = (of / 20).max(1);
            if n == of || n >= last.0 + step || last.1.elapsed().as_secs() >= 30 {
                *last = (n, Instant::now());
                eprintln!(
                    "shard {shard}: {n}/{of} runs ({:.0} %), {:.0} s",
                    100.0 * n as f64 / of.max(1) as f64,
                    start.elapsed().as_secs_f64()
                );
            }
        },
    );
    let errors = file
        .runs
        .iter()
        .filter(|r| r.record.error.is_some())
        .count();
    let path = dir.join(shard.file_name());
    write_json(&path, &file)?;
    println!(
        "shard {shard}: {} runs ({} without a flight) in {:.0} s -> {}",
        file.runs.len(),
        errors,
        file.wall_time_s,
        path.display()
    );
    Ok(())
}

fn plan(campaign: &Path, controller: ControllerOverride, out: &Path) -> Result<()> {
    let (file, _, _, plan) = load(campaign, controller)?;
    println!(
        "campaign          {} ({} on {}, controller {})",
        plan.name,
        campaign.display(),
        plan.scenario,
        plan.controller.name()
    );
    println!(
        "cells             {} x {} runs = {} runs, seeds {}..{} in every cell",
        plan.cells.len(),
        plan.runs_per_cell,
        plan.total_runs(),
        plan.base_seed,
        plan.base_seed + plan.runs_per_cell as u64 - 1
    );
    for (c, _) in plan.cells.iter().enumerate() {
        println!("  cell {c:>4}: {}", plan.describe_cell(c));
    }
    println!(
        "shards            {} (shard K flies the global runs g with g % {} == K)",
        file.shards, file.shards
    );
    println!(
        "each shard        atmo-sim campaign run {} --shard K/{} --out {}",
        campaign.display(),
        file.shards,
        out.display()
    );
    open_shared(out)?;
    let path = out.join("plan.json");
    write_json(&path, &plan)?;
    println!("wrote             {}", path.display());
    Ok(())
}

fn run_campaign(
    campaign: &Path,
    controller_override: ControllerOverride,
    shard: Option<ShardSpec>,
    run_index: Option<usize>,
    jobs: Option<usize>,
    out: &Path,
) -> Result<()> {
    let (_, scenario, controller, plan) = load(campaign, controller_override)?;
    if let Some(g) = run_index {
        if g >= plan.total_runs() {
            bail!(
                "--run-index {g}: the campaign has runs 0..{}",
                plan.total_runs()
            );
        }
        let (cell, index) = plan.locate(g);
        let limit = std::time::Duration::from_secs_f64(plan.run_time_limit_s);
        let record = monte_carlo::fly_run(
            &plan.cell_scenario(&scenario, cell),
            &controller,
            plan.base_seed,
            index,
            limit,
        );
        println!(
            "run {g}: cell {cell} ({}), run {index} of the cell",
            plan.describe_cell(cell)
        );
        println!("{}", serde_json::to_string_pretty(&record)?);
        return Ok(());
    }
    if let Some(shard) = shard {
        return fly_and_write_shard(&plan, &scenario, &controller, shard, jobs, out);
    }
    fly_and_write_shard(&plan, &scenario, &controller, ShardSpec::WHOLE, jobs, out)?;
    merge(
        &[out.join("shards").join(ShardSpec::WHOLE.file_name())],
        out,
    )
}

/// `campaign.json`: the plan and each cell's report.
#[derive(Serialize)]
struct CampaignReport<'a> {
    plan: &'a Plan,
    build: &'a BuildIdentity,
    cells: Vec<CellReport<'a>>,
}

#[derive(Serialize)]
struct CellReport<'a> {
    values: &'a [f64],
    /// The campaign's target, counted over the cell.
    target: Count,
    report: &'a MonteCarloReport,
}

fn in_target(report: &MonteCarloReport, target: &Target) -> Count {
    let n = report
        .per_run
        .iter()
        .filter(|r| {
            !r.crashed
                && r.touchdown_tilt_deg
                    .is_some_and(|t| t >= target.touchdown_tilt_min_deg)
                && r.impact_speed_mps
                    .is_some_and(|v| v <= target.impact_speed_max_mps)
        })
        .count();
    Count::of(n, report.runs)
}

fn merge(paths: &[PathBuf], out: &Path) -> Result<()> {
    open_shared(out)?;
    let files = shard::shard_paths(paths)?;
    let shards: Vec<(PathBuf, ShardFile)> = files
        .into_iter()
        .map(|p| shard::read_shard(&p).map(|s| (p, s)))
        .collect::<std::result::Result<_, _>>()?;
    let n = shards.len();
    let merged = shard::merge(shards)?;
    println!(
        "merged            {n} shards, {} runs, {:.0} s of shard time",
        merged.plan.total_runs(),
        merged.shard_wall_time_s
    );
    if merged.plan.parameters.is_empty() {
        let report = &merged.cells[0];
        let path = out.join("monte_carlo.json");
        write_json(&path, report)?;
        let c = &report.criteria_met;
        println!("success           {}", c.success);
        println!(
            "target            {}",
            in_target(report, &merged.plan.target)
        );
        println!("no crash          {}", c.no_crash);
        println!("runs without a flight {}", report.errors);
        println!("wrote             {}", path.display());
        return Ok(());
    }
    write_campaign(&merged, out)
}

fn write_campaign(merged: &Merged, out: &Path) -> Result<()> {
    let plan = &merged.plan;
    let cells: Vec<CellReport<'_>> = plan
        .cells
        .iter()
        .zip(&merged.cells)
        .map(|(values, report)| CellReport {
            values,
            target: in_target(report, &plan.target),
            report,
        })
        .collect();
    let table = cell_table(plan, &cells);
    print!("{table}");
    // The table and the report replace an earlier merge's together, before
    // the map is drawn: a figure that fails loses no result.
    let mut files = StagedFiles::new(out);
    files.write("cells.md", &table)?;
    let report = CampaignReport {
        plan,
        build: &merged.build,
        cells,
    };
    files.write(
        "campaign.json",
        serde_json::to_string_pretty(&report)? + "\n",
    )?;
    files.commit()?;
    println!(
        "wrote             {}, {}",
        out.join("campaign.json").display(),
        out.join("cells.md").display()
    );
    let map = out.join("map.png");
    if plan.parameters.len() > 2 {
        println!(
            "map               none: {} swept parameters (a map has two axes)",
            plan.parameters.len()
        );
        return Ok(());
    }
    let mut figure = StagedFiles::new(out);
    let drawn = figure
        .stage("map.png")
        .map_err(anyhow::Error::from)
        .and_then(|path| write_map(merged, path))
        .and_then(|()| Ok(figure.commit()?));
    if let Err(e) = drawn {
        // An earlier merge's map does not show these results.
        let _ = std::fs::remove_file(&map);
        return Err(e.context(format!(
            "drawing {} (campaign.json and cells.md are written)",
            map.display()
        )));
    }
    println!("map               {}", map.display());
    Ok(())
}

fn cell_table(plan: &Plan, cells: &[CellReport<'_>]) -> String {
    let t = &plan.target;
    let mut s = String::new();
    let params: Vec<&str> = plan.parameters.iter().map(|p| p.label()).collect();
    let _ = writeln!(
        s,
        "| {} | runs | target (>= {} deg, <= {} m/s) | Wilson 95 % | success | crashes | no flight | tilt median (deg) | impact median (m/s) | impact p95 (m/s) |",
        params.join(" | "),
        t.touchdown_tilt_min_deg,
        t.impact_speed_max_mps
    );
    let _ = writeln!(s, "|{}", " --- |".repeat(params.len() + 9));
    let med = |d: &Option<monte_carlo::Distribution>,
               f: fn(&monte_carlo::Distribution) -> f64,
               p: usize| {
        d.as_ref()
            .map_or("-".to_string(), |d| format!("{:.p$}", f(d)))
    };
    for c in cells {
        let values: Vec<String> = c.values.iter().map(ToString::to_string).collect();
        let r = c.report;
        let _ = writeln!(
            s,
            "| {} | {} | {} ({:.1} %) | {:.1}-{:.1} % | {} | {} | {} | {} | {} | {} |",
            values.join(" | "),
            r.runs,
            c.target.count,
            100.0 * c.target.rate,
            100.0 * c.target.wilson_95[0],
            100.0 * c.target.wilson_95[1],
            r.successes,
            r.crashes,
            r.errors,
            med(&r.touchdown_tilt_deg, |d| d.median, 1),
            med(&r.impact_speed_mps, |d| d.median, 3),
            med(&r.impact_speed_mps, |d| d.p95, 3),
        );
    }
    s
}

fn write_map(merged: &Merged, path: &Path) -> Result<()> {
    let plan = &merged.plan;
    let axis_values = |k: usize| -> Vec<f64> {
        let mut v: Vec<f64> = plan.cells.iter().map(|c| c[k]).collect();
        v.dedup();
        v.sort_by(f64::total_cmp);
        v.dedup();
        v
    };
    let xs = axis_values(0);
    let ys = if plan.parameters.len() == 2 {
        axis_values(1)
    } else {
        vec![0.0]
    };
    let cells: Vec<MapCell> = merged
        .cells
        .iter()
        .map(|r| {
            let t = in_target(r, &plan.target);
            MapCell {
                in_target: t.count,
                runs: t.runs,
                wilson_95: t.wilson_95,
                touchdown_tilt_deg: r.touchdown_tilt_deg.as_ref().map(|d| d.median),
                impact_speed_mps: r.impact_speed_mps.as_ref().map(|d| d.median),
            }
        })
        .collect();
    let title = format!(
        "{}: {} on {}, {} runs per cell from seed {}",
        plan.name,
        plan.controller.name(),
        plan.scenario,
        plan.runs_per_cell,
        plan.base_seed
    );
    let y_label = plan.parameters.get(1).map_or("", |p| p.label());
    write_success_map(
        path,
        &title,
        MapAxis {
            label: plan.parameters[0].label(),
            values: &xs,
        },
        MapAxis {
            label: y_label,
            values: &ys,
        },
        &cells,
        plan.target.touchdown_tilt_min_deg,
        plan.target.impact_speed_max_mps,
    )?;
    Ok(())
}

fn write_slurm(
    campaign: &Path,
    controller: ControllerOverride,
    out: &Path,
    binary: Option<PathBuf>,
) -> Result<()> {
    let (file, _, _, plan) = load(campaign, controller)?;
    let absolute =
        |p: &Path| std::path::absolute(p).with_context(|| format!("resolving {}", p.display()));
    let binary = match binary {
        Some(b) => absolute(&b)?,
        None => std::env::current_exe().context("locating this executable")?,
    };
    let out = absolute(out)?;
    open_shared(&out)?;
    std::fs::create_dir_all(out.join("logs"))
        .with_context(|| format!("creating {}", out.join("logs").display()))?;
    let script = slurm::sbatch_script(&slurm::ArrayJob {
        name: &plan.name,
        shards: file.shards,
        resources: &file.slurm,
        binary: &binary,
        campaign: &absolute(campaign)?,
        controller: plan.controller.name(),
        out: &out,
    });
    let path = out.join("campaign.sbatch");
    let mut files = StagedFiles::new(&out);
    files.write("campaign.sbatch", script)?;
    files.commit()?;
    println!("wrote             {}", path.display());
    println!("submit            sbatch {}", path.display());
    println!(
        "then              atmo-sim campaign merge {} --out {}",
        out.join("shards").display(),
        out.display()
    );
    Ok(())
}
