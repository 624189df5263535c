//! The 7-body model of ATMO: base, two arms, four rotors.
//!
//! The tilt varphi is a parameter, not a state: at a given varphi the seven
//! bodies form one rigid body, so the projected Newton-Euler equations
//! `M(q, varphi) nu_dot + b + g = S(varphi)^T u` reduce to the composite body
//! about the base origin B. With `c = sum m_i r_i` (first moment about B),
//! `I_B = sum (I_i + m_i [r_i]x^T [r_i]x)`, body-frame acceleration of B
//! `a = R^T v_dot` and gravity in body axes `g_b = R^T (0, 0, g)`:
//!
//! ```text
//! m a + w_dot x c + w x (w x c)     = A_F u + m g_b
//! I_B w_dot + c x a + w x (I_B w)   = A_T u + c x g_b
//! ```
//!
//! The left side is the constant (per varphi) symmetric matrix
//! `M_b = [[m I, -[c]x], [[c]x, I_B]]`, factored once per tilt. `A_F`, `A_T`
//! (3x4) map normalized rotor commands to body force and torque about B:
//! rotor i at `r_i` with thrust axis `n_i` contributes `kT n_i` and
//! `kT (r_i x n_i) - s_i kM kT n_i` (s_i the yaw sign).
//!
//! State x (12): p (NED, m), Euler ZYX (yaw, pitch, roll), world velocity of
//! B, body rates. `x_dot = (v, E(theta)^-1 w, R a, w_dot)`.
//!
//! Parity with the authors' model (checked to 1e-9 against their 60 points,
//! reached to about 1e-14): the listed arm inertia is used as the tensor
//! about the hinge A, as listed for the left arm and with the xz and yz
//! products negated for the right arm. Rotor spin (gyroscopic) terms and all
//! aerodynamics are left out, as in their model; atmo-sim adds them.

use nalgebra::{
    Cholesky, Matrix3, Matrix3x4, Matrix6, SMatrix, SVector, U6, Vector3, Vector4, Vector6,
};

use crate::config::{ArmInertiaConvention, RobotConfig};

mod stopped_rotor;
mod tilt_partial;
pub use tilt_partial::TiltPartial;

/// Number of states.
pub const NX: usize = 12;
/// Number of inputs (normalized rotor commands).
pub const NU: usize = 4;

pub type State = SVector<f64, NX>;
pub type Input = SVector<f64, NU>;
pub type StateJacobian = SMatrix<f64, NX, NX>;
pub type InputJacobian = SMatrix<f64, NX, NU>;

/// Index of each state in x.
pub mod idx {
    pub const X: usize = 0;
    pub const Y: usize = 1;
    pub const Z: usize = 2;
    pub const YAW: usize = 3;
    pub const PITCH: usize = 4;
    pub const ROLL: usize = 5;
    pub const VX: usize = 6;
    pub const VY: usize = 7;
    pub const VZ: usize = 8;
    pub const WX: usize = 9;
    pub const WY: usize = 10;
    pub const WZ: usize = 11;
}

/// `(sin x, cos x)` from the pure-Rust `libm` rather than the platform's C
/// library: the same bits on every machine (glibc versions, the robot's
/// aarch64 computer), so a seeded simulation replays bit for bit anywhere,
/// and about a third faster than glibc's `sincos` here (BENCHMARKS.md).
/// Every attitude sine and cosine of the model and of the plant goes
/// through it.
#[inline]
pub fn sin_cos(x: f64) -> (f64, f64) {
    libm::sincos(x)
}

/// Rotation about the body x axis.
pub fn rot_x(a: f64) -> Matrix3<f64> {
    let (s, c) = sin_cos(a);
    Matrix3::new(1.0, 0.0, 0.0, 0.0, c, -s, 0.0, s, c)
}

/// How level the body of `state` is: the cosine of the angle between its
/// z axis and the vertical, `cos(roll) cos(pitch)` (1 level, 0 on its
/// side, negative upside down).
pub fn level_cosine(state: &State) -> f64 {
    state[idx::ROLL].cos() * state[idx::PITCH].cos()
}

/// Body-to-world rotation for Euler ZYX angles: `R = Rz(yaw) Ry(pitch) Rx(roll)`.
pub fn rotation(yaw: f64, pitch: f64, roll: f64) -> Matrix3<f64> {
    rotation_of(sin_cos(yaw), sin_cos(pitch), sin_cos(roll))
}

