//! Topic names and types of the ROS 2 node (TOML, strict).

use std::path::Path;

use atmo_core::config_file::{Checker, ConfigFile};
use serde::Deserialize;

use crate::error::{IoError, Result};
use crate::msg::{
    ActuatorMotors, Clock, DiagnosticArray, InputRc, MpcStatus, Odometry, OffboardControlMode,
    PilotInput, PointStamped, RosMessage, Twist, Vector3Stamped, VehicleOdometry,
};

/// The node's settings: a `[ros2]`-style table (or a whole file).
/// Every key has a default; unknown keys are errors.
#[derive(Debug, Clone, PartialEq, Eq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Ros2Config {
    /// ROS 2 node name.
    pub node_name: String,
    /// Node namespace (`/` or `/name`).
    pub namespace: String,
    /// Keep DDS traffic on 127.0.0.1 (no other interface, no multicast).
    pub loopback_only: bool,
    /// Period of the node's own `diagnostics` message, ms.
    pub diagnostics_period_ms: u64,
    /// Slots of the queue from the control thread to the ROS 2 thread.
    pub publish_queue: usize,
    /// ROS time is the newest `topics.clock` message (`rosgraph_msgs/Clock`,
    /// 0 until the first), not the wall clock: ROS 2's `use_sim_time`.
    pub use_sim_time: bool,
    pub topics: Topics,
}

/// One topic: its ROS 2 name, its type, and whether it is used.
#[derive(Debug, Clone, PartialEq, Eq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TopicConfig {
    pub name: String,
    #[serde(rename = "type")]
    pub type_name: String,
    #[serde(default = "atmo_core::config_file::default_true")]
    pub enabled: bool,
}

/// The node's topics (see the README's table).
#[derive(Debug, Clone, PartialEq, Eq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Topics {
    /// Out: one `MpcStatus` per tick.
    pub status: TopicConfig,
    /// In: the state estimate (`nav_msgs/msg/Odometry` ENU/FLU from motion
    /// capture, or `px4_msgs/msg/VehicleOdometry` NED/FRD from PX4).
    pub estimate: TopicConfig,
    /// In: drive commands (`geometry_msgs/msg/Twist`, FLU: linear.x forward,
    /// angular.z yaw rate left-positive).
    pub drive_command: TopicConfig,
    /// In: pilot inputs (`atmo_msgs/msg/PilotInput`: NED velocity command,
    /// FRD yaw rate, throttle in [0, 1], switches), e.g. from the SITL plant
    /// server or a ground station.
    pub pilot: TopicConfig,
    /// Out: thruster commands through PX4 offboard.
    pub actuator_motors: TopicConfig,
    /// Out: PX4 offboard heartbeat (direct actuator control).
    pub offboard_mode: TopicConfig,
    /// Out: health.
    pub diagnostics: TopicConfig,
    /// In: the ground height (`geometry_msgs/msg/PointStamped`, ENU world
    /// frame: `point.z` is the height of the ground under the robot, up).
    pub ground: TopicConfig,
    /// In: the ground plane's normal (`geometry_msgs/msg/Vector3Stamped`,
    /// ENU world frame: the unit normal of the ground under the robot,
    /// pointing out of the ground, so `vector.z > 0`). Optional: while no
    /// fresh normal arrives the ground is level.
    pub ground_normal: TopicConfig,
    /// In, with `use_sim_time` only: ROS time (`rosgraph_msgs/msg/Clock`).
    pub clock: TopicConfig,
    /// In: the radio through PX4 (`px4_msgs/msg/InputRc`, raw pulse
    /// widths); off unless enabled. The daemon's `[rc]` table maps it.
    pub rc: TopicConfig,
}

fn topic(name: &str, type_name: &str) -> TopicConfig {
    TopicConfig {
        name: name.into(),
        type_name: type_name.into(),
        enabled: true,
    }
}

