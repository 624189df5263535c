//! CDR round trips against byte vectors computed by hand from the XCDR1
//! rules (little endian; alignment of each primitive to its size, counted
//! from the start of the body after the 4-byte encapsulation header).

use super::*;

fn f64s(values: &[f64]) -> Vec<u8> {
    values.iter().flat_map(|v| v.to_le_bytes()).collect()
}

fn f32s(values: &[f32]) -> Vec<u8> {
    values.iter().flat_map(|v| v.to_le_bytes()).collect()
}

fn round_trip<M: RosMessage + PartialEq>(message: &M, expected_body: &[u8]) {
    let bytes = encode_to_vec(message).unwrap();
    assert_eq!(&bytes[..4], &CDR_LE_HEADER);
    assert_eq!(&bytes[4..], expected_body, "{}", M::TYPE_NAME);
    let back: M = decode("/test", &bytes).unwrap();
    assert_eq!(&back, message);
}

#[test]
fn time_and_header() {
    round_trip(&Time { sec: 1, nanosec: 2 }, &[1, 0, 0, 0, 2, 0, 0, 0]);
    let header = Header {
        stamp: Time {
            sec: -1,
            nanosec: 7,
        },
        frame_id: "odom".into(),
    };
    round_trip(
        &header,
        &[
            0xff, 0xff, 0xff, 0xff, 7, 0, 0, 0, // stamp
            5, 0, 0, 0, b'o', b'd', b'o', b'm', 0, // string: length with NUL
        ],
    );
    assert_eq!(Time::from_ns(3_000_000_004), Time { sec: 3, nanosec: 4 });
    assert_eq!(Time { sec: 3, nanosec: 4 }.to_ns(), Some(3_000_000_004));
    assert_eq!(
        Time {
            sec: -3,
            nanosec: 4
        }
        .to_ns(),
        None
    );
}

#[test]
fn twist_is_six_doubles() {
    let twist = Twist {
        linear: Vector3 {
            x: 1.0,
            y: -2.0,
            z: 3.5,
        },
        angular: Vector3 {
            x: 0.25,
            y: 0.0,
            z: -6.0,
        },
    };
    round_trip(&twist, &f64s(&[1.0, -2.0, 3.5, 0.25, 0.0, -6.0]));
}

#[test]
fn odometry_alignment_after_strings() {
    let mut odom = Odometry {
        header: Header {
            stamp: Time {
                sec: 10,
                nanosec: 0,
            },
            frame_id: "map".into(), // 4 + 4 bytes: body offset 16 after it
        },
        child_frame_id: "base".into(), // 4 + 5 bytes: offset 25, pad to 32
        ..Odometry::default()
    };
    odom.pose.pose.position = Point {
        x: 1.0,
        y: 2.0,
        z: 3.0,
    };
    odom.pose.covariance[35] = 9.0;
    odom.twist.twist.angular.z = 0.5;
    odom.twist.covariance[0] = -1.0;

    let mut body = vec![10, 0, 0, 0, 0, 0, 0, 0, 4, 0, 0, 0, b'm', b'a', b'p', 0];
    body.extend_from_slice(&[5, 0, 0, 0, b'b', b'a', b's', b'e', 0, 0, 0, 0, 0, 0, 0, 0]);
    assert_eq!(body.len(), 32);
    body.extend(f64s(&[1.0, 2.0, 3.0, 0.0, 0.0, 0.0, 1.0])); // pose
    let mut cov = [0.0; 36];
    cov[35] = 9.0;
    body.extend(f64s(&cov)); // fixed array: no length
    body.extend(f64s(&[0.0, 0.0, 0.0, 0.0, 0.0, 0.5]));
    let mut cov = [0.0; 36];
    cov[0] = -1.0;
    body.extend(f64s(&cov));
    round_trip(&odom, &body);
}

