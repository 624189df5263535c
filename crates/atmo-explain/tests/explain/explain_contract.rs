//! The reader contract (docs/input-contract.md) on hostile inputs: every
//! format's time base, rotations, sizes and the neighbour check end in a
//! clean error naming the file and the line (or message), or in a result
//! whose skips are counted.
#![allow(clippy::unwrap_used, reason = "test")]

use std::path::{Path, PathBuf};
use std::time::Instant;

use atmo_core::{ConfigFile, RobotConfig};
use atmo_explain::recording::neural_fly::split_row;
use atmo_explain::recording::{Recording, Sample};
use atmo_explain::{Options, explain};

use super::explain_hostile::{cruise_with_motor_lag, found};

const NF_FLIGHT: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/tests/data/neural_fly_L1_nowind_12s.csv"
);

fn scratch(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("contract");
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

/// The Neural-Fly fixture with `edit(row index, cells)` applied to every
/// data row, written to a scratch file.
fn neural_fly_edited(name: &str, edit: impl Fn(usize, &mut Vec<String>)) -> PathBuf {
    let text = std::fs::read_to_string(NF_FLIGHT).unwrap();
    let mut lines = text.lines();
    let mut out = String::from(lines.next().unwrap());
    out.push('\n');
    for (i, line) in lines.enumerate() {
        let mut cells: Vec<String> = split_row(line).into_iter().map(String::from).collect();
        edit(i, &mut cells);
        let quoted: Vec<String> = cells
            .iter()
            .map(|c| {
                if c.starts_with('[') {
                    format!("\"{c}\"")
                } else {
                    c.clone()
                }
            })
            .collect();
        out.push_str(&quoted.join(","));
        out.push('\n');
    }
    let path = scratch(name);
    std::fs::write(&path, out).unwrap();
    path
}

fn nf_robot() -> RobotConfig {
    RobotConfig::load(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../config/neural_fly_quadrotor.toml"
    ))
    .unwrap()
}

/// A row with `t = 1e300` panicked in the figure's per-second bins (sized
/// from the overflowed duration). Mid-file it is a time glitch, skipped and
/// counted; as the last row it is a gap refused naming the line.
#[test]
fn neural_fly_t_1e300_is_a_counted_glitch_or_a_refused_gap_never_a_panic() {
    let clean = Recording::load(NF_FLIGHT).unwrap();
    let mid = neural_fly_edited("nf_t_1e300.csv", |i, c| {
        if i == 300 {
            c[1] = "1e300".into();
        }
    });
    let rec = Recording::load(&mid).unwrap();
    assert_eq!(rec.samples.len(), clean.samples.len() - 1);
    assert_eq!(rec.skipped_time, clean.skipped_time + 1);
    let ex = explain(&rec, &nf_robot(), &Options::default()).unwrap();
    assert!(ex.duration_s < 13.0, "{}", ex.duration_s);
    let dir = scratch("nf_t_1e300_out");
    let _ = std::fs::remove_dir_all(&dir);
    atmo_explain::output::write_all(&ex, &dir).unwrap();

    let last = clean.samples.len() - 1;
    let tail = neural_fly_edited("nf_t_1e300_last.csv", |i, c| {
        if i == last {
            c[1] = "1e300".into();
        }
    });
    let err = Recording::load(&tail).unwrap_err().to_string();
    assert!(
        err.contains("nf_t_1e300_last.csv")
            && err.contains(&format!("line {}: t = 1e300", last + 2)),
        "{err}"
    );
}

/// `t` in milliseconds was analysed as "3960 s at 0 Hz", in microseconds it
/// hung the replay (a 20 000 s gap integrated at 1 ms): both are refused at
/// load, naming the line and the unit the times look like.
#[test]
fn neural_fly_t_in_ms_or_us_is_refused_naming_the_unit() {
    for (name, scale, unit) in [("ms", 1e3, "milliseconds"), ("us", 1e6, "microseconds")] {
        let path = neural_fly_edited(&format!("nf_t_{name}.csv"), |_, c| {
            let t: f64 = c[1].parse().unwrap();
            c[1] = format!("{}", t * scale);
        });
        let start = Instant::now();
        let err = Recording::load(&path).unwrap_err().to_string();
        assert!(start.elapsed().as_secs_f64() < 5.0);
        assert!(
            err.contains(&format!("nf_t_{name}.csv"))
                && err.contains("line 3: t = ")
                && err.contains(unit),
            "{name}: {err}"
        );
    }
}

