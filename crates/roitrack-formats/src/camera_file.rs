//! Camera calibration files of every common kind, recognised from their content: [`read_camera_file`].
//!
//! | format | recognised by | intrinsics | distortion | image size | name |
//! | --- | --- | --- | --- | --- | --- |
//! | ROS camera_info YAML (ROS 1 and ROS 2 `camera_calibration`) | `image_width`, `camera_matrix` | `camera_matrix.data` | `distortion_model`, `distortion_coefficients.data` | `image_width`, `image_height` | `camera_name` |
//! | a camera_info message as `ros2 topic echo` (lower case) or `rostopic echo` (upper case) prints it | `k`/`K`, `d`/`D` and `width` at the top | `k` | `distortion_model`, `d` | `width`, `height` | `header.frame_id` |
//! | OpenCV FileStorage YAML (`%YAML:1.0` from OpenCV 4, `%YAML 1.2` from OpenCV 5) or XML (`<opencv_storage>`) | the header, `!!opencv-matrix` or the XML root | `camera_matrix`, `cameraMatrix` or `K` | `distortion_coefficients`, `dist_coeffs`, `distCoeffs` or `D`; `distortion_model` where given | `image_width`, `image_height`, else `--image-size` | the file's stem |
//! | Kalibr camchain YAML | `cam0:` ... with `intrinsics` | `intrinsics: [fu, fv, pu, pv]` (`camera_model: pinhole`) | `distortion_model` `radtan`, `equidistant` or `none`, `distortion_coeffs` | `resolution: [w, h]` | the camera's key (`--camera-name`, default `cam0`) |
//! | BoofCV `intrinsic.yaml` (`CalibrationIO.save`, `model: pinhole_radial_tangential` or `pinhole`, or no `model` in older files) | `pinhole:` with `fx` at the top, or a BoofCV `model` | `pinhole.fx`, `fy`, `cx`, `cy`, `skew` | `radial_tangential`: `radial` (0 to 3: `k1 k2 k3`), `t1`, `t2` (plumb_bob with `p1 = t1`, `p2 = t2`); none without it | `pinhole.width`, `pinhole.height` | the file's stem |
//!
//! Distortion models and their coefficients (ROS's and OpenCV's order): `plumb_bob` 4 or 5 (`k1 k2 p1 p2 [k3]`),
//! `rational_polynomial` 8 (`k1 k2 p1 p2 k3 k4 k5 k6`), `equidistant` 4 (`k1 k2 k3 k4`, `cv::fisheye`), `none` 0.
//! OpenCV files do not say which model their coefficients belong to: 5, 8 (or 12 and 14 with the extra thin-prism and
//! tilt terms zero) are unambiguous; 4 could be plumb_bob (`cv::calibrateCamera`) or equidistant (`cv::fisheye`), so
//! such a file needs a `distortion_model` entry. BoofCV's other models (`kannala_brandt`, `omnidirectional_universal`)
//! and its stereo and other multi-part files are refused, naming the model.

use std::fmt::Write as _;
use std::path::Path;

use roitrack_core::{CameraModel, Distortion, PinholeIntrinsics};
use serde_yaml_ng::{Mapping, Value};

use crate::FormatError;
use crate::limits::{MAX_CAMERA_FILE_BYTES, check_yaml_depth, read_text_file};

/// What a camera file should be, for errors.
pub(crate) const CAMERA_FILE: &str = "a camera calibration (YAML or XML)";

/// What [`read_camera_file`] needs besides the file: what the file may leave out.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct CameraFileOptions {
    /// The image size (width, height in pixels) for files that do not carry one (OpenCV files may not); refused if
    /// the file has a different one.
    pub image_size: Option<(u32, u32)>,
    /// Which camera of a Kalibr camchain (`cam0` if `None`); refused for other formats, which hold one camera.
    pub camera_name: Option<String>,
}

/// The kinds of camera file [`read_camera_file`] reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CameraFileFormat {
    /// ROS camera_info YAML as `camera_calibration` writes it (ROS 1 and ROS 2).
    RosYaml,
    /// A `sensor_msgs/CameraInfo` message as `ros2 topic echo` or `rostopic echo` prints it.
    RosMessage,
    /// OpenCV FileStorage YAML.
    OpenCvYaml,
    /// OpenCV FileStorage XML.
    OpenCvXml,
    /// A Kalibr camchain YAML.
    Kalibr,
    /// A BoofCV camera YAML (`intrinsic.yaml`) as `CalibrationIO.save` writes it.
    BoofCv,
}

