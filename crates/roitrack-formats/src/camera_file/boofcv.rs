//! BoofCV's `intrinsic.yaml` as `CalibrationIO.save` writes it: pinhole and Brown (radial-tangential) cameras,
//! its other models refused by name.

use std::path::Path;

use roitrack_core::{CameraModel, Distortion, PinholeIntrinsics};
use serde_yaml_ng::{Mapping, Value};

use super::assemble::build;
use super::fields::{describe, field_error, file_stem, get, number, numbers, width_height};
use super::{CameraFileOptions, not_a_camera_file};
use crate::FormatError;

/// The `model` names BoofCV's `CalibrationIO` writes at the top of its files.
pub(super) const BOOFCV_MODELS: [&str; 8] = [
    "pinhole",
    "pinhole_radial_tangential",
    "omnidirectional_universal",
    "kannala_brandt",
    "stereo_camera",
    "rigid_body",
    "visual_depth",
    "monocular_plane",
];

/// Why roitrack does not read a BoofCV file of `model`.
fn boofcv_unsupported(model: &str) -> String {
    let what = match model {
        "kannala_brandt" => {
            "a BoofCV Kannala-Brandt camera (symmetric, radial and tangential polynomials in the angle); roitrack's \
             equidistant model is only its symmetric 4-coefficient case, so it is not read"
        }
        "omnidirectional_universal" => {
            "a BoofCV universal omnidirectional camera (Mei and Rives, with a mirror offset); roitrack has no such model"
        }
        "stereo_camera" => {
            "a BoofCV stereo pair (left, right, rightToLeft); roitrack reads one camera: save the left or right \
             camera on its own with CalibrationIO.save"
        }
        "visual_depth" | "monocular_plane" => {
            "a BoofCV file with a camera inside another model (intrinsic: ...); save the camera on its own with \
             CalibrationIO.save"
        }
        "rigid_body" => "a BoofCV rigid-body transform, not a camera",
        _ => "a model roitrack does not know",
    };
    format!(
        "BoofCV camera model {model:?} is not supported: this is {what}. roitrack reads BoofCV's \
         pinhole_radial_tangential (Brown) and pinhole models"
    )
}

/// A BoofCV camera as `CalibrationIO.save` writes a `CameraPinholeBrown` or `CameraPinhole`:
/// `model`, `pinhole: {fx, fy, cx, cy, width, height, skew}`, `radial_tangential: {radial: [k1, k2, k3], t1, t2}`.
/// BoofCV's Brown model is OpenCV's plumb_bob with `p1 = t1`, `p2 = t2`; its skew is K's `[0][1]`, as roitrack's.
pub(super) fn parse_boofcv(
    value: &Value,
    path: &Path,
    options: &CameraFileOptions,
) -> Result<CameraModel, FormatError> {
    let map = value.as_mapping().ok_or_else(|| not_a_camera_file(path))?;
    let model = match get(map, "model") {
        Some(Value::String(s)) => Some(s.trim()),
        Some(Value::Null) | None => None,
        Some(other) => {
            return Err(field_error(
                path,
                "model",
                format!("expected a name, got {}", describe(other)),
            ));
        }
    };
    match model {
        Some("pinhole" | "pinhole_radial_tangential") => {}
        None if ["left", "right"].iter().any(|k| map.contains_key(*k)) => {
            return Err(field_error(
                path,
                "model",
                boofcv_unsupported("stereo_camera"),
            ));
        }
        None => {}
        Some(other) => return Err(field_error(path, "model", boofcv_unsupported(other))),
    }
    let pinhole = get(map, "pinhole")
        .ok_or_else(|| field_error(path, "pinhole", "missing"))?
        .as_mapping()
        .ok_or_else(|| field_error(path, "pinhole", "expected a mapping {fx, fy, cx, cy, ...}"))?;
    let p = |key: &str| format!("pinhole.{key}");
    let value_of = |key: &str| -> Result<Option<f64>, FormatError> {
        match get(pinhole, key) {
            None | Some(Value::Null) => Ok(None),
            Some(v) => number(v, path, &p(key)).map(Some),
        }
    };
    let required = |key: &str| value_of(key)?.ok_or_else(|| field_error(path, &p(key), "missing"));
    let intrinsics = PinholeIntrinsics {
        fx_px: required("fx")?,
        fy_px: required("fy")?,
        skew_px: value_of("skew")?.unwrap_or(0.0),
        cx_px: required("cx")?,
        cy_px: required("cy")?,
    };
    intrinsics.validate().map_err(|e| {
        let key = match &e {
            roitrack_core::CameraError::NotPositive { field, .. }
            | roitrack_core::CameraError::NotFinite { field, .. } => field,
            _ => "fx",
        };
        field_error(path, &p(key), e.to_string())
    })?;
    let distortion = match (model, get(map, "radial_tangential")) {
        (_, None | Some(Value::Null)) => Distortion::None,
        (Some("pinhole"), Some(_)) => {
            return Err(field_error(
                path,
                "radial_tangential",
                "model pinhole has no distortion, yet the file has radial_tangential: set model to \
                 pinhole_radial_tangential or remove radial_tangential",
            ));
        }
        (_, Some(Value::Mapping(rt))) => boofcv_brown(rt, path)?,
        (_, Some(other)) => {
            return Err(field_error(
                path,
                "radial_tangential",
                format!(
                    "expected a mapping {{radial, t1, t2}}, got {}",
                    describe(other)
                ),
            ));
        }
    };
    let (width, height) = width_height(
        pinhole,
        ["width", "height"],
        path,
        ["pinhole.width", "pinhole.height"],
    )?;
    build(
        file_stem(path),
        (width, height),
        intrinsics,
        distortion,
        options,
        path,
        ("pinhole.width", "pinhole.height"),
    )
}

