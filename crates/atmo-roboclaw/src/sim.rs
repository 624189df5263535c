//! A simulated Roboclaw: the packet-serial answers of the subset in
//! [`crate::protocol`], two motors with first-order speed dynamics and
//! quadrature encoders, a home switch on M2, the board's serial timeout, and
//! fault injection (corrupt answers, silence, a reset).
//!
//! Model, per motor, with the speed target `w` (counts/s) set by a speed
//! command (35/36) or a duty command (32/33: `duty / 32767 x max_speed`):
//!
//! ```text
//! dv/dt = (w - v) / tau          (the board's PID and the rotor's inertia)
//! dp/dt = v                      (true position, counts)
//! encoder = round(p - offset)    (offset: where the counter was zeroed)
//! ```
//!
//! integrated exactly over 1 ms steps (`v` relaxes by `exp(-dt/tau)`), so a
//! run depends only on the times passed in, never on the wall clock.
//!
//! Home switch (M2): triggered while `p <= home_position`; motion towards it
//! stops there (the board's Home(User) mode) and, on the trigger, the
//! encoder is zeroed (the counter is 0 at home) and the status word shows
//! the switch (S4 or S5 bit).
//!
//! Serial timeout (command 14): when no valid packet arrived for that long,
//! both targets go to zero. A reset (power cycle, brown-out) zeroes the
//! counters, the targets and the serial timeout (back to the value the
//! board keeps in EEPROM, 0 here): the rotors keep their speed and coast
//! down.

use std::sync::atomic::{AtomicU64, Ordering};

use crate::protocol::{
    self, Command, DecodeError, Motor, Reply, Request, Version, encode_reply, status,
};

/// Where the simulated board's time comes from.
pub trait Clock: Send + Sync {
    /// Nanoseconds on a monotonic clock.
    fn now_ns(&self) -> u64;
}

/// CLOCK_MONOTONIC (real time: the `sim` subcommand).
#[derive(Debug, Clone, Copy, Default)]
pub struct MonotonicClock;

impl Clock for MonotonicClock {
    fn now_ns(&self) -> u64 {
        atmo_io::drivers::monotonic_ns()
    }
}

/// A clock set by hand (tests: the driver and the board share it).
#[derive(Debug, Default)]
pub struct ManualClock(AtomicU64);

impl ManualClock {
    pub fn new(ns: u64) -> Self {
        Self(AtomicU64::new(ns))
    }

    pub fn set(&self, ns: u64) {
        self.0.store(ns, Ordering::SeqCst);
    }

    /// Moves the clock on by `ns`; returns the new time.
    pub fn advance(&self, ns: u64) -> u64 {
        self.0.fetch_add(ns, Ordering::SeqCst) + ns
    }
}

impl Clock for ManualClock {
    fn now_ns(&self) -> u64 {
        self.0.load(Ordering::SeqCst)
    }
}

/// Which status bit the home switch sets.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SwitchInput {
    S4,
    S5,
}

impl SwitchInput {
    pub fn status_bit(self) -> u32 {
        match self {
            Self::S4 => status::S4_TRIGGERED,
            Self::S5 => status::S5_TRIGGERED,
        }
    }
}

/// The simulated board's parameters.
#[derive(Debug, Clone, PartialEq)]
pub struct SimConfig {
    pub address: u8,
    pub firmware: String,
    /// Speed time constant, s.
    pub time_constant_s: f64,
    /// Speed at full duty, counts/s (speed commands saturate here).
    pub max_speed: [f64; 2],
    /// M2's home switch: true position of the trigger (counts, on the
    /// counter's power-up scale) and the input it is wired to; `None`: none.
    pub home_switch: Option<(f64, SwitchInput)>,
    /// True positions at power-up (counts; the counters read 0 there).
    pub start_position: [f64; 2],
    /// Serial timeout the board has after power-up or a reset (100 ms units).
    pub eeprom_serial_timeout: u8,
    /// A partial packet is dropped after this gap (the firmware's 10 ms).
    pub packet_gap_ns: u64,
}

