//! [`FrameSource`]: a stream of timed grey frames from a folder of images, a numbered file pattern, a glob or a
//! video, for tracking from full frames (`roitrack track --images SOURCE`).

use std::cmp::Ordering;
use std::io;
use std::path::{Path, PathBuf};

use roitrack_image::Frame;

use crate::FormatError;
use crate::csv_util::{check_time_order, csv_reader, for_each_row};
use crate::image_file::{decode_frame_into, read_image_file};
use crate::limits::{Limited, MAX_TIMESTAMPS_FILE_BYTES, open_file};
use crate::units::{TimeUnit, check_time_unit};
use crate::video::{Tools, VIDEO_EXTENSIONS, VideoDecoder};

/// File extensions of the images a folder or a pattern is read for (compared without regard to case).
pub const FRAME_IMAGE_EXTENSIONS: &[&str] =
    &["png", "jpg", "jpeg", "pgm", "ppm", "pnm", "tif", "tiff"];

/// The first number a printf pattern's frames may start at: the first of these whose file exists (as ffmpeg's image
/// reader does).
const PATTERN_START_NUMBERS: std::ops::RangeInclusive<u64> = 0..=4;

/// Where the frames' times come from: a timestamps CSV file or a constant frame rate, else (videos only) the video's
/// own timestamps. At most one of the two may be given.
///
/// ```
/// use roitrack_formats::FrameTiming;
///
/// use roitrack_formats::TimeUnit;
///
/// let from_csv = FrameTiming { timestamps: Some("times.csv".into()), ..FrameTiming::default() };
/// let from_csv_in_ms = FrameTiming { time_units: Some(TimeUnit::Ms), ..from_csv.clone() };
/// let at_100_hz = FrameTiming { fps: Some(100.0), ..FrameTiming::default() };
/// let video_own = FrameTiming::default(); // videos only: image sequences have no times of their own
/// # let _ = (from_csv, from_csv_in_ms, at_100_hz, video_own);
/// ```
#[derive(Debug, Clone, Default, PartialEq)]
pub struct FrameTiming {
    /// A CSV file with a header, a column `t` (s) and one row per frame, in order; optionally a column `file`
    /// holding each frame's file name (without its folder), checked against the frame's (image sequences only).
    pub timestamps: Option<PathBuf>,
    /// A constant frame rate (frames per second): frame `i` is at `i / fps` s; from [`MIN_FRAME_RATE_HZ`] to
    /// [`MAX_FRAME_RATE_HZ`].
    pub fps: Option<f64>,
    /// The unit of the timestamps CSV's times. `None`: seconds, and times that look like milliseconds, microseconds
    /// or nanoseconds are refused (as a measurements file's are: frames more than 0.2 s apart, the median over the
    /// first 1,000 rows, or times past the year 5000), naming the likely unit.
    pub time_units: Option<TimeUnit>,
}

/// The lowest frame rate (`--fps`, Hz) taken: a frame every 1,000 s.
pub const MIN_FRAME_RATE_HZ: f64 = 1e-3;
/// The highest frame rate (`--fps`, Hz) taken: 10 million frames a second, beyond the fastest cameras built.
pub const MAX_FRAME_RATE_HZ: f64 = 1e7;
/// How many timestamps the unit check looks at.
const TIME_CHECK_ROWS: usize = 1000;

/// What was read into the frame by [`FrameSource::next_frame`].
#[derive(Debug, Clone, PartialEq)]
pub struct FrameInfo {
    /// 0-based position of the frame in the source.
    pub index: usize,
    /// The frame's file name (without its folder), or `frame N of VIDEO` (N 0-based, VIDEO the video's file name).
    pub name: String,
    /// The frame's time (s), also written to the frame's `t_s`.
    pub t_s: f64,
}

/// How a source was understood.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum SourceKind {
    /// An existing folder: its image files, in natural order.
    Directory,
    /// A printf pattern such as `frames/frame_%05d.png`: consecutive numbers.
    Pattern,
    /// A glob such as `frames/*.png`: the matching files, in natural order.
    Glob,
    /// A video file, decoded by ffmpeg.
    Video,
}

