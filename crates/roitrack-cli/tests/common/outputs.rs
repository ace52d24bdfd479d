//! Helpers of the tests of the output discipline and of fault injection (included with `#[path]` by
//! output_discipline.rs and fault_injection.rs): the binary, signals, a folder's state and its temporaries, bags.

#![allow(dead_code)]

use std::collections::BTreeMap;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, Command, Output, Stdio};
use std::time::{Duration, Instant};

pub fn roitrack() -> Command {
    Command::new(env!("CARGO_BIN_EXE_roitrack"))
}

pub fn p(path: &Path) -> &str {
    path.to_str().unwrap()
}

pub fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

pub fn succeeded(args: &[&str]) {
    let out = roitrack().args(args).output().unwrap();
    assert!(out.status.success(), "{args:?}: {}", stderr(&out));
}

pub fn send(child: &Child, signal: i32) {
    // SAFETY: sends a signal to a child this test spawned.
    assert_eq!(unsafe { libc::kill(child.id() as libc::pid_t, signal) }, 0);
}

/// Every file under `dir` (recursively) with its bytes: a folder's state, to compare byte for byte.
pub fn snapshot(dir: &Path) -> BTreeMap<PathBuf, Vec<u8>> {
    let mut files = BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(&d).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                stack.push(path);
            } else {
                files.insert(path.clone(), std::fs::read(&path).unwrap());
            }
        }
    }
    files
}

/// The temporaries left under `dir` (recursively): `.NAME.PID.XXXXXX.tmp` files or folders, a version saved aside.
pub fn temporaries(dir: &Path) -> Vec<PathBuf> {
    let mut found = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(&d).unwrap() {
            let path = entry.unwrap().path();
            let name = path.file_name().unwrap().to_string_lossy().into_owned();
            if name.starts_with('.') && (name.ends_with(".tmp") || name.ends_with(".old")) {
                found.push(path.clone());
            }
            if path.is_dir() {
                stack.push(path);
            }
        }
    }
    found
}

/// Whether `path` is a complete MCAP bag (its summary written) holding at least one pose.
pub fn bag_is_readable(path: &Path) -> bool {
    let Ok(bytes) = std::fs::read(path) else {
        return false;
    };
    let summary = mcap::Summary::read(&bytes).ok().flatten();
    let poses = mcap::MessageStream::new(&bytes)
        .map(|stream| {
            stream
                .map_while(Result::ok)
                .filter(|m| m.channel.topic == "/roitrack/pose")
                .count()
        })
        .unwrap_or(0);
    summary.is_some() && poses > 0
}

/// The camera and target of the bench scene (`roitrack target`), in `dir`.
pub fn bench_scene(dir: &Path) -> (PathBuf, PathBuf) {
    let (target, camera) = (dir.join("target.csv"), dir.join("camera.yaml"));
    succeeded(&["target", "--out", p(&target), "--camera-out", p(&camera)]);
    (camera, target)
}

/// Feeds `child` an endless stream of measurements of the grid at rest (4 kHz) until it stops reading.
pub fn feed_forever(child: &mut Child) -> std::thread::JoinHandle<()> {
    let mut stdin = child.stdin.take().unwrap();
    std::thread::spawn(move || {
        let mut text = String::from("t,id,u,v\n");
        for k in 0u64.. {
            let id = k % 16;
            let (c, r) = ((id % 4) as f64, (id / 4) as f64);
            text += &format!(
                "{},{},{},{}\n",
                k as f64 / 4000.0,
                id,
                437.0 + 50.0 * c,
                437.0 + 50.0 * r
            );
            if text.len() > 1 << 16 {
                if stdin.write_all(text.as_bytes()).is_err() {
                    return;
                }
                text.clear();
            }
        }
    })
}

/// A small deterministic generator (xorshift) for the moments faults come at.
pub struct Seeded(pub u64);

impl Seeded {
    /// A number in [lo, hi).
    pub fn next_in(&mut self, lo: u64, hi: u64) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        lo + self.0 % (hi - lo)
    }
}

