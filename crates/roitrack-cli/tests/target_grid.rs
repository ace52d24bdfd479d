//! `roitrack target grid`: circle-grid targets written from the command line, next to the bundled target.

use std::path::Path;

use roitrack::core::Target;
use roitrack::core::target::{CircleGrid, GridLayout};

mod common;
use common::{fails, ok};

fn p(path: &Path) -> &str {
    path.to_str().unwrap()
}

#[test]
fn grid_writes_square_and_hexagonal_targets() {
    let tmp = tempfile::tempdir().unwrap();
    let hex = tmp.path().join("hex.csv");
    ok(&[
        "target",
        "grid",
        "--rows",
        "24",
        "--cols",
        "28",
        "--spacing-m",
        "0.012",
        "--diameter-m",
        "0.006",
        "--hexagonal",
        "--out",
        p(&hex),
    ]);
    let t = roitrack::formats::read_target_csv(&hex).unwrap();
    let spec = CircleGrid {
        rows: 24,
        cols: 28,
        spacing_m: 0.012,
        diameter_m: 0.006,
        layout: GridLayout::Hexagonal,
    };
    assert_eq!(t, Target::circle_grid(&spec).unwrap());
    assert_eq!(t.len(), 336);
    let last = t.points()[t.index_of(335).unwrap()];
    assert!((last.point_in_obj_m.x - 0.156).abs() < 1e-12);
    assert!((last.point_in_obj_m.y - 0.2390).abs() < 1e-4);
    assert_eq!(last.diameter_m, Some(0.006));

    let square = tmp.path().join("square.csv");
    ok(&[
        "target",
        "grid",
        "--rows",
        "6",
        "--cols",
        "6",
        "--spacing-m",
        "0.02",
        "--diameter-m",
        "0.01",
        "--out",
        p(&square),
    ]);
    let t = roitrack::formats::read_target_csv(&square).unwrap();
    assert_eq!(t.len(), 36);
    // id = row * cols + col at (col S, row S, 0): id 8 is row 1, column 2.
    let p8 = t.points()[t.index_of(8).unwrap()].point_in_obj_m;
    assert!((p8 - roitrack::nalgebra::Vector3::new(0.04, 0.02, 0.0)).norm() < 1e-15);
}

#[test]
fn grid_refuses_bad_specifications_and_writes_nothing() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("t.csv");
    let grid = |rows: &str, spacing: &str, diameter: &str| {
        fails(&[
            "target",
            "grid",
            "--rows",
            rows,
            "--cols",
            "5",
            "--spacing-m",
            spacing,
            "--diameter-m",
            diameter,
            "--out",
            p(&out),
        ])
    };
    let e = grid("4", "0.01", "0.012");
    assert!(
        e.contains("diameter") && e.contains("smaller than the spacing"),
        "{e}"
    );
    let e = grid("4", "-0.01", "0.005");
    assert!(
        e.contains("spacing must be a finite positive length"),
        "{e}"
    );
    let e = grid("0", "0.01", "0.005");
    assert!(e.contains("at least 1 row"), "{e}");
    let e = grid("1", "0.01", "0.005");
    assert!(e.contains("collinear"), "{e}");
    assert!(!out.exists());
    // The bundled target's options do not mix with the subcommand.
    let e = fails(&[
        "target",
        "--out",
        p(&out),
        "grid",
        "--rows",
        "4",
        "--cols",
        "4",
        "--spacing-m",
        "0.01",
        "--diameter-m",
        "0.005",
    ]);
    assert!(e.contains("cannot be used with"), "{e}");
    // Without the subcommand, --out is still required.
    assert!(fails(&["target"]).contains("--out"));
}

#[test]
fn the_bundled_target_is_still_written_by_name() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("grid4x4.csv");
    ok(&["target", "--name", "grid4x4", "--out", p(&out)]);
    assert_eq!(
        roitrack::formats::read_target_csv(&out).unwrap(),
        Target::grid4x4()
    );
}

#[test]
fn grid_help_explains_the_layouts_and_the_ids() {
    let help = ok(&["target", "grid", "--help"]);
    for words in [
        "--hexagonal",
        "row + col has the parity of rows - 1",
        "id 0",
        "row by row",
        "sin 60",
    ] {
        assert!(help.contains(words), "{words}: {help}");
    }
}
