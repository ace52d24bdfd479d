//! [`AtomicFile`]: write a file completely or not at all; and what an output path may be.

use std::fs::File;
use std::io::{self, BufWriter, Seek, Write};
use std::path::{Path, PathBuf};

use crate::FormatError;
use crate::output_set::Temporary;

/// A buffered output that, for a regular file, appears at its path only when [`AtomicFile::finish`] succeeds.
///
/// What is at the path decides how it is written:
///
/// - nothing, or a regular file: the content goes to a temporary file in the target's directory (so the final rename
///   stays on one file system); `finish` flushes it, syncs it to disk and renames it onto the target, replacing any
///   previous file at once. Dropping an `AtomicFile` without `finish` (an error, a panic, an interrupted run) deletes
///   the temporary file and leaves whatever was at the target path untouched: readers never see a half-written file.
///   While an [`OutputSet`](crate::OutputSet) is open, `finish` does not rename: the set's commit moves every output
///   of the run into place together. The temporary is listed from its creation, so that even a process ending at
///   once deletes it ([`remove_temporaries_before_exit`](crate::remove_temporaries_before_exit)).
/// - a symbolic link: the same, at the file the link points to (resolved through every link), so the link stays a
///   link and its target gets the new content.
/// - a FIFO, a character device (a terminal, `/dev/stdout`, `/dev/null`) or a socket: written in place, never
///   replaced by a regular file; what was written before an error has been read already.
/// - `-`: the standard output, in place.
///
/// The target's directory must exist; it is not created.
///
/// ```
/// use std::io::Write;
/// use roitrack_formats::AtomicFile;
///
/// let dir = tempfile::tempdir().unwrap();
/// let path = dir.path().join("out.csv");
/// let mut file = AtomicFile::create(&path).unwrap();
/// file.write_all(b"t,x\n").unwrap();
/// assert!(!path.exists()); // not before finish
/// file.finish().unwrap();
/// assert_eq!(std::fs::read_to_string(&path).unwrap(), "t,x\n");
/// ```
#[derive(Debug)]
pub struct AtomicFile {
    target: PathBuf,
    sink: Sink,
}

#[derive(Debug)]
enum Sink {
    /// A temporary file renamed onto `real_target` (the path given, or the file its links lead to) by `finish`.
    // Fields drop in order: the file is closed, then the temporary deleted.
    Atomic {
        real_target: PathBuf,
        writer: BufWriter<File>,
        temporary: Temporary,
    },
    /// A FIFO or a device, written where it is.
    InPlace(BufWriter<File>),
    Stdout(BufWriter<io::Stdout>),
}

/// The file a path leads to through symbolic links (the path itself if it is not a link), resolved link by link so
/// that a dangling link leads to the file it would create.
fn follow_links(path: &Path) -> Result<PathBuf, FormatError> {
    let mut current = path.to_path_buf();
    for _ in 0..40 {
        match std::fs::symlink_metadata(&current) {
            Ok(m) if m.file_type().is_symlink() => {
                let link = std::fs::read_link(&current)
                    .map_err(|e| FormatError::io(path, "cannot read the symbolic link", e))?;
                current = match current.parent() {
                    Some(dir) if link.is_relative() => dir.join(link),
                    _ => link,
                };
            }
            _ => return Ok(current),
        }
    }
    Err(FormatError::new(path, "too many levels of symbolic links"))
}

/// Whether `path` is a FIFO, a character device or a socket: written in place.
fn is_stream(path: &Path) -> bool {
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        std::fs::metadata(path).is_ok_and(|m| {
            let t = m.file_type();
            t.is_fifo() || t.is_char_device() || t.is_socket()
        })
    }
    #[cfg(not(unix))]
    {
        let _ = path;
        false
    }
}

