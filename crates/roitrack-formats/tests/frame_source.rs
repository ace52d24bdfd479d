//! Frame sources: folders, patterns, globs and videos, with their times, and every error naming what is at fault.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::Mutex;

use roitrack_formats::{
    FrameInfo, FrameSource, FrameTiming, SourceKind, TimeUnit, read_frame, write_frame_png,
};
use roitrack_image::Frame;

const WIDTH: u32 = 64;
const HEIGHT: u32 = 48;
const BACKGROUND: u16 = 20;
const SQUARE: u16 = 230;
const SQUARE_SIDE: u32 = 8;

/// Frame `i` of the test sequence: a bright square on a dark background, moving 4 px to the right per frame.
fn moving_square(i: u32, scale: u16, bit_depth: u8) -> Frame {
    let mut frame = Frame::new(WIDTH, HEIGHT, bit_depth);
    frame.pixels.fill(BACKGROUND * scale);
    let (x0, y0) = (4 + 4 * i, 20);
    for y in y0..y0 + SQUARE_SIDE {
        for x in x0..x0 + SQUARE_SIDE {
            let k = frame.index(x, y);
            frame.pixels[k] = SQUARE * scale;
        }
    }
    frame
}

/// Writes frame `i` of the sequence (8 bits) as `dir/name`.
fn write_square(dir: &Path, name: &str, i: u32) -> PathBuf {
    let path = dir.join(name);
    write_frame_png(&path, &moving_square(i, 1, 8)).unwrap();
    path
}

fn fps(f: f64) -> FrameTiming {
    FrameTiming {
        fps: Some(f),
        ..FrameTiming::default()
    }
}

/// A timestamps CSV in seconds, said so: these tests' frames are slow (a second apart), which the unit check would
/// take for milliseconds (`frame_times_in_milliseconds_are_caught` tests that check).
fn csv_timing(path: &Path) -> FrameTiming {
    FrameTiming {
        timestamps: Some(path.to_path_buf()),
        time_units: Some(TimeUnit::S),
        ..FrameTiming::default()
    }
}

fn open(source: &Path, timing: &FrameTiming) -> FrameSource {
    FrameSource::open(source, timing).unwrap_or_else(|e| panic!("{e}"))
}

fn open_error(source: &Path, timing: &FrameTiming) -> String {
    match FrameSource::open(source, timing) {
        Ok(s) => panic!("{} opened as {:?}", source.display(), s.kind()),
        Err(e) => e.to_string(),
    }
}

/// Every frame until the end or the first error: the frames read (info and pixels) and the error, if any.
fn read_all(source: &mut FrameSource) -> (Vec<(FrameInfo, Frame)>, Option<String>) {
    let mut frame = Frame::default();
    let mut frames = Vec::new();
    while let Some(result) = source.next_frame(&mut frame) {
        match result {
            Ok(info) => {
                assert_eq!(frame.t_s, info.t_s);
                assert_eq!(info.index, frames.len());
                frames.push((info, frame.clone()));
            }
            Err(e) => {
                // The stream ends at an error.
                assert!(source.next_frame(&mut frame).is_none());
                return (frames, Some(e.to_string()));
            }
        }
    }
    assert!(source.next_frame(&mut frame).is_none());
    (frames, None)
}

fn names(frames: &[(FrameInfo, Frame)]) -> Vec<&str> {
    frames.iter().map(|(info, _)| info.name.as_str()).collect()
}

fn assert_contains(text: &str, parts: &[&str]) {
    for part in parts {
        assert!(text.contains(part), "{part:?} not in: {text}");
    }
}

#[test]
fn a_folder_gives_its_images_in_natural_order() {
    let dir = tempfile::tempdir().unwrap();
    for (i, name) in [
        "frame_1.png",
        "frame_2.png",
        "frame_10.png",
        "frame_3.PNG",
        "frame_0.pgm",
    ]
    .iter()
    .enumerate()
    {
        let path = dir.path().join(name);
        let mut frame = Frame::new(WIDTH, HEIGHT, 8);
        frame.pixels[0] = i as u16;
        if name.ends_with(".pgm") {
            image::GrayImage::from_raw(WIDTH, HEIGHT, vec![0; (WIDTH * HEIGHT) as usize])
                .unwrap()
                .save(&path)
                .unwrap();
        } else {
            write_frame_png(&path, &frame).unwrap();
        }
    }
    // Ignored: other files, hidden files, folders.
    std::fs::write(dir.path().join("notes.txt"), "not a frame").unwrap();
    std::fs::write(dir.path().join("times.csv"), "t\n0\n").unwrap();
    std::fs::write(dir.path().join(".frame_5.png"), "hidden").unwrap();
    std::fs::create_dir(dir.path().join("frame_4.png")).unwrap();

    let mut source = open(dir.path(), &fps(25.0));
    assert_eq!(source.kind(), SourceKind::Directory);
    assert_eq!(source.source(), dir.path());
    assert_eq!(source.frame_count(), Some(5));
    let (frames, error) = read_all(&mut source);
    assert_eq!(error, None);
    assert_eq!(
        names(&frames),
        [
            "frame_0.pgm",
            "frame_1.png",
            "frame_2.png",
            "frame_3.PNG",
            "frame_10.png"
        ]
    );
    for (i, (info, frame)) in frames.iter().enumerate() {
        assert_eq!(info.index, i);
        assert_eq!(info.t_s, i as f64 / 25.0);
        assert_eq!(
            (frame.width, frame.height, frame.bit_depth),
            (WIDTH, HEIGHT, 8)
        );
    }
    // The pixels are those written (the value of pixel 0 is the file's position in the list above).
    let first_pixels: Vec<u16> = frames.iter().map(|(_, f)| f.pixels[0]).collect();
    assert_eq!(first_pixels, [0, 0, 1, 3, 2]);
}

