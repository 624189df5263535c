//! The records of an MCAP file, walked with every length the file claims
//! checked against the bytes it holds before anything is allocated.
//!
//! The `mcap` crate trusts some claimed sizes: its chunk reader reserves a
//! record's claimed length inside a chunk before decompressing it (no limit
//! there, unlike the file level), and its decompressor the chunk's claimed
//! uncompressed size; its string fields reserve their claimed length (up to
//! 4 GiB) before reading. One flipped byte in any of them aborted the process
//! (found by fuzzing, fuzz/ targets `mcap_read` and `mcap_recover`). Here:
//!
//! - a record's length is at most the bytes left in the file, or in the
//!   decompressed chunk it is in;
//! - a chunk claims at most [`MAX_CHUNK_BYTES`] uncompressed, and is
//!   decompressed as a stream into a buffer that grows with what the data
//!   really decompresses to (never past the claim), then must match the
//!   claimed size and CRC;
//! - every string and string map of a record fits in the record (checked
//!   before `mcap::parse_record` parses it);
//!
//! so the memory a hostile file can make a reader take is bounded by its own
//! size plus one chunk of at most [`MAX_CHUNK_BYTES`]. A violation is a
//! [`RecordError`] naming the record's byte offset and type.

use std::borrow::Cow;
use std::io::Read;

use mcap::McapError;
use mcap::records::{ChunkHeader, Record, op};

/// Largest uncompressed chunk read, bytes (the logger closes its chunks at
/// 1 MiB; other writers' defaults are smaller still).
pub(super) const MAX_CHUNK_BYTES: u64 = 256 << 20;

/// Opcode and length in front of every record.
const RECORD_PREFIX: usize = 1 + 8;

/// A record that cannot be read: where it is and why.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(super) struct RecordError {
    /// Byte offset of the record in the file (for a record inside a chunk,
    /// of that chunk).
    pub offset: usize,
    pub reason: String,
}

impl std::fmt::Display for RecordError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "record at byte {}: {}", self.offset, self.reason)
    }
}

/// The name of a record type, for messages.
fn record_name(opcode: u8) -> String {
    let name = match opcode {
        op::HEADER => "header",
        op::FOOTER => "footer",
        op::SCHEMA => "schema",
        op::CHANNEL => "channel",
        op::MESSAGE => "message",
        op::CHUNK => "chunk",
        op::MESSAGE_INDEX => "message index",
        op::CHUNK_INDEX => "chunk index",
        op::ATTACHMENT => "attachment",
        op::ATTACHMENT_INDEX => "attachment index",
        op::STATISTICS => "statistics",
        op::METADATA => "metadata",
        op::METADATA_INDEX => "metadata index",
        op::SUMMARY_OFFSET => "summary offset",
        op::DATA_END => "data end",
        _ => return format!("opcode {opcode:#04x}"),
    };
    format!("{name} (opcode {opcode:#04x})")
}

/// An MCAP error with its causes (`McapError::Parse` says only "Record
/// parse failed"; binrw's error under it says what and where).
pub(super) fn mcap_reason(e: &McapError) -> String {
    let mut text = e.to_string();
    let mut source = std::error::Error::source(e);
    while let Some(inner) = source {
        text.push_str(": ");
        text.push_str(&inner.to_string());
        source = inner.source();
    }
    text
}

/// Walks the records of `bytes`: a whole file (after its start magic) or a
/// chunk's decompressed records.
pub(super) struct Records<'a> {
    bytes: &'a [u8],
    at: usize,
    /// Offset reported for errors inside a chunk (the chunk's), or `None`
    /// at the file level (each record's own offset).
    chunk_offset: Option<usize>,
    /// File level: a file may end without footer and end magic.
    truncated_ok: bool,
    done: bool,
}

impl<'a> Records<'a> {
    /// The records of an MCAP file. `truncated_ok` accepts a file that ends
    /// after any complete record (a killed writer's), without footer or end
    /// magic. The start magic is checked by the caller.
    pub(super) fn of_file(bytes: &'a [u8], truncated_ok: bool) -> Result<Self, RecordError> {
        if !bytes.starts_with(mcap::MAGIC) {
            return Err(RecordError {
                offset: 0,
                reason: "no MCAP magic".into(),
            });
        }
        Ok(Self {
            bytes,
            at: mcap::MAGIC.len(),
            chunk_offset: None,
            truncated_ok,
            done: false,
        })
    }

