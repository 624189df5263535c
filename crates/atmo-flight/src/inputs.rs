//! The tick's input assembly, shared by every [`crate::control_loop::TickIo`]:
//! the onboard I/O (ROS 2, driver ports) and the simulator's I/O feed the
//! same [`InputLatch`] with what arrived, and it builds the tick's
//! [`StepInputs`]. Only the sources differ; the rules below are one code.
//!
//! Times are ns on the tick's clock (the flight stack's `now_ns`); a source
//! whose messages carry another clock converts the time it *accepted* a
//! message to this one.
//!
//! - Estimate: the newest wins; its `stamp_ns` is set by the source (onboard:
//!   when the ROS 2 thread accepted it). Older than `estimate_timeout` at
//!   the tick is counted as stale (the flight stack then flies its failsafe).
//! - Pilot: the newest wins. When the pilot stream is silent for longer than
//!   `pilot_timeout` its switches hold (disarming a flying robot because a
//!   radio dropped would drop it) but velocity, yaw-rate and throttle go to
//!   zero: the robot holds its position.
//! - Radio (with `rc_timeout` set: PX4's `InputRc` is the pilot source,
//!   mapped by [`crate::rc`]): a usable frame is the pilot input. The radio
//!   is *lost* (`pilot_lost`, a failsafe input like a stale estimate) before
//!   its first frame, when PX4 flags the frame lost, and when no frame came
//!   for `rc_timeout`. A lost radio's frames are not used: its switches
//!   hold (a receiver's failsafe values would disarm a flying robot) and
//!   velocity, yaw rate and throttle go to zero.
//! - Drive command: newer than the pilot input and younger than
//!   `drive_timeout`, it sets velocity (forward along the current yaw) and
//!   yaw rate while the stack is in [`Mode::Drive`].
//! - Encoder, contact, driver liveness: the newest reading holds.
//! - Ground height: the NED z of the ground under the robot, from a source
//!   (a terrain map, a rangefinder, a topic): the newest wins while it is
//!   younger than `ground_timeout`; before a source has spoken, and when it
//!   has been silent longer than that (counted as stale), the configured
//!   constant.
//! - Ground normal: the unit normal of the ground plane (NED, pointing out
//!   of the ground), from a source of its own (a terrain map, a slope
//!   estimate, a topic), by the same rule with the same timeout; without a
//!   fresh normal the ground is level (`None`). The flight stack checks it
//!   (see [`StepInputs::ground_normal`]).

use std::time::Duration;

use atmo_core::model::idx;

use crate::flight_stack::{Estimate, PilotInput, StepInputs};
use crate::modes::Mode;

/// The pilot and drive timeouts when a config names none, ms.
pub const DEFAULT_INPUT_TIMEOUT_MS: u64 = 500;
/// The ground-height timeout when a config names none, ms (the ground
/// changes slowly; a terrain source may speak a few times a second).
pub const DEFAULT_GROUND_TIMEOUT_MS: u64 = 1000;

/// How the latch turns arrivals into inputs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct InputSettings {
    /// NED z of the ground when no ground-height source is fresh, m.
    pub ground_z: f64,
    /// Age after which a ground height is replaced by `ground_z`.
    pub ground_timeout: Duration,
    /// Pilot stream silence after which its commands go to zero.
    pub pilot_timeout: Duration,
    /// Age after which a drive command is ignored.
    pub drive_timeout: Duration,
    /// The flight stack's estimate timeout, s (for the stale count).
    pub estimate_timeout: f64,
    /// The radio is the pilot source and is lost after this silence; `None`:
    /// the pilot source is the `PilotInput` stream (its silence is no
    /// failsafe).
    pub rc_timeout: Option<Duration>,
}

/// A drive command (`geometry_msgs/Twist`) as the latch keeps it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DriveCommand {
    /// Forward speed, m/s.
    pub forward: f64,
    /// Yaw rate, rad/s (FRD).
    pub yaw_rate: f64,
    /// When it was accepted, ns on the tick's clock.
    pub received_ns: u64,
}

/// One tick's inputs and what was wrong with them (for the counters).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Assembled {
    pub inputs: StepInputs,
    /// The pilot stream is silent (its commands were zeroed).
    pub pilot_stale: bool,
    /// No estimate young enough to fly on.
    pub estimate_stale: bool,
    /// A ground-height (or ground-normal) source spoke, but too long ago: the
    /// tick uses the configured ground height (level ground).
    pub ground_stale: bool,
}

