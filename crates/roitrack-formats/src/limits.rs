//! How much of an input the readers take: a limit on the length of a line for every text file, and on the size of
//! each kind of file that is read whole (docs/model.md#limits).
//!
//! A reader meets inputs it was not meant for: `/dev/zero`, a file without a line break, a 2 GB bag given as a
//! camera file. Without limits these grow a buffer until memory runs out. With them, a text reader keeps at most one
//! line of [`MAX_LINE_BYTES`] in memory and stops at the first longer line, naming it; a reader that holds the whole
//! file checks its size before reading it (and counts the bytes as it reads, for pipes and devices that have no
//! size); and a reader of text looks at the first bytes of a file before reading the rest, so that a binary file is
//! refused at once, named for what it looks like.
//!
//! The streaming readers (measurements CSV, ROI recordings) read files of any size in constant memory and have no
//! file size limit.

use std::fs::File;
use std::io::{self, Read};
use std::path::Path;

use crate::FormatError;

/// The longest line (bytes, its line break excluded) a text input may have. The longest lines roitrack writes are
/// those of a covariance CSV, under 2 KiB; a calibration's longest, a matrix on one line, under 1 KiB.
pub const MAX_LINE_BYTES: usize = 64 * 1024;

/// The largest camera calibration file (bytes): real ones hold a few kilobytes.
pub const MAX_CAMERA_FILE_BYTES: u64 = 1 << 20;
/// The largest target CSV (bytes): 16 MiB is over 200,000 points.
pub const MAX_TARGET_FILE_BYTES: u64 = 16 << 20;
/// The largest timestamps CSV (bytes): 64 MiB is over a million frames (ten hours at 30 frames a second).
pub const MAX_TIMESTAMPS_FILE_BYTES: u64 = 64 << 20;
/// The largest image file (bytes) a frame is read from; decoding is bounded separately (512 MiB of pixels).
pub const MAX_IMAGE_FILE_BYTES: u64 = 256 << 20;
/// The default largest trajectory file (bytes): TUM poses, twists, diagnostics and covariance CSV, which are read
/// whole. 2 GiB is about 15 million poses, an hour of ground truth at 4 kHz; the readers' `*_limited` forms (and the
/// commands' `--max-file-mib`) take another limit.
pub const DEFAULT_MAX_TRAJECTORY_FILE_BYTES: u64 = 2 << 30;

/// Lists and mappings nested deeper than this in a camera file are refused before the YAML parser sees them (its
/// time grows with the square of the depth). Calibration files nest 4 levels at most.
pub const MAX_YAML_DEPTH: usize = 32;

/// How many bytes of a text file are looked at before the rest is read.
const SNIFF_BYTES: usize = 4096;

/// Which limit a [`LimitExceeded`] is about.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Limit {
    Line,
    File,
}

/// The payload of the `io::Error` a [`Limited`] reader returns, turned into a [`FormatError`] by
/// [`read_error`].
#[derive(Debug)]
struct LimitExceeded {
    limit: Limit,
    /// The 1-based line being read.
    line: u64,
    /// The limit (bytes).
    max_bytes: u64,
    /// What the file is, for the message (`a target CSV`).
    what: &'static str,
}

impl std::fmt::Display for LimitExceeded {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.limit {
            Limit::Line => write!(
                f,
                "line {} is longer than {} bytes: not {} (a binary file, or one without line breaks such as \
                 /dev/zero?)",
                self.line, self.max_bytes, self.what
            ),
            Limit::File => write!(
                f,
                "the file holds more than {}, the most {} may hold: is this the right file?",
                format_bytes(self.max_bytes),
                self.what
            ),
        }
    }
}

impl std::error::Error for LimitExceeded {}

/// `bytes` for a message: `64 KiB`, `16 MiB`, `2 GiB`, or the bytes.
pub(crate) fn format_bytes(bytes: u64) -> String {
    for (unit, size) in [("GiB", 1u64 << 30), ("MiB", 1 << 20), ("KiB", 1 << 10)] {
        if bytes >= size && bytes.is_multiple_of(size) {
            return format!("{} {unit}", bytes / size);
        }
    }
    if bytes >= 1 << 20 {
        return format!("{:.1} MiB", bytes as f64 / (1u64 << 20) as f64);
    }
    format!("{bytes} bytes")
}

