//! The simulated flight: Newton-Euler about the centre of mass with a unit
//! quaternion attitude (not the flight stack's Euler-angle, base-origin
//! formulation), RK4 on a fixed sub-step, the rotor commands held over
//! each recording sample, and the concealed effects.
//!
//! ```text
//! p_c' = v_c                      m v_c' = R f_b + m g e_z (NED)
//! q'   = q (0, w) / 2             I_c w' = tau_c - w x I_c w
//! ```
//!
//! with `f_b`, `tau_c` the body force and torque about the centre of mass
//! of the rotor thrusts and the effects. The base origin B is at
//! `p = p_c - R c`, `v = v_c - R (w x c)` (c: CoM relative to B).

use nalgebra::{UnitQuaternion, Vector3};

use crate::robot::RigidBody;

/// Air density used by the body drag (kg/m^3).
pub const AIR_DENSITY: f64 = 1.225;

/// How the thrust rises to its steady value.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum MotorLag {
    /// First-order lag of each rotor's thrust, time constant (s).
    Thrust(f64),
    /// First-order lag of each rotor's speed, thrust as its square: a rise
    /// faster from high speed than from low; the same time constant (s)
    /// for small steps.
    RotorSpeed(f64),
}

/// Ground effect on each rotor's thrust.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum GroundEffect {
    /// Cheeseman-Bennett, `T / (1 - (R / 4 z)^2)`: rotor radius R (m), z
    /// the hub height along the rotor axis.
    CheesemanBennett(f64),
    /// A gain `T / T_inf - 1` continuous in the hub height h and the tilt:
    /// `G(varphi) exp(-(h - 0.25 m) / 0.1 m)` with `G` a smooth curve
    /// through 5 % up to 30 deg, a peak of 15 % at 55 deg (between the
    /// finder's table rows), 0 at 65 deg and suction (-6 %) from 75 deg, the
    /// shape of the paper's Fig. 3C.
    Continuous,
}

/// Where the centre of mass moved.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ComOffset {
    /// The centre of mass moved by this (body, m), the inertia about it
    /// unchanged.
    MovedCentre([f64; 3]),
    /// A battery of [`BATTERY_MASS`] at the base origin slid so the centre
    /// of mass moves by this (body, m): the composite inertia (parallel
    /// axes of battery and the rest) and every rotor's moment arm follow.
    Composite([f64; 3]),
}

/// Mass of the battery [`ComOffset::Composite`] slides (kg).
pub const BATTERY_MASS: f64 = 1.2;

/// Shape of the command-to-thrust curve (thrust per `k_thrust`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ThrustCurve {
    /// `(1 - b) u + b u^2`.
    Quadratic(f64),
    /// `u^e`.
    Power(f64),
}

/// The physics the robot file does not know (all off by default).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Concealed {
    pub ground_effect: Option<GroundEffect>,
    pub motor_lag: Option<MotorLag>,
    /// Rotor drag `-k_r T (in-plane hub air velocity)` (N per N of thrust
    /// per m/s) and body drag areas `Cd A` along body x, y, z (m^2).
    pub drag: Option<(f64, [f64; 3])>,
    /// Steady wind (NED, m/s); only felt through the drag.
    pub wind: [f64; 3],
    pub com_offset: Option<ComOffset>,
    /// Thrust = (1 + s) times the file's.
    pub thrust_scale: Option<f64>,
    pub thrust_curve: Option<ThrustCurve>,
}

/// Gain of [`GroundEffect::Continuous`] at hub height `h` (m) and tilt
/// `varphi` (rad).
pub fn continuous_ground_gain(h: f64, varphi: f64) -> f64 {
    // (tilt deg, G): joined by smoothsteps, flat at each knot.
    const KNOTS: [(f64, f64); 5] = [
        (30.0, 0.05),
        (55.0, 0.15),
        (65.0, 0.0),
        (75.0, -0.06),
        (90.0, -0.06),
    ];
    let deg = varphi.to_degrees();
    let mut g = KNOTS[0].1;
    for pair in KNOTS.windows(2) {
        let ((a, ga), (b, gb)) = (pair[0], pair[1]);
        if deg > a {
            let x = ((deg - a) / (b - a)).clamp(0.0, 1.0);
            g = ga + (gb - ga) * x * x * (3.0 - 2.0 * x);
        }
    }
    g * (-(h.max(0.05) - 0.25) / 0.1).exp()
}

