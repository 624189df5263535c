//! `try_log` of the fixed-size message kinds does not allocate: a counting
//! global allocator counts the allocations made on this thread while the
//! control-path calls run (the writer thread allocates freely).

#![allow(unsafe_code)] // a GlobalAlloc impl is unsafe by definition

mod support;

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::atomic::{AtomicU64, Ordering};

use atmo_io::mcap_log::{LoggerOptions, McapLogger, read_log};
use atmo_io::msg::{ActuatorMotors, MpcStatus};
use support::{drive, motors, status};

struct Counting;

static ALLOCATIONS: AtomicU64 = AtomicU64::new(0);

thread_local! {
    static COUNTING: Cell<bool> = const { Cell::new(false) };
}

// SAFETY: forwards to the system allocator unchanged; only counts.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        if COUNTING.with(Cell::get) {
            ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        }
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: same contract as the caller's.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        if COUNTING.with(Cell::get) {
            ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        }
        // SAFETY: same contract as the caller's.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

fn counted<R>(f: impl FnOnce() -> R) -> (R, u64) {
    let before = ALLOCATIONS.load(Ordering::Relaxed);
    COUNTING.with(|c| c.set(true));
    let r = f();
    COUNTING.with(|c| c.set(false));
    (r, ALLOCATIONS.load(Ordering::Relaxed) - before)
}

#[test]
fn try_log_does_not_allocate() {
    // The counter itself works.
    let (_, n) = counted(|| std::hint::black_box(vec![1u8; 16]));
    assert_eq!(n, 1);

    let path = std::env::temp_dir().join(format!("atmo-io-noalloc-{}.mcap", std::process::id()));
    let options = LoggerOptions {
        queue_capacity: 64,
        ..LoggerOptions::default()
    };
    let (log, thread) = McapLogger::spawn(&path, options).unwrap();
    let status_ch = log.channel::<MpcStatus>("/atmo/status").unwrap();
    let motors_ch = log
        .channel::<ActuatorMotors>("/fmu/in/actuator_motors")
        .unwrap();
    let drive_ch = log.channel("/atmo/cmd_drive").unwrap();
    // Prebuilt records (building them is the flight stack's business).
    let statuses: Vec<MpcStatus> = (0..3000).map(status).collect();
    let commands: Vec<ActuatorMotors> = (0..3000).map(motors).collect();
    let drives: Vec<_> = (0..3000).map(drive).collect();

    // 20 s of 150 Hz ticks in bursts: some records go through, some are
    // dropped (a 64-slot queue) — both paths must be allocation-free.
    let (accepted, n) = counted(|| {
        let mut accepted = 0u64;
        for k in 0..3000 {
            accepted += u64::from(log.try_log(status_ch, k as u64, &statuses[k]));
            accepted += u64::from(log.try_log(motors_ch, k as u64, &commands[k]));
            accepted += u64::from(log.try_log(drive_ch, k as u64, &drives[k]));
            let _ = log.dropped();
        }
        accepted
    });
    assert_eq!(n, 0, "try_log allocated {n} times");
    assert!(accepted > 0);
    eprintln!("accepted {accepted}, dropped {}", log.dropped());
    log.finish();
    thread.join().unwrap();
    let written = read_log(&path).unwrap();
    assert!(written.len() as u64 > accepted);
    std::fs::remove_file(&path).unwrap();
}
