//! Video files in, grey [`Frame`]s out, decoded by the `ffprobe` and `ffmpeg` programs of the `ffmpeg` package run as
//! child processes (no codec library is linked in: the system's FFmpeg reads every container and codec it knows).
//!
//! `ffprobe` first tells the size, the pixel format, the time base and (when the container says it, or by counting
//! packets without decoding) the number of frames. Then `ffmpeg` decodes the first video stream to raw grey pixels on
//! its standard output, every frame as it is (`-fps_mode passthrough`: none dropped or duplicated), read one frame of
//! exactly `width * height * bytes` at a time. When the video's own times are wanted, a second `ffprobe` lists each
//! decoded frame's timestamp alongside, read one line per frame.

use std::ffi::{OsStr, OsString};
use std::fs::File;
use std::io::{self, BufRead, BufReader, Read, Seek};
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdout, Command, ExitStatus, Stdio};

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

/// A running program whose error output goes to an unnamed temporary file: unlike a pipe, the file never fills up, so
/// the program can never block on it while we read its standard output, and it needs no thread.
#[derive(Debug)]
struct Process {
    name: String,
    child: Child,
    stderr: File,
}

impl Process {
    /// Starts `program args`, its standard output piped to us.
    fn spawn(
        program: &OsStr,
        args: &[OsString],
        video: &Path,
    ) -> Result<(Self, ChildStdout), FormatError> {
        let name = program.to_string_lossy().into_owned();
        let stderr = tempfile::tempfile().map_err(|e| {
            FormatError::io(
                video,
                &format!("cannot create a temporary file for {name}'s messages"),
                e,
            )
        })?;
        let stderr_for_child = stderr
            .try_clone()
            .map_err(|e| FormatError::io(video, "cannot duplicate a file handle", e))?;
        let mut child = Command::new(program)
            .args(args)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(stderr_for_child)
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
                stderr,
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

    /// What the program wrote to its error output so far (its end, when long), trimmed.
    fn stderr_text(&mut self) -> String {
        let mut bytes = Vec::new();
        if self.stderr.rewind().is_err() || self.stderr.read_to_end(&mut bytes).is_err() {
            return String::new();
        }
        tail(&String::from_utf8_lossy(&bytes))
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

/// The value of `key=value` among `ffprobe -of default=nw=1` lines, unless absent or `N/A`.
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

/// The deepest component of `pix_fmt` (bits) from `ffmpeg -pix_fmts`'s table
/// (`FLAGS NAME NB_COMPONENTS BITS_PER_PIXEL BIT_DEPTHS`, e.g. `IO... yuv420p10le 3 15 10-10-10`).
fn bit_depth_from_table(table: &str, pix_fmt: &str) -> Option<u32> {
    table.lines().find_map(|line| {
        let fields: Vec<&str> = line.split_whitespace().collect();
        if fields.len() < 5 || fields[1] != pix_fmt {
            return None;
        }
        fields[4]
            .split('-')
            .map(|d| d.parse::<u32>().ok())
            .collect::<Option<Vec<u32>>>()?
            .into_iter()
            .max()
    })
}

/// One frame time read from the lister, in timestamp units, or none when the video has none for that frame.
fn parse_timestamp_line(line: &str) -> Option<Option<i64>> {
    let v = line.trim().strip_prefix("best_effort_timestamp=")?;
    Some(v.parse::<i64>().ok())
}

/// The video's own frame times, listed by a second `ffprobe` as it decodes, one line per frame.
///
/// Why decoded frames' `best_effort_timestamp` and not packets sorted by their pts: with B-frames, packets come in
/// decoding order and a decoder may drop some, hold others back, or (edit lists, open GOPs) emit a different number
/// of frames than there are packets; a packet list re-sorted by pts is only usually right. `best_effort_timestamp` is
/// the time the decoder gives each frame it outputs, in output order, and is the very timestamp `ffmpeg` itself gives
/// a decoded frame: with `-fps_mode passthrough` the n-th line is the time of the n-th frame on ffmpeg's pipe. The
/// cost is a second decoding, run alongside ffmpeg's (so it adds no wait before the first frame), not before it.
#[derive(Debug)]
struct TimeLister {
    process: Process,
    lines: BufReader<ChildStdout>,
    line: String,
}

impl TimeLister {
    /// The next listed frame's timestamp: `Ok(None)` when ffprobe's list has ended.
    fn next(&mut self, video: &Path) -> Result<Option<Option<i64>>, FormatError> {
        loop {
            self.line.clear();
            let n = self.lines.read_line(&mut self.line).map_err(|e| {
                FormatError::io(video, "cannot read the frame times from ffprobe", e)
            })?;
            if n == 0 {
                return Ok(None);
            }
            if let Some(timestamp) = parse_timestamp_line(&self.line) {
                return Ok(Some(timestamp));
            }
        }
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
    times: Option<TimeLister>,
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
            "-of",
            "default=nw=1",
            "-i",
        ]);
        args.push(input_arg(video));
        let (text, messages) = run(&tools.ffprobe, &args, video)?;
        let info = parse_stream_info(&text, &messages, video)?;

        let source_bits = run(
            &tools.ffmpeg,
            &os_args(&["-hide_banner", "-pix_fmts"]),
            video,
        )
        .ok()
        .and_then(|(table, _)| bit_depth_from_table(&table, &info.pix_fmt))
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

        let mut args = os_args(&[
            "-nostdin",
            "-hide_banner",
            "-v",
            "error",
            // The pixels as stored: a camera's calibration is of its sensor, not of a player's rotated view (and the
            // size stays the one ffprobe said).
            "-noautorotate",
            "-i",
        ]);
        args.push(input_arg(video));
        args.extend(os_args(&[
            "-map",
            "0:V:0",
            "-fps_mode",
            "passthrough",
            // The raw output's own timestamps are never used (the times come from ffprobe, a CSV or --fps); numbering
            // the frames 0, 1, 2... in seconds keeps them increasing, so that a video whose timestamps repeat (ours
            // then reports it) does not make the muxer complain, which would read as a decoding error.
            "-vf",
            "settb=1,setpts=N",
            "-f",
            "rawvideo",
            "-pix_fmt",
            out_pix_fmt,
            "-",
        ]));
        let times = if want_times {
            if info.time_base.0 == 0 {
                return Err(FormatError::new(
                    video,
                    "ffprobe gives no time base for the video's timestamps: give --fps F or --timestamps FILE.csv",
                ));
            }
            let mut args = os_args(&[
                "-v",
                "error",
                "-select_streams",
                "V:0",
                "-show_entries",
                "frame=best_effort_timestamp",
                "-of",
                "default=nw=1",
                "-i",
            ]);
            args.push(input_arg(video));
            let (process, stdout) = Process::spawn(&tools.ffprobe, &args, video)?;
            Some(TimeLister {
                process,
                lines: BufReader::new(stdout),
                line: String::new(),
            })
        } else {
            None
        };
        let (ffmpeg, pixels) = Process::spawn(&tools.ffmpeg, &args, video)?;
        Ok(Self {
            path: video.to_path_buf(),
            width: info.width,
            height: info.height,
            bit_depth,
            time_base: info.time_base,
            frame_count,
            pixels,
            ffmpeg,
            times,
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
            let messages = self.ffmpeg.stderr_text();
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
        let listed = match &mut self.times {
            None => return Ok(Some(None)),
            Some(times) => times.next(&self.path)?,
        };
        Ok(Some(Some(self.time_of(index, listed)?)))
    }

    /// The time (s) of frame `index` from its listed timestamp.
    fn time_of(&mut self, index: usize, listed: Option<Option<i64>>) -> Result<f64, FormatError> {
        match listed {
            Some(Some(timestamp)) => {
                let (num, den) = self.time_base;
                // Exact product in integers, one rounding in the division.
                Ok((i128::from(timestamp) * i128::from(num)) as f64 / den as f64)
            }
            Some(None) => Err(FormatError::new(
                &self.path,
                format!(
                    "frame {index} has no timestamp in the video: give --fps F or --timestamps FILE.csv"
                ),
            )),
            None => {
                let messages = match &mut self.times {
                    Some(times) => {
                        let _ = times.process.wait(&self.path);
                        times.process.stderr_text()
                    }
                    None => String::new(),
                };
                Err(FormatError::new(
                    &self.path,
                    with_messages(
                        format!(
                            "frame {index}: ffprobe lists the times of only {index} frames, but ffmpeg decodes more"
                        ),
                        "ffprobe",
                        &messages,
                    ),
                ))
            }
        }
    }

    /// At the end of ffmpeg's output: checks that ffmpeg succeeded without complaint and that the time list ends too.
    fn finish(&mut self) -> Result<(), FormatError> {
        let decoded = self.decoded;
        let status = self.ffmpeg.wait(&self.path)?;
        let messages = self.ffmpeg.stderr_text();
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
        // With `-v error`, anything ffmpeg says is an error: a truncated file ("File ended prematurely") or damaged
        // frames still end with exit status 0 and the frames before the damage.
        if !messages.is_empty() {
            return Err(FormatError::new(
                &self.path,
                format!(
                    "ffmpeg reports errors after decoding {decoded} frames (a truncated or damaged video?): {messages}"
                ),
            ));
        }
        if let Some(times) = &mut self.times {
            if times.next(&self.path)?.is_some() {
                return Err(FormatError::new(
                    &self.path,
                    format!(
                        "ffprobe lists more frame times than the {decoded} frames ffmpeg decodes"
                    ),
                ));
            }
            let status = times.process.wait(&self.path)?;
            if !status.success() {
                let messages = times.process.stderr_text();
                return Err(FormatError::new(
                    &self.path,
                    with_messages(
                        format!("ffprobe failed ({status}) listing the frame times"),
                        "ffprobe",
                        &messages,
                    ),
                ));
            }
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
        let table = "FLAGS NAME            NB_COMPONENTS BITS_PER_PIXEL BIT_DEPTHS\n-----\n\
                     IO... yuv420p                3             12      8-8-8\n\
                     IO... yuv420p10le            3             15      10-10-10\n\
                     IO... gray16le               1             16      16\n";
        assert_eq!(bit_depth_from_table(table, "yuv420p"), Some(8));
        assert_eq!(bit_depth_from_table(table, "yuv420p10le"), Some(10));
        assert_eq!(bit_depth_from_table(table, "gray16le"), Some(16));
        assert_eq!(bit_depth_from_table(table, "yuv420p1"), None);
        assert_eq!(bit_depth_from_table("garbage", "gray"), None);
    }

    #[test]
    fn timestamp_lines_are_parsed() {
        assert_eq!(
            parse_timestamp_line("best_effort_timestamp=1024\n"),
            Some(Some(1024))
        );
        assert_eq!(
            parse_timestamp_line("best_effort_timestamp=N/A\n"),
            Some(None)
        );
        assert_eq!(parse_timestamp_line("\n"), None);
        assert_eq!(parse_timestamp_line("pkt_dts=3\n"), None);
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
