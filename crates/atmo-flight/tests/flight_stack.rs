//! FlightStack against the atmo-core model (no plant effects): it flies,
//! morphs within its limits, and each failsafe does what it says.
// Test, bench and example code: an unwrap that fails is the failure report.
#![allow(clippy::unwrap_used)]

use atmo_core::model::{Input, State, idx};
use atmo_core::{Linkage, Model, RobotConfig};
use atmo_flight::{
    Estimate, FlightSettings, FlightStack, Mode, PilotInput, SolverStatus, StepInputs, StepOutputs,
};
use atmo_mpc::MpcSettings;

const NS: u64 = 1_000_000_000;

/// A minimal closed loop: the nominal model integrated at 1 ms, a perfect
/// estimate at the control rate, the tilt integrating its command.
#[allow(clippy::struct_excessive_bools)] // independent signals, as in StepInputs
struct Loop {
    stack: FlightStack,
    model: Model,
    linkage: Linkage,
    x: State,
    tilt: f64,
    now_ns: u64,
    pilot: PilotInput,
    period_ns: u64,
    /// When false, the estimate stops updating (a dead motion-capture link).
    estimate_alive: bool,
    last_estimate: Option<Estimate>,
    /// A wrench the controller's model does not have (CoM offset, mass error).
    disturbance: nalgebra::Vector6<f64>,
    /// The pilot's radio is lost (the input latch's verdict).
    pilot_lost: bool,
    /// Arming checks failing (the onboard monitor's verdict).
    arming_failures: u8,
    /// The radio's manual tilt lever and encoder reset switch.
    tilt_lever: f64,
    rehome_tilt: bool,
    /// The autopilot's own estimate arrives every tick (the truth).
    autopilot_alive: bool,
}

impl Loop {
    fn new(height: f64) -> Self {
        let robot = RobotConfig::atmo();
        let settings = FlightSettings::atmo();
        let stack = FlightStack::new(
            &robot,
            deterministic(MpcSettings::atmo(&settings.mpc_preset).unwrap()),
            settings,
        )
        .unwrap();
        let mut x = State::zeros();
        x[idx::Z] = -height;
        let period_ns = (stack.period() * 1e9).round() as u64;
        Self {
            stack,
            model: Model::new(&robot),
            linkage: Linkage::from_config(&robot.linkage, robot.limits.tilt_max()).unwrap(),
            x,
            tilt: 0.0,
            now_ns: NS,
            pilot: PilotInput {
                arm: true,
                offboard: true,
                mpc_enabled: true,
                ..PilotInput::default()
            },
            period_ns,
            estimate_alive: true,
            last_estimate: None,
            disturbance: nalgebra::Vector6::zeros(),
            pilot_lost: false,
            arming_failures: 0,
            tilt_lever: 0.0,
            rehome_tilt: false,
            autopilot_alive: false,
        }
    }

    fn inputs(&mut self) -> StepInputs {
        if self.estimate_alive {
            self.last_estimate = Some(Estimate {
                stamp_ns: self.now_ns,
                state: self.x,
            });
        }
        StepInputs {
            now_ns: self.now_ns,
            estimate: self.last_estimate,
            tilt_counts: Some(self.linkage.counts_from_tilt(self.tilt).unwrap()),
            pilot: self.pilot,
            ground_contact: false,
            ground_z: 0.0,
            ground_normal: None,
            driver_lost: false,
            pilot_lost: self.pilot_lost,
            arming_failures: self.arming_failures,
            tilt_lever: self.tilt_lever,
            rehome_tilt: self.rehome_tilt,
            autopilot_estimate: self.autopilot_alive.then_some(Estimate {
                stamp_ns: self.now_ns,
                state: self.x,
            }),
            rotor_speeds: None,
        }
    }

