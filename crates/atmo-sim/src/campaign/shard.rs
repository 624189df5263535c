//! Shards: which runs of a campaign one process flies, the partial result
//! it writes, and the merge of all of them.
//!
//! Shard `k` of `n` flies the global runs `g` with `g % n == k` (round
//! robin, so that every shard gets a share of every cell). A run's record
//! depends on the plan and `g` only, so merging the shards in any number
//! and order gives the reports one process flying all runs gives, byte for
//! byte once serialized ([`crate::monte_carlo::report`] is a pure function
//! of the records, and JSON numbers read back to the same `f64`).

use std::collections::BTreeMap;
use std::fmt::{self, Write as _};
use std::path::{Path, PathBuf};
use std::str::FromStr;

use atmo_core::input_file::{self, InputKind};
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

use super::Plan;
use crate::monte_carlo::{self, MonteCarloReport, RunRecord};

/// The shard format's version, refused when it differs.
pub const SHARD_FORMAT: u32 = 1;

/// `K/N`: shard `K` (0-based) of `N`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct ShardSpec {
    pub index: usize,
    pub count: usize,
}

impl FromStr for ShardSpec {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        let (k, n) = s
            .split_once('/')
            .ok_or_else(|| format!("{s:?}: expected K/N, e.g. 0/8"))?;
        let index: usize = k
            .trim()
            .parse()
            .map_err(|_| format!("{s:?}: K is not a count"))?;
        let count: usize = n
            .trim()
            .parse()
            .map_err(|_| format!("{s:?}: N is not a count"))?;
        if count == 0 || count > 10_000 || index >= count {
            return Err(format!("{s:?}: expected 0 <= K < N <= 10000"));
        }
        Ok(Self { index, count })
    }
}

impl fmt::Display for ShardSpec {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

impl ShardSpec {
    /// The whole campaign in one process.
    pub const WHOLE: Self = Self { index: 0, count: 1 };

    /// The global runs this shard flies, in order.
    pub fn runs(self, total: usize) -> Vec<usize> {
        (self.index..total).step_by(self.count).collect()
    }

    /// `shard-K-of-N.json`.
    pub fn file_name(self) -> String {
        format!("shard-{:05}-of-{:05}.json", self.index, self.count)
    }
}

/// What flew a shard: the binary and everything it flew from. Shards of
/// one campaign must agree, or their runs are not the same experiment.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct BuildIdentity {
    /// SHA-256 of the executable that flew the shard.
    pub binary_sha256: String,
    /// SHA-256 of the scenario and controller configuration as flown (their
    /// full parsed form, which includes every config file's content).
    pub config_sha256: String,
}

impl BuildIdentity {
    /// The identity of `binary` (bytes) flying `config` (the parsed
    /// scenario and controller, in their `Debug` form: every value flown).
    pub fn of(binary: &[u8], config: &str) -> Self {
        let hex = |bytes: &[u8]| {
            Sha256::digest(bytes)
                .iter()
                .fold(String::with_capacity(64), |mut s, b| {
                    let _ = write!(s, "{b:02x}");
                    s
                })
        };
        Self {
            binary_sha256: hex(binary),
            config_sha256: hex(config.as_bytes()),
        }
    }
}

/// One flown run of a campaign.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CampaignRun {
    /// Global run index.
    pub global: usize,
    pub cell: usize,
    pub record: RunRecord,
}

/// A shard's partial result (`shard-K-of-N.json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ShardFile {
    pub format: u32,
    pub build: BuildIdentity,
    pub plan: Plan,
    pub shard: ShardSpec,
    pub runs: Vec<CampaignRun>,
    /// Wall-clock time the shard took, s (not part of any report).
    pub wall_time_s: f64,
}

/// Why shards do not merge; each names the shard file at fault.
#[derive(Debug, thiserror::Error)]
pub enum MergeError {
    #[error("{path}: {message}")]
    Read { path: PathBuf, message: String },
    #[error("no shard-*.json found in {0}")]
    Empty(String),
    #[error("{path}: shard format {found}, this build reads {SHARD_FORMAT}")]
    Format { path: PathBuf, found: u32 },
    #[error("{path}: flown by another build ({what} {theirs} against {ours} in {first})")]
    Build {
        path: PathBuf,
        first: PathBuf,
        what: &'static str,
        theirs: String,
        ours: String,
    },
    #[error("{path}: another campaign's plan than {first}'s ({what} differs)")]
    Plan {
        path: PathBuf,
        first: PathBuf,
        what: String,
    },
    #[error("{path}: shard {shard} is also in {other}")]
    Duplicate {
        path: PathBuf,
        other: PathBuf,
        shard: ShardSpec,
    },
    #[error("shards missing of {count}: {missing} (found: {found})")]
    Missing {
        count: usize,
        missing: String,
        found: String,
    },
    #[error("{path}: shard {shard} holds run {global}, which is not one of its runs")]
    ForeignRun {
        path: PathBuf,
        shard: ShardSpec,
        global: usize,
    },
    #[error("{path}: shard {shard} does not hold each of its runs once (missing: {missing})")]
    IncompleteShard {
        path: PathBuf,
        shard: ShardSpec,
        missing: String,
    },
}