/// A reader that stops with an error at the first line longer than `max_line_bytes` and after `max_file_bytes` in
/// all: what a text reader holds is then bounded whatever the source (a file, a pipe, a device).
#[derive(Debug)]
pub(crate) struct Limited<R> {
    inner: R,
    what: &'static str,
    max_line_bytes: usize,
    max_file_bytes: Option<u64>,
    /// The 1-based line being read, and its bytes so far.
    line: u64,
    line_bytes: usize,
    total_bytes: u64,
}

impl<R: Read> Limited<R> {
    /// `inner` read with lines of at most [`MAX_LINE_BYTES`] and, if given, at most `max_file_bytes` in all; `what`
    /// says what the file should be (`a target CSV`).
    pub(crate) fn new(inner: R, what: &'static str, max_file_bytes: Option<u64>) -> Self {
        Self {
            inner,
            what,
            max_line_bytes: MAX_LINE_BYTES,
            max_file_bytes,
            line: 1,
            line_bytes: 0,
            total_bytes: 0,
        }
    }

    fn exceeded(&self, limit: Limit, max_bytes: u64) -> io::Error {
        io::Error::new(
            io::ErrorKind::InvalidData,
            LimitExceeded {
                limit,
                line: self.line,
                max_bytes,
                what: self.what,
            },
        )
    }
}

impl<R: Read> Read for Limited<R> {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        let n = self.inner.read(buf)?;
        self.total_bytes += n as u64;
        for chunk in buf[..n].split_inclusive(|&b| b == b'\n') {
            let ends_line = chunk.last() == Some(&b'\n');
            self.line_bytes += chunk.len() - usize::from(ends_line);
            if self.line_bytes > self.max_line_bytes {
                return Err(self.exceeded(Limit::Line, self.max_line_bytes as u64));
            }
            if ends_line {
                self.line += 1;
                self.line_bytes = 0;
            }
        }
        if let Some(max) = self.max_file_bytes
            && self.total_bytes > max
        {
            return Err(self.exceeded(Limit::File, max));
        }
        Ok(n)
    }
}

/// An input/output error while reading `path` as a [`FormatError`]: a limit of a [`Limited`] reader names its line
/// (or the file's size), anything else is "cannot read" on `line` if known.
pub(crate) fn read_error(path: &Path, error: io::Error, line: Option<u64>) -> FormatError {
    if let Some(exceeded) = error
        .get_ref()
        .and_then(|e| e.downcast_ref::<LimitExceeded>())
    {
        let e = FormatError::new(path, exceeded.to_string());
        return match exceeded.limit {
            Limit::Line => e.with_line(exceeded.line),
            Limit::File => e,
        };
    }
    FormatError::io(path, "cannot read", error).with_line(line)
}

/// Opens `path` for reading, refusing a folder and a file larger than `max_file_bytes` before reading a byte of it
/// (a file's size is known from its metadata; devices and pipes, which have none, are bounded by [`Limited`] as
/// they are read). `what` says what the file should be (`a target CSV`).
pub(crate) fn open_file(
    path: &Path,
    what: &'static str,
    max_file_bytes: Option<u64>,
) -> Result<File, FormatError> {
    let file = File::open(path).map_err(|e| FormatError::io(path, "cannot open for reading", e))?;
    check_file(&file, path, what, max_file_bytes)?;
    Ok(file)
}

/// The checks of [`open_file`] on a file already open.
pub(crate) fn check_file(
    file: &File,
    path: &Path,
    what: &'static str,
    max_file_bytes: Option<u64>,
) -> Result<(), FormatError> {
    let metadata = file
        .metadata()
        .map_err(|e| FormatError::io(path, "cannot read its metadata", e))?;
    if metadata.is_dir() {
        return Err(FormatError::new(
            path,
            format!("is a folder: expected {what}"),
        ));
    }
    if let Some(max) = max_file_bytes
        && metadata.is_file()
        && metadata.len() > max
    {
        return Err(FormatError::new(
            path,
            format!(
                "the file is {}: {what} is at most {}; is this the right file?",
                format_bytes(metadata.len()),
                format_bytes(max)
            ),
        ));
    }
    Ok(())
}

