//! Deterministic replay of a flight log through the flight stack.
//!
//! A flight log ([`crate::flight_log`]) holds every tick's inputs
//! ([`StepInputs`](crate::step_io::StepInputs), the tick's clock value included), every tick's outputs
//! (`MpcStatus`) and the configuration files. [`replay`] rebuilds the
//! flight stack from a configuration, feeds it the logged inputs tick by
//! tick (`step`, then `prepare_next`, as `ControlLoop::tick` does) and
//! compares every output field with the logged one *bit for bit*
//! (`f64::to_bits`): thruster commands, tilt velocity, wheel rates, mode,
//! MPC status and counters, the state, references and predictions.
//! Compute times and I/O health are measurements of the machine, not
//! outputs of the maths, and are not compared.
//!
//! The flight stack is a pure function of its inputs and its clock with
//! one exception: the MPC's wall-clock time limit, which ends a solve after
//! however many iterations the flying machine managed. The log records each
//! cut solve and the iteration it ended at (`TickInputs.solver_cut_*`,
//! `atmo_mpc::qp::cuts`); a replay lifts the time limit
//! ([`REPLAY_TIME_LIMIT_S`]) and ends exactly those solves at exactly those
//! iterations ([`CutReplay::AsLogged`]), so a flight whose solves were cut
//! replays bit for bit too. A window with more cuts than the log holds
//! (`solver_cut_overflow`) cannot be reproduced: counted in the report.
//!
//! With another configuration (what-if) the same inputs go through a changed
//! flight stack. That is open loop with respect to the plant: the robot's
//! estimate, encoder and contact are as recorded, not as the new commands
//! would have made them. Its solves are different ones, so no cut is
//! repeated ([`CutReplay::None`]): every solve runs to convergence or to the
//! iteration cap.

use std::path::{Path, PathBuf};

use atmo_io::IoError;
use atmo_io::mcap_log::{Integrity, LogExtras, read_extras, read_topic_lossy};
use atmo_io::msg::{Label, Mode, MpcStatus, RosMessage, SolverStatus, TickInputs};

use crate::control_loop::TickTiming;
use crate::error::{FlightError, Result};
use crate::flight_log::{FlightConfig, FlightConfigFiles, INPUTS_TOPIC};
use crate::telemetry::{cuts_from_message, inputs_from_message, status_message};

/// The MPC time limit of a replay, s: the settings' maximum, so that no
/// solve is cut by how busy the replaying machine is.
pub const REPLAY_TIME_LIMIT_S: f64 = 10.0;

/// A flight log read for a replay: the configuration and the ticks that
/// have both their inputs and their status.
#[derive(Debug, Clone)]
pub struct RecordedFlight {
    pub path: PathBuf,
    pub files: FlightConfigFiles,
    pub extras: LogExtras,
    /// Inputs of ticks `0..n`, in order.
    pub inputs: Vec<TickInputs>,
    /// Status of ticks `0..n`, in order (same length as `inputs`).
    pub status: Vec<MpcStatus>,
    /// Records at the end without their partner (a log cut between a
    /// tick's inputs and its status): `(inputs, status)` left over.
    pub incomplete_tail: (usize, usize),
}

fn log_error(path: &Path, reason: String) -> FlightError {
    FlightError::Log {
        file: path.to_path_buf(),
        reason,
    }
}

