//! `FlightStack`: one pure, deterministic `step` per control tick.
//!
//! The clock is an input (`now_ns`), so the same code runs in real time
//! onboard, faster than real time in simulation, and identically when
//! replayed. Bad inputs are rejected, counted and the last good value held;
//! `step` never panics and never allocates after `new` (tested).
//!
//! RTI split: [`FlightStack::step`] runs the MPC feedback phase (estimate in,
//! command out); [`FlightStack::prepare_next`] runs the preparation phase for
//! the next tick (reference, tilt sequence, alpha, linearization) and belongs
//! after the outputs have been sent.

use atmo_core::control::{DiffDrive, blending_alpha};
use atmo_core::ground_plane::{LEVEL_NORMAL, unit_ground_normal};
use atmo_core::model::{Input, State, TiltedBody, idx, level_cosine};
use atmo_core::{GroundPlane, Linkage, Model, RobotConfig};
use atmo_mpc::{AlphaSchedule, Mpc, MpcSettings, Outcome, SolverCuts, TiltPlan};
use nalgebra::Vector3;

use crate::actuator_monitor::{ActuatorMonitor, Detected};
use crate::arming::ArmingCheck;
use crate::backup_control::LevelDescent;
use crate::error::{FlightError, Result};
use crate::flare::{Flare, FlareSettings, Touchdown};
use crate::ground_model::{Surface, ground_surface};
use crate::modes::{Conditions, Mode, Thresholds, next_mode};
use crate::observer::{DisturbanceObserver, ObserverSettings};
use crate::rotor_estimate::RotorEstimate;
use crate::settings::FlightSettings;
use failsafe::FailsafeControl;

mod drive;
mod failsafe;
mod landing;
mod monitoring;
mod tilt;

pub use crate::step_io::{
    Estimate, PilotInput, RejectCounters, SolverStatus, Status, StepInputs, StepOutputs,
};

/// Morphing hands over to the transition below z* once the tilt is within
/// this of the flight limit, deg (a descent from z_varphi at the pilot's
/// 0.3 m/s reaches the limit itself before z*).
const TRANSITION_TILT_MARGIN_DEG: f64 = 5.0;

/// SQP iterations spent re-planning on a mode change (a one-off cost of a
/// few feedback times).
const REPLAN_ITERATIONS: usize = 4;

