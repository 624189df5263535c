//! Software in the loop, two processes: the unmodified `atmo-daemon`
//! binary flies the wheel landing against `atmo-sim serve` over the real
//! transports (ROS 2 on loopback in a domain of its own, iceoryx2 under a
//! prefix of its own), is stopped with SIGTERM, and the landing is checked
//! from the daemon's MCAP log (and the server's truth in summary.json).
//!
//! `cargo test --workspace` (the README's test command) builds both
//! binaries. `CARGO_BIN_EXE_` names only this package's, so the daemon is
//! looked for next to it; `cargo test -p atmo-sim` alone does not build it,
//! so then the test builds it there itself (same cargo, profile and target
//! directory).
// Test, bench and example code: an unwrap that fails is the failure report.
#![allow(clippy::unwrap_used)]

use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::OnceLock;
use std::time::{Duration, Instant};

use atmo_flight::flight_log::INPUTS_TOPIC;
use atmo_io::mcap_log::read_topic;
use atmo_io::msg::{MpcStatus, SolverStatus, TickInputs};

/// Every driver alive in every tick from arming until the server's last
/// plant step (`server.served_until_ns` of its summary.json), nothing lost
/// on the way. After that step the drivers the server plays (or the boards
/// it answers for) are silent, and the daemon, stopped by the test only
/// once the server has exited, rightly sees them die.
pub(crate) fn assert_drivers_alive_while_served(
    status: &[(u64, MpcStatus)],
    summary: &serde_json::Value,
) {
    let served_until = summary["server"]["served_until_ns"].as_u64().unwrap();
    let armed: Vec<&MpcStatus> = status
        .iter()
        .map(|(_, s)| s)
        .skip_while(|s| s.mode.name() == "disarmed")
        .take_while(|s| s.ros_stamp_ns <= served_until)
        .collect();
    assert!(armed.len() > 150 * 5, "{} armed ticks", armed.len());
    for s in armed {
        assert_eq!(s.io.drivers_alive, [true; 4], "tick {}", s.tick);
        assert_eq!(s.io.driver_deaths, [0; 4], "tick {}", s.tick);
    }
}

pub(crate) fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// The `atmo-daemon` binary next to this package's `atmo-sim`, built first
/// if it is not there (once per test process).
fn daemon_binary() -> PathBuf {
    static DAEMON: OnceLock<PathBuf> = OnceLock::new();
    DAEMON.get_or_init(|| sibling_binary("atmo-daemon")).clone()
}

/// The binary of workspace package `name` (its binary has the package's
/// name) next to this package's `atmo-sim`, built there first if missing.
pub(crate) fn sibling_binary(name: &str) -> PathBuf {
    let sim = PathBuf::from(env!("CARGO_BIN_EXE_atmo-sim"));
    let binary = sim.with_file_name(format!("{name}{}", std::env::consts::EXE_SUFFIX));
    if !binary.exists() {
        build_sibling(&sim, name);
    }
    assert!(
        binary.exists(),
        "{} is still missing after building it; run `cargo build -p {name}`",
        binary.display()
    );
    binary
}

/// `cargo build -p NAME --bin NAME` into the target directory and profile
/// `sim` (.../<target dir>/<profile>/atmo-sim) was built in.
fn build_sibling(sim: &Path, name: &str) {
    let profile_dir = sim.parent().expect("atmo-sim's directory");
    let target_dir = profile_dir.parent().expect("the target directory");
    let profile = match profile_dir.file_name().and_then(|n| n.to_str()) {
        Some("debug") => "dev",
        Some(name) => name,
        None => panic!("no profile in {}", sim.display()),
    };
    eprintln!(
        "sitl: {} is not built (not a workspace build): building it",
        profile_dir.join(name).display()
    );
    let status = Command::new(env!("CARGO"))
        .current_dir(repo())
        .args(["build", "-p", name, "--bin", name, "--profile"])
        .arg(profile)
        .arg("--target-dir")
        .arg(target_dir)
        .status()
        .unwrap_or_else(|e| panic!("running {} build: {e}", env!("CARGO")));
    assert!(
        status.success(),
        "`cargo build -p {name} --profile {profile}` failed ({status}); \
         build it yourself or run `cargo test --workspace`"
    );
}

