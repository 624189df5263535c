//! The tilt-planning prediction model: ATMO's 12 states plus the tilt
//! varphi, its 4 rotor commands plus the tilt rate omega.
//!
//! ```text
//! z = (x, varphi),  v = (u, omega),  z_dot = (f(x, u, varphi), omega)
//! dz_dot/dz = [[f_x, f_varphi], [0, 0]],  dz_dot/dv = [[f_u, 0], [0, 1]]
//! ```
//!
//! `f` is atmo-core's body at tilt varphi (with the ground effect when the
//! MPC has a surface), `f_varphi` its exact tilt derivative
//! (atmo-core `TiltPartial`). With omega held over a stage, RK4 propagates
//! the tilt exactly (`varphi_{k+1} = varphi_k + dt omega_k`), and
//! atmo-core's generic RK4 sensitivities give the exact derivative of the
//! discrete map, as for the nominal model.

use atmo_core::ground_effect::{GroundedBody, ThrustGainSurface};
use atmo_core::model::{Dynamics, Input, Linearization, Model, NU, NX, State, TiltedBody};
use nalgebra::{SMatrix, SVector, Vector6};

/// States of the tilt-planning model.
pub const NXT: usize = NX + 1;
/// Inputs of the tilt-planning model.
pub const NUT: usize = NU + 1;
/// Index of varphi in the state.
pub const TILT: usize = NX;
/// Index of the tilt rate in the input.
pub const TILT_RATE: usize = NU;

pub type TiltState = SVector<f64, NXT>;
pub type TiltInput = SVector<f64, NUT>;

/// `(x, varphi)`.
pub fn tilt_state(x: &State, varphi: f64) -> TiltState {
    TiltState::from_fn(|i, _| if i < NX { x[i] } else { varphi })
}

/// `(u, omega)`.
pub fn tilt_input(u: &Input, omega: f64) -> TiltInput {
    TiltInput::from_fn(|i, _| if i < NU { u[i] } else { omega })
}

/// ATMO with the tilt as a state.
#[derive(Clone, Copy)]
pub struct TiltingBody<'a> {
    pub model: &'a Model,
    /// The constant wrench of the offset-free MPC (see atmo-core `TiltedBody`).
    pub disturbance: Vector6<f64>,
    pub surface: Option<&'a dyn ThrustGainSurface>,
    /// NED z of the ground plane, m.
    pub ground_z: f64,
}

impl TiltingBody<'_> {
    fn body(&self, varphi: f64) -> TiltedBody {
        self.model
            .at_tilt(varphi)
            .with_disturbance(self.disturbance)
    }

    fn split(z: &TiltState, v: &TiltInput) -> (State, Input) {
        (
            z.fixed_rows::<NX>(0).into_owned(),
            v.fixed_rows::<NU>(0).into_owned(),
        )
    }
}

impl Dynamics<NXT, NUT> for TiltingBody<'_> {
    fn dynamics(&self, z: &TiltState, v: &TiltInput) -> TiltState {
        let (x, u) = Self::split(z, v);
        let body = self.body(z[TILT]);
        let f = match self.surface {
            Some(surface) => GroundedBody {
                body,
                surface,
                ground_z: self.ground_z,
            }
            .dynamics(&x, &u),
            None => body.dynamics(&x, &u),
        };
        tilt_state(&f, v[TILT_RATE])
    }

    fn linearize(&self, z: &TiltState, v: &TiltInput) -> Linearization<NXT, NUT> {
        let (x, u) = Self::split(z, v);
        let body = self.body(z[TILT]);
        let partial = self.model.tilt_partial(&body);
        let (lin, f_tilt): (Linearization, State) = match self.surface {
            Some(surface) => GroundedBody {
                body,
                surface,
                ground_z: self.ground_z,
            }
            .linearize_with_tilt(&partial, &x, &u),
            None => body.linearize_with_tilt(&partial, &x, &u),
        };
        let mut dfdx = SMatrix::<f64, NXT, NXT>::zeros();
        dfdx.fixed_view_mut::<NX, NX>(0, 0).copy_from(&lin.dfdx);
        dfdx.fixed_view_mut::<NX, 1>(0, TILT).copy_from(&f_tilt);
        let mut dfdu = SMatrix::<f64, NXT, NUT>::zeros();
        dfdu.fixed_view_mut::<NX, NU>(0, 0).copy_from(&lin.dfdu);
        dfdu[(TILT, TILT_RATE)] = 1.0;
        Linearization {
            xdot: tilt_state(&lin.xdot, v[TILT_RATE]),
            dfdx,
            dfdu,
        }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)] // reason: test set-up

    use atmo_core::ConfigFile as _;
    use atmo_core::config::RobotConfig;
    use atmo_core::ground_effect::GainPartials;
    use atmo_core::model::{idx, rk4_step, rk4_step_sensitivity};

    use super::*;

    #[derive(Debug)]
    struct Smooth;
    impl ThrustGainSurface for Smooth {
        fn gain_partials(&self, h: f64, varphi: f64) -> GainPartials {
            let e = 0.3 * (-h / 0.2).exp();
            GainPartials {
                gain: e * (1.0 + 0.5 * varphi),
                d_height: -e / 0.2 * (1.0 + 0.5 * varphi),
                d_tilt: e * 0.5,
            }
        }
    }

    #[test]
    fn rk4_sensitivity_of_the_tilting_body_matches_finite_differences() {
        let text = include_str!("../../../config/atmo.toml");
        let model = Model::new(&RobotConfig::from_toml_str(text, "config/atmo.toml").unwrap());
        let surface = Smooth;
        let mut x = State::zeros();
        x[idx::Z] = -0.2;
        x[idx::PITCH] = 0.05;
        x[idx::ROLL] = -0.04;
        x[idx::VZ] = 0.2;
        x[idx::WY] = 0.1;
        let z = tilt_state(&x, 1.0);
        let v = tilt_input(&Input::new(0.8, 0.85, 0.8, 0.9), 0.35);
        for surface in [None, Some(&surface as &dyn ThrustGainSurface)] {
            let f = TiltingBody {
                model: &model,
                disturbance: Vector6::new(0.3, 0.0, -0.5, 0.01, 0.0, 0.0),
                surface,
                ground_z: 0.0,
            };
            let dt = 0.1;
            let s = rk4_step_sensitivity(&f, &z, &v, dt);
            // The tilt is propagated exactly.
            assert!((s.next[TILT] - (1.0 + 0.35 * dt)).abs() < 1e-14);
            let eps = 1e-6;
            for j in 0..NXT {
                let mut zp = z;
                let mut zm = z;
                zp[j] += eps;
                zm[j] -= eps;
                let fd = (rk4_step(&f, &zp, &v, dt) - rk4_step(&f, &zm, &v, dt)) / (2.0 * eps);
                let err = (fd - s.a.column(j)).amax();
                assert!(err < 1e-6, "A column {j}: {err}");
            }
            for j in 0..NUT {
                let mut vp = v;
                let mut vm = v;
                vp[j] += eps;
                vm[j] -= eps;
                let fd = (rk4_step(&f, &z, &vp, dt) - rk4_step(&f, &z, &vm, dt)) / (2.0 * eps);
                let err = (fd - s.b.column(j)).amax();
                assert!(err < 1e-6, "B column {j}: {err}");
            }
            // The tilt moves the vertical velocity (thrust axis) over a stage.
            assert!(s.a[(idx::VZ, TILT)].abs() > 0.1);
            assert!(s.b[(idx::VZ, TILT_RATE)].abs() > 1e-3);
        }
    }
}