#[test]
fn colour_images_become_grey_as_read_frame_makes_them() {
    let dir = tempfile::tempdir().unwrap();
    let rgb = image::RgbImage::from_fn(WIDTH, HEIGHT, |x, y| {
        image::Rgb([(x * 3) as u8, (y * 5) as u8, (x + y) as u8])
    });
    rgb.save(dir.path().join("c0.png")).unwrap();
    rgb.save(dir.path().join("c1.jpg")).unwrap();
    let mut source = open(dir.path(), &fps(10.0));
    let (frames, error) = read_all(&mut source);
    assert_eq!(error, None);
    for (info, frame) in &frames {
        let expected = read_frame(dir.path().join(&info.name)).unwrap();
        assert_eq!(frame.pixels, expected.pixels, "{}", info.name);
        assert_eq!(frame.bit_depth, expected.bit_depth);
    }
}

#[test]
fn the_frame_buffer_is_reused() {
    let dir = tempfile::tempdir().unwrap();
    for i in 0..5 {
        write_square(dir.path(), &format!("f{i}.png"), i);
    }
    let mut source = open(dir.path(), &fps(10.0));
    let mut frame = Frame::default();
    source.next_frame(&mut frame).unwrap().unwrap();
    let buffer = frame.pixels.as_ptr();
    while let Some(info) = source.next_frame(&mut frame) {
        let info = info.unwrap();
        assert_eq!(frame.pixels.as_ptr(), buffer, "{}", info.name);
        assert_eq!(frame.pixels, moving_square(info.index as u32, 1, 8).pixels);
    }
}

#[test]
fn patterns_number_frames_from_0_to_4_up_to_the_first_gap() {
    let dir = tempfile::tempdir().unwrap();
    // %05d from 1, with a gap after 3: frames 1 to 3.
    for i in [1, 2, 3, 5] {
        write_square(dir.path(), &format!("frame_{i:05}.png"), i);
    }
    let pattern = dir.path().join("frame_%05d.png");
    let mut source = open(&pattern, &fps(10.0));
    assert_eq!(source.kind(), SourceKind::Pattern);
    assert_eq!(source.frame_count(), Some(3));
    let (frames, error) = read_all(&mut source);
    assert_eq!(error, None);
    assert_eq!(
        names(&frames),
        ["frame_00001.png", "frame_00002.png", "frame_00003.png"]
    );
    assert_eq!(frames[2].1.pixels, moving_square(3, 1, 8).pixels);

    // %d from 0, past 9 into two digits.
    for i in 0..12 {
        write_square(dir.path(), &format!("img{i}.png"), i % 10);
    }
    let mut source = open(&dir.path().join("img%d.png"), &fps(10.0));
    let (frames, error) = read_all(&mut source);
    assert_eq!(error, None);
    let expected: Vec<String> = (0..12).map(|i| format!("img{i}.png")).collect();
    assert_eq!(names(&frames), expected);

    // Starting at 4 is found; at 5 it is not.
    write_square(dir.path(), "late_4.png", 0);
    assert_eq!(
        open(&dir.path().join("late_%d.png"), &fps(1.0)).frame_count(),
        Some(1)
    );
    std::fs::rename(dir.path().join("late_4.png"), dir.path().join("late_5.png")).unwrap();
    let missing = dir.path().join("late_%d.png");
    let e = open_error(&missing, &fps(1.0));
    assert!(e.starts_with(&missing.display().to_string()), "{e}");
    assert_contains(
        &e,
        &["no file matches this pattern", "late_0.png", "late_4.png"],
    );

    let e = open_error(&dir.path().join("a%d_%d.png"), &fps(1.0));
    assert_contains(&e, &["more than one"]);
}

#[test]
fn globs_give_the_matching_files_in_natural_order() {
    let dir = tempfile::tempdir().unwrap();
    for i in [10, 2, 1] {
        write_square(dir.path(), &format!("cam_{i}.png"), i % 10);
    }
    write_square(dir.path(), "other_3.png", 3);
    std::fs::create_dir(dir.path().join("cam_dir.png")).unwrap();
    let glob = dir.path().join("cam_*.png");
    let mut source = open(&glob, &fps(10.0));
    assert_eq!(source.kind(), SourceKind::Glob);
    let (frames, error) = read_all(&mut source);
    assert_eq!(error, None);
    assert_eq!(names(&frames), ["cam_1.png", "cam_2.png", "cam_10.png"]);

    let question = dir.path().join("cam_?.png");
    assert_eq!(open(&question, &fps(1.0)).frame_count(), Some(2));

    let none = dir.path().join("nothing_*.png");
    let e = open_error(&none, &fps(1.0));
    assert_eq!(
        e,
        format!("{}: no file matches this glob pattern", none.display())
    );
    let bad = dir.path().join("cam_[.png");
    let e = open_error(&bad, &fps(1.0));
    assert_contains(
        &e,
        &[&bad.display().to_string(), "not a valid glob pattern"],
    );
}

