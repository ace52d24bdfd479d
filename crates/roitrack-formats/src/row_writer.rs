//! Shared machinery of the line-oriented writers: atomic file, line count, finiteness and time-order checks.

use std::fmt;
use std::io::Write;
use std::path::Path;

use crate::csv_util::check_time_order;
use crate::{AtomicFile, FormatError};

/// Writes one record per line to an [`AtomicFile`], refusing what the matching reader would refuse (non-finite
/// values, times out of order), so that every finished file reads back.
#[derive(Debug)]
pub(crate) struct RowWriter {
    file: AtomicFile,
    /// 1-based line the next record goes to.
    next_line: u64,
    previous: Option<(f64, u64)>,
    strict_time: bool,
}

impl RowWriter {
    /// Creates the temporary file and writes the header line, if any.
    pub(crate) fn create(
        path: &Path,
        header: Option<&str>,
        strict_time: bool,
    ) -> Result<Self, FormatError> {
        let mut writer = Self {
            file: AtomicFile::create(path)?,
            next_line: 1,
            previous: None,
            strict_time,
        };
        if let Some(header) = header {
            writer.write_line(format_args!("{header}"))?;
        }
        Ok(writer)
    }

    /// Checks a record before writing it: time `t_s` (field `t`) in order, every value finite.
    pub(crate) fn check(&self, t_s: f64, values: &[(&str, f64)]) -> Result<(), FormatError> {
        let path = self.file.path();
        for &(field, value) in std::iter::once(&("t", t_s)).chain(values) {
            if !value.is_finite() {
                return Err(FormatError::new(
                    path,
                    format!("cannot write a non-finite value: {value}"),
                )
                .with_line(self.next_line)
                .with_field(field));
            }
        }
        check_time_order(
            self.previous,
            t_s,
            self.strict_time,
            path,
            self.next_line,
            "t",
        )
    }

    /// Writes one checked record (time `t_s`) as one line.
    pub(crate) fn write_record(
        &mut self,
        t_s: f64,
        args: fmt::Arguments<'_>,
    ) -> Result<(), FormatError> {
        let line = self.next_line;
        self.write_line(args)?;
        self.previous = Some((t_s, line));
        Ok(())
    }

    fn write_line(&mut self, args: fmt::Arguments<'_>) -> Result<(), FormatError> {
        let result = self
            .file
            .write_fmt(args)
            .and_then(|()| self.file.write_all(b"\n"));
        result.map_err(|e| self.file.write_error(e))?;
        self.next_line += 1;
        Ok(())
    }

    /// Persists the file at its path.
    pub(crate) fn finish(self) -> Result<(), FormatError> {
        self.file.finish()
    }
}