/// Every shard merged: the plan and each cell's report.
#[derive(Debug, Clone, PartialEq)]
pub struct Merged {
    pub plan: Plan,
    pub build: BuildIdentity,
    /// One report per cell, in cell order.
    pub cells: Vec<MonteCarloReport>,
    /// Sum of the shards' wall-clock times, s.
    pub shard_wall_time_s: f64,
}

/// A shard file as an input ([`atmo_core::input_file`]): one cell's runs
/// are a few hundred bytes each, so this is far above any campaign's.
const SHARD: InputKind = InputKind {
    name: "a shard file",
    max_bytes: 1 << 30,
    advice: "",
};

/// Reads a shard file.
pub fn read_shard(path: &Path) -> Result<ShardFile, MergeError> {
    let read = |message: String| MergeError::Read {
        path: path.to_path_buf(),
        message,
    };
    let text = input_file::read_text(path, SHARD).map_err(|e| read(e.to_string()))?;
    let format: serde_json::Value =
        serde_json::from_str(&text).map_err(|e| read(format!("not JSON: {e}")))?;
    let found = format.get("format").and_then(serde_json::Value::as_u64);
    if found != Some(u64::from(SHARD_FORMAT)) {
        return Err(MergeError::Format {
            path: path.to_path_buf(),
            found: found.map_or(0, |f| f as u32),
        });
    }
    serde_json::from_value(format).map_err(|e| read(format!("not a shard: {e}")))
}

/// The shard files in `paths`: each a shard file, or a folder whose
/// `shard-*.json` are read.
pub fn shard_paths(paths: &[PathBuf]) -> Result<Vec<PathBuf>, MergeError> {
    let mut out = Vec::new();
    for p in paths {
        if p.is_dir() {
            let mut found: Vec<PathBuf> = std::fs::read_dir(p)
                .map_err(|e| MergeError::Read {
                    path: p.clone(),
                    message: e.to_string(),
                })?
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|f| {
                    f.file_name()
                        .and_then(|n| n.to_str())
                        .is_some_and(|n| n.starts_with("shard-"))
                        && f.extension().is_some_and(|e| e == "json")
                })
                .collect();
            if found.is_empty() {
                return Err(MergeError::Empty(p.display().to_string()));
            }
            found.sort();
            out.extend(found);
        } else {
            out.push(p.clone());
        }
    }
    Ok(out)
}

/// Merges shards: the same build and plan in all, each of the `N` shards
/// once, each holding exactly its runs. Gives each cell's report.
pub fn merge(shards: Vec<(PathBuf, ShardFile)>) -> Result<Merged, MergeError> {
    let Some((first_path, first)) = shards.first().map(|(p, s)| (p.clone(), s.clone())) else {
        return Err(MergeError::Empty("the arguments".to_string()));
    };
    let count = first.shard.count;
    let mut by_index: BTreeMap<usize, PathBuf> = BTreeMap::new();
    let mut records: Vec<Option<CampaignRun>> = vec![None; first.plan.total_runs()];
    let mut wall = 0.0;
    for (path, shard) in shards {
        check_same(&path, &first_path, &first, &shard)?;
        if let Some(other) = by_index.insert(shard.shard.index, path.clone()) {
            return Err(MergeError::Duplicate {
                path,
                other,
                shard: shard.shard,
            });
        }
        let expected = shard.shard.runs(records.len());
        let mut got: Vec<usize> = shard.runs.iter().map(|r| r.global).collect();
        got.sort_unstable();
        for run in shard.runs {
            let global = run.global;
            let foreign = || MergeError::ForeignRun {
                path: path.clone(),
                shard: shard.shard,
                global,
            };
            if run.global % count != shard.shard.index || run.global >= records.len() {
                return Err(foreign());
            }
            if first.plan.locate(run.global).0 != run.cell
                || run.record.run != first.plan.locate(run.global).1
            {
                return Err(foreign());
            }
            records[global] = Some(run);
        }
        if got != expected {
            let missing: Vec<String> = expected
                .iter()
                .filter(|g| got.binary_search(g).is_err())
                .take(20)
                .map(ToString::to_string)
                .collect();
            return Err(MergeError::IncompleteShard {
                path,
                shard: shard.shard,
                missing: missing.join(", "),
            });
        }
        wall += shard.wall_time_s;
    }
    let missing: Vec<String> = (0..count)
        .filter(|k| !by_index.contains_key(k))
        .map(|k| ShardSpec { index: k, count }.to_string())
        .collect();
    if !missing.is_empty() {
        return Err(MergeError::Missing {
            count,
            missing: missing.join(", "),
            found: by_index.len().to_string(),
        });
    }
    let plan = first.plan;
    let mut per_cell: Vec<Vec<RunRecord>> =
        vec![Vec::with_capacity(plan.runs_per_cell); plan.cells.len()];
    // Every slot is filled: each shard held exactly its runs, and every shard is here.
    for run in records.into_iter().flatten() {
        per_cell[run.cell].push(run.record);
    }
    let cells = per_cell
        .into_iter()
        .map(|runs| monte_carlo::report(&plan.scenario, plan.base_seed, plan.success, runs))
        .collect();
    Ok(Merged {
        plan,
        build: first.build,
        cells,
        shard_wall_time_s: wall,
    })
}