impl CameraFileFormat {
    /// A name for messages: `ROS camera_info YAML`, `OpenCV FileStorage XML`, ...
    pub fn describe(self) -> &'static str {
        match self {
            Self::RosYaml => "ROS camera_info YAML",
            Self::RosMessage => "ROS camera_info message (topic echo)",
            Self::OpenCvYaml => "OpenCV FileStorage YAML",
            Self::OpenCvXml => "OpenCV FileStorage XML",
            Self::Kalibr => "Kalibr camchain YAML",
            Self::BoofCv => "BoofCV intrinsic YAML",
        }
    }
}

/// Reads a camera calibration file of any kind in the table above, recognised from its content.
///
/// ```
/// use roitrack_formats::{CameraFileOptions, read_camera_file};
///
/// let dir = tempfile::tempdir().unwrap();
/// let path = dir.path().join("camchain.yaml");
/// std::fs::write(&path, "cam0:\n  camera_model: pinhole\n  intrinsics: [461.6, 460.3, 366.3, 249.0]\n  \
///     distortion_model: equidistant\n  distortion_coeffs: [-0.01, 0.02, -0.01, 0.002]\n  resolution: [752, 480]\n")
///     .unwrap();
/// let camera = read_camera_file(&path, &CameraFileOptions::default()).unwrap();
/// assert_eq!((camera.width_px, camera.distortion.model_name()), (752, "equidistant"));
/// // OpenCV files may need the image size: errors name the file and the field.
/// std::fs::write(&path, "%YAML:1.0\n---\nK: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n   \
///     data: [ 500., 0., 320., 0., 500., 240., 0., 0., 1. ]\n").unwrap();
/// let e = read_camera_file(&path, &CameraFileOptions::default()).unwrap_err();
/// assert!(e.to_string().contains("field 'image_width'") && e.to_string().contains("--image-size"));
/// let options = CameraFileOptions { image_size: Some((640, 480)), ..Default::default() };
/// assert!(read_camera_file(&path, &options).unwrap().distortion.is_identity());
/// ```
pub fn read_camera_file(
    path: impl AsRef<Path>,
    options: &CameraFileOptions,
) -> Result<CameraModel, FormatError> {
    let path = path.as_ref();
    let text = read_text_file(path, CAMERA_FILE, MAX_CAMERA_FILE_BYTES)?;
    parse_camera_file(&text, path, options).map(|(camera, _)| camera)
}

/// Parses camera calibration text of any kind in the table above; `path` names it in errors (and gives an OpenCV
/// camera its name). Returns the camera and the format found. A leading byte-order mark is skipped; YAML nested
/// deeper than [`MAX_YAML_DEPTH`](crate::MAX_YAML_DEPTH) is refused before it is parsed.
pub fn parse_camera_file(
    text: &str,
    path: impl AsRef<Path>,
    options: &CameraFileOptions,
) -> Result<(CameraModel, CameraFileFormat), FormatError> {
    let path = path.as_ref();
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let format = detect_camera_format(text, path)?;
    if options.camera_name.is_some() && format != CameraFileFormat::Kalibr {
        return Err(FormatError::new(
            path,
            format!(
                "--camera-name picks a camera of a Kalibr camchain, but this is a {} file with one camera",
                format.describe()
            ),
        ));
    }
    let camera = match format {
        CameraFileFormat::RosYaml => {
            let camera = crate::parse_camera_yaml(first_document(text), path)?;
            check_image_size(camera, options, path, ("image_width", "image_height"))?
        }
        CameraFileFormat::RosMessage => parse_ros_message(&yaml_value(text, path)?, path, options)?,
        CameraFileFormat::OpenCvYaml => {
            let cleaned = clean_opencv_yaml(text);
            parse_opencv(&yaml_value(&cleaned, path)?, path, options)?
        }
        CameraFileFormat::OpenCvXml => {
            let value = crate::camera_xml::opencv_xml_to_value(text)
                .map_err(|(line, message)| FormatError::new(path, message).with_line(line))?;
            parse_opencv(&value, path, options)?
        }
        CameraFileFormat::Kalibr => parse_kalibr(&yaml_value(text, path)?, path, options)?,
        CameraFileFormat::BoofCv => parse_boofcv(&yaml_value(text, path)?, path, options)?,
    };
    Ok((camera, format))
}