impl SimConfig {
    /// ATMO's tilt board: M2 with the home switch on S5, starting
    /// `start_counts` from home (positive: away from it).
    pub fn tilt(start_counts: f64) -> Self {
        Self {
            address: protocol::DEFAULT_ADDRESS,
            firmware: "USB Roboclaw 2x15a v4.2.8 (simulated)".into(),
            time_constant_s: 0.05,
            max_speed: [10000.0, 10000.0],
            home_switch: Some((-start_counts, SwitchInput::S5)),
            start_position: [0.0, 0.0],
            eeprom_serial_timeout: 0,
            packet_gap_ns: 10_000_000,
        }
    }

    /// ATMO's wheel board: two belt drives, no switch.
    pub fn wheels() -> Self {
        Self {
            home_switch: None,
            max_speed: [8000.0, 8000.0],
            ..Self::tilt(0.0)
        }
    }
}

#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct MotorSim {
    position: f64,
    offset: f64,
    speed: f64,
    target: f64,
}

/// What the simulated board did (for tests and the `sim` subcommand).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SimStats {
    /// Valid packets received.
    pub packets: u64,
    /// Answers sent.
    pub answers: u64,
    /// Bytes dropped (bad CRC, wrong address, unknown command, partial packet).
    pub dropped_bytes: u64,
    /// Packets with a bad CRC (the real board ignores them, no answer).
    pub bad_crc: u64,
    pub corrupted_answers: u64,
    pub silenced_answers: u64,
    /// Serial timeouts that stopped the motors.
    pub serial_timeouts: u64,
    pub resets: u64,
    /// Times the home switch triggered.
    pub home_triggers: u64,
}

impl std::fmt::Display for SimStats {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "packets {}, answers {}, dropped bytes {}, bad CRC {}, corrupted answers {}, \
             silenced answers {}, serial timeouts {}, resets {}, home triggers {}",
            self.packets,
            self.answers,
            self.dropped_bytes,
            self.bad_crc,
            self.corrupted_answers,
            self.silenced_answers,
            self.serial_timeouts,
            self.resets,
            self.home_triggers
        )
    }
}

/// Faults to inject.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Faults {
    /// The next n answers go out with a corrupted CRC.
    pub corrupt_next: u32,
    /// The next n requests are not answered.
    pub silent_next: u32,
    /// No answers at all until cleared.
    pub silent: bool,
}

/// The simulated board.
#[derive(Debug, Clone)]
pub struct SimBoard {
    config: SimConfig,
    version: Version,
    motors: [MotorSim; 2],
    serial_timeout: u8,
    last_packet_ns: Option<u64>,
    timeout_fired: bool,
    now_ns: Option<u64>,
    at_home: bool,
    rx: [u8; 32],
    rx_len: usize,
    rx_last_ns: u64,
    pub faults: Faults,
    pub stats: SimStats,
}

/// Integration step, s.
const STEP_S: f64 = 1e-3;
/// Longest span integrated step by step; beyond it everything has settled
/// and the rest is one step (bounds the work of a huge time jump).
const MAX_STEPS: u64 = 20_000;

impl SimBoard {
    pub fn new(config: SimConfig) -> Self {
        let mut motors = [MotorSim::default(); 2];
        for (m, p) in motors.iter_mut().zip(config.start_position) {
            m.position = p;
            m.offset = p;
        }
        let mut board = Self {
            version: Version::new(&config.firmware),
            serial_timeout: config.eeprom_serial_timeout,
            config,
            motors,
            last_packet_ns: None,
            timeout_fired: false,
            now_ns: None,
            at_home: false,
            rx: [0; 32],
            rx_len: 0,
            rx_last_ns: 0,
            faults: Faults::default(),
            stats: SimStats::default(),
        };
        board.update_switch();
        board
    }

    pub fn config(&self) -> &SimConfig {
        &self.config
    }

    /// The encoder counter of `motor`.
    pub fn encoder(&self, motor: Motor) -> i32 {
        let m = &self.motors[motor.index()];
        (m.position - m.offset).round() as i64 as i32
    }

    /// True position of `motor`, counts on the power-up scale.
    pub fn position(&self, motor: Motor) -> f64 {
        self.motors[motor.index()].position
    }

