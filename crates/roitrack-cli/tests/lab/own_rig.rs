//! The lab's studies on a rig of one's own (as `demo` in tests/own_rig.rs): `lab compare` and `lab tradeoff` take the
//! rig's options, `lab compare --sweep` refuses them.

use std::path::Path;

use crate::common::{fails, ok};
use crate::rig::fisheye_camera_and_grid;

fn p(path: &Path) -> &str {
    path.to_str().unwrap()
}

#[test]
fn compare_and_tradeoff_take_the_rig() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let (camera, target) = fisheye_camera_and_grid(dir);
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