impl Default for Topics {
    fn default() -> Self {
        Self {
            status: topic("/atmo/status", MpcStatus::TYPE_NAME),
            estimate: topic("/atmo/mocap/odom", Odometry::TYPE_NAME),
            drive_command: topic("/atmo/cmd_drive", Twist::TYPE_NAME),
            pilot: topic("/atmo/pilot", PilotInput::TYPE_NAME),
            actuator_motors: topic("/fmu/in/actuator_motors", ActuatorMotors::TYPE_NAME),
            offboard_mode: topic(
                "/fmu/in/offboard_control_mode",
                OffboardControlMode::TYPE_NAME,
            ),
            diagnostics: topic("/diagnostics", DiagnosticArray::TYPE_NAME),
            ground: topic("/atmo/ground", PointStamped::TYPE_NAME),
            ground_normal: topic("/atmo/ground_normal", Vector3Stamped::TYPE_NAME),
            clock: topic("/clock", Clock::TYPE_NAME),
            rc: TopicConfig {
                enabled: false,
                ..topic("/fmu/out/input_rc", InputRc::TYPE_NAME)
            },
        }
    }
}

impl Default for Ros2Config {
    fn default() -> Self {
        Self {
            node_name: "atmo_daemon".into(),
            namespace: "/".into(),
            loopback_only: true,
            diagnostics_period_ms: 1000,
            publish_queue: 64,
            use_sim_time: false,
            topics: Topics::default(),
        }
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
        let c = Checker::new(file);
        if !valid_segment(&self.node_name) {
            return Err(c
                .fail(
                    "node_name",
                    "a ROS 2 name ([A-Za-z_][A-Za-z0-9_]*)",
                    &self.node_name,
                )
                .into());
        }
        if self.namespace != "/" && !valid_topic_name(&self.namespace) {
            return Err(c
                .fail(
                    "namespace",
                    "`/` or an absolute name like /atmo",
                    &self.namespace,
                )
                .into());
        }
        c.range(
            "diagnostics_period_ms",
            self.diagnostics_period_ms,
            10..=60_000,
            "ms",
        )?;
        c.range("publish_queue", self.publish_queue, 1..=65_536, "slots")?;
        let t = &self.topics;
        if self.use_sim_time && !t.clock.enabled {
            return Err(c
                .fail(
                    "topics.clock.enabled",
                    "true: use_sim_time takes ROS time from it",
                    false,
                )
                .into());
        }
        let roles: [(&str, &TopicConfig, &[&str]); 11] = [
            ("topics.status", &t.status, &[MpcStatus::TYPE_NAME]),
            (
                "topics.estimate",
                &t.estimate,
                &[Odometry::TYPE_NAME, VehicleOdometry::TYPE_NAME],
            ),
            (
                "topics.drive_command",
                &t.drive_command,
                &[Twist::TYPE_NAME],
            ),
            ("topics.pilot", &t.pilot, &[PilotInput::TYPE_NAME]),
            (
                "topics.actuator_motors",
                &t.actuator_motors,
                &[ActuatorMotors::TYPE_NAME],
            ),
            (
                "topics.offboard_mode",
                &t.offboard_mode,
                &[OffboardControlMode::TYPE_NAME],
            ),
            (
                "topics.diagnostics",
                &t.diagnostics,
                &[DiagnosticArray::TYPE_NAME],
            ),
            ("topics.ground", &t.ground, &[PointStamped::TYPE_NAME]),
            (
                "topics.ground_normal",
                &t.ground_normal,
                &[Vector3Stamped::TYPE_NAME],
            ),
            ("topics.clock", &t.clock, &[Clock::TYPE_NAME]),
            ("topics.rc", &t.rc, &[InputRc::TYPE_NAME]),
        ];
        let mut names: Vec<&str> = Vec::new();
        for (key, topic, types) in roles {
            if !valid_topic_name(&topic.name) {
                return Err(c
                    .fail(
                        &format!("{key}.name"),
                        "an absolute ROS 2 topic name like /atmo/status",
                        &topic.name,
                    )
                    .into());
            }
            if !types.contains(&topic.type_name.as_str()) {
                return Err(c
                    .fail(
                        &format!("{key}.type"),
                        format!("one of {types:?}"),
                        &topic.type_name,
                    )
                    .into());
            }
            if topic.enabled {
                if names.contains(&topic.name.as_str()) {
                    return Err(c
                        .fail(
                            &format!("{key}.name"),
                            "a name no other topic uses",
                            &topic.name,
                        )
                        .into());
                }
                names.push(&topic.name);
            }
        }
        Ok(())
    }
}
