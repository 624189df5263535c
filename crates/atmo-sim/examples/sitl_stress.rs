//! The two-process SITL wheel landing (the `atmo-daemon` binary
//! against `atmo-sim serve`, ROS 2 on loopback, iceoryx2 drivers), with
//! `--load N` busy-loop processes competing for the CPUs, and the daemon's
//! tick timing read back from its MCAP log: wake-up jitter (wake-up minus
//! deadline) median, p99 and max, compute p99, overruns and skipped
//! deadlines. A measurement (BENCHMARKS.md), not a test.
//!
//! ```text
//! cargo build -p atmo-daemon --bin atmo-daemon
//! cargo build -p atmo-sim --features sitl --bin atmo-sim --example sitl_stress
//! target/debug/examples/sitl_stress --load 0
//! target/debug/examples/sitl_stress --load 2
//! target/debug/examples/sitl_stress --load 2 --fifo 50   # the daemon real-time (chrt)
//! ```
//!
//! The binaries are taken from the example's own profile folder. Exit
//! status 0 when the landing succeeded and the daemon exited 0, else 1.
// Example code: an unwrap that fails is the failure report.
#![allow(clippy::unwrap_used)]

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use atmo_io::mcap_log::read_topic;
use atmo_io::msg::MpcStatus;

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// A child killed when dropped.
struct Process(Child);

impl Drop for Process {
    fn drop(&mut self) {
        if matches!(self.0.try_wait(), Ok(None)) {
            let _ = self.0.kill();
            let _ = self.0.wait();
        }
    }
}

fn busy_loop() -> ! {
    let mut x = 0u64;
    loop {
        x = std::hint::black_box(x.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1));
    }
}

/// The shipped daemon config with loopback-only DDS, a private iceoryx2
/// prefix and absolute config paths (as tests/sitl/sitl.rs writes it).
fn daemon_config(dir: &Path, tag: &str) -> PathBuf {
    let shipped = std::fs::read_to_string(repo().join("config/daemon.toml")).unwrap();
    let config = repo().join("config").canonicalize().unwrap();
    let mut text = shipped
        .replace("loopback_only = false", "loopback_only = true")
        .replace(
            "iceoryx_prefix = \"\"",
            &format!("iceoryx_prefix = \"{tag}_\""),
        );
    for (key, file) in [("robot", "atmo"), ("flight", "flight"), ("mpc", "mpc")] {
        let shipped = format!("{key} = \"{file}.toml\"");
        assert!(
            text.contains(&shipped),
            "config/daemon.toml: no `{shipped}`"
        );
        text = text.replace(
            &shipped,
            &format!(
                "{key} = \"{}\"",
                config.join(format!("{file}.toml")).display()
            ),
        );
    }
    let path = dir.join("daemon.toml");
    std::fs::write(&path, text).unwrap();
    path
}