#[test]
fn diagnostics_sequences_and_bytes() {
    let array = DiagnosticArray {
        header: Header::default(),
        status: vec![DiagnosticStatus {
            level: DiagnosticStatus::WARN,
            name: "a".into(),
            message: String::new(),
            hardware_id: "hw".into(),
            values: vec![KeyValue {
                key: "k".into(),
                value: "vv".into(),
            }],
        }],
    };
    let body = vec![
        0, 0, 0, 0, 0, 0, 0, 0, // stamp
        1, 0, 0, 0, 0, // frame_id "" (length 1: the NUL), offset 13
        0, 0, 0, // pad to 16
        1, 0, 0, 0, // status: 1 element
        1, // level (byte)
        0, 0, 0, // pad
        2, 0, 0, 0, b'a', 0, // name
        0, 0, // pad
        1, 0, 0, 0, 0, // message ""
        0, 0, 0, // pad
        3, 0, 0, 0, b'h', b'w', 0, // hardware_id
        0, // pad
        1, 0, 0, 0, // values: 1 element
        2, 0, 0, 0, b'k', 0, // key
        0, 0, // pad
        3, 0, 0, 0, b'v', b'v', 0, // value
    ];
    round_trip(&array, &body);
}

#[test]
fn px4_messages() {
    let odom = VehicleOdometry {
        timestamp: 1,
        timestamp_sample: 2,
        pose_frame: VehicleOdometry::POSE_FRAME_NED,
        position: [1.0, 2.0, -3.0],
        q: [1.0, 0.0, 0.0, 0.0],
        velocity_frame: VehicleOdometry::VELOCITY_FRAME_NED,
        velocity: [0.5, 0.0, 0.0],
        angular_velocity: [0.0, 0.0, 0.1],
        position_variance: [0.01; 3],
        orientation_variance: [0.02; 3],
        velocity_variance: [0.03; 3],
        reset_counter: 4,
        quality: -1,
    };
    let mut body = Vec::new();
    body.extend(1u64.to_le_bytes());
    body.extend(2u64.to_le_bytes());
    body.extend([1, 0, 0, 0]); // pose_frame + pad to 4
    body.extend(f32s(&[1.0, 2.0, -3.0, 1.0, 0.0, 0.0, 0.0]));
    body.extend([1, 0, 0, 0]);
    body.extend(f32s(&[0.5, 0.0, 0.0, 0.0, 0.0, 0.1]));
    body.extend(f32s(&[
        0.01, 0.01, 0.01, 0.02, 0.02, 0.02, 0.03, 0.03, 0.03,
    ]));
    body.extend([4, 0xff]);
    round_trip(&odom, &body);

    let motors = ActuatorMotors {
        timestamp: 5,
        timestamp_sample: 6,
        reversible_flags: 0x0102,
        control: [
            0.1,
            0.2,
            0.3,
            0.4,
            f32::NAN,
            f32::NAN,
            f32::NAN,
            f32::NAN,
            f32::NAN,
            f32::NAN,
            f32::NAN,
            f32::NAN,
        ],
    };
    let mut body = Vec::new();
    body.extend(5u64.to_le_bytes());
    body.extend(6u64.to_le_bytes());
    body.extend([2, 1, 0, 0]); // u16 + pad to 4
    body.extend(f32s(&motors.control));
    let bytes = encode_to_vec(&motors).unwrap();
    assert_eq!(&bytes[4..], &body[..]);
    let back: ActuatorMotors = decode("/m", &bytes).unwrap();
    assert_eq!(back.control[..4], motors.control[..4]);
    assert!(back.control[4..].iter().all(|c| c.is_nan()));

    let mode = OffboardControlMode {
        timestamp: 7,
        direct_actuator: true,
        ..OffboardControlMode::default()
    };
    let mut body = 7u64.to_le_bytes().to_vec();
    body.extend([0, 0, 0, 0, 0, 0, 1]);
    round_trip(&mode, &body);
}

