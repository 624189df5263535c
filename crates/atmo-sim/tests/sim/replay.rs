//! A simulated landing's flight log replays through a rebuilt
//! flight stack bit for bit; a changed MPC weight is reported at its first
//! differing tick and field; a log cut mid-flight (after `recover`) replays
//! to its last complete tick; a missing or damaged inputs channel is an
//! error naming it; `atmo-mcap summary`'s review of the log reproduces the
//! landing's summary.json values exactly.
// Test, bench and example code: an unwrap that fails is the failure report.
#![allow(clippy::unwrap_used)]

use std::borrow::Cow;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use atmo_flight::flight_log::INPUTS_TOPIC;
use atmo_flight::replay::{CutReplay, RecordedFlight, replay};
use atmo_mpc::settings::GroundEffectSource;
use atmo_sim::closed_loop::{ControllerConfig, STATUS_TOPIC, Summary, fly_logged};
use atmo_sim::scenario::Scenario;

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// Written apart from `target/tmp/atmo-io-interop` (the Python reference
/// reader's folder, whose logs need an `.expected.json` each).
fn dir() -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("sim-replay");
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// The README landing (`atmo-sim fly`, deterministic controller), flown once
/// per test process: its log and summary.
fn landing() -> &'static (PathBuf, Summary) {
    static LANDING: OnceLock<(PathBuf, Summary)> = OnceLock::new();
    LANDING.get_or_init(|| {
        let scenario = Scenario::load(repo().join("config/scenarios/wheel_landing.toml")).unwrap();
        let controller = ControllerConfig::atmo().unwrap().deterministic();
        let path = dir().join("wheel_landing.mcap");
        let (summary, _) = fly_logged(&scenario, &controller, &path, |_| {}).unwrap();
        (path, summary)
    })
}

#[test]
fn a_simulated_landing_replays_bit_for_bit() {
    let (log, _) = landing();
    let flight = RecordedFlight::read(log, STATUS_TOPIC).unwrap();
    assert_eq!(flight.incomplete_tail, (0, 0));
    // A log records the schema it was written with: nothing to migrate.
    assert_eq!(
        flight.files.schema_version,
        atmo_flight::schema::CONFIG_SCHEMA_VERSION
    );
    assert!(flight.files.migrated.is_empty());
    let config = RecordedFlight::config(&flight.files).unwrap();
    let mut compared = 0;
    let report = replay(&flight, &config, CutReplay::AsLogged, |_| compared += 1).unwrap();
    assert_eq!(report.first_difference, None, "{report:?}");
    assert_eq!(report.differing_ticks, 0);
    // 14 s at 150 Hz: every tick of the flight.
    assert_eq!(report.ticks, 2100);
    assert_eq!(compared, 2100);
}

#[test]
fn one_changed_mpc_weight_reports_the_first_differing_tick_and_field() {
    let (log, _) = landing();
    let flight = RecordedFlight::read(log, STATUS_TOPIC).unwrap();
    let mut files = flight.files.clone();
    // The fig5 preset's q1 weight on z, 1.0 -> 2.0.
    let before = "q1 = [1.0, 1.0, 1.0, 10.0, 10.0, 20.0,";
    assert!(files.mpc.text.contains(before));
    files.mpc.text = files
        .mpc
        .text
        .replacen(before, "q1 = [1.0, 1.0, 2.0, 10.0, 10.0, 20.0,", 1);
    let report = replay(
        &flight,
        &RecordedFlight::config(&files).unwrap(),
        CutReplay::None,
        |_| {},
    )
    .unwrap();
    let first = report.first_difference.clone().expect("a difference");
    // The stack flies from the first tick: the weight shows at once, in the
    // first compared output, the first thruster command.
    assert_eq!(first.tick, 0, "{first}");
    assert_eq!(first.field, "thrust[0]", "{first}");
    assert!(!first.logged.identical(&first.replayed));
    assert!(report.differing_ticks > 0 && report.differing_ticks <= report.ticks);
    let text = first.to_string();
    assert!(
        text.contains("tick 0") && text.contains("thrust[0]"),
        "{text}"
    );
}