/// What a file that starts with `bytes` looks like, if it is one of the binary kinds a user may give by mistake.
fn binary_kind(bytes: &[u8]) -> Option<&'static str> {
    const KINDS: [(&[u8], &str); 10] = [
        (b"\x89MCAP", "an MCAP file (a ROS 2 bag)"),
        (
            b"SQLite format 3\0",
            "an SQLite database (a ROS 2 bag in sqlite3 storage?)",
        ),
        (b"\x89PNG", "a PNG image"),
        (b"\xff\xd8\xff", "a JPEG image"),
        (b"II*\0", "a TIFF image"),
        (b"MM\0*", "a TIFF image"),
        (b"\x1f\x8b", "a gzip-compressed file"),
        (b"PK\x03\x04", "a zip archive"),
        (b"\x7fELF", "a program"),
        (crate::ROI_RECORDING_MAGIC, "a roitrack ROI recording"),
    ];
    KINDS
        .iter()
        .find(|(magic, _)| bytes.starts_with(magic))
        .map(|(_, kind)| *kind)
}

/// Reads the text file `path` whole, as a reader of `what` (`a camera calibration`) that holds at most
/// `max_file_bytes`: a folder or a larger file is refused before reading, the first bytes are looked at before the
/// rest (a binary file is refused, named for what it looks like), lines are at most [`MAX_LINE_BYTES`], the text must
/// be UTF-8 (the line of the first bad byte is named), and a leading byte-order mark is dropped.
pub(crate) fn read_text_file(
    path: &Path,
    what: &'static str,
    max_file_bytes: u64,
) -> Result<String, FormatError> {
    let file = open_file(path, what, Some(max_file_bytes))?;
    let mut reader = Limited::new(file, what, Some(max_file_bytes));
    let mut bytes = Vec::new();
    (&mut reader)
        .take(SNIFF_BYTES as u64)
        .read_to_end(&mut bytes)
        .map_err(|e| read_error(path, e, None))?;
    check_text_start(&bytes, path, what)?;
    reader
        .read_to_end(&mut bytes)
        .map_err(|e| read_error(path, e, None))?;
    let text = String::from_utf8(bytes).map_err(|e| {
        let at = e.utf8_error().valid_up_to();
        let bytes = e.as_bytes();
        let line = 1 + bytes[..at].iter().filter(|&&b| b == b'\n').count() as u64;
        FormatError::new(
            path,
            format!("not UTF-8 text: byte {at} is not valid UTF-8"),
        )
        .with_line(line)
    })?;
    Ok(match text.strip_prefix('\u{feff}') {
        Some(rest) => rest.to_string(),
        None => text,
    })
}

/// Refuses a file whose first bytes `start` are not text: a known binary kind, a NUL byte or bytes that are not
/// UTF-8 (a character cut by the end of `start` is not held against it).
pub(crate) fn check_text_start(
    start: &[u8],
    path: &Path,
    what: &'static str,
) -> Result<(), FormatError> {
    if let Some(kind) = binary_kind(start) {
        return Err(FormatError::new(
            path,
            format!("this is {kind}, not {what}"),
        ));
    }
    let not_text = |offset: usize, why: &str| {
        let line = 1 + start[..offset].iter().filter(|&&b| b == b'\n').count() as u64;
        FormatError::new(
            path,
            format!("not a text file ({why} at byte {offset}): expected {what}"),
        )
        .with_line(line)
    };
    if let Some(offset) = start.iter().position(|&b| b == 0) {
        return Err(not_text(offset, "a NUL byte"));
    }
    if let Err(e) = std::str::from_utf8(start)
        && e.error_len().is_some()
    {
        return Err(not_text(e.valid_up_to(), "a byte that is not UTF-8"));
    }
    Ok(())
}

