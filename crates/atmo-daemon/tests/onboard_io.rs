//! The onboard tick's I/O (`OnboardIo::gather` + `emit`: ROS 2 inputs and
//! status, iceoryx2 driver ports, MCAP log) allocates nothing of its own
//! after start-up: a counting allocator that counts only on the control
//! thread, around ticks whose every input stream is live (a ROS 2 peer
//! sending estimates and pilot inputs, a driver endpoint sending encoder,
//! contact and heartbeats), with the outputs checked to arrive.
//!
//! The one exception is inside iceoryx2 0.10: every loaned sample
//! allocates the small reference-counted state that tracks it
//! (`ChunkMutSharedState::new`; upstream eclipse-iceoryx/iceoryx2#101, a
//! custom allocator for it, is open), freed when the sample is sent. The
//! test measures a bare send and allows exactly that for the tick's three
//! command sends, nothing more.
// Test, bench and example code: an unwrap that fails is the failure report.
#![allow(clippy::unwrap_used)]

use std::sync::Arc;
use std::time::{Duration, Instant};

use atmo_core::RobotConfig;
use atmo_core::alloc_counter::thread_allocations;
use atmo_core::model::{State, idx};
use atmo_daemon::onboard::{OnboardIo, OnboardSettings, OnboardShared};
use atmo_flight::control_loop::{TickIo, TickTiming};
use atmo_flight::flight_log::{INPUTS_TOPIC, TickChannels};
use atmo_flight::{Estimate, FlightSettings, FlightStack, PilotInput, StepInputs};
use atmo_io::drivers::{DriverEndpoint, DriverId, DriverPortsConfig};
use atmo_io::mcap_log::{LoggerOptions, McapLogger};
use atmo_io::msg::TickInputs;
use atmo_io::ros2::{Ros2Config, Ros2Node, Ros2StartOptions, SitlNode};
use atmo_mpc::MpcSettings;

#[global_allocator]
static GLOBAL: atmo_core::alloc_counter::CountingAllocator =
    atmo_core::alloc_counter::CountingAllocator;

/// Allocations of one bare iceoryx2 send through the driver ports.
fn iceoryx_allocations_per_send() -> usize {
    let drivers = DriverPortsConfig {
        iceoryx_prefix: format!("atmo_bare_send_{}_", std::process::id()),
        ..DriverPortsConfig::default()
    };
    let mut ports = atmo_io::drivers::FlightPorts::open(&drivers).unwrap();
    let mut driver = DriverEndpoint::open(&drivers, "bare_driver").unwrap();
    let mut total = 0;
    for i in 0..40 {
        let before = thread_allocations();
        ports.send_thrust([0.5; 4]);
        if i >= 20 {
            total += thread_allocations() - before;
        }
        let _ = driver.receive();
    }
    total / 20
}

