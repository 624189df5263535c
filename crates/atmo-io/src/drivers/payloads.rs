//! Zero-copy payloads of the driver ports: `repr(C)`, plain data, each with
//! a sequence number and a CLOCK_MONOTONIC stamp, and a fixed iceoryx2 type
//! name (the default name holds the crate path, which differs between
//! binaries and makes the second process fail with `IncompatibleTypes`).

// The derive emits `unsafe impl ZeroCopySend`: iceoryx2 requires it to
// share a type through shared memory. Sound here: every type is `repr(C)`,
// holds only plain numbers, no pointers and no references.
#![allow(unsafe_code)]

use iceoryx2::prelude::ZeroCopySend;

/// Sequence number (per publisher, from 0) and stamp of a sample.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, ZeroCopySend)]
#[type_name("atmo::drivers::PortHeader")]
pub struct PortHeader {
    pub sequence: u64,
    /// CLOCK_MONOTONIC, ns (the same clock in every process of the machine).
    pub stamp_ns: u64,
}

/// Daemon -> thruster driver: normalized commands in [0, 1], rotors 1..4.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend)]
#[type_name("atmo::drivers::ThrusterCommand")]
pub struct ThrusterCommand {
    pub header: PortHeader,
    pub thrust: [f64; 4],
}

/// Daemon -> tilt driver: tilt velocity, rad/s, positive towards drive,
/// and the pilot's request to home again (the encoder reset switch; the
/// daemon sets it only while disarmed, the driver acts on its rising edge).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend)]
#[type_name("atmo::drivers::TiltVelocityCommand")]
pub struct TiltVelocityCommand {
    pub header: PortHeader,
    pub velocity: f64,
    pub rehome: bool,
}

/// Tilt driver -> daemon: encoder counts (continuous, zero at varphi = 0).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, ZeroCopySend)]
#[type_name("atmo::drivers::TiltEncoder")]
pub struct TiltEncoder {
    pub header: PortHeader,
    pub counts: i64,
}

/// Daemon -> wheel driver: wheel rates, rad/s, left and right.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend)]
#[type_name("atmo::drivers::WheelRateCommand")]
pub struct WheelRateCommand {
    pub header: PortHeader,
    pub rates: [f64; 2],
}

/// Contact sensor -> daemon: the wheels touch the ground.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, ZeroCopySend)]
#[type_name("atmo::drivers::GroundContact")]
pub struct GroundContact {
    pub header: PortHeader,
    /// 1 = contact, 0 = none (a byte, not a bool: every bit pattern is valid).
    pub contact: u8,
    /// Zero (explicit padding).
    pub reserved: [u8; 7],
}

/// Any driver -> daemon: "I am alive", with the last command it received
/// (for liveness and for the tick-to-driver latency).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, ZeroCopySend)]
#[type_name("atmo::drivers::DriverHeartbeat")]
pub struct DriverHeartbeat {
    pub header: PortHeader,
    /// [`super::DriverId`] as a number.
    pub driver: u32,
    /// Zero (explicit padding).
    pub reserved: u32,
    /// Sequence and stamp of the last command received, and when it was
    /// received (CLOCK_MONOTONIC ns); zeros if none yet.
    pub last_command_sequence: u64,
    pub last_command_stamp_ns: u64,
    pub last_command_received_ns: u64,
}