/// Three frames `f0.png` to `f2.png` in a new folder.
fn three_frames() -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    for i in 0..3 {
        write_square(dir.path(), &format!("f{i}.png"), i);
    }
    dir
}

fn write_csv(dir: &Path, text: &str) -> PathBuf {
    let path = dir.join("times.csv");
    std::fs::write(&path, text).unwrap();
    path
}

#[test]
fn timestamps_csv_gives_the_times_with_or_without_file_names() {
    let dir = three_frames();
    let frames_dir = dir.path().to_path_buf();
    let csv_dir = tempfile::tempdir().unwrap();

    let csv = write_csv(csv_dir.path(), "t\n0.5\n0.75\n1.125\n");
    let (frames, error) = read_all(&mut open(&frames_dir, &csv_timing(&csv)));
    assert_eq!(error, None);
    let times: Vec<f64> = frames.iter().map(|(i, _)| i.t_s).collect();
    assert_eq!(times, [0.5, 0.75, 1.125]);

    // Either column order; spaces around fields are trimmed.
    let csv = write_csv(
        csv_dir.path(),
        "file,t\nf0.png, 10\nf1.png,10.001\n f2.png ,10.002\n",
    );
    let (frames, error) = read_all(&mut open(&frames_dir, &csv_timing(&csv)));
    assert_eq!(error, None);
    let times: Vec<f64> = frames.iter().map(|(i, f)| (i.t_s + f.t_s) / 2.0).collect();
    assert_eq!(times, [10.0, 10.001, 10.002]);
}

#[test]
fn timestamps_csv_errors_name_the_file_line_and_field() {
    let dir = three_frames();
    let frames_dir = dir.path().to_path_buf();
    let csv_dir = tempfile::tempdir().unwrap();
    let csv_name = csv_dir.path().join("times.csv").display().to_string();
    let error = |text: &str| {
        let csv = write_csv(csv_dir.path(), text);
        let e = open_error(&frames_dir, &csv_timing(&csv));
        assert!(e.starts_with(&csv_name), "{e}");
        e[csv_name.len()..].to_string()
    };
    assert_contains(
        &error("time\n0\n1\n2\n"),
        &[":1: field 'time': unexpected column"],
    );
    assert_contains(&error("file\nf0.png\n"), &[":1: field 't': missing column"]);
    assert_contains(&error("t,t\n0,0\n"), &[":1: field 't': column named twice"]);
    assert_contains(&error(""), &[": empty file"]);
    assert_contains(
        &error("t\n0\nabc\n2\n"),
        &[":3: field 't': not a number: \"abc\""],
    );
    assert_contains(
        &error("t\n0\nNaN\n2\n"),
        &[":3: field 't': must be a finite number"],
    );
    assert_contains(
        &error("t\n0\n1\ninf\n"),
        &[":4: field 't': must be a finite number"],
    );
    assert_contains(
        &error("t\n0\n2\n1\n"),
        &[":4: field 't': time 1 s is not after 2 s on line 3"],
    );
    assert_contains(
        &error("t\n0\n0\n1\n"),
        &[":3: field 't': time 0 s is not after 0 s on line 2"],
    );
    assert_contains(
        &error("t,file\n0,f0.png\n1,f2.png\n2,f1.png\n"),
        &[":3: field 'file': 'f2.png', but frame 1 is 'f1.png'"],
    );
    assert_contains(
        &error("t\n0\n1\n"),
        &[": no row for frame 2 (f2.png): 2 rows for 3 frames"],
    );
    assert_contains(&error("t\n0\n1\n2\n3\n"), &[":5: 4 rows for 3 frames"]);
    assert_contains(
        &error("t\n0,1\n"),
        &[":2: field 'column 2': unexpected extra field"],
    );

    let missing = csv_dir.path().join("missing.csv");
    let e = open_error(&frames_dir, &csv_timing(&missing));
    assert!(
        e.starts_with(&format!("{}: cannot open for reading", missing.display())),
        "{e}"
    );
}

/// Mutated and truncated copies of a valid timestamps CSV: the source opens, or the error names the CSV; never a
/// panic.
#[test]
fn mutated_timestamps_csv_never_panics() {
    let dir = three_frames();
    let csv_dir = tempfile::tempdir().unwrap();
    let valid = b"t,file\n0,f0.png\n0.5,f1.png\n1,f2.png\n".to_vec();
    let mut inputs: Vec<Vec<u8>> = (0..valid.len()).map(|n| valid[..n].to_vec()).collect();
    let mut state = 0x9e37_79b9_7f4a_7c15u64;
    let mut next = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        state
    };
    for _ in 0..2000 {
        let mut bytes = valid.clone();
        for _ in 0..1 + next() % 4 {
            let at = (next() % bytes.len() as u64) as usize;
            bytes[at] = match next() % 4 {
                0 => b",\n0.9x\"\xff"[(next() % 8) as usize],
                _ => next() as u8,
            };
        }
        inputs.push(bytes);
    }
    let path = csv_dir.path().join("times.csv");
    let name = path.display().to_string();
    let mut opened = 0;
    for bytes in inputs {
        std::fs::write(&path, &bytes).unwrap();
        match FrameSource::open(dir.path(), &csv_timing(&path)) {
            Ok(_) => opened += 1,
            Err(e) => assert!(e.to_string().starts_with(&name), "{e}"),
        }
    }
    assert!(opened > 0);
}

