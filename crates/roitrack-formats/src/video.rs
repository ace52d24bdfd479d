//! Video files in, grey [`Frame`]s out, decoded by the `ffprobe` and `ffmpeg` programs of the `ffmpeg` package run as
//! child processes (no codec library is linked in: the system's FFmpeg reads every container and codec it knows).
//!
//! `ffprobe` first tells the size, the pixel format, the time base and (when the container says it, or by counting
//! packets without decoding) the number of frames. Then `ffmpeg` decodes the first video stream to raw grey pixels on
//! its standard output, every frame as it is (`-fps_mode passthrough`: none dropped or duplicated), read one frame of
//! exactly `width * height * bytes` at a time. When the video's own times are wanted, the same `ffmpeg` logs each
//! decoded frame's timestamp as its first filter (`showinfo`) receives it, and we read that log alongside the pixels:
//! the video is decoded once.

use std::ffi::{OsStr, OsString};
use std::fs::File;
use std::io::{self, BufRead, BufReader, Read};
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdout, Command, ExitStatus, Stdio};

use tempfile::NamedTempFile;

use roitrack_image::Frame;

use crate::FormatError;

/// File extensions read as videos (compared without regard to case).
pub(crate) const VIDEO_EXTENSIONS: &[&str] = &["mp4", "mkv", "avi", "mov", "webm", "m4v"];

/// What to tell a user who has no `ffmpeg`.
const INSTALL_HINT: &str = "videos are decoded by the ffmpeg and ffprobe programs: install the ffmpeg package \
     (Debian: apt-get install ffmpeg, or run scripts/setup-test-deps)";

/// At most this much of a program's error output goes into an error message (its end, where the cause usually is).
const MAX_STDERR_CHARS: usize = 2000;

/// The programs to run (their names are looked up on `PATH`); tests give names that do not exist.
#[derive(Debug, Clone)]
pub(crate) struct Tools {
    pub(crate) ffmpeg: OsString,
    pub(crate) ffprobe: OsString,
}

impl Default for Tools {
    fn default() -> Self {
        Self {
            ffmpeg: "ffmpeg".into(),
            ffprobe: "ffprobe".into(),
        }
    }
}

/// A running ffmpeg whose log (its error output) goes to a temporary file: unlike a pipe, the file never fills up, so
/// ffmpeg can never block on it while we read its standard output, and reading it needs no thread. We read the file
/// through a second handle of our own, with its own position, while ffmpeg writes it.
#[derive(Debug)]
struct Process {
    name: String,
    child: Child,
    log: Log,
    /// The log's file, named so that it can be opened a second time; removed when the process is dropped.
    _log_file: NamedTempFile,
}

impl Process {
    /// Starts `program args`, its standard output piped to us, its log to a temporary file.
    fn spawn(
        program: &OsStr,
        args: &[OsString],
        video: &Path,
    ) -> Result<(Self, ChildStdout), FormatError> {
        let name = program.to_string_lossy().into_owned();
        let file_error = |e| {
            FormatError::io(
                video,
                &format!("cannot create a temporary file for {name}'s messages"),
                e,
            )
        };
        let log_file = NamedTempFile::new().map_err(file_error)?;
        let reader = log_file.reopen().map_err(file_error)?;
        let log_for_child = log_file.as_file().try_clone().map_err(file_error)?;
        let mut child = Command::new(program)
            .args(args)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(log_for_child)
            .spawn()
            .map_err(|e| spawn_error(&name, video, e))?;
        let Some(stdout) = child.stdout.take() else {
            // Cannot happen with Stdio::piped(); still, no panic.
            let _ = child.kill();
            let _ = child.wait();
            return Err(FormatError::new(
                video,
                format!("{name} started without an output pipe"),
            ));
        };
        Ok((
            Self {
                name,
                child,
                log: Log::new(reader),
                _log_file: log_file,
            },
            stdout,
        ))
    }

    /// Waits for the program to end.
    fn wait(&mut self, video: &Path) -> Result<ExitStatus, FormatError> {
        self.child
            .wait()
            .map_err(|e| FormatError::io(video, &format!("cannot wait for {}", self.name), e))
    }

    /// The error messages of the log (its end, when long), trimmed, once the program has ended; with the number of
    /// frame times in the log not yet read.
    fn messages_at_end(&mut self) -> (String, usize) {
        let unread_times = self.log.read_to_end();
        (tail(&self.log.errors), unread_times)
    }
}

impl Drop for Process {
    /// Ends the program if it still runs and reaps it, so that no zombie process is left behind (also when the
    /// caller stops reading early or an error ends the stream).
    fn drop(&mut self) {
        if matches!(self.child.try_wait(), Ok(None)) {
            let _ = self.child.kill();
        }
        let _ = self.child.wait();
    }
}

/// The levels ffmpeg's `-loglevel level+...` writes in brackets before each message.
const LOG_LEVELS: &[&str] = &[
    "quiet", "panic", "fatal", "error", "warning", "info", "verbose", "debug", "trace",
];