/// Timed grey frames, one after the other, from a folder of images, a numbered file pattern, a glob or a video.
///
/// [`FrameSource::open`] decides what `source` is, in this order:
///
/// 1. an existing **folder**: every file in it whose extension is one of [`FRAME_IMAGE_EXTENSIONS`] (in any case),
///    in natural order (`frame2` before `frame10`: digit runs compare as numbers); hidden files (`.name`) and every
///    other file are ignored;
/// 2. an existing **video** file, by its extension: mp4, mkv, avi, mov, webm or m4v (in any case), decoded by the
///    `ffmpeg` program (package `ffmpeg`, version 5.1 or later; see below);
/// 3. a printf **pattern**: a path containing `%d` or `%0Nd` (`%%` for a `%`), e.g. `frames/frame_%05d.png`; the
///    frames are numbered from the first of 0 to 4 whose file exists, consecutively up to the first number missing;
/// 4. a **glob**: a path containing `*`, `?` or `[` (quoted, so that the shell leaves it): every matching file (folders
///    skipped, any extension), in natural order;
///
/// and refuses anything else: a single image file (give its folder, a pattern or a glob: the error suggests them), a
/// file of another kind, a path that does not exist; and sources with no frame.
///
/// Images are decoded as by [`decode_frame`](crate::decode_frame) (colour made grey); every frame must have the size
/// and the bit depth of the first. Frame times, by [`FrameTiming`]:
///
/// - a **timestamps CSV** (`--timestamps FILE.csv`): a header naming `t` and optionally `file` (in either order, no
///   other column), then one row per frame in order; `t` finite and strictly increasing; `file`, when present, equal
///   to the frame's file name (a video's frames have none: a `file` column is refused for a video); times that look
///   like milliseconds, microseconds or nanoseconds refused unless [`FrameTiming::time_units`] says the unit. For an image
///   sequence the whole file is checked at `open`, row count included; for a video, rows are matched as frames come
///   and the count is checked at the end;
/// - else a **frame rate** (`--fps F`): frame `i` at `i / F` s (`F` from [`MIN_FRAME_RATE_HZ`] to
///   [`MAX_FRAME_RATE_HZ`]);
/// - else, for a video, **its own timestamps**: each decoded frame's presentation time, as the container gives it
///   (not shifted to start at 0), listed by `ffprobe` alongside the decoding; for an image sequence, an error:
///   roitrack never guesses frame times.
///
/// Giving both a CSV and a frame rate is an error. Times must increase strictly, whatever their source.
///
/// Videos are decoded by running `ffprobe` (size, pixel format, time base, frame count) and then `ffmpeg`, which
/// writes the first video stream (not cover art) as raw grey pixels to a pipe: 8 bits (`gray`) for sources of 8 bits
/// or fewer, else 16 bits (`gray16le`, scaled to the full 16 bits by ffmpeg, `bit_depth` 16). Limited-range
/// (TV) luma is expanded to the full range; rotation metadata is ignored (the pixels as stored). Every frame is kept
/// (`-fps_mode passthrough`). A missing `ffmpeg` is an error saying to install it; ffmpeg's messages go into the
/// error when it fails, and since ffmpeg decodes what it can of a truncated file and exits with success, anything it
/// reports at its error level ends the stream with an error after the last good frame. Dropping the source ends the
/// programs and reaps them.
///
/// After an error, [`FrameSource::next_frame`] returns `None`: the stream ends there.
///
/// ```
/// use roitrack_formats::{FrameSource, FrameTiming, write_frame_png};
/// use roitrack_image::Frame;
///
/// # fn main() -> Result<(), roitrack_formats::FormatError> {
/// let dir = tempfile::tempdir().unwrap();
/// for i in [2, 10, 1] {
///     let mut frame = Frame::new(8, 6, 8);
///     frame.pixels[0] = i;
///     write_frame_png(dir.path().join(format!("frame{i}.png")), &frame)?;
/// }
/// let timing = FrameTiming { fps: Some(50.0), ..FrameTiming::default() };
/// let mut source = FrameSource::open(dir.path(), &timing)?;
/// assert_eq!(source.frame_count(), Some(3));
///
/// let mut frame = Frame::default(); // one buffer for every frame
/// let mut seen = Vec::new();
/// while let Some(info) = source.next_frame(&mut frame) {
///     let info = info?;
///     assert_eq!(frame.t_s, info.t_s);
///     seen.push((info.name, info.t_s, frame.pixels[0]));
/// }
/// assert_eq!(
///     seen,
///     [("frame1.png".into(), 0.0, 1), ("frame2.png".into(), 0.02, 2), ("frame10.png".into(), 0.04, 10)]
/// );
///
/// // No times, no frames.
/// let e = FrameSource::open(dir.path(), &FrameTiming::default()).unwrap_err();
/// assert!(e.to_string().contains("--timestamps FILE.csv"));
/// # Ok(())
/// # }
/// ```
#[derive(Debug)]
pub struct FrameSource {
    source: PathBuf,
    kind: SourceKind,
    frames: Frames,
    times: Times,
    index: usize,
    /// The first frame's name, size and bit depth, which every later frame must have.
    first: Option<(String, u32, u32, u8)>,
    previous_t_s: Option<f64>,
    done: bool,
}

