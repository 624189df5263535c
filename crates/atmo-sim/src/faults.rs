//! Deterministic fault injection on the closed loop's input path: a
//! scenario's `[faults]` table (docs/faults.md: each fault, the flight
//! stack's defined reaction and its test).
//!
//! The injector sits between the plant's sensors and [`crate::sim_io::SimIo`]:
//! the motion capture's estimates go through a FIFO transport that can
//! drop, hold, delay, duplicate and reorder them and that stamps them with
//! the estimator's own clock (which can jump); the drivers can die; the
//! MPC's solves can be cut as the wall-clock time limit cuts them. Times
//! are plant seconds from the start; a window `[t, t + duration)` applies to
//! the estimates *published* in it. Same scenario, same faults, same flight.
//!
//! ```toml
//! [[faults.estimate_dropout]]      # estimates published in the window are lost
//! t = 3.0
//! duration = 0.03
//! [[faults.estimate_burst]]        # ... held and delivered at once at its end
//! t = 3.0
//! duration = 0.3
//! [[faults.estimate_latency]]      # ... delivered `delay` s late (FIFO: later ones queue behind)
//! t = 3.0
//! duration = 0.5
//! delay = 0.03
//! [[faults.estimate_duplicate]]    # ... delivered twice
//! t = 3.0
//! duration = 1.0
//! [[faults.estimate_reorder]]      # ... delivered in swapped pairs
//! t = 3.0
//! duration = 1.0
//! [[faults.estimate_clock_jump]]   # the estimator's clock steps by `jump` s from t on
//! t = 3.0
//! jump = -5.0
//! [faults.driver_death]            # every driver dies: `delay` s after `t`, or after
//! mode = "transition"              # the first tick in `mode` (one of the two)
//! delay = 0.1
//! [[faults.solver_overrun]]        # every MPC solve in the window is cut by the
//! t = 3.0                          # time limit at interior-point `iteration`
//! duration = 0.05
//! iteration = 1
//! ```
//!
//! The actuator side (`[faults.actuators]`: rotors, tilt encoder, contact
//! signal) is [`crate::actuator_faults`].
//!
//! Dead drivers: heartbeats stop (the flight stack's `driver_lost`), the
//! encoder and contact readings stop, and the actuators get nothing: the
//! motor controllers stop the rotors on signal loss, the self-locking
//! linkage holds its tilt, the wheels stop.

use std::collections::VecDeque;
use std::path::Path;

use atmo_core::config_file::Checker;
use atmo_core::model::State;
use atmo_core::params::Params as _;
use atmo_flight::Mode;
use atmo_mpc::SolverCuts;
use atmo_mpc::qp::cuts::MAX_CUTS;

use crate::actuator_faults::Onset;

use crate::error::Result;

/// The estimator's clock at plant time 0, s: it started before the flight,
/// so a backward jump of up to this much keeps its stamps positive.
pub const ESTIMATOR_CLOCK_ORIGIN_S: f64 = 1000.0;

/// Longest window or delay, s (bounds the transport's queue).
pub const MAX_FAULT_SPAN_S: f64 = 60.0;

atmo_core::params! {
    /// A window of plant time, `[t, t + duration)`.
    #[derive(Debug, Clone, Copy, PartialEq)]
    pub struct FaultWindow {
        /// Start (within the scenario's duration).
        pub t: f64, unit "s";
        /// Length.
        pub duration: f64, range 1e-3..=MAX_FAULT_SPAN_S, unit "s";
    }
}

atmo_core::params! {
    /// `[[faults.estimate_latency]]`.
    #[derive(Debug, Clone, Copy, PartialEq)]
    pub struct LatencySpike {
        /// Start (within the scenario's duration).
        pub t: f64, unit "s";
        /// Length.
        pub duration: f64, range 1e-3..=MAX_FAULT_SPAN_S, unit "s";
        /// Added to each estimate's delivery.
        pub delay: f64, range 1e-4..=MAX_FAULT_SPAN_S, unit "s";
    }
}