    /// Imposes the true position of `motor` (a plant that owns the
    /// mechanism: SITL moves the linkage and the board counts it); the
    /// counter moves with it, the home switch is re-evaluated.
    pub fn set_position(&mut self, motor: Motor, position: f64) {
        if position.is_finite() {
            self.motors[motor.index()].position = position;
            self.update_switch();
        }
    }

    pub fn speed(&self, motor: Motor) -> f64 {
        self.motors[motor.index()].speed
    }

    pub fn target(&self, motor: Motor) -> f64 {
        self.motors[motor.index()].target
    }

    pub fn serial_timeout(&self) -> u8 {
        self.serial_timeout
    }

    pub fn home_triggered(&self) -> bool {
        self.at_home
    }

    /// A power cycle: counters, targets and serial timeout back to their
    /// power-up values; the rotors coast down from their speed.
    pub fn reset(&mut self) {
        for m in &mut self.motors {
            m.offset = m.position;
            m.target = 0.0;
        }
        self.serial_timeout = self.config.eeprom_serial_timeout;
        self.last_packet_ns = None;
        self.timeout_fired = false;
        self.rx_len = 0;
        self.stats.resets += 1;
    }

    fn update_switch(&mut self) {
        let Some((home, _)) = self.config.home_switch else {
            return;
        };
        let m2 = &mut self.motors[Motor::M2.index()];
        let triggered = m2.position <= home;
        if triggered {
            m2.position = home;
            if m2.speed < 0.0 {
                m2.speed = 0.0;
            }
            if !self.at_home {
                // Home(User): the counter reads 0 at home.
                m2.offset = home;
                self.stats.home_triggers += 1;
            }
        }
        self.at_home = triggered;
    }

    fn step(&mut self, dt: f64) {
        let a = (-dt / self.config.time_constant_s).exp();
        let home_blocks = self.at_home;
        for (i, m) in self.motors.iter_mut().enumerate() {
            let mut target = m.target;
            if i == Motor::M2.index() && home_blocks && target < 0.0 {
                // The switch holds the motor against the stop.
                target = 0.0;
            }
            let v0 = m.speed;
            m.speed = target + (v0 - target) * a;
            m.position += target * dt + (v0 - target) * self.config.time_constant_s * (1.0 - a);
        }
        self.update_switch();
    }

    fn integrate(&mut self, from: u64, to: u64) {
        let span = to.saturating_sub(from);
        let step_ns = (STEP_S * 1e9) as u64;
        let steps = span / step_ns;
        for _ in 0..steps.min(MAX_STEPS) {
            self.step(STEP_S);
        }
        let rest = span - steps.min(MAX_STEPS) * step_ns;
        if rest > 0 {
            self.step(rest as f64 * 1e-9);
        }
    }

    /// Moves the model on to `now_ns` (earlier times are ignored).
    pub fn advance(&mut self, now_ns: u64) {
        let Some(from) = self.now_ns else {
            self.now_ns = Some(now_ns);
            return;
        };
        if now_ns <= from {
            return;
        }
        // The serial timeout stops the motors at its deadline, inside the span.
        let deadline = match (self.serial_timeout, self.last_packet_ns) {
            (t, Some(last)) if t > 0 && !self.timeout_fired => {
                Some(last + u64::from(t) * 100_000_000)
            }
            _ => None,
        };
        match deadline {
            Some(d) if d <= now_ns => {
                self.integrate(from, d.max(from));
                for m in &mut self.motors {
                    m.target = 0.0;
                }
                self.timeout_fired = true;
                self.stats.serial_timeouts += 1;
                self.integrate(d.max(from), now_ns);
            }
            _ => self.integrate(from, now_ns),
        }
        self.now_ns = Some(now_ns);
    }

