//! Driver ports across processes (iceoryx2, isolated by a per-test file
//! prefix): the daemon side in this process, a driver in a child process
//! (this test binary re-run as `child_driver`). Commands out, sensors and
//! heartbeats in, tick-to-driver latency, a killed driver detected within
//! the liveness timeout, a restarted driver reconnecting, and the stale
//! resources of a crashed run cleaned at start-up.
// Test, bench and example code: an unwrap that fails is the failure report.
#![allow(clippy::unwrap_used)]

use std::process::{Child, Command};

use std::time::Duration;

use atmo_core::ConfigFile;
use atmo_io::drivers::{
    DriverEndpoint, DriverId, DriverInputs, DriverPortsConfig, FlightPorts, GroundContact,
    PortHeader, ThrusterCommand, TiltEncoder, cleanup_stale, monotonic_ns,
};

fn config(tag: &str) -> DriverPortsConfig {
    DriverPortsConfig {
        iceoryx_prefix: format!("atmo{tag}{}_", std::process::id()),
        liveness_timeout_ms: 100,
        ..DriverPortsConfig::default()
    }
}

const DIRS: [&str; 4] = [
    "/dev/shm",
    "/tmp/iceoryx2",
    "/tmp/iceoryx2/nodes",
    "/tmp/iceoryx2/services",
];

/// Files iceoryx2 keeps for nodes and services of a prefix (shared memory
/// and management files), without the one per-prefix `global_mgmt` segment
/// that iceoryx2 keeps for the prefix itself.
fn files_with(prefix: &str) -> usize {
    let mut n = 0;
    for dir in DIRS {
        let Ok(entries) = std::fs::read_dir(dir) else {
            continue;
        };
        for e in entries.flatten() {
            let name = e.file_name().to_string_lossy().to_string();
            if name.contains(prefix) && !name.ends_with(".global_mgmt") {
                n += 1;
            }
        }
    }
    n
}

/// Test hygiene: removes the per-prefix global segment of a test prefix.
fn remove_prefix_segment(prefix: &str) {
    for dir in DIRS {
        let Ok(entries) = std::fs::read_dir(dir) else {
            continue;
        };
        for e in entries.flatten() {
            if e.file_name().to_string_lossy().contains(prefix) {
                let _ = std::fs::remove_file(e.path());
            }
        }
    }
}

/// The process tests run one at a time (a spinning driver would disturb the
/// others on a 2-core machine).
static SERIAL: std::sync::Mutex<()> = std::sync::Mutex::new(());

fn serial() -> std::sync::MutexGuard<'static, ()> {
    SERIAL
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// What a child driver prints once every port is open.
const READY: &str = "ATMO_DRIVER_READY";

/// A child process killed when dropped (also when a test fails); its
/// standard output is drained by a thread that reports [`READY`].
struct Killed(Child, std::sync::mpsc::Receiver<()>);

impl Killed {
    fn kill(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }

    /// Waits until the child has opened all its ports (not merely started
    /// creating files: a kill in the middle of creating them leaves a
    /// half-made node, which is a different test).
    fn wait_ready(&self, timeout: Duration) {
        self.1
            .recv_timeout(timeout)
            .expect("the child driver never reported its ports open");
    }
}

impl Drop for Killed {
    fn drop(&mut self) {
        self.kill();
    }
}

fn spawn_driver(prefix: &str, name: &str) -> Killed {
    spawn_driver_with(prefix, name, "sleep")
}

fn spawn_driver_with(prefix: &str, name: &str, mode: &str) -> Killed {
    use std::io::BufRead as _;
    let mut child = Command::new(std::env::current_exe().unwrap())
        .args(["--exact", "child_driver", "--nocapture"])
        .env("ATMO_DRIVER_CHILD_PREFIX", prefix)
        .env("ATMO_DRIVER_CHILD_NAME", name)
        .env("ATMO_DRIVER_CHILD_MODE", mode)
        .stdout(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let stdout = child.stdout.take().unwrap();
    let (ready, ready_rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        for line in std::io::BufReader::new(stdout).lines() {
            let Ok(line) = line else { break };
            if line.contains(READY) {
                let _ = ready.send(());
            }
        }
    });
    Killed(child, ready_rx)
}