/// The flight stack.
pub struct FlightStack {
    settings: FlightSettings,
    thresholds: Thresholds,
    model: Model,
    linkage: Linkage,
    drive: DiffDrive,
    mpc: Mpc,
    alpha: AlphaSchedule,
    /// Per-stage reference buffer (N + 1), allocated once.
    reference: Vec<State>,
    stage_dt: f64,
    tilt_rate_max: f64,
    flight_tilt_max: f64,
    transition_tilt_max: f64,
    tilt_max: f64,
    mode: Mode,
    mode_since_ns: u64,
    /// When the ground contact began, while it lasts (ns).
    contact_since_ns: Option<u64>,
    mpc_warm: bool,
    mpc_failures_total: u64,
    last_estimate: Option<Estimate>,
    /// The autopilot's own estimate, last good one
    /// (`StepInputs::autopilot_estimate`).
    last_autopilot_estimate: Option<Estimate>,
    last_tilt: f64,
    last_pilot: PilotInput,
    /// The pilot's manual tilt lever, -1..1 (0 if the last one was bad).
    tilt_lever: f64,
    last_ground_z: f64,
    /// Unit normal of the last good ground plane (NED, out of the ground).
    last_ground_normal: Vector3<f64>,
    last_thrust: Input,
    touchdown_thrust: Input,
    /// Moving position reference (see `fill_reference`).
    carrot: Vector3<f64>,
    hold_yaw: f64,
    last_preparation_time: f64,
    rejected: RejectCounters,
    tilt_command: f64,
    observer: DisturbanceObserver,
    /// Tilt limit of the transition so far (it only grows), rad.
    transition_limit: f64,
    /// The mode changed: re-plan with a few SQP iterations before the next feedback.
    replan: bool,
    /// In the transition the MPC plans the tilt (`[tilt_plan] enabled`).
    plans_tilt: bool,
    wheel_radius: f64,
    /// The tilt rate of the MPC's last plan (when it plans the tilt).
    mpc_tilt_rate: Option<f64>,
    /// The flare ending a planned-tilt transition (`None`: no flare).
    flare_settings: Option<FlareSettings>,
    flare: Flare,
    /// The touchdown of a tilt-up begun at the last preparation's state.
    flare_prediction: Option<Touchdown>,
    /// The MPC's thrust-gain surface (shared with it), for the prediction.
    ground_effect: Option<Surface>,
    /// The body at the transition's tilt limit (the flare's clearance),
    /// frozen once at start-up.
    limit_body: TiltedBody,
    /// The observer's vertical body force learned aloft: its last value
    /// before the transition where the model's ground effect was below 1 %
    /// (the flare's prediction takes it as a floor, `flare` module docs).
    aloft_force: Option<f64>,
    /// The robot file's motor time constant, s.
    motor_time_constant: f64,
    /// What the actuators are seen to do (`actuator_monitor`).
    monitor: ActuatorMonitor,
    /// The encoder's last good tilt, rad (`last_tilt` is the tilt flown on:
    /// the encoder's, or dead-reckoned while it is stuck).
    encoder_tilt: f64,
    /// The tilt velocity the last tick commanded, rad/s.
    tilt_sent: f64,
    /// The failed rotor and what it delivers (`last_thrust` and the MPC's
    /// plan are in delivered thrust; the commands sent are over it).
    rotor: RotorEstimate,
    /// This tick's ESC speeds, if valid (`StepInputs::rotor_speeds`).
    rotor_speeds: Option<[f64; 4]>,
    /// The backup controller's memory (`backup_control`).
    backup: LevelDescent,
    /// Who flies the thrusters in failsafe this tick.
    failsafe_control: FailsafeControl,
}

impl FlightStack {
    /// Builds the stack and its MPC (all allocations happen here); the
    /// MPC's ground-effect surface is loaded as its settings name it.
    pub fn new(
        robot: &RobotConfig,
        mpc_settings: MpcSettings,
        settings: FlightSettings,
    ) -> Result<Self> {
        let surface = ground_surface(&mpc_settings.model.ground_effect)?;
        Self::with_ground_surface(robot, mpc_settings, settings, surface)
    }

