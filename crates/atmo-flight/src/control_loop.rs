//! The periodic control loop: absolute deadlines, per-tick timing.
//!
//! Deadlines are `t0 + k T` (never `previous wake-up + T`), so sleep error
//! and compute time never accumulate into drift. A tick that overruns
//! its period is counted; if the loop falls more than a whole period behind,
//! the missed deadlines are skipped (and counted) instead of being run back
//! to back. The clock is a trait so that tests and replays drive time.
//!
//! One tick ([`ControlLoop::tick`]) is the same code everywhere: gather
//! ([`TickIo`]) -> `FlightStack::step` -> emit -> `prepare_next`, with the
//! scheduler's bookkeeping. [`ControlThread`] runs it on the monotonic
//! clock; atmo-sim runs it on the plant's clock with a simulated `TickIo`.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, SyncSender, sync_channel};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use atmo_mpc::SolverCuts;

use crate::error::{FlightError, Result};
use crate::flight_stack::{FlightStack, StepInputs, StepOutputs};

/// Monotonic time source, ns since an arbitrary origin.
pub trait Clock {
    fn now_ns(&self) -> u64;
    /// Blocks until `deadline_ns` (returns at once if it has passed).
    fn sleep_until(&self, deadline_ns: u64);
}

/// The machine's monotonic clock.
#[derive(Debug, Clone, Copy)]
pub struct MonotonicClock {
    origin: Instant,
}

impl MonotonicClock {
    pub fn new() -> Self {
        Self {
            origin: Instant::now(),
        }
    }
}

impl Default for MonotonicClock {
    fn default() -> Self {
        Self::new()
    }
}

impl Clock for MonotonicClock {
    fn now_ns(&self) -> u64 {
        u64::try_from(self.origin.elapsed().as_nanos()).unwrap_or(u64::MAX)
    }

    fn sleep_until(&self, deadline_ns: u64) {
        let now = self.now_ns();
        if deadline_ns > now {
            std::thread::sleep(Duration::from_nanos(deadline_ns - now));
        }
    }
}

pub use atmo_io::msg::TickTiming;

/// Scheduler state of a periodic loop.
#[derive(Debug, Clone)]
pub struct Scheduler {
    period_ns: u64,
    start_ns: u64,
    tick: u64,
    overruns: u64,
    skipped: u64,
}

impl Scheduler {
    /// A loop whose first deadline is `start_ns`.
    pub fn new(period_ns: u64, start_ns: u64) -> Self {
        Self {
            period_ns: period_ns.max(1),
            start_ns,
            tick: 0,
            overruns: 0,
            skipped: 0,
        }
    }

    pub fn period_ns(&self) -> u64 {
        self.period_ns
    }

    /// The deadline of the next tick, ns (before any skip `wait` may make).
    pub fn next_deadline_ns(&self) -> u64 {
        self.deadline(self.tick)
    }

    fn deadline(&self, tick: u64) -> u64 {
        self.start_ns + tick * self.period_ns
    }

    /// Sleeps until the next deadline and returns it with the wake-up time.
    pub fn wait<C: Clock>(&mut self, clock: &C) -> (u64, u64) {
        let mut deadline = self.deadline(self.tick);
        let now = clock.now_ns();
        if now > deadline + self.period_ns {
            // More than a whole period behind: skip to the latest deadline.
            let behind = (now - deadline) / self.period_ns;
            self.skipped += behind;
            self.tick += behind;
            deadline = self.deadline(self.tick);
        }
        clock.sleep_until(deadline);
        (deadline, clock.now_ns())
    }

    /// Closes the tick that woke at `woke_ns` for `deadline_ns`.
    pub fn finish<C: Clock>(&mut self, clock: &C, deadline_ns: u64, woke_ns: u64) -> TickTiming {
        let end = clock.now_ns();
        let overrun = end > deadline_ns + self.period_ns;
        if overrun {
            self.overruns += 1;
        }
        let timing = TickTiming {
            tick: self.tick,
            deadline_ns,
            wake_latency: woke_ns.saturating_sub(deadline_ns) as f64 * 1e-9,
            compute: end.saturating_sub(woke_ns) as f64 * 1e-9,
            overrun,
            overruns_total: self.overruns,
            skipped_total: self.skipped,
        };
        self.tick += 1;
        timing
    }
}

