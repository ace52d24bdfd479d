//! The outputs of a run as one set ([`OutputSet`]): written to temporaries, moved into place together at the end, and
//! never left behind as temporaries, whatever the way the run ends.
//!
//! Every file [`AtomicFile`](crate::AtomicFile) writes goes to a temporary `.NAME.XXXXXX.tmp` beside its path, and a
//! folder [`OutputDir`] writes to `.NAME.XXXXXX.tmp/` beside its path. Each temporary is listed here from the moment
//! it is created until it is moved into place or deleted, so that a process ending at once (a second Ctrl-C) can still
//! delete every one of them ([`remove_temporaries_before_exit`]).
//!
//! Without an open [`OutputSet`], a finished output is moved into place at once (as a library caller expects). While
//! one is open, a finished output waits: [`OutputSet::commit`] moves them all into place at the end of a run that
//! succeeded; a run that failed or was interrupted ends with [`OutputSet::abandon`] (or drops the set), which deletes
//! them, so that every previous output stays exactly as it was. Outputs marked with [`keep_if_failed`] (a bag up to
//! its last estimate) are then kept under their own name, [`partial_path`], instead.

use std::collections::BTreeSet;
use std::fs::File;
use std::io;
use std::path::{Path, PathBuf};
use std::sync::{Mutex, MutexGuard};

use crate::FormatError;

/// A temporary waiting for the commit: where it is, where it goes, and the path it was given as (the path of a
/// symbolic link, for example).
#[derive(Debug)]
struct Staged {
    temporary: PathBuf,
    destination: PathBuf,
    given: PathBuf,
    is_dir: bool,
}

/// The outputs of the open set.
#[derive(Debug, Default)]
struct Pending {
    staged: Vec<Staged>,
    /// Outputs (as given, or their destinations) to keep under their partial name if the run fails.
    keep_if_failed: Vec<PathBuf>,
    /// Folders the run created (the topmost, and the deepest): removed, when empty, if the run fails.
    created_dirs: Vec<(PathBuf, PathBuf)>,
    /// Files of a previous run to remove at the commit (they do not belong with the new ones).
    remove_on_commit: Vec<PathBuf>,
}

#[derive(Debug)]
struct Registry {
    /// Every temporary file or folder alive.
    temporaries: BTreeSet<PathBuf>,
    /// The open set, if any.
    set: Option<Pending>,
    /// Set when the process is ending at once: no temporary may be created any more.
    closed: bool,
}

static REGISTRY: Mutex<Registry> = Mutex::new(Registry {
    temporaries: BTreeSet::new(),
    set: None,
    closed: false,
});

/// The registry; a panic while holding it leaves a list that is still right (every change is one call), so a
/// poisoned lock is taken as it is.
fn registry() -> MutexGuard<'static, Registry> {
    REGISTRY
        .lock()
        .unwrap_or_else(|poisoned| poisoned.into_inner())
}

/// The name a partial output is kept under when the run that writes it fails (see [`keep_if_failed`]):
/// `NAME.partial.EXT` beside `NAME.EXT` (`run.mcap` -> `run.partial.mcap`, `poses` -> `poses.partial`).
///
/// ```
/// use std::path::Path;
/// use roitrack_formats::partial_path;
///
/// assert_eq!(partial_path(Path::new("out/run.mcap")), Path::new("out/run.partial.mcap"));
/// assert_eq!(partial_path(Path::new("poses")), Path::new("poses.partial"));
/// ```
pub fn partial_path(path: &Path) -> PathBuf {
    let mut name = path.file_stem().unwrap_or_default().to_os_string();
    name.push(".partial");
    if let Some(extension) = path.extension() {
        name.push(".");
        name.push(extension);
    }
    path.with_file_name(name)
}

/// Marks the output `path` (as given to its writer) as one whose finished content is kept under
/// [`partial_path`] if the run fails or is interrupted, instead of being deleted. The output at `path` itself is left
/// as it was either way. Without an open [`OutputSet`] this does nothing (the output is moved into place when
/// finished).
pub fn keep_if_failed(path: &Path) {
    if let Some(set) = registry().set.as_mut() {
        set.keep_if_failed.push(path.to_path_buf());
    }
}

/// Removes the file `path` when the open set is committed (a file a previous run wrote that does not belong with the
/// new outputs); without an open set, at once. A file that is not there is no error.
pub fn remove_at_commit(path: &Path) -> Result<(), FormatError> {
    let mut registry = registry();
    match registry.set.as_mut() {
        Some(set) => {
            set.remove_on_commit.push(path.to_path_buf());
            Ok(())
        }
        None => remove_if_present(path),
    }
}

