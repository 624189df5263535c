//! Ground effect in the controller's model: the rotor thrust gain
//! `1 + g(h_i, varphi)` over a horizontal ground plane.
//!
//! Rotor i's hub is at `p_i = p + R(theta) r_i(varphi)` (NED); above a ground
//! plane at NED height `z_g` its height is `h_i = z_g - p_i,z`. The thrust of
//! rotor i is `kT u_i (1 + g(h_i, varphi))`, so with `u_eff,i = u_i (1 + g_i)`
//! the dynamics are atmo-core's at `u_eff` and, with `f` the nominal dynamics,
//!
//! ```text
//! df/du   = f_u(x, u_eff) diag(1 + g_i)
//! df/dx   = f_x(x, u_eff) + f_u(x, u_eff) diag(u_i) dg/dx
//! dg_i/dx = g_h(h_i, varphi) dh_i/dx,   dh_i/dz = -1,
//! dh_i/dpitch = -(dR/dpitch r_i)_z,  dh_i/droll = -(dR/droll r_i)_z  (yaw: 0)
//! ```
//!
//! The surface `g` is [`table::GroundEffect`] (the classical law, the
//! table after the paper's Fig. 3C and their blend, [`GroundEffectConfig`]),
//! the one the MPC predicts with and the plant flies through as its truth;
//! the dynamics need only its value and partials, through
//! [`ThrustGainSurface`].
//! RK4 and its exact sensitivities are shared with the nominal body
//! (atmo-core's `rk4_step` and `rk4_step_sensitivity` over [`Dynamics`]).

pub mod table;

use std::fmt::Debug;

use nalgebra::Vector3;

pub use table::{GroundEffect, GroundEffectConfig};

use crate::model::{
    Dynamics, Input, InputJacobian, Linearization, State, TiltPartial, TiltedBody, idx, rk4_step,
    sin_cos,
};

/// One RK4 step of `body`, with the thrust gains of `surface` above the
/// ground plane `z = ground_z` (NED, m) when there is a surface: the one
/// step the MPC's model, the disturbance observer and the flare's
/// touchdown prediction share.
pub fn rk4_step_above_ground(
    body: TiltedBody,
    surface: Option<&dyn ThrustGainSurface>,
    ground_z: f64,
    x: &State,
    u: &Input,
    dt: f64,
) -> State {
    match surface {
        Some(surface) => rk4_step(
            &GroundedBody {
                body,
                surface,
                ground_z,
            },
            x,
            u,
            dt,
        ),
        None => body.rk4_step(x, u, dt),
    }
}

/// `g(h, varphi)` and its partials, at one point.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct GainPartials {
    /// `T / T_inf - 1`.
    pub gain: f64,
    /// `dg/dh`, 1/m.
    pub d_height: f64,
    /// `dg/dvarphi`, 1/rad.
    pub d_tilt: f64,
}

/// A mean thrust-gain surface over hub height above ground (m) and tilt (rad).
/// Piecewise-smooth surfaces give the partials of the piece that holds the
/// point (one-sided at a kink).
pub trait ThrustGainSurface: Debug + Send + Sync {
    fn gain_partials(&self, height: f64, varphi: f64) -> GainPartials;
}

/// A tilted body above a horizontal ground plane with a thrust-gain surface.
#[derive(Debug, Clone, Copy)]
pub struct GroundedBody<'a, S: ThrustGainSurface + ?Sized> {
    pub body: TiltedBody,
    pub surface: &'a S,
    /// NED z of the ground plane, m.
    pub ground_z: f64,
}

/// Per rotor: the gain and `dg_i/d(z, pitch, roll)`.
struct RotorGains {
    gain: [f64; 4],
    /// `dg_i/dh` and `dg_i/dvarphi` (the surface's partials).
    d_height_raw: [f64; 4],
    d_tilt: [f64; 4],
    d_z: [f64; 4],
    d_pitch: [f64; 4],
    d_roll: [f64; 4],
}

