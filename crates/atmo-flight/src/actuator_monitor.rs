//! Actuator monitoring: what the flight stack can tell, from the signals it
//! has, about actuators that do not do what it commands (docs/faults.md,
//! the actuator table).
//!
//! | detector | signal | rule |
//! | --- | --- | --- |
//! | tilt encoder stuck | commanded tilt velocity, encoder | the commanded travel since the encoder last moved by `encoder_step` reaches `encoder_stuck_travel` |
//! | tilt not where believed (motor slipping, linkage jammed) | the observer's body-z force | upward (more lift than predicted) at or above `tilt_force` for `tilt_force_time`, the wheels clear of the ground |
//! | rotor fault | the observer's roll and pitch torque | either at the observer's limit (`observer.max_torque`: what is left it cannot take up) for `rotor_time`, the wheels clear of the ground |
//! | rotor stopped | the ESCs' speeds, the rotor commands | the command a rotor's thrust (speed squared) followed since the last report, inverted through the motor's first-order lag (the robot file's `rotor.time_constant`), under `rotor_stopped_ratio` of the command sent, for `rotor_stopped_time`, flying (not in the take-off: a motor starting from rest is not a first-order lag) |
//! | ground contact missed | the estimate | fresh, the wheels (at the tilt in use) within `contact_clearance` of the ground and the vertical speed within `contact_speed`, for `contact_time` |
//!
//! What each detection makes the stack do is `FlightStack::step`'s (and
//! the mode table's): a stuck encoder's tilt is dead-reckoned from the
//! commands (the tilt motor is velocity-commanded: the linkage goes where
//! it is told while its encoder is silent); a tilt that is not where it is
//! believed is a failsafe held until disarmed (and with the encoder also
//! stuck, a jammed linkage: the encoder was right and is flown on again);
//! a failed rotor is named and its effectiveness learned into the MPC
//! (`crate::rotor_estimate`), and one out is a failsafe descent above z*
//! while a transition under way lands; an inferred contact is a contact.
//!
//! Detections latch until the arm switches are off: none of these faults
//! heals in flight, and a detector that let go would hand a flight back to
//! the mode that met the fault. Every update is a few comparisons on fixed
//! state: no allocation, no blocking.

use crate::modes::Mode;

/// Default of `monitor.rotor_out_effectiveness` (also of a disabled monitor).
const ROTOR_OUT_EFFECTIVENESS: f64 = 0.5;
/// Default of `monitor.rotor_out_descent_speed`, m/s.
const ROTOR_OUT_DESCENT_SPEED: f64 = 0.3;
/// Default of `monitor.rotor_out_landing_tilt_deg`: folded, as a flight
/// log written before the key was flown.
const ROTOR_OUT_LANDING_TILT_DEG: f64 = 0.0;