fn remove_if_present(path: &Path) -> Result<(), FormatError> {
    match std::fs::remove_file(path) {
        Err(e) if e.kind() != io::ErrorKind::NotFound => Err(FormatError::io(
            path,
            "cannot remove this file of a previous run",
            e,
        )),
        _ => Ok(()),
    }
}

/// Creates the folder `dir` and its missing parents, for outputs; if the open set is abandoned, the folders created
/// here are removed again where they are still empty, so that a failed run leaves no new empty folder.
pub fn create_output_dir(dir: &Path) -> Result<(), FormatError> {
    if dir.is_dir() {
        return Ok(());
    }
    // The topmost folder that is missing: what a failed run removes.
    let mut topmost = dir.to_path_buf();
    while let Some(parent) = topmost.parent() {
        if parent.as_os_str().is_empty() || parent.exists() {
            break;
        }
        topmost = parent.to_path_buf();
    }
    std::fs::create_dir_all(dir)
        .map_err(|e| FormatError::io(dir, "cannot create the folder", e))?;
    if let Some(set) = registry().set.as_mut() {
        set.created_dirs.push((topmost, dir.to_path_buf()));
    }
    Ok(())
}

/// The outputs of one run, moved into place together by [`Self::commit`] at its end, or none of them if it fails
/// ([`Self::abandon`], or dropping the set).
///
/// There is one set per process: it gathers every output finished while it is open, on any thread. A second
/// [`Self::begin`] while one is open joins it: its commit and abandon do nothing, the first one's decide.
///
/// ```
/// use std::io::Write;
/// use roitrack_formats::{AtomicFile, OutputSet};
///
/// let dir = tempfile::tempdir().unwrap();
/// let (a, b) = (dir.path().join("a.csv"), dir.path().join("b.csv"));
/// std::fs::write(&a, "previous\n").unwrap();
/// let set = OutputSet::begin();
/// let mut file = AtomicFile::create(&a).unwrap();
/// file.write_all(b"new\n").unwrap();
/// file.finish().unwrap();
/// assert_eq!(std::fs::read_to_string(&a).unwrap(), "previous\n"); // not before the commit
/// // The second output fails: the set is abandoned, and the first one stays as it was.
/// drop(AtomicFile::create(&b).unwrap());
/// set.abandon();
/// assert_eq!(std::fs::read_to_string(&a).unwrap(), "previous\n");
/// assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1); // no temporary left
/// ```
#[derive(Debug)]
#[must_use = "an output set dropped at once abandons the outputs"]
pub struct OutputSet {
    /// Whether this guard opened the set (not joined one already open) and has not ended it yet.
    owner: bool,
}

impl OutputSet {
    /// Opens the process's output set (or joins the one already open).
    pub fn begin() -> Self {
        let mut registry = registry();
        let owner = registry.set.is_none();
        if owner {
            registry.set = Some(Pending::default());
        }
        Self { owner }
    }

    /// Moves every finished output into place, in the order they were finished, and removes the files of a previous
    /// run given to [`remove_at_commit`]. The moves are renames within each output's folder, done while holding the
    /// list of temporaries, so that a process ending at once waits for them. On the first failure the rest are
    /// deleted and the error is returned (what was moved stays).
    pub fn commit(mut self) -> Result<(), FormatError> {
        if !std::mem::take(&mut self.owner) {
            return Ok(());
        }
        let mut registry = registry();
        let Some(pending) = registry.set.take() else {
            return Ok(());
        };
        let mut result = Ok(());
        for staged in pending.staged {
            if result.is_ok() {
                result = move_into_place(&staged);
            }
            if result.is_err() {
                discard(&staged.temporary, staged.is_dir);
            }
            registry.temporaries.remove(&staged.temporary);
        }
        for path in &pending.remove_on_commit {
            if result.is_ok() {
                result = remove_if_present(path);
            }
        }
        result
    }

    /// Ends the set without moving anything into place: every finished output is deleted, but those marked with
    /// [`keep_if_failed`], kept under their [`partial_path`], whose paths are returned; the folders the run created
    /// are removed where empty.
    pub fn abandon(mut self) -> Vec<PathBuf> {
        self.end_without_commit()
    }

    fn end_without_commit(&mut self) -> Vec<PathBuf> {
        if !std::mem::take(&mut self.owner) {
            return Vec::new();
        }
        let mut registry = registry();
        let Some(pending) = registry.set.take() else {
            return Vec::new();
        };
        let mut kept = Vec::new();
        for staged in &pending.staged {
            let keep = !staged.is_dir
                && pending
                    .keep_if_failed
                    .iter()
                    .any(|p| *p == staged.given || *p == staged.destination);
            let partial = partial_path(&staged.destination);
            if keep && std::fs::rename(&staged.temporary, &partial).is_ok() {
                kept.push(partial);
            } else {
                discard(&staged.temporary, staged.is_dir);
            }
            registry.temporaries.remove(&staged.temporary);
        }
        remove_created_dirs(&pending.created_dirs);
        kept
    }
}

