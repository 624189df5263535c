//! The serial link to one board: a [`Transport`] (a serial port, a
//! pseudo-terminal, or the in-process simulated board), and [`Board`], which
//! runs one request-answer transaction at a time with a deadline and
//! retries, and counts every way one can fail in [`BoardHealth`].
//!
//! Framing. Packet serial has no sequence numbers: an answer is known only
//! by its length and, for reads, by its CRC (which covers the address and
//! the command byte of the request). A board that answers after the
//! attempt gave up (a scheduler that held the simulated board back, a
//! driver preempted past its deadline) still answers, in order, once per
//! request. So an attempt that gives up leaves its answer *owed*: the next
//! attempt does not flush the input but reads the owed answers off the
//! front of the stream first (each matched by its command: length, CRC or
//! acknowledgement), then its own. An owed answer that does not match
//! where it should was never sent (the board dropped the request) and is
//! skipped. With nothing owed, bytes waiting before a request are noise
//! and are flushed. A late answer is thus never read as the answer to a
//! later request.
//!
//! Deadline. An attempt waits for the request and its longest answer on
//! the wire at the configured baud rate plus the board's turnaround
//! (`answer_timeout`), and takes one last look at the input before it
//! calls the answer missing: a driver preempted past its deadline finds
//! the answer that arrived meanwhile instead of flushing it.
//!
//! Nothing here panics or allocates per transaction: requests and answers
//! live in fixed buffers, errors are `Copy` values.

use std::io;
use std::time::{Duration, Instant};

use crate::protocol::{
    Command, DecodeError, MAX_REPLY, Motor, Reply, Request, Version, decode_reply,
};

/// A byte pipe to a board.
pub trait Transport {
    /// Writes every byte of `bytes`.
    fn write_all(&mut self, bytes: &[u8]) -> io::Result<()>;
    /// Waits at most `timeout` for input, then reads what is there into
    /// `buf`; `Ok(0)` when nothing arrived in time.
    fn read_timeout(&mut self, buf: &mut [u8], timeout: Duration) -> io::Result<usize>;
    /// Drops input nobody read; returns how many bytes it dropped (as far
    /// as the transport can tell).
    fn clear_input(&mut self) -> io::Result<usize>;
}

/// A serial port that could not be opened.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("serial port {path}: {reason}")]
pub struct SerialOpenError {
    pub path: String,
    pub reason: String,
}

/// A real serial port (or a pseudo-terminal's slave side) through the
/// `serialport` crate: 8N1, no flow control, raw.
pub struct SerialTransport {
    port: serialport::TTYPort,
}

impl SerialTransport {
    /// Opens `path` at `baud`.
    pub fn open(path: &str, baud: u32) -> Result<Self, SerialOpenError> {
        let port = serialport::new(path, baud)
            .timeout(Duration::from_millis(100))
            .open_native()
            .map_err(|e| SerialOpenError {
                path: path.to_string(),
                reason: e.to_string(),
            })?;
        Ok(Self { port })
    }

    fn fd(&self) -> rustix::fd::BorrowedFd<'_> {
        use std::os::fd::AsRawFd;
        // SAFETY: the descriptor belongs to `self.port`, which outlives the
        // borrow (tied to `&self`) and is never closed while borrowed.
        #[allow(unsafe_code)]
        unsafe {
            rustix::fd::BorrowedFd::borrow_raw(self.port.as_raw_fd())
        }
    }
}

/// Waits until `fd` is readable or `timeout` passes (false). Our own
/// poll: serialport's timed read builds an error string on every timeout.
pub(crate) fn wait_readable(fd: rustix::fd::BorrowedFd<'_>, timeout: Duration) -> io::Result<bool> {
    use rustix::event::{PollFd, PollFlags, Timespec, poll};
    let ts = Timespec {
        tv_sec: timeout.as_secs() as i64,
        tv_nsec: i64::from(timeout.subsec_nanos()),
    };
    let mut fds = [PollFd::new(&fd, PollFlags::IN)];
    match poll(&mut fds, Some(&ts)) {
        Ok(n) => Ok(n > 0),
        // A signal: the caller's deadline loop asks again.
        Err(rustix::io::Errno::INTR) => Ok(false),
        Err(e) => Err(e.into()),
    }
}

impl Transport for SerialTransport {
    fn write_all(&mut self, bytes: &[u8]) -> io::Result<()> {
        io::Write::write_all(&mut self.port, bytes)
    }

