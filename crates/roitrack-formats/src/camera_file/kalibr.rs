//! Kalibr camchain YAML: one pinhole camera of the chain (`cam0` or `--camera-name`), with radtan, equidistant or
//! no distortion.

use std::fmt::Write as _;
use std::path::Path;

use roitrack_core::{CameraModel, Distortion, PinholeIntrinsics};
use serde_yaml_ng::Value;

use super::assemble::build;
use super::fields::{field_error, get, image_size_px, numbers};
use super::{CameraFileOptions, not_a_camera_file};
use crate::FormatError;

/// A Kalibr camchain: `cam0: {camera_model, intrinsics, distortion_model, distortion_coeffs, resolution}`.
pub(super) fn parse_kalibr(
    value: &Value,
    path: &Path,
    options: &CameraFileOptions,
) -> Result<CameraModel, FormatError> {
    let map = value.as_mapping().ok_or_else(|| not_a_camera_file(path))?;
    let name = options.camera_name.as_deref().unwrap_or("cam0");
    let Some(cam) = get(map, name) else {
        let mut names = String::new();
        for key in map.keys().filter_map(Value::as_str) {
            let _ = write!(names, "{}{key}", if names.is_empty() { "" } else { ", " });
        }
        return Err(field_error(
            path,
            name,
            format!("no such camera in the camchain (it has {names}): pick one with --camera-name"),
        ));
    };
    let cam = cam
        .as_mapping()
        .ok_or_else(|| field_error(path, name, "expected a mapping"))?;
    let f = |key: &str| format!("{name}.{key}");
    match get(cam, "camera_model").and_then(Value::as_str) {
        Some("pinhole") | None => {}
        Some(other) => {
            return Err(field_error(
                path,
                &f("camera_model"),
                format!(
                    "unsupported camera model {other:?}: roitrack reads Kalibr's pinhole cameras (with radtan, equidistant or none)"
                ),
            ));
        }
    }
    let intrinsics_value =
        get(cam, "intrinsics").ok_or_else(|| field_error(path, &f("intrinsics"), "missing"))?;
    let k = numbers(intrinsics_value, path, &f("intrinsics"))?;
    let &[fx_px, fy_px, cx_px, cy_px] = k.as_slice() else {
        return Err(field_error(
            path,
            &f("intrinsics"),
            format!("expected 4 numbers [fu, fv, pu, pv], got {}", k.len()),
        ));
    };
    let intrinsics = PinholeIntrinsics {
        fx_px,
        fy_px,
        skew_px: 0.0,
        cx_px,
        cy_px,
    };
    intrinsics
        .validate()
        .map_err(|e| field_error(path, &f("intrinsics"), e.to_string()))?;
    let coefficients = match get(cam, "distortion_coeffs") {
        Some(v) => numbers(v, path, &f("distortion_coeffs"))?,
        None => Vec::new(),
    };
    let model = match get(cam, "distortion_model").and_then(Value::as_str) {
        Some("radtan") => "plumb_bob",
        Some("equidistant") => "equidistant",
        Some("none") => "none",
        None if coefficients.is_empty() => "none",
        None => return Err(field_error(path, &f("distortion_model"), "missing")),
        Some(other) => {
            return Err(field_error(
                path,
                &f("distortion_model"),
                format!(
                    "unsupported distortion model {other:?}: roitrack reads radtan, equidistant and none"
                ),
            ));
        }
    };
    let distortion = match (model, coefficients.len()) {
        ("plumb_bob", n) if n != 4 => {
            Err(format!("radtan takes 4 numbers [k1, k2, r1, r2], got {n}"))
        }
        _ => Distortion::from_model(model, &coefficients),
    }
    .map_err(|e| field_error(path, &f("distortion_coeffs"), e))?;
    let resolution = match get(cam, "resolution") {
        Some(v) => {
            let r = numbers(v, path, &f("resolution"))?;
            let Some((w, h)) = image_size_px(&r) else {
                return Err(field_error(
                    path,
                    &f("resolution"),
                    "expected [width, height] in pixels",
                ));
            };
            (Some(w), Some(h))
        }
        None => (None, None),
    };
    let (wf, hf) = (f("resolution"), f("resolution"));
    build(
        name.to_string(),
        resolution,
        intrinsics,
        distortion,
        options,
        path,
        (&wf, &hf),
    )
}