impl Drop for OutputSet {
    fn drop(&mut self) {
        self.end_without_commit();
    }
}

/// Removes the folders a failed run created, deepest first, where they are empty.
fn remove_created_dirs(created: &[(PathBuf, PathBuf)]) {
    for (topmost, deepest) in created.iter().rev() {
        let mut dir = deepest.as_path();
        loop {
            if std::fs::remove_dir(dir).is_err() || dir == topmost {
                break;
            }
            match dir.parent() {
                Some(parent) => dir = parent,
                None => break,
            }
        }
    }
}

/// Deletes every temporary file and folder of the process and the folders an open set created, for a process about
/// to end at once (a second signal): nothing is moved into place, nothing kept. No temporary can be created after
/// this call (creating one fails), and a commit that is under way completes first.
pub fn remove_temporaries_before_exit() {
    let mut registry = registry();
    registry.closed = true;
    for path in std::mem::take(&mut registry.temporaries) {
        discard(&path, path.is_dir());
    }
    if let Some(set) = registry.set.take() {
        remove_created_dirs(&set.created_dirs);
    }
    // The lock is kept until the process ends: no other thread may create or move anything now.
    std::mem::forget(registry);
}

fn discard(path: &Path, is_dir: bool) {
    let _ = if is_dir {
        std::fs::remove_dir_all(path)
    } else {
        std::fs::remove_file(path)
    };
}

fn move_into_place(staged: &Staged) -> Result<(), FormatError> {
    let failed = |e| {
        FormatError::io(
            &staged.given,
            "cannot move the finished output into place",
            e,
        )
    };
    if !staged.is_dir {
        return std::fs::rename(&staged.temporary, &staged.destination).map_err(failed);
    }
    // A folder: the previous one (if any) is moved aside, the new one in, and the previous one deleted.
    let previous = match std::fs::symlink_metadata(&staged.destination) {
        Ok(m) if m.is_dir() => Some(aside_name(&staged.destination)),
        Ok(_) => {
            return Err(FormatError::new(
                &staged.given,
                "is not a folder: cannot put the new folder in its place",
            ));
        }
        Err(_) => None,
    };
    if let Some(previous) = &previous {
        std::fs::rename(&staged.destination, previous).map_err(failed)?;
    }
    if let Err(e) = std::fs::rename(&staged.temporary, &staged.destination) {
        if let Some(previous) = &previous {
            let _ = std::fs::rename(previous, &staged.destination);
        }
        return Err(failed(e));
    }
    if let Some(previous) = &previous {
        std::fs::remove_dir_all(previous).map_err(|e| {
            FormatError::io(
                previous,
                "cannot delete the previous folder (moved aside)",
                e,
            )
        })?;
    }
    Ok(())
}

/// A name beside `path` for its previous version, moved aside while the new one takes its place.
fn aside_name(path: &Path) -> PathBuf {
    let mut name = std::ffi::OsString::from(".");
    name.push(path.file_name().unwrap_or_default());
    name.push(format!(".{}.old", std::process::id()));
    path.with_file_name(name)
}

/// A temporary file or folder, deleted (and struck from the list) when dropped unless handed over.
#[derive(Debug)]
pub(crate) struct Temporary {
    path: PathBuf,
    is_dir: bool,
    armed: bool,
}

impl Temporary {
    /// Creates a temporary file `.NAME.XXXXXX.tmp` in `dir` for the output `file_name`, listed before it exists, so
    /// that no moment passes where it exists unlisted. Its permissions are left to the umask (an ordinary output).
    pub(crate) fn file(dir: &Path, file_name: &std::ffi::OsStr) -> io::Result<(File, Self)> {
        let mut file = None;
        let path = create_listed(dir, file_name, |path| {
            let mut options = std::fs::OpenOptions::new();
            options.write(true).create_new(true);
            #[cfg(unix)]
            {
                use std::os::unix::fs::OpenOptionsExt;
                options.mode(0o666);
            }
            file = Some(options.open(path)?);
            Ok(())
        })?;
        let file = file.ok_or_else(|| io::Error::other("the temporary file was not created"))?;
        Ok((
            file,
            Self {
                path,
                is_dir: false,
                armed: true,
            },
        ))
    }

    /// Creates a temporary folder `.NAME.XXXXXX.tmp` in `dir` for the output folder `name`.
    pub(crate) fn dir(dir: &Path, name: &std::ffi::OsStr) -> io::Result<Self> {
        let path = create_listed(dir, name, |path| std::fs::create_dir(path))?;
        Ok(Self {
            path,
            is_dir: true,
            armed: true,
        })
    }

    pub(crate) fn path(&self) -> &Path {
        &self.path
    }