/// What the latch keeps of the radio.
#[derive(Debug, Clone, Copy, PartialEq)]
struct RadioLatch {
    /// When the newest frame arrived (tick clock), and whether PX4 flagged
    /// it lost.
    last: Option<(u64, bool)>,
    /// The newest usable frame's manual tilt lever and encoder reset switch.
    tilt_lever: f64,
    rehome_tilt: bool,
}

/// The newest value of every source, and the rules that make a tick's
/// inputs of them. Fixed size, no allocation.
#[derive(Debug, Clone, Copy)]
pub struct InputLatch {
    settings: InputSettings,
    estimate: Option<Estimate>,
    autopilot_estimate: Option<Estimate>,
    /// The newest ESC speeds and when they arrived (tick clock).
    rotor_speeds: Option<([f64; 4], u64)>,
    pilot: PilotInput,
    pilot_received_ns: Option<u64>,
    radio: RadioLatch,
    drive: Option<DriveCommand>,
    tilt_counts: Option<f64>,
    contact: bool,
    drivers_alive: bool,
    /// The newest ground height and when it arrived (tick clock).
    ground: Option<(f64, u64)>,
    /// The newest ground normal and when it arrived (tick clock).
    ground_normal: Option<([f64; 3], u64)>,
    mode: Mode,
}

fn ns(d: Duration) -> u64 {
    u64::try_from(d.as_nanos()).unwrap_or(u64::MAX)
}

impl InputSettings {
    /// The daemon's defaults (`config/daemon.toml` without the keys) with
    /// the flight settings' estimate timeout and the ground at `ground_z`.
    pub fn defaults(ground_z: f64, estimate_timeout: f64) -> Self {
        let timeout = Duration::from_millis(DEFAULT_INPUT_TIMEOUT_MS);
        Self {
            ground_z,
            ground_timeout: Duration::from_millis(DEFAULT_GROUND_TIMEOUT_MS),
            pilot_timeout: timeout,
            drive_timeout: timeout,
            estimate_timeout,
            rc_timeout: None,
        }
    }
}

impl InputLatch {
    /// Nothing heard yet: no estimate, no encoder, pilot silent, drivers alive
    /// (a source that checks liveness says otherwise), ground at the
    /// configured height.
    pub fn new(settings: InputSettings) -> Self {
        Self {
            settings,
            estimate: None,
            autopilot_estimate: None,
            rotor_speeds: None,
            pilot: PilotInput::default(),
            pilot_received_ns: None,
            radio: RadioLatch {
                last: None,
                tilt_lever: 0.0,
                rehome_tilt: false,
            },
            drive: None,
            tilt_counts: None,
            contact: false,
            drivers_alive: true,
            ground: None,
            ground_normal: None,
            mode: Mode::Disarmed,
        }
    }

    pub fn settings(&self) -> &InputSettings {
        &self.settings
    }

    /// A state estimate arrived.
    pub fn estimate(&mut self, estimate: Estimate) {
        self.estimate = Some(estimate);
    }

    /// The autopilot's own estimate arrived (`StepInputs::autopilot_estimate`).
    pub fn autopilot_estimate(&mut self, estimate: Estimate) {
        self.autopilot_estimate = Some(estimate);
    }

    /// A pilot input arrived at `received_ns`.
    pub fn pilot(&mut self, pilot: PilotInput, received_ns: u64) {
        self.pilot = pilot;
        self.pilot_received_ns = Some(received_ns);
    }

    /// A usable radio frame arrived at `received_ns` (mapped by
    /// [`crate::rc::RcPilot`]); a frame PX4 flags lost only marks the
    /// radio lost.
    pub fn radio(&mut self, reading: crate::rc::RcReading, received_ns: u64) {
        if !reading.lost {
            self.pilot = reading.pilot;
            self.pilot_received_ns = Some(received_ns);
            self.radio.tilt_lever = reading.tilt_lever;
            self.radio.rehome_tilt = reading.rehome_tilt;
        }
        self.radio.last = Some((received_ns, reading.lost));
    }

    /// Whether the radio is lost at `now_ns` (always false without one).
    fn radio_lost(&self, now_ns: u64) -> bool {
        let Some(timeout) = self.settings.rc_timeout else {
            return false;
        };
        self.radio
            .last
            .is_none_or(|(at, lost)| lost || now_ns.saturating_sub(at) > ns(timeout))
    }

