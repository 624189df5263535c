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
//!
//! A folder that several runs add to (a campaign's plan, the shards of an
//! array job and their merge; a SITL server's board logs and summary)
//! cannot be staged whole: [`open_shared`] applies the same rule to it and
//! marks it, and [`StagedFiles`] writes each run's files into it all or
//! none, each under a temporary name until every one is written.

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

/// Opens `target` as a folder several runs add files to: created with
/// [`MARKER`] (and its parents) if absent, accepted if it is empty or holds
/// the marker; anything else is refused as [`check_replaceable`] refuses
/// it, before anything is written. Safe to call from processes that start
/// together (the shards of an array job).
///
/// # Errors
/// The target may not be used, or cannot be created; the message names it.
pub fn open_shared(target: &Path) -> io::Result<()> {
    check_replaceable(target)?;
    std::fs::create_dir_all(target).map_err(|e| context("creating", target, &e))?;
    let marker = target.join(MARKER);
    match std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(&marker)
    {
        Ok(mut file) => io::Write::write_all(&mut file, MARKER_TEXT)
            .map_err(|e| context("writing", &marker, &e)),
        Err(e) if e.kind() == io::ErrorKind::AlreadyExists => Ok(()),
        Err(e) => Err(context("writing", &marker, &e)),
    }
}

const MARKER_TEXT: &[u8] = b"written by an ATMO tool, which may replace it or add to it\n";

/// Files written into one folder all or none: each is written under a
/// hidden temporary name beside its own (same file system, same extension,
/// so a writer that picks its format by the extension still can), and
/// [`StagedFiles::commit`] renames them into place once every one is
/// written. Dropped without a commit (an error, a panic), the temporary
/// files are removed and the folder is as it was.
#[derive(Debug)]
pub struct StagedFiles {
    dir: PathBuf,
    staged: Vec<(tempfile::TempPath, PathBuf)>,
}

impl StagedFiles {
    /// Files for the existing folder `dir`.
    pub fn new(dir: impl Into<PathBuf>) -> Self {
        Self {
            dir: dir.into(),
            staged: Vec::new(),
        }
    }

    /// The temporary path to write the file `name` to.
    ///
    /// # Errors
    /// The temporary file cannot be created; the message names the folder.
    pub fn stage(&mut self, name: impl AsRef<std::ffi::OsStr>) -> io::Result<&Path> {
        let name = Path::new(name.as_ref());
        let suffix = name
            .extension()
            .map_or_else(String::new, |e| format!(".{}", e.to_string_lossy()));
        let mut builder = tempfile::Builder::new();
        // A temporary file is the owner's alone by default; the outputs are
        // created as any file is (0666 less the umask).
        #[cfg(unix)]
        builder.permissions(std::os::unix::fs::PermissionsExt::from_mode(0o666));
        let temp = builder
            .prefix(&format!(".{}.partial-", name.to_string_lossy()))
            .suffix(&suffix)
            .tempfile_in(&self.dir)
            .map_err(|e| context("creating a temporary file in", &self.dir, &e))?
            .into_temp_path();
        self.staged.push((temp, self.dir.join(name)));
        Ok(&self.staged[self.staged.len() - 1].0)
    }

    /// Writes the file `name` (under its temporary name until the commit).
    ///
    /// # Errors
    /// As [`StagedFiles::stage`], or the write fails; the message names the file.
    pub fn write(
        &mut self,
        name: impl AsRef<std::ffi::OsStr>,
        contents: impl AsRef<[u8]>,
    ) -> io::Result<()> {
        let path = self.stage(name)?.to_path_buf();
        std::fs::write(&path, contents).map_err(|e| context("writing", &path, &e))
    }

    /// Renames every staged file to its name, replacing an earlier file (or
    /// symbolic link) of that name; returns the final paths. A name taken
    /// by anything else (a folder, a device) is refused before any rename.
    ///
    /// # Errors
    /// A name is taken by something that is not a file, or a rename fails;
    /// the message names the file. After a failed rename the files renamed
    /// before it stay renamed, the others are removed.
    pub fn commit(self) -> io::Result<Vec<PathBuf>> {
        for (_, path) in &self.staged {
            if let Ok(meta) = std::fs::symlink_metadata(path) {
                let kind = meta.file_type();
                if !kind.is_file() && !kind.is_symlink() {
                    return Err(io::Error::new(
                        io::ErrorKind::AlreadyExists,
                        format!(
                            "{}: exists and is not a file (a folder, a device, a FIFO or a \
                             socket); nothing was replaced",
                            path.display()
                        ),
                    ));
                }
            }
        }
        let mut written = Vec::with_capacity(self.staged.len());
        for (temp, path) in self.staged {
            temp.persist(&path)
                .map_err(|e| context("renaming into", &path, &e.error))?;
            written.push(path);
        }
        Ok(written)
    }
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
        std::fs::write(&marker, MARKER_TEXT).map_err(|e| context("writing", &marker, &e))?;
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

