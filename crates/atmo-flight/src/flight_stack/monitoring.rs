//! The actuator monitor's inputs, gathered from the flight stack each tick
//! (`crate::actuator_monitor` decides what they show).

use atmo_core::model::{State, idx};
use atmo_mpc::wheel_clearance;

use super::FlightStack;
use crate::actuator_monitor::{Detected, MonitorInputs};

impl FlightStack {
    /// Runs the actuator monitor on this tick's signals (the mode is the
    /// previous tick's: what the commands it checks were made in).
    pub(super) fn monitor_actuators(
        &mut self,
        now: u64,
        armed: bool,
        estimate_fresh: bool,
        state: &State,
        height: f64,
    ) -> Detected {
        // The wheels' clearance matters only near the ground; the body at a
        // tilt costs a model evaluation.
        let clearance = if height <= self.thresholds.takeoff_height {
            wheel_clearance(
                &self.model.at_tilt(self.last_tilt),
                &self.ground_plane(state),
                state,
                self.wheel_radius,
            )
        } else {
            f64::INFINITY
        };
        self.monitor.update(&MonitorInputs {
            now_ns: now,
            armed,
            mode: self.mode,
            encoder_tilt: self.encoder_tilt,
            last_tilt_command: self.tilt_sent,
            disturbance: self.observer.wrench().into(),
            estimate_fresh,
            wheel_clearance: clearance,
            vertical_speed: state[idx::VZ],
        })
    }
}
