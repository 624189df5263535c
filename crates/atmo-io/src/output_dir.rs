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

use std::io;
use std::path::{Path, PathBuf};

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
    /// The parent cannot be created or written; the message names the path.
    pub fn new(target: impl Into<PathBuf>) -> io::Result<Self> {
        let target: PathBuf = target.into();
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
        let staged = staging.keep();
        if !target.exists() {
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

    use super::StagedDir;

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
        std::fs::write(out.join("stale.png"), b"old").unwrap();
        std::fs::write(out.join("explain.json"), b"old").unwrap();
        let staged = StagedDir::new(&out).unwrap();
        std::fs::write(staged.path().join("explain.json"), b"new").unwrap();
        assert_eq!(
            names(&out),
            ["explain.json", "stale.png"],
            "untouched until commit"
        );
        staged.commit().unwrap();
        assert_eq!(names(&out), ["explain.json"]);
        assert_eq!(std::fs::read(out.join("explain.json")).unwrap(), b"new");
        assert_eq!(names(&root), ["out"], "no staging or replaced folder left");
        std::fs::remove_dir_all(root).unwrap();
    }

    #[test]
    fn a_failed_run_leaves_the_earlier_folder_as_it_was() {
        let root = scratch("fail");
        let out = root.join("out");
        std::fs::create_dir_all(&out).unwrap();
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
        assert_eq!(names(&out), ["x"]);
        std::fs::remove_dir_all(root).unwrap();
    }
}
