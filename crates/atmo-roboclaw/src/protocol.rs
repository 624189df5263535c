//! Basicmicro packet serial: the subset the ATMO boards use, as pure frame
//! encoding and decoding (no I/O, no heap, no panics on any input).
//!
//! A request is `[address, command, data..., crc_hi, crc_lo]` where the CRC
//! covers address, command and data; read commands (16-19, 21, 15, 90) send
//! no data and no CRC. A write is acknowledged by one byte `0xFF` (nothing
//! at all if the board refused the packet). A read answers
//! `[data..., crc_hi, crc_lo]` where the CRC covers the request's address
//! and command and the answered data. Multi-byte numbers are big-endian.
//!
//! The CRC is Basicmicro's CRC16: polynomial 0x1021, initial value 0, no
//! reflection, no final XOR, i.e. CRC-16/XMODEM of the `crc` catalogue
//! (check value 0x31C3 on "123456789", tested below).
//!
//! Sources: the Basicmicro RoboClaw series user manual (packet serial and
//! advanced packet serial chapters) and the authors' Python library
//! (mandralis/ATMO, `atmo_ws/src/atmo/atmo/mpc/roboclaw_3.py`).

use crc::{CRC_16_XMODEM, Crc};

/// Basicmicro's CRC16.
const CRC16: Crc<u16> = Crc::<u16>::new(&CRC_16_XMODEM);

/// CRC16 of `bytes` as Basicmicro computes it.
pub fn crc16(bytes: &[u8]) -> u16 {
    CRC16.checksum(bytes)
}

/// CRC16 over the concatenation of `head` and `tail` (address and command,
/// then the answered data) without copying them together.
pub fn crc16_parts(head: &[u8], tail: &[u8]) -> u16 {
    let mut digest = CRC16.digest();
    digest.update(head);
    digest.update(tail);
    digest.finalize()
}

/// The acknowledgement byte of a valid write packet.
pub const ACK: u8 = 0xFF;

/// Longest firmware version text, terminator included (manual: 48 bytes).
pub const VERSION_MAX: usize = 48;

/// Longest request frame of the subset (address, command, 4 data, CRC).
pub const MAX_REQUEST: usize = 8;

/// Longest reply frame (the version text and its CRC).
pub const MAX_REPLY: usize = VERSION_MAX + 2;

/// Default packet-serial address (board mode 7).
pub const DEFAULT_ADDRESS: u8 = 0x80;

/// A motor channel of one board.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Motor {
    M1,
    M2,
}

impl Motor {
    pub fn index(self) -> usize {
        match self {
            Self::M1 => 0,
            Self::M2 => 1,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Self::M1 => "M1",
            Self::M2 => "M2",
        }
    }

    fn pick(self, m1: Command, m2: Command) -> Command {
        match self {
            Self::M1 => m1,
            Self::M2 => m2,
        }
    }
}

/// The commands of the subset, with Basicmicro's numbers.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum Command {
    /// 14: motors stop when no valid packet arrives for this long (100 ms units).
    SetSerialTimeout = 14,
    /// 15: reads the serial timeout back (100 ms units).
    ReadSerialTimeout = 15,
    /// 16/17: encoder count (signed 32 bit) and its status byte.
    ReadEncoderM1 = 16,
    ReadEncoderM2 = 17,
    /// 18/19: speed in counts/s and a direction byte.
    ReadSpeedM1 = 18,
    ReadSpeedM2 = 19,
    /// 20: both encoders to zero.
    ResetEncoders = 20,
    /// 21: firmware version text.
    ReadFirmwareVersion = 21,
    /// 22/23: set one encoder's count.
    SetEncoderM1 = 22,
    SetEncoderM2 = 23,
    /// 32/33: signed duty, -32767..=32767 (0 = coast to a stop).
    DutyM1 = 32,
    DutyM2 = 33,
    /// 35/36: signed speed, counts/s (the board's velocity PID).
    SpeedM1 = 35,
    SpeedM2 = 36,
    /// 90: status / error bits (32 bit, firmware 4.x).
    ReadStatus = 90,
}