/// A child process killed when dropped (a failing test leaves nothing behind).
pub(crate) struct Process {
    name: &'static str,
    child: Child,
    stderr: PathBuf,
}

impl Process {
    pub(crate) fn spawn(name: &'static str, mut command: Command, dir: &Path) -> Self {
        let stderr = dir.join(format!("{name}.stderr"));
        let child = command
            .stdout(std::fs::File::create(dir.join(format!("{name}.stdout"))).unwrap())
            .stderr(std::fs::File::create(&stderr).unwrap())
            .stdin(Stdio::null())
            .spawn()
            .unwrap_or_else(|e| panic!("starting {name}: {e}"));
        Self {
            name,
            child,
            stderr,
        }
    }

    pub(crate) fn wait(&mut self, timeout: Duration) -> ExitStatus {
        let start = Instant::now();
        loop {
            if let Some(status) = self.child.try_wait().unwrap() {
                return status;
            }
            if start.elapsed() > timeout {
                let _ = self.child.kill();
                panic!(
                    "{} did not finish within {timeout:?}; stderr:\n{}",
                    self.name,
                    std::fs::read_to_string(&self.stderr).unwrap_or_default()
                );
            }
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    pub(crate) fn signal(&self, signal: &str) {
        let status = Command::new("kill")
            .args([format!("-{signal}"), self.child.id().to_string()])
            .status()
            .expect("running kill");
        assert!(status.success(), "kill -{signal} {}", self.name);
    }

    pub(crate) fn stderr(&self) -> String {
        std::fs::read_to_string(&self.stderr).unwrap_or_default()
    }
}

impl Drop for Process {
    fn drop(&mut self) {
        if matches!(self.child.try_wait(), Ok(None)) {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

/// `source` with each `(from, to)` replaced, written to `out`. Each `from`
/// must occur exactly once in `source`: a shipped file that moved fails
/// here, not as a test flying something it did not mean to.
pub(crate) fn patched_copy(source: &Path, out: &Path, replacements: &[(&str, &str)]) {
    let mut text = std::fs::read_to_string(source).unwrap();
    for (from, to) in replacements {
        assert_eq!(
            text.matches(from).count(),
            1,
            "{}: `{from}` should occur once",
            source.display()
        );
        text = text.replace(from, to);
    }
    std::fs::write(out, text).unwrap();
}

/// A daemon config for this run: the shipped one with loopback-only DDS,
/// an iceoryx2 prefix of its own and absolute config paths.
pub(crate) fn daemon_config(dir: &Path, tag: &str) -> PathBuf {
    let config = repo().join("config").canonicalize().unwrap();
    let absolute = |key: &str, file: &str| format!("{key} = \"{}\"", config.join(file).display());
    let path = dir.join("daemon.toml");
    patched_copy(
        &config.join("daemon.toml"),
        &path,
        &[
            ("robot = \"atmo.toml\"", &absolute("robot", "atmo.toml")),
            (
                "flight = \"flight.toml\"",
                &absolute("flight", "flight.toml"),
            ),
            ("mpc = \"mpc.toml\"", &absolute("mpc", "mpc.toml")),
            ("loopback_only = false", "loopback_only = true"),
            (
                "iceoryx_prefix = \"\"",
                &format!("iceoryx_prefix = \"{tag}_\""),
            ),
        ],
    );
    path
}

/// The wheel landing these flights serve: the shipped scenario, its plant
/// file's path made absolute, and 11 s of plant time instead of 14 (every
/// flight is on the wall clock: 3 s less each). The touchdown is at about
/// 5.5 s, so 11 s still drives on for more than 2 m (the tests ask for
/// 1 m) and logs more than the 10 s of ticks they count.
fn scenario(dir: &Path) -> PathBuf {
    let plant = repo().join("config/plant.toml").canonicalize().unwrap();
    let path = dir.join("wheel_landing.toml");
    patched_copy(
        &repo().join("config/scenarios/wheel_landing.toml"),
        &path,
        &[
            (
                "plant = \"../plant.toml\"",
                &format!("plant = \"{}\"", plant.display()),
            ),
            ("duration = 14.0", "duration = 11.0"),
        ],
    );
    path
}

pub(crate) fn run_dir(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

pub(crate) fn domain() -> String {
    // Away from 0 and from the other test binaries' domains (100..200).
    (200 + std::process::id() % 30).to_string()
}

/// The tests run real time against the wall clock: one at a time.
pub(crate) fn serial() -> std::sync::MutexGuard<'static, ()> {
    static LOCK: std::sync::Mutex<()> = std::sync::Mutex::new(());
    LOCK.lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
}

fn spawn_pair(dir: &Path, config: &Path, log: &Path, domain: &str) -> (Process, Process) {
    spawn_pair_with(dir, config, log, domain, &[])
}

/// The daemon and `atmo-sim serve` (the wheel landing, its summary in
/// DIR/sitl) with `serve_args` added to the server's arguments.
pub(crate) fn spawn_pair_with(
    dir: &Path,
    config: &Path,
    log: &Path,
    domain: &str,
    serve_args: &[std::ffi::OsString],
) -> (Process, Process) {
    let mut daemon = Command::new(daemon_binary());
    daemon
        .args(["run", "--config"])
        .arg(config)
        .arg("--log")
        .arg(log)
        .env("ROS_DOMAIN_ID", domain)
        .env("RUST_LOG", "info,rustdds=off");
    let daemon = Process::spawn("atmo-daemon", daemon, dir);
    let mut server = Command::new(env!("CARGO_BIN_EXE_atmo-sim"));
    server
        .arg("serve")
        .arg(scenario(dir))
        .arg("--config")
        .arg(config)
        .arg("--out")
        .arg(dir.join("sitl"))
        .args(["--quiet", "--start-timeout", "60"])
        .args(serve_args)
        .env("ROS_DOMAIN_ID", domain);
    let server = Process::spawn("atmo-sim serve", server, dir);
    (daemon, server)
}

fn modes_of(status: &[(u64, MpcStatus)]) -> Vec<&'static str> {
    let mut modes: Vec<&str> = Vec::new();
    for (_, s) in status {
        let name = s.mode.name();
        if modes.last() != Some(&name) {
            modes.push(name);
        }
    }
    modes
}

/// The landing, and its replay: `atmo-daemon replay` of the daemon's log
/// exits 0 having compared every tick. One flight serves both (each
/// real-time flight is most of this binary's time). The replay is checked
/// first: it must hold whatever the flight was, while a busy machine can
/// make a real-time flight land hard. The MPC's wall-clock time limit is
/// the shipped one: solves a busy machine cut are logged with their
/// iteration and cut again by the replay.
#[test]
fn the_daemon_binary_lands_on_the_wheels_against_the_plant_server_and_replays() {
    let _serial = serial();
    let dir = run_dir("sitl");
    let tag = format!("atmo_sitl_{}", std::process::id());
    let config = daemon_config(&dir, &tag);
    // The ESCs' telemetry too: PX4's EscStatus from the server, the
    // rotors' speeds in the daemon's ticks.
    let text = std::fs::read_to_string(&config)
        .unwrap()
        .replace(
            "type = \"px4_msgs/msg/EscStatus\", enabled = false",
            "type = \"px4_msgs/msg/EscStatus\", enabled = true",
        )
        .replace("full_speed_rpm = 0.0", "full_speed_rpm = 20000.0");
    assert!(text.contains("full_speed_rpm = 20000.0"));
    assert!(text.contains("EscStatus\", enabled = true"));
    std::fs::write(&config, text).unwrap();
    let log = dir.join("flight.mcap");
    let domain = domain();

    let (mut daemon, mut server) = spawn_pair(&dir, &config, &log, &domain);

    let served = server.wait(Duration::from_secs(150));
    daemon.signal("TERM");
    let stopped = daemon.wait(Duration::from_secs(20));
    assert!(
        stopped.success(),
        "the daemon must exit 0 on SIGTERM; stderr:\n{}",
        daemon.stderr()
    );
    assert_replays_every_tick(&log);
    let summary: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(dir.join("sitl/summary.json")).unwrap_or_else(|e| {
            panic!("no summary.json ({e}); server stderr:\n{}", server.stderr())
        }),
    )
    .unwrap();
    assert!(
        served.success(),
        "the server judged the landing a failure: {summary:#}\nserver stderr:\n{}\ndaemon stderr:\n{}",
        server.stderr(),
        daemon.stderr()
    );

    // The daemon's log, finished on SIGTERM: readable as it is.
    let status: Vec<(u64, MpcStatus)> = read_topic(&log, "/atmo/status").expect("daemon log");
    assert!(status.len() > 150 * 10, "{} status records", status.len());
    let modes = modes_of(&status);
    let flown: Vec<&str> = modes
        .iter()
        .copied()
        .skip_while(|m| *m == "disarmed")
        .collect();
    assert_eq!(
        flown,
        ["flight", "morphing", "transition", "touchdown", "drive"],
        "mode sequence {modes:?}"
    );
    let touchdown = status
        .iter()
        .find(|(_, s)| s.mode.name() == "touchdown")
        .map(|(_, s)| s)
        .unwrap();
    assert!(
        touchdown.varphi.to_degrees() >= 60.0,
        "touchdown at {:.1} deg (encoder)",
        touchdown.varphi.to_degrees()
    );
    assert!(touchdown.ground_contact);
    // The estimate-to-command latency the robot felt: the MPC
    // feedback phase of every tick that ran it, as the daemon logged it.
    let mut feedback: Vec<f64> = status
        .iter()
        .filter(|(_, s)| s.solver_status != SolverStatus::Idle)
        .map(|(_, s)| s.feedback_time)
        .collect();
    assert!(!feedback.is_empty(), "no tick ran the MPC");
    feedback.sort_by(f64::total_cmp);
    let at = |q: f64| feedback[((feedback.len() - 1) as f64 * q).round() as usize] * 1e6;
    println!(
        "sitl: MPC feedback over {} ticks: median {:.1} us, p99 {:.1} us, max {:.1} us",
        feedback.len(),
        at(0.5),
        at(0.99),
        at(1.0)
    );
    assert_drivers_alive_while_served(&status, &summary);
    // Every flying tick had the rotors' speeds, and none read stopped.
    let inputs: Vec<(u64, TickInputs)> = read_topic(&log, INPUTS_TOPIC).unwrap();
    let flying_ticks: std::collections::HashSet<u64> = status
        .iter()
        .filter(|(_, s)| matches!(s.mode.name(), "flight" | "morphing" | "transition"))
        .map(|(_, s)| s.tick)
        .collect();
    let flying: Vec<&TickInputs> = inputs
        .iter()
        .map(|(_, i)| i)
        .filter(|i| flying_ticks.contains(&i.tick))
        .collect();
    assert!(flying.len() > 150, "{} flying ticks", flying.len());
    let with_speeds = flying.iter().filter(|i| i.has_rotor_speeds).count();
    assert!(
        with_speeds * 100 >= flying.len() * 99,
        "{with_speeds} of {} flying ticks had the rotors' speeds",
        flying.len()
    );
    assert!(
        flying
            .iter()
            .filter(|i| i.has_rotor_speeds)
            .flat_map(|i| i.rotor_speeds)
            .all(|v| (0.3..=1.0).contains(&v)),
        "a rotor's speed out of the flight's range"
    );
    assert!(status.iter().all(|(_, s)| s.actuator_faults == 0));
    let last = &status.last().unwrap().1;
    assert_eq!(last.io.log_dropped, 0);
    // The solver's 4 ms time limit is wall-clock: on a shared machine a
    // preempted solve can hit it, and the stack then flies the shifted plan
    // (by design). What must hold: no solve failed outright, and such
    // fallbacks stay rare.
    let solving: Vec<SolverStatus> = status
        .iter()
        .map(|(_, s)| s.solver_status)
        .filter(|s| *s != SolverStatus::Idle)
        .collect();
    let fallbacks = solving
        .iter()
        .filter(|s| **s == SolverStatus::Fallback)
        .count();
    println!(
        "MPC ticks {}, fallbacks {fallbacks}, failures counted {}",
        solving.len(),
        last.mpc_failures_total
    );
    assert!(solving.len() > 150 * 3, "{} MPC ticks", solving.len());
    assert!(!solving.contains(&SolverStatus::Failed), "a solve failed");
    assert!(
        fallbacks * 100 <= solving.len(),
        "{fallbacks} fallback ticks of {}",
        solving.len()
    );

    // The plant's truth agrees.
    let truth = &summary["summary"];
    assert_eq!(truth["crashed"], false, "{summary:#}");
    assert!(
        truth["touchdown_tilt_deg"].as_f64().unwrap() >= 60.0,
        "{summary:#}"
    );
    assert!(
        truth["impact_speed_mps"].as_f64().unwrap() <= 0.5,
        "{summary:#}"
    );
    assert!(
        truth["drive_distance_m"].as_f64().unwrap() >= 1.0,
        "{summary:#}"
    );
}

/// Mid-flight, the plant server (every driver and the motion capture) is
/// killed: the daemon must notice the drivers die and fly its failsafe.
/// Then the daemon itself is killed (SIGKILL, no clean-up): its log is
/// recovered up to at most the last second (the logger flushes every 0.5 s).
#[test]
fn drivers_killed_mid_flight_failsafe_then_daemon_killed_log_recovered() {
    let _serial = serial();
    let dir = run_dir("sitl-kill");
    let tag = format!("atmo_sitl_kill_{}", std::process::id());
    let config = daemon_config(&dir, &tag);
    let log = dir.join("flight.mcap");
    let (mut daemon, mut server) = spawn_pair(&dir, &config, &log, &domain());

    // In flight by then (arming takes a fraction of a second; morphing
    // starts about 2 s into the descent).
    std::thread::sleep(Duration::from_secs(4));
    server.signal("KILL");
    server.wait(Duration::from_secs(5));
    std::thread::sleep(Duration::from_secs(2));
    daemon.signal("KILL");
    daemon.wait(Duration::from_secs(5));

    let recovered = dir.join("recovered.mcap");
    let report = atmo_io::mcap_log::recover(&log, &recovered).expect("recover the killed log");
    let status: Vec<(u64, MpcStatus)> = read_topic(&recovered, "/atmo/status").unwrap();
    assert!(report.messages >= status.len() as u64);
    let modes = modes_of(&status);
    assert!(
        modes.contains(&"flight") && modes.last() == Some(&"failsafe"),
        "modes {modes:?}; daemon stderr:\n{}",
        daemon.stderr()
    );
    let (failsafe_at, first) = status
        .iter()
        .find(|(_, s)| s.mode.name() == "failsafe")
        .unwrap();
    assert!(
        first.io.driver_deaths.iter().sum::<u64>() > 0 || first.estimate_age > 0.05,
        "failsafe for a reason: deaths {:?}, estimate age {}",
        first.io.driver_deaths,
        first.estimate_age
    );
    let last = &status.last().unwrap().1;
    assert_eq!(last.io.drivers_alive, [false; 4], "every driver seen dead");
    assert!(last.io.driver_deaths.iter().all(|d| *d >= 1));
    // The daemon was killed about 1.9 s after the failsafe began: a log that
    // loses at most the last second reaches at least 0.8 s past it.
    let last_at = status.last().unwrap().0;
    let kept = (last_at - failsafe_at) as f64 * 1e-9;
    assert!(
        kept >= 0.8,
        "the recovered log ends {kept:.2} s after the failsafe began (killed ~1.9 s after)"
    );
}

/// `atmo-daemon replay LOG` exits 0, says the flight is identical, and
/// compared every tick the log holds.
fn assert_replays_every_tick(log: &Path) {
    let output = Command::new(daemon_binary())
        .arg("replay")
        .arg(log)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&output.stdout);
    println!("{stdout}");
    assert!(
        output.status.success(),
        "replay exit {:?}\n{stdout}\n{}",
        output.status,
        String::from_utf8_lossy(&output.stderr)
    );
    assert!(stdout.contains("identical"), "{stdout}");
    let status: Vec<(u64, MpcStatus)> = read_topic(log, "/atmo/status").unwrap();
    assert!(status.len() > 150 * 10, "{} ticks", status.len());
    assert!(
        stdout.contains(&format!(": {} ticks", status.len())),
        "{stdout}"
    );
}