/// The levels of the messages that are errors (what `-v error` shows).
const ERROR_LEVELS: &[&str] = &["panic", "fatal", "error"];

/// The name ffmpeg gives the first filter of `-vf`, when it is `showinfo`: it logs the frames' timestamps.
const TIME_FILTER: &str = "Parsed_showinfo_0";

/// One line of ffmpeg's log, written with `-loglevel level+...`: `[context @ 0x55...] [level] message`, the context
/// (nested contexts, or none) telling which part of ffmpeg speaks.
#[derive(Debug, PartialEq)]
enum LogLine {
    /// The time filter's line for a frame: its number (from 0) and its timestamp in the stream's time base (none
    /// when the video has none for it: `NOPTS`).
    Frame { number: u64, timestamp: Option<i64> },
    /// A line of the time filter that starts as a frame's but cannot be read (another format of another ffmpeg).
    UnreadableFrame(String),
    /// A message at an error level, as `-v error` would show it (without the level).
    Error(String),
    /// A message at another level.
    Other,
    /// A line without a level: the rest of the message before it, which had a line break in it.
    Continuation(String),
}

/// Reads one line of ffmpeg's log (its line break removed or not).
fn parse_log_line(line: &str) -> LogLine {
    let line = line.trim_end_matches(['\n', '\r']);
    let mut rest = line;
    let mut first_context: Option<&str> = None;
    while let Some(group) = rest.strip_prefix('[') {
        let Some(end) = group.find(']') else {
            break;
        };
        let name = &group[..end];
        let after = group[end + 1..]
            .strip_prefix(' ')
            .unwrap_or(&group[end + 1..]);
        if LOG_LEVELS.contains(&name) {
            let level_start = line.len() - rest.len();
            if ERROR_LEVELS.contains(&name) {
                return LogLine::Error(format!("{}{after}", &line[..level_start]));
            }
            if name == "info"
                && first_context == Some(TIME_FILTER)
                && let Some(numbers) = after.strip_prefix("n:")
            {
                return parse_frame_line(numbers)
                    .unwrap_or_else(|| LogLine::UnreadableFrame(after.to_string()));
            }
            return LogLine::Other;
        }
        match name.split_once(" @ ") {
            Some((context, _)) => {
                first_context.get_or_insert(context);
                rest = after;
            }
            None => break,
        }
    }
    LogLine::Continuation(line.to_string())
}

/// The frame number and timestamp of the time filter's line, after its `n:` (`   0 pts:  15360 pts_time:1 ...`).
fn parse_frame_line(text: &str) -> Option<LogLine> {
    let mut words = text.split_whitespace();
    let number = words.next()?.parse().ok()?;
    // `pts:` and its value are one word or two (`pts:      0`, or `pts:12345678` when the value fills the column).
    let value = match words.next()?.strip_prefix("pts:")? {
        "" => words.next()?,
        value => value,
    };
    let timestamp = match value {
        "NOPTS" => None,
        value => Some(value.parse().ok()?),
    };
    Some(LogLine::Frame { number, timestamp })
}

/// At most this many bytes of error messages are kept while reading a log (more than [`MAX_STDERR_CHARS`], which
/// the messages shown are cut to, so that the cut is at a character).
const MAX_KEPT_ERROR_BYTES: usize = 8 * MAX_STDERR_CHARS;

/// A frame line of the log: the frame's number and timestamp, or the text of a frame line that cannot be read.
type LoggedFrame = Result<(u64, Option<i64>), String>;

/// ffmpeg's log, read line by line as ffmpeg writes it.
#[derive(Debug)]
struct Log {
    reader: BufReader<File>,
    /// The line being read: ffmpeg may not have written its end yet.
    line: Vec<u8>,
    /// Whether the last message with a level was an error (its continuation lines are then part of it).
    in_error: bool,
    /// The error messages read so far, one a line (their end, when long).
    errors: String,
}

impl Log {
    fn new(file: File) -> Self {
        Self {
            reader: BufReader::new(file),
            line: Vec::new(),
            in_error: false,
            errors: String::new(),
        }
    }

    /// Reads the log up to the next frame line of the time filter, keeping the error messages on the way. `Ok(None)`
    /// when the log has no complete line left (for now, while ffmpeg runs); `Err` with the text of a frame line that
    /// cannot be read.
    fn next_frame(&mut self) -> io::Result<Option<LoggedFrame>> {
        loop {
            let n = self.reader.read_until(b'\n', &mut self.line)?;
            if n == 0 || self.line.last() != Some(&b'\n') {
                // The end of what ffmpeg has written so far: a part of a line waits for the rest.
                return Ok(None);
            }
            if let Some(frame) = self.take_line() {
                return Ok(Some(frame));
            }
        }
    }

    /// Reads the rest of the log, once ffmpeg has ended, keeping the error messages; returns how many frame lines
    /// were in it.
    fn read_to_end(&mut self) -> usize {
        let mut frames = 0;
        loop {
            match self.reader.read_until(b'\n', &mut self.line) {
                Ok(0) | Err(_) => break,
                Ok(_) => {
                    if self.take_line().is_some() {
                        frames += 1;
                    }
                }
            }
        }
        // A last line without a line break.
        if !self.line.is_empty() && self.take_line().is_some() {
            frames += 1;
        }
        frames
    }