impl Command {
    pub const ALL: [Command; 15] = [
        Command::SetSerialTimeout,
        Command::ReadSerialTimeout,
        Command::ReadEncoderM1,
        Command::ReadEncoderM2,
        Command::ReadSpeedM1,
        Command::ReadSpeedM2,
        Command::ResetEncoders,
        Command::ReadFirmwareVersion,
        Command::SetEncoderM1,
        Command::SetEncoderM2,
        Command::DutyM1,
        Command::DutyM2,
        Command::SpeedM1,
        Command::SpeedM2,
        Command::ReadStatus,
    ];

    pub fn from_u8(byte: u8) -> Option<Self> {
        Self::ALL.iter().copied().find(|c| *c as u8 == byte)
    }

    pub fn name(self) -> &'static str {
        match self {
            Self::SetSerialTimeout => "set serial timeout (14)",
            Self::ReadSerialTimeout => "read serial timeout (15)",
            Self::ReadEncoderM1 => "read encoder M1 (16)",
            Self::ReadEncoderM2 => "read encoder M2 (17)",
            Self::ReadSpeedM1 => "read speed M1 (18)",
            Self::ReadSpeedM2 => "read speed M2 (19)",
            Self::ResetEncoders => "reset encoders (20)",
            Self::ReadFirmwareVersion => "read firmware version (21)",
            Self::SetEncoderM1 => "set encoder M1 (22)",
            Self::SetEncoderM2 => "set encoder M2 (23)",
            Self::DutyM1 => "duty M1 (32)",
            Self::DutyM2 => "duty M2 (33)",
            Self::SpeedM1 => "speed M1 (35)",
            Self::SpeedM2 => "speed M2 (36)",
            Self::ReadStatus => "read status (90)",
        }
    }

    /// Bytes of the longest answer the board sends to this command (a
    /// write's acknowledgement is one byte; the version text is at most
    /// [`VERSION_MAX`] with its 0, then the CRC).
    pub fn reply_len(self) -> usize {
        match self {
            Self::ReadEncoderM1 | Self::ReadEncoderM2 | Self::ReadSpeedM1 | Self::ReadSpeedM2 => 7,
            Self::ReadStatus => 6,
            Self::ReadSerialTimeout => 3,
            Self::ReadFirmwareVersion => MAX_REPLY,
            Self::SetSerialTimeout
            | Self::ResetEncoders
            | Self::SetEncoderM1
            | Self::SetEncoderM2
            | Self::SpeedM1
            | Self::SpeedM2
            | Self::DutyM1
            | Self::DutyM2 => 1,
        }
    }

    /// Data bytes of a write request (`None`: a read, sent without data or CRC).
    pub fn write_data_len(self) -> Option<usize> {
        match self {
            Self::SetSerialTimeout => Some(1),
            Self::ResetEncoders => Some(0),
            Self::SetEncoderM1 | Self::SetEncoderM2 | Self::SpeedM1 | Self::SpeedM2 => Some(4),
            Self::DutyM1 | Self::DutyM2 => Some(2),
            Self::ReadSerialTimeout
            | Self::ReadEncoderM1
            | Self::ReadEncoderM2
            | Self::ReadSpeedM1
            | Self::ReadSpeedM2
            | Self::ReadFirmwareVersion
            | Self::ReadStatus => None,
        }
    }
}

impl std::fmt::Display for Command {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// One request of the subset, with its arguments.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Request {
    ReadFirmwareVersion,
    ReadEncoder(Motor),
    ReadSpeed(Motor),
    ReadStatus,
    ReadSerialTimeout,
    /// In 100 ms units (0 = off, 255 = 25.5 s).
    SetSerialTimeout(u8),
    ResetEncoders,
    SetEncoder(Motor, i32),
    Duty(Motor, i16),
    Speed(Motor, i32),
}

