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
//!
//! A file per format here (`ros_message`, `opencv`, `kalibr`, `boofcv`; ROS camera_info YAML is `camera_yaml`'s),
//! the YAML reading they share in `fields` and the camera made from what they read in `assemble`.

mod assemble;
mod boofcv;
mod fields;
mod kalibr;
mod opencv;
mod ros_message;

use std::path::Path;

use roitrack_core::{CameraModel, Distortion};
use serde_yaml_ng::{Mapping, Value};

use crate::FormatError;
use crate::limits::{MAX_CAMERA_FILE_BYTES, read_text_file};

use assemble::check_image_size;
use boofcv::{BOOFCV_MODELS, parse_boofcv};
use fields::{first_document, get, yaml_value};
use kalibr::parse_kalibr;
use opencv::{OPENCV_K_KEYS, clean_opencv_yaml, parse_opencv};
use ros_message::parse_ros_message;

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

pub(super) fn not_a_camera_file(path: &Path) -> FormatError {
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
