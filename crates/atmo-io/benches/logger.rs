//! Cost of MCAP logging per control tick.
//!
//! - `try_log_status`: the control thread's cost of one `try_log` of an
//!   `MpcStatus` that is accepted (the queue has room; the writer drains it
//!   between batches, outside the timed region).
//! - `try_log_status_full`: the same call when the queue is full (dropped).
//! - `encode_status`: CDR encoding of one status on the writer thread.
//! - `writer_status`: wall time per status from `try_log` until the writer
//!   has encoded and written it (zstd chunks, flush every 0.5 s): the writer
//!   thread's cost per tick.
// Test, bench and example code: an unwrap that fails is the failure report.
#![allow(clippy::unwrap_used)]

use std::hint::black_box;
use std::time::{Duration, Instant};

use atmo_io::mcap_log::{LoggerOptions, McapLogger};
use atmo_io::msg::{Label, Mode, MpcStatus, SolverStatus, encode};
use criterion::{Criterion, criterion_group, criterion_main};

fn status(k: u64) -> MpcStatus {
    let mut s = MpcStatus {
        stamp_ns: k * 6_666_667,
        ros_stamp_ns: 1_700_000_000_000_000_000 + k * 6_666_667,
        tick: k,
        mode: Mode::Flight,
        transition: Label::EMPTY,
        solver_status: SolverStatus::Solved,
        alpha: 0.5,
        varphi: 0.3,
        ..MpcStatus::default()
    };
    for i in 0..12 {
        s.state[i] = (k as f64 * 0.01 + i as f64).sin();
        s.reference[i] = 0.1 * i as f64;
        s.predicted_next[i] = s.state[i] + 1e-3;
    }
    s
}

fn wait_drained(log: &atmo_io::mcap_log::LoggerHandle) {
    while log.queued() > 0 {
        std::thread::sleep(Duration::from_micros(50));
    }
}

fn bench(c: &mut Criterion) {
    let dir = std::env::temp_dir();
    let statuses: Vec<MpcStatus> = (0..1024).map(status).collect();

    let path = dir.join(format!("atmo-io-bench-{}.mcap", std::process::id()));
    let (log, thread) = McapLogger::spawn(&path, LoggerOptions::default()).unwrap();
    let ch = log.channel::<MpcStatus>("/atmo/status").unwrap();
    c.bench_function("try_log_status", |b| {
        b.iter_custom(|iters| {
            let mut total = Duration::ZERO;
            let mut done = 0;
            while done < iters {
                let batch = (iters - done).min(1024);
                wait_drained(&log);
                let t0 = Instant::now();
                for k in 0..batch {
                    black_box(log.try_log(ch, k, &statuses[k as usize]));
                }
                total += t0.elapsed();
                done += batch;
            }
            total
        });
    });
    c.bench_function("writer_status", |b| {
        b.iter_custom(|iters| {
            wait_drained(&log);
            let t0 = Instant::now();
            let mut sent = 0;
            while sent < iters {
                if log.try_log(ch, sent, &statuses[(sent % 1024) as usize]) {
                    sent += 1;
                } else {
                    std::thread::yield_now();
                }
            }
            wait_drained(&log);
            t0.elapsed()
        });
    });
    log.finish();
    thread.join().unwrap();
    std::fs::remove_file(&path).unwrap();

    let options = LoggerOptions {
        queue_capacity: 1,
        ..LoggerOptions::default()
    };
    let (log, thread) = McapLogger::spawn(&path, options).unwrap();
    let ch = log.channel::<MpcStatus>("/atmo/status").unwrap();
    log.try_log(ch, 0, &statuses[0]);
    c.bench_function("try_log_status_full", |b| {
        // The writer may take the one record now and then: mostly drops.
        b.iter(|| black_box(log.try_log(ch, 0, &statuses[0])));
    });
    log.finish();
    thread.join().unwrap();
    std::fs::remove_file(&path).unwrap();

    let mut buffer = Vec::with_capacity(1024);
    c.bench_function("encode_status", |b| {
        b.iter(|| encode(black_box(&statuses[7]), &mut buffer).unwrap());
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