#[derive(Debug)]
enum Frames {
    Images {
        files: Vec<PathBuf>,
        /// The file being decoded, reused from frame to frame.
        bytes: Vec<u8>,
    },
    Video {
        decoder: Box<VideoDecoder>,
        /// The video's file name, for the frames' names.
        name: String,
    },
}

#[derive(Debug)]
enum Times {
    Csv { path: PathBuf, rows: Vec<TimeRow> },
    Fps(f64),
    Video,
}

/// One row of a timestamps CSV.
#[derive(Debug, Clone, PartialEq)]
struct TimeRow {
    t_s: f64,
    line: u64,
    file: Option<String>,
}

impl FrameSource {
    /// Opens `source` (see [`FrameSource`] for what it may be) with the frame times of `timing`.
    ///
    /// Fails, naming the source or the file at fault: a source that is none of the kinds above or has no frame, a bad
    /// or mismatched timestamps CSV (for image sequences every row is checked here), both or neither timing for an
    /// image sequence, a frame rate that is not finite and positive, a video that ffprobe cannot read or a missing
    /// ffmpeg.
    pub fn open(source: impl AsRef<Path>, timing: &FrameTiming) -> Result<Self, FormatError> {
        Self::open_with(source.as_ref(), timing, &Tools::default())
    }

    pub(crate) fn open_with(
        source: &Path,
        timing: &FrameTiming,
        tools: &Tools,
    ) -> Result<Self, FormatError> {
        let (kind, files) = locate(source)?;
        if let (Some(_), Some(_)) = (&timing.timestamps, timing.fps) {
            return Err(FormatError::new(
                source,
                "give the frame times by --timestamps FILE.csv or by --fps F, not both",
            ));
        }
        let is_video = kind == SourceKind::Video;
        let times = if let Some(csv) = &timing.timestamps {
            let mut rows = read_times_csv(csv, is_video)?;
            if let Some(files) = &files {
                check_rows_against_files(csv, &rows, files)?;
            }
            match timing.time_units {
                Some(unit) => rows.iter_mut().for_each(|row| row.t_s *= unit.seconds()),
                None => {
                    let first: Vec<(f64, u64)> = rows
                        .iter()
                        .take(TIME_CHECK_ROWS)
                        .map(|row| (row.t_s, row.line))
                        .collect();
                    check_time_unit(&first, csv, "frames")?;
                }
            }
            Times::Csv {
                path: csv.clone(),
                rows,
            }
        } else if let Some(fps) = timing.fps {
            if !(MIN_FRAME_RATE_HZ..=MAX_FRAME_RATE_HZ).contains(&fps) {
                return Err(FormatError::new(
                    source,
                    format!(
                        "frame rate {} fps: --fps must be from {MIN_FRAME_RATE_HZ} (a frame every 1,000 s) to \
                         {MAX_FRAME_RATE_HZ:e} (beyond the fastest cameras)",
                        if (1e-4..1e9).contains(&fps.abs()) {
                            format!("{fps}")
                        } else {
                            format!("{fps:e}")
                        }
                    ),
                ));
            }
            Times::Fps(fps)
        } else if is_video {
            Times::Video
        } else {
            return Err(FormatError::new(
                source,
                "no frame times: give --timestamps FILE.csv (a header with a column t, in seconds, then one row \
                 per frame) or --fps F (frame i at i / F s); roitrack never guesses frame times",
            ));
        };
        let frames = match files {
            Some(files) => Frames::Images {
                files,
                bytes: Vec::new(),
            },
            None => Frames::Video {
                decoder: Box::new(VideoDecoder::open(
                    source,
                    tools,
                    matches!(times, Times::Video),
                )?),
                name: file_name(source),
            },
        };
        Ok(Self {
            source: source.to_path_buf(),
            kind,
            frames,
            times,
            index: 0,
            first: None,
            previous_t_s: None,
            done: false,
        })
    }