fn check_same(
    path: &Path,
    first_path: &Path,
    first: &ShardFile,
    shard: &ShardFile,
) -> Result<(), MergeError> {
    let build = |what, theirs: &str, ours: &str| MergeError::Build {
        path: path.to_path_buf(),
        first: first_path.to_path_buf(),
        what,
        theirs: theirs.to_string(),
        ours: ours.to_string(),
    };
    if shard.build.binary_sha256 != first.build.binary_sha256 {
        return Err(build(
            "binary",
            &shard.build.binary_sha256,
            &first.build.binary_sha256,
        ));
    }
    if shard.build.config_sha256 != first.build.config_sha256 {
        return Err(build(
            "configuration",
            &shard.build.config_sha256,
            &first.build.config_sha256,
        ));
    }
    if shard.shard.count != first.shard.count {
        return Err(MergeError::Plan {
            path: path.to_path_buf(),
            first: first_path.to_path_buf(),
            what: format!(
                "shard count {} against {}",
                shard.shard.count, first.shard.count
            ),
        });
    }
    if shard.plan != first.plan {
        let what = if shard.plan.name != first.plan.name {
            format!("name {:?} against {:?}", shard.plan.name, first.plan.name)
        } else if shard.plan.base_seed != first.plan.base_seed {
            format!(
                "base seed {} against {}",
                shard.plan.base_seed, first.plan.base_seed
            )
        } else {
            "its cells, runs or criteria".to_string()
        };
        return Err(MergeError::Plan {
            path: path.to_path_buf(),
            first: first_path.to_path_buf(),
            what,
        });
    }
    Ok(())
}

/// Flies shard `shard` of `plan` on `threads` threads (`config` is what
/// [`BuildIdentity`] hashes, `binary` the executable's bytes). `progress`
/// is called after each run with the number finished and the total.
#[allow(clippy::too_many_arguments)]
pub fn fly_shard(
    plan: &Plan,
    base: &crate::scenario::Scenario,
    controller: &crate::closed_loop::ControllerConfig,
    shard: ShardSpec,
    threads: usize,
    build: BuildIdentity,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> ShardFile {
    let wall = std::time::Instant::now();
    let runs = shard.runs(plan.total_runs());
    let limit = std::time::Duration::from_secs_f64(plan.run_time_limit_s);
    let mut flown = Vec::with_capacity(runs.len());
    let mut done = 0;
    // Cell by cell: each cell's scenario is built once.
    for cell in 0..plan.cells.len() {
        let in_cell: Vec<usize> = runs
            .iter()
            .copied()
            .filter(|g| plan.locate(*g).0 == cell)
            .collect();
        if in_cell.is_empty() {
            continue;
        }
        let scenario = plan.cell_scenario(base, cell);
        let indices: Vec<usize> = in_cell.iter().map(|g| plan.locate(*g).1).collect();
        let records = monte_carlo::fly_runs(
            &scenario,
            controller,
            &indices,
            plan.base_seed,
            threads,
            limit,
            &|n| progress(done + n, runs.len()),
        );
        done += records.len();
        flown.extend(
            in_cell
                .into_iter()
                .zip(records)
                .map(|(global, record)| CampaignRun {
                    global,
                    cell,
                    record,
                }),
        );
    }
    flown.sort_by_key(|r| r.global);
    ShardFile {
        format: SHARD_FORMAT,
        build,
        plan: plan.clone(),
        shard,
        runs: flown,
        wall_time_s: wall.elapsed().as_secs_f64(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shards_cover_every_run_once() {
        for count in 1..9 {
            let mut all: Vec<usize> = (0..count)
                .flat_map(|index| ShardSpec { index, count }.runs(37))
                .collect();
            all.sort_unstable();
            assert_eq!(all, (0..37).collect::<Vec<_>>());
        }
    }

    #[test]
    fn shard_specs_parse_and_refuse() {
        assert_eq!(
            "3/8".parse::<ShardSpec>().unwrap(),
            ShardSpec { index: 3, count: 8 }
        );
        for bad in ["8/8", "1", "a/2", "0/0", "-1/3"] {
            assert!(bad.parse::<ShardSpec>().is_err(), "{bad}");
        }
    }

    /// A shard is read through the one input rule: a device or a folder
    /// is refused before reading, naming the path.
    #[test]
    fn a_device_or_a_folder_is_refused_as_a_shard() {
        let mut paths = vec![std::env::temp_dir()];
        paths.extend(
            ["/dev/zero", "/dev/null"]
                .map(PathBuf::from)
                .into_iter()
                .filter(|p| p.exists()),
        );
        for path in paths {
            let err = read_shard(&path).unwrap_err().to_string();
            assert!(
                err.starts_with(&path.display().to_string()) && err.contains("not a regular file"),
                "{err}"
            );
        }
    }
}
