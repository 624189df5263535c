//! Faults on the actuator side of the closed loop: what the rotors, the
//! tilt encoder and the ground-contact signal do differs from what the
//! flight stack commanded or believes (docs/faults.md, the actuator table).
//!
//! ```toml
//! [[faults.actuators.rotor]]        # rotor 2 at 60 % of its command from t = 3 s
//! t = 3.0
//! rotor = 2
//! scale = 0.6                       # 0: stopped
//! [[faults.actuators.rotor]]        # rotor 1 stuck at its command, 50 ms into the transition
//! mode = "transition"
//! delay = 0.05
//! rotor = 1
//! stuck = true
//! [[faults.actuators.tilt_encoder]] # the encoder reads the same count from t on
//! t = 2.0
//! stuck = true
//! [[faults.actuators.tilt_encoder]] # ... or `jump_counts` more than the truth
//! t = 2.0
//! jump_counts = 400.0
//! [[faults.actuators.contact]]      # contact reported though there is none
//! t = 1.0                           # (`missed`: none reported though there is)
//! duration = 0.5
//! kind = "false"
//! [[faults.actuators.tilt_slip]]    # the tilt motor turns, the arms stay: the
//! mode = "morphing"                 # encoder follows the command, the linkage holds
//! [[faults.actuators.tilt_jam]]     # the linkage jams: neither the arms nor the
//! mode = "morphing"                 # motor (nor its encoder) move from the onset
//! [[faults.actuators.radio]]        # no radio frame for `duration`
//! t = 1.0
//! duration = 1.0
//! ```
//!
//! With a `radio` fault the scenario's pilot reaches the flight stack as
//! the radio does onboard (PX4's `InputRc`, lost after the daemon's
//! `[rc] timeout_ms` of silence) instead of as a `PilotInput` stream.
//!
//! An onset is `t` (plant s) or the first tick in `mode` (a `Mode` name),
//! each plus `delay`. The faults act on the simulated I/O only, between the
//! plant and the flight stack: same scenario, same faults, same flight.

use std::path::Path;

use atmo_core::config_file::Checker;
use atmo_core::model::Input;
use atmo_flight::Mode;
use serde::Deserialize;

use crate::error::Result;

fn ns(t: f64) -> u64 {
    crate::sim_time::time_ns(t)
}

/// When a fault starts: `t`, or the first tick in `mode`, plus `delay`.
#[derive(Debug, Clone, Default, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Onset {
    pub t: Option<f64>,
    pub mode: Option<String>,
    #[serde(default)]
    pub delay: f64,
}

/// `[[faults.actuators.rotor]]`: one rotor's thrust scaled, or stuck.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct RotorFault {
    pub t: Option<f64>,
    pub mode: Option<String>,
    #[serde(default)]
    pub delay: f64,
    /// 1..=4, the project's numbering.
    pub rotor: usize,
    /// Fraction of the command the rotor delivers (0: stopped).
    #[serde(default = "RotorFault::default_scale")]
    pub scale: f64,
    /// The rotor keeps the command it had at the onset.
    #[serde(default)]
    pub stuck: bool,
}

impl RotorFault {
    fn default_scale() -> f64 {
        1.0
    }
}

/// `[[faults.actuators.tilt_encoder]]`: stuck, or offset by `jump_counts`.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct EncoderFault {
    pub t: Option<f64>,
    pub mode: Option<String>,
    #[serde(default)]
    pub delay: f64,
    #[serde(default)]
    pub stuck: bool,
    #[serde(default)]
    pub jump_counts: f64,
}

/// `[[faults.actuators.contact]]`: the contact signal wrong for `duration`.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ContactFault {
    pub t: Option<f64>,
    pub mode: Option<String>,
    #[serde(default)]
    pub delay: f64,
    pub duration: f64,
    /// `"false"`: contact reported without one; `"missed"`: none reported.
    pub kind: String,
}

/// `[[faults.actuators.tilt_slip]]`: from its onset the tilt motor turns
/// as commanded (the encoder, on the motor, counts it) but the arms stay.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct SlipFault {
    pub t: Option<f64>,
    pub mode: Option<String>,
    #[serde(default)]
    pub delay: f64,
}

/// `[[faults.actuators.tilt_jam]]`: from its onset the linkage does not
/// move whatever is commanded; the encoder, on the stalled motor, reads
/// the arms' true (unmoving) tilt.
pub type JamFault = SlipFault;

/// `[[faults.actuators.radio]]`: no radio frame for `duration`.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct RadioFault {
    pub t: Option<f64>,
    pub mode: Option<String>,
    #[serde(default)]
    pub delay: f64,
    pub duration: f64,
}

/// `[faults.actuators]`.
#[derive(Debug, Clone, Default, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ActuatorFaults {
    #[serde(default)]
    pub rotor: Vec<RotorFault>,
    #[serde(default)]
    pub tilt_encoder: Vec<EncoderFault>,
    #[serde(default)]
    pub contact: Vec<ContactFault>,
    #[serde(default)]
    pub tilt_slip: Vec<SlipFault>,
    #[serde(default)]
    pub tilt_jam: Vec<JamFault>,
    #[serde(default)]
    pub radio: Vec<RadioFault>,
}