    /// The source as given to [`FrameSource::open`].
    pub fn source(&self) -> &Path {
        &self.source
    }

    /// How the source was understood.
    pub fn kind(&self) -> SourceKind {
        self.kind
    }

    /// The number of frames, when known before reading them: always for image sequences; for a video, the number its
    /// container announces (or, when it does not, the number of its video packets, counted without decoding), which
    /// is meant for a progress display, not as a promise (the stream ends when ffmpeg's output does).
    pub fn frame_count(&self) -> Option<usize> {
        match &self.frames {
            Frames::Images { files, .. } => Some(files.len()),
            Frames::Video { decoder, .. } => decoder.frame_count(),
        }
    }

    /// Reads the next frame into `frame` (its pixel buffer reused), sets its `t_s` and says which frame it is;
    /// `None` after the last frame or after an error.
    pub fn next_frame(&mut self, frame: &mut Frame) -> Option<Result<FrameInfo, FormatError>> {
        if self.done {
            return None;
        }
        let next = self.read_next(frame);
        crate::error::ending_at_end_or_error(&mut self.done, next)
    }

    fn read_next(&mut self, frame: &mut Frame) -> Result<Option<FrameInfo>, FormatError> {
        let index = self.index;
        let (name, own_t_s) = match &mut self.frames {
            Frames::Images { files, bytes } => {
                let Some(path) = files.get(index) else {
                    return Ok(None);
                };
                read_image_file(path, bytes)?;
                decode_frame_into(bytes, path, frame)?;
                (file_name(path), None)
            }
            Frames::Video { decoder, name } => {
                let Some(own_t_s) = decoder.next(frame)? else {
                    if let Times::Csv { path, rows } = &self.times
                        && rows.len() > index
                    {
                        return Err(FormatError::new(
                            path,
                            format!("{} rows for {index} frames of {name}", rows.len()),
                        )
                        .with_line(rows[index].line));
                    }
                    return Ok(None);
                };
                (format!("frame {index} of {name}"), own_t_s)
            }
        };
        self.check_size(index, &name, frame)?;
        let t_s = self.time_of(index, &name, own_t_s)?;
        if let Some(previous) = self.previous_t_s
            && t_s <= previous
        {
            // Only a video's own times can get here: CSV times were checked as read, fps times increase.
            return Err(FormatError::new(
                self.location(index),
                format!(
                    "{name}: time {t_s} s is not after the previous frame's {previous} s: the video's timestamps \
                     repeat or go backwards (give --fps F or --timestamps FILE.csv)"
                ),
            ));
        }
        self.previous_t_s = Some(t_s);
        frame.t_s = t_s;
        self.index += 1;
        Ok(Some(FrameInfo { index, name, t_s }))
    }

    /// The file that frame `index` comes from, for errors about it.
    fn location(&self, index: usize) -> &Path {
        match &self.frames {
            Frames::Images { files, .. } => files.get(index).map_or(&self.source, |p| p),
            Frames::Video { .. } => &self.source,
        }
    }

    /// Checks that a frame has the size and bit depth of the first.
    fn check_size(&mut self, index: usize, name: &str, frame: &Frame) -> Result<(), FormatError> {
        let Some((first_name, width, height, bit_depth)) = &self.first else {
            self.first = Some((name.to_string(), frame.width, frame.height, frame.bit_depth));
            return Ok(());
        };
        if (frame.width, frame.height) != (*width, *height) {
            return Err(FormatError::new(
                self.location(index),
                format!(
                    "frame {index} is {} x {} px, but the first frame ({first_name}) is {width} x {height} px: \
                     every frame must have the same size",
                    frame.width, frame.height
                ),
            ));
        }
        if frame.bit_depth != *bit_depth {
            return Err(FormatError::new(
                self.location(index),
                format!(
                    "frame {index} has {} bits per pixel, but the first frame ({first_name}) has {bit_depth}: \
                     every frame must have the same bit depth",
                    frame.bit_depth
                ),
            ));
        }
        Ok(())
    }