pub(crate) fn sample_status() -> MpcStatus {
    let mut status = MpcStatus {
        stamp_ns: 12_000_000_345,
        ros_stamp_ns: 1_780_000_012_000_000_345,
        tick: 1800,
        mode: Mode::Transition,
        transition: Label::new("below z*"),
        solver_status: SolverStatus::Degraded,
        solver_iterations: 3,
        mpc_failed_ticks: 1,
        mpc_failures_total: 2,
        feedback_fallbacks_total: 1,
        thrust: [0.5, 0.6, 0.7, 0.8],
        alpha: 0.25,
        varphi: 1.0,
        tilt_limit: 1.2,
        tilt_velocity: 0.39,
        drive_velocity: [0.1, -0.2],
        wheel_rates: [3.0, 4.0],
        height: 0.3,
        ground_contact: true,
        estimate_age: 0.004,
        feedback_time: 0.0011,
        preparation_time: 0.0022,
        pilot: PilotInput {
            velocity: [0.0, 0.0, 0.3],
            yaw_rate: 0.1,
            throttle: 0.6,
            arm: true,
            offboard: true,
            mpc_enabled: true,
        },
        timing: TickTiming {
            tick: 1800,
            deadline_ns: 12_000_000_000,
            wake_latency: 5e-5,
            compute: 0.0015,
            overrun: false,
            overruns_total: 3,
            skipped_total: 1,
        },
        rejected_estimate: 4,
        rejected_tilt: 5,
        rejected_pilot: 6,
        rejected_ground: 7,
        io: IoHealth {
            malformed: 8,
            invalid: 9,
            stamp_backwards: 10,
            inputs_dropped: 11,
            publish_dropped: 12,
            log_dropped: 13,
            drivers_alive: [true, false, true, true],
            driver_deaths: [0, 1, 0, 2],
        },
        actuator_faults: 6,
        rejected_rotor_speeds: 14,
        ..MpcStatus::default()
    };
    for i in 0..12 {
        status.state[i] = i as f64;
        status.reference[i] = -(i as f64);
        status.predicted_next[i] = 0.5 * i as f64;
    }
    status
}

#[test]
fn mpc_status_layout() {
    let status = sample_status();
    let mut body = Vec::new();
    body.extend(1_780_000_012i32.to_le_bytes()); // header.stamp: ROS time
    body.extend(345u32.to_le_bytes());
    body.extend([1, 0, 0, 0, 0]); // frame_id ""
    body.extend([0, 0, 0]); // pad to 16 for the u64 tick
    body.extend(1800u64.to_le_bytes());
    body.extend(12_000_000_345u64.to_le_bytes()); // clock_ns: the stack's clock
    body.push(5); // mode, offset 32
    body.extend([0, 0, 0]);
    body.extend(11u32.to_le_bytes());
    body.extend(b"transition\0"); // offset 40..51
    body.push(0); // pad to 52
    body.extend(9u32.to_le_bytes());
    body.extend(b"below z*\0"); // 56..65
    body.push(2); // solver_status, 65
    body.extend([0, 0]); // pad to 68
    body.extend(9u32.to_le_bytes());
    body.extend(b"degraded\0"); // 72..81
    body.extend([0, 0, 0]); // pad to 84
    body.extend(3u32.to_le_bytes()); // solver_iterations 84..88
    body.extend(1u32.to_le_bytes()); // mpc_failed_ticks 88..92
    body.extend([0, 0, 0, 0]); // pad to 96
    body.extend(2u64.to_le_bytes()); // mpc_failures_total
    body.extend(1u64.to_le_bytes()); // feedback_fallbacks_total
    body.extend(f64s(&status.state));
    body.extend(f64s(&status.reference));
    body.extend(f64s(&status.predicted_next));
    body.extend(f64s(&[
        0.5, 0.6, 0.7, 0.8, 0.25, 1.0, 1.2, 0.39, 0.1, -0.2, 3.0, 4.0, 0.3,
    ]));
    body.push(1); // ground_contact
    body.extend([0; 7]);
    body.extend(f64s(&[0.004, 0.0011, 0.0022]));
    body.extend(f64s(&[0.0, 0.0, 0.3, 0.1, 0.6]));
    body.extend([1, 1, 1]);
    body.extend([0; 5]);
    body.extend(1800u64.to_le_bytes());
    body.extend(12_000_000_000u64.to_le_bytes());
    body.extend(f64s(&[5e-5, 0.0015]));
    body.push(0);
    body.extend([0; 7]);
    for v in [3u64, 1, 4, 5, 6, 7] {
        body.extend(v.to_le_bytes());
    }
    for v in [8u64, 9, 10, 11, 12, 13] {
        body.extend(v.to_le_bytes());
    }
    body.extend([1, 0, 1, 1]); // drivers_alive
    body.extend([0; 4]); // pad to 16
    for v in [0u64, 1, 0, 2] {
        body.extend(v.to_le_bytes());
    }
    body.push(6); // actuator_faults
    body.extend([0; 7]); // pad to 8
    body.extend(14u64.to_le_bytes()); // rejected_rotor_speeds
    round_trip(&status, &body);
    // Logs written before the trailing fields end at them: they decode, 0.
    let bytes = encode_to_vec(&status).unwrap();
    for (cut, faults) in [(12, 6), (16, 0)] {
        let old = decode::<MpcStatus>("/atmo/status", &bytes[..bytes.len() - cut]).unwrap();
        let (actuator_faults, rejected_rotor_speeds) = (faults, 0);
        let expected = MpcStatus {
            actuator_faults,
            rejected_rotor_speeds,
            ..status
        };
        assert_eq!(old, expected, "{cut} bytes cut");
    }
}

