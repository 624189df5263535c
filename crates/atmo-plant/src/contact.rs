//! Ground contact: the terrain plane, where each wheel touches it, and the
//! compliant contact law.
//!
//! **Geometry.** Each rotor's shroud is a wheel (the paper's design: "the
//! shrouds that protect them become the system's wheels", one belt drive per
//! side). A wheel is a circle of radius R centred at its rotor hub, in the
//! plane normal to the rotor axis. Its lowest point towards the ground is
//! `c + R d_p / |d_p|`, with `d_p` the downward ground normal projected into
//! the wheel plane (the centre itself when the wheel lies flat). At
//! varphi = 90 deg the hubs sit at x = +0.171 / -0.158 m, y = +-0.138 m,
//! 0.116 m below B, so the four wheels stand 0.241 m below B on a track of
//! 2 x 0.138 m (the robot file's half track is 0.135 m).
//!
//! The rest of the body is the base box (corners in the plant config);
//! a corner below the ground is a crash.
//!
//! **Law**, per contact point with penetration `d > 0`, velocity `v` of the
//! material point (including wheel spin), unit up-normal `n`:
//!
//! ```text
//! F_n = max(0, k d - c (v . n))                          (spring-damper, no pull)
//! v_t = v - (v . n) n,   s_dot = v_t                     (tangential spring s)
//! F_t = -k_t s - c_t v_t, |F_t| <= mu F_n                (Coulomb cap)
//! ```
//!
//! For a wheel the cap is an ellipse: `mu F_n` in the rolling direction and
//! `mu_lat F_n` along the axle. A shroud rim is a narrow rounded hoop that
//! slides sideways far more easily than a tyre; with isotropic friction the
//! four-wheel skid steer (wheelbase 0.33 m > track 0.28 m) could not turn.
//!
//! After each step `s` is held at `|k_t s| <= mu F_n` (sliding) and reset
//! when the contact opens. The spring `s` gives true stiction: a robot
//! parked on a slope does not creep, as it would with a regularized
//! `mu F_n v / |v|` law.
//!
//! **Two forms of the law, side by side.** [`ContactLaw`] states the law for
//! one point with nalgebra vectors; the plant uses it for the base-box
//! corners. The wheels take the same law four at a time (`WheelLanes`:
//! `forces` inside the RK4 derivative, `report` after the step), restated as
//! straight-line arithmetic on `[component][wheel]` arrays so that the
//! compiler vectorizes it. The test `the_wheel_kernels_are_the_scalar_contact_law`
//! at the end of this file keeps the two equal (to 1e-12) at random poses on
//! flat and sloped ground, sticking, sliding and with the wheels flat.
//!
//! Every function the plant's step calls here is `#[inline(always)]`: see
//! the AVX2 rule in the plant's `step` module.

use atmo_core::model::TiltedBody;
use nalgebra::{Matrix3, Vector3};

use crate::config::{GroundContactConfig, TerrainConfig};

/// The ground plane in NED: `height(P) = n . (P - P0)`, n pointing up.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Plane {
    /// Unit normal pointing out of the ground (NED, so mostly -z).
    pub normal: Vector3<f64>,
    /// A point of the plane (NED).
    pub point: Vector3<f64>,
}

impl Plane {
    #[inline(never)] // start-up
    pub fn new(terrain: &TerrainConfig) -> Self {
        let slope = terrain.slope_deg.to_radians();
        let azimuth = terrain.slope_azimuth_deg.to_radians();
        let (ss, cs) = slope.sin_cos();
        let (sa, ca) = azimuth.sin_cos();
        Self {
            normal: Vector3::new(-ss * ca, -ss * sa, -cs),
            point: Vector3::new(0.0, 0.0, -terrain.height),
        }
    }

    /// Signed distance of `p` (NED) above the plane, m.
    #[inline(always)]
    pub fn height(&self, p: &Vector3<f64>) -> f64 {
        self.normal.dot(&(p - self.point))
    }
}

