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

use nalgebra::Vector3;

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
/// unit down direction `down` (all body frame), radius `r`.
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