atmo_core::params! {
    /// `[monitor]` of `config/flight.toml`: the detectors' thresholds.
    #[derive(Debug, Clone, Copy, PartialEq)]
    pub struct MonitorSettings {
        /// Whether the detectors run (detections latch until disarmed).
        pub enabled: bool;
        /// Encoder change that counts as movement.
        pub encoder_step_deg: f64, range 0.0..=10.0, unit "deg";
        /// Commanded tilt travel without encoder movement that makes the
        /// encoder stuck.
        pub encoder_stuck_travel_deg: f64, range *encoder_step_deg..=45.0, unit "deg";
        /// Observer body-z force that says the tilt is not where it is
        /// believed.
        pub tilt_force: f64, range 0.0..=200.0, unit "N";
        /// ... held this long.
        pub tilt_force_time: f64, range 0.0..=5.0, unit "s";
        /// The observer's roll or pitch torque held at its limit this long
        /// says a rotor has failed.
        pub rotor_time: f64, range 0.0..=5.0, unit "s";
        /// Wheel clearance at or below which the estimate says the wheels
        /// touch.
        pub contact_clearance: f64, range -0.1..=0.5, unit "m";
        /// Vertical speed within which the estimate says the robot rests.
        pub contact_speed: f64, range 0.0..=2.0, unit "m/s";
        /// ... both held this long.
        pub contact_time: f64, range 0.0..=5.0, unit "s";
        /// A failed rotor that delivers less than this of its command is out:
        /// below half, two full rotors and two at this fraction (roll and
        /// pitch balanced) cannot hold the robot at the flight tilt limit
        /// (50 deg), so the transition cannot be flown; the robot descends
        /// with its arms at `rotor_out_landing_tilt_deg`.
        pub rotor_out_effectiveness: f64 = ROTOR_OUT_EFFECTIVENESS, range 0.0..=1.0;
        /// With a rotor out: the descent speed to the ground.
        pub rotor_out_descent_speed: f64 = ROTOR_OUT_DESCENT_SPEED, range 0.05..=2.0, unit "m/s";
        /// With a rotor out (and in the backup controller's descent,
        /// `failsafe.backup_attitude_bandwidth`): the arms' tilt in the
        /// descent, whatever the thrust left (folded, every touchdown is
        /// on the base box). Tilted past the tilt where the wheels' rims
        /// pass under the base box, the robot comes down on its wheels, not
        /// its body (for ATMO from about 33 deg: atmo-sim's
        /// `the_rotor_out_landing_tilt_puts_the_wheels_under_the_base`).
        pub rotor_out_landing_tilt_deg: f64 = ROTOR_OUT_LANDING_TILT_DEG, range 0.0..=90.0, unit "deg";
        /// A rotor whose thrust (its ESC's speed squared) follows less than
        /// this fraction of its command is stopped: the command it
        /// followed since the last report is its thrust's change through
        /// the motor's first-order lag, inverted (0: never, as a flight
        /// log written before the key). Told from the first report after
        /// a stop, not after the thrust has decayed: a rotor that stops
        /// follows 0.
        pub rotor_stopped_ratio: f64 = 0.0, range 0.0..=1.0;
        /// ... for this long.
        pub rotor_stopped_time: f64 = 0.0, range 0.0..=1.0, unit "s";
    }
}

impl MonitorSettings {
    /// No detector (a flight log written before the monitor existed).
    pub fn disabled() -> Self {
        Self {
            enabled: false,
            encoder_step_deg: 0.0,
            encoder_stuck_travel_deg: 0.0,
            tilt_force: 0.0,
            tilt_force_time: 0.0,
            rotor_time: 0.0,
            contact_clearance: 0.0,
            contact_speed: 0.0,
            contact_time: 0.0,
            rotor_out_effectiveness: ROTOR_OUT_EFFECTIVENESS,
            rotor_out_descent_speed: ROTOR_OUT_DESCENT_SPEED,
            rotor_out_landing_tilt_deg: ROTOR_OUT_LANDING_TILT_DEG,
            rotor_stopped_ratio: 0.0,
            rotor_stopped_time: 0.0,
        }
    }
}

impl Default for MonitorSettings {
    fn default() -> Self {
        Self::disabled()
    }
}

/// What the monitor has detected, as bits (`Status::actuator_faults`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Detected(u8);

impl Detected {
    pub const ENCODER_STUCK: u8 = 1;
    pub const TILT_MISMATCH: u8 = 2;
    pub const ROTOR: u8 = 4;
    pub const CONTACT_INFERRED: u8 = 8;
    /// A rotor's ESC reports it stopped (with [`Self::ROTOR`]).
    pub const ROTOR_STOPPED: u8 = 16;

    pub fn bits(self) -> u8 {
        self.0
    }

    pub fn from_bits(bits: u8) -> Self {
        Self(bits)
    }

    pub fn has(self, bit: u8) -> bool {
        self.0 & bit != 0
    }

    /// The tilt is not where it is believed (a slipping motor, a jammed
    /// linkage): no landing on the wheels can be planned.
    pub fn tilt_unknown(self) -> bool {
        self.has(Self::TILT_MISMATCH)
    }

    /// A rotor does not deliver what it is commanded.
    pub fn rotor_failed(self) -> bool {
        self.has(Self::ROTOR)
    }
}