    fn of_chunk(records: &'a [u8], chunk_offset: usize) -> Self {
        Self {
            bytes: records,
            at: 0,
            chunk_offset: Some(chunk_offset),
            truncated_ok: true,
            done: false,
        }
    }

    /// The next record, or where and why it cannot be read.
    fn read_next(&mut self) -> Result<Option<(usize, Record<'a>)>, (usize, String)> {
        let at = self.at;
        let left = self.bytes.len() - at;
        if left == 0 {
            if self.truncated_ok {
                return Ok(None);
            }
            return Err((
                at,
                "the file ends without a footer and end magic (truncated: `atmo-mcap recover` \
                 keeps its complete records)"
                    .into(),
            ));
        }
        if left < RECORD_PREFIX {
            return Err((
                at,
                format!("ended in the middle of a record ({left} bytes)"),
            ));
        }
        let opcode = self.bytes[at];
        let mut claimed = [0; 8];
        claimed.copy_from_slice(&self.bytes[at + 1..at + RECORD_PREFIX]);
        let claimed = u64::from_le_bytes(claimed);
        let room = left - RECORD_PREFIX;
        let name = record_name(opcode);
        let len = usize::try_from(claimed)
            .ok()
            .filter(|&len| len <= room)
            .ok_or_else(|| {
                (
                    at,
                    format!("{name} claims {claimed} bytes, {room} are left"),
                )
            })?;
        let body = &self.bytes[at + RECORD_PREFIX..at + RECORD_PREFIX + len];
        self.at = at + RECORD_PREFIX + len;
        check_strings(opcode, body).map_err(|reason| (at, format!("{name}: {reason}")))?;
        let record = mcap::parse_record(opcode, body)
            .map_err(|e| (at, format!("{name}: {}", mcap_reason(&e))))?;
        if let Record::Footer(footer) = &record {
            self.done = true;
            if !self.truncated_ok {
                check_summary_crc(self.bytes, at, footer).map_err(|reason| (at, reason))?;
            }
            let rest = &self.bytes[self.at..];
            if !self.truncated_ok && rest != mcap::MAGIC {
                return Err((
                    at,
                    format!(
                        "the footer is followed by {} bytes, not the end magic",
                        rest.len()
                    ),
                ));
            }
        }
        Ok(Some((at, record)))
    }
}

/// The footer's CRC of the summary section (from `summary_start` through
/// the footer's own fields before the CRC), when the writer gave one
/// (0: none). The summary indexes a reader may trust instead of the data.
fn check_summary_crc(
    bytes: &[u8],
    footer_at: usize,
    footer: &mcap::records::Footer,
) -> Result<(), String> {
    if footer.summary_crc == 0 {
        return Ok(());
    }
    let end = footer_at + RECORD_PREFIX + 16;
    let start = if footer.summary_start == 0 {
        footer_at
    } else {
        usize::try_from(footer.summary_start).unwrap_or(usize::MAX)
    };
    if start > footer_at || end > bytes.len() {
        return Err(format!(
            "footer: summary_start {} is not before the footer at {footer_at}",
            footer.summary_start
        ));
    }
    let calculated = crc32fast::hash(&bytes[start..end]);
    if calculated != footer.summary_crc {
        return Err(format!(
            "footer: the summary section's CRC is {calculated:#010x}, the footer says {:#010x} \
             (the summary or the footer was changed)",
            footer.summary_crc
        ));
    }
    Ok(())
}

impl<'a> Iterator for Records<'a> {
    /// A record and its byte offset.
    type Item = Result<(usize, Record<'a>), RecordError>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.done {
            return None;
        }
        match self.read_next() {
            Ok(Some(record)) => Some(Ok(record)),
            Ok(None) => {
                self.done = true;
                None
            }
            Err((offset, reason)) => {
                self.done = true;
                Some(Err(match self.chunk_offset {
                    Some(chunk) => RecordError {
                        offset: chunk,
                        reason: format!("inside the chunk, at byte {offset}: {reason}"),
                    },
                    None => RecordError { offset, reason },
                }))
            }
        }
    }
}

/// A field of a record, as far as the allocation checks need it.
#[derive(Clone, Copy)]
enum Field {
    /// Fixed-size integers.
    Fixed(usize),
    /// `u32` length, then that many bytes (UTF-8).
    Str,
    /// `u32` length in bytes, then key and value strings.
    StrMap,
    /// `u32` length in bytes, then fixed-size entries (read one by one).
    Sized,
}

