//! The lab's studies on a rig of one's own (as `demo` in tests/own_rig.rs): `lab compare` and `lab tradeoff` take the
//! rig's options, `lab compare --sweep` refuses them.

use std::path::Path;

use crate::common::{fails, ok};
use crate::rig::FISHEYE_YAML;

fn p(path: &Path) -> &str {
    path.to_str().unwrap()
}

#[test]
fn compare_and_tradeoff_take_the_rig() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let camera = dir.join("fisheye.yaml");
    std::fs::write(&camera, FISHEYE_YAML).unwrap();
    let target = dir.join("grid.csv");
    ok(&[
        "target",
        "grid",
        "--rows",
        "4",
        "--cols",
        "5",
        "--spacing-m",
        "0.025",
        "--diameter-m",
        "0.01",
        "--out",
        p(&target),
    ]);
    let table = ok(&[
        "lab",
        "compare",
        "--scenario",
        "random",
        "--camera",
        p(&camera),
        "--target",
        p(&target),
        "--distance-m",
        "1.0",
        "--duration-s",
        "1.5",
    ]);
    assert!(
        table.contains("kalman (default)") && table.contains("batch baseline"),
        "{table}"
    );
    let tradeoff = dir.join("tradeoff");
    ok(&[
        "lab",
        "tradeoff",
        "--scenario",
        "random",
        "--camera",
        p(&camera),
        "--target",
        p(&target),
        "--distance-m",
        "1.0",
        "--duration-s",
        "1.0",
        "--out",
        p(&tradeoff),
    ]);
    assert!(tradeoff.join("tradeoff.csv").is_file() && tradeoff.join("tradeoff.svg").is_file());
    let err = fails(&[
        "lab",
        "compare",
        "--sweep",
        "--quick",
        "--target",
        p(&target),
    ]);
    assert!(err.contains("--sweep"), "{err}");
}