/// Lowest point of a wheel rim (body frame): centre `c`, unit axle `a`,
/// unit down direction `down` (all body frame), radius `r`. The scalar
/// form of `WheelLanes::rim`, for tests and scenario set-up.
#[inline(never)] // not step code
pub fn rim_lowest_point(
    c: &Vector3<f64>,
    a: &Vector3<f64>,
    down: &Vector3<f64>,
    r: f64,
) -> Vector3<f64> {
    let d_p = down - a * down.dot(a);
    let len = d_p.norm();
    if len > 1e-9 { c + d_p * (r / len) } else { *c }
}

/// The contact parameters the law needs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ContactLaw {
    pub stiffness: f64,
    pub damping: f64,
    /// Coulomb coefficient (body points; wheels in the rolling direction).
    pub friction: f64,
    /// Coulomb coefficient of a wheel along its axle (sideways).
    pub lateral_friction: f64,
    pub tangential_stiffness: f64,
    pub tangential_damping: f64,
}

impl ContactLaw {
    #[inline(never)] // start-up
    pub fn new(c: &GroundContactConfig) -> Self {
        Self {
            stiffness: c.stiffness,
            damping: c.damping,
            friction: c.friction,
            lateral_friction: c.lateral_friction,
            tangential_stiffness: c.tangential_stiffness,
            tangential_damping: c.tangential_damping,
        }
    }

    /// Scales a tangential vector `f` (a force, or a spring force) into the
    /// friction limit for normal force `f_n`: a circle of radius `mu f_n`, or
    /// for a wheel with unit sideways direction `lateral` the ellipse with
    /// half-axes `mu f_n` (rolling) and `mu_lat f_n` (sideways).
    #[inline(always)]
    fn limit(&self, f: Vector3<f64>, f_n: f64, lateral: Option<&Vector3<f64>>) -> Vector3<f64> {
        if f_n <= 0.0 {
            return Vector3::zeros();
        }
        let l = lateral.map_or([0.0; 3], |l| [l.x, l.y, l.z]);
        f / self.limit_divisor(&[f.x, f.y, f.z], f_n, &l, lateral.is_some())
    }

    /// The divisor that brings a tangential vector `f` into the friction
    /// limit for normal force `f_n > 0`: 1 inside it (sticking, the usual
    /// case), else the square root of `f`'s squared size relative to the
    /// limit. `elliptic` selects the wheel's ellipse with unit sideways
    /// direction `lateral`, else the circle. Branch-free apart from the
    /// selects, so that the four-wheel loops that call it vectorize.
    #[inline(always)]
    pub fn limit_divisor(&self, f: &[f64; 3], f_n: f64, lateral: &[f64; 3], elliptic: bool) -> f64 {
        let cap = self.friction * f_n;
        let cap_lat = self.lateral_friction * f_n;
        let (c2, l2) = (cap * cap, cap_lat * cap_lat);
        let f_sq = f[0] * f[0] + f[1] * f[1] + f[2] * f[2];
        let f_lat = f[0] * lateral[0] + f[1] * lateral[1] + f[2] * lateral[2];
        let f_lat_sq = f_lat * f_lat;
        let f_roll_sq = (f_sq - f_lat_sq).max(0.0);
        // f_roll^2 / c^2 + f_lat^2 / l^2 (ellipse) or f^2 / c^2 (circle) <= 1.
        let (size, limit) = if elliptic {
            (f_roll_sq * l2 + f_lat_sq * c2, c2 * l2)
        } else {
            (f_sq, c2)
        };
        if size <= limit {
            1.0
        } else {
            (size / limit).sqrt()
        }
    }

    /// Normal force (N) of a point `depth` m into the ground moving at
    /// `v_n` m/s along the up-normal: spring-damper, never pulling.
    #[inline(always)]
    pub fn normal_force(&self, depth: f64, v_n: f64) -> f64 {
        (self.stiffness * depth - self.damping * v_n).max(0.0)
    }

