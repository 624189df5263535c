//! Turning a truncated log into a valid one.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufWriter, Write as _};
use std::path::{Path, PathBuf};

use super::PROFILE;
use super::attachments::{extras_of, write_extras};
use super::reader::check_magic;
use super::scan::{Integrity, scan};
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
    /// Corrupt chunks skipped (CRC mismatch) and the messages they held.
    pub skipped: Integrity,
}

/// Copies every complete message of `input` (a log whose writer was killed:
/// no summary, no footer, maybe half a chunk) into a new, finished log at
/// `output` with the same schemas and channels, attachments and metadata. Messages of the chunk being
/// written at the kill are lost; with the logger's periodic flush that is at
/// most the last flush period. A valid log is copied whole. A chunk whose CRC
/// does not match is skipped and counted in [`RecoverReport::skipped`]. Input
/// that does not start with the MCAP magic (random bytes, CSV, an empty file)
/// is refused with [`IoError::NotMcap`] before anything is written.
///
/// The log is written to a temporary file next to `output` and renamed
/// onto it once finished: a recovery that fails leaves `output` as it was,
/// and one that succeeds replaces it (a symbolic link at `output` is
/// replaced, not written through). An `output` that is the input file
/// under another name (a link, `./`) is refused: the input would be lost.
pub fn recover(input: impl AsRef<Path>, output: impl AsRef<Path>) -> Result<RecoverReport> {
    let input = input.as_ref();
    let output = output.as_ref();
    if input == output || same_file(input, output) {
        return Err(IoError::Logger(format!(
            "recover: {}: output must differ from the input ({} is the same file)",
            input.display(),
            output.display()
        )));
    }
    let file_err = |file: &Path| {
        let file = file.to_path_buf();
        move |cause| IoError::File { file, cause }
    };
    let bytes = super::reader::read_file(input)?;
    check_magic(input, &bytes)?;
    let folder = match output.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    let name = output.file_name().ok_or_else(|| {
        IoError::Logger(format!("recover: {}: not a file name", output.display()))
    })?;
    let mut staged = crate::output_dir::StagedFiles::new(folder);
    let out: File = staged
        .stage(name)
        .and_then(File::create)
        .map_err(file_err(output))?;
    let mcap_err = |file: &Path| {
        let file = file.to_path_buf();
        move |cause| IoError::Mcap { file, cause }
    };
    let mut writer = mcap::WriteOptions::new()
        .profile(PROFILE)
        .library(concat!("atmo-io recover ", env!("CARGO_PKG_VERSION")))
        .compression_threads(0)
        .create(BufWriter::new(out))
        .map_err(mcap_err(output))?;
    write_extras(&mut writer, &extras_of(&bytes), output)?;

    // Input channel id -> output channel id.
    let mut channels: BTreeMap<u16, u16> = BTreeMap::new();
    let mut schemas: BTreeMap<u16, u16> = BTreeMap::new();
    let mut copied = 0u64;
    let mut last = 0u64;
    let end = scan(&bytes, true, |message| {
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
        Ok::<(), IoError>(())
    })?;
    writer.finish().map_err(mcap_err(output))?;
    // Written whole before it is renamed into place.
    writer.into_inner().flush().map_err(file_err(output))?;
    staged.commit().map_err(file_err(output))?;
    Ok(RecoverReport {
        output: output.to_path_buf(),
        messages: copied,
        channels: channels.len(),
        last_log_time_ns: last,
        stopped_by: end.stopped_by.map(|e| e.to_string()),
        skipped: end.integrity,
    })
}

/// Whether `a` and `b` name one file (a hard or symbolic link, `./`): the
/// same device and inode. A path that does not exist is no file's.
fn same_file(a: &Path, b: &Path) -> bool {
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt as _;
        match (std::fs::metadata(a), std::fs::metadata(b)) {
            (Ok(a), Ok(b)) => a.dev() == b.dev() && a.ino() == b.ino(),
            _ => false,
        }
    }
    #[cfg(not(unix))]
    {
        match (std::fs::canonicalize(a), std::fs::canonicalize(b)) {
            (Ok(a), Ok(b)) => a == b,
            _ => false,
        }
    }
}
