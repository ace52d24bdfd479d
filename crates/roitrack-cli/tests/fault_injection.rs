//! Fault injection on long runs of `track` and `simulate`, each fault with its expected outcome:
//!
//! - SIGINT, SIGTERM, SIGHUP and SIGPIPE sent at seeded random moments: the run ends by that signal (status 128 +
//!   its number in a shell), every previous output byte-identical, no temporary left, and `track`'s bag kept,
//!   readable, as NAME.partial.mcap;
//! - a second signal while the first waits for the next estimate: the run ends at once, by the second, no temporary
//!   left;
//! - a full disk (a file-size limit, RLIMIT_FSIZE, with SIGXFSZ ignored so that a write fails with EFBIG as on a full
//!   disk; no root or tmpfs needed): the run fails with status 1 naming the file, every previous output
//!   byte-identical, no temporary left;
//! - `kill -9`, which cannot be caught: the temporaries stay, and the next run writing those outputs removes them.
//!
//! Every run is long (an endless stream of measurements, an hour of simulation) and stopped within a second or so:
//! the whole file takes well under a minute.

#![cfg(unix)]

#[path = "common/outputs.rs"]
mod outputs;

use outputs::*;
use std::io::Write;
use std::os::unix::process::{CommandExt, ExitStatusExt};
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// `simulate` of ten minutes (far longer than any test waits) into `out`.
fn long_simulation(out: &Path, seed: &str) -> Command {
    let mut command = roitrack();
    command
        .args(["simulate", "--scenario", "spin", "--seed", seed])
        .args(["--duration-s", "600", "--out", p(out)])
        .stdout(Stdio::null())
        .stderr(Stdio::piped());
    command
}

/// Waits until a temporary appears in `dir` (the run is writing its outputs), at most 10 s.
fn until_writing(dir: &Path) {
    let start = Instant::now();
    while start.elapsed() < Duration::from_secs(10) {
        if dir.is_dir() && !temporaries(dir).is_empty() {
            return;
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    panic!("{} holds no temporary after 10 s", dir.display());
}

/// Limits the files the command may write to `bytes` (RLIMIT_FSIZE) and ignores SIGXFSZ, so that a write beyond
/// fails with EFBIG, as on a full disk.
fn with_file_size_limit(command: &mut Command, bytes: u64) {
    // SAFETY: only async-signal-safe calls (setrlimit, signal) in the child between fork and exec.
    unsafe {
        command.pre_exec(move || {
            libc::signal(libc::SIGXFSZ, libc::SIG_IGN);
            let limit = libc::rlimit {
                rlim_cur: bytes as libc::rlim_t,
                rlim_max: bytes as libc::rlim_t,
            };
            if libc::setrlimit(libc::RLIMIT_FSIZE, &limit) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            Ok(())
        });
    }
}

const SIGNALS: [i32; 4] = [libc::SIGINT, libc::SIGTERM, libc::SIGHUP, libc::SIGPIPE];

#[test]
fn each_signal_at_a_random_moment_of_track_keeps_the_outputs_and_the_partial_bag() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let (camera, target) = bench_scene(dir);
    let out = dir.join("out");
    let mut moments = Seeded(0x7ac4_5167_a15e);
    for signal in SIGNALS {
        previous_track_outputs(&out);
        let before = snapshot(&out);
        let delay_ms = moments.next_in(200, 1000);
        let result = track_signalled(&camera, &target, &out, signal, delay_ms);
        let context = format!("signal {signal} at {delay_ms} ms: {}", stderr(&result));
        assert_eq!(result.status.signal(), Some(signal), "{context}");
        // A reader gone (SIGPIPE) wants no message; the others say what happened and what was kept.
        if signal == libc::SIGPIPE {
            assert!(!stderr(&result).contains("error"), "{context}");
        } else {
            assert!(stderr(&result).contains("interrupted"), "{context}");
        }
        assert_kept_with_partial_bag(&out, &before, &context);
        assert!(temporaries(dir).is_empty(), "{:?}", temporaries(dir));
    }
}

#[test]
fn each_signal_at_a_random_moment_of_simulate_leaves_the_previous_folder() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let sim = dir.join("sim");
    // A previous run, and a file of the user's beside it.
    succeeded(&[
        "simulate",
        "--scenario",
        "spin",
        "--duration-s",
        "0.5",
        "--rois",
        "--out",
        p(&sim),
    ]);
    std::fs::write(sim.join("notes.txt"), "mine").unwrap();
    let before = snapshot(&sim);
    let mut moments = Seeded(0x5137_0fa5_e1de);
    for signal in SIGNALS {
        let child = long_simulation(&sim, "2").spawn().unwrap();
        // At a random moment while it writes its files beside the previous ones.
        until_writing(&sim);
        let delay_ms = moments.next_in(0, 800);
        std::thread::sleep(Duration::from_millis(delay_ms));
        send(&child, signal);
        let result = wait_within(child, Duration::from_secs(5));
        let context = format!("signal {signal} at {delay_ms} ms: {}", stderr(&result));
        assert_eq!(result.status.signal(), Some(signal), "{context}");
        assert_eq!(snapshot(&sim), before, "{context}");
        assert!(temporaries(dir).is_empty(), "{:?}", temporaries(dir));
    }
    // Into a folder that did not exist: it is not left behind.
    let new = dir.join("new").join("sim");
    let child = long_simulation(&new, "3").spawn().unwrap();
    until_writing(&new);
    std::thread::sleep(Duration::from_millis(moments.next_in(0, 400)));
    send(&child, libc::SIGTERM);
    let result = wait_within(child, Duration::from_secs(5));
    assert_eq!(result.status.signal(), Some(libc::SIGTERM));
    assert!(!dir.join("new").exists());
}

