//! Fault injection on the outputs: outputs that alias inputs (by another spelling of the path, a symbolic link, a hard
//! link) refused before anything is read or written, naming both; a run that fails leaves every previous output
//! byte-identical and no temporary; SIGINT, SIGTERM, SIGHUP sent at seeded random moments of long runs end them by
//! that signal, with the previous outputs as they were, no temporary, and the bag kept, readable, as
//! NAME.partial.mcap; a second signal ends a run at once; SIGPIPE and a closed standard output end a run that writes
//! `-` with a failure, never a silent success.

#![cfg(unix)]

#[path = "common/outputs.rs"]
mod outputs;

use outputs::*;
use std::os::unix::process::{CommandExt, ExitStatusExt};
use std::path::Path;
use std::process::{Child, Output, Stdio};
use std::time::{Duration, Instant};

fn run(args: &[&str]) -> Output {
    roitrack().args(args).output().unwrap()
}

/// Sends `signal` to `child` after `delay_ms`, and asserts that it ended by that signal; how it ended.
fn ended_by(child: Child, signal: i32, delay_ms: u64) -> Output {
    std::thread::sleep(Duration::from_millis(delay_ms));
    send(&child, signal);
    let result = child.wait_with_output().unwrap();
    assert_eq!(result.status.signal(), Some(signal), "{}", stderr(&result));
    result
}

#[test]
fn outputs_that_alias_inputs_are_refused_naming_both() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let (camera, target) = bench_scene(dir);
    let measurements = dir.join("m.csv");
    std::fs::write(&measurements, "t,id,u,v\n0,0,437,437\n").unwrap();
    let sub = dir.join("sub");
    std::fs::create_dir(&sub).unwrap();
    let symlink = dir.join("link.mcap");
    std::os::unix::fs::symlink(&measurements, &symlink).unwrap();
    let hard = sub.join("hard.mcap");
    std::fs::hard_link(&camera, &hard).unwrap();
    let before = snapshot(dir);
    let spelled = format!("{}/../m.csv", p(&sub));
    let track = |poses: &str, mcap: &str| {
        run(&[
            "track",
            "--camera",
            p(&camera),
            "--target",
            p(&target),
            "--measurements",
            p(&measurements),
            "--poses",
            poses,
            "--twists",
            p(&dir.join("twists.csv")),
            "--mcap",
            mcap,
        ])
    };
    let poses = dir.join("poses.tum");
    for (mcap, input) in [
        (p(&camera), "--camera"),
        (p(&target), "--target"),
        (spelled.as_str(), "--measurements"),
        (p(&symlink), "--measurements"),
        (p(&hard), "--camera"),
    ] {
        let out = track(p(&poses), mcap);
        let error = stderr(&out);
        assert!(!out.status.success(), "{error}");
        assert!(
            error.contains("the output --mcap is the input given as")
                && error.contains(input)
                && error.contains(mcap),
            "{mcap}: {error}"
        );
    }
    // Two outputs to one file, and the bag's partial name onto an output.
    let error = stderr(&track(p(&poses), p(&poses)));
    assert!(
        error.contains("--poses and --mcap would both write"),
        "{error}"
    );
    let error = stderr(&track(
        p(&dir.join("run.partial.mcap")),
        p(&dir.join("run.mcap")),
    ));
    assert!(
        error.contains("--poses and --mcap's partial bag would both write"),
        "{error}"
    );
    // simulate and demo: a file of the folder that is the camera given, through a hard link.
    std::fs::hard_link(&camera, dir.join("camera_link.yaml")).unwrap();
    let folder = dir.join("folder");
    std::fs::create_dir(&folder).unwrap();
    std::fs::hard_link(&camera, folder.join("camera.yaml")).unwrap();
    let before_folder = snapshot(dir);
    for command in ["simulate", "demo"] {
        let out = run(&[
            command,
            "--camera",
            p(&dir.join("camera_link.yaml")),
            "--out",
            p(&folder),
        ]);
        let error = stderr(&out);
        assert!(
            !out.status.success()
                && error.contains("the output --out's camera.yaml is the input given as --camera"),
            "{command}: {error}"
        );
    }
    let error = stderr(&run(&[
        "demo",
        "--target",
        p(&target),
        "--mcap",
        p(&target),
        "--out",
        p(&folder),
    ]));
    assert!(
        error.contains("the output --mcap is the input given as --target"),
        "{error}"
    );
    // detect: two images of one name would share an overlay.
    let other = sub.join("camera.yaml");
    std::fs::write(&other, "x").unwrap();
    let error = stderr(&run(&[
        "detect",
        "--camera",
        p(&camera),
        "--target",
        p(&target),
        "--overlay",
        p(&dir.join("overlays")),
        p(&camera),
        p(&other),
    ]));
    assert!(error.contains("would both write"), "{error}");
    assert!(!dir.join("overlays").exists());
    // Nothing was read as an output or written: every input and previous file is byte-identical.
    let mut after = snapshot(dir);
    after.remove(&other);
    assert_eq!(after, before_folder);
    assert!(
        before
            .iter()
            .all(|(path, bytes)| after.get(path) == Some(bytes))
    );
    assert!(temporaries(dir).is_empty());
}