/// Reads one per-tick channel: every message must decode and the ticks
/// must run 0, 1, 2, ... (a gap names the channel and the tick).
fn read_channel<M: RosMessage>(
    path: &Path,
    topic: &str,
    tick_of: impl Fn(&M) -> u64,
) -> Result<Vec<M>> {
    let (messages, integrity): (Vec<(u64, M)>, Integrity) =
        read_topic_lossy(path, topic).map_err(|e| match e {
            IoError::LogChannel { reason, .. } => {
                log_error(path, format!("channel `{topic}`: {reason}"))
            }
            other => other.into(),
        })?;
    if integrity.undecodable_messages > 0 {
        return Err(log_error(
            path,
            format!(
                "channel `{topic}` is corrupt: {} of its messages do not decode as {} ({})",
                integrity.undecodable_messages,
                M::TYPE_NAME,
                integrity.first_problem.unwrap_or_default()
            ),
        ));
    }
    if integrity.corrupt_chunks > 0 {
        return Err(log_error(
            path,
            format!(
                "corrupt log: {integrity}; channel `{topic}` may have lost messages (run `atmo-mcap recover` and replay what is sound)"
            ),
        ));
    }
    if messages.is_empty() {
        return Err(log_error(
            path,
            format!(
                "channel `{topic}` ({}) is missing or empty: the log cannot be replayed",
                M::TYPE_NAME
            ),
        ));
    }
    for (expected, (_, m)) in messages.iter().enumerate() {
        let tick = tick_of(m);
        if tick != expected as u64 {
            return Err(log_error(
                path,
                format!(
                    "channel `{topic}`: message {expected} is tick {tick}, expected tick {expected} (messages missing or out of order)"
                ),
            ));
        }
    }
    Ok(messages.into_iter().map(|(_, m)| m).collect())
}

impl RecordedFlight {
    /// Reads the log at `path` (finished, or recovered by `atmo-mcap
    /// recover`) with its status on `status_topic`.
    ///
    /// # Errors
    /// A file that is not a readable MCAP log; a missing or corrupt
    /// configuration, inputs or status channel (named).
    pub fn read(path: impl AsRef<Path>, status_topic: &str) -> Result<Self> {
        let path = path.as_ref();
        let extras = read_extras(path)?;
        let files = FlightConfigFiles::from_log(&extras, path)?;
        let mut inputs = read_channel(path, INPUTS_TOPIC, |m: &TickInputs| m.tick)?;
        let mut status = read_channel(path, status_topic, |m: &MpcStatus| m.tick)?;
        let n = inputs.len().min(status.len());
        let incomplete_tail = (inputs.len() - n, status.len() - n);
        inputs.truncate(n);
        status.truncate(n);
        for (i, s) in inputs.iter().zip(&status) {
            if i.clock_ns != s.stamp_ns {
                return Err(log_error(
                    path,
                    format!(
                        "tick {}: clock {} ns on `{INPUTS_TOPIC}` but {} ns on `{status_topic}`",
                        i.tick, i.clock_ns, s.stamp_ns
                    ),
                ));
            }
        }
        Ok(Self {
            path: path.to_path_buf(),
            files,
            extras,
            inputs,
            status,
            incomplete_tail,
        })
    }

    /// The flight stack's configuration from `files` (the logged ones or a
    /// what-if's), with the replay's MPC time limit.
    ///
    /// # Errors
    /// Texts that do not parse or validate.
    pub fn config(files: &FlightConfigFiles) -> Result<FlightConfig> {
        let mut config = files.parse()?;
        config.mpc.solver.time_limit = REPLAY_TIME_LIMIT_S;
        Ok(config)
    }

    /// Duration covered, s (clock of the last tick minus the first).
    pub fn duration_s(&self) -> f64 {
        match (self.inputs.first(), self.inputs.last()) {
            (Some(a), Some(b)) => b.clock_ns.saturating_sub(a.clock_ns) as f64 * 1e-9,
            _ => 0.0,
        }
    }
}

/// One compared value.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Value {
    Real(f64),
    Count(u64),
    Mode(Mode),
    Solver(SolverStatus),
    Text(Label),
}

impl Value {
    /// Bit-for-bit equality (`NaN` equals the same `NaN`, `0.0` differs from `-0.0`).
    pub fn identical(&self, other: &Self) -> bool {
        match (self, other) {
            (Self::Real(a), Self::Real(b)) => a.to_bits() == b.to_bits(),
            _ => self == other,
        }
    }

