"""ROS 2 message types as Cyclone DDS IDL structs, named as ROS 2 names them
on the wire (`pkg::msg::dds_::Type_`). Field order and types follow the
`.msg` files (ros2/atmo_msgs/msg, crates/atmo-io/msg)."""

from dataclasses import dataclass, field

from cyclonedds.idl import IdlStruct
from cyclonedds.idl.types import array, float64, int32, sequence, uint8, uint32, uint64


@dataclass
class Time(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
    sec: int32 = 0
    nanosec: uint32 = 0


@dataclass
class Header(IdlStruct, typename="std_msgs::msg::dds_::Header_"):
    stamp: Time = field(default_factory=Time)
    frame_id: str = ""


@dataclass
class Vector3(IdlStruct, typename="geometry_msgs::msg::dds_::Vector3_"):
    x: float64 = 0.0
    y: float64 = 0.0
    z: float64 = 0.0


@dataclass
class Point(IdlStruct, typename="geometry_msgs::msg::dds_::Point_"):
    x: float64 = 0.0
    y: float64 = 0.0
    z: float64 = 0.0


@dataclass
class Quaternion(IdlStruct, typename="geometry_msgs::msg::dds_::Quaternion_"):
    x: float64 = 0.0
    y: float64 = 0.0
    z: float64 = 0.0
    w: float64 = 1.0


@dataclass
class Pose(IdlStruct, typename="geometry_msgs::msg::dds_::Pose_"):
    position: Point = field(default_factory=Point)
    orientation: Quaternion = field(default_factory=Quaternion)


@dataclass
class Twist(IdlStruct, typename="geometry_msgs::msg::dds_::Twist_"):
    linear: Vector3 = field(default_factory=Vector3)
    angular: Vector3 = field(default_factory=Vector3)


@dataclass
class PoseWithCovariance(IdlStruct, typename="geometry_msgs::msg::dds_::PoseWithCovariance_"):
    pose: Pose = field(default_factory=Pose)
    covariance: array[float64, 36] = field(default_factory=lambda: [0.0] * 36)


@dataclass
class TwistWithCovariance(IdlStruct, typename="geometry_msgs::msg::dds_::TwistWithCovariance_"):
    twist: Twist = field(default_factory=Twist)
    covariance: array[float64, 36] = field(default_factory=lambda: [0.0] * 36)


@dataclass
class Odometry(IdlStruct, typename="nav_msgs::msg::dds_::Odometry_"):
    header: Header = field(default_factory=Header)
    child_frame_id: str = ""
    pose: PoseWithCovariance = field(default_factory=PoseWithCovariance)
    twist: TwistWithCovariance = field(default_factory=TwistWithCovariance)


@dataclass
class KeyValue(IdlStruct, typename="diagnostic_msgs::msg::dds_::KeyValue_"):
    key: str = ""
    value: str = ""


@dataclass
class DiagnosticStatus(IdlStruct, typename="diagnostic_msgs::msg::dds_::DiagnosticStatus_"):
    level: uint8 = 0
    name: str = ""
    message: str = ""
    hardware_id: str = ""
    values: sequence[KeyValue] = field(default_factory=list)


@dataclass
class DiagnosticArray(IdlStruct, typename="diagnostic_msgs::msg::dds_::DiagnosticArray_"):
    header: Header = field(default_factory=Header)
    status: sequence[DiagnosticStatus] = field(default_factory=list)


@dataclass
class PilotInput(IdlStruct, typename="atmo_msgs::msg::dds_::PilotInput_"):
    velocity: array[float64, 3] = field(default_factory=lambda: [0.0] * 3)
    yaw_rate: float64 = 0.0
    throttle: float64 = 0.0
    arm: bool = False
    offboard: bool = False
    mpc_enabled: bool = False


@dataclass
class TickTiming(IdlStruct, typename="atmo_msgs::msg::dds_::TickTiming_"):
    tick: uint64 = 0
    deadline_ns: uint64 = 0
    wake_latency: float64 = 0.0
    compute: float64 = 0.0
    overrun: bool = False
    overruns_total: uint64 = 0
    skipped_total: uint64 = 0


@dataclass
class IoHealth(IdlStruct, typename="atmo_msgs::msg::dds_::IoHealth_"):
    malformed: uint64 = 0
    invalid: uint64 = 0
    stamp_backwards: uint64 = 0
    inputs_dropped: uint64 = 0
    publish_dropped: uint64 = 0
    log_dropped: uint64 = 0
    drivers_alive: array[bool, 4] = field(default_factory=lambda: [False] * 4)
    driver_deaths: array[uint64, 4] = field(default_factory=lambda: [0] * 4)


@dataclass
class MpcStatus(IdlStruct, typename="atmo_msgs::msg::dds_::MpcStatus_"):
    header: Header = field(default_factory=Header)
    tick: uint64 = 0
    clock_ns: uint64 = 0
    mode: uint8 = 0
    mode_name: str = ""
    transition: str = ""
    solver_status: uint8 = 0
    solver_status_name: str = ""
    solver_iterations: uint32 = 0
    mpc_failed_ticks: uint32 = 0
    mpc_failures_total: uint64 = 0
    feedback_fallbacks_total: uint64 = 0
    state: array[float64, 12] = field(default_factory=lambda: [0.0] * 12)
    reference: array[float64, 12] = field(default_factory=lambda: [0.0] * 12)
    predicted_next: array[float64, 12] = field(default_factory=lambda: [0.0] * 12)
    thrust: array[float64, 4] = field(default_factory=lambda: [0.0] * 4)
    alpha: float64 = 0.0
    varphi: float64 = 0.0
    tilt_limit: float64 = 0.0
    tilt_velocity: float64 = 0.0
    drive_velocity: array[float64, 2] = field(default_factory=lambda: [0.0] * 2)
    wheel_rates: array[float64, 2] = field(default_factory=lambda: [0.0] * 2)
    height: float64 = 0.0
    ground_contact: bool = False
    estimate_age: float64 = 0.0
    feedback_time: float64 = 0.0
    preparation_time: float64 = 0.0
    pilot: PilotInput = field(default_factory=PilotInput)
    timing: TickTiming = field(default_factory=TickTiming)
    rejected_estimate: uint64 = 0
    rejected_tilt: uint64 = 0
    rejected_pilot: uint64 = 0
    rejected_ground: uint64 = 0
    io: IoHealth = field(default_factory=IoHealth)
    actuator_faults: uint8 = 0
    rejected_rotor_speeds: uint64 = 0
