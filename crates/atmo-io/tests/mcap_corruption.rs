//! Hostile logs: a flipped bit inside a chunk is caught by the
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
    flip_bit_in_chunk(log, name, 1)
}

/// A copy of `log` with one bit flipped in the middle of chunk `index`.
fn flip_bit_in_chunk(log: &Path, name: &str, index: usize) -> PathBuf {
    let mut bytes = std::fs::read(log).unwrap();
    let chunks = chunk_payloads(&bytes);
    assert!(
        chunks.len() >= 3,
        "{} chunks: test needs several",
        chunks.len()
    );
    let target = &chunks[index];
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
        let records = chunk_payloads(&bytes)[1].start;
        let (size_at, _) = chunk_size_and_crc_at(records, codec);
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

/// The header fields of the chunk whose records start at `records`:
/// (offset of `uncompressed_size`, offset of `uncompressed_crc`).
fn chunk_size_and_crc_at(records: usize, codec: &str) -> (usize, usize) {
    // ... uncompressed size (8), crc (4), compression (4 + len), records length (8)
    let crc_at = records - 8 - codec.len() - 4 - 4;
    (crc_at - 8, crc_at)
}

/// The first input the fuzzer crashed (fuzz/corpus/mcap/, copied here): an lz4
/// chunk whose decompressed records claim a length of 2^56 bytes. The
/// `mcap` chunk reader reserved that length before decompressing
/// ("memory allocation of 72057594037928710 bytes failed", an abort; the
/// chunk-size check above did not cover it). Now the chunk is decompressed
/// here into a buffer bounded by its claimed size, fails its lz4 checksum,
/// and is skipped and counted by offset.
#[test]
fn the_fuzzed_mcap_that_aborted_the_reader_is_a_corrupt_chunk() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/mcap_read_alloc_abort.mcap");
    let err = read_log(&path).unwrap_err();
    assert!(matches!(err, IoError::LogCorrupt { .. }), "{err}");
    let (messages, integrity) = read_log_lossy(&path).unwrap();
    assert_eq!(
        (
            messages.len(),
            integrity.corrupt_chunks,
            integrity.messages_in_corrupt_chunks
        ),
        (0, 1, 8),
        "{integrity}"
    );
    let note = integrity.first_problem.as_deref().unwrap();
    assert!(note.starts_with("chunk 1 at byte 42: lz4"), "{note}");
    let report = recover(&path, corruption_dir().join("fuzz_finding_recovered.mcap")).unwrap();
    assert_eq!(
        (report.messages, report.skipped.corrupt_chunks),
        (0, 1),
        "{report:?}"
    );
    assert!(atmo_io::mcap_log::read_extras(&path).is_ok());
}

/// The same claim where no checksum catches it first (an uncompressed
/// chunk with CRC 0, "not computed"): a record inside the chunk claiming
/// 2^56 bytes is refused against the bytes the chunk holds.
#[test]
fn a_record_in_a_chunk_claiming_more_than_the_chunk_holds_is_skipped() {
    let log = write_log("inner_claim.mcap", Compression::None);
    let original = read_log(&log).unwrap();
    let mut bytes = std::fs::read(&log).unwrap();
    let records = chunk_payloads(&bytes)[1].clone();
    let (_, crc_at) = chunk_size_and_crc_at(records.start, "");
    bytes[crc_at..crc_at + 4].fill(0);
    bytes[records.start + 1..records.start + 9].copy_from_slice(&(1u64 << 56).to_le_bytes());
    let bad = corruption_dir().join("inner_claim_bad.mcap");
    std::fs::write(&bad, bytes).unwrap();

    let (messages, integrity) = read_log_lossy(&bad).unwrap();
    assert_eq!(integrity.corrupt_chunks, 1, "{integrity}");
    assert_eq!(
        messages.len() as u64 + integrity.messages_in_corrupt_chunks,
        original.len() as u64,
        "{integrity}"
    );
    let note = integrity.first_problem.as_deref().unwrap();
    let claimed = format!(
        "claims {} bytes, {} are left",
        1u64 << 56,
        records.len() - 9
    );
    assert!(
        note.contains("inside the chunk, at byte 0") && note.contains(&claimed),
        "{note}"
    );
    let report = recover(&bad, corruption_dir().join("inner_claim_recovered.mcap")).unwrap();
    assert_eq!(report.skipped.corrupt_chunks, 1, "{report:?}");
}

/// File-level records: a length beyond the end of the file, and a string
/// claiming more than its record (mcap reserves a string's claimed length,
/// up to 4 GiB, before reading it) stop the read with the record's offset.
#[test]
fn a_record_or_string_claiming_more_than_the_file_holds_is_an_error_naming_its_offset() {
    let log = write_log("outer_claim.mcap", Compression::Zstd);
    let good = std::fs::read(&log).unwrap();
    // The header record at byte 8: opcode, length, then the profile string.
    let cases: [(&str, usize, &[u8], String); 2] = [
        (
            "record_length",
            9,
            &(1u64 << 56).to_le_bytes(),
            format!(
                "header (opcode 0x01) claims {} bytes, {} are left",
                1u64 << 56,
                good.len() - 17
            ),
        ),
        (
            "string_length",
            17,
            &0xffff_fff0u32.to_le_bytes(),
            "a string at byte 0 of the record claims 4294967280 bytes".to_string(),
        ),
    ];
    for (name, at, patch, expected) in cases {
        let mut bytes = good.clone();
        bytes[at..at + patch.len()].copy_from_slice(patch);
        let bad = corruption_dir().join(format!("outer_claim_{name}.mcap"));
        std::fs::write(&bad, bytes).unwrap();
        let err = read_log(&bad).unwrap_err();
        let text = err.to_string();
        assert!(
            matches!(err, IoError::LogRecord { offset: 8, .. }) && text.contains(&expected),
            "{name}: {text}"
        );
        assert!(text.contains(&bad.display().to_string()), "{text}");
        let report = recover(
            &bad,
            corruption_dir().join(format!("outer_claim_{name}_rec.mcap")),
        )
        .unwrap();
        let stop = report.stopped_by.unwrap();
        assert!(
            stop.starts_with("record at byte 8: ") && stop.contains(&expected),
            "{stop}"
        );
        assert!(atmo_io::mcap_log::read_extras(&bad).is_ok());
    }
}

