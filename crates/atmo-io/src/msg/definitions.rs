//! `.msg` texts and `ros2msg` schema assembly.

use crate::error::{IoError, Result};

/// Every definition known to this crate, by `pkg/Type` (ROS 1 style key,
/// as used after `MSG:` in a `ros2msg` schema).
const DEFINITIONS: &[(&str, &str)] = &[
    (
        "builtin_interfaces/Time",
        include_str!("../../msg/builtin_interfaces/Time.msg"),
    ),
    (
        "std_msgs/Header",
        include_str!("../../msg/std_msgs/Header.msg"),
    ),
    (
        "geometry_msgs/Vector3",
        include_str!("../../msg/geometry_msgs/Vector3.msg"),
    ),
    (
        "geometry_msgs/Point",
        include_str!("../../msg/geometry_msgs/Point.msg"),
    ),
    (
        "geometry_msgs/Quaternion",
        include_str!("../../msg/geometry_msgs/Quaternion.msg"),
    ),
    (
        "geometry_msgs/Pose",
        include_str!("../../msg/geometry_msgs/Pose.msg"),
    ),
    (
        "geometry_msgs/Twist",
        include_str!("../../msg/geometry_msgs/Twist.msg"),
    ),
    (
        "geometry_msgs/PointStamped",
        include_str!("../../msg/geometry_msgs/PointStamped.msg"),
    ),
    (
        "geometry_msgs/Vector3Stamped",
        include_str!("../../msg/geometry_msgs/Vector3Stamped.msg"),
    ),
    (
        "rosgraph_msgs/Clock",
        include_str!("../../msg/rosgraph_msgs/Clock.msg"),
    ),
    (
        "geometry_msgs/PoseWithCovariance",
        include_str!("../../msg/geometry_msgs/PoseWithCovariance.msg"),
    ),
    (
        "geometry_msgs/TwistWithCovariance",
        include_str!("../../msg/geometry_msgs/TwistWithCovariance.msg"),
    ),
    (
        "nav_msgs/Odometry",
        include_str!("../../msg/nav_msgs/Odometry.msg"),
    ),
    (
        "diagnostic_msgs/KeyValue",
        include_str!("../../msg/diagnostic_msgs/KeyValue.msg"),
    ),
    (
        "diagnostic_msgs/DiagnosticStatus",
        include_str!("../../msg/diagnostic_msgs/DiagnosticStatus.msg"),
    ),
    (
        "diagnostic_msgs/DiagnosticArray",
        include_str!("../../msg/diagnostic_msgs/DiagnosticArray.msg"),
    ),
    (
        "px4_msgs/VehicleOdometry",
        include_str!("../../msg/px4_msgs/VehicleOdometry.msg"),
    ),
    (
        "px4_msgs/InputRc",
        include_str!("../../msg/px4_msgs/InputRc.msg"),
    ),
    (
        "px4_msgs/EscReport",
        include_str!("../../msg/px4_msgs/EscReport.msg"),
    ),
    (
        "px4_msgs/EscStatus",
        include_str!("../../msg/px4_msgs/EscStatus.msg"),
    ),
    (
        "px4_msgs/ActuatorMotors",
        include_str!("../../msg/px4_msgs/ActuatorMotors.msg"),
    ),
    (
        "px4_msgs/OffboardControlMode",
        include_str!("../../msg/px4_msgs/OffboardControlMode.msg"),
    ),
    (
        "atmo_msgs/PilotInput",
        include_str!("../../../../ros2/atmo_msgs/msg/PilotInput.msg"),
    ),
    (
        "atmo_msgs/SimTruth",
        include_str!("../../../../ros2/atmo_msgs/msg/SimTruth.msg"),
    ),
    (
        "atmo_msgs/TickInputs",
        include_str!("../../../../ros2/atmo_msgs/msg/TickInputs.msg"),
    ),
    (
        "atmo_msgs/TickTiming",
        include_str!("../../../../ros2/atmo_msgs/msg/TickTiming.msg"),
    ),
    (
        "atmo_msgs/IoHealth",
        include_str!("../../../../ros2/atmo_msgs/msg/IoHealth.msg"),
    ),
    (
        "atmo_msgs/MpcStatus",
        include_str!("../../../../ros2/atmo_msgs/msg/MpcStatus.msg"),
    ),
];

const PRIMITIVES: &[&str] = &[
    "bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16", "int32",
    "uint32", "int64", "uint64", "string", "wstring",
];

