//! Landing campaigns: Monte Carlo runs swept over conditions, flown in
//! shards on any number of machines and merged exactly (docs/campaigns.md).
//!
//! - [`CampaignFile`]: the TOML a campaign is written in (scenario,
//!   controller, base seed, runs per cell, swept parameters and their grid).
//! - [`Plan`]: the campaign expanded: its cells (one value per swept
//!   parameter) and, for each global run index `g`, its cell `g / runs_per_cell`
//!   and its seed `base_seed + g % runs_per_cell`. Every cell flies the same
//!   seeds (common random numbers), so two cells differ by their parameters
//!   only; a campaign without a sweep is the plain Monte Carlo
//!   (`atmo-sim fly --runs N --seed S`), run for run.
//! - [`shard`]: which runs a shard flies, the partial result it writes, and
//!   the merge that checks coverage and build and gives the reports.
//! - [`slurm`]: the `sbatch` array-job script of a campaign.

pub mod shard;
pub mod slurm;

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::closed_loop::ControllerPreset;
use crate::monte_carlo::{PAST_IMPACT_MPS, PAST_TILT_DEG};
use crate::scenario::{Scenario, SuccessConfig};
use atmo_core::CoreError;
use atmo_plant::config::{ComOffsetConfig, MassErrorConfig};

/// A condition a campaign sweeps. Each is applied to the plant (the truth)
/// before a run's randomization, which then draws around it as in any
/// Monte Carlo; the controller's model never changes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SweepParameter {
    /// The plant's ground-effect gains against its table's (needs a
    /// scenario with a ground effect).
    GroundEffectScale,
    /// The rotors' thrust coefficient against the robot file's.
    ThrustScale,
    /// Mass and inertia against the robot file's.
    MassScale,
    /// A steady wind from the south (along +north), m/s.
    WindNorthMps,
    /// The centre of mass ahead of the body origin (body +x), mm.
    ComOffsetXMm,
}

impl SweepParameter {
    /// The parameter's name and unit, as in a table header or an axis.
    pub fn label(self) -> &'static str {
        match self {
            Self::GroundEffectScale => "ground-effect scale",
            Self::ThrustScale => "thrust scale",
            Self::MassScale => "mass scale",
            Self::WindNorthMps => "steady wind north (m/s)",
            Self::ComOffsetXMm => "CoM offset x (mm)",
        }
    }

    /// The values the parameter may take (beyond them the robot cannot
    /// fly or the plant's models do not hold).
    fn range(self) -> std::ops::RangeInclusive<f64> {
        match self {
            Self::GroundEffectScale => 0.0..=3.0,
            Self::ThrustScale | Self::MassScale => 0.5..=1.5,
            Self::WindNorthMps => -15.0..=15.0,
            Self::ComOffsetXMm => -50.0..=50.0,
        }
    }

    /// `scenario` with the parameter at `value`.
    fn apply(self, scenario: &mut Scenario, value: f64) {
        let fx = &mut scenario.plant.effects;
        match self {
            Self::GroundEffectScale => {
                if let Some(ge) = fx.ground_effect.as_mut() {
                    *ge = ge.perturbed(value, 0.0);
                }
            }
            Self::ThrustScale => scenario.robot.rotor.k_thrust *= value,
            Self::MassScale => {
                let mass = fx.mass_error.get_or_insert(MassErrorConfig {
                    enabled: true,
                    mass_scale: 1.0,
                    inertia_scale: 1.0,
                });
                mass.enabled = true;
                mass.mass_scale *= value;
                mass.inertia_scale *= value;
            }
            Self::WindNorthMps => {
                let wind = fx.wind.get_or_insert_with(Default::default);
                wind.enabled = true;
                wind.steady[0] += value;
            }
            Self::ComOffsetXMm => {
                let com = fx.com_offset.get_or_insert(ComOffsetConfig {
                    enabled: true,
                    offset: [0.0; 3],
                });
                com.enabled = true;
                com.offset[0] += value * 1e-3;
            }
        }
    }
}

