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

use std::marker::PhantomData;
use std::path::Path;

use atmo_core::config_file::Checker;
use atmo_core::model::Input;
use atmo_core::params::{ParamInfo, Params};
use atmo_flight::Mode;
use serde::de::{self, DeserializeSeed, IntoDeserializer, MapAccess, Visitor};
use serde::{Deserialize, Deserializer};

use crate::error::Result;

fn ns(t: f64) -> u64 {
    crate::sim_time::time_ns(t)
}

atmo_core::params! {
    /// When a fault starts: `t`, or the first tick in `mode`, plus `delay`
    /// (the keys every fault table has beside its own, see [`Timed`]).
    /// Both bounds are the scenario's duration, checked by
    /// [`ActuatorFaults::validate`].
    #[derive(Debug, Clone, Default, PartialEq)]
    pub struct Onset {
        /// Plant time of the onset (exactly one of `t` and `mode`).
        pub t: Option<f64> = None, unit "s";
        /// A `Mode` name: the onset is the first tick in it.
        pub mode: Option<String> = None;
        /// Added to the onset.
        pub delay: f64 = 0.0, unit "s";
    }
}

impl Onset {
    /// Exactly one of `t` and `mode`, `t` and `delay` within the
    /// scenario's `duration`, `mode` a mode's name; errors name `key.<field>`.
    pub(crate) fn check_within(&self, c: &Checker<'_>, key: &str, duration: f64) -> Result<()> {
        match (self.t, &self.mode) {
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
        c.range(&format!("{key}.delay"), self.delay, 0.0..=duration, "s")?;
        Ok(())
    }
}

/// One fault table: its [`Onset`]'s keys and the fault's own, side by side
/// in the file (`t = 3.0` beside `rotor = 2`). Read strictly: a key of
/// neither is an error naming its path and line.
#[derive(Debug, Clone, PartialEq)]
pub struct Timed<F> {
    pub onset: Onset,
    pub fault: F,
}

impl<F> std::ops::Deref for Timed<F> {
    type Target = F;
    fn deref(&self) -> &F {
        &self.fault
    }
}

impl<'de, F: Deserialize<'de>> Deserialize<'de> for Timed<F> {
    fn deserialize<D: Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        struct TableVisitor<F>(PhantomData<F>);
        impl<'de, F: Deserialize<'de>> Visitor<'de> for TableVisitor<F> {
            type Value = Timed<F>;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("a fault table")
            }
            fn visit_map<A: MapAccess<'de>>(
                self,
                map: A,
            ) -> std::result::Result<Timed<F>, A::Error> {
                let mut onset = Onset::default();
                let mut seen = [false; 3];
                let keys = OnsetKeys {
                    map,
                    onset: &mut onset,
                    seen: &mut seen,
                };
                let fault = F::deserialize(de::value::MapAccessDeserializer::new(keys))?;
                Ok(Timed { onset, fault })
            }
        }
        d.deserialize_map(TableVisitor(PhantomData))
    }
}

/// A fault table's keys as the fault sees them: the onset's are read into
/// `onset` on the way (with their own paths and lines in errors), the
/// rest handed to the fault's strict reader.
struct OnsetKeys<'a, A> {
    map: A,
    onset: &'a mut Onset,
    seen: &'a mut [bool; 3],
}

impl<'de, A: MapAccess<'de>> MapAccess<'de> for OnsetKeys<'_, A> {
    type Error = A::Error;

    fn next_key_seed<K: DeserializeSeed<'de>>(
        &mut self,
        seed: K,
    ) -> std::result::Result<Option<K::Value>, A::Error> {
        while let Some(key) = self.map.next_key::<String>()? {
            let Some(i) = ["t", "mode", "delay"].iter().position(|k| *k == key) else {
                // The fault's reader lists its own keys; name the onset's too.
                return seed
                    .deserialize(IntoDeserializer::<A::Error>::into_deserializer(key))
                    .map(Some)
                    .map_err(|e| {
                        de::Error::custom(format!(
                            "{}, or the onset's `t`, `mode`, `delay`",
                            e.to_string().trim_end()
                        ))
                    });
            };
            if std::mem::replace(&mut self.seen[i], true) {
                return Err(de::Error::duplicate_field(["t", "mode", "delay"][i]));
            }
            match i {
                0 => self.onset.t = Some(self.map.next_value()?),
                1 => self.onset.mode = Some(self.map.next_value()?),
                _ => self.onset.delay = self.map.next_value()?,
            }
        }
        Ok(None)
    }

    fn next_value_seed<V: DeserializeSeed<'de>>(
        &mut self,
        seed: V,
    ) -> std::result::Result<V::Value, A::Error> {
        self.map.next_value_seed(seed)
    }
}

