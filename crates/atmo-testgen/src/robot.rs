//! The robot file, read on its own (the keys of `config/atmo.toml` the
//! rigid body needs; other sections are ignored), and the seven bodies
//! combined into one rigid body at a fixed tilt, described about its
//! centre of mass.
//!
//! Bodies: the base (CoM at the base origin B), two arms hinged at A (the
//! right arm turned by +varphi about body x, the left by -varphi, the left
//! arm the right one mirrored in y), four rotors (PX4 quad-x: 1 front-right
//! and 4 back-right on the right arm, 2 back-left and 3 front-left on the
//! left). Arm inertia, `authors_model` convention: the listed tensor is
//! about the hinge, in the arm frame, as listed for the left arm and with
//! its xz and yz products negated for the right arm (the mirror image in
//! y of a tensor negates xy and yz; the authors' right-arm tensor negates
//! xz and yz). `about_com`: the tensor about the arm's CoM, right arm as
//! listed, left arm mirrored.

use std::path::Path;

use nalgebra::{Matrix3, Vector3};
use serde::Deserialize;

use crate::GenError;

#[derive(Debug, Clone, Copy, Deserialize)]
struct Tensor {
    xx: f64,
    yy: f64,
    zz: f64,
    xy: f64,
    xz: f64,
    yz: f64,
}

impl Tensor {
    fn matrix(self) -> Matrix3<f64> {
        Matrix3::new(
            self.xx, self.xy, self.xz, self.xy, self.yy, self.yz, self.xz, self.yz, self.zz,
        )
    }
}

#[derive(Debug, Clone, Deserialize)]
struct Environment {
    gravity: f64,
}

#[derive(Debug, Clone, Deserialize)]
struct Base {
    mass: f64,
    inertia: Tensor,
}

#[derive(Debug, Clone, Copy, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
enum Convention {
    AuthorsModel,
    AboutCom,
}

#[derive(Debug, Clone, Deserialize)]
struct Arm {
    mass: f64,
    inertia: Tensor,
    inertia_convention: Convention,
    base_to_hinge: [f64; 3],
    hinge_to_com: [f64; 3],
    hinge_to_rotor1: [f64; 3],
}

#[derive(Debug, Clone, Deserialize)]
struct Rotor {
    mass: f64,
    inertia: [f64; 3],
    k_thrust: f64,
    k_moment: f64,
    yaw_sign: [f64; 4],
}

#[derive(Debug, Clone, Deserialize)]
struct Wheels {
    radius: f64,
}

/// The sections of a robot file the generator reads.
#[derive(Debug, Clone, Deserialize)]
pub struct RobotFile {
    environment: Environment,
    base: Base,
    arm: Arm,
    rotor: Rotor,
    wheels: Wheels,
}

impl RobotFile {
    /// Reads a robot file (TOML).
    pub fn load(path: &Path) -> Result<Self, GenError> {
        let text = read_robot_file(path).map_err(|message| GenError::Robot {
            file: path.display().to_string(),
            message,
        })?;
        toml::from_str(&text).map_err(|e| GenError::Robot {
            file: path.display().to_string(),
            message: e.to_string(),
        })
    }
}

/// Largest robot file read, bytes.
const ROBOT_FILE_MAX_BYTES: u64 = 1 << 20;

/// The robot file's text: a regular file of at most
/// [`ROBOT_FILE_MAX_BYTES`], checked before it is read (`--robot
/// /dev/zero` was read until the kernel killed the process). The same rule
/// as atmo-core's `input_file`, kept apart: this crate shares no code with
/// the flight stack.
fn read_robot_file(path: &Path) -> Result<String, String> {
    use std::io::Read as _;
    let file = std::fs::File::open(path).map_err(|e| format!("cannot read: {e}"))?;
    let meta = file.metadata().map_err(|e| format!("cannot read: {e}"))?;
    if !meta.is_file() {
        return Err("not a regular file (a folder, a device, a FIFO or a socket)".into());
    }
    let mut text = String::new();
    file.take(ROBOT_FILE_MAX_BYTES + 1)
        .read_to_string(&mut text)
        .map_err(|e| format!("cannot read: {e}"))?;
    if text.len() as u64 > ROBOT_FILE_MAX_BYTES {
        return Err(format!(
            "larger than {ROBOT_FILE_MAX_BYTES} bytes: not a robot file"
        ));
    }
    Ok(text)
}

