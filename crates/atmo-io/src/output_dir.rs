//! Output folders written whole or not at all.
//!
//! A tool that writes several files into `--out DIR` and fails half-way
//! must not leave its new files mixed with an earlier run's (a fresh
//! `explain.json` beside a stale `heatmap_after.png`). [`StagedDir`] stages
//! the run in a hidden temporary folder beside `DIR` (same file system, so
//! the final move is a rename) and [`StagedDir::commit`] moves it into
//! place: the earlier `DIR`, if any, is renamed aside, the staged folder
//! renamed to `DIR`, and the earlier one removed. A run that fails (an
//! error or a panic before `commit`) removes its staging folder and leaves
//! `DIR` as it was.
//!
//! Only a folder this tool wrote is ever replaced: every staged folder
//! holds the marker file [`MARKER`], and an existing `DIR` is accepted only
//! if it is a real folder (not a symlink) that is empty or holds the
//! marker. Anything else (a file, a device, a symlink, someone's folder) is
//! refused by [`StagedDir::new`] before anything is written or moved, and
//! checked again by [`StagedDir::commit`] before anything is renamed.

use std::io;
use std::path::{Path, PathBuf};

/// The file every output folder holds: the sign that this tool wrote it
/// and may replace it.
pub const MARKER: &str = ".atmo-output";

/// Whether `target` may be replaced: absent, or a real folder that is empty
/// or holds [`MARKER`]. The error says what it is and names it.
pub fn check_replaceable(target: &Path) -> io::Result<()> {
    let meta = match std::fs::symlink_metadata(target) {
        Ok(m) => m,
        Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(()),
        Err(e) => return Err(context("inspecting", target, &e)),
    };
    let refuse = |what: &str| {
        Err(io::Error::new(
            io::ErrorKind::AlreadyExists,
            format!(
                "output folder {}: exists and is {what}; nothing was written or moved \
                 (give a new path, or a folder this tool wrote)",
                target.display()
            ),
        ))
    };
    let kind = meta.file_type();
    if kind.is_symlink() {
        return refuse("a symbolic link");
    }
    if kind.is_file() {
        return refuse("a file");
    }
    if !kind.is_dir() {
        return refuse("a device, FIFO or socket");
    }
    if target.join(MARKER).is_file() {
        return Ok(());
    }
    let mut entries = std::fs::read_dir(target).map_err(|e| context("reading", target, &e))?;
    if entries.next().is_none() {
        return Ok(());
    }
    refuse(&format!(
        "a folder this tool did not write (no {MARKER} in it)"
    ))
}

/// A run's output folder, staged until [`StagedDir::commit`].
#[derive(Debug)]
pub struct StagedDir {
    staging: tempfile::TempDir,
    target: PathBuf,
}

fn context(what: &str, path: &Path, e: &io::Error) -> io::Error {
    io::Error::new(e.kind(), format!("{what} {}: {e}", path.display()))
}

