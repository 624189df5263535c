//! The wheels' commands: the pilot's drive on the ground, and the spin-up
//! before touchdown so that the wheels land rolling.

use atmo_core::control::WheelRates;
use atmo_core::model::{State, idx};

use super::{FlightStack, PilotInput, Status};
use crate::modes::Mode;

impl FlightStack {
    /// The wheel rates for `mode` (drive velocity reported in `status`).
    pub(super) fn wheels(
        &self,
        mode: Mode,
        state: &State,
        height: f64,
        pilot: PilotInput,
        status: &mut Status,
    ) -> WheelRates {
        let yaw = state[idx::YAW];
        let (sy, cy) = yaw.sin_cos();
        let forward = |v: [f64; 3]| cy * v[0] + sy * v[1];
        match mode {
            Mode::Drive => {
                let v = forward(pilot.velocity);
                status.drive_velocity = [v, pilot.yaw_rate];
                self.drive.wheel_rates(v, pilot.yaw_rate)
            }
            Mode::Transition | Mode::Touchdown
                if mode == Mode::Touchdown || height < self.settings.modes.wheel_spinup_height =>
            {
                // Spin up to the ground speed so that the wheels land rolling.
                let v = forward([state[idx::VX], state[idx::VY], 0.0]);
                status.drive_velocity = [v, 0.0];
                self.drive.wheel_rates(v, 0.0)
            }
            _ => WheelRates {
                left: 0.0,
                right: 0.0,
            },
        }
    }
}