impl<S: ThrustGainSurface + ?Sized> GroundedBody<'_, S> {
    /// Hub height of rotor i above the ground plane, m.
    pub fn hub_height(&self, x: &State, rotor: usize) -> f64 {
        let r = &self.body.rotor_position[rotor];
        let (sp, cp) = sin_cos(x[idx::PITCH]);
        let (sr, cr) = sin_cos(x[idx::ROLL]);
        // Third row of R(yaw, pitch, roll): (-sp, cp sr, cp cr).
        let down = -sp * r.x + cp * sr * r.y + cp * cr * r.z;
        self.ground_z - (x[idx::Z] + down)
    }

    fn rotor_gains(&self, x: &State) -> RotorGains {
        let (sp, cp) = sin_cos(x[idx::PITCH]);
        let (sr, cr) = sin_cos(x[idx::ROLL]);
        let mut out = RotorGains {
            gain: [0.0; 4],
            d_height_raw: [0.0; 4],
            d_tilt: [0.0; 4],
            d_z: [0.0; 4],
            d_pitch: [0.0; 4],
            d_roll: [0.0; 4],
        };
        for i in 0..4 {
            let r: &Vector3<f64> = &self.body.rotor_position[i];
            let down = -sp * r.x + cp * sr * r.y + cp * cr * r.z;
            let h = self.ground_z - (x[idx::Z] + down);
            let g = self.surface.gain_partials(h, self.body.varphi);
            out.gain[i] = g.gain;
            out.d_height_raw[i] = g.d_height;
            out.d_tilt[i] = g.d_tilt;
            // dh/dz = -1; dh/dpitch = -d(down)/dpitch; dh/droll = -d(down)/droll.
            out.d_z[i] = -g.d_height;
            out.d_pitch[i] = -g.d_height * (-cp * r.x - sp * sr * r.y - sp * cr * r.z);
            out.d_roll[i] = -g.d_height * (cp * cr * r.y - cp * sr * r.z);
        }
        out
    }

    /// [`Dynamics::linearize`] and `df/dvarphi` together, given
    /// `partial = model.tilt_partial(&self.body)`: with `u_eff,i = u_i (1 + g_i)`,
    /// `df/dvarphi = f_varphi(x, u_eff) + f_u(x, u_eff) diag(u_i) dg/dvarphi`,
    /// `dg_i/dvarphi = g_h dh_i/dvarphi + g_varphi`,
    /// `dh_i/dvarphi = -(R(theta) dr_i/dvarphi)_z`.
    pub fn linearize_with_tilt(
        &self,
        partial: &TiltPartial,
        x: &State,
        u: &Input,
    ) -> (Linearization, State) {
        let (sp, cp) = sin_cos(x[idx::PITCH]);
        let (sr, cr) = sin_cos(x[idx::ROLL]);
        let lin = self.linearize(x, u);
        let g = self.rotor_gains(x);
        let u_eff = Input::from_fn(|i, _| u[i] * (1.0 + g.gain[i]));
        let mut d_tilt = self.body.tilt_derivative(partial, x, &u_eff);
        for i in 0..4 {
            let dr = &partial.rotor_position[i];
            let d_height = -(-sp * dr.x + cp * sr * dr.y + cp * cr * dr.z);
            let dg = g.d_height_raw[i] * d_height + g.d_tilt[i];
            // lin.dfdu column i is f_u(x, u_eff) e_i (1 + g_i).
            d_tilt += lin.dfdu.column(i) * (u[i] * dg / (1.0 + g.gain[i]));
        }
        (lin, d_tilt)
    }

    /// The gains `g_i` at state x (for logs and tests).
    pub fn gains(&self, x: &State) -> [f64; 4] {
        self.rotor_gains(x).gain
    }
}