    /// Force (world frame) on a point `depth` m into the ground moving at `v`
    /// with tangential spring `s`; `lateral` is a wheel's sideways direction
    /// in the ground plane (None for body points). Returns (force, normal
    /// force, `s_dot`).
    #[inline(always)]
    pub fn force(
        &self,
        n: &Vector3<f64>,
        depth: f64,
        v: &Vector3<f64>,
        s: &Vector3<f64>,
        lateral: Option<&Vector3<f64>>,
    ) -> (Vector3<f64>, f64, Vector3<f64>) {
        let v_n = v.dot(n);
        let f_n = self.normal_force(depth, v_n);
        let v_t = v - n * v_n;
        let f_t = -(s * self.tangential_stiffness) - v_t * self.tangential_damping;
        (n * f_n + self.limit(f_t, f_n, lateral), f_n, v_t)
    }

    /// Holds the tangential spring at the friction limit (sliding).
    #[inline(always)]
    pub fn limit_spring(
        &self,
        n: &Vector3<f64>,
        s: &Vector3<f64>,
        normal_force: f64,
        lateral: Option<&Vector3<f64>>,
    ) -> Vector3<f64> {
        let s_t = s - n * s.dot(n);
        self.limit(s_t * self.tangential_stiffness, normal_force, lateral)
            / self.tangential_stiffness
    }
}

/// A wheel's sideways direction in the ground plane: its axle projected on
/// the plane (None when the wheel lies flat and has no rolling direction).
#[inline(always)]
pub fn wheel_lateral(axle: &Vector3<f64>, n: &Vector3<f64>) -> Option<Vector3<f64>> {
    let l = axle - n * axle.dot(n);
    let len = l.norm();
    (len > 1e-6).then(|| l / len)
}

// ---------------------------------------------------------------------------
// The four-lane kernels: the law above at the four wheels at once.
// ---------------------------------------------------------------------------

/// Which side each rotor's wheel is on (0 = left, 1 = right), PX4 quad-x:
/// rotors 1 and 4 on the right arm, 2 and 3 on the left.
pub(crate) const WHEEL_SIDE: [usize; 4] = [1, 0, 0, 1];
/// Sign from the rotor axis to the forward spin axis: at varphi = 90 deg the
/// right rotors' axes point +y and the left ones' -y; forward rolling is a
/// spin about -y for both.
pub(crate) const SPIN_SIGN: [f64; 4] = [-1.0, 1.0, 1.0, -1.0];

/// The four wheels' body-frame geometry, `[component][wheel]` (rotor
/// order), the layout the four-lane contact kernels read.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct WheelLanes {
    hub: [[f64; 4]; 3],
    axle: [[f64; 4]; 3],
    /// Forward spin axis: the axle times `SPIN_SIGN`.
    spin_axis: [[f64; 4]; 3],
    /// Wheel radius, m.
    radius: f64,
}

/// Where the body is against the ground plane, as the wheel kernels read it.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Pose<'a> {
    /// Body to world.
    pub r: &'a Matrix3<f64>,
    /// The plane's unit up-normal (world frame).
    pub normal: Vector3<f64>,
    /// The ground's down direction in the body frame, `-R^T n`.
    pub down: Vector3<f64>,
    /// Height of B above the plane, m.
    pub height: f64,
    /// Velocity of B (world frame).
    pub v: Vector3<f64>,
    /// Body rates (body frame).
    pub w: Vector3<f64>,
}

/// Wheel j's lowest rim point towards unit `down` (body frame), as the
/// four-wheel loops compute it: `c + R d_p / |d_p|` and the sideways
/// direction `l_p / |l_p|`, with d_p = d - a (a.d) and l_p = a - d (a.d).
/// For unit a and d both have the length sqrt(1 - (a.d)^2), so one square
/// root serves both. A wheel lying flat (|d_p| <= 1e-6) touches at its hub
/// and has no sideways direction (`upright` false).
#[derive(Debug, Clone, Copy)]
struct Rim {
    upright: bool,
    /// From the hub to the point.
    offset: [f64; 3],
    point: [f64; 3],
    /// Sideways (along the axle, in the ground plane); body frame.
    lateral: [f64; 3],
}

