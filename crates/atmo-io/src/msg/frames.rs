//! Frame conversion at the ROS 2 edge: ROS (REP 103: ENU world, FLU body)
//! to and from the flight stack's NED world, FRD body, Euler ZYX state.
//!
//! With T the ENU -> NED axis swap (x_ned = y_enu, y_ned = x_enu,
//! z_ned = -z_enu) and B = diag(1, -1, -1) the FRD -> FLU body flip:
//!
//!   p_ned = T p_enu,  R_ned_frd = T R_enu_flu B,
//!   v_ned = R_ned_frd B v_flu (odometry twist is in the child, body frame),
//!   w_frd = B w_flu,
//!
//! and (yaw, pitch, roll) are the ZYX Euler angles of R_ned_frd
//! (R = Rz(yaw) Ry(pitch) Rx(roll)).

use atmo_core::model::{State, idx};
use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3 as V3};

use super::px4::VehicleOdometry;
use super::standard::{Header, Odometry, Point, Pose, Quaternion, Time, Twist, Vector3};
use crate::error::{IoError, Result};

fn enu_to_ned() -> Matrix3<f64> {
    Matrix3::new(0.0, 1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, -1.0)
}

fn frd_to_flu() -> Matrix3<f64> {
    Matrix3::from_diagonal(&V3::new(1.0, -1.0, -1.0))
}

/// Largest accepted deviation of the quaternion norm from 1.
pub const QUATERNION_NORM_TOLERANCE: f64 = 1e-3;

/// Converts a ROS odometry (ENU/FLU) to the 12-state (NED/FRD). Rejects
/// non-finite fields and quaternions whose norm is not 1 (within
/// [`QUATERNION_NORM_TOLERANCE`]); `topic` names the origin in errors.
pub fn odometry_to_state(topic: &str, odom: &Odometry) -> Result<State> {
    let invalid = |field: &'static str, reason: String| IoError::InvalidField {
        topic: topic.to_string(),
        field,
        reason,
    };
    let p = odom.pose.pose.position;
    let q = odom.pose.pose.orientation;
    let v = odom.twist.twist.linear;
    let w = odom.twist.twist.angular;
    let checks: [(&'static str, [f64; 4]); 4] = [
        ("pose.pose.position", [p.x, p.y, p.z, 0.0]),
        ("pose.pose.orientation", [q.x, q.y, q.z, q.w]),
        ("twist.twist.linear", [v.x, v.y, v.z, 0.0]),
        ("twist.twist.angular", [w.x, w.y, w.z, 0.0]),
    ];
    for (field, values) in checks {
        if let Some(bad) = values.iter().find(|x| !x.is_finite()) {
            return Err(invalid(field, format!("non-finite value {bad}")));
        }
    }
    let norm = (q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w).sqrt();
    if (norm - 1.0).abs() > QUATERNION_NORM_TOLERANCE {
        return Err(invalid(
            "pose.pose.orientation",
            format!("quaternion norm {norm} is not 1"),
        ));
    }
    let t = enu_to_ned();
    let b = frd_to_flu();
    let r_enu_flu = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(q.w, q.x, q.y, q.z))
        .to_rotation_matrix()
        .into_inner();
    let r_ned_frd = t * r_enu_flu * b;
    let (roll, pitch, yaw) = Rotation3::from_matrix_unchecked(r_ned_frd).euler_angles();
    let p_ned = t * V3::new(p.x, p.y, p.z);
    let v_ned = r_ned_frd * b * V3::new(v.x, v.y, v.z);
    let w_frd = b * V3::new(w.x, w.y, w.z);

    let mut x = State::zeros();
    x[idx::X] = p_ned.x;
    x[idx::Y] = p_ned.y;
    x[idx::Z] = p_ned.z;
    x[idx::YAW] = yaw;
    x[idx::PITCH] = pitch;
    x[idx::ROLL] = roll;
    x[idx::VX] = v_ned.x;
    x[idx::VY] = v_ned.y;
    x[idx::VZ] = v_ned.z;
    x[idx::WX] = w_frd.x;
    x[idx::WY] = w_frd.y;
    x[idx::WZ] = w_frd.z;
    Ok(x)
}

