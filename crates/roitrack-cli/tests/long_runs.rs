//! Long runs: an interrupted run leaves the previous output untouched (a soak run stays flat: tests/lab/soak.rs).

use std::io::Write;
use std::process::Command;
use std::time::Duration;

fn roitrack() -> Command {
    Command::new(env!("CARGO_BIN_EXE_roitrack"))
}

#[cfg(unix)]
#[test]
fn an_interrupted_run_leaves_the_previous_output() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let p = |name: &str| dir.join(name).to_str().unwrap().to_owned();
    let status = roitrack()
        .args([
            "target",
            "--out",
            &p("target.csv"),
            "--camera-out",
            &p("camera.yaml"),
        ])
        .status();
    assert!(status.unwrap().success());
    // A long static stream: the grid at rest, 2 million measurements (several seconds to track).
    let mut file = std::io::BufWriter::new(std::fs::File::create(dir.join("long.csv")).unwrap());
    writeln!(file, "t,id,u,v").unwrap();
    for k in 0..2_000_000u64 {
        let id = k % 16;
        let (c, r) = ((id % 4) as f64, (id / 4) as f64);
        // The grid 0.6 m away, facing the camera: 50 px pitch around the centre.
        writeln!(
            file,
            "{},{},{},{}",
            k as f64 / 4000.0,
            id,
            437.0 + 50.0 * c,
            437.0 + 50.0 * r
        )
        .unwrap();
    }
    drop(file);
    std::fs::write(dir.join("poses.tum"), "previous\n").unwrap();
    let mut child = roitrack()
        .args([
            "track",
            "--camera",
            &p("camera.yaml"),
            "--target",
            &p("target.csv"),
            "--measurements",
            &p("long.csv"),
            "--poses",
            &p("poses.tum"),
            "--twists",
            &p("twists.csv"),
        ])
        .spawn()
        .unwrap();
    std::thread::sleep(Duration::from_millis(400));
    assert!(
        child.try_wait().unwrap().is_none(),
        "the run ended before the interrupt: make the stream longer"
    );
    // SAFETY: sends SIGINT (Ctrl-C) to our own child process.
    unsafe {
        libc::kill(child.id() as libc::pid_t, libc::SIGINT);
    }
    let status = child.wait().unwrap();
    assert!(!status.success());
    assert_eq!(
        std::fs::read_to_string(dir.join("poses.tum")).unwrap(),
        "previous\n"
    );
    assert!(!dir.join("twists.csv").exists());
}
