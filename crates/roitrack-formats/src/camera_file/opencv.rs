//! OpenCV FileStorage files (YAML from OpenCV 4 and 5, or XML as a value): `!!opencv-matrix` entries, the keys
//! common programs use for K and the distortion, and the distortion model told from the coefficients' count.

use std::path::Path;

use roitrack_core::{CameraModel, Distortion};
use serde_yaml_ng::Value;

use super::assemble::{build, intrinsics_from_k};
use super::fields::{describe, field_error, file_stem, get, image_size_px, numbers, width_height};
use super::{CameraFileOptions, not_a_camera_file};
use crate::FormatError;

/// OpenCV's YAML made plain YAML: its `%YAML:1.0` directive (not valid YAML 1.1) and its `!!opencv-matrix` tags
/// blanked out, keeping every line and column where it was.
pub(super) fn clean_opencv_yaml(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for (i, line) in text.split_inclusive('\n').enumerate() {
        if i == 0 && line.trim_start_matches('\u{feff}').starts_with("%YAML") {
            out.push('\n');
            continue;
        }
        let mut rest = line;
        while let Some(at) = rest.find("!!opencv-") {
            out.push_str(&rest[..at]);
            let tag_len = rest[at..]
                .find(char::is_whitespace)
                .unwrap_or(rest.len() - at);
            out.extend(std::iter::repeat_n(' ', tag_len));
            rest = &rest[at + tag_len..];
        }
        out.push_str(rest);
    }
    out
}

/// Keys of K and of the distortion coefficients in OpenCV files, as OpenCV's samples and common programs write them.
pub(super) const OPENCV_K_KEYS: [&str; 4] = ["camera_matrix", "cameraMatrix", "K", "Camera_Matrix"];
const OPENCV_D_KEYS: [&str; 5] = [
    "distortion_coefficients",
    "dist_coeffs",
    "distCoeffs",
    "D",
    "Distortion_Coefficients",
];

/// An `!!opencv-matrix` mapping `{rows, cols, dt, data}`: its numbers, row-major.
fn opencv_matrix(value: &Value, path: &Path, field: &str) -> Result<Vec<f64>, FormatError> {
    let Value::Mapping(m) = value else {
        // A plain list is taken too (some programs write K as a list of 9).
        return numbers(value, path, field);
    };
    let rows =
        get(m, "rows").ok_or_else(|| field_error(path, &format!("{field}.rows"), "missing"))?;
    let cols =
        get(m, "cols").ok_or_else(|| field_error(path, &format!("{field}.cols"), "missing"))?;
    let (rows, cols) = (
        rows.as_u64()
            .ok_or_else(|| field_error(path, &format!("{field}.rows"), "expected a count"))?,
        cols.as_u64()
            .ok_or_else(|| field_error(path, &format!("{field}.cols"), "expected a count"))?,
    );
    if let Some(dt) = get(m, "dt").and_then(Value::as_str)
        && !matches!(dt, "d" | "f")
    {
        return Err(field_error(
            path,
            &format!("{field}.dt"),
            format!("expected d or f (floating point), got {dt:?}"),
        ));
    }
    let data_field = format!("{field}.data");
    let data = get(m, "data").ok_or_else(|| field_error(path, &data_field, "missing"))?;
    let data = numbers(data, path, &data_field)?;
    if rows.checked_mul(cols) != Some(data.len() as u64) {
        return Err(field_error(
            path,
            field,
            format!(
                "rows x cols = {rows} x {cols} does not match the {} numbers of data",
                data.len()
            ),
        ));
    }
    Ok(data)
}

/// OpenCV FileStorage (YAML or XML, as a value).
pub(super) fn parse_opencv(
    value: &Value,
    path: &Path,
    options: &CameraFileOptions,
) -> Result<CameraModel, FormatError> {
    let map = value.as_mapping().ok_or_else(|| not_a_camera_file(path))?;
    let Some((k_field, k)) = OPENCV_K_KEYS
        .iter()
        .find_map(|&key| get(map, key).map(|v| (key, v)))
    else {
        return Err(field_error(
            path,
            "camera_matrix",
            "missing (looked for camera_matrix, cameraMatrix and K)",
        ));
    };
    let intrinsics = intrinsics_from_k(&opencv_matrix(k, path, k_field)?, path, k_field)?;
    let (d_field, coefficients) = match OPENCV_D_KEYS
        .iter()
        .find_map(|&key| get(map, key).map(|v| (key, v)))
    {
        Some((key, d)) => (key, opencv_matrix(d, path, key)?),
        None => ("distortion_coefficients", Vec::new()),
    };
    let model = match get(map, "distortion_model") {
        Some(Value::String(s)) => match s.trim() {
            "fisheye" => "equidistant".to_string(),
            "radtan" => "plumb_bob".to_string(),
            s => s.to_string(),
        },
        Some(other) => {
            return Err(field_error(
                path,
                "distortion_model",
                format!("expected a name, got {}", describe(other)),
            ));
        }
        None => String::new(),
    };
    let distortion = match (model.as_str(), coefficients.len()) {
        ("", 4) => {
            return Err(field_error(
                path,
                d_field,
                "4 coefficients could be plumb_bob [k1, k2, p1, p2] (cv::calibrateCamera) or equidistant [k1, k2, \
                 k3, k4] (cv::fisheye::calibrate): add a line distortion_model: plumb_bob or distortion_model: \
                 equidistant to the file",
            ));
        }
        ("" | "rational_polynomial", 12 | 14) => {
            // Thin-prism (s1..s4) and tilt (tauX, tauY) terms: roitrack has neither, so they must be zero.
            if let Some(i) = coefficients[8..].iter().position(|&c| c != 0.0) {
                return Err(field_error(
                    path,
                    &format!("{d_field}.data[{}]", i + 8),
                    "thin-prism and tilt coefficients (after the 8th) are not supported and must be 0",
                ));
            }
            Distortion::from_model("rational_polynomial", &coefficients[..8])
        }
        ("", 8) => Distortion::from_model("rational_polynomial", &coefficients),
        ("", n) if n != 0 && n != 5 => Err(format!(
            "OpenCV's distortion vectors have 4, 5, 8, 12 or 14 coefficients, got {n}"
        )),
        (m, _) => Distortion::from_model(m, &coefficients),
    }
    .map_err(|e| field_error(path, d_field, e))?;
    let (mut width, mut height) = width_height(
        map,
        ["image_width", "image_height"],
        path,
        ["image_width", "image_height"],
    )?;
    for key in ["image_size", "imageSize", "cameraResolution"] {
        if let Some(v) = get(map, key) {
            let wh = numbers(v, path, key)?;
            let Some((w, h)) = image_size_px(&wh) else {
                return Err(field_error(path, key, "expected [width, height] in pixels"));
            };
            width = width.or(Some(w));
            height = height.or(Some(h));
        }
    }
    build(
        file_stem(path),
        (width, height),
        intrinsics,
        distortion,
        options,
        path,
        ("image_width", "image_height"),
    )
}