impl Request {
    pub fn command(self) -> Command {
        use Command as C;
        match self {
            Self::ReadFirmwareVersion => C::ReadFirmwareVersion,
            Self::ReadEncoder(m) => m.pick(C::ReadEncoderM1, C::ReadEncoderM2),
            Self::ReadSpeed(m) => m.pick(C::ReadSpeedM1, C::ReadSpeedM2),
            Self::ReadStatus => C::ReadStatus,
            Self::ReadSerialTimeout => C::ReadSerialTimeout,
            Self::SetSerialTimeout(_) => C::SetSerialTimeout,
            Self::ResetEncoders => C::ResetEncoders,
            Self::SetEncoder(m, _) => m.pick(C::SetEncoderM1, C::SetEncoderM2),
            Self::Duty(m, _) => m.pick(C::DutyM1, C::DutyM2),
            Self::Speed(m, _) => m.pick(C::SpeedM1, C::SpeedM2),
        }
    }

    /// The request's frame for the board at `address`.
    pub fn encode(self, address: u8) -> Frame<MAX_REQUEST> {
        let mut frame = Frame::new();
        frame.push(address);
        frame.push(self.command() as u8);
        match self {
            Self::SetSerialTimeout(v) => frame.push(v),
            Self::SetEncoder(_, v) | Self::Speed(_, v) => frame.extend(&v.to_be_bytes()),
            Self::Duty(_, v) => frame.extend(&v.to_be_bytes()),
            _ => {}
        }
        if self.command().write_data_len().is_some() {
            let crc = crc16(frame.as_bytes());
            frame.extend(&crc.to_be_bytes());
        }
        frame
    }
}

/// A frame in a fixed buffer (no heap on the control path).
#[derive(Clone, Copy, PartialEq, Eq)]
pub struct Frame<const N: usize> {
    buf: [u8; N],
    len: usize,
}

impl<const N: usize> Frame<N> {
    pub fn new() -> Self {
        Self {
            buf: [0; N],
            len: 0,
        }
    }

    /// Appends a byte; beyond capacity the byte is dropped (the subset's
    /// frames are sized so that this never happens; tested).
    pub fn push(&mut self, byte: u8) {
        if let Some(slot) = self.buf.get_mut(self.len) {
            *slot = byte;
            self.len += 1;
        }
    }

    pub fn extend(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.push(b);
        }
    }

    pub fn as_bytes(&self) -> &[u8] {
        &self.buf[..self.len]
    }

    /// Mutable view (fault injection in the simulator corrupts replies).
    pub fn as_mut_bytes(&mut self) -> &mut [u8] {
        &mut self.buf[..self.len]
    }
}

impl<const N: usize> Default for Frame<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> std::fmt::Debug for Frame<N> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Frame{:02x?}", self.as_bytes())
    }
}

/// Firmware version text (without its "\n\0" terminator), in a fixed buffer.
#[derive(Clone, Copy, PartialEq, Eq)]
pub struct Version {
    bytes: [u8; VERSION_MAX],
    len: usize,
}

impl Version {
    /// `text` truncated to what fits a reply.
    pub fn new(text: &str) -> Self {
        let mut bytes = [0; VERSION_MAX];
        let n = text.len().min(VERSION_MAX - 2);
        bytes[..n].copy_from_slice(&text.as_bytes()[..n]);
        Self { bytes, len: n }
    }

    /// The text; bytes that are not UTF-8 are reported as such.
    pub fn as_str(&self) -> &str {
        std::str::from_utf8(&self.bytes[..self.len]).unwrap_or("(not UTF-8)")
    }
}

impl std::fmt::Debug for Version {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Version({:?})", self.as_str())
    }
}

/// Encoder status byte bits (commands 16/17).
pub mod encoder_status {
    /// The counter wrapped below its minimum.
    pub const UNDERFLOW: u8 = 0x01;
    /// Counting backwards.
    pub const BACKWARD: u8 = 0x02;
    /// The counter wrapped above its maximum.
    pub const OVERFLOW: u8 = 0x04;
}