#[test]
fn a_slope_landing_logs_the_ground_normal_and_replays_bit_for_bit() {
    // The ground plane's normal is a tick input, logged with it.
    let scenario =
        Scenario::load(repo().join("config/scenarios/landing_slope_25deg.toml")).unwrap();
    let controller = ControllerConfig::atmo().unwrap().deterministic();
    let path = dir().join("landing_slope_25deg.mcap");
    fly_logged(&scenario, &controller, &path, |_| {}).unwrap();
    let mut flight = RecordedFlight::read(&path, STATUS_TOPIC).unwrap();
    let s = 25f64.to_radians();
    let with_normal: Vec<_> = flight
        .inputs
        .iter()
        .filter(|i| i.has_ground_normal)
        .collect();
    assert!(with_normal.len() > 1000, "{}", with_normal.len());
    for i in with_normal {
        let n = i.ground_normal;
        assert!(
            (n[0] + s.sin()).abs() < 1e-12 && n[1].abs() < 1e-12 && (n[2] + s.cos()).abs() < 1e-12,
            "{n:?}"
        );
    }
    let config = RecordedFlight::config(&flight.files).unwrap();
    let report = replay(&flight, &config, CutReplay::AsLogged, |_| {}).unwrap();
    assert_eq!(report.first_difference, None, "{report:?}");
    // Without the normal (as a log before it would read) the ground is
    // level and the flare's clearance differs: the replay tells.
    for i in &mut flight.inputs {
        i.has_ground_normal = false;
    }
    let level = replay(&flight, &config, CutReplay::AsLogged, |_| {}).unwrap();
    assert!(level.first_difference.is_some(), "{level:?}");
}

#[test]
fn a_log_cut_mid_flight_replays_to_its_last_complete_tick() {
    let (log, _) = landing();
    let bytes = std::fs::read(log).unwrap();
    let cut = dir().join("cut.mcap");
    // A writer killed half-way (no summary, no footer, half a chunk).
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    let recovered = dir().join("cut_recovered.mcap");
    let rec = atmo_io::mcap_log::recover(&cut, &recovered).unwrap();
    assert!(rec.stopped_by.is_some(), "the cut log is truncated");
    let flight = RecordedFlight::read(&recovered, STATUS_TOPIC).unwrap();
    let status: Vec<(u64, atmo_io::msg::MpcStatus)> =
        atmo_io::mcap_log::read_topic(&recovered, STATUS_TOPIC).unwrap();
    let ticks = flight.inputs.len();
    assert!(ticks > 100 && ticks < 2100, "{ticks} ticks kept");
    // The last complete tick: the last one whose status survived (its
    // inputs are logged just before it).
    assert_eq!(ticks, status.len());
    let report = replay(
        &flight,
        &RecordedFlight::config(&flight.files).unwrap(),
        CutReplay::AsLogged,
        |_| {},
    )
    .unwrap();
    assert_eq!(report.ticks, ticks);
    assert_eq!(report.first_difference, None, "{report:?}");
}

/// A flight whose solves the wall-clock time limit cut (10 us, the
/// settings' minimum: shorter than one interior-point iteration of the
/// MPC's QP, so every Clarabel solve is cut) replays bit for bit: the log
/// records each cut solve's iteration and the replay ends the same solves
/// there. (Whether a replay without the cuts would differ depends on the
/// machine: a cut preparation solve only seeds the homotopy, which reaches
/// the same exact solution.)
#[test]
fn a_flight_with_solves_cut_by_the_time_limit_replays_bit_for_bit() {
    let mut scenario = Scenario::load(repo().join("config/scenarios/wheel_landing.toml")).unwrap();
    scenario.file.duration = 3.0;
    let mut controller = ControllerConfig::atmo().unwrap();
    controller.mpc.solver.time_limit = 1e-5;
    let path = dir().join("time_limited.mcap");
    fly_logged(&scenario, &controller, &path, |_| {}).unwrap();
    let flight = RecordedFlight::read(&path, STATUS_TOPIC).unwrap();
    let cut: usize = flight
        .inputs
        .iter()
        .map(|m| usize::from(m.solver_cut_count))
        .sum();
    assert!(cut > 0, "no solve was cut: the test tests nothing");
    let config = RecordedFlight::config(&flight.files).unwrap();
    let report = replay(&flight, &config, CutReplay::AsLogged, |_| {}).unwrap();
    println!(
        "{} ticks, {cut} solves cut in flight, {} cut again",
        report.ticks, report.cuts_replayed
    );
    assert_eq!(report.first_difference, None, "{report:?}");
    assert_eq!(report.cuts_replayed, cut);
    assert_eq!(report.cut_overflow_ticks, 0);
}