/// Child half: a driver process playing every driver. Echoes the last
/// thruster command's sequence as encoder counts, sends heartbeats every
/// 2 ms, until killed (or 60 s). `ATMO_DRIVER_CHILD_MODE`: `sleep` polls
/// every 2 ms; `spin` polls without sleeping; `wait` sleeps in
/// `wait_for_commands` until the daemon's event. In `spin` and `wait` it
/// answers each thruster command at once (latency).
#[test]
fn child_driver() {
    let Ok(prefix) = std::env::var("ATMO_DRIVER_CHILD_PREFIX") else {
        return;
    };
    let name = std::env::var("ATMO_DRIVER_CHILD_NAME").unwrap();
    let config = DriverPortsConfig {
        iceoryx_prefix: prefix,
        ..DriverPortsConfig::default()
    };
    let mode = std::env::var("ATMO_DRIVER_CHILD_MODE").unwrap_or_default();
    let spin = mode == "spin";
    let wait = mode == "wait";
    let mut driver = DriverEndpoint::open(&config, &name).unwrap();
    println!("{READY}");
    let mut last_sequence = -1i64;
    let start = monotonic_ns();
    let mut next_beat = start;
    let limit = if spin { 10_000_000_000 } else { 60_000_000_000 };
    while monotonic_ns() - start < limit {
        let commands = if wait {
            driver.wait_for_commands(Duration::from_millis(2)).unwrap()
        } else {
            driver.receive()
        };
        if let Some(c) = commands.thrust {
            last_sequence = c.header.sequence as i64;
            if spin || wait {
                driver.publish_heartbeat(DriverId::Thrusters);
            }
        }
        if monotonic_ns() >= next_beat {
            driver.publish_tilt_encoder(last_sequence);
            driver.publish_ground_contact(true);
            for id in DriverId::ALL {
                driver.publish_heartbeat(id);
            }
            next_beat += 2_000_000;
        }
        if spin {
            std::hint::spin_loop();
        } else if !wait {
            std::thread::sleep(Duration::from_millis(2));
        }
    }
}

/// Whether a poll drained anything from the drivers.
fn heard_anything(inputs: &DriverInputs) -> bool {
    inputs.tilt_encoder.is_some()
        || inputs.ground_contact.is_some()
        || inputs.heartbeats.iter().any(Option::is_some)
}

fn percentile(sorted: &[u64], p: f64) -> u64 {
    sorted[((sorted.len() - 1) as f64 * p).round() as usize]
}