atmo_core::params! {
    /// One swept parameter and its grid: `values`, or `from`, `to` and `steps`
    /// (evenly spaced, both ends included).
    #[derive(Debug, Clone, PartialEq)]
    pub struct SweepAxis {
        /// What is swept.
        pub parameter: SweepParameter;
        /// The grid as a list (1 to 1000 values).
        pub values: Option<Vec<f64>> = None;
        /// Or: the first value,
        pub from: Option<f64> = None;
        /// the last,
        pub to: Option<f64> = None;
        /// and how many (2 to 1000).
        pub steps: Option<usize> = None;
    }
}

atmo_core::params! {
    /// The wheel-landing target a campaign counts per cell.
    #[derive(Debug, Clone, Copy, PartialEq, Serialize)]
    pub struct Target {
        /// Least touchdown tilt.
        pub touchdown_tilt_min_deg: f64, range 0.0..=90.0, unit "deg";
        /// Largest impact speed.
        pub impact_speed_max_mps: f64, range 0.0..=10.0, unit "m/s";
    }
}

/// A file without `[target]`: the wheel-landing target. A `[target]` table
/// gives both keys.
impl Default for Target {
    fn default() -> Self {
        Self {
            touchdown_tilt_min_deg: PAST_TILT_DEG,
            impact_speed_max_mps: PAST_IMPACT_MPS,
        }
    }
}

atmo_core::params! {
    /// A campaign file (TOML; examples in config/campaigns/).
    #[derive(Debug, Clone, PartialEq)]
    pub struct CampaignFile {
        /// Names the campaign's outputs (a folder name).
        pub name: String;
        /// Scenario file, relative to the campaign file.
        pub scenario: PathBuf;
        /// The controller every run flies.
        pub controller: ControllerPreset = ControllerPreset::Config;
        /// Seed of run 0 of every cell.
        pub base_seed: u64 = 1;
        /// Runs per cell.
        pub runs_per_cell: usize, range 1..=100_000;
        /// How many shards `campaign plan` and `campaign slurm` split it into.
        pub shards: usize = 1, range 1..=10_000;
        /// The target counted per cell.
        pub target: Target = Target::default();
        /// Each run's wall-clock budget.
        pub run_time_limit_s: f64 = crate::monte_carlo::RUN_TIME_LIMIT.as_secs_f64(),
            range 1.0..=86_400.0, unit "s";
        /// At most two axes for the map; more give the table only.
        pub sweep: Vec<SweepAxis> = Vec::new();
        /// `sbatch` resources of each array task.
        pub slurm: slurm::SlurmResources = slurm::SlurmResources::default();
    }
}

impl CampaignFile {
    /// Reads and checks `path`; every error names the file and the key.
    pub fn load(path: &Path) -> Result<Self, CoreError> {
        Self::from_toml_str(&atmo_core::config_file::read_config_file(path)?, path)
    }

    /// Parses and checks a campaign text (`path` names it in errors).
    pub fn from_toml_str(text: &str, path: &Path) -> Result<Self, CoreError> {
        let file: Self = atmo_core::config_file::parse_toml(text, path)?;
        // `message`: "<what was given>: <what is expected>".
        let checker = atmo_core::config_file::Checker::new(path);
        let bad = |key: &str, message: String| {
            let (got, expected) = message.split_once(": ").unwrap_or(("", &message));
            checker.fail(key, expected, got)
        };
        if file.name.is_empty() || file.name.contains(['/', '\\']) || file.name.starts_with('.') {
            return Err(bad("name", format!("{:?}: a folder name", file.name)));
        }
        atmo_core::params::check_file(&file, path)?;
        let mut seen = Vec::new();
        for (i, axis) in file.sweep.iter().enumerate() {
            let key = |k: &str| format!("sweep[{i}].{k}");
            if seen.contains(&axis.parameter) {
                return Err(bad(
                    &key("parameter"),
                    format!("{:?} again: each parameter swept once", axis.parameter),
                ));
            }
            seen.push(axis.parameter);
            let values = axis.grid().map_err(|(k, m)| bad(&key(k), m))?;
            let range = axis.parameter.range();
            if let Some(v) = values
                .iter()
                .find(|v| !(v.is_finite() && range.contains(v)))
            {
                return Err(bad(
                    &key("values"),
                    format!(
                        "{v}: {} to {} for {}",
                        range.start(),
                        range.end(),
                        axis.parameter.label()
                    ),
                ));
            }
            // Two equal values fly one cell twice and leave the map a
            // column short of its cells.
            let mut sorted = values.clone();
            sorted.sort_by(f64::total_cmp);
            if let Some(twice) = sorted
                .windows(2)
                .find_map(|w| (w[0] == w[1]).then_some(w[0]))
            {
                let at = if axis.values.is_some() {
                    "values"
                } else {
                    "to"
                };
                return Err(bad(
                    &key(at),
                    format!("{twice} twice: each value of a sweep once"),
                ));
            }
        }
        let cells: usize = file
            .sweep
            .iter()
            .map(|a| a.grid().map_or(0, |v| v.len()))
            .product();
        if cells.saturating_mul(file.runs_per_cell) > 10_000_000 {
            return Err(bad(
                "runs_per_cell",
                format!(
                    "{cells} cells x {} runs: at most 10^7 runs in all",
                    file.runs_per_cell
                ),
            ));
        }
        Ok(file)
    }
}

