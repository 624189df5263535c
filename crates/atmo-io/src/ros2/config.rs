//! Topic names and types of the ROS 2 node (TOML, strict).

use std::path::Path;

use atmo_core::config_file::{Checker, ConfigFile};

use crate::error::{IoError, Result};
use crate::msg::{
    ActuatorMotors, Clock, DiagnosticArray, EscStatus, InputRc, MpcStatus, Odometry,
    OffboardControlMode, PilotInput, PointStamped, RosMessage, Twist, Vector3Stamped,
    VehicleOdometry,
};

fn topic(name: &str, type_name: &str) -> TopicConfig {
    TopicConfig {
        name: name.into(),
        type_name: type_name.into(),
        enabled: true,
    }
}

atmo_core::params! {
    /// The node's settings: a `[ros2]`-style table (or a whole file).
    /// Every key has a default; unknown keys are errors.
    #[derive(Debug, Clone, PartialEq, Eq)]
    pub struct Ros2Config: Default {
        /// ROS 2 node name (`[A-Za-z_][A-Za-z0-9_]*`).
        pub node_name: String = "atmo_daemon".into();
        /// Node namespace (`/` or `/name`).
        pub namespace: String = "/".into();
        /// Keep DDS traffic on 127.0.0.1 (no other interface, no multicast).
        pub loopback_only: bool = true;
        /// Period of the node's own `diagnostics` message.
        pub diagnostics_period_ms: u64 = 1000, range 10..=60_000, unit "ms";
        /// Slots of the queue from the control thread to the ROS 2 thread.
        pub publish_queue: usize = 64, range 1..=65_536, unit "slots";
        /// ROS time is the newest `topics.clock` message (`rosgraph_msgs/Clock`,
        /// 0 until the first), not the wall clock: ROS 2's `use_sim_time`.
        pub use_sim_time: bool = false;
        /// The node's topics.
        pub topics: Topics = Topics::default();
    }
    check |ros2, c, prefix| {
        let key = |name| atmo_core::params::key(prefix, name);
        if !valid_segment(&ros2.node_name) {
            return Err(c.fail(
                &key("node_name"),
                "a ROS 2 name ([A-Za-z_][A-Za-z0-9_]*)",
                &ros2.node_name,
            ));
        }
        if ros2.namespace != "/" && !valid_topic_name(&ros2.namespace) {
            return Err(c.fail(
                &key("namespace"),
                "`/` or an absolute name like /atmo",
                &ros2.namespace,
            ));
        }
        if ros2.use_sim_time && !ros2.topics.clock.enabled {
            return Err(c.fail(
                &key("topics.clock.enabled"),
                "true: use_sim_time takes ROS time from it",
                false,
            ));
        }
        Ok(())
    }
}

atmo_core::params! {
    /// One topic: its ROS 2 name, its type, and whether it is used.
    #[derive(Debug, Clone, PartialEq, Eq)]
    pub struct TopicConfig {
        /// Absolute ROS 2 topic name (`/seg(/seg)*`).
        pub name: String;
        /// The message type (each role allows its own).
        pub type_name: String, key "type";
        /// Whether the node uses it.
        pub enabled: bool = true;
    }
    check |topic, c, prefix| {
        if !valid_topic_name(&topic.name) {
            return Err(c.fail(
                &atmo_core::params::key(prefix, "name"),
                "an absolute ROS 2 topic name like /atmo/status",
                &topic.name,
            ));
        }
        Ok(())
    }
}

