//! The actuator monitor's inputs, gathered from the flight stack each tick
//! (`crate::actuator_monitor` decides what they show).

use atmo_core::model::{Input, State, idx};
use atmo_mpc::{YawCost, wheel_clearance};

use super::FlightStack;
use crate::actuator_monitor::{Detected, MonitorInputs};
use crate::backup_control::StoppedRotor;
use crate::modes::{Mode, Thresholds};
use crate::rotor_estimate::RotorEstimate;

/// The fastest rotor speed an ESC may report, as a fraction of the speed at
/// full command (a rotor unloaded, or over-driven, may spin past it; no
/// rotor spins at twice it).
const MAX_ROTOR_SPEED: f64 = 2.0;

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
        rotor_speeds: Option<[f64; 4]>,
    ) -> Detected {
        // A speed that is not a finite fraction of full is no reading (the
        // tick's whole report goes, counted).
        self.rotor_speeds = rotor_speeds.filter(|speeds| {
            let valid = speeds
                .iter()
                .all(|v| v.is_finite() && (0.0..=MAX_ROTOR_SPEED).contains(v));
            if !valid {
                self.rejected.rotor_speeds += 1;
            }
            valid
        });
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
            rotor_commands: self.rotor_commands(&self.last_thrust),
            rotor_speeds: self.rotor_speeds,
        })
    }
}

impl FlightStack {
    /// Names the failed rotor at the monitor's detection (from the
    /// observer's torque at the tilt flown) and forgets it once the
    /// detection is (disarmed).
    pub(super) fn track_rotor(&mut self, detected: Detected) {
        if !detected.rotor_failed() {
            self.rotor.reset();
        } else if let Some(stopped) = self.monitor.stopped_rotor() {
            // Its ESC names it, whatever the torque said before.
            self.rotor.stopped(stopped);
        } else if self.rotor.rotor().is_none() {
            let body = self.model.at_tilt(self.last_tilt);
            let (rotor, stuck) = RotorEstimate::name_rotor(&body, &self.observer.wrench());
            self.rotor.start(rotor, stuck);
        }
    }

    /// After the observer's update: what the failed rotor explains of its
    /// wrench becomes the rotor's effectiveness (`rotor_estimate`).
    pub(super) fn learn_rotor(&mut self, tilt: f64) {
        if self.rotor.rotor().is_none() {
            return;
        }
        let body = self.model.at_tilt(tilt);
        let explained = self.rotor.learn(
            &body,
            &self.observer.wrench(),
            &self.last_thrust,
            self.settings.monitor.rotor_out_effectiveness,
        );
        self.observer.take(&explained);
    }

    /// The rotor its ESC reports stopped and the thrust it still gives
    /// (its speed squared; nothing while its speed is not reported).
    pub(super) fn stopped_rotor(&self) -> Option<StoppedRotor> {
        let rotor = self.monitor.stopped_rotor()?;
        let delivered = self.rotor_speeds.map_or(0.0, |s| s[rotor] * s[rotor]);
        Some(StoppedRotor { rotor, delivered })
    }

    /// A failed rotor delivers too little to fly the wheel landing on.
    pub(super) fn rotor_out(&self) -> bool {
        self.rotor
            .out(self.settings.monitor.rotor_out_effectiveness)
    }

    /// The MPC's rotor bounds and yaw cost for what the rotors can do: a
    /// failed rotor bounded by its effectiveness (around what it still
    /// delivers once out). With a rotor bounded under full thrust the
    /// heading is not held, its rate still is ([`YawCost::RateOnly`]):
    /// the rotors left cannot hold the heading and the lift both, and
    /// near the ground, where the cost weighs the rates and not the
    /// height, the MPC cut a diagonal pair for 0.1 s to turn the heading
    /// back and came down on the base (docs/decisions/
    /// 2026-12-06-heading-with-a-failed-rotor.md). In the rotor-out
    /// descent the rate goes too ([`YawCost::Free`]: Mueller and
    /// D'Andrea's relaxed hover); not in the transition, where the wheels
    /// meet the ground: a free heading spun the robot onto them at 8
    /// rad/s, and a stuck rotor's spin (to 18 rad/s) lifted it away.
    pub(super) fn configure_rotors(&mut self) {
        let out_below = self.settings.monitor.rotor_out_effectiveness;
        // In [0, 1] by construction: refused only if not, keeping the old.
        let (min, max) = self.rotor.rotor_bounds(out_below);
        let _ = self.mpc.set_rotor_bounds(&min, &max);
        let yaw = if self.rotor_out() && self.mode == Mode::Failsafe {
            YawCost::Free
        } else if max.iter().any(|m| *m < 1.0) {
            YawCost::RateOnly
        } else {
            YawCost::Held
        };
        self.mpc.set_yaw_cost(yaw);
    }

    /// The commands sent for the delivered thrust `planned`.
    pub(super) fn rotor_commands(&self, planned: &Input) -> [f64; 4] {
        let u = self
            .rotor
            .command(planned, self.settings.monitor.rotor_out_effectiveness);
        [u[0], u[1], u[2], u[3]]
    }
}

impl FlightStack {
    /// The balanced collective thrust left with a failed rotor, as a
    /// fraction of four full rotors: rotor i at e and its diagonal
    /// partner matched to it (roll and pitch balance), the other diagonal
    /// full: (2 + 2 e) / 4, where `e` is what the rotor can give (nothing
    /// once out, what it delivers once stuck). `None` without a rotor
    /// fault.
    pub(super) fn thrust_left(&self) -> Option<f64> {
        self.rotor.rotor()?;
        let out_below = self.settings.monitor.rotor_out_effectiveness;
        let e = if self.rotor_out() {
            self.rotor.out_thrust(out_below).unwrap_or(0.0)
        } else {
            self.rotor.effectiveness()
        };
        Some(0.5 * (1.0 + e))
    }

    /// The flight tilt limit for the thrust left, rad: the robot file's
    /// keeps its thrust reserve with four full rotors (4 kT cos phi_max
    /// over m g); the same reserve with a fraction `left` of them holds at
    /// cos phi = cos phi_max / left. Zero when even folded it cannot.
    pub(super) fn flight_limit(&self) -> f64 {
        let Some(left) = self.thrust_left() else {
            return self.flight_tilt_max;
        };
        let c = self.flight_tilt_max.cos() / left;
        if c >= 1.0 {
            0.0
        } else {
            c.acos().min(self.flight_tilt_max)
        }
    }

    /// The mode machine's thresholds with morphing's hand-over tilt
    /// following the flight limit in force.
    pub(super) fn thresholds_now(&self) -> Thresholds {
        let mut t = self.thresholds;
        if self.thrust_left().is_some() {
            t.transition_min_tilt =
                self.flight_limit() - super::TRANSITION_TILT_MARGIN_DEG.to_radians();
        }
        t
    }
}