    fn read_timeout(&mut self, buf: &mut [u8], timeout: Duration) -> io::Result<usize> {
        if buf.is_empty() || !wait_readable(self.fd(), timeout)? {
            return Ok(0);
        }
        match io::Read::read(&mut self.port, buf) {
            Ok(n) => Ok(n),
            Err(e) if e.kind() == io::ErrorKind::TimedOut => Ok(0),
            Err(e) => Err(e),
        }
    }

    fn clear_input(&mut self) -> io::Result<usize> {
        // The count is for the health counters only: a byte arriving
        // between the two calls is flushed uncounted.
        let waiting = rustix::io::ioctl_fionread(self.fd()).unwrap_or(0);
        rustix::termios::tcflush(self.fd(), rustix::termios::QueueSelector::IFlush)
            .map_err(io::Error::from)?;
        Ok(usize::try_from(waiting).unwrap_or(usize::MAX))
    }
}

/// Why a transaction failed after all its attempts.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum LinkError {
    #[error("{command}: no answer within {timeout_ms} ms, {attempts} attempts")]
    NoAnswer {
        command: Command,
        attempts: u32,
        timeout_ms: u64,
    },
    #[error("{error} ({attempts} attempts)")]
    Decode { error: DecodeError, attempts: u32 },
    #[error("{command}: serial error {kind:?}")]
    Serial {
        command: Command,
        kind: io::ErrorKind,
    },
    #[error("{command}: unexpected answer {reply:?}")]
    Unexpected { command: Command, reply: Reply },
}

/// Counters of one board's link, reported, never fatal.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct BoardHealth {
    /// Transactions started (one request and its answer, with retries).
    pub transactions: u64,
    /// Requests sent (first tries and retries).
    pub attempts: u64,
    pub retries: u64,
    /// Attempts without a complete answer in time (a silent board).
    pub no_answer: u64,
    /// Answers whose CRC did not match.
    pub crc_errors: u64,
    /// Answers malformed otherwise (no acknowledgement, bad direction byte,
    /// unterminated version text).
    pub bad_answers: u64,
    /// Read or write errors of the serial device.
    pub serial_errors: u64,
    /// Transactions that failed after every attempt.
    pub failed: u64,
    /// Failed transactions in a row (0 after any success).
    pub consecutive_failures: u32,
    /// Bytes nobody asked for: after a complete answer, or waiting before
    /// a request with no answer owed (line noise).
    pub stray_bytes: u64,
    /// Answers that came after their attempt had given up, read off the
    /// stream by the next attempt (see the module doc).
    pub late_answers: u64,
    /// Owed answers that never came (the board dropped the request).
    pub owed_skipped: u64,
    /// Answer times, from the request written to the answer complete:
    /// counts below 1, 2, 5, 10, 20, 50, 100 ms and above.
    pub answer_ms: [u64; 8],
    /// Board resets detected by the driver (serial timeout or encoder
    /// back at its power-up value).
    pub resets: u64,
    /// Status reads with an error bit set (see [`crate::protocol::status`]).
    pub status_errors: u64,
    /// The last failure, if any.
    pub last_error: Option<LinkError>,
}

impl std::fmt::Display for BoardHealth {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "transactions {} retries {} no_answer {} crc {} bad {} serial {} failed {} resets {} status_errors {} late {} stray {} answer ms <1/2/5/10/20/50/100/more {:?}",
            self.transactions,
            self.retries,
            self.no_answer,
            self.crc_errors,
            self.bad_answers,
            self.serial_errors,
            self.failed,
            self.resets,
            self.status_errors,
            self.late_answers,
            self.stray_bytes,
            self.answer_ms
        )
    }
}

/// Link settings.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LinkSettings {
    pub address: u8,
    /// The line's baud rate (8N1: 10 bits a byte on the wire).
    pub baud: u32,
    /// The board's turnaround: how much longer than the request and its
    /// answer take on the wire one attempt waits. Basicmicro's manual: the
    /// board discards a packet after a 10 ms gap, so a 10 ms turnaround
    /// also resynchronises the board's receiver.
    pub answer_timeout: Duration,
    /// Attempts after the first.
    pub retries: u32,
}

/// Answers owed at most (attempts that gave up before their answer came);
/// more are forgotten, oldest first (a board that late is resynchronised
/// by the flush after the mismatch it causes).
const MAX_OWED: usize = 8;

/// Received bytes kept: the owed answers and the own one, with room.
const RX_LEN: usize = MAX_REPLY * (MAX_OWED + 1) + 16;

