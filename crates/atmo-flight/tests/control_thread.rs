//! The control thread ticks the flight stack on its own thread, takes the
//! newest input, never blocks on a full output channel (drops and counts),
//! and reports each tick's timing. No wall-clock assertions on speed.

use std::sync::atomic::Ordering;
use std::sync::mpsc::{channel, sync_channel};
use std::time::Duration;

use atmo_core::RobotConfig;
use atmo_core::model::{State, idx};
use atmo_flight::control_loop::ControlThread;
use atmo_flight::{Estimate, FlightSettings, FlightStack, Mode, PilotInput, StepInputs};
use atmo_mpc::MpcSettings;

#[test]
fn ticks_on_its_own_thread_and_drops_instead_of_blocking() {
    let robot = RobotConfig::atmo();
    let settings = FlightSettings::atmo();
    let stack = FlightStack::new(
        &robot,
        MpcSettings::atmo(&settings.mpc_preset).unwrap(),
        settings,
    )
    .unwrap();
    let (input_tx, input_rx) = channel();
    let (report_tx, report_rx) = sync_channel(4); // tiny on purpose: must overflow
    let thread =
        ControlThread::spawn(stack, Duration::from_millis(2), input_rx, report_tx).unwrap();
    let mut state = State::zeros();
    state[idx::Z] = -1.0;
    // Estimates stamped far in the future are refused; stamp 0 = stale. Use a
    // disarmed pilot: the stack stays Disarmed and reports every tick.
    input_tx
        .send(StepInputs {
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
        })
        .unwrap();
    // Let it run without reading: the channel fills and reports are dropped.
    while thread.counters().ticks.load(Ordering::Relaxed) < 30 {
        std::thread::sleep(Duration::from_millis(5));
    }
    let dropped = thread.counters().reports_dropped.load(Ordering::Relaxed);
    assert!(dropped > 0, "a full channel must drop, not block");
    let reports: Vec<_> = report_rx.try_iter().collect();
    assert_eq!(reports.len(), 4);
    assert!(
        reports
            .iter()
            .all(|r| r.outputs.status.mode == Mode::Disarmed)
    );
    // Deadlines are on the period grid and ticks count up.
    let later: Vec<_> = {
        std::thread::sleep(Duration::from_millis(20));
        report_rx.try_iter().collect()
    };
    assert!(!later.is_empty());
    for pair in later.windows(2) {
        let (a, b) = (pair[0].outputs.status.now_ns, pair[1].outputs.status.now_ns);
        assert_eq!((b - a) % 2_000_000, 0, "deadlines off the 2 ms grid");
        assert!(pair[1].timing.tick > pair[0].timing.tick);
    }
    let stack = thread.stop().expect("control thread panicked");
    assert_eq!(stack.mode(), Mode::Disarmed);
}