atmo_core::params! {
    /// `[[faults.estimate_clock_jump]]`.
    #[derive(Debug, Clone, Copy, PartialEq)]
    pub struct ClockJump {
        /// When (within the scenario's duration).
        pub t: f64, unit "s";
        /// The step of the estimator's clock (negative: back).
        pub jump: f64, range -ESTIMATOR_CLOCK_ORIGIN_S..=1e6, unit "s";
    }
}

/// `[faults.driver_death]`: the drivers stop at an [`Onset`] (`t`, or the
/// first tick in `mode`, e.g. "transition", plus `delay`).
pub type DriverDeath = Onset;

atmo_core::params! {
    /// `[[faults.solver_overrun]]`.
    #[derive(Debug, Clone, Copy, PartialEq)]
    pub struct SolverOverrun {
        /// Start (within the scenario's duration).
        pub t: f64, unit "s";
        /// Length.
        pub duration: f64, range 1e-3..=MAX_FAULT_SPAN_S, unit "s";
        /// Interior-point iteration each solve is cut at (0: before the first).
        pub iteration: u32 = 1, range 0..=1000;
    }
}

atmo_core::params! {
    /// A scenario's `[faults]` (every list empty: no fault).
    #[derive(Debug, Clone, PartialEq)]
    pub struct FaultsConfig: Default {
        /// Estimates lost.
        pub estimate_dropout: Vec<FaultWindow> = Vec::new();
        /// Estimates held back and delivered at once.
        pub estimate_burst: Vec<FaultWindow> = Vec::new();
        /// Estimates delivered late.
        pub estimate_latency: Vec<LatencySpike> = Vec::new();
        /// Estimates delivered twice.
        pub estimate_duplicate: Vec<FaultWindow> = Vec::new();
        /// Estimates delivered out of order.
        pub estimate_reorder: Vec<FaultWindow> = Vec::new();
        /// Steps of the estimator's clock.
        pub estimate_clock_jump: Vec<ClockJump> = Vec::new();
        /// The drivers stop.
        pub driver_death: Option<DriverDeath> = None;
        /// Solves cut short.
        pub solver_overrun: Vec<SolverOverrun> = Vec::new();
        /// Faults of the rotors, the tilt encoder and the contact signal
        /// ([`crate::actuator_faults`]).
        pub actuators: crate::actuator_faults::ActuatorFaults =
            crate::actuator_faults::ActuatorFaults::default();
    }
}

impl FaultsConfig {
    /// Range checks; errors name `file` and the key (`faults.<kind>[i].<field>`).
    ///
    /// # Errors
    /// A value out of range, a driver death with both or neither of `t` and
    /// `mode`, or a mode that is not one.
    pub fn validate(&self, file: &Path, duration: f64) -> Result<()> {
        let c = Checker::new(file);
        self.check(&c, "faults")?;
        // What the declarations cannot say: every start lies within the
        // scenario.
        let starts: [(&str, &mut dyn Iterator<Item = f64>); 7] = [
            (
                "estimate_dropout",
                &mut self.estimate_dropout.iter().map(|w| w.t),
            ),
            (
                "estimate_burst",
                &mut self.estimate_burst.iter().map(|w| w.t),
            ),
            (
                "estimate_latency",
                &mut self.estimate_latency.iter().map(|w| w.t),
            ),
            (
                "estimate_duplicate",
                &mut self.estimate_duplicate.iter().map(|w| w.t),
            ),
            (
                "estimate_reorder",
                &mut self.estimate_reorder.iter().map(|w| w.t),
            ),
            (
                "estimate_clock_jump",
                &mut self.estimate_clock_jump.iter().map(|w| w.t),
            ),
            (
                "solver_overrun",
                &mut self.solver_overrun.iter().map(|w| w.t),
            ),
        ];
        for (kind, list) in starts {
            for (i, t) in list.enumerate() {
                c.within(&format!("faults.{kind}[{i}].t"), t, 0.0, duration)?;
            }
        }
        if let Some(d) = &self.driver_death {
            d.check_within(&c, "faults.driver_death", duration)?;
        }
        self.actuators.validate(file, duration)?;
        Ok(())
    }

    pub fn is_empty(&self) -> bool {
        *self == Self::default()
    }
}