    /// Reads the line in `self.line` (and empties it): the frame it tells of, if it is a frame line.
    fn take_line(&mut self) -> Option<LoggedFrame> {
        let line = String::from_utf8_lossy(&self.line).into_owned();
        self.line.clear();
        match parse_log_line(&line) {
            LogLine::Frame { number, timestamp } => {
                self.in_error = false;
                Some(Ok((number, timestamp)))
            }
            LogLine::UnreadableFrame(text) => {
                self.in_error = false;
                Some(Err(text))
            }
            LogLine::Error(text) => {
                self.in_error = true;
                self.push_error(&text);
                None
            }
            LogLine::Other => {
                self.in_error = false;
                None
            }
            LogLine::Continuation(text) => {
                if self.in_error {
                    self.push_error(&text);
                }
                None
            }
        }
    }

    fn push_error(&mut self, text: &str) {
        if !self.errors.is_empty() {
            self.errors.push('\n');
        }
        self.errors.push_str(text);
        if self.errors.len() > MAX_KEPT_ERROR_BYTES {
            let mut cut = self.errors.len() - MAX_KEPT_ERROR_BYTES / 2;
            while !self.errors.is_char_boundary(cut) {
                cut += 1;
            }
            self.errors.drain(..cut);
        }
    }
}

/// The last [`MAX_STDERR_CHARS`] characters of `text`, trimmed.
fn tail(text: &str) -> String {
    let text = text.trim();
    let count = text.chars().count();
    if count <= MAX_STDERR_CHARS {
        return text.to_string();
    }
    let start = text
        .char_indices()
        .nth(count - MAX_STDERR_CHARS)
        .map_or(0, |(i, _)| i);
    format!("...{}", &text[start..])
}

fn spawn_error(name: &str, video: &Path, error: io::Error) -> FormatError {
    if error.kind() == io::ErrorKind::NotFound {
        FormatError::new(
            video,
            format!("cannot run {name}: it is not installed (or not on PATH); {INSTALL_HINT}"),
        )
    } else {
        FormatError::io(video, &format!("cannot run {name}"), error)
    }
}

/// `text` with the program's messages appended, when it printed any.
fn with_messages(text: String, name: &str, messages: &str) -> String {
    if messages.is_empty() {
        text
    } else {
        format!("{text}; {name} says: {messages}")
    }
}

/// The input argument for `video`: through the `file:` protocol, so that a name with a colon (`a:b.mp4`) or one
/// starting with a dash is never taken for a protocol or an option.
fn input_arg(video: &Path) -> OsString {
    let mut arg = OsString::from("file:");
    arg.push(video.as_os_str());
    arg
}

/// Runs `program args` to its end and returns its standard output and its messages, or an error with its messages.
fn run(program: &OsStr, args: &[OsString], video: &Path) -> Result<(String, String), FormatError> {
    let name = program.to_string_lossy();
    let output = Command::new(program)
        .args(args)
        .stdin(Stdio::null())
        .output()
        .map_err(|e| spawn_error(&name, video, e))?;
    if !output.status.success() {
        let messages = tail(&String::from_utf8_lossy(&output.stderr));
        return Err(FormatError::new(
            video,
            with_messages(
                format!("{name} cannot read the video ({})", output.status),
                &name,
                &messages,
            ),
        ));
    }
    Ok((
        String::from_utf8_lossy(&output.stdout).into_owned(),
        tail(&String::from_utf8_lossy(&output.stderr)),
    ))
}

fn os_args(args: &[&str]) -> Vec<OsString> {
    args.iter().map(OsString::from).collect()
}

/// The value of `key=value` among `ffprobe -of default` lines, unless absent or `N/A`.
fn value<'a>(text: &'a str, key: &str) -> Option<&'a str> {
    text.lines()
        .filter_map(|line| line.trim().split_once('='))
        .find(|(k, _)| *k == key)
        .map(|(_, v)| v)
        .filter(|v| !v.is_empty() && *v != "N/A")
}

/// What `ffprobe` says of the first video stream.
#[derive(Debug, Clone, PartialEq)]
struct StreamInfo {
    width: u32,
    height: u32,
    pix_fmt: String,
    /// Seconds per timestamp unit, as a fraction (numerator, denominator).
    time_base: (i64, i64),
    bits_per_raw_sample: Option<u32>,
    nb_frames: Option<usize>,
}