#[test]
fn a_second_signal_ends_a_run_at_once_without_temporaries() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let (camera, target) = bench_scene(dir);
    let out = dir.join("out");
    // Each pair: the first is noted (the run waits for measurements that do not come, so never reaches its next
    // estimate), the second ends it.
    for (first, second) in [
        (libc::SIGHUP, libc::SIGPIPE),
        (libc::SIGPIPE, libc::SIGINT),
        (libc::SIGTERM, libc::SIGHUP),
    ] {
        previous_track_outputs(&out);
        let before = snapshot(&out);
        let (mut child, _stdin) = track_waiting(&camera, &target, &out);
        send(&child, first);
        std::thread::sleep(Duration::from_millis(200));
        assert!(child.try_wait().unwrap().is_none(), "{first} waits");
        send(&child, second);
        let result = wait_within(child, Duration::from_secs(2));
        assert_eq!(result.status.signal(), Some(second), "{}", stderr(&result));
        assert!(temporaries(dir).is_empty(), "{:?}", temporaries(dir));
        assert_eq!(snapshot(&out), before);
    }
}

#[test]
fn a_full_disk_fails_the_run_naming_the_file_and_changes_nothing() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let sim = dir.join("sim");
    succeeded(&["simulate", "--scenario", "spin", "--out", p(&sim)]);
    let out = dir.join("out");
    // track: the poses outgrow 64 KiB (3 s of estimates at 400 Hz are about 200 KB).
    previous_track_outputs(&out);
    let before = snapshot(&out);
    let mut command = roitrack();
    command
        .args(["track", "--camera", p(&sim.join("camera.yaml"))])
        .args(["--target", p(&sim.join("target.csv"))])
        .args(["--measurements", p(&sim.join("measurements.csv"))])
        .args(["--poses", p(&out.join("poses.tum"))])
        .args(["--twists", p(&out.join("twists.csv"))]);
    with_file_size_limit(&mut command, 64 << 10);
    let result = command.output().unwrap();
    let error = stderr(&result);
    assert_eq!(result.status.code(), Some(1), "{error}");
    assert!(
        error.contains("File too large")
            && (error.contains("poses.tum") || error.contains("twists.csv")),
        "{error}"
    );
    assert_eq!(snapshot(&out), before);
    assert!(temporaries(dir).is_empty(), "{:?}", temporaries(dir));
    // simulate: the measurements outgrow 256 KiB, into the previous folder and into a new one.
    let before = snapshot(&sim);
    for folder in [&sim, &dir.join("fresh")] {
        let mut command = roitrack();
        command.args([
            "simulate",
            "--scenario",
            "orthoglide",
            "--seed",
            "4",
            "--out",
            p(folder),
        ]);
        with_file_size_limit(&mut command, 256 << 10);
        let result = command.output().unwrap();
        let error = stderr(&result);
        assert_eq!(result.status.code(), Some(1), "{error}");
        assert!(error.contains("File too large"), "{error}");
        assert!(temporaries(dir).is_empty(), "{:?}", temporaries(dir));
    }
    assert_eq!(snapshot(&sim), before);
    assert!(!dir.join("fresh").exists());
}