/// Converts a PX4 odometry (NED world, FRD body; no frame change) to the
/// 12-state. Only `pose_frame` NED is accepted; the velocity may be in NED or
/// in the FRD body frame.
pub fn vehicle_odometry_to_state(topic: &str, odom: &VehicleOdometry) -> Result<State> {
    let invalid = |field: &'static str, reason: String| IoError::InvalidField {
        topic: topic.to_string(),
        field,
        reason,
    };
    let checks: [(&'static str, &[f32]); 4] = [
        ("position", &odom.position),
        ("q", &odom.q),
        ("velocity", &odom.velocity),
        ("angular_velocity", &odom.angular_velocity),
    ];
    for (field, values) in checks {
        if let Some(bad) = values.iter().find(|x| !x.is_finite()) {
            return Err(invalid(field, format!("non-finite value {bad}")));
        }
    }
    if odom.pose_frame != VehicleOdometry::POSE_FRAME_NED {
        return Err(invalid(
            "pose_frame",
            format!("{} is not POSE_FRAME_NED (1)", odom.pose_frame),
        ));
    }
    let [w, qx, qy, qz] = odom.q.map(f64::from);
    let norm = (w * w + qx * qx + qy * qy + qz * qz).sqrt();
    if (norm - 1.0).abs() > QUATERNION_NORM_TOLERANCE * 10.0 {
        // float32 quaternions: 1e-2 on the norm.
        return Err(invalid("q", format!("quaternion norm {norm} is not 1")));
    }
    let r = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(w, qx, qy, qz))
        .to_rotation_matrix();
    let (roll, pitch, yaw) = r.euler_angles();
    let v = V3::from(odom.velocity.map(f64::from));
    let v_ned = match odom.velocity_frame {
        VehicleOdometry::VELOCITY_FRAME_NED => v,
        VehicleOdometry::VELOCITY_FRAME_BODY_FRD => r * v,
        other => {
            return Err(invalid(
                "velocity_frame",
                format!("{other} is neither NED (1) nor BODY_FRD (3)"),
            ));
        }
    };
    let p = odom.position.map(f64::from);
    let wb = odom.angular_velocity.map(f64::from);
    Ok(State::from_row_slice(&[
        p[0], p[1], p[2], yaw, pitch, roll, v_ned.x, v_ned.y, v_ned.z, wb[0], wb[1], wb[2],
    ]))
}

/// The inverse of [`odometry_to_state`]: a ROS odometry (ENU world `odom`,
/// FLU body `base_link`, zero covariances) for a 12-state.
pub fn state_to_odometry(state: &State, stamp_ns: u64) -> Odometry {
    let t = enu_to_ned(); // its own inverse
    let b = frd_to_flu(); // its own inverse
    let r_ned_frd =
        Rotation3::from_euler_angles(state[idx::ROLL], state[idx::PITCH], state[idx::YAW])
            .into_inner();
    let r_enu_flu = t * r_ned_frd * b;
    let q = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(r_enu_flu));
    let p_enu = t * V3::new(state[idx::X], state[idx::Y], state[idx::Z]);
    let v_flu = b * r_ned_frd.transpose() * V3::new(state[idx::VX], state[idx::VY], state[idx::VZ]);
    let w_flu = b * V3::new(state[idx::WX], state[idx::WY], state[idx::WZ]);
    let mut odom = Odometry {
        header: Header {
            stamp: Time::from_ns(stamp_ns),
            frame_id: "odom".into(),
        },
        child_frame_id: "base_link".into(),
        ..Odometry::default()
    };
    odom.pose.pose = Pose {
        position: Point {
            x: p_enu.x,
            y: p_enu.y,
            z: p_enu.z,
        },
        orientation: Quaternion {
            x: q.i,
            y: q.j,
            z: q.k,
            w: q.w,
        },
    };
    odom.twist.twist = Twist {
        linear: Vector3 {
            x: v_flu.x,
            y: v_flu.y,
            z: v_flu.z,
        },
        angular: Vector3 {
            x: w_flu.x,
            y: w_flu.y,
            z: w_flu.z,
        },
    };
    odom
}