/// Status bits of command 90 (32 bit, firmware 4.x; RoboClaw user manual).
pub mod status {
    pub const E_STOP: u32 = 0x0000_0001;
    pub const TEMPERATURE_ERROR: u32 = 0x0000_0002;
    pub const TEMPERATURE2_ERROR: u32 = 0x0000_0004;
    pub const MAIN_VOLTAGE_HIGH_ERROR: u32 = 0x0000_0008;
    pub const LOGIC_VOLTAGE_HIGH_ERROR: u32 = 0x0000_0010;
    pub const LOGIC_VOLTAGE_LOW_ERROR: u32 = 0x0000_0020;
    pub const M1_DRIVER_FAULT: u32 = 0x0000_0040;
    pub const M2_DRIVER_FAULT: u32 = 0x0000_0080;
    pub const M1_SPEED_ERROR: u32 = 0x0000_0100;
    pub const M2_SPEED_ERROR: u32 = 0x0000_0200;
    pub const M1_POSITION_ERROR: u32 = 0x0000_0400;
    pub const M2_POSITION_ERROR: u32 = 0x0000_0800;
    pub const M1_CURRENT_ERROR: u32 = 0x0000_1000;
    pub const M2_CURRENT_ERROR: u32 = 0x0000_2000;
    pub const M1_OVER_CURRENT_WARNING: u32 = 0x0001_0000;
    pub const M2_OVER_CURRENT_WARNING: u32 = 0x0002_0000;
    pub const MAIN_VOLTAGE_HIGH_WARNING: u32 = 0x0004_0000;
    pub const MAIN_VOLTAGE_LOW_WARNING: u32 = 0x0008_0000;
    pub const TEMPERATURE_WARNING: u32 = 0x0010_0000;
    pub const TEMPERATURE2_WARNING: u32 = 0x0020_0000;
    /// S4 input triggered (a home / limit switch wired to S4).
    pub const S4_TRIGGERED: u32 = 0x0040_0000;
    /// S5 input triggered (the M2 home switch on ATMO's tilt board).
    pub const S5_TRIGGERED: u32 = 0x0080_0000;
    pub const SPEED_ERROR_LIMIT_WARNING: u32 = 0x0100_0000;
    pub const POSITION_ERROR_LIMIT_WARNING: u32 = 0x0200_0000;
    /// Every error bit: the board refuses to drive while one is set.
    pub const ERRORS: u32 = 0x0000_3FFF;
}

/// A decoded reply.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Reply {
    /// A write was accepted.
    Ack,
    /// Encoder count and status byte ([`encoder_status`]).
    Encoder {
        count: i32,
        status: u8,
    },
    /// Signed speed, counts/s.
    Speed(i32),
    /// Status bits ([`status`]).
    Status(u32),
    /// Serial timeout, 100 ms units.
    SerialTimeout(u8),
    Version(Version),
}

/// Why a reply (or, in the simulated board, a request) could not be decoded.
/// Each names the command and the offending byte or value.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum DecodeError {
    /// More bytes are needed (not an error until the answer's time is up).
    #[error("{command}: incomplete answer, {have} of {needed} bytes")]
    Incomplete {
        command: Command,
        have: usize,
        needed: usize,
    },
    #[error("{command}: CRC mismatch, computed {computed:#06x}, received {received:#06x}")]
    Crc {
        command: Command,
        computed: u16,
        received: u16,
    },
    #[error("{command}: expected the acknowledgement 0xff, got byte {byte:#04x}")]
    BadAck { command: Command, byte: u8 },
    #[error("{command}: version text without its terminating 0 within {VERSION_MAX} bytes")]
    Unterminated { command: Command },
    #[error("{command}: direction byte {byte:#04x} is neither 0 (forward) nor 1 (backward)")]
    BadDirection { command: Command, byte: u8 },
    /// Simulated board: a request for another address.
    #[error("request for address {byte:#04x}, this board is {address:#04x}")]
    WrongAddress { byte: u8, address: u8 },
    /// Simulated board: a command outside the subset.
    #[error("unknown command byte {byte} (address {address:#04x})")]
    UnknownCommand { byte: u8, address: u8 },
}

impl DecodeError {
    pub fn is_incomplete(&self) -> bool {
        matches!(self, Self::Incomplete { .. })
    }
}

