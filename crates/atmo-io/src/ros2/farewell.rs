//! The participant's farewell: one SPDP `DATA(p[UD])` sent after the DDS
//! participant has stopped, so that peers drop it, and every endpoint it
//! had, at once instead of after its lease (50 s).
//!
//! Why it is needed: RustDDS 0.15.1 does dispose its endpoints (SEDP) and
//! its participant (SPDP) at shutdown, but as key-only DATA submessages
//! whose payload is the serialized key (a PL_CDR parameter list holding
//! `PID_ENDPOINT_GUID` or `PID_PARTICIPANT_GUID`: 28 bytes), with
//! `PID_STATUS_INFO` and without `PID_KEY_HASH` in the inline QoS (rustdds
//! `src/rtps/message.rs`, `data_msg`, the `DDSData::DisposeByKey` arm; the
//! discovery writers dispose by key in `src/discovery/discovery.rs`,
//! `send_endpoint_dispose_message` and `on_participant_shutting_down`).
//! Fast DDS takes the instance of a dispose from `PID_KEY_HASH`, or from a
//! key-only payload of at most 16 bytes (`MessageReceiver::proc_Submsg_Data`
//! ignores a longer one); its SPDP and SEDP listeners then find no key and
//! drop the dispose, so the daemon's endpoints stay in a Fast DDS peer's
//! graph until the participant lease runs out.
//!
//! The farewell is the dispose Fast DDS (and the RTPS spec, 9.6.4.8) expect:
//! inline QoS `PID_KEY_HASH` = the participant GUID (prefix + `00 00 01 c1`)
//! and `PID_STATUS_INFO` = disposed | unregistered, no payload, from the
//! participant's SPDP writer to the SPDP readers. It goes where RustDDS
//! sends its own SPDP announcements: the SPDP multicast group (unless the
//! node is loopback-only) and the well-known SPDP unicast port of each of
//! the 12 same-host participant slots on 127.0.0.1. A peer that removes a
//! participant removes its endpoints with it. The sequence number is 2^32,
//! above any announcement RustDDS sends, so a best-effort SPDP reader takes
//! it as the newest sample of that writer. It is sent only once the
//! participant's threads have stopped: an announcement after it would bring
//! the participant back. Peers that are neither on this host's first 12
//! slots nor reachable by multicast (unicast-only discovery to another
//! host) still see the endpoints until the lease ends.

use std::net::{Ipv4Addr, SocketAddrV4, UdpSocket};

/// RTPS spec 9.6.2.3: port base, domain gain, participant gain, and the
/// offsets of SPDP multicast (d0) and unicast (d1).
const PORT_BASE: u16 = 7400;
const DOMAIN_GAIN: u16 = 250;
const PARTICIPANT_GAIN: u16 = 2;
const SPDP_UNICAST_OFFSET: u16 = 10;
/// The SPDP multicast group of the RTPS spec (9.6.1.4.1).
const SPDP_MULTICAST: Ipv4Addr = Ipv4Addr::new(239, 255, 0, 1);
/// Same-host participant slots RustDDS announces to
/// (`rustdds::network::constant::SPDP_LOCALHOST_PEER_COUNT`).
const LOCALHOST_SLOTS: u16 = 12;

/// RTPS 2.3, vendor id 01.12 (RustDDS: the participant's own vendor).
const RTPS_HEADER: [u8; 8] = [b'R', b'T', b'P', b'S', 2, 3, 0x01, 0x12];
const DATA: u8 = 0x15;
/// Little endian (E) and inline QoS (Q); neither data (D) nor key (K).
const DATA_FLAGS: u8 = 0x01 | 0x02;
const SPDP_READER: [u8; 4] = [0x00, 0x01, 0x00, 0xc7];
const SPDP_WRITER: [u8; 4] = [0x00, 0x01, 0x00, 0xc2];
const PARTICIPANT_ENTITY: [u8; 4] = [0x00, 0x00, 0x01, 0xc1];
const PID_KEY_HASH: u16 = 0x0070;
const PID_STATUS_INFO: u16 = 0x0071;
const PID_SENTINEL: u16 = 0x0001;
/// Status info flags: disposed (1) | unregistered (2).
const DISPOSED_UNREGISTERED: [u8; 4] = [0, 0, 0, 3];
/// Sequence number 2^32 (high 1, low 0).
const SEQUENCE_HIGH: i32 = 1;
const SEQUENCE_LOW: u32 = 0;

/// Length of [`spdp_dispose`]'s message: header 20, submessage header 4,
/// DATA fields 20, key hash 20, status info 8, sentinel 4.
pub(super) const MESSAGE_LEN: usize = 76;

/// Who says farewell, taken from the participant before it stops.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) struct Farewell {
    pub(super) guid_prefix: [u8; 12],
    pub(super) domain: u16,
    pub(super) participant_id: u16,
    pub(super) loopback_only: bool,
}