/// The stream's description from ffprobe's output `text`; `messages` (ffprobe's) go into the errors.
fn parse_stream_info(text: &str, messages: &str, video: &Path) -> Result<StreamInfo, FormatError> {
    let error =
        |m: &str| FormatError::new(video, with_messages(m.to_string(), "ffprobe", messages));
    let (Some(width), Some(height)) = (value(text, "width"), value(text, "height")) else {
        return Err(error("no video stream in this file (ffprobe finds none)"));
    };
    let size = |v: &str, what: &str| {
        v.parse::<u32>()
            .ok()
            .filter(|&n| n > 0)
            .ok_or_else(|| error(&format!("ffprobe gives the {what} as {v:?}")))
    };
    let (width, height) = (size(width, "width")?, size(height, "height")?);
    let pix_fmt = match value(text, "pix_fmt") {
        Some(p) if p != "unknown" => p.to_string(),
        _ => {
            return Err(error(
                "ffprobe cannot tell the video's pixel format (a truncated or damaged file?)",
            ));
        }
    };
    let time_base = value(text, "time_base")
        .and_then(|tb| tb.split_once('/'))
        .and_then(|(n, d)| Some((n.parse::<i64>().ok()?, d.parse::<i64>().ok()?)))
        .filter(|&(n, d)| n > 0 && d > 0)
        .unwrap_or((0, 1));
    Ok(StreamInfo {
        width,
        height,
        pix_fmt,
        time_base,
        bits_per_raw_sample: value(text, "bits_per_raw_sample").and_then(|v| v.parse().ok()),
        nb_frames: value(text, "nb_frames").and_then(|v| v.parse().ok()),
    })
}

/// What `ffprobe -show_entries stream=... -show_pixel_formats -of default` prints, by section: the stream's
/// `key=value` lines, and each pixel format's name with the depths (bits) of its components.
#[derive(Debug, Default, PartialEq)]
struct Probe {
    /// The lines of the `[STREAM]` section (empty when the file has no video stream).
    stream: String,
    /// Each `[PIXEL_FORMAT]` section's name and its `[COMPONENT]` sections' `bit_depth`s, in the order printed.
    pixel_formats: Vec<(String, Vec<u32>)>,
}

impl Probe {
    fn parse(text: &str) -> Self {
        let mut probe = Self::default();
        // The top-level section being read, if any.
        let mut section: Option<&str> = None;
        for line in text.lines().map(str::trim) {
            match (section, line) {
                (None, "[STREAM]") => section = Some("STREAM"),
                (None, "[PIXEL_FORMAT]") => {
                    section = Some("PIXEL_FORMAT");
                    probe.pixel_formats.push((String::new(), Vec::new()));
                }
                (Some("STREAM"), "[/STREAM]") | (Some("PIXEL_FORMAT"), "[/PIXEL_FORMAT]") => {
                    section = None;
                }
                (Some("STREAM"), line) => {
                    probe.stream.push_str(line);
                    probe.stream.push('\n');
                }
                (Some(_), line) => {
                    let Some((name, depths)) = probe.pixel_formats.last_mut() else {
                        continue;
                    };
                    match line.split_once('=') {
                        Some(("name", value)) => *name = value.to_string(),
                        Some(("bit_depth", value)) => depths.extend(value.parse::<u32>().ok()),
                        _ => {}
                    }
                }
                (None, _) => {}
            }
        }
        probe
    }

    /// The deepest component of `pix_fmt` (bits), if the table has it with components.
    fn bit_depth(&self, pix_fmt: &str) -> Option<u32> {
        self.pixel_formats
            .iter()
            .find(|(name, _)| name == pix_fmt)
            .and_then(|(_, depths)| depths.iter().copied().max())
    }
}

/// A video being decoded frame by frame.
#[derive(Debug)]
pub(crate) struct VideoDecoder {
    path: PathBuf,
    width: u32,
    height: u32,
    /// 8 (ffmpeg writes `gray`, one byte a pixel) or 16 (`gray16le`, two bytes).
    bit_depth: u8,
    time_base: (i64, i64),
    frame_count: Option<usize>,
    // The pipe is declared before its process so that it is closed first when dropped.
    pixels: ChildStdout,
    ffmpeg: Process,
    /// Whether ffmpeg logs the frames' times (they are wanted).
    times: bool,
    bytes: Vec<u8>,
    decoded: usize,
}