atmo_core::params! {
    /// The node's topics (see the README's table).
    #[derive(Debug, Clone, PartialEq, Eq)]
    pub struct Topics: Default {
        /// Out: one `MpcStatus` per tick.
        pub status: TopicConfig = topic("/atmo/status", MpcStatus::TYPE_NAME);
        /// In: the state estimate (`nav_msgs/msg/Odometry` ENU/FLU from motion
        /// capture, or `px4_msgs/msg/VehicleOdometry` NED/FRD from PX4).
        pub estimate: TopicConfig = topic("/atmo/mocap/odom", Odometry::TYPE_NAME);
        /// In: drive commands (`geometry_msgs/msg/Twist`, FLU: linear.x forward,
        /// angular.z yaw rate left-positive).
        pub drive_command: TopicConfig = topic("/atmo/cmd_drive", Twist::TYPE_NAME);
        /// In: pilot inputs (`atmo_msgs/msg/PilotInput`: NED velocity command,
        /// FRD yaw rate, throttle in [0, 1], switches), e.g. from the SITL plant
        /// server or a ground station.
        pub pilot: TopicConfig = topic("/atmo/pilot", PilotInput::TYPE_NAME);
        /// Out: thruster commands through PX4 offboard.
        pub actuator_motors: TopicConfig =
            topic("/fmu/in/actuator_motors", ActuatorMotors::TYPE_NAME);
        /// Out: PX4 offboard heartbeat (direct actuator control).
        pub offboard_mode: TopicConfig =
            topic("/fmu/in/offboard_control_mode", OffboardControlMode::TYPE_NAME);
        /// Out: health.
        pub diagnostics: TopicConfig = topic("/diagnostics", DiagnosticArray::TYPE_NAME);
        /// In: the ground height (`geometry_msgs/msg/PointStamped`, ENU world
        /// frame: `point.z` is the height of the ground under the robot, up).
        pub ground: TopicConfig = topic("/atmo/ground", PointStamped::TYPE_NAME);
        /// In: the ground plane's normal (`geometry_msgs/msg/Vector3Stamped`,
        /// ENU world frame: the unit normal of the ground under the robot,
        /// pointing out of the ground, so `vector.z > 0`). Optional: while no
        /// fresh normal arrives the ground is level.
        pub ground_normal: TopicConfig =
            topic("/atmo/ground_normal", Vector3Stamped::TYPE_NAME);
        /// In, with `use_sim_time` only: ROS time (`rosgraph_msgs/msg/Clock`).
        pub clock: TopicConfig = topic("/clock", Clock::TYPE_NAME);
        /// In: the radio through PX4 (`px4_msgs/msg/InputRc`, raw pulse
        /// widths); off unless enabled. The daemon's `[rc]` table maps it.
        pub rc: TopicConfig = TopicConfig {
            enabled: false,
            ..topic("/fmu/out/input_rc", InputRc::TYPE_NAME)
        };
        /// In: the ESCs' telemetry through PX4 (`px4_msgs/msg/EscStatus`,
        /// each rotor's RPM); off unless enabled. The daemon's `[esc]`
        /// table turns the RPM into the rotors' speeds.
        pub esc_status: TopicConfig = TopicConfig {
            enabled: false,
            ..topic("/fmu/out/esc_status", EscStatus::TYPE_NAME)
        };
        /// In: the autopilot's own estimate (`px4_msgs/msg/VehicleOdometry`
        /// from PX4's IMU and barometer) beside an `estimate` taken from
        /// elsewhere (the motion capture straight over ROS 2): what the
        /// failsafe flies on once that one is lost (its attitude, body
        /// rates and vertical speed). Off unless enabled; with PX4's
        /// odometry as the `estimate` it is that topic and not needed.
        pub autopilot_estimate: TopicConfig = TopicConfig {
            enabled: false,
            ..topic("/fmu/out/vehicle_odometry", VehicleOdometry::TYPE_NAME)
        };
    }
    check |topics, c, prefix| topics.check_roles(c, prefix)
}

impl Topics {
    /// Each topic's type is one its role takes, and no two used topics
    /// share a name; errors name `prefix.<role>.<key>`.
    fn check_roles(&self, c: &Checker<'_>, prefix: &str) -> atmo_core::Result<()> {
        let t = self;
        let roles: [(&str, &TopicConfig, &[&str]); 13] = [
            ("status", &t.status, &[MpcStatus::TYPE_NAME]),
            (
                "estimate",
                &t.estimate,
                &[Odometry::TYPE_NAME, VehicleOdometry::TYPE_NAME],
            ),
            (
                "autopilot_estimate",
                &t.autopilot_estimate,
                &[VehicleOdometry::TYPE_NAME],
            ),
            ("drive_command", &t.drive_command, &[Twist::TYPE_NAME]),
            ("pilot", &t.pilot, &[PilotInput::TYPE_NAME]),
            (
                "actuator_motors",
                &t.actuator_motors,
                &[ActuatorMotors::TYPE_NAME],
            ),
            (
                "offboard_mode",
                &t.offboard_mode,
                &[OffboardControlMode::TYPE_NAME],
            ),
            ("diagnostics", &t.diagnostics, &[DiagnosticArray::TYPE_NAME]),
            ("ground", &t.ground, &[PointStamped::TYPE_NAME]),
            (
                "ground_normal",
                &t.ground_normal,
                &[Vector3Stamped::TYPE_NAME],
            ),
            ("clock", &t.clock, &[Clock::TYPE_NAME]),
            ("rc", &t.rc, &[InputRc::TYPE_NAME]),
            ("esc_status", &t.esc_status, &[EscStatus::TYPE_NAME]),
        ];
        let mut names: Vec<&str> = Vec::new();
        for (role, topic, types) in roles {
            let key = atmo_core::params::key(prefix, role);
            if !types.contains(&topic.type_name.as_str()) {
                return Err(c.fail(
                    &format!("{key}.type"),
                    format!("one of {types:?}"),
                    &topic.type_name,
                ));
            }
            if topic.enabled {
                if names.contains(&topic.name.as_str()) {
                    return Err(c.fail(
                        &format!("{key}.name"),
                        "a name no other topic uses",
                        &topic.name,
                    ));
                }
                names.push(&topic.name);
            }
        }
        Ok(())
    }
}

/// A ROS 2 name segment: `[A-Za-z_][A-Za-z0-9_]*` without `__`.
fn valid_segment(s: &str) -> bool {
    s.chars()
        .next()
        .is_some_and(|c| c.is_ascii_alphabetic() || c == '_')
        && s.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
        && !s.contains("__")
}

/// An absolute ROS 2 topic name: `/seg(/seg)*`.
pub(crate) fn valid_topic_name(name: &str) -> bool {
    name.strip_prefix('/')
        .is_some_and(|rest| rest.split('/').all(valid_segment))
}

impl ConfigFile for Ros2Config {
    type Error = IoError;

    /// Checks names, types and ranges; errors name `file` and the key.
    fn validate(&self, file: &Path) -> Result<()> {
        Ok(atmo_core::params::check_file(self, file)?)
    }
}