#[test]
fn a_failed_run_changes_no_output_and_leaves_no_temporary() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let sim = dir.join("sim");
    succeeded(&["simulate", "--scenario", "spin", "--out", p(&sim)]);
    let out = dir.join("out");
    previous_outputs(&out);
    let text = std::fs::read_to_string(sim.join("measurements.csv")).unwrap();
    let track = |measurements: &Path| {
        roitrack()
            .args(track_into(
                &sim.join("camera.yaml"),
                &sim.join("target.csv"),
                measurements,
                &out,
            ))
            .output()
            .unwrap()
    };
    let before = snapshot(&out);
    // Times in milliseconds, the commonest mistake: refused, nothing changed, no partial bag (no estimate).
    let in_ms: String = text
        .lines()
        .enumerate()
        .map(|(k, line)| match (k, line.split_once(',')) {
            (0, _) | (_, None) => format!("{line}\n"),
            (_, Some((t, rest))) => format!("{},{rest}\n", t.parse::<f64>().unwrap() * 1e3),
        })
        .collect();
    std::fs::write(dir.join("ms.csv"), in_ms).unwrap();
    let result = track(&dir.join("ms.csv"));
    assert!(!result.status.success());
    assert!(stderr(&result).contains("ms.csv"), "{}", stderr(&result));
    assert_eq!(snapshot(&out), before);
    // A row broken near the end: the error comes after thousands of estimates. The outputs stay as they were; the
    // bag up to the last estimate is kept, readable, under its own name.
    let mut broken: Vec<&str> = text.lines().collect();
    let last = broken.len() - 10;
    broken[last] = "not,a,row,here";
    std::fs::write(dir.join("broken.csv"), broken.join("\n") + "\n").unwrap();
    let result = track(&dir.join("broken.csv"));
    let error = stderr(&result);
    assert!(!result.status.success(), "{error}");
    assert!(
        error.contains("broken.csv") && error.contains("run.partial.mcap"),
        "{error}"
    );
    assert_kept_with_partial_bag(&out, &before, &error);
    assert!(temporaries(dir).is_empty(), "{:?}", temporaries(dir));
    // The same run on good measurements replaces them all.
    let result = track(&sim.join("measurements.csv"));
    assert!(result.status.success(), "{}", stderr(&result));
    assert!(std::fs::read(out.join("poses.tum")).unwrap().len() > 1000);
    assert!(temporaries(dir).is_empty());
}

#[test]
fn signals_at_random_moments_keep_the_previous_outputs_and_the_partial_bag() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let (camera, target) = bench_scene(dir);
    let out = dir.join("out");
    let mut moments = Seeded(0x05ee_d0f5_19a1);
    for signal in [
        libc::SIGTERM,
        libc::SIGINT,
        libc::SIGHUP,
        libc::SIGTERM,
        libc::SIGINT,
        libc::SIGHUP,
    ] {
        previous_track_outputs(&out);
        let before = snapshot(&out);
        let delay_ms = moments.next_in(150, 900);
        let result = track_signalled(&camera, &target, &out, signal, delay_ms);
        let error = stderr(&result);
        assert_eq!(result.status.signal(), Some(signal), "{error}");
        assert!(error.contains("interrupted"), "{error}");
        assert_kept_with_partial_bag(
            &out,
            &before,
            &format!("signal {signal} at {delay_ms} ms: {error}"),
        );
        assert!(temporaries(dir).is_empty(), "{:?}", temporaries(dir));
    }
}