/// [`rotation`] from the (sine, cosine) of yaw, pitch and roll.
#[allow(clippy::inline_always)] // the plant's AVX2 step inlines it (atmo-plant `avx2_rule`)
#[inline(always)]
fn rotation_of((sy, cy): (f64, f64), (sp, cp): (f64, f64), (sr, cr): (f64, f64)) -> Matrix3<f64> {
    Matrix3::new(
        cy * cp,
        cy * sp * sr - sy * cr,
        cy * sp * cr + sy * sr,
        sy * cp,
        sy * sp * sr + cy * cr,
        sy * sp * cr - cy * sr,
        -sp,
        cp * sr,
        cp * cr,
    )
}

/// The sines and cosines of one attitude's pitch and roll, and its
/// rotation: computed once per evaluation where several formulas need them.
#[derive(Debug, Clone, Copy)]
pub struct Attitude {
    pub sp: f64,
    pub cp: f64,
    pub sr: f64,
    pub cr: f64,
    /// Body to world, [`rotation`].
    pub r: Matrix3<f64>,
}

impl Attitude {
    /// The attitude of state `x` (the same operations as [`rotation`]).
    #[allow(clippy::inline_always)] // the plant's AVX2 step inlines it (atmo-plant `avx2_rule`)
    #[inline(always)]
    pub fn of(x: &State) -> Self {
        let yaw = sin_cos(x[idx::YAW]);
        let (sp, cp) = sin_cos(x[idx::PITCH]);
        let (sr, cr) = sin_cos(x[idx::ROLL]);
        let r = rotation_of(yaw, (sp, cp), (sr, cr));
        Self { sp, cp, sr, cr, r }
    }

    /// Gravity in the body frame for a gravitational acceleration `g`.
    #[allow(clippy::inline_always)] // the plant's AVX2 step inlines it (atmo-plant `avx2_rule`)
    #[inline(always)]
    pub fn gravity_body(&self, g: f64) -> Vector3<f64> {
        Vector3::new(-self.sp, self.cp * self.sr, self.cp * self.cr) * g
    }
}

/// `x_dot` of state `x` at attitude `att` (that of `x`) given body-frame
/// accelerations (a, w_dot): the kinematics of the 12-state model, the one
/// copy ([`TiltedBody::state_derivative`] and the plant's step).
/// `inline(always)`: the plant's AVX2 step inlines it.
#[allow(clippy::inline_always)] // the plant's AVX2 step inlines it (atmo-plant `avx2_rule`)
#[inline(always)]
pub fn state_derivative_at(x: &State, att: &Attitude, acc: &Vector6<f64>) -> State {
    let a = att.r * Vector3::new(acc[0], acc[1], acc[2]);
    let (sr, cr, sp, cp) = (att.sr, att.cr, att.sp, att.cp);
    let (wx, wy, wz) = (x[idx::WX], x[idx::WY], x[idx::WZ]);
    let q = sr * wy + cr * wz;
    let mut xdot = State::zeros();
    xdot[idx::X] = x[idx::VX];
    xdot[idx::Y] = x[idx::VY];
    xdot[idx::Z] = x[idx::VZ];
    xdot[idx::YAW] = q / cp;
    xdot[idx::PITCH] = cr * wy - sr * wz;
    xdot[idx::ROLL] = wx + sp / cp * q;
    xdot[idx::VX] = a.x;
    xdot[idx::VY] = a.y;
    xdot[idx::VZ] = a.z;
    xdot[idx::WX] = acc[3];
    xdot[idx::WY] = acc[4];
    xdot[idx::WZ] = acc[5];
    xdot
}

/// Partial derivatives of [`rotation`] with respect to yaw, pitch and roll.
pub fn rotation_partials(yaw: f64, pitch: f64, roll: f64) -> [Matrix3<f64>; 3] {
    let (sy, cy) = sin_cos(yaw);
    let (sp, cp) = sin_cos(pitch);
    let (sr, cr) = sin_cos(roll);
    let d_yaw = Matrix3::new(
        -sy * cp,
        -sy * sp * sr - cy * cr,
        -sy * sp * cr + cy * sr,
        cy * cp,
        cy * sp * sr - sy * cr,
        cy * sp * cr + sy * sr,
        0.0,
        0.0,
        0.0,
    );
    let d_pitch = Matrix3::new(
        -cy * sp,
        cy * cp * sr,
        cy * cp * cr,
        -sy * sp,
        sy * cp * sr,
        sy * cp * cr,
        -cp,
        -sp * sr,
        -sp * cr,
    );
    let d_roll = Matrix3::new(
        0.0,
        cy * sp * cr + sy * sr,
        -cy * sp * sr + sy * cr,
        0.0,
        sy * sp * cr - cy * sr,
        -sy * sp * sr - cy * cr,
        0.0,
        cp * cr,
        -cp * sr,
    );
    [d_yaw, d_pitch, d_roll]
}

