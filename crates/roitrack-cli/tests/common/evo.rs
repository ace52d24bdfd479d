//! evo (installed by scripts/setup-test-deps into the venv named by ROITRACK_EVO_VENV), for the tests that check
//! `roitrack eval` against `evo_ape`.

use std::path::{Path, PathBuf};
use std::process::Command;

/// The evo virtual environment, or `None` (with a message) where it is not installed; under CI a missing evo is a
/// failure.
pub fn venv() -> Option<PathBuf> {
    let venv = std::env::var_os("ROITRACK_EVO_VENV").map(PathBuf::from);
    let found = venv.filter(|v| v.join("bin/evo_ape").is_file());
    if found.is_none() {
        assert!(
            std::env::var_os("CI").is_none(),
            "CI must provide evo (ROITRACK_EVO_VENV)"
        );
        eprintln!(
            "skipped: evo not installed; run scripts/setup-test-deps and set ROITRACK_EVO_VENV"
        );
    }
    found
}

/// `evo_ape tum TRUTH ESTIMATE FLAGS...`'s translation RMSE (m); its results are saved in `dir`.
pub fn ape_rmse_m(venv: &Path, dir: &Path, truth: &Path, estimate: &Path, flags: &[&str]) -> f64 {
    let results = dir.join(format!("ape{}.zip", flags.join("").replace('-', "_")));
    let out = Command::new(venv.join("bin/evo_ape"))
        .args(["tum".as_ref(), truth.as_os_str(), estimate.as_os_str()])
        .args(flags)
        .args([
            "--save_results".as_ref(),
            results.as_os_str(),
            "--no_warnings".as_ref(),
        ])
        .env("HOME", dir)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "evo_ape failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let script = "import json, sys, zipfile; print(json.load(zipfile.ZipFile(sys.argv[1]).open('stats.json'))['rmse'])";
    let out = Command::new(venv.join("bin/python"))
        .args(["-c".as_ref(), script.as_ref(), results.as_os_str()])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout)
        .unwrap()
        .trim()
        .parse()
        .unwrap()
}