/// BoofCV's `radial_tangential: {radial: [k1, k2, k3], t1, t2}` as plumb_bob `[k1, k2, p1 = t1, p2 = t2, k3]`;
/// missing terms are zero.
fn boofcv_brown(rt: &Mapping, path: &Path) -> Result<Distortion, FormatError> {
    let radial_field = "radial_tangential.radial";
    let radial = match get(rt, "radial") {
        None | Some(Value::Null) => Vec::new(),
        Some(v) => numbers(v, path, radial_field)?,
    };
    if let Some(i) = radial.iter().skip(3).position(|&k| k != 0.0) {
        return Err(field_error(
            path,
            &format!("{radial_field}[{}]", i + 3),
            format!(
                "roitrack's plumb_bob has 3 radial terms (k1, k2, k3), the file has {} and this one is not 0",
                radial.len()
            ),
        ));
    }
    let tangential = |key: &str| -> Result<f64, FormatError> {
        let field = format!("radial_tangential.{key}");
        match get(rt, key) {
            None | Some(Value::Null) => Ok(0.0),
            Some(v) => {
                let t = number(v, path, &field)?;
                if t.is_finite() {
                    Ok(t)
                } else {
                    Err(field_error(
                        path,
                        &field,
                        format!("must be a finite number, got {t}"),
                    ))
                }
            }
        }
    };
    let k = |i: usize| radial.get(i).copied().unwrap_or(0.0);
    let (t1, t2) = (tangential("t1")?, tangential("t2")?);
    Distortion::from_model("plumb_bob", &[k(0), k(1), t1, t2, k(2)])
        .map_err(|e| field_error(path, "radial_tangential", e))
}

#[cfg(test)]
mod tests {
    use nalgebra::Vector3;

    use super::*;
    use crate::camera_file::{
        CameraFileFormat, CameraFileOptions, parse_camera_file, read_camera_file,
    };