    /// [`Self::new`] with the MPC's ground-effect surface given (e.g. parsed
    /// from the text a flight log stores).
    pub fn with_ground_surface(
        robot: &RobotConfig,
        mpc_settings: MpcSettings,
        settings: FlightSettings,
        surface: Option<Surface>,
    ) -> Result<Self> {
        let model = Model::new(robot);
        let linkage = Linkage::from_config(&robot.linkage, robot.limits.tilt_max())?;
        let plans_tilt = mpc_settings.tilt_plan.is_some_and(|t| t.enabled);
        let mut mpc = Mpc::new(model.clone(), mpc_settings)?;
        let mut observer = DisturbanceObserver::new(ObserverSettings {
            force_gain: settings.observer.force_gain,
            torque_gain: settings.observer.torque_gain,
            max_force: settings.observer.max_force,
            max_torque: settings.observer.max_torque,
            min_interval: settings.observer.min_interval,
        });
        // The observer learns what the MPC's model leaves out: with its surface.
        observer.set_ground_effect(surface.clone());
        mpc.set_ground_effect(surface.clone());
        let steps = mpc.steps();
        let stage_dt = mpc.stage_dt();
        let alpha = AlphaSchedule::new(mpc.settings().cost.alpha_refresh_ticks);
        let lim = &robot.limits;
        if settings.modes.takeoff_max_tilt_deg > lim.tilt_flight_max_deg {
            return Err(FlightError::Setup(format!(
                "modes.takeoff_max_tilt_deg ({}) must not exceed the robot's limits.tilt_flight_max_deg ({})",
                settings.modes.takeoff_max_tilt_deg, lim.tilt_flight_max_deg
            )));
        }
        if settings.modes.transition_full_tilt_height >= lim.transition_height {
            return Err(FlightError::Setup(format!(
                "modes.transition_full_tilt_height ({} m) must be below the robot's limits.transition_height ({} m)",
                settings.modes.transition_full_tilt_height, lim.transition_height
            )));
        }
        let thresholds = Thresholds {
            takeoff_throttle: settings.modes.takeoff_throttle,
            takeoff_height: settings.modes.takeoff_height,
            morph_height: lim.morph_height,
            morph_hysteresis: settings.modes.morph_hysteresis,
            transition_height: lim.transition_height,
            transition_min_tilt: lim.tilt_flight_max() - TRANSITION_TILT_MARGIN_DEG.to_radians(),
            thrust_cut_time: settings.modes.thrust_cut_time,
            touchdown_max_tip: settings.modes.touchdown_max_tip_deg.to_radians(),
            touchdown_level_timeout: settings.modes.touchdown_level_timeout,
            failsafe_recovery_time: settings.failsafe.recovery_time,
            failsafe_recovery_tilt: settings.failsafe.recovery_tilt_deg.to_radians(),
        };
        Ok(Self {
            thresholds,
            linkage,
            drive: DiffDrive::new(&robot.wheels),
            mpc,
            alpha,
            reference: vec![State::zeros(); steps + 1],
            stage_dt,
            tilt_rate_max: lim.tilt_rate_max,
            flight_tilt_max: lim.tilt_flight_max(),
            transition_tilt_max: lim.tilt_transition_max(),
            tilt_max: lim.tilt_max(),
            mode: Mode::Disarmed,
            mode_since_ns: 0,
            contact_since_ns: None,
            mpc_warm: false,
            mpc_failures_total: 0,
            last_estimate: None,
            last_autopilot_estimate: None,
            last_tilt: 0.0,
            last_pilot: PilotInput::default(),
            tilt_lever: 0.0,
            last_ground_z: 0.0,
            last_ground_normal: Vector3::from(LEVEL_NORMAL),
            last_thrust: Input::zeros(),
            touchdown_thrust: Input::zeros(),
            carrot: Vector3::zeros(),
            hold_yaw: 0.0,
            last_preparation_time: 0.0,
            rejected: RejectCounters::default(),
            tilt_command: 0.0,
            observer,
            replan: false,
            plans_tilt,
            wheel_radius: robot.wheels.radius,
            mpc_tilt_rate: None,
            flare_settings: plans_tilt.then_some(settings.flare),
            flare: Flare::default(),
            flare_prediction: None,
            transition_limit: 0.0,
            ground_effect: surface,
            limit_body: model.at_tilt(lim.tilt_transition_max()),
            aloft_force: None,
            motor_time_constant: robot.rotor.time_constant,
            monitor: ActuatorMonitor::new(
                settings.monitor,
                settings.observer.max_torque,
                lim.tilt_max(),
                robot.rotor.time_constant,
            ),
            rotor_speeds: None,
            encoder_tilt: 0.0,
            tilt_sent: 0.0,
            rotor: RotorEstimate::default(),
            backup: LevelDescent::default(),
            failsafe_control: FailsafeControl::OpenLoop,
            model,
            settings,
        })
    }

    pub fn mode(&self) -> Mode {
        self.mode
    }

    pub fn settings(&self) -> &FlightSettings {
        &self.settings
    }

    pub fn mpc(&self) -> &Mpc {
        &self.mpc
    }

    pub fn rejected(&self) -> RejectCounters {
        self.rejected
    }

    /// Control period, s.
    pub fn period(&self) -> f64 {
        self.settings.control_loop.period()
    }