fn need(command: Command, bytes: &[u8], needed: usize) -> Result<(), DecodeError> {
    if bytes.len() < needed {
        Err(DecodeError::Incomplete {
            command,
            have: bytes.len(),
            needed,
        })
    } else {
        Ok(())
    }
}

fn be_u32(b: &[u8]) -> u32 {
    let mut a = [0u8; 4];
    for (dst, src) in a.iter_mut().zip(b) {
        *dst = *src;
    }
    u32::from_be_bytes(a)
}

/// Checks the CRC of `data` (the reply without its last two bytes) against
/// `crc_bytes`, with the request's address and command in front.
fn check_crc(
    address: u8,
    command: Command,
    data: &[u8],
    crc_bytes: &[u8],
) -> Result<(), DecodeError> {
    let computed = crc16_parts(&[address, command as u8], data);
    let received = match crc_bytes {
        [hi, lo, ..] => u16::from_be_bytes([*hi, *lo]),
        _ => {
            return Err(DecodeError::Incomplete {
                command,
                have: data.len() + crc_bytes.len(),
                needed: data.len() + 2,
            });
        }
    };
    if computed == received {
        Ok(())
    } else {
        Err(DecodeError::Crc {
            command,
            computed,
            received,
        })
    }
}

/// Decodes the answer to `command` sent to `address` from the start of
/// `bytes`; returns the reply and the bytes it used. Never panics.
pub fn decode_reply(
    address: u8,
    command: Command,
    bytes: &[u8],
) -> Result<(Reply, usize), DecodeError> {
    if command.write_data_len().is_some() {
        need(command, bytes, 1)?;
        return if bytes[0] == ACK {
            Ok((Reply::Ack, 1))
        } else {
            Err(DecodeError::BadAck {
                command,
                byte: bytes[0],
            })
        };
    }
    match command {
        Command::ReadEncoderM1 | Command::ReadEncoderM2 => {
            need(command, bytes, 7)?;
            check_crc(address, command, &bytes[..5], &bytes[5..7])?;
            let count = be_u32(&bytes[..4]) as i32;
            Ok((
                Reply::Encoder {
                    count,
                    status: bytes[4],
                },
                7,
            ))
        }
        Command::ReadSpeedM1 | Command::ReadSpeedM2 => {
            need(command, bytes, 7)?;
            check_crc(address, command, &bytes[..5], &bytes[5..7])?;
            let raw = be_u32(&bytes[..4]) as i32;
            // Firmware sends the speed signed; older manuals describe a
            // magnitude with a direction byte. Accept both: a positive
            // value with "backward" is negated.
            let speed = match bytes[4] {
                1 if raw > 0 => -raw,
                0 | 1 => raw,
                byte => return Err(DecodeError::BadDirection { command, byte }),
            };
            Ok((Reply::Speed(speed), 7))
        }
        Command::ReadStatus => {
            need(command, bytes, 6)?;
            check_crc(address, command, &bytes[..4], &bytes[4..6])?;
            Ok((Reply::Status(be_u32(&bytes[..4])), 6))
        }
        Command::ReadSerialTimeout => {
            need(command, bytes, 3)?;
            check_crc(address, command, &bytes[..1], &bytes[1..3])?;
            Ok((Reply::SerialTimeout(bytes[0]), 3))
        }
        Command::ReadFirmwareVersion => decode_version(address, command, bytes),
        // Writes were answered above.
        _ => Err(DecodeError::BadAck {
            command,
            byte: bytes.first().copied().unwrap_or(0),
        }),
    }
}

fn decode_version(
    address: u8,
    command: Command,
    bytes: &[u8],
) -> Result<(Reply, usize), DecodeError> {
    let window = &bytes[..bytes.len().min(VERSION_MAX)];
    let Some(zero) = window.iter().position(|&b| b == 0) else {
        return if bytes.len() >= VERSION_MAX {
            Err(DecodeError::Unterminated { command })
        } else {
            Err(DecodeError::Incomplete {
                command,
                have: bytes.len(),
                needed: bytes.len() + 1,
            })
        };
    };
    let total = zero + 3;
    need(command, bytes, total)?;
    check_crc(address, command, &bytes[..=zero], &bytes[zero + 1..total])?;
    // The text ends in "\n\0"; keep neither.
    let text = &bytes[..zero];
    let text = text.strip_suffix(b"\n").unwrap_or(text);
    let mut version = Version {
        bytes: [0; VERSION_MAX],
        len: text.len(),
    };
    version.bytes[..text.len()].copy_from_slice(text);
    Ok((Reply::Version(version), total))
}

