//! Flight-stack settings (`config/flight.toml`), strictly parsed and validated.

use std::path::Path;

use atmo_core::CoreError;
use atmo_core::config_file::{Checker, ConfigFile};
use serde::Deserialize;

pub use crate::actuator_monitor::MonitorSettings;
pub use crate::flare::FlareSettings;

#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct FlightSettings {
    /// Cost preset of the MPC file.
    pub mpc_preset: String,
    pub pilot: PilotSettings,
    pub modes: ModeSettings,
    pub failsafe: FailsafeSettings,
    pub observer: ObserverConfig,
    pub flare: FlareSettings,
    /// The actuator monitor's thresholds; a file without the table (a
    /// flight log written before the monitor) flies without it.
    #[serde(default)]
    pub monitor: MonitorSettings,
    #[serde(rename = "loop")]
    pub control_loop: LoopSettings,
}

#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct PilotSettings {
    pub max_speed: f64,
    pub max_yaw_rate: f64,
    pub descent_threshold: f64,
    /// m, how far the position reference may run ahead of the robot.
    pub reference_leash: f64,
}

#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ModeSettings {
    pub takeoff_throttle: f64,
    pub takeoff_max_tilt_deg: f64,
    pub takeoff_height: f64,
    pub takeoff_target_height: f64,
    pub morph_hysteresis: f64,
    pub transition_descent_speed: f64,
    pub wheel_spinup_height: f64,
    /// m, height at which the transition may use its full tilt limit.
    pub transition_full_tilt_height: f64,
    pub thrust_cut_time: f64,
}

#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct FailsafeSettings {
    pub estimate_timeout: f64,
    pub recovery_time: f64,
    pub recovery_tilt_deg: f64,
    pub open_loop_thrust_scale: f64,
}

#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ObserverConfig {
    pub enabled: bool,
    pub force_gain: f64,
    pub torque_gain: f64,
    pub max_force: f64,
    pub max_torque: f64,
    pub min_interval: f64,
}

#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct LoopSettings {
    pub rate_hz: f64,
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
        let c = Checker::new(file);
        let p = &self.pilot;
        c.range("pilot.max_speed", p.max_speed, 0.0..=1.0, "m/s")?;
        c.range("pilot.max_yaw_rate", p.max_yaw_rate, 0.0..=5.0, "rad/s")?;
        c.range(
            "pilot.descent_threshold",
            p.descent_threshold,
            0.0..=p.max_speed,
            "m/s",
        )?;
        let m = &self.modes;
        c.range("modes.takeoff_throttle", m.takeoff_throttle, 0.0..=1.0, "")?;
        c.range(
            "modes.takeoff_max_tilt_deg",
            m.takeoff_max_tilt_deg,
            0.0..=90.0,
            "deg",
        )?;
        c.positive("modes.takeoff_height", m.takeoff_height)?;
        if !(m.takeoff_target_height.is_finite() && m.takeoff_target_height > m.takeoff_height) {
            return Err(c.fail(
                "modes.takeoff_target_height",
                format!(
                    "a height above modes.takeoff_height ({} m)",
                    m.takeoff_height
                ),
                m.takeoff_target_height,
            ));
        }
        c.range("modes.morph_hysteresis", m.morph_hysteresis, 0.0..=5.0, "m")?;
        c.range(
            "modes.transition_descent_speed",
            m.transition_descent_speed,
            0.01..=2.0,
            "m/s",
        )?;
        c.range(
            "modes.transition_full_tilt_height",
            m.transition_full_tilt_height,
            0.0..=2.0,
            "m",
        )?;
        c.range(
            "modes.wheel_spinup_height",
            m.wheel_spinup_height,
            0.0..=2.0,
            "m",
        )?;
        c.range("modes.thrust_cut_time", m.thrust_cut_time, 0.0..=5.0, "s")?;
        let f = &self.failsafe;
        c.range(
            "failsafe.estimate_timeout",
            f.estimate_timeout,
            0.001..=1.0,
            "s",
        )?;
        c.range("failsafe.recovery_time", f.recovery_time, 0.0..=60.0, "s")?;
        c.range(
            "failsafe.recovery_tilt_deg",
            f.recovery_tilt_deg,
            0.0..=90.0,
            "deg",
        )?;
        c.range(
            "failsafe.open_loop_thrust_scale",
            f.open_loop_thrust_scale,
            0.0..=1.5,
            "",
        )?;
        let o = &self.observer;
        c.range("observer.force_gain", o.force_gain, 0.0..=1.0, "")?;
        c.range("observer.torque_gain", o.torque_gain, 0.0..=1.0, "")?;
        c.range("observer.max_force", o.max_force, 0.0..=200.0, "N")?;
        c.range("observer.max_torque", o.max_torque, 0.0..=20.0, "N m")?;
        c.range("observer.min_interval", o.min_interval, 0.0..=0.05, "s")?;
        c.range(
            "loop.rate_hz",
            self.control_loop.rate_hz,
            1.0..=2000.0,
            "Hz",
        )?;
        validate_flare(&c, &self.flare)?;
        validate_monitor(&c, &self.monitor)
    }
}

fn validate_monitor(c: &Checker, m: &MonitorSettings) -> Result<(), CoreError> {
    c.range(
        "monitor.encoder_step_deg",
        m.encoder_step_deg,
        0.0..=10.0,
        "deg",
    )?;
    c.range(
        "monitor.encoder_stuck_travel_deg",
        m.encoder_stuck_travel_deg,
        m.encoder_step_deg..=45.0,
        "deg",
    )?;
    c.range("monitor.tilt_force", m.tilt_force, 0.0..=200.0, "N")?;
    c.range("monitor.tilt_force_time", m.tilt_force_time, 0.0..=5.0, "s")?;
    c.range("monitor.rotor_time", m.rotor_time, 0.0..=5.0, "s")?;
    c.range(
        "monitor.contact_clearance",
        m.contact_clearance,
        -0.1..=0.5,
        "m",
    )?;
    c.range("monitor.contact_speed", m.contact_speed, 0.0..=2.0, "m/s")?;
    c.range("monitor.contact_time", m.contact_time, 0.0..=5.0, "s")?;
    c.range(
        "monitor.rotor_out_effectiveness",
        m.rotor_out_effectiveness,
        0.0..=1.0,
        "",
    )?;
    c.range(
        "monitor.rotor_out_descent_speed",
        m.rotor_out_descent_speed,
        0.05..=2.0,
        "m/s",
    )?;
    Ok(())
}

fn validate_flare(c: &Checker, f: &FlareSettings) -> Result<(), CoreError> {
    c.range("flare.hold_clearance", f.hold_clearance, -0.1..=0.5, "m")?;
    c.range("flare.time_constant", f.time_constant, 0.01..=5.0, "s")?;
    c.range(
        "flare.impact_speed_max",
        f.impact_speed_max,
        0.01..=2.0,
        "m/s",
    )?;
    c.range(
        "flare.touchdown_tilt_min_deg",
        f.touchdown_tilt_min_deg,
        0.0..=90.0,
        "deg",
    )?;
    let errors = [
        ("flare.impact_speed_error", f.impact_speed_error, 1.0, "m/s"),
        (
            "flare.touchdown_tilt_error_deg",
            f.touchdown_tilt_error_deg,
            20.0,
            "deg",
        ),
    ];
    for (key, e, limit, unit) in errors {
        c.range(&format!("{key}.mean"), e.mean, -limit..=limit, unit)?;
        c.range(
            &format!("{key}.spread"),
            e.spread,
            limit * 1e-3..=limit,
            unit,
        )?;
    }
    Ok(())
}
