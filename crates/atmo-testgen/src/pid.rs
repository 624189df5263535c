//! Cascaded PID at the recording rate.
//!
//! Position: `a_cmd = a_ref + kp e_p + kd e_v + ki int e_p` (NED); the thrust
//! vector `F = m (a_cmd - g e_z)` sets the desired body -z axis and, with
//! the reference yaw, the desired attitude `R_d`. Attitude: desired rates
//! `w_d = -k_att e_R`, torque `tau = I_c k_rate (w_d - w) + w x I_c w`.

use nalgebra::Vector3;

use crate::control::{Control, Measured, Nominal, Reference};

/// Gains (SI, per second).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Gains {
    pub kp: f64,
    pub kd: f64,
    pub ki: f64,
    pub k_att: f64,
    pub k_rate: f64,
}

impl Default for Gains {
    fn default() -> Self {
        Self {
            kp: 4.0,
            kd: 3.6,
            ki: 1.0,
            k_att: 6.0,
            k_rate: 16.0,
        }
    }
}

/// The controller and its integrator.
#[derive(Debug, Clone, PartialEq)]
pub struct Pid {
    gains: Gains,
    nominal: Nominal,
    integral: Vector3<f64>,
}

impl Pid {
    pub fn new(nominal: Nominal, gains: Gains) -> Self {
        Self {
            gains,
            nominal,
            integral: Vector3::zeros(),
        }
    }
}

impl Control for Pid {
    fn command(&mut self, m: &Measured, r: &Reference, dt: f64) -> [f64; 4] {
        let g = &self.gains;
        let nominal = &self.nominal;
        let (p_com, v_com) = nominal.com_motion(m);
        let e_p = r.p - p_com;
        let e_v = r.v - v_com;
        Nominal::integrate(&mut self.integral, &e_p, dt);
        let a_cmd = r.a + e_p * g.kp + e_v * g.kd + self.integral * g.ki;
        let force = nominal.force_for(&a_cmd);
        let r_d = Nominal::attitude_for(&force, r.yaw);
        let rm = m.r.matrix();
        let e_r = Nominal::attitude_error(&r_d, rm);
        let w_d = -e_r * g.k_att;
        let inertia = &nominal.inertia;
        let torque = inertia * (w_d - m.w) * g.k_rate + m.w.cross(&(inertia * m.w));
        let collective = -force.dot(&(rm * Vector3::z()));
        nominal.commands(collective, &torque)
    }
}
