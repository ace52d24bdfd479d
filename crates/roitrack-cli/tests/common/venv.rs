//! The Python of a virtual environment that scripts/setup-test-deps makes for a test (the ROS 2 bag readers, Cyclone
//! DDS, OpenCV), included with `#[path]` by the tests that run one: found, or the test is skipped, saying so, unless
//! the variable that requires it is set (as `.ci/run` does), when its absence is a failure.

use std::path::{Path, PathBuf};
use std::process::Command;

/// What a test needs of a virtual environment.
pub struct Venv<'a> {
    /// The variable naming the environment's folder, else `target/DEFAULT_DIR` of the workspace.
    pub dir_var: &'a str,
    pub default_dir: &'a str,
    /// The modules it must import (`import ...`).
    pub imports: &'a str,
    /// What is installed there, as the messages name it.
    pub what: &'a str,
    /// The variable that makes its absence a failure.
    pub require_var: &'a str,
}

/// The environment's Python, if it imports what the test needs; else `None` (the test is then skipped), or a
/// failure if `venv.require_var` is set.
pub fn python(venv: &Venv<'_>) -> Option<PathBuf> {
    let dir = std::env::var_os(venv.dir_var).map_or_else(
        || {
            Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("../../target")
                .join(venv.default_dir)
        },
        PathBuf::from,
    );
    let python = dir.join("bin/python");
    let ready = python.is_file()
        && Command::new(&python)
            .args(["-c", &format!("import {}", venv.imports)])
            .status()
            .is_ok_and(|s| s.success());
    if ready {
        return Some(python);
    }
    assert!(
        std::env::var_os(venv.require_var).is_none(),
        "{} is required ({} is set) but not in {}",
        venv.what,
        venv.require_var,
        dir.display()
    );
    eprintln!(
        "skipped: {} is not installed in {}; run scripts/setup-test-deps",
        venv.what,
        dir.display()
    );
    None
}
