//! `roitrack detect` end to end on synthetic photographs (`roitrack::sim::photo`) written as PNG files: the JSON line
//! of each image against the truth, the overlay, images that cannot be used (each reported, the others still
//! detected, the exit status non-zero), symmetric grids written by `roitrack target grid`, and a target file too small
//! to identify.

use std::path::Path;

use roitrack::math::target::{CircleGrid, GridLayout};
use roitrack::math::{CameraModel, Target, so3};
use roitrack::nalgebra::{Quaternion, Rotation3, UnitQuaternion, Vector3};
use roitrack::sim::photo::{CircleShade, PhotoScene, RenderedPhoto, render_photo};

mod common;
use common::{fails, ok, roitrack};

fn p(path: &Path) -> &str {
    path.to_str().unwrap()
}

/// Writes the photograph as a grey PNG of its bit depth (8 or 16).
fn write_png(path: &Path, photo: &RenderedPhoto) {
    let f = &photo.frame;
    match f.bit_depth {
        8 => {
            let bytes: Vec<u8> = f.pixels.iter().map(|&v| v as u8).collect();
            image::GrayImage::from_raw(f.width, f.height, bytes)
                .unwrap()
                .save(path)
                .unwrap();
        }
        16 => {
            image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::from_raw(
                f.width,
                f.height,
                f.pixels.clone(),
            )
            .unwrap()
            .save(path)
            .unwrap();
        }
        other => panic!("bit depth {other}"),
    }
}

/// A 1024 x 768 camera with some barrel distortion.
fn camera() -> CameraModel {
    CameraModel::new(
        "detect_test",
        1024,
        768,
        roitrack::math::camera::PinholeIntrinsics {
            fx_px: 1200.0,
            fy_px: 1200.0,
            skew_px: 0.0,
            cx_px: 515.0,
            cy_px: 380.0,
        },
        roitrack::math::camera::PlumbBob::from_coefficients([-0.15, 0.08, 5e-4, -3e-4, 0.0]),
    )
    .unwrap()
}

fn tilt(deg: f64, axis_deg: f64, roll_deg: f64) -> Rotation3<f64> {
    let a = axis_deg.to_radians();
    let axis = roitrack::nalgebra::Unit::new_normalize(Vector3::new(a.cos(), a.sin(), 0.0));
    Rotation3::from_axis_angle(&axis, deg.to_radians())
        * Rotation3::from_axis_angle(&Vector3::z_axis(), roll_deg.to_radians())
}

fn lines(stdout: &str) -> Vec<serde_json::Value> {
    stdout
        .lines()
        .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("{e}: {l}")))
        .collect()
}

fn num(v: &serde_json::Value, key: &str) -> f64 {
    v[key].as_f64().unwrap_or_else(|| panic!("{key} in {v}"))
}

fn vector(v: &serde_json::Value, key: &str) -> Vec<f64> {
    v[key]
        .as_array()
        .unwrap_or_else(|| panic!("{key} in {v}"))
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}

/// Checks a successful JSON line against the scene: every point within a pixel of the truth centre of its id, the
/// pose within 1 % of the distance and half a degree.
fn check_found(
    line: &serde_json::Value,
    scene: &PhotoScene,
    photo: &RenderedPhoto,
    polarity: &str,
) {
    assert_eq!(line["ok"], true, "{line}");
    assert_eq!(line["polarity"], polarity, "{line}");
    assert_eq!(line["ambiguous"], false, "{line}");
    let points = line["points"].as_array().unwrap();
    assert_eq!(points.len(), scene.target.len(), "{line}");
    for point in points {
        let id = point["id"].as_u64().unwrap() as u32;
        let truth = photo.truth[scene.target.index_of(id).unwrap()]
            .centre_px
            .unwrap();
        let (u, v) = (num(point, "u_px"), num(point, "v_px"));
        let error = ((u - truth.x).powi(2) + (v - truth.y).powi(2)).sqrt();
        assert!(error < 1.0, "point {id}: {error:.3} px off");
    }
    let t = vector(line, "cam_t_obj_m");
    let t = Vector3::new(t[0], t[1], t[2]);
    let position = (t - scene.cam_t_obj_m).norm() / scene.cam_t_obj_m.norm();
    let q = vector(line, "cam_q_obj_xyzw");
    let q = UnitQuaternion::from_quaternion(Quaternion::new(q[3], q[0], q[1], q[2]));
    let rotation = so3::angle_between(&q.to_rotation_matrix(), &scene.cam_r_obj).to_degrees();
    assert!(
        position < 0.01 && rotation < 0.5,
        "pose off by {:.3} % and {rotation:.3} deg",
        100.0 * position
    );
    let rms = num(line, "residual_rms_px");
    assert!((0.0..0.5).contains(&rms), "residual {rms}");
    assert!(num(line, "time_ms") > 0.0);
    assert_eq!(line["missing"], 0);
    assert!(line["blobs"].as_u64().unwrap() >= scene.target.len() as u64);
    eprintln!(
        "{}: pose {:.4} % {rotation:.4} deg, rms {rms:.3} px, {:.0} ms",
        line["image"],
        100.0 * position,
        num(line, "time_ms")
    );
}