/// Encodes the board's answer `reply` to `command` (the simulated board).
pub fn encode_reply(address: u8, command: Command, reply: &Reply) -> Frame<MAX_REPLY> {
    let mut frame = Frame::new();
    match reply {
        Reply::Ack => {
            frame.push(ACK);
            return frame;
        }
        Reply::Encoder { count, status } => {
            frame.extend(&count.to_be_bytes());
            frame.push(*status);
        }
        Reply::Speed(speed) => {
            frame.extend(&speed.to_be_bytes());
            frame.push(u8::from(*speed < 0));
        }
        Reply::Status(bits) => frame.extend(&bits.to_be_bytes()),
        Reply::SerialTimeout(v) => frame.push(*v),
        Reply::Version(v) => {
            frame.extend(&v.bytes[..v.len]);
            frame.extend(b"\n\0");
        }
    }
    let crc = crc16_parts(&[address, command as u8], frame.as_bytes());
    frame.extend(&crc.to_be_bytes());
    frame
}

/// Decodes one request from the start of `bytes` for the board at
/// `address` (the simulated board); returns it and the bytes it used.
pub fn decode_request(address: u8, bytes: &[u8]) -> Result<(Request, usize), DecodeError> {
    let (Some(&addr), Some(&cmd)) = (bytes.first(), bytes.get(1)) else {
        // Not even a command byte yet: name the command we cannot know as
        // the firmware read, the shortest request.
        return Err(DecodeError::Incomplete {
            command: Command::ReadFirmwareVersion,
            have: bytes.len(),
            needed: 2,
        });
    };
    if addr != address {
        return Err(DecodeError::WrongAddress {
            byte: addr,
            address,
        });
    }
    let command =
        Command::from_u8(cmd).ok_or(DecodeError::UnknownCommand { byte: cmd, address })?;
    let Some(n) = command.write_data_len() else {
        let request = match command {
            Command::ReadEncoderM1 => Request::ReadEncoder(Motor::M1),
            Command::ReadEncoderM2 => Request::ReadEncoder(Motor::M2),
            Command::ReadSpeedM1 => Request::ReadSpeed(Motor::M1),
            Command::ReadSpeedM2 => Request::ReadSpeed(Motor::M2),
            Command::ReadStatus => Request::ReadStatus,
            Command::ReadSerialTimeout => Request::ReadSerialTimeout,
            _ => Request::ReadFirmwareVersion,
        };
        return Ok((request, 2));
    };
    let total = 2 + n + 2;
    need(command, bytes, total)?;
    let computed = crc16(&bytes[..2 + n]);
    let received = u16::from_be_bytes([bytes[2 + n], bytes[3 + n]]);
    if computed != received {
        return Err(DecodeError::Crc {
            command,
            computed,
            received,
        });
    }
    let data = &bytes[2..2 + n];
    let word = be_u32(data) as i32;
    let half = i16::from_be_bytes([
        data.first().copied().unwrap_or(0),
        data.get(1).copied().unwrap_or(0),
    ]);
    let request = match command {
        Command::SetSerialTimeout => Request::SetSerialTimeout(data.first().copied().unwrap_or(0)),
        Command::ResetEncoders => Request::ResetEncoders,
        Command::SetEncoderM1 => Request::SetEncoder(Motor::M1, word),
        Command::SetEncoderM2 => Request::SetEncoder(Motor::M2, word),
        Command::SpeedM1 => Request::Speed(Motor::M1, word),
        Command::SpeedM2 => Request::Speed(Motor::M2, word),
        Command::DutyM1 => Request::Duty(Motor::M1, half),
        _ => Request::Duty(Motor::M2, half),
    };
    Ok((request, total))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crc_is_basicmicros_crc16() {
        // CRC-16/XMODEM check value.
        assert_eq!(crc16(b"123456789"), 0x31C3);
        // Against the manual's bitwise algorithm on a real frame.
        let bitwise = |bytes: &[u8]| {
            let mut crc: u16 = 0;
            for &b in bytes {
                crc ^= u16::from(b) << 8;
                for _ in 0..8 {
                    crc = if crc & 0x8000 != 0 {
                        (crc << 1) ^ 0x1021
                    } else {
                        crc << 1
                    };
                }
            }
            crc
        };
        let frame = [0x80, 36, 0xff, 0xff, 0xfc, 0x18];
        assert_eq!(crc16(&frame), bitwise(&frame));
        assert_eq!(crc16_parts(&frame[..2], &frame[2..]), bitwise(&frame));
    }

    #[test]
    fn requests_round_trip_through_the_boards_decoder() {
        let requests = [
            Request::ReadFirmwareVersion,
            Request::ReadEncoder(Motor::M2),
            Request::ReadSpeed(Motor::M1),
            Request::ReadStatus,
            Request::ReadSerialTimeout,
            Request::SetSerialTimeout(5),
            Request::ResetEncoders,
            Request::SetEncoder(Motor::M2, -7),
            Request::Duty(Motor::M1, -32767),
            Request::Speed(Motor::M2, -1000),
            Request::Speed(Motor::M1, i32::MAX),
        ];
        for r in requests {
            let frame = r.encode(0x80);
            assert!(frame.as_bytes().len() <= MAX_REQUEST);
            assert_eq!(
                decode_request(0x80, frame.as_bytes()),
                Ok((r, frame.as_bytes().len()))
            );
        }
        // Speed M2 -1000 counts/s on the wire.
        let f = Request::Speed(Motor::M2, -1000).encode(0x80);
        assert_eq!(&f.as_bytes()[..6], &[0x80, 36, 0xff, 0xff, 0xfc, 0x18]);
    }

    #[test]
    fn replies_round_trip_and_errors_name_command_and_byte() {
        let cases = [
            (
                Command::ReadEncoderM2,
                Reply::Encoder {
                    count: -26325,
                    status: 2,
                },
            ),
            (Command::ReadSpeedM1, Reply::Speed(-1200)),
            (Command::ReadStatus, Reply::Status(status::S5_TRIGGERED)),
            (Command::ReadSerialTimeout, Reply::SerialTimeout(3)),
            (
                Command::ReadFirmwareVersion,
                Reply::Version(Version::new("USB Roboclaw 2x15a v4.2.8")),
            ),
            (Command::SpeedM2, Reply::Ack),
        ];
        for (command, reply) in cases {
            let frame = encode_reply(0x80, command, &reply);
            let bytes = frame.as_bytes();
            assert_eq!(decode_reply(0x80, command, bytes), Ok((reply, bytes.len())));
            // Every strict prefix is incomplete, never wrong.
            for n in 0..bytes.len() {
                let e = decode_reply(0x80, command, &bytes[..n]).unwrap_err();
                assert!(e.is_incomplete(), "{command}: prefix {n}: {e}");
            }
        }
        let mut frame = encode_reply(
            0x80,
            Command::ReadEncoderM2,
            &Reply::Encoder {
                count: 5,
                status: 0,
            },
        );
        frame.as_mut_bytes()[6] ^= 0x01;
        let e = decode_reply(0x80, Command::ReadEncoderM2, frame.as_bytes()).unwrap_err();
        assert!(matches!(
            e,
            DecodeError::Crc {
                command: Command::ReadEncoderM2,
                ..
            }
        ));
        assert!(e.to_string().contains("read encoder M2 (17)"), "{e}");
        let e = decode_reply(0x80, Command::SpeedM2, &[0x00]).unwrap_err();
        assert_eq!(
            e.to_string(),
            "speed M2 (36): expected the acknowledgement 0xff, got byte 0x00"
        );
    }
}
