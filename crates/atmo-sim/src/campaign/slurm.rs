//! The `sbatch` array-job script of a campaign: one array task per shard.

use std::fmt::Write as _;
use std::path::Path;

atmo_core::params! {
    /// `[slurm]` of a campaign file: what each array task asks for.
    #[derive(Debug, Clone, PartialEq)]
    pub struct SlurmResources: Default {
        /// Cores per task (the shard's threads).
        pub cpus_per_task: usize = 1, range 1..=1024;
        /// Memory per task.
        pub mem_mib: usize = 1024, range 64..=(4 << 20), unit "MiB";
        /// Wall-clock limit per task.
        pub time_minutes: usize = 60, range 1..=43_200, unit "min";
        /// Partition (none: the cluster's default): letters, digits, `_ - .`.
        pub partition: Option<String> = None;
        /// At most this many tasks at once (none: as many as fit).
        pub max_parallel: Option<usize> = None, range 1..=usize::MAX;
    }
    check |slurm, c, prefix| {
        match &slurm.partition {
            Some(p)
                if p.is_empty()
                    || !p
                        .chars()
                        .all(|ch| ch.is_ascii_alphanumeric() || "_-.".contains(ch)) =>
            {
                Err(c.fail(
                    &atmo_core::params::key(prefix, "partition"),
                    "letters, digits, _ - .",
                    format!("{p:?}"),
                ))
            }
            _ => Ok(()),
        }
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