impl VideoDecoder {
    /// Probes `video` and starts decoding it; `want_times` also starts listing the video's own frame times.
    pub(crate) fn open(video: &Path, tools: &Tools, want_times: bool) -> Result<Self, FormatError> {
        let mut args = os_args(&[
            "-v",
            "error",
            "-select_streams",
            // V, not v: a video stream that is not an attached picture (cover art).
            "V:0",
            "-show_entries",
            "stream=width,height,pix_fmt,time_base,bits_per_raw_sample,nb_frames",
            // And FFmpeg's table of pixel formats, for the depth of the stream's: one program started instead of
            // two (`ffmpeg -pix_fmts` gave it before, for 0.06 s of CPU, mostly loading FFmpeg's libraries).
            "-show_pixel_formats",
            // Each section between its `[NAME]` and `[/NAME]` lines, to tell the stream's keys from the formats'.
            "-of",
            "default",
            "-i",
        ]);
        args.push(input_arg(video));
        let (text, messages) = run(&tools.ffprobe, &args, video)?;
        let probe = Probe::parse(&text);
        let info = parse_stream_info(&probe.stream, &messages, video)?;

        let source_bits = probe
            .bit_depth(&info.pix_fmt)
            .or(info.bits_per_raw_sample)
            .unwrap_or(8);
        let (bit_depth, out_pix_fmt) = if source_bits > 8 {
            (16, "gray16le")
        } else {
            (8, "gray")
        };
        let frame_count = match info.nb_frames {
            Some(n) => Some(n),
            // Matroska and WebM do not store the count: count the packets, which reads the file but decodes nothing.
            None => count_packets(video, tools),
        };

        if want_times && info.time_base.0 == 0 {
            return Err(FormatError::new(
                video,
                "ffprobe gives no time base for the video's timestamps: give --fps F or --timestamps FILE.csv",
            ));
        }
        let mut args = os_args(&[
            "-nostdin",
            "-hide_banner",
            "-nostats",
            // Each message with its level in brackets, so that the errors can be told from the frame times (which
            // showinfo logs as information); every message, even one that repeats the one before.
            "-loglevel",
            if want_times {
                "repeat+level+info"
            } else {
                "repeat+level+error"
            },
            // The pixels as stored: a camera's calibration is of its sensor, not of a player's rotated view (and the
            // size stays the one ffprobe said).
            "-noautorotate",
        ]);
        if want_times {
            // The timestamps as the file has them: without this, ffmpeg shifts them to start at 0.
            args.push("-copyts".into());
        }
        args.push("-i".into());
        args.push(input_arg(video));
        args.extend(os_args(&[
            "-map",
            "0:V:0",
            "-fps_mode",
            "passthrough",
            "-vf",
            // showinfo (first, so that it sees the frames as decoded) logs each frame's number and timestamp: the
            // decoder's best_effort_timestamp, which ffmpeg gives the frame, in the stream's time base (what
            // `ffprobe -show_entries frame=best_effort_timestamp` lists, without a second decoding). Its checksums
            // are not needed. The raw output's own timestamps are never used (the times come from that log, a CSV
            // or --fps); numbering the frames 0, 1, 2... in seconds keeps them increasing, so that a video whose
            // timestamps repeat (ours then reports it) does not make the muxer complain, which would read as a
            // decoding error.
            if want_times {
                "showinfo=checksum=0,settb=1,setpts=N"
            } else {
                "settb=1,setpts=N"
            },
            "-f",
            "rawvideo",
            "-pix_fmt",
            out_pix_fmt,
            "-",
        ]));
        let (ffmpeg, pixels) = Process::spawn(&tools.ffmpeg, &args, video)?;
        let bytes_per_value = if bit_depth > 8 { 2 } else { 1 };
        enlarge_pipe(
            &pixels,
            info.width as usize * info.height as usize * bytes_per_value,
        );
        Ok(Self {
            path: video.to_path_buf(),
            width: info.width,
            height: info.height,
            bit_depth,
            time_base: info.time_base,
            frame_count,
            pixels,
            ffmpeg,
            times: want_times,
            bytes: Vec::new(),
            decoded: 0,
        })
    }

    /// The number of frames the container announces (or that its packets count), if known.
    pub(crate) fn frame_count(&self) -> Option<usize> {
        self.frame_count
    }

    /// Decodes the next frame into `frame`; with the video's own time (s) when times were wanted. `Ok(None)` at the
    /// end of a video that ffmpeg decoded without error.
    pub(crate) fn next(&mut self, frame: &mut Frame) -> Result<Option<Option<f64>>, FormatError> {
        let index = self.decoded;
        let bytes_per_value = if self.bit_depth > 8 { 2 } else { 1 };
        let size = self.width as usize * self.height as usize * bytes_per_value;
        self.bytes.resize(size, 0);
        let got = read_full(&mut self.pixels, &mut self.bytes)
            .map_err(|e| FormatError::io(&self.path, "cannot read the frames ffmpeg decodes", e))?;
        if got == 0 {
            self.finish()?;
            return Ok(None);
        }
        if got < size {
            let _ = self.ffmpeg.wait(&self.path);
            let (messages, _) = self.ffmpeg.messages_at_end();
            return Err(FormatError::new(
                &self.path,
                with_messages(
                    format!(
                        "frame {index}: the video is truncated: ffmpeg gave {got} of the frame's {size} bytes"
                    ),
                    "ffmpeg",
                    &messages,
                ),
            ));
        }
        frame.resize(self.width, self.height, self.bit_depth);
        if bytes_per_value == 1 {
            for (p, &b) in frame.pixels.iter_mut().zip(&self.bytes) {
                *p = u16::from(b);
            }
        } else {
            for (p, b) in frame.pixels.iter_mut().zip(self.bytes.chunks_exact(2)) {
                *p = u16::from_le_bytes([b[0], b[1]]);
            }
        }
        self.decoded += 1;
        if !self.times {
            return Ok(Some(None));
        }
        Ok(Some(Some(self.time_of(index)?)))
    }

