//! FlightStack::step with the MPC tick (feedback) and prepare_next
//! (preparation) allocate nothing of their own after start-up, alone and in
//! the shared tick body (`ControlLoop::tick` with the input latch): a
//! counting global allocator around the ticks of a flight, morphing and
//! transition.
//! The one exception is inside Clarabel: its profiling timers rebuild a small
//! hash table at every solve (one allocation, freed at the next solve); the
//! test measures a bare solve and allows exactly that, nothing more.
// Test, bench and example code: an unwrap that fails is the failure report.
#![allow(clippy::unwrap_used)]

use atmo_core::alloc_counter::thread_allocations;
use atmo_core::model::{Input, State, idx};
use atmo_core::{Linkage, Model, RobotConfig};
use atmo_flight::control_loop::{Clock, ControlLoop, TickIo, TickTiming};
use atmo_flight::inputs::{InputLatch, InputSettings};
use atmo_flight::{
    Estimate, FlightSettings, FlightStack, Mode, PilotInput, SolverStatus, StepInputs, StepOutputs,
};
use atmo_mpc::MpcSettings;
use atmo_mpc::settings::GroundEffectSource;

#[global_allocator]
static GLOBAL: atmo_core::alloc_counter::CountingAllocator =
    atmo_core::alloc_counter::CountingAllocator;

/// Allocations of one bare Clarabel solve of the MPC's QP (nothing of ours around it).
fn clarabel_allocations_per_solve() -> usize {
    let mut mpc = atmo_mpc::Mpc::new(
        Model::new(&RobotConfig::atmo()),
        deterministic(MpcSettings::atmo("fig5").unwrap()),
    )
    .unwrap();
    let mut x = State::zeros();
    x[idx::Z] = -1.0;
    mpc.reset(&x).unwrap();
    for _ in 0..5 {
        mpc.tick(&x).unwrap();
    }
    let before = thread_allocations();
    for _ in 0..10 {
        mpc.resolve_loaded_qp();
    }
    (thread_allocations() - before) / 10
}

#[test]
fn flight_stack_step_does_not_allocate_after_start_up() {
    flight_stack_allocations(GroundEffectSource::None, None);
}

/// The same with the ground effect in the MPC's model (its surface is read
/// at start-up; each preparation evaluates it 16 times per stage).
#[test]
fn flight_stack_step_with_ground_effect_model_does_not_allocate() {
    flight_stack_allocations(GroundEffectSource::PlantDefault, None);
}

/// The same on a 25 deg slope (the ground plane's normal checked every
/// tick, the clearances measured against the plane).
#[test]
fn flight_stack_step_on_a_sloped_ground_plane_does_not_allocate() {
    let s = 25f64.to_radians();
    flight_stack_allocations(
        GroundEffectSource::PlantDefault,
        Some([-s.sin(), 0.0, -s.cos()]),
    );
}