impl<S: ThrustGainSurface + ?Sized> Dynamics for GroundedBody<'_, S> {
    fn dynamics(&self, x: &State, u: &Input) -> State {
        let g = self.rotor_gains(x).gain;
        let u_eff = Input::from_fn(|i, _| u[i] * (1.0 + g[i]));
        self.body.dynamics(x, &u_eff)
    }

    fn linearize(&self, x: &State, u: &Input) -> Linearization {
        let g = self.rotor_gains(x);
        let u_eff = Input::from_fn(|i, _| u[i] * (1.0 + g.gain[i]));
        let nominal = self.body.linearize(x, &u_eff);
        let mut dfdx = nominal.dfdx;
        let mut dfdu = InputJacobian::zeros();
        for i in 0..4 {
            let column = nominal.dfdu.column(i);
            dfdu.set_column(i, &(column * (1.0 + g.gain[i])));
            for (col, dg) in [
                (idx::Z, g.d_z[i]),
                (idx::PITCH, g.d_pitch[i]),
                (idx::ROLL, g.d_roll[i]),
            ] {
                let mut target = dfdx.column_mut(col);
                target += column * (u[i] * dg);
            }
        }
        Linearization {
            xdot: nominal.xdot,
            dfdx,
            dfdu,
        }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)] // reason: test set-up

    use super::*;
    use crate::ConfigFile as _;
    use crate::config::RobotConfig;
    use crate::model::Model;
    use crate::model::{rk4_step, rk4_step_sensitivity};

    /// A smooth test surface, `g = a exp(-h / l) (1 + b varphi)`.
    #[derive(Debug)]
    struct Smooth;
    impl ThrustGainSurface for Smooth {
        fn gain_partials(&self, h: f64, varphi: f64) -> GainPartials {
            let (a, l, b) = (0.3, 0.2, 0.5);
            let e = a * (-h / l).exp();
            GainPartials {
                gain: e * (1.0 + b * varphi),
                d_height: -e / l * (1.0 + b * varphi),
                d_tilt: e * b,
            }
        }
    }

    fn model() -> Model {
        let text = include_str!("../../../../config/atmo.toml");
        Model::new(&RobotConfig::from_toml_str(text, "config/atmo.toml").unwrap())
    }

    #[test]
    fn linearization_matches_finite_differences() {
        let model = model();
        let surface = Smooth;
        let body = GroundedBody {
            body: model.at_tilt(0.9),
            surface: &surface,
            ground_z: 0.1,
        };
        let mut x = State::zeros();
        x[idx::Z] = -0.15;
        x[idx::PITCH] = 0.08;
        x[idx::ROLL] = -0.06;
        x[idx::YAW] = 0.3;
        x[idx::VZ] = 0.2;
        x[idx::WX] = 0.1;
        x[idx::WY] = -0.2;
        let u = Input::new(0.6, 0.7, 0.8, 0.65);
        let lin = body.linearize(&x, &u);
        let eps = 1e-6;
        for j in 0..12 {
            let mut xp = x;
            let mut xm = x;
            xp[j] += eps;
            xm[j] -= eps;
            let fd = (body.dynamics(&xp, &u) - body.dynamics(&xm, &u)) / (2.0 * eps);
            let err = (fd - lin.dfdx.column(j)).amax();
            assert!(err < 1e-6, "df/dx column {j}: {err}");
        }
        for j in 0..4 {
            let mut up = u;
            let mut um = u;
            up[j] += eps;
            um[j] -= eps;
            let fd = (body.dynamics(&x, &up) - body.dynamics(&x, &um)) / (2.0 * eps);
            let err = (fd - lin.dfdu.column(j)).amax();
            assert!(err < 1e-6, "df/du column {j}: {err}");
        }
        // The ground effect enters: height and attitude columns differ from
        // the nominal body's at the same effective input.
        let nominal = model.at_tilt(0.9).linearize(&x, &u);
        assert!((lin.dfdx.column(idx::Z) - nominal.dfdx.column(idx::Z)).amax() > 1e-2);
        let step = rk4_step_sensitivity(&body, &x, &u, 0.1);
        for j in 0..12 {
            let mut xp = x;
            let mut xm = x;
            xp[j] += eps;
            xm[j] -= eps;
            let fd = (rk4_step(&body, &xp, &u, 0.1) - rk4_step(&body, &xm, &u, 0.1)) / (2.0 * eps);
            let err = (fd - step.a.column(j)).amax();
            assert!(err < 1e-6, "RK4 A column {j}: {err}");
        }
    }

    #[test]
    fn tilt_derivative_matches_finite_differences() {
        let model = model();
        let surface = Smooth;
        let mut x = State::zeros();
        x[idx::Z] = -0.15;
        x[idx::PITCH] = 0.08;
        x[idx::ROLL] = -0.06;
        x[idx::WX] = 0.1;
        let u = Input::new(0.6, 0.7, 0.8, 0.65);
        let eps = 1e-6;
        let at = |v: f64| GroundedBody {
            body: model.at_tilt(v),
            surface: &surface,
            ground_z: 0.1,
        };
        for varphi in [0.3, 0.9, 1.2] {
            let grounded = at(varphi);
            let partial = model.tilt_partial(&grounded.body);
            let (lin, d_tilt) = grounded.linearize_with_tilt(&partial, &x, &u);
            assert_eq!(lin, grounded.linearize(&x, &u));
            let fd = (at(varphi + eps).dynamics(&x, &u) - at(varphi - eps).dynamics(&x, &u))
                / (2.0 * eps);
            let err = (fd - d_tilt).amax();
            assert!(err < 1e-6 * (1.0 + fd.amax()), "varphi {varphi}: {err}");
            // The surface's own tilt and height terms are in it.
            let nominal = grounded.body.tilt_derivative(&partial, &x, &u);
            assert!((d_tilt - nominal).amax() > 1e-2, "varphi {varphi}");
        }
    }

    #[test]
    fn hub_height_is_the_ground_distance_of_the_hub() {
        let model = model();
        let surface = Smooth;
        let body = GroundedBody {
            body: model.at_tilt(0.5),
            surface: &surface,
            ground_z: 0.0,
        };
        let mut x = State::zeros();
        x[idx::Z] = -1.0;
        x[idx::PITCH] = 0.2;
        let r = crate::model::rotation(0.0, 0.2, 0.0);
        for i in 0..4 {
            let hub = Vector3::new(0.0, 0.0, -1.0) + r * body.body.rotor_position[i];
            assert!((body.hub_height(&x, i) + hub.z).abs() < 1e-12);
        }
    }

    /// A table from 0 deg leaves no classical law: at 0 deg the table's
    /// first row applies, in the surface and in its partials alike.
    #[test]
    fn a_table_from_zero_tilt_applies_at_zero_tilt() {
        use table::{GroundEffect, GroundEffectConfig};
        let config = GroundEffectConfig {
            classical_below_deg: 0.0,
            heights: vec![0.2, 0.8],
            tilts_deg: vec![0.0, 90.0],
            gain: vec![vec![0.05, 0.0], vec![0.05, 0.0]],
            std: vec![vec![0.0; 2]; 2],
            ..GroundEffectConfig::default()
        };
        let surface = GroundEffect::new(&config);
        assert!((surface.gain(0.2, 0.0).mean - 0.05).abs() < 1e-12);
        assert!((surface.gain_partials(0.2, 0.0).gain - 0.05).abs() < 1e-12);
    }
}