/// One rigid body: ATMO frozen at a tilt.
#[derive(Debug, Clone, PartialEq)]
pub struct RigidBody {
    pub gravity: f64,
    pub mass: f64,
    /// Centre of mass relative to B, body frame (m).
    pub com: Vector3<f64>,
    /// Inertia about the centre of mass, body frame (kg m^2).
    pub inertia_com: Matrix3<f64>,
    /// Rotor hubs relative to B, body frame (m).
    pub rotor_position: [Vector3<f64>; 4],
    /// Unit thrust directions, body frame.
    pub rotor_axis: [Vector3<f64>; 4],
    /// Thrust of one rotor at full command (N).
    pub k_thrust: f64,
    /// Reaction moment per unit thrust (m).
    pub k_moment: f64,
    pub yaw_sign: [f64; 4],
    pub wheel_radius: f64,
    pub varphi: f64,
}

/// `m (|d|^2 I - d d^T)`: the Steiner term of a point mass at d.
fn steiner(m: f64, d: &Vector3<f64>) -> Matrix3<f64> {
    (Matrix3::identity() * d.dot(d) - d * d.transpose()) * m
}

fn turn_about_x(angle: f64) -> Matrix3<f64> {
    let (s, c) = angle.sin_cos();
    Matrix3::new(1.0, 0.0, 0.0, 0.0, c, -s, 0.0, s, c)
}

/// Point masses with a tensor about their own CoM, body frame.
struct Part {
    mass: f64,
    at: Vector3<f64>,
    inertia: Matrix3<f64>,
}

impl RigidBody {
    /// The composite body at tilt `varphi` (rad).
    pub fn at_tilt(robot: &RobotFile, varphi: f64) -> Self {
        let mirror = Matrix3::from_diagonal(&Vector3::new(1.0, -1.0, 1.0));
        let arm = &robot.arm;
        let hinge_right = Vector3::from(arm.base_to_hinge);
        let com_right = Vector3::from(arm.hinge_to_com);
        let listed = arm.inertia.matrix();
        // Each arm: (sign of its turn, hinge, hinge -> CoM in the arm frame,
        // tensor about the arm CoM in the arm frame).
        let arm_about_com = |hinge_to_com: &Vector3<f64>, about_hinge: Matrix3<f64>| {
            about_hinge - steiner(arm.mass, hinge_to_com)
        };
        let (right_tensor, left_tensor) = match arm.inertia_convention {
            Convention::AuthorsModel => {
                let mut right = listed;
                for (i, j) in [(0, 2), (1, 2)] {
                    right[(i, j)] = -right[(i, j)];
                    right[(j, i)] = -right[(j, i)];
                }
                (
                    arm_about_com(&com_right, right),
                    arm_about_com(&(mirror * com_right), listed),
                )
            }
            Convention::AboutCom => (listed, mirror * listed * mirror),
        };
        let arms = [
            (turn_about_x(varphi), hinge_right, com_right, right_tensor),
            (
                turn_about_x(-varphi),
                mirror * hinge_right,
                mirror * com_right,
                left_tensor,
            ),
        ];
        let mut parts = vec![Part {
            mass: robot.base.mass,
            at: Vector3::zeros(),
            inertia: robot.base.inertia.matrix(),
        }];
        for (turn, hinge, to_com, tensor) in &arms {
            parts.push(Part {
                mass: arm.mass,
                at: hinge + turn * to_com,
                inertia: turn * tensor * turn.transpose(),
            });
        }
        let r1 = Vector3::from(arm.hinge_to_rotor1);
        // Rotor i: (arm, hinge -> hub in that arm's frame).
        let rotors = [
            (0, r1),
            (1, Vector3::new(-r1.x, -r1.y, r1.z)),
            (1, Vector3::new(r1.x, -r1.y, r1.z)),
            (0, Vector3::new(-r1.x, r1.y, r1.z)),
        ];
        let [ixx, iyy, izz] = robot.rotor.inertia;
        let mut rotor_position = [Vector3::zeros(); 4];
        let mut rotor_axis = [Vector3::zeros(); 4];
        for (i, (a, hub)) in rotors.iter().enumerate() {
            let (turn, hinge, _, _) = &arms[*a];
            rotor_position[i] = hinge + turn * hub;
            rotor_axis[i] = turn * Vector3::new(0.0, 0.0, -1.0);
            parts.push(Part {
                mass: robot.rotor.mass,
                at: rotor_position[i],
                inertia: turn
                    * Matrix3::from_diagonal(&Vector3::new(ixx, iyy, izz))
                    * turn.transpose(),
            });
        }
        let mass: f64 = parts.iter().map(|p| p.mass).sum();
        let com = parts.iter().map(|p| p.at * p.mass).sum::<Vector3<f64>>() / mass;
        let inertia_com = parts
            .iter()
            .map(|p| p.inertia + steiner(p.mass, &(p.at - com)))
            .sum();
        Self {
            gravity: robot.environment.gravity,
            mass,
            com,
            inertia_com,
            rotor_position,
            rotor_axis,
            k_thrust: robot.rotor.k_thrust,
            k_moment: robot.rotor.k_moment,
            yaw_sign: robot.rotor.yaw_sign,
            wheel_radius: robot.wheels.radius,
            varphi,
        }
    }