#[test]
fn big_endian_payloads_decode() {
    let mut bytes = CDR_BE_HEADER.to_vec();
    bytes.extend(1i32.to_be_bytes());
    bytes.extend(2u32.to_be_bytes());
    assert_eq!(
        decode::<Time>("/t", &bytes).unwrap(),
        Time { sec: 1, nanosec: 2 }
    );
}

#[test]
fn malformed_payloads_are_errors_naming_the_topic() {
    let good = encode_to_vec(&sample_status()).unwrap();
    // Every truncation of a valid status fails cleanly, but for the last
    // fields', which older logs lack (1 + 7 padding + 8 bytes).
    for len in 0..good.len() - 16 {
        let err = decode::<MpcStatus>("/atmo/status", &good[..len]).unwrap_err();
        let text = err.to_string();
        assert!(
            text.contains("/atmo/status") && text.contains("MpcStatus"),
            "{text}"
        );
    }
    // Unknown encapsulation.
    let mut bad = good.clone();
    bad[1] = 0x07;
    assert!(decode::<MpcStatus>("/s", &bad).is_err());
    // A bad mode code names the field.
    let mut bad = good.clone();
    bad[4 + 32] = 42; // mode, after the header, tick and clock_ns
    let text = decode::<MpcStatus>("/s", &bad).unwrap_err().to_string();
    assert!(text.contains("mode"), "{text}");
    // A huge string length does not allocate its way to a crash.
    let mut bad = encode_to_vec(&Header::default()).unwrap();
    bad[12..16].copy_from_slice(&u32::MAX.to_le_bytes());
    assert!(decode::<Header>("/h", &bad).is_err());
    // A message of another type: a Twist is not an Odometry, an Odometry is
    // not a Twist (left-over bytes).
    let twist = encode_to_vec(&Twist::default()).unwrap();
    assert!(decode::<Odometry>("/o", &twist).is_err());
    let odom = encode_to_vec(&Odometry::default()).unwrap();
    assert!(decode::<Twist>("/o", &odom).is_err());
}

#[test]
fn type_names_follow_ros2() {
    assert_eq!(MpcStatus::TYPE_NAME, "atmo_msgs/msg/MpcStatus");
    assert_eq!(
        MpcStatus::dds_type_name(),
        "atmo_msgs::msg::dds_::MpcStatus_"
    );
    assert_eq!(Odometry::dds_type_name(), "nav_msgs::msg::dds_::Odometry_");
}