/// The control period as the loop counts it: whole nanoseconds, rounded
/// down, so that tick `k` is never scheduled after `k T`.
pub fn tick_period(period_s: f64) -> Duration {
    Duration::from_nanos((period_s.max(0.0) * 1e9) as u64)
}

/// The daemon's control loop, one tick at a time: wait for the deadline,
/// gather the inputs, `FlightStack::step`, emit the outputs, run the MPC's
/// preparation phase, close the tick's timing. The control thread runs it
/// on the monotonic clock with the onboard I/O; the simulator runs the same
/// code on the plant's clock with its simulated I/O.
#[derive(Debug, Clone)]
pub struct ControlLoop {
    scheduler: Scheduler,
    previous: TickTiming,
}

impl ControlLoop {
    /// A loop ticking every `period`, the first deadline at `first_deadline_ns`.
    pub fn new(period: Duration, first_deadline_ns: u64) -> Self {
        let period_ns = u64::try_from(period.as_nanos()).unwrap_or(u64::MAX);
        Self {
            scheduler: Scheduler::new(period_ns, first_deadline_ns),
            previous: TickTiming::default(),
        }
    }

    /// The deadline the next tick waits for, ns.
    pub fn next_deadline_ns(&self) -> u64 {
        self.scheduler.next_deadline_ns()
    }

    /// The last finished tick's timing.
    pub fn previous(&self) -> &TickTiming {
        &self.previous
    }

    /// Runs one tick; returns whether the flight stack stepped (`false`:
    /// the I/O had nothing to act on yet). `emit` gets the previous tick's
    /// timing (this one is still running).
    pub fn tick<C: Clock, I: TickIo>(
        &mut self,
        clock: &C,
        stack: &mut FlightStack,
        io: &mut I,
    ) -> bool {
        let (deadline, woke) = self.scheduler.wait(clock);
        let stepped = match io.gather(deadline) {
            Some(inputs) => {
                let outputs = stack.step(&inputs);
                io.emit(&inputs, &outputs, &self.previous);
                stack.open_cut_window(io.cut_script());
                stack.prepare_next();
                true
            }
            None => false,
        };
        self.previous = self.scheduler.finish(clock, deadline, woke);
        stepped
    }
}

/// What the channel-fed control thread publishes each tick.
#[derive(Debug, Clone, Copy)]
pub struct TickReport {
    pub outputs: StepOutputs,
    pub timing: TickTiming,
}

/// Counters of the control thread.
#[derive(Debug, Default)]
pub struct LoopCounters {
    /// Ticks run.
    pub ticks: AtomicU64,
    /// Reports dropped because the output channel was full.
    pub reports_dropped: AtomicU64,
}

/// The I/O of one tick, run on the control thread. Implementations must
/// never block and, after start-up, never allocate: they read what has
/// arrived and hand out what must leave through bounded, non-blocking
/// queues (or zero-copy ports).
pub trait TickIo {
    /// The inputs of the tick scheduled at `deadline_ns` (the flight
    /// stack's clock); `None` skips the step (nothing to act on yet).
    fn gather(&mut self, deadline_ns: u64) -> Option<StepInputs>;
    /// The tick's outputs; `timing` is the previous tick's (the current one
    /// is still running).
    fn emit(&mut self, inputs: &StepInputs, outputs: &StepOutputs, timing: &TickTiming);
    /// The time-limit cuts the next window of MPC solves must take
    /// (`atmo_mpc::qp::cuts`): `None` (the wall clock decides) except where
    /// a simulation injects solver overruns deterministically.
    fn cut_script(&mut self) -> Option<SolverCuts> {
        None
    }
}

/// Tick I/O over std channels: the newest input wins; a full report
/// channel drops the report and counts it.
struct ChannelIo {
    inputs: Receiver<StepInputs>,
    latest: Option<StepInputs>,
    reports: SyncSender<TickReport>,
    counters: Arc<LoopCounters>,
}