    /// What BoofCV's `CalibrationIO.save` writes for a `CameraPinholeBrown`.
    const BOOFCV_EXAMPLE: &str = "\
# Pinhole camera model with radial and tangential distortion
# (fx,fy) = focal length, (cx,cy) = principle point, (width,height) = image shape
# radial = radial distortion, (t1,t2) = tangential distortion

pinhole:
  fx: 632.6331008160633
  fy: 629.4057227776121
  cx: 401.16829030891256
  cy: 229.2684635210703
  width: 800
  height: 450
  skew: 0.0
model: pinhole_radial_tangential
radial_tangential:
  radial:
  - 0.07946796807805329
  - -0.1703344505939042
  t1: 0.0
  t2: 0.0
version: 0
";

    const PINHOLE_BLOCK: &str = "pinhole:\n  fx: 500.0\n  fy: 510.0\n  cx: 320.5\n  cy: 240.25\n  width: 640\n  \
                                 height: 480\n  skew: 0.0\n";

    fn boofcv(text: &str) -> Result<CameraModel, FormatError> {
        let (camera, format) =
            parse_camera_file(text, "calib/intrinsic.yaml", &CameraFileOptions::default())?;
        assert_eq!(format, CameraFileFormat::BoofCv);
        Ok(camera)
    }

    fn plumb_bob(camera: &CameraModel) -> [f64; 5] {
        match camera.distortion {
            Distortion::PlumbBob(d) => d.coefficients(),
            ref other => panic!("expected plumb_bob, got {other:?}"),
        }
    }

    /// BoofCV's Brown model written out: `(x, y)` normalised, `radial = [k1, k2, k3]`, then K with skew.
    fn brown_pixel(
        k: (f64, f64, f64, f64, f64),
        radial: [f64; 3],
        (t1, t2): (f64, f64),
        p: Vector3<f64>,
    ) -> (f64, f64) {
        let (fx, fy, skew, cx, cy) = k;
        let (x, y) = (p.x / p.z, p.y / p.z);
        let r2 = x * x + y * y;
        let a = radial[0] * r2 + radial[1] * r2 * r2 + radial[2] * r2 * r2 * r2;
        let xd = x * (1.0 + a) + 2.0 * t1 * x * y + t2 * (r2 + 2.0 * x * x);
        let yd = y * (1.0 + a) + t1 * (r2 + 2.0 * y * y) + 2.0 * t2 * x * y;
        (fx * xd + skew * yd + cx, fy * yd + cy)
    }

    #[test]
    fn boofcv_example_is_read_with_its_values() {
        let camera = boofcv(BOOFCV_EXAMPLE).unwrap();
        assert_eq!(camera.name, "intrinsic");
        assert_eq!((camera.width_px, camera.height_px), (800, 450));
        let k = camera.intrinsics;
        assert_eq!(
            (k.fx_px, k.fy_px, k.skew_px, k.cx_px, k.cy_px),
            (
                632.6331008160633,
                629.4057227776121,
                0.0,
                401.16829030891256,
                229.2684635210703
            )
        );
        assert_eq!(
            plumb_bob(&camera),
            [0.07946796807805329, -0.1703344505939042, 0.0, 0.0, 0.0]
        );
        // Read from disk too: the name is the file's stem.
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("left_camera.yaml");
        std::fs::write(&path, BOOFCV_EXAMPLE).unwrap();
        let camera = read_camera_file(&path, &CameraFileOptions::default()).unwrap();
        assert_eq!(camera.name, "left_camera");
    }