    /// The time (s) of frame `index`; `own_t_s` is the video's own.
    fn time_of(&self, index: usize, name: &str, own_t_s: Option<f64>) -> Result<f64, FormatError> {
        match &self.times {
            Times::Csv { path, rows } => match rows.get(index) {
                Some(row) => Ok(row.t_s),
                None => Err(FormatError::new(
                    path,
                    format!(
                        "no row for frame {index} ({name}): {} rows for more frames",
                        rows.len()
                    ),
                )),
            },
            // Exact for every index below 2^53.
            Times::Fps(fps) => Ok(index as f64 / fps),
            Times::Video => own_t_s.ok_or_else(|| {
                FormatError::new(&self.source, format!("{name}: no time from the video"))
            }),
        }
    }
}

/// The file name of `path` (without its folder), or the whole path when it has none.
fn file_name(path: &Path) -> String {
    path.file_name().map_or_else(
        || path.display().to_string(),
        |n| n.to_string_lossy().into_owned(),
    )
}

fn has_extension(path: &Path, extensions: &[&str]) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| extensions.iter().any(|x| x.eq_ignore_ascii_case(e)))
}

/// What `source` is and, for image sequences, its files in order.
fn locate(source: &Path) -> Result<(SourceKind, Option<Vec<PathBuf>>), FormatError> {
    match std::fs::metadata(source) {
        Ok(meta) if meta.is_dir() => {
            return Ok((SourceKind::Directory, Some(list_folder(source)?)));
        }
        Ok(_) if has_extension(source, VIDEO_EXTENSIONS) => return Ok((SourceKind::Video, None)),
        Ok(_) if has_extension(source, FRAME_IMAGE_EXTENSIONS) => {
            return Err(one_image_error(source));
        }
        Ok(_) => {
            return Err(FormatError::new(
                source,
                format!(
                    "not a folder of images, a video ({}), a numbered pattern such as frame_%05d.png or a glob",
                    VIDEO_EXTENSIONS.join(", ")
                ),
            ));
        }
        Err(e) if e.kind() == io::ErrorKind::NotFound => {}
        Err(e) => return Err(FormatError::io(source, "cannot read", e)),
    }
    let text = source.to_str();
    if let Some(pattern) = text.and_then(|t| PrintfPattern::parse(t).transpose()) {
        let pattern = pattern.map_err(|m| FormatError::new(source, m))?;
        return Ok((SourceKind::Pattern, Some(pattern.files(source)?)));
    }
    if let Some(text) = text.filter(|t| t.contains(['*', '?', '['])) {
        return Ok((SourceKind::Glob, Some(glob_files(source, text)?)));
    }
    let what = if has_extension(source, VIDEO_EXTENSIONS) {
        "no such video file"
    } else {
        "no such file or folder (nor is it a pattern with %d or %05d, or a glob with * or ?)"
    };
    Err(FormatError::new(source, what))
}

/// The error for a single image given as the source, suggesting its folder, a pattern built from its number and a
/// glob.
fn one_image_error(path: &Path) -> FormatError {
    let folder = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let name = file_name(path);
    let extension = path
        .extension()
        .map_or_else(String::new, |e| e.to_string_lossy().into_owned());
    let mut suggestions = vec![format!("its folder '{}'", folder.display())];
    if let Some(pattern) = pattern_of_name(&name) {
        suggestions.push(format!(
            "a pattern such as '{}'",
            folder.join(pattern).display()
        ));
    }
    suggestions.push(format!(
        "a quoted glob such as '{}'",
        folder.join(format!("*.{extension}")).display()
    ));
    FormatError::new(
        path,
        format!(
            "is a single image, not a sequence of frames: give {}",
            suggestions.join(", ")
        ),
    )
}

/// `frame_00012.png` → `frame_%05d.png`: the last run of digits as a printf conversion of its width.
fn pattern_of_name(name: &str) -> Option<String> {
    let end = name.rfind(|c: char| c.is_ascii_digit())? + 1;
    let start = name[..end]
        .rfind(|c: char| !c.is_ascii_digit())
        .map_or(0, |i| i + 1);
    let digits = end - start;
    let conversion = if digits > 1 && name[start..].starts_with('0') {
        format!("%0{digits}d")
    } else {
        "%d".to_string()
    };
    let escape = |s: &str| s.replace('%', "%%");
    Some(format!(
        "{}{conversion}{}",
        escape(&name[..start]),
        escape(&name[end..])
    ))
}

