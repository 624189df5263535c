//! The radio as a pilot source: PX4's `InputRc` (raw pulse widths per
//! channel) mapped to the flight stack's [`PilotInput`] by the daemon
//! config's `[rc]` table.
//!
//! Shipped defaults: the ATMO authors' Futaba T18SZ mapping
//! (mandralis/ATMO, `atmo_ws/src/atmo/atmo/mpc/parameters.py`; their
//! 0-based indices into `values` are the channel numbers here minus one):
//! roll 1, pitch 2, throttle 3, yaw 4, MPC switch 8, offboard switch 9,
//! manual tilt lever 10, encoder reset switch 12,
//! pulses 1094..1934 us centred at 1514 us, 0.75 m/s and 45 deg/s at full
//! stick, with their signs (pitch forward is north negative, and so on:
//! each stick `reversed`). The kill switch is not in the authors' code
//! (PX4's own kill switch cut their motors); channel 5 high is this
//! mapping's default and must be set to the radio's kill switch.
//!
//! Sticks: a pulse within `deadband_us` of `center_us` is 0; beyond it the
//! stick grows linearly to +-1 at `max_us` / `min_us` (each side scaled on
//! its own, clamped). The vertical stick also gives the throttle, its
//! upper half only (0 at centre, 1 at full up): a spring-less throttle
//! stick left at centre must not read as "take off" (the flight stack
//! takes off at throttle 0.5).
//!
//! The manual tilt lever (a stick, -1..1, positive towards the drive
//! configuration) moves the arms while the stack is disarmed, as the
//! authors' manual mode drove the tilt motor from it; the encoder reset
//! switch asks the tilt driver to home again (the authors zeroed the
//! counter with it in the drive configuration; this driver finds home on
//! its switch). Both are auxiliary: a receiver that does not deliver their
//! channels leaves them at rest instead of losing the frame.
//!
//! Switches: on when the normalized pulse is above `switch_threshold`
//! (`on = "high"`) or below minus it (`on = "low"`); a three-position
//! switch's middle is off.
//!
//! The kill switch disarms at once and stays latched: the robot re-arms
//! only once the kill switch is off *and* the offboard switch has been
//! off (so releasing the kill switch alone never restarts the rotors).
//!
//! Lost radio: PX4's `rc_lost` or `rc_failsafe` (its "true" is reliable),
//! or no usable frame for `timeout_ms` ([`crate::inputs::InputLatch`]).
//! A frame whose mapped channels are missing (`channel_count` too small)
//! or outside 800..2200 us is rejected and counted, never used.
//!
//! Mapping is pure, allocation-free and never panics: it runs on the
//! control thread.

use std::path::Path;

use atmo_core::config_file::Checker;
use atmo_core::params::Params as _;
use atmo_io::msg::InputRc;
use serde::Deserialize;

use crate::error::Result;
use crate::flight_stack::PilotInput;

/// A pulse outside this range is no servo pulse (a missing or broken
/// channel), us.
pub const PLAUSIBLE_PULSE_US: std::ops::RangeInclusive<u16> = 800..=2200;

/// The highest channel a mapping may read.
const MAX_CHANNEL: u32 = InputRc::RC_INPUT_MAX_CHANNELS as u32;

atmo_core::params! {
    /// One stick: its channel (1-based, as on the radio and in PX4's
    /// `RC_MAP_*`) and whether its sign is turned.
    #[derive(Debug, Clone, Copy, PartialEq, Eq)]
    pub struct Stick {
        /// 1-based channel.
        pub channel: u32, range 1..=MAX_CHANNEL;
        /// Whether the stick's sign is turned.
        pub reversed: bool = false;
    }
}

/// Which end of a switch's travel is "on".
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SwitchOn {
    High,
    Low,
}

atmo_core::params! {
    /// One switch: its channel (1-based) and the position that is "on".
    #[derive(Debug, Clone, Copy, PartialEq, Eq)]
    pub struct Switch {
        /// 1-based channel.
        pub channel: u32, range 1..=MAX_CHANNEL;
        /// `high` or `low`: the end of travel that is on.
        pub on: SwitchOn;
    }
}

const fn stick(channel: u32, reversed: bool) -> Stick {
    Stick { channel, reversed }
}

const fn switch_high(channel: u32) -> Switch {
    Switch {
        channel,
        on: SwitchOn::High,
    }
}

atmo_core::params! {
    /// `[rc.sticks]`: the velocity command's axes (NED world frame, as the
    /// flight stack's pilot input) and the yaw rate (FRD, positive right).
    #[derive(Debug, Clone, Copy, PartialEq, Eq)]
    pub struct Sticks: Default {
        pub north: Stick = stick(2, true);
        pub east: Stick = stick(1, true);
        /// Up (negative NED z); its upper half is also the throttle.
        pub up: Stick = stick(3, false);
        pub yaw: Stick = stick(4, true);
        /// The manual tilt lever (auxiliary).
        pub tilt: Stick = stick(10, false);
    }
}