#[test]
fn frame_rates_must_be_finite_and_positive_and_times_must_be_given() {
    let dir = three_frames();
    let (frames, _) = read_all(&mut open(dir.path(), &fps(4.0)));
    let times: Vec<f64> = frames.iter().map(|(i, _)| i.t_s).collect();
    assert_eq!(times, [0.0, 0.25, 0.5]);

    for bad in [0.0, -10.0, f64::NAN, f64::INFINITY, 1e300, 1e-4] {
        let e = open_error(dir.path(), &fps(bad));
        assert!(e.starts_with(&dir.path().display().to_string()), "{e}");
        assert_contains(&e, &["--fps must be from 0.001", "to 1e7"]);
    }

    let e = open_error(dir.path(), &FrameTiming::default());
    assert_eq!(
        e,
        format!(
            "{}: no frame times: give --timestamps FILE.csv (a header with a column t, in seconds, then one row per \
             frame) or --fps F (frame i at i / F s); roitrack never guesses frame times",
            dir.path().display()
        )
    );

    let csv = write_csv(dir.path(), "t\n0\n1\n2\n");
    let both = FrameTiming {
        timestamps: Some(csv),
        fps: Some(10.0),
        ..FrameTiming::default()
    };
    assert_contains(&open_error(dir.path(), &both), &["not both"]);
}

#[test]
fn frames_of_another_size_or_depth_end_the_stream_with_an_error() {
    let dir = tempfile::tempdir().unwrap();
    write_square(dir.path(), "f0.png", 0);
    write_square(dir.path(), "f1.png", 1);
    let odd = dir.path().join("f2.png");
    write_frame_png(&odd, &Frame::new(WIDTH, HEIGHT - 8, 8)).unwrap();
    write_square(dir.path(), "f3.png", 3);
    let (frames, error) = read_all(&mut open(dir.path(), &fps(10.0)));
    assert_eq!(names(&frames), ["f0.png", "f1.png"]);
    assert_eq!(
        error.unwrap(),
        format!(
            "{}: frame 2 is 64 x 40 px, but the first frame (f0.png) is 64 x 48 px: every frame must have the same size",
            odd.display()
        )
    );

    write_frame_png(&odd, &Frame::new(WIDTH, HEIGHT, 16)).unwrap();
    let (frames, error) = read_all(&mut open(dir.path(), &fps(10.0)));
    assert_eq!(frames.len(), 2);
    assert_contains(
        &error.unwrap(),
        &[
            &odd.display().to_string(),
            "frame 2 has 16 bits per pixel",
            "has 8",
        ],
    );
}

#[test]
fn a_corrupt_or_missing_file_ends_the_stream_after_the_good_frames() {
    let dir = tempfile::tempdir().unwrap();
    for i in 0..5 {
        write_square(dir.path(), &format!("f{i}.png"), i);
    }
    let bad = dir.path().join("f2.png");
    let bytes = std::fs::read(&bad).unwrap();
    std::fs::write(&bad, &bytes[..bytes.len() / 2]).unwrap();
    let (frames, error) = read_all(&mut open(dir.path(), &fps(10.0)));
    assert_eq!(names(&frames), ["f0.png", "f1.png"]);
    let error = error.unwrap();
    assert!(error.starts_with(&bad.display().to_string()), "{error}");
    assert_contains(&error, &["PNG"]);

    // A file that disappears between open and read.
    std::fs::write(&bad, &bytes).unwrap();
    let mut source = open(dir.path(), &fps(10.0));
    std::fs::remove_file(dir.path().join("f3.png")).unwrap();
    let (frames, error) = read_all(&mut source);
    assert_eq!(frames.len(), 3);
    let error = error.unwrap();
    assert!(
        error.starts_with(&format!(
            "{}: cannot read",
            dir.path().join("f3.png").display()
        )),
        "{error}"
    );
}

#[test]
fn what_is_not_a_source_is_refused_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let one = write_square(dir.path(), "frame_0007.png", 0);
    let e = open_error(&one, &fps(10.0));
    assert_eq!(
        e,
        format!(
            "{one}: is a single image, not a sequence of frames: give its folder '{dir}', a pattern such as \
             '{dir}/frame_%04d.png', a quoted glob such as '{dir}/*.png'",
            one = one.display(),
            dir = dir.path().display()
        )
    );

    let empty = dir.path().join("empty");
    std::fs::create_dir(&empty).unwrap();
    std::fs::write(empty.join("readme.txt"), "no frames here").unwrap();
    let e = open_error(&empty, &fps(10.0));
    assert!(
        e.starts_with(&format!(
            "{}: no image files in this folder",
            empty.display()
        )),
        "{e}"
    );

    let missing = dir.path().join("nowhere");
    assert_eq!(
        open_error(&missing, &fps(10.0)),
        format!(
            "{}: no such file or folder (nor is it a pattern with %d or %05d, or a glob with * or ?)",
            missing.display()
        )
    );
    let missing_video = dir.path().join("clip.mp4");
    assert_eq!(
        open_error(&missing_video, &FrameTiming::default()),
        format!("{}: no such video file", missing_video.display())
    );
    let text = dir.path().join("notes.txt");
    std::fs::write(&text, "x").unwrap();
    assert_contains(
        &open_error(&text, &fps(10.0)),
        &[
            &text.display().to_string(),
            "not a folder of images, a video (mp4",
        ],
    );
}