    /// A drive command arrived.
    pub fn drive(&mut self, drive: DriveCommand) {
        self.drive = Some(drive);
    }

    /// The rotors' speeds arrived at `received_ns` (their ESCs', each a
    /// fraction of its speed at full command). Flown on while no older
    /// than the estimate timeout: a stopped rotor is told by its speed
    /// within ticks, a silent ESC telemetry must not look like one.
    pub fn rotor_speeds(&mut self, speeds: [f64; 4], received_ns: u64) {
        self.rotor_speeds = Some((speeds, received_ns));
    }

    /// A tilt encoder reading arrived (counts, continuous).
    pub fn tilt_counts(&mut self, counts: f64) {
        self.tilt_counts = Some(counts);
    }

    /// A ground-contact reading arrived.
    pub fn ground_contact(&mut self, contact: bool) {
        self.contact = contact;
    }

    /// The drivers' liveness: whether every required driver is heard from.
    pub fn drivers_alive(&mut self, alive: bool) {
        self.drivers_alive = alive;
    }

    /// A ground height arrived at `received_ns`: NED z of the ground under
    /// the robot, m.
    pub fn ground_z(&mut self, z: f64, received_ns: u64) {
        self.ground = Some((z, received_ns));
    }

    /// A ground normal arrived at `received_ns`: the unit normal of the
    /// ground plane under the robot, NED, pointing out of the ground.
    pub fn ground_normal(&mut self, normal: [f64; 3], received_ns: u64) {
        self.ground_normal = Some((normal, received_ns));
    }

    /// A ground plane arrived at `received_ns` (one source for both: a
    /// terrain map): its NED z under the robot and its unit normal.
    pub fn ground_plane(&mut self, z: f64, normal: [f64; 3], received_ns: u64) {
        self.ground_z(z, received_ns);
        self.ground_normal(normal, received_ns);
    }

    /// The mode the last tick ended in (drive commands count only in
    /// [`Mode::Drive`]).
    pub fn mode(&mut self, mode: Mode) {
        self.mode = mode;
    }

    /// The newest estimate, if any.
    pub fn latest_estimate(&self) -> Option<Estimate> {
        self.estimate
    }

    /// The inputs of the tick at `now_ns`.
    pub fn assemble(&self, now_ns: u64) -> Assembled {
        let pilot_lost = self.radio_lost(now_ns);
        let pilot_stale = pilot_lost
            || self
                .pilot_received_ns
                .is_none_or(|at| now_ns.saturating_sub(at) > ns(self.settings.pilot_timeout));
        let estimate_stale = !self
            .estimate
            .is_some_and(|e| e.age(now_ns) <= self.settings.estimate_timeout);
        let yaw = self.estimate.map_or(0.0, |e| e.state[idx::YAW]);
        let ground_timeout = ns(self.settings.ground_timeout);
        let fresh_ground = self
            .ground
            .filter(|&(_, at)| now_ns.saturating_sub(at) <= ground_timeout);
        let fresh_normal = self
            .ground_normal
            .filter(|&(_, at)| now_ns.saturating_sub(at) <= ground_timeout);
        Assembled {
            inputs: StepInputs {
                now_ns,
                estimate: self.estimate,
                tilt_counts: self.tilt_counts,
                pilot: self.pilot_now(now_ns, yaw, pilot_stale),
                ground_contact: self.contact,
                ground_z: fresh_ground.map_or(self.settings.ground_z, |(z, _)| z),
                ground_normal: fresh_normal.map(|(n, _)| n),
                driver_lost: !self.drivers_alive,
                pilot_lost,
                arming_failures: 0,
                // A silent radio's lever is at rest: the arms stop.
                tilt_lever: if pilot_stale {
                    0.0
                } else {
                    self.radio.tilt_lever
                },
                rehome_tilt: !pilot_stale && self.radio.rehome_tilt,
                autopilot_estimate: self.autopilot_estimate,
                rotor_speeds: self
                    .rotor_speeds
                    .filter(|&(_, at)| {
                        now_ns.saturating_sub(at) as f64 * 1e-9 <= self.settings.estimate_timeout
                    })
                    .map(|(speeds, _)| speeds),
            },
            pilot_stale,
            estimate_stale,
            ground_stale: (self.ground.is_some() && fresh_ground.is_none())
                || (self.ground_normal.is_some() && fresh_normal.is_none()),
        }
    }