#[test]
fn driver_process_round_trip_death_and_restart() {
    let _serial = serial();
    let config = config("rt");
    let mut ports = FlightPorts::open(&config).unwrap();
    let mut child = spawn_driver(&config.iceoryx_prefix, "driver_a");

    // Up: every driver alive within 5 s of starting the process.
    let period = Duration::from_micros(6667);
    let start = monotonic_ns();
    let mut sent = 0u64;
    let mut latencies = Vec::new();
    let mut last_echo = u64::MAX;
    let mut alive_since = None;
    let mut encoder_seen = 0;
    // The daemon side times a driver's silence from the last poll that
    // drained anything from it; the test tracks that poll itself.
    let mut last_heard = 0;
    while monotonic_ns() - start < 8_000_000_000 {
        assert!(ports.send_thrust([0.1, 0.2, 0.3, 0.4]));
        assert!(ports.send_tilt_velocity(0.1, false));
        assert!(ports.send_wheel_rates([1.0, -1.0]));
        sent += 1;
        std::thread::sleep(period);
        let now = monotonic_ns();
        let inputs = ports.poll(now);
        if heard_anything(&inputs) {
            last_heard = now;
        }
        if let Some(e) = inputs.tilt_encoder {
            assert!(e.counts < sent as i64, "echo of a command not sent yet");
            if e.counts >= 0 {
                encoder_seen += 1;
            }
        }
        if let Some(c) = inputs.ground_contact {
            assert_eq!(c.contact, 1);
        }
        if let Some(beat) = inputs.heartbeats[DriverId::Thrusters as usize]
            && beat.last_command_stamp_ns != 0
            && beat.last_command_sequence != last_echo
        {
            last_echo = beat.last_command_sequence;
            latencies.push(beat.last_command_received_ns - beat.last_command_stamp_ns);
        }
        if inputs.health.all_required_alive() {
            alive_since.get_or_insert(now);
        } else {
            assert!(
                alive_since.is_none(),
                "a driver died while running: {:?}",
                inputs.health
            );
        }
        if alive_since.is_some_and(|t| now - t > 1_500_000_000) {
            break;
        }
    }
    assert!(
        alive_since.is_some(),
        "drivers never came up: {:?}",
        ports.counters()
    );
    assert!(encoder_seen > 50, "{encoder_seen} encoder samples");
    latencies.sort_unstable();
    assert!(latencies.len() > 50);
    eprintln!(
        "tick-to-driver latency over {} commands: median {:.1} us, p99 {:.1} us, max {:.1} us \
         (driver polls every 2 ms)",
        latencies.len(),
        percentile(&latencies, 0.5) as f64 * 1e-3,
        percentile(&latencies, 0.99) as f64 * 1e-3,
        *latencies.last().unwrap() as f64 * 1e-3
    );

    // Killed: detected within the timeout (plus one poll period and the
    // heartbeat period). On a loaded machine the kill can come several ms
    // after the last poll, and messages sent before the kill can still be
    // drained after it, so silence is timed from the last poll that heard.
    child.kill();
    let killed = monotonic_ns();
    let detected_at = loop {
        std::thread::sleep(Duration::from_millis(1));
        let now = monotonic_ns();
        let inputs = ports.poll(now);
        if heard_anything(&inputs) {
            last_heard = now;
        }
        let health = inputs.health;
        if !health.all_required_alive() {
            assert!(DriverId::ALL.iter().all(|d| !health.is_alive(*d)));
            break now;
        }
        assert!(now - killed < 1_000_000_000, "death not detected");
    };
    let detected_ms = (detected_at - killed) as f64 * 1e-6;
    eprintln!("killed driver detected after {detected_ms:.1} ms (timeout 100 ms)");
    // The law: dead once nothing was heard for 100 ms (the last heartbeat
    // left at most 2 ms before the kill). The margin is the scheduling
    // slack of this 1 ms poll loop on a loaded 2-core machine.
    assert!(detected_ms <= 100.0 + 25.0, "{detected_ms} ms");
    let silent_ms = (detected_at - last_heard) as f64 * 1e-6;
    assert!(
        silent_ms > 100.0,
        "declared dead after {silent_ms} ms of silence (timeout 100 ms)"
    );
    assert!(ports.counters().deaths.iter().all(|d| *d == 1));

    // Restarted: reconnects without restarting the daemon side, and the
    // encoder stream counts the restart (its sequence starts again). The
    // streams are separate services: the heartbeat can make the driver
    // alive a poll before the first encoder sample is heard.
    let mut child = spawn_driver(&config.iceoryx_prefix, "driver_b");
    let restart = monotonic_ns();
    loop {
        ports.send_thrust([0.0; 4]);
        std::thread::sleep(period);
        let alive = ports.poll(monotonic_ns()).health.all_required_alive();
        if alive && ports.counters().tilt_encoder.restarts >= 1 {
            break;
        }
        assert!(
            monotonic_ns() - restart < 8_000_000_000,
            "restarted driver not seen (alive {alive}): {:?}",
            ports.counters()
        );
    }
    let c = ports.counters();
    assert!(c.tilt_encoder.restarts >= 1, "{c:?}");
    assert_eq!(c.send_errors, 0);
    child.kill();
    drop(ports);
    // Our own resources are gone with the ports; the killed child's are
    // cleaned by the next start-up.
    cleanup_stale(&config).unwrap();
    assert_eq!(files_with(&config.iceoryx_prefix), 0);
    remove_prefix_segment(&config.iceoryx_prefix);
}