impl AtomicFile {
    /// Starts writing `path`: creates the temporary file beside it (or beside the file its links lead to), or opens
    /// a FIFO or a device in place, or takes the standard output for `-`.
    pub fn create(path: impl AsRef<Path>) -> Result<Self, FormatError> {
        let target = path.as_ref().to_path_buf();
        if target.as_os_str() == "-" {
            check_stdout_open()?;
            return Ok(Self {
                target,
                sink: Sink::Stdout(BufWriter::new(io::stdout())),
            });
        }
        if is_stream(&target) {
            let file = std::fs::OpenOptions::new()
                .write(true)
                .open(&target)
                .map_err(|e| FormatError::io(&target, "cannot open for writing", e))?;
            return Ok(Self {
                target,
                sink: Sink::InPlace(BufWriter::new(file)),
            });
        }
        let real_target = follow_links(&target)?;
        if real_target.is_dir() {
            return Err(FormatError::new(&target, "is a directory, not a file"));
        }
        let Some(file_name) = real_target.file_name() else {
            return Err(FormatError::new(&target, "not a file path"));
        };
        let dir = match real_target.parent() {
            Some(dir) if !dir.as_os_str().is_empty() => dir,
            _ => Path::new("."),
        };
        if !dir.is_dir() {
            return Err(FormatError::new(
                &target,
                format!("directory '{}' does not exist", dir.display()),
            ));
        }
        let (file, temporary) = Temporary::file(dir, file_name).map_err(|e| {
            FormatError::io(
                &target,
                &format!(
                    "cannot create a temporary file in directory '{}'",
                    dir.display()
                ),
                e,
            )
        })?;
        Ok(Self {
            target,
            sink: Sink::Atomic {
                real_target: real_target.clone(),
                writer: BufWriter::new(file),
                temporary,
            },
        })
    }

    /// The path the file will have once finished (as given: a link's path, not its target's).
    pub fn path(&self) -> &Path {
        &self.target
    }

    /// Flushes, syncs and renames the temporary file onto the target path (or flushes a stream written in place).
    /// While an [`OutputSet`](crate::OutputSet) is open, the rename waits for its commit.
    pub fn finish(self) -> Result<(), FormatError> {
        let target = self.target;
        match self.sink {
            Sink::Atomic {
                real_target,
                writer,
                temporary,
            } => {
                let file = writer
                    .into_inner()
                    .map_err(|e| FormatError::io(&target, "cannot write", e.into_error()))?;
                file.sync_all()
                    .map_err(|e| FormatError::io(&target, "cannot sync to disk", e))?;
                drop(file);
                // Renamed now, or with an open output set, at its commit.
                temporary.finish(&real_target, &target)?;
            }
            Sink::InPlace(mut writer) => writer
                .flush()
                .map_err(|e| FormatError::io(&target, "cannot write", e))?,
            Sink::Stdout(mut writer) => writer
                .flush()
                .map_err(|e| FormatError::io(&target, "cannot write", e))?,
        }
        Ok(())
    }

    /// An input/output error while writing this file, as a [`FormatError`].
    pub(crate) fn write_error(&self, error: io::Error) -> FormatError {
        FormatError::io(&self.target, "cannot write", error)
    }

    fn writer(&mut self) -> &mut dyn Write {
        match &mut self.sink {
            Sink::Atomic { writer, .. } => writer,
            Sink::InPlace(writer) => writer,
            Sink::Stdout(writer) => writer,
        }
    }
}

/// Seeking works on a regular file's temporary (an MCAP bag writes its index that way), not on a stream.
impl Seek for AtomicFile {
    fn seek(&mut self, position: io::SeekFrom) -> io::Result<u64> {
        match &mut self.sink {
            Sink::Atomic { writer, .. } => writer.seek(position),
            Sink::InPlace(_) | Sink::Stdout(_) => Err(io::Error::new(
                io::ErrorKind::Unsupported,
                "cannot seek in a stream (a FIFO, a device or the standard output)",
            )),
        }
    }
}

