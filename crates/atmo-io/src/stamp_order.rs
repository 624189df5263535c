//! The order rule of a stamped stream (the state estimate): what the ROS 2
//! node and the simulator's I/O both apply to each estimate's own stamp
//! (the estimator's clock, not the receiver's) before the control thread
//! sees it.
//!
//! - A stamp after the last accepted one: accepted.
//! - A stamp at or before it (a duplicate, or an estimate overtaken by a
//!   newer one): dropped and counted (`out_of_order`).
//! - A backward step of the estimator's clock (a clock jump) would drop
//!   every estimate until its stamps pass the old ones again, which for a
//!   jump of hours is forever (stale estimate, failsafe). So when
//!   [`REBASE_AFTER`] dropped stamps in a row increase among themselves,
//!   the stream is taken to have a new clock: the last of them is accepted
//!   and later stamps are compared with it (counted in `clock_jumps`).
//!   Duplicates (equal stamps) and a reordered pair never form such a run.
//!
//! Fixed size, no allocation.

/// Dropped stamps in a row, increasing among themselves, after which the
/// estimator's clock is taken to have jumped back (at 120 Hz, 25 ms of
/// estimates: less than the flight stack's 50 ms estimate timeout).
pub const REBASE_AFTER: u32 = 3;

/// Accepts or drops each stamp of one stream (see the module).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct StampOrder {
    last_accepted: Option<u64>,
    /// The last dropped stamp and how many dropped ones in a row increased up to it.
    behind: Option<(u64, u32)>,
    out_of_order: u64,
    clock_jumps: u64,
}

impl StampOrder {
    /// Whether the estimate stamped `stamp_ns` is passed on.
    pub fn accept(&mut self, stamp_ns: u64) -> bool {
        if self.last_accepted.is_none_or(|last| stamp_ns > last) {
            self.last_accepted = Some(stamp_ns);
            self.behind = None;
            return true;
        }
        let run = match self.behind {
            Some((previous, run)) if stamp_ns > previous => run + 1,
            _ => 1,
        };
        if run >= REBASE_AFTER {
            self.clock_jumps += 1;
            self.last_accepted = Some(stamp_ns);
            self.behind = None;
            return true;
        }
        self.behind = Some((stamp_ns, run));
        self.out_of_order += 1;
        false
    }

    /// Estimates dropped: stamps at or before the last accepted one.
    pub fn out_of_order(&self) -> u64 {
        self.out_of_order
    }

    /// Backward clock steps taken as a new clock.
    pub fn clock_jumps(&self) -> u64 {
        self.clock_jumps
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn accepted(order: &mut StampOrder, stamps: &[u64]) -> Vec<u64> {
        stamps
            .iter()
            .copied()
            .filter(|s| order.accept(*s))
            .collect()
    }

    #[test]
    fn duplicates_and_reordered_stamps_are_dropped_and_counted() {
        let mut order = StampOrder::default();
        let kept = accepted(&mut order, &[1, 2, 2, 4, 3, 5, 5, 5, 5, 6]);
        assert_eq!(kept, [1, 2, 4, 5, 6]);
        assert_eq!((order.out_of_order(), order.clock_jumps()), (5, 0));
    }

    #[test]
    fn a_backward_clock_jump_rebases_after_a_run_of_increasing_stamps() {
        let mut order = StampOrder::default();
        let kept = accepted(&mut order, &[100, 110, 120, 20, 30, 40, 50, 60]);
        assert_eq!(kept, [100, 110, 120, 40, 50, 60]);
        assert_eq!((order.out_of_order(), order.clock_jumps()), (2, 1));
        // A forward jump is simply newer.
        assert!(order.accept(1_000_000));
        assert_eq!(order.clock_jumps(), 1);
    }
}