/// The MPC predicting with a plant file's ground-effect surface: the file's
/// text is logged (`config/ground_effect`), and the replay builds the MPC
/// from that text, not from the file (deleted before the replay); a
/// what-if with a changed surface file differs.
#[test]
fn a_ground_effect_file_is_logged_and_replayed_from_the_log() {
    let scenario = Scenario::load(repo().join("config/scenarios/wheel_landing.toml")).unwrap();
    let surface = dir().join("surface.toml");
    let shipped = std::fs::read_to_string(repo().join("config/plant.toml")).unwrap();
    std::fs::write(&surface, &shipped).unwrap();
    // The tilt on the paper's law (off in the text too: the log says so).
    let controller = ControllerConfig::atmo()
        .unwrap()
        .deterministic()
        .with_ground_effect(&GroundEffectSource::File(surface.clone()))
        .unwrap()
        .with_tilt_plan(false)
        .unwrap();
    let path = dir().join("ground_effect_file.mcap");
    fly_logged(&scenario, &controller, &path, |_| {}).unwrap();
    std::fs::remove_file(&surface).unwrap();

    let flight = RecordedFlight::read(&path, STATUS_TOPIC).unwrap();
    let logged = flight
        .files
        .ground_effect
        .clone()
        .expect("the surface file is logged");
    assert_eq!(logged.text, shipped);
    assert_eq!(logged.source, surface);
    assert!(
        flight
            .files
            .mpc
            .text
            .contains(&format!("ground_effect = \"{}\"", surface.display()))
    );
    let config = RecordedFlight::config(&flight.files).unwrap();
    assert!(!config.mpc.tilt_plan.unwrap().enabled);
    let report = replay(&flight, &config, CutReplay::AsLogged, |_| {}).unwrap();
    assert_eq!(report.first_difference, None, "{report:?}");

    // What-if: the 60 deg gains doubled (a file of the same name).
    let stronger = dir().join("what_if");
    std::fs::create_dir_all(&stronger).unwrap();
    let row_60_deg = "[0.070, 0.045, 0.025, 0.010, 0.003, 0.0],";
    assert!(shipped.contains(row_60_deg));
    let scaled = shipped.replacen(row_60_deg, "[0.140, 0.090, 0.050, 0.020, 0.006, 0.0],", 1);
    std::fs::write(stronger.join("surface.toml"), scaled).unwrap();
    let mut files = flight.files.clone();
    let replaced = files.override_with(&stronger).unwrap();
    assert_eq!(replaced, [stronger.join("surface.toml")]);
    let what_if = replay(
        &flight,
        &RecordedFlight::config(&files).unwrap(),
        CutReplay::None,
        |_| {},
    )
    .unwrap();
    assert!(what_if.first_difference.is_some(), "{what_if:?}");
}

/// Copies `input` to `output`, passing each message through `edit`
/// (`None` drops it), keeping attachments and metadata.
fn rewrite(input: &Path, output: &Path, edit: impl Fn(&str, &[u8]) -> Option<Vec<u8>>) {
    let bytes = std::fs::read(input).unwrap();
    let mut writer = mcap::WriteOptions::new()
        .profile("ros2")
        .create(std::io::BufWriter::new(
            std::fs::File::create(output).unwrap(),
        ))
        .unwrap();
    let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
    for index in &summary.attachment_indexes {
        let a = mcap::read::attachment(&bytes, index).unwrap();
        writer.attach(&a).unwrap();
    }
    for index in &summary.metadata_indexes {
        writer
            .write_metadata(&mcap::read::metadata(&bytes, index).unwrap())
            .unwrap();
    }
    let mut channels: BTreeMap<u16, u16> = BTreeMap::new();
    for message in mcap::MessageStream::new(&bytes).unwrap() {
        let message = message.unwrap();
        let Some(data) = edit(&message.channel.topic, &message.data) else {
            continue;
        };
        let id = *channels.entry(message.channel.id).or_insert_with(|| {
            let schema = message.channel.schema.as_ref().unwrap();
            let schema_id = writer
                .add_schema(&schema.name, &schema.encoding, &schema.data)
                .unwrap();
            writer
                .add_channel(
                    schema_id,
                    &message.channel.topic,
                    &message.channel.message_encoding,
                    &message.channel.metadata,
                )
                .unwrap()
        });
        writer
            .write_to_known_channel(
                &mcap::records::MessageHeader {
                    channel_id: id,
                    sequence: message.sequence,
                    log_time: message.log_time,
                    publish_time: message.publish_time,
                },
                &data,
            )
            .unwrap();
    }
    writer.finish().unwrap();
}

fn replay_error(log: &Path) -> String {
    RecordedFlight::read(log, STATUS_TOPIC)
        .expect_err("the log must be refused")
        .to_string()
}

