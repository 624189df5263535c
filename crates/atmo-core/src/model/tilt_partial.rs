//! `d/dvarphi` of the composite body: how the dynamics change with the tilt.
//!
//! Arm j turns by `Rj = Rx(+-varphi)`, so `dRj/dvarphi = +-Rx'(+-varphi)`
//! (`Rx'` the derivative of [`rot_x`]). Every varphi-dependent quantity of
//! [`Model::at_tilt`] is a sum over the bodies of products with `Rj`:
//!
//! ```text
//! r     = A_j + Rj l            dr = dRj l
//! c     = sum m r               dc = sum m dr
//! I_B   = sum Rj J Rj' + m P(r) dI = sum (dRj J Rj' + Rj J dRj') + m dP,
//!                               P(r) = |r|^2 I - r r',  dP = 2 (r.dr) I - dr r' - r dr'
//! n_i   = -Rj e3                dn = -dRj e3
//! F_i   = kT n_i                dF = kT dn
//! T_i   = kT (r x n - s kM n)   dT = kT (dr x n + r x dn - s kM dn)
//! M_b^-1                        d(M_b^-1) = -M_b^-1 dM_b M_b^-1,  dM_b = [[0, -[dc]x], [[dc]x, dI]]
//! ```
//!
//! and with `rhs` the right side of the Newton-Euler equations
//! (see the [`crate::model`] docs), `acc = M_b^-1 rhs`:
//!
//! ```text
//! d acc = d(M_b^-1) rhs + M_b^-1 (dF u - w x (w x dc),  dT u + dc x g_b - w x (dI w))
//! df/dvarphi = (0, 0, R d acc_lin, d acc_ang)
//! ```
//!
//! Exact for the unfloored composite body (the floor of `at_tilt` only acts
//! with the authors' inertia convention above about 86 deg, outside the
//! flight envelope; there the derivative is that of the unfloored body).

use nalgebra::{Matrix3, Matrix3x4, Matrix6, Vector3, Vector6};

use super::{
    Input, Linearization, Model, ROTOR_ARM, State, TiltedBody, idx, rot_x, rotation, sin_cos, skew,
};

/// `d/dvarphi` of the varphi-dependent parts of a [`TiltedBody`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TiltPartial {
    pub first_moment: Vector3<f64>,
    pub inertia: Matrix3<f64>,
    pub mass_matrix_inv: Matrix6<f64>,
    pub thrust_force: Matrix3x4<f64>,
    pub thrust_torque: Matrix3x4<f64>,
    pub rotor_position: [Vector3<f64>; 4],
}

/// `d Rx(a) / da`.
fn rot_x_derivative(a: f64) -> Matrix3<f64> {
    let (s, c) = sin_cos(a);
    Matrix3::new(0.0, 0.0, 0.0, 0.0, -s, -c, 0.0, c, -s)
}

/// `d P(r)` for `P(r) = |r|^2 I - r r'`.
fn parallel_axis_derivative(r: &Vector3<f64>, dr: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::identity() * (2.0 * r.dot(dr)) - dr * r.transpose() - r * dr.transpose()
}

impl Model {
    /// The body at `varphi` and its derivative in varphi.
    pub fn at_tilt_with_partial(&self, varphi: f64) -> (TiltedBody, TiltPartial) {
        let body = self.at_tilt(varphi);
        let partial = self.tilt_partial(&body);
        (body, partial)
    }

    /// `d/dvarphi` of `body = self.at_tilt(varphi)`.
    pub fn tilt_partial(&self, body: &TiltedBody) -> TiltPartial {
        let varphi = body.varphi;
        let arm_rot = [rot_x(varphi), rot_x(-varphi)];
        let d_arm_rot = [rot_x_derivative(varphi), -rot_x_derivative(-varphi)];
        let mut dc = Vector3::zeros();
        let mut di = Matrix3::zeros();
        for arm in 0..2 {
            let (rot, drot) = (arm_rot[arm], d_arm_rot[arm]);
            let r = self.hinge[arm] + rot * self.hinge_to_com[arm];
            let dr = drot * self.hinge_to_com[arm];
            dc += dr * self.arm_mass;
            let j = self.arm_inertia[arm];
            di += drot * j * rot.transpose()
                + rot * j * drot.transpose()
                + parallel_axis_derivative(&r, &dr) * self.arm_mass;
        }
        let mut d_force = Matrix3x4::zeros();
        let mut d_torque = Matrix3x4::zeros();
        let mut d_position = [Vector3::zeros(); 4];
        for i in 0..4 {
            let arm = ROTOR_ARM[i];
            let (rot, drot) = (arm_rot[arm], d_arm_rot[arm]);
            let r = self.hinge[arm] + rot * self.hinge_to_rotor[i];
            let dr = drot * self.hinge_to_rotor[i];
            dc += dr * self.rotor_mass;
            let j = self.rotor_inertia;
            di += drot * j * rot.transpose()
                + rot * j * drot.transpose()
                + parallel_axis_derivative(&r, &dr) * self.rotor_mass;
            let axis = -rot.column(2).into_owned();
            let d_axis = -drot.column(2).into_owned();
            d_force.set_column(i, &(d_axis * self.k_thrust));
            let dt = (dr.cross(&axis) + r.cross(&d_axis)) * self.k_thrust
                - d_axis * (self.yaw_sign[i] * self.k_moment * self.k_thrust);
            d_torque.set_column(i, &dt);
            d_position[i] = dr;
        }
        let mut dm = Matrix6::zeros();
        dm.fixed_view_mut::<3, 3>(0, 3).copy_from(&(-skew(&dc)));
        dm.fixed_view_mut::<3, 3>(3, 0).copy_from(&skew(&dc));
        dm.fixed_view_mut::<3, 3>(3, 3).copy_from(&di);
        TiltPartial {
            first_moment: dc,
            inertia: di,
            mass_matrix_inv: -(body.mass_matrix_inv * dm * body.mass_matrix_inv),
            thrust_force: d_force,
            thrust_torque: d_torque,
            rotor_position: d_position,
        }
    }
}

