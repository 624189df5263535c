//! Campaign shards merge into the report one process gives, whatever the
//! shard count and order; a missing, repeated or foreign shard is refused
//! by name; a sweep's cells fly the cell's conditions.

#![allow(clippy::unwrap_used)]

use std::path::PathBuf;

use atmo_sim::campaign::shard::{self, BuildIdentity, MergeError, ShardFile, ShardSpec};
use atmo_sim::campaign::{CampaignFile, Plan};
use atmo_sim::closed_loop::{ControllerConfig, ControllerPreset};
use atmo_sim::monte_carlo;
use atmo_sim::scenario::Scenario;

fn wheel_landing() -> Scenario {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../config/scenarios");
    Scenario::load(root.join("wheel_landing.toml")).unwrap()
}

fn controller() -> ControllerConfig {
    ControllerConfig::atmo().unwrap().deterministic()
}

fn build() -> BuildIdentity {
    BuildIdentity::of(b"this test", "its config")
}

fn fly_shards(plan: &Plan, scenario: &Scenario, count: usize) -> Vec<(PathBuf, ShardFile)> {
    (0..count)
        .map(|index| {
            let spec = ShardSpec { index, count };
            let file =
                shard::fly_shard(plan, scenario, &controller(), spec, 2, build(), &|_, _| {});
            (PathBuf::from(spec.file_name()), file)
        })
        .collect()
}

/// Through JSON, as a shard file goes from a node to the merge.
fn through_json(shards: Vec<(PathBuf, ShardFile)>) -> Vec<(PathBuf, ShardFile)> {
    shards
        .into_iter()
        .map(|(p, s)| {
            let text = serde_json::to_string_pretty(&s).unwrap();
            (p, serde_json::from_str(&text).unwrap())
        })
        .collect()
}

#[test]
fn shards_in_any_number_and_order_merge_into_the_single_process_report() {
    let scenario = wheel_landing();
    let (runs, seed) = (7, 930_001);
    let single = monte_carlo::run(&scenario, &controller(), runs, seed, 2, &|_| {});
    let expected = serde_json::to_string_pretty(&single).unwrap();
    let plan = Plan::monte_carlo(&scenario, ControllerPreset::Config, runs, seed);
    for count in [1, 3] {
        let mut shards = through_json(fly_shards(&plan, &scenario, count));
        shards.reverse();
        let merged = shard::merge(shards).unwrap();
        assert_eq!(merged.cells.len(), 1);
        assert_eq!(
            serde_json::to_string_pretty(&merged.cells[0]).unwrap(),
            expected,
            "{count} shards"
        );
    }
}

#[test]
fn a_missing_repeated_or_foreign_shard_is_refused_by_name() {
    let scenario = wheel_landing();
    let plan = Plan::monte_carlo(&scenario, ControllerPreset::Config, 3, 940_001);
    let shards = fly_shards(&plan, &scenario, 3);

    let missing = shard::merge(vec![shards[0].clone(), shards[2].clone()]).unwrap_err();
    assert!(matches!(missing, MergeError::Missing { .. }), "{missing}");
    assert!(missing.to_string().contains("1/3"), "{missing}");

    let twice = shard::merge(vec![
        shards[0].clone(),
        shards[1].clone(),
        shards[1].clone(),
    ])
    .unwrap_err();
    assert!(matches!(twice, MergeError::Duplicate { .. }), "{twice}");
    assert!(
        twice.to_string().contains("shard-00001-of-00003.json"),
        "{twice}"
    );

    let mut other_build = shards.clone();
    other_build[2].1.build = BuildIdentity::of(b"another binary", "its config");
    let err = shard::merge(other_build).unwrap_err();
    assert!(
        matches!(err, MergeError::Build { what: "binary", .. }),
        "{err}"
    );
    assert!(
        err.to_string().contains("shard-00002-of-00003.json"),
        "{err}"
    );

    let mut other_config = shards.clone();
    other_config[1].1.build = BuildIdentity::of(b"this test", "another config");
    let err = shard::merge(other_config).unwrap_err();
    assert!(
        matches!(
            err,
            MergeError::Build {
                what: "configuration",
                ..
            }
        ),
        "{err}"
    );

    let mut other_seed = shards.clone();
    other_seed[1].1.plan.base_seed += 1;
    let err = shard::merge(other_seed).unwrap_err();
    assert!(err.to_string().contains("base seed"), "{err}");

    let mut lost_run = shards;
    lost_run[0].1.runs.pop();
    let err = shard::merge(lost_run).unwrap_err();
    assert!(matches!(err, MergeError::IncompleteShard { .. }), "{err}");
}

#[test]
fn a_run_past_its_time_limit_is_recorded_with_its_seed_not_lost() {
    let scenario = wheel_landing();
    let record = monte_carlo::fly_run(
        &scenario,
        &controller(),
        950_001,
        4,
        std::time::Duration::ZERO,
    );
    assert_eq!(record.seed, 950_005);
    assert!(!record.success && !record.crashed);
    let error = record.error.clone().expect("the run was stopped");
    assert!(error.contains("time limit"), "{error}");
    let report = monte_carlo::report(
        "wheel_landing",
        950_001,
        scenario.file.success,
        vec![record],
    );
    assert_eq!(report.errors, 1);
    assert_eq!(report.failures[0].seed, 950_005);
    assert!(report.failures[0].reason.contains("time limit"));
}

#[test]
fn a_sweep_flies_each_cell_on_the_same_seeds_with_its_own_conditions() {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../config/campaigns");
    let text = format!(
        r#"
name = "weak_and_strong"
scenario = "{}"
runs_per_cell = 2
base_seed = 960001
shards = 2
[[sweep]]
parameter = "thrust_scale"
values = [0.85, 1.1]
"#,
        dir.join("../scenarios/wheel_landing.toml").display()
    );
    let file = CampaignFile::from_toml_str(&text, &dir.join("weak_and_strong.toml")).unwrap();
    let scenario = wheel_landing();
    let plan = Plan::of(&file, &scenario);
    assert_eq!(plan.cells, vec![vec![0.85], vec![1.1]]);
    let weak = plan.cell_scenario(&scenario, 0);
    let strong = plan.cell_scenario(&scenario, 1);
    let k = scenario.robot.rotor.k_thrust;
    assert!((weak.robot.rotor.k_thrust - 0.85 * k).abs() < 1e-12);
    assert!((strong.robot.rotor.k_thrust - 1.1 * k).abs() < 1e-12);
    let merged = shard::merge(through_json(fly_shards(&plan, &scenario, 2))).unwrap();
    let [weak, strong] = [&merged.cells[0], &merged.cells[1]];
    // The same seeds and draws in both cells: only the thrust differs.
    for (w, s) in weak.per_run.iter().zip(&strong.per_run) {
        assert_eq!((w.seed, w.draws), (s.seed, s.draws));
    }
    // A robot 15 % weaker than its file cannot hold its weight as far
    // into the tilt as one 10 % stronger (thrust x cos(tilt) carries the
    // weight): it touches down at a lower tilt, on every seed.
    for (w, s) in weak.per_run.iter().zip(&strong.per_run) {
        let (w, s) = (w.touchdown_tilt_deg.unwrap(), s.touchdown_tilt_deg.unwrap());
        assert!(
            w < s,
            "touchdown tilt {w:.2} deg weak against {s:.2} deg strong"
        );
    }
}