#[test]
fn onboard_tick_io_allocates_nothing_of_its_own() {
    let per_send = iceoryx_allocations_per_send();
    assert!(per_send <= 1, "iceoryx2 send allocated {per_send} times");
    let domain = 170 + (std::process::id() % 30) as u16;
    let ros2 = Ros2Config {
        loopback_only: true,
        ..Ros2Config::default()
    };
    let options = Ros2StartOptions {
        domain_id: Some(domain),
    };
    let drivers = DriverPortsConfig {
        iceoryx_prefix: format!("atmo_onboard_io_{}_", std::process::id()),
        liveness_timeout_ms: 500,
        ..DriverPortsConfig::default()
    };
    let (ros_out, ros_in, ros_thread) = Ros2Node::start(&ros2, options).unwrap();
    let (peer_out, mut peer_in, peer_thread) = SitlNode::start(&ros2, options).unwrap();
    let log_path =
        std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("onboard_io_no_alloc.mcap");
    let (log, log_thread) = McapLogger::spawn(&log_path, LoggerOptions::default()).unwrap();
    let channels = TickChannels::register(&log, "/atmo/status").unwrap();
    let shared = Arc::new(OnboardShared::default());
    let settings = OnboardSettings {
        ground_z: 0.0,
        ground_timeout: Duration::from_secs(1),
        pilot_timeout: Duration::from_millis(500),
        drive_timeout: Duration::from_millis(500),
        px4_offboard: true, // exercise every output
        estimate_timeout: 0.05,
        rc: None,
        esc: None,
        arming: atmo_flight::arming::ArmingSettings::default(),
        configuration_ok: true,
    };
    let mut io = OnboardIo::open(
        &drivers,
        ros_in,
        ros_out,
        log.clone(),
        channels,
        settings,
        Arc::clone(&shared),
    )
    .unwrap();
    let mut driver = DriverEndpoint::open(&drivers, "test_driver").unwrap();

    // Real outputs of a real step to send each tick.
    let flight = FlightSettings::atmo();
    let mut stack = FlightStack::new(
        &RobotConfig::atmo(),
        MpcSettings::atmo(&flight.mpc_preset).unwrap(),
        flight,
    )
    .unwrap();
    let mut state = State::zeros();
    state[idx::Z] = -1.0;
    let outputs = stack.step(&StepInputs {
        now_ns: 0,
        estimate: Some(Estimate { stamp_ns: 0, state }),
        tilt_counts: Some(0.0),
        pilot: PilotInput::default(),
        ground_contact: false,
        ground_z: 0.0,
        ground_normal: None,
        driver_lost: false,
        pilot_lost: false,
        arming_failures: 0,
        tilt_lever: 0.0,
        rehome_tilt: false,
        autopilot_estimate: None,
        rotor_speeds: None,
    });

    let pilot = PilotInput {
        velocity: [0.1, 0.0, 0.0],
        throttle: 0.3,
        arm: true,
        offboard: true,
        mpc_enabled: true,
        ..PilotInput::default()
    };
    let start = Instant::now();
    let (warm_up, measured) = (150, 300);
    let (mut gather_allocations, mut emit_allocations) = (0, 0);
    let mut last: Option<StepInputs> = None;
    for tick in 0..warm_up + measured {
        // The peers (not the control thread): live input streams.
        let stamp = 1_000_000_000 + tick * 5_000_000;
        peer_out.try_publish_estimate(&state, stamp);
        peer_out.try_publish_pilot(&pilot);
        for d in DriverId::ALL {
            driver.publish_heartbeat(d);
        }
        driver.publish_tilt_encoder(1234);
        driver.publish_ground_contact(false);
        std::thread::sleep(Duration::from_millis(3));
        let _ = driver.receive();

        let deadline = u64::try_from(start.elapsed().as_nanos()).unwrap();
        let timing = TickTiming {
            tick,
            deadline_ns: deadline,
            ..TickTiming::default()
        };
        let before = thread_allocations();
        let inputs = io.gather(deadline).unwrap();
        let gathered = thread_allocations();
        io.emit(&inputs, &outputs, &timing);
        if tick >= warm_up {
            gather_allocations += gathered - before;
            emit_allocations += thread_allocations() - gathered;
        }
        last = Some(inputs);
    }
    let last = last.unwrap();
    // The streams really flowed through the measured ticks.
    assert!(last.estimate.is_some(), "no estimate reached the tick");
    assert!(last.pilot.arm && (last.pilot.throttle - 0.3).abs() < 1e-12);
    assert_eq!(last.tilt_counts, Some(1234.0));
    assert!(!last.driver_lost, "drivers alive");
    let commands = driver.receive();
    let mut statuses = 0;
    let wait = Instant::now();
    while statuses == 0 && wait.elapsed() < Duration::from_secs(5) {
        while peer_in.latest_status().is_some() {
            statuses += 1;
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    assert!(statuses > 0, "status reached the ROS 2 peer");
    let _ = commands;
    assert_eq!(
        gather_allocations, 0,
        "allocations gathering the inputs of {measured} ticks"
    );
    // Three command sends a tick (thrusters, tilt velocity, wheel rates).
    assert_eq!(
        emit_allocations,
        measured as usize * 3 * per_send,
        "allocations emitting {measured} ticks beyond iceoryx2's {per_send} per send"
    );
    println!(
        "onboard I/O: 0 allocations gathering, {per_send} per iceoryx2 send ({} per tick), nothing else",
        3 * per_send
    );
    drop(io);
    log.finish();
    let written = log_thread.join().unwrap();
    assert_eq!(written.dropped, 0);
    // Every tick's inputs and status (the log replays).
    assert!(written.written >= 2 * (warm_up + measured));
    let inputs = atmo_io::mcap_log::read_topic::<TickInputs>(&log_path, INPUTS_TOPIC).unwrap();
    assert_eq!(inputs.len() as u64, warm_up + measured);
    assert_eq!(inputs.last().unwrap().1.tilt_counts, 1234.0);
    ros_thread.stop().unwrap();
    peer_thread.stop().unwrap();
}