/// `pkg/Type` from `pkg/msg/Type` or `pkg/Type`.
fn short_name(type_name: &str) -> String {
    let parts: Vec<&str> = type_name.split('/').collect();
    match parts.as_slice() {
        [pkg, "msg", name] => format!("{pkg}/{name}"),
        _ => type_name.to_string(),
    }
}

/// The `.msg` text of a type (`pkg/msg/Type` or `pkg/Type`).
pub fn definition(type_name: &str) -> Option<&'static str> {
    let key = short_name(type_name);
    DEFINITIONS
        .iter()
        .find(|(name, _)| *name == key)
        .map(|(_, text)| *text)
}

/// How a field repeats: `T`, `T[N]`, `T[<=N]`, `T[]`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum ArrayKind {
    None,
    Fixed(u64),
    Bounded(u64),
    Unbounded,
}

/// One field of a `.msg` definition (constants are not fields).
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct FieldDecl {
    pub name: String,
    /// A primitive (`float64`, `string`...) or `pkg/Type` (resolved:
    /// `Header` is `std_msgs/Header`, a bare name is in `package`).
    pub base: String,
    /// `N` of `string<=N` / `wstring<=N`.
    pub string_bound: Option<u64>,
    pub array: ArrayKind,
}

/// The fields of a definition of `package`, in order. Comments, blank
/// lines and constants (`TYPE NAME=VALUE`) are skipped; a default value
/// after the name is ignored.
pub(crate) fn fields(package: &str, text: &str) -> Vec<FieldDecl> {
    let mut out = Vec::new();
    for line in text.lines() {
        let line = line.split('#').next().unwrap_or_default().trim();
        let mut tokens = line.split_whitespace();
        let (Some(field_type), Some(name)) = (tokens.next(), tokens.next()) else {
            continue;
        };
        if line[field_type.len()..].contains('=') {
            continue; // a constant
        }
        let (element, array) = match field_type.split_once('[') {
            None => (field_type, ArrayKind::None),
            Some((element, rest)) => {
                let inside = rest.trim_end_matches(']');
                let array = if inside.is_empty() {
                    ArrayKind::Unbounded
                } else if let Some(n) = inside.strip_prefix("<=") {
                    ArrayKind::Bounded(n.parse().unwrap_or(0))
                } else {
                    ArrayKind::Fixed(inside.parse().unwrap_or(0))
                };
                (element, array)
            }
        };
        let (base, string_bound) = match element.split_once("<=") {
            Some((base, n)) => (base, n.parse().ok()),
            None => (element, None),
        };
        let base = if PRIMITIVES.contains(&base) {
            base.to_string()
        } else if base.contains('/') {
            short_name(base)
        } else if base == "Header" {
            "std_msgs/Header".to_string()
        } else {
            format!("{package}/{base}")
        };
        out.push(FieldDecl {
            name: name.to_string(),
            base,
            string_bound,
            array,
        });
    }
    out
}

/// The complex field types a definition uses, as `pkg/Type`, in order.
fn field_types(package: &str, text: &str) -> Vec<String> {
    let mut out: Vec<String> = Vec::new();
    for field in fields(package, text) {
        if !PRIMITIVES.contains(&field.base.as_str()) && !out.contains(&field.base) {
            out.push(field.base);
        }
    }
    out
}

/// The `ros2msg` schema of a type: its definition, then each dependency
/// (transitively, each once) after a line of 80 `=` and `MSG: pkg/Type`.
pub fn schema_text(type_name: &str) -> Result<String> {
    let root = short_name(type_name);
    let unknown = |field_type: &str| IoError::UnknownType {
        type_name: root.clone(),
        field_type: field_type.to_string(),
    };
    let root_text = definition(&root).ok_or_else(|| unknown(&root))?;
    let mut out = String::from(root_text);
    let mut seen = vec![root.clone()];
    let mut queue = vec![root.clone()];
    while let Some(current) = queue.pop() {
        let package = current.split('/').next().unwrap_or_default().to_string();
        let text = definition(&current).ok_or_else(|| unknown(&current))?;
        for dep in field_types(&package, text) {
            if seen.contains(&dep) {
                continue;
            }
            let dep_text = definition(&dep).ok_or_else(|| unknown(&dep))?;
            if !out.ends_with('\n') {
                out.push('\n');
            }
            out.push_str(&"=".repeat(80));
            out.push_str("\nMSG: ");
            out.push_str(&dep);
            out.push('\n');
            out.push_str(dep_text);
            seen.push(dep.clone());
            queue.insert(0, dep);
        }
    }
    Ok(out)
}