fn skew(r: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -r.z, r.y, r.z, 0.0, -r.x, -r.y, r.x, 0.0)
}

/// `[r]x^T [r]x = |r|^2 I - r r^T`: the parallel-axis tensor of a unit mass at r.
fn parallel_axis(r: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::identity() * r.norm_squared() - r * r.transpose()
}

/// Smallest principal moment about the CoM kept by the floor, kg m^2.
pub const MIN_PRINCIPAL_INERTIA: f64 = 1e-3;

/// Raises the principal moments about the centre of mass to
/// [`MIN_PRINCIPAL_INERTIA`] and returns the tensor about B again.
fn floor_inertia_about_com(
    inertia_b: &Matrix3<f64>,
    first_moment: &Vector3<f64>,
    mass: f64,
) -> Matrix3<f64> {
    let shift = parallel_axis(first_moment) / mass;
    let eig = (inertia_b - shift).symmetric_eigen();
    let floored = eig.eigenvalues.map(|l| l.max(MIN_PRINCIPAL_INERTIA));
    eig.eigenvectors * Matrix3::from_diagonal(&floored) * eig.eigenvectors.transpose() + shift
}

/// Robot constants the dynamics need, taken from a [`RobotConfig`].
#[derive(Debug, Clone, PartialEq)]
pub struct Model {
    pub gravity: f64,
    base_mass: f64,
    base_inertia: Matrix3<f64>,
    arm_mass: f64,
    /// Right and left arm tensors about their centres of mass, arm frames.
    arm_inertia: [Matrix3<f64>; 2],
    /// Hinge positions A (right, left), body frame.
    hinge: [Vector3<f64>; 2],
    /// Hinge to arm CoM (right, left), arm frames.
    hinge_to_com: [Vector3<f64>; 2],
    /// Hinge to rotor i, in the frame of the arm that carries it.
    hinge_to_rotor: [Vector3<f64>; 4],
    rotor_mass: f64,
    rotor_inertia: Matrix3<f64>,
    pub k_thrust: f64,
    pub k_moment: f64,
    yaw_sign: [f64; 4],
}

/// Which arm carries rotor i (0 = right, 1 = left); PX4 quad-x numbering.
const ROTOR_ARM: [usize; 4] = [0, 1, 1, 0];