impl<F: Params> Params for Timed<F> {
    fn check(&self, c: &Checker, prefix: &str) -> atmo_core::Result<()> {
        self.fault.check(c, prefix)
    }

    fn list(prefix: &str, out: &mut Vec<ParamInfo>) {
        Onset::list(prefix, out);
        F::list(prefix, out);
    }
}

atmo_core::params! {
    /// `[[faults.actuators.rotor]]`: one rotor's thrust scaled, or stuck.
    #[derive(Debug, Clone, PartialEq)]
    pub struct RotorFault {
        /// 1..=4, the project's numbering.
        pub rotor: usize, range 1..=4;
        /// Fraction of the command the rotor delivers (0: stopped).
        pub scale: f64 = 1.0, range 0.0..=1.0;
        /// The rotor keeps the command it had at the onset.
        pub stuck: bool = false;
    }
}

atmo_core::params! {
    /// `[[faults.actuators.tilt_encoder]]`: stuck, or offset by `jump_counts`.
    #[derive(Debug, Clone, PartialEq)]
    pub struct EncoderFault {
        /// The encoder keeps the count it had at the onset.
        pub stuck: bool = false;
        /// Added to every count from the onset.
        pub jump_counts: f64 = 0.0, range -1e6..=1e6, unit "counts";
    }
}

/// What a contact fault reports.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ContactKind {
    /// Contact reported without one.
    False,
    /// None reported though there is one.
    Missed,
}

atmo_core::params! {
    /// `[[faults.actuators.contact]]`: the contact signal wrong for `duration`.
    #[derive(Debug, Clone, PartialEq)]
    pub struct ContactFault {
        /// How long (at most the scenario's duration).
        pub duration: f64, unit "s";
        /// `"false"`: contact reported without one; `"missed"`: none reported.
        pub kind: ContactKind;
    }
}

atmo_core::params! {
    /// `[[faults.actuators.tilt_slip]]` and `[[faults.actuators.tilt_jam]]`:
    /// nothing but the onset.
    #[derive(Debug, Clone, PartialEq)]
    pub struct LinkageFault {}
}

/// `[[faults.actuators.tilt_slip]]`: from its onset the tilt motor turns
/// as commanded (the encoder, on the motor, counts it) but the arms stay.
pub type SlipFault = LinkageFault;

/// `[[faults.actuators.tilt_jam]]`: from its onset the linkage does not
/// move whatever is commanded; the encoder, on the stalled motor, reads
/// the arms' true (unmoving) tilt.
pub type JamFault = LinkageFault;

atmo_core::params! {
    /// `[[faults.actuators.radio]]`: no radio frame for `duration`.
    #[derive(Debug, Clone, PartialEq)]
    pub struct RadioFault {
        /// How long (at most the scenario's duration).
        pub duration: f64, unit "s";
    }
}

atmo_core::params! {
    /// `[faults.actuators]`.
    #[derive(Debug, Clone, PartialEq)]
    pub struct ActuatorFaults: Default {
        pub rotor: Vec<Timed<RotorFault>> = Vec::new();
        pub tilt_encoder: Vec<Timed<EncoderFault>> = Vec::new();
        pub contact: Vec<Timed<ContactFault>> = Vec::new();
        pub tilt_slip: Vec<Timed<SlipFault>> = Vec::new();
        pub tilt_jam: Vec<Timed<JamFault>> = Vec::new();
        pub radio: Vec<Timed<RadioFault>> = Vec::new();
    }
}

