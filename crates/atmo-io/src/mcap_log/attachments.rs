//! The attachments and metadata records of a log (the configuration a
//! flight ran with, stored at start-up), read from finished and truncated
//! logs alike.

use std::collections::BTreeMap;
use std::path::Path;

use mcap::records::Record;

use super::reader::{check_magic, read_file};
use super::records::Records;
use crate::error::{IoError, Result};

/// A file stored whole in a log.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LogAttachment {
    pub name: String,
    pub media_type: String,
    pub log_time_ns: u64,
    pub data: Vec<u8>,
}

/// A log's attachments and metadata records, in file order.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct LogExtras {
    pub attachments: Vec<LogAttachment>,
    /// `(name, entries)` of each metadata record.
    pub metadata: Vec<(String, BTreeMap<String, String>)>,
}

impl LogExtras {
    /// The attachment named `name`, if any.
    pub fn attachment(&self, name: &str) -> Option<&LogAttachment> {
        self.attachments.iter().find(|a| a.name == name)
    }

    /// The metadata record named `name`, if any.
    pub fn metadata(&self, name: &str) -> Option<&BTreeMap<String, String>> {
        self.metadata
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, entries)| entries)
    }
}

/// The attachments and metadata of the MCAP bytes, up to the data end or the
/// first record that does not parse (a truncated log keeps what precedes it).
pub(super) fn extras_of(bytes: &[u8]) -> LogExtras {
    let mut extras = LogExtras::default();
    let Ok(records) = Records::of_file(bytes, true) else {
        return extras;
    };
    for record in records {
        match record.map(|(_, record)| record) {
            Ok(Record::Attachment { header, data, .. }) => {
                extras.attachments.push(LogAttachment {
                    name: header.name,
                    media_type: header.media_type,
                    log_time_ns: header.log_time,
                    data: data.into_owned(),
                });
            }
            Ok(Record::Metadata(m)) => extras.metadata.push((m.name, m.metadata)),
            Ok(Record::DataEnd(_)) | Err(_) => break,
            Ok(_) => {}
        }
    }
    extras
}

/// Reads the attachments and metadata records of the log at `path` (finished
/// or truncated).
///
/// # Errors
/// A file that cannot be read or is not MCAP.
pub fn read_extras(path: impl AsRef<Path>) -> Result<LogExtras> {
    let path = path.as_ref();
    let bytes = read_file(path)?;
    check_magic(path, &bytes)?;
    Ok(extras_of(&bytes))
}

/// Writes `extras` into `writer` (used by `recover` to keep them).
pub(super) fn write_extras<W: std::io::Write + std::io::Seek>(
    writer: &mut mcap::Writer<W>,
    extras: &LogExtras,
    file: &Path,
) -> Result<()> {
    let err = |cause| IoError::Mcap {
        file: file.to_path_buf(),
        cause,
    };
    for a in &extras.attachments {
        writer
            .attach(&mcap::Attachment {
                log_time: a.log_time_ns,
                create_time: a.log_time_ns,
                name: a.name.clone(),
                media_type: a.media_type.clone(),
                data: std::borrow::Cow::Borrowed(&a.data),
            })
            .map_err(err)?;
    }
    for (name, entries) in &extras.metadata {
        writer
            .write_metadata(&mcap::records::Metadata {
                name: name.clone(),
                metadata: entries.clone(),
            })
            .map_err(err)?;
    }
    Ok(())
}