impl Model {
    pub fn new(config: &RobotConfig) -> Self {
        let mirror_y = Vector3::new(1.0, -1.0, 1.0);
        let mirror_x = Vector3::new(-1.0, 1.0, 1.0);
        let hinge_r = Vector3::from(config.arm.base_to_hinge);
        let com_r = Vector3::from(config.arm.hinge_to_com);
        let com_l = com_r.component_mul(&mirror_y);
        let rotor1 = Vector3::from(config.arm.hinge_to_rotor1);
        let listed = config.arm.inertia.matrix();
        let m_arm = config.arm.mass;
        let [arm_right, arm_left] = match config.arm.inertia_convention {
            ArmInertiaConvention::AuthorsModel => {
                let flip_z = Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, -1.0));
                [
                    flip_z * listed * flip_z - parallel_axis(&com_r) * m_arm,
                    listed - parallel_axis(&com_l) * m_arm,
                ]
            }
            ArmInertiaConvention::AboutCom => {
                let mirror = Matrix3::from_diagonal(&mirror_y);
                [listed, mirror * listed * mirror]
            }
        };
        let [rxx, ryy, rzz] = config.rotor.inertia;
        Self {
            gravity: config.environment.gravity,
            base_mass: config.base.mass,
            base_inertia: config.base.inertia.matrix(),
            arm_mass: m_arm,
            arm_inertia: [arm_right, arm_left],
            hinge: [hinge_r, hinge_r.component_mul(&mirror_y)],
            hinge_to_com: [com_r, com_l],
            hinge_to_rotor: [
                rotor1,                                                   // 1 front-right
                rotor1.component_mul(&mirror_x).component_mul(&mirror_y), // 2 back-left
                rotor1.component_mul(&mirror_y),                          // 3 front-left
                rotor1.component_mul(&mirror_x),                          // 4 back-right
            ],
            rotor_mass: config.rotor.mass,
            rotor_inertia: Matrix3::from_diagonal(&Vector3::new(rxx, ryy, rzz)),
            k_thrust: config.rotor.k_thrust,
            k_moment: config.rotor.k_moment,
            yaw_sign: config.rotor.yaw_sign,
        }
    }

    /// Total mass, kg.
    pub fn mass(&self) -> f64 {
        self.base_mass + 2.0 * self.arm_mass + 4.0 * self.rotor_mass
    }

    /// Weight, N.
    pub fn weight(&self) -> f64 {
        self.mass() * self.gravity
    }

    /// Sum of the rotors' full thrust, N.
    pub fn max_total_thrust(&self) -> f64 {
        4.0 * self.k_thrust
    }

    /// The composite rigid body at tilt `varphi` (rad).
    pub fn at_tilt(&self, varphi: f64) -> TiltedBody {
        // Right arm rotates by +varphi about body x, the left arm by -varphi.
        let arm_rot = [rot_x(varphi), rot_x(-varphi)];
        let (first_moment, mut inertia, mass) = self.at_tilt_unfloored(varphi);
        let mut thrust_force = Matrix3x4::zeros();
        let mut thrust_torque = Matrix3x4::zeros();
        let mut rotor_position = [Vector3::zeros(); 4];
        let mut rotor_axis = [Vector3::zeros(); 4];
        for i in 0..4 {
            let arm = ROTOR_ARM[i];
            let rot = arm_rot[arm];
            let r = self.hinge[arm] + rot * self.hinge_to_rotor[i];
            // Thrust along the arm's -z (up at varphi = 0).
            let axis = -rot.column(2).into_owned();
            thrust_force.set_column(i, &(axis * self.k_thrust));
            let torque = r.cross(&axis) * self.k_thrust
                - axis * (self.yaw_sign[i] * self.k_moment * self.k_thrust);
            thrust_torque.set_column(i, &torque);
            rotor_position[i] = r;
            rotor_axis[i] = axis;
        }
        let mut mass_matrix = Matrix6::zeros();
        mass_matrix.fixed_view_mut::<3, 3>(0, 0).fill_diagonal(mass);
        mass_matrix
            .fixed_view_mut::<3, 3>(0, 3)
            .copy_from(&(-skew(&first_moment)));
        mass_matrix
            .fixed_view_mut::<3, 3>(3, 0)
            .copy_from(&skew(&first_moment));
        mass_matrix.fixed_view_mut::<3, 3>(3, 3).copy_from(&inertia);
        let mass_matrix_inv = if let Some(chol) = Cholesky::<f64, U6>::new(mass_matrix) {
            chol.inverse()
        } else {
            // Only the authors' inertia convention gets here, above ~86 deg
            // (validation keeps it out of the flight envelope). Floor the
            // principal moments about the CoM so that the body stays a body.
            inertia = floor_inertia_about_com(&inertia, &first_moment, mass);
            mass_matrix.fixed_view_mut::<3, 3>(3, 3).copy_from(&inertia);
            Cholesky::<f64, U6>::new(mass_matrix)
                .expect("floored composite inertia is positive definite")
                .inverse()
        };
        TiltedBody {
            varphi,
            gravity: self.gravity,
            mass,
            first_moment,
            inertia,
            mass_matrix,
            mass_matrix_inv,
            thrust_force,
            thrust_torque,
            rotor_position,
            rotor_axis,
            disturbance: Vector6::zeros(),
        }
    }

    /// Whether the composite body at `varphi` is physical without flooring
    /// (positive-definite inertia about its centre of mass).
    pub fn composite_is_physical(&self, varphi: f64) -> bool {
        let body = self.at_tilt_unfloored(varphi);
        let about_com = body.1 - parallel_axis(&body.0) / body.2;
        about_com.symmetric_eigenvalues().min() > 0.0
    }

    /// First moment, inertia about B and mass, without the floor of `at_tilt`.
    fn at_tilt_unfloored(&self, varphi: f64) -> (Vector3<f64>, Matrix3<f64>, f64) {
        let arm_rot = [rot_x(varphi), rot_x(-varphi)];
        let mut mass = self.base_mass;
        let mut first_moment = Vector3::zeros();
        let mut inertia = self.base_inertia;
        for arm in 0..2 {
            let r = self.hinge[arm] + arm_rot[arm] * self.hinge_to_com[arm];
            mass += self.arm_mass;
            first_moment += r * self.arm_mass;
            inertia += arm_rot[arm] * self.arm_inertia[arm] * arm_rot[arm].transpose()
                + parallel_axis(&r) * self.arm_mass;
        }
        for i in 0..4 {
            let rot = arm_rot[ROTOR_ARM[i]];
            let r = self.hinge[ROTOR_ARM[i]] + rot * self.hinge_to_rotor[i];
            mass += self.rotor_mass;
            first_moment += r * self.rotor_mass;
            inertia +=
                rot * self.rotor_inertia * rot.transpose() + parallel_axis(&r) * self.rotor_mass;
        }
        (first_moment, inertia, mass)
    }

    /// `x_dot = f(x, u, varphi)`.
    pub fn dynamics(&self, x: &State, u: &Input, varphi: f64) -> State {
        self.at_tilt(varphi).dynamics(x, u)
    }
}