#[test]
fn a_missing_or_damaged_inputs_channel_is_an_error_naming_it() {
    let (log, _) = landing();
    let keep = |_: &str, data: &[u8]| Some(data.to_vec());
    // The rewrite itself keeps a log replayable.
    let copy = dir().join("copy.mcap");
    rewrite(log, &copy, keep);
    assert!(RecordedFlight::read(&copy, STATUS_TOPIC).is_ok());

    let missing = dir().join("no_inputs.mcap");
    rewrite(log, &missing, |topic, data| {
        (topic != INPUTS_TOPIC).then(|| data.to_vec())
    });
    let e = replay_error(&missing);
    assert!(e.contains(INPUTS_TOPIC) && e.contains("missing"), "{e}");
    assert!(e.contains("no_inputs.mcap"), "names the file: {e}");

    // Every 100th inputs record cut short: it no longer decodes.
    let damaged = dir().join("damaged_inputs.mcap");
    let count = std::cell::Cell::new(0);
    rewrite(log, &damaged, |topic, data| {
        if topic != INPUTS_TOPIC {
            return Some(data.to_vec());
        }
        count.set(count.get() + 1);
        Some(if count.get() % 100 == 0 {
            data[..data.len() / 2].to_vec()
        } else {
            data.to_vec()
        })
    });
    let e = replay_error(&damaged);
    assert!(e.contains(INPUTS_TOPIC) && e.contains("corrupt"), "{e}");

    // A tick dropped from the middle: a gap, named with the tick.
    let gap = dir().join("gap_inputs.mcap");
    let count = std::cell::Cell::new(0);
    rewrite(log, &gap, |topic, data| {
        if topic == INPUTS_TOPIC {
            count.set(count.get() + 1);
            if count.get() == 501 {
                return None;
            }
        }
        Some(data.to_vec())
    });
    let e = replay_error(&gap);
    assert!(e.contains(INPUTS_TOPIC) && e.contains("tick 501"), "{e}");

    // The status channel missing is named too.
    let no_status = dir().join("no_status.mcap");
    rewrite(log, &no_status, |topic, data| {
        (topic != STATUS_TOPIC).then(|| data.to_vec())
    });
    let e = replay_error(&no_status);
    assert!(e.contains(STATUS_TOPIC) && e.contains("missing"), "{e}");
}

#[test]
fn a_changed_configuration_attachment_is_refused_by_its_hash() {
    let (log, _) = landing();
    let bytes = std::fs::read(log).unwrap();
    let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
    let out = dir().join("edited_config.mcap");
    let mut writer = mcap::WriteOptions::new()
        .create(std::io::BufWriter::new(
            std::fs::File::create(&out).unwrap(),
        ))
        .unwrap();
    for index in &summary.attachment_indexes {
        let mut a = mcap::read::attachment(&bytes, index).unwrap();
        if a.name == "config/mpc" {
            let text = String::from_utf8(a.data.to_vec()).unwrap();
            a.data = Cow::Owned(
                text.replacen("max_iter = 40", "max_iter = 41", 1)
                    .into_bytes(),
            );
        }
        writer.attach(&a).unwrap();
    }
    for index in &summary.metadata_indexes {
        writer
            .write_metadata(&mcap::read::metadata(&bytes, index).unwrap())
            .unwrap();
    }
    writer.finish().unwrap();
    let e = replay_error(&out);
    assert!(e.contains("config/mpc") && e.contains("SHA-256"), "{e}");
}

#[test]
fn the_review_of_the_log_reproduces_the_landing_summary() {
    let (log, flown) = landing();
    let review = atmo_io::review::log::review_log(log, STATUS_TOPIC).unwrap();
    assert_eq!(review.truth, atmo_io::review::log::TruthSource::Simulation);
    let mut expected = flown.clone();
    // Not in the log: how long the simulation took on this machine.
    assert!(expected.wall_time_s.is_some());
    expected.wall_time_s = None;
    // Not in the log either: the flare's decision (the status message does
    // not carry it), which the simulator records from the flight stack.
    assert!(expected.predicted_touchdown.is_some());
    expected.predicted_touchdown = None;
    // Every value, exactly (f64 equality): touchdown tilt, impact speed,
    // max mean thrust, mode sequence, drive distance, feedback times...
    assert_eq!(review.summary, expected);
    assert!(review.summary.touchdown_tilt_deg.unwrap() > 60.0);
    assert_eq!(
        review.summary.mode_sequence,
        ["flight", "morphing", "transition", "touchdown", "drive"]
    );
    assert_eq!(review.trace.time.len(), 2100);
}