/// A recovered log with a chunk missing was summarized as a landing at
/// 0.00 m/s with no warning (`replay` refuses it): the review names the
/// missing span of ticks and withholds the landing values it cannot know.
#[test]
fn a_recovered_log_with_a_chunk_missing_is_reviewed_as_partial() {
    use atmo_io::review::log::review_log;
    let log = write_log("hole.mcap", Compression::Zstd);
    let whole = review_log(&log, "/atmo/status").unwrap();
    assert!(whole.missing.is_empty(), "{:?}", whole.missing);
    for (index, starts_the_log) in [(1, true), (3, false)] {
        let bad = flip_bit_in_chunk(&log, &format!("hole{index}_flipped.mcap"), index);
        let recovered = corruption_dir().join(format!("hole{index}_recovered.mcap"));
        let report = recover(&bad, &recovered).unwrap();
        assert_eq!(report.skipped.corrupt_chunks, 1);
        let review = review_log(&recovered, "/atmo/status").unwrap();
        assert_eq!(review.missing.len(), 1, "{:?}", review.missing);
        let hole = review.missing[0];
        assert_eq!(hole.count(), report.skipped.messages_in_corrupt_chunks);
        assert_eq!(hole.after.is_none(), starts_the_log, "{hole}");
        // Withheld when the hole comes first (the first contact may be in
        // it); kept when the touchdown was found before the hole.
        let touchdown_first = matches!(
            (review.summary.touchdown_time_s, hole.from_s),
            (Some(t), Some(from)) if t < from
        );
        assert_eq!(touchdown_first, !starts_the_log, "{:?}", review.summary);
        if touchdown_first {
            assert_eq!(
                review.summary.impact_speed_mps,
                whole.summary.impact_speed_mps
            );
        } else {
            assert!(review.summary.impact_speed_mps.is_none());
            assert!(review.summary.touchdown_tilt_deg.is_none());
        }

        // The command line: a warning naming the span, a partial summary.json.
        let out = corruption_dir().join(format!("hole{index}_summary"));
        let _ = std::fs::remove_dir_all(&out);
        let output = std::process::Command::new(env!("CARGO_BIN_EXE_atmo-mcap"))
            .arg("summary")
            .arg(&recovered)
            .arg("--out")
            .arg(&out)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert!(
            stderr.contains("partial summary") && stderr.contains(&hole.to_string()),
            "{stderr}"
        );
        let json: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap())
                .unwrap();
        assert_eq!(
            json["partial"]["missing_ticks"][0]["before"], hole.before,
            "{json}"
        );
        assert_eq!(json["impact_speed_mps"].is_null(), !touchdown_first);
    }
}

/// The summary section's CRC in the footer is checked: a byte changed in
/// the summary (its indexes, which other readers trust) is an error naming
/// the footer.
#[test]
fn a_changed_summary_section_fails_the_footer_crc() {
    let log = write_log("summary_crc.mcap", Compression::Zstd);
    let mut bytes = std::fs::read(&log).unwrap();
    let footer = bytes.len() - 8 - (1 + 8 + 20);
    assert_eq!(bytes[footer], 0x02, "footer opcode");
    let summary_start =
        u64::from_le_bytes(bytes[footer + 9..footer + 17].try_into().unwrap()) as usize;
    assert!(summary_start > 0 && summary_start < footer);
    bytes[summary_start + 20] ^= 0x01;
    let bad = corruption_dir().join("summary_crc_changed.mcap");
    std::fs::write(&bad, bytes).unwrap();
    let err = read_log(&bad).unwrap_err().to_string();
    assert!(err.contains("summary section's CRC"), "{err}");
    assert!(read_log(&log).is_ok());
}

/// A device given as a log (`/dev/zero`) was read until memory ran out:
/// refused before reading, by every reader and by `recover`.
#[test]
fn a_device_or_a_folder_is_refused_as_a_log() {
    for path in ["/dev/zero", "/dev/null"] {
        if !Path::new(path).exists() {
            continue;
        }
        let err = read_log(path).unwrap_err().to_string();
        assert!(
            err.contains(path) && err.contains("not a regular file"),
            "{err}"
        );
        let out = corruption_dir().join("from_device.mcap");
        let err = recover(path, &out).unwrap_err().to_string();
        assert!(err.contains("not a regular file"), "{err}");
        assert!(!out.exists());
    }
    let err = read_log(corruption_dir()).unwrap_err().to_string();
    assert!(err.contains("not a regular file"), "{err}");
}