    fn tick(&mut self) -> StepOutputs {
        let inputs = self.inputs();
        let out = self.stack.step(&inputs);
        self.stack.prepare_next();
        let u = Input::from_column_slice(&out.thrust);
        let substeps = 7;
        let dt = self.period_ns as f64 * 1e-9 / f64::from(substeps);
        for _ in 0..substeps {
            self.x = self
                .model
                .at_tilt(self.tilt)
                .with_disturbance(self.disturbance)
                .rk4_step(&self.x, &u, dt);
            self.tilt =
                (self.tilt + out.tilt_velocity * dt).clamp(0.0, std::f64::consts::FRAC_PI_2);
        }
        self.now_ns += self.period_ns;
        out
    }

    fn run(&mut self, seconds: f64) -> Vec<StepOutputs> {
        let ticks = (seconds * 150.0).round() as usize;
        (0..ticks).map(|_| self.tick()).collect()
    }

    fn height(&self) -> f64 {
        -self.x[idx::Z]
    }
}

#[test]
fn armed_in_the_air_it_hovers_with_inputs_in_range() {
    let mut lp = Loop::new(1.5);
    let outs = lp.run(3.0);
    assert_eq!(outs[0].status.mode, Mode::Flight);
    for o in &outs {
        assert!(o.thrust.iter().all(|u| (0.0..=1.0).contains(u)));
        assert!(
            matches!(
                o.status.solver,
                SolverStatus::Solved | SolverStatus::Degraded
            ),
            "{:?}",
            o.status.solver
        );
    }
    assert!((lp.height() - 1.5).abs() < 0.02, "height {}", lp.height());
}

#[test]
fn descending_below_z_varphi_morphs_and_respects_the_flight_tilt_limit() {
    let mut lp = Loop::new(1.5);
    lp.run(0.5);
    lp.pilot.velocity = [0.0, 0.0, 0.2];
    let outs = lp.run(4.0);
    assert!(outs.iter().any(|o| o.status.mode == Mode::Morphing));
    let max_tilt = outs.iter().map(|o| o.status.tilt).fold(0.0, f64::max);
    assert!(
        max_tilt > 45f64.to_radians(),
        "morphing tilted only to {:.1} deg",
        max_tilt.to_degrees()
    );
    assert!(
        max_tilt <= 50f64.to_radians() + 1e-9,
        "flight limit broken: {:.3} deg",
        max_tilt.to_degrees()
    );
}

/// The first failsafe tick of `outs`, a stale estimate's (50 ms timeout
/// at 150 Hz: within 8 ticks, not before 7), and the hover trim at its tilt.
fn first_failsafe_and_trim(outs: &[StepOutputs]) -> (&StepOutputs, Input) {
    let first = outs
        .iter()
        .position(|o| o.status.mode == Mode::Failsafe)
        .expect("no failsafe");
    assert!((6..=8).contains(&first), "failsafe after {first} ticks");
    let o = &outs[first];
    let trim = Model::new(&RobotConfig::atmo())
        .at_tilt(o.status.tilt)
        .hover_trim();
    (o, trim)
}

#[test]
fn stale_estimate_triggers_failsafe_with_open_loop_trim_and_tilt_back() {
    let mut lp = Loop::new(1.5);
    lp.run(0.3);
    lp.tilt = 0.3; // as if it had morphed a little
    lp.estimate_alive = false;
    let outs = lp.run(0.2);
    let (o, trim) = first_failsafe_and_trim(&outs);
    assert!(o.status.estimate_age > 0.05);
    assert!(o.tilt_velocity < 0.0, "tilts back to 0");
    for i in 0..4 {
        assert!(
            (o.thrust[i] - 0.95 * trim[i]).abs() < 1e-12,
            "open-loop trim on rotor {}",
            i + 1
        );
    }
    // The estimate comes back: after the recovery time and tilted back, flight again.
    lp.estimate_alive = true;
    let outs = lp.run(2.0);
    assert!(outs.iter().any(|o| o.status.mode == Mode::Flight));
}