impl StagedDir {
    /// Stages the folder `target` (its parent is created if missing).
    ///
    /// # Errors
    /// The target exists and may not be replaced ([`check_replaceable`]);
    /// the parent cannot be created or written; the message names the path.
    pub fn new(target: impl Into<PathBuf>) -> io::Result<Self> {
        let target: PathBuf = target.into();
        check_replaceable(&target)?;
        let name = target
            .file_name()
            .ok_or_else(|| {
                io::Error::new(
                    io::ErrorKind::InvalidInput,
                    format!("output folder {} has no name", target.display()),
                )
            })?
            .to_string_lossy()
            .into_owned();
        let parent = match target.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => PathBuf::from("."),
        };
        std::fs::create_dir_all(&parent).map_err(|e| context("creating", &parent, &e))?;
        let staging = tempfile::Builder::new()
            .prefix(&format!(".{name}.partial-"))
            .tempdir_in(&parent)
            .map_err(|e| context("creating a staging folder in", &parent, &e))?;
        let marker = staging.path().join(MARKER);
        std::fs::write(
            &marker,
            b"written by an ATMO tool; replaced whole by its next run\n",
        )
        .map_err(|e| context("writing", &marker, &e))?;
        Ok(Self { staging, target })
    }

    /// Where the run writes its files until it commits.
    pub fn path(&self) -> &Path {
        self.staging.path()
    }

    /// The folder the outputs end up in.
    pub fn target(&self) -> &Path {
        &self.target
    }

    /// Moves the staged folder to the target, replacing an earlier one.
    ///
    /// # Errors
    /// A rename or removal fails; the message names the path. If the earlier
    /// folder was already renamed aside, it is moved back.
    pub fn commit(self) -> io::Result<PathBuf> {
        let Self { staging, target } = self;
        check_replaceable(&target)?;
        let staged = staging.keep();
        if std::fs::symlink_metadata(&target).is_err() {
            std::fs::rename(&staged, &target).map_err(|e| context("renaming into", &target, &e))?;
            return Ok(target);
        }
        let aside = staged.with_file_name(format!(
            ".{}.replaced-{}",
            target
                .file_name()
                .map_or_else(String::new, |n| n.to_string_lossy().into_owned()),
            std::process::id()
        ));
        std::fs::rename(&target, &aside).map_err(|e| context("moving aside", &target, &e))?;
        if let Err(e) = std::fs::rename(&staged, &target) {
            let _ = std::fs::rename(&aside, &target);
            return Err(context("renaming into", &target, &e));
        }
        std::fs::remove_dir_all(&aside).map_err(|e| context("removing", &aside, &e))?;
        Ok(target)
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)] // test code: an unwrap that fails is the failure report

    use super::{MARKER, StagedDir};

    fn scratch(tag: &str) -> std::path::PathBuf {
        let dir = std::env::temp_dir().join(format!("atmo-staged-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    fn names(dir: &std::path::Path) -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    }

    #[test]
    fn a_committed_run_replaces_the_earlier_folder_whole() {
        let root = scratch("commit");
        let out = root.join("out");
        std::fs::create_dir_all(&out).unwrap();
        std::fs::write(out.join(MARKER), b"").unwrap();
        std::fs::write(out.join("stale.png"), b"old").unwrap();
        std::fs::write(out.join("explain.json"), b"old").unwrap();
        let staged = StagedDir::new(&out).unwrap();
        std::fs::write(staged.path().join("explain.json"), b"new").unwrap();
        assert_eq!(
            names(&out),
            [MARKER, "explain.json", "stale.png"],
            "untouched until commit"
        );
        staged.commit().unwrap();
        assert_eq!(names(&out), [MARKER, "explain.json"]);
        assert_eq!(std::fs::read(out.join("explain.json")).unwrap(), b"new");
        assert_eq!(names(&root), ["out"], "no staging or replaced folder left");
        std::fs::remove_dir_all(root).unwrap();
    }

    #[test]
    fn a_failed_run_leaves_the_earlier_folder_as_it_was() {
        let root = scratch("fail");
        let out = root.join("out");
        std::fs::create_dir_all(&out).unwrap();
        std::fs::write(out.join(MARKER), b"").unwrap();
        std::fs::write(out.join("explain.json"), b"old").unwrap();
        {
            let staged = StagedDir::new(&out).unwrap();
            std::fs::write(staged.path().join("explain.json"), b"half").unwrap();
            // dropped without commit: the run failed
        }
        assert_eq!(std::fs::read(out.join("explain.json")).unwrap(), b"old");
        assert_eq!(names(&root), ["out"]);
        std::fs::remove_dir_all(root).unwrap();
    }

    #[test]
    fn a_new_folder_and_missing_parents_are_created_on_commit() {
        let root = scratch("new");
        let out = root.join("a/b/out");
        let staged = StagedDir::new(&out).unwrap();
        std::fs::write(staged.path().join("x"), b"1").unwrap();
        assert!(!out.exists());
        assert_eq!(staged.commit().unwrap(), out);
        assert_eq!(names(&out), [MARKER, "x"]);
        std::fs::remove_dir_all(root).unwrap();
    }

    /// `--out` at an existing file put a folder in its place (the file
    /// renamed aside), at a device node it moved the device: a file, a
    /// symlink (to a file or a folder), a device and a folder this tool did
    /// not write are refused before anything is written, and nothing moves.
    #[test]
    fn a_target_that_is_not_our_folder_is_refused_and_nothing_moves() {
        let root = scratch("refuse");
        let file = root.join("notes.txt");
        std::fs::write(&file, b"keep me").unwrap();
        let theirs = root.join("theirs");
        std::fs::create_dir_all(&theirs).unwrap();
        std::fs::write(theirs.join("thesis.tex"), b"keep me").unwrap();
        let link_file = root.join("link_file");
        let link_dir = root.join("link_dir");
        std::os::unix::fs::symlink(&file, &link_file).unwrap();
        std::os::unix::fs::symlink(&theirs, &link_dir).unwrap();
        let before = names(&root);
        for (target, what) in [
            (&file, "is a file"),
            (&theirs, "a folder this tool did not write"),
            (&link_file, "a symbolic link"),
            (&link_dir, "a symbolic link"),
        ] {
            let err = StagedDir::new(target).unwrap_err().to_string();
            assert!(
                err.contains(what) && err.contains(&target.display().to_string()),
                "{err}"
            );
        }
        assert_eq!(names(&root), before, "nothing written beside them");
        assert_eq!(std::fs::read(&file).unwrap(), b"keep me");
        assert_eq!(names(&theirs), ["thesis.tex"]);
        let device = std::path::Path::new("/dev/null");
        let err = StagedDir::new(device).unwrap_err().to_string();
        assert!(err.contains("a device"), "{err}");
        assert!(device.exists());

        // A target that turns into a file between staging and commit.
        let late = root.join("late");
        let staged = StagedDir::new(&late).unwrap();
        std::fs::write(&late, b"arrived meanwhile").unwrap();
        assert!(staged.commit().is_err());
        assert_eq!(std::fs::read(&late).unwrap(), b"arrived meanwhile");
        std::fs::remove_dir_all(root).unwrap();
    }

    #[test]
    fn an_empty_folder_or_our_own_is_replaced() {
        let root = scratch("ours");
        let empty = root.join("empty");
        std::fs::create_dir_all(&empty).unwrap();
        let staged = StagedDir::new(&empty).unwrap();
        std::fs::write(staged.path().join("a"), b"1").unwrap();
        staged.commit().unwrap();
        let again = StagedDir::new(&empty).unwrap();
        std::fs::write(again.path().join("b"), b"2").unwrap();
        again.commit().unwrap();
        assert_eq!(names(&empty), [MARKER, "b"]);
        std::fs::remove_dir_all(root).unwrap();
    }
}