/// Upper bounds (ms) of [`BoardHealth::answer_ms`]'s buckets.
const ANSWER_BUCKETS_MS: [u128; 7] = [1, 2, 5, 10, 20, 50, 100];

/// One board on a transport.
pub struct Board<T: Transport> {
    transport: T,
    settings: LinkSettings,
    health: BoardHealth,
    /// Bytes received and not yet matched to an answer.
    rx: [u8; RX_LEN],
    rx_len: usize,
    /// Commands whose answers are owed, oldest first.
    owed: [Command; MAX_OWED],
    owed_len: usize,
}

enum AttemptError {
    NoAnswer,
    Decode(DecodeError),
    Serial(io::ErrorKind),
}

/// What the received bytes say about the current attempt.
enum Parse {
    /// Its answer, ending at byte `end`; `owed_used` owed answers (read or
    /// skipped) in the bytes before `owed_end`.
    Done {
        reply: Reply,
        end: usize,
        owed_end: usize,
        owed_used: usize,
    },
    /// Not complete yet; `owed_used` owed answers (ending at byte `end`) read.
    Wait { end: usize, owed_used: usize },
    /// Bytes that are neither an owed answer nor its own.
    Bad(DecodeError),
}

impl<T: Transport> Board<T> {
    pub fn new(transport: T, settings: LinkSettings) -> Self {
        Self {
            transport,
            settings,
            health: BoardHealth::default(),
            rx: [0; RX_LEN],
            rx_len: 0,
            owed: [Command::ReadStatus; MAX_OWED],
            owed_len: 0,
        }
    }

    /// How long one attempt at `command` (a request of `request_len`
    /// bytes) waits: both frames on the wire, then the board's turnaround.
    fn attempt_time(&self, command: Command, request_len: usize) -> Duration {
        let bits = 10 * (request_len + command.reply_len()) as u64;
        let wire = Duration::from_micros(bits * 1_000_000 / u64::from(self.settings.baud.max(1)));
        wire + self.settings.answer_timeout
    }

    /// Matches the received bytes: the owed answers in order (one that
    /// does not match was never sent and is skipped), then `command`'s.
    /// `last_look`: no more bytes will come in this attempt, so an owed
    /// answer still incomplete is taken as never sent.
    fn parse(&self, command: Command, last_look: bool) -> Parse {
        let address = self.settings.address;
        let bytes = &self.rx[..self.rx_len];
        let mut pos = 0;
        let mut owed_used = 0;
        // The owed answers settled: read, or known never sent (other bytes
        // stand where they would be). On the last look an incomplete one is
        // skipped to see whether this attempt's answer follows, but stays
        // owed if it does not: it may still come.
        let mut settled = (0, 0);
        let mut undecided = false;
        // The newest owed answer to the same command, if one was read:
        // if nothing follows it, it is this attempt's own (the owed request
        // was the one the board dropped; both ask the same).
        let mut same: Option<(Reply, usize)> = None;
        for &owed in &self.owed[..self.owed_len] {
            match decode_reply(address, owed, &bytes[pos..]) {
                Ok((reply, used)) => {
                    pos += used;
                    owed_used += 1;
                    same = (owed == command).then_some((reply, pos));
                }
                Err(e) if e.is_incomplete() && self.rx_len < RX_LEN => {
                    if !last_look {
                        return Parse::Wait {
                            end: settled.0,
                            owed_used: settled.1,
                        };
                    }
                    owed_used += 1;
                    undecided = true;
                }
                // Never sent: what is here belongs to a later request.
                Err(_) => owed_used += 1,
            }
            if !undecided {
                settled = (pos, owed_used);
            }
        }
        let own = decode_reply(address, command, &bytes[pos..]);
        if let (Err(_), true, true, Some((reply, end))) =
            (&own, last_look, pos == bytes.len(), same)
        {
            return Parse::Done {
                reply,
                end,
                owed_end: end,
                owed_used,
            };
        }
        match own {
            Ok((reply, used)) => Parse::Done {
                reply,
                end: pos + used,
                owed_end: pos,
                owed_used,
            },
            Err(e) if e.is_incomplete() && self.rx_len < RX_LEN => Parse::Wait {
                end: settled.0,
                owed_used: settled.1,
            },
            Err(e) => Parse::Bad(e),
        }
    }

    /// Drops the first `end` received bytes and the first `owed_used`
    /// owed answers (read, or found never sent).
    fn consume(&mut self, end: usize, owed_used: usize) {
        let end = end.min(self.rx_len);
        self.rx.copy_within(end..self.rx_len, 0);
        self.rx_len -= end;
        let used = owed_used.min(self.owed_len);
        self.owed.copy_within(used..self.owed_len, 0);
        self.owed_len -= used;
    }