/// An estimate on its way to the flight stack.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Delivery {
    /// Plant time it reaches the receiver, ns.
    pub at_ns: u64,
    /// Its stamp on the estimator's clock, ns.
    pub stamp_ns: u64,
    pub state: State,
}

/// What the injector did so far.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct FaultCounts {
    pub estimates_published: u64,
    pub estimates_dropped: u64,
    pub estimates_held: u64,
    pub estimates_delayed: u64,
    pub estimates_duplicated: u64,
    pub estimates_reordered: u64,
}

fn ns(t: f64) -> u64 {
    crate::sim_time::time_ns(t)
}

fn in_window(now_ns: u64, t: f64, duration: f64) -> bool {
    (ns(t)..ns(t + duration)).contains(&now_ns)
}

/// The runtime side of a [`FaultsConfig`] (see the module).
#[derive(Debug, Clone)]
pub struct FaultInjector {
    config: FaultsConfig,
    /// The transport, first in first out.
    queue: VecDeque<Delivery>,
    /// A reordered estimate waiting for its successor.
    held_for_swap: Option<Delivery>,
    /// Plant time the drivers die, ns, once known.
    drivers_die_ns: Option<u64>,
    counts: FaultCounts,
}

impl FaultInjector {
    /// The injector of `config` (validated: [`FaultsConfig::validate`]).
    pub fn new(config: &FaultsConfig) -> Self {
        let drivers_die_ns = config
            .driver_death
            .as_ref()
            .and_then(|d| d.t.map(|t| ns(t + d.delay)));
        // Sized once: at most one estimate per plant step (1 kHz) is held
        // over the longest span, twice if duplicated.
        let span = config
            .estimate_burst
            .iter()
            .map(|w| w.duration)
            .chain(config.estimate_latency.iter().map(|s| s.delay))
            .fold(0.0, f64::max);
        Self {
            config: config.clone(),
            queue: VecDeque::with_capacity(2 * (span * 1000.0).ceil() as usize + 4),
            held_for_swap: None,
            drivers_die_ns,
            counts: FaultCounts::default(),
        }
    }

    pub fn counts(&self) -> FaultCounts {
        self.counts
    }

    /// The estimator's stamp of an instant `measured_ns` of plant time: its
    /// clock's origin plus every jump made by `now_ns`.
    fn estimator_stamp(&self, now_ns: u64, measured_ns: u64) -> u64 {
        let jumped: f64 = self
            .config
            .estimate_clock_jump
            .iter()
            .filter(|j| now_ns >= ns(j.t))
            .map(|j| j.jump)
            .sum();
        let origin = ESTIMATOR_CLOCK_ORIGIN_S + jumped;
        (measured_ns as f64 + origin.max(0.0) * 1e9) as u64
    }

    /// The motion capture published `state` (describing plant time
    /// `measured_ns`) at plant time `now_ns`: into the transport.
    pub fn publish(&mut self, now_ns: u64, measured_ns: u64, state: State) {
        self.counts.estimates_published += 1;
        let c = &self.config;
        let within = |w: &FaultWindow| in_window(now_ns, w.t, w.duration);
        if c.estimate_dropout.iter().any(within) {
            self.counts.estimates_dropped += 1;
            return;
        }
        let mut at_ns = now_ns;
        if let Some(w) = c.estimate_burst.iter().find(|w| within(w)) {
            at_ns = ns(w.t + w.duration);
            self.counts.estimates_held += 1;
        }
        if let Some(s) = c
            .estimate_latency
            .iter()
            .find(|s| in_window(now_ns, s.t, s.duration))
        {
            at_ns += ns(s.delay);
            self.counts.estimates_delayed += 1;
        }
        let delivery = Delivery {
            at_ns,
            stamp_ns: self.estimator_stamp(now_ns, measured_ns),
            state,
        };
        let copies = if c.estimate_duplicate.iter().any(within) {
            self.counts.estimates_duplicated += 1;
            2
        } else {
            1
        };
        let reorder = c.estimate_reorder.iter().any(within);
        for _ in 0..copies {
            if reorder {
                match self.held_for_swap.take() {
                    // This one overtakes the one held.
                    Some(earlier) => {
                        self.queue.push_back(delivery);
                        self.queue.push_back(Delivery { at_ns, ..earlier });
                        self.counts.estimates_reordered += 1;
                    }
                    None => self.held_for_swap = Some(delivery),
                }
            } else {
                self.release_held();
                self.queue.push_back(delivery);
            }
        }
    }

