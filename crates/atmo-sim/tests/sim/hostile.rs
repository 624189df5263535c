//! Valid-looking inputs that used to fail late: refused at load naming the
//! file and the key, or carried through to complete outputs.
#![allow(clippy::unwrap_used, reason = "test")]

use std::path::{Path, PathBuf};

use atmo_core::ConfigFile;
use atmo_plant::config::PlantConfig;
use atmo_sim::Scenario;
use atmo_sim::closed_loop::{ControllerConfig, fly_logged};

const PLANT: &str = include_str!("../../../../config/plant.toml");
const SCENARIO: &str = include_str!("../../../../config/scenarios/wheel_landing.toml");

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn scratch(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join("hostile")
        .join(name);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// A scenario starting underground (z = +5, NED) or at 1e6 m/s passed
/// validation and failed in the figure naming neither file nor key.
#[test]
fn a_scenario_underground_or_at_absurd_speed_is_refused_naming_file_and_key() {
    let path = repo().join("config/scenarios/bad_start.toml");
    for (from, to, key) in [
        (
            "position = [0.0, 0.0, -1.5]",
            "position = [0.0, 0.0, 5.0]",
            "initial.position[2]",
        ),
        (
            "velocity = [0.4, 0.0, 0.0]      # m/s",
            "velocity = [1e6, 0.0, 0.0]      # m/s",
            "initial.velocity[0]",
        ),
        (
            "position = [0.0, 0.0, -1.5]",
            "position = [1e300, 0.0, -1.5]",
            "initial.position[0]",
        ),
    ] {
        assert!(SCENARIO.contains(from), "{from}");
        let err = Scenario::from_toml_str(&SCENARIO.replacen(from, to, 1), &path)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("bad_start.toml") && err.contains(&format!("`{key}`")),
            "{to}: {err}"
        );
    }
}

/// A contact stiffness of 1e12 N/m was accepted and reported an impact of
/// -1.5e10 m/s: refused naming the file and the key.
#[test]
fn a_contact_stiffness_the_step_cannot_resolve_is_refused() {
    for (from, to, key) in [
        (
            "stiffness = 20000.0",
            "stiffness = 1e12",
            "effects.ground_contact.stiffness",
        ),
        (
            "tangential_stiffness = 5000.0",
            "tangential_stiffness = 1e12",
            "effects.ground_contact.tangential_stiffness",
        ),
    ] {
        assert!(PLANT.contains(from));
        let err = PlantConfig::from_toml_str(&PLANT.replacen(from, to, 1), "plants/stiff.toml")
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("plants/stiff.toml") && err.contains(&format!("`{key}`")),
            "{err}"
        );
    }
}

/// At the plant's smallest documented step (1 us) the truth topic gets a
/// record per step, a million per simulated second, and the logger's queue
/// dropped 1.3 M of them: the simulation now waits for the writer, and
/// every step's record is in the log.
#[test]
fn the_smallest_plant_step_logs_every_record() {
    let mut scenario = Scenario::load(repo().join("config/scenarios/hover.toml")).unwrap();
    scenario.plant.dt = 1e-6;
    scenario.file.duration = 0.2;
    let controller = ControllerConfig::atmo().unwrap().deterministic();
    let path = scratch("smallest_dt").join("flight.mcap");
    let (_, written) = fly_logged(&scenario, &controller, &path, |_| {}).unwrap();
    assert_eq!(written.dropped, 0);
    let truth = atmo_io::mcap_log::read_topic::<atmo_io::msg::SimTruth>(
        &path,
        atmo_sim::closed_loop::TRUTH_TOPIC,
    )
    .unwrap();
    // The initial state and one record per step.
    assert!(truth.len() >= 200_000, "{}", truth.len());
}

