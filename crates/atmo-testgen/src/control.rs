//! Cascaded PID at the recording rate, knowing only the robot file's
//! nominal rigid body.
//!
//! Position: `a_cmd = a_ref + kp e_p + kd e_v + ki int e_p` (NED); the thrust
//! vector `F = m (a_cmd - g e_z)` sets the desired body -z axis and, with
//! the reference yaw, the desired attitude `R_d`. Attitude:
//! `e_R = vee(R_d^T R - R^T R_d) / 2`, desired rates `w_d = -k_att e_R`,
//! torque `tau = I_c k_rate (w_d - w) + w x I_c w`. Allocation: the 4x4
//! map from rotor thrusts to (thrust along body -z, torque about the
//! nominal CoM) inverted once; commands `u = T / k_thrust` clamped to
//! [0, 1].

use nalgebra::{Matrix3, Matrix4, Rotation3, Vector3, Vector4};

use crate::robot::RigidBody;

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

/// A measured state: base position and velocity (NED), attitude, rates.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Measured {
    pub p: Vector3<f64>,
    pub v: Vector3<f64>,
    pub r: Rotation3<f64>,
    pub w: Vector3<f64>,
}

/// Reference: position, velocity, acceleration (NED), yaw.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Reference {
    pub p: Vector3<f64>,
    pub v: Vector3<f64>,
    pub a: Vector3<f64>,
    pub yaw: f64,
}

/// The controller and its integrator.
#[derive(Debug, Clone, PartialEq)]
pub struct Controller {
    gains: Gains,
    mass: f64,
    gravity: f64,
    inertia: Matrix3<f64>,
    com: Vector3<f64>,
    k_thrust: f64,
    allocation_inv: Matrix4<f64>,
    integral: Vector3<f64>,
}

fn vee(m: &Matrix3<f64>) -> Vector3<f64> {
    Vector3::new(m[(2, 1)], m[(0, 2)], m[(1, 0)])
}

impl Controller {
    /// For the nominal body (the robot file's).
    pub fn new(nominal: &RigidBody, gains: Gains) -> Self {
        let mut alloc = Matrix4::zeros();
        for i in 0..4 {
            let mut unit = [0.0; 4];
            unit[i] = 1.0;
            let (f, t) = nominal.rotor_wrench(&unit);
            alloc.set_column(i, &Vector4::new(-f.z, t.x, t.y, t.z));
        }
        Self {
            gains,
            mass: nominal.mass,
            gravity: nominal.gravity,
            inertia: nominal.inertia_com,
            com: nominal.com,
            k_thrust: nominal.k_thrust,
            allocation_inv: alloc.try_inverse().unwrap_or_else(Matrix4::zeros),
            integral: Vector3::zeros(),
        }
    }

    /// Hover command of the nominal body (per rotor).
    pub fn hover_command(&self) -> f64 {
        self.mass * self.gravity / (4.0 * self.k_thrust)
    }

    /// Commands for one sample of `dt`.
    pub fn command(&mut self, m: &Measured, r: &Reference, dt: f64) -> [f64; 4] {
        let g = &self.gains;
        // The CoM's motion is what the thrust accelerates.
        let p_com = m.p + m.r * self.com;
        let v_com = m.v + m.r * m.w.cross(&self.com);
        let e_p = r.p - p_com;
        let e_v = r.v - v_com;
        self.integral += e_p * dt;
        let limit = 2.0;
        self.integral = self.integral.map(|x| x.clamp(-limit, limit));
        let a_cmd = r.a + e_p * g.kp + e_v * g.kd + self.integral * g.ki;
        let force = (a_cmd - Vector3::new(0.0, 0.0, self.gravity)) * self.mass;
        let z_d = -force.normalize();
        // Desired body axes: z_d = -F/|F|, x_d from the yaw.
        let heading = Vector3::new(r.yaw.cos(), r.yaw.sin(), 0.0);
        let y_d = z_d.cross(&heading).normalize();
        let x_d = y_d.cross(&z_d);
        let r_d = Matrix3::from_columns(&[x_d, y_d, z_d]);
        let rm = m.r.matrix();
        let e_r = vee(&(r_d.transpose() * rm - rm.transpose() * r_d)) * 0.5;
        let w_d = -e_r * g.k_att;
        let torque = self.inertia * (w_d - m.w) * g.k_rate + m.w.cross(&(self.inertia * m.w));
        let collective = -force.dot(&(rm * Vector3::z()));
        let thrust =
            self.allocation_inv * Vector4::new(collective.max(0.0), torque.x, torque.y, torque.z);
        let mut u = [0.0; 4];
        for i in 0..4 {
            u[i] = (thrust[i] / self.k_thrust).clamp(0.0, 1.0);
        }
        u
    }
}