fn check_onset(
    c: &Checker<'_>,
    key: &str,
    t: Option<f64>,
    mode: Option<&String>,
    delay: f64,
    duration: f64,
) -> Result<()> {
    match (t, mode) {
        (Some(t), None) => c.within(&format!("{key}.t"), t, 0.0, duration)?,
        (None, Some(mode)) => {
            let names: Vec<&str> = Mode::ALL.iter().map(|m| m.name()).collect();
            c.one_of(&format!("{key}.mode"), mode, &names)?;
        }
        _ => {
            return Err(c
                .fail(key, "exactly one of `t` and `mode`", "both or neither")
                .into());
        }
    }
    c.range(&format!("{key}.delay"), delay, 0.0..=duration, "s")?;
    Ok(())
}

impl ActuatorFaults {
    /// Range checks; errors name `file` and the key
    /// (`faults.actuators.rotor[0].scale`).
    ///
    /// # Errors
    /// A value out of range, an onset with both or neither of `t` and `mode`.
    pub fn validate(&self, file: &Path, duration: f64) -> Result<()> {
        let c = Checker::new(file);
        for (i, f) in self.rotor.iter().enumerate() {
            let key = format!("faults.actuators.rotor[{i}]");
            check_onset(&c, &key, f.t, f.mode.as_ref(), f.delay, duration)?;
            c.range(&format!("{key}.rotor"), f.rotor, 1..=4, "")?;
            c.range(&format!("{key}.scale"), f.scale, 0.0..=1.0, "")?;
        }
        for (i, f) in self.tilt_encoder.iter().enumerate() {
            let key = format!("faults.actuators.tilt_encoder[{i}]");
            check_onset(&c, &key, f.t, f.mode.as_ref(), f.delay, duration)?;
            c.range(
                &format!("{key}.jump_counts"),
                f.jump_counts,
                -1e6..=1e6,
                "counts",
            )?;
        }
        for (i, f) in self.contact.iter().enumerate() {
            let key = format!("faults.actuators.contact[{i}]");
            check_onset(&c, &key, f.t, f.mode.as_ref(), f.delay, duration)?;
            c.range(&format!("{key}.duration"), f.duration, 1e-3..=duration, "s")?;
            c.one_of(&format!("{key}.kind"), &f.kind, &["false", "missed"])?;
        }
        for (i, f) in self.tilt_slip.iter().enumerate() {
            let key = format!("faults.actuators.tilt_slip[{i}]");
            check_onset(&c, &key, f.t, f.mode.as_ref(), f.delay, duration)?;
        }
        for (i, f) in self.tilt_jam.iter().enumerate() {
            let key = format!("faults.actuators.tilt_jam[{i}]");
            check_onset(&c, &key, f.t, f.mode.as_ref(), f.delay, duration)?;
        }
        for (i, f) in self.radio.iter().enumerate() {
            let key = format!("faults.actuators.radio[{i}]");
            check_onset(&c, &key, f.t, f.mode.as_ref(), f.delay, duration)?;
            c.range(&format!("{key}.duration"), f.duration, 1e-3..=duration, "s")?;
        }
        Ok(())
    }
}

/// One fault's onset at run time.
#[derive(Debug, Clone, Copy, Default)]
struct Start {
    at_ns: Option<u64>,
}

impl Start {
    fn of(t: Option<f64>, delay: f64) -> Self {
        Self {
            at_ns: t.map(|t| ns(t + delay)),
        }
    }

    fn on_mode(&mut self, mode: Option<&String>, delay: f64, now: Mode, now_ns: u64) {
        if self.at_ns.is_none() && mode.is_some_and(|m| m == now.name()) {
            self.at_ns = Some(now_ns + ns(delay));
        }
    }

    fn active(self, now_ns: u64) -> bool {
        self.at_ns.is_some_and(|at| now_ns >= at)
    }
}

/// The runtime side of [`ActuatorFaults`].
#[derive(Debug, Clone, Default)]
pub struct ActuatorInjector {
    config: ActuatorFaults,
    rotor: Vec<(Start, Option<f64>)>,
    encoder: Vec<(Start, Option<f64>)>,
    contact: Vec<Start>,
    slip: Vec<Start>,
    jam: Vec<Start>,
    radio: Vec<Start>,
    /// While slipping: the tilt the encoder counts (the arms' at the onset
    /// plus every commanded rate since), rad.
    slipped_tilt: Option<f64>,
    slip_rate: f64,
    slip_sensed_ns: Option<u64>,
}

