//! The two processes as deployed: `atmo-roboclaw sim` (the board on a pty,
//! real time) and `atmo-roboclaw run` (the driver) on the iceoryx2 driver
//! ports, with the daemon's side of the ports in this test: heartbeats,
//! the tilt encoder at home, a velocity command moving it, the watchdog
//! stopping it when the commands stop, and a clean stop on SIGTERM.
#![allow(clippy::unwrap_used)]

mod common;

use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use atmo_io::drivers::{DriverId, DriverPortsConfig, FlightPorts, monotonic_ns};

const BIN: &str = env!("CARGO_BIN_EXE_atmo-roboclaw");

struct Kill(Child);

impl Drop for Kill {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn remove_prefix_files(prefix: &str) {
    for dir in [
        "/dev/shm",
        "/tmp/iceoryx2",
        "/tmp/iceoryx2/nodes",
        "/tmp/iceoryx2/services",
    ] {
        let Ok(entries) = std::fs::read_dir(dir) else {
            continue;
        };
        for e in entries.flatten() {
            if e.file_name().to_string_lossy().contains(prefix) {
                let _ = std::fs::remove_dir_all(e.path());
                let _ = std::fs::remove_file(e.path());
            }
        }
    }
}

/// `atmo-roboclaw sim ARGS`, and the pty it prints on its first line.
fn start_sim(args: &[&str]) -> (Kill, String) {
    let mut sim = Kill(
        Command::new(BIN)
            .arg("sim")
            .args(args)
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .unwrap(),
    );
    let mut line = String::new();
    BufReader::new(sim.0.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    let pty = line.trim().to_string();
    assert!(pty.starts_with("/dev/pts/"), "{pty}");
    (sim, pty)
}

#[test]
fn sim_and_run_processes_on_the_driver_ports() {
    let prefix = format!("atmorc{}_", std::process::id());
    let (sim, pty) = start_sim(&["--mode", "tilt", "--start-counts", "400"]);

    let dir = tempfile::tempdir().unwrap();
    let robot = common::repo_config("atmo.toml");
    let text = std::fs::read_to_string(common::repo_config("drivers/tilt.toml"))
        .unwrap()
        .replace("port = \"/dev/ttyACM0\"", &format!("port = \"{pty}\""))
        .replace(
            "robot_file = \"../atmo.toml\"",
            &format!("robot_file = \"{}\"", robot.display()),
        )
        .replace(
            "[ports]",
            &format!("[ports]\niceoryx_prefix = \"{prefix}\""),
        )
        // Wall-clock timeouts, generous for a busy machine.
        .replace("answer_timeout_ms = 10 ", "answer_timeout_ms = 100 ");
    let file = dir.path().join("tilt.toml");
    std::fs::write(&file, text).unwrap();

    let ports = DriverPortsConfig {
        iceoryx_prefix: prefix.clone(),
        liveness_timeout_ms: 1000,
        required: vec!["tilt".into()],
        ..DriverPortsConfig::default()
    };
    let mut daemon = FlightPorts::open(&ports).unwrap();
    let run = Command::new(BIN)
        .args(["run", "--config", file.to_str().unwrap()])
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut run = Kill(run);

    // Homing (400 counts) then running: alive, the encoder at home.
    let t0 = Instant::now();
    let mut first_counts = None;
    while t0.elapsed() < Duration::from_secs(5) {
        daemon.send_tilt_velocity(0.0, false);
        daemon.notify_drivers();
        std::thread::sleep(Duration::from_millis(10));
        let inputs = daemon.poll(monotonic_ns());
        if inputs.health.is_alive(DriverId::Tilt)
            && let Some(e) = inputs.tilt_encoder
        {
            first_counts = Some(e.counts);
            break;
        }
    }
    let home = first_counts.expect("the tilt driver never came alive with an encoder");
    assert!((home - 19929).abs() <= 1, "model counts at 90 deg: {home}");

    // -0.1 rad/s for 1 s: about 0.1 rad less tilt.
    let mut last = home;
    let t1 = Instant::now();
    while t1.elapsed() < Duration::from_secs(1) {
        daemon.send_tilt_velocity(-0.1, false);
        daemon.notify_drivers();
        std::thread::sleep(Duration::from_millis(7));
        let inputs = daemon.poll(monotonic_ns());
        if let Some(e) = inputs.tilt_encoder {
            last = e.counts;
        }
    }
    assert!(daemon.poll(monotonic_ns()).health.is_alive(DriverId::Tilt));
    assert_eq!(daemon.counters().deaths[DriverId::Tilt as usize], 0);
    assert!(
        last < home - 300,
        "the encoder did not follow: {home} -> {last}"
    );

    // The daemon goes quiet: the driver's watchdog (200 ms) stops the
    // motor, the encoder stands still while the heartbeat goes on.
    let poll_for = |daemon: &mut FlightPorts, d: Duration| {
        let t = Instant::now();
        let mut counts = None;
        while t.elapsed() < d {
            std::thread::sleep(Duration::from_millis(10));
            if let Some(e) = daemon.poll(monotonic_ns()).tilt_encoder {
                counts = Some(e.counts);
            }
        }
        counts
    };
    let settled = poll_for(&mut daemon, Duration::from_millis(700)).unwrap();
    let later = poll_for(&mut daemon, Duration::from_millis(300)).unwrap();
    assert_eq!(settled, later, "the motor still moves without commands");
    assert!(settled < last, "moved on after the last command");
    assert!(daemon.poll(monotonic_ns()).health.is_alive(DriverId::Tilt));

    // The pilot's encoder reset, held on: one homing, back at the switch.
    let t2 = Instant::now();
    let mut rehomed = None;
    while t2.elapsed() < Duration::from_secs(8) {
        daemon.send_tilt_velocity(0.0, true);
        daemon.notify_drivers();
        std::thread::sleep(Duration::from_millis(10));
        if let Some(e) = daemon.poll(monotonic_ns()).tilt_encoder
            && (e.counts - home).abs() <= 1
        {
            rehomed = Some(e.counts);
            break;
        }
    }
    assert!(rehomed.is_some(), "not back home after the encoder reset");

    // SIGTERM: the driver stops the motors and exits cleanly.
    let status = Command::new("kill")
        .args(["-TERM", &run.0.id().to_string()])
        .status()
        .unwrap();
    assert!(status.success());
    let output = std::mem::replace(&mut run.0, Command::new("true").spawn().unwrap())
        .wait_with_output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(output.status.success(), "{stderr}");
    assert!(stderr.contains("stopped (motors at 0)"), "{stderr}");
    assert!(stderr.contains("homings 2, rehome requests 1,"), "{stderr}");
    drop(daemon);
    drop(sim);
    remove_prefix_files(&prefix);
}

/// `sim --link PATH` removed whatever was at PATH to put its link there,
/// and removed it again on exit: a user's file named by mistake was lost.
/// A file there is refused before the board starts; a stale link (an
/// earlier board's) is replaced, and removed on a clean stop.
#[test]
fn sim_link_replaces_a_stale_link_and_refuses_anything_else() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("notes.txt");
    std::fs::write(&file, b"keep me").unwrap();
    let mut refused = Kill(
        Command::new(BIN)
            .env("RUST_BACKTRACE", "0")
            .args(["sim", "--link"])
            .arg(&file)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap(),
    );
    let deadline = Instant::now() + Duration::from_secs(10);
    while refused.0.try_wait().unwrap().is_none() {
        assert!(
            Instant::now() < deadline,
            "the board started on a file's name"
        );
        std::thread::sleep(Duration::from_millis(10));
    }
    let output = std::mem::replace(&mut refused.0, Command::new("true").spawn().unwrap())
        .wait_with_output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("exists and is not a symbolic link"),
        "{stderr}"
    );
    assert!(output.stdout.is_empty(), "no board started");
    assert_eq!(std::fs::read(&file).unwrap(), b"keep me");

    let link = dir.path().join("roboclaw-tilt");
    std::os::unix::fs::symlink("/dev/pts/no-such-board", &link).unwrap();
    let (mut sim, pty) = start_sim(&["--link", link.to_str().unwrap()]);
    let deadline = Instant::now() + Duration::from_secs(10);
    while std::fs::read_link(&link).ok().as_deref() != Some(std::path::Path::new(&pty)) {
        assert!(Instant::now() < deadline, "the stale link was not replaced");
        std::thread::sleep(Duration::from_millis(10));
    }
    let status = Command::new("kill")
        .args(["-TERM", &sim.0.id().to_string()])
        .status()
        .unwrap();
    assert!(status.success());
    assert!(sim.0.wait().unwrap().success());
    assert!(
        std::fs::symlink_metadata(&link).is_err(),
        "its link removed on exit"
    );
}