#[test]
fn schemas_carry_every_dependency_once() {
    let schema = schema_text(Odometry::TYPE_NAME).unwrap();
    let separator = "=".repeat(80);
    let deps: Vec<&str> = schema
        .lines()
        .filter_map(|l| l.strip_prefix("MSG: "))
        .collect();
    for dep in [
        "std_msgs/Header",
        "builtin_interfaces/Time",
        "geometry_msgs/PoseWithCovariance",
        "geometry_msgs/TwistWithCovariance",
        "geometry_msgs/Pose",
        "geometry_msgs/Point",
        "geometry_msgs/Quaternion",
        "geometry_msgs/Twist",
        "geometry_msgs/Vector3",
    ] {
        assert_eq!(
            deps.iter().filter(|d| **d == dep).count(),
            1,
            "{dep} in {deps:?}"
        );
    }
    assert_eq!(deps.len(), 9);
    assert_eq!(schema.matches(&separator).count(), 9);
    // Each separator is a whole line followed by its MSG line.
    for (i, line) in schema.lines().enumerate() {
        if line.starts_with('=') {
            assert_eq!(line, separator);
            assert!(schema.lines().nth(i + 1).unwrap().starts_with("MSG: "));
        }
    }
    let status = schema_text(MpcStatus::TYPE_NAME).unwrap();
    for dep in [
        "std_msgs/Header",
        "builtin_interfaces/Time",
        "atmo_msgs/PilotInput",
        "atmo_msgs/TickTiming",
        "atmo_msgs/IoHealth",
    ] {
        assert!(status.contains(&format!("MSG: {dep}\n")), "{dep}");
    }
    for type_name in [
        DiagnosticArray::TYPE_NAME,
        VehicleOdometry::TYPE_NAME,
        ActuatorMotors::TYPE_NAME,
        OffboardControlMode::TYPE_NAME,
        Twist::TYPE_NAME,
    ] {
        schema_text(type_name).unwrap();
    }
    assert!(schema_text("nope_msgs/msg/Nope").is_err());
}

#[test]
fn labels_cut_at_char_boundaries() {
    let long = "é".repeat(40); // 80 bytes
    let label = Label::new(&long);
    assert_eq!(label.as_str().len(), 62);
    assert_eq!(Label::new("abc").as_str(), "abc");
    assert!(Label::default().is_empty());
}

#[test]
fn helpers_for_the_flight_stack() {
    let m = ActuatorMotors::from_thrust(7, [0.1, 0.2, 0.3, 0.4]);
    assert_eq!(m.control[..4], [0.1f32, 0.2, 0.3, 0.4]);
    assert!(m.control[4..].iter().all(|c| c.is_nan()));
    assert!(OffboardControlMode::direct_actuator(7).direct_actuator);
    let x = atmo_core::model::State::from_fn(|i, _| i as f64);
    assert_eq!(MpcStatus::array(&x)[11], 11.0);
}