atmo_core::params! {
    /// `[rc.switches]`.
    #[derive(Debug, Clone, Copy, PartialEq, Eq)]
    pub struct Switches: Default {
        /// Offboard: the daemon flies (with the kill switch off, this is arming).
        pub offboard: Switch = switch_high(9);
        /// MPC on: off in the air is a failsafe (the backup controller's
        /// level descent, `backup_control`).
        pub mpc: Switch = switch_high(8);
        /// Kill: disarmed at once, latched until the offboard switch is off.
        pub kill: Switch = switch_high(5);
        /// Home the tilt driver again, while disarmed (auxiliary).
        pub encoder_reset: Switch = switch_high(12);
    }
}

/// The plausible pulses' bounds, us.
const PULSE_LO: u32 = *PLAUSIBLE_PULSE_US.start() as u32;
const PULSE_HI: u32 = *PLAUSIBLE_PULSE_US.end() as u32;

atmo_core::params! {
    /// `[rc]` of `config/daemon.toml`: how `px4_msgs/InputRc` becomes the
    /// pilot input (used when `ros2.topics.rc` is enabled).
    #[derive(Debug, Clone, Copy, PartialEq)]
    pub struct RcConfig: Default {
        /// No usable frame for this long: the radio is lost.
        pub timeout_ms: u64 = 300, range 20..=5000, unit "ms";
        /// Pulse at full stick down / left.
        pub min_us: u32 = 1094, range PULSE_LO..=PULSE_HI, unit "us";
        /// Pulse at the stick's centre.
        pub center_us: u32 = 1514, range *min_us + 1..=PULSE_HI, unit "us";
        /// Pulse at full stick up / right.
        pub max_us: u32 = 1934, range *center_us + 1..=PULSE_HI, unit "us";
        /// Half-width of the band around the centre that reads as 0 (at
        /// most half the shorter half travel).
        pub deadband_us: u32 = 10,
            range 0..=(*center_us - *min_us).min(*max_us - *center_us) / 2, unit "us";
        /// A switch is on beyond this fraction of its half travel.
        pub switch_threshold: f64 = 0.5, range 0.05..=0.95;
        /// Horizontal speed at full stick (each axis).
        pub max_horizontal_speed: f64 = 0.75, range 0.0..=5.0, unit "m/s";
        /// Vertical speed at full stick.
        pub max_vertical_speed: f64 = 0.75, range 0.0..=3.0, unit "m/s";
        /// Yaw rate at full stick.
        pub max_yaw_rate_deg_s: f64 = 45.0, range 0.0..=360.0, unit "deg/s";
        pub sticks: Sticks = Sticks::default();
        pub switches: Switches = Switches::default();
    }
    check |rc, c, prefix| {
        let channels = rc.channels();
        for (i, (name, channel)) in channels.iter().enumerate() {
            if let Some((other, _)) = channels[..i].iter().find(|(_, ch)| ch == channel) {
                return Err(c.fail(
                    &atmo_core::params::key(prefix, name),
                    format!(
                        "a channel no other function uses ({} is {channel})",
                        atmo_core::params::key(prefix, other)
                    ),
                    channel,
                ));
            }
        }
        Ok(())
    }
}

impl RcConfig {
    /// Every mapped channel with its key in `[rc]`, sticks first.
    fn channels(&self) -> [(&'static str, u32); 9] {
        let (s, w) = (&self.sticks, &self.switches);
        [
            ("sticks.north.channel", s.north.channel),
            ("sticks.east.channel", s.east.channel),
            ("sticks.up.channel", s.up.channel),
            ("sticks.yaw.channel", s.yaw.channel),
            ("sticks.tilt.channel", s.tilt.channel),
            ("switches.offboard.channel", w.offboard.channel),
            ("switches.mpc.channel", w.mpc.channel),
            ("switches.kill.channel", w.kill.channel),
            ("switches.encoder_reset.channel", w.encoder_reset.channel),
        ]
    }

    /// Checks ranges and consistency; errors name `file` and the key
    /// (under `rc`).
    pub fn validate(&self, file: &Path) -> Result<()> {
        Ok(self.check(&Checker::new(file), "rc")?)
    }
}

/// Why a frame was not used (counted by the daemon).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RcReject {
    /// The receiver delivers fewer channels than the mapping reads.
    MissingChannel { channel: u32, channel_count: u8 },
    /// A mapped channel's pulse is no servo pulse.
    ImplausiblePulse { channel: u32, pulse_us: u16 },
}

impl std::fmt::Display for RcReject {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::MissingChannel {
                channel,
                channel_count,
            } => write!(
                f,
                "channel {channel} is mapped but the receiver delivers {channel_count}"
            ),
            Self::ImplausiblePulse { channel, pulse_us } => write!(
                f,
                "channel {channel}: {pulse_us} us is outside {}..{} us",
                PLAUSIBLE_PULSE_US.start(),
                PLAUSIBLE_PULSE_US.end()
            ),
        }
    }
}