    /// The time (s) of frame `index`, which ffmpeg has just output, from ffmpeg's log.
    ///
    /// ffmpeg logs a frame's line (its showinfo filter) before the frame goes on to the output, so once a frame's
    /// pixels are read its line is in the log: this never waits, and a line that is not there is an error at once.
    fn time_of(&mut self, index: usize) -> Result<f64, FormatError> {
        let logged = self.ffmpeg.log.next_frame().map_err(|e| {
            FormatError::io(&self.path, "cannot read ffmpeg's log of the frame times", e)
        })?;
        let fallback = "give --fps F or --timestamps FILE.csv";
        let problem = match logged {
            Some(Ok((number, Some(timestamp)))) if number == index as u64 => {
                let (num, den) = self.time_base;
                // Exact product in integers, one rounding in the division.
                return Ok((i128::from(timestamp) * i128::from(num)) as f64 / den as f64);
            }
            Some(Ok((number, None))) if number == index as u64 => {
                format!("frame {index} has no timestamp in the video: {fallback}")
            }
            Some(Ok((number, _))) => format!(
                "frame {index}: ffmpeg's log gives the time of its frame {number} instead (does the video change \
                 size or format midway?): {fallback}"
            ),
            Some(Err(text)) => format!(
                "frame {index}: cannot read its time in ffmpeg's log (showinfo says {text:?}): {fallback}"
            ),
            None => format!(
                "frame {index}: ffmpeg outputs it, but its log gives no time for it: {fallback}"
            ),
        };
        Err(FormatError::new(&self.path, problem))
    }

    /// At the end of ffmpeg's output: checks that ffmpeg succeeded without complaint and that its log has no more
    /// frame times than it output frames.
    fn finish(&mut self) -> Result<(), FormatError> {
        let decoded = self.decoded;
        let status = self.ffmpeg.wait(&self.path)?;
        let (messages, unread_times) = self.ffmpeg.messages_at_end();
        if !status.success() {
            return Err(FormatError::new(
                &self.path,
                with_messages(
                    format!("ffmpeg failed ({status}) after {decoded} frames"),
                    "ffmpeg",
                    &messages,
                ),
            ));
        }
        if decoded == 0 {
            return Err(FormatError::new(
                &self.path,
                with_messages(
                    "ffmpeg decodes no frame from this video".to_string(),
                    "ffmpeg",
                    &messages,
                ),
            ));
        }
        // Any error message is an error: a truncated file ("File ended prematurely") or damaged frames still end
        // with exit status 0 and the frames before the damage.
        if !messages.is_empty() {
            return Err(FormatError::new(
                &self.path,
                format!(
                    "ffmpeg reports errors after decoding {decoded} frames (a truncated or damaged video?): {messages}"
                ),
            ));
        }
        if unread_times > 0 {
            return Err(FormatError::new(
                &self.path,
                format!(
                    "ffmpeg logs the times of {} frames but outputs {decoded}",
                    decoded + unread_times
                ),
            ));
        }
        Ok(())
    }
}

/// The number of video packets, read without decoding, if ffprobe can tell.
fn count_packets(video: &Path, tools: &Tools) -> Option<usize> {
    let mut args = os_args(&[
        "-v",
        "error",
        "-select_streams",
        "V:0",
        "-count_packets",
        "-show_entries",
        "stream=nb_read_packets",
        "-of",
        "default=nw=1",
        "-i",
    ]);
    args.push(input_arg(video));
    let (text, _) = run(&tools.ffprobe, &args, video).ok()?;
    value(&text, "nb_read_packets")?.parse().ok()
}

/// Linux's default pipe capacity.
const DEFAULT_PIPE_BYTES: usize = 1 << 16;
/// Pipes larger than this are not asked for: Linux's limit for a user (`/proc/sys/fs/pipe-max-size`) by default.
const MAX_PIPE_BYTES: usize = 1 << 20;

/// Asks for `pipe` to hold a frame of `frame_bytes` (at most [`MAX_PIPE_BYTES`]) instead of Linux's default 64 KiB
/// (never less than that): a frame then goes through in one or a few writes, and ffmpeg no longer waits, spinning on
/// the pipe's lock, while we read each 64 KiB, which took its system time down to about that of decoding to /dev/null
/// (measured in docs/results.md, "Whole-frame detection speed"). Nothing changes when the system refuses, or off Linux.
fn enlarge_pipe(pipe: &ChildStdout, frame_bytes: usize) {
    #[cfg(target_os = "linux")]
    {
        use std::os::fd::AsRawFd;
        let Ok(size) = libc::c_int::try_from(frame_bytes.clamp(DEFAULT_PIPE_BYTES, MAX_PIPE_BYTES))
        else {
            return;
        };
        // SAFETY: F_SETPIPE_SZ on a pipe's open descriptor, which `pipe` owns for the call; it changes only the
        // pipe's capacity, and its failure (-1) is ignored.
        let _ = unsafe { libc::fcntl(pipe.as_raw_fd(), libc::F_SETPIPE_SZ, size) };
    }
    #[cfg(not(target_os = "linux"))]
    let _ = (pipe, frame_bytes);
}

