//! The MCAP logger end to end: every message type through the logger thread,
//! read back with the Rust reader; drops counted; a killed writer's log
//! recovered up to the last flush. Logs are left in the interop folder for
//! the Python reference readers (tests/python/check_mcap.py).

mod support;

use std::process::Command;
use std::time::{Duration, Instant};

use atmo_io::mcap_log::{
    AnyMessage, Compression, LOGGER_TOPIC, LoggerOptions, McapLogger, read_log, read_topic,
    recover, unused_log_path,
};
use atmo_io::msg::{DiagnosticArray, MpcStatus};
use support::*;

#[test]
fn every_message_type_round_trips_through_the_logger() {
    let path = interop_dir().join("all_types.mcap");
    let (log, thread) = McapLogger::spawn(&path, LoggerOptions::default()).unwrap();
    let status_ch = log.channel::<MpcStatus>("/atmo/status").unwrap();
    let motors_ch = log.channel("/fmu/in/actuator_motors").unwrap();
    let px4_odom_ch = log.channel("/fmu/out/vehicle_odometry").unwrap();
    let offboard_ch = log.channel("/fmu/in/offboard_control_mode").unwrap();
    let drive_ch = log.channel("/atmo/cmd_drive").unwrap();
    let mocap_ch = log.channel("/atmo/mocap/odom").unwrap();
    let diag_ch = log.channel("/diagnostics").unwrap();
    assert!(
        log.channel::<MpcStatus>("/atmo/status").is_err(),
        "duplicate topic"
    );
    assert!(log.channel::<MpcStatus>("no_slash").is_err());

    let n = 300u64;
    for k in 0..n {
        let t = 1_000_000_000 + k * 6_666_667;
        assert!(log.try_log(status_ch, t, &status(k)));
        assert!(log.try_log(motors_ch, t, &motors(k)));
        if k % 3 == 0 {
            assert!(log.try_log_at(px4_odom_ch, t, t - 1000, &px4_odometry(k)));
            assert!(log.try_log(offboard_ch, t, &offboard(k)));
            assert!(log.try_log(drive_ch, t, &drive(k)));
            assert!(log.try_log(mocap_ch, t, &mocap(k)));
        }
        if k % 100 == 0 {
            assert!(log.try_log(diag_ch, t, &diagnostics(k)));
        }
    }
    log.finish();
    assert!(
        !log.try_log(status_ch, 0, &status(0)),
        "closed after finish"
    );
    let summary = thread.join().unwrap();
    assert_eq!(log.dropped(), 1, "the one record after finish");
    assert_eq!(summary.dropped, 1);

    let messages = write_expected(&path);
    let mut counts = std::collections::BTreeMap::<String, u64>::new();
    for m in &messages {
        *counts.entry(m.topic.clone()).or_default() += 1;
    }
    assert_eq!(counts["/atmo/status"], n);
    assert_eq!(counts["/fmu/in/actuator_motors"], n);
    assert_eq!(counts["/fmu/out/vehicle_odometry"], n / 3);
    assert_eq!(counts["/diagnostics"], 3);
    assert!(counts[LOGGER_TOPIC] >= 1);
    assert_eq!(summary.written, messages.len() as u64);

    // Values, sequence numbers and times are what was sent.
    let mut seq = std::collections::BTreeMap::<String, u32>::new();
    let mut k_status = 0;
    for m in &messages {
        let s = seq.entry(m.topic.clone()).or_default();
        assert_eq!(m.sequence, *s, "{}", m.topic);
        *s += 1;
        match &m.message {
            AnyMessage::MpcStatus(got) => {
                let want = status(k_status);
                // NaN-free by construction; INFINITY compares equal.
                assert_eq!(*got, want);
                assert_eq!(m.log_time_ns, 1_000_000_000 + k_status * 6_666_667);
                k_status += 1;
            }
            AnyMessage::VehicleOdometry(got) => {
                let k = got.timestamp / 10_000;
                assert_eq!(*got, px4_odometry(k));
                assert_eq!(m.publish_time_ns, m.log_time_ns - 1000);
            }
            AnyMessage::ActuatorMotors(got) => {
                let k = got.timestamp / 6667;
                let want = motors(k);
                assert_eq!(got.control[..4], want.control[..4]);
                assert!(got.control[4..].iter().all(|c| c.is_nan()));
            }
            AnyMessage::OffboardControlMode(got) => {
                assert_eq!(*got, offboard(got.timestamp / 10_000));
            }
            AnyMessage::Twist(got) => {
                let k = ((got.linear.x - 0.5) / 0.01).round() as u64;
                assert_eq!(*got, drive(k));
            }
            AnyMessage::Odometry(got) => {
                let k = (got.header.stamp.to_ns().unwrap() - 2_000_000_000) / 10_000_000;
                assert_eq!(*got, mocap(k));
            }
            AnyMessage::DiagnosticArray(got) if m.topic == "/diagnostics" => {
                assert_eq!(*got, diagnostics(u64::from(got.header.stamp.sec as u32)));
            }
            AnyMessage::DiagnosticArray(got) => {
                assert_eq!(m.topic, LOGGER_TOPIC);
                let values = &got.status[0].values;
                assert_eq!(values[0].key, "dropped");
            }
            other => panic!("unexpected {other:?}"),
        }
    }
    assert_eq!(k_status, n);

    // Typed reading, and a type mismatch named.
    let statuses = read_topic::<MpcStatus>(&path, "/atmo/status").unwrap();
    assert_eq!(statuses.len(), n as usize);
    let err = read_topic::<DiagnosticArray>(&path, "/atmo/status").unwrap_err();
    assert!(err.to_string().contains("/atmo/status"), "{err}");

    // File-level properties the reference tools rely on.
    let bytes = std::fs::read(&path).unwrap();
    let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
    let header = mcap::read::LinearReader::new(&bytes)
        .unwrap()
        .find_map(|r| match r.unwrap() {
            mcap::records::Record::Header(h) => Some(h),
            _ => None,
        })
        .unwrap();
    assert_eq!(header.profile, "ros2");
    for channel in summary.channels.values() {
        assert_eq!(channel.message_encoding, "cdr");
        let schema = channel.schema.as_ref().unwrap();
        assert_eq!(schema.encoding, "ros2msg");
    }
    assert!(!summary.chunk_indexes.is_empty());
    assert!(
        summary
            .chunk_indexes
            .iter()
            .all(|c| c.compression == "zstd")
    );
}