/// RIHS01 hashes as ROS 2 Kilted computes them: `type_hashes` of the
/// `share/<pkg>/msg/<Type>.json` files of the PyPI wheels ros-builtin-interfaces
/// 2.3.0, ros-std-msgs / ros-geometry-msgs / ros-nav-msgs /
/// ros-diagnostic-msgs 5.5.1, ros-rosgraph-msgs 2.3.0, and of atmo_msgs built by colcon
/// (scripts/ros2-peer.sh). tests/python/rclpy_peer.py checks every type of
/// the node against rclpy at run time.
#[test]
fn type_hashes_match_ros2() {
    for (type_name, hash) in [
        (
            "builtin_interfaces/msg/Time",
            "RIHS01_b106235e25a4c5ed35098aa0a61a3ee9c9b18d197f398b0e4206cea9acf9c197",
        ),
        (
            "std_msgs/msg/Header",
            "RIHS01_f49fb3ae2cf070f793645ff749683ac6b06203e41c891e17701b1cb597ce6a01",
        ),
        (
            Twist::TYPE_NAME,
            "RIHS01_9c45bf16fe0983d80e3cfe750d6835843d265a9a6c46bd2e609fcddde6fb8d2a",
        ),
        (
            Odometry::TYPE_NAME,
            "RIHS01_3cc97dc7fb7502f8714462c526d369e35b603cfc34d946e3f2eda2766dfec6e0",
        ),
        (
            DiagnosticArray::TYPE_NAME,
            "RIHS01_5a8a36efb05fb25070fa0fb3810290c0e6cd4862b54a8fb975a1ee8dc55a333e",
        ),
        (
            "geometry_msgs/msg/PointStamped",
            "RIHS01_4c0296af86e01e562e9e0405d138a01537247580076c58ea38d7923ac1045897",
        ),
        (
            "rosgraph_msgs/msg/Clock",
            "RIHS01_692f7a66e93a3c83e71765d033b60349ba68023a8c689a79e48078bcb5c58564",
        ),
        (
            PilotInput::TYPE_NAME,
            "RIHS01_ac378df3770012e3651e1f07f4f6ae0d2ea7f9dd9982f2d4607c411ea162cc9c",
        ),
    ] {
        assert_eq!(type_hash(type_name).unwrap(), hash, "{type_name}");
    }
}

#[test]
fn type_descriptions_follow_rosidl() {
    // Constants are left out, fixed arrays add 48 to the element's id,
    // sequences 144, and nested types are named in full.
    let d = hashed_description(DiagnosticArray::TYPE_NAME).unwrap();
    assert!(
        d.starts_with(
            "{\"type_description\": {\"type_name\": \"diagnostic_msgs/msg/DiagnosticArray\", \
             \"fields\": [{\"name\": \"header\", \"type\": {\"type_id\": 1, \"capacity\": 0, \
             \"string_capacity\": 0, \"nested_type_name\": \"std_msgs/msg/Header\"}}, \
             {\"name\": \"status\", \"type\": {\"type_id\": 145,"
        ),
        "{d}"
    );
    assert!(!d.contains("\"OK\""), "constants are not hashed: {d}");
    let names: Vec<&str> = d
        .match_indices("{\"type_name\": \"")
        .map(|(i, m)| d[i + m.len()..].split('"').next().unwrap())
        .collect();
    assert_eq!(
        names,
        [
            "diagnostic_msgs/msg/DiagnosticArray",
            "builtin_interfaces/msg/Time",
            "diagnostic_msgs/msg/DiagnosticStatus",
            "diagnostic_msgs/msg/KeyValue",
            "std_msgs/msg/Header",
        ]
    );
    assert!(matches!(
        type_hash("atmo_msgs/msg/Nope"),
        Err(IoError::UnknownType { .. })
    ));
}