/// The inverse of [`vehicle_odometry_to_state`]: a PX4 odometry (NED world,
/// FRD body, velocity in NED, `float32` as on the wire) for a 12-state, both
/// stamps `timestamp_us`. Variances are NaN (unknown, as PX4 writes them).
#[allow(clippy::cast_possible_truncation)] // the message is float32
pub fn state_to_vehicle_odometry(state: &State, timestamp_us: u64) -> VehicleOdometry {
    let q = UnitQuaternion::from_euler_angles(state[idx::ROLL], state[idx::PITCH], state[idx::YAW]);
    let f = |i: usize| state[i] as f32;
    VehicleOdometry {
        timestamp: timestamp_us,
        timestamp_sample: timestamp_us,
        pose_frame: VehicleOdometry::POSE_FRAME_NED,
        position: [f(idx::X), f(idx::Y), f(idx::Z)],
        q: [q.w as f32, q.i as f32, q.j as f32, q.k as f32],
        velocity_frame: VehicleOdometry::VELOCITY_FRAME_NED,
        velocity: [f(idx::VX), f(idx::VY), f(idx::VZ)],
        angular_velocity: [f(idx::WX), f(idx::WY), f(idx::WZ)],
        position_variance: [f32::NAN; 3],
        orientation_variance: [f32::NAN; 3],
        velocity_variance: [f32::NAN; 3],
        reset_counter: 0,
        quality: 0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn state(values: [f64; 12]) -> State {
        State::from_row_slice(&values)
    }

    #[test]
    fn facing_north_level() {
        // NED: 1 m north, 2 m east, 3 m up, facing north, flying north at
        // 1 m/s, turning right at 0.2 rad/s.
        let x = state([1.0, 2.0, -3.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.2]);
        let odom = state_to_odometry(&x, 5);
        let p = odom.pose.pose.position;
        assert_eq!((p.x, p.y, p.z), (2.0, 1.0, 3.0)); // ENU: east, north, up
        let q = odom.pose.pose.orientation;
        let h = std::f64::consts::FRAC_1_SQRT_2;
        // Facing north in ENU is a +90 deg rotation about z (up).
        assert!((q.w - h).abs() < 1e-12 && (q.z - h).abs() < 1e-12, "{q:?}");
        assert!(q.x.abs() < 1e-12 && q.y.abs() < 1e-12);
        let v = odom.twist.twist.linear; // body FLU: forward
        assert!((v.x - 1.0).abs() < 1e-12 && v.y.abs() < 1e-12 && v.z.abs() < 1e-12);
        // Turning right (FRD +z) is a negative FLU z rate.
        assert!((odom.twist.twist.angular.z + 0.2).abs() < 1e-12);
        let back = odometry_to_state("/odom", &odom).unwrap();
        assert!((back - x).abs().max() < 1e-12, "{back}");
    }

    #[test]
    fn round_trip_at_many_attitudes() {
        let mut seed = 7u64;
        let mut next = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((seed >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
        };
        for _ in 0..200 {
            let mut v = [0.0; 12];
            for (i, slot) in v.iter_mut().enumerate() {
                *slot = next() * if i == 4 { 1.5 } else { 3.0 };
            }
            let x = state(v);
            let back = odometry_to_state("/odom", &state_to_odometry(&x, 0)).unwrap();
            assert!((back - x).abs().max() < 1e-9, "{x} -> {back}");
        }
    }

    #[test]
    fn px4_odometry_is_already_ned() {
        // Yaw 90 deg (facing east), flying east at 2 m/s, given in the body frame.
        let h = std::f32::consts::FRAC_1_SQRT_2;
        let mut odom = VehicleOdometry {
            pose_frame: VehicleOdometry::POSE_FRAME_NED,
            position: [1.0, 2.0, -3.0],
            q: [h, 0.0, 0.0, h],
            velocity_frame: VehicleOdometry::VELOCITY_FRAME_BODY_FRD,
            velocity: [2.0, 0.0, 0.0],
            angular_velocity: [0.1, 0.2, 0.3],
            ..VehicleOdometry::default()
        };
        let x = vehicle_odometry_to_state("/fmu/out/vehicle_odometry", &odom).unwrap();
        let want = [
            1.0,
            2.0,
            -3.0,
            std::f64::consts::FRAC_PI_2,
            0.0,
            0.0,
            0.0,
            2.0,
            0.0,
            0.1,
            0.2,
            0.3,
        ];
        for i in 0..12 {
            assert!(
                (x[i] - want[i]).abs() < 1e-6,
                "{i}: {} vs {}",
                x[i],
                want[i]
            );
        }
        odom.pose_frame = VehicleOdometry::POSE_FRAME_FRD;
        assert!(vehicle_odometry_to_state("/o", &odom).is_err());
        odom.pose_frame = VehicleOdometry::POSE_FRAME_NED;
        odom.q[0] = f32::NAN;
        let text = vehicle_odometry_to_state("/o", &odom)
            .unwrap_err()
            .to_string();
        assert!(text.contains("`q`"), "{text}");
    }

    #[test]
    fn px4_round_trip_to_float32_precision() {
        let x = state([
            1.5, -2.25, -3.0, 2.5, 0.3, -0.2, 0.5, -1.0, 0.25, 0.1, -0.2, 0.3,
        ]);
        let odom = state_to_vehicle_odometry(&x, 1234);
        assert_eq!((odom.timestamp, odom.timestamp_sample), (1234, 1234));
        let back = vehicle_odometry_to_state("/fmu/out/vehicle_odometry", &odom).unwrap();
        assert!((back - x).abs().max() < 1e-6, "{x} -> {back}");
    }

    #[test]
    fn bad_odometry_is_rejected_with_the_field() {
        let mut odom = state_to_odometry(&State::zeros(), 0);
        odom.twist.twist.linear.y = f64::NAN;
        let text = odometry_to_state("/mocap", &odom).unwrap_err().to_string();
        assert!(
            text.contains("/mocap") && text.contains("twist.twist.linear"),
            "{text}"
        );
        let mut odom = state_to_odometry(&State::zeros(), 0);
        odom.pose.pose.orientation.w = 2.0;
        let text = odometry_to_state("/mocap", &odom).unwrap_err().to_string();
        assert!(
            text.contains("orientation") && text.contains("norm"),
            "{text}"
        );
        let mut odom = state_to_odometry(&State::zeros(), 0);
        odom.pose.pose.position.z = f64::INFINITY;
        assert!(odometry_to_state("/mocap", &odom).is_err());
    }
}
