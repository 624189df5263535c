//! The landing summary and Fig. 5A of a flight, from its log alone.
//!
//! A simulated flight's log carries the plant's truth after every plant
//! step ([`TRUTH_TOPIC`]): the summary and figure are then computed from
//! exactly what `atmo-sim fly` computed them from, with the same code
//! ([`LandingTracker`], [`FlightTrace::push`]), and agree with its
//! `summary.json` value for value (the wall time excepted). A real flight
//! has no truth: the flight stack's own view stands in, tick by tick (the
//! estimate's position and vertical speed, the encoder's tilt, the contact
//! signal, the height above the configured ground).

use std::path::Path;

use atmo_core::ConfigFile as _;
use atmo_core::RobotConfig;

use super::figure::{FlightTrace, Markers};
use super::landing::{LandingTracker, RunEnd, Summary};
use crate::error::{IoError, Result};
use crate::mcap_log::{AnyMessage, read_extras, read_log};
use crate::msg::{MpcStatus, SimTruth, SolverStatus};

/// Topic of the plant's truth in a simulated flight's log.
pub const TRUTH_TOPIC: &str = "/atmo/sim/truth";
/// Metadata record of a simulated flight: `scenario`, `seed`, `crash`
/// (empty: none), `controller_matches_files`.
pub const SIM_METADATA: &str = "atmo.sim";
/// The attachment holding the robot configuration's text.
pub const ROBOT_ATTACHMENT: &str = "config/robot";

/// What the truth of a review is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TruthSource {
    /// The simulator's plant, after every plant step.
    Simulation,
    /// The flight stack's own view, every tick (a real flight).
    FlightStack,
}

/// A flight reviewed from its log.
#[derive(Debug, Clone)]
pub struct LogReview {
    pub summary: Summary,
    pub trace: FlightTrace,
    pub markers: Markers,
    pub truth: TruthSource,
    /// The figure's title.
    pub title: String,
    /// Spans of control ticks missing from the log (a chunk lost and
    /// skipped by `recover`): the summary is then partial, and its landing
    /// values are withheld when a hole comes before the touchdown found.
    pub missing: Vec<MissingTicks>,
}

/// Control ticks missing from a log: the status messages' `tick` counter
/// (0 at the flight stack's first tick) jumps from `after` to `before`.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct MissingTicks {
    /// The last tick present before the hole; `None`: the hole starts the
    /// log (its first tick present is not tick 0).
    pub after: Option<u64>,
    /// The first tick present after it.
    pub before: u64,
    /// Flight stack clock of those two ticks, s.
    pub from_s: Option<f64>,
    pub to_s: f64,
}

impl MissingTicks {
    pub fn count(&self) -> u64 {
        self.before - self.after.map_or(0, |a| a + 1)
    }
}

impl std::fmt::Display for MissingTicks {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match (self.after, self.from_s) {
            (Some(after), Some(from_s)) => write!(
                f,
                "{} ticks missing between tick {after} ({from_s:.3} s) and tick {} ({:.3} s)",
                self.count(),
                self.before,
                self.to_s
            ),
            _ => write!(
                f,
                "{} ticks missing before tick {} ({:.3} s), the first in the log",
                self.count(),
                self.before,
                self.to_s
            ),
        }
    }
}

/// The flight stack's view of a tick as a truth sample (real flights).
fn view_of(s: &MpcStatus) -> SimTruth {
    SimTruth {
        time: s.stamp_ns as f64 * 1e-9,
        state: s.state,
        tilt: s.varphi,
        height: s.height,
        contact: s.ground_contact,
    }
}

/// Feeds one tick to the tracker.
fn control_tick(tracker: &mut LandingTracker, s: &MpcStatus) {
    tracker.on_control_tick(
        s.mode,
        &s.thrust,
        (s.solver_status != SolverStatus::Idle).then_some(s.feedback_time),
        s.mpc_failures_total,
        s.rejected_inputs(),
    );
}