/// Tick-to-driver latency through iceoryx2: command stamp in the daemon to
/// receipt in the driver process, both CLOCK_MONOTONIC, for a driver that
/// polls continuously (the transport) and one that sleeps until the
/// daemon's event (what a real driver should do). Printed for
/// BENCHMARKS.md, not asserted (a wall-clock figure depends on the
/// machine's load); what is asserted is that every command reaches the
/// driver and is echoed in its heartbeat (each waited for up to 2 s).
fn latency(mode: &str) -> Vec<u64> {
    let config = config(&format!("lat{mode}"));
    let mut ports = FlightPorts::open(&config).unwrap();
    let mut child = spawn_driver_with(&config.iceoryx_prefix, "fast_driver", mode);
    let start = monotonic_ns();
    while !ports
        .poll(monotonic_ns())
        .health
        .is_alive(DriverId::Thrusters)
    {
        assert!(
            monotonic_ns() - start < 5_000_000_000,
            "driver never came up"
        );
        ports.notify_drivers();
        std::thread::sleep(Duration::from_millis(5));
    }
    let mut latencies = Vec::new();
    let mut last_echo = u64::MAX;
    let mut missed = 0;
    for _ in 0..450 {
        ports.send_thrust([0.5; 4]);
        assert!(ports.notify_drivers());
        let sent = monotonic_ns();
        loop {
            std::thread::sleep(Duration::from_micros(200));
            if let Some(beat) = ports.poll(monotonic_ns()).heartbeats[DriverId::Thrusters as usize]
                && beat.last_command_sequence != last_echo
                && beat.last_command_stamp_ns != 0
            {
                last_echo = beat.last_command_sequence;
                latencies.push(beat.last_command_received_ns - beat.last_command_stamp_ns);
                break;
            }
            if monotonic_ns() - sent > 2_000_000_000 {
                missed += 1;
                break;
            }
        }
        // The rest of a 150 Hz period.
        let spent = Duration::from_nanos(monotonic_ns() - sent);
        std::thread::sleep(Duration::from_micros(6667).saturating_sub(spent));
    }
    child.kill();
    drop(ports);
    cleanup_stale(&config).unwrap();
    remove_prefix_segment(&config.iceoryx_prefix);
    assert_eq!(
        missed, 0,
        "{missed} of 450 commands never echoed by the driver"
    );
    latencies.sort_unstable();
    let us = |ns: u64| ns as f64 * 1e-3;
    eprintln!(
        "tick-to-driver latency ({mode} driver) over {} commands: median {:.1} us, p90 {:.1} us, p99 {:.1} us, max {:.1} us",
        latencies.len(),
        us(percentile(&latencies, 0.5)),
        us(percentile(&latencies, 0.9)),
        us(percentile(&latencies, 0.99)),
        us(*latencies.last().unwrap())
    );
    latencies
}

#[test]
fn tick_to_driver_latency() {
    let _serial = serial();
    for mode in ["spin", "wait"] {
        assert_eq!(latency(mode).len(), 450);
    }
}

#[test]
fn stale_resources_of_a_crashed_run_are_cleaned_at_start_up() {
    let _serial = serial();
    let config = config("st");
    // A driver that dies holding its ports.
    let mut child = spawn_driver(&config.iceoryx_prefix, "crashing_driver");
    // Waiting for its files and then 300 ms was not enough on a loaded CI
    // machine: the kill could land while the node was still being built.
    child.wait_ready(Duration::from_secs(20));
    std::thread::sleep(Duration::from_millis(50));
    child.kill();
    let left = files_with(&config.iceoryx_prefix);
    assert!(left > 0, "a killed process leaves its files");
    assert_eq!(cleanup_stale(&config).unwrap(), 1, "one dead node");
    assert_eq!(files_with(&config.iceoryx_prefix), 0, "everything removed");
    // And a fresh start works on the same prefix.
    let ports = FlightPorts::open(&config).unwrap();
    assert_eq!(ports.counters().cleaned_nodes, 0);
    drop(ports);
    assert_eq!(files_with(&config.iceoryx_prefix), 0);
    remove_prefix_segment(&config.iceoryx_prefix);
}

