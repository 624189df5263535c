//! `atmo-daemon run` with its log on a full disk (the fault campaign,
//! docs/faults.md): the binary flies on, says so once at the first failed
//! write (naming the file and the OS error), and exits non-zero at the end
//! with that error. The logger's own reaction (every record counted, the
//! control thread never blocked) is atmo-io's
//! `a_full_disk_fails_the_writer_and_every_record_is_counted_never_blocked`.
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
}