/// An all-zero `R`, a reflection and `1000 I` were taken as level flight,
/// uncounted: each row is skipped and counted; all rows bad is an error
/// that says why.
#[test]
fn neural_fly_r_that_is_not_a_rotation_is_skipped_and_counted() {
    let bad = [
        "[[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]]",
        "[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, -1.0]]",
        "[[1000.0, 0.0, 0.0], [0.0, 1000.0, 0.0], [0.0, 0.0, 1000.0]]",
    ];
    let clean = Recording::load(NF_FLIGHT).unwrap();
    assert_eq!(clean.skipped_rotation, 0, "the real logs' R are rotations");
    let path = neural_fly_edited("nf_bad_r.csv", |i, c| {
        if let Some(r) = [100, 200, 400].iter().position(|&k| k == i) {
            c[7] = bad[r].into();
        }
    });
    let rec = Recording::load(&path).unwrap();
    assert_eq!(rec.skipped_rotation, 3);
    assert_eq!(rec.samples.len(), clean.samples.len() - 3);
    let ex = explain(&rec, &nf_robot(), &Options::default()).unwrap();
    assert_eq!(ex.skipped_rotation, 3);
    let md = atmo_explain::output::report_md(&ex);
    assert!(
        md.contains("Skipped rows: 3 whose rotation matrix is not a rotation"),
        "{md}"
    );

    let all = neural_fly_edited("nf_all_zero_r.csv", |_, c| c[7] = bad[0].into());
    let err = Recording::load(&all).unwrap_err().to_string();
    assert!(
        err.contains("no usable rows (dropped 600 whose rotation matrix is not a rotation)"),
        "{err}"
    );
}

/// One tick per sample of `rec`, the tick `wild` stamped `9e18` ns.
fn write_ticks(rec: &Recording, wild: Option<usize>, path: &Path) {
    use atmo_io::mcap_log::{LoggerOptions, McapLogger};
    use atmo_io::msg::MpcStatus;
    let (log, thread) = McapLogger::spawn(path, LoggerOptions::default()).unwrap();
    let ch = log.channel::<MpcStatus>("/atmo/status").unwrap();
    for (k, s) in rec.samples.iter().enumerate() {
        let stamp_ns = if wild == Some(k) {
            9_000_000_000_000_000_000
        } else {
            (s.t * 1e9).round() as u64
        };
        let mut state = [0.0; 12];
        state.copy_from_slice(s.x.as_slice());
        let msg = MpcStatus {
            stamp_ns,
            tick: k as u64,
            state,
            thrust: [s.u[0], s.u[1], s.u[2], s.u[3]],
            varphi: s.varphi,
            height: s.ground_z - s.x[2],
            estimate_age: 0.0,
            ..MpcStatus::default()
        };
        while !log.try_log(ch, stamp_ns, &msg) {
            std::thread::sleep(std::time::Duration::from_millis(1));
        }
    }
    log.finish();
    thread.join().unwrap();
}

/// One tick with `clock_ns = 9e18` made `explain` allocate 72 GB for the
/// figure's per-second bins (SIGABRT): the tick is a time glitch, skipped
/// and counted, and the rest of the log is read as without it.
#[test]
fn an_mcap_tick_with_a_wild_clock_is_a_counted_glitch() {
    let rec = cruise_with_motor_lag();
    let clean_path = scratch("clean_clock.mcap");
    write_ticks(&rec, None, &clean_path);
    let clean = Recording::load(&clean_path).unwrap();
    let path = scratch("wild_clock.mcap");
    write_ticks(&rec, Some(1200), &path);
    let got = Recording::load(&path).unwrap();
    assert_eq!(got.skipped_time, clean.skipped_time + 1);
    assert_eq!(got.samples.len(), clean.samples.len() - 1);
    let ex = explain(&got, &RobotConfig::atmo(), &Options::default()).unwrap();
    assert!(ex.duration_s < 30.0, "{}", ex.duration_s);
    let dir = scratch("wild_clock_out");
    let _ = std::fs::remove_dir_all(&dir);
    atmo_explain::output::write_all(&ex, &dir).unwrap();
}

