//! The ground under the robot as a plane (NED): a point of it and its unit
//! normal pointing out of the ground (up, so its z is negative).
//!
//! The flight stack knows the ground through this plane: a height source
//! (terrain map, rangefinder, the ROS 2 ground topic) gives the NED z of the
//! ground under the robot's base origin, and a normal source the plane's
//! inclination. Without a normal the ground is level, `(0, 0, -1)`.
//! Planes steeper than [`MAX_GROUND_SLOPE_DEG`] are refused: ATMO's wheel
//! landing is not defined there (the plant models slopes up to 25 deg) and a
//! normal that steep is more likely a bad estimate than a landing site.

use nalgebra::Vector3;

use crate::error::{CoreError, Result};

/// The steepest ground plane the flight stack accepts, deg.
pub const MAX_GROUND_SLOPE_DEG: f64 = 35.0;

/// Shortest normal that is normalized rather than refused (a normal of
/// zero length has no direction).
const MIN_NORMAL_NORM: f64 = 1e-6;

/// The level ground's normal, NED.
pub const LEVEL_NORMAL: [f64; 3] = [0.0, 0.0, -1.0];

/// A ground plane, NED.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GroundPlane {
    /// A point of the plane (the ground under the robot's base origin), m.
    pub point: Vector3<f64>,
    /// Unit normal pointing out of the ground.
    pub normal: Vector3<f64>,
}

impl GroundPlane {
    /// The level ground at NED height `z`.
    pub fn level(z: f64) -> Self {
        Self {
            point: Vector3::new(0.0, 0.0, z),
            normal: Vector3::from(LEVEL_NORMAL),
        }
    }

    /// The plane through `point` with normal `normal` (any length, pointing
    /// out of the ground: normalized here). Refused: a non-finite point or
    /// normal, a normal shorter than 1e-6, a plane steeper than
    /// [`MAX_GROUND_SLOPE_DEG`] (a normal pointing down is 180 deg steep).
    pub fn new(point: Vector3<f64>, normal: Vector3<f64>) -> Result<Self> {
        if !point.iter().all(|v| v.is_finite()) {
            return Err(CoreError::OutOfRange {
                quantity: "ground plane point (NED, m)",
                value: point
                    .iter()
                    .copied()
                    .find(|v| !v.is_finite())
                    .unwrap_or(0.0),
                min: f64::MIN,
                max: f64::MAX,
            });
        }
        Ok(Self {
            point,
            normal: unit_ground_normal(normal)?,
        })
    }

    /// The plane's inclination from the level, rad.
    pub fn slope(&self) -> f64 {
        slope_of(&self.normal)
    }

    /// Signed height of `p` (NED) above the plane along its normal, m.
    /// For the level plane this is exactly `point.z - p.z`.
    #[inline]
    pub fn height(&self, p: &Vector3<f64>) -> f64 {
        let (n, q) = (&self.normal, &self.point);
        n.z * (p.z - q.z) + n.x * (p.x - q.x) + n.y * (p.y - q.y)
    }
}

/// The inclination of a unit normal from the level, rad.
fn slope_of(unit: &Vector3<f64>) -> f64 {
    (-unit.z).clamp(-1.0, 1.0).acos()
}

/// `normal` as a unit ground normal (pointing out of the ground, NED), or
/// why it is not one: non-finite, shorter than 1e-6, or steeper than
/// [`MAX_GROUND_SLOPE_DEG`].
pub fn unit_ground_normal(normal: Vector3<f64>) -> Result<Vector3<f64>> {
    let norm = normal.norm();
    if !norm.is_finite() || norm < MIN_NORMAL_NORM {
        return Err(CoreError::OutOfRange {
            quantity: "ground normal length",
            value: norm,
            min: MIN_NORMAL_NORM,
            max: f64::MAX,
        });
    }
    let unit = normal / norm;
    let slope = slope_of(&unit).to_degrees();
    if slope > MAX_GROUND_SLOPE_DEG {
        return Err(CoreError::OutOfRange {
            quantity: "ground slope (deg)",
            value: slope,
            min: 0.0,
            max: MAX_GROUND_SLOPE_DEG,
        });
    }
    Ok(unit)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn level_heights_are_the_z_difference_exactly() {
        let g = GroundPlane::level(-0.3);
        let p = Vector3::new(12.5, -3.25, -1.1);
        assert_eq!(g.height(&p), -0.3 - -1.1);
        assert_eq!(g.slope(), 0.0);
    }

    #[test]
    fn a_sloped_plane_measures_along_its_normal() {
        // 25 deg rising to the north (+x): n = (-sin 25, 0, -cos 25).
        let s = 25f64.to_radians();
        let g = GroundPlane::new(
            Vector3::new(1.0, 2.0, -0.5),
            Vector3::new(-s.sin(), 0.0, -s.cos()) * 3.0,
        )
        .unwrap();
        assert!((g.normal.norm() - 1.0).abs() < 1e-15);
        assert!((g.slope() - s).abs() < 1e-12);
        // 1 m straight above the point: cos 25 m from the plane.
        let above = g.height(&Vector3::new(1.0, 2.0, -1.5));
        assert!((above - s.cos()).abs() < 1e-12);
        // A point of the plane 1 m to the north (tan 25 m higher) is on it.
        let on = g.height(&Vector3::new(2.0, 2.0, -0.5 - s.tan()));
        assert!(on.abs() < 1e-12);
    }

    #[test]
    fn bad_normals_are_refused() {
        let p = Vector3::zeros();
        for n in [
            Vector3::new(f64::NAN, 0.0, -1.0),
            Vector3::new(0.0, f64::INFINITY, -1.0),
            Vector3::zeros(),
            Vector3::new(0.0, 0.0, 1.0), // points into the ground
            Vector3::new(-36f64.to_radians().sin(), 0.0, -36f64.to_radians().cos()), // too steep
        ] {
            assert!(GroundPlane::new(p, n).is_err(), "{n:?}");
        }
        assert!(GroundPlane::new(Vector3::new(f64::NAN, 0.0, 0.0), Vector3::z() * -1.0).is_err());
        let at_limit = 34.9f64.to_radians();
        assert!(GroundPlane::new(p, Vector3::new(0.0, at_limit.sin(), -at_limit.cos())).is_ok());
    }
}