/// ATMO frozen at one tilt: the composite body and its actuation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TiltedBody {
    pub varphi: f64,
    pub gravity: f64,
    /// kg.
    pub mass: f64,
    /// `c = sum m_i r_i` about B, body frame (kg m).
    pub first_moment: Vector3<f64>,
    /// `I_B`, about B, body frame.
    pub inertia: Matrix3<f64>,
    /// `M_b` in body-frame generalized velocities (a, w_dot).
    pub mass_matrix: Matrix6<f64>,
    pub mass_matrix_inv: Matrix6<f64>,
    /// Body force per unit rotor command (N).
    pub thrust_force: Matrix3x4<f64>,
    /// Body torque about B per unit rotor command (N m).
    pub thrust_torque: Matrix3x4<f64>,
    /// Rotor hub positions, body frame (m).
    pub rotor_position: [Vector3<f64>; 4],
    /// Unit thrust directions, body frame.
    pub rotor_axis: [Vector3<f64>; 4],
    /// A constant wrench (body force, body torque about B) added to the
    /// dynamics: the disturbance an offset-free controller estimates (CoM
    /// offset, mass error, steady wind...). Zero from [`Model::at_tilt`].
    pub disturbance: Vector6<f64>,
}

/// `x_dot` with its Jacobians (N states, M inputs; ATMO's 12 and 4 by default).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Linearization<const N: usize = NX, const M: usize = NU> {
    pub xdot: SVector<f64, N>,
    pub dfdx: SMatrix<f64, N, N>,
    pub dfdu: SMatrix<f64, N, M>,
}

/// An RK4 step with its sensitivities.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepSensitivity<const N: usize = NX, const M: usize = NU> {
    pub next: SVector<f64, N>,
    /// dx+/dx.
    pub a: SMatrix<f64, N, N>,
    /// dx+/du.
    pub b: SMatrix<f64, N, M>,
}

impl TiltedBody {
    /// The same body with a constant disturbance wrench (see `disturbance`).
    /// The Jacobians do not change: the wrench is constant in x and u.
    #[must_use]
    pub fn with_disturbance(mut self, wrench: Vector6<f64>) -> Self {
        self.disturbance = wrench;
        self
    }

    /// Gravity in body axes, `R^T (0, 0, g)`.
    fn gravity_body(&self, pitch: f64, roll: f64) -> Vector3<f64> {
        let (sp, cp) = sin_cos(pitch);
        let (sr, cr) = sin_cos(roll);
        Vector3::new(-sp, cp * sr, cp * cr) * self.gravity
    }

    /// Body-frame generalized accelerations (a, w_dot) for body force and
    /// torque about B from everything but gravity and the rotors (`extra`).
    /// atmo-sim passes its aerodynamic and contact wrenches here.
    pub fn accelerations(&self, x: &State, u: &Input, extra: &Vector6<f64>) -> Vector6<f64> {
        let g_b = self.gravity_body(x[idx::PITCH], x[idx::ROLL]);
        self.accelerations_with_gravity(x, &g_b, u, extra)
    }