/// Refuses YAML `text` whose lists and mappings nest deeper than [`MAX_YAML_DEPTH`], naming the line, before a YAML
/// parser takes quadratic time over it. The count is of block levels (indentation, `- ` entries) plus open flow
/// collections (`[`, `{` where a value starts); quoted scalars, comments and block scalars (`|`, `>`) are skipped.
pub(crate) fn check_yaml_depth(text: &str, path: &Path) -> Result<(), FormatError> {
    let mut indents: Vec<usize> = Vec::new();
    let mut flow_depth = 0usize;
    // A quoted scalar may run over several lines: the quote being read.
    let mut quote: Option<char> = None;
    // Inside a block scalar: the indentation of the line that opened it.
    let mut block_scalar: Option<usize> = None;
    for (index, line) in text.lines().enumerate() {
        let indent = line.len() - line.trim_start_matches(' ').len();
        let content = &line[indent..];
        if let Some(opened_at) = block_scalar {
            if content.trim().is_empty() || indent > opened_at {
                continue;
            }
            block_scalar = None;
        }
        let mut chars = content.char_indices().peekable();
        if quote.is_none() && flow_depth == 0 {
            if content.is_empty() || content.starts_with('#') || content.starts_with('%') {
                continue;
            }
            if content.starts_with("---") || content.starts_with("...") {
                indents.clear();
                continue;
            }
            while indents.last().is_some_and(|&top| top > indent) {
                indents.pop();
            }
            if indents.last().is_none_or(|&top| top < indent) {
                indents.push(indent);
            }
            // Compact nested sequences (`- - - x`): each entry a level deeper.
            while let Some(&(at, '-' | '?')) = chars.peek() {
                let rest = &content[at + 1..];
                if !(rest.is_empty() || rest.starts_with(' ')) {
                    break;
                }
                chars.next();
                while chars.peek().is_some_and(|&(_, c)| c == ' ') {
                    chars.next();
                }
                if let Some(&(next, _)) = chars.peek() {
                    indents.push(indent + next);
                }
            }
        }
        let mut node_start = true;
        let mut previous = ' ';
        while let Some((at, c)) = chars.next() {
            match quote {
                Some('"') => {
                    if c == '\\' {
                        chars.next();
                    } else if c == '"' {
                        quote = None;
                        node_start = false;
                    }
                    previous = c;
                    continue;
                }
                Some(_) => {
                    if c == '\'' {
                        if chars.peek().is_some_and(|&(_, n)| n == '\'') {
                            chars.next();
                        } else {
                            quote = None;
                            node_start = false;
                        }
                    }
                    previous = c;
                    continue;
                }
                None => {}
            }
            let next_is_blank = content[at + c.len_utf8()..]
                .chars()
                .next()
                .is_none_or(char::is_whitespace);
            match c {
                '#' if previous.is_whitespace() => break,
                '"' | '\'' if node_start => quote = Some(c),
                '[' | '{' if node_start => {
                    flow_depth += 1;
                    let depth = indents.len() + flow_depth;
                    if depth > MAX_YAML_DEPTH {
                        return Err(too_deep(path, index, depth));
                    }
                }
                ']' | '}' if flow_depth > 0 => {
                    flow_depth -= 1;
                    node_start = false;
                }
                ',' if flow_depth > 0 => node_start = true,
                ':' if next_is_blank || flow_depth > 0 => node_start = true,
                '-' | '?' if node_start && next_is_blank => {}
                '|' | '>' if node_start && flow_depth == 0 => {
                    block_scalar = Some(indent);
                    break;
                }
                c if c.is_whitespace() => {}
                _ => node_start = false,
            }
            previous = c;
        }
        if indents.len() + flow_depth > MAX_YAML_DEPTH {
            return Err(too_deep(path, index, indents.len() + flow_depth));
        }
    }
    Ok(())
}