/// The post-step pass at the four wheels, `[component][wheel]`.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct WheelReport {
    pub touching: [bool; 4],
    pub normal_force: [f64; 4],
    pub approach_speed: [f64; 4],
    /// Tangential spring held at the friction limit (zero when open).
    pub spring: [[f64; 4]; 3],
}

/// The contact law's result at the four wheels, `[component][wheel]`
/// (body frame); only wheels with `touching` count.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct WheelForces {
    pub touching: [bool; 4],
    pub force: [[f64; 4]; 3],
    /// Torque about B without the spin-axis part.
    pub torque: [[f64; 4]; 3],
    /// Torque about the spin axis (turns the wheel).
    pub axial: [f64; 4],
    /// Tangential spring rate (world frame).
    pub spring_rate: [[f64; 4]; 3],
}

impl WheelLanes {
    #[inline(always)]
    pub fn of(body: &TiltedBody, radius: f64) -> Self {
        Self {
            hub: std::array::from_fn(|k| std::array::from_fn(|j| body.rotor_position[j][k])),
            axle: std::array::from_fn(|k| std::array::from_fn(|j| body.rotor_axis[j][k])),
            spin_axis: std::array::from_fn(|k| {
                std::array::from_fn(|j| body.rotor_axis[j][k] * SPIN_SIGN[j])
            }),
            radius,
        }
    }

    #[inline(always)]
    fn rim(&self, j: usize, down: &Vector3<f64>) -> Rim {
        let c = [self.hub[0][j], self.hub[1][j], self.hub[2][j]];
        let a = [self.axle[0][j], self.axle[1][j], self.axle[2][j]];
        let ad = a[0] * down.x + a[1] * down.y + a[2] * down.z;
        let len_sq = 1.0 - ad * ad;
        let upright = len_sq > 1e-12;
        let inv = 1.0 / len_sq.max(1e-12).sqrt();
        let reach = if upright { self.radius * inv } else { 0.0 };
        let offset: [f64; 3] = std::array::from_fn(|i| (down[i] - a[i] * ad) * reach);
        Rim {
            upright,
            offset,
            point: std::array::from_fn(|i| c[i] + offset[i]),
            lateral: std::array::from_fn(|i| (a[i] - down[i] * ad) * inv),
        }
    }

    /// Touching, approach speed and normal force of each wheel's lowest rim
    /// point after a step (wheel spin moves the point along the ground, not
    /// into it), and the tangential springs `spring` (`[component][wheel]`,
    /// world frame) held as `ContactLaw::limit_spring` holds them; one
    /// branch-free loop like `forces`.
    #[inline(always)]
    pub fn report(&self, pose: &Pose, law: &ContactLaw, spring: &[[f64; 4]; 3]) -> WheelReport {
        let Pose {
            r,
            normal: n,
            down,
            height,
            v,
            w,
        } = *pose;
        let v_n_b = v.dot(&n);
        let kt = law.tangential_stiffness;
        let mut out = WheelReport::default();
        for j in 0..4 {
            let rim = self.rim(j, &down);
            let pt = rim.point;
            let depth = down.x * pt[0] + down.y * pt[1] + down.z * pt[2] - height;
            // (v + R (w x p)) . n, with R^T n = -down.
            let w_x_p = [
                w.y * pt[2] - w.z * pt[1],
                w.z * pt[0] - w.x * pt[2],
                w.x * pt[1] - w.y * pt[0],
            ];
            let v_n = v_n_b - (down.x * w_x_p[0] + down.y * w_x_p[1] + down.z * w_x_p[2]);
            let touching = depth > 0.0;
            let f_n = if touching {
                law.normal_force(depth, v_n)
            } else {
                0.0
            };
            // The spring's tangential part, held at the friction limit.
            let lat: [f64; 3] = std::array::from_fn(|i| {
                r[(i, 0)] * rim.lateral[0] + r[(i, 1)] * rim.lateral[1] + r[(i, 2)] * rim.lateral[2]
            });
            let s: [f64; 3] = std::array::from_fn(|k| spring[k][j]);
            let s_n = s[0] * n.x + s[1] * n.y + s[2] * n.z;
            let f: [f64; 3] = std::array::from_fn(|i| (s[i] - n[i] * s_n) * kt);
            let held = touching && f_n > 0.0;
            let scale = if held {
                1.0 / (law.limit_divisor(&f, f_n, &lat, rim.upright) * kt)
            } else {
                0.0
            };
            for i in 0..3 {
                out.spring[i][j] = f[i] * scale;
            }
            out.touching[j] = touching;
            out.normal_force[j] = f_n;
            out.approach_speed[j] = -v_n;
        }
        out
    }