/// What the monitor looks at each tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MonitorInputs {
    pub now_ns: u64,
    /// The arm switches are on: with them off every detection is forgotten.
    pub armed: bool,
    pub mode: Mode,
    /// The encoder's tilt, rad.
    pub encoder_tilt: f64,
    /// The tilt velocity commanded by the previous tick, rad/s.
    pub last_tilt_command: f64,
    /// The observer's wrench (body force N, torque N m).
    pub disturbance: [f64; 6],
    /// The estimate is fresh.
    pub estimate_fresh: bool,
    /// The wheels' clearance above the ground at the tilt in use, m.
    pub wheel_clearance: f64,
    /// Vertical speed of the estimate (NED), m/s.
    pub vertical_speed: f64,
    /// The rotor commands the previous tick sent, each in [0, 1].
    pub rotor_commands: [f64; 4],
    /// The ESCs' rotor speeds, each a fraction of full (`StepInputs`).
    pub rotor_speeds: Option<[f64; 4]>,
}

/// A rotor command this small says too little to tell a stopped rotor by
/// (the rotor estimate's smallest informative command).
const MIN_COMMAND: f64 = 0.05;

/// The detectors' state.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ActuatorMonitor {
    settings: MonitorSettings,
    /// The observer's torque limit (`observer.max_torque`), N m.
    torque_limit: f64,
    /// The mechanism's range is [0, tilt_max], rad.
    tilt_max: f64,
    /// The motors' thrust time constant (the robot file's), s.
    motor_time_constant: f64,
    detected: Detected,
    last_ns: Option<u64>,
    /// Encoder tilt at its last movement, rad.
    anchor: f64,
    /// Commanded travel since then (signed), rad, within the mechanism's
    /// range: a command against an end stop moves nothing, so an encoder
    /// that stands still there is not stuck (a calibration whose range ends
    /// short of 0, as the authors' table at 0.8 deg, stops the motor there).
    travel: f64,
    tilt_force_since: Option<u64>,
    rotor_since: Option<u64>,
    contact_since: Option<u64>,
    /// Each rotor's thrust at the last ESC report (its speed squared).
    last_thrust: Option<[f64; 4]>,
    /// Since when a rotor has read stopped, and which (the lowest ratio).
    stopped_since: Option<u64>,
    stopped_rotor: Option<usize>,
}

fn held(since: &mut Option<u64>, now: u64, holds: bool, time: f64) -> bool {
    if !holds {
        *since = None;
        return false;
    }
    let start = *since.get_or_insert(now);
    now.saturating_sub(start) as f64 * 1e-9 >= time
}

impl ActuatorMonitor {
    /// `torque_limit`: the observer's (`observer.max_torque`): a torque held
    /// there is one the observer cannot take up.
    /// `tilt_max`: the mechanism's range is [0, tilt_max], rad.
    /// `motor_time_constant`: the robot file's `rotor.time_constant`, s.
    pub fn new(
        settings: MonitorSettings,
        torque_limit: f64,
        tilt_max: f64,
        motor_time_constant: f64,
    ) -> Self {
        Self {
            settings,
            torque_limit,
            tilt_max,
            motor_time_constant,
            detected: Detected::default(),
            last_ns: None,
            anchor: 0.0,
            travel: 0.0,
            tilt_force_since: None,
            rotor_since: None,
            contact_since: None,
            last_thrust: None,
            stopped_since: None,
            stopped_rotor: None,
        }
    }

    /// The rotor its ESC reports stopped, once detected (latched).
    pub fn stopped_rotor(&self) -> Option<usize> {
        self.stopped_rotor
            .filter(|_| self.detected.has(Detected::ROTOR_STOPPED))
    }

    pub fn detected(&self) -> Detected {
        self.detected
    }