    /// Accepts or rejects this tick's raw inputs; keeps the last good values.
    fn ingest(&mut self, inputs: &StepInputs) {
        for (given, last) in [
            (inputs.estimate, &mut self.last_estimate),
            (inputs.autopilot_estimate, &mut self.last_autopilot_estimate),
        ] {
            if let Some(est) = given
                && !accept_estimate(last, est, inputs.now_ns)
            {
                self.rejected.estimate += 1;
            }
        }
        if let Some(counts) = inputs.tilt_counts {
            match self.linkage.tilt_from_counts(counts) {
                Ok(tilt) => self.encoder_tilt = tilt,
                Err(_) => self.rejected.tilt += 1,
            }
        }
        let p = inputs.pilot;
        let pilot_ok = p.velocity.iter().all(|v| v.is_finite())
            && p.yaw_rate.is_finite()
            && (0.0..=1.0).contains(&p.throttle);
        if pilot_ok {
            let mut accepted = p;
            let v = Vector3::from(p.velocity);
            let limit = self.settings.pilot.max_speed;
            if v.norm() > limit {
                accepted.velocity = (v * (limit / v.norm())).into();
            }
            let yaw_limit = self.settings.pilot.max_yaw_rate;
            accepted.yaw_rate = p.yaw_rate.clamp(-yaw_limit, yaw_limit);
            self.last_pilot = accepted;
        } else {
            self.rejected.pilot += 1;
        }
        self.tilt_lever = if (-1.0..=1.0).contains(&inputs.tilt_lever) {
            inputs.tilt_lever
        } else {
            self.rejected.pilot += 1;
            0.0
        };
        // The ground plane is taken or rejected whole: a finite height and,
        // if there is one, a normal that `unit_ground_normal` accepts.
        let normal = inputs
            .ground_normal
            .map_or(Ok(Vector3::from(LEVEL_NORMAL)), |n| {
                unit_ground_normal(Vector3::from(n))
            });
        match normal {
            Ok(normal) if inputs.ground_z.is_finite() => {
                self.last_ground_z = inputs.ground_z;
                self.last_ground_normal = normal;
            }
            _ => self.rejected.ground += 1,
        }
    }