    /// The body with a point mass `part` (kg) of it, at `at` (relative to
    /// B), slid by `shift`: the centre of mass follows, and the inertia
    /// about it is the rest's plus the two-body term `mu S(at - rest)`,
    /// `mu` the reduced mass, `rest` the centre of mass of the rest.
    #[must_use]
    pub fn with_mass_moved(&self, part: f64, at: &Vector3<f64>, shift: &Vector3<f64>) -> Self {
        let rest_mass = self.mass - part;
        let rest = (self.com * self.mass - at * part) / rest_mass;
        let mu = part * rest_mass / self.mass;
        let moved = at + shift;
        Self {
            com: self.com + shift * (part / self.mass),
            inertia_com: self.inertia_com + steiner(mu, &(moved - rest))
                - steiner(mu, &(at - rest)),
            ..self.clone()
        }
    }

    /// Body force and torque about the CoM of rotor thrusts `t` (N).
    pub fn rotor_wrench(&self, t: &[f64; 4]) -> (Vector3<f64>, Vector3<f64>) {
        let mut force = Vector3::zeros();
        let mut torque = Vector3::zeros();
        for i in 0..4 {
            let f = self.rotor_axis[i] * t[i];
            force += f;
            torque += (self.rotor_position[i] - self.com).cross(&f)
                - self.rotor_axis[i] * (self.yaw_sign[i] * self.k_moment * t[i]);
        }
        (force, torque)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Inertia about the base origin B is additive over the parts: sliding
    /// a part of mass `m` from `a` to `a + d` changes it by
    /// `m (S(a + d) - S(a))`, whatever the rest; the centre of mass moves
    /// by `m d / M`.
    #[test]
    fn a_moved_mass_changes_the_inertia_about_b_by_its_own_steiner_terms() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/atmo.toml");
        let body = RigidBody::at_tilt(&RobotFile::load(&path).unwrap(), 0.4);
        let (part, at, shift) = (
            1.2,
            Vector3::new(0.01, -0.02, 0.0),
            Vector3::new(-0.03, 0.04, 0.005),
        );
        let moved = body.with_mass_moved(part, &at, &shift);
        let about_b = |b: &RigidBody| b.inertia_com + steiner(b.mass, &b.com);
        let expected = about_b(&body) + steiner(part, &(at + shift)) - steiner(part, &at);
        assert!(
            (about_b(&moved) - expected).amax() < 1e-12,
            "{}",
            about_b(&moved) - expected
        );
        assert!((moved.com - body.com - shift * (part / body.mass)).amax() < 1e-15);
        assert!((moved.rotor_position[0] - body.rotor_position[0]).amax() == 0.0);
    }
}
