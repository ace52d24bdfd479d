//! Programs run by hand, for the tests that need more than `common::ok` (a child to interrupt, pipes, a Python
//! script): the `roitrack` binary as a command, a simulated scene, a finished program checked, Ctrl-C (included by
//! the tests that use it with `#[path]`, not through `common`).

// Each test that includes this module uses some of it.
#![allow(dead_code)]

use std::path::Path;
use std::process::{Command, Output};

/// The `roitrack` binary, as a command to set up.
pub fn roitrack_command() -> Command {
    Command::new(env!("CARGO_BIN_EXE_roitrack"))
}

/// Asserts that a program ended with success (else fails showing its standard output and error) and returns its
/// standard output.
pub fn succeeded(out: Output) -> String {
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        out.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    stdout
}

/// `roitrack simulate ARGS --out OUT`: a simulated scene (camera.yaml, target.csv, measurements.csv, ...) in `out`.
pub fn simulate(out: &Path, args: &[&str]) {
    succeeded(
        roitrack_command()
            .arg("simulate")
            .args(args)
            .arg("--out")
            .arg(out)
            .output()
            .unwrap(),
    );
}

/// Sends SIGINT (Ctrl-C) to a child the test spawned.
#[cfg(unix)]
pub fn interrupt(child: &std::process::Child) {
    // SAFETY: sends SIGINT to the child we spawned.
    assert_eq!(
        unsafe { libc::kill(child.id() as libc::pid_t, libc::SIGINT) },
        0
    );
}
