//! The outputs of a run as one set: nothing moves into place before the commit, a failed run changes nothing and
//! keeps only what it marked (under its partial name), no temporary is left behind, folders are replaced whole.
//! One test function: the output set is the process's, so its steps must not run beside each other.

use std::io::Write;
use std::path::Path;

use roitrack_formats::{
    AtomicFile, OutputDir, OutputSet, create_output_dir, keep_if_failed, partial_path,
    remove_at_commit,
};

fn write(path: &Path, text: &str) {
    let mut file = AtomicFile::create(path).unwrap();
    file.write_all(text.as_bytes()).unwrap();
    file.finish().unwrap();
}

fn names(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    names
}

#[test]
fn a_run_commits_all_its_outputs_or_none() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let (a, b, bag) = (dir.join("a.tum"), dir.join("b.csv"), dir.join("run.mcap"));
    for path in [&a, &b, &bag] {
        std::fs::write(path, "previous\n").unwrap();
    }

    // A run that fails after finishing two outputs: none moves, the marked one is kept under its partial name.
    let set = OutputSet::begin();
    write(&a, "new a\n");
    write(&bag, "partial bag\n");
    keep_if_failed(&bag);
    let unfinished = AtomicFile::create(&b).unwrap();
    assert_eq!(
        names(dir).len(),
        6,
        "three outputs and their three temporaries"
    );
    drop(unfinished);
    let kept = set.abandon();
    assert_eq!(kept, vec![partial_path(&bag)]);
    for path in [&a, &b, &bag] {
        assert_eq!(std::fs::read_to_string(path).unwrap(), "previous\n");
    }
    assert_eq!(
        std::fs::read_to_string(dir.join("run.partial.mcap")).unwrap(),
        "partial bag\n"
    );
    assert_eq!(
        names(dir),
        ["a.tum", "b.csv", "run.mcap", "run.partial.mcap"]
    );

    // A run that succeeds: everything moves at the commit, and a stale file of a previous run goes.
    let stale = dir.join("rois.bin");
    std::fs::write(&stale, "stale").unwrap();
    let set = OutputSet::begin();
    write(&a, "new a\n");
    write(&b, "new b\n");
    remove_at_commit(&stale).unwrap();
    assert_eq!(std::fs::read_to_string(&a).unwrap(), "previous\n");
    assert!(stale.exists());
    set.commit().unwrap();
    assert_eq!(std::fs::read_to_string(&a).unwrap(), "new a\n");
    assert_eq!(std::fs::read_to_string(&b).unwrap(), "new b\n");
    assert!(!stale.exists());

    // A folder written as a whole, in a folder the run creates: abandoned, both go; committed, it replaces the old.
    let out = dir.join("new").join("sim");
    let set = OutputSet::begin();
    create_output_dir(&out).unwrap();
    let frames = OutputDir::create(out.join("frames")).unwrap();
    write(&frames.path().join("frame_00000.png"), "x");
    frames.finish().unwrap();
    write(&out.join("camera.yaml"), "camera");
    drop(set);
    assert!(!dir.join("new").exists(), "{:?}", names(dir));
    let frames_path = dir.join("frames");
    std::fs::create_dir(&frames_path).unwrap();
    for k in 0..3 {
        std::fs::write(frames_path.join(format!("frame_{k:05}.png")), "old").unwrap();
    }
    let set = OutputSet::begin();
    let frames = OutputDir::create(&frames_path).unwrap();
    write(&frames.path().join("frame_00000.png"), "new");
    frames.finish().unwrap();
    assert_eq!(names(&frames_path).len(), 3);
    set.commit().unwrap();
    assert_eq!(names(&frames_path), ["frame_00000.png"]);
    assert_eq!(
        std::fs::read_to_string(frames_path.join("frame_00000.png")).unwrap(),
        "new"
    );
    assert_eq!(
        names(dir),
        ["a.tum", "b.csv", "frames", "run.mcap", "run.partial.mcap"]
    );

    // Ending at once: every temporary goes, and none can be created after.
    let _set = OutputSet::begin();
    let _open = AtomicFile::create(&a).unwrap();
    write(&b, "staged\n");
    roitrack_formats::remove_temporaries_before_exit();
    assert_eq!(
        names(dir),
        ["a.tum", "b.csv", "frames", "run.mcap", "run.partial.mcap"]
    );
    assert_eq!(std::fs::read_to_string(&b).unwrap(), "new b\n");
    std::mem::forget(_open);
    std::mem::forget(_set);
}
