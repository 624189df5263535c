//! The control thread's I/O calls and their allocations: `try_log` of the
//! fixed-size message kinds, the ROS 2 node's `try_publish_*` and input
//! polling (and the SITL node's, for the plant server's loop), and the driver ports' notify and poll do not allocate; a driver-port send
//! allocates exactly once, inside iceoryx2 0.10 (`Publisher::loan_uninit`
//! creates a 48-byte shared-state `Arc` per sample, iceoryx2-cal's
//! single-threaded arc policy; `send_copy` goes through the same loan). A
//! counting global allocator counts the allocations made on the calling
//! thread while those calls run (the logger, DDS and iceoryx2 threads
//! allocate freely).

mod support;

use atmo_core::alloc_counter::count;
use atmo_io::drivers::{DriverPortsConfig, FlightPorts, monotonic_ns};
use atmo_io::mcap_log::{LoggerOptions, McapLogger, read_log};
use atmo_io::msg::{ActuatorMotors, MpcStatus, OffboardControlMode, PilotInput};
use atmo_io::ros2::{Ros2Config, Ros2Node, Ros2StartOptions, SitlNode};
use support::{drive, motors, status};

#[global_allocator]
static GLOBAL: atmo_core::alloc_counter::CountingAllocator =
    atmo_core::alloc_counter::CountingAllocator;

#[test]
fn try_log_does_not_allocate() {
    // The counter itself works.
    let (_, n) = count(|| std::hint::black_box(vec![1u8; 16]));
    assert_eq!(n, 1);

    let path = std::env::temp_dir().join(format!("atmo-io-noalloc-{}.mcap", std::process::id()));
    let options = LoggerOptions {
        queue_capacity: 64,
        ..LoggerOptions::default()
    };
    let (log, thread) = McapLogger::spawn(&path, options).unwrap();
    let status_ch = log.channel::<MpcStatus>("/atmo/status").unwrap();
    let motors_ch = log
        .channel::<ActuatorMotors>("/fmu/in/actuator_motors")
        .unwrap();
    let drive_ch = log.channel("/atmo/cmd_drive").unwrap();
    // Prebuilt records (building them is the flight stack's business).
    let statuses: Vec<MpcStatus> = (0..3000).map(status).collect();
    let commands: Vec<ActuatorMotors> = (0..3000).map(motors).collect();
    let drives: Vec<_> = (0..3000).map(drive).collect();

    // 20 s of 150 Hz ticks in bursts: some records go through, some are
    // dropped (a 64-slot queue) — both paths must be allocation-free.
    let (accepted, n) = count(|| {
        let mut accepted = 0u64;
        for k in 0..3000 {
            accepted += u64::from(log.try_log(status_ch, k as u64, &statuses[k]));
            accepted += u64::from(log.try_log(motors_ch, k as u64, &commands[k]));
            accepted += u64::from(log.try_log(drive_ch, k as u64, &drives[k]));
            let _ = log.dropped();
        }
        accepted
    });
    assert_eq!(n, 0, "try_log allocated {n} times");
    assert!(accepted > 0);
    eprintln!("accepted {accepted}, dropped {}", log.dropped());
    log.finish();
    thread.join().unwrap();
    let written = read_log(&path).unwrap();
    assert!(written.len() as u64 > accepted);
    std::fs::remove_file(&path).unwrap();
}

#[test]
fn ros2_and_driver_port_calls_do_not_allocate() {
    let options = Ros2StartOptions {
        domain_id: Some(200 + (std::process::id() % 30) as u16),
    };
    let (ros, mut inputs, node) = Ros2Node::start(&Ros2Config::default(), options).unwrap();
    let (sitl, mut sitl_inputs, sitl_node) =
        SitlNode::start(&Ros2Config::default(), options).unwrap();
    let plant_state = atmo_core::model::State::zeros();
    let pilot = PilotInput {
        throttle: 0.5,
        ..PilotInput::default()
    };
    let config = DriverPortsConfig {
        iceoryx_prefix: format!("atmona{}_", std::process::id()),
        ..DriverPortsConfig::default()
    };
    let mut ports = FlightPorts::open(&config).unwrap();
    let statuses: Vec<MpcStatus> = (0..300).map(status).collect();
    let commands: Vec<ActuatorMotors> = (0..300).map(motors).collect();
    let offboard = OffboardControlMode::default();
    // Warm up (first sends may set up lazily).
    for k in 0..10 {
        ros.try_publish_status(&statuses[k]);
        ports.send_thrust([0.1; 4]);
        ports.poll(monotonic_ns());
    }
    let mut ros_allocations = 0;
    let mut send_allocations = 0;
    let mut poll_allocations = 0;
    for k in 0..300 {
        let ((), n) = count(|| {
            ros.try_publish_status(&statuses[k]);
            ros.try_publish_motors(&commands[k]);
            ros.try_publish_offboard(&offboard);
            let _ = inputs.latest_estimate();
            let _ = inputs.latest_drive();
            let _ = inputs.latest_pilot();
            let _ = ros.counters();
            sitl.try_publish_estimate(&plant_state, 1_000_000 * (k as u64 + 1));
            sitl.try_publish_pilot(&pilot);
            let _ = sitl_inputs.latest_status();
            let _ = sitl.counters();
        });
        ros_allocations += n;
        let ((), n) = count(|| {
            assert!(ports.send_thrust([0.1, 0.2, 0.3, 0.4]));
            assert!(ports.send_tilt_velocity(0.1, false));
            assert!(ports.send_wheel_rates([1.0, 1.0]));
        });
        send_allocations += n;
        let (_, n) = count(|| {
            assert!(ports.notify_drivers());
            ports.poll(monotonic_ns())
        });
        poll_allocations += n;
        std::thread::sleep(std::time::Duration::from_micros(200));
    }
    assert_eq!(ros_allocations, 0, "the ROS 2 calls allocated");
    assert_eq!(
        poll_allocations, 0,
        "the driver-port notify and poll allocated"
    );
    assert_eq!(
        send_allocations,
        3 * 300,
        "one allocation per iceoryx2 send"
    );
    drop(ports);
    node.stop().unwrap();
    sitl_node.stop().unwrap();
    // Test hygiene: the per-prefix segments of this run.
    for dir in ["/dev/shm", "/tmp/iceoryx2/nodes", "/tmp/iceoryx2/services"] {
        for entry in std::fs::read_dir(dir).into_iter().flatten().flatten() {
            if entry
                .file_name()
                .to_string_lossy()
                .contains(&config.iceoryx_prefix)
            {
                let _ = std::fs::remove_file(entry.path());
            }
        }
    }
}