#[test]
fn a_second_signal_ends_the_run_at_once_without_temporaries() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let (camera, target) = bench_scene(dir);
    let out = dir.join("out");
    previous_outputs(&out);
    let before = snapshot(&out);
    // Waiting for measurements that do not come: the first signal is noted, but the run never reaches its next
    // estimate.
    let (mut child, _stdin) = track_waiting(&camera, &target, &out);
    send(&child, libc::SIGINT);
    std::thread::sleep(Duration::from_millis(300));
    assert!(
        child.try_wait().unwrap().is_none(),
        "the first signal waits for the next estimate"
    );
    send(&child, libc::SIGTERM);
    let start = Instant::now();
    let status = child.wait().unwrap();
    assert!(start.elapsed() < Duration::from_secs(2));
    assert_eq!(status.signal(), Some(libc::SIGTERM));
    assert!(temporaries(dir).is_empty(), "{:?}", temporaries(dir));
    assert_eq!(snapshot(&out), before);
}

#[test]
fn a_reader_gone_or_a_closed_standard_output_fails_the_run() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let (camera, target) = bench_scene(dir);
    let out = dir.join("out");
    previous_outputs(&out);
    let before = snapshot(&out);
    // The poses to a pipe whose reader goes away: the run ends by SIGPIPE, quietly, changing nothing.
    let mut child = track_stdin(&camera, &target, &out, "-")
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    let feeder = feed_forever(&mut child);
    let mut stdout = child.stdout.take().unwrap();
    let mut first = [0u8; 4096];
    std::io::Read::read_exact(&mut stdout, &mut first).unwrap();
    drop(stdout);
    let result = child.wait_with_output().unwrap();
    feeder.join().unwrap();
    assert_eq!(
        result.status.signal(),
        Some(libc::SIGPIPE),
        "{}",
        stderr(&result)
    );
    assert!(!stderr(&result).contains("error"), "{}", stderr(&result));
    let mut after = snapshot(&out);
    after.remove(&out.join("run.partial.mcap"));
    assert_eq!(after, before);
    assert!(temporaries(dir).is_empty());
    // The standard output closed (`>&-`): refused, not written to nowhere with success.
    let mut command = track_stdin(&camera, &target, &out, "-");
    // SAFETY: only closes a file descriptor in the child before it runs roitrack.
    unsafe {
        command.pre_exec(|| {
            libc::close(1);
            Ok(())
        });
    }
    let result = command
        .stdout(Stdio::inherit())
        .stdin(Stdio::null())
        .output()
        .unwrap();
    assert_eq!(result.status.code(), Some(1));
    assert!(
        stderr(&result).contains("the standard output is closed"),
        "{}",
        stderr(&result)
    );
    assert!(temporaries(dir).is_empty());
}

#[test]
fn interrupted_simulate_and_demo_leave_their_previous_folders() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let mut moments = Seeded(0xf01d_e125);
    // simulate --frames: the previous folder (a shorter run) byte-identical after SIGTERM while rendering.
    let sim = dir.join("sim");
    succeeded(&[
        "simulate",
        "--frames",
        "--frame-count",
        "6",
        "--out",
        p(&sim),
    ]);
    let before = snapshot(&sim);
    let child = roitrack()
        .args(["simulate", "--frames", "--seed", "2", "--out", p(&sim)])
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    ended_by(child, libc::SIGTERM, moments.next_in(300, 1200));
    assert_eq!(snapshot(&sim), before);
    assert!(temporaries(dir).is_empty(), "{:?}", temporaries(dir));
    // demo --mcap: SIGHUP during its runs stops it after the current one; its folder stays as it was, and the bag
    // of the default estimator's run is kept, readable.
    let demo = dir.join("demo");
    let bag = dir.join("demo.mcap");
    succeeded(&["demo", "--out", p(&demo), "--mcap", p(&bag)]);
    let before = snapshot(&demo);
    let bag_before = std::fs::read(&bag).unwrap();
    let child = roitrack()
        .args(["demo", "--seed", "3", "--out", p(&demo), "--mcap", p(&bag)])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let result = ended_by(child, libc::SIGHUP, moments.next_in(1200, 1800));
    assert_eq!(snapshot(&demo), before);
    assert_eq!(std::fs::read(&bag).unwrap(), bag_before);
    assert!(
        bag_is_readable(&dir.join("demo.partial.mcap")),
        "{}",
        stderr(&result)
    );
    assert!(temporaries(dir).is_empty(), "{:?}", temporaries(dir));
}