    /// One control tick: validate inputs, run the mode machine, command
    /// thrusters (MPC feedback phase), tilt and wheels.
    pub fn step(&mut self, inputs: &StepInputs) -> StepOutputs {
        self.ingest(inputs);
        let now = inputs.now_ns;
        let pilot = self.last_pilot;
        let estimate_age = self.last_estimate.map_or(f64::INFINITY, |e| e.age(now));
        let estimate_fresh = estimate_age <= self.settings.failsafe.estimate_timeout;
        let state = self.last_estimate.map_or(State::zeros(), |e| e.state);
        let height = self.last_ground_z - state[idx::Z];
        let detected = self.monitor_actuators(
            now,
            pilot.arm && pilot.offboard,
            estimate_fresh,
            &state,
            height,
            inputs.rotor_speeds,
        );
        self.track_rotor(detected);
        self.last_tilt = self.monitor.tilt(self.encoder_tilt);
        let tilt = self.last_tilt;
        let mpc_failed_ticks = self.mpc.failed_ticks();
        let grounded = inputs.ground_contact || detected.has(Detected::CONTACT_INFERRED);
        self.contact_since_ns = grounded.then(|| self.contact_since_ns.unwrap_or(now));
        let conditions = Conditions {
            armed: pilot.arm && pilot.offboard,
            arming_ok: inputs.arming_failures == 0,
            grounded,
            height,
            throttle: pilot.throttle,
            descent_commanded: pilot.velocity[2] > self.settings.pilot.descent_threshold,
            estimate_fresh,
            mpc_failed: mpc_failed_ticks > self.mpc.settings().failure.grace_ticks
                || (self.mode.is_airborne_mode() && !pilot.mpc_enabled),
            driver_lost: inputs.driver_lost,
            pilot_lost: inputs.pilot_lost,
            tilt_unknown: detected.tilt_unknown(),
            rotor_failed: detected.rotor_failed(),
            rotor_out: self.rotor_out(),
            body_tip: level_cosine(&state).acos(),
            time_grounded: now.saturating_sub(self.contact_since_ns.unwrap_or(now)) as f64 * 1e-9,
            tilt,
            time_in_mode: now.saturating_sub(self.mode_since_ns) as f64 * 1e-9,
        };
        let (mode, mut transition) = next_mode(self.mode, &conditions, &self.thresholds_now());
        if mode == Mode::Disarmed && conditions.armed && !conditions.rotor_failed {
            // Why the switches did not arm it.
            transition =
                ArmingCheck::first_failed(inputs.arming_failures).map(ArmingCheck::refusal);
        }
        if mode != self.mode {
            self.enter(mode, now, &state);
        }
        let autopilot_fresh = self
            .last_autopilot_estimate
            .is_some_and(|e| e.age(now) <= self.settings.failsafe.estimate_timeout);
        self.failsafe_control =
            self.failsafe_control(estimate_fresh, autopilot_fresh, conditions.mpc_failed);

        if mode == Mode::Transition {
            self.transition_limit = self.transition_limit.max(self.transition_schedule(height));
            if let Some(flare) = self.flare_settings {
                let clearance = self.flare_clearance(&state);
                self.flare
                    .update(&flare, now, tilt, clearance, self.flare_prediction);
            }
        }
        let limit = self.tilt_limit(mode);
        let tilt_velocity = self.limit_tilt_velocity(
            self.tilt_velocity_wanted(mode, inputs.ground_contact, tilt),
            tilt,
            limit,
        );
        self.tilt_command = tilt_velocity;

        let mut status = Status {
            now_ns: now,
            mode,
            transition,
            alpha: self.mpc.alpha(),
            tilt,
            tilt_limit: limit,
            height,
            estimate_age,
            state,
            reference: self.reference[0],
            predicted_next: self.mpc.plan_states().get(1).copied().unwrap_or(state),
            solver: SolverStatus::Idle,
            mpc_failed_ticks,
            mpc_failures_total: self.mpc_failures_total,
            feedback_fallbacks_total: self.mpc.homotopy_fallbacks(),
            feedback_time: 0.0,
            preparation_time: self.last_preparation_time,
            solver_iterations: 0,
            qp_solves: 0,
            drive_velocity: [0.0, 0.0],
            disturbance: [0.0; 6],
            rejected: self.rejected,
            solver_cuts: SolverCuts::default(),
            actuator_faults: detected.bits(),
        };
        self.observe(mode, tilt);
        self.learn_rotor(tilt);
        status.disturbance = self.observer.wrench().into();

        let thrust = self.thrust(mode, &state, pilot, tilt, &mut status);
        let tilt_velocity = match self.mpc_tilt_rate.take() {
            // In the transition the MPC's plan decides, within the same limits.
            Some(rate) if mode == Mode::Transition && self.plans_tilt => {
                // A committed flare tilts up at full speed whatever the plan.
                let rate = if self.flare.committed() {
                    self.tilt_rate_max
                } else {
                    rate
                };
                let planned = self.limit_tilt_velocity(rate, tilt, limit);
                self.tilt_command = planned;
                planned
            }
            _ => tilt_velocity,
        };
        let wheel_rates = self.wheels(mode, &state, height, pilot, &mut status);
        self.last_thrust = thrust;
        self.tilt_sent = tilt_velocity;
        status.rejected = self.rejected;
        status.solver_cuts = self.mpc.solver_cuts();
        StepOutputs {
            thrust: self.rotor_commands(&thrust),
            tilt_velocity,
            rehome_tilt: inputs.rehome_tilt && mode == Mode::Disarmed,
            wheel_rates,
            status,
        }
    }

    /// Learns the disturbance in free flight, holds it near the ground
    /// (ground effect and contact are not a constant wrench), forgets it on
    /// the ground. Other failsafes pause it (their commands may not reach
    /// the rotors, or the estimate is gone); the rotor-out descent learns:
    /// it flies on a model that has just lost a rotor, and a rotor stuck
    /// below what was asked of it, named weak and then out, still
    /// delivers what only the observer sees
    /// (decisions/2026-12-06-stuck-rotor-in-flight.md).
    fn observe(&mut self, mode: Mode, tilt: f64) {
        let learning = self.settings.observer.enabled
            && (matches!(mode, Mode::Flight | Mode::Morphing | Mode::Transition)
                || (mode == Mode::Failsafe && self.rotor_out()))
            && self.last_estimate.is_some();
        if learning {
            if let Some(est) = self.last_estimate {
                self.observer.set_ground_height(self.last_ground_z);
                self.observer.update(
                    &self.model,
                    est.stamp_ns,
                    &est.state,
                    tilt,
                    &self.last_thrust,
                );
            }
        } else if mode.is_airborne_mode() {
            self.observer.pause();
        } else {
            self.observer.reset();
            self.aloft_force = None;
        }
    }