    /// [`Self::accelerations`] with the gravity in the body frame already
    /// computed (`g_b = g (-sin p, cos p sin r, cos p cos r)`): the one
    /// formula, shared by the plant, which holds the attitude's sines once
    /// per evaluation. `inline(always)`: the plant's AVX2 step inlines it.
    #[allow(clippy::inline_always)] // the plant's AVX2 step inlines it (atmo-plant `avx2_rule`)
    #[inline(always)]
    pub fn accelerations_with_gravity(
        &self,
        x: &State,
        g_b: &Vector3<f64>,
        u: &Input,
        extra: &Vector6<f64>,
    ) -> Vector6<f64> {
        let w = Vector3::new(x[idx::WX], x[idx::WY], x[idx::WZ]);
        let c = &self.first_moment;
        let force = self.thrust_force * u + g_b * self.mass - w.cross(&w.cross(c));
        let torque = self.thrust_torque * u + c.cross(g_b) - w.cross(&(self.inertia * w));
        let rhs = Vector6::new(force.x, force.y, force.z, torque.x, torque.y, torque.z)
            + extra
            + self.disturbance;
        self.mass_matrix_inv * rhs
    }

    /// `x_dot` given body-frame accelerations (a, w_dot).
    pub fn state_derivative(x: &State, acc: &Vector6<f64>) -> State {
        state_derivative_at(x, &Attitude::of(x), acc)
    }

    /// `x_dot = f(x, u)` at this tilt.
    pub fn dynamics(&self, x: &State, u: &Input) -> State {
        Self::state_derivative(x, &self.accelerations(x, u, &Vector6::zeros()))
    }

    /// `x_dot` and the analytic Jacobians df/dx, df/du.
    pub fn linearize(&self, x: &State, u: &Input) -> Linearization {
        let (yaw, pitch, roll) = (x[idx::YAW], x[idx::PITCH], x[idx::ROLL]);
        let w = Vector3::new(x[idx::WX], x[idx::WY], x[idx::WZ]);
        let acc = self.accelerations(x, u, &Vector6::zeros());
        let xdot = Self::state_derivative(x, &acc);
        let a_body = Vector3::new(acc[0], acc[1], acc[2]);
        let r = rotation(yaw, pitch, roll);
        let dr = rotation_partials(yaw, pitch, roll);
        let minv_top = self.mass_matrix_inv.fixed_rows::<3>(0);
        let minv_bot = self.mass_matrix_inv.fixed_rows::<3>(3);
        let c = &self.first_moment;

        let mut dfdx = StateJacobian::zeros();
        // p_dot = v.
        dfdx.fixed_view_mut::<3, 3>(idx::X, idx::VX)
            .fill_diagonal(1.0);

        // Euler kinematics.
        let (sr, cr) = sin_cos(roll);
        let (sp, cp) = sin_cos(pitch);
        let (wy, wz) = (w.y, w.z);
        let q = sr * wy + cr * wz;
        let dq_droll = cr * wy - sr * wz;
        let tp = sp / cp;
        dfdx[(idx::YAW, idx::PITCH)] = q * sp / (cp * cp);
        dfdx[(idx::YAW, idx::ROLL)] = dq_droll / cp;
        dfdx[(idx::YAW, idx::WY)] = sr / cp;
        dfdx[(idx::YAW, idx::WZ)] = cr / cp;
        dfdx[(idx::PITCH, idx::ROLL)] = -sr * wy - cr * wz;
        dfdx[(idx::PITCH, idx::WY)] = cr;
        dfdx[(idx::PITCH, idx::WZ)] = -sr;
        dfdx[(idx::ROLL, idx::PITCH)] = q / (cp * cp);
        dfdx[(idx::ROLL, idx::ROLL)] = tp * dq_droll;
        dfdx[(idx::ROLL, idx::WX)] = 1.0;
        dfdx[(idx::ROLL, idx::WY)] = tp * sr;
        dfdx[(idx::ROLL, idx::WZ)] = tp * cr;

        // Gravity in body axes depends on pitch and roll.
        let g = self.gravity;
        let dg_dpitch = Vector3::new(-cp, -sp * sr, -sp * cr) * g;
        let dg_droll = Vector3::new(0.0, cp * cr, -cp * sr) * g;
        for (col, dg) in [(idx::PITCH, dg_dpitch), (idx::ROLL, dg_droll)] {
            let drhs = {
                let f = dg * self.mass;
                let t = c.cross(&dg);
                Vector6::new(f.x, f.y, f.z, t.x, t.y, t.z)
            };
            let da = minv_top * drhs;
            let dw = minv_bot * drhs;
            dfdx.fixed_view_mut::<3, 1>(idx::VX, col)
                .copy_from(&(r * da));
            dfdx.fixed_view_mut::<3, 1>(idx::WX, col).copy_from(&dw);
        }
        // v_dot = R a: the rotation itself depends on all three angles.
        for (k, col) in [idx::YAW, idx::PITCH, idx::ROLL].into_iter().enumerate() {
            let extra = dr[k] * a_body;
            let mut column = dfdx.fixed_view_mut::<3, 1>(idx::VX, col);
            column += extra;
        }
        // Rates: -w x (w x c) and -w x (I w).
        let d_centripetal =
            Matrix3::identity() * w.dot(c) + w * c.transpose() - c * w.transpose() * 2.0;
        let iw = self.inertia * w;
        let d_gyro = skew(&w) * self.inertia - skew(&iw);
        let mut drhs_dw = SMatrix::<f64, 6, 3>::zeros();
        drhs_dw
            .fixed_view_mut::<3, 3>(0, 0)
            .copy_from(&(-d_centripetal));
        drhs_dw.fixed_view_mut::<3, 3>(3, 0).copy_from(&(-d_gyro));
        let dacc_dw = self.mass_matrix_inv * drhs_dw;
        dfdx.fixed_view_mut::<3, 3>(idx::VX, idx::WX)
            .copy_from(&(r * dacc_dw.fixed_rows::<3>(0)));
        dfdx.fixed_view_mut::<3, 3>(idx::WX, idx::WX)
            .copy_from(&dacc_dw.fixed_rows::<3>(3));

        // Inputs.
        let mut drhs_du = SMatrix::<f64, 6, 4>::zeros();
        drhs_du
            .fixed_view_mut::<3, 4>(0, 0)
            .copy_from(&self.thrust_force);
        drhs_du
            .fixed_view_mut::<3, 4>(3, 0)
            .copy_from(&self.thrust_torque);
        let dacc_du = self.mass_matrix_inv * drhs_du;
        let mut dfdu = InputJacobian::zeros();
        dfdu.fixed_view_mut::<3, 4>(idx::VX, 0)
            .copy_from(&(r * dacc_du.fixed_rows::<3>(0)));
        dfdu.fixed_view_mut::<3, 4>(idx::WX, 0)
            .copy_from(&dacc_du.fixed_rows::<3>(3));

        Linearization { xdot, dfdx, dfdu }
    }