    /// `command`'s answer is owed from now on (its attempt gave up).
    fn owe(&mut self, command: Command) {
        if self.owed_len == MAX_OWED {
            self.consume(0, 1);
        }
        self.owed[self.owed_len] = command;
        self.owed_len += 1;
    }

    /// Forgets everything received and owed, and flushes the input.
    fn resynchronise(&mut self) -> io::Result<()> {
        self.rx_len = 0;
        self.owed_len = 0;
        let dropped = self.transport.clear_input()?;
        self.health.stray_bytes += dropped as u64;
        Ok(())
    }

    pub fn health(&self) -> &BoardHealth {
        &self.health
    }

    pub fn health_mut(&mut self) -> &mut BoardHealth {
        &mut self.health
    }

    pub fn transport_mut(&mut self) -> &mut T {
        &mut self.transport
    }

    /// One transaction: the request, its answer, up to `retries` retries.
    pub fn transact(&mut self, request: Request) -> Result<Reply, LinkError> {
        let frame = request.encode(self.settings.address);
        let command = request.command();
        self.health.transactions += 1;
        let attempts = self.settings.retries + 1;
        let mut last = AttemptError::NoAnswer;
        for attempt in 0..attempts {
            if attempt > 0 {
                self.health.retries += 1;
            }
            self.health.attempts += 1;
            match self.attempt(command, frame.as_bytes()) {
                Ok(reply) => {
                    self.health.consecutive_failures = 0;
                    return Ok(reply);
                }
                Err(e) => {
                    match &e {
                        AttemptError::NoAnswer => self.health.no_answer += 1,
                        AttemptError::Decode(DecodeError::Crc { .. }) => {
                            self.health.crc_errors += 1;
                        }
                        AttemptError::Decode(_) => self.health.bad_answers += 1,
                        AttemptError::Serial(_) => self.health.serial_errors += 1,
                    }
                    last = e;
                }
            }
        }
        let error = match last {
            AttemptError::NoAnswer => LinkError::NoAnswer {
                command,
                attempts,
                timeout_ms: self.settings.answer_timeout.as_millis() as u64,
            },
            AttemptError::Decode(error) => LinkError::Decode { error, attempts },
            AttemptError::Serial(kind) => LinkError::Serial { command, kind },
        };
        self.fail(error);
        Err(error)
    }

    fn fail(&mut self, error: LinkError) {
        self.health.failed += 1;
        self.health.consecutive_failures = self.health.consecutive_failures.saturating_add(1);
        self.health.last_error = Some(error);
    }

    fn attempt(&mut self, command: Command, request: &[u8]) -> Result<Reply, AttemptError> {
        let serial = |e: io::Error| AttemptError::Serial(e.kind());
        if self.owed_len == 0 {
            // Nothing owed: whatever is waiting is not an answer.
            self.resynchronise().map_err(serial)?;
        }
        self.transport.write_all(request).map_err(serial)?;
        let sent = Instant::now();
        let deadline = sent + self.attempt_time(command, request.len());
        let mut last_look = false;
        loop {
            match self.parse(command, last_look) {
                Parse::Done {
                    reply,
                    end,
                    owed_end,
                    owed_used,
                } => {
                    self.count_late(owed_end, owed_used);
                    // Everything owed came before this answer, or never.
                    self.health.stray_bytes += (self.rx_len - end) as u64;
                    self.rx_len = 0;
                    self.owed_len = 0;
                    let ms = sent.elapsed().as_millis();
                    let bucket = ANSWER_BUCKETS_MS
                        .iter()
                        .position(|&b| ms < b)
                        .unwrap_or(ANSWER_BUCKETS_MS.len());
                    self.health.answer_ms[bucket] += 1;
                    return Ok(reply);
                }
                Parse::Bad(e) => {
                    // Neither owed nor its own: noise, or an answer to a
                    // request forgotten. Start afresh (the retry flushes).
                    self.resynchronise().map_err(serial)?;
                    return Err(AttemptError::Decode(e));
                }
                Parse::Wait { end, owed_used } => {
                    if last_look {
                        // The owed answers read are settled; this one is
                        // owed now, after the rest.
                        self.count_late(end, owed_used);
                        self.consume(end, owed_used);
                        self.owe(command);
                        return Err(AttemptError::NoAnswer);
                    }
                }
            }
            let now = Instant::now();
            // Past the deadline: one look without waiting (what arrived
            // while this process was not running), then the last parse.
            let wait = deadline.saturating_duration_since(now);
            let have = self.rx_len;
            let n = self
                .transport
                .read_timeout(&mut self.rx[have..], wait)
                .map_err(serial)?;
            self.rx_len += n;
            if n == 0 && now >= deadline {
                last_look = true;
            }
        }
    }

