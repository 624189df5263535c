//! Arming checks (PX4's pre-arm checks are the model): the robot arms only
//! when every check passes; a refused arming names the first failed check
//! in the status (`MpcStatus.transition`, "arming refused: ...") and the
//! daemon's diagnostics (`atmo/arming`, every check with its verdict).
//!
//! The checks are evaluated at the edge that sees the transports
//! ([`ArmingMonitor`], fed by the onboard I/O each tick) and reach the
//! flight stack as one bit set ([`crate::StepInputs::arming_failures`],
//! logged with the tick's inputs), so the flight stack's refusal replays
//! bit for bit. They gate arming only: once armed, the failsafes act.
//!
//! | check | passes when |
//! | --- | --- |
//! | configuration | the daemon's configuration can fly (a pilot source, the tilt driver required, a thruster path) |
//! | estimate rate | at least `min_estimate_rate_hz` estimates accepted over the last `estimate_window_ms` |
//! | radio | the pilot's radio is not lost (always passes without a radio) |
//! | drivers | every required driver is alive |
//! | tilt encoder | an encoder reading has arrived, and over the last `tilt_window_ms` the measured tilt moved as the commanded tilt velocity says, within `tilt_tolerance_deg` |
//!
//! A check whose window has not filled yet (the daemon just started) fails
//! as "measuring". Everything here is fixed-size: the monitor runs on the
//! control thread.

use std::path::Path;

use atmo_core::config_file::Checker;

use crate::error::Result;

/// One arming check: its bit in [`crate::StepInputs::arming_failures`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ArmingCheck {
    Configuration = 0,
    EstimateRate = 1,
    Radio = 2,
    Drivers = 3,
    TiltEncoder = 4,
}

impl ArmingCheck {
    pub const ALL: [ArmingCheck; 5] = [
        ArmingCheck::Configuration,
        ArmingCheck::EstimateRate,
        ArmingCheck::Radio,
        ArmingCheck::Drivers,
        ArmingCheck::TiltEncoder,
    ];

    pub fn bit(self) -> u8 {
        1 << (self as u8)
    }

    pub fn name(self) -> &'static str {
        match self {
            Self::Configuration => "configuration",
            Self::EstimateRate => "estimate rate",
            Self::Radio => "radio",
            Self::Drivers => "drivers",
            Self::TiltEncoder => "tilt encoder",
        }
    }

    /// The status text of a refusal for this check.
    pub fn refusal(self) -> &'static str {
        match self {
            Self::Configuration => "arming refused: configuration cannot fly",
            Self::EstimateRate => "arming refused: estimate below its rate",
            Self::Radio => "arming refused: radio lost",
            Self::Drivers => "arming refused: a required driver is silent",
            Self::TiltEncoder => "arming refused: tilt encoder disagrees or is silent",
        }
    }

    /// The first failed check of a bit set, in [`Self::ALL`] order.
    pub fn first_failed(failures: u8) -> Option<Self> {
        Self::ALL.into_iter().find(|c| failures & c.bit() != 0)
    }
}

atmo_core::params! {
    /// `[arming]` of `config/daemon.toml`.
    #[derive(Debug, Clone, Copy, PartialEq)]
    pub struct ArmingSettings: Default {
        /// Fewest estimates per second to arm on.
        pub min_estimate_rate_hz: f64 = 50.0, range 1.0..=1000.0, unit "Hz";
        /// Window of the estimate rate.
        pub estimate_window_ms: u64 = 1000, range 100..=10_000, unit "ms";
        /// Window of the tilt encoder's agreement with the command.
        pub tilt_window_ms: u64 = 2000, range 100..=10_000, unit "ms";
        /// Largest difference between the measured and the commanded tilt
        /// motion over the window.
        pub tilt_tolerance_deg: f64 = 3.0, range 0.1..=45.0, unit "deg";
    }
}

impl ArmingSettings {
    /// Checks ranges; errors name `file` and the key (under `arming`).
    pub fn validate(&self, file: &Path) -> Result<()> {
        use atmo_core::params::Params as _;
        Ok(self.check(&Checker::new(file), "arming")?)
    }
}

/// Ticks of history kept: the longest window (10 s) at up to 400 Hz would
/// need more; the oldest sample then stands for the window's start (the
/// rate and the motion are measured over what is kept).
const HISTORY: usize = 1024;

/// One tick as the checks remember it.
#[derive(Debug, Clone, Copy, Default)]
struct Sample {
    now_ns: u64,
    /// Estimates accepted since start.
    estimates: u64,
    /// Measured tilt, rad (`None`: no encoder reading yet).
    tilt: Option<f64>,
    /// Tilt velocity commanded this tick, rad/s.
    tilt_velocity: f64,
}

/// What one tick tells the checks.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ArmingObservation {
    pub now_ns: u64,
    /// Estimates accepted since start (a counter).
    pub estimates_total: u64,
    pub pilot_lost: bool,
    pub driver_lost: bool,
    /// The tilt the flight stack measured this tick (`None`: no encoder
    /// reading has arrived).
    pub tilt: Option<f64>,
    /// The tilt velocity it commanded this tick, rad/s.
    pub tilt_velocity: f64,
}

/// The checks' state: a ring of the last ticks. Fixed size, no allocation
/// after [`ArmingMonitor::new`].
#[derive(Debug, Clone)]
pub struct ArmingMonitor {
    settings: ArmingSettings,
    configuration_ok: bool,
    history: Box<[Sample]>,
    /// Index of the next slot; `len` samples are valid.
    next: usize,
    len: usize,
    failures: u8,
}