    /// Feeds received bytes at `now_ns`; every answer goes to `send`.
    pub fn receive(&mut self, bytes: &[u8], now_ns: u64, mut send: impl FnMut(&[u8])) {
        self.advance(now_ns);
        if self.rx_len > 0 && now_ns.saturating_sub(self.rx_last_ns) > self.config.packet_gap_ns {
            // The firmware drops a packet interrupted by a gap.
            self.stats.dropped_bytes += self.rx_len as u64;
            self.rx_len = 0;
        }
        self.rx_last_ns = now_ns;
        for &b in bytes {
            if self.rx_len == self.rx.len() {
                self.stats.dropped_bytes += self.rx_len as u64;
                self.rx_len = 0;
            }
            self.rx[self.rx_len] = b;
            self.rx_len += 1;
            self.parse(now_ns, &mut send);
        }
    }

    fn parse(&mut self, now_ns: u64, send: &mut impl FnMut(&[u8])) {
        match protocol::decode_request(self.config.address, &self.rx[..self.rx_len]) {
            Ok((request, used)) => {
                self.rx_len -= used.min(self.rx_len);
                self.stats.packets += 1;
                self.last_packet_ns = Some(now_ns);
                self.timeout_fired = false;
                let reply = self.apply(request);
                self.answer(request.command(), &reply, send);
            }
            Err(e) if e.is_incomplete() => {}
            Err(e) => {
                if matches!(e, DecodeError::Crc { .. }) {
                    self.stats.bad_crc += 1;
                }
                // Drop the first byte and look for a packet in the rest.
                self.stats.dropped_bytes += 1;
                self.rx.copy_within(1..self.rx_len, 0);
                self.rx_len -= 1;
                if self.rx_len > 0 {
                    self.parse(now_ns, send);
                }
            }
        }
    }

    fn answer(&mut self, command: Command, reply: &Reply, send: &mut impl FnMut(&[u8])) {
        if self.faults.silent {
            self.stats.silenced_answers += 1;
            return;
        }
        if self.faults.silent_next > 0 {
            self.faults.silent_next -= 1;
            self.stats.silenced_answers += 1;
            return;
        }
        let mut frame = encode_reply(self.config.address, command, reply);
        if self.faults.corrupt_next > 0 {
            self.faults.corrupt_next -= 1;
            self.stats.corrupted_answers += 1;
            if let Some(last) = frame.as_mut_bytes().last_mut() {
                // The acknowledgement has no CRC: corrupt it to a 0 byte.
                *last = if *reply == Reply::Ack {
                    0
                } else {
                    *last ^ 0x5A
                };
            }
        }
        self.stats.answers += 1;
        send(frame.as_bytes());
    }

    fn status_word(&self) -> u32 {
        match self.config.home_switch {
            Some((_, input)) if self.at_home => input.status_bit(),
            _ => 0,
        }
    }

    fn apply(&mut self, request: Request) -> Reply {
        match request {
            Request::ReadFirmwareVersion => Reply::Version(self.version),
            Request::ReadEncoder(motor) => {
                let m = &self.motors[motor.index()];
                let status = if m.speed < 0.0 {
                    protocol::encoder_status::BACKWARD
                } else {
                    0
                };
                Reply::Encoder {
                    count: self.encoder(motor),
                    status,
                }
            }
            Request::ReadSpeed(motor) => Reply::Speed(self.speed(motor).round() as i32),
            Request::ReadStatus => Reply::Status(self.status_word()),
            Request::ReadSerialTimeout => Reply::SerialTimeout(self.serial_timeout),
            Request::SetSerialTimeout(v) => {
                self.serial_timeout = v;
                Reply::Ack
            }
            Request::ResetEncoders => {
                for m in &mut self.motors {
                    m.offset = m.position;
                }
                Reply::Ack
            }
            Request::SetEncoder(motor, count) => {
                let m = &mut self.motors[motor.index()];
                m.offset = m.position - f64::from(count);
                Reply::Ack
            }
            Request::Speed(motor, speed) => {
                let max = self.config.max_speed[motor.index()];
                self.motors[motor.index()].target = f64::from(speed).clamp(-max, max);
                Reply::Ack
            }
            Request::Duty(motor, duty) => {
                let max = self.config.max_speed[motor.index()];
                self.motors[motor.index()].target =
                    f64::from(duty).clamp(-32767.0, 32767.0) / 32767.0 * max;
                Reply::Ack
            }
        }
    }
}

