//! The flight stack's side of the landing decision: what it feeds the
//! flare (`crate::flare`) in the preparation phase, after the outputs are
//! sent: the observer's force learned aloft, the touchdown prediction near
//! the hold, and the clearance the flare holds.

use atmo_core::ground_effect::GroundedBody;
use atmo_core::model::State;
use atmo_mpc::wheel_clearance;

use super::FlightStack;
use crate::flare::{
    COMMITTED_THRUST_MAX, Decision, PREDICTION_RANGE, TouchdownModel, predict_touchdown,
    predicted_vertical_force,
};
use crate::modes::Mode;

/// Below this model ground-effect gain the observer's force counts as
/// learned aloft (the flare's force floor).
const ALOFT_GAIN: f64 = 0.01;

impl FlightStack {
    /// Keeps the observer's vertical force while it counts as learned
    /// aloft: airborne before the transition, the model's ground-effect gain
    /// below `ALOFT_GAIN` (in the preparation: off the feedback's path).
    pub(super) fn learn_aloft_force(&mut self, state: &State) {
        if self.mode != Mode::Transition
            && self.model_ground_gain(state, self.last_tilt).abs() < ALOFT_GAIN
        {
            self.aloft_force = Some(self.observer.wrench()[2]);
        }
    }

    /// The model's ground-effect gain `g` at `state` and `tilt`, the
    /// rotors weighted by the last command (0 without a surface).
    fn model_ground_gain(&self, state: &State, tilt: f64) -> f64 {
        let Some(surface) = self.ground_effect.as_deref() else {
            return 0.0;
        };
        let gains = GroundedBody {
            body: self.model.at_tilt(tilt),
            surface,
            ground_z: self.last_ground_z,
        }
        .gains(state);
        let total: f64 = self.last_thrust.iter().sum();
        if total > 0.1 {
            gains
                .iter()
                .zip(self.last_thrust.iter())
                .map(|(g, u)| g * u)
                .sum::<f64>()
                / total
        } else {
            gains.iter().sum::<f64>() / 4.0
        }
    }

    /// In a flare's approach: the touchdown if the tilt-up began now
    /// (`flare::predict_touchdown`, 5 ms steps, within 0.6 s), every rotor
    /// reaching full thrust less the attitude control's share of it now
    /// (the largest command above their mean).
    pub(super) fn predict_flare(&mut self, state: &State) {
        self.flare_prediction = None;
        if self.flare_settings.is_none() || self.mode != Mode::Transition || self.flare.committed()
        {
            return;
        }
        // Near the hold only: the prediction costs up to 120 RK4 steps.
        if self.flare_clearance(state) >= PREDICTION_RANGE {
            return;
        }
        let u = self.last_thrust;
        let attitude_share = u.max() - u.sum() / 4.0;
        let mut disturbance = self.observer.wrench();
        disturbance[2] = predicted_vertical_force(disturbance[2], self.aloft_force);
        let model = TouchdownModel {
            model: &self.model,
            surface: self.ground_effect.as_deref(),
            ground: self.ground_plane(state),
            disturbance,
            wheel_radius: self.wheel_radius,
            tilt_rate: self.tilt_rate_max,
            tilt_max: self.transition_tilt_max,
            // A failed rotor: the balanced collective left (its asymmetry
            // is the plan's, not attitude control's share).
            thrust: match self.thrust_left() {
                Some(left) => COMMITTED_THRUST_MAX * left,
                None => (COMMITTED_THRUST_MAX - attitude_share).max(0.0),
            },
            thrust_now: u,
            motor_time_constant: self.motor_time_constant,
        };
        self.flare_prediction = predict_touchdown(&model, state, self.last_tilt, 0.005, 0.6);
    }

    /// The flare's decision in this transition (its prediction and when it
    /// was taken), once committed.
    pub fn flare_decision(&self) -> Option<Decision> {
        self.flare.decision()
    }

    /// Whether the flare of this transition has committed its tilt-up.
    pub fn flare_committed(&self) -> bool {
        self.flare.committed()
    }

    /// The wheels' clearance above the ground plane input as if at the
    /// transition's tilt limit, m (what the flare holds, `flare`).
    pub(super) fn flare_clearance(&self, state: &State) -> f64 {
        wheel_clearance(
            &self.limit_body,
            &self.ground_plane(state),
            state,
            self.wheel_radius,
        )
    }
}