/// The fields of each record type up to its last string (mcap's records.rs).
fn layout(opcode: u8) -> &'static [Field] {
    use Field::{Fixed, Sized, Str, StrMap};
    match opcode {
        op::HEADER => &[Str, Str],
        op::SCHEMA => &[Fixed(2), Str, Str],
        op::CHANNEL => &[Fixed(4), Str, Str, StrMap],
        op::CHUNK => &[Fixed(28), Str],
        op::CHUNK_INDEX => &[Fixed(32), Sized, Fixed(8), Str],
        op::ATTACHMENT => &[Fixed(16), Str, Str],
        op::ATTACHMENT_INDEX => &[Fixed(40), Str, Str],
        op::METADATA => &[Str, StrMap],
        op::METADATA_INDEX => &[Fixed(16), Str],
        _ => &[],
    }
}

/// The `u32` length at `at` and the end of the bytes it covers, or `None`
/// if the record ends first (binrw then fails without a large allocation).
fn sized_at(body: &[u8], at: usize, what: &str) -> Result<Option<usize>, String> {
    let Some(prefix) = body.get(at..at + 4) else {
        return Ok(None);
    };
    let len = u32::from_le_bytes(prefix.try_into().unwrap_or_default()) as usize;
    let room = body.len() - at - 4;
    if len > room {
        return Err(format!(
            "{what} at byte {at} of the record claims {len} bytes, {room} are left"
        ));
    }
    Ok(Some(at + 4 + len))
}

/// Checks that every string (and string map) of a record fits in it:
/// `mcap` reserves a string's claimed length before reading it.
fn check_strings(opcode: u8, body: &[u8]) -> Result<(), String> {
    let mut at = 0;
    for field in layout(opcode) {
        let end = match *field {
            Field::Fixed(n) => Some(at + n),
            Field::Str => sized_at(body, at, "a string")?,
            Field::Sized => sized_at(body, at, "an index")?,
            Field::StrMap => {
                let end = sized_at(body, at, "a map")?;
                if let Some(end) = end {
                    let map = &body[..end];
                    let mut entry = at + 4;
                    while entry < end {
                        match sized_at(map, entry, "a map string")? {
                            Some(next) => entry = next,
                            None => break,
                        }
                    }
                }
                end
            }
        };
        match end {
            Some(end) if end <= body.len() => at = end,
            _ => return Ok(()),
        }
    }
    Ok(())
}

/// The records of a chunk (at byte `offset` of its file), decompressed and
/// checked whole: its claimed uncompressed size within [`MAX_CHUNK_BYTES`],
/// the data decompressing to exactly that size, its CRC (if not 0), and
/// every record in it within the decompressed bytes.
pub(super) fn chunk_records(
    header: &ChunkHeader,
    data: &[u8],
    offset: usize,
) -> Result<Vec<Record<'static>>, String> {
    let claimed = header.uncompressed_size;
    if claimed > MAX_CHUNK_BYTES {
        return Err(format!(
            "uncompressed size {claimed} bytes, over the {MAX_CHUNK_BYTES}-byte limit"
        ));
    }
    let records: Cow<'_, [u8]> = match header.compression.as_str() {
        "" => Cow::Borrowed(data),
        "lz4" => Cow::Owned(decompress(lz4::Decoder::new(data), claimed, "lz4")?),
        "zstd" => Cow::Owned(decompress(
            zstd::stream::read::Decoder::with_buffer(data),
            claimed,
            "zstd",
        )?),
        other => return Err(format!("unsupported compression `{other}`")),
    };
    if records.len() as u64 != claimed {
        return Err(format!(
            "{} bytes of records, the header claims {claimed}",
            records.len()
        ));
    }
    let saved = header.uncompressed_crc;
    let calculated = crc32fast::hash(&records);
    if saved != 0 && saved != calculated {
        return Err(format!(
            "chunk CRC mismatch (saved {saved:08x}, calculated {calculated:08x})"
        ));
    }
    Records::of_chunk(&records, offset)
        .map(|record| {
            record
                .map(|(_, record)| record.into_owned())
                .map_err(|e| e.reason)
        })
        .collect()
}

/// Reads what `decoder` decompresses, at most `claimed + 1` bytes (one more
/// than claimed shows a wrong claim); the buffer grows with the data.
fn decompress(
    decoder: std::io::Result<impl Read>,
    claimed: u64,
    codec: &str,
) -> Result<Vec<u8>, String> {
    let mut out = Vec::new();
    decoder
        .and_then(|decoder| decoder.take(claimed + 1).read_to_end(&mut out))
        .map_err(|e| format!("{codec} does not decompress: {e}"))?;
    Ok(out)
}