    #[test]
    fn boofcv_radial_with_0_1_or_3_coefficients() {
        for (radial, t, want) in [
            ("  radial: []\n", "", [0.0, 0.0, 0.0, 0.0, 0.0]),
            (
                "",
                "  t1: 0.001\n  t2: -0.002\n",
                [0.0, 0.0, 0.001, -0.002, 0.0],
            ),
            // (-0.25 alone would fold back inside this image: see `check_lens`.)
            ("  radial:\n  - -0.2\n", "", [-0.2, 0.0, 0.0, 0.0, 0.0]),
            (
                // SnakeYAML writes small doubles as Java does: 1.5E-4.
                "  radial:\n  - -0.25\n  - 0.125\n  - 1.5E-4\n",
                "  t1: 3.0E-4\n  t2: -0.0005\n",
                [-0.25, 0.125, 3.0e-4, -0.0005, 1.5e-4],
            ),
        ] {
            let text = format!(
                "{PINHOLE_BLOCK}model: pinhole_radial_tangential\nradial_tangential:\n{radial}{t}version: 0\n"
            );
            let camera = boofcv(&text).unwrap_or_else(|e| panic!("{text}\n{e}"));
            assert_eq!(plumb_bob(&camera), want, "{text}");
        }
        // A fourth radial term roitrack does not have is refused unless it is 0.
        let four = format!(
            "{PINHOLE_BLOCK}model: pinhole_radial_tangential\nradial_tangential:\n  radial: [0.1, 0.2, 0.3, 0.0]\n"
        );
        assert_eq!(
            plumb_bob(&boofcv(&four).unwrap()),
            [0.1, 0.2, 0.0, 0.0, 0.3]
        );
        let e = boofcv(&four.replace("0.3, 0.0]", "0.3, 0.01]")).unwrap_err();
        assert!(
            e.to_string()
                .starts_with("calib/intrinsic.yaml: field 'radial_tangential.radial[3]'"),
            "{e}"
        );
    }

    #[test]
    fn boofcv_without_radial_tangential_is_undistorted() {
        for text in [
            format!("{PINHOLE_BLOCK}model: pinhole\nversion: 0\n"),
            format!("{PINHOLE_BLOCK}model: pinhole_radial_tangential\n"),
            // Older files: the same pinhole block, no model.
            PINHOLE_BLOCK.to_string(),
        ] {
            let camera = boofcv(&text).unwrap_or_else(|e| panic!("{text}\n{e}"));
            assert_eq!(camera.distortion, Distortion::None, "{text}");
            assert_eq!((camera.width_px, camera.height_px), (640, 480));
            assert_eq!(
                (camera.intrinsics.fx_px, camera.intrinsics.cy_px),
                (500.0, 240.25)
            );
        }
        // No model and radial_tangential: an older Brown file.
        let old = format!("{PINHOLE_BLOCK}radial_tangential:\n  radial: [0.1]\n");
        assert_eq!(plumb_bob(&boofcv(&old).unwrap()), [0.1, 0.0, 0.0, 0.0, 0.0]);
        // model: pinhole with distortion contradicts itself.
        let e = boofcv(&format!(
            "{PINHOLE_BLOCK}model: pinhole\nradial_tangential:\n  radial: [0.1]\n"
        ))
        .unwrap_err();
        assert!(e.to_string().contains("field 'radial_tangential'"), "{e}");
    }

    #[test]
    fn boofcv_skew_is_kept_as_roitrack_has_skew() {
        // roitrack's pinhole has skew (K[0][1], as BoofCV's), so a skewed BoofCV camera is read, not refused.
        let text = BOOFCV_EXAMPLE.replace("skew: 0.0", "skew: 1.25");
        assert_eq!(boofcv(&text).unwrap().intrinsics.skew_px, 1.25);
        let e = boofcv(&BOOFCV_EXAMPLE.replace("skew: 0.0", "skew: abc")).unwrap_err();
        assert!(
            e.to_string()
                .starts_with("calib/intrinsic.yaml: field 'pinhole.skew': expected a number"),
            "{e}"
        );
    }

    #[test]
    fn boofcv_errors_name_the_file_and_the_field() {
        for (text, want) in [
            (
                BOOFCV_EXAMPLE.replace("  fx: 632.6331008160633\n", ""),
                "calib/intrinsic.yaml: field 'pinhole.fx': missing",
            ),
            (
                BOOFCV_EXAMPLE.replace("fy: 629.4057227776121", "fy: -1.0"),
                "calib/intrinsic.yaml: field 'pinhole.fy': fy must be positive",
            ),
            (
                BOOFCV_EXAMPLE.replace("t2: 0.0", "t2: .nan"),
                "calib/intrinsic.yaml: field 'radial_tangential.t2': must be a finite number",
            ),
            (
                BOOFCV_EXAMPLE.replace("width: 800", "width: 0"),
                "calib/intrinsic.yaml: field 'pinhole.width': expected a positive image size",
            ),
        ] {
            let e = boofcv(&text).unwrap_err().to_string();
            assert!(e.starts_with(want), "{e}");
        }
        let options = CameraFileOptions {
            image_size: Some((640, 480)),
            ..Default::default()
        };
        let e = parse_camera_file(BOOFCV_EXAMPLE, "intrinsic.yaml", &options).unwrap_err();
        assert!(
            e.to_string()
                .contains("field 'pinhole.width': the file says 800x450"),
            "{e}"
        );
    }

