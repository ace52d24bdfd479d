//! The outputs of a run as one set ([`OutputSet`]): written to temporaries, moved into place together at the end, and
//! never left behind as temporaries, whatever the way the run ends.
//!
//! Every file [`AtomicFile`](crate::AtomicFile) writes goes to a temporary `.NAME.PID.XXXXXX.tmp` beside its path
//! (`PID`: this process), and a folder [`OutputDir`] writes to `.NAME.PID.XXXXXX.tmp/` beside its path. Each temporary
//! is listed here from the moment it is created until it is moved into place or deleted, so that a process ending at
//! once (a second Ctrl-C) can still delete every one of them ([`remove_temporaries_before_exit`]). A process killed
//! outright (`kill -9`) cannot: the next one to write the same output deletes the temporaries whose process is gone.
//!
//! Without an open [`OutputSet`], a finished output is moved into place at once (as a library caller expects). While
//! one is open, a finished output waits: [`OutputSet::commit`] moves them all into place at the end of a run that
//! succeeded; a run that failed or was interrupted ends with [`OutputSet::abandon`] (or drops the set), which deletes
//! them, so that every previous output stays exactly as it was. Outputs marked with [`keep_if_failed`] (a bag up to
//! its last estimate) are then kept under their own name, [`partial_path`], instead.

use std::collections::{BTreeMap, BTreeSet};
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
    /// For each folder an output was written in: when it was listed, and the temporaries that dead processes left
    /// there, not deleted yet.
    stale: BTreeMap<PathBuf, (std::time::Instant, StaleList)>,
}

/// Temporaries of dead processes found in a folder, each with the output it was for.
type StaleList = Vec<(std::ffi::OsString, PathBuf)>;

/// How long a listing of a folder's stale temporaries is used before the folder is listed again.
const RELIST_AFTER: std::time::Duration = std::time::Duration::from_secs(10);