#[test]
fn lz4_and_uncompressed_logs() {
    for (name, compression) in [
        ("lz4.mcap", Compression::Lz4),
        ("plain.mcap", Compression::None),
    ] {
        let path = interop_dir().join(name);
        let options = LoggerOptions {
            compression,
            ..LoggerOptions::default()
        };
        let (log, thread) = McapLogger::spawn(&path, options).unwrap();
        let ch = log.channel("/atmo/status").unwrap();
        for k in 0..50 {
            assert!(log.try_log(ch, k * 1000, &status(k)));
        }
        log.finish();
        thread.join().unwrap();
        let read = read_topic::<MpcStatus>(&path, "/atmo/status").unwrap();
        assert_eq!(read.len(), 50);
        assert_eq!(read[49].1, status(49));
        write_expected(&path);
    }
}

#[test]
fn a_full_queue_drops_and_counts_without_blocking() {
    let path = std::env::temp_dir().join(format!("atmo-io-drops-{}.mcap", std::process::id()));
    let options = LoggerOptions {
        queue_capacity: 2,
        ..LoggerOptions::default()
    };
    let (log, thread) = McapLogger::spawn(&path, options).unwrap();
    let ch = log.channel("/atmo/status").unwrap();
    let n = 20_000u64;
    let start = Instant::now();
    let mut slowest = Duration::ZERO;
    for k in 0..n {
        let t0 = Instant::now();
        log.try_log(ch, k, &status(k));
        slowest = slowest.max(t0.elapsed());
    }
    let elapsed = start.elapsed();
    assert_eq!(log.accepted() + log.dropped(), n);
    assert!(
        log.dropped() > 0,
        "a 2-slot queue must overflow under a burst"
    );
    log.finish();
    let summary = thread.join().unwrap();
    let statuses = read_topic::<MpcStatus>(&path, "/atmo/status").unwrap();
    assert_eq!(statuses.len() as u64, log.accepted());
    // The drop count is in the log itself.
    let health = read_topic::<DiagnosticArray>(&path, LOGGER_TOPIC).unwrap();
    let last = &health.last().unwrap().1.status[0];
    assert_eq!(last.values[0].value, summary.dropped.to_string());
    assert_eq!(last.level, atmo_io::msg::DiagnosticStatus::WARN);
    std::fs::remove_file(&path).unwrap();
    eprintln!(
        "{n} try_log in {elapsed:?} (slowest {slowest:?}), dropped {}",
        summary.dropped
    );
}

