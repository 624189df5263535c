//! The cost of a replayable flight log.
//!
//! - `flight_log/log_tick`: the control thread's cost per tick of logging
//!   it (`TickChannels::log_tick`: the `TickInputs` and `MpcStatus` records
//!   into the logger's queue, accepted; the writer drains between batches,
//!   outside the timed region). Budget: <= 1 us.
//! - `replay/wheel_landing_14s`: `atmo-daemon replay` of the README landing's
//!   log (14 s, 2100 ticks): read the log, rebuild the flight stack from
//!   its configuration, step it through every tick, compare every output.
//!   Target: >= 50x real time, i.e. <= 0.3 s.
//!
//! `cargo bench -p atmo --bench replay`
// Test, bench and example code: an unwrap that fails is the failure report.
#![allow(clippy::unwrap_used)]

use std::hint::black_box;
use std::path::PathBuf;
use std::time::{Duration, Instant};

use atmo_flight::control_loop::TickTiming;
use atmo_flight::flight_log::TickChannels;
use atmo_flight::replay::{CutReplay, RecordedFlight, replay};
use atmo_flight::telemetry::status_message;
use atmo_io::mcap_log::{LoggerOptions, McapLogger};
use atmo_sim::closed_loop::{ControllerConfig, STATUS_TOPIC, TickRecord, fly_logged};
use atmo_sim::scenario::Scenario;
use criterion::{Criterion, criterion_group, criterion_main};

fn landing_log(records: &mut Vec<TickRecord>) -> PathBuf {
    let scenario_path: PathBuf = [
        env!("CARGO_MANIFEST_DIR"),
        "config",
        "scenarios",
        "wheel_landing.toml",
    ]
    .iter()
    .collect();
    let scenario = Scenario::load(&scenario_path).unwrap();
    let controller = ControllerConfig::atmo().unwrap().deterministic();
    let path = std::env::temp_dir().join(format!("atmo-replay-bench-{}.mcap", std::process::id()));
    fly_logged(&scenario, &controller, &path, |r| records.push(*r)).unwrap();
    path
}

fn bench(c: &mut Criterion) {
    let mut records = Vec::new();
    let log_path = landing_log(&mut records);

    let queue_path =
        std::env::temp_dir().join(format!("atmo-log-tick-bench-{}.mcap", std::process::id()));
    let (log, thread) = McapLogger::spawn(&queue_path, LoggerOptions::default()).unwrap();
    let channels = TickChannels::register(&log, STATUS_TOPIC).unwrap();
    let statuses: Vec<_> = records
        .iter()
        .take(1024)
        .enumerate()
        .map(|(k, r)| status_message(k as u64, &r.inputs, &r.outputs, &TickTiming::default()))
        .collect();
    c.bench_function("flight_log/log_tick", |b| {
        b.iter_custom(|iters| {
            let mut total = Duration::ZERO;
            let mut done = 0;
            while done < iters {
                // Two records a tick: a batch fits the default queue (4096).
                let batch = (iters - done).min(1024);
                while log.queued() > 0 {
                    std::thread::sleep(Duration::from_micros(50));
                }
                let t0 = Instant::now();
                for k in 0..batch {
                    let i = k as usize % statuses.len();
                    let r = &records[i];
                    channels.log_tick(&log, k, black_box(&r.inputs), &r.outputs, &statuses[i]);
                }
                total += t0.elapsed();
                done += batch;
            }
            total
        });
    });
    log.finish();
    let written = thread.join().unwrap();
    assert_eq!(written.dropped, 0, "the timed records were all accepted");
    std::fs::remove_file(&queue_path).unwrap();

    let mut group = c.benchmark_group("replay");
    group.sample_size(10);
    group.bench_function("wheel_landing_14s", |b| {
        b.iter(|| {
            let flight = RecordedFlight::read(&log_path, STATUS_TOPIC).unwrap();
            let config = RecordedFlight::config(&flight.files).unwrap();
            let report = replay(&flight, &config, CutReplay::AsLogged, |_| {}).unwrap();
            assert!(report.identical() && report.ticks == 2100);
            black_box(report)
        });
    });
    group.finish();
    std::fs::remove_file(&log_path).unwrap();
}

criterion_group!(benches, bench);
criterion_main!(benches);
