//! The serial link to one board: a [`Transport`] (a serial port, a
//! pseudo-terminal, or the in-process simulated board), and [`Board`], which
//! runs one request-answer transaction at a time with a deadline and
//! retries, and counts every way one can fail in [`BoardHealth`].
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
    /// Drops input nobody read (a late answer to an earlier request).
    fn clear_input(&mut self) -> io::Result<()>;
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

    fn clear_input(&mut self) -> io::Result<()> {
        rustix::termios::tcflush(self.fd(), rustix::termios::QueueSelector::IFlush)
            .map_err(io::Error::from)
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
    /// Bytes after a complete answer (line noise or a late answer).
    pub stray_bytes: u64,
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
            "transactions {} retries {} no_answer {} crc {} bad {} serial {} failed {} resets {} status_errors {}",
            self.transactions,
            self.retries,
            self.no_answer,
            self.crc_errors,
            self.bad_answers,
            self.serial_errors,
            self.failed,
            self.resets,
            self.status_errors
        )
    }
}

/// Link settings.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LinkSettings {
    pub address: u8,
    /// How long one attempt waits for its complete answer. Basicmicro's
    /// manual: the board discards a packet after a 10 ms gap, so a 10 ms
    /// timeout also resynchronises the board.
    pub answer_timeout: Duration,
    /// Attempts after the first.
    pub retries: u32,
}

/// One board on a transport.
pub struct Board<T: Transport> {
    transport: T,
    settings: LinkSettings,
    health: BoardHealth,
    rx: [u8; MAX_REPLY + 16],
}

enum AttemptError {
    NoAnswer,
    Decode(DecodeError),
    Serial(io::ErrorKind),
}

impl<T: Transport> Board<T> {
    pub fn new(transport: T, settings: LinkSettings) -> Self {
        Self {
            transport,
            settings,
            health: BoardHealth::default(),
            rx: [0; MAX_REPLY + 16],
        }
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
        self.transport.clear_input().map_err(serial)?;
        self.transport.write_all(request).map_err(serial)?;
        let deadline = Instant::now() + self.settings.answer_timeout;
        let mut have = 0;
        loop {
            match decode_reply(self.settings.address, command, &self.rx[..have]) {
                Ok((reply, used)) => {
                    self.health.stray_bytes += (have - used) as u64;
                    return Ok(reply);
                }
                Err(e) if e.is_incomplete() && have < self.rx.len() => {}
                Err(e) => return Err(AttemptError::Decode(e)),
            }
            let now = Instant::now();
            if now >= deadline {
                return Err(AttemptError::NoAnswer);
            }
            let n = self
                .transport
                .read_timeout(&mut self.rx[have..], deadline - now)
                .map_err(serial)?;
            have += n;
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