fn quantile(sorted: &[f64], q: f64) -> f64 {
    sorted[((sorted.len() - 1) as f64 * q).round() as usize]
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if args.get(1).map(String::as_str) == Some("--busy") {
        busy_loop();
    }
    let mut load = 0usize;
    // The daemon under `chrt --fifo <priority>` (real-time scheduling).
    let mut fifo: Option<u32> = None;
    let mut out = std::env::temp_dir().join(format!("atmo-sitl-stress-{}", std::process::id()));
    let mut i = 1;
    while i < args.len() {
        match (args[i].as_str(), args.get(i + 1)) {
            ("--load", Some(n)) => load = n.parse().expect("--load: a number of processes"),
            ("--out", Some(dir)) => out = PathBuf::from(dir),
            ("--fifo", Some(p)) => fifo = Some(p.parse().expect("--fifo: a SCHED_FIFO priority")),
            _ => {
                eprintln!("usage: sitl_stress [--load N] [--fifo PRIORITY] [--out DIR]");
                std::process::exit(2);
            }
        }
        i += 2;
    }
    let _ = std::fs::remove_dir_all(&out);
    std::fs::create_dir_all(&out).unwrap();
    let me = std::env::current_exe().unwrap();
    let bin = me.parent().and_then(Path::parent).unwrap();
    let (daemon_bin, sim_bin) = (bin.join("atmo-daemon"), bin.join("atmo-sim"));
    for b in [&daemon_bin, &sim_bin] {
        assert!(
            b.exists(),
            "{} is not built (see the example's doc)",
            b.display()
        );
    }

    let busy: Vec<Process> = (0..load)
        .map(|_| Process(Command::new(&me).arg("--busy").spawn().unwrap()))
        .collect();
    let tag = format!("atmo_stress_{}", std::process::id());
    let config = daemon_config(&out, &tag);
    let log = out.join("flight.mcap");
    // Away from 0 and from the SITL tests' domains (200..230).
    let domain = (230 + std::process::id() % 3).to_string();
    let stderr = |name: &str| std::fs::File::create(out.join(format!("{name}.stderr"))).unwrap();
    let mut daemon = match fifo {
        Some(priority) => {
            let mut c = Command::new("chrt");
            c.args(["--fifo", &priority.to_string()]).arg(&daemon_bin);
            c
        }
        None => Command::new(&daemon_bin),
    };
    let mut daemon = Process(
        daemon
            .args(["run", "--config"])
            .arg(&config)
            .arg("--log")
            .arg(&log)
            .env("ROS_DOMAIN_ID", &domain)
            .env("RUST_LOG", "info,rustdds=off")
            .stdout(Stdio::null())
            .stderr(stderr("atmo-daemon"))
            .spawn()
            .unwrap(),
    );
    let started = Instant::now();
    let served = Command::new(&sim_bin)
        .arg("serve")
        .arg(repo().join("config/scenarios/wheel_landing.toml"))
        .arg("--config")
        .arg(&config)
        .arg("--out")
        .arg(out.join("sitl"))
        .args(["--quiet", "--start-timeout", "60"])
        .env("ROS_DOMAIN_ID", &domain)
        .stdout(Stdio::null())
        .stderr(stderr("atmo-sim-serve"))
        .status()
        .unwrap();
    let _ = Command::new("kill")
        .args(["-TERM", &daemon.0.id().to_string()])
        .status();
    let deadline = Instant::now() + Duration::from_secs(20);
    let daemon_exit = loop {
        if let Some(status) = daemon.0.try_wait().unwrap() {
            break Some(status);
        }
        if Instant::now() > deadline {
            break None;
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    drop(busy);

    let status: Vec<(u64, MpcStatus)> = match read_topic(&log, "/atmo/status") {
        Ok(status) if !status.is_empty() => status,
        other => {
            eprintln!(
                "no daemon log to read ({:?}); see {}/*.stderr",
                other.err(),
                out.display()
            );
            std::process::exit(1);
        }
    };
    // The armed flight: from the first tick out of `disarmed` on.
    let flown: Vec<&MpcStatus> = status
        .iter()
        .map(|(_, s)| s)
        .skip_while(|s| s.mode.name() == "disarmed")
        .collect();
    let mut wake: Vec<f64> = flown.iter().map(|s| s.timing.wake_latency).collect();
    let mut compute: Vec<f64> = flown.iter().map(|s| s.timing.compute).collect();
    wake.sort_by(f64::total_cmp);
    compute.sort_by(f64::total_cmp);
    let (first, last) = (flown.first().unwrap(), flown.last().unwrap());
    let overruns = last.timing.overruns_total - first.timing.overruns_total;
    let skipped = last.timing.skipped_total - first.timing.skipped_total;
    let mut modes: Vec<&str> = Vec::new();
    for s in &flown {
        if modes.last() != Some(&s.mode.name()) {
            modes.push(s.mode.name());
        }
    }
    let us = |v: f64| v * 1e6;
    println!(
        "load {load} busy-loop processes on {} CPUs, daemon {}; wall {:.1} s; {} ticks flown",
        std::thread::available_parallelism().map_or(0, std::num::NonZero::get),
        fifo.map_or("SCHED_OTHER".to_string(), |p| format!("SCHED_FIFO {p}")),
        started.elapsed().as_secs_f64(),
        flown.len()
    );
    println!(
        "tick jitter (wake-up - deadline): median {:.0} us, p99 {:.0} us, max {:.0} us",
        us(quantile(&wake, 0.5)),
        us(quantile(&wake, 0.99)),
        us(quantile(&wake, 1.0))
    );
    println!(
        "tick compute: median {:.0} us, p99 {:.0} us, max {:.0} us",
        us(quantile(&compute, 0.5)),
        us(quantile(&compute, 0.99)),
        us(quantile(&compute, 1.0))
    );
    println!(
        "overruns {overruns}, skipped deadlines {skipped}, MPC failures {}, modes {modes:?}",
        last.mpc_failures_total - first.mpc_failures_total
    );
    let summary = std::fs::read_to_string(out.join("sitl/summary.json")).unwrap_or_default();
    println!(
        "landing judged {} by the server; daemon exit {daemon_exit:?}; files in {}",
        if served.success() {
            "a success"
        } else {
            "a failure"
        },
        out.display()
    );
    if !served.success() {
        println!("{summary}");
    }
    let ok = served.success() && daemon_exit.is_some_and(|s| s.success());
    std::process::exit(i32::from(!ok));
}