/// The image files of a folder, in natural order.
fn list_folder(folder: &Path) -> Result<Vec<PathBuf>, FormatError> {
    let entries = std::fs::read_dir(folder)
        .map_err(|e| FormatError::io(folder, "cannot list the folder", e))?;
    let mut files = Vec::new();
    for entry in entries {
        let entry = entry.map_err(|e| FormatError::io(folder, "cannot list the folder", e))?;
        let path = entry.path();
        let hidden = entry.file_name().to_string_lossy().starts_with('.');
        if !hidden && has_extension(&path, FRAME_IMAGE_EXTENSIONS) && path.is_file() {
            files.push(path);
        }
    }
    if files.is_empty() {
        return Err(FormatError::new(
            folder,
            format!(
                "no image files in this folder (looked for the extensions {})",
                FRAME_IMAGE_EXTENSIONS.join(", ")
            ),
        ));
    }
    sort_naturally(&mut files);
    Ok(files)
}

fn sort_naturally(files: &mut [PathBuf]) {
    files.sort_by(|a, b| {
        natural_cmp(&a.to_string_lossy(), &b.to_string_lossy()).then_with(|| a.cmp(b))
    });
}

/// The files matching a glob pattern, in natural order.
fn glob_files(source: &Path, pattern: &str) -> Result<Vec<PathBuf>, FormatError> {
    let options = glob::MatchOptions {
        case_sensitive: true,
        require_literal_separator: true,
        require_literal_leading_dot: true,
    };
    let matches = glob::glob_with(pattern, options).map_err(|e| {
        FormatError::new(
            source,
            format!(
                "not a valid glob pattern: {} (at character {})",
                e.msg,
                e.pos + 1
            ),
        )
    })?;
    let mut files = Vec::new();
    for path in matches {
        let path = path.map_err(|e| {
            let at = e.path().to_path_buf();
            FormatError::io(&at, "cannot read while matching the glob", e.into())
        })?;
        if path.is_file() {
            files.push(path);
        }
    }
    if files.is_empty() {
        return Err(FormatError::new(
            source,
            "no file matches this glob pattern",
        ));
    }
    sort_naturally(&mut files);
    Ok(files)
}

/// A path with one printf conversion `%d` or `%0Nd`.
#[derive(Debug, Clone, PartialEq, Eq)]
struct PrintfPattern {
    prefix: String,
    width: usize,
    suffix: String,
}

impl PrintfPattern {
    /// `Ok(None)` when `text` has no conversion (it is then not a pattern); an error for two conversions.
    fn parse(text: &str) -> Result<Option<Self>, String> {
        let mut prefix = String::new();
        let mut found: Option<usize> = None;
        let mut suffix = String::new();
        let mut rest = text;
        while let Some(at) = rest.find('%') {
            let out = if found.is_some() {
                &mut suffix
            } else {
                &mut prefix
            };
            out.push_str(&rest[..at]);
            let after = &rest[at + 1..];
            if let Some(r) = after.strip_prefix('%') {
                out.push('%');
                rest = r;
                continue;
            }
            let digits = after.len() - after.trim_start_matches(|c: char| c.is_ascii_digit()).len();
            let spec = &after[..digits];
            let is_conversion = after[digits..].starts_with('d')
                && (spec.is_empty() || (spec.starts_with('0') && spec.len() > 1));
            if !is_conversion {
                out.push('%');
                rest = after;
                continue;
            }
            if found.is_some() {
                return Err(
                    "a pattern takes one number (%d or %0Nd), this one has more than one"
                        .to_string(),
                );
            }
            let width = spec.parse::<usize>().unwrap_or(0);
            if width > 20 {
                return Err(format!(
                    "%0{width}d: a number of {width} digits is more than a frame number needs"
                ));
            }
            found = Some(width);
            rest = &after[digits + 1..];
        }
        let Some(width) = found else {
            return Ok(None);
        };
        suffix.push_str(rest);
        Ok(Some(Self {
            prefix,
            width,
            suffix,
        }))
    }

    fn path(&self, number: u64) -> PathBuf {
        PathBuf::from(format!(
            "{}{number:0width$}{}",
            self.prefix,
            self.suffix,
            width = self.width
        ))
    }

