//! Standard ROS 2 types: builtin_interfaces, std_msgs, geometry_msgs,
//! nav_msgs, diagnostic_msgs, rosgraph_msgs.

use serde::{Deserialize, Serialize};

use super::RosMessage;

macro_rules! ros_message {
    ($ty:ty, $name:literal) => {
        impl RosMessage for $ty {
            const TYPE_NAME: &'static str = $name;
        }
    };
}

/// `builtin_interfaces/msg/Time`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct Time {
    pub sec: i32,
    pub nanosec: u32,
}

impl Time {
    /// From nanoseconds since the clock's epoch (saturating past 2^31 s).
    pub fn from_ns(ns: u64) -> Self {
        let sec = (ns / 1_000_000_000).min(i32::MAX as u64) as i32;
        Self {
            sec,
            nanosec: (ns % 1_000_000_000) as u32,
        }
    }

    /// Nanoseconds, or `None` for a negative time or `nanosec` >= 1e9.
    pub fn to_ns(self) -> Option<u64> {
        if self.sec < 0 || self.nanosec >= 1_000_000_000 {
            return None;
        }
        Some(self.sec as u64 * 1_000_000_000 + u64::from(self.nanosec))
    }
}

/// `std_msgs/msg/Header`.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct Header {
    pub stamp: Time,
    pub frame_id: String,
}

/// `geometry_msgs/msg/Vector3`.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Vector3 {
    pub x: f64,
    pub y: f64,
    pub z: f64,
}

/// `geometry_msgs/msg/Point`.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Point {
    pub x: f64,
    pub y: f64,
    pub z: f64,
}

/// `geometry_msgs/msg/Quaternion` (default: identity).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Quaternion {
    pub x: f64,
    pub y: f64,
    pub z: f64,
    pub w: f64,
}

impl Default for Quaternion {
    fn default() -> Self {
        Self {
            x: 0.0,
            y: 0.0,
            z: 0.0,
            w: 1.0,
        }
    }
}

/// `geometry_msgs/msg/Pose`.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Pose {
    pub position: Point,
    pub orientation: Quaternion,
}

/// `geometry_msgs/msg/Twist`: drive commands (linear.x forward m/s,
/// angular.z yaw rate rad/s, FLU) and odometry velocities.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Twist {
    pub linear: Vector3,
    pub angular: Vector3,
}

/// `geometry_msgs/msg/PoseWithCovariance`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PoseWithCovariance {
    pub pose: Pose,
    #[serde(with = "super::big_array")]
    pub covariance: [f64; 36],
}

impl Default for PoseWithCovariance {
    fn default() -> Self {
        Self {
            pose: Pose::default(),
            covariance: [0.0; 36],
        }
    }
}

/// `geometry_msgs/msg/TwistWithCovariance`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TwistWithCovariance {
    pub twist: Twist,
    #[serde(with = "super::big_array")]
    pub covariance: [f64; 36],
}

impl Default for TwistWithCovariance {
    fn default() -> Self {
        Self {
            twist: Twist::default(),
            covariance: [0.0; 36],
        }
    }
}

/// `nav_msgs/msg/Odometry`: pose in `header.frame_id` (ENU world per
/// REP 103), twist in `child_frame_id` (FLU body).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct Odometry {
    pub header: Header,
    pub child_frame_id: String,
    pub pose: PoseWithCovariance,
    pub twist: TwistWithCovariance,
}

/// `diagnostic_msgs/msg/KeyValue`.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct KeyValue {
    pub key: String,
    pub value: String,
}

/// `diagnostic_msgs/msg/DiagnosticStatus`.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct DiagnosticStatus {
    pub level: u8,
    pub name: String,
    pub message: String,
    pub hardware_id: String,
    pub values: Vec<KeyValue>,
}

impl DiagnosticStatus {
    pub const OK: u8 = 0;
    pub const WARN: u8 = 1;
    pub const ERROR: u8 = 2;
    pub const STALE: u8 = 3;
}

/// `geometry_msgs/msg/PointStamped`: the ground height input (a point on
/// the ground under the robot, ENU world frame).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct PointStamped {
    pub header: Header,
    pub point: Point,
}

/// `geometry_msgs/msg/Vector3Stamped`: the ground normal input (the unit
/// normal of the ground plane under the robot, ENU world frame, pointing
/// out of the ground).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct Vector3Stamped {
    pub header: Header,
    pub vector: Vector3,
}

/// `rosgraph_msgs/msg/Clock`: ROS time when `use_sim_time` is set.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct Clock {
    pub clock: Time,
}

/// `diagnostic_msgs/msg/DiagnosticArray`.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct DiagnosticArray {
    pub header: Header,
    pub status: Vec<DiagnosticStatus>,
}

ros_message!(Time, "builtin_interfaces/msg/Time");
ros_message!(Header, "std_msgs/msg/Header");
ros_message!(Vector3, "geometry_msgs/msg/Vector3");
ros_message!(Point, "geometry_msgs/msg/Point");
ros_message!(Quaternion, "geometry_msgs/msg/Quaternion");
ros_message!(Pose, "geometry_msgs/msg/Pose");
ros_message!(Twist, "geometry_msgs/msg/Twist");
ros_message!(PoseWithCovariance, "geometry_msgs/msg/PoseWithCovariance");
ros_message!(TwistWithCovariance, "geometry_msgs/msg/TwistWithCovariance");
ros_message!(Odometry, "nav_msgs/msg/Odometry");
ros_message!(KeyValue, "diagnostic_msgs/msg/KeyValue");
ros_message!(DiagnosticStatus, "diagnostic_msgs/msg/DiagnosticStatus");
ros_message!(DiagnosticArray, "diagnostic_msgs/msg/DiagnosticArray");
ros_message!(PointStamped, "geometry_msgs/msg/PointStamped");
ros_message!(Vector3Stamped, "geometry_msgs/msg/Vector3Stamped");
ros_message!(Clock, "rosgraph_msgs/msg/Clock");
