//! Hostile logs (issue 21): a flipped bit inside a chunk is caught by the
//! chunk CRC and that chunk alone is skipped and counted; `recover` refuses
//! input that is not MCAP instead of writing an empty log.

// Helpers outside #[test] functions unwrap too (clippy.toml allows it in tests only).
#![allow(clippy::unwrap_used)]

mod support;

use std::path::{Path, PathBuf};

use atmo_io::IoError;
use atmo_io::mcap_log::{
    Compression, LoggerOptions, McapLogger, read_log, read_log_lossy, read_topic, recover,
};
use atmo_io::msg::MpcStatus;
use support::status;

/// Corrupt logs live apart from the interop folder, whose every log the
/// Python reference reader checks against its expected messages.
fn corruption_dir() -> std::path::PathBuf {
    let dir = std::path::PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("atmo-io-corruption");
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

const MESSAGES: u64 = 400;
const CHUNK_OPCODE: u8 = 0x06;

/// A finished log of `MESSAGES` statuses in small chunks (several chunks).
fn write_log(name: &str, compression: Compression) -> PathBuf {
    let path = corruption_dir().join(name);
    let options = LoggerOptions {
        compression,
        chunk_size: 4096,
        ..LoggerOptions::default()
    };
    let (log, thread) = McapLogger::spawn(&path, options).unwrap();
    let channel = log.channel::<MpcStatus>("/atmo/status").unwrap();
    for k in 0..MESSAGES {
        assert!(log.try_log(channel, status(k).stamp_ns, &status(k)));
    }
    log.finish();
    thread.join().unwrap();
    path
}

/// Byte ranges of the records (compressed or not) of every chunk record.
fn chunk_payloads(bytes: &[u8]) -> Vec<std::ops::Range<usize>> {
    let u64_at = |at: usize| u64::from_le_bytes(bytes[at..at + 8].try_into().unwrap()) as usize;
    let u32_at = |at: usize| u32::from_le_bytes(bytes[at..at + 4].try_into().unwrap()) as usize;
    let mut at = 8; // magic
    let mut chunks = Vec::new();
    while at + 9 <= bytes.len() {
        let opcode = bytes[at];
        let len = u64_at(at + 1);
        let body = at + 9;
        if opcode == CHUNK_OPCODE {
            // start, end, uncompressed size (u64 each), crc (u32), compression (string)
            let compression_len = u32_at(body + 28);
            let records_len_at = body + 32 + compression_len;
            let records = records_len_at + 8;
            chunks.push(records..records + u64_at(records_len_at));
        }
        at = body + len;
    }
    chunks
}

/// A copy of `log` with one bit flipped in the middle of its second chunk.
fn flip_bit_in_second_chunk(log: &Path, name: &str) -> PathBuf {
    let mut bytes = std::fs::read(log).unwrap();
    let chunks = chunk_payloads(&bytes);
    assert!(
        chunks.len() >= 3,
        "{} chunks: test needs several",
        chunks.len()
    );
    let target = &chunks[1];
    bytes[target.start + target.len() / 2] ^= 0x10;
    let out = corruption_dir().join(name);
    std::fs::write(&out, bytes).unwrap();
    out
}

fn flipped_bit_is_caught(compression: Compression, name: &str) {
    let log = write_log(&format!("{name}.mcap"), compression);
    let original = read_log(&log).unwrap();
    let statuses = read_topic::<MpcStatus>(&log, "/atmo/status").unwrap();
    assert_eq!(statuses.len() as u64, MESSAGES);
    let bad = flip_bit_in_second_chunk(&log, &format!("{name}_flipped.mcap"));

    // Strict readers: an error naming the file and the count, not changed values.
    let err = read_log(&bad).unwrap_err();
    assert!(matches!(err, IoError::LogCorrupt { .. }), "{err}");
    let text = err.to_string();
    assert!(text.contains(&bad.display().to_string()), "{text}");
    assert!(text.contains("1 corrupt chunk(s)"), "{text}");
    assert!(read_topic::<MpcStatus>(&bad, "/atmo/status").is_err());

    // Lossy reader: that chunk skipped and counted, every other message intact.
    let (messages, integrity) = read_log_lossy(&bad).unwrap();
    assert_eq!(integrity.corrupt_chunks, 1, "{integrity}");
    assert!(integrity.messages_in_corrupt_chunks > 0, "{integrity}");
    assert_eq!(
        messages.len() as u64 + integrity.messages_in_corrupt_chunks,
        original.len() as u64,
        "{integrity}"
    );
    for m in &messages {
        let same = original
            .iter()
            .find(|o| o.topic == m.topic && o.sequence == m.sequence)
            .unwrap();
        assert_eq!(m, same, "a message outside the corrupt chunk changed");
    }

    // recover copies the sound chunks and reports the skipped one.
    let recovered = corruption_dir().join(format!("{name}_recovered.mcap"));
    let report = recover(&bad, &recovered).unwrap();
    assert_eq!(report.skipped.corrupt_chunks, 1, "{report:?}");
    assert_eq!(report.messages, messages.len() as u64);
    assert_eq!(read_log(&recovered).unwrap().len(), messages.len());
}

#[test]
fn a_flipped_bit_in_a_zstd_chunk_skips_that_chunk_with_a_count() {
    flipped_bit_is_caught(Compression::Zstd, "corrupt_zstd");
}

#[test]
fn a_flipped_bit_in_an_uncompressed_chunk_fails_its_crc() {
    // No decompressor to notice: only the CRC can.
    flipped_bit_is_caught(Compression::None, "corrupt_plain");
}

#[test]
fn recover_refuses_input_that_is_not_mcap() {
    let dir = corruption_dir();
    let random: Vec<u8> = (0..4096u32)
        .map(|i| (i.wrapping_mul(2_654_435_761) >> 13) as u8)
        .collect();
    let cases: [(&str, &[u8]); 3] = [
        ("random.bin", &random),
        ("recording.csv", b"t,x,y,z\n0.0,1,2,3\n0.01,1,2,3\n"),
        ("empty.mcap", b""),
    ];
    for (name, bytes) in cases {
        let input = dir.join(name);
        std::fs::write(&input, bytes).unwrap();
        let output = dir.join(format!("{name}.recovered.mcap"));
        let _ = std::fs::remove_file(&output);
        let err = recover(&input, &output).unwrap_err();
        assert!(matches!(err, IoError::NotMcap { .. }), "{name}: {err}");
        let text = err.to_string();
        assert!(
            text.contains(name) && text.contains("not an MCAP file"),
            "{text}"
        );
        assert!(
            !output.exists(),
            "{name}: recover wrote {}",
            output.display()
        );
        assert!(
            matches!(read_log(&input), Err(IoError::NotMcap { .. })),
            "{name}"
        );
    }
}

/// Found by fuzzing (fuzz/, target `mcap_read`): a chunk header claiming
/// 2^56 bytes uncompressed made the decompressor reserve them, and the
/// process aborted. It is a corrupt chunk, skipped and counted like a bad CRC.
#[test]
fn a_chunk_claiming_a_huge_uncompressed_size_is_skipped_not_an_abort() {
    for (compression, codec, name) in [
        (Compression::Lz4, "lz4", "huge_lz4"),
        (Compression::Zstd, "zstd", "huge_zstd"),
        (Compression::None, "", "huge_plain"),
    ] {
        let log = write_log(&format!("{name}.mcap"), compression);
        let original = read_log(&log).unwrap();
        let mut bytes = std::fs::read(&log).unwrap();
        // The second chunk's header: start, end, uncompressed size, crc,
        // compression, records length, then its records.
        let records = chunk_payloads(&bytes)[1].start;
        let size_at = records - 8 - codec.len() - 4 - 4 - 8;
        bytes[size_at + 7] = 0x01;
        let bad = corruption_dir().join(format!("{name}_sized.mcap"));
        std::fs::write(&bad, bytes).unwrap();

        let err = read_log(&bad).unwrap_err();
        assert!(matches!(err, IoError::LogCorrupt { .. }), "{err}");
        assert!(err.to_string().contains("uncompressed size"), "{err}");
        let (messages, integrity) = read_log_lossy(&bad).unwrap();
        assert_eq!(integrity.corrupt_chunks, 1, "{name}: {integrity}");
        assert_eq!(
            messages.len() as u64 + integrity.messages_in_corrupt_chunks,
            original.len() as u64,
            "{name}: {integrity}"
        );
        let report = recover(
            &bad,
            corruption_dir().join(format!("{name}_sized_recovered.mcap")),
        )
        .unwrap();
        assert_eq!(report.skipped.corrupt_chunks, 1, "{name}: {report:?}");
    }
}