/// A header of 300 000 names took minutes (the duplicate check compared
/// every pair): refused at once naming the count; a duplicate in a wide
/// header is still found.
#[test]
fn a_huge_header_is_refused_at_once_and_duplicates_are_found_in_linear_time() {
    let names: Vec<String> = (0..300_000).map(|i| format!("c{i}")).collect();
    let text = format!("{}\n", names.join(","));
    let start = Instant::now();
    let err = Recording::from_csv_str(&text, "wide.csv")
        .unwrap_err()
        .to_string();
    assert!(start.elapsed().as_secs_f64() < 2.0);
    assert!(
        err.contains("wide.csv") && err.contains("300000 columns"),
        "{err}"
    );

    let mut wide: Vec<String> = atmo_explain::recording::REQUIRED_COLUMNS
        .iter()
        .map(|c| (*c).to_string())
        .collect();
    wide.extend((0..4000).map(|i| format!("extra{i}")));
    wide.push("extra3999".into());
    let err = Recording::from_csv_str(&format!("{}\n", wide.join(",")), "dup.csv")
        .unwrap_err()
        .to_string();
    assert!(err.contains("column `extra3999` appears twice"), "{err}");
}

/// `/dev/zero` was read until memory ran out; a file of NULs took four times
/// its size: a device is refused before reading, NULs at their offset.
#[test]
fn devices_and_binary_files_are_refused_before_reading() {
    for device in ["/dev/zero", "/dev/null"] {
        if Path::new(device).exists() {
            let err = Recording::load(device).unwrap_err().to_string();
            assert!(
                err.contains(device) && err.contains("not a regular file"),
                "{err}"
            );
        }
    }
    let dir = scratch("a_folder.csv");
    std::fs::create_dir_all(&dir).unwrap();
    let err = Recording::load(&dir).unwrap_err().to_string();
    assert!(err.contains("a folder, not a regular file"), "{err}");
    let nul = scratch("nul.csv");
    std::fs::write(&nul, vec![0u8; 8 << 20]).unwrap();
    let err = Recording::load(&nul).unwrap_err().to_string();
    assert!(err.contains("NUL byte at offset 0"), "{err}");
}

/// One glitch row inside the plausible ranges (wx = 99 rad/s, vx = 99 m/s,
/// ...) turned "explained by motor_lag" into "no candidate explains it":
/// one glitch per channel, each in its own row, is dropped by the
/// neighbour check with its row and the verdict is the clean file's.
#[test]
fn one_glitch_row_per_channel_is_dropped_and_the_verdict_stands() {
    let robot = RobotConfig::atmo();
    let clean_rec = cruise_with_motor_lag();
    let clean = explain(&clean_rec, &robot, &Options::default()).unwrap();
    assert_eq!(clean.jumps.rows, 0, "a clean flight has no jumps");
    assert!(clean.mismatch_found, "{}", clean.verdict);
    let mut rec = clean_rec.clone();
    let rows = [401, 701, 1001, 1301, 1601, 1901];
    for (c, &k) in rows.iter().enumerate() {
        let s: &mut Sample = &mut rec.samples[k];
        s.x[6 + c] = if c < 3 { 99.0 } else { -99.0 };
    }
    let ex = explain(&rec, &robot, &Options::default()).unwrap();
    assert_eq!(ex.verdict, clean.verdict);
    assert_eq!(found(&ex), found(&clean));
    assert_eq!(ex.jumps.rows, 6, "{:?}", ex.jumps);
    let described = ex.jumps.describe();
    for (c, name) in ["vx", "vy", "vz", "wx", "wy", "wz"].iter().enumerate() {
        assert!(
            described.contains(&format!("{name} 1 (first at row {}", rows[c] + 1)),
            "{described}"
        );
    }
    assert_eq!(ex.rows, clean.rows - 6);
    let md = atmo_explain::output::report_md(&ex);
    assert!(
        md.contains("Dropped rows: 6 jumping from their neighbours"),
        "{md}"
    );
}

/// The neighbour check leaves the real Neural-Fly flights alone (noisy
/// 50 Hz rates are motion, not glitches).
#[test]
fn the_neighbour_check_drops_nothing_from_the_real_flights() {
    let robot = nf_robot();
    let bounds = atmo_explain::recording::contract::JumpBounds::of(&robot);
    for name in [
        "neural_fly_L1_nowind_12s.csv",
        "neural_fly_L1_100wind_12s.csv",
        "neural_fly_L1_100wind_36s_12s.csv",
        "neural_fly_L1_nowind_18s_18s.csv",
        "neural_fly_L1_nowind_39s_11s.csv",
    ] {
        let path = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("tests/data")
            .join(name);
        let rec = Recording::load(&path).unwrap();
        let found = atmo_explain::recording::contract::find_jumps(&rec, &bounds);
        assert!(
            found.is_none(),
            "{name}: {bounds:?}: {:?}",
            found.map(|f| f.1)
        );
    }
}