    #[test]
    fn boofcv_other_models_are_refused_naming_the_model() {
        let kannala_brandt = "pinhole:\n  fx: 300.0\n  fy: 300.0\n  cx: 320.0\n  cy: 240.0\n  width: 640\n  \
            height: 480\n  skew: 0.0\nmodel: kannala_brandt\nsymmetric: [1.0, 0.01, 0.0, 0.0, 0.0]\nradial: []\n\
            radial_trig: []\ntangent: []\ntangent_trig: []\nversion: 0\n";
        let universal = format!(
            "{PINHOLE_BLOCK}model: omnidirectional_universal\nmirror_offset: 1.2\nradial_tangential:\n  radial: [0.1]\n"
        );
        let stereo = "model: stereo_camera\nversion: 0\nleft:\n  model: pinhole_radial_tangential\n  pinhole:\n    \
            fx: 1.0\nright:\n  model: pinhole_radial_tangential\nrightToLeft:\n  x: 0.1\n";
        let stereo_without_model =
            "left:\n  pinhole:\n    fx: 1.0\nright:\n  pinhole:\n    fx: 1.0\n";
        for (text, model, what) in [
            (kannala_brandt, "kannala_brandt", "Kannala-Brandt"),
            (
                &universal,
                "omnidirectional_universal",
                "universal omnidirectional",
            ),
            (stereo, "stereo_camera", "stereo pair"),
            (stereo_without_model, "stereo_camera", "stereo pair"),
        ] {
            let e = boofcv(text).unwrap_err().to_string();
            assert!(
                e.starts_with(&format!(
                    "calib/intrinsic.yaml: field 'model': BoofCV camera model \"{model}\" is not supported: this is a"
                )) && e.contains(what),
                "{e}"
            );
        }
    }

    #[test]
    fn boofcv_camera_projects_by_the_brown_formula() {
        let skewed = "pinhole:\n  fx: 612.5\n  fy: 598.25\n  cx: 330.75\n  cy: 241.5\n  width: 640\n  height: 480\n  \
            skew: 0.75\nmodel: pinhole_radial_tangential\nradial_tangential:\n  radial: [-0.28, 0.09, -0.012]\n  \
            t1: 0.0013\n  t2: -0.0021\nversion: 0\n";
        let example_k = (
            632.6331008160633,
            629.4057227776121,
            0.0,
            401.16829030891256,
            229.2684635210703,
        );
        let example_radial = [0.07946796807805329, -0.1703344505939042, 0.0];
        for (text, k, radial, t) in [
            (BOOFCV_EXAMPLE, example_k, example_radial, (0.0, 0.0)),
            (
                skewed,
                (612.5, 598.25, 0.75, 330.75, 241.5),
                [-0.28, 0.09, -0.012],
                (0.0013, -0.0021),
            ),
        ] {
            let camera = boofcv(text).unwrap();
            for p in [
                Vector3::new(0.0, 0.0, 1.0),
                Vector3::new(0.21, -0.13, 0.9),
                Vector3::new(-0.35, 0.27, 1.4),
                Vector3::new(0.4, 0.3, 1.1),
            ] {
                let px = camera.raw_pixel_from_cam(&p).unwrap();
                let (u, v) = brown_pixel(k, radial, t, p);
                assert!(
                    (px.x - u).abs() < 1e-9 && (px.y - v).abs() < 1e-9,
                    "{p:?}: roitrack {px:?}, Brown ({u}, {v})"
                );
            }
        }
    }
}
