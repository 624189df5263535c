//! One test per arming check of [`super::ArmingMonitor`].

use super::*;

/// A healthy robot's ticks at 150 Hz: estimates at 100 Hz, the tilt
/// following its command exactly.
struct Feed {
    monitor: ArmingMonitor,
    now_ns: u64,
    estimates: f64,
    tilt: Option<f64>,
    pilot_lost: bool,
    driver_lost: bool,
    estimate_rate_hz: f64,
    /// The tilt velocity commanded, rad/s, and how much of it the
    /// mechanism follows (1: exactly).
    command: f64,
    follows: f64,
}

impl Feed {
    fn new() -> Self {
        Self {
            monitor: ArmingMonitor::new(ArmingSettings::default(), true),
            now_ns: 0,
            estimates: 0.0,
            tilt: Some(1.5),
            pilot_lost: false,
            driver_lost: false,
            estimate_rate_hz: 100.0,
            command: 0.0,
            follows: 1.0,
        }
    }

    fn run(&mut self, seconds: f64) -> u8 {
        let period_ns = 6_666_667;
        let ticks = (seconds * 150.0).round() as usize;
        for _ in 0..ticks {
            self.now_ns += period_ns;
            self.estimates += self.estimate_rate_hz * period_ns as f64 * 1e-9;
            self.monitor.observe(&ArmingObservation {
                now_ns: self.now_ns,
                estimates_total: self.estimates as u64,
                pilot_lost: self.pilot_lost,
                driver_lost: self.driver_lost,
                tilt: self.tilt,
                tilt_velocity: self.command,
            });
            if let Some(t) = &mut self.tilt {
                *t += self.command * self.follows * period_ns as f64 * 1e-9;
            }
        }
        self.monitor.failures()
    }
}

fn failed(bits: u8) -> Vec<&'static str> {
    ArmingCheck::ALL
        .into_iter()
        .filter(|c| bits & c.bit() != 0)
        .map(ArmingCheck::name)
        .collect()
}

#[test]
fn a_healthy_robot_passes_every_check_once_the_windows_have_filled() {
    let mut f = Feed::new();
    assert_ne!(f.monitor.failures(), 0, "nothing measured yet");
    let early = f.run(0.5);
    assert_eq!(
        failed(early),
        ["estimate rate", "tilt encoder"],
        "measuring"
    );
    assert_eq!(f.run(2.0), 0, "{:?}", failed(f.monitor.failures()));
}

#[test]
fn configuration_check() {
    let mut f = Feed::new();
    f.monitor = ArmingMonitor::new(ArmingSettings::default(), false);
    assert_eq!(failed(f.run(3.0)), ["configuration"]);
}

#[test]
fn estimate_rate_check() {
    let mut f = Feed::new();
    f.estimate_rate_hz = 40.0; // below the default 50 Hz
    assert_eq!(failed(f.run(3.0)), ["estimate rate"]);
    f.estimate_rate_hz = 60.0;
    assert_eq!(f.run(1.1), 0, "a second at 60 Hz");
    f.estimate_rate_hz = 0.0; // the estimate stops
    assert_eq!(f.run(0.1), 0, "still 54 in the last second");
    assert_eq!(
        failed(f.run(0.2)),
        ["estimate rate"],
        "42 in the last second"
    );
}

#[test]
fn radio_check() {
    let mut f = Feed::new();
    f.pilot_lost = true;
    assert_eq!(failed(f.run(3.0)), ["radio"]);
    f.pilot_lost = false;
    assert_eq!(f.run(0.01), 0);
}

#[test]
fn drivers_check() {
    let mut f = Feed::new();
    f.driver_lost = true;
    assert_eq!(failed(f.run(3.0)), ["drivers"]);
}

#[test]
fn tilt_encoder_check_needs_a_reading() {
    let mut f = Feed::new();
    f.tilt = None;
    assert_eq!(failed(f.run(3.0)), ["tilt encoder"]);
}

#[test]
fn tilt_encoder_check_compares_the_motion_with_the_command() {
    let mut f = Feed::new();
    f.command = -0.2; // towards flight
    assert_eq!(f.run(2.5), 0, "followed exactly");
    // A slipping belt: half the commanded motion, 0.2 rad (11 deg) short
    // over the 2 s window.
    f.follows = 0.5;
    assert_eq!(failed(f.run(2.5)), ["tilt encoder"]);
    // Standing still with the command at rest passes again.
    f.command = 0.0;
    f.follows = 1.0;
    assert_eq!(f.run(2.5), 0);
    // An encoder that moves while nothing is commanded (a reset counter,
    // a loose linkage) fails.
    f.tilt = Some(0.5);
    assert_eq!(failed(f.run(0.1)), ["tilt encoder"]);
}

#[test]
fn refusal_names_the_first_failed_check() {
    let bits = ArmingCheck::Radio.bit() | ArmingCheck::TiltEncoder.bit();
    assert_eq!(ArmingCheck::first_failed(bits), Some(ArmingCheck::Radio));
    assert_eq!(ArmingCheck::first_failed(0), None);
    for check in ArmingCheck::ALL {
        assert!(check.refusal().starts_with("arming refused: "));
        assert!(check.refusal().len() <= atmo_io::msg::Label::CAPACITY);
    }
}

#[test]
fn settings_are_checked_by_key() {
    let file = Path::new("daemon.toml");
    ArmingSettings::default().validate(file).unwrap();
    let bad = ArmingSettings {
        tilt_tolerance_deg: 0.0,
        ..ArmingSettings::default()
    };
    let err = bad.validate(file).unwrap_err().to_string();
    assert!(err.contains("arming.tilt_tolerance_deg"), "{err}");
    let bad = ArmingSettings {
        min_estimate_rate_hz: f64::NAN,
        ..ArmingSettings::default()
    };
    let err = bad.validate(file).unwrap_err().to_string();
    assert!(err.contains("arming.min_estimate_rate_hz"), "{err}");
}

#[test]
fn diagnostics_name_every_check_and_the_failed_ones() {
    use atmo_io::msg::DiagnosticStatus;
    let ok = diagnostics(0, None);
    assert_eq!(
        (ok.level, ok.name.as_str()),
        (DiagnosticStatus::OK, "atmo/arming")
    );
    assert_eq!(ok.values.len(), ArmingCheck::ALL.len());
    let bad = diagnostics(
        ArmingCheck::Configuration.bit() | ArmingCheck::Drivers.bit(),
        Some("no pilot source"),
    );
    assert_eq!(bad.level, DiagnosticStatus::ERROR);
    assert_eq!(bad.message, "arming refused: configuration, drivers");
    let value = |k: &str| {
        bad.values
            .iter()
            .find(|v| v.key == k)
            .map(|v| v.value.as_str())
    };
    assert_eq!(value("drivers"), Some("fail"));
    assert_eq!(value("radio"), Some("pass"));
    assert_eq!(value("configuration problem"), Some("no pilot source"));
}