    /// The contact law at the four wheels at once, with the wheels spinning
    /// at `spin` (rad/s, forward) and tangential springs `spring`
    /// (`[component][wheel]`, world frame): one loop over the wheels with
    /// straight-line arithmetic and selects (no branches), which the compiler
    /// turns into 4-wide vector code (2-wide in the portable copy). The law
    /// is `ContactLaw::force` at each wheel's lowest rim point (`rim`); the
    /// rim point moves with the body and with the wheel's spin.
    #[inline(always)]
    #[allow(clippy::similar_names)]
    pub fn forces(
        &self,
        pose: &Pose,
        law: &ContactLaw,
        spin: &[f64; 4],
        spring: &[[f64; 4]; 3],
    ) -> WheelForces {
        let Pose {
            r,
            normal: n,
            down,
            height,
            v,
            w,
        } = *pose;
        let mut out = WheelForces::default();
        for j in 0..4 {
            let c = [self.hub[0][j], self.hub[1][j], self.hub[2][j]];
            let e = [
                self.spin_axis[0][j],
                self.spin_axis[1][j],
                self.spin_axis[2][j],
            ];
            let Rim {
                upright,
                offset: rim,
                point: pt,
                lateral: lat_b,
            } = self.rim(j, &down);
            let depth = down.x * pt[0] + down.y * pt[1] + down.z * pt[2] - height;
            // Velocity of the rim point: body motion plus wheel spin (body frame).
            let vl = [
                w.y * pt[2] - w.z * pt[1] + (e[1] * rim[2] - e[2] * rim[1]) * spin[j],
                w.z * pt[0] - w.x * pt[2] + (e[2] * rim[0] - e[0] * rim[2]) * spin[j],
                w.x * pt[1] - w.y * pt[0] + (e[0] * rim[1] - e[1] * rim[0]) * spin[j],
            ];
            let vp: [f64; 3] = std::array::from_fn(|i| {
                v[i] + r[(i, 0)] * vl[0] + r[(i, 1)] * vl[1] + r[(i, 2)] * vl[2]
            });
            let lat: [f64; 3] = std::array::from_fn(|i| {
                r[(i, 0)] * lat_b[0] + r[(i, 1)] * lat_b[1] + r[(i, 2)] * lat_b[2]
            });
            // Normal spring-damper, tangential spring-damper (world frame).
            let v_n = vp[0] * n.x + vp[1] * n.y + vp[2] * n.z;
            let f_n = law.normal_force(depth, v_n);
            let v_t = [vp[0] - n.x * v_n, vp[1] - n.y * v_n, vp[2] - n.z * v_n];
            let f_t: [f64; 3] = std::array::from_fn(|i| {
                -(spring[i][j] * law.tangential_stiffness) - v_t[i] * law.tangential_damping
            });
            // Coulomb cap: an ellipse (rolling / sideways), a circle when flat.
            let scale = if f_n <= 0.0 {
                0.0
            } else {
                1.0 / law.limit_divisor(&f_t, f_n, &lat, upright)
            };
            let f_w: [f64; 3] = std::array::from_fn(|i| n[i] * f_n + f_t[i] * scale);
            // Into the body frame; torque about B less the spin-axis part,
            // which turns the wheel instead.
            let f_b: [f64; 3] = std::array::from_fn(|i| {
                r[(0, i)] * f_w[0] + r[(1, i)] * f_w[1] + r[(2, i)] * f_w[2]
            });
            let rim_x_f = [
                rim[1] * f_b[2] - rim[2] * f_b[1],
                rim[2] * f_b[0] - rim[0] * f_b[2],
                rim[0] * f_b[1] - rim[1] * f_b[0],
            ];
            let axial = e[0] * rim_x_f[0] + e[1] * rim_x_f[1] + e[2] * rim_x_f[2];
            let tq = [
                pt[1] * f_b[2] - pt[2] * f_b[1] - e[0] * axial,
                pt[2] * f_b[0] - pt[0] * f_b[2] - e[1] * axial,
                pt[0] * f_b[1] - pt[1] * f_b[0] - e[2] * axial,
            ];
            // A rim point is at most the radius below its hub.
            let hub_low = down.x * c[0] + down.y * c[1] + down.z * c[2] + self.radius > height;
            let touching = hub_low && depth > 0.0;
            out.touching[j] = touching;
            for i in 0..3 {
                out.force[i][j] = f_b[i];
                out.torque[i][j] = tq[i];
                out.spring_rate[i][j] = v_t[i];
            }
            out.axial[j] = axial;
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::PlantConfig;
    use atmo_core::RobotConfig;
    use atmo_core::model::Attitude;
    use atmo_core::model::{Model, State, idx};
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// The four-lane wheel kernels against the scalar law they restate
    /// (`rim_lowest_point`, `wheel_lateral`, `ContactLaw::force` and
    /// `ContactLaw::limit_spring`, one wheel at a time), at
    /// random poses, velocities, spins and springs on flat and sloped
    /// ground, with the wheels upright (90 deg), tilted (45 deg) and flat
    /// (0 deg), sticking and sliding.
    #[test]
    fn the_wheel_kernels_are_the_scalar_contact_law() {
        let robot = RobotConfig::atmo();
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let Some(contact) = PlantConfig::full().effects.ground_contact else {
            panic!("the full plant has ground contact");
        };
        let law = ContactLaw::new(&contact);
        let (mut touching, mut sliding, mut flat) = (0, 0, 0);
        for (tilt_deg, slope_deg) in [(90.0, 0.0), (90.0, 20.0), (45.0, 10.0), (0.0, 0.0)] {
            let tilt = f64::to_radians(tilt_deg);
            let terrain = TerrainConfig {
                height: 0.0,
                slope_deg,
                slope_azimuth_deg: 30.0,
            };
            let body = Model::new(&robot).at_tilt(tilt);
            let plane = Plane::new(&terrain);
            let lanes_of_body = WheelLanes::of(&body, robot.wheels.radius);
            // Level at 0 deg, the wheels lie flat: the hub is the lowest point.
            let lying_flat = tilt_deg == 0.0;
            let rest =
                body.rotor_position[0].z + if lying_flat { 0.0 } else { robot.wheels.radius };
            for _ in 0..200 {
                let mut x = State::zeros();
                x[idx::X] = rng.random_range(-1.0..1.0);
                x[idx::Y] = rng.random_range(-1.0..1.0);
                let ground_z =
                    -plane.height(&Vector3::new(x[idx::X], x[idx::Y], 0.0)) / plane.normal.z.abs();
                x[idx::Z] = ground_z - rest + rng.random_range(-0.02..0.03);
                if !lying_flat {
                    for i in [idx::YAW, idx::PITCH, idx::ROLL] {
                        x[i] = rng.random_range(-0.4..0.4);
                    }
                }
                for i in [idx::VX, idx::VY, idx::VZ, idx::WX, idx::WY, idx::WZ] {
                    x[i] = rng.random_range(-1.5..1.5);
                }
                let spin_side: [f64; 2] = std::array::from_fn(|_| rng.random_range(-20.0..20.0));
                let spin: [f64; 4] = std::array::from_fn(|j| spin_side[WHEEL_SIDE[j]]);
                let spring_scale = if rng.random_bool(0.5) { 1e-4 } else { 0.05 };
                // [component][wheel], drawn wheel by wheel.
                let mut spring = [[0.0; 4]; 3];
                for j in 0..4 {
                    for k in 0..3 {
                        spring[k][j] = rng.random_range(-spring_scale..spring_scale);
                    }
                }
                let r = Attitude::of(&x).r;
                let rt = r.transpose();
                let n = plane.normal;
                let down_b = -(rt * n);
                let p = Vector3::new(x[idx::X], x[idx::Y], x[idx::Z]);
                let v = Vector3::new(x[idx::VX], x[idx::VY], x[idx::VZ]);
                let w = Vector3::new(x[idx::WX], x[idx::WY], x[idx::WZ]);
                let height = plane.height(&p);
                let pose = Pose {
                    r: &r,
                    normal: n,
                    down: down_b,
                    height,
                    v,
                    w,
                };
                let lanes = lanes_of_body.forces(&pose, &law, &spin, &spring);
                let report = lanes_of_body.report(&pose, &law, &spring);
                let close = |a: f64, b: f64, j: usize, what: &str| {
                    assert!(
                        (a - b).abs() <= 1e-12 * (1.0 + b.abs()),
                        "{tilt_deg} deg, wheel {j}, {what}: kernel {a}, law {b}"
                    );
                };
                for j in 0..4 {
                    let c = body.rotor_position[j];
                    let axle = body.rotor_axis[j];
                    let pt = rim_lowest_point(&c, &axle, &down_b, robot.wheels.radius);
                    let lateral = wheel_lateral(&(r * axle), &n);
                    let depth = down_b.dot(&pt) - height;
                    assert_eq!(lanes.touching[j], depth > 0.0, "wheel {j} depth {depth}");
                    // The post-step report (no spin: it moves the point along the ground).
                    let v_n = (v + r * w.cross(&pt)).dot(&n);
                    assert_eq!(report.touching[j], depth > 0.0);
                    close(report.approach_speed[j], -v_n, j, "approach speed");
                    let s = Vector3::new(spring[0][j], spring[1][j], spring[2][j]);
                    if depth <= 0.0 {
                        assert_eq!(report.normal_force[j], 0.0);
                        assert!((0..3).all(|i| report.spring[i][j] == 0.0));
                        continue;
                    }
                    let f_n = law.normal_force(depth, v_n);
                    close(report.normal_force[j], f_n, j, "report normal force");
                    let held = law.limit_spring(&n, &s, f_n, lateral.as_ref());
                    for i in 0..3 {
                        close(report.spring[i][j], held[i], j, "held spring");
                    }
                    touching += 1;
                    flat += usize::from(lateral.is_none());
                    let spin_axis = axle * SPIN_SIGN[j];
                    let rim = pt - c;
                    let spin = spin[j];
                    let v_point = v + r * (w.cross(&pt) + spin_axis.cross(&rim) * spin);
                    let (f_world, f_n, s_dot) =
                        law.force(&n, depth, &v_point, &s, lateral.as_ref());
                    let f_t = f_world - n * f_n;
                    let unlimited =
                        -(s * law.tangential_stiffness) - s_dot * law.tangential_damping;
                    sliding += usize::from((f_t - unlimited).norm() > 1e-9 * unlimited.norm());
                    let f_b = rt * f_world;
                    let axial = spin_axis.dot(&rim.cross(&f_b));
                    let tq = pt.cross(&f_b) - spin_axis * axial;
                    for i in 0..3 {
                        close(lanes.force[i][j], f_b[i], j, "force");
                        close(lanes.torque[i][j], tq[i], j, "torque");
                        close(lanes.spring_rate[i][j], s_dot[i], j, "spring rate");
                    }
                    close(lanes.axial[j], axial, j, "axial torque");
                }
            }
        }
        // Every branch of the law was compared, many times.
        assert!(touching > 500, "{touching} touching wheels");
        assert!(sliding > 50, "{sliding} sliding wheels");
        assert!(flat > 50, "{flat} flat wheels");
    }
}