impl ActuatorInjector {
    pub fn new(config: &ActuatorFaults) -> Self {
        Self {
            config: config.clone(),
            rotor: config
                .rotor
                .iter()
                .map(|f| (Start::of(f.t, f.delay), None))
                .collect(),
            encoder: config
                .tilt_encoder
                .iter()
                .map(|f| (Start::of(f.t, f.delay), None))
                .collect(),
            contact: config
                .contact
                .iter()
                .map(|f| Start::of(f.t, f.delay))
                .collect(),
            slip: config
                .tilt_slip
                .iter()
                .map(|f| Start::of(f.t, f.delay))
                .collect(),
            jam: config
                .tilt_jam
                .iter()
                .map(|f| Start::of(f.t, f.delay))
                .collect(),
            radio: config
                .radio
                .iter()
                .map(|f| Start::of(f.t, f.delay))
                .collect(),
            slipped_tilt: None,
            slip_rate: 0.0,
            slip_sensed_ns: None,
        }
    }

    /// Whether the scenario's pilot comes as the radio (a radio fault).
    pub fn has_radio(&self) -> bool {
        !self.config.radio.is_empty()
    }

    /// Whether the radio is silent at `now_ns`.
    pub fn radio_silent(&self, now_ns: u64) -> bool {
        self.config.radio.iter().zip(&self.radio).any(|(f, start)| {
            start
                .at_ns
                .is_some_and(|at| (at..at + ns(f.duration)).contains(&now_ns))
        })
    }

    fn slipping(&self, now_ns: u64) -> bool {
        self.slip.iter().any(|s| s.active(now_ns))
    }

    /// What the tilt motor does of the commanded `rate`: jammed, nothing;
    /// slipping, the arms hold (rate 0) and the rate is counted by
    /// [`Self::sense_slip`].
    pub fn tilt_rate(&mut self, now_ns: u64, rate: f64) -> f64 {
        if self.jam.iter().any(|s| s.active(now_ns)) {
            return 0.0;
        }
        if !self.slipping(now_ns) {
            return rate;
        }
        self.slip_rate = rate;
        0.0
    }

    /// The tilt the encoder counts at `now_ns` for arms at `tilt` (rad,
    /// within `[0, tilt_max]`): slipping, the arms' tilt at the onset plus
    /// the commanded rate integrated since; `None` while not slipping.
    pub fn sense_slip(&mut self, now_ns: u64, tilt: f64, tilt_max: f64) -> Option<f64> {
        if !self.slipping(now_ns) {
            return None;
        }
        let dt = self
            .slip_sensed_ns
            .map_or(0.0, |t| now_ns.saturating_sub(t) as f64 * 1e-9);
        self.slip_sensed_ns = Some(now_ns);
        let counted = self.slipped_tilt.get_or_insert(tilt);
        *counted = (*counted + self.slip_rate * dt).clamp(0.0, tilt_max);
        Some(*counted)
    }

    /// The flight stack's mode at a tick (onsets by mode).
    pub fn on_mode(&mut self, mode: Mode, now_ns: u64) {
        let c = &self.config;
        for (f, s) in c.rotor.iter().zip(&mut self.rotor) {
            s.0.on_mode(f.mode.as_ref(), f.delay, mode, now_ns);
        }
        for (f, s) in c.tilt_encoder.iter().zip(&mut self.encoder) {
            s.0.on_mode(f.mode.as_ref(), f.delay, mode, now_ns);
        }
        for (f, s) in c.contact.iter().zip(&mut self.contact) {
            s.on_mode(f.mode.as_ref(), f.delay, mode, now_ns);
        }
        for (f, s) in c.tilt_slip.iter().zip(&mut self.slip) {
            s.on_mode(f.mode.as_ref(), f.delay, mode, now_ns);
        }
        for (f, s) in c.tilt_jam.iter().zip(&mut self.jam) {
            s.on_mode(f.mode.as_ref(), f.delay, mode, now_ns);
        }
        for (f, s) in c.radio.iter().zip(&mut self.radio) {
            s.on_mode(f.mode.as_ref(), f.delay, mode, now_ns);
        }
    }

    /// What the rotors deliver of the commanded `u`.
    pub fn rotors(&mut self, now_ns: u64, mut u: Input) -> Input {
        for (f, (start, held)) in self.config.rotor.iter().zip(&mut self.rotor) {
            if !start.active(now_ns) {
                continue;
            }
            let i = f.rotor - 1;
            if f.stuck {
                u[i] = *held.get_or_insert(u[i]);
            }
            u[i] *= f.scale;
        }
        u
    }

    /// What the encoder reads of the true `counts`.
    pub fn encoder(&mut self, now_ns: u64, mut counts: f64) -> f64 {
        for (f, (start, held)) in self.config.tilt_encoder.iter().zip(&mut self.encoder) {
            if !start.active(now_ns) {
                continue;
            }
            if f.stuck {
                counts = *held.get_or_insert(counts);
            }
            counts += f.jump_counts;
        }
        counts
    }

    /// What the contact signal says of the true `contact`.
    pub fn contact(&self, now_ns: u64, contact: bool) -> bool {
        for (f, start) in self.config.contact.iter().zip(&self.contact) {
            let Some(at) = start.at_ns else { continue };
            if (at..at + ns(f.duration)).contains(&now_ns) {
                return f.kind == "false";
            }
        }
        contact
    }
}