    /// The pilot input at `now_ns`: held switches, zeroed commands when the
    /// stream is silent, a fresh drive command while driving.
    fn pilot_now(&self, now_ns: u64, yaw: f64, stale: bool) -> PilotInput {
        let mut pilot = self.pilot;
        if stale {
            pilot.velocity = [0.0; 3];
            pilot.yaw_rate = 0.0;
            pilot.throttle = 0.0;
        }
        if let Some(drive) = self.drive
            && self.mode == Mode::Drive
            && now_ns.saturating_sub(drive.received_ns) <= ns(self.settings.drive_timeout)
            && self
                .pilot_received_ns
                .is_none_or(|at| drive.received_ns > at)
        {
            pilot.velocity = [drive.forward * yaw.cos(), drive.forward * yaw.sin(), 0.0];
            pilot.yaw_rate = drive.yaw_rate;
        }
        pilot
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use atmo_core::model::State;

    fn latch() -> InputLatch {
        InputLatch::new(InputSettings {
            ground_z: -0.5,
            ground_timeout: Duration::from_secs(1),
            pilot_timeout: Duration::from_millis(500),
            drive_timeout: Duration::from_millis(300),
            estimate_timeout: 0.1,
            rc_timeout: None,
        })
    }

    fn radio_latch() -> InputLatch {
        let mut l = latch();
        l.settings.rc_timeout = Some(Duration::from_millis(300));
        l
    }

    fn reading(lost: bool) -> crate::rc::RcReading {
        crate::rc::RcReading {
            pilot: PilotInput {
                velocity: [0.5, 0.0, 0.0],
                yaw_rate: 0.1,
                throttle: 0.2,
                arm: true,
                offboard: true,
                mpc_enabled: true,
            },
            tilt_lever: 0.5,
            rehome_tilt: true,
            lost,
        }
    }

    #[test]
    fn the_radio_is_lost_before_its_first_frame_and_after_its_timeout() {
        let mut l = radio_latch();
        let before = l.assemble(0);
        assert!(before.inputs.pilot_lost && before.pilot_stale);
        l.radio(reading(false), 100 * MS);
        let fresh = l.assemble(400 * MS);
        assert!(!fresh.inputs.pilot_lost && !fresh.pilot_stale);
        assert_eq!(fresh.inputs.pilot, reading(false).pilot);
        assert_eq!(
            (fresh.inputs.tilt_lever, fresh.inputs.rehome_tilt),
            (0.5, true)
        );
        let silent = l.assemble(401 * MS);
        assert!(silent.inputs.pilot_lost, "300 ms of silence");
        assert_eq!(
            (silent.inputs.tilt_lever, silent.inputs.rehome_tilt),
            (0.0, false),
            "a silent radio's lever rests"
        );
        let p = silent.inputs.pilot;
        assert_eq!((p.velocity, p.yaw_rate, p.throttle), ([0.0; 3], 0.0, 0.0));
        assert!(p.arm && p.offboard && p.mpc_enabled, "switches held");
    }

    #[test]
    fn a_frame_px4_flags_lost_marks_the_radio_lost_and_is_not_used() {
        let mut l = radio_latch();
        l.radio(reading(false), 100 * MS);
        let mut failsafe_values = reading(true);
        failsafe_values.pilot.arm = false;
        failsafe_values.pilot.offboard = false;
        l.radio(failsafe_values, 120 * MS);
        let a = l.assemble(130 * MS);
        assert!(a.inputs.pilot_lost);
        assert!(
            a.inputs.pilot.arm && a.inputs.pilot.offboard,
            "not disarmed by it"
        );
        assert_eq!(a.inputs.pilot.velocity, [0.0; 3]);
        l.radio(reading(false), 140 * MS);
        assert!(!l.assemble(150 * MS).inputs.pilot_lost, "back");
    }

    #[test]
    fn without_a_radio_a_silent_pilot_stream_is_no_failsafe() {
        let l = latch();
        let a = l.assemble(10_000 * MS);
        assert!(a.pilot_stale && !a.inputs.pilot_lost);
    }

    const MS: u64 = 1_000_000;

    #[test]
    fn silent_pilot_holds_switches_and_zeroes_commands() {
        let mut l = latch();
        let pilot = PilotInput {
            velocity: [0.5, 0.0, 0.2],
            yaw_rate: 0.3,
            throttle: 0.6,
            arm: true,
            offboard: true,
            mpc_enabled: true,
        };
        l.pilot(pilot, 1000 * MS);
        let fresh = l.assemble(1400 * MS);
        assert!(!fresh.pilot_stale);
        assert_eq!(fresh.inputs.pilot, pilot);
        let stale = l.assemble(1501 * MS);
        assert!(stale.pilot_stale);
        let p = stale.inputs.pilot;
        assert_eq!((p.velocity, p.yaw_rate, p.throttle), ([0.0; 3], 0.0, 0.0));
        assert!(p.arm && p.offboard && p.mpc_enabled);
    }

    #[test]
    fn drive_command_counts_only_while_driving_fresh_and_newer_than_the_pilot() {
        let mut l = latch();
        let mut state = State::zeros();
        state[idx::YAW] = std::f64::consts::FRAC_PI_2;
        l.estimate(Estimate {
            stamp_ns: 100 * MS,
            state,
        });
        l.pilot(PilotInput::default(), 100 * MS);
        l.drive(DriveCommand {
            forward: 1.0,
            yaw_rate: 0.2,
            received_ns: 110 * MS,
        });
        assert_eq!(
            l.assemble(120 * MS).inputs.pilot.yaw_rate,
            0.0,
            "not driving"
        );
        l.mode(Mode::Drive);
        let p = l.assemble(120 * MS).inputs.pilot;
        assert!((p.velocity[1] - 1.0).abs() < 1e-12 && p.velocity[0].abs() < 1e-12);
        assert_eq!(p.yaw_rate, 0.2);
        assert_eq!(l.assemble(411 * MS).inputs.pilot.yaw_rate, 0.0, "too old");
        l.pilot(PilotInput::default(), 115 * MS);
        assert_eq!(
            l.assemble(120 * MS).inputs.pilot.yaw_rate,
            0.0,
            "pilot newer"
        );
    }

    #[test]
    fn ground_height_is_the_constant_unless_a_source_is_fresh() {
        let mut l = latch();
        let before = l.assemble(0);
        assert_eq!(before.inputs.ground_z, -0.5);
        assert!(!before.ground_stale, "no source yet is not stale");
        l.ground_z(-0.2, 100 * MS);
        let fresh = l.assemble(1100 * MS);
        assert_eq!((fresh.inputs.ground_z, fresh.ground_stale), (-0.2, false));
        let stale = l.assemble(1101 * MS);
        assert_eq!((stale.inputs.ground_z, stale.ground_stale), (-0.5, true));
        l.ground_z(-0.3, 1200 * MS);
        assert_eq!(l.assemble(1200 * MS).inputs.ground_z, -0.3, "back");
    }

    #[test]
    fn ground_normal_is_level_unless_a_source_is_fresh() {
        let mut l = latch();
        assert_eq!(l.assemble(0).inputs.ground_normal, None, "level by default");
        let n = [-0.2, 0.0, -0.9];
        l.ground_plane(-0.2, n, 100 * MS);
        let fresh = l.assemble(1100 * MS);
        assert_eq!(
            (
                fresh.inputs.ground_z,
                fresh.inputs.ground_normal,
                fresh.ground_stale
            ),
            (-0.2, Some(n), false)
        );
        let stale = l.assemble(1101 * MS);
        assert_eq!(
            (
                stale.inputs.ground_z,
                stale.inputs.ground_normal,
                stale.ground_stale
            ),
            (-0.5, None, true)
        );
        // A normal alone (its own topic) with a fresh height: stale normal, level.
        l.ground_z(-0.3, 1200 * MS);
        let normal_stale = l.assemble(1200 * MS);
        assert_eq!(normal_stale.inputs.ground_normal, None);
        assert!(normal_stale.ground_stale, "the normal's source went silent");
        l.ground_normal(n, 1300 * MS);
        assert_eq!(l.assemble(1300 * MS).inputs.ground_normal, Some(n), "back");
    }

    #[test]
    fn estimate_staleness_and_driver_liveness() {
        let mut l = latch();
        assert!(l.assemble(0).estimate_stale);
        l.estimate(Estimate {
            stamp_ns: 50 * MS,
            state: State::zeros(),
        });
        assert!(!l.assemble(150 * MS).estimate_stale);
        assert!(l.assemble(151 * MS).estimate_stale);
        assert!(!l.assemble(0).inputs.driver_lost);
        l.drivers_alive(false);
        assert!(l.assemble(0).inputs.driver_lost);
    }
}
