//! The command line refuses what it cannot generate, naming the flag or
//! the file: `--duration 1e300` panicked sizing its buffer, `--rate 0`
//! wrote an empty recording, `--robot /dev/zero` was read until the kernel
//! killed the process, and errors were printed as Rust debug structures.
#![allow(clippy::unwrap_used, reason = "test")]

use std::process::Command;

fn testgen(args: &[&str]) -> (Option<i32>, String) {
    let out = std::env::temp_dir().join(format!("atmo-testgen-cli-{}.csv", std::process::id()));
    let output = Command::new(env!("CARGO_BIN_EXE_atmo-testgen"))
        .current_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/../.."))
        .env("RUST_BACKTRACE", "0")
        .arg("--out")
        .arg(&out)
        .args(args)
        .output()
        .unwrap();
    let _ = std::fs::remove_file(&out);
    (
        output.status.code(),
        String::from_utf8_lossy(&output.stderr).into_owned(),
    )
}

#[test]
fn numbers_out_of_range_are_refused_naming_the_flag() {
    for (flag, value) in [
        ("--duration", "1e300"),
        ("--duration", "0"),
        ("--rate", "0"),
        ("--rate", "inf"),
        ("--tilt-deg", "nan"),
        ("--tilt-deg", "91"),
    ] {
        let (code, stderr) = testgen(&[flag, value]);
        assert_eq!(code, Some(2), "{flag} {value}: {stderr}");
        assert!(
            stderr.contains(flag) && stderr.contains("is not a finite number"),
            "{flag} {value}: {stderr}"
        );
    }
}

#[test]
fn a_robot_file_that_is_not_a_file_is_refused_by_name() {
    for (robot, what) in [
        ("/dev/zero", "not a regular file"),
        ("crates", "not a regular file"),
        ("no/such/robot.toml", "cannot read"),
    ] {
        let (code, stderr) = testgen(&["--robot", robot, "--duration", "1"]);
        assert_eq!(code, Some(1), "{robot}: {stderr}");
        assert!(
            stderr.starts_with(&format!("atmo-testgen: {robot}: {what}")),
            "{robot}: {stderr}"
        );
    }
}