impl TickIo for ChannelIo {
    fn gather(&mut self, deadline_ns: u64) -> Option<StepInputs> {
        while let Ok(input) = self.inputs.try_recv() {
            self.latest = Some(input);
        }
        self.latest.map(|input| StepInputs {
            now_ns: deadline_ns,
            ..input
        })
    }

    fn emit(&mut self, _inputs: &StepInputs, outputs: &StepOutputs, timing: &TickTiming) {
        let report = TickReport {
            outputs: *outputs,
            timing: *timing,
        };
        if self.reports.try_send(report).is_err() {
            self.counters
                .reports_dropped
                .fetch_add(1, Ordering::Relaxed);
        }
    }
}

/// A running control thread: `FlightStack::step` at a fixed rate on its own
/// thread with absolute deadlines, its I/O done by a [`TickIo`].
pub struct ControlThread {
    stop: Arc<AtomicBool>,
    counters: Arc<LoopCounters>,
    join: JoinHandle<FlightStack>,
}

impl ControlThread {
    /// Moves `stack` to a new thread ticking every `period`. `inputs` gives
    /// the newest inputs (drained each tick, the last one used, `now_ns`
    /// replaced by the tick's deadline on the monotonic clock); reports go
    /// to `reports`.
    pub fn spawn(
        stack: FlightStack,
        period: Duration,
        inputs: Receiver<StepInputs>,
        reports: SyncSender<TickReport>,
    ) -> Result<Self> {
        Self::spawn_with(stack, period, move |counters| {
            Ok::<_, std::convert::Infallible>(ChannelIo {
                inputs,
                latest: None,
                reports,
                counters,
            })
        })
    }

    /// Like [`Self::spawn`], with the I/O built by `make_io` on the control
    /// thread itself (ports that are not `Send` are opened where they are
    /// used). An error from `make_io` is returned here and no tick runs.
    pub fn spawn_with<I, E, F>(stack: FlightStack, period: Duration, make_io: F) -> Result<Self>
    where
        I: TickIo,
        E: std::fmt::Display,
        F: FnOnce(Arc<LoopCounters>) -> std::result::Result<I, E> + Send + 'static,
    {
        let stop = Arc::new(AtomicBool::new(false));
        let counters = Arc::new(LoopCounters::default());
        let (stop_flag, shared) = (stop.clone(), counters.clone());
        let (ready_tx, ready_rx) = sync_channel::<std::result::Result<(), String>>(1);
        let join = std::thread::Builder::new()
            .name("atmo-control".into())
            .spawn(move || {
                let mut io = match make_io(shared.clone()) {
                    Ok(io) => {
                        let _ = ready_tx.send(Ok(()));
                        io
                    }
                    Err(e) => {
                        let _ = ready_tx.send(Err(e.to_string()));
                        return stack;
                    }
                };
                let mut stack = stack;
                let clock = MonotonicClock::new();
                let first = clock
                    .now_ns()
                    .saturating_add(u64::try_from(period.as_nanos()).unwrap_or(u64::MAX));
                let mut control = ControlLoop::new(period, first);
                loop {
                    control.tick(&clock, &mut stack, &mut io);
                    shared.ticks.fetch_add(1, Ordering::Relaxed);
                    if stop_flag.load(Ordering::Relaxed) {
                        return stack;
                    }
                }
            })
            .map_err(|e| FlightError::Setup(format!("control thread: {e}")))?;
        match ready_rx.recv() {
            Ok(Ok(())) => Ok(Self {
                stop,
                counters,
                join,
            }),
            Ok(Err(reason)) => {
                let _ = join.join();
                Err(FlightError::Setup(format!("control thread I/O: {reason}")))
            }
            Err(_) => Err(FlightError::Setup(
                "control thread ended before its I/O was ready".into(),
            )),
        }
    }

    pub fn counters(&self) -> &LoopCounters {
        &self.counters
    }

    /// Whether the thread is still ticking (false after a panic).
    pub fn is_running(&self) -> bool {
        !self.join.is_finished()
    }

    /// Stops after the current tick and hands the flight stack back.
    pub fn stop(self) -> std::thread::Result<FlightStack> {
        self.stop.store(true, Ordering::Relaxed);
        self.join.join()
    }
}
