//! [`FormatError`]: what went wrong, in which file, on which line, in which field.

use std::fmt;
use std::io;
use std::path::{Path, PathBuf};

/// An error reading or writing one of roitrack's files.
///
/// It names the file (as given by the caller), the 1-based line where that is meaningful, the field or column, and
/// says what is wrong. Its [`Display`](fmt::Display) reads like a compiler diagnostic:
///
/// ```text
/// measurements.csv:17: field 'u': not a number: "abc"
/// camera.yaml: field 'distortion_model': missing, but distortion_coefficients has 5 values (expected plumb_bob)
/// out/poses.tum: cannot create a temporary file in directory 'out': No such file or directory (os error 2)
/// ```
#[derive(Debug)]
pub struct FormatError {
    path: PathBuf,
    line: Option<u64>,
    field: Option<String>,
    message: String,
    io: Option<io::Error>,
}

impl FormatError {
    /// An error about the file `path`, with neither line nor field.
    pub fn new(path: impl AsRef<Path>, message: impl Into<String>) -> Self {
        Self {
            path: path.as_ref().to_path_buf(),
            line: None,
            field: None,
            message: message.into(),
            io: None,
        }
    }

    /// An input/output error on `path`; `doing` says what was attempted (e.g. "cannot open for reading").
    pub fn io(path: impl AsRef<Path>, doing: &str, error: io::Error) -> Self {
        let mut e = Self::new(path, format!("{doing}: {error}"));
        e.io = Some(error);
        e
    }

    /// The same error, located on a 1-based line.
    #[must_use]
    pub fn with_line(mut self, line: impl Into<Option<u64>>) -> Self {
        self.line = line.into();
        self
    }

    /// The same error, about a field (a CSV column, a YAML key path such as `camera_matrix.data[0] (fx)`).
    #[must_use]
    pub fn with_field(mut self, field: impl Into<String>) -> Self {
        self.field = Some(field.into());
        self
    }

    /// The file, as the caller named it.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The 1-based line, if the error is about one line.
    pub fn line(&self) -> Option<u64> {
        self.line
    }

    /// The field or column, if the error is about one.
    pub fn field(&self) -> Option<&str> {
        self.field.as_deref()
    }

    /// What is wrong (without the path, line and field).
    pub fn message(&self) -> &str {
        &self.message
    }

    /// The underlying input/output error, if this is one. Its text is already part of [`Self::message`].
    pub fn io_error(&self) -> Option<&io::Error> {
        self.io.as_ref()
    }
}

impl fmt::Display for FormatError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.path.display())?;
        if let Some(line) = self.line {
            write!(f, ":{line}")?;
        }
        f.write_str(": ")?;
        if let Some(field) = &self.field {
            write!(f, "field '{field}': ")?;
        }
        f.write_str(&self.message)
    }
}

impl std::error::Error for FormatError {}

/// A reader's next item from `next` (`Ok(None)`: the end), setting `done` at the end or at an error, so that the
/// reader gives nothing more after either.
pub(crate) fn ending_at_end_or_error<T>(
    done: &mut bool,
    next: Result<Option<T>, FormatError>,
) -> Option<Result<T, FormatError>> {
    let next = next.transpose();
    *done = !matches!(next, Some(Ok(_)));
    next
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn display_names_path_line_and_field() {
        let e = FormatError::new("measurements.csv", "not a number: \"abc\"")
            .with_line(17)
            .with_field("u");
        assert_eq!(
            e.to_string(),
            "measurements.csv:17: field 'u': not a number: \"abc\""
        );
        let e = FormatError::new("target.csv", "too few points");
        assert_eq!(e.to_string(), "target.csv: too few points");
        let e = FormatError::io(
            "x.csv",
            "cannot open for reading",
            io::Error::from(io::ErrorKind::NotFound),
        );
        assert!(
            e.to_string()
                .starts_with("x.csv: cannot open for reading: ")
        );
        assert_eq!(e.io_error().unwrap().kind(), io::ErrorKind::NotFound);
    }
}
