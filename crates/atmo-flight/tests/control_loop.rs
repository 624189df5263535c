//! The scheduler keeps absolute deadlines (no drift) and counts overruns
//! and skipped deadlines. Driven by a fake clock: no wall-clock assertions.

use std::cell::Cell;

use atmo_flight::control_loop::{Clock, Scheduler};

/// Time moves only when the loop sleeps or the test says so.
struct FakeClock {
    now: Cell<u64>,
}

impl Clock for FakeClock {
    fn now_ns(&self) -> u64 {
        self.now.get()
    }
    fn sleep_until(&self, deadline_ns: u64) {
        if deadline_ns > self.now.get() {
            // Oversleep by 30 us, as a real sleep does.
            self.now.set(deadline_ns + 30_000);
        }
    }
}

const PERIOD: u64 = 6_666_667;

#[test]
fn deadlines_do_not_drift_with_sleep_error_and_compute_time() {
    let clock = FakeClock { now: Cell::new(0) };
    let mut s = Scheduler::new(PERIOD, PERIOD);
    for k in 0..1000u64 {
        let (deadline, woke) = s.wait(&clock);
        assert_eq!(deadline, PERIOD * (k + 1), "tick {k}");
        clock.now.set(clock.now.get() + 2_000_000); // 2 ms of work
        let t = s.finish(&clock, deadline, woke);
        assert!((t.wake_latency - 30e-6).abs() < 1e-12);
        assert!((t.compute - 2e-3).abs() < 1e-12);
        assert!(!t.overrun);
    }
}

#[test]
fn overruns_are_counted_and_far_behind_deadlines_are_skipped() {
    let clock = FakeClock { now: Cell::new(0) };
    let mut s = Scheduler::new(PERIOD, PERIOD);
    let (d, w) = s.wait(&clock);
    clock.now.set(clock.now.get() + PERIOD + 1_000_000); // one slow tick
    let t = s.finish(&clock, d, w);
    assert!(t.overrun);
    assert_eq!(t.overruns_total, 1);
    // The next deadline is already past, but by less than a period: run it at once.
    let (d2, _) = s.wait(&clock);
    assert_eq!(d2, 2 * PERIOD);
    let t2 = s.finish(&clock, d2, clock.now_ns());
    assert_eq!(t2.skipped_total, 0);
    // A stall of five periods skips the missed deadlines instead of bursting.
    clock.now.set(clock.now.get() + 5 * PERIOD);
    let (d3, _) = s.wait(&clock);
    let t3 = s.finish(&clock, d3, clock.now_ns());
    assert!(t3.skipped_total >= 4, "skipped {}", t3.skipped_total);
    assert_eq!(d3 % PERIOD, 0, "still on the original grid");
}
