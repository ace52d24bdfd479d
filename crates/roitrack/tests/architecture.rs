//! The architecture of docs/architecture.md, checked: which crate may depend on which, the pure math free of I/O and
//! threads, the simulator out of the image side, and the command-line tool a thin shell (its sources at most 15 % of
//! the workspace's).

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

/// Each workspace crate and the roitrack crates it may depend on (docs/architecture.md).
const ALLOWED: &[(&str, &[&str])] = &[
    ("roitrack-core", &[]),
    ("roitrack-estimators", &["roitrack-core"]),
    // The image side, on any camera's pixels; the simulator that renders them is in roitrack-sim, which depends on it.
    ("roitrack-image", &["roitrack-core"]),
    (
        "roitrack-formats",
        &["roitrack-core", "roitrack-estimators", "roitrack-image"],
    ),
    (
        "roitrack-sim",
        &["roitrack-core", "roitrack-estimators", "roitrack-image"],
    ),
    ("roitrack-eval", &["roitrack-core", "roitrack-estimators"]),
    (
        "roitrack-plot",
        &["roitrack-core", "roitrack-estimators", "roitrack-eval"],
    ),
    (
        "roitrack-detect",
        &["roitrack-core", "roitrack-estimators", "roitrack-image"],
    ),
    (
        "roitrack-pipeline",
        &[
            "roitrack-core",
            "roitrack-estimators",
            "roitrack-image",
            "roitrack-detect",
        ],
    ),
    (
        "roitrack-demo",
        &[
            "roitrack-core",
            "roitrack-estimators",
            "roitrack-image",
            "roitrack-sim",
            "roitrack-eval",
            "roitrack-pipeline",
            "roitrack-plot",
        ],
    ),
    (
        "roitrack-experiments",
        &[
            "roitrack-core",
            "roitrack-estimators",
            "roitrack-image",
            "roitrack-sim",
            "roitrack-eval",
            "roitrack-pipeline",
            "roitrack-plot",
            "roitrack-demo",
        ],
    ),
    (
        "roitrack-bench",
        &[
            "roitrack-core",
            "roitrack-estimators",
            "roitrack-image",
            "roitrack-sim",
            "roitrack-pipeline",
        ],
    ),
    (
        "roitrack-ros",
        &[
            "roitrack-core",
            "roitrack-estimators",
            "roitrack-image",
            "roitrack-formats",
        ],
    ),
    (
        "roitrack-servo",
        &[
            "roitrack-core",
            "roitrack-estimators",
            "roitrack-image",
            "roitrack-sim",
            "roitrack-formats",
            "roitrack-pipeline",
            "roitrack-plot",
        ],
    ),
    (
        "roitrack",
        &[
            "roitrack-core",
            "roitrack-estimators",
            "roitrack-image",
            "roitrack-sim",
            "roitrack-eval",
            "roitrack-formats",
            "roitrack-detect",
            "roitrack-pipeline",
            "roitrack-plot",
            "roitrack-demo",
            "roitrack-experiments",
            "roitrack-bench",
            "roitrack-ros",
            "roitrack-servo",
        ],
    ),
    (
        "roitrack-genicam",
        &[
            "roitrack-core",
            "roitrack-estimators",
            "roitrack-image",
            "roitrack-sim",
            "roitrack-pipeline",
        ],
    ),
    // roitrack-genicam with the feature genicam only, roitrack-ros (for its feature ros2) with the feature ros2 only.
    (
        "roitrack-cli",
        &["roitrack", "roitrack-genicam", "roitrack-ros"],
    ),
    ("roitrack-python", &["roitrack"]),
    ("roitrack-testkit", &[]),
];

fn crates_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// The roitrack crates in the `[dependencies]` tables (not dev-dependencies) of a manifest.
fn roitrack_dependencies(manifest: &str) -> BTreeSet<String> {
    dependencies(manifest)
        .into_iter()
        .filter(|name| name == "roitrack" || name.starts_with("roitrack-"))
        .collect()
}

