//! The ESCs' telemetry as the rotors' speeds: PX4's `EscStatus` (each
//! ESC's RPM, `/fmu/out/esc_status`) into [`crate::StepInputs::rotor_speeds`]
//! (each rotor's speed as a fraction of its speed at full command), which
//! the actuator monitor reads to tell a stopped rotor (docs/faults.md).
//!
//! Rotor k (0-based, the robot file's order: PX4's quad-x numbering 1 FR,
//! 2 BL, 3 FL, 4 BR) is the ESC whose `actuator_function` is PX4's
//! Motor(k+1); when no ESC says its function (older PX4, or a driver that
//! does not fill it), ESC k. Its ESC must be among the `esc_count`
//! reported and online, else the report is refused whole: a missing
//! rotor's speed must not read as a stopped one.
//!
//! Pure and fixed-size: it runs on the control thread.

use atmo_io::msg::EscStatus;

atmo_core::params! {
    /// `[esc]` of `config/daemon.toml`: how PX4's `EscStatus` becomes the
    /// rotors' speeds (used when `ros2.topics.esc_status` is enabled).
    #[derive(Debug, Clone, Copy, PartialEq)]
    pub struct EscConfig: Default {
        /// A rotor's speed at full command: the scale of the reports. Not
        /// in the robot file's numbers (they give thrust, not speed):
        /// measured on the stand, the rotor at full command. 0: unknown
        /// (the topic cannot be enabled).
        pub full_speed_rpm: f64 = 0.0, range 0.0..=1e6, unit "RPM";
    }
}

/// Why an ESC report gives no speeds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EscReject {
    /// Rotor `0` (0-based) has no ESC in the report.
    Missing(usize),
    /// Rotor `0`'s ESC is reported offline.
    Offline(usize),
}

impl std::fmt::Display for EscReject {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Missing(k) => write!(f, "no ESC reports rotor {}", k + 1),
            Self::Offline(k) => write!(f, "rotor {}'s ESC is offline", k + 1),
        }
    }
}

impl EscConfig {
    /// Each rotor's speed, a fraction of `full_speed_rpm` (negative if it
    /// turns backwards: the flight stack refuses and counts it), from
    /// `status`.
    pub fn rotor_speeds(&self, status: &EscStatus) -> Result<[f64; 4], EscReject> {
        let count = usize::from(status.esc_count.min(EscStatus::CONNECTED_ESC_MAX));
        let reports = &status.esc[..count];
        let by_function = reports.iter().any(|r| r.actuator_function != 0);
        let mut speeds = [0.0; 4];
        for (k, speed) in speeds.iter_mut().enumerate() {
            let index = if by_function {
                let motor = EscStatus::ACTUATOR_FUNCTION_MOTOR1 + k as u8;
                reports.iter().position(|r| r.actuator_function == motor)
            } else {
                (k < count).then_some(k)
            }
            .ok_or(EscReject::Missing(k))?;
            if status.esc_online_flags & (1 << index) == 0 {
                return Err(EscReject::Offline(k));
            }
            *speed = f64::from(reports[index].esc_rpm) / self.full_speed_rpm;
        }
        Ok(speeds)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn status(rpm: [i32; 4]) -> EscStatus {
        let mut s = EscStatus {
            esc_count: 4,
            esc_online_flags: 0b1111,
            ..EscStatus::default()
        };
        for (r, v) in s.esc.iter_mut().zip(rpm) {
            r.esc_rpm = v;
        }
        s
    }

    #[test]
    fn each_rotor_is_its_motors_esc_and_a_missing_or_offline_one_refuses_the_report() {
        let esc = EscConfig {
            full_speed_rpm: 20_000.0,
        };
        // No functions given: ESC k is rotor k.
        let s = status([10_000, 0, 14_000, -2_000]);
        assert_eq!(esc.rotor_speeds(&s), Ok([0.5, 0.0, 0.7, -0.1]));
        // Functions given: by function, whatever the order.
        let mut by_function = s;
        for (r, function) in by_function.esc.iter_mut().zip([102, 101, 104, 103]) {
            r.actuator_function = function;
        }
        assert_eq!(esc.rotor_speeds(&by_function), Ok([0.0, 0.5, -0.1, 0.7]));
        // Three ESCs reported: the fourth rotor is missing, not stopped.
        let mut three = s;
        three.esc_count = 3;
        assert_eq!(esc.rotor_speeds(&three), Err(EscReject::Missing(3)));
        let mut offline = s;
        offline.esc_online_flags = 0b1101;
        assert_eq!(esc.rotor_speeds(&offline), Err(EscReject::Offline(1)));
        assert_eq!(
            EscReject::Offline(1).to_string(),
            "rotor 2's ESC is offline"
        );
    }
}