    /// Counts the owed answers among the first `owed_used` that were read
    /// (before byte `end`) as late, the rest as never sent.
    fn count_late(&mut self, end: usize, owed_used: usize) {
        if owed_used == 0 {
            return;
        }
        let mut pos = 0;
        for &owed in &self.owed[..owed_used.min(self.owed_len)] {
            match decode_reply(self.settings.address, owed, &self.rx[pos..end]) {
                Ok((_, used)) => {
                    pos += used;
                    self.health.late_answers += 1;
                }
                Err(_) => self.health.owed_skipped += 1,
            }
        }
    }

    fn expect_reply<V>(
        &mut self,
        request: Request,
        pick: impl Fn(Reply) -> Option<V>,
    ) -> Result<V, LinkError> {
        let reply = self.transact(request)?;
        pick(reply).ok_or_else(|| {
            let error = LinkError::Unexpected {
                command: request.command(),
                reply,
            };
            self.fail(error);
            error
        })
    }

    pub fn read_firmware_version(&mut self) -> Result<Version, LinkError> {
        self.expect_reply(Request::ReadFirmwareVersion, |r| match r {
            Reply::Version(v) => Some(v),
            _ => None,
        })
    }

    /// Encoder count and status byte of `motor`.
    pub fn read_encoder(&mut self, motor: Motor) -> Result<(i32, u8), LinkError> {
        self.expect_reply(Request::ReadEncoder(motor), |r| match r {
            Reply::Encoder { count, status } => Some((count, status)),
            _ => None,
        })
    }

    /// Speed of `motor`, counts/s.
    pub fn read_speed(&mut self, motor: Motor) -> Result<i32, LinkError> {
        self.expect_reply(Request::ReadSpeed(motor), |r| match r {
            Reply::Speed(s) => Some(s),
            _ => None,
        })
    }

    /// Status bits ([`crate::protocol::status`]); an error bit is counted.
    pub fn read_status(&mut self) -> Result<u32, LinkError> {
        let bits = self.expect_reply(Request::ReadStatus, |r| match r {
            Reply::Status(s) => Some(s),
            _ => None,
        })?;
        if bits & crate::protocol::status::ERRORS != 0 {
            self.health.status_errors += 1;
        }
        Ok(bits)
    }

    /// Serial timeout, 100 ms units.
    pub fn read_serial_timeout(&mut self) -> Result<u8, LinkError> {
        self.expect_reply(Request::ReadSerialTimeout, |r| match r {
            Reply::SerialTimeout(v) => Some(v),
            _ => None,
        })
    }

    fn write(&mut self, request: Request) -> Result<(), LinkError> {
        self.expect_reply(request, |r| (r == Reply::Ack).then_some(()))
    }

    /// Serial timeout in 100 ms units (0: off).
    pub fn set_serial_timeout(&mut self, tenths: u8) -> Result<(), LinkError> {
        self.write(Request::SetSerialTimeout(tenths))
    }

    /// Signed speed of `motor`, counts/s (the board's velocity PID).
    pub fn set_speed(&mut self, motor: Motor, counts_per_s: i32) -> Result<(), LinkError> {
        self.write(Request::Speed(motor, counts_per_s))
    }

    /// Signed duty of `motor`, -32767..=32767.
    pub fn set_duty(&mut self, motor: Motor, duty: i16) -> Result<(), LinkError> {
        self.write(Request::Duty(motor, duty))
    }

    /// Both motors to duty 0 (the PID let go: the motors coast to a stop).
    /// Tries both even if the first fails; returns the first failure.
    pub fn stop(&mut self) -> Result<(), LinkError> {
        let m1 = self.set_duty(Motor::M1, 0);
        let m2 = self.set_duty(Motor::M2, 0);
        m1.and(m2)
    }

    pub fn reset_encoders(&mut self) -> Result<(), LinkError> {
        self.write(Request::ResetEncoders)
    }

    pub fn set_encoder(&mut self, motor: Motor, count: i32) -> Result<(), LinkError> {
        self.write(Request::SetEncoder(motor, count))
    }
}

#[cfg(test)]
#[path = "link_tests.rs"]
mod tests;