#[test]
fn payloads_are_plain_fixed_layouts() {
    use std::mem::{align_of, size_of};
    assert_eq!(size_of::<PortHeader>(), 16);
    assert_eq!(size_of::<ThrusterCommand>(), 48);
    assert_eq!(size_of::<TiltEncoder>(), 24);
    assert_eq!(size_of::<GroundContact>(), 24);
    assert_eq!(align_of::<ThrusterCommand>(), 8);
}

#[test]
fn config_is_checked() {
    let file = std::path::Path::new("drivers.toml");
    let bad = DriverPortsConfig {
        liveness_timeout_ms: 0,
        ..DriverPortsConfig::default()
    };
    let err = bad.validate(file).unwrap_err().to_string();
    assert!(
        err.contains("drivers.toml") && err.contains("liveness_timeout_ms"),
        "{err}"
    );
    let bad = DriverPortsConfig {
        required: vec!["rotors".into()],
        ..DriverPortsConfig::default()
    };
    assert!(bad.validate(file).is_err());
    DriverPortsConfig::default().validate(file).unwrap();
    let parsed = DriverPortsConfig::from_toml_str("liveness_timeout_ms = 50\n", file).unwrap();
    assert_eq!(parsed.liveness_timeout_ms, 50);
    assert_eq!(parsed.prefix, "atmo/drivers");
    let err = DriverPortsConfig::from_toml_str("timeout = 50\n", file)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("drivers.toml:1") && err.contains("timeout"),
        "{err}"
    );
}

/// A zero (or sub-microsecond) wait returns at once, with or without a
/// pending signal; a real timeout still waits for it.
#[test]
fn a_zero_wait_for_commands_does_not_block() {
    let _serial = serial();
    let config = config("zw");
    let mut ports = FlightPorts::open(&config).unwrap();
    // The driver waits on its own thread (iceoryx2 ports stay on the thread
    // that opened them), so that a regression fails instead of hanging.
    let (report_tx, report) = std::sync::mpsc::channel();
    let (sent_tx, sent) = std::sync::mpsc::channel::<()>();
    let driver_config = config.clone();
    let waiter = std::thread::spawn(move || {
        let mut driver = DriverEndpoint::open(&driver_config, "zero_wait").unwrap();
        report_tx.send(None).unwrap(); // opened
        for timeout in [Duration::ZERO, Duration::from_nanos(500)] {
            let start = std::time::Instant::now();
            let commands = driver.wait_for_commands(timeout).unwrap();
            report_tx
                .send(Some((start.elapsed(), commands.thrust.map(|c| c.thrust))))
                .unwrap();
        }
        sent.recv().unwrap();
        let commands = driver.wait_for_commands(Duration::ZERO).unwrap();
        report_tx
            .send(Some((Duration::ZERO, commands.thrust.map(|c| c.thrust))))
            .unwrap();
        let start = std::time::Instant::now();
        let _ = driver.wait_for_commands(Duration::from_millis(30)).unwrap();
        report_tx.send(Some((start.elapsed(), None))).unwrap();
    });
    let next = || {
        report
            .recv_timeout(Duration::from_secs(5))
            .expect("wait_for_commands blocked")
    };
    assert_eq!(next(), None, "driver opened");
    for _ in 0..2 {
        let (elapsed, thrust) = next().unwrap();
        assert!(elapsed < Duration::from_millis(50), "{elapsed:?}");
        assert_eq!(thrust, None, "nothing was sent");
    }
    // With a command and its signal pending, a zero wait takes both.
    assert!(ports.send_thrust([0.25; 4]) && ports.notify_drivers());
    sent_tx.send(()).unwrap();
    assert_eq!(next().unwrap().1, Some([0.25; 4]));
    let (waited, _) = next().unwrap();
    assert!(
        waited >= Duration::from_millis(25),
        "the signal was consumed: a real timeout waits ({waited:?})"
    );
    waiter.join().unwrap();
    drop(ports);
    remove_prefix_segment(&config.iceoryx_prefix);
}