#[test]
fn detect_reports_every_image_as_json_and_draws_overlays() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let camera = camera();
    let target = Target::grid4x4();
    let camera_path = dir.join("camera.yaml");
    let target_path = dir.join("target.csv");
    roitrack::formats::write_camera_yaml(&camera_path, &camera).unwrap();
    roitrack::formats::write_target_csv(&target_path, &target).unwrap();

    // Printed circles in a cluttered, unevenly lit scene (8 bits), and bright circles on black (16 bits).
    // (Seed 1 puts two blobs of a board mark on the grid's lattice, which hides the target: see
    // `stray_blobs_on_the_lattice_beyond_the_target_do_not_hide_it` in roitrack-pipeline's tests/photographs.rs.)
    let dark = PhotoScene::facing(camera.clone(), target.clone(), 0.45, tilt(35.0, 60.0, 20.0))
        .harsh()
        .with_seed(2);
    let bright = PhotoScene::facing(
        camera.clone(),
        target.clone(),
        0.5,
        tilt(25.0, -30.0, 200.0),
    )
    .harsh()
    .with_shade(CircleShade::BrightOnDark)
    .with_bit_depth(16)
    .with_seed(2);
    let (dark_photo, bright_photo) = (render_photo(&dark).unwrap(), render_photo(&bright).unwrap());
    let dark_png = dir.join("dark.png");
    let bright_png = dir.join("bright.png");
    write_png(&dark_png, &dark_photo);
    write_png(&bright_png, &bright_photo);
    // Images that cannot be used: not an image, no file, the wrong size.
    let broken = dir.join("broken.png");
    std::fs::write(&broken, b"\x89PNG\r\n\x1a\nnot really a png").unwrap();
    let missing = dir.join("missing.png");
    let small = dir.join("small.png");
    image::GrayImage::new(64, 48).save(&small).unwrap();

    let overlays = dir.join("overlays");
    let args = [
        "detect",
        "--camera",
        p(&camera_path),
        "--target",
        p(&target_path),
        "--json",
        "--overlay",
        p(&overlays),
        p(&dark_png),
        p(&broken),
        p(&missing),
        p(&small),
        p(&bright_png),
    ];
    let out = roitrack(&args);
    let stdout = String::from_utf8(out.stdout).unwrap();
    let stderr = String::from_utf8(out.stderr).unwrap();
    assert!(!out.status.success(), "three images failed: {stdout}");
    assert!(
        stderr.contains("3 of 5 images"),
        "standard error: {stderr}, standard output: {stdout}"
    );
    let json = lines(&stdout);
    assert_eq!(json.len(), 5, "{stdout}");
    for (line, path) in json
        .iter()
        .zip([&dark_png, &broken, &missing, &small, &bright_png])
    {
        assert_eq!(line["image"], p(path), "{line}");
    }
    check_found(&json[0], &dark, &dark_photo, "dark");
    check_found(&json[4], &bright, &bright_photo, "bright");
    for (line, name) in json[1..4]
        .iter()
        .zip(["broken.png", "missing.png", "small.png"])
    {
        assert_eq!(line["ok"], false, "{line}");
        let error = line["error"].as_str().unwrap();
        assert!(error.contains(name), "{error}");
        assert!(num(line, "time_ms") >= 0.0);
        assert!(line.get("points").is_none(), "{line}");
    }
    assert!(
        json[3]["error"].as_str().unwrap().contains("64 x 48"),
        "{}",
        json[3]
    );

    // An overlay per image found, of the image's size; none for the others.
    let mut written: Vec<String> = std::fs::read_dir(&overlays)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    written.sort();
    assert_eq!(written, ["bright.png.overlay.png", "dark.png.overlay.png"]);
    for name in &written {
        let overlay = image::open(overlays.join(name)).unwrap();
        assert_eq!((overlay.width(), overlay.height()), (1024, 768), "{name}");
    }

    // The table: one row per image, success.
    let table = ok(&[
        "detect",
        "--camera",
        p(&camera_path),
        "--target",
        p(&target_path),
        "--polarity",
        "dark",
        p(&dark_png),
    ]);
    let row = table.lines().nth(1).unwrap();
    assert!(
        row.contains("dark.png") && row.contains(" 16 ") && row.contains("found"),
        "{table}"
    );
    // The wrong polarity forced: not found, said so.
    let out = roitrack(&[
        "detect",
        "--camera",
        p(&camera_path),
        "--target",
        p(&target_path),
        "--polarity",
        "bright",
        "--json",
        p(&dark_png),
    ]);
    assert!(!out.status.success());
    let json = lines(&String::from_utf8(out.stdout).unwrap());
    assert_eq!(json[0]["ok"], false, "{}", json[0]);
    assert!(
        json[0]["error"].as_str().unwrap().contains("dark.png"),
        "{}",
        json[0]
    );
}

