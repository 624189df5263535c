//! After start-up the driver's tick allocates nothing: not when running,
//! not on a corrupt answer, not on a silent board (errors are `Copy`,
//! frames live in fixed buffers, the serial waits are our own polls).
#![allow(clippy::unwrap_used)]

mod common;

use atmo_core::alloc_counter::{CountingAllocator, count};
use atmo_roboclaw::driver::{DriverCommand, Phase};
use atmo_roboclaw::sim::SimConfig;
use common::Rig;

#[global_allocator]
static GLOBAL: CountingAllocator = CountingAllocator;

#[test]
fn the_tick_does_not_allocate() {
    let mut rig = Rig::new(SimConfig::tilt(500.0), "tilt.toml");
    assert!(rig.run_until(3.0, None, |r| r.driver.phase() == Phase::Running));
    rig.tick(Some(DriverCommand::TiltVelocity(-0.1)));
    let ((), allocations) = count(|| {
        for i in 0..300 {
            match i {
                100 => rig.sim(|b| b.faults.corrupt_next = 3),
                200 => rig.sim(|b| b.faults.silent_next = 2),
                _ => {}
            }
            // Commands stop for a while: the watchdog path too.
            let command = (i % 100 < 50).then_some(DriverCommand::TiltVelocity(-0.1));
            rig.tick(command);
        }
    });
    let h = *rig.board.health();
    assert!(h.crc_errors + h.bad_answers >= 3 && h.no_answer >= 2, "{h}");
    assert!(rig.driver.counters().watchdog_stops >= 2);
    assert_eq!(allocations, 0, "allocations in 300 ticks");
}