    /// One classical RK4 step of length `dt` with u held constant.
    pub fn rk4_step(&self, x: &State, u: &Input, dt: f64) -> State {
        rk4_step(self, x, u, dt)
    }

    /// One RK4 step with its exact sensitivities dx+/dx and dx+/du
    /// (the derivative of the discrete map, not of the continuous flow).
    pub fn rk4_step_sensitivity(&self, x: &State, u: &Input, dt: f64) -> StepSensitivity {
        rk4_step_sensitivity(self, x, u, dt)
    }

    /// Level hover trim: the rotor commands that hold zero acceleration at
    /// zero attitude and rates (with the disturbance wrench, if any; its
    /// lateral force is left to the attitude). May exceed 1 past the
    /// critical angle; +inf in every entry when no trim exists (a singular
    /// allocation: never a panic on the control path).
    pub fn hover_trim(&self) -> Input {
        self.commands_for(-self.mass * self.gravity, &Vector3::zeros())
    }

    /// The rotor commands whose thrust gives the body z force `force_z`
    /// (N, body frame: negative is up) and, with gravity's torque about B
    /// at a level attitude and the disturbance wrench, the net torque
    /// `torque` about B (N m). Unclamped; +inf in every entry when no
    /// allocation exists (as [`Self::hover_trim`]).
    pub fn commands_for(&self, force_z: f64, torque: &Vector3<f64>) -> Input {
        // Rows F_z, tau_x, tau_y, tau_z; F_x and F_y vanish by symmetry.
        let mut a = nalgebra::Matrix4::zeros();
        a.set_row(0, &self.thrust_force.row(2));
        for k in 0..3 {
            a.set_row(k + 1, &self.thrust_torque.row(k));
        }
        let rhs = self.thrust_wrench_for(force_z, torque);
        // Singular only when no command moves one of the four rows (no
        // vertical thrust, no yaw authority): no trim exists, and every
        // caller clamps or compares, so +inf reads as "beyond full".
        a.lu()
            .solve(&rhs)
            .unwrap_or_else(|| Input::from_element(f64::INFINITY))
    }

