//! The radio and arming path of the control thread allocates nothing after
//! start-up: mapping `InputRc` frames (good, lost, rejected), latching them,
//! assembling the tick's inputs and running the arming checks, counted by a
//! global allocator on this thread.
// Test, bench and example code: an unwrap that fails is the failure report.
#![allow(clippy::unwrap_used)]

use std::time::Duration;

use atmo_core::alloc_counter::thread_allocations;
use atmo_flight::arming::{ArmingMonitor, ArmingObservation, ArmingSettings};
use atmo_flight::inputs::{InputLatch, InputSettings};
use atmo_flight::rc::{RcConfig, RcPilot};
use atmo_io::msg::InputRc;

#[global_allocator]
static GLOBAL: atmo_core::alloc_counter::CountingAllocator =
    atmo_core::alloc_counter::CountingAllocator;

#[test]
fn the_radio_and_the_arming_checks_do_not_allocate() {
    let config = RcConfig::default();
    let mut rc = RcPilot::new(config);
    let mut latch = InputLatch::new(InputSettings {
        rc_timeout: Some(Duration::from_millis(config.timeout_ms)),
        ..InputSettings::defaults(0.0, 0.05)
    });
    let mut monitor = ArmingMonitor::new(ArmingSettings::default(), true);
    let mut frame = InputRc {
        channel_count: 16,
        ..InputRc::default()
    };
    frame.values = [1514; 18];
    let (warm_up, measured) = (200u64, 3000u64);
    let (mut allocations, mut used, mut rejected, mut lost) = (0, 0, 0, 0);
    for tick in 0..warm_up + measured {
        let now_ns = tick * 6_666_667;
        // Sticks sweeping, the kill switch toggling, every 7th frame lost,
        // every 11th with a missing channel.
        frame.values[1] = 1094 + (tick % 840) as u16;
        frame.values[4] = if tick % 50 < 25 { 1094 } else { 1934 };
        frame.rc_lost = tick % 7 == 0;
        frame.channel_count = if tick % 11 == 0 { 4 } else { 16 };
        let before = thread_allocations();
        let verdict = rc.map(&frame);
        if let Ok(reading) = verdict {
            latch.radio(reading, now_ns);
        }
        let assembled = latch.assemble(now_ns);
        monitor.observe(&ArmingObservation {
            now_ns,
            estimates_total: tick,
            pilot_lost: assembled.inputs.pilot_lost,
            driver_lost: false,
            tilt: Some(0.5),
            tilt_velocity: 0.0,
        });
        if tick >= warm_up {
            allocations += thread_allocations() - before;
            match verdict {
                Ok(r) if r.lost => lost += 1,
                Ok(_) => used += 1,
                Err(_) => rejected += 1,
            }
        }
    }
    assert!(
        used > 0 && rejected > 0 && lost > 0,
        "{used} {rejected} {lost}"
    );
    assert_eq!(allocations, 0, "allocations over {measured} ticks");
}
