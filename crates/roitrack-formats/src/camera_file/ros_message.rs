//! A `sensor_msgs/CameraInfo` message as `ros2 topic echo` or `rostopic echo` prints it (camera_info YAML as
//! `camera_calibration` writes it is `camera_yaml`'s).

use std::path::Path;

use roitrack_core::{CameraModel, Distortion};
use serde_yaml_ng::Value;

use super::assemble::{build, intrinsics_from_k};
use super::fields::{describe, field_error, file_stem, get, numbers, width_height};
use super::{CameraFileOptions, not_a_camera_file};
use crate::FormatError;

/// A `sensor_msgs/CameraInfo` message as a topic echo prints it (`k`, `d` in ROS 2; `K`, `D` in ROS 1).
pub(super) fn parse_ros_message(
    value: &Value,
    path: &Path,
    options: &CameraFileOptions,
) -> Result<CameraModel, FormatError> {
    let map = value.as_mapping().ok_or_else(|| not_a_camera_file(path))?;
    let pick = |lower: &'static str, upper: &'static str| {
        get(map, lower)
            .map(|v| (lower, v))
            .or_else(|| get(map, upper).map(|v| (upper, v)))
    };
    let (k_field, k) = pick("k", "K").ok_or_else(|| field_error(path, "k", "missing"))?;
    let intrinsics = intrinsics_from_k(&numbers(k, path, k_field)?, path, k_field)?;
    let coefficients = match pick("d", "D") {
        Some((field, d)) if !d.is_null() => numbers(d, path, field)?,
        _ => Vec::new(),
    };
    let model = match get(map, "distortion_model") {
        Some(Value::String(s)) => s.trim().to_string(),
        Some(Value::Null) | None => String::new(),
        Some(other) => {
            return Err(field_error(
                path,
                "distortion_model",
                format!("expected a name, got {}", describe(other)),
            ));
        }
    };
    let d_field = if map.contains_key("D") { "D" } else { "d" };
    let distortion =
        Distortion::from_model(&model, &coefficients).map_err(|e| field_error(path, d_field, e))?;
    let (width, height) = width_height(map, ["width", "height"], path, ["width", "height"])?;
    // A message from a driver that has no calibration says 0 x 0 and K all zero; K is refused above.
    let name = get(map, "header")
        .and_then(|h| h.get("frame_id"))
        .and_then(Value::as_str)
        .map_or_else(|| file_stem(path), str::to_string);
    build(
        name,
        (width, height),
        intrinsics,
        distortion,
        options,
        path,
        ("width", "height"),
    )
}