/// Every crate in the `[dependencies]` tables (not dev-dependencies) of a manifest.
fn dependencies(manifest: &str) -> BTreeSet<String> {
    let mut deps = BTreeSet::new();
    let mut in_dependencies = false;
    for line in manifest.lines().map(str::trim) {
        if line.starts_with('[') {
            in_dependencies = line == "[dependencies]"
                || (line.starts_with("[target.") && line.ends_with(".dependencies]"));
            continue;
        }
        if !in_dependencies {
            continue;
        }
        let name = line.split(['=', '.', ' ']).next().unwrap_or("");
        if !name.is_empty() && !name.starts_with('#') {
            deps.insert(name.to_string());
        }
    }
    deps
}

#[test]
fn every_crate_depends_only_on_what_the_architecture_allows() {
    let mut seen = BTreeSet::new();
    for entry in std::fs::read_dir(crates_dir()).unwrap() {
        let manifest_path = entry.unwrap().path().join("Cargo.toml");
        let Ok(manifest) = std::fs::read_to_string(&manifest_path) else {
            continue;
        };
        let name = manifest
            .lines()
            .find_map(|l| l.trim().strip_prefix("name = \""))
            .and_then(|rest| rest.strip_suffix('"'))
            .expect("a package name")
            .to_string();
        let (_, allowed) = ALLOWED
            .iter()
            .find(|(crate_name, _)| *crate_name == name)
            .unwrap_or_else(|| panic!("{name} is not in docs/architecture.md's table"));
        for dependency in roitrack_dependencies(&manifest) {
            assert!(
                allowed.contains(&dependency.as_str()),
                "{name} depends on {dependency}, which docs/architecture.md does not allow"
            );
        }
        seen.insert(name);
    }
    assert_eq!(seen.len(), ALLOWED.len(), "crates found: {seen:?}");
}

/// The simulator (the renderer, the sensor's noise, the simulated camera) is in roitrack-sim: roitrack-image, what
/// runs on a real camera's pixels, needs no random numbers outside its tests.
#[test]
fn the_image_side_holds_no_simulator() {
    let manifest = std::fs::read_to_string(crates_dir().join("roitrack-image/Cargo.toml")).unwrap();
    let deps = dependencies(&manifest);
    assert!(deps.contains("roitrack-core"), "{deps:?}");
    for random in ["rand", "rand_chacha", "rand_distr"] {
        assert!(
            !deps.contains(random),
            "roitrack-image depends on {random}: the simulator belongs in roitrack-sim"
        );
    }
}

/// Every `.rs` file under `dir`, recursively.
fn rust_files(dir: &Path) -> Vec<PathBuf> {
    let mut files = Vec::new();
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            files.extend(rust_files(&path));
        } else if path.extension().is_some_and(|e| e == "rs") {
            files.push(path);
        }
    }
    files
}

#[test]
fn the_pure_math_has_no_io_and_no_threads() {
    let forbidden = [
        "std::fs",
        "std::io",
        "std::net",
        "std::thread",
        "std::process",
        "std::env",
    ];
    for pure_math in ["roitrack-core", "roitrack-estimators"] {
        for file in rust_files(&crates_dir().join(pure_math).join("src")) {
            let text = std::fs::read_to_string(&file).unwrap();
            for path in forbidden {
                assert!(
                    !text.contains(path),
                    "{} uses {path}: {pure_math} is the pure math, without I/O or threads",
                    file.display()
                );
            }
        }
    }
}

fn lines(files: &[PathBuf]) -> usize {
    files
        .iter()
        .map(|f| std::fs::read_to_string(f).unwrap().lines().count())
        .sum()
}

#[test]
fn the_command_line_tool_is_a_thin_shell() {
    let mut all = Vec::new();
    for entry in std::fs::read_dir(crates_dir()).unwrap() {
        let src = entry.unwrap().path().join("src");
        if src.is_dir() {
            all.extend(rust_files(&src));
        }
    }
    let cli = rust_files(&crates_dir().join("roitrack-cli/src"));
    let (cli_lines, all_lines) = (lines(&cli), lines(&all));
    let share = cli_lines as f64 / all_lines as f64;
    assert!(
        share <= 0.15,
        "the CLI's sources are {cli_lines} of the workspace's {all_lines} source lines ({:.1} %): move the work into the library",
        100.0 * share
    );
}