fn flight_stack_allocations(ground_effect: GroundEffectSource, ground_normal: Option<[f64; 3]>) {
    let robot = RobotConfig::atmo();
    let settings = FlightSettings::atmo();
    let mut mpc = deterministic(MpcSettings::atmo(&settings.mpc_preset).unwrap());
    mpc.model.ground_effect = ground_effect;
    let planned_tilt = mpc.tilt_plan.is_some_and(|t| t.enabled);
    let mut stack = FlightStack::new(&robot, mpc, settings).unwrap();
    let model = Model::new(&robot);
    let linkage = Linkage::from_config(&robot.linkage, robot.limits.tilt_max()).unwrap();
    let mut x = State::zeros();
    x[idx::Z] = -1.0;
    let mut tilt = 0.0;
    let pilot = PilotInput {
        arm: true,
        offboard: true,
        mpc_enabled: true,
        velocity: [0.2, 0.0, 0.3],
        ..PilotInput::default()
    };
    let period_ns = 6_666_667;
    let mut modes = [false; 8];
    let clarabel_per_solve = clarabel_allocations_per_solve();
    let mut step_allocations = 0;
    let mut allowed = 0;
    let mut flared = false;
    for tick in 0..1500u64 {
        let now_ns = 1_000_000_000 + tick * period_ns;
        let inputs = StepInputs {
            now_ns,
            estimate: Some(Estimate {
                stamp_ns: now_ns,
                state: x,
            }),
            tilt_counts: Some(linkage.counts_from_tilt(tilt).unwrap()),
            pilot,
            ground_contact: false,
            ground_z: 0.0,
            ground_normal,
            driver_lost: false,
            pilot_lost: false,
            arming_failures: 0,
            tilt_lever: 0.0,
            rehome_tilt: false,
            autopilot_estimate: None,
            // Rotor 2's ESC reports it stopped from tick 1000: the
            // detection and the descent on three allocate nothing either.
            rotor_speeds: Some(if tick < 1000 {
                [0.7; 4]
            } else {
                [0.7, 0.0, 0.7, 0.7]
            }),
        };
        // The first ticks warm the MPC up (start-up); count from tick 20 on.
        let before = thread_allocations();
        let out = stack.step(&inputs);
        let mid = thread_allocations();
        stack.prepare_next();
        let after = thread_allocations();
        if tick >= 20 {
            // The preparation runs one Clarabel solve (at the predicted state,
            // seeding the MPC's homotopy feedback): only its own block may appear.
            assert!(
                after - mid <= clarabel_per_solve,
                "prepare_next allocated {} times at tick {tick}",
                after - mid
            );
            // Only the Clarabel solve inside the feedback phase may allocate,
            // and no more than a bare solve does (measured above).
            let solves = out.status.qp_solves as usize;
            assert_eq!(
                out.status.qp_solves > 0,
                out.status.solver != SolverStatus::Idle
            );
            step_allocations += mid - before;
            allowed += solves * clarabel_per_solve;
        }
        modes[out.status.mode.code() as usize] = true;
        let u = Input::from_column_slice(&out.thrust);
        x = model
            .at_tilt(tilt)
            .rk4_step(&x, &u, period_ns as f64 * 1e-9);
        tilt = (tilt + out.tilt_velocity * period_ns as f64 * 1e-9).clamp(0.0, 1.5);
        flared |= stack.flare_committed();
        // Down to the wheels' touchdown height at 70 deg (no ground here):
        // through the flare's approach, its predictions and its tilt-up.
        if -x[idx::Z] < 0.17 {
            break;
        }
    }
    assert!(
        modes[Mode::Flight.code() as usize] && modes[Mode::Morphing.code() as usize],
        "{modes:?}"
    );
    assert!(
        modes[Mode::Transition.code() as usize],
        "the descent must reach the transition: {modes:?}"
    );
    assert_eq!(
        flared, planned_tilt,
        "a planned-tilt transition must reach the flare's tilt-up"
    );
    assert!(
        step_allocations <= allowed,
        "FlightStack::step allocated {step_allocations} times; Clarabel's solves account for at most {allowed}"
    );
    // What the report says: Clarabel's profiling timers rebuild one small
    // hash table per solve; everything of ours is allocation-free.
    assert!(
        clarabel_per_solve <= 1,
        "Clarabel allocates {clarabel_per_solve} times per solve"
    );
    eprintln!(
        "Clarabel allocations per solve: {clarabel_per_solve}; step allocations {step_allocations}"
    );
}

/// The MPC's wall-clock time limit would make these results depend on how
/// loaded the test machine is (a solve cut short is a fallback tick); the
/// iteration cap still bounds every solve.
fn deterministic(mut settings: MpcSettings) -> MpcSettings {
    settings.solver.time_limit = 10.0;
    settings
}

/// Time moves only when the test says so.
struct StepClock(std::cell::Cell<u64>);

impl Clock for StepClock {
    fn now_ns(&self) -> u64 {
        self.0.get()
    }
    fn sleep_until(&self, deadline_ns: u64) {
        self.0.set(self.0.get().max(deadline_ns));
    }
}

/// A `TickIo` over the shared input assembly, fed from a model of the robot.
struct ModelIo {
    latch: InputLatch,
    thrust: [f64; 4],
    tilt_velocity: f64,
    mode: Mode,
    solves: u32,
}

impl TickIo for ModelIo {
    fn gather(&mut self, deadline_ns: u64) -> Option<StepInputs> {
        Some(self.latch.assemble(deadline_ns).inputs)
    }
    fn emit(&mut self, _inputs: &StepInputs, outputs: &StepOutputs, _timing: &TickTiming) {
        self.thrust = outputs.thrust;
        self.tilt_velocity = outputs.tilt_velocity;
        self.mode = outputs.status.mode;
        self.solves = outputs.status.qp_solves;
        self.latch.mode(outputs.status.mode);
    }
}