static REGISTRY: Mutex<Registry> = Mutex::new(Registry {
    temporaries: BTreeSet::new(),
    set: None,
    closed: false,
    stale: BTreeMap::new(),
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

/// Removes the file or folder `path` when the open set is committed (what a previous run wrote that does not belong
/// with the new outputs), as one step of the commit (undone if the commit fails); without an open set, at once.
/// Nothing there is no error.
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
    let removed = match std::fs::symlink_metadata(path) {
        Ok(m) if m.is_dir() => std::fs::remove_dir_all(path),
        _ => std::fs::remove_file(path),
    };
    match removed {
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

    /// Moves every finished output into place and removes the files of a previous run given to [`remove_at_commit`],
    /// all or nothing as far as POSIX allows: every previous output is first saved beside itself (a hard link
    /// `.NAME.PID.old`, so that it stays in place until the new one replaces it in one rename; moved aside where links
    /// are not possible, and for folders), then the new ones are renamed in, then the files of a previous run moved
    /// aside, and only when every step has succeeded are the saved versions deleted. A step that fails undoes every
    /// step before it, in reverse (each saved version renamed back), deletes the new outputs, and returns the error:
    /// the outputs are then as they were before the commit. Everything is done while holding the list of
    /// temporaries, so that a process ending at once (a second signal) waits for the commit or its undoing.
    pub fn commit(mut self) -> Result<(), FormatError> {
        if !std::mem::take(&mut self.owner) {
            return Ok(());
        }
        let mut registry = registry();
        let Some(pending) = registry.set.take() else {
            return Ok(());
        };
        let result = commit_all(&pending.staged, &pending.remove_on_commit, &mut FileSystem);
        for staged in &pending.staged {
            registry.temporaries.remove(&staged.temporary);
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

/// The file-system steps of a commit that can fail halfway, through which a test makes the k-th one fail.
trait Steps {
    fn rename(&mut self, from: &Path, to: &Path) -> io::Result<()>;
    fn hard_link(&mut self, original: &Path, link: &Path) -> io::Result<()>;
}

/// The real file system.
struct FileSystem;

impl Steps for FileSystem {
    fn rename(&mut self, from: &Path, to: &Path) -> io::Result<()> {
        std::fs::rename(from, to)
    }

    fn hard_link(&mut self, original: &Path, link: &Path) -> io::Result<()> {
        std::fs::hard_link(original, link)
    }
}

/// A step of a commit, done: what undoing the commit must undo.
#[derive(Debug)]
enum Done {
    /// The previous version of `path` saved at `backup`: as a hard link (`path` still holds it) or moved there.
    Saved {
        path: PathBuf,
        backup: PathBuf,
        linked: bool,
        is_dir: bool,
    },
    /// A new output moved onto `path`.
    Placed { path: PathBuf, is_dir: bool },
}

/// Moves `staged` into place and `removals` aside, all or nothing (see [`OutputSet::commit`]). The temporaries of
/// `staged` that were not moved into place are deleted either way.
fn commit_all(
    staged: &[Staged],
    removals: &[PathBuf],
    steps: &mut impl Steps,
) -> Result<(), FormatError> {
    let mut done = Vec::new();
    let result = commit_steps(staged, removals, steps, &mut done);
    match result {
        Ok(()) => {
            for step in &done {
                if let Done::Saved { backup, is_dir, .. } = step {
                    // The commit stands; a backup that cannot be deleted is one more file, not a failure.
                    discard(backup, *is_dir);
                }
            }
            Ok(())
        }
        Err(error) => {
            for s in staged {
                discard(&s.temporary, s.is_dir);
            }
            let left = roll_back(&done, steps);
            if left.is_empty() {
                return Err(error);
            }
            let list: Vec<String> = left
                .iter()
                .map(|(path, backup)| format!("{} is at {}", path.display(), backup.display()))
                .collect();
            Err(FormatError::new(
                error.path(),
                format!(
                    "{}; undoing the commit, the previous version of some outputs could not be put back: {}",
                    error.message(),
                    list.join(", ")
                ),
            ))
        }
    }
}

fn commit_steps(
    staged: &[Staged],
    removals: &[PathBuf],
    steps: &mut impl Steps,
    done: &mut Vec<Done>,
) -> Result<(), FormatError> {
    let failed = |s: &Staged| {
        let given = s.given.clone();
        move |e| FormatError::io(&given, "cannot move the finished output into place", e)
    };
    // Every previous output saved first.
    for s in staged {
        let Ok(metadata) = std::fs::symlink_metadata(&s.destination) else {
            continue;
        };
        if metadata.is_dir() != s.is_dir {
            let message = match s.is_dir {
                true => "is not a folder: cannot put the new folder in its place",
                false => "is a folder: cannot put the new file in its place",
            };
            return Err(FormatError::new(&s.given, message));
        }
        done.push(save(&s.destination, s.is_dir, steps).map_err(failed(s))?);
    }
    // The new outputs in.
    for s in staged {
        steps
            .rename(&s.temporary, &s.destination)
            .map_err(failed(s))?;
        done.push(Done::Placed {
            path: s.destination.clone(),
            is_dir: s.is_dir,
        });
    }
    // The files of a previous run that do not belong with the new ones, aside.
    for path in removals {
        let metadata = match std::fs::symlink_metadata(path) {
            Ok(m) => m,
            Err(e) if e.kind() == io::ErrorKind::NotFound => continue,
            Err(e) => {
                return Err(FormatError::io(
                    path,
                    "cannot remove this file of a previous run",
                    e,
                ));
            }
        };
        let backup = backup_name(path);
        discard_any(&backup);
        steps
            .rename(path, &backup)
            .map_err(|e| FormatError::io(path, "cannot remove this file of a previous run", e))?;
        done.push(Done::Saved {
            path: path.clone(),
            backup,
            linked: false,
            is_dir: metadata.is_dir(),
        });
    }
    Ok(())
}

/// Saves the previous version of `path` beside it: a hard link for a file, so that the file stays in place until the
/// new one replaces it; else (a folder, a file system without hard links) moved aside.
fn save(path: &Path, is_dir: bool, steps: &mut impl Steps) -> io::Result<Done> {
    let backup = backup_name(path);
    // Left by a process of the same number that was killed: nothing of ours.
    discard_any(&backup);
    let linked = !is_dir && steps.hard_link(path, &backup).is_ok();
    if !linked {
        steps.rename(path, &backup)?;
    }
    Ok(Done::Saved {
        path: path.to_path_buf(),
        backup,
        linked,
        is_dir,
    })
}

/// Undoes the steps `done`, last first. Returns the outputs whose previous version could not be put back, with where
/// it is (those backups are left in place).
fn roll_back(done: &[Done], steps: &mut impl Steps) -> Vec<(PathBuf, PathBuf)> {
    let mut restored: Vec<&Path> = Vec::new();
    let mut left = Vec::new();
    for step in done.iter().rev() {
        match step {
            Done::Placed { path, is_dir } => {
                let linked_backup = done.iter().find_map(|d| match d {
                    Done::Saved {
                        path: p,
                        backup,
                        linked: true,
                        ..
                    } if p == path => Some(backup),
                    _ => None,
                });
                match linked_backup {
                    // The previous version back over the new one, in one rename.
                    Some(backup) => match steps.rename(backup, path) {
                        Ok(()) => restored.push(path),
                        Err(_) => {
                            left.push((path.clone(), backup.clone()));
                            restored.push(path);
                        }
                    },
                    // Nothing was there, or the previous version was moved aside (put back below).
                    None => discard(path, *is_dir),
                }
            }
            Done::Saved {
                path,
                backup,
                linked,
                is_dir,
            } => {
                if restored.contains(&path.as_path()) {
                    continue;
                }
                if *linked {
                    // The new output never replaced it: the previous version is still in place.
                    discard(backup, *is_dir);
                } else if steps.rename(backup, path).is_err() {
                    left.push((path.clone(), backup.clone()));
                }
            }
        }
    }
    left
}

/// The name beside `path` its previous version is saved under during a commit: `.NAME.PID.old`.
fn backup_name(path: &Path) -> PathBuf {
    let mut name = std::ffi::OsString::from(".");
    name.push(path.file_name().unwrap_or_default());
    name.push(format!(".{}.old", std::process::id()));
    path.with_file_name(name)
}

/// Deletes whatever is at `path` (a file, a link, a folder with its content), if anything.
fn discard_any(path: &Path) {
    if let Ok(metadata) = std::fs::symlink_metadata(path) {
        discard(path, metadata.is_dir());
    }
}

/// A temporary file or folder, deleted (and struck from the list) when dropped unless handed over.
#[derive(Debug)]
pub(crate) struct Temporary {
    path: PathBuf,
    is_dir: bool,
    armed: bool,
}

impl Temporary {
    /// Creates a temporary file `.NAME.PID.XXXXXX.tmp` in `dir` for the output `file_name`, listed before it exists, so
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

    /// Creates a temporary folder `.NAME.PID.XXXXXX.tmp` in `dir` for the output folder `name`.
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
        let result = commit_all(std::slice::from_ref(&staged), &[], &mut FileSystem);
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
    remove_stale_temporaries(dir, name);
    // `.NAME.PID.XXXXXX.tmp`: the process's number tells a later run whether its writer is still alive.
    let mut prefix = std::ffi::OsString::from(".");
    prefix.push(name);
    prefix.push(format!(".{}.", std::process::id()));
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

/// Deletes the temporaries of the output `name` in `dir` that a process no longer alive left behind (killed by
/// `kill -9`, which no program can catch, or by a power cut): `.NAME.PID.XXXXXX.tmp` files or folders whose process
/// `PID` does not exist. The folder is listed at most once every [`RELIST_AFTER`] (a folder of 100,000 frames is not
/// listed for each frame; a long-lived process, a Python session, still sees what a process killed since left); the
/// temporaries of a live process (another run writing the same output now) are left alone, as is anything of another
/// name.
fn remove_stale_temporaries(dir: &Path, name: &std::ffi::OsStr) {
    let fresh = registry()
        .stale
        .get(dir)
        .is_some_and(|(listed, _)| listed.elapsed() < RELIST_AFTER);
    if !fresh {
        let found = find_stale_temporaries(dir);
        registry()
            .stale
            .insert(dir.to_path_buf(), (std::time::Instant::now(), found));
    }
    let mine: Vec<PathBuf> = {
        let mut registry = registry();
        let Some((_, stale)) = registry.stale.get_mut(dir) else {
            return;
        };
        let (mine, others) = std::mem::take(stale)
            .into_iter()
            .partition(|(output, _)| output.as_os_str() == name);
        *stale = others;
        mine.into_iter().map(|(_, path)| path).collect()
    };
    for path in mine {
        discard_any(&path);
    }
}

/// Deletes at once, in `dir`, the temporaries that processes no longer alive left for the outputs whose names
/// `is_ours` accepts: for a writer whose outputs vary in number from run to run (the frames of `simulate --frames`),
/// where a temporary of a killed run may be for an output the next run does not write. Returns how many went.
///
/// ```
/// let dir = tempfile::tempdir().unwrap();
/// let mut ended = std::process::Command::new("true").spawn().unwrap();
/// let pid = ended.id();
/// ended.wait().unwrap();
/// std::fs::write(dir.path().join(format!(".frame_00007.png.{pid}.aB3xYz.tmp")), "half").unwrap();
/// std::fs::write(dir.path().join(format!(".notes.txt.{pid}.aB3xYz.tmp")), "half").unwrap();
/// let removed = roitrack_formats::remove_dead_temporaries(dir.path(), |name| name.starts_with("frame_"));
/// assert_eq!(removed, 1);
/// assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
/// ```
pub fn remove_dead_temporaries(dir: &Path, is_ours: impl Fn(&str) -> bool) -> usize {
    let mut removed = 0;
    for (output, path) in find_stale_temporaries(dir) {
        if output.to_str().is_some_and(&is_ours) {
            discard_any(&path);
            removed += 1;
        }
    }
    removed
}

/// The temporaries in `dir` of processes no longer alive, each with the output it was for.
fn find_stale_temporaries(dir: &Path) -> StaleList {
    let listing = if dir.as_os_str().is_empty() {
        Path::new(".")
    } else {
        dir
    };
    let Ok(entries) = std::fs::read_dir(listing) else {
        return Vec::new();
    };
    let own = std::process::id();
    entries
        .filter_map(Result::ok)
        .filter_map(|entry| {
            let file_name = entry.file_name();
            let (output, pid) = parse_temporary_name(file_name.to_str()?)?;
            (pid != own && !process_alive(pid)).then(|| (output.into(), dir.join(&file_name)))
        })
        .collect()
}

/// The output and the process of a temporary's name `.NAME.PID.XXXXXX.tmp` (`XXXXXX` six letters or digits).
fn parse_temporary_name(file_name: &str) -> Option<(&str, u32)> {
    let inner = file_name.strip_prefix('.')?.strip_suffix(".tmp")?;
    let (rest, random) = inner.rsplit_once('.')?;
    if random.len() != 6 || !random.bytes().all(|b| b.is_ascii_alphanumeric()) {
        return None;
    }
    let (output, pid) = rest.rsplit_once('.')?;
    if output.is_empty() || pid.is_empty() || !pid.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    Some((output, pid.parse().ok()?))
}

/// Whether a process `pid` exists (on this machine). Where that cannot be told, it is taken as alive: nothing is
/// deleted.
fn process_alive(pid: u32) -> bool {
    #[cfg(unix)]
    {
        let Ok(pid) = libc::pid_t::try_from(pid) else {
            return true;
        };
        if pid <= 0 {
            return true;
        }
        // SAFETY: signal 0 sends nothing; it only asks whether the process exists.
        if unsafe { libc::kill(pid, 0) } == 0 {
            return true;
        }
        // EPERM: it exists, as another user's.
        io::Error::last_os_error().raw_os_error() != Some(libc::ESRCH)
    }
    #[cfg(not(unix))]
    {
        let _ = pid;
        true
    }
}

/// A folder written as a whole: its content goes to a temporary folder `.NAME.PID.XXXXXX.tmp/` beside its path, which
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

#[cfg(test)]
mod tests {
    use std::collections::BTreeMap;

    use super::*;

    /// The real file system, but its `fail_at`-th step (from 1) fails, and with `for_good` every step after it too.
    struct Failing {
        count: usize,
        fail_at: usize,
        for_good: bool,
    }

    impl Failing {
        fn step(&mut self) -> io::Result<()> {
            self.count += 1;
            if self.count == self.fail_at || (self.for_good && self.count > self.fail_at) {
                return Err(io::Error::other("injected failure"));
            }
            Ok(())
        }
    }

    impl Steps for Failing {
        fn rename(&mut self, from: &Path, to: &Path) -> io::Result<()> {
            self.step()?;
            std::fs::rename(from, to)
        }

        fn hard_link(&mut self, original: &Path, link: &Path) -> io::Result<()> {
            self.step()?;
            std::fs::hard_link(original, link)
        }
    }

    /// Every file under `dir`, by its path below `dir`, with its content.
    fn snapshot(dir: &Path) -> BTreeMap<String, String> {
        let mut files = BTreeMap::new();
        let mut stack = vec![dir.to_path_buf()];
        while let Some(d) = stack.pop() {
            for entry in std::fs::read_dir(&d).unwrap() {
                let path = entry.unwrap().path();
                if path.is_dir() {
                    stack.push(path);
                } else {
                    let name = path.strip_prefix(dir).unwrap().display().to_string();
                    files.insert(name, std::fs::read_to_string(&path).unwrap());
                }
            }
        }
        files
    }

    fn files(pairs: &[(&str, &str)]) -> BTreeMap<String, String> {
        pairs
            .iter()
            .map(|(k, v)| (k.to_string(), v.to_string()))
            .collect()
    }

    /// Previous outputs in `dir` (two files, a folder, a file of a previous run that the commit removes), and the
    /// finished temporaries of a new run: the two files, a file where there was none, the folder.
    fn scene(dir: &Path) -> (Vec<Staged>, Vec<PathBuf>) {
        std::fs::write(dir.join("a.tum"), "old a").unwrap();
        std::fs::write(dir.join("b.csv"), "old b").unwrap();
        std::fs::write(dir.join("rois.bin"), "old rois").unwrap();
        std::fs::create_dir(dir.join("frames")).unwrap();
        std::fs::write(dir.join("frames/frame_00000.png"), "old frame").unwrap();
        let mut staged = Vec::new();
        for (name, content) in [("a.tum", "new a"), ("b.csv", "new b"), ("c.csv", "new c")] {
            let temporary = dir.join(format!(".{name}.1.abcdef.tmp"));
            std::fs::write(&temporary, content).unwrap();
            staged.push(Staged {
                temporary,
                destination: dir.join(name),
                given: dir.join(name),
                is_dir: false,
            });
        }
        let temporary = dir.join(".frames.1.abcdef.tmp");
        std::fs::create_dir(&temporary).unwrap();
        std::fs::write(temporary.join("frame_00000.png"), "new frame").unwrap();
        staged.push(Staged {
            temporary,
            destination: dir.join("frames"),
            given: dir.join("frames"),
            is_dir: true,
        });
        (staged, vec![dir.join("rois.bin"), dir.join("absent.bin")])
    }

    fn previous() -> BTreeMap<String, String> {
        files(&[
            ("a.tum", "old a"),
            ("b.csv", "old b"),
            ("rois.bin", "old rois"),
            ("frames/frame_00000.png", "old frame"),
        ])
    }

    #[test]
    fn a_commit_failing_at_its_kth_step_leaves_every_previous_output() {
        let committed = files(&[
            ("a.tum", "new a"),
            ("b.csv", "new b"),
            ("c.csv", "new c"),
            ("frames/frame_00000.png", "new frame"),
        ]);
        let (mut failed, mut fell_back) = (0, 0);
        for fail_at in 1.. {
            let tmp = tempfile::tempdir().unwrap();
            let (staged, removals) = scene(tmp.path());
            let mut steps = Failing {
                count: 0,
                fail_at,
                for_good: false,
            };
            match commit_all(&staged, &removals, &mut steps) {
                Err(e) => {
                    failed += 1;
                    assert!(e.to_string().contains("injected failure"), "{e}");
                    assert!(!e.to_string().contains("put back"), "{e}");
                    // Undone: byte for byte as before, no temporary, no backup.
                    assert_eq!(snapshot(tmp.path()), previous(), "step {fail_at}");
                    assert_eq!(std::fs::read_dir(tmp.path()).unwrap().count(), 4);
                }
                Ok(()) if steps.count < fail_at => {
                    assert_eq!(snapshot(tmp.path()), committed);
                    assert_eq!(std::fs::read_dir(tmp.path()).unwrap().count(), 4);
                    break;
                }
                // A failed hard link falls back to moving the previous file aside: the commit goes through.
                Ok(()) => {
                    fell_back += 1;
                    assert_eq!(snapshot(tmp.path()), committed, "step {fail_at}");
                }
            }
        }
        // Three saves (two hard links, the folder moved aside), four renames in, one removal moved aside; the two
        // links fall back to moving the file aside.
        assert_eq!((failed, fell_back), (6, 2));
    }

    #[test]
    fn an_undo_that_fails_too_says_where_each_previous_output_is() {
        for fail_at in 1..=8 {
            let tmp = tempfile::tempdir().unwrap();
            let dir = tmp.path();
            let (staged, removals) = scene(dir);
            let mut steps = Failing {
                count: 0,
                fail_at,
                for_good: true,
            };
            let e = commit_all(&staged, &removals, &mut steps)
                .unwrap_err()
                .to_string();
            // Every previous output is at its path or at the backup the error names.
            let after = snapshot(dir);
            for (name, content) in previous() {
                let path = dir.join(&name);
                let top = dir.join(name.split('/').next().unwrap());
                if after.get(&name) == Some(&content) {
                    continue;
                }
                let backup = backup_name(&top);
                assert!(
                    e.contains(&format!("{} is at {}", top.display(), backup.display())),
                    "step {fail_at}: {name}: {e}"
                );
                let saved = backup.join(path.strip_prefix(&top).unwrap());
                let saved = if name.contains('/') { saved } else { backup };
                assert_eq!(std::fs::read_to_string(saved).unwrap(), content, "{e}");
            }
            // A new output is left only where its previous version could not be put back (and is named).
            for (name, content) in &after {
                if content.starts_with("new") {
                    let top = dir.join(name.split('/').next().unwrap());
                    assert!(
                        e.contains(&format!("{} is at", top.display())),
                        "step {fail_at}: {name}: {e}"
                    );
                }
            }
        }
    }

    #[test]
    fn temporaries_of_dead_processes_go_when_their_output_is_written_again() {
        assert_eq!(
            parse_temporary_name(".poses.tum.123.aB3xYz.tmp"),
            Some(("poses.tum", 123))
        );
        for name in [
            ".poses.tum.aB3xYz.tmp",
            ".poses.tum.12a.aB3xYz.tmp",
            ".poses.tum.123.aB3x.tmp",
            "poses.tum.123.aB3xYz.tmp",
            "..123.aB3xYz.tmp",
        ] {
            assert_eq!(parse_temporary_name(name), None, "{name}");
        }
        // A process that has ended (and been waited for), and one alive (this one's parent).
        let mut child = std::process::Command::new("true").spawn().unwrap();
        let dead = child.id();
        child.wait().unwrap();
        assert!(!process_alive(dead));
        let alive = std::os::unix::process::parent_id();
        assert!(process_alive(alive));
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path();
        let stale_file = dir.join(format!(".poses.tum.{dead}.aB3xYz.tmp"));
        let stale_dir = dir.join(format!(".poses.tum.{dead}.qQ9wEr.tmp"));
        let live = dir.join(format!(".poses.tum.{alive}.aB3xYz.tmp"));
        let other_output = dir.join(format!(".twists.csv.{dead}.aB3xYz.tmp"));
        let not_ours = dir.join(".poses.tum.tmp");
        for path in [&stale_file, &live, &other_output, &not_ours] {
            std::fs::write(path, "x").unwrap();
        }
        std::fs::create_dir(&stale_dir).unwrap();
        std::fs::write(stale_dir.join("frame_00000.png"), "x").unwrap();
        let mut file = crate::AtomicFile::create(dir.join("poses.tum")).unwrap();
        io::Write::write_all(&mut file, b"new").unwrap();
        file.finish().unwrap();
        let mut names: Vec<PathBuf> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().path())
            .collect();
        names.sort();
        let mut expected = vec![live, other_output, not_ours, dir.join("poses.tum")];
        expected.sort();
        assert_eq!(names, expected);
    }
}