/// Which kind of camera file `text` is.
pub fn detect_camera_format(
    text: &str,
    path: impl AsRef<Path>,
) -> Result<CameraFileFormat, FormatError> {
    let path = path.as_ref();
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let start = text.trim_start();
    if start.is_empty() {
        return Err(FormatError::new(
            path,
            "empty file: expected a camera calibration",
        ));
    }
    if start.starts_with("<?xml") || start.starts_with("<opencv_storage") {
        return Ok(CameraFileFormat::OpenCvXml);
    }
    if start.starts_with("%YAML:") || text.contains("!!opencv-matrix") {
        return Ok(CameraFileFormat::OpenCvYaml);
    }
    // Other YAML: by the keys at the top.
    let value = yaml_value(text, path)?;
    let Value::Mapping(map) = &value else {
        return Err(not_a_camera_file(path));
    };
    let has = |key: &str| map.contains_key(key);
    if has("image_width") && has("camera_matrix") {
        return Ok(CameraFileFormat::RosYaml);
    }
    if (has("k") || has("K")) && (has("width") || has("height")) {
        return Ok(CameraFileFormat::RosMessage);
    }
    if OPENCV_K_KEYS.iter().any(|k| has(k)) {
        return Ok(CameraFileFormat::OpenCvYaml);
    }
    let kalibr = map.iter().any(|(k, v)| {
        k.as_str().is_some_and(|k| k.starts_with("cam"))
            && v.as_mapping().is_some_and(|m| m.contains_key("intrinsics"))
    });
    if kalibr {
        return Ok(CameraFileFormat::Kalibr);
    }
    // BoofCV: a `pinhole: {fx, ...}` block at the top (or in a stereo pair's `left`, `right`), or one of its models.
    let boofcv_pinhole = |m: &Mapping| {
        get(m, "pinhole")
            .and_then(Value::as_mapping)
            .is_some_and(|p| p.contains_key("fx"))
    };
    let boofcv_pinhole = boofcv_pinhole(map)
        || ["left", "right"].iter().any(|k| {
            get(map, k)
                .and_then(Value::as_mapping)
                .is_some_and(boofcv_pinhole)
        });
    let boofcv_model = get(map, "model")
        .and_then(Value::as_str)
        .is_some_and(|m| BOOFCV_MODELS.contains(&m.trim()));
    if boofcv_pinhole || boofcv_model {
        return Ok(CameraFileFormat::BoofCv);
    }
    if has("camera_matrix") {
        // camera_info YAML without its image size: let its reader name what is missing.
        return Ok(CameraFileFormat::RosYaml);
    }
    Err(not_a_camera_file(path))
}

fn not_a_camera_file(path: &Path) -> FormatError {
    FormatError::new(
        path,
        "not a camera file roitrack knows: expected ROS camera_info YAML (image_width, camera_matrix, ...), a \
         camera_info message (width, height, k, d), OpenCV FileStorage YAML or XML (camera_matrix or K, \
         distortion_coefficients or D), a Kalibr camchain (cam0: intrinsics, distortion_coeffs, resolution) or a \
         BoofCV intrinsic.yaml (pinhole: fx, fy, cx, cy, ...; radial_tangential)",
    )
}

/// The distortion model `name` with `coefficients`: [`Distortion::from_model`], the one table of lens models,
/// under the name the Python package calls.
pub fn distortion_from(name: &str, coefficients: &[f64]) -> Result<Distortion, String> {
    Distortion::from_model(name, coefficients)
}

/// The text up to the end of its first YAML document (a `---` or `...` line after some content), so that a topic
/// echo's trailing separators and later messages are left out. Line numbers are unchanged.
fn first_document(text: &str) -> &str {
    let mut offset = 0;
    let mut seen_content = false;
    for line in text.split_inclusive('\n') {
        let trimmed = line.trim_end();
        if (trimmed == "---" || trimmed == "...") && seen_content {
            return &text[..offset];
        }
        if !trimmed.is_empty()
            && !trimmed.starts_with('#')
            && !trimmed.starts_with('%')
            && trimmed != "---"
        {
            seen_content = true;
        }
        offset += line.len();
    }
    text
}