/// The estimate stops, the autopilot's does not: the failsafe flies the
/// backup controller's level descent on it (commands unlike the open-loop
/// trim, the arms to the landing tilt, the robot coming down), and the
/// estimate's return ends it as the stale estimate's failsafe ends.
#[test]
fn a_stale_estimate_with_the_autopilots_fresh_descends_level_on_it() {
    let mut lp = Loop::new(1.5);
    lp.autopilot_alive = true;
    lp.run(0.3);
    lp.estimate_alive = false;
    let outs = lp.run(2.0);
    let (o, trim) = first_failsafe_and_trim(&outs);
    assert!(
        (0..4).any(|i| (o.thrust[i] - 0.95 * trim[i]).abs() > 1e-6),
        "the open-loop trim: {:?}",
        o.thrust
    );
    let landing_tilt = FlightSettings::atmo()
        .monitor
        .rotor_out_landing_tilt_deg
        .to_radians();
    assert!(o.tilt_velocity > 0.0, "towards the landing tilt");
    assert!((lp.tilt - landing_tilt).abs() < 0.02, "{} rad", lp.tilt);
    assert!(lp.x[idx::VZ] > 0.1, "descending: vz {}", lp.x[idx::VZ]);
    assert!(
        lp.x[idx::ROLL].abs() < 0.05 && lp.x[idx::PITCH].abs() < 0.05,
        "level: {:?}",
        lp.x
    );
    lp.estimate_alive = true;
    let outs = lp.run(4.0);
    assert!(outs.iter().any(|o| o.status.mode == Mode::Flight));
}

#[test]
fn non_finite_and_out_of_range_inputs_are_rejected_counted_and_held() {
    let mut lp = Loop::new(1.5);
    lp.run(0.2);
    let good_state = lp.last_estimate.unwrap().state;
    let mut inputs = lp.inputs();
    let mut bad = good_state;
    bad[idx::VX] = f64::NAN;
    inputs.now_ns += 1000;
    inputs.estimate = Some(Estimate {
        stamp_ns: inputs.now_ns,
        state: bad,
    });
    inputs.tilt_counts = Some(-1e6);
    inputs.pilot.throttle = 3.0;
    inputs.ground_z = f64::INFINITY;
    let out = lp.stack.step(&inputs);
    let r = out.status.rejected;
    assert_eq!((r.estimate, r.tilt, r.pilot, r.ground), (1, 1, 1, 1));
    assert!(
        out.status.state.iter().all(|v| v.is_finite()),
        "held the last good estimate"
    );
    assert_eq!(out.status.state, good_state);
    assert!(
        out.thrust
            .iter()
            .all(|u| u.is_finite() && (0.0..=1.0).contains(u))
    );
    // Timestamps going backwards are refused too.
    inputs.estimate = Some(Estimate {
        stamp_ns: 1,
        state: good_state,
    });
    inputs.pilot.throttle = 0.0;
    inputs.tilt_counts = None;
    inputs.ground_z = 0.0;
    let out = lp.stack.step(&inputs);
    assert_eq!(out.status.rejected.estimate, 2);
    assert_eq!(out.status.rejected.pilot, 1);
}

#[test]
fn bad_ground_planes_are_rejected_counted_and_the_last_good_one_held() {
    let mut lp = Loop::new(1.5);
    lp.run(0.2);
    let mut inputs = lp.inputs();
    let height = |out: &StepOutputs| out.status.height;
    let before = height(&lp.stack.step(&inputs));
    let steep = 36f64.to_radians();
    let bad = [
        [f64::NAN, 0.0, -1.0],
        [0.0, 0.0, 0.0],
        [0.0, 0.0, 1.0], // into the ground
        [-steep.sin(), 0.0, -steep.cos()],
    ];
    for (k, normal) in bad.into_iter().enumerate() {
        inputs.now_ns += 1000;
        inputs.ground_z = -0.2;
        inputs.ground_normal = Some(normal);
        let out = lp.stack.step(&inputs);
        assert_eq!(out.status.rejected.ground, k as u64 + 1, "{normal:?}");
        assert_eq!(
            height(&out),
            before,
            "the last good plane holds: {normal:?}"
        );
    }
    // A 25 deg slope, any length: taken, height and all.
    let slope = 25f64.to_radians();
    inputs.now_ns += 1000;
    inputs.ground_normal = Some([-2.0 * slope.sin(), 0.0, -2.0 * slope.cos()]);
    let out = lp.stack.step(&inputs);
    assert_eq!(out.status.rejected.ground, 4);
    assert!((height(&out) - (before - 0.2)).abs() < 1e-12);
}