#[test]
fn bad_options_and_paths_are_errors() {
    let dir = std::env::temp_dir();
    let bad = LoggerOptions {
        flush_period: Duration::from_secs(2),
        ..LoggerOptions::default()
    };
    assert!(McapLogger::spawn(dir.join("x.mcap"), bad).is_err());
    let err = McapLogger::spawn("/nonexistent-dir/x.mcap", LoggerOptions::default())
        .err()
        .unwrap();
    assert!(err.to_string().contains("/nonexistent-dir/x.mcap"), "{err}");
    assert!(read_log("/nonexistent-dir/x.mcap").is_err());
}

/// Child half of the kill test: logs 150 Hz status stamped with the wall
/// clock until it is killed. Runs only when the parent sets the variable.
#[test]
fn child_logs_until_killed() {
    let Ok(path) = std::env::var("ATMO_IO_KILL_CHILD_LOG") else {
        return;
    };
    let (log, _thread) = McapLogger::spawn(&path, LoggerOptions::default()).unwrap();
    let ch = log.channel("/atmo/status").unwrap();
    let mocap_ch = log.channel("/atmo/mocap/odom").unwrap();
    let mut k = 0;
    loop {
        let now = atmo_io::wall_clock_ns();
        log.try_log(ch, now, &status(k));
        if k % 3 == 0 {
            log.try_log(mocap_ch, now, &mocap(k));
        }
        k += 1;
        std::thread::sleep(Duration::from_micros(6667));
    }
}

#[test]
fn a_killed_writer_loses_at_most_the_last_flush_period() {
    let dir = interop_dir();
    let truncated = dir.join("killed.mcap.partial");
    let recovered = dir.join("killed_recovered.mcap");
    let _ = std::fs::remove_file(&truncated);
    let mut child = Command::new(std::env::current_exe().unwrap())
        .args(["--exact", "child_logs_until_killed", "--nocapture"])
        .env("ATMO_IO_KILL_CHILD_LOG", &truncated)
        .spawn()
        .unwrap();
    std::thread::sleep(Duration::from_millis(2500));
    let killed_at = atmo_io::wall_clock_ns();
    child.kill().unwrap(); // SIGKILL: no destructor, no finish
    child.wait().unwrap();

    // Not a finished log: the summary reader fails.
    let bytes = std::fs::read(&truncated).unwrap();
    assert!(read_log(&truncated).is_err());
    let report = recover(&truncated, &recovered).unwrap();
    assert!(report.messages > 100, "{report:?}");
    let lost_s = (killed_at - report.last_log_time_ns) as f64 * 1e-9;
    eprintln!(
        "killed log: {} bytes, recovered {} messages, lost the last {lost_s:.3} s ({:?})",
        bytes.len(),
        report.messages,
        report.stopped_by
    );
    // Flush period 0.5 s by default: the loss is bounded by it plus scheduling.
    assert!(lost_s < 1.0, "lost {lost_s} s");
    let messages = write_expected(&recovered);
    assert_eq!(messages.len() as u64, report.messages);
    // The statuses are the child's, in order, intact.
    let statuses: Vec<MpcStatus> = messages
        .iter()
        .filter_map(|m| match &m.message {
            AnyMessage::MpcStatus(s) => Some(*s),
            _ => None,
        })
        .collect();
    for (k, s) in statuses.iter().enumerate() {
        assert_eq!(*s, status(k as u64));
    }
    // Recovering a finished log copies it whole.
    let again = dir.join("killed_recovered_twice.mcap");
    let report2 = recover(&recovered, &again).unwrap();
    assert_eq!(report2.messages, report.messages);
    assert_eq!(report2.stopped_by, None);
    std::fs::remove_file(&again).unwrap();
}