    use super::{MARKER, StagedDir, StagedFiles, open_shared};

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

    /// A folder runs add to: created and marked, opened again by the next
    /// run with what it holds, and refused as [`StagedDir`] refuses.
    #[test]
    fn a_shared_folder_is_marked_reopened_and_refused_like_a_staged_one() {
        let root = scratch("shared");
        let out = root.join("a/campaign");
        open_shared(&out).unwrap();
        std::fs::write(out.join("plan.json"), b"{}").unwrap();
        open_shared(&out).unwrap();
        assert_eq!(names(&out), [MARKER, "plan.json"], "kept, not replaced");
        let theirs = root.join("theirs");
        std::fs::create_dir_all(&theirs).unwrap();
        std::fs::write(theirs.join("thesis.tex"), b"keep me").unwrap();
        let file = root.join("notes.txt");
        std::fs::write(&file, b"keep me").unwrap();
        let link = root.join("link");
        std::os::unix::fs::symlink(&out, &link).unwrap();
        for (target, what) in [
            (&theirs, "a folder this tool did not write"),
            (&file, "is a file"),
            (&link, "a symbolic link"),
        ] {
            let err = open_shared(target).unwrap_err().to_string();
            assert!(err.contains(what), "{err}");
        }
        assert_eq!(names(&theirs), ["thesis.tex"]);
        assert_eq!(std::fs::read(&file).unwrap(), b"keep me");
        std::fs::remove_dir_all(root).unwrap();
    }

    /// Files staged together appear together, each replacing an earlier
    /// one; a run that stops before the commit leaves the folder as it was.
    #[test]
    fn staged_files_appear_together_or_not_at_all() {
        let root = scratch("files");
        std::fs::write(root.join("cells.md"), b"old").unwrap();
        std::fs::write(root.join("map.png"), b"old").unwrap();
        {
            let mut files = StagedFiles::new(&root);
            files.write("cells.md", b"new").unwrap();
            let map = files.stage("map.png").unwrap();
            assert_eq!(
                map.extension().unwrap(),
                "png",
                "a writer may pick the format by it"
            );
            // dropped without commit: the map failed
        }
        assert_eq!(names(&root), ["cells.md", "map.png"], "no temporary left");
        assert_eq!(std::fs::read(root.join("cells.md")).unwrap(), b"old");
        let mut files = StagedFiles::new(&root);
        files.write("cells.md", b"new").unwrap();
        let map = files.stage("map.png").unwrap().to_path_buf();
        std::fs::write(&map, b"new").unwrap();
        assert_eq!(std::fs::read(root.join("map.png")).unwrap(), b"old");
        let written = files.commit().unwrap();
        assert_eq!(written, [root.join("cells.md"), root.join("map.png")]);
        assert_eq!(names(&root), ["cells.md", "map.png"]);
        assert_eq!(std::fs::read(root.join("map.png")).unwrap(), b"new");
        // A name taken by a folder: nothing is replaced, not even the
        // files staged before it.
        std::fs::create_dir(root.join("campaign.json")).unwrap();
        let mut files = StagedFiles::new(&root);
        files.write("cells.md", b"newer").unwrap();
        files.write("campaign.json", b"{}").unwrap();
        let err = files.commit().unwrap_err().to_string();
        assert!(
            err.contains("campaign.json") && err.contains("not a file"),
            "{err}"
        );
        assert_eq!(std::fs::read(root.join("cells.md")).unwrap(), b"new");
        std::fs::remove_dir(root.join("campaign.json")).unwrap();
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            let mode = std::fs::metadata(root.join("cells.md"))
                .unwrap()
                .permissions()
                .mode();
            assert_ne!(mode & 0o600, 0, "the owner reads and writes it");
            assert_eq!(
                mode & 0o044,
                0o044 & !umask(),
                "readable by others as the umask allows, not the owner's alone"
            );
        }
        std::fs::remove_dir_all(root).unwrap();
    }

    /// The process's umask, read back by creating a file with mode 0o777
    /// in a scratch folder.
    #[cfg(unix)]
    fn umask() -> u32 {
        use std::os::unix::fs::{OpenOptionsExt, PermissionsExt};
        let dir = scratch("umask");
        let probe = dir.join("probe");
        std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .mode(0o777)
            .open(&probe)
            .unwrap();
        let mode = std::fs::metadata(&probe).unwrap().permissions().mode() & 0o777;
        std::fs::remove_dir_all(dir).unwrap();
        0o777 & !mode
    }
}