// ---- Videos, made here with the ffmpeg program ----

/// Video tests run one at a time: they start processes (and one counts them).
static VIDEO_LOCK: Mutex<()> = Mutex::new(());

/// Whether ffmpeg and ffprobe can be run; without them the video tests fail when `ROITRACK_REQUIRE_FFMPEG=1` (as in
/// CI) and are otherwise skipped with a note.
fn have_ffmpeg(test: &str) -> bool {
    let runs = |program: &str| {
        Command::new(program)
            .arg("-version")
            .output()
            .is_ok_and(|o| o.status.success())
    };
    if runs("ffmpeg") && runs("ffprobe") {
        return true;
    }
    assert!(
        std::env::var("ROITRACK_REQUIRE_FFMPEG").as_deref() != Ok("1"),
        "{test}: ffmpeg and ffprobe are required (ROITRACK_REQUIRE_FFMPEG=1) but not on PATH: \
         install the ffmpeg package (bash scripts/setup-test-deps)"
    );
    // Straight to stderr, not through eprintln!, which the test harness captures and hides for passing tests.
    let _ = writeln!(
        std::io::stderr(),
        "note: {test} skipped: ffmpeg or ffprobe not on PATH (install the ffmpeg package)"
    );
    false
}

/// Makes `dir/name` from the frames by running ffmpeg at 10 frames per second with the output arguments `args`.
fn make_video(dir: &Path, name: &str, frames: &[Frame], args: &[&str]) -> PathBuf {
    let images = dir.join(format!("{name}.frames"));
    std::fs::create_dir_all(&images).unwrap();
    for (i, frame) in frames.iter().enumerate() {
        write_frame_png(images.join(format!("f_{i:03}.png")), frame).unwrap();
    }
    let video = dir.join(name);
    let output = Command::new("ffmpeg")
        .args(["-nostdin", "-v", "error", "-y", "-framerate", "10", "-i"])
        .arg(images.join("f_%03d.png"))
        .args(args)
        .arg(&video)
        .output()
        .unwrap();
    assert!(
        output.status.success(),
        "ffmpeg: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    video
}

fn squares(count: u32, scale: u16, bit_depth: u8) -> Vec<Frame> {
    (0..count)
        .map(|i| moving_square(i, scale, bit_depth))
        .collect()
}

const LOSSLESS_GREY: &[&str] = &["-c:v", "ffv1", "-pix_fmt", "gray"];
/// H.264 with up to 3 B-frames between references (a stream whose packets come out of presentation order).
const H264_B_FRAMES: &[&str] = &[
    "-c:v", "libx264", "-pix_fmt", "yuv420p", "-bf", "3", "-g", "10", "-crf", "10",
];

/// Whether the packets of the video come in an order other than their presentation times' (B-frames).
fn has_reordered_packets(video: &Path) -> bool {
    let output = Command::new("ffprobe")
        .args([
            "-v",
            "error",
            "-select_streams",
            "v:0",
            "-show_entries",
            "packet=pts",
            "-of",
            "csv=p=0",
        ])
        .arg(video)
        .output()
        .unwrap();
    let pts: Vec<i64> = String::from_utf8_lossy(&output.stdout)
        .lines()
        .filter_map(|l| l.trim().trim_end_matches(',').parse().ok())
        .collect();
    pts.windows(2).any(|w| w[1] < w[0])
}

fn mean_abs_difference(a: &Frame, b: &Frame) -> f64 {
    let sum: u64 = a
        .pixels
        .iter()
        .zip(&b.pixels)
        .map(|(&x, &y)| u64::from(x.abs_diff(y)))
        .sum();
    sum as f64 / a.pixels.len() as f64
}

/// Reads the whole video with its own times and checks 10 frames of the square at 10 frames per second.
fn check_video(video: &Path, max_mean_difference: f64) {
    let mut source = open(video, &FrameTiming::default());
    assert_eq!(source.kind(), SourceKind::Video);
    assert_eq!(source.frame_count(), Some(10), "{}", video.display());
    let (frames, error) = read_all(&mut source);
    assert_eq!(error, None, "{}", video.display());
    assert_eq!(frames.len(), 10);
    let file = video.file_name().unwrap().to_string_lossy();
    for (i, (info, frame)) in frames.iter().enumerate() {
        assert_eq!(info.name, format!("frame {i} of {file}"));
        assert!(
            (info.t_s - i as f64 / 10.0).abs() < 1e-6,
            "{}: frame {i} at {} s",
            video.display(),
            info.t_s
        );
        assert_eq!(
            (frame.width, frame.height, frame.bit_depth),
            (WIDTH, HEIGHT, 8)
        );
        let expected = moving_square(i as u32, 1, 8);
        let difference = mean_abs_difference(frame, &expected);
        assert!(
            difference <= max_mean_difference,
            "{}: frame {i} differs by {difference} on average",
            video.display()
        );
        // The square is where it should be.
        let centre = frame.index(4 + 4 * i as u32 + SQUARE_SIDE / 2, 20 + SQUARE_SIDE / 2);
        assert!(frame.pixels[centre] > 180, "{}: frame {i}", video.display());
    }
}

#[test]
fn lossless_videos_read_back_exactly_with_their_times() {
    let _lock = VIDEO_LOCK.lock().unwrap_or_else(|e| e.into_inner());
    if !have_ffmpeg("lossless_videos_read_back_exactly_with_their_times") {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let mkv = make_video(dir.path(), "clip.mkv", &squares(10, 1, 8), LOSSLESS_GREY);
    check_video(&mkv, 0.0);

    // 16-bit grey: read as 16 bits, values as stored.
    let mkv16 = make_video(
        dir.path(),
        "deep.MKV",
        &squares(10, 256, 16),
        &["-c:v", "ffv1", "-pix_fmt", "gray16le"],
    );
    let (frames, error) = read_all(&mut open(&mkv16, &FrameTiming::default()));
    assert_eq!(error, None);
    assert_eq!(frames.len(), 10);
    for (i, (_, frame)) in frames.iter().enumerate() {
        assert_eq!(frame.bit_depth, 16);
        assert_eq!(frame.pixels, moving_square(i as u32, 256, 16).pixels);
    }
}

#[test]
fn h264_videos_with_b_frames_give_frames_in_presentation_order() {
    let _lock = VIDEO_LOCK.lock().unwrap_or_else(|e| e.into_inner());
    if !have_ffmpeg("h264_videos_with_b_frames_give_frames_in_presentation_order") {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    for name in ["clip.mp4", "clip.mkv"] {
        let video = make_video(dir.path(), name, &squares(10, 1, 8), H264_B_FRAMES);
        assert!(has_reordered_packets(&video), "{name}: no B-frames");
        check_video(&video, 3.0);
    }
    let plain = make_video(
        dir.path(),
        "plain.mov",
        &squares(10, 1, 8),
        &[
            "-c:v", "libx264", "-pix_fmt", "yuv420p", "-bf", "0", "-crf", "10",
        ],
    );
    check_video(&plain, 3.0);
}

#[test]
fn video_times_from_a_frame_rate_or_a_csv() {
    let _lock = VIDEO_LOCK.lock().unwrap_or_else(|e| e.into_inner());
    if !have_ffmpeg("video_times_from_a_frame_rate_or_a_csv") {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let video = make_video(dir.path(), "clip.mkv", &squares(10, 1, 8), LOSSLESS_GREY);

    let (frames, error) = read_all(&mut open(&video, &fps(1000.0)));
    assert_eq!(error, None);
    let times: Vec<f64> = frames.iter().map(|(i, _)| i.t_s).collect();
    let expected: Vec<f64> = (0..10).map(|i| f64::from(i) / 1000.0).collect();
    assert_eq!(times, expected);

    let rows: String = (0..10)
        .map(|i| format!("{}\n", 3.0 + f64::from(i) * 0.5))
        .collect();
    let csv = write_csv(dir.path(), &format!("t\n{rows}"));
    let (frames, error) = read_all(&mut open(&video, &csv_timing(&csv)));
    assert_eq!(error, None);
    assert_eq!(frames[9].0.t_s, 7.5);

    // Too few rows: the frames that have one, then an error naming the first frame without.
    let csv = write_csv(dir.path(), "t\n0\n1\n2\n");
    let (frames, error) = read_all(&mut open(&video, &csv_timing(&csv)));
    assert_eq!(frames.len(), 3);
    assert_eq!(
        error.unwrap(),
        format!(
            "{}: no row for frame 3 (frame 3 of clip.mkv): 3 rows for more frames",
            csv.display()
        )
    );

    // Too many: every frame, then an error at the end.
    let rows: String = (0..12).map(|i| format!("{i}\n")).collect();
    let csv = write_csv(dir.path(), &format!("t\n{rows}"));
    let (frames, error) = read_all(&mut open(&video, &csv_timing(&csv)));
    assert_eq!(frames.len(), 10);
    assert_eq!(
        error.unwrap(),
        format!("{}:12: 12 rows for 10 frames of clip.mkv", csv.display())
    );

    // A video's frames have no file names.
    let csv = write_csv(dir.path(), "t,file\n0,a.png\n");
    let e = open_error(&video, &csv_timing(&csv));
    assert!(
        e.starts_with(&format!(
            "{}:1: field 'file': a video's frames have no file names",
            csv.display()
        )),
        "{e}"
    );
}

#[test]
fn repeated_video_timestamps_are_an_error_naming_the_frame() {
    let _lock = VIDEO_LOCK.lock().unwrap_or_else(|e| e.into_inner());
    if !have_ffmpeg("repeated_video_timestamps_are_an_error_naming_the_frame") {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    // Frames at 0, 0, 0.1, 0.1, ...
    let mut args = vec![
        "-vf",
        "setpts='floor(N/2)/TB*0.1'",
        "-fps_mode",
        "passthrough",
    ];
    args.extend_from_slice(LOSSLESS_GREY);
    let video = make_video(dir.path(), "dup.mkv", &squares(6, 1, 8), &args);
    let (frames, error) = read_all(&mut open(&video, &FrameTiming::default()));
    assert_eq!(frames.len(), 1);
    assert_eq!(
        error.unwrap(),
        format!(
            "{}: frame 1 of dup.mkv: time 0 s is not after the previous frame's 0 s: the video's timestamps repeat \
             or go backwards (give --fps F or --timestamps FILE.csv)",
            video.display()
        )
    );
    // A frame rate overrides them.
    let (frames, error) = read_all(&mut open(&video, &fps(10.0)));
    assert_eq!((frames.len(), error), (6, None));
}

/// Frames of noise, which compress poorly: most of a video made of them is frame data.
fn noise(count: u32) -> Vec<Frame> {
    let mut state = 0x2545_f491_4f6c_dd1du64;
    (0..count)
        .map(|_| {
            let mut frame = Frame::new(WIDTH, HEIGHT, 8);
            for v in &mut frame.pixels {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                *v = (state >> 56) as u16;
            }
            frame
        })
        .collect()
}

#[test]
fn truncated_or_bogus_videos_give_errors_not_panics() {
    let _lock = VIDEO_LOCK.lock().unwrap_or_else(|e| e.into_inner());
    if !have_ffmpeg("truncated_or_bogus_videos_give_errors_not_panics") {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let cut = |video: &Path, fraction: f64| {
        let bytes = std::fs::read(video).unwrap();
        let name = video.file_name().unwrap().to_string_lossy();
        let cut = dir.path().join(format!("cut_{name}"));
        std::fs::write(&cut, &bytes[..(bytes.len() as f64 * fraction) as usize]).unwrap();
        cut
    };

    // Cut in the middle of the frames: the frames before the cut, then an error (ffmpeg itself exits with success).
    let mut faststart = H264_B_FRAMES.to_vec();
    faststart.extend(["-movflags", "+faststart"]);
    for (name, args) in [("noise.mkv", LOSSLESS_GREY), ("noise.mp4", &faststart[..])] {
        let video = cut(&make_video(dir.path(), name, &noise(10), args), 0.6);
        let (frames, error) = read_all(&mut open(&video, &FrameTiming::default()));
        assert!(
            (1..10).contains(&frames.len()),
            "{name}: {} frames",
            frames.len()
        );
        let error = error.unwrap_or_else(|| panic!("{name}: truncated, yet no error"));
        assert!(
            error.starts_with(&format!(
                "{}: ffmpeg reports errors after decoding {} frames (a truncated or damaged video?): ",
                video.display(),
                frames.len()
            )),
            "{error}"
        );
    }

    // Cut where the container's header is: refused at open, naming the file.
    for (name, args) in [("clip.mkv", LOSSLESS_GREY), ("clip.mp4", H264_B_FRAMES)] {
        let video = cut(&make_video(dir.path(), name, &squares(10, 1, 8), args), 0.3);
        let e = open_error(&video, &FrameTiming::default());
        assert!(e.starts_with(&video.display().to_string()), "{e}");
    }

    let bogus = dir.path().join("bogus.mp4");
    std::fs::write(&bogus, b"this is not a video at all").unwrap();
    let e = open_error(&bogus, &FrameTiming::default());
    assert!(
        e.starts_with(&format!(
            "{}: ffprobe cannot read the video (exit status: 1); ffprobe says: ",
            bogus.display()
        )),
        "{e}"
    );
}

/// The ffmpeg and ffprobe children of this process (state, name), from `/proc`.
#[cfg(target_os = "linux")]
fn ffmpeg_children() -> Vec<(char, String)> {
    let me = std::process::id().to_string();
    let mut children = Vec::new();
    for entry in std::fs::read_dir("/proc").unwrap().flatten() {
        let Ok(stat) = std::fs::read_to_string(entry.path().join("stat")) else {
            continue;
        };
        // pid (comm) state ppid ...
        let (Some(open), Some(close)) = (stat.find('('), stat.rfind(')')) else {
            continue;
        };
        let comm = &stat[open + 1..close];
        let rest: Vec<&str> = stat[close + 1..].split_whitespace().collect();
        if rest.get(1) == Some(&me.as_str()) && comm.starts_with("ff") {
            children.push((rest[0].chars().next().unwrap_or('?'), comm.to_string()));
        }
    }
    children
}

#[cfg(target_os = "linux")]
#[test]
fn dropping_a_video_source_leaves_no_process_behind() {
    let _lock = VIDEO_LOCK.lock().unwrap_or_else(|e| e.into_inner());
    if !have_ffmpeg("dropping_a_video_source_leaves_no_process_behind") {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let video = make_video(dir.path(), "clip.mkv", &squares(10, 1, 8), LOSSLESS_GREY);
    {
        let mut source = open(&video, &FrameTiming::default());
        let mut frame = Frame::default();
        source.next_frame(&mut frame).unwrap().unwrap();
        source.next_frame(&mut frame).unwrap().unwrap();
        assert!(!ffmpeg_children().is_empty());
        // Dropped with 8 frames unread.
    }
    assert_eq!(ffmpeg_children(), []);
    {
        let mut source = open(&video, &FrameTiming::default());
        let (frames, _) = read_all(&mut source);
        assert_eq!(frames.len(), 10);
    }
    assert_eq!(ffmpeg_children(), []);
}

#[test]
fn frame_times_in_milliseconds_are_caught() {
    let dir = three_frames();
    let csv = write_csv(dir.path(), "t\n0\n33.4\n66.7\n");
    let unchecked = FrameTiming {
        timestamps: Some(csv.clone()),
        ..FrameTiming::default()
    };
    let e = open_error(dir.path(), &unchecked);
    assert!(
        e.starts_with(&format!(
            "{}:3: field 't': successive frames are 33.",
            csv.display()
        )),
        "{e}"
    );
    assert_contains(&e, &["milliseconds (29.", "--time-units ms"]);
    // Said in milliseconds, they are read so.
    let in_ms = FrameTiming {
        time_units: Some(TimeUnit::Ms),
        ..unchecked.clone()
    };
    let (frames, error) = read_all(&mut open(dir.path(), &in_ms));
    assert!(error.is_none());
    let times: Vec<f64> = frames.iter().map(|(info, _)| info.t_s).collect();
    assert_eq!(times, [0.0, 33.4 * 1e-3, 66.7 * 1e-3]);
    // Nanoseconds since 1970 are past the year 5000 as seconds.
    let csv = write_csv(
        dir.path(),
        "t\n1700000000000000000\n1700000000033000000\n1700000000066000000\n",
    );
    let e = open_error(
        dir.path(),
        &FrameTiming {
            timestamps: Some(csv),
            ..FrameTiming::default()
        },
    );
    assert_contains(
        &e,
        &[":2: field 't'", "past the year 5000", "--time-units ns"],
    );
}

/// The decoded frames' `best_effort_timestamp` as a second, independent ffprobe decoding lists them, in seconds.
fn ffprobe_frame_times_s(video: &Path) -> Vec<f64> {
    let run = |entries: &str| {
        let output = Command::new("ffprobe")
            .args([
                "-v",
                "error",
                "-select_streams",
                "V:0",
                "-show_entries",
                entries,
            ])
            .args(["-of", "default=nw=1:nk=1"])
            .arg(video)
            .output()
            .unwrap();
        assert!(output.status.success(), "ffprobe {}", video.display());
        String::from_utf8_lossy(&output.stdout).into_owned()
    };
    let time_base = run("stream=time_base");
    let (num, den) = time_base.trim().split_once('/').unwrap();
    let (num, den): (i128, i128) = (num.parse().unwrap(), den.parse().unwrap());
    run("frame=best_effort_timestamp")
        .lines()
        .filter(|l| !l.trim().is_empty())
        .map(|l| (l.trim().parse::<i128>().unwrap() * num) as f64 / den as f64)
        .collect()
}

#[test]
fn video_times_are_those_an_independent_decoding_lists() {
    let _lock = VIDEO_LOCK.lock().unwrap_or_else(|e| e.into_inner());
    if !have_ffmpeg("video_times_are_those_an_independent_decoding_lists") {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let frames = squares(12, 1, 8);
    let h264 = ["-c:v", "libx264", "-pix_fmt", "yuv420p"];
    // Irregular, increasing times (in milliseconds, so that none round onto another): 10 Hz, then 20 Hz, then steps
    // of 0.12 and 0.14 s.
    let vfr = "settb=1/1000,setpts='if(lt(N\\,4)\\,N/10\\,if(lt(N\\,8)\\,0.3+(N-3)/20\\,0.5+(N-7)*0.13+0.01*mod(N\\,2)))/TB'";
    let mut videos = Vec::new();
    // Constant rate, libx264's default B-frames (and the edit list that mp4 then has for their delay).
    videos.push(make_video(dir.path(), "cfr.mp4", &frames, &h264));
    for name in ["vfr.mkv", "vfr.mp4"] {
        let mut args = vec![
            "-vf",
            vfr,
            "-fps_mode",
            "passthrough",
            "-enc_time_base",
            "1/1000",
        ];
        args.extend(h264);
        videos.push(make_video(dir.path(), name, &frames, &args));
    }
    // A first timestamp of 7.5 s.
    for name in ["late.mp4", "late.mkv"] {
        let mut args = vec!["-output_ts_offset", "7.5"];
        args.extend(h264);
        videos.push(make_video(dir.path(), name, &frames, &args));
    }
    // An edit list that starts after the first frames, which are decoded (their successors need them) and dropped.
    let trimmed = dir.path().join("trimmed.mp4");
    let output = Command::new("ffmpeg")
        .args(["-nostdin", "-v", "error", "-y", "-ss", "0.35", "-i"])
        .arg(&videos[0])
        .args(["-c", "copy"])
        .arg(&trimmed)
        .output()
        .unwrap();
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    videos.push(trimmed);

    for video in &videos {
        let expected = ffprobe_frame_times_s(video);
        let (frames, error) = read_all(&mut open(video, &FrameTiming::default()));
        assert_eq!(error, None, "{}", video.display());
        let times: Vec<f64> = frames.iter().map(|(info, _)| info.t_s).collect();
        assert_eq!(times, expected, "{}", video.display());
    }
    // The files are what they are said to be.
    let steps: Vec<f64> = ffprobe_frame_times_s(&videos[1])
        .windows(2)
        .map(|w| w[1] - w[0])
        .collect();
    assert!(
        steps.iter().any(|&s| s < 0.06) && steps.iter().any(|&s| s > 0.12),
        "{steps:?}"
    );
    assert_eq!(ffprobe_frame_times_s(&videos[3])[0], 7.5);
    let trimmed_times = ffprobe_frame_times_s(&videos[5]);
    assert!((1..12).contains(&trimmed_times.len()), "{trimmed_times:?}");
}
