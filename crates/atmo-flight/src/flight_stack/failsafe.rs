//! The failsafe's flying: who commands the thrusters (the MPC, the backup
//! controller or the open-loop trim) and the tilt of a failsafe that lands.

use atmo_core::model::{Input, State, idx};

use super::FlightStack;
use crate::modes::Mode;
use crate::step_io::{PilotInput, Status};

/// Who flies the thrusters in failsafe (`FlightStack::failsafe_control`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum FailsafeControl {
    /// The MPC, holding position (or the rotor-out descent).
    Mpc,
    /// The backup controller's level descent (`backup_control`), on three
    /// rotors with one its ESC reports stopped.
    Backup,
    /// The same descent on the autopilot's own estimate: the estimate is
    /// stale, the autopilot's is not (`StepInputs::autopilot_estimate`).
    AutopilotBackup,
    /// The hover trim, open loop: no estimate to fly on.
    OpenLoop,
}

impl FlightStack {
    /// The arms' tilt in a failsafe descent (a rotor out, or the backup
    /// controller flying), rad: the landing tilt
    /// (`monitor.rotor_out_landing_tilt_deg`), where the wheels' rims are
    /// under the base box. Whatever the thrust left: folded, the base box
    /// is the lowest point and every touchdown is a body contact, and an
    /// out rotor's thrust is not known when it goes out (a stuck rotor
    /// named lost is believed to give nothing until the observer sees
    /// what it gives), so folding for lift landed stuck rotors on their
    /// base (docs/decisions/2026-12-06-stuck-rotor-in-flight.md).
    pub(super) fn descent_tilt(&self) -> f64 {
        self.settings
            .monitor
            .rotor_out_landing_tilt_deg
            .to_radians()
    }

    /// Who would fly a failsafe now: without an estimate, the backup
    /// controller on the autopilot's if that one is fresh, else the
    /// open-loop trim; with one, the MPC switched off or failed past its
    /// grace (`mpc_failed`) or a rotor its ESC reports stopped, the backup
    /// controller (`backup_control`; with a zero bandwidth the failed MPC's
    /// held command, or switched off the open-loop trim, as logs written
    /// before the key flew); else the MPC. A stopped rotor leaves three,
    /// which cannot hold the heading, the lift and level together: the
    /// backup lets the heading go and flies the spin that follows, which
    /// the MPC's model, linearised about a hover that does not spin, does
    /// not (decisions/2026-12-07-stopped-rotor-bound.md).
    pub(super) fn failsafe_control(
        &self,
        estimate_fresh: bool,
        autopilot_fresh: bool,
        mpc_failed: bool,
    ) -> FailsafeControl {
        let backup = self.settings.failsafe.backup_attitude_bandwidth > 0.0;
        let switched_off = !self.last_pilot.mpc_enabled;
        if !estimate_fresh {
            if autopilot_fresh && backup {
                FailsafeControl::AutopilotBackup
            } else {
                FailsafeControl::OpenLoop
            }
        } else if switched_off && !backup {
            FailsafeControl::OpenLoop
        } else if (mpc_failed || self.monitor.stopped_rotor().is_some()) && backup {
            FailsafeControl::Backup
        } else {
            FailsafeControl::Mpc
        }
    }

    /// In failsafe the backup controller flies.
    pub(super) fn backup_flies(&self) -> bool {
        self.mode == Mode::Failsafe
            && matches!(
                self.failsafe_control,
                FailsafeControl::Backup | FailsafeControl::AutopilotBackup
            )
    }

    /// A failsafe that lands: the rotor-out descent or the backup's.
    pub(super) fn failsafe_descends(&self) -> bool {
        self.mode == Mode::Failsafe && (self.rotor_out() || self.backup_flies())
    }

    /// The backup's level descent. A failed MPC still runs on the estimate
    /// (its solves may come back: recovery), its stale plan unflown;
    /// switched off, or with the estimate stale, it does not run. On the
    /// autopilot's estimate only its attitude, body rates and vertical
    /// speed are flown: its horizontal velocity, drifting without the
    /// motion capture, is not braked against.
    pub(super) fn backup_thrust(
        &mut self,
        state: &State,
        pilot: PilotInput,
        tilt: f64,
        status: &mut Status,
    ) -> Input {
        let autopilot = self.failsafe_control == FailsafeControl::AutopilotBackup;
        let flown = match self.last_autopilot_estimate {
            Some(e) if autopilot => {
                let mut level_only = e.state;
                level_only[idx::VX] = 0.0;
                level_only[idx::VY] = 0.0;
                level_only
            }
            _ => *state,
        };
        let planned = if pilot.mpc_enabled && !autopilot {
            self.mpc_feedback(state, status)
        } else {
            self.last_thrust
        };
        let bandwidth = self.settings.failsafe.backup_attitude_bandwidth;
        let body = self
            .model
            .at_tilt(tilt)
            .with_disturbance(self.observer.wrench());
        let stopped = self.stopped_rotor();
        let speed = if stopped.is_some() {
            self.settings.monitor.rotor_out_descent_speed
        } else {
            self.settings.failsafe.backup_descent_speed
        };
        let dt = self.period();
        self.backup
            .command(&body, &flown, dt, bandwidth, speed, stopped)
            .unwrap_or(planned)
    }
}
