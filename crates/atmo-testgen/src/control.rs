//! What the generator's controllers share: the measured state, the
//! reference, the nominal body they know (the robot file's only), and the
//! steps before and after each control law: the centre of mass's motion
//! from the measured base, the attitude that points the thrust, and the
//! allocation of a collective thrust and a torque to the four rotors (the
//! 4x4 map from rotor thrusts to thrust along body -z and torque about the
//! nominal CoM, inverted once; commands `u = T / k_thrust` clamped to
//! [0, 1]).
//!
//! Two laws, so that a finder rule chosen on one controller's flights can
//! be checked on the other's: [`crate::pid`] (cascaded PID) and
//! [`crate::lqr`] (a discrete LQR on the full state).

use nalgebra::{Matrix3, Matrix4, Rotation3, Vector3, Vector4};

use crate::robot::RigidBody;

/// Largest position integral either controller keeps, per axis (m s).
pub const INTEGRAL_LIMIT: f64 = 2.0;

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

/// A control law computing at the recording rate.
pub trait Control {
    /// Commands for one sample of `dt`.
    fn command(&mut self, m: &Measured, r: &Reference, dt: f64) -> [f64; 4];
}

/// Which control law flies the generator's flight.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum ControllerKind {
    /// Cascaded PID (position, attitude, rate).
    #[default]
    Pid,
    /// Discrete LQR on position, velocity, attitude, rates and the
    /// position integral, designed for the recording rate.
    Lqr,
}

/// The nominal rigid body as the controllers know it.
#[derive(Debug, Clone, PartialEq)]
pub struct Nominal {
    pub mass: f64,
    pub gravity: f64,
    pub inertia: Matrix3<f64>,
    pub com: Vector3<f64>,
    pub k_thrust: f64,
    allocation_inv: Matrix4<f64>,
}

fn vee(m: &Matrix3<f64>) -> Vector3<f64> {
    Vector3::new(m[(2, 1)], m[(0, 2)], m[(1, 0)])
}

impl Nominal {
    pub fn new(body: &RigidBody) -> Self {
        let mut alloc = Matrix4::zeros();
        for i in 0..4 {
            let mut unit = [0.0; 4];
            unit[i] = 1.0;
            let (f, t) = body.rotor_wrench(&unit);
            alloc.set_column(i, &Vector4::new(-f.z, t.x, t.y, t.z));
        }
        Self {
            mass: body.mass,
            gravity: body.gravity,
            inertia: body.inertia_com,
            com: body.com,
            k_thrust: body.k_thrust,
            allocation_inv: alloc.try_inverse().unwrap_or_else(Matrix4::zeros),
        }
    }

    /// Hover command of the nominal body (per rotor).
    pub fn hover_command(&self) -> f64 {
        self.mass * self.gravity / (4.0 * self.k_thrust)
    }

    /// Position and velocity of the centre of mass (NED): what the thrust
    /// accelerates.
    pub fn com_motion(&self, m: &Measured) -> (Vector3<f64>, Vector3<f64>) {
        (m.p + m.r * self.com, m.v + m.r * m.w.cross(&self.com))
    }

    /// The world force (N) giving the acceleration `a` (NED) against gravity.
    pub fn force_for(&self, a: &Vector3<f64>) -> Vector3<f64> {
        (a - Vector3::new(0.0, 0.0, self.gravity)) * self.mass
    }

    /// The attitude whose body -z is along `force`, body x towards `yaw`.
    pub fn attitude_for(force: &Vector3<f64>, yaw: f64) -> Matrix3<f64> {
        let z_d = -force.normalize();
        let heading = Vector3::new(yaw.cos(), yaw.sin(), 0.0);
        let y_d = z_d.cross(&heading).normalize();
        let x_d = y_d.cross(&z_d);
        Matrix3::from_columns(&[x_d, y_d, z_d])
    }

    /// Attitude error `vee(R_d^T R - R^T R_d) / 2` (body frame; the small
    /// rotation from `r_d` to `r`).
    pub fn attitude_error(r_d: &Matrix3<f64>, r: &Matrix3<f64>) -> Vector3<f64> {
        vee(&(r_d.transpose() * r - r.transpose() * r_d)) * 0.5
    }

    /// Adds `e dt` to a position integral (m s), each axis held within
    /// [`INTEGRAL_LIMIT`] (anti-windup).
    pub fn integrate(integral: &mut Vector3<f64>, e: &Vector3<f64>, dt: f64) {
        *integral = (*integral + e * dt).map(|x| x.clamp(-INTEGRAL_LIMIT, INTEGRAL_LIMIT));
    }

    /// Rotor commands for a collective thrust along body -z (N) and a
    /// torque about the nominal CoM (N m).
    pub fn commands(&self, collective: f64, torque: &Vector3<f64>) -> [f64; 4] {
        let thrust =
            self.allocation_inv * Vector4::new(collective.max(0.0), torque.x, torque.y, torque.z);
        std::array::from_fn(|i| (thrust[i] / self.k_thrust).clamp(0.0, 1.0))
    }
}