    /// The value as a number (modes and solver states by code), for plots and sizes.
    pub fn number(&self) -> f64 {
        match self {
            Self::Real(v) => *v,
            Self::Count(v) => *v as f64,
            Self::Mode(m) => f64::from(m.code()),
            Self::Solver(s) => f64::from(s.code()),
            Self::Text(_) => 0.0,
        }
    }
}

impl std::fmt::Display for Value {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            // `{:?}` of an f64 is the shortest text that reads back to the same bits.
            Self::Real(v) => write!(f, "{v:?}"),
            Self::Count(v) => write!(f, "{v}"),
            Self::Mode(m) => write!(f, "{}", m.name()),
            Self::Solver(s) => write!(f, "{}", s.name()),
            Self::Text(t) => write!(f, "\"{t}\""),
        }
    }
}

const AXES: [&str; 12] = [
    "x", "y", "z", "yaw", "pitch", "roll", "vx", "vy", "vz", "wx", "wy", "wz",
];

/// Every compared output of a tick, in a fixed order, with its name.
pub fn compared_fields(s: &MpcStatus) -> Vec<(String, Value)> {
    let mut out = Vec::with_capacity(80);
    let mut real = |name: String, v: f64| out.push((name, Value::Real(v)));
    for (i, v) in s.thrust.iter().enumerate() {
        real(format!("thrust[{i}]"), *v);
    }
    real("tilt_velocity".into(), s.tilt_velocity);
    real("wheel_rates[left]".into(), s.wheel_rates[0]);
    real("wheel_rates[right]".into(), s.wheel_rates[1]);
    real("alpha".into(), s.alpha);
    real("varphi".into(), s.varphi);
    real("tilt_limit".into(), s.tilt_limit);
    real("height".into(), s.height);
    real("estimate_age".into(), s.estimate_age);
    real("drive_velocity[forward]".into(), s.drive_velocity[0]);
    real("drive_velocity[yaw_rate]".into(), s.drive_velocity[1]);
    for (name, array) in [
        ("state", &s.state),
        ("reference", &s.reference),
        ("predicted_next", &s.predicted_next),
    ] {
        for (axis, v) in AXES.iter().zip(array.iter()) {
            real(format!("{name}.{axis}"), *v);
        }
    }
    let p = &s.pilot;
    for (i, v) in p.velocity.iter().enumerate() {
        real(format!("pilot.velocity[{i}]"), *v);
    }
    real("pilot.yaw_rate".into(), p.yaw_rate);
    real("pilot.throttle".into(), p.throttle);
    out.push(("mode".into(), Value::Mode(s.mode)));
    out.push(("transition".into(), Value::Text(s.transition)));
    out.push(("solver_status".into(), Value::Solver(s.solver_status)));
    for (name, v) in [
        ("solver_iterations", u64::from(s.solver_iterations)),
        ("mpc_failed_ticks", u64::from(s.mpc_failed_ticks)),
        ("mpc_failures_total", s.mpc_failures_total),
        ("feedback_fallbacks_total", s.feedback_fallbacks_total),
        ("rejected_estimate", s.rejected_estimate),
        ("rejected_tilt", s.rejected_tilt),
        ("rejected_pilot", s.rejected_pilot),
        ("rejected_ground", s.rejected_ground),
        ("rejected_rotor_speeds", s.rejected_rotor_speeds),
        ("ground_contact", u64::from(s.ground_contact)),
        ("actuator_faults", u64::from(s.actuator_faults)),
        (
            "pilot.switches",
            u64::from(p.arm) | u64::from(p.offboard) << 1 | u64::from(p.mpc_enabled) << 2,
        ),
    ] {
        out.push((name.into(), Value::Count(v)));
    }
    out
}

/// The first field that differs between a logged and a replayed tick.
#[derive(Debug, Clone, PartialEq)]
pub struct Difference {
    pub tick: u64,
    /// The tick's clock, s.
    pub time_s: f64,
    pub field: String,
    pub logged: Value,
    pub replayed: Value,
}

