//! The plant's rigid body: atmo-core's rigid-body equations with the
//! attitude trigonometry computed once per evaluation, the composite body
//! between tilts (interpolation on the plant's tilt grid), and the body with
//! the mass-property errors of the `mass_error` and `com_offset` effects.
//!
//! `TiltedBody::accelerations` and `TiltedBody::state_derivative` each take
//! the sines and cosines of the Euler angles again (7 `sin_cos` per `f`);
//! the plant also needs the rotation for its effects, so it computes one
//! [`Attitude`] (3 `sin_cos`) and calls atmo-core's formulas at it
//! (`accelerations_with_gravity`, `state_derivative_at`). The plant test
//! `with_every_effect_off_the_plant_is_atmo_core` checks that the result is
//! atmo-core's bit for bit.

use atmo_core::model::{Attitude, Input, Model, State, TiltedBody};
use nalgebra::{Cholesky, Matrix3, U6, Vector3, Vector6};

/// `TiltedBody::accelerations` at a precomputed attitude.
#[inline(always)]
pub(crate) fn accelerations(
    body: &TiltedBody,
    x: &State,
    att: &Attitude,
    u: &Input,
    extra: &Vector6<f64>,
) -> Vector6<f64> {
    body.accelerations_with_gravity(x, &att.gravity_body(body.gravity), u, extra)
}

/// The composite body a fraction `w` of the way from `a` to `b` (two
/// bodies at neighbouring tilts), every field interpolated linearly. On a
/// 0.25 deg grid the error against the exact body is below 1e-5 relative
/// (second-order in the spacing), far below the model errors the plant
/// simulates on purpose.
#[inline(always)]
pub fn lerp_body(a: &TiltedBody, b: &TiltedBody, w: f64, varphi: f64) -> TiltedBody {
    let v = 1.0 - w;
    TiltedBody {
        varphi,
        gravity: a.gravity,
        mass: a.mass * v + b.mass * w,
        first_moment: a.first_moment * v + b.first_moment * w,
        inertia: a.inertia * v + b.inertia * w,
        mass_matrix: a.mass_matrix * v + b.mass_matrix * w,
        mass_matrix_inv: a.mass_matrix_inv * v + b.mass_matrix_inv * w,
        thrust_force: a.thrust_force * v + b.thrust_force * w,
        thrust_torque: a.thrust_torque * v + b.thrust_torque * w,
        rotor_position: std::array::from_fn(|i| a.rotor_position[i] * v + b.rotor_position[i] * w),
        rotor_axis: std::array::from_fn(|i| a.rotor_axis[i] * v + b.rotor_axis[i] * w),
        disturbance: a.disturbance * v + b.disturbance * w,
    }
}

#[inline(always)]
fn skew(r: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -r.z, r.y, r.z, 0.0, -r.x, -r.y, r.x, 0.0)
}

/// The composite body at `tilt` with the mass-property errors applied:
/// mass and first moment scaled by `ms`, inertia about B by `is`, then the
/// whole mass distribution shifted by `d` (body frame):
/// `c' = c + m d`, `I' = I + m (|d|^2 1 - d d^T) + 2 (c . d) 1 - c d^T - d c^T`.
#[inline(never)] // out of line on purpose: see the AVX2 rule (plant::step)
pub(crate) fn effective_body(
    model: &Model,
    tilt: f64,
    mass_error: Option<(f64, f64)>,
    com_offset: Option<Vector3<f64>>,
) -> Option<TiltedBody> {
    let mut b = model.at_tilt(tilt);
    if mass_error.is_none() && com_offset.is_none() {
        return Some(b);
    }
    if let Some((ms, is)) = mass_error {
        b.mass *= ms;
        b.first_moment *= ms;
        b.inertia *= is;
    }
    if let Some(d) = com_offset {
        let (m, c) = (b.mass, b.first_moment);
        b.inertia += (Matrix3::identity() * d.norm_squared() - d * d.transpose()) * m
            + Matrix3::identity() * (2.0 * c.dot(&d))
            - c * d.transpose()
            - d * c.transpose();
        b.first_moment = c + d * m;
    }
    let mut mm = b.mass_matrix;
    mm.fixed_view_mut::<3, 3>(0, 0).fill_with_identity();
    mm.fixed_view_mut::<3, 3>(0, 0).scale_mut(b.mass);
    mm.fixed_view_mut::<3, 3>(0, 3)
        .copy_from(&(-skew(&b.first_moment)));
    mm.fixed_view_mut::<3, 3>(3, 0)
        .copy_from(&skew(&b.first_moment));
    mm.fixed_view_mut::<3, 3>(3, 3).copy_from(&b.inertia);
    b.mass_matrix = mm;
    b.mass_matrix_inv = Cholesky::<f64, U6>::new(mm)?.inverse();
    Some(b)
}