/// Refuses `-` as an output when the standard output was closed (`>&-`): the Rust runtime then puts `/dev/null` in
/// its place, opened for reading and writing, and the output would be discarded without a word. A user's own
/// `>/dev/null` opens it for writing only, and is accepted.
fn check_stdout_open() -> Result<(), FormatError> {
    #[cfg(target_os = "linux")]
    {
        use std::os::unix::fs::{FileTypeExt, MetadataExt};
        let flags = std::fs::read_to_string("/proc/self/fdinfo/1").unwrap_or_default();
        let read_write = flags
            .lines()
            .find_map(|l| l.strip_prefix("flags:"))
            .and_then(|f| u32::from_str_radix(f.trim(), 8).ok())
            .is_some_and(|f| f & 0o3 == 0o2);
        let null = std::fs::metadata("/dev/null").ok();
        let stdout = std::fs::metadata("/proc/self/fd/1").ok();
        if let (true, Some(null), Some(stdout)) = (read_write, null, stdout)
            && stdout.file_type().is_char_device()
            && stdout.rdev() == null.rdev()
        {
            return Err(FormatError::new(
                "-",
                "the standard output is closed: give a file instead of '-', or redirect it (> FILE)",
            ));
        }
    }
    Ok(())
}

impl Write for AtomicFile {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        self.writer().write(buf)
    }

    fn write_all(&mut self, buf: &[u8]) -> io::Result<()> {
        self.writer().write_all(buf)
    }

    fn flush(&mut self) -> io::Result<()> {
        self.writer().flush()
    }
}

/// What a path is, for comparing outputs with inputs and with one another: the file it leads to (device and inode
/// on Unix, where it exists), else the absolute path it would create.
#[derive(Debug, Clone, PartialEq, Eq)]
enum FileIdentity {
    #[cfg(unix)]
    Inode(u64, u64),
    Path(PathBuf),
}

fn identity(path: &Path) -> Option<FileIdentity> {
    #[cfg(unix)]
    if let Ok(m) = std::fs::metadata(path) {
        use std::os::unix::fs::MetadataExt;
        return Some(FileIdentity::Inode(m.dev(), m.ino()));
    }
    let real = follow_links(path).ok()?;
    Some(FileIdentity::Path(absolute_path(&real)?))
}

/// The absolute path `path` would have: its nearest existing folder canonicalised (through links), the folders and
/// file still to be created appended, `.` and `..` among them resolved by name.
fn absolute_path(path: &Path) -> Option<PathBuf> {
    let mut missing = Vec::new();
    let mut existing = path;
    loop {
        let here = if existing.as_os_str().is_empty() {
            Path::new(".")
        } else {
            existing
        };
        if let Ok(real) = std::fs::canonicalize(here) {
            let mut result = real;
            for part in missing.iter().rev() {
                match part {
                    std::path::Component::ParentDir => {
                        result.pop();
                    }
                    std::path::Component::Normal(name) => result.push(name),
                    _ => {}
                }
            }
            return Some(result);
        }
        let mut components = existing.components();
        missing.push(components.next_back()?);
        existing = components.as_path();
    }
}