#[test]
fn temporaries_left_by_kill_9_go_with_the_next_run() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let (camera, target) = bench_scene(dir);
    let out = dir.join("out");
    previous_track_outputs(&out);
    let mut moments = Seeded(0x0c11_9e55);
    // track: killed outright while writing, its four temporaries stay, named with its process.
    let mut child = track_stdin(&camera, &target, &out, p(&out.join("poses.tum")))
        .spawn()
        .unwrap();
    let pid = child.id();
    let feeder = feed_forever(&mut child);
    std::thread::sleep(Duration::from_millis(moments.next_in(200, 800)));
    send(&child, libc::SIGKILL);
    let result = child.wait_with_output().unwrap();
    feeder.join().unwrap();
    assert_eq!(result.status.signal(), Some(libc::SIGKILL));
    let left = temporaries(&out);
    assert_eq!(left.len(), 4, "{left:?}");
    assert!(
        left.iter()
            .all(|t| t.to_string_lossy().contains(&format!(".{pid}."))),
        "{left:?}"
    );
    // The next run over the same outputs (half a second of measurements) succeeds and removes them.
    let mut child = track_stdin(&camera, &target, &out, p(&out.join("poses.tum")))
        .spawn()
        .unwrap();
    let mut stdin = child.stdin.take().unwrap();
    let mut text = String::from("t,id,u,v\n");
    for k in 0..2000u32 {
        let id = k % 16;
        let (c, r) = (f64::from(id % 4), f64::from(id / 4));
        text += &format!(
            "{},{id},{},{}\n",
            f64::from(k) / 4000.0,
            437.0 + 50.0 * c,
            437.0 + 50.0 * r
        );
    }
    stdin.write_all(text.as_bytes()).unwrap();
    drop(stdin);
    let result = wait_within(child, Duration::from_secs(20));
    assert!(result.status.success(), "{}", stderr(&result));
    assert!(temporaries(dir).is_empty(), "{:?}", temporaries(dir));
    // simulate: the same, for a folder's files.
    let sim = dir.join("sim");
    let child = long_simulation(&sim, "5").spawn().unwrap();
    until_writing(&sim);
    std::thread::sleep(Duration::from_millis(moments.next_in(0, 500)));
    send(&child, libc::SIGKILL);
    let result = child.wait_with_output().unwrap();
    assert_eq!(result.status.signal(), Some(libc::SIGKILL));
    assert!(!temporaries(&sim).is_empty());
    succeeded(&[
        "simulate",
        "--scenario",
        "spin",
        "--duration-s",
        "0.5",
        "--out",
        p(&sim),
    ]);
    assert!(temporaries(dir).is_empty(), "{:?}", temporaries(dir));
    // simulate --frames: every finished frame waits as a temporary until the commit, so a killed run leaves many;
    // the next run, shorter, or of measurements, removes them all.
    for next in [
        vec!["--frames", "--frame-count", "2"],
        vec!["--duration-s", "0.5"],
    ] {
        let child = roitrack()
            .args([
                "simulate",
                "--frames",
                "--frame-count",
                "5000",
                "--out",
                p(&sim),
            ])
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let frames = sim.join("frames");
        until_writing(&frames);
        std::thread::sleep(Duration::from_millis(moments.next_in(200, 600)));
        send(&child, libc::SIGKILL);
        assert_eq!(
            child.wait_with_output().unwrap().status.signal(),
            Some(libc::SIGKILL)
        );
        assert!(temporaries(&frames).len() > 2, "{:?}", temporaries(&frames));
        let mut args = vec!["simulate", "--scenario", "spin", "--out", p(&sim)];
        args.extend(next);
        succeeded(&args);
        assert!(temporaries(dir).is_empty(), "{:?}", temporaries(dir));
    }
}