    /// The files from the first existing start number, consecutively up to the first number missing.
    fn files(&self, source: &Path) -> Result<Vec<PathBuf>, FormatError> {
        let Some(start) = PATTERN_START_NUMBERS
            .clone()
            .find(|&n| self.path(n).is_file())
        else {
            return Err(FormatError::new(
                source,
                format!(
                    "no file matches this pattern: none of '{}' to '{}' exists (numbering starts at 0 to 4)",
                    self.path(*PATTERN_START_NUMBERS.start()).display(),
                    self.path(*PATTERN_START_NUMBERS.end()).display()
                ),
            ));
        };
        Ok((start..)
            .map(|n| self.path(n))
            .take_while(|p| p.is_file())
            .collect())
    }
}

/// Compares two names in natural order: runs of ASCII digits compare as the numbers they write (`frame2` <
/// `frame10`, however long the run), everything else byte by byte; names equal that way (`a01`, `a1`) compare as
/// plain strings, so that the order is total.
pub(crate) fn natural_cmp(a: &str, b: &str) -> Ordering {
    let (x, y) = (a.as_bytes(), b.as_bytes());
    let (mut i, mut j) = (0, 0);
    while i < x.len() && j < y.len() {
        if x[i].is_ascii_digit() && y[j].is_ascii_digit() {
            let ((nx, ex), (ny, ey)) = (digit_run(x, i), digit_run(y, j));
            let by_number = nx.len().cmp(&ny.len()).then_with(|| nx.cmp(ny));
            if by_number != Ordering::Equal {
                return by_number;
            }
            (i, j) = (ex, ey);
        } else {
            if x[i] != y[j] {
                return x[i].cmp(&y[j]);
            }
            i += 1;
            j += 1;
        }
    }
    (x.len() - i).cmp(&(y.len() - j)).then_with(|| a.cmp(b))
}

/// The digits of the run of ASCII digits starting at `from`, without leading zeros, and the index after the run.
fn digit_run(s: &[u8], from: usize) -> (&[u8], usize) {
    let end = from + s[from..].iter().take_while(|c| c.is_ascii_digit()).count();
    let start = from + s[from..end].iter().take_while(|&&c| c == b'0').count();
    (&s[start..end], end)
}

/// Reads a timestamps CSV: header naming `t` and optionally `file`, rows with strictly increasing finite times.
fn read_times_csv(path: &Path, is_video: bool) -> Result<Vec<TimeRow>, FormatError> {
    let what = "a timestamps CSV (t[,file])";
    let file = open_file(path, what, Some(MAX_TIMESTAMPS_FILE_BYTES))?;
    let mut reader = csv_reader(Limited::new(
        io::BufReader::new(file),
        what,
        Some(MAX_TIMESTAMPS_FILE_BYTES),
    ));
    let header = reader
        .headers()
        .map_err(|e| match e.into_kind() {
            csv::ErrorKind::Io(e) => crate::limits::read_error(path, e, Some(1)),
            other => {
                FormatError::new(path, format!("cannot read the header: {other:?}")).with_line(1)
            }
        })?
        .clone();
    let header_line = header.position().map_or(1, |p| p.line());
    if header.is_empty() || (header.len() == 1 && header[0].is_empty()) {
        return Err(FormatError::new(
            path,
            "empty file: expected a header line naming the column t (and optionally file)",
        ));
    }
    let mut columns: Vec<&'static str> = Vec::new();
    for name in &header {
        let column = match name {
            "t" => "t",
            "file" => "file",
            other => {
                return Err(FormatError::new(
                    path,
                    "unexpected column: the header names t (the frame times, s) and optionally file (the frames' \
                     file names), nothing else",
                )
                .with_line(header_line)
                .with_field(other));
            }
        };
        if columns.contains(&column) {
            return Err(FormatError::new(path, "column named twice")
                .with_line(header_line)
                .with_field(column));
        }
        columns.push(column);
    }
    let Some(t_column) = columns.iter().position(|&c| c == "t") else {
        return Err(FormatError::new(
            path,
            "missing column: the header must name t (the frame times, s), and optionally file",
        )
        .with_line(header_line)
        .with_field("t"));
    };
    let file_column = columns.iter().position(|&c| c == "file");
    if is_video && file_column.is_some() {
        return Err(FormatError::new(
            path,
            "a video's frames have no file names: leave out the column file for a video",
        )
        .with_line(header_line)
        .with_field("file"));
    }
    let mut rows = Vec::new();
    let mut previous: Option<(f64, u64)> = None;
    for_each_row(&mut reader, path, &columns, |row| {
        let t_s = row.finite(t_column)?;
        check_time_order(previous, t_s, true, path, row.line, "t")?;
        previous = Some((t_s, row.line));
        rows.push(TimeRow {
            t_s,
            line: row.line,
            file: file_column.map(|i| row.text(i).to_string()),
        });
        Ok(())
    })?;
    Ok(rows)
}