/// Reads until `buffer` is full or the input ends; returns the number of bytes read.
fn read_full(reader: &mut impl Read, buffer: &mut [u8]) -> io::Result<usize> {
    let mut filled = 0;
    while filled < buffer.len() {
        match reader.read(&mut buffer[filled..]) {
            Ok(0) => break,
            Ok(n) => filled += n,
            Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(filled)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stream_info_is_parsed_from_ffprobe_key_value_lines() {
        let text = "width=64\nheight=48\npix_fmt=yuv420p10le\ntime_base=1/12800\nbits_per_raw_sample=10\n\
                    nb_frames=N/A\n";
        let info = parse_stream_info(text, "", Path::new("v.mkv")).unwrap();
        assert_eq!(
            info,
            StreamInfo {
                width: 64,
                height: 48,
                pix_fmt: "yuv420p10le".into(),
                time_base: (1, 12800),
                bits_per_raw_sample: Some(10),
                nb_frames: None,
            }
        );
        let e = parse_stream_info("", "", Path::new("v.mkv")).unwrap_err();
        assert!(e.to_string().starts_with("v.mkv: no video stream"), "{e}");
        let e = parse_stream_info(
            "width=64\nheight=48\npix_fmt=unknown\n",
            "oops",
            Path::new("v.mkv"),
        )
        .unwrap_err();
        assert!(e.to_string().contains("pixel format"), "{e}");
        assert!(e.to_string().ends_with("; ffprobe says: oops"), "{e}");
        let e = parse_stream_info("width=0\nheight=48\npix_fmt=gray\n", "", Path::new("v.mkv"))
            .unwrap_err();
        assert!(e.to_string().contains("width"), "{e}");
    }

    #[test]
    fn bit_depth_comes_from_the_pixel_format_table() {
        // ffprobe 5.1's sections, shortened.
        let text = "[PIXEL_FORMAT]\nname=yuv420p\nnb_components=3\nbits_per_pixel=12\nFLAGS:planar=1\n\
                    [COMPONENT]\nindex=1\nbit_depth=8\n[/COMPONENT]\n[COMPONENT]\nindex=2\nbit_depth=8\n[/COMPONENT]\n\
                    [/PIXEL_FORMAT]\n\
                    [PIXEL_FORMAT]\nname=yuv420p10le\nnb_components=3\n[COMPONENT]\nindex=1\nbit_depth=10\n\
                    [/COMPONENT]\n[/PIXEL_FORMAT]\n\
                    [PIXEL_FORMAT]\nname=vaapi\nnb_components=0\nbits_per_pixel=0\n[/PIXEL_FORMAT]\n\
                    [PIXEL_FORMAT]\nname=gray16le\nnb_components=1\n[COMPONENT]\nindex=1\nbit_depth=16\n\
                    [/COMPONENT]\n[/PIXEL_FORMAT]\n\
                    [STREAM]\nwidth=640\nheight=480\npix_fmt=yuv420p\ntime_base=1/15360\nnb_frames=300\n[/STREAM]\n";
        let probe = Probe::parse(text);
        assert_eq!(probe.bit_depth("yuv420p"), Some(8));
        assert_eq!(probe.bit_depth("yuv420p10le"), Some(10));
        assert_eq!(probe.bit_depth("gray16le"), Some(16));
        assert_eq!(probe.bit_depth("yuv420p1"), None);
        // A format without components (a hardware surface) has no depth.
        assert_eq!(probe.bit_depth("vaapi"), None);
        assert_eq!(
            probe.stream,
            "width=640\nheight=480\npix_fmt=yuv420p\ntime_base=1/15360\nnb_frames=300\n"
        );
        let info = parse_stream_info(&probe.stream, "", Path::new("v.mp4")).unwrap();
        assert_eq!((info.width, info.pix_fmt.as_str()), (640, "yuv420p"));
        // No stream section: no stream.
        let probe = Probe::parse("garbage\nname=gray\nbit_depth=8\n");
        assert_eq!(probe, Probe::default());
        assert_eq!(probe.bit_depth("gray"), None);
    }

    #[test]
    fn log_lines_are_told_apart() {
        let frame = |number, timestamp| LogLine::Frame { number, timestamp };
        assert_eq!(
            parse_log_line(
                "[Parsed_showinfo_0 @ 0x564dd01d8480] [info] n:   0 pts:      0 pts_time:0       pos:       48 \
                 fmt:yuv420p sar:1/1 s:320x240 i:P iskey:1 type:I \n"
            ),
            frame(0, Some(0))
        );
        // A value that fills its column, a negative one, none.
        assert_eq!(
            parse_log_line("[Parsed_showinfo_0 @ 0x1] [info] n:1234 pts:12345678 pts_time:803.7\n"),
            frame(1234, Some(12_345_678))
        );
        assert_eq!(
            parse_log_line("[Parsed_showinfo_0 @ 0x1] [info] n:   3 pts:  -1024 pts_time:-0.08"),
            frame(3, Some(-1024))
        );
        assert_eq!(
            parse_log_line("[Parsed_showinfo_0 @ 0x1] [info] n:   3 pts:  NOPTS pts_time:NOPTS"),
            frame(3, None)
        );
        assert_eq!(
            parse_log_line("[Parsed_showinfo_0 @ 0x1] [info] n:   3 time:  1024"),
            LogLine::UnreadableFrame("n:   3 time:  1024".into())
        );
        // The filter's other lines, and another filter's.
        for line in [
            "[Parsed_showinfo_0 @ 0x1] [info] config in time_base: 1/15360, frame_rate: 30/1",
            "[Parsed_showinfo_0 @ 0x1] [info] color_range:unknown color_space:unknown",
            "[Parsed_showinfo_1 @ 0x1] [info] n:   0 pts:      0",
            "[Parsed_showinfo_0 @ 0x1] [warning] n:   0 pts:      0",
            "[info] Input #0, mov,mp4,m4a,3gp,3g2,mj2, from 'file:n: 0 pts: 0.mp4':",
        ] {
            assert_eq!(parse_log_line(line), LogLine::Other, "{line}");
        }
        // Errors as `-v error` shows them, from nested contexts or none.
        assert_eq!(
            parse_log_line(
                "[mov,mp4,m4a,3gp,3g2,mj2 @ 0x5] [error] stream 0, offset 0x30: partial file\n"
            ),
            LogLine::Error(
                "[mov,mp4,m4a,3gp,3g2,mj2 @ 0x5] stream 0, offset 0x30: partial file".into()
            )
        );
        assert_eq!(
            parse_log_line("[fatal] Conversion failed!"),
            LogLine::Error("Conversion failed!".into())
        );
        assert_eq!(
            parse_log_line("[a @ 0x1] [h264 @ 0x2] [panic] Assertion failed"),
            LogLine::Error("[a @ 0x1] [h264 @ 0x2] Assertion failed".into())
        );
        for line in ["    vendor_id [0][0][0][0]", "[0][0] more", ""] {
            assert_eq!(
                parse_log_line(line),
                LogLine::Continuation(line.into()),
                "{line}"
            );
        }
    }

    #[test]
    fn the_log_is_read_as_it_grows_and_keeps_the_errors() {
        let mut file = tempfile::NamedTempFile::new().unwrap();
        let mut log = Log::new(file.reopen().unwrap());
        let mut write = |text: &str| {
            use std::io::Write;
            file.write_all(text.as_bytes()).unwrap();
            file.flush().unwrap();
        };
        write(
            "[info] Stream mapping:\n[h264 @ 0x1] [error] bad slice\n  at 3\n[Parsed_showinfo_0 @ 0x2] [info] n:",
        );
        // The frame line is not complete yet.
        assert_eq!(log.next_frame().unwrap(), None);
        write("   0 pts:   512 pts_time:0.03\n[Parsed_showinfo_0 @ 0x2] [info] color_range:tv\n");
        assert_eq!(log.next_frame().unwrap(), Some(Ok((0, Some(512)))));
        assert_eq!(log.next_frame().unwrap(), None);
        write("[Parsed_showinfo_0 @ 0x2] [info] n:   1 pts:  NOPTS\n  continued\n[error] last");
        assert_eq!(log.next_frame().unwrap(), Some(Ok((1, None))));
        // At the end: the last line even without its line break; one frame line left unread.
        write("\n[Parsed_showinfo_0 @ 0x2] [info] n:   2 pts:  1024\n[error] really last");
        assert_eq!(log.read_to_end(), 1);
        assert_eq!(
            log.errors,
            "[h264 @ 0x1] bad slice\n  at 3\nlast\nreally last"
        );

        // Many errors: the last ones are kept, cut at a character.
        let mut log = Log::new(tempfile::tempfile().unwrap());
        for i in 0..2000 {
            log.push_error(&format!("é{i}"));
        }
        assert!(log.errors.len() <= MAX_KEPT_ERROR_BYTES);
        assert!(
            log.errors.ends_with("\né1999"),
            "{}",
            &log.errors[log.errors.len() - 20..]
        );
    }

    #[test]
    fn long_messages_keep_their_end() {
        let long = format!("{}the cause", "x".repeat(5000));
        let t = tail(&long);
        assert!(t.starts_with("...") && t.ends_with("the cause"));
        assert_eq!(t.chars().count(), MAX_STDERR_CHARS + 3);
        assert_eq!(tail("  short\n"), "short");
    }

    #[test]
    fn missing_ffmpeg_says_to_install_it() {
        let tools = Tools {
            ffmpeg: "roitrack-no-such-ffmpeg".into(),
            ffprobe: "roitrack-no-such-ffprobe".into(),
        };
        let e = VideoDecoder::open(Path::new("clip.mp4"), &tools, true).unwrap_err();
        let text = e.to_string();
        assert!(
            text.starts_with("clip.mp4: cannot run roitrack-no-such-ffprobe: it is not installed"),
            "{text}"
        );
        assert!(text.contains("apt-get install ffmpeg"), "{text}");
        assert!(text.contains("scripts/setup-test-deps"), "{text}");
    }
}