/// State of the true body.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Body {
    /// Centre of mass, NED (m).
    pub p_com: Vector3<f64>,
    /// Velocity of the centre of mass, NED (m/s).
    pub v_com: Vector3<f64>,
    /// Body (FRD) to world (NED).
    pub q: UnitQuaternion<f64>,
    /// Body rates, FRD (rad/s).
    pub w: Vector3<f64>,
    /// Each rotor's lag state ([`Truth::lag_state`]): its thrust (N), or
    /// for a rotor-speed lag the square root of it.
    pub thrust: [f64; 4],
}

/// The true robot: the file's rigid body with the concealed effects.
#[derive(Debug, Clone, PartialEq)]
pub struct Truth {
    pub body: RigidBody,
    pub fx: Concealed,
    /// NED z of the ground plane.
    pub ground_z: f64,
}

/// Time derivative of [`Body`] (the same fields as rates).
#[derive(Debug, Clone, Copy)]
struct Rate {
    p: Vector3<f64>,
    v: Vector3<f64>,
    w_quat: Vector3<f64>,
    w: Vector3<f64>,
    thrust: [f64; 4],
}

impl Truth {
    pub fn new(body: RigidBody, fx: Concealed) -> Self {
        let body = match fx.com_offset {
            None => body,
            Some(ComOffset::MovedCentre(d)) => RigidBody {
                com: body.com + Vector3::from(d),
                ..body
            },
            Some(ComOffset::Composite(d)) => {
                // The battery sits at the base origin.
                let slide = Vector3::from(d) * (body.mass / BATTERY_MASS);
                body.with_mass_moved(BATTERY_MASS, &Vector3::zeros(), &slide)
            }
        };
        Self {
            body,
            fx,
            ground_z: 0.0,
        }
    }

    /// Thrust a command gives in steady state (N).
    pub fn steady_thrust(&self, u: f64) -> f64 {
        let shape = match self.fx.thrust_curve {
            None => u,
            Some(ThrustCurve::Quadratic(b)) => (1.0 - b) * u + b * u * u,
            Some(ThrustCurve::Power(e)) => u.max(0.0).powf(e),
        };
        self.body.k_thrust * shape * (1.0 + self.fx.thrust_scale.unwrap_or(0.0))
    }

    /// The lag state of a rotor at a steady `thrust` (N).
    pub fn lag_state(&self, thrust: f64) -> f64 {
        match self.fx.motor_lag {
            Some(MotorLag::RotorSpeed(_)) => thrust.max(0.0).sqrt(),
            _ => thrust,
        }
    }

    /// Base-origin position and velocity (NED).
    pub fn base(&self, s: &Body) -> (Vector3<f64>, Vector3<f64>) {
        let c = self.body.com;
        (s.p_com - s.q * c, s.v_com - s.q * s.w.cross(&c))
    }

    /// A body at rest-in-hover at base position `p`, level, thrusts at hover.
    pub fn at(&self, p: Vector3<f64>, hover_thrust: f64) -> Body {
        Body {
            p_com: p + self.body.com,
            v_com: Vector3::zeros(),
            q: UnitQuaternion::identity(),
            w: Vector3::zeros(),
            thrust: [self.lag_state(hover_thrust); 4],
        }
    }