    /// A reordered estimate left without a successor goes on as it is.
    fn release_held(&mut self) {
        if let Some(held) = self.held_for_swap.take() {
            self.queue.push_back(held);
        }
    }

    /// The next estimate that has reached the receiver by `now_ns` (first
    /// in, first out: a late one holds up those behind it).
    pub fn next_delivery(&mut self, now_ns: u64) -> Option<Delivery> {
        if self
            .config
            .estimate_reorder
            .iter()
            .all(|w| now_ns >= ns(w.t + w.duration))
        {
            self.release_held();
        }
        if self.queue.front().is_some_and(|d| d.at_ns <= now_ns) {
            self.queue.pop_front()
        } else {
            None
        }
    }

    /// The flight stack is in `mode` at plant time `now_ns` (after a tick).
    pub fn on_mode(&mut self, mode: Mode, now_ns: u64) {
        if self.drivers_die_ns.is_none()
            && let Some(d) = &self.config.driver_death
            && d.mode.as_deref() == Some(mode.name())
        {
            self.drivers_die_ns = Some(now_ns + ns(d.delay));
        }
    }

    /// Whether the drivers are dead at `now_ns`.
    pub fn drivers_dead(&self, now_ns: u64) -> bool {
        self.drivers_die_ns.is_some_and(|at| now_ns >= at)
    }