#[test]
fn recover_never_panics_on_any_truncation() {
    let dir = std::env::temp_dir().join(format!("atmo-io-trunc-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let full = dir.join("full.mcap");
    let options = LoggerOptions {
        chunk_size: 4096, // many chunks
        ..LoggerOptions::default()
    };
    let (log, thread) = McapLogger::spawn(&full, options).unwrap();
    let ch = log.channel("/atmo/status").unwrap();
    for k in 0..200 {
        assert!(log.try_log(ch, k, &status(k)));
    }
    log.finish();
    thread.join().unwrap();
    let bytes = std::fs::read(&full).unwrap();
    let cut = dir.join("cut.mcap");
    let out = dir.join("out.mcap");
    let mut previous = 0;
    for len in (0..bytes.len()).step_by(97) {
        std::fs::write(&cut, &bytes[..len]).unwrap();
        match recover(&cut, &out) {
            Ok(report) => {
                // Longer prefixes never recover fewer messages, and the
                // output is a valid log of exactly those messages.
                assert!(report.messages >= previous);
                previous = report.messages;
                let read = read_log(&out).unwrap();
                assert_eq!(read.len() as u64, report.messages);
            }
            Err(e) => assert!(len < 8, "{len}: {e}"), // shorter than the magic
        }
    }
    assert!(previous > 150);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn the_recover_command_line() {
    let dir = std::env::temp_dir().join(format!("atmo-io-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let full = dir.join("full.mcap");
    let options = LoggerOptions {
        chunk_size: 4096, // several chunks, so that a cut keeps some
        ..LoggerOptions::default()
    };
    let (log, thread) = McapLogger::spawn(&full, options).unwrap();
    let ch = log.channel("/atmo/status").unwrap();
    for k in 0..100 {
        assert!(log.try_log(ch, k * 1000, &status(k)));
    }
    log.finish();
    thread.join().unwrap();
    let bytes = std::fs::read(&full).unwrap();
    let cut = dir.join("cut.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() * 2 / 3]).unwrap();
    let out = dir.join("out.mcap");
    let exe = env!("CARGO_BIN_EXE_atmo-mcap");
    let run = Command::new(exe)
        .args(["recover", cut.to_str().unwrap(), out.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    assert!(String::from_utf8_lossy(&run.stdout).contains("input truncated"));
    assert!(read_log(&out).unwrap().len() > 10);
    let info = Command::new(exe)
        .args(["info", out.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(info.status.success());
    assert!(String::from_utf8_lossy(&info.stdout).contains("atmo_msgs/msg/MpcStatus"));
    // Its reader gone (`| head`): ended by SIGPIPE as a C tool is, no
    // panic in println!.
    #[cfg(unix)]
    atmo_core::closed_stdout::ends_by_sigpipe(
        Command::new(exe).args(["info", out.to_str().unwrap()]),
    )
    .unwrap();
    // The command line writes a new file: an existing output is refused,
    // untouched. The library replaces its output, but never the input
    // under another name (it overwrote the log it was recovering).
    let keep = dir.join("keep.txt");
    std::fs::write(&keep, b"keep me").unwrap();
    let refused = Command::new(exe)
        .args(["recover", cut.to_str().unwrap(), keep.to_str().unwrap()])
        .output()
        .unwrap();
    assert_eq!(refused.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&refused.stderr).contains("exists"));
    assert_eq!(std::fs::read(&keep).unwrap(), b"keep me");
    // `summary --out` is an output folder like every other: a file there
    // is refused, untouched (it was written into with create_dir_all).
    let refused = Command::new(exe)
        .args([
            "summary",
            out.to_str().unwrap(),
            "--out",
            keep.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    assert_eq!(refused.status.code(), Some(1));
    let stderr = String::from_utf8_lossy(&refused.stderr);
    assert!(stderr.contains("nothing was written or moved"), "{stderr}");
    assert_eq!(std::fs::read(&keep).unwrap(), b"keep me");
    let cut_bytes = std::fs::read(&cut).unwrap();
    let mut aliases = vec![dir.join(".").join("cut.mcap")];
    #[cfg(unix)]
    {
        let link = dir.join("alias.mcap");
        std::os::unix::fs::symlink(&cut, &link).unwrap();
        aliases.push(link);
    }
    for alias in aliases {
        let err = recover(&cut, &alias).unwrap_err().to_string();
        assert!(err.contains("same file"), "{err}");
        assert_eq!(std::fs::read(&cut).unwrap(), cut_bytes);
    }
    // Bad use: exit code 2; a missing file: 1 with the path named.
    assert_eq!(
        Command::new(exe).arg("nope").status().unwrap().code(),
        Some(2)
    );
    let missing = Command::new(exe)
        .args(["info", "/nonexistent.mcap"])
        .output()
        .unwrap();
    assert_eq!(missing.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&missing.stderr).contains("/nonexistent.mcap"));
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Log disk full: on `/dev/full` every write fails with ENOSPC.
/// The handle never blocks: records queued before the failure and every
/// record after it are dropped and counted, `failed()` says so with the
/// writer's error (the file and the OS's reason), and `join` returns it.
#[cfg(target_os = "linux")]
#[test]
fn a_full_disk_fails_the_writer_and_every_record_is_counted_never_blocked() {
    // Small chunks: the first chunk's write hits the full disk at once.
    let options = LoggerOptions {
        chunk_size: 1024,
        ..LoggerOptions::default()
    };
    let (log, thread) = McapLogger::spawn("/dev/full", options).unwrap();
    let channel = log.channel::<MpcStatus>("/atmo/status").unwrap();
    let deadline = Instant::now() + Duration::from_secs(5);
    let mut sent = 0u64;
    while !log.failed() {
        assert!(Instant::now() < deadline, "the writer never failed");
        let _ = log.try_log(channel, sent, &status(sent));
        sent += 1;
        std::thread::sleep(Duration::from_micros(200));
    }
    let failure = log.failure().unwrap();
    assert!(
        failure.contains("/dev/full") && failure.contains("No space left on device"),
        "{failure}"
    );
    // From now on each record is refused at once and counted.
    let dropped = log.dropped();
    for k in 0..100 {
        assert!(!log.try_log(channel, sent + k, &status(k)));
    }
    assert_eq!(log.dropped(), dropped + 100);
    let error = thread.join().unwrap_err().to_string();
    assert_eq!(error, failure);
    println!(
        "{sent} records offered before the failure; {}",
        log.dropped()
    );
}

/// A daemon started again with the same log path overwrote the earlier
/// flight's log: the new log takes the first free numbered name beside it;
/// a device (the full-disk test's `/dev/full`) is written as named.
#[test]
fn a_new_log_never_takes_the_name_of_an_earlier_one() {
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("unused-log-path-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let named = dir.join("flight.mcap");
    assert_eq!(unused_log_path(&named).unwrap(), named);
    std::fs::write(&named, b"first flight").unwrap();
    let second = unused_log_path(&named).unwrap();
    assert_eq!(second, dir.join("flight.1.mcap"));
    std::fs::write(&second, b"second flight").unwrap();
    assert_eq!(unused_log_path(&named).unwrap(), dir.join("flight.2.mcap"));
    assert_eq!(std::fs::read(&named).unwrap(), b"first flight");
    let full = std::path::Path::new("/dev/full");
    if full.exists() {
        assert_eq!(unused_log_path(full).unwrap(), full);
    }
    std::fs::remove_dir_all(&dir).unwrap();
}