/// Refuses output paths that would destroy an input or each other, before anything is written: an output that is an
/// input file (the same path, or the same file through a symbolic or hard link), two outputs to one file, `-`
/// (standard output) for more than one output. Each path comes with the option or role that names it in errors.
/// `/dev/null` may take any number of outputs.
///
/// ```
/// use std::path::Path;
/// use roitrack_formats::check_output_paths;
///
/// let dir = tempfile::tempdir().unwrap();
/// let input = dir.path().join("m.csv");
/// std::fs::write(&input, "t,id,u,v\n").unwrap();
/// let poses = dir.path().join("poses.tum");
/// let ok = check_output_paths(&[("--measurements", &input)], &[("--poses", &poses), ("--twists", Path::new("-"))]);
/// assert!(ok.is_ok());
/// let e = check_output_paths(&[("--measurements", &input)], &[("--poses", &input)]).unwrap_err();
/// assert!(e.to_string().contains("--poses is the input given as --measurements"), "{e}");
/// let e = check_output_paths(&[], &[("--poses", &poses), ("--twists", &poses)]).unwrap_err();
/// assert!(e.to_string().contains("--poses and --twists"), "{e}");
/// ```
pub fn check_output_paths(
    inputs: &[(&str, &Path)],
    outputs: &[(&str, &Path)],
) -> Result<(), FormatError> {
    let stdout: Vec<&str> = outputs
        .iter()
        .filter(|(_, p)| p.as_os_str() == "-")
        .map(|(name, _)| *name)
        .collect();
    if stdout.len() > 1 {
        return Err(FormatError::new(
            "-",
            format!(
                "{} all write to the standard output: give '-' to one output at most",
                stdout.join(", ")
            ),
        ));
    }
    let inputs: Vec<(&str, &Path, FileIdentity)> = inputs
        .iter()
        .filter(|(_, p)| p.as_os_str() != "-")
        .filter_map(|&(name, p)| identity(p).map(|id| (name, p, id)))
        .collect();
    let mut seen: Vec<(&str, FileIdentity)> = Vec::new();
    for &(name, path) in outputs {
        if path.as_os_str() == "-" || path == Path::new("/dev/null") {
            continue;
        }
        let Some(id) = identity(path) else {
            continue;
        };
        if let Some((input_name, input_path, _)) = inputs.iter().find(|(_, _, i)| *i == id) {
            let through = if path == *input_path {
                String::new()
            } else {
                format!(" ({} leads to the same file)", path.display())
            };
            return Err(FormatError::new(
                path,
                format!(
                    "the output {name} is the input given as {input_name}{through}: writing it would destroy the \
                     input; choose another output path"
                ),
            ));
        }
        if let Some((other, _)) = seen.iter().find(|(_, i)| *i == id) {
            return Err(FormatError::new(
                path,
                format!(
                    "{other} and {name} would both write this file: give each output its own path"
                ),
            ));
        }
        seen.push((name, id));
    }
    Ok(())
}