impl std::fmt::Display for Difference {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "tick {} (t = {:.4} s): field `{}`: logged {}, replayed {}",
            self.tick, self.time_s, self.field, self.logged, self.replayed
        )
    }
}

/// One replayed tick: the logged and the replayed status.
#[derive(Debug, Clone, Copy)]
pub struct TickPair<'a> {
    pub tick: u64,
    pub time_s: f64,
    pub logged: &'a MpcStatus,
    pub replayed: &'a MpcStatus,
}

/// How a replay went.
#[derive(Debug, Clone, PartialEq)]
pub struct ReplayReport {
    /// Ticks replayed (every tick with both inputs and status).
    pub ticks: usize,
    /// Ticks with at least one differing field.
    pub differing_ticks: usize,
    pub first_difference: Option<Difference>,
    /// Simulated duration, s.
    pub duration_s: f64,
    /// Solves the time limit cut in flight, cut again at the same iteration.
    pub cuts_replayed: usize,
    /// Ticks whose cuts overflowed the log's record (not reproducible).
    pub cut_overflow_ticks: usize,
}

/// Whether a replay repeats the solves the time limit cut in flight.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CutReplay {
    /// The same configuration: end each logged cut solve at its iteration.
    AsLogged,
    /// A what-if: no solve is cut.
    None,
}

impl ReplayReport {
    pub fn identical(&self) -> bool {
        self.first_difference.is_none()
    }
}

/// The first differing field of a tick, if any.
pub fn first_difference(
    tick: u64,
    time_s: f64,
    logged: &MpcStatus,
    replayed: &MpcStatus,
) -> Option<Difference> {
    compared_fields(logged)
        .into_iter()
        .zip(compared_fields(replayed))
        .find(|((_, a), (_, b))| !a.identical(b))
        .map(|((field, logged), (_, replayed))| Difference {
            tick,
            time_s,
            field,
            logged,
            replayed,
        })
}

/// Replays `flight` through a flight stack built from `config`; `on_tick`
/// sees every tick's logged and replayed status (for a what-if's table).
///
/// # Errors
/// A configuration the flight stack refuses.
pub fn replay(
    flight: &RecordedFlight,
    config: &FlightConfig,
    cuts: CutReplay,
    mut on_tick: impl FnMut(&TickPair<'_>),
) -> Result<ReplayReport> {
    let mut stack = config.stack()?;
    let mut report = ReplayReport {
        ticks: flight.inputs.len(),
        differing_ticks: 0,
        first_difference: None,
        duration_s: flight.duration_s(),
        cuts_replayed: 0,
        cut_overflow_ticks: 0,
    };
    // The window of a tick opens before the preparation that precedes it
    // (the first one before its step), as `ControlLoop::tick` opens it.
    let mut script = |message: Option<&TickInputs>| match (cuts, message) {
        (CutReplay::AsLogged, Some(m)) => {
            let logged = cuts_from_message(m);
            report.cuts_replayed += usize::from(logged.count);
            report.cut_overflow_ticks += usize::from(logged.overflow > 0);
            Some(logged)
        }
        _ => Some(atmo_mpc::SolverCuts::default()),
    };
    stack.open_cut_window(script(flight.inputs.first()));
    let timing = TickTiming::default();
    for (k, (message, logged)) in flight.inputs.iter().zip(&flight.status).enumerate() {
        let inputs = inputs_from_message(message);
        let outputs = stack.step(&inputs);
        stack.open_cut_window(script(flight.inputs.get(k + 1)));
        stack.prepare_next();
        let replayed = status_message(message.tick, &inputs, &outputs, &timing);
        let time_s = message.clock_ns as f64 * 1e-9;
        if let Some(d) = first_difference(message.tick, time_s, logged, &replayed) {
            report.differing_ticks += 1;
            report.first_difference.get_or_insert(d);
        }
        on_tick(&TickPair {
            tick: message.tick,
            time_s,
            logged,
            replayed: &replayed,
        });
    }
    Ok(report)
}
