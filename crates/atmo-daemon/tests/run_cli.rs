//! `atmo-daemon run` with its log on a full disk (the fault campaign,
//! docs/faults.md): the binary flies on, says so once at the first failed
//! write (naming the file and the OS error), and exits non-zero at the end
//! with that error. The logger's own reaction (every record counted, the
//! control thread never blocked) is atmo-io's
//! `a_full_disk_fails_the_writer_and_every_record_is_counted_never_blocked`.
//! And `atmo-daemon replay`'s what-if folder, staged as every output folder.
// Test code: an unwrap that fails is the failure report.
#![allow(clippy::unwrap_used)]

use std::path::Path;
use std::process::Command;

#[test]
fn a_full_log_disk_is_reported_at_once_and_in_the_exit_status() {
    let full = Path::new("/dev/full");
    assert!(
        full.exists(),
        "the test needs Linux's /dev/full (ENOSPC on write)"
    );
    let repo = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let out = Command::new(env!("CARGO_BIN_EXE_atmo-daemon"))
        .current_dir(&repo)
        // A domain of its own: the SITL and ROS 2 tests use others.
        .env("ROS_DOMAIN_ID", "173")
        .env("RUST_LOG", "info,rustdds=off")
        .args(["run", "--log", "/dev/full", "--duration", "1"])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "exit 0 with a failed log: {stderr}");
    assert_eq!(
        stderr
            .matches("the log cannot be written: flying on, its records dropped and counted")
            .count(),
        1,
        "the failure said once when it happened: {stderr}"
    );
    assert!(
        stderr.contains("writing the log /dev/full")
            && stderr.contains("/dev/full: No space left on device"),
        "the exit names the file and the OS error: {stderr}"
    );
    // Every record the control thread could not log is counted and told.
    let dropped: u64 = stderr
        .split("log_dropped=")
        .nth(1)
        .and_then(|rest| rest.split(|c: char| !c.is_ascii_digit()).next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no log_dropped in the exit report: {stderr}"));
    assert!(
        dropped > 0,
        "a second of ticks on /dev/full dropped none: {stderr}"
    );
    for counter in ["rc_rejected=", "esc_rejected=", "estimates_stale_ticks="] {
        assert!(stderr.contains(counter), "{counter} not reported: {stderr}");
    }
}

/// `replay --config ... --out DIR` wrote its what-if files into DIR as it
/// was (someone's folder: theirs overwritten, a half-written set on a
/// failure). The folder is now staged like every output folder: a file
/// or a folder this tool did not write is refused before the replay, and
/// a new folder is written whole.
#[test]
fn a_what_if_replay_never_writes_into_what_it_did_not_make() {
    let repo = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let log = repo.join("crates/atmo-flight/tests/data/sitl_estimate_burst.mcap");
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("whatif-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(dir.join("theirs")).unwrap();
    std::fs::write(dir.join("theirs/whatif.csv"), b"their data").unwrap();
    std::fs::write(dir.join("notes.txt"), b"keep me").unwrap();
    let replay = |out: &str| {
        Command::new(env!("CARGO_BIN_EXE_atmo-daemon"))
            .arg("replay")
            .arg(&log)
            .arg("--config")
            .arg(repo.join("config/mpc.toml"))
            .arg("--out")
            .arg(dir.join(out))
            .output()
            .unwrap()
    };
    for out in ["notes.txt", "theirs"] {
        let run = replay(out);
        let stderr = String::from_utf8_lossy(&run.stderr);
        assert_eq!(run.status.code(), Some(2), "{out}: {stderr}");
        assert!(stderr.contains("nothing was written or moved"), "{stderr}");
        let stdout = String::from_utf8_lossy(&run.stdout);
        assert!(
            !stdout.contains("replayed in"),
            "refused after the replay: {stdout}"
        );
    }
    assert_eq!(std::fs::read(dir.join("notes.txt")).unwrap(), b"keep me");
    assert_eq!(
        std::fs::read(dir.join("theirs/whatif.csv")).unwrap(),
        b"their data"
    );
    let run = replay("new");
    assert!(
        run.status.code().is_some_and(|c| c < 2),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    for file in ["whatif.csv", "whatif.txt", "whatif.png", ".atmo-output"] {
        assert!(dir.join("new").join(file).is_file(), "{file}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}