/// `track` over the standard input into `out` (poses, twists, covariance, bag).
pub fn track_stdin(camera: &Path, target: &Path, out: &Path, poses: &str) -> Command {
    let mut command = roitrack();
    command
        .args(["track", "--camera", p(camera), "--target", p(target)])
        .args(["--measurements", "-", "--poses", poses])
        .args(["--twists", p(&out.join("twists.csv"))])
        .args(["--covariance", p(&out.join("covariance.csv"))])
        .args(["--mcap", p(&out.join("run.mcap"))])
        .stdin(Stdio::piped())
        .stdout(Stdio::null())
        .stderr(Stdio::piped());
    command
}

/// `track --camera CAMERA --target TARGET --measurements MEASUREMENTS` writing every output it has into `out`:
/// poses.tum, twists.csv, covariance.csv and the bag run.mcap (the files [`previous_outputs`] leaves).
pub fn track_into(camera: &Path, target: &Path, measurements: &Path, out: &Path) -> Vec<String> {
    [
        "track",
        "--camera",
        p(camera),
        "--target",
        p(target),
        "--measurements",
        p(measurements),
        "--poses",
        p(&out.join("poses.tum")),
        "--twists",
        p(&out.join("twists.csv")),
        "--covariance",
        p(&out.join("covariance.csv")),
        "--mcap",
        p(&out.join("run.mcap")),
    ]
    .map(String::from)
    .to_vec()
}

/// Previous outputs in `out`, as a run before would have left them.
pub fn previous_outputs(out: &Path) {
    std::fs::create_dir_all(out).unwrap();
    for name in ["poses.tum", "twists.csv", "covariance.csv", "run.mcap"] {
        std::fs::write(out.join(name), format!("previous {name}\n")).unwrap();
    }
}

/// Previous outputs of `track` in `out`, as a run before would have left them, and no partial bag.
pub fn previous_track_outputs(out: &Path) {
    previous_outputs(out);
    let _ = std::fs::remove_file(out.join("run.partial.mcap"));
}

/// Waits for `child` to end, at most `limit`, and returns how it ended.
pub fn wait_within(child: Child, limit: Duration) -> Output {
    let start = Instant::now();
    let out = child.wait_with_output().unwrap();
    assert!(
        start.elapsed() < limit,
        "took {:?}: {}",
        start.elapsed(),
        stderr(&out)
    );
    out
}

/// [`track_stdin`] fed measurements without end, sent `signal` after `delay_ms` (asserting it still runs then); how
/// it ended, within 5 s of the signal.
pub fn track_signalled(
    camera: &Path,
    target: &Path,
    out: &Path,
    signal: i32,
    delay_ms: u64,
) -> Output {
    let mut child = track_stdin(camera, target, out, p(&out.join("poses.tum")))
        .spawn()
        .unwrap();
    let feeder = feed_forever(&mut child);
    std::thread::sleep(Duration::from_millis(delay_ms));
    assert!(child.try_wait().unwrap().is_none(), "ended before {signal}");
    send(&child, signal);
    let result = wait_within(child, Duration::from_secs(5));
    feeder.join().unwrap();
    result
}

/// [`track_stdin`] into `out` once its four outputs' temporaries are there (at most 10 s), waiting for measurements
/// that do not come (so never reaching its next estimate); the child and its standard input, to keep open.
pub fn track_waiting(camera: &Path, target: &Path, out: &Path) -> (Child, ChildStdin) {
    let mut child = track_stdin(camera, target, out, p(&out.join("poses.tum")))
        .spawn()
        .unwrap();
    let stdin = child.stdin.take().unwrap();
    let started = Instant::now();
    while temporaries(out).len() < 4 && started.elapsed() < Duration::from_secs(10) {
        std::thread::sleep(Duration::from_millis(20));
    }
    assert_eq!(
        temporaries(out).len(),
        4,
        "the outputs' temporaries are there"
    );
    (child, stdin)
}

/// `out` as it was (`before`) but for `track`'s bag, kept, readable, as `run.partial.mcap`.
pub fn assert_kept_with_partial_bag(
    out: &Path,
    before: &BTreeMap<PathBuf, Vec<u8>>,
    context: &str,
) {
    let mut after = snapshot(out);
    let partial = out.join("run.partial.mcap");
    assert!(
        after.remove(&partial).is_some(),
        "no partial bag: {context}"
    );
    assert_eq!(&after, before, "{context}");
    assert!(bag_is_readable(&partial), "{context}");
}
