//! The status record of a tick as the `atmo_msgs/MpcStatus` message that
//! goes to ROS 2 and the MCAP log. Copies fixed-size data only: safe on the
//! control thread.

use atmo_core::model::State;
use atmo_io::msg::{IoHealth, Label, MpcStatus, TickInputs};
use atmo_mpc::SolverCuts;

use crate::control_loop::TickTiming;
use crate::flight_stack::{Estimate, StepInputs, StepOutputs};

/// The tick's inputs as the `atmo_msgs/TickInputs` message (every field of
/// [`StepInputs`], bit for bit, and the solves the time limit cut).
pub fn inputs_message(tick: u64, inputs: &StepInputs, cuts: &SolverCuts) -> TickInputs {
    let estimate = inputs.estimate;
    TickInputs {
        tick,
        clock_ns: inputs.now_ns,
        has_estimate: estimate.is_some(),
        estimate_received_ns: estimate.map_or(0, |e| e.stamp_ns),
        estimate: estimate.map_or([0.0; 12], |e| MpcStatus::array(&e.state)),
        has_tilt_counts: inputs.tilt_counts.is_some(),
        tilt_counts: inputs.tilt_counts.unwrap_or(0.0),
        pilot: inputs.pilot,
        ground_contact: inputs.ground_contact,
        ground_z: inputs.ground_z,
        driver_lost: inputs.driver_lost,
        solver_cut_count: cuts.count,
        solver_cut_solve: cuts.solve,
        solver_cut_iteration: cuts.iteration,
        solver_cut_overflow: cuts.overflow,
        has_ground_normal: inputs.ground_normal.is_some(),
        ground_normal: inputs.ground_normal.unwrap_or([0.0; 3]),
        pilot_lost: inputs.pilot_lost,
        arming_failures: inputs.arming_failures,
        tilt_lever: inputs.tilt_lever,
        rehome_tilt: inputs.rehome_tilt,
        has_autopilot_estimate: inputs.autopilot_estimate.is_some(),
        autopilot_estimate_received_ns: inputs.autopilot_estimate.map_or(0, |e| e.stamp_ns),
        autopilot_estimate: inputs
            .autopilot_estimate
            .map_or([0.0; 12], |e| MpcStatus::array(&e.state)),
        has_rotor_speeds: inputs.rotor_speeds.is_some(),
        rotor_speeds: inputs.rotor_speeds.unwrap_or([0.0; 4]),
    }
}

/// The time-limit cuts a `TickInputs` message carries.
pub fn cuts_from_message(m: &TickInputs) -> SolverCuts {
    SolverCuts {
        count: m.solver_cut_count,
        solve: m.solver_cut_solve,
        iteration: m.solver_cut_iteration,
        overflow: m.solver_cut_overflow,
    }
}

/// The `atmo_msgs/TickInputs` message as the flight stack's inputs (the
/// inverse of [`inputs_message`]).
pub fn inputs_from_message(m: &TickInputs) -> StepInputs {
    StepInputs {
        now_ns: m.clock_ns,
        estimate: m.has_estimate.then(|| Estimate {
            stamp_ns: m.estimate_received_ns,
            state: State::from_column_slice(&m.estimate),
        }),
        tilt_counts: m.has_tilt_counts.then_some(m.tilt_counts),
        pilot: m.pilot,
        ground_contact: m.ground_contact,
        ground_z: m.ground_z,
        ground_normal: m.has_ground_normal.then_some(m.ground_normal),
        driver_lost: m.driver_lost,
        pilot_lost: m.pilot_lost,
        arming_failures: m.arming_failures,
        tilt_lever: m.tilt_lever,
        rehome_tilt: m.rehome_tilt,
        autopilot_estimate: m.has_autopilot_estimate.then(|| Estimate {
            stamp_ns: m.autopilot_estimate_received_ns,
            state: State::from_column_slice(&m.autopilot_estimate),
        }),
        rotor_speeds: m.has_rotor_speeds.then_some(m.rotor_speeds),
    }
}

/// `MpcStatus` for one tick.
pub fn status_message(
    tick: u64,
    inputs: &StepInputs,
    outputs: &StepOutputs,
    timing: &TickTiming,
) -> MpcStatus {
    let s = &outputs.status;
    let p = &inputs.pilot;
    MpcStatus {
        stamp_ns: s.now_ns,
        // The stack's clock is ROS time in a simulation; the onboard daemon
        // stamps the wall clock instead (its clock starts at 0).
        ros_stamp_ns: s.now_ns,
        tick,
        mode: s.mode,
        transition: Label::new(s.transition.unwrap_or("")),
        solver_status: s.solver,
        solver_iterations: s.solver_iterations,
        mpc_failed_ticks: s.mpc_failed_ticks,
        mpc_failures_total: s.mpc_failures_total,
        feedback_fallbacks_total: s.feedback_fallbacks_total,
        state: s.state.into(),
        reference: s.reference.into(),
        predicted_next: s.predicted_next.into(),
        thrust: outputs.thrust,
        alpha: s.alpha,
        varphi: s.tilt,
        tilt_limit: s.tilt_limit,
        tilt_velocity: outputs.tilt_velocity,
        drive_velocity: s.drive_velocity,
        wheel_rates: [outputs.wheel_rates.left, outputs.wheel_rates.right],
        height: s.height,
        ground_contact: inputs.ground_contact,
        estimate_age: if s.estimate_age.is_finite() {
            s.estimate_age
        } else {
            -1.0
        },
        feedback_time: s.feedback_time,
        preparation_time: s.preparation_time,
        pilot: *p,
        timing: *timing,
        rejected_estimate: s.rejected.estimate,
        rejected_tilt: s.rejected.tilt,
        rejected_pilot: s.rejected.pilot,
        rejected_ground: s.rejected.ground,
        // Filled in by the I/O layer that owns the transports (zero in simulation).
        io: IoHealth::default(),
        actuator_faults: s.actuator_faults,
        rejected_rotor_speeds: s.rejected.rotor_speeds,
    }
}