/// The shared tick body (`ControlLoop::tick`: scheduler, gather through the
/// input latch, step, emit, prepare_next) allocates nothing beyond
/// Clarabel's one allocation per solve.
#[test]
fn control_loop_tick_does_not_allocate_after_start_up() {
    let robot = RobotConfig::atmo();
    let settings = FlightSettings::atmo();
    let estimate_timeout = settings.failsafe.estimate_timeout;
    let mut stack = FlightStack::new(
        &robot,
        deterministic(MpcSettings::atmo(&settings.mpc_preset).unwrap()),
        settings,
    )
    .unwrap();
    let model = Model::new(&robot);
    let linkage = Linkage::from_config(&robot.linkage, robot.limits.tilt_max()).unwrap();
    let period_ns = 6_666_667;
    let clock = StepClock(std::cell::Cell::new(1_000_000_000));
    let mut control = ControlLoop::new(std::time::Duration::from_nanos(period_ns), clock.now_ns());
    let mut io = ModelIo {
        latch: InputLatch::new(InputSettings::defaults(0.0, estimate_timeout)),
        thrust: [0.0; 4],
        tilt_velocity: 0.0,
        mode: Mode::Disarmed,
        solves: 0,
    };
    let pilot = PilotInput {
        arm: true,
        offboard: true,
        mpc_enabled: true,
        velocity: [0.2, 0.0, 0.3],
        ..PilotInput::default()
    };
    let mut x = State::zeros();
    x[idx::Z] = -1.0;
    let mut tilt = 0.0;
    let clarabel_per_solve = clarabel_allocations_per_solve();
    let (mut allocations, mut allowed) = (0, 0);
    let mut modes = [false; 8];
    let mut flared = false;
    for tick in 0..1500u64 {
        let now = control.next_deadline_ns();
        io.latch.estimate(Estimate {
            stamp_ns: now,
            state: x,
        });
        io.latch.pilot(pilot, now);
        io.latch
            .tilt_counts(linkage.counts_from_tilt(tilt).unwrap());
        let before = thread_allocations();
        assert!(control.tick(&clock, &mut stack, &mut io));
        if tick >= 20 {
            allocations += thread_allocations() - before;
            // The feedback's solves (status.qp_solves) and the preparation's
            // one Clarabel solve (prepare_next, checked alone to be exactly
            // that in the test above).
            allowed += (io.solves as usize + 1) * clarabel_per_solve;
        }
        modes[io.mode.code() as usize] = true;
        let u = Input::from_column_slice(&io.thrust);
        x = model
            .at_tilt(tilt)
            .rk4_step(&x, &u, period_ns as f64 * 1e-9);
        tilt = (tilt + io.tilt_velocity * period_ns as f64 * 1e-9).clamp(0.0, 1.5);
        flared |= stack.flare_committed();
        // Down to the wheels' touchdown height at 70 deg (no ground here):
        // through the flare's approach, its predictions and its tilt-up.
        if -x[idx::Z] < 0.17 {
            break;
        }
    }
    assert!(
        modes[Mode::Morphing.code() as usize] && modes[Mode::Transition.code() as usize],
        "{modes:?}"
    );
    assert!(flared, "the transition must reach the flare's tilt-up");
    assert_eq!(control.previous().overruns_total, 0);
    assert!(
        allocations <= allowed,
        "ControlLoop::tick allocated {allocations} times; Clarabel's solves account for at most {allowed}"
    );
}

/// Logging a tick (its `TickInputs` and `MpcStatus` records, as
/// `OnboardIo::emit` and the simulator do) allocates nothing on the
/// control thread. Counted on this thread only: the logger's writer thread
/// encodes and compresses (and allocates) off the control thread.
#[test]
fn logging_a_tick_does_not_allocate() {
    use atmo_flight::flight_log::{INPUTS_TOPIC, TickChannels};
    use atmo_io::mcap_log::{LoggerOptions, McapLogger, read_topic};
    use atmo_io::msg::TickInputs;
    let dir = std::path::PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("no_alloc_log");
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("no_alloc_tick_log.mcap");
    let ticks = 2000u64;
    let options = LoggerOptions {
        queue_capacity: 2 * ticks as usize + 16,
        ..LoggerOptions::default()
    };
    let (log, thread) = McapLogger::spawn(&path, options).unwrap();
    let channels = TickChannels::register(&log, "/atmo/status").unwrap();
    let flight = FlightSettings::atmo();
    let mut stack = FlightStack::new(
        &RobotConfig::atmo(),
        deterministic(MpcSettings::atmo(&flight.mpc_preset).unwrap()),
        flight,
    )
    .unwrap();
    let mut state = State::zeros();
    state[idx::Z] = -1.0;
    let mut inputs = StepInputs {
        now_ns: 1_000_000,
        estimate: Some(Estimate { stamp_ns: 0, state }),
        tilt_counts: Some(12.0),
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
    };
    let outputs = stack.step(&inputs);
    let timing = TickTiming::default();
    let before = thread_allocations();
    for tick in 0..ticks {
        inputs.now_ns += 6_666_666;
        let status = atmo_flight::telemetry::status_message(tick, &inputs, &outputs, &timing);
        channels.log_tick(&log, tick, &inputs, &outputs, &status);
    }
    let allocations = thread_allocations() - before;
    log.finish();
    let written = thread.join().unwrap();
    assert_eq!(written.dropped, 0);
    let logged = read_topic::<TickInputs>(&path, INPUTS_TOPIC).unwrap();
    assert_eq!(logged.len() as u64, ticks, "every tick's inputs in the log");
    assert_eq!(logged[7].1.clock_ns, 1_000_000 + 8 * 6_666_666);
    assert_eq!(
        allocations, 0,
        "allocations logging {ticks} ticks on the control thread"
    );
}
