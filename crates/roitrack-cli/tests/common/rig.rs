//! A rig of one's own, shared by the tests that run on it.

/// A 1280 x 1024 fisheye camera (OpenCV's cv::fisheye model), as OpenCV's FileStorage writes it.
pub const FISHEYE_YAML: &str = "%YAML:1.0\n---\nimage_width: 1280\nimage_height: 1024\ncamera_matrix: !!opencv-matrix\n   \
    rows: 3\n   cols: 3\n   dt: d\n   data: [ 900., 0., 639.5, 0., 900., 511.5, 0., 0., 1. ]\n\
    distortion_model: equidistant\n\
    distortion_coefficients: !!opencv-matrix\n   rows: 1\n   cols: 4\n   dt: d\n   data: [ 0.05, -0.01, 0.002, 0. ]\n";

/// Writes the fisheye camera (`fisheye.yaml`) and a plain 4 x 5 grid of 10 mm dots 25 mm apart (`grid.csv`, made
/// by `roitrack target grid`) into `dir`; returns their paths (camera, target).
pub fn fisheye_camera_and_grid(dir: &std::path::Path) -> (std::path::PathBuf, std::path::PathBuf) {
    let camera = dir.join("fisheye.yaml");
    std::fs::write(&camera, FISHEYE_YAML).unwrap();
    let target = dir.join("grid.csv");
    crate::common::ok(&[
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
        target.to_str().unwrap(),
    ]);
    (camera, target)
}