#[test]
fn tick_inputs_and_sim_truth_layouts() {
    // The .msg fields and the Rust fields agree in order and width:
    // bools are one byte, each uint64/float64 aligned to 8.
    let mut m = TickInputs {
        tick: 3,
        clock_ns: 20_000_000,
        has_estimate: true,
        estimate_received_ns: 19_000_000,
        has_tilt_counts: true,
        tilt_counts: 1234.5,
        ground_contact: true,
        ground_z: -0.25,
        driver_lost: false,
        ..TickInputs::default()
    };
    m.estimate[2] = -1.5;
    m.pilot.throttle = 0.5;
    m.pilot.arm = true;
    let mut body = Vec::new();
    body.extend(3u64.to_le_bytes());
    body.extend(20_000_000u64.to_le_bytes());
    body.push(1);
    body.extend([0; 7]);
    body.extend(19_000_000u64.to_le_bytes());
    body.extend(f64s(&m.estimate));
    body.push(1);
    body.extend([0; 7]);
    body.extend(f64s(&[1234.5]));
    body.extend(f64s(&[0.0, 0.0, 0.0, 0.0, 0.5]));
    body.extend([1, 0, 0]);
    body.push(1);
    body.extend([0; 4]);
    body.extend(f64s(&[-0.25]));
    body.push(0);
    // The time-limit cuts: a count, twelve solve numbers, twelve iterations
    // (each uint32 aligned to 4), the overflow.
    m.solver_cut_count = 2;
    m.solver_cut_solve[1] = 7;
    m.solver_cut_iteration[1] = 9;
    m.solver_cut_overflow = 1;
    body.push(2);
    body.extend([0, 7, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0]);
    while body.len() % 4 != 0 {
        body.push(0);
    }
    for iteration in [0u32, 9, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0] {
        body.extend(iteration.to_le_bytes());
    }
    body.extend(1u32.to_le_bytes());
    // A log written before the ground normal ends here: it decodes as level ground.
    let mut old = CDR_LE_HEADER.to_vec();
    old.extend(&body);
    let decoded: TickInputs = decode("/old", &old).unwrap();
    assert_eq!(decoded, m);
    assert!(!decoded.has_ground_normal);
    // The ground normal: a presence flag, three float64 aligned to 8.
    m.has_ground_normal = true;
    m.ground_normal = [-0.25, 0.0, -0.5];
    body.push(1);
    while body.len() % 8 != 0 {
        body.push(0);
    }
    body.extend(f64s(&[-0.25, 0.0, -0.5]));
    let normal_end = body.len();
    // A log written before the pilot's radio ends here: the radio present.
    let mut before_radio = CDR_LE_HEADER.to_vec();
    before_radio.extend(&body);
    let decoded: TickInputs = decode("/before-radio", &before_radio).unwrap();
    assert_eq!(decoded, m);
    m.pilot_lost = true;
    m.arming_failures = 0b10100;
    body.extend([1, 0b10100]);
    // A log written before the manual tilt lever ends here: the lever at rest.
    let mut before_lever = CDR_LE_HEADER.to_vec();
    before_lever.extend(&body);
    let decoded: TickInputs = decode("/before-lever", &before_lever).unwrap();
    assert_eq!(decoded, m);
    m.tilt_lever = -0.5;
    m.rehome_tilt = true;
    while body.len() % 8 != 0 {
        body.push(0);
    }
    body.extend(f64s(&[-0.5]));
    body.push(1);
    // A log written before the autopilot's estimate ends here: none.
    let mut before_autopilot = CDR_LE_HEADER.to_vec();
    before_autopilot.extend(&body);
    let decoded: TickInputs = decode("/before-autopilot", &before_autopilot).unwrap();
    assert_eq!(decoded, m);
    m.has_autopilot_estimate = true;
    m.autopilot_estimate_received_ns = 18_000_000;
    m.autopilot_estimate[3] = 0.25;
    body.push(1);
    while body.len() % 8 != 0 {
        body.push(0);
    }
    body.extend(18_000_000u64.to_le_bytes());
    body.extend(f64s(&m.autopilot_estimate));
    // A log written before the ESC speeds ends here: none.
    let mut before_speeds = CDR_LE_HEADER.to_vec();
    before_speeds.extend(&body);
    let decoded: TickInputs = decode("/before-speeds", &before_speeds).unwrap();
    assert_eq!(decoded, m);
    m.has_rotor_speeds = true;
    m.rotor_speeds = [0.5, 0.0, 0.75, 1.0];
    body.push(1);
    while body.len() % 8 != 0 {
        body.push(0);
    }
    body.extend(f64s(&m.rotor_speeds));
    round_trip(&m, &body);
    // A payload cut inside the normal is refused, not read as an old one.
    let mut cut = CDR_LE_HEADER.to_vec();
    cut.extend(&body[..normal_end - 8]);
    assert!(decode::<TickInputs>("/cut", &cut).is_err());
    assert_eq!(
        super::definitions::fields("atmo_msgs", definition(TickInputs::TYPE_NAME).unwrap())
            .iter()
            .map(|f| f.name.as_str())
            .collect::<Vec<_>>(),
        super::atmo::TICK_INPUTS_FIELDS
    );
    let truth = SimTruth {
        time: 0.5,
        state: [1.0; 12],
        tilt: 0.25,
        height: 0.125,
        contact: true,
    };
    let mut body = f64s(&[0.5]);
    body.extend(f64s(&[1.0; 12]));
    body.extend(f64s(&[0.25, 0.125]));
    body.push(1);
    round_trip(&truth, &body);
    let schema = schema_text(TickInputs::TYPE_NAME).unwrap();
    assert!(schema.contains("MSG: atmo_msgs/PilotInput\n"));
    schema_text(SimTruth::TYPE_NAME).unwrap();
}