    /// Hands the finished temporary over: moved onto `destination` at once without an open set, else staged for the
    /// commit. `given` names the output in errors and in [`keep_if_failed`].
    pub(crate) fn finish(mut self, destination: &Path, given: &Path) -> Result<(), FormatError> {
        self.armed = false;
        let staged = Staged {
            temporary: std::mem::take(&mut self.path),
            destination: destination.to_path_buf(),
            given: given.to_path_buf(),
            is_dir: self.is_dir,
        };
        let mut registry = registry();
        if let Some(set) = registry.set.as_mut() {
            set.staged.push(staged);
            return Ok(());
        }
        let result = move_into_place(&staged);
        if result.is_err() {
            discard(&staged.temporary, staged.is_dir);
        }
        registry.temporaries.remove(&staged.temporary);
        result
    }
}

impl Drop for Temporary {
    fn drop(&mut self) {
        if self.armed {
            // Deleted first, struck off after: a process ending in between deletes it once more, harmlessly.
            discard(&self.path, self.is_dir);
            registry().temporaries.remove(&self.path);
        }
    }
}

/// Creates (with `create`) a temporary of a fresh random name for `name` in `dir`, listing it under the same lock.
fn create_listed(
    dir: &Path,
    name: &std::ffi::OsStr,
    mut create: impl FnMut(&Path) -> io::Result<()>,
) -> io::Result<PathBuf> {
    let mut prefix = std::ffi::OsString::from(".");
    prefix.push(name);
    prefix.push(".");
    let named = tempfile::Builder::new()
        .prefix(&prefix)
        .suffix(".tmp")
        .make_in(dir, |path| {
            let mut registry = registry();
            if registry.closed {
                return Err(io::Error::other("the process is ending"));
            }
            create(path)?;
            registry.temporaries.insert(path.to_path_buf());
            Ok(())
        })?;
    // Ours from now on (tempfile would delete it when dropped, without striking it off the list).
    named
        .into_temp_path()
        .keep()
        .map_err(|e| io::Error::other(e.to_string()))
}

/// A folder written as a whole: its content goes to a temporary folder `.NAME.XXXXXX.tmp/` beside its path, which
/// takes the place of the previous folder (if any) only when finished (and, with an open [`OutputSet`], committed).
/// Dropped unfinished, the temporary folder is deleted with everything in it.
///
/// ```
/// use roitrack_formats::OutputDir;
///
/// let parent = tempfile::tempdir().unwrap();
/// let frames = parent.path().join("frames");
/// std::fs::create_dir(&frames).unwrap();
/// std::fs::write(frames.join("old.png"), b"old").unwrap();
/// let dir = OutputDir::create(&frames).unwrap();
/// std::fs::write(dir.path().join("new.png"), b"new").unwrap();
/// dir.finish().unwrap();
/// assert!(frames.join("new.png").exists() && !frames.join("old.png").exists());
/// assert_eq!(std::fs::read_dir(parent.path()).unwrap().count(), 1); // nothing beside it
/// ```
#[derive(Debug)]
pub struct OutputDir {
    temporary: Temporary,
    destination: PathBuf,
    given: PathBuf,
}

impl OutputDir {
    /// Starts the folder `path`: a temporary folder beside it (the parent folder must exist). A `path` that is a
    /// symbolic link to a folder is replaced at the folder it leads to.
    pub fn create(path: impl AsRef<Path>) -> Result<Self, FormatError> {
        let given = path.as_ref().to_path_buf();
        let destination = match std::fs::symlink_metadata(&given) {
            Ok(m) if m.file_type().is_symlink() => std::fs::canonicalize(&given)
                .map_err(|e| FormatError::io(&given, "cannot follow the symbolic link", e))?,
            Ok(m) if !m.is_dir() => {
                return Err(FormatError::new(&given, "is a file, not a folder"));
            }
            _ => given.clone(),
        };
        let Some(name) = destination.file_name() else {
            return Err(FormatError::new(&given, "not a folder path"));
        };
        let parent = match destination.parent() {
            Some(dir) if !dir.as_os_str().is_empty() => dir,
            _ => Path::new("."),
        };
        let temporary = Temporary::dir(parent, name).map_err(|e| {
            FormatError::io(
                &given,
                &format!("cannot create a temporary folder in '{}'", parent.display()),
                e,
            )
        })?;
        Ok(Self {
            temporary,
            destination,
            given,
        })
    }

    /// Where to write the folder's content now (the temporary folder).
    pub fn path(&self) -> &Path {
        self.temporary.path()
    }

    /// Puts the folder in place of the previous one, or (with an open set) stages it for the commit.
    pub fn finish(self) -> Result<(), FormatError> {
        self.temporary.finish(&self.destination, &self.given)
    }
}