    fn enter(&mut self, mode: Mode, now: u64, state: &State) {
        let previous = self.mode;
        self.mode = mode;
        self.mode_since_ns = now;
        self.carrot = Vector3::new(state[idx::X], state[idx::Y], state[idx::Z]);
        if previous == Mode::Takeoff && mode == Mode::Flight {
            // Airborne: keep climbing to the take-off height, not hold here.
            self.carrot.z = self.last_ground_z - self.settings.modes.takeoff_target_height;
        }
        self.hold_yaw = state[idx::YAW];
        if mode == Mode::Touchdown {
            self.touchdown_thrust = self.last_thrust;
        }
        self.transition_limit = self.flight_limit();
        self.flare.reset();
        self.backup.reset();
        if !mode.is_airborne_mode() {
            self.mpc_warm = false;
        }
        // A new mode changes the horizon's tilt ramp, reference and weights at
        // once: one Gauss-Newton step from the old plan can be far off (it
        // was: a 50 % thrust dip entering the transition), so converge once.
        self.replan = self.mpc_warm;
    }

    fn thrust(
        &mut self,
        mode: Mode,
        state: &State,
        pilot: PilotInput,
        tilt: f64,
        status: &mut Status,
    ) -> Input {
        match mode {
            Mode::Disarmed | Mode::Drive => Input::zeros(),
            Mode::Touchdown => {
                let t = status.now_ns.saturating_sub(self.mode_since_ns) as f64 * 1e-9;
                let cut = self.settings.modes.thrust_cut_time;
                let scale = if cut > 0.0 {
                    (1.0 - t / cut).clamp(0.0, 1.0)
                } else {
                    0.0
                };
                self.touchdown_thrust * scale
            }
            Mode::Takeoff if tilt > self.settings.modes.takeoff_max_tilt_deg.to_radians() => {
                Input::zeros()
            }
            Mode::Failsafe if self.backup_flies() => self.backup_thrust(state, pilot, tilt, status),
            Mode::Failsafe if self.failsafe_control == FailsafeControl::OpenLoop => {
                // No state to fly on (or no backup): open-loop hover trim
                // at the current tilt, slightly under, a descent with
                // nothing holding the attitude.
                let trim = self.model.at_tilt(tilt).hover_trim();
                (trim * self.settings.failsafe.open_loop_thrust_scale).map(|u| u.clamp(0.0, 1.0))
            }
            _ => self.mpc_feedback(state, status),
        }
    }

    fn mpc_feedback(&mut self, state: &State, status: &mut Status) -> Input {
        if !self.mpc_warm {
            // First MPC tick of this flight: start the plan at the estimate.
            if self.mpc.reset(state).is_err() {
                status.solver = SolverStatus::Failed;
                return self.last_thrust;
            }
            self.fill_reference(state);
            self.configure_mpc(state);
            if let Ok(prep) = self.mpc.prepare() {
                self.last_preparation_time = prep.as_secs_f64();
                // The homotopy's preparation is a Clarabel solve of this tick.
                if self.mpc.uses_homotopy() {
                    status.qp_solves += 1;
                }
            }
            self.mpc_warm = true;
        }
        // Setters refuse only non-finite values, which `ingest` keeps out.
        let _ = self.mpc.set_measured_tilt(self.last_tilt);
        let result = if self.replan {
            self.replan = false;
            self.fill_reference(state);
            self.configure_mpc(state);
            let result = self.mpc.replan(state, REPLAN_ITERATIONS);
            status.qp_solves += REPLAN_ITERATIONS as u32;
            result
        } else {
            status.qp_solves += 1;
            self.mpc.feedback(state)
        };
        let Ok(out) = result else {
            self.mpc_failures_total += 1;
            status.solver = SolverStatus::Failed;
            return self.last_thrust;
        };
        self.mpc_tilt_rate = out.tilt_rate;
        status.solver = match out.outcome {
            Outcome::Solved => SolverStatus::Solved,
            Outcome::Degraded(_) => SolverStatus::Degraded,
            Outcome::Fallback { .. } => SolverStatus::Fallback,
            Outcome::Failed { .. } => SolverStatus::Failed,
        };
        if !out.outcome.is_fresh() {
            self.mpc_failures_total += 1;
        }
        status.mpc_failures_total = self.mpc_failures_total;
        status.feedback_fallbacks_total = self.mpc.homotopy_fallbacks();
        status.feedback_time = out.timings.feedback.as_secs_f64();
        status.solver_iterations = out.timings.solver_iterations;
        status.predicted_next = self.mpc.plan_states().get(1).copied().unwrap_or(*state);
        status.alpha = self.mpc.alpha();
        status.reference = self.reference[0];
        out.u.map(|u| {
            if u.is_finite() {
                u.clamp(0.0, 1.0)
            } else {
                0.0
            }
        })
    }