/// The RTPS message disposing the participant `guid_prefix` (see the
/// module docs): one DATA submessage, everything in the inline QoS.
pub(super) fn spdp_dispose(guid_prefix: [u8; 12]) -> [u8; MESSAGE_LEN] {
    let mut m = Vec::with_capacity(MESSAGE_LEN);
    m.extend_from_slice(&RTPS_HEADER);
    m.extend_from_slice(&guid_prefix);
    m.push(DATA);
    m.push(DATA_FLAGS);
    let body_len = MESSAGE_LEN - 24;
    m.extend_from_slice(&(body_len as u16).to_le_bytes());
    m.extend_from_slice(&0u16.to_le_bytes()); // extra flags
    m.extend_from_slice(&16u16.to_le_bytes()); // octets to inline QoS
    m.extend_from_slice(&SPDP_READER);
    m.extend_from_slice(&SPDP_WRITER);
    m.extend_from_slice(&SEQUENCE_HIGH.to_le_bytes());
    m.extend_from_slice(&SEQUENCE_LOW.to_le_bytes());
    m.extend_from_slice(&PID_KEY_HASH.to_le_bytes());
    m.extend_from_slice(&16u16.to_le_bytes());
    m.extend_from_slice(&guid_prefix);
    m.extend_from_slice(&PARTICIPANT_ENTITY);
    m.extend_from_slice(&PID_STATUS_INFO.to_le_bytes());
    m.extend_from_slice(&4u16.to_le_bytes());
    m.extend_from_slice(&DISPOSED_UNREGISTERED);
    m.extend_from_slice(&PID_SENTINEL.to_le_bytes());
    m.extend_from_slice(&0u16.to_le_bytes());
    let mut out = [0u8; MESSAGE_LEN];
    out.copy_from_slice(&m);
    out
}

/// Where RustDDS sends its SPDP announcements: the multicast group (unless
/// loopback-only) and 127.0.0.1 at the unicast port of every same-host
/// slot but the participant's own.
pub(super) fn destinations(
    domain: u16,
    participant_id: u16,
    loopback_only: bool,
) -> Vec<SocketAddrV4> {
    let base = PORT_BASE + DOMAIN_GAIN * domain;
    let multicast = (!loopback_only).then(|| SocketAddrV4::new(SPDP_MULTICAST, base));
    let unicast = (0..LOCALHOST_SLOTS)
        .filter(|&slot| slot != participant_id)
        .map(|slot| {
            SocketAddrV4::new(
                Ipv4Addr::LOCALHOST,
                base + SPDP_UNICAST_OFFSET + PARTICIPANT_GAIN * slot,
            )
        });
    multicast.into_iter().chain(unicast).collect()
}

impl Farewell {
    /// Sends the farewell to every destination; `Ok(n)` with the number of
    /// datagrams the OS accepted (a destination without a route, such as
    /// multicast on a host with none, is skipped), an error if none was.
    pub(super) fn send(&self) -> std::io::Result<usize> {
        let bind = if self.loopback_only {
            Ipv4Addr::LOCALHOST
        } else {
            Ipv4Addr::UNSPECIFIED
        };
        let socket = UdpSocket::bind((bind, 0))?;
        let message = spdp_dispose(self.guid_prefix);
        let mut sent = 0;
        let mut last_error = None;
        for to in destinations(self.domain, self.participant_id, self.loopback_only) {
            match socket.send_to(&message, to) {
                Ok(_) => sent += 1,
                Err(e) => last_error = Some(e),
            }
        }
        match (sent, last_error) {
            (0, Some(e)) => Err(e),
            _ => Ok(sent),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_dispose_names_the_participant_in_its_key_hash() {
        let prefix = [0x01, 0x12, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12];
        let m = spdp_dispose(prefix);
        assert_eq!(&m[..8], b"RTPS\x02\x03\x01\x12");
        assert_eq!(&m[8..20], &prefix);
        assert_eq!((m[20], m[21]), (DATA, DATA_FLAGS));
        let body_len = usize::from(u16::from_le_bytes([m[22], m[23]]));
        assert_eq!(24 + body_len, MESSAGE_LEN, "submessage length");
        assert_eq!(&m[28..32], &SPDP_READER);
        assert_eq!(&m[32..36], &SPDP_WRITER);
        assert_eq!(
            &m[36..44],
            &[1, 0, 0, 0, 0, 0, 0, 0],
            "sequence number 2^32"
        );
        // Inline QoS: key hash = GUID, status info = disposed | unregistered.
        assert_eq!(&m[44..48], &[0x70, 0x00, 16, 0]);
        assert_eq!(&m[48..60], &prefix);
        assert_eq!(&m[60..64], &PARTICIPANT_ENTITY);
        assert_eq!(&m[64..72], &[0x71, 0x00, 4, 0, 0, 0, 0, 3]);
        assert_eq!(&m[72..76], &[0x01, 0x00, 0, 0], "sentinel");
    }

    #[test]
    fn destinations_are_the_spdp_ports_of_the_domain() {
        let loopback = destinations(194, 1, true);
        assert_eq!(loopback.len(), 11, "12 slots but our own");
        assert!(loopback.iter().all(|a| *a.ip() == Ipv4Addr::LOCALHOST));
        assert_eq!(loopback[0].port(), 7400 + 250 * 194 + 10);
        assert!(!loopback.iter().any(|a| a.port() == 7400 + 250 * 194 + 12));
        let lan = destinations(0, 0, false);
        assert_eq!(lan[0], SocketAddrV4::new(SPDP_MULTICAST, 7400));
        assert_eq!(lan.len(), 12);
        assert_eq!(lan[1].port(), 7412);
    }
}
