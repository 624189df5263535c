//! A discrete LQR at the recording rate: one gain on the whole state,
//! where the PID nests three loops.
//!
//! Design model (the nominal body in hover, heading frame, NED):
//!
//! ```text
//! e_p' = e_v          e_v' = (-g th_y, g th_x, -dc / m)
//! th'  = w            w'   = I_c^-1 tau         (int e_p)' = e_p
//! ```
//!
//! with `th` the attitude error against the attitude that points the
//! reference's thrust, `dc` the collective beyond it. Discretized for a
//! command held over a sample (the matrix exponential of the augmented
//! system), the gain from the discrete Riccati equation by iteration,
//! weights by Bryson's rule ([`Weights`]). Flown: `[dc, tau] = -K x`, the
//! reference thrust's collective and `w x I_c w` added.

use nalgebra::{SMatrix, SVector, Vector3};

use crate::control::{Control, Measured, Nominal, Reference};

const NX: usize = 15;
const NU: usize = 4;
const NA: usize = NX + NU;

/// Largest acceptable excursion of each state and input (Bryson's rule:
/// weight `1 / max^2`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Weights {
    /// Position (m), velocity (m/s), attitude (rad), rates (rad/s),
    /// position integral (m s).
    pub position: f64,
    pub velocity: f64,
    pub attitude: f64,
    pub rate: f64,
    pub integral: f64,
    /// Collective (N), roll/pitch torque and yaw torque (N m).
    pub collective: f64,
    pub torque: f64,
    pub yaw_torque: f64,
}

impl Default for Weights {
    fn default() -> Self {
        Self {
            position: 0.1,
            velocity: 0.4,
            attitude: 0.15,
            rate: 1.0,
            integral: 0.3,
            collective: 8.0,
            torque: 0.6,
            yaw_torque: 0.3,
        }
    }
}

/// The controller and its integrator.
#[derive(Debug, Clone, PartialEq)]
pub struct Lqr {
    nominal: Nominal,
    gain: SMatrix<f64, NU, NX>,
    integral: Vector3<f64>,
}

impl Lqr {
    /// The gain for the nominal body at the sample time `dt` (s).
    pub fn new(nominal: Nominal, weights: Weights, dt: f64) -> Self {
        let mut a = SMatrix::<f64, NX, NX>::zeros();
        let mut b = SMatrix::<f64, NX, NU>::zeros();
        let g = nominal.gravity;
        for i in 0..3 {
            a[(i, 3 + i)] = 1.0;
            a[(6 + i, 9 + i)] = 1.0;
            a[(12 + i, i)] = 1.0;
        }
        a[(3, 7)] = -g;
        a[(4, 6)] = g;
        b[(5, 0)] = -1.0 / nominal.mass;
        let inertia_inv = nominal.inertia.try_inverse().unwrap_or_default();
        b.fixed_view_mut::<3, 3>(9, 1).copy_from(&inertia_inv);
        // Zero-order hold: exp([[A, B], [0, 0]] dt).
        let mut aug = SMatrix::<f64, NA, NA>::zeros();
        aug.fixed_view_mut::<NX, NX>(0, 0).copy_from(&(a * dt));
        aug.fixed_view_mut::<NX, NU>(0, NX).copy_from(&(b * dt));
        let held = aug.exp();
        let ad = held.fixed_view::<NX, NX>(0, 0).into_owned();
        let bd = held.fixed_view::<NX, NU>(0, NX).into_owned();
        let w = &weights;
        let per_state = [w.position, w.velocity, w.attitude, w.rate, w.integral];
        let q = SMatrix::<f64, NX, NX>::from_diagonal(&SVector::from_fn(|i, _| {
            per_state[i / 3].powi(-2)
        }));
        let r = SMatrix::<f64, NU, NU>::from_diagonal(&SVector::from([
            w.collective.powi(-2),
            w.torque.powi(-2),
            w.torque.powi(-2),
            w.yaw_torque.powi(-2),
        ]));
        Self {
            nominal,
            gain: riccati_gain(&ad, &bd, &q, &r),
            integral: Vector3::zeros(),
        }
    }

    /// The state feedback gain (inputs x states).
    pub fn gain(&self) -> &SMatrix<f64, NU, NX> {
        &self.gain
    }
}

/// The steady gain of the discrete Riccati recursion
/// `P <- Q + A^T P (A - B K)`, `K = (R + B^T P B)^-1 B^T P A`, iterated
/// until P stops changing.
fn riccati_gain(
    a: &SMatrix<f64, NX, NX>,
    b: &SMatrix<f64, NX, NU>,
    q: &SMatrix<f64, NX, NX>,
    r: &SMatrix<f64, NU, NU>,
) -> SMatrix<f64, NU, NX> {
    let mut p = *q;
    let mut k = SMatrix::<f64, NU, NX>::zeros();
    for _ in 0..200_000 {
        let bt_p = b.transpose() * p;
        let s = r + bt_p * b;
        k = s.try_inverse().unwrap_or_default() * bt_p * a;
        let next = q + a.transpose() * p * (a - b * k);
        let next = (next + next.transpose()) * 0.5;
        let change = (next - p).abs().max() / next.abs().max().max(1e-12);
        p = next;
        if change < 1e-12 {
            break;
        }
    }
    k
}

impl Control for Lqr {
    fn command(&mut self, m: &Measured, r: &Reference, dt: f64) -> [f64; 4] {
        let nominal = &self.nominal;
        let (p_com, v_com) = nominal.com_motion(m);
        let e_p = p_com - r.p;
        Nominal::integrate(&mut self.integral, &e_p, dt);
        let force = nominal.force_for(&r.a);
        let r_d = Nominal::attitude_for(&force, r.yaw);
        let rm = m.r.matrix();
        // Errors in the heading frame, where the design model holds.
        let (s, c) = r.yaw.sin_cos();
        let to_heading = |v: Vector3<f64>| Vector3::new(c * v.x + s * v.y, -s * v.x + c * v.y, v.z);
        let mut x = SVector::<f64, NX>::zeros();
        x.fixed_rows_mut::<3>(0).copy_from(&to_heading(e_p));
        x.fixed_rows_mut::<3>(3).copy_from(&to_heading(v_com - r.v));
        x.fixed_rows_mut::<3>(6)
            .copy_from(&Nominal::attitude_error(&r_d, rm));
        x.fixed_rows_mut::<3>(9).copy_from(&m.w);
        x.fixed_rows_mut::<3>(12)
            .copy_from(&to_heading(self.integral));
        let nu = -(self.gain * x);
        let inertia = &nominal.inertia;
        let torque = Vector3::new(nu[1], nu[2], nu[3]) + m.w.cross(&(inertia * m.w));
        let collective = -force.dot(&(rm * Vector3::z())) + nu[0];
        nominal.commands(collective, &torque)
    }
}