#[test]
fn velocity_commands_are_limited_to_one_metre_per_second() {
    let mut lp = Loop::new(1.5);
    lp.pilot.velocity = [3.0, 0.0, 0.0];
    let outs = lp.run(3.0);
    let vx_ref = outs.last().unwrap().status.reference[idx::VX];
    assert!((vx_ref - 1.0).abs() < 1e-12, "reference speed {vx_ref}");
    let vx = lp.x[idx::VX];
    assert!(vx < 1.1, "flies at {vx} m/s");
}

/// Switched off in the air, the MPC hands over to the backup controller:
/// a level descent at `failsafe.backup_descent_speed` (0.3 m/s).
#[test]
fn mpc_switch_off_in_flight_is_a_failsafe_descending_level() {
    let mut lp = Loop::new(1.5);
    lp.run(0.2);
    lp.pilot.mpc_enabled = false;
    let out = lp.tick();
    assert_eq!(out.status.mode, Mode::Failsafe);
    let outs = lp.run(3.0);
    assert!(outs.iter().all(|o| o.status.mode == Mode::Failsafe));
    let vz = lp.x[idx::VZ];
    assert!((vz - 0.3).abs() < 0.03, "descends at {vz} m/s");
    let lean = lp.x[idx::ROLL].abs().max(lp.x[idx::PITCH].abs());
    assert!(lean.to_degrees() < 1.0, "{} deg", lean.to_degrees());
    assert!(lp.height() < 1.5 - 0.5, "at {} m", lp.height());
}

#[test]
fn a_lost_radio_in_flight_is_a_failsafe_that_holds_and_ends_when_it_is_back() {
    let mut lp = Loop::new(1.5);
    lp.run(0.5);
    lp.pilot_lost = true;
    let out = lp.tick();
    assert_eq!(out.status.mode, Mode::Failsafe, "at once");
    lp.run(2.0);
    assert!((lp.height() - 1.5).abs() < 0.05, "held at {}", lp.height());
    lp.pilot_lost = false;
    let outs = lp.run(1.0);
    assert_eq!(outs.last().unwrap().status.mode, Mode::Flight, "recovered");
}

#[test]
fn a_refused_arming_stays_disarmed_and_says_why_until_the_checks_pass() {
    use atmo_flight::arming::ArmingCheck;
    let mut lp = Loop::new(1.5);
    lp.arming_failures = ArmingCheck::Radio.bit() | ArmingCheck::TiltEncoder.bit();
    let outs = lp.run(0.1);
    for o in &outs {
        assert_eq!(o.status.mode, Mode::Disarmed);
        assert_eq!(o.thrust, [0.0; 4]);
        assert_eq!(o.status.transition, Some("arming refused: radio lost"));
    }
    lp.arming_failures = ArmingCheck::TiltEncoder.bit();
    assert_eq!(
        lp.tick().status.transition,
        Some("arming refused: tilt encoder disagrees or is silent")
    );
    lp.pilot.offboard = false;
    assert_eq!(lp.tick().status.transition, None, "not asked to arm");
    lp.pilot.offboard = true;
    lp.arming_failures = 0;
    let armed = lp.tick();
    assert_eq!(armed.status.mode, Mode::Flight);
    assert_eq!(armed.status.transition, Some("armed in the air"));
}

#[test]
fn the_kill_switch_disarms_in_one_tick_with_the_thrust_cut() {
    let mut lp = Loop::new(1.5);
    lp.run(0.5);
    lp.pilot.arm = false; // what the radio's kill switch makes of the pilot input
    let out = lp.tick();
    assert_eq!(out.status.mode, Mode::Disarmed);
    assert_eq!(out.thrust, [0.0; 4]);
    assert_eq!(out.tilt_velocity, 0.0);
}

