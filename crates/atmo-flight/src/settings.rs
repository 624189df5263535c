//! Flight-stack settings (`config/flight.toml`), strictly parsed and validated.

use std::path::Path;

use atmo_core::CoreError;
use atmo_core::config_file::ConfigFile;

pub use crate::actuator_monitor::MonitorSettings;
pub use crate::flare::FlareSettings;

atmo_core::params! {
    /// `config/flight.toml`: the flight stack's settings.
    #[derive(Debug, Clone, PartialEq)]
    pub struct FlightSettings {
        /// Cost preset of the MPC file.
        pub mpc_preset: String;
        pub pilot: PilotSettings;
        pub modes: ModeSettings;
        pub failsafe: FailsafeSettings;
        pub observer: ObserverConfig;
        pub flare: FlareSettings;
        /// The actuator monitor's thresholds; a file without the table (a
        /// flight log written before the monitor) flies without it.
        pub monitor: MonitorSettings = MonitorSettings::disabled();
        pub control_loop: LoopSettings, key "loop";
    }
}

atmo_core::params! {
    /// `[pilot]`: what the pilot's sticks command.
    #[derive(Debug, Clone, PartialEq)]
    pub struct PilotSettings {
        /// Velocity commands are limited to this norm.
        pub max_speed: f64, range 0.0..=1.0, unit "m/s";
        /// Yaw rate at full command.
        pub max_yaw_rate: f64, range 0.0..=5.0, unit "rad/s";
        /// A downward command above this below z_varphi starts morphing.
        pub descent_threshold: f64, range 0.0..=*max_speed, unit "m/s";
        /// How far the position reference may run ahead of the robot.
        pub reference_leash: f64, unit "m";
    }
}

atmo_core::params! {
    /// `[modes]`: the mode machine's thresholds.
    #[derive(Debug, Clone, PartialEq)]
    pub struct ModeSettings {
        /// Throttle at which a grounded ATMO tilts back and takes off.
        pub takeoff_throttle: f64, range 0.0..=1.0;
        /// Thrusters start at or below this tilt.
        pub takeoff_max_tilt_deg: f64, range 0.0..=90.0, unit "deg";
        /// Airborne above this height: flight (> 0).
        pub takeoff_height: f64, range 0.01..=100.0, unit "m";
        /// Climb target when the pilot gives no vertical command (above
        /// `takeoff_height`).
        pub takeoff_target_height: f64, unit "m";
        /// Climbing this far above z_varphi aborts morphing.
        pub morph_hysteresis: f64, range 0.0..=5.0, unit "m";
        /// Descent reference below z*.
        pub transition_descent_speed: f64, range 0.01..=2.0, unit "m/s";
        /// Wheels spun up to ground speed below this in transition.
        pub wheel_spinup_height: f64, range 0.0..=2.0, unit "m";
        /// Height at which the transition may use its full tilt limit.
        pub transition_full_tilt_height: f64, range 0.0..=2.0, unit "m";
        /// Thrust ramp to zero after touchdown.
        pub thrust_cut_time: f64, range 0.0..=5.0, unit "s";
        /// With a rotor failed, a wheel contact with the body tipped further
        /// from level than this is one wheel touching, not a landing: the
        /// transition flies on until the body is level (the touchdown's
        /// thrust ramp would drop it onto its other wheels).
        pub touchdown_max_tip_deg: f64 = 10.0, range 0.0..=90.0, unit "deg";
        /// ... and flies on at most this long with the contact lasting:
        /// still tipped after it, the robot rests on something, and the
        /// touchdown comes anyway.
        pub touchdown_level_timeout: f64 = 1.0, range 0.0..=5.0, unit "s";
    }
    check |_table, c, prefix| {
        let key = |name| atmo_core::params::key(prefix, name);
        if !(takeoff_target_height.is_finite() && takeoff_target_height > takeoff_height) {
            return Err(c.fail(
                &key("takeoff_target_height"),
                format!("a height above {} ({takeoff_height} m)", key("takeoff_height")),
                takeoff_target_height,
            ));
        }
        Ok(())
    }
}

atmo_core::params! {
    /// `[failsafe]`: when the estimate is lost and when it is trusted again.
    #[derive(Debug, Clone, PartialEq)]
    pub struct FailsafeSettings {
        /// An older estimate is stale.
        pub estimate_timeout: f64, range 0.001..=1.0, unit "s";
        /// Minimum time in failsafe before handing back.
        pub recovery_time: f64, range 0.0..=60.0, unit "s";
        /// Tilt below which a failsafe may hand back to flight.
        pub recovery_tilt_deg: f64, range 0.0..=90.0, unit "deg";
        /// Times the hover trim when there is no usable estimate (a slow
        /// descent).
        pub open_loop_thrust_scale: f64, range 0.0..=1.5;
        /// The backup controller's attitude bandwidth (`backup_control`),
        /// flown in failsafe once the MPC has failed past its grace or is
        /// switched off; 0 flies the failed MPC's last plan on (switched
        /// off: the open-loop trim), as logs written before the key did.
        pub backup_attitude_bandwidth: f64 = 0.0, range 0.0..=100.0, unit "rad/s";
        /// ... and its descent speed.
        pub backup_descent_speed: f64 = 0.3, range 0.0..=5.0, unit "m/s";
    }
}

atmo_core::params! {
    /// `[observer]`: the disturbance observer of the offset-free MPC.
    #[derive(Debug, Clone, PartialEq)]
    pub struct ObserverConfig {
        /// Whether the observer learns the body wrench in flight.
        pub enabled: bool;
        /// Gain per estimate.
        pub force_gain: f64, range 0.0..=1.0;
        /// Gain per estimate.
        pub torque_gain: f64, range 0.0..=1.0;
        /// Per axis.
        pub max_force: f64, range 0.0..=200.0, unit "N";
        /// Per axis.
        pub max_torque: f64, range 0.0..=20.0, unit "N m";
        /// An estimate accepted sooner than this after the base sample is
        /// not differenced (a burst from a loaded transport). 0 differences
        /// every estimate: what a file without the key flew.
        pub min_interval: f64 = 0.0, range 0.0..=0.05, unit "s";
    }
}

atmo_core::params! {
    /// `[loop]`: the control loop.
    #[derive(Debug, Clone, PartialEq)]
    pub struct LoopSettings {
        /// Control rate.
        pub rate_hz: f64, range 1.0..=2000.0, unit "Hz";
    }
}

impl LoopSettings {
    /// Control period, s.
    pub fn period(&self) -> f64 {
        1.0 / self.rate_hz
    }
}

impl FlightSettings {
    /// The shipped `config/flight.toml`.
    pub fn atmo() -> Self {
        Self::from_toml_str(
            include_str!("../../../config/flight.toml"),
            "config/flight.toml",
        )
        .expect("the shipped config/flight.toml is valid (tested)")
    }
}

impl ConfigFile for FlightSettings {
    type Error = CoreError;

    fn validate(&self, file: &Path) -> Result<(), CoreError> {
        atmo_core::params::check_file(self, file)
    }
}