    /// The cuts of the MPC solve window opened at `now_ns`: every solve cut
    /// at the overrun's iteration while one is active, else `None` (the
    /// wall clock, lifted in a deterministic simulation).
    pub fn cut_script(&self, now_ns: u64) -> Option<SolverCuts> {
        let overrun = self
            .config
            .solver_overrun
            .iter()
            .find(|o| in_window(now_ns, o.t, o.duration))?;
        let mut cuts = SolverCuts::default();
        for solve in 0..MAX_CUTS as u32 {
            cuts.record(solve, overrun.iteration);
        }
        Some(cuts)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: u64 = 1_000_000;

    fn fly_transport(config: &FaultsConfig, until_ms: u64) -> Vec<(u64, u64)> {
        // An estimate every 10 ms measured 5 ms earlier; (delivered, measured) ms.
        let mut injector = FaultInjector::new(config);
        let mut got = Vec::new();
        for now in 0..=until_ms {
            if now % 10 == 0 && now >= 10 {
                injector.publish(now * MS, (now - 5) * MS, State::zeros());
            }
            while let Some(d) = injector.next_delivery(now * MS) {
                let measured = d.stamp_ns / MS - (ESTIMATOR_CLOCK_ORIGIN_S * 1e3) as u64;
                got.push((now, measured));
            }
        }
        got
    }

    fn window(t: f64, duration: f64) -> FaultWindow {
        FaultWindow { t, duration }
    }

    #[test]
    fn dropout_burst_latency_duplicate_and_reorder_shape_the_stream() {
        let none = fly_transport(&FaultsConfig::default(), 60);
        assert_eq!(
            none,
            [(10, 5), (20, 15), (30, 25), (40, 35), (50, 45), (60, 55)]
        );
        let dropout = FaultsConfig {
            estimate_dropout: vec![window(0.02, 0.02)],
            ..FaultsConfig::default()
        };
        assert_eq!(
            fly_transport(&dropout, 60),
            [(10, 5), (40, 35), (50, 45), (60, 55)]
        );
        let burst = FaultsConfig {
            estimate_burst: vec![window(0.02, 0.025)],
            ..FaultsConfig::default()
        };
        assert_eq!(
            fly_transport(&burst, 60),
            [(10, 5), (45, 15), (45, 25), (45, 35), (50, 45), (60, 55)]
        );
        let latency = FaultsConfig {
            estimate_latency: vec![LatencySpike {
                t: 0.02,
                duration: 0.01,
                delay: 0.025,
            }],
            ..FaultsConfig::default()
        };
        // The late one holds up the next (first in, first out).
        assert_eq!(
            fly_transport(&latency, 60),
            [(10, 5), (45, 15), (45, 25), (45, 35), (50, 45), (60, 55)]
        );
        let duplicate = FaultsConfig {
            estimate_duplicate: vec![window(0.02, 0.01)],
            ..FaultsConfig::default()
        };
        assert_eq!(
            fly_transport(&duplicate, 40),
            [(10, 5), (20, 15), (20, 15), (30, 25), (40, 35)]
        );
        let reorder = FaultsConfig {
            estimate_reorder: vec![window(0.02, 0.03)],
            ..FaultsConfig::default()
        };
        assert_eq!(
            fly_transport(&reorder, 60),
            [(10, 5), (30, 25), (30, 15), (50, 35), (50, 45), (60, 55)]
        );
    }

    #[test]
    fn clock_jump_steps_the_stamps_from_its_time_on() {
        let jump = FaultsConfig {
            estimate_clock_jump: vec![ClockJump {
                t: 0.03,
                jump: -0.5,
            }],
            ..FaultsConfig::default()
        };
        let mut injector = FaultInjector::new(&jump);
        injector.publish(20 * MS, 15 * MS, State::zeros());
        injector.publish(30 * MS, 25 * MS, State::zeros());
        let a = injector.next_delivery(30 * MS).unwrap().stamp_ns;
        let b = injector.next_delivery(30 * MS).unwrap().stamp_ns;
        assert_eq!(a as i64 - b as i64, 490 * MS as i64);
    }

    #[test]
    fn solver_overrun_scripts_every_solve_of_its_window() {
        let overrun = FaultsConfig {
            solver_overrun: vec![SolverOverrun {
                t: 1.0,
                duration: 0.5,
                iteration: 2,
            }],
            ..FaultsConfig::default()
        };
        let injector = FaultInjector::new(&overrun);
        assert_eq!(injector.cut_script(999 * MS), None);
        let cuts = injector.cut_script(1000 * MS).unwrap();
        assert_eq!((cuts.cut_of(0), cuts.cut_of(11)), (Some(2), Some(2)));
        assert_eq!(injector.cut_script(1500 * MS), None);
    }

    #[test]
    fn driver_death_after_the_first_tick_in_a_mode() {
        let death = FaultsConfig {
            driver_death: Some(DriverDeath {
                t: None,
                mode: Some("transition".into()),
                delay: 0.1,
            }),
            ..FaultsConfig::default()
        };
        let mut injector = FaultInjector::new(&death);
        injector.on_mode(Mode::Morphing, 100 * MS);
        assert!(!injector.drivers_dead(10_000 * MS));
        injector.on_mode(Mode::Transition, 2000 * MS);
        injector.on_mode(Mode::Transition, 2050 * MS);
        assert!(!injector.drivers_dead(2099 * MS));
        assert!(injector.drivers_dead(2100 * MS));
    }

    #[test]
    fn validation_names_the_key() {
        let bad = FaultsConfig {
            estimate_latency: vec![LatencySpike {
                t: 1.0,
                duration: 0.5,
                delay: f64::NAN,
            }],
            ..FaultsConfig::default()
        };
        let e = bad
            .validate(Path::new("s.toml"), 10.0)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("faults.estimate_latency[0].delay") && e.contains("s.toml"),
            "{e}"
        );
        let both = FaultsConfig {
            driver_death: Some(DriverDeath {
                t: Some(1.0),
                mode: Some("flight".into()),
                delay: 0.0,
            }),
            ..FaultsConfig::default()
        };
        let e = both
            .validate(Path::new("s.toml"), 10.0)
            .unwrap_err()
            .to_string();
        assert!(e.contains("faults.driver_death"), "{e}");
        let mode = FaultsConfig {
            driver_death: Some(DriverDeath {
                t: None,
                mode: Some("hovering".into()),
                delay: 0.0,
            }),
            ..FaultsConfig::default()
        };
        let e = mode
            .validate(Path::new("s.toml"), 10.0)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("faults.driver_death.mode") && e.contains("hovering"),
            "{e}"
        );
    }
}
