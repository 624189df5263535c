//! Disturbance observer for offset-free MPC.
//!
//! The MPC's model (the authors' 7-body model) leaves out the centre-of-mass
//! offset, mass errors, steady wind and drag. Without integral action a
//! constant torque leaves a steady attitude error that the MPC trades
//! against collective thrust, and the robot sinks. The observer estimates a
//! constant wrench d (body force, torque about B) from the one-step
//! prediction error of the model between two estimates:
//!
//! ```text
//! x_pred = RK4(f_d, x_prev, u_applied, dt)
//! d <- d + k M_b [R^T (v - v_pred); w - w_pred] / dt,  clamped
//! ```
//!
//! and the MPC predicts with `f + M_b^-1 d` (atmo-core `TiltedBody::with_disturbance`).
//! The gains low-pass the estimate (time constant ~ dt / k).
//!
//! `dt` is the spacing of the estimates' stamps, which onboard are the
//! times the ROS 2 thread accepted them: on a loaded machine two estimates
//! measured a sample period apart can be accepted microseconds apart, and
//! their velocity difference over that `dt` reads as a force of thousands
//! of newtons (seen in SITL: the estimate jumped to its limits in one
//! update, the MPC cut the thrust to zero and ATMO fell from 0.8 m). So an
//! estimate less than `min_interval` after the base sample is not
//! differenced; the next one is, against the same base.
//! (Bounding each update's innovation by the limits as well was tried: it
//! clips innovations the shipped tuning relies on, which ones was not
//! traced, and the Monte Carlo fell from 194 to 180 of 200.)
//!
//! `f` is the MPC's own prediction model: with a ground-effect surface in
//! the MPC ([`DisturbanceObserver::set_ground_effect`]) the observer
//! predicts with the same surface, so that it learns only what the MPC does
//! not know. (Learning the ground effect with the nominal model while the
//! MPC also predicts it counted it twice: near the ground the MPC expected
//! about 8 % more lift than there was and could not stop a descent.)

use std::sync::Arc;

use atmo_core::Model;
use atmo_core::ground_effect::{ThrustGainSurface, rk4_step_above_ground};
use atmo_core::model::{Input, State, idx, rotation};
use nalgebra::{Vector3, Vector6};

/// Observer gains and limits.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ObserverSettings {
    /// Per-update gain of the force estimate, in (0, 1].
    pub force_gain: f64,
    /// Per-update gain of the torque estimate, in (0, 1].
    pub torque_gain: f64,
    /// N, per axis.
    pub max_force: f64,
    /// N m, per axis.
    pub max_torque: f64,
    /// s: estimates closer than this to the base sample are not differenced.
    pub min_interval: f64,
}

#[derive(Debug, Clone, Copy, PartialEq)]
struct Sample {
    stamp_ns: u64,
    state: State,
    tilt: f64,
}

/// The estimator state.
#[derive(Debug, Clone)]
pub struct DisturbanceObserver {
    settings: ObserverSettings,
    wrench: Vector6<f64>,
    previous: Option<Sample>,
    /// The MPC's thrust-gain surface and the ground plane's z (NED, m).
    ground_effect: Option<Arc<dyn ThrustGainSurface>>,
    ground_z: f64,
}

impl DisturbanceObserver {
    pub fn new(settings: ObserverSettings) -> Self {
        Self {
            settings,
            wrench: Vector6::zeros(),
            previous: None,
            ground_effect: None,
            ground_z: 0.0,
        }
    }

    /// Predicts with this thrust-gain surface (the MPC's), `None`: nominal.
    pub fn set_ground_effect(&mut self, surface: Option<Arc<dyn ThrustGainSurface>>) {
        self.ground_effect = surface;
    }

    /// The ground plane under the robot, z (NED, m), for the surface.
    pub fn set_ground_height(&mut self, ground_z: f64) {
        self.ground_z = ground_z;
    }

    /// The current estimate (body force, torque about B).
    pub fn wrench(&self) -> Vector6<f64> {
        self.wrench
    }

    /// Takes `explained` out of the estimate: a part of it now in the
    /// model (a failed rotor's effectiveness, `rotor_estimate`).
    pub fn take(&mut self, explained: &Vector6<f64>) {
        self.wrench -= explained;
    }

    /// Forgets everything (on the ground).
    pub fn reset(&mut self) {
        self.wrench = Vector6::zeros();
        self.previous = None;
    }

    /// Keeps the estimate but forgets the last sample (learning paused).
    pub fn pause(&mut self) {
        self.previous = None;
    }

    /// Updates with a new estimate, given the command applied since the
    /// previous one. Repeated stamps are ignored; stamps less than
    /// `min_interval` after the base sample wait for a later one; gaps over
    /// 50 ms restart.
    pub fn update(
        &mut self,
        model: &Model,
        stamp_ns: u64,
        state: &State,
        tilt: f64,
        applied: &Input,
    ) {
        let sample = Sample {
            stamp_ns,
            state: *state,
            tilt,
        };
        let Some(prev) = self.previous else {
            self.previous = Some(sample);
            return;
        };
        if stamp_ns <= prev.stamp_ns {
            return;
        }
        let dt = (stamp_ns - prev.stamp_ns) as f64 * 1e-9;
        if dt < self.settings.min_interval {
            return;
        }
        self.previous = Some(sample);
        if dt > 0.05 {
            return;
        }
        let body = model
            .at_tilt(0.5 * (prev.tilt + tilt))
            .with_disturbance(self.wrench);
        let predicted = rk4_step_above_ground(
            body,
            self.ground_effect.as_deref(),
            self.ground_z,
            &prev.state,
            applied,
            dt,
        );
        let r = rotation(state[idx::YAW], state[idx::PITCH], state[idx::ROLL]);
        let dv = r.transpose()
            * Vector3::new(
                state[idx::VX] - predicted[idx::VX],
                state[idx::VY] - predicted[idx::VY],
                state[idx::VZ] - predicted[idx::VZ],
            );
        let dw = Vector3::new(
            state[idx::WX] - predicted[idx::WX],
            state[idx::WY] - predicted[idx::WY],
            state[idx::WZ] - predicted[idx::WZ],
        );
        let innovation = body.mass_matrix * Vector6::new(dv.x, dv.y, dv.z, dw.x, dw.y, dw.z) / dt;
        if !innovation.iter().all(|v| v.is_finite()) {
            return;
        }
        let s = &self.settings;
        for k in 0..6 {
            let (gain, limit) = if k < 3 {
                (s.force_gain, s.max_force)
            } else {
                (s.torque_gain, s.max_torque)
            };
            self.wrench[k] = (self.wrench[k] + gain * innovation[k]).clamp(-limit, limit);
        }
    }
}