/// Opens an input for reading: a file, or the standard input for `-`.
///
/// ```
/// let e = roitrack_formats::open_input("no/such.csv".as_ref()).err().unwrap();
/// assert!(e.to_string().starts_with("no/such.csv: cannot open for reading"));
/// ```
pub fn open_input(path: &Path) -> Result<Box<dyn io::Read + Send>, FormatError> {
    if path.as_os_str() == "-" {
        return Ok(Box::new(io::stdin()));
    }
    let file = File::open(path).map_err(|e| FormatError::io(path, "cannot open for reading", e))?;
    Ok(Box::new(file))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn previous_file_survives_a_writer_dropped_without_finish() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("poses.tum");
        std::fs::write(&path, "old content\n").unwrap();
        {
            let mut f = AtomicFile::create(&path).unwrap();
            f.write_all(&vec![b'x'; 100_000]).unwrap();
            f.flush().unwrap();
            // Dropped here, without finish.
        }
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "old content\n");
        // No temporary file is left behind.
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);

        let mut f = AtomicFile::create(&path).unwrap();
        f.write_all(b"new content\n").unwrap();
        f.finish().unwrap();
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "new content\n");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
    }

    #[test]
    fn missing_directory_is_an_error_naming_the_path() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("missing").join("out.csv");
        let e = AtomicFile::create(&path).unwrap_err();
        let text = e.to_string();
        assert!(text.contains("out.csv"), "{text}");
        assert!(text.contains("missing"), "{text}");
        assert!(!dir.path().join("missing").exists());
    }

    #[test]
    fn relative_file_name_without_directory_works() {
        // A bare file name lives in the current directory; only check that creation is accepted and then dropped.
        let f = AtomicFile::create("roitrack-formats-atomic-test.tmp-out").unwrap();
        assert_eq!(f.path(), Path::new("roitrack-formats-atomic-test.tmp-out"));
        drop(f);
        assert!(!Path::new("roitrack-formats-atomic-test.tmp-out").exists());
    }

    #[cfg(unix)]
    #[test]
    fn a_symlink_output_writes_its_target_and_stays_a_link() {
        let dir = tempfile::tempdir().unwrap();
        let real = dir.path().join("real.csv");
        std::fs::write(&real, "old\n").unwrap();
        let link = dir.path().join("link.csv");
        std::os::unix::fs::symlink("real.csv", &link).unwrap();
        let mut f = AtomicFile::create(&link).unwrap();
        f.write_all(b"new\n").unwrap();
        f.finish().unwrap();
        assert!(
            std::fs::symlink_metadata(&link)
                .unwrap()
                .file_type()
                .is_symlink()
        );
        assert_eq!(std::fs::read_to_string(&real).unwrap(), "new\n");
        // A dangling link creates the file it points to.
        let dangling = dir.path().join("dangling.csv");
        std::os::unix::fs::symlink("created.csv", &dangling).unwrap();
        let mut f = AtomicFile::create(&dangling).unwrap();
        f.write_all(b"x\n").unwrap();
        f.finish().unwrap();
        assert_eq!(
            std::fs::read_to_string(dir.path().join("created.csv")).unwrap(),
            "x\n"
        );
        assert!(
            std::fs::symlink_metadata(&dangling)
                .unwrap()
                .file_type()
                .is_symlink()
        );
    }

    #[cfg(unix)]
    #[test]
    fn a_fifo_and_a_device_are_written_in_place() {
        use std::os::unix::fs::FileTypeExt;
        let dir = tempfile::tempdir().unwrap();
        let fifo = dir.path().join("pipe");
        let status = std::process::Command::new("mkfifo")
            .arg(&fifo)
            .status()
            .unwrap();
        assert!(status.success());
        let reader = {
            let fifo = fifo.clone();
            std::thread::spawn(move || std::fs::read_to_string(fifo).unwrap())
        };
        let mut f = AtomicFile::create(&fifo).unwrap();
        f.write_all(b"through the pipe\n").unwrap();
        f.finish().unwrap();
        assert_eq!(reader.join().unwrap(), "through the pipe\n");
        assert!(
            std::fs::symlink_metadata(&fifo)
                .unwrap()
                .file_type()
                .is_fifo()
        );
        let mut f = AtomicFile::create("/dev/null").unwrap();
        f.write_all(b"gone").unwrap();
        f.finish().unwrap();
        assert!(
            std::fs::metadata("/dev/null")
                .unwrap()
                .file_type()
                .is_char_device()
        );
    }

    #[cfg(unix)]
    #[test]
    fn outputs_that_are_inputs_or_each_other_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let input = dir.path().join("m.csv");
        std::fs::write(&input, "t,id,u,v\n").unwrap();
        let link = dir.path().join("link.csv");
        std::os::unix::fs::symlink(&input, &link).unwrap();
        let hard = dir.path().join("hard.csv");
        std::fs::hard_link(&input, &hard).unwrap();
        let inputs = [("--measurements", input.as_path())];
        for out in [&input, &link, &hard] {
            let e = check_output_paths(&inputs, &[("--poses", out)])
                .unwrap_err()
                .to_string();
            assert!(
                e.contains("the output --poses is the input given as --measurements"),
                "{e}"
            );
        }
        // The same new file by two spellings.
        let a = dir.path().join("out.tum");
        let b = dir.path().join(".").join("out.tum");
        let e = check_output_paths(&inputs, &[("--poses", &a), ("--twists", &b)])
            .unwrap_err()
            .to_string();
        assert!(e.contains("--poses and --twists would both write"), "{e}");
        let e = check_output_paths(
            &[],
            &[("--poses", Path::new("-")), ("--twists", Path::new("-"))],
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("--poses, --twists all write to the standard output"),
            "{e}"
        );
        let null = Path::new("/dev/null");
        assert!(check_output_paths(&inputs, &[("--poses", null), ("--twists", null)]).is_ok());
    }
}
