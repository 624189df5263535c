//! The `sbatch` array-job script of a campaign: one array task per shard.

use std::fmt::Write as _;
use std::path::Path;

use serde::Deserialize;

/// `[slurm]` of a campaign file: what each array task asks for.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SlurmResources {
    /// Cores per task (the shard's threads).
    pub cpus_per_task: usize,
    /// Memory per task, MiB.
    pub mem_mib: usize,
    /// Wall-clock limit per task, minutes.
    pub time_minutes: usize,
    /// Partition (none: the cluster's default).
    pub partition: Option<String>,
    /// At most this many tasks at once (none: as many as fit).
    pub max_parallel: Option<usize>,
}

impl Default for SlurmResources {
    fn default() -> Self {
        Self {
            cpus_per_task: 1,
            mem_mib: 1024,
            time_minutes: 60,
            partition: None,
            max_parallel: None,
        }
    }
}

impl SlurmResources {
    /// The key at fault and why (`"<given>: <expected>"`).
    pub(super) fn check(&self) -> Result<(), (&'static str, String)> {
        if !(1..=1024).contains(&self.cpus_per_task) {
            return Err((
                "cpus_per_task",
                format!("{}: 1 to 1024", self.cpus_per_task),
            ));
        }
        if !(64..=4 << 20).contains(&self.mem_mib) {
            return Err(("mem_mib", format!("{}: 64 to 4194304 MiB", self.mem_mib)));
        }
        if !(1..=43_200).contains(&self.time_minutes) {
            return Err((
                "time_minutes",
                format!("{}: 1 to 43200 min", self.time_minutes),
            ));
        }
        if let Some(p) = &self.partition {
            if p.is_empty()
                || !p
                    .chars()
                    .all(|c| c.is_ascii_alphanumeric() || "_-.".contains(c))
            {
                return Err(("partition", format!("{p:?}: letters, digits, _ - .")));
            }
        }
        if self.max_parallel == Some(0) {
            return Err(("max_parallel", "0: at least 1".to_string()));
        }
        Ok(())
    }
}

/// Quotes `s` for a POSIX shell.
fn quote(s: &str) -> String {
    format!("'{}'", s.replace('\'', r"'\''"))
}

/// What an array job runs. Paths are written as given: pass absolute ones,
/// the tasks run on other machines.
#[derive(Debug, Clone, Copy)]
pub struct ArrayJob<'a> {
    pub name: &'a str,
    pub shards: usize,
    pub resources: &'a SlurmResources,
    /// The atmo-sim every task runs.
    pub binary: &'a Path,
    pub campaign: &'a Path,
    /// `--controller` of every task (the plan's).
    pub controller: &'a str,
    pub out: &'a Path,
}

/// The array-job script: task `K` runs `atmo-sim campaign run CAMPAIGN
/// --controller C --shard K/SHARDS --out OUT` (which writes `OUT/shards/`);
/// logs in `OUT/logs/`.
pub fn sbatch_script(job: &ArrayJob<'_>) -> String {
    let ArrayJob {
        name,
        shards,
        resources,
        binary,
        campaign,
        controller,
        out,
    } = *job;
    let out_s = out.display().to_string();
    let mut s = String::new();
    let _ = writeln!(s, "#!/bin/bash");
    let _ = writeln!(
        s,
        "# Written by `atmo-sim campaign slurm`: one array task per shard."
    );
    let _ = writeln!(
        s,
        "# Submit: sbatch {}",
        quote(&format!("{out_s}/campaign.sbatch"))
    );
    let _ = writeln!(
        s,
        "# Then:   atmo-sim campaign merge {}",
        quote(&format!("{out_s}/shards"))
    );
    let _ = writeln!(s, "#SBATCH --job-name={}", quote(&format!("atmo-{name}")));
    let throttle = resources
        .max_parallel
        .map(|m| format!("%{m}"))
        .unwrap_or_default();
    let _ = writeln!(
        s,
        "#SBATCH --array=0-{}{throttle}",
        shards.saturating_sub(1)
    );
    let _ = writeln!(s, "#SBATCH --cpus-per-task={}", resources.cpus_per_task);
    let _ = writeln!(s, "#SBATCH --mem={}M", resources.mem_mib);
    let _ = writeln!(s, "#SBATCH --time={}", resources.time_minutes);
    if let Some(p) = &resources.partition {
        let _ = writeln!(s, "#SBATCH --partition={p}");
    }
    let _ = writeln!(
        s,
        "#SBATCH --output={}",
        quote(&format!("{out_s}/logs/shard-%a.out"))
    );
    let _ = writeln!(s, "set -euo pipefail");
    let _ = writeln!(
        s,
        "exec {} campaign run {} --controller {controller} --shard \"${{SLURM_ARRAY_TASK_ID}}/{shards}\" --jobs \"${{SLURM_CPUS_PER_TASK:-1}}\" --out {}",
        quote(&binary.display().to_string()),
        quote(&campaign.display().to_string()),
        quote(&out_s)
    );
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_script_is_an_array_of_one_task_per_shard() {
        let s = sbatch_script(&ArrayJob {
            name: "grid",
            shards: 8,
            resources: &SlurmResources {
                max_parallel: Some(4),
                partition: Some("cpu".into()),
                ..SlurmResources::default()
            },
            binary: Path::new("/opt/atmo sim/atmo-sim"),
            campaign: Path::new("/c/grid.toml"),
            controller: "nominal",
            out: Path::new("/scratch/grid"),
        });
        assert!(s.contains("#SBATCH --array=0-7%4\n"), "{s}");
        assert!(s.contains("#SBATCH --partition=cpu\n"));
        assert!(s.contains("'/opt/atmo sim/atmo-sim' campaign run '/c/grid.toml' --controller nominal --shard \"${SLURM_ARRAY_TASK_ID}/8\""));
        assert!(s.contains("--out '/scratch/grid'\n"), "{s}");
    }
}