    /// What the rotors' thrust must give (F_z, tau_x, tau_y, tau_z) for the
    /// body z force `force_z` and the net torque `torque` about B, with
    /// gravity's torque at a level attitude and the disturbance wrench
    /// taken out ([`Self::commands_for`], `commands_without`).
    pub(crate) fn thrust_wrench_for(&self, force_z: f64, torque: &Vector3<f64>) -> Vector4<f64> {
        let g_b = Vector3::new(0.0, 0.0, self.gravity);
        let gravity_torque = self.first_moment.cross(&g_b);
        let d = &self.disturbance;
        Vector4::new(
            force_z - d[2],
            torque.x - gravity_torque.x - d[3],
            torque.y - gravity_torque.y - d[4],
            torque.z - gravity_torque.z - d[5],
        )
    }
}

/// Something RK4 can step: `x_dot` and its Jacobians (N states, M inputs;
/// ATMO's 12 and 4 by default, atmo-mpc's tilt-planning model has 13 and 5).
pub trait Dynamics<const N: usize = NX, const M: usize = NU> {
    fn dynamics(&self, x: &SVector<f64, N>, u: &SVector<f64, M>) -> SVector<f64, N>;
    fn linearize(&self, x: &SVector<f64, N>, u: &SVector<f64, M>) -> Linearization<N, M>;
}

impl Dynamics for TiltedBody {
    fn dynamics(&self, x: &State, u: &Input) -> State {
        TiltedBody::dynamics(self, x, u)
    }
    fn linearize(&self, x: &State, u: &Input) -> Linearization {
        TiltedBody::linearize(self, x, u)
    }
}

/// One classical RK4 step of length `dt` with u held constant.
pub fn rk4_step<const N: usize, const M: usize, D: Dynamics<N, M> + ?Sized>(
    f: &D,
    x: &SVector<f64, N>,
    u: &SVector<f64, M>,
    dt: f64,
) -> SVector<f64, N> {
    let k1 = f.dynamics(x, u);
    let k2 = f.dynamics(&(x + k1 * (0.5 * dt)), u);
    let k3 = f.dynamics(&(x + k2 * (0.5 * dt)), u);
    let k4 = f.dynamics(&(x + k3 * dt), u);
    x + (k1 + k2 * 2.0 + k3 * 2.0 + k4) * (dt / 6.0)
}

/// One RK4 step with its exact sensitivities dx+/dx and dx+/du
/// (the derivative of the discrete map, not of the continuous flow).
pub fn rk4_step_sensitivity<const N: usize, const M: usize, D: Dynamics<N, M> + ?Sized>(
    f: &D,
    x: &SVector<f64, N>,
    u: &SVector<f64, M>,
    dt: f64,
) -> StepSensitivity<N, M> {
    let h = dt;
    let eye = SMatrix::<f64, N, N>::identity();
    let l1 = f.linearize(x, u);
    let s1x = l1.dfdx;
    let s1u = l1.dfdu;

    let x2 = x + l1.xdot * (0.5 * h);
    let l2 = f.linearize(&x2, u);
    let s2x = l2.dfdx * (eye + s1x * (0.5 * h));
    let s2u = l2.dfdx * (s1u * (0.5 * h)) + l2.dfdu;

    let x3 = x + l2.xdot * (0.5 * h);
    let l3 = f.linearize(&x3, u);
    let s3x = l3.dfdx * (eye + s2x * (0.5 * h));
    let s3u = l3.dfdx * (s2u * (0.5 * h)) + l3.dfdu;

    let x4 = x + l3.xdot * h;
    let l4 = f.linearize(&x4, u);
    let s4x = l4.dfdx * (eye + s3x * h);
    let s4u = l4.dfdx * (s3u * h) + l4.dfdu;

    let w = h / 6.0;
    StepSensitivity {
        next: x + (l1.xdot + l2.xdot * 2.0 + l3.xdot * 2.0 + l4.xdot) * w,
        a: eye + (s1x + s2x * 2.0 + s3x * 2.0 + s4x) * w,
        b: (s1u + s2u * 2.0 + s3u * 2.0 + s4u) * w,
    }
}