#[test]
fn transition_limit_is_enforced_whatever_is_commanded() {
    // Start morphing at 0.5 m: the stack goes to transition and tilts at most to 70 deg.
    let mut lp = Loop::new(0.6);
    lp.tilt = 55f64.to_radians(); // already past the flight limit when morphing starts
    lp.pilot.velocity = [0.0, 0.0, 0.3];
    let outs = lp.run(3.0);
    let morph = outs
        .iter()
        .find(|o| o.status.mode == Mode::Morphing)
        .expect("morphing");
    assert!(
        morph.tilt_velocity < 0.0,
        "above the 50 deg flight limit it must tilt back"
    );
    for o in &outs {
        assert!(o.status.tilt <= 70f64.to_radians() + 1e-9);
        let next = o.status.tilt + o.tilt_velocity / 150.0;
        if o.status.tilt <= o.status.tilt_limit {
            assert!(
                next <= o.status.tilt_limit + 1e-9,
                "would overshoot the {:?} limit",
                o.status.mode
            );
        }
    }
}

#[test]
fn the_observer_removes_the_offset_of_an_unmodelled_torque_and_weight() {
    // A 5 mm CoM offset (0.27 N m pitch torque) and 3 % more weight: without
    // integral action the MPC trades the attitude error against collective
    // thrust and sinks (0.9 m/s instead of 0.3 against the plant).
    let mut lp = Loop::new(2.5);
    lp.disturbance = nalgebra::Vector6::new(0.0, 0.0, 0.03 * 53.8, 0.0, -0.27, 0.0);
    lp.pilot.velocity = [0.0, 0.0, 0.3];
    let outs = lp.run(3.0);
    assert!(outs.iter().all(|o| o.status.mode == Mode::Flight));
    let vz = lp.x[idx::VZ];
    assert!((vz - 0.3).abs() < 0.05, "descends at {vz:.3} m/s");
    assert!(
        lp.x[idx::PITCH].abs() < 1f64.to_radians(),
        "pitch {:.2} deg",
        lp.x[idx::PITCH].to_degrees()
    );
    let d = outs.last().unwrap().status.disturbance;
    assert!(
        (d[4] + 0.27).abs() < 0.05 && (d[2] - 1.61).abs() < 0.3,
        "learned {d:?}"
    );
}

/// The MPC's wall-clock time limit would make these results depend on how
/// loaded the test machine is (a solve cut short is a fallback tick); the
/// iteration cap still bounds every solve.
fn deterministic(mut settings: MpcSettings) -> MpcSettings {
    settings.solver.time_limit = 10.0;
    settings
}

#[test]
fn disarmed_the_tilt_lever_moves_the_arms_and_armed_it_does_nothing() {
    let mut lp = Loop::new(0.0);
    lp.pilot.arm = false;
    lp.tilt_lever = 0.5;
    lp.rehome_tilt = true;
    let outs = lp.run(1.0);
    let rate = RobotConfig::atmo().limits.tilt_rate_max;
    for o in &outs {
        assert_eq!(o.status.mode, Mode::Disarmed);
        assert!(
            o.rehome_tilt,
            "the reset switch is passed on while disarmed"
        );
    }
    assert!((outs[10].tilt_velocity - 0.5 * rate).abs() < 1e-12);
    assert!(
        (lp.tilt - 0.5 * rate).abs() < 0.05 * rate,
        "one second at half speed: {} rad",
        lp.tilt
    );
    // Lever back to rest: the arms stop where they are.
    lp.tilt_lever = 0.0;
    assert_eq!(lp.tick().tilt_velocity, 0.0);
    // Out of range: rejected and counted, the arms stop.
    lp.tilt_lever = 1.5;
    let o = lp.tick();
    assert_eq!(o.tilt_velocity, 0.0);
    assert!(o.status.rejected.pilot >= 1);

    // Armed in the air, the lever and the reset switch are not the pilot's
    // to use: the flight modes own the tilt.
    let mut lp = Loop::new(1.5);
    lp.tilt_lever = 1.0;
    lp.rehome_tilt = true;
    for o in lp.run(0.5) {
        assert_eq!(o.status.mode, Mode::Flight);
        assert!(o.tilt_velocity <= 0.0, "no lever in flight");
        assert!(!o.rehome_tilt);
    }
}