    /// Fills the per-stage MPC reference for the current mode.
    fn fill_reference(&mut self, state: &State) {
        let p = Vector3::new(state[idx::X], state[idx::Y], state[idx::Z]);
        let pilot = self.last_pilot;
        let mut v = Vector3::from(pilot.velocity);
        let ts = self.period();
        let height = self.last_ground_z - state[idx::Z];
        match self.mode {
            Mode::Transition => v.z = self.settings.modes.transition_descent_speed,
            // A rotor out: down at a set speed (`modes`; the tilt: `tilt`).
            Mode::Failsafe if self.rotor_out() => {
                v = Vector3::new(0.0, 0.0, self.settings.monitor.rotor_out_descent_speed);
            }
            Mode::Failsafe => v = Vector3::zeros(),
            // Below z* still folded (see `Thresholds::transition_min_tilt`):
            // hold the height until tilted, then the transition descends.
            Mode::Morphing if height < self.thresholds.transition_height => v.z = v.z.min(0.0),
            _ => {}
        }
        // Position reference: a carrot that moves at the commanded velocity
        // from where the mode began (held still when the sticks are centred).
        // Unlike the paper's p_ref = p + v T_s, a robot that lags (heavier
        // than the model, a head wind) builds a position error that the MPC
        // corrects, so the commanded velocity is met without a steady offset.
        // The MPC sees the carrot at most `reference_leash` away; the carrot
        // stops advancing while it is that far ahead (no wind-up).
        let leash = self.settings.pilot.reference_leash;
        if (self.carrot - p).norm() < leash {
            self.carrot += v * ts;
        }
        let lead = self.carrot - p;
        let mut anchor = if lead.norm() > leash {
            p + lead * (leash / lead.norm())
        } else {
            self.carrot
        };
        if self.mode == Mode::Takeoff && pilot.velocity[2].abs() < 1e-6 {
            // Climb to the take-off height unless the pilot commands vertically.
            anchor.z = self.last_ground_z - self.settings.modes.takeoff_target_height;
            v.z = 0.0;
        }
        let yaw_rate = pilot.yaw_rate;
        if yaw_rate.abs() > 1e-9 {
            self.hold_yaw = state[idx::YAW];
        }
        let flare = match (self.mode, self.flare_settings) {
            (Mode::Transition, Some(f)) => Some((f, self.flare_clearance(state))),
            _ => None,
        };
        for (k, r) in self.reference.iter_mut().enumerate() {
            let t = k as f64 * self.stage_dt;
            let mut pos = anchor + v * t;
            let mut vz = v.z;
            if let Some((f, c0)) = flare {
                // Down is +z: the reference sinks by the clearance it loses.
                let (c, speed) = Flare::approach(&f, v.z, c0, t);
                pos.z = state[idx::Z] + (c0 - c);
                vz = speed;
            }
            *r = State::zeros();
            r[idx::X] = pos.x;
            r[idx::Y] = pos.y;
            r[idx::Z] = pos.z;
            r[idx::YAW] = self.hold_yaw + yaw_rate * t;
            r[idx::VX] = v.x;
            r[idx::VY] = v.y;
            r[idx::VZ] = vz;
            r[idx::WZ] = yaw_rate;
        }
    }