/// The first YAML document of `text` as a value; syntax errors name the line. Nesting is checked first: the parser's
/// time grows with the square of the depth.
fn yaml_value(text: &str, path: &Path) -> Result<Value, FormatError> {
    let text = first_document(text);
    check_yaml_depth(text, path)?;
    serde_yaml_ng::from_str::<Value>(text).map_err(|e| {
        let line = e.location().map(|l| l.line() as u64);
        FormatError::new(path, format!("not valid YAML: {e}")).with_line(line)
    })
}

/// OpenCV's YAML made plain YAML: its `%YAML:1.0` directive (not valid YAML 1.1) and its `!!opencv-matrix` tags
/// blanked out, keeping every line and column where it was.
fn clean_opencv_yaml(text: &str) -> String {
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

/// `path`'s stem, the name of a camera from a file that has none.
fn file_stem(path: &Path) -> String {
    path.file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default()
}

fn field_error(path: &Path, field: &str, message: impl Into<String>) -> FormatError {
    FormatError::new(path, message).with_field(field)
}

/// The value at `key` of `map`.
fn get<'a>(map: &'a Mapping, key: &str) -> Option<&'a Value> {
    map.get(key)
}

/// A number (YAML integer or float).
fn number(value: &Value, path: &Path, field: &str) -> Result<f64, FormatError> {
    match value {
        Value::Number(n) => n
            .as_f64()
            .ok_or_else(|| field_error(path, field, "not a number")),
        other => Err(field_error(
            path,
            field,
            format!("expected a number, got {}", describe(other)),
        )),
    }
}

fn describe(value: &Value) -> String {
    match value {
        Value::Null => "nothing".to_string(),
        Value::Bool(b) => format!("{b}"),
        Value::Number(n) => format!("{n}"),
        Value::String(s) => format!("{s:?}"),
        Value::Sequence(s) => format!("a list of {}", s.len()),
        Value::Mapping(_) => "a mapping".to_string(),
        Value::Tagged(_) => "a tagged value".to_string(),
    }
}

/// A list of finite numbers.
fn numbers(value: &Value, path: &Path, field: &str) -> Result<Vec<f64>, FormatError> {
    let Value::Sequence(items) = value else {
        return Err(field_error(
            path,
            field,
            format!("expected a list of numbers, got {}", describe(value)),
        ));
    };
    items
        .iter()
        .enumerate()
        .map(|(i, v)| {
            let f = format!("{field}[{i}]");
            let x = number(v, path, &f)?;
            if x.is_finite() {
                Ok(x)
            } else {
                Err(field_error(
                    path,
                    &f,
                    format!("must be a finite number, got {x}"),
                ))
            }
        })
        .collect()
}

/// A positive image size.
fn size(value: &Value, path: &Path, field: &str) -> Result<u32, FormatError> {
    match value.as_u64().and_then(|v| u32::try_from(v).ok()) {
        Some(v) if v > 0 => Ok(v),
        _ => Err(field_error(
            path,
            field,
            format!(
                "expected a positive image size in pixels, got {}",
                describe(value)
            ),
        )),
    }
}

/// The image width and height at `keys` of `map`, each optional ([`size`]), named `fields` in errors; the width
/// is read first.
fn width_height(
    map: &Mapping,
    keys: [&str; 2],
    path: &Path,
    fields: [&str; 2],
) -> Result<(Option<u32>, Option<u32>), FormatError> {
    let width = get(map, keys[0])
        .map(|v| size(v, path, fields[0]))
        .transpose()?;
    let height = get(map, keys[1])
        .map(|v| size(v, path, fields[1]))
        .transpose()?;
    Ok((width, height))
}

/// `[width, height]` as an image size: two whole numbers of pixels from 1 to `u32::MAX`; else `None`.
fn image_size_px(wh: &[f64]) -> Option<(u32, u32)> {
    match *wh {
        [w, h]
            if w >= 1.0
                && h >= 1.0
                && w.fract() == 0.0
                && h.fract() == 0.0
                && w <= u32::MAX as f64
                && h <= u32::MAX as f64 =>
        {
            Some((w as u32, h as u32))
        }
        _ => None,
    }
}