/// Checks a timestamps CSV against an image sequence: one row per frame, and the `file` column (if any) naming it.
fn check_rows_against_files(
    csv: &Path,
    rows: &[TimeRow],
    files: &[PathBuf],
) -> Result<(), FormatError> {
    for (index, (row, path)) in rows.iter().zip(files).enumerate() {
        if let Some(file) = &row.file {
            let name = file_name(path);
            if *file != name {
                return Err(FormatError::new(
                    csv,
                    format!("'{file}', but frame {index} is '{name}'"),
                )
                .with_line(row.line)
                .with_field("file"));
            }
        }
    }
    match rows.len().cmp(&files.len()) {
        Ordering::Less => Err(FormatError::new(
            csv,
            format!(
                "no row for frame {} ({}): {} rows for {} frames",
                rows.len(),
                file_name(&files[rows.len()]),
                rows.len(),
                files.len()
            ),
        )),
        Ordering::Greater => Err(FormatError::new(
            csv,
            format!("{} rows for {} frames", rows.len(), files.len()),
        )
        .with_line(rows[files.len()].line)),
        Ordering::Equal => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn natural_order_compares_digit_runs_as_numbers() {
        let mut names = vec![
            "frame10.png",
            "frame2.png",
            "frame1.png",
            "frame02.png",
            "frame.png",
            "frame100000000000000000000001.png",
            "frame99999999999999999999999.png",
            "a.png",
            "frame2b.png",
            "frame2a.png",
        ];
        names.sort_by(|a, b| natural_cmp(a, b));
        assert_eq!(
            names,
            [
                "a.png",
                "frame.png",
                "frame1.png",
                "frame02.png",
                "frame2.png",
                "frame2a.png",
                "frame2b.png",
                "frame10.png",
                "frame99999999999999999999999.png",
                "frame100000000000000000000001.png",
            ]
        );
        assert_eq!(natural_cmp("x_9_10", "x_9_9"), Ordering::Greater);
        assert_eq!(natural_cmp("x", "x"), Ordering::Equal);
        assert_eq!(natural_cmp("x1", "x1y"), Ordering::Less);
        assert_eq!(natural_cmp("0", "00"), "0".cmp("00"));
        assert_eq!(natural_cmp("é2", "é10"), Ordering::Less);
    }

    #[test]
    fn printf_patterns_are_recognised() {
        let p = PrintfPattern::parse("frames/frame_%05d.png")
            .unwrap()
            .unwrap();
        assert_eq!(p.path(12), PathBuf::from("frames/frame_00012.png"));
        let p = PrintfPattern::parse("f%d.png").unwrap().unwrap();
        assert_eq!(p.path(123), PathBuf::from("f123.png"));
        let p = PrintfPattern::parse("100%%/f%03d%%.png").unwrap().unwrap();
        assert_eq!(p.path(7), PathBuf::from("100%/f007%.png"));
        assert_eq!(PrintfPattern::parse("frames/*.png"), Ok(None));
        assert_eq!(PrintfPattern::parse("50%off/%5d.png"), Ok(None));
        assert!(PrintfPattern::parse("%d/%d.png").is_err());
    }

    #[test]
    fn a_single_image_suggests_a_pattern() {
        assert_eq!(
            pattern_of_name("frame_00012.png").as_deref(),
            Some("frame_%05d.png")
        );
        assert_eq!(pattern_of_name("f7.png").as_deref(), Some("f%d.png"));
        assert_eq!(pattern_of_name("x.png"), None);
        assert_eq!(
            pattern_of_name("run2_%_0010.tif").as_deref(),
            Some("run2_%%_%04d.tif")
        );
    }
}