impl SweepAxis {
    /// The grid's values, or the key at fault and why.
    fn grid(&self) -> Result<Vec<f64>, (&'static str, String)> {
        match (&self.values, self.from, self.to, self.steps) {
            (Some(v), None, None, None) if !v.is_empty() && v.len() <= 1000 => Ok(v.clone()),
            (Some(v), None, None, None) => {
                Err(("values", format!("{} values: 1 to 1000 values", v.len())))
            }
            (None, Some(a), Some(b), Some(n)) if (2..=1000).contains(&n) => Ok((0..n)
                .map(|k| a + (b - a) * k as f64 / (n - 1) as f64)
                .collect()),
            (None, Some(_), Some(_), Some(n)) => Err(("steps", format!("{n}: 2 to 1000 steps"))),
            _ => Err((
                "values",
                "neither or both forms: either `values` or `from`, `to` and `steps`".to_string(),
            )),
        }
    }
}

/// A campaign expanded: what every run flies. Stored in each shard, so
/// that the merge can tell shards of different campaigns apart.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Plan {
    pub name: String,
    /// The scenario's own name and criteria.
    pub scenario: String,
    pub success: SuccessConfig,
    pub controller: ControllerPreset,
    pub base_seed: u64,
    pub runs_per_cell: usize,
    pub target: Target,
    pub run_time_limit_s: f64,
    pub parameters: Vec<SweepParameter>,
    /// One value per parameter, the last parameter varying fastest.
    pub cells: Vec<Vec<f64>>,
}

impl Plan {
    /// The campaign `file` on `scenario`.
    pub fn of(file: &CampaignFile, scenario: &Scenario) -> Self {
        let grids: Vec<Vec<f64>> = file
            .sweep
            .iter()
            .map(|a| a.grid().unwrap_or_default())
            .collect();
        let mut cells = vec![Vec::new()];
        for grid in &grids {
            cells = cells
                .into_iter()
                .flat_map(|cell| {
                    grid.iter().map(move |v| {
                        let mut c = cell.clone();
                        c.push(*v);
                        c
                    })
                })
                .collect();
        }
        Self {
            name: file.name.clone(),
            scenario: scenario.file.name.clone(),
            success: scenario.file.success,
            controller: file.controller,
            base_seed: file.base_seed,
            runs_per_cell: file.runs_per_cell,
            target: file.target,
            run_time_limit_s: file.run_time_limit_s,
            parameters: file.sweep.iter().map(|a| a.parameter).collect(),
            cells,
        }
    }

    /// The plain Monte Carlo `--runs runs --seed base_seed` of `scenario`.
    pub fn monte_carlo(
        scenario: &Scenario,
        controller: ControllerPreset,
        runs: usize,
        base_seed: u64,
    ) -> Self {
        Self {
            name: scenario.file.name.clone(),
            scenario: scenario.file.name.clone(),
            success: scenario.file.success,
            controller,
            base_seed,
            runs_per_cell: runs,
            target: Target::default(),
            run_time_limit_s: crate::monte_carlo::RUN_TIME_LIMIT.as_secs_f64(),
            parameters: Vec::new(),
            cells: vec![Vec::new()],
        }
    }