/// The 9 numbers of K checked: its layout `[[fx, s, cx], [0, fy, cy], [0, 0, 1]]` and positive focal lengths.
fn intrinsics_from_k(
    k: &[f64],
    path: &Path,
    field: &str,
) -> Result<PinholeIntrinsics, FormatError> {
    if k.len() != 9 {
        return Err(field_error(
            path,
            field,
            format!("the camera matrix needs 9 numbers (3 x 3), got {}", k.len()),
        ));
    }
    for (i, want) in [(3, 0.0), (6, 0.0), (7, 0.0), (8, 1.0)] {
        if k[i] != want {
            return Err(field_error(
                path,
                &format!("{field}[{i}]"),
                format!(
                    "must be {want} (K must be [[fx, s, cx], [0, fy, cy], [0, 0, 1]]), got {}",
                    k[i]
                ),
            ));
        }
    }
    let intrinsics = PinholeIntrinsics {
        fx_px: k[0],
        fy_px: k[4],
        skew_px: k[1],
        cx_px: k[2],
        cy_px: k[5],
    };
    intrinsics.validate().map_err(|e| {
        let index = match &e {
            roitrack_core::CameraError::NotPositive { field: "fy", .. }
            | roitrack_core::CameraError::NotFinite { field: "fy", .. } => 4,
            _ => 0,
        };
        field_error(path, &format!("{field}[{index}]"), e.to_string())
    })?;
    Ok(intrinsics)
}

/// The camera, its image size taken from the file or, if the file has none, from the options.
fn build(
    name: String,
    file_size: (Option<u32>, Option<u32>),
    intrinsics: PinholeIntrinsics,
    distortion: Distortion,
    options: &CameraFileOptions,
    path: &Path,
    size_fields: (&str, &str),
) -> Result<CameraModel, FormatError> {
    let (width_px, height_px) = match (file_size, options.image_size) {
        ((Some(w), Some(h)), Some((ow, oh))) if (w, h) != (ow, oh) => {
            return Err(field_error(
                path,
                size_fields.0,
                format!(
                    "the file says {w}x{h} px, --image-size says {ow}x{oh}: a calibration holds for the size it was \
                     made at; leave --image-size out or recalibrate"
                ),
            ));
        }
        ((Some(w), Some(h)), _) => (w, h),
        (_, Some(size)) => size,
        ((None, _), None) => {
            return Err(field_error(
                path,
                size_fields.0,
                "missing: give the image size with --image-size WxH",
            ));
        }
        ((_, None), None) => {
            return Err(field_error(
                path,
                size_fields.1,
                "missing: give the image size with --image-size WxH",
            ));
        }
    };
    CameraModel::new(name, width_px, height_px, intrinsics, distortion).map_err(|e| {
        use roitrack_core::CameraError as E;
        // The value at fault, by its name (fx, k1, ...): each format keeps it under a key of its own.
        let field = match &e {
            E::NotFinite { field, .. } | E::NotPositive { field, .. } => Some(*field),
            E::Implausible(e) => Some(e.field),
            E::Lens(e) => Some(e.coefficient()),
            E::ImageTooLarge { .. } | E::EmptyImage { .. } => Some(size_fields.0),
            E::UndistortionDiverged { .. } | E::TimeModel(_) => None,
        };
        let error = FormatError::new(path, e.to_string());
        match field {
            Some(field) => error.with_field(field),
            None => error,
        }
    })
}

/// A camera read by the ROS YAML reader, with its size checked against the options.
fn check_image_size(
    camera: CameraModel,
    options: &CameraFileOptions,
    path: &Path,
    size_fields: (&str, &str),
) -> Result<CameraModel, FormatError> {
    build(
        camera.name.clone(),
        (Some(camera.width_px), Some(camera.height_px)),
        camera.intrinsics,
        camera.distortion,
        options,
        path,
        size_fields,
    )
}

/// A `sensor_msgs/CameraInfo` message as a topic echo prints it (`k`, `d` in ROS 2; `K`, `D` in ROS 1).
fn parse_ros_message(
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

/// Keys of K and of the distortion coefficients in OpenCV files, as OpenCV's samples and common programs write them.
const OPENCV_K_KEYS: [&str; 4] = ["camera_matrix", "cameraMatrix", "K", "Camera_Matrix"];
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
fn parse_opencv(
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

/// A Kalibr camchain: `cam0: {camera_model, intrinsics, distortion_model, distortion_coeffs, resolution}`.
fn parse_kalibr(
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

/// The `model` names BoofCV's `CalibrationIO` writes at the top of its files.
const BOOFCV_MODELS: [&str; 8] = [
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
fn parse_boofcv(
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