    /// The tilt to fly on, rad: the encoder's, or while it is stuck its
    /// last movement plus the commanded travel since. A stuck encoder
    /// whose dead-reckoned tilt then lifts as the believed one cannot
    /// (the tilt detector) was right: the linkage is jammed, the motor and
    /// its encoder stalled with the arms; its reading is flown again.
    pub fn tilt(&self, encoder_tilt: f64) -> f64 {
        if self.detected.has(Detected::ENCODER_STUCK) && !self.detected.tilt_unknown() {
            self.anchor + self.travel
        } else {
            encoder_tilt
        }
    }

    /// One tick: updates every detector and returns what is detected.
    pub fn update(&mut self, i: &MonitorInputs) -> Detected {
        let s = self.settings;
        if !s.enabled {
            return self.detected;
        }
        if !i.armed {
            *self = Self::new(
                s,
                self.torque_limit,
                self.tilt_max,
                self.motor_time_constant,
            );
            self.anchor = i.encoder_tilt;
            self.last_ns = Some(i.now_ns);
            return self.detected;
        }
        let dt = self
            .last_ns
            .map_or(0.0, |t| i.now_ns.saturating_sub(t) as f64 * 1e-9);
        self.last_ns = Some(i.now_ns);
        self.travel = (self.anchor + self.travel + i.last_tilt_command * dt)
            .clamp(0.0, self.tilt_max)
            - self.anchor;
        if !self.detected.has(Detected::ENCODER_STUCK) {
            if (i.encoder_tilt - self.anchor).abs() >= s.encoder_step_deg.to_radians() {
                self.anchor = i.encoder_tilt;
                self.travel = 0.0;
            } else if self.travel.abs() >= s.encoder_stuck_travel_deg.to_radians() {
                self.detected.0 |= Detected::ENCODER_STUCK;
            }
        }
        // The observer's wrench is an actuator's only while it learns and
        // the ground does not push on the wheels (wheels down, it learns
        // the ground's reaction: seen with a missed contact).
        let learning = matches!(i.mode, Mode::Flight | Mode::Morphing | Mode::Transition)
            && i.wheel_clearance > s.contact_clearance;
        let d = i.disturbance;
        if held(
            &mut self.tilt_force_since,
            i.now_ns,
            // Lift the model did not predict (upward: body z points down):
            // the arms are less tilted than believed. A robot short of
            // thrust (a weak motor, a heavy robot) reads the other way.
            learning && -d[2] >= s.tilt_force,
            s.tilt_force_time,
        ) {
            self.detected.0 |= Detected::TILT_MISMATCH;
        }
        if held(
            &mut self.rotor_since,
            i.now_ns,
            learning && d[3].abs().max(d[4].abs()) >= self.torque_limit,
            s.rotor_time,
        ) {
            self.detected.0 |= Detected::ROTOR;
        }
        self.watch_rotor_speeds(i, dt);
        let rests = i.mode.is_airborne_mode()
            && i.estimate_fresh
            && i.wheel_clearance <= s.contact_clearance
            && i.vertical_speed.abs() <= s.contact_speed;
        if held(&mut self.contact_since, i.now_ns, rests, s.contact_time) {
            self.detected.0 |= Detected::CONTACT_INFERRED;
        } else {
            self.detected.0 &= !Detected::CONTACT_INFERRED;
        }
        self.detected
    }