/// Reviews the finished log at `path` whose status is on `status_topic`.
///
/// # Errors
/// A log that cannot be read (a cut one: `atmo-mcap recover` it first), no
/// status message on `status_topic`, a robot attachment that does not parse.
pub fn review_log(path: impl AsRef<Path>, status_topic: &str) -> Result<LogReview> {
    let path = path.as_ref();
    let messages = read_log(path)?;
    let extras = read_extras(path)?;
    let has_truth = messages.iter().any(|m| m.topic == TRUTH_TOPIC);
    let mut tracker = LandingTracker::new(messages.len());
    let mut trace = FlightTrace::default();
    let mut truth: Option<SimTruth> = None;
    let mut ticks = 0usize;
    let mut missing = Vec::new();
    let mut last_tick: Option<(u64, f64)> = None;
    for m in &messages {
        match &m.message {
            AnyMessage::SimTruth(t) if m.topic == TRUTH_TOPIC => {
                if let Some(before) = truth {
                    tracker.after_plant_step(t, before.contact);
                }
                truth = Some(*t);
            }
            AnyMessage::MpcStatus(s) if m.topic == status_topic => {
                ticks += 1;
                let clock = s.stamp_ns as f64 * 1e-9;
                let expected = last_tick.map_or(0, |(after, _)| after.saturating_add(1));
                if s.tick > expected {
                    missing.push(MissingTicks {
                        after: last_tick.map(|(a, _)| a),
                        before: s.tick,
                        from_s: last_tick.map(|(_, t)| t),
                        to_s: clock,
                    });
                }
                last_tick = Some((s.tick, clock));
                control_tick(&mut tracker, s);
                let now = if has_truth {
                    truth.unwrap_or_else(|| view_of(s))
                } else {
                    let view = view_of(s);
                    // The tick's view stands in for a plant step.
                    let before = truth.map_or(view.contact, |t| t.contact);
                    tracker.after_plant_step(&view, before);
                    truth = Some(view);
                    view
                };
                trace.push(now.time, now.height, now.tilt, s.mode, s.alpha, &s.thrust);
            }
            _ => {}
        }
    }
    if ticks == 0 {
        return Err(IoError::LogChannel {
            file: path.to_path_buf(),
            topic: status_topic.to_string(),
            reason: "no atmo_msgs/MpcStatus message: nothing to review".into(),
        });
    }
    let sim = extras.metadata(SIM_METADATA);
    let stem = path
        .file_stem()
        .map_or_else(String::new, |s| s.to_string_lossy().into_owned());
    let end = RunEnd {
        scenario: sim.and_then(|m| m.get("scenario").cloned()).unwrap_or(stem),
        seed: sim
            .and_then(|m| m.get("seed"))
            .and_then(|s| s.parse().ok())
            .unwrap_or(0),
        crash_reason: sim
            .and_then(|m| m.get("crash"))
            .filter(|c| !c.is_empty())
            .cloned(),
        wall_time_s: None,
    };
    let mut summary = tracker.summary(&end);
    withhold_unknowable(&mut summary, &missing);
    let robot = match extras.attachment(ROBOT_ATTACHMENT) {
        Some(a) => RobotConfig::from_toml_str(
            &String::from_utf8_lossy(&a.data),
            format!("{}: attachment {ROBOT_ATTACHMENT}", path.display()),
        )?,
        None => RobotConfig::atmo(),
    };
    let (title, source) = if has_truth {
        (
            format!("ATMO {} (simulated, seed {})", end.scenario, end.seed),
            TruthSource::Simulation,
        )
    } else {
        (
            format!("ATMO {} (flight log, flight stack's view)", end.scenario),
            TruthSource::FlightStack,
        )
    };
    Ok(LogReview {
        markers: Markers {
            morph_height: robot.limits.morph_height,
            transition_height: robot.limits.transition_height,
            touchdown: summary.touchdown_time_s,
        },
        summary,
        trace,
        truth: source,
        title,
        missing,
    })
}

/// A hole before (or without) the touchdown found means the first contact
/// may be in it: the landing values are not known and are withheld.
fn withhold_unknowable(summary: &mut Summary, missing: &[MissingTicks]) {
    let Some(first) = missing.first() else {
        return;
    };
    let before_touchdown = match (summary.touchdown_time_s, first.from_s) {
        (Some(t), Some(from_s)) => from_s <= t,
        _ => true,
    };
    if before_touchdown {
        summary.touchdown_tilt_deg = None;
        summary.impact_speed_mps = None;
        summary.touchdown_time_s = None;
        summary.predicted_touchdown = None;
    }
}