impl ArmingMonitor {
    /// `configuration_ok`: the configuration check's verdict, found once at
    /// start (atmo-daemon's `DaemonConfig::flight_problem`).
    pub fn new(settings: ArmingSettings, configuration_ok: bool) -> Self {
        let mut monitor = Self {
            settings,
            configuration_ok,
            history: vec![Sample::default(); HISTORY].into_boxed_slice(),
            next: 0,
            len: 0,
            failures: 0,
        };
        monitor.failures = monitor.evaluate(false, false);
        monitor
    }

    /// The failed checks after the last observation (bits of [`ArmingCheck`]).
    pub fn failures(&self) -> u8 {
        self.failures
    }

    /// Records one tick and re-evaluates every check; returns the failed
    /// checks.
    pub fn observe(&mut self, o: &ArmingObservation) -> u8 {
        self.history[self.next] = Sample {
            now_ns: o.now_ns,
            estimates: o.estimates_total,
            tilt: o.tilt,
            tilt_velocity: o.tilt_velocity,
        };
        self.next = (self.next + 1) % HISTORY;
        self.len = (self.len + 1).min(HISTORY);
        self.failures = self.evaluate(o.pilot_lost, o.driver_lost);
        self.failures
    }

    /// The `age`-th newest sample (0: the newest).
    fn sample(&self, age: usize) -> Sample {
        self.history[(self.next + HISTORY - 1 - age) % HISTORY]
    }

    /// The newest sample and the oldest one no younger than `window_ns`
    /// before it (`None` while the history is shorter than the window).
    fn window(&self, window_ns: u64) -> Option<(Sample, usize)> {
        let newest = self.sample(0);
        (0..self.len).find_map(|age| {
            let s = self.sample(age);
            (newest.now_ns.saturating_sub(s.now_ns) >= window_ns).then_some((s, age))
        })
    }

    fn estimate_rate_ok(&self) -> bool {
        let window_ns = self.settings.estimate_window_ms * 1_000_000;
        self.window(window_ns).is_some_and(|(start, _)| {
            let newest = self.sample(0);
            let seconds = newest.now_ns.saturating_sub(start.now_ns) as f64 * 1e-9;
            let count = newest.estimates.saturating_sub(start.estimates) as f64;
            count / seconds >= self.settings.min_estimate_rate_hz
        })
    }

    /// Over the window, the measured tilt change equals the integral of the
    /// commanded tilt velocity (each tick's command held until the next).
    fn tilt_ok(&self) -> bool {
        let window_ns = self.settings.tilt_window_ms * 1_000_000;
        let Some((start, start_age)) = self.window(window_ns) else {
            return false;
        };
        let (Some(tilt_start), Some(tilt_now)) = (start.tilt, self.sample(0).tilt) else {
            return false;
        };
        let mut commanded = 0.0;
        for age in (1..=start_age).rev() {
            let (s, later) = (self.sample(age), self.sample(age - 1));
            if later.tilt.is_none() {
                return false;
            }
            commanded += s.tilt_velocity * later.now_ns.saturating_sub(s.now_ns) as f64 * 1e-9;
        }
        ((tilt_now - tilt_start) - commanded).abs() <= self.settings.tilt_tolerance_deg.to_radians()
    }

    fn evaluate(&self, pilot_lost: bool, driver_lost: bool) -> u8 {
        let verdicts = [
            (ArmingCheck::Configuration, self.configuration_ok),
            (
                ArmingCheck::EstimateRate,
                self.len > 0 && self.estimate_rate_ok(),
            ),
            (ArmingCheck::Radio, !pilot_lost),
            (ArmingCheck::Drivers, !driver_lost),
            (ArmingCheck::TiltEncoder, self.len > 0 && self.tilt_ok()),
        ];
        verdicts
            .into_iter()
            .filter(|(_, ok)| !ok)
            .fold(0, |bits, (check, _)| bits | check.bit())
    }
}

/// The checks as a diagnostics entry (`atmo/arming`): OK when all pass,
/// else ERROR naming the failed ones; one value per check, and the
/// configuration's problem if it has one. Allocates: not for the control
/// thread.
pub fn diagnostics(
    failures: u8,
    configuration_problem: Option<&str>,
) -> atmo_io::msg::DiagnosticStatus {
    use atmo_io::msg::{DiagnosticStatus, KeyValue};
    let failed: Vec<&str> = ArmingCheck::ALL
        .into_iter()
        .filter(|c| failures & c.bit() != 0)
        .map(ArmingCheck::name)
        .collect();
    let mut values: Vec<KeyValue> = ArmingCheck::ALL
        .into_iter()
        .map(|c| KeyValue {
            key: c.name().into(),
            value: if failures & c.bit() == 0 {
                "pass"
            } else {
                "fail"
            }
            .into(),
        })
        .collect();
    if let Some(problem) = configuration_problem {
        values.push(KeyValue {
            key: "configuration problem".into(),
            value: problem.into(),
        });
    }
    DiagnosticStatus {
        level: if failed.is_empty() {
            DiagnosticStatus::OK
        } else {
            DiagnosticStatus::ERROR
        },
        name: "atmo/arming".into(),
        message: if failed.is_empty() {
            "ready to arm".into()
        } else {
            format!("arming refused: {}", failed.join(", "))
        },
        hardware_id: String::new(),
        values,
    }
}

#[cfg(test)]
#[path = "arming_tests.rs"]
mod tests;