/// `fly hover.toml --runs 2` printed "2/2 successful", then failed on the
/// figure ("no touchdown to plot") and discarded monte_carlo.json: the
/// results are written, and the touchdown figure skipped with a line
/// saying so.
#[test]
fn a_monte_carlo_without_touchdowns_writes_its_results() {
    let out = scratch("hover_runs");
    let output = std::process::Command::new(env!("CARGO_BIN_EXE_atmo-sim"))
        .current_dir(repo())
        .args(["fly", "config/scenarios/hover.toml", "--runs", "2", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&output.stdout);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(output.status.success(), "{stdout}\n{stderr}");
    assert!(
        stdout.contains("none (no run touched down): touchdown.png not drawn"),
        "{stdout}"
    );
    let report = std::fs::read_to_string(out.join("hover/monte_carlo.json")).unwrap();
    let json: serde_json::Value = serde_json::from_str(&report).unwrap();
    assert_eq!(json["runs"], 2, "{json}");
    assert!(!out.join("hover/touchdown.png").exists());
}

/// `atmo-sim physics | head` panicked in println! once `head` had gone: a
/// command that only prints ends by SIGPIPE, as a C tool does.
#[cfg(unix)]
#[test]
fn a_command_ends_quietly_when_its_reader_is_gone() {
    let mut physics = std::process::Command::new(env!("CARGO_BIN_EXE_atmo-sim"));
    physics.current_dir(repo()).arg("physics");
    atmo_core::closed_stdout::ends_by_sigpipe(&mut physics).unwrap();
}

/// `campaign plan --out FILE` said only "File exists (os error 17)", and a
/// campaign, a shard or the SITL server wrote into any folder it was
/// given, through a symbolic link too. Every command that adds to a
/// shared output folder refuses a file, a symbolic link and a folder this
/// tool did not write, names it, and writes nothing.
#[cfg(unix)]
#[test]
fn a_shared_output_folder_that_is_not_ours_is_refused_and_nothing_is_written() {
    let root = scratch("shared_out");
    let file = root.join("notes.txt");
    std::fs::write(&file, b"keep me").unwrap();
    let theirs = root.join("theirs");
    std::fs::create_dir_all(theirs.join("wheel_landing")).unwrap();
    std::fs::write(theirs.join("wheel_landing/data.csv"), b"keep me").unwrap();
    let link = root.join("link");
    std::os::unix::fs::symlink(&theirs, &link).unwrap();
    let before = walk(&root);
    let refused = |args: &[&str], what: &str| {
        let output = std::process::Command::new(env!("CARGO_BIN_EXE_atmo-sim"))
            .current_dir(repo())
            .env("RUST_BACKTRACE", "0")
            .args(args)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert!(!output.status.success(), "{args:?} accepted");
        assert!(
            stderr.contains(what) && stderr.contains("nothing was written or moved"),
            "{args:?}: {stderr}"
        );
    };
    let campaign = "config/campaigns/ground_effect_x_thrust.toml";
    for (target, what) in [
        (&file, "a file"),
        (&theirs, "a folder this tool did not write"),
        (&link, "a symbolic link"),
    ] {
        let t = target.to_str().unwrap();
        refused(&["campaign", "plan", campaign, "--out", t], what);
        refused(
            &["campaign", "run", campaign, "--shard", "0/8", "--out", t],
            what,
        );
        refused(&["campaign", "merge", "no/such/shards", "--out", t], what);
        refused(&["campaign", "slurm", campaign, "--out", t], what);
        refused(&["serve", "--quiet", "--out", t], what);
    }
    // `fly --shard` adds to OUT/<scenario name>: here theirs/wheel_landing.
    refused(
        &[
            "fly",
            "--runs",
            "2",
            "--shard",
            "0/2",
            "--out",
            theirs.to_str().unwrap(),
        ],
        "a folder this tool did not write",
    );
    assert_eq!(walk(&root), before, "nothing written or moved");
    assert_eq!(std::fs::read(&file).unwrap(), b"keep me");
}

/// Every path under `dir` (symbolic links not followed), sorted.
fn walk(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if std::fs::symlink_metadata(&path).unwrap().is_dir() {
            out.extend(walk(&path));
        }
        out.push(path);
    }
    out.sort();
    out
}
