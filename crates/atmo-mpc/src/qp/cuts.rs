//! Solves cut by the wall-clock time limit, recorded so that a replay can
//! cut them again.
//!
//! The MPC is a pure function of its inputs except for one thing: the
//! per-solve time limit, which ends a Clarabel solve after however many
//! interior-point iterations the machine managed. Clarabel itself is
//! deterministic, so a cut solve is reproduced exactly by ending it at the
//! same iteration. The solves of a *window* (the flight stack opens one
//! before each preparation phase: the preparation and the next tick's
//! feedback, re-plans included) are numbered from 0, whichever of the
//! controller's QPs (nominal or tilt-planning) makes them: the window is the
//! controller's, passed to each solve. Every cut is recorded
//! as (ordinal, iteration). A replay opens each window with the recorded
//! cuts as a script and the wall clock lifted, so each scripted solve ends
//! where it ended in flight and no other one is cut.
//!
//! A window holds at most [`MAX_CUTS`] cuts: every solve a window can hold
//! (the preparation, the warm-up's, four re-plan iterations of a
//! preparation and a feedback each, and the feedback: 11) with one to spare.
//! More are counted in `overflow` and make the window unreplayable, which a
//! replay reports.

/// Cuts one window can record.
pub const MAX_CUTS: usize = 12;

/// The cut solves of one window: `solve[i]` (its ordinal in the window)
/// ended at interior-point iteration `iteration[i]`, for `i < count`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct SolverCuts {
    pub count: u8,
    pub solve: [u8; MAX_CUTS],
    pub iteration: [u32; MAX_CUTS],
    /// Cuts beyond [`MAX_CUTS`] (or at an ordinal above 255), not recorded.
    pub overflow: u32,
}

impl SolverCuts {
    /// Records that solve `ordinal` of the window ended at `iteration`.
    pub fn record(&mut self, ordinal: u32, iteration: u32) {
        let slot = usize::from(self.count);
        match u8::try_from(ordinal) {
            Ok(ordinal) if slot < MAX_CUTS => {
                self.solve[slot] = ordinal;
                self.iteration[slot] = iteration;
                self.count += 1;
            }
            _ => self.overflow = self.overflow.saturating_add(1),
        }
    }

    /// The iteration solve `ordinal` was cut at, if it was.
    pub fn cut_of(&self, ordinal: u32) -> Option<u32> {
        self.recorded()
            .find(|(solve, _)| u32::from(*solve) == ordinal)
            .map(|(_, iteration)| iteration)
    }

    /// `(ordinal, iteration)` of each recorded cut.
    pub fn recorded(&self) -> impl Iterator<Item = (u8, u32)> + '_ {
        let n = usize::from(self.count).min(MAX_CUTS);
        self.solve[..n]
            .iter()
            .copied()
            .zip(self.iteration[..n].iter().copied())
    }

    pub fn is_empty(&self) -> bool {
        self.count == 0 && self.overflow == 0
    }
}

/// The solver's side of a window: the solves numbered so far, the cuts seen,
/// and the script of a replay.
#[derive(Debug, Clone, Copy, Default)]
pub struct CutWindow {
    solves: u32,
    cuts: SolverCuts,
    script: Option<SolverCuts>,
}

impl CutWindow {
    /// Starts a window; `script`: the cuts to repeat (a replay), `None` in flight.
    pub fn open(&mut self, script: Option<SolverCuts>) {
        *self = Self {
            script,
            ..Self::default()
        };
    }

    /// The next solve's ordinal and, in a replay, the iteration to end it
    /// at (`Some(None)`: a replay, not cut; `None`: in flight, the wall clock).
    pub fn next_solve(&mut self) -> (u32, Option<Option<u32>>) {
        let ordinal = self.solves;
        self.solves = self.solves.saturating_add(1);
        (ordinal, self.script.map(|s| s.cut_of(ordinal)))
    }

    pub fn record(&mut self, ordinal: u32, iteration: u32) {
        self.cuts.record(ordinal, iteration);
    }

    /// The cuts of the window so far.
    pub fn cuts(&self) -> SolverCuts {
        self.cuts
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn records_up_to_the_cap_and_counts_the_rest() {
        let mut cuts = SolverCuts::default();
        for k in 0..14 {
            cuts.record(k, 10 + k);
        }
        assert_eq!(cuts.count as usize, MAX_CUTS);
        assert_eq!(cuts.overflow, 2);
        assert_eq!(cuts.cut_of(2), Some(12));
        assert_eq!(cuts.cut_of(13), None);
        cuts = SolverCuts::default();
        cuts.record(300, 1);
        assert_eq!((cuts.count, cuts.overflow), (0, 1));
    }

    #[test]
    fn a_window_numbers_its_solves_and_follows_its_script() {
        let mut window = CutWindow::default();
        assert_eq!(window.next_solve(), (0, None));
        let mut script = SolverCuts::default();
        script.record(1, 7);
        window.open(Some(script));
        assert_eq!(window.next_solve(), (0, Some(None)));
        assert_eq!(window.next_solve(), (1, Some(Some(7))));
        window.record(1, 7);
        assert_eq!(window.cuts(), script);
    }
}
