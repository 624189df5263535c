//! Reading a file the user names, whole and bounded: the one rule every
//! reader of an input goes through (configurations, flight logs,
//! recordings, campaign shards).
//!
//! An input is a regular file: a device such as `/dev/zero` would be read
//! until memory runs out, a FIFO would block. Its size is checked against
//! the limit of its kind before anything is allocated, and the read itself
//! is bounded too (a file that grows while read).
//!
//! Refusals are `std::io::Error`s of kind `InvalidInput` whose message
//! names the kind of input; the caller puts the path on them, as it does
//! on the operating system's own errors.

use std::io::Read as _;
use std::path::Path;

/// What kind of input a file is: its name in messages and its size limit.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct InputKind {
    /// The kind with its article, as a message says it: "a configuration".
    pub name: &'static str,
    /// The largest file read, bytes.
    pub max_bytes: u64,
    /// What to do with a file over the limit ("" for nothing).
    pub advice: &'static str,
}

/// A TOML configuration (robot, flight, MPC, scenario, campaign, daemon):
/// the largest shipped is a few kilobytes.
pub const CONFIGURATION: InputKind = InputKind {
    name: "a configuration",
    max_bytes: 16 << 20,
    advice: "",
};

/// Checks that `path` is a regular file of at most `kind.max_bytes` and
/// returns its size.
///
/// # Errors
/// The operating system's error (no such file, permission), or
/// `InvalidInput` for a folder, a device, a FIFO, a socket, or a file over
/// the limit.
pub fn check(path: &Path, kind: InputKind) -> std::io::Result<u64> {
    let meta = std::fs::metadata(path)?;
    if !meta.is_file() {
        let what = if meta.is_dir() {
            "a folder"
        } else {
            "a device, FIFO or socket"
        };
        return Err(refuse(format!(
            "{what}, not a regular file: {} is read from a file",
            kind.name
        )));
    }
    if meta.len() > kind.max_bytes {
        return Err(refuse(format!(
            "{} bytes, over the {}-byte limit of {}{}",
            meta.len(),
            kind.max_bytes,
            kind.name,
            advice(kind)
        )));
    }
    Ok(meta.len())
}

/// Reads `path` whole after [`check`], at most `kind.max_bytes` even if the
/// file grows meanwhile.
///
/// # Errors
/// As [`check`], and `InvalidInput` for a file that grew past the limit
/// while read.
pub fn read(path: &Path, kind: InputKind) -> std::io::Result<Vec<u8>> {
    let len = check(path, kind)?;
    let mut bytes = Vec::with_capacity(usize::try_from(len).unwrap_or(0));
    std::fs::File::open(path)?
        .take(kind.max_bytes + 1)
        .read_to_end(&mut bytes)?;
    if bytes.len() as u64 > kind.max_bytes {
        return Err(refuse(format!(
            "grew past the {}-byte limit of {} while being read",
            kind.max_bytes, kind.name
        )));
    }
    Ok(bytes)
}

/// [`read`] as UTF-8 text.
///
/// # Errors
/// As [`read`], and `InvalidData` naming the offset of the first byte
/// that is not UTF-8.
pub fn read_text(path: &Path, kind: InputKind) -> std::io::Result<String> {
    String::from_utf8(read(path, kind)?).map_err(|e| {
        std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!(
                "not UTF-8 text: invalid byte at offset {}",
                e.utf8_error().valid_up_to()
            ),
        )
    })
}

fn advice(kind: InputKind) -> String {
    if kind.advice.is_empty() {
        String::new()
    } else {
        format!(": {}", kind.advice)
    }
}

fn refuse(message: String) -> std::io::Error {
    std::io::Error::new(std::io::ErrorKind::InvalidInput, message)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)] // reason: test set-up

    use super::*;

    const SMALL: InputKind = InputKind {
        name: "a test input",
        max_bytes: 8,
        advice: "split it",
    };

    fn scratch(name: &str) -> std::path::PathBuf {
        let dir = std::env::temp_dir().join(format!("atmo-input-file-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        dir.join(name)
    }

    #[test]
    fn devices_and_folders_are_refused_before_reading() {
        for device in ["/dev/zero", "/dev/null"] {
            if Path::new(device).exists() {
                let err = read(Path::new(device), SMALL).unwrap_err();
                assert_eq!(err.kind(), std::io::ErrorKind::InvalidInput);
                assert_eq!(
                    err.to_string(),
                    "a device, FIFO or socket, not a regular file: a test input is read from a file"
                );
            }
        }
        let err = read(&std::env::temp_dir(), SMALL).unwrap_err();
        assert!(err.to_string().starts_with("a folder, not a regular file"));
    }

    #[test]
    fn a_file_over_its_kinds_limit_is_refused_with_the_advice() {
        let path = scratch("nine.txt");
        std::fs::write(&path, b"123456789").unwrap();
        let err = read(&path, SMALL).unwrap_err();
        assert_eq!(
            err.to_string(),
            "9 bytes, over the 8-byte limit of a test input: split it"
        );
        std::fs::write(&path, b"12345678").unwrap();
        assert_eq!(read(&path, SMALL).unwrap(), b"12345678");
    }

    #[test]
    fn text_that_is_not_utf8_names_the_offset() {
        let path = scratch("latin1.txt");
        std::fs::write(&path, b"ab\xe9").unwrap();
        let err = read_text(&path, SMALL).unwrap_err();
        assert_eq!(err.kind(), std::io::ErrorKind::InvalidData);
        assert!(err.to_string().contains("offset 2"), "{err}");
        let missing = read(&scratch("missing"), SMALL).unwrap_err();
        assert_eq!(missing.kind(), std::io::ErrorKind::NotFound);
    }
}