/// Hexagonal grids written by `roitrack target grid`: 6 x 10 has a half-turn symmetry (found, flagged ambiguous,
/// the labelling the truth's or its half turn), 6 x 9 has none (found with the true labels).
#[test]
fn detect_finds_hexagonal_grids_written_by_target_grid() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let camera = camera();
    let camera_path = dir.join("camera.yaml");
    roitrack::formats::write_camera_yaml(&camera_path, &camera).unwrap();
    for (cols, symmetric) in [(10u32, true), (9, false)] {
        let target_path = dir.join(format!("hex{cols}.csv"));
        ok(&[
            "target",
            "grid",
            "--rows",
            "6",
            "--cols",
            &cols.to_string(),
            "--spacing-m",
            "0.03",
            "--diameter-m",
            "0.015",
            "--hexagonal",
            "--out",
            p(&target_path),
        ]);
        let target = Target::circle_grid(&CircleGrid {
            rows: 6,
            cols,
            spacing_m: 0.03,
            diameter_m: 0.015,
            layout: GridLayout::Hexagonal,
        })
        .unwrap();
        assert_eq!(
            roitrack::formats::read_target_csv(&target_path).unwrap(),
            target
        );
        let scene =
            PhotoScene::facing(camera.clone(), target.clone(), 0.6, tilt(30.0, 100.0, 30.0))
                .harsh()
                .with_seed(3);
        let photo = render_photo(&scene).unwrap();
        let png = dir.join(format!("hex{cols}.png"));
        write_png(&png, &photo);
        let stdout = ok(&[
            "detect",
            "--camera",
            p(&camera_path),
            "--target",
            p(&target_path),
            "--json",
            p(&png),
        ]);
        let line = &lines(&stdout)[0];
        if !symmetric {
            check_found(line, &scene, &photo, "dark");
            continue;
        }
        assert_eq!(line["ok"], true, "{line}");
        assert_eq!(line["ambiguous"], true, "{line}");
        let points = line["points"].as_array().unwrap();
        assert_eq!(points.len(), target.len());
        // Every point on the true centre of its id, or every point on that of the id the half turn gives it.
        let last = target.len() - 1;
        let on = |point: &serde_json::Value, k: usize| {
            let c = photo.truth[k].centre_px.unwrap();
            ((c.x - num(point, "u_px")).powi(2) + (c.y - num(point, "v_px")).powi(2)).sqrt() < 1.0
        };
        let id = |point: &serde_json::Value| point["id"].as_u64().unwrap() as usize;
        let same = points.iter().all(|q| on(q, id(q)));
        let turned = points.iter().all(|q| on(q, last - id(q)));
        assert!(same || turned, "{line}");
        eprintln!(
            "hex 6 x {cols}: ambiguous, labelled {}",
            if same { "as the truth" } else { "half turned" }
        );
    }
}

#[test]
fn detect_refuses_a_target_of_three_points() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let camera_path = dir.join("camera.yaml");
    roitrack::formats::write_camera_yaml(&camera_path, &camera()).unwrap();
    let target_path = dir.join("three.csv");
    std::fs::write(
        &target_path,
        "id,x,y,z,diameter\n0,0,0,0,0.01\n1,0.05,0,0,0.01\n2,0,0.05,0,0.01\n",
    )
    .unwrap();
    let png = dir.join("blank.png");
    image::GrayImage::new(1024, 768).save(&png).unwrap();
    let stderr = fails(&[
        "detect",
        "--camera",
        p(&camera_path),
        "--target",
        p(&target_path),
        p(&png),
    ]);
    assert!(
        stderr.contains("three.csv: a target of 3 points")
            && stderr.contains("identifies no blobs")
            && stderr.contains("not found in 1 of 1 images"),
        "{stderr}"
    );
}