/// One usable frame as the flight stack's pilot input.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RcReading {
    pub pilot: PilotInput,
    /// The manual tilt lever, -1..1 (0 if its channel is not delivered).
    pub tilt_lever: f64,
    /// The encoder reset switch (off if its channel is not delivered).
    pub rehome_tilt: bool,
    /// PX4 says the radio is lost (`rc_lost` or `rc_failsafe`): the values
    /// are the receiver's failsafe values or stale, not the pilot's.
    pub lost: bool,
}

/// The mapping with its one piece of state, the kill latch.
#[derive(Debug, Clone, Copy)]
pub struct RcPilot {
    config: RcConfig,
    kill_latched: bool,
}

impl RcPilot {
    /// `config` must have passed [`RcConfig::validate`].
    pub fn new(config: RcConfig) -> Self {
        Self {
            config,
            kill_latched: false,
        }
    }

    /// Whether the kill switch has disarmed the robot and re-arming waits
    /// for the offboard switch to go off.
    pub fn kill_latched(&self) -> bool {
        self.kill_latched
    }

    fn pulse(rc: &InputRc, channel: u32) -> std::result::Result<u16, RcReject> {
        let index = channel.saturating_sub(1) as usize;
        if index >= usize::from(rc.channel_count) || index >= rc.values.len() {
            return Err(RcReject::MissingChannel {
                channel,
                channel_count: rc.channel_count,
            });
        }
        let pulse_us = rc.values[index];
        if PLAUSIBLE_PULSE_US.contains(&pulse_us) {
            Ok(pulse_us)
        } else {
            Err(RcReject::ImplausiblePulse { channel, pulse_us })
        }
    }

    /// A pulse as -1..1: 0 within the dead band, each side scaled on its own.
    fn normalized(&self, pulse_us: u16) -> f64 {
        let c = &self.config;
        let (p, centre, band) = (
            f64::from(pulse_us),
            f64::from(c.center_us),
            f64::from(c.deadband_us),
        );
        let offset = p - centre;
        if offset.abs() <= band {
            return 0.0;
        }
        let span = if offset > 0.0 {
            f64::from(c.max_us) - centre - band
        } else {
            centre - f64::from(c.min_us) - band
        };
        ((offset.abs() - band) / span).min(1.0).copysign(offset)
    }

    fn stick(&self, rc: &InputRc, stick: Stick) -> std::result::Result<f64, RcReject> {
        let v = self.normalized(Self::pulse(rc, stick.channel)?);
        Ok(if stick.reversed { -v } else { v })
    }

    /// An auxiliary channel: one the receiver does not deliver is at rest.
    fn auxiliary<T: Default>(
        read: std::result::Result<T, RcReject>,
    ) -> std::result::Result<T, RcReject> {
        match read {
            Err(RcReject::MissingChannel { .. }) => Ok(T::default()),
            other => other,
        }
    }

    fn switch(&self, rc: &InputRc, switch: Switch) -> std::result::Result<bool, RcReject> {
        let v = self.normalized(Self::pulse(rc, switch.channel)?);
        let t = self.config.switch_threshold;
        Ok(match switch.on {
            SwitchOn::High => v > t,
            SwitchOn::Low => v < -t,
        })
    }

    /// The pilot input of one frame, or why it cannot be used. Updates the
    /// kill latch only for a usable frame.
    pub fn map(&mut self, rc: &InputRc) -> std::result::Result<RcReading, RcReject> {
        let c = self.config;
        let (s, w) = (&c.sticks, &c.switches);
        let north = self.stick(rc, s.north)?;
        let east = self.stick(rc, s.east)?;
        let up = self.stick(rc, s.up)?;
        let yaw = self.stick(rc, s.yaw)?;
        let offboard = self.switch(rc, w.offboard)?;
        let mpc_enabled = self.switch(rc, w.mpc)?;
        let kill = self.switch(rc, w.kill)?;
        let tilt_lever = Self::auxiliary(self.stick(rc, s.tilt))?;
        let rehome_tilt = Self::auxiliary(self.switch(rc, w.encoder_reset))?;
        let lost = rc.rc_lost || rc.rc_failsafe;
        if !lost {
            if kill {
                self.kill_latched = true;
            } else if !offboard {
                self.kill_latched = false;
            }
        }
        Ok(RcReading {
            pilot: PilotInput {
                velocity: [
                    north * c.max_horizontal_speed,
                    east * c.max_horizontal_speed,
                    -up * c.max_vertical_speed,
                ],
                yaw_rate: yaw * c.max_yaw_rate_deg_s.to_radians(),
                throttle: up.max(0.0),
                // A lost radio's kill switch is not read: the latch holds.
                arm: !self.kill_latched && (lost || !kill),
                offboard,
                mpc_enabled,
            },
            tilt_lever,
            rehome_tilt,
            lost,
        })
    }
}

#[cfg(test)]
#[path = "rc_tests.rs"]
mod tests;