impl ActuatorFaults {
    /// Range checks; errors name `file` and the key
    /// (`faults.actuators.rotor[0].scale`).
    ///
    /// # Errors
    /// A value out of range, an onset with both or neither of `t` and `mode`.
    pub fn validate(&self, file: &Path, duration: f64) -> Result<()> {
        let c = Checker::new(file);
        let prefix = "faults.actuators";
        self.check(&c, prefix)?;
        let onsets = [
            (
                "rotor",
                self.rotor.iter().map(|f| &f.onset).collect::<Vec<_>>(),
            ),
            (
                "tilt_encoder",
                self.tilt_encoder.iter().map(|f| &f.onset).collect(),
            ),
            ("contact", self.contact.iter().map(|f| &f.onset).collect()),
            (
                "tilt_slip",
                self.tilt_slip.iter().map(|f| &f.onset).collect(),
            ),
            ("tilt_jam", self.tilt_jam.iter().map(|f| &f.onset).collect()),
            ("radio", self.radio.iter().map(|f| &f.onset).collect()),
        ];
        for (table, list) in onsets {
            for (i, onset) in list.into_iter().enumerate() {
                onset.check_within(&c, &format!("{prefix}.{table}[{i}]"), duration)?;
            }
        }
        let lasting = [
            (
                "contact",
                self.contact.iter().map(|f| f.duration).collect::<Vec<_>>(),
            ),
            ("radio", self.radio.iter().map(|f| f.duration).collect()),
        ];
        for (table, list) in lasting {
            for (i, length) in list.into_iter().enumerate() {
                let key = format!("{prefix}.{table}[{i}].duration");
                c.range(&key, length, 1e-3..=duration, "s")?;
            }
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

    fn on_mode(&mut self, onset: &Onset, now: Mode, now_ns: u64) {
        if self.at_ns.is_none() && onset.mode.as_ref().is_some_and(|m| m == now.name()) {
            self.at_ns = Some(now_ns + ns(onset.delay));
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
                .map(|f| (Start::of(f.onset.t, f.onset.delay), None))
                .collect(),
            encoder: config
                .tilt_encoder
                .iter()
                .map(|f| (Start::of(f.onset.t, f.onset.delay), None))
                .collect(),
            contact: config
                .contact
                .iter()
                .map(|f| Start::of(f.onset.t, f.onset.delay))
                .collect(),
            slip: config
                .tilt_slip
                .iter()
                .map(|f| Start::of(f.onset.t, f.onset.delay))
                .collect(),
            jam: config
                .tilt_jam
                .iter()
                .map(|f| Start::of(f.onset.t, f.onset.delay))
                .collect(),
            radio: config
                .radio
                .iter()
                .map(|f| Start::of(f.onset.t, f.onset.delay))
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
            s.0.on_mode(&f.onset, mode, now_ns);
        }
        for (f, s) in c.tilt_encoder.iter().zip(&mut self.encoder) {
            s.0.on_mode(&f.onset, mode, now_ns);
        }
        for (f, s) in c.contact.iter().zip(&mut self.contact) {
            s.on_mode(&f.onset, mode, now_ns);
        }
        for (f, s) in c.tilt_slip.iter().zip(&mut self.slip) {
            s.on_mode(&f.onset, mode, now_ns);
        }
        for (f, s) in c.tilt_jam.iter().zip(&mut self.jam) {
            s.on_mode(&f.onset, mode, now_ns);
        }
        for (f, s) in c.radio.iter().zip(&mut self.radio) {
            s.on_mode(&f.onset, mode, now_ns);
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
                return f.kind == ContactKind::False;
            }
        }
        contact
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_unknown_key_beside_an_onset_names_both_kinds_of_key() {
        let text = "[[rotor]]\nmode = \"flight\"\nrotor = 1\nspeed = 2.0\n";
        let err = atmo_core::config_file::parse_toml::<ActuatorFaults>(text, Path::new("f.toml"))
            .unwrap_err()
            .to_string();
        assert!(err.contains("`rotor[0]`") && err.contains("speed"), "{err}");
        assert!(err.contains("`t`, `mode`, `delay`"), "{err}");
        let ok = "[[rotor]]\nrotor = 2\nt = 1.0\nscale = 0.5\ndelay = 0.1\n";
        let f: ActuatorFaults =
            atmo_core::config_file::parse_toml(ok, Path::new("f.toml")).unwrap();
        assert_eq!(
            (f.rotor[0].onset.t, f.rotor[0].onset.delay),
            (Some(1.0), 0.1)
        );
        assert_eq!((f.rotor[0].rotor, f.rotor[0].scale), (2, 0.5));
    }
}
