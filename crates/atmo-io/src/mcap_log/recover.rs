//! Turning a truncated log into a valid one.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufReader, BufWriter};
use std::path::{Path, PathBuf};

use mcap::sans_io::LinearReaderOptions;

use super::PROFILE;
use crate::error::{IoError, Result};

/// What [`recover`] saved.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RecoverReport {
    pub output: PathBuf,
    /// Messages copied.
    pub messages: u64,
    pub channels: usize,
    /// Latest log time copied, ns (0 if none).
    pub last_log_time_ns: u64,
    /// Why reading stopped early (the truncated record), if it did.
    pub stopped_by: Option<String>,
}

/// Copies every complete message of `input` (a log whose writer was killed:
/// no summary, no footer, maybe half a chunk) into a new, finished log at
/// `output` with the same schemas and channels. Messages of the chunk being
/// written at the kill are lost; with the logger's periodic flush that is at
/// most the last flush period. A valid log is copied whole.
pub fn recover(input: impl AsRef<Path>, output: impl AsRef<Path>) -> Result<RecoverReport> {
    let input = input.as_ref();
    let output = output.as_ref();
    if input == output {
        return Err(IoError::Logger(format!(
            "recover: {}: output must differ from the input",
            input.display()
        )));
    }
    let file_err = |file: &Path| {
        let file = file.to_path_buf();
        move |source| IoError::File { file, source }
    };
    let reader = BufReader::new(File::open(input).map_err(file_err(input))?);
    let out = File::create(output).map_err(file_err(output))?;
    let mcap_err = |file: &Path| {
        let file = file.to_path_buf();
        move |source| IoError::Mcap { file, source }
    };
    let mut writer = mcap::WriteOptions::new()
        .profile(PROFILE)
        .library(concat!("atmo-io recover ", env!("CARGO_PKG_VERSION")))
        .compression_threads(0)
        .create(BufWriter::new(out))
        .map_err(mcap_err(output))?;

    let messages = mcap::io::MessageReader::new_with_options(
        reader,
        LinearReaderOptions::default().with_skip_end_magic(true),
    );
    // Input channel id -> output channel id.
    let mut channels: BTreeMap<u16, u16> = BTreeMap::new();
    let mut schemas: BTreeMap<u16, u16> = BTreeMap::new();
    let mut copied = 0u64;
    let mut last = 0u64;
    let mut stopped_by = None;
    for message in messages {
        let message = match message {
            Ok(m) => m,
            Err(e) => {
                stopped_by = Some(e.to_string());
                break;
            }
        };
        let channel = &message.channel;
        let out_channel = if let Some(id) = channels.get(&channel.id) {
            *id
        } else {
            let schema_id = match &channel.schema {
                None => 0,
                Some(schema) => {
                    if let Some(id) = schemas.get(&schema.id) {
                        *id
                    } else {
                        let id = writer
                            .add_schema(&schema.name, &schema.encoding, &schema.data)
                            .map_err(mcap_err(output))?;
                        schemas.insert(schema.id, id);
                        id
                    }
                }
            };
            let id = writer
                .add_channel(
                    schema_id,
                    &channel.topic,
                    &channel.message_encoding,
                    &channel.metadata,
                )
                .map_err(mcap_err(output))?;
            channels.insert(channel.id, id);
            id
        };
        writer
            .write_to_known_channel(
                &mcap::records::MessageHeader {
                    channel_id: out_channel,
                    sequence: message.sequence,
                    log_time: message.log_time,
                    publish_time: message.publish_time,
                },
                &message.data,
            )
            .map_err(mcap_err(output))?;
        copied += 1;
        last = last.max(message.log_time);
    }
    writer.finish().map_err(mcap_err(output))?;
    Ok(RecoverReport {
        output: output.to_path_buf(),
        messages: copied,
        channels: channels.len(),
        last_log_time_ns: last,
        stopped_by,
    })
}