/// The simulated board as an in-process [`crate::link::Transport`]: no
/// pseudo-terminal, answers at once (fast unit tests of the driver).
pub struct Loopback<'a, C: Clock> {
    pub board: &'a std::sync::Mutex<SimBoard>,
    pub clock: &'a C,
    pending: [u8; 64],
    pending_len: usize,
}

impl<'a, C: Clock> Loopback<'a, C> {
    pub fn new(board: &'a std::sync::Mutex<SimBoard>, clock: &'a C) -> Self {
        Self {
            board,
            clock,
            pending: [0; 64],
            pending_len: 0,
        }
    }
}

impl<C: Clock> crate::link::Transport for Loopback<'_, C> {
    fn write_all(&mut self, bytes: &[u8]) -> std::io::Result<()> {
        let Ok(mut board) = self.board.lock() else {
            return Err(std::io::Error::from(std::io::ErrorKind::BrokenPipe));
        };
        let pending = &mut self.pending;
        let len = &mut self.pending_len;
        board.receive(bytes, self.clock.now_ns(), |answer| {
            for &b in answer {
                if let Some(slot) = pending.get_mut(*len) {
                    *slot = b;
                    *len += 1;
                }
            }
        });
        Ok(())
    }

    fn read_timeout(
        &mut self,
        buf: &mut [u8],
        timeout: std::time::Duration,
    ) -> std::io::Result<usize> {
        if self.pending_len == 0 {
            // Nothing more will come: an answer is written at once or never.
            std::thread::sleep(timeout);
            return Ok(0);
        }
        let n = self.pending_len.min(buf.len());
        buf[..n].copy_from_slice(&self.pending[..n]);
        self.pending.copy_within(n..self.pending_len, 0);
        self.pending_len -= n;
        Ok(n)
    }

    fn clear_input(&mut self) -> std::io::Result<usize> {
        let dropped = self.pending_len;
        self.pending_len = 0;
        Ok(dropped)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::link::{Board, LinkSettings};

    const MS: u64 = 1_000_000;

    fn board(config: SimConfig) -> std::sync::Mutex<SimBoard> {
        std::sync::Mutex::new(SimBoard::new(config))
    }

    fn link<'a>(
        board: &'a std::sync::Mutex<SimBoard>,
        clock: &'a ManualClock,
    ) -> Board<Loopback<'a, ManualClock>> {
        Board::new(
            Loopback::new(board, clock),
            LinkSettings {
                address: 0x80,
                baud: 115_200,
                answer_timeout: std::time::Duration::from_millis(1),
                retries: 1,
            },
        )
    }

    #[test]
    fn speed_follows_a_first_order_lag_and_the_counter_integrates_it() {
        let b = board(SimConfig::wheels());
        let clock = ManualClock::new(0);
        let mut link = link(&b, &clock);
        link.set_speed(Motor::M1, 1000).unwrap();
        // One time constant: 1 - e^-1 of the step.
        clock.set(50 * MS);
        let v = link.read_speed(Motor::M1).unwrap();
        assert_eq!(v, (1000.0 * (1.0 - (-1.0f64).exp())).round() as i32);
        // Position: 1000 (t - tau (1 - e^(-t/tau))) at t = 1 s.
        clock.set(1000 * MS);
        let (count, status) = link.read_encoder(Motor::M1).unwrap();
        let expected = 1000.0 * (1.0 - 0.05 * (1.0 - (-20.0f64).exp()));
        assert!(
            (f64::from(count) - expected).abs() <= 1.0,
            "{count} vs {expected}"
        );
        assert_eq!(status & protocol::encoder_status::BACKWARD, 0);
        // Duty: a fraction of the top speed, backwards.
        link.set_duty(Motor::M2, -16384).unwrap();
        clock.set(2000 * MS);
        assert!((link.read_speed(Motor::M2).unwrap() + 4000).abs() <= 1);
    }

    #[test]
    fn runs_depend_only_on_the_times_passed_in() {
        let run = || {
            let b = board(SimConfig::tilt(1234.5));
            let clock = ManualClock::new(0);
            let mut link = link(&b, &clock);
            let mut trace = Vec::new();
            for i in 1..=300u64 {
                clock.set(i * 7 * MS + i % 3);
                link.set_speed(Motor::M2, if i < 150 { -3000 } else { 2500 })
                    .unwrap();
                trace.push(link.read_encoder(Motor::M2).unwrap());
            }
            trace
        };
        assert_eq!(run(), run());
    }

    #[test]
    fn the_home_switch_stops_m2_zeroes_its_counter_and_shows_in_the_status() {
        let b = board(SimConfig::tilt(500.0));
        let clock = ManualClock::new(0);
        let mut link = link(&b, &clock);
        assert_eq!(link.read_status().unwrap(), 0);
        link.set_speed(Motor::M2, -2000).unwrap();
        clock.set(1000 * MS);
        assert_eq!(link.read_status().unwrap(), status::S5_TRIGGERED);
        assert_eq!(link.read_encoder(Motor::M2).unwrap().0, 0);
        assert_eq!(link.read_speed(Motor::M2).unwrap(), 0);
        // Away from home again: the switch lets go.
        link.set_speed(Motor::M2, 1000).unwrap();
        clock.set(1500 * MS);
        assert_eq!(link.read_status().unwrap(), 0);
        assert!(link.read_encoder(Motor::M2).unwrap().0 > 300);
        assert_eq!(b.lock().unwrap().stats.home_triggers, 1);
        // A plant imposing the position: the counter follows it, and back
        // at home the switch triggers again.
        b.lock().unwrap().set_position(Motor::M2, 0.0);
        assert_eq!(link.read_encoder(Motor::M2).unwrap().0, 500);
        b.lock().unwrap().set_position(Motor::M2, -600.0);
        assert_eq!(link.read_status().unwrap(), status::S5_TRIGGERED);
        assert_eq!(b.lock().unwrap().stats.home_triggers, 2);
    }

    #[test]
    fn the_serial_timeout_stops_both_motors_at_its_deadline() {
        let b = board(SimConfig::wheels());
        let clock = ManualClock::new(0);
        let mut link = link(&b, &clock);
        link.set_serial_timeout(3).unwrap();
        assert_eq!(link.read_serial_timeout().unwrap(), 3);
        link.set_speed(Motor::M1, 1000).unwrap();
        link.set_speed(Motor::M2, -1000).unwrap();
        // Silence from the driver: stopped 300 ms after the last packet.
        b.lock().unwrap().advance(299 * MS);
        assert_eq!(b.lock().unwrap().target(Motor::M1), 1000.0);
        b.lock().unwrap().advance(2000 * MS);
        let board = b.lock().unwrap();
        assert_eq!(board.stats.serial_timeouts, 1);
        assert_eq!(
            (board.target(Motor::M1), board.target(Motor::M2)),
            (0.0, 0.0)
        );
        assert!(board.speed(Motor::M1).abs() < 1e-6);
    }

    #[test]
    fn faults_corrupt_silence_and_reset() {
        let b = board(SimConfig::wheels());
        let clock = ManualClock::new(0);
        let mut link = link(&b, &clock);
        link.set_serial_timeout(5).unwrap();
        link.set_speed(Motor::M1, 500).unwrap();
        clock.set(1000 * MS);
        b.lock().unwrap().faults.corrupt_next = 2;
        // Both attempts corrupted: the transaction fails, named.
        let e = link.read_encoder(Motor::M1).unwrap_err();
        assert!(
            e.to_string().contains("read encoder M1 (16): CRC mismatch"),
            "{e}"
        );
        assert_eq!(link.health().crc_errors, 2);
        b.lock().unwrap().faults.silent_next = 1;
        assert!(
            link.read_encoder(Motor::M1).is_ok(),
            "the retry is answered"
        );
        assert_eq!(link.health().no_answer, 1);
        b.lock().unwrap().reset();
        assert_eq!(link.read_serial_timeout().unwrap(), 0);
        assert_eq!(link.read_encoder(Motor::M1).unwrap().0, 0);
        assert_eq!(b.lock().unwrap().target(Motor::M1), 0.0);
        let version = link.read_firmware_version().unwrap();
        assert!(version.as_str().starts_with("USB Roboclaw"));
    }
}
