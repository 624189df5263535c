//! The landing in numbers (`summary.json`), one code for every source: the
//! simulator's closed loop and SITL server feed it as they run, a flight
//! log feeds it afterwards ([`super::log`]).
//!
//! Per control tick: the mode (the sequence of modes entered), the mean
//! thrust command (its maximum over the transition), the MPC's feedback
//! time and counters. Per plant step (the truth, in a simulation; the
//! flight stack's own view, tick by tick, for a real flight): the landing
//! is the first rise of the wheel-contact signal after flying; its time,
//! tilt and vertical speed are the touchdown's; after it the distance
//! driven is the sum of the horizontal steps.

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use crate::msg::{Mode, SimTruth};

/// The landing, in numbers (`summary.json`).
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct Summary {
    pub scenario: String,
    pub seed: u64,
    /// Tilt when the wheels first carried load, deg (null if never).
    pub touchdown_tilt_deg: Option<f64>,
    /// Vertical speed at first wheel contact, m/s (positive = downwards).
    pub impact_speed_mps: Option<f64>,
    pub touchdown_time_s: Option<f64>,
    /// The touchdown the flight stack predicted when it decided its
    /// tilt-up (null without that decision, and when summarized from a log).
    pub predicted_touchdown: Option<PredictedTouchdown>,
    /// Max over the transition of the mean normalized thrust command.
    pub max_mean_thrust: f64,
    pub crashed: bool,
    pub crash_reason: Option<String>,
    /// Ground distance travelled after touchdown, m.
    pub drive_distance_m: f64,
    /// Modes in the order they were entered.
    pub mode_sequence: Vec<String>,
    /// Ticks whose MPC command did not come from a fresh solve.
    pub mpc_failures: u64,
    /// Inputs rejected by the flight stack (estimate, tilt, pilot, ground,
    /// rotor speeds).
    pub rejected_inputs: [u64; 5],
    pub sim_time_s: f64,
    /// Wall-clock time of the run, s (null when summarized from a log).
    pub wall_time_s: Option<f64>,
    /// Median and max MPC feedback time, s.
    pub feedback_time_median_s: f64,
    pub feedback_time_max_s: f64,
}

/// A touchdown as predicted at a decision.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq)]
pub struct PredictedTouchdown {
    /// When the decision was taken, s.
    pub decided_at_s: f64,
    pub tilt_deg: f64,
    pub impact_speed_mps: f64,
    /// Predicted time from the decision to the touchdown, s.
    pub time_to_touchdown_s: f64,
}

/// Indices of the 12-state (`MpcStatus.msg`).
const X: usize = 0;
const Y: usize = 1;
const VZ: usize = 8;

/// The landing's bookkeeping: what the controller did each tick, and what
/// the plant did each step.
#[derive(Debug, Clone, Default)]
pub struct LandingTracker {
    modes: Vec<Mode>,
    has_flown: bool,
    max_mean_thrust: f64,
    mpc_failures: u64,
    rejected: [u64; 5],
    feedback_times: Vec<f64>,
    /// Time, tilt and vertical speed at the first wheel contact after flying.
    touchdown: Option<(f64, f64, f64)>,
    predicted: Option<PredictedTouchdown>,
    last_ground_xy: Option<Vector3<f64>>,
    drive_distance: f64,
    last_time: f64,
}

/// How a run ended, for [`LandingTracker::summary`].
#[derive(Debug, Clone, PartialEq)]
pub struct RunEnd {
    pub scenario: String,
    pub seed: u64,
    pub crash_reason: Option<String>,
    pub wall_time_s: Option<f64>,
}

impl LandingTracker {
    /// Room for `expected_ticks` feedback times (no reallocation in the loop).
    pub fn new(expected_ticks: usize) -> Self {
        Self {
            feedback_times: Vec::with_capacity(expected_ticks),
            ..Self::default()
        }
    }

    /// One control tick: its mode, thrust commands, MPC feedback time
    /// (`None` if the MPC did not run) and the controller's counters.
    pub fn on_control_tick(
        &mut self,
        mode: Mode,
        thrust: &[f64; 4],
        feedback_time: Option<f64>,
        mpc_failures_total: u64,
        rejected: [u64; 5],
    ) {
        if self.modes.last() != Some(&mode) {
            self.modes.push(mode);
        }
        self.has_flown |= matches!(mode, Mode::Flight | Mode::Morphing | Mode::Transition);
        if mode == Mode::Transition {
            let mean = thrust.iter().sum::<f64>() / 4.0;
            self.max_mean_thrust = self.max_mean_thrust.max(mean);
        }
        if let Some(t) = feedback_time {
            self.feedback_times.push(t);
        }
        self.mpc_failures = mpc_failures_total;
        self.rejected = rejected;
    }

    /// The flight stack's touchdown prediction at its decision (the first
    /// one given is kept).
    pub fn on_decision(&mut self, predicted: PredictedTouchdown) {
        self.predicted.get_or_insert(predicted);
    }

    /// After one plant step; `was_grounded` is the contact signal before it.
    pub fn after_plant_step(&mut self, truth: &SimTruth, was_grounded: bool) {
        let state = &truth.state;
        self.last_time = truth.time;
        // The landing is the first wheel contact after flying (a scenario may
        // start on the ground, and then take off).
        if self.touchdown.is_none() && self.has_flown && !was_grounded && truth.contact {
            self.touchdown = Some((truth.time, truth.tilt, state[VZ]));
        }
        if self.touchdown.is_some() {
            let xy = Vector3::new(state[X], state[Y], 0.0);
            if let Some(last) = self.last_ground_xy {
                self.drive_distance += (xy - last).norm();
            }
            self.last_ground_xy = Some(xy);
        }
    }

    /// The summary of the run so far; `sim_time_s` is the last step's time.
    pub fn summary(&self, end: &RunEnd) -> Summary {
        let mut feedback_times = self.feedback_times.clone();
        feedback_times.sort_by(f64::total_cmp);
        let touchdown = self.touchdown;
        Summary {
            scenario: end.scenario.clone(),
            seed: end.seed,
            touchdown_tilt_deg: touchdown.map(|(_, tilt, _)| tilt.to_degrees()),
            impact_speed_mps: touchdown.map(|(_, _, vz)| vz),
            touchdown_time_s: touchdown.map(|(t, _, _)| t),
            predicted_touchdown: self.predicted,
            max_mean_thrust: self.max_mean_thrust,
            crashed: end.crash_reason.is_some(),
            crash_reason: end.crash_reason.clone(),
            drive_distance_m: self.drive_distance,
            mode_sequence: self.modes.iter().map(|m| m.name().to_string()).collect(),
            mpc_failures: self.mpc_failures,
            rejected_inputs: self.rejected,
            sim_time_s: self.last_time,
            wall_time_s: end.wall_time_s,
            feedback_time_median_s: feedback_times
                .get(feedback_times.len() / 2)
                .copied()
                .unwrap_or(0.0),
            feedback_time_max_s: feedback_times.last().copied().unwrap_or(0.0),
        }
    }
}