fn too_deep(path: &Path, index: usize, depth: usize) -> FormatError {
    FormatError::new(
        path,
        format!(
            "lists and mappings nested {depth} deep, more than the {MAX_YAML_DEPTH} a camera file may have \
             (calibrations nest 4 at most): not a camera calibration"
        ),
    )
    .with_line(index as u64 + 1)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn read_all(bytes: &[u8], max_file_bytes: Option<u64>) -> Result<Vec<u8>, FormatError> {
        let mut out = Vec::new();
        Limited::new(bytes, "a test file", max_file_bytes)
            .read_to_end(&mut out)
            .map_err(|e| read_error(Path::new("t.csv"), e, None))?;
        Ok(out)
    }

    #[test]
    fn long_lines_and_large_files_are_refused_naming_the_line() {
        let mut text = b"a,b\r\n1,2\n".to_vec();
        text.extend(std::iter::repeat_n(b'x', MAX_LINE_BYTES));
        text.extend(b"\n3,4\n");
        assert_eq!(read_all(&text, None).unwrap(), text);
        text.insert(12, b'x');
        let e = read_all(&text, None).unwrap_err().to_string();
        assert!(
            e.starts_with("t.csv:3: line 3 is longer than 65536 bytes"),
            "{e}"
        );
        let e = read_all(b"1,2\n3,4\n", Some(5)).unwrap_err().to_string();
        assert_eq!(
            e,
            "t.csv: the file holds more than 5 bytes, the most a test file may hold: is this the right file?"
        );
    }

    #[test]
    fn binary_files_are_named_for_what_they_look_like() {
        let path = Path::new("c.yaml");
        let e = check_text_start(b"\x89MCAP0\r\n", path, "a camera calibration").unwrap_err();
        assert_eq!(
            e.to_string(),
            "c.yaml: this is an MCAP file (a ROS 2 bag), not a camera calibration"
        );
        let e = check_text_start(b"a: 1\nb\0", path, "a camera").unwrap_err();
        assert_eq!(
            e.to_string(),
            "c.yaml:2: not a text file (a NUL byte at byte 6): expected a camera"
        );
        // A character cut by the end of the bytes looked at is not an error.
        check_text_start("a: é".as_bytes().split_last().unwrap().1, path, "x").unwrap();
        assert!(check_text_start(b"a: \xff\xfe", path, "x").is_err());
    }

    #[test]
    fn yaml_depth_counts_flow_and_block_levels_only() {
        let path = Path::new("c.yaml");
        let deep = format!("a: {}{}\n", "[".repeat(40), "]".repeat(40));
        let e = check_yaml_depth(&deep, path).unwrap_err().to_string();
        assert!(
            e.starts_with("c.yaml:1: lists and mappings nested 33 deep"),
            "{e}"
        );
        let flow_maps = format!("a: {}1{}\n", "{b: ".repeat(40), "}".repeat(40));
        assert!(check_yaml_depth(&flow_maps, path).is_err());
        let mut block = String::new();
        for level in 0..40 {
            block += &format!("{}k{level}:\n", " ".repeat(level));
        }
        let e = check_yaml_depth(&block, path).unwrap_err().to_string();
        assert!(e.starts_with("c.yaml:33: "), "{e}");
        let dashes = format!("{}x\n", "- ".repeat(40));
        assert!(check_yaml_depth(&dashes, path).is_err());
        // Brackets inside plain or quoted scalars, comments and block scalars are not collections.
        let fine = format!(
            "name: a{}\nq: \"{}\"\ns: '[''{}'\n# {}\nt: |\n  {}\n  more\nk: [[1, 2], {{a: [3]}}]\n",
            "[".repeat(50),
            "[".repeat(50),
            "[".repeat(50),
            "[".repeat(50),
            "[".repeat(50),
        );
        check_yaml_depth(&fine, path).unwrap();
        let kalibr = "cam0:\n  T_cn_cnm1:\n  - [1.0, 0.0]\n  - [0.0, 1.0]\n  intrinsics: [1, 2, 3, 4]\ncam1:\n  x: 1\n";
        check_yaml_depth(kalibr, path).unwrap();
    }

    #[test]
    fn byte_counts_read_well() {
        assert_eq!(format_bytes(64 * 1024), "64 KiB");
        assert_eq!(format_bytes(2 << 30), "2 GiB");
        assert_eq!(format_bytes(1_500_000), "1.4 MiB");
        assert_eq!(format_bytes(12), "12 bytes");
    }
}