impl TiltedBody {
    /// `df/dvarphi` at (x, u) given `partial = model.tilt_partial(self)`.
    pub fn tilt_derivative(&self, partial: &TiltPartial, x: &State, u: &Input) -> State {
        let w = Vector3::new(x[idx::WX], x[idx::WY], x[idx::WZ]);
        let g_b = self.gravity_body(x[idx::PITCH], x[idx::ROLL]);
        let c = &self.first_moment;
        let force = self.thrust_force * u + g_b * self.mass - w.cross(&w.cross(c));
        let torque = self.thrust_torque * u + c.cross(&g_b) - w.cross(&(self.inertia * w));
        let rhs = Vector6::new(force.x, force.y, force.z, torque.x, torque.y, torque.z)
            + self.disturbance;
        let dc = &partial.first_moment;
        let d_force = partial.thrust_force * u - w.cross(&w.cross(dc));
        let d_torque = partial.thrust_torque * u + dc.cross(&g_b) - w.cross(&(partial.inertia * w));
        let d_rhs = Vector6::new(
            d_force.x, d_force.y, d_force.z, d_torque.x, d_torque.y, d_torque.z,
        );
        let d_acc = partial.mass_matrix_inv * rhs + self.mass_matrix_inv * d_rhs;
        let r = rotation(x[idx::YAW], x[idx::PITCH], x[idx::ROLL]);
        let d_lin = r * Vector3::new(d_acc[0], d_acc[1], d_acc[2]);
        let mut out = State::zeros();
        out[idx::VX] = d_lin.x;
        out[idx::VY] = d_lin.y;
        out[idx::VZ] = d_lin.z;
        out[idx::WX] = d_acc[3];
        out[idx::WY] = d_acc[4];
        out[idx::WZ] = d_acc[5];
        out
    }

    /// [`TiltedBody::linearize`] and [`TiltedBody::tilt_derivative`] together.
    pub fn linearize_with_tilt(
        &self,
        partial: &TiltPartial,
        x: &State,
        u: &Input,
    ) -> (Linearization, State) {
        (self.linearize(x, u), self.tilt_derivative(partial, x, u))
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)] // reason: test set-up

    use super::*;
    use crate::ConfigFile as _;
    use crate::config::RobotConfig;

    fn model() -> Model {
        let text = include_str!("../../../../config/atmo.toml");
        Model::new(&RobotConfig::from_toml_str(text, "config/atmo.toml").unwrap())
    }

    #[test]
    fn tilt_derivative_matches_finite_differences() {
        let model = model();
        let mut x = State::zeros();
        x[idx::PITCH] = 0.07;
        x[idx::ROLL] = -0.05;
        x[idx::YAW] = 0.4;
        x[idx::WX] = 0.3;
        x[idx::WY] = -0.2;
        x[idx::WZ] = 0.15;
        let u = Input::new(0.6, 0.7, 0.8, 0.65);
        let eps = 1e-6;
        for varphi in [0.0, 0.5, 0.9, 1.15, 1.3] {
            let (body, partial) = model.at_tilt_with_partial(varphi);
            let body = body.with_disturbance(Vector6::new(0.5, -0.3, 1.0, 0.02, -0.01, 0.03));
            let analytic = body.tilt_derivative(&partial, &x, &u);
            let f = |v: f64| {
                model
                    .at_tilt(v)
                    .with_disturbance(body.disturbance)
                    .dynamics(&x, &u)
            };
            let fd = (f(varphi + eps) - f(varphi - eps)) / (2.0 * eps);
            let err = (fd - analytic).amax();
            assert!(err < 1e-6 * (1.0 + fd.amax()), "varphi {varphi}: {err}");
            let dpos = (model.at_tilt(varphi + eps).rotor_position[2]
                - model.at_tilt(varphi - eps).rotor_position[2])
                / (2.0 * eps);
            assert!((dpos - partial.rotor_position[2]).amax() < 1e-8);
            // The tilt matters: the derivative is not trivially zero.
            assert!(analytic.amax() > 0.1, "varphi {varphi}: {analytic}");
        }
    }
}