    fn configure_mpc(&mut self, state: &State) {
        let height = self.last_ground_z - state[idx::Z];
        let tilt = self.last_tilt;
        let limit = self.tilt_limit(self.mode);
        let alpha = self
            .alpha
            .update(height, tilt, self.thresholds.transition_height);
        // Setters only refuse non-finite or mis-sized data, which cannot
        // reach here (inputs are validated); a refusal keeps the old value.
        let _ = self.mpc.set_reference(&self.reference);
        if self.mode == Mode::Transition && self.plans_tilt {
            let plan = TiltPlan {
                tilt_min: 0.0,
                tilt_max: self.transition_tilt_max,
                // With the flare the planned tilt only grows. After its
                // commit `step` commands the full rate whatever the plan says;
                // the plan keeps the tilt as its decision, re-measured every
                // tick.
                rate_min: if self.flare_settings.is_some() {
                    0.0
                } else {
                    -self.tilt_rate_max
                },
                rate_max: self.tilt_rate_max,
                wheel_radius: self.wheel_radius,
                // Full range after the commit (`flare::COMMITTED_THRUST_MAX`).
                thrust_max: self.flare.thrust_max(),
            };
            let _ = self.mpc.set_tilt_plan(&plan);
        } else {
            let _ = self
                .mpc
                .set_tilt_ramp(tilt, self.tilt_command, 0.0, limit.max(tilt));
        }
        self.configure_rotors();
        let _ = self.mpc.set_alpha(alpha);
        let _ = self.mpc.set_disturbance(&self.observer.wrench());
        let _ = self.mpc.set_ground_plane(&self.ground_plane(state));
    }

    /// The ground plane under the robot in `state`: through the ground
    /// height below its base origin, with the last good normal.
    fn ground_plane(&self, state: &State) -> GroundPlane {
        GroundPlane {
            point: Vector3::new(state[idx::X], state[idx::Y], self.last_ground_z),
            normal: self.last_ground_normal,
        }
    }

    /// Opens the window of MPC solves whose time-limit cuts the next
    /// `step` reports (`Status::solver_cuts`): call before `prepare_next`.
    /// A replay passes the logged window's cuts as `script` (see
    /// `atmo_mpc::qp::cuts`); in flight, `None`.
    pub fn open_cut_window(&mut self, script: Option<SolverCuts>) {
        self.mpc.open_cut_window(script);
    }

    /// The RTI preparation phase for the next tick. Call after the outputs
    /// of `step` have been sent; does nothing when the MPC is idle.
    pub fn prepare_next(&mut self) {
        if !self.mpc_warm || !self.mode.is_airborne_mode() {
            return;
        }
        let Some(est) = self.last_estimate else {
            return;
        };
        self.fill_reference(&est.state);
        self.configure_mpc(&est.state);
        self.learn_aloft_force(&est.state);
        self.predict_flare(&est.state);
        if let Ok(prep) = self.mpc.prepare() {
            self.last_preparation_time = prep.as_secs_f64();
        }
    }

    /// alpha as the paper defines it for the current state (for logs).
    pub fn alpha_now(&self) -> f64 {
        let state = self.last_estimate.map_or(State::zeros(), |e| e.state);
        blending_alpha(
            self.last_ground_z - state[idx::Z],
            self.last_tilt,
            self.thresholds.transition_height,
        )
    }
}

/// Takes `est` as the newest of an estimate stream whose last good one is
/// `last`: finite, not stamped after `now_ns`, not older than `last`.
/// Returns false for a rejected one (a repeat of `last` is neither).
fn accept_estimate(last: &mut Option<Estimate>, est: Estimate, now_ns: u64) -> bool {
    if *last == Some(est) {
        return true;
    }
    let finite = est.state.iter().all(|v| v.is_finite());
    let from_future = est.stamp_ns > now_ns;
    let backwards = last.is_some_and(|l| est.stamp_ns < l.stamp_ns);
    let ok = finite && !from_future && !backwards;
    if ok {
        *last = Some(est);
    }
    ok
}
