//! The plant's effects that are neither ground effect, contact nor sensors:
//! wind (steady, turbulence, gusts), rotor and body drag, and the wheel drive
//! parameters. Step code: every function here is `#[inline(always)]` (the
//! AVX2 rule, module `step`).

use atmo_core::model::{Input, TiltedBody};
use nalgebra::{Matrix3, Vector3, Vector6};
use rand_chacha::ChaCha8Rng;

use crate::config::{DragConfig, WindConfig};
use crate::noise::GaussMarkov;

/// The wheel drive of each side: a PI speed controller with a torque limit
/// on a wheel of this inertia.
#[derive(Debug, Clone, Copy)]
pub(super) struct Drive {
    pub inertia: f64,
    pub kp: f64,
    pub ki: f64,
    pub torque_max: f64,
}

/// Wind: steady + per-axis Gauss-Markov turbulence + scripted 1 - cos gusts.
#[derive(Debug, Clone)]
pub(super) struct Wind {
    pub config: WindConfig,
    pub turbulence: [GaussMarkov; 3],
    pub rng: ChaCha8Rng,
}

impl Wind {
    /// Wind velocity (NED, m/s) at `time` with the turbulence as it stands.
    #[inline(always)]
    pub fn at(&self, time: f64) -> Vector3<f64> {
        let c = &self.config;
        let mut w = Vector3::from(c.steady);
        for k in 0..3 {
            w[k] += c.turbulence_std[k] * self.turbulence[k].value;
        }
        for g in &c.gusts {
            if time >= g.t && time < g.t + g.duration {
                let shape =
                    0.5 * (1.0 - (2.0 * std::f64::consts::PI * (time - g.t) / g.duration).cos());
                w += Vector3::from(g.velocity) * shape;
            }
        }
        w
    }
}

/// Drag wrench on the body (body force, torque about B): body drag
/// `-1/2 rho CdA_k |v_k| v_k` per body axis on the air velocity
/// `v_air = R^T (v - wind)` acting at `centre` (body frame), and rotor drag
/// `-k_r t_i (v_i - (v_i . n_i) n_i)` at each hub with thrust `t_i > 0`
/// (v_i the hub's air velocity).
#[inline(always)]
pub(super) fn drag_wrench(
    drag: &DragConfig,
    body: &TiltedBody,
    centre: &Vector3<f64>,
    r: &Matrix3<f64>,
    air_velocity_world: &Vector3<f64>,
    w: &Vector3<f64>,
    t: &Input,
) -> Vector6<f64> {
    let v_air = r.transpose() * air_velocity_world;
    let q = 0.5 * drag.air_density;
    let mut force = -Vector3::new(
        q * drag.body_cd_area[0] * v_air.x.abs() * v_air.x,
        q * drag.body_cd_area[1] * v_air.y.abs() * v_air.y,
        q * drag.body_cd_area[2] * v_air.z.abs() * v_air.z,
    );
    // Torques about B: the body drag's, acting at `centre`; each rotor's
    // drag adds its own at its hub below.
    let mut torque = centre.cross(&force);
    for i in 0..4 {
        if t[i] <= 0.0 {
            continue; // rotor drag scales with thrust
        }
        let n = &body.rotor_axis[i];
        let vi = v_air + w.cross(&body.rotor_position[i]);
        let axial = n * vi.dot(n);
        let fi = -((vi - axial) * drag.rotor_drag + axial * drag.axial_drag) * t[i].max(0.0);
        force += fi;
        torque += body.rotor_position[i].cross(&fi);
    }
    Vector6::new(force.x, force.y, force.z, torque.x, torque.y, torque.z)
}