#[test]
fn input_rc_layout() {
    let mut rc = InputRc {
        timestamp: 7,
        timestamp_last_signal: 6,
        channel_count: 16,
        rssi: 100,
        rc_failsafe: false,
        rc_lost: true,
        rc_lost_frame_count: 3,
        rc_total_frame_count: 900,
        rc_ppm_frame_length: 0,
        input_source: 9,
        link_quality: -1,
        rssi_dbm: -50.0,
        ..InputRc::default()
    };
    for (i, v) in rc.values.iter_mut().enumerate() {
        *v = 1000 + i as u16;
    }
    let mut body = Vec::new();
    body.extend(7u64.to_le_bytes());
    body.extend(6u64.to_le_bytes());
    body.extend([16, 0, 0, 0]); // channel_count + pad to 4
    body.extend(100i32.to_le_bytes());
    body.extend([0, 1]);
    for v in [3u16, 900, 0] {
        body.extend(v.to_le_bytes());
    }
    body.extend([9, 0]); // input_source + pad to 2
    for v in rc.values {
        body.extend(v.to_le_bytes());
    }
    body.extend([0xff, 0]); // link_quality + pad to 4
    body.extend((-50.0f32).to_le_bytes());
    round_trip(&rc, &body);
    schema_text(InputRc::TYPE_NAME).unwrap();
    type_hash(InputRc::TYPE_NAME).unwrap();
}

#[test]
fn esc_status_layout() {
    let mut status = EscStatus {
        timestamp: 9,
        counter: 300,
        esc_count: 4,
        esc_connectiontype: 5,
        esc_online_flags: 0b1111,
        esc_armed_flags: 0b1111,
        ..EscStatus::default()
    };
    status.esc[1] = EscReport {
        timestamp: 8,
        esc_errorcount: 2,
        esc_rpm: -12_000,
        esc_voltage: 16.5,
        esc_current: 3.25,
        esc_temperature: 40.0,
        esc_address: 2,
        esc_cmdcount: 7,
        esc_state: 1,
        actuator_function: 102,
        failures: 0b10_0000,
        esc_power: -1,
    };
    let mut body = Vec::new();
    body.extend(9u64.to_le_bytes());
    body.extend(300u16.to_le_bytes());
    body.extend([4, 5, 0b1111, 0b1111]);
    body.extend([0; 2]); // to the first report's uint64
    for (k, report) in status.esc.iter().enumerate() {
        // Each report starts at a multiple of 8: 35 bytes and 5 of padding.
        assert_eq!(body.len() % 8, 0, "report {k}");
        body.extend(report.timestamp.to_le_bytes());
        body.extend(report.esc_errorcount.to_le_bytes());
        body.extend(report.esc_rpm.to_le_bytes());
        body.extend(f32s(&[
            report.esc_voltage,
            report.esc_current,
            report.esc_temperature,
        ]));
        body.extend([
            report.esc_address,
            report.esc_cmdcount,
            report.esc_state,
            report.actuator_function,
        ]);
        body.extend(report.failures.to_le_bytes());
        body.extend(report.esc_power.to_le_bytes());
        if k < 7 {
            body.extend([0; 5]);
        }
    }
    round_trip(&status, &body);
    schema_text(EscStatus::TYPE_NAME).unwrap();
    type_hash(EscStatus::TYPE_NAME).unwrap();
}