    /// Runs over all cells.
    pub fn total_runs(&self) -> usize {
        self.cells.len() * self.runs_per_cell
    }

    /// The cell of global run `g` and its index within the cell.
    pub fn locate(&self, g: usize) -> (usize, usize) {
        (g / self.runs_per_cell, g % self.runs_per_cell)
    }

    /// The scenario cell `cell` flies: `base` with the cell's parameters.
    pub fn cell_scenario(&self, base: &Scenario, cell: usize) -> Scenario {
        let mut s = base.clone();
        for (p, v) in self.parameters.iter().zip(&self.cells[cell]) {
            p.apply(&mut s, *v);
        }
        s
    }

    /// The cell's parameters in words ("thrust scale = 0.96, ...").
    pub fn describe_cell(&self, cell: usize) -> String {
        self.parameters
            .iter()
            .zip(&self.cells[cell])
            .map(|(p, v)| format!("{} = {v}", p.label()))
            .collect::<Vec<_>>()
            .join(", ")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const FILE: &str = r#"
name = "grid"
scenario = "../scenarios/wheel_landing.toml"
runs_per_cell = 3
shards = 4
[[sweep]]
parameter = "thrust_scale"
values = [0.9, 1.0]
[[sweep]]
parameter = "ground_effect_scale"
from = 0.5
to = 1.5
steps = 3
"#;

    #[test]
    fn the_grid_expands_last_parameter_fastest() {
        let f = CampaignFile::from_toml_str(FILE, Path::new("c.toml")).unwrap();
        let grids: Vec<Vec<f64>> = f.sweep.iter().map(|a| a.grid().unwrap()).collect();
        assert_eq!(grids[1], vec![0.5, 1.0, 1.5]);
    }

    #[test]
    fn bad_campaigns_name_the_key() {
        let cases = [
            (
                FILE.replace("runs_per_cell = 3", "runs_per_cell = 0"),
                "runs_per_cell",
            ),
            (
                FILE.replace("values = [0.9, 1.0]", "values = [0.9, 9.0]"),
                "sweep[0].values",
            ),
            (
                FILE.replace("values = [0.9, 1.0]", "values = []"),
                "sweep[0].values",
            ),
            (FILE.replace("steps = 3", "steps = 1"), "sweep[1].steps"),
            (
                FILE.replace("values = [0.9, 1.0]", "values = [1.0, 0.9, 1.0]"),
                "sweep[0].values",
            ),
            (FILE.replace("to = 1.5", "to = 0.5"), "sweep[1].to"),
            (
                FILE.replace("\"ground_effect_scale\"", "\"thrust_scale\""),
                "sweep[1].parameter",
            ),
            (FILE.replace("shards = 4", "shards = 0"), "shards"),
            (FILE.replace("name = \"grid\"", "name = \"../x\""), "name"),
            (FILE.replace("shards = 4", "shards = 4\nspeed = 3"), "speed"),
            (
                format!("{FILE}\n[target]\ntouchdown_tilt_min_deg = 64.0\n"),
                "impact_speed_max_mps",
            ),
            (format!("{FILE}\n[slurm]\nmem_mib = 10\n"), "slurm.mem_mib"),
        ];
        for (text, key) in cases {
            let err = CampaignFile::from_toml_str(&text, Path::new("c.toml"))
                .unwrap_err()
                .to_string();
            assert!(err.contains(key) && err.contains("c.toml"), "{key}: {err}");
        }
        // A value out of range as the other keys give it: 1e300, not its
        // 301 digits.
        let err = CampaignFile::from_toml_str(
            &FILE.replace("values = [0.9, 1.0]", "values = [0.9, 1e300]"),
            Path::new("c.toml"),
        )
        .unwrap_err()
        .to_string();
        assert!(err.ends_with("got 1e300"), "{err}");
    }
}
