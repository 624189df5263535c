//! Walking a log's records chunk by chunk, checking every chunk's CRC.
//!
//! The `mcap` crate's message streams leave chunk CRCs unchecked by default
//! and stop at the first error, so a flipped bit inside a compressed chunk
//! either changes values silently or loses the rest of the log. Here each
//! chunk is decompressed whole and its CRC checked ([`chunk_records`]) before
//! any of its messages is handed on: a corrupt chunk is skipped and counted,
//! with the number of messages it held (from the message index records that
//! follow it), and reading goes on with the next chunk. Every length a record
//! claims is checked before it is allocated ([`super::records`]).

use std::borrow::Cow;

pub use crate::error::Integrity;
use mcap::read::ChannelAccumulator;
use mcap::records::Record;

use super::records::{RecordError, Records, chunk_records, mcap_reason};

/// How a scan ended.
pub(super) struct ScanEnd {
    pub integrity: Integrity,
    /// The structural error that stopped the scan (truncation, a record
    /// claiming more bytes than the file has), if any; the messages before
    /// it were delivered.
    pub stopped_by: Option<RecordError>,
}

/// Calls `on_message` for every message of `bytes` (an MCAP file) whose
/// chunk is sound, in file order. `truncated_ok` reads a log without footer
/// or end magic (a killed writer's) up to its last complete record.
/// `on_message`'s error aborts the scan and is returned.
pub(super) fn scan<E>(
    bytes: &[u8],
    truncated_ok: bool,
    mut on_message: impl FnMut(mcap::Message<'static>) -> Result<(), E>,
) -> Result<ScanEnd, E> {
    let mut integrity = Integrity::default();
    let records = match Records::of_file(bytes, truncated_ok) {
        Ok(records) => records,
        Err(e) => {
            return Ok(ScanEnd {
                integrity,
                stopped_by: Some(e),
            });
        }
    };
    let mut channels = ChannelAccumulator::<'static>::default();
    let mut after_corrupt_chunk = false;
    let mut past_data_end = false;
    let mut chunk_number = 0u64;
    let mut stopped_by = None;
    for record in records {
        let (offset, record) = match record {
            Ok(record) => record,
            Err(e) => {
                stopped_by = Some(e);
                break;
            }
        };
        if past_data_end {
            continue; // the summary repeats schemas and channels
        }
        match record {
            Record::Chunk { header, data } => {
                chunk_number += 1;
                match chunk_records(&header, &data, offset) {
                    Ok(inner) => {
                        after_corrupt_chunk = false;
                        for record in inner {
                            if let Err(e) = dispatch(record, &mut channels, &mut on_message) {
                                return handled(e, offset, integrity);
                            }
                        }
                    }
                    Err(e) => {
                        integrity.corrupt_chunks += 1;
                        integrity.note(|| format!("chunk {chunk_number} at byte {offset}: {e}"));
                        after_corrupt_chunk = true;
                    }
                }
            }
            Record::MessageIndex(index) if after_corrupt_chunk => {
                integrity.messages_in_corrupt_chunks += index.records.len() as u64;
            }
            Record::DataEnd(_) => {
                if truncated_ok {
                    break;
                }
                past_data_end = true;
            }
            other => {
                after_corrupt_chunk = false;
                if let Err(e) = dispatch(other, &mut channels, &mut on_message) {
                    return handled(e, offset, integrity);
                }
            }
        }
    }
    Ok(ScanEnd {
        integrity,
        stopped_by,
    })
}

/// A structural error of a record (bad schema or channel) or the caller's own.
enum DispatchError<E> {
    Mcap(mcap::McapError),
    Caller(E),
}

/// The caller's error aborts; a bad schema or channel record (at byte
/// `offset`, or in the chunk there) stops the scan like a truncation.
fn handled<E>(e: DispatchError<E>, offset: usize, integrity: Integrity) -> Result<ScanEnd, E> {
    match e {
        DispatchError::Caller(e) => Err(e),
        DispatchError::Mcap(e) => Ok(ScanEnd {
            integrity,
            stopped_by: Some(RecordError {
                offset,
                reason: mcap_reason(&e),
            }),
        }),
    }
}

fn dispatch<E>(
    record: Record<'_>,
    channels: &mut ChannelAccumulator<'static>,
    on_message: &mut impl FnMut(mcap::Message<'static>) -> Result<(), E>,
) -> Result<(), DispatchError<E>> {
    match record {
        Record::Schema { header, data } => channels
            .add_schema(header, Cow::Owned(data.into_owned()))
            .map_err(DispatchError::Mcap),
        Record::Channel(channel) => channels.add_channel(channel).map_err(DispatchError::Mcap),
        Record::Message { header, data } => {
            let channel = channels.get(header.channel_id).ok_or(DispatchError::Mcap(
                mcap::McapError::UnknownChannel(header.sequence, header.channel_id),
            ))?;
            on_message(mcap::Message {
                channel,
                sequence: header.sequence,
                log_time: header.log_time,
                publish_time: header.publish_time,
                data: Cow::Owned(data.into_owned()),
            })
            .map_err(DispatchError::Caller)
        }
        _ => Ok(()),
    }
}