    fn rate(&self, s: &Body, u: &[f64; 4]) -> Rate {
        let b = &self.body;
        let mut thrust_rate = [0.0; 4];
        let mut t = s.thrust;
        for i in 0..4 {
            let steady = self.steady_thrust(u[i]);
            match self.fx.motor_lag {
                Some(MotorLag::Thrust(tau)) => thrust_rate[i] = (steady - s.thrust[i]) / tau,
                Some(MotorLag::RotorSpeed(tau)) => {
                    thrust_rate[i] = (self.lag_state(steady) - s.thrust[i]) / tau;
                    t[i] = s.thrust[i] * s.thrust[i];
                }
                None => t[i] = steady,
            }
        }
        if let Some(ge) = self.fx.ground_effect {
            for i in 0..4 {
                let hub = s.p_com + s.q * (b.rotor_position[i] - b.com);
                let height = self.ground_z - hub.z;
                match ge {
                    GroundEffect::CheesemanBennett(radius) => {
                        let axis_z = (s.q * b.rotor_axis[i]).z.abs().max(0.2);
                        let along = (height / axis_z).max(radius / 2.0);
                        t[i] /= 1.0 - (radius / (4.0 * along)).powi(2);
                    }
                    GroundEffect::Continuous => {
                        t[i] *= 1.0 + continuous_ground_gain(height, b.varphi);
                    }
                }
            }
        }
        let (mut force, mut torque) = b.rotor_wrench(&t);
        if let Some((k_rotor, cda)) = self.fx.drag {
            let rot = s.q.to_rotation_matrix();
            let v_air_com = rot.transpose() * (s.v_com - Vector3::from(self.fx.wind));
            for i in 0..4 {
                let arm = b.rotor_position[i] - b.com;
                let v_hub = v_air_com + s.w.cross(&arm);
                let n = b.rotor_axis[i];
                let in_plane = v_hub - n * n.dot(&v_hub);
                let f = -in_plane * (k_rotor * t[i]);
                force += f;
                torque += arm.cross(&f);
            }
            for k in 0..3 {
                let v = v_air_com[k];
                force[k] -= 0.5 * AIR_DENSITY * cda[k] * v.abs() * v;
            }
        }
        let gravity = Vector3::new(0.0, 0.0, b.gravity);
        let i_w = b.inertia_com * s.w;
        let w_dot = b
            .inertia_com
            .try_inverse()
            .unwrap_or_else(nalgebra::Matrix3::identity)
            * (torque - s.w.cross(&i_w));
        Rate {
            p: s.v_com,
            v: s.q * force / b.mass + gravity,
            w_quat: s.w,
            w: w_dot,
            thrust: thrust_rate,
        }
    }

    /// World acceleration of the base origin B and body angular
    /// acceleration: `a_B = a_c - R (w' x c + w x (w x c))`.
    pub fn base_accelerations(&self, s: &Body, u: &[f64; 4]) -> (Vector3<f64>, Vector3<f64>) {
        let r = self.rate(s, u);
        let c = self.body.com;
        let a = r.v - s.q * (r.w.cross(&c) + s.w.cross(&s.w.cross(&c)));
        (a, r.w)
    }

    /// A body whose base origin B is at `p` with velocity `v` (NED),
    /// attitude `q`, rates `w`; thrusts in steady state for `u`.
    pub fn from_base(
        &self,
        p: Vector3<f64>,
        v: Vector3<f64>,
        q: UnitQuaternion<f64>,
        w: Vector3<f64>,
        u: &[f64; 4],
    ) -> Body {
        let c = self.body.com;
        Body {
            p_com: p + q * c,
            v_com: v + q * w.cross(&c),
            q,
            w,
            thrust: u.map(|x| self.lag_state(self.steady_thrust(x))),
        }
    }

    fn advance(s: &Body, r: &Rate, h: f64) -> Body {
        let mut thrust = s.thrust;
        for i in 0..4 {
            thrust[i] += r.thrust[i] * h;
        }
        Body {
            p_com: s.p_com + r.p * h,
            v_com: s.v_com + r.v * h,
            q: s.q * UnitQuaternion::from_scaled_axis(r.w_quat * h),
            w: s.w + r.w * h,
            thrust,
        }
    }

    /// One RK4 step of `h` with the commands `u` held.
    pub fn step(&self, s: &Body, u: &[f64; 4], h: f64) -> Body {
        let k1 = self.rate(s, u);
        let k2 = self.rate(&Self::advance(s, &k1, h / 2.0), u);
        let k3 = self.rate(&Self::advance(s, &k2, h / 2.0), u);
        let k4 = self.rate(&Self::advance(s, &k3, h), u);
        let mix = |a: Vector3<f64>, b: Vector3<f64>, c: Vector3<f64>, d: Vector3<f64>| {
            (a + b * 2.0 + c * 2.0 + d) / 6.0
        };
        let mut thrust = [0.0; 4];
        for (i, t) in thrust.iter_mut().enumerate() {
            *t = (k1.thrust[i] + 2.0 * k2.thrust[i] + 2.0 * k3.thrust[i] + k4.thrust[i]) / 6.0;
        }
        let mean = Rate {
            p: mix(k1.p, k2.p, k3.p, k4.p),
            v: mix(k1.v, k2.v, k3.v, k4.v),
            w_quat: mix(k1.w_quat, k2.w_quat, k3.w_quat, k4.w_quat),
            w: mix(k1.w, k2.w, k3.w, k4.w),
            thrust,
        };
        Self::advance(s, &mean, h)
    }
}
