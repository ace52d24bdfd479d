//! [`AtomicFile`]: write a file completely or not at all.

use std::io::{self, BufWriter, Write};
use std::path::{Path, PathBuf};

use tempfile::NamedTempFile;

use crate::FormatError;

/// A buffered file that appears at its path only when [`AtomicFile::finish`] succeeds.
///
/// The content goes to a temporary file in the target's directory (so the final rename stays on one file system);
/// `finish` flushes it, syncs it to disk and renames it onto the target, replacing any previous file at once.
/// Dropping an `AtomicFile` without `finish` (an error, a panic, an interrupted run) deletes the temporary file and
/// leaves whatever was at the target path untouched: readers never see a half-written file.
///
/// The target's directory must exist; it is not created.
#[derive(Debug)]
pub struct AtomicFile {
    target: PathBuf,
    writer: BufWriter<NamedTempFile>,
}

impl AtomicFile {
    /// Starts writing `path`: creates the temporary file beside it.
    pub fn create(path: impl AsRef<Path>) -> Result<Self, FormatError> {
        let target = path.as_ref().to_path_buf();
        let Some(file_name) = target.file_name() else {
            return Err(FormatError::new(&target, "not a file path"));
        };
        let dir = match target.parent() {
            Some(dir) if !dir.as_os_str().is_empty() => dir,
            _ => Path::new("."),
        };
        if !dir.is_dir() {
            return Err(FormatError::new(
                &target,
                format!("directory '{}' does not exist", dir.display()),
            ));
        }
        let mut prefix = std::ffi::OsString::from(".");
        prefix.push(file_name);
        prefix.push(".");
        let mut builder = tempfile::Builder::new();
        builder.prefix(&prefix).suffix(".tmp");
        // NamedTempFile is private to its owner (0600) by default; the result is an ordinary output file, so let the
        // umask decide, as for any file the user creates.
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            builder.permissions(std::fs::Permissions::from_mode(0o666));
        }
        let temp = builder.tempfile_in(dir).map_err(|e| {
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
            writer: BufWriter::new(temp),
        })
    }

    /// The path the file will have once finished.
    pub fn path(&self) -> &Path {
        &self.target
    }

    /// Flushes, syncs and renames the temporary file onto the target path.
    pub fn finish(self) -> Result<(), FormatError> {
        let target = self.target;
        let temp = self
            .writer
            .into_inner()
            .map_err(|e| FormatError::io(&target, "cannot write", e.into_error()))?;
        temp.as_file()
            .sync_all()
            .map_err(|e| FormatError::io(&target, "cannot sync to disk", e))?;
        temp.persist(&target).map_err(|e| {
            FormatError::io(&target, "cannot move the finished file into place", e.error)
        })?;
        Ok(())
    }

    /// An input/output error while writing this file, as a [`FormatError`].
    pub(crate) fn write_error(&self, error: io::Error) -> FormatError {
        FormatError::io(&self.target, "cannot write", error)
    }
}

impl Write for AtomicFile {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        self.writer.write(buf)
    }

    fn write_all(&mut self, buf: &[u8]) -> io::Result<()> {
        self.writer.write_all(buf)
    }

    fn flush(&mut self) -> io::Result<()> {
        self.writer.flush()
    }
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
}