    /// The stopped-rotor detector. Over `dt` the motor's thrust `t` moves
    /// towards the command it follows by `1 - exp(-dt / tau)` of the gap;
    /// the command followed is so `t0 + (t1 - t0) / (1 - exp(-dt / tau))`
    /// from two reports. A rotor that follows under `rotor_stopped_ratio`
    /// of the command the previous tick sent is stopped. A rotor that
    /// delivers a fraction of its command follows that fraction, so the
    /// ratio is also the line between a weak rotor and a stopped one.
    /// Without ESC speeds (or a first report) nothing is decided.
    fn watch_rotor_speeds(&mut self, i: &MonitorInputs, dt: f64) {
        let s = self.settings;
        let thrust = i.rotor_speeds.map(|speeds| speeds.map(|v| v * v));
        let last = std::mem::replace(&mut self.last_thrust, thrust);
        if self.detected.has(Detected::ROTOR_STOPPED) {
            return;
        }
        let follow = if self.motor_time_constant > 0.0 {
            1.0 - (-dt / self.motor_time_constant).exp()
        } else {
            1.0
        };
        let flying = i.mode.is_airborne_mode() && i.mode != Mode::Takeoff;
        let lowest = match (thrust, last) {
            (Some(now), Some(before)) if flying && follow > 0.0 => (0..4)
                .filter(|&r| i.rotor_commands[r] >= MIN_COMMAND)
                .map(|r| {
                    let followed = before[r] + (now[r] - before[r]) / follow;
                    (r, followed / i.rotor_commands[r])
                })
                .min_by(|a, b| a.1.total_cmp(&b.1)),
            _ => None,
        };
        let stopped = lowest.filter(|&(_, ratio)| ratio < s.rotor_stopped_ratio);
        if stopped.is_some_and(|(r, _)| self.stopped_rotor != Some(r)) {
            // Another rotor: its own time.
            self.stopped_since = None;
        }
        self.stopped_rotor = stopped.map(|(r, _)| r);
        if held(
            &mut self.stopped_since,
            i.now_ns,
            stopped.is_some(),
            s.rotor_stopped_time,
        ) {
            self.detected.0 |= Detected::ROTOR | Detected::ROTOR_STOPPED;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn settings() -> MonitorSettings {
        MonitorSettings {
            enabled: true,
            encoder_step_deg: 0.5,
            encoder_stuck_travel_deg: 3.0,
            tilt_force: 10.0,
            tilt_force_time: 0.2,
            rotor_time: 0.1,
            contact_clearance: 0.01,
            contact_speed: 0.05,
            contact_time: 0.2,
            ..MonitorSettings::disabled()
        }
    }

    const TILT_MAX: f64 = std::f64::consts::FRAC_PI_2;

    fn inputs(k: u64, encoder_tilt: f64, command: f64) -> MonitorInputs {
        MonitorInputs {
            now_ns: k * 10_000_000,
            armed: true,
            mode: Mode::Morphing,
            encoder_tilt,
            last_tilt_command: command,
            disturbance: [0.0; 6],
            estimate_fresh: true,
            wheel_clearance: 1.0,
            vertical_speed: 0.3,
            rotor_commands: [0.5; 4],
            rotor_speeds: None,
        }
    }

    #[test]
    fn an_encoder_that_follows_the_command_is_not_stuck_and_a_silent_one_is_dead_reckoned() {
        let rate = 0.39;
        let mut m = ActuatorMonitor::new(settings(), 1.0, TILT_MAX, 0.03);
        for k in 0..200 {
            let tilt = (k as f64 * 0.01 * rate).min(0.87);
            m.update(&inputs(k, tilt, rate));
        }
        assert_eq!(m.detected(), Detected::default());
        let mut m = ActuatorMonitor::new(settings(), 1.0, TILT_MAX, 0.03);
        let mut first = None;
        for k in 0..100 {
            let tilt = (k as f64 * 0.01 * rate).min(0.3);
            if m.update(&inputs(k, tilt, rate))
                .has(Detected::ENCODER_STUCK)
            {
                first.get_or_insert(k);
            }
        }
        // Stuck at 0.3 rad from about k = 77; 3 deg of travel at 0.39 rad/s
        // is 13-14 ticks.
        let first = first.unwrap();
        assert!((89..=93).contains(&first), "{first}");
        let expected = 99.0 * 0.01 * rate;
        assert!((m.tilt(0.3) - expected).abs() < 0.01);
    }

    #[test]
    fn an_encoder_at_an_end_stop_is_not_stuck() {
        // The authors' table ends at 0.8 deg: commanded towards 0 for a
        // second, the encoder stands still there, and the tilt flown is
        // the encoder's.
        let end = 0.8f64.to_radians();
        let mut m = ActuatorMonitor::new(settings(), 1.0, TILT_MAX, 0.03);
        for k in 0..100 {
            m.update(&inputs(k, end, -0.39));
        }
        assert_eq!(m.detected(), Detected::default());
        assert_eq!(m.tilt(end), end);
        // The same still encoder commanded away from the stop is stuck.
        for k in 100..120 {
            m.update(&inputs(k, end, 0.39));
        }
        assert!(m.detected().has(Detected::ENCODER_STUCK));
    }

    #[test]
    fn a_torque_must_hold_its_time_and_a_detection_latches_until_disarmed() {
        let mut m = ActuatorMonitor::new(settings(), 1.0, TILT_MAX, 0.03);
        let mut i = inputs(0, 0.0, 0.0);
        i.disturbance[3] = 1.0;
        for k in 0..5 {
            i.now_ns = k * 10_000_000;
            m.update(&i);
        }
        assert!(!m.detected().has(Detected::ROTOR));
        for k in 5..20 {
            i.now_ns = k * 10_000_000;
            m.update(&i);
        }
        assert!(m.detected().has(Detected::ROTOR));
        i.disturbance[3] = 0.0;
        m.update(&i);
        assert!(m.detected().rotor_failed());
        i.mode = Mode::Disarmed;
        m.update(&i);
        assert!(m.detected().rotor_failed(), "held while armed");
        i.armed = false;
        m.update(&i);
        assert_eq!(m.detected(), Detected::default());
    }
    /// The thrust of a rotor following `command` from `thrust` through
    /// the 0.03 s lag, `dt` later.
    fn lagged(thrust: f64, command: f64, dt: f64) -> f64 {
        command + (thrust - command) * (-dt / 0.03).exp()
    }

    #[test]
    fn a_rotor_that_stops_is_told_in_two_reports_a_weak_one_or_a_lagging_one_never() {
        let mut s = settings();
        s.rotor_stopped_ratio = 0.1;
        s.rotor_stopped_time = 0.005;
        let dt = 1.0 / 150.0;
        let tick = |k: u64| (k as f64 * dt * 1e9) as u64;
        // Each case: the thrust each rotor's motor follows (a fraction of
        // its command) from tick 10 on, while commanded `command`.
        let fly = |follows: [f64; 4], command: [f64; 4]| {
            let mut m = ActuatorMonitor::new(s, 1.0, TILT_MAX, 0.03);
            let mut thrust = [0.5; 4];
            let mut first = None;
            for k in 0..60 {
                let mut i = inputs(0, 0.0, 0.0);
                i.now_ns = tick(k);
                i.mode = Mode::Flight;
                i.rotor_commands = if k > 10 { command } else { [0.5; 4] };
                i.rotor_speeds = Some(thrust.map(f64::sqrt));
                if m.update(&i).has(Detected::ROTOR_STOPPED) {
                    first.get_or_insert((k, m.stopped_rotor()));
                }
                for r in 0..4 {
                    let followed = if k >= 10 { follows[r] } else { 1.0 };
                    thrust[r] = lagged(thrust[r], followed * i.rotor_commands[r], dt);
                }
            }
            first
        };
        // Rotor 3 stops at tick 10: its next two reports tell it.
        let stopped = fly([1.0, 1.0, 0.0, 1.0], [0.5; 4]);
        assert_eq!(stopped, Some((12, Some(2))), "{stopped:?}");
        // At 60 % it is weak (the observer's), not stopped.
        assert_eq!(fly([1.0, 0.6, 1.0, 1.0], [0.5; 4]), None);
        // Commanded from 0.5 to full and to 0.1 at once: the lag is the
        // motor's, nothing stopped.
        assert_eq!(fly([1.0; 4], [1.0, 0.1, 1.0, 0.1]), None);
        // Without speeds nothing is decided.
        let mut m = ActuatorMonitor::new(s, 1.0, TILT_MAX, 0.03);
        for k in 0..60 {
            let mut i = inputs(0, 0.0, 0.0);
            i.now_ns = tick(k);
            i.mode = Mode::Flight;
            m.update(&i);
        }
        assert_eq!(m.stopped_rotor(), None);
    }
}
