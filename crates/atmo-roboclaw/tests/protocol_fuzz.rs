//! Decoding never panics on any input, and never takes a prefix of a valid
//! answer for a wrong one.
#![allow(clippy::unwrap_used)]

use atmo_roboclaw::protocol::{Command, decode_reply, decode_request};
use proptest::prelude::*;

proptest! {
    #![proptest_config(ProptestConfig::with_cases(4000))]

    #[test]
    fn decode_reply_takes_any_bytes(
        bytes in proptest::collection::vec(any::<u8>(), 0..80),
        which in 0usize..Command::ALL.len(),
        address in any::<u8>(),
    ) {
        let command = Command::ALL[which];
        match decode_reply(address, command, &bytes) {
            Ok((_, used)) => prop_assert!(used <= bytes.len() && used > 0),
            Err(e) => {
                // Every error names its command (or the byte it refused).
                prop_assert!(!e.to_string().is_empty());
            }
        }
    }

    #[test]
    fn decode_request_takes_any_bytes(
        bytes in proptest::collection::vec(any::<u8>(), 0..40),
        address in any::<u8>(),
    ) {
        if let Ok((request, used)) = decode_request(address, &bytes) {
            prop_assert!(used <= bytes.len());
            // What decodes re-encodes to the same bytes.
            let frame = request.encode(address);
            prop_assert_eq!(frame.as_bytes(), &bytes[..used]);
        }
    }

    #[test]
    fn random_bytes_after_a_valid_header_rarely_pass_the_crc(
        data in proptest::collection::vec(any::<u8>(), 7..8),
    ) {
        // 5 random data bytes and a random CRC: accepted only if the CRC
        // happens to match (then the decode is the data's).
        let r = decode_reply(0x80, Command::ReadEncoderM2, &data);
        if let Ok((_, used)) = r {
            prop_assert_eq!(used, 7);
        }
    }
}
