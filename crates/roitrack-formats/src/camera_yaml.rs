//! Camera: ROS camera_info YAML (docs/model.md), as written by ROS `camera_calibration` and read by
//! `camera_info_manager`:
//!
//! ```yaml
//! image_width: 1024
//! image_height: 1024
//! camera_name: roitrack_canonical
//! camera_matrix:
//!   rows: 3
//!   cols: 3
//!   data: [1500.0, 0.0, 512.0, 0.0, 1500.0, 512.0, 0.0, 0.0, 1.0]
//! distortion_model: plumb_bob
//! distortion_coefficients:
//!   rows: 1
//!   cols: 5
//!   data: [0.0, 0.0, 0.0, 0.0, 0.0]
//! ```
//!
//! Sizes are in pixels; `camera_matrix` is K = `[[fx, s, cx], [0, fy, cy], [0, 0, 1]]` row-major (pixels, skew `s`
//! at `data[1]`); `distortion_coefficients` are plumb_bob's `[k1, k2, p1, p2, k3]` acting on normalised
//! coordinates. `rectification_matrix` and `projection_matrix` (and any other key) are ignored on reading; on
//! writing they are the identity and `[K | 0]`, as for a monocular camera.

use std::fmt::{self, Write as _};
use std::io::Write as _;
use std::path::Path;

use roitrack_core::{CameraError, CameraModel, Distortion, PinholeIntrinsics};
use serde::Deserialize;
use serde::de::{self, DeserializeSeed, IgnoredAny, MapAccess, SeqAccess, Unexpected, Visitor};

use crate::{AtomicFile, FormatError};

/// Reads a ROS camera_info YAML file (see [`parse_camera_yaml`]).
///
/// ```
/// use roitrack_core::CameraModel;
/// use roitrack_formats::{read_camera_yaml, write_camera_yaml};
///
/// let dir = tempfile::tempdir().unwrap();
/// let path = dir.path().join("camera.yaml");
/// write_camera_yaml(&path, &CameraModel::wide_angle_example()).unwrap();
/// assert_eq!(read_camera_yaml(&path).unwrap(), CameraModel::wide_angle_example());
/// // Errors name the file.
/// let missing = read_camera_yaml(dir.path().join("nope.yaml")).unwrap_err();
/// assert!(missing.to_string().contains("nope.yaml"));
/// ```
pub fn read_camera_yaml(path: impl AsRef<Path>) -> Result<CameraModel, FormatError> {
    let path = path.as_ref();
    let text = crate::limits::read_text_file(
        path,
        crate::camera_file::CAMERA_FILE,
        crate::MAX_CAMERA_FILE_BYTES,
    )?;
    parse_camera_yaml(&text, path)
}

/// Parses ROS camera_info YAML text; `path` names it in errors.
///
/// Checks: YAML syntax; image sizes positive integers; `camera_matrix` 3 x 3 with 9 finite numbers, `fx, fy > 0`,
/// bottom row `[0, 0, 1]` and `data[3] = 0`; `distortion_model` `plumb_bob` with 4 or 5 finite coefficients,
/// `rational_polynomial` with 8, `equidistant` with 4, or no coefficients at all (no distortion; the model may then be
/// absent, empty or `none`). Errors carry the parser's line and the
/// key path, e.g. `camera.yaml:7: field 'camera_matrix.data[0] (fx)': fx must be positive, got 0 (column 10)`.
pub fn parse_camera_yaml(text: &str, path: impl AsRef<Path>) -> Result<CameraModel, FormatError> {
    let path = path.as_ref();
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    if text.trim().is_empty() {
        return Err(FormatError::new(
            path,
            "empty file: expected a ROS camera_info YAML document",
        ));
    }
    crate::limits::check_yaml_depth(text, path)?;
    let doc: CameraInfoYaml = serde_yaml_ng::from_str(text).map_err(|e| yaml_error(&e, path))?;
    let coefficients = doc.distortion_coefficients.map(|c| c.0).unwrap_or_default();
    let model = match doc.distortion_model {
        Some(DistortionModel(name)) => name,
        None if coefficients.is_empty() => String::new(),
        None => {
            return Err(FormatError::new(
                path,
                format!(
                    "missing, but distortion_coefficients has {} values: set it to plumb_bob, \
                     rational_polynomial or equidistant",
                    coefficients.len()
                ),
            )
            .with_field("distortion_model"));
        }
    };
    let distortion = Distortion::from_model(&model, &coefficients)
        .map_err(|e| FormatError::new(path, e).with_field("distortion_coefficients.data"))?;
    // The deserializer has checked that K has 9 numbers in the right layout.
    let &[fx_px, skew_px, cx_px, _, fy_px, cy_px, ..] = doc.camera_matrix.0.as_slice() else {
        return Err(FormatError::new(path, "expected 9 numbers").with_field("camera_matrix.data"));
    };
    let intrinsics = PinholeIntrinsics {
        fx_px,
        fy_px,
        skew_px,
        cx_px,
        cy_px,
    };
    CameraModel::new(
        doc.camera_name.unwrap_or_default(),
        doc.image_width.0,
        doc.image_height.0,
        intrinsics,
        distortion,
    )
    .map_err(|e| camera_error(&e, &distortion, path))
}

/// The camera as ROS camera_info YAML text. Numbers are written with full round-trip precision and always as YAML
/// floats (with a decimal point), so that ROS's Python and C++ readers and this crate read back the same `f64`.
pub fn camera_yaml_string(camera: &CameraModel) -> String {
    let k = &camera.intrinsics;
    let camera_matrix = [
        k.fx_px, k.skew_px, k.cx_px, 0.0, k.fy_px, k.cy_px, 0.0, 0.0, 1.0,
    ];
    let rectification = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0];
    let projection = [
        k.fx_px, k.skew_px, k.cx_px, 0.0, 0.0, k.fy_px, k.cy_px, 0.0, 0.0, 0.0, 1.0, 0.0,
    ];
    let mut text = String::new();
    // Writing to a String cannot fail.
    let _ = write!(
        text,
        "image_width: {}\nimage_height: {}\ncamera_name: {}\n",
        camera.width_px,
        camera.height_px,
        yaml_string(&camera.name)
    );
    write_matrix(&mut text, "camera_matrix", 3, 3, &camera_matrix);
    // No distortion is written as plumb_bob without coefficients, which every ROS reader takes.
    let model = match camera.distortion {
        Distortion::None => "plumb_bob",
        d => d.model_name(),
    };
    let coefficients = camera.distortion.coefficients();
    let _ = writeln!(text, "distortion_model: {model}");
    write_matrix(
        &mut text,
        "distortion_coefficients",
        1,
        coefficients.len(),
        &coefficients,
    );
    write_matrix(&mut text, "rectification_matrix", 3, 3, &rectification);
    write_matrix(&mut text, "projection_matrix", 3, 4, &projection);
    text
}

/// Writes a ROS camera_info YAML file atomically (its directory must exist). An invalid camera (non-finite values,
/// non-positive focal length, empty image) is refused, since it could not be read back.
pub fn write_camera_yaml(path: impl AsRef<Path>, camera: &CameraModel) -> Result<(), FormatError> {
    let path = path.as_ref();
    CameraModel::new(
        camera.name.clone(),
        camera.width_px,
        camera.height_px,
        camera.intrinsics,
        camera.distortion,
    )
    .map_err(|e| camera_error(&e, &camera.distortion, path))?;
    let mut file = AtomicFile::create(path)?;
    file.write_all(camera_yaml_string(camera).as_bytes())
        .map_err(|e| file.write_error(e))?;
    file.finish()
}

fn write_matrix(text: &mut String, key: &str, rows: usize, cols: usize, data: &[f64]) {
    let data: Vec<String> = data.iter().map(|&v| yaml_float(v)).collect();
    let _ = writeln!(
        text,
        "{key}:\n  rows: {rows}\n  cols: {cols}\n  data: [{}]",
        data.join(", ")
    );
}

/// `v` as a YAML float that reads back bit-exactly: Rust's shortest round-trip digits, never an exponent, always a
/// decimal point (YAML 1.1 readers such as PyYAML take `1500` for an integer and `1e-05` for a string).
fn yaml_float(v: f64) -> String {
    if v.is_nan() {
        return ".nan".to_string();
    }
    if v.is_infinite() {
        return if v > 0.0 { ".inf" } else { "-.inf" }.to_string();
    }
    let mut s = v.to_string();
    if !s.contains('.') {
        s.push_str(".0");
    }
    s
}

/// `s` as a YAML scalar that reads back as the same string: plain when unambiguous, else double-quoted.
fn yaml_string(s: &str) -> String {
    const RESERVED: [&str; 11] = [
        "true", "false", "yes", "no", "on", "off", "null", "y", "n", "nan", "inf",
    ];
    let plain = s.starts_with(|c: char| c.is_ascii_alphabetic() || c == '_')
        && s.chars()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '.' | '/'))
        && !RESERVED.contains(&s.to_ascii_lowercase().as_str());
    if plain {
        return s.to_string();
    }
    let mut quoted = String::with_capacity(s.len() + 2);
    quoted.push('"');
    for c in s.chars() {
        match c {
            '"' => quoted.push_str("\\\""),
            '\\' => quoted.push_str("\\\\"),
            '\n' => quoted.push_str("\\n"),
            '\t' => quoted.push_str("\\t"),
            c if c.is_control() || matches!(c, '\u{2028}' | '\u{2029}' | '\u{feff}') => {
                let _ = write!(quoted, "\\u{:04x}", c as u32);
            }
            c => quoted.push(c),
        }
    }
    quoted.push('"');
    quoted
}

/// A serde_yaml_ng error as a [`FormatError`]: the parser's line, the key path as the field.
fn yaml_error(error: &serde_yaml_ng::Error, path: &Path) -> FormatError {
    let location = error.location();
    let mut text = error.to_string();
    let mut column = None;
    if let Some(loc) = &location {
        let suffix = format!(" at line {} column {}", loc.line(), loc.column());
        if let Some(stripped) = text.strip_suffix(&suffix) {
            column = Some(loc.column());
            text.truncate(stripped.len());
        }
    }
    // serde_yaml_ng writes "key.path[3]: message"; our keys are plain identifiers.
    let is_key_path = |s: &str| {
        !s.is_empty()
            && s.chars()
                .all(|c| c.is_ascii_alphanumeric() || matches!(c, '_' | '.' | '[' | ']'))
    };
    let (mut field, mut message) = match text.split_once(": ") {
        Some((head, rest)) if is_key_path(head) => (Some(head.to_string()), rest.to_string()),
        _ => (None, text.clone()),
    };
    for (prefix, short) in [
        ("missing field `", "missing"),
        ("duplicate field `", "given twice"),
    ] {
        if let Some(key) = message
            .strip_prefix(prefix)
            .and_then(|r| r.strip_suffix('`'))
        {
            field = Some(match field {
                Some(parent) => format!("{parent}.{key}"),
                None => key.to_string(),
            });
            message = short.to_string();
            break;
        }
    }
    if let Some(column) = column {
        let _ = write!(message, " (column {column})");
    }
    let mut e = FormatError::new(path, message).with_line(location.map(|l| l.line() as u64));
    if let Some(field) = field {
        e = e.with_field(annotate_field(&field));
    }
    e
}

/// `camera_matrix.data[0]` -> `camera_matrix.data[0] (fx)`, and likewise for the distortion coefficients.
fn annotate_field(field: &str) -> String {
    const K_NAMES: [&str; 9] = ["fx", "skew", "cx", "", "fy", "cy", "", "", ""];
    // plumb_bob's and rational_polynomial's order; equidistant's k3 and k4 stand where these have p1 and p2.
    const D_NAMES: [&str; 8] = ["k1", "k2", "p1 or k3", "p2 or k4", "k3", "k4", "k5", "k6"];
    let name = field
        .strip_prefix("camera_matrix.data[")
        .and_then(|r| r.strip_suffix(']'))
        .and_then(|i| i.parse::<usize>().ok())
        .and_then(|i| K_NAMES.get(i))
        .or_else(|| {
            field
                .strip_prefix("distortion_coefficients.data[")
                .and_then(|r| r.strip_suffix(']'))
                .and_then(|i| i.parse::<usize>().ok())
                .and_then(|i| D_NAMES.get(i))
        });
    match name {
        Some(name) if !name.is_empty() => format!("{field} ({name})"),
        _ => field.to_string(),
    }
}

/// A [`CameraError`] as a [`FormatError`] naming the YAML field of the offending value.
fn camera_error(error: &CameraError, distortion: &Distortion, path: &Path) -> FormatError {
    let named = match error {
        CameraError::NotFinite { field, .. } | CameraError::NotPositive { field, .. } => {
            Some(*field)
        }
        CameraError::Implausible(e) => Some(e.field),
        CameraError::Lens(e) => Some(e.coefficient()),
        _ => None,
    };
    let field = match (error, named) {
        (_, Some(name)) => match name {
            "fx" => "camera_matrix.data[0] (fx)".to_string(),
            "skew" => "camera_matrix.data[1] (skew)".to_string(),
            "cx" => "camera_matrix.data[2] (cx)".to_string(),
            "fy" => "camera_matrix.data[4] (fy)".to_string(),
            "cy" => "camera_matrix.data[5] (cy)".to_string(),
            name => match distortion
                .coefficient_names()
                .iter()
                .position(|n| n == &name)
            {
                Some(i) => format!("distortion_coefficients.data[{i}] ({name})"),
                None => name.to_string(),
            },
        },
        (CameraError::EmptyImage { width_px: 0, .. }, _) => "image_width".to_string(),
        (CameraError::EmptyImage { .. }, _) => "image_height".to_string(),
        (CameraError::ImageTooLarge { width_px, .. }, _)
            if *width_px > roitrack_core::camera::MAX_IMAGE_SIDE_PX =>
        {
            "image_width".to_string()
        }
        (CameraError::ImageTooLarge { .. }, _) => "image_height".to_string(),
        (CameraError::UndistortionDiverged { .. }, _) => "distortion_coefficients".to_string(),
        // A camera_info file carries no time model: a camera read from one has the default (sequential ROIs).
        (CameraError::TimeModel(_), _) => "time model".to_string(),
        // Named above.
        (
            CameraError::NotFinite { .. }
            | CameraError::NotPositive { .. }
            | CameraError::Implausible(_)
            | CameraError::Lens(_),
            None,
        ) => String::new(),
    };
    FormatError::new(path, error.to_string()).with_field(field)
}

// ---------------------------------------------------------------------------------------------------------------
// Deserialisation. The checks run inside the YAML deserializer, so that their errors carry the parser's location.

#[derive(Deserialize)]
#[serde(expecting = "a ROS camera_info mapping (image_width, image_height, camera_matrix, ...)")]
struct CameraInfoYaml {
    image_width: ImageSize,
    image_height: ImageSize,
    camera_name: Option<String>,
    camera_matrix: CameraMatrix,
    distortion_model: Option<DistortionModel>,
    distortion_coefficients: Option<DistortionCoefficients>,
}

/// A positive image size (pixels).
struct ImageSize(u32);

impl<'de> Deserialize<'de> for ImageSize {
    fn deserialize<D: de::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        struct V;
        impl Visitor<'_> for V {
            type Value = ImageSize;
            fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str("a positive image size in pixels")
            }
            fn visit_u64<E: de::Error>(self, v: u64) -> Result<ImageSize, E> {
                match u32::try_from(v) {
                    Ok(size) if size > 0 => Ok(ImageSize(size)),
                    _ => Err(E::invalid_value(Unexpected::Unsigned(v), &self)),
                }
            }
            fn visit_i64<E: de::Error>(self, v: i64) -> Result<ImageSize, E> {
                match u64::try_from(v) {
                    Ok(v) => self.visit_u64(v),
                    Err(_) => Err(E::invalid_value(Unexpected::Signed(v), &self)),
                }
            }
        }
        deserializer.deserialize_u32(V)
    }
}

/// The `distortion_model` string (checked against the coefficients once both are read).
struct DistortionModel(String);

impl<'de> Deserialize<'de> for DistortionModel {
    fn deserialize<D: de::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        struct V;
        impl Visitor<'_> for V {
            type Value = DistortionModel;
            fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str("a distortion model name (plumb_bob, rational_polynomial, equidistant)")
            }
            fn visit_str<E: de::Error>(self, v: &str) -> Result<DistortionModel, E> {
                let name = v.trim();
                match Distortion::check_model_name(name) {
                    Ok(()) => Ok(DistortionModel(name.to_string())),
                    Err(e) => Err(E::custom(e)),
                }
            }
        }
        deserializer.deserialize_str(V)
    }
}

/// Which matrix is being read: decides the shape and the value checks.
#[derive(Clone, Copy)]
enum MatrixKind {
    /// K, 3 x 3.
    Camera,
    /// The distortion coefficients, 1 x N.
    Distortion,
}

impl MatrixKind {
    fn describe(self) -> &'static str {
        match self {
            Self::Camera => "9 numbers (3 x 3, row-major)",
            Self::Distortion => {
                "4, 5 or 8 numbers (k1, k2, p1, p2[, k3[, k4, k5, k6]] or equidistant's k1, k2, k3, k4), or none"
            }
        }
    }

    fn count_ok(self, n: usize) -> bool {
        match self {
            Self::Camera => n == 9,
            Self::Distortion => matches!(n, 0 | 4 | 5 | 8),
        }
    }

    /// Checks element `index` of the data: finite, and for K the fixed structure and positive focal lengths.
    fn check_value(self, index: usize, v: f64) -> Result<(), String> {
        const K_LAYOUT: &str = "K must be [[fx, s, cx], [0, fy, cy], [0, 0, 1]]";
        if !v.is_finite() {
            return Err(format!("must be a finite number, got {v}"));
        }
        if let Self::Camera = self {
            match index {
                0 | 4 if v <= 0.0 => {
                    let name = if index == 0 { "fx" } else { "fy" };
                    return Err(format!("{name} must be positive, got {v}"));
                }
                3 | 6 | 7 if v != 0.0 => return Err(format!("must be 0 ({K_LAYOUT}), got {v}")),
                8 if v != 1.0 => return Err(format!("must be 1 ({K_LAYOUT}), got {v}")),
                _ => {}
            }
        }
        Ok(())
    }
}

/// The 9 numbers of K, row-major, checked.
struct CameraMatrix(Vec<f64>);

/// 0, 4, 5 or 8 distortion coefficients, checked.
struct DistortionCoefficients(Vec<f64>);

impl<'de> Deserialize<'de> for CameraMatrix {
    fn deserialize<D: de::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        deserializer
            .deserialize_map(MatrixVisitor(MatrixKind::Camera))
            .map(Self)
    }
}

impl<'de> Deserialize<'de> for DistortionCoefficients {
    fn deserialize<D: de::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        deserializer
            .deserialize_map(MatrixVisitor(MatrixKind::Distortion))
            .map(Self)
    }
}

/// A ROS matrix mapping `{rows, cols, data}`.
struct MatrixVisitor(MatrixKind);

impl<'de> Visitor<'de> for MatrixVisitor {
    type Value = Vec<f64>;

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("a matrix mapping {rows, cols, data}")
    }

    fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<Vec<f64>, A::Error> {
        let (mut rows, mut cols, mut data) = (None::<u64>, None::<u64>, None::<Vec<f64>>);
        while let Some(key) = map.next_key::<String>()? {
            match key.as_str() {
                "rows" if rows.is_some() => return Err(de::Error::duplicate_field("rows")),
                "cols" if cols.is_some() => return Err(de::Error::duplicate_field("cols")),
                "data" if data.is_some() => return Err(de::Error::duplicate_field("data")),
                "rows" => rows = Some(map.next_value()?),
                "cols" => cols = Some(map.next_value()?),
                "data" => data = Some(map.next_value_seed(DataSeed(self.0))?),
                _ => {
                    map.next_value::<IgnoredAny>()?;
                }
            }
        }
        let rows = rows.ok_or_else(|| de::Error::missing_field("rows"))?;
        let cols = cols.ok_or_else(|| de::Error::missing_field("cols"))?;
        let data = data.ok_or_else(|| de::Error::missing_field("data"))?;
        match self.0 {
            MatrixKind::Camera if rows != 3 || cols != 3 => Err(de::Error::custom(format!(
                "the camera matrix must be 3 x 3, got rows x cols = {rows} x {cols}"
            ))),
            MatrixKind::Distortion if rows.checked_mul(cols) != Some(data.len() as u64) => {
                Err(de::Error::custom(format!(
                    "rows x cols = {rows} x {cols} does not match the {} numbers of data",
                    data.len()
                )))
            }
            _ => Ok(data),
        }
    }
}

/// The `data` sequence of a matrix.
struct DataSeed(MatrixKind);

impl<'de> DeserializeSeed<'de> for DataSeed {
    type Value = Vec<f64>;

    fn deserialize<D: de::Deserializer<'de>>(self, deserializer: D) -> Result<Vec<f64>, D::Error> {
        deserializer.deserialize_seq(self)
    }
}

impl<'de> Visitor<'de> for DataSeed {
    type Value = Vec<f64>;

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "a sequence of {}", self.0.describe())
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Vec<f64>, A::Error> {
        let mut data = Vec::new();
        while let Some(v) = seq.next_element_seed(NumberSeed {
            kind: self.0,
            index: data.len(),
        })? {
            data.push(v);
            if data.len() > 64 {
                break;
            }
        }
        if !self.0.count_ok(data.len()) {
            let count = if data.len() > 64 {
                "more than 64".to_string()
            } else {
                data.len().to_string()
            };
            return Err(de::Error::custom(format!(
                "expected {}, got {count}",
                self.0.describe()
            )));
        }
        Ok(data)
    }
}

/// One element of a matrix's data, checked where it stands.
struct NumberSeed {
    kind: MatrixKind,
    index: usize,
}

impl<'de> DeserializeSeed<'de> for NumberSeed {
    type Value = f64;

    fn deserialize<D: de::Deserializer<'de>>(self, deserializer: D) -> Result<f64, D::Error> {
        deserializer.deserialize_f64(self)
    }
}

impl Visitor<'_> for NumberSeed {
    type Value = f64;

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("a number")
    }

    fn visit_f64<E: de::Error>(self, v: f64) -> Result<f64, E> {
        self.kind.check_value(self.index, v).map_err(E::custom)?;
        Ok(v)
    }

    fn visit_i64<E: de::Error>(self, v: i64) -> Result<f64, E> {
        self.visit_f64(v as f64)
    }

    fn visit_u64<E: de::Error>(self, v: u64) -> Result<f64, E> {
        self.visit_f64(v as f64)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use roitrack_core::PlumbBob;

    const CANONICAL: &str = "\
image_width: 1024
image_height: 1024
camera_name: roitrack_canonical
camera_matrix:
  rows: 3
  cols: 3
  data: [1500.0, 0.0, 512.0, 0.0, 1500.0, 512.0, 0.0, 0.0, 1.0]
distortion_model: plumb_bob
distortion_coefficients:
  rows: 1
  cols: 5
  data: [0.0, 0.0, 0.0, 0.0, 0.0]
rectification_matrix:
  rows: 3
  cols: 3
  data: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
projection_matrix:
  rows: 3
  cols: 4
  data: [1500.0, 0.0, 512.0, 0.0, 0.0, 1500.0, 512.0, 0.0, 0.0, 0.0, 1.0, 0.0]
";

    fn distorted() -> CameraModel {
        CameraModel::new(
            "cam0",
            1280,
            960,
            PinholeIntrinsics {
                fx_px: 1_480.123_456_789_012_3,
                fy_px: 1_510.000_000_000_001,
                skew_px: 0.8,
                cx_px: 0.1 + 0.2,
                cy_px: 506.0,
            },
            PlumbBob::from_coefficients([-0.28, 0.12, 1.2e-3, -8e-4, -3.000_000_000_000_1e-7]),
        )
        .unwrap()
    }

    fn parse_err(text: &str) -> String {
        parse_camera_yaml(text, "camera.yaml")
            .unwrap_err()
            .to_string()
    }

    /// The canonical document with `from` replaced by `to`.
    fn canonical_with(from: &str, to: &str) -> String {
        assert!(CANONICAL.contains(from), "{from}");
        CANONICAL.replacen(from, to, 1)
    }

    #[test]
    fn canonical_text_is_what_we_write() {
        assert_eq!(camera_yaml_string(&CameraModel::canonical()), CANONICAL);
        assert_eq!(
            parse_camera_yaml(CANONICAL, "c.yaml").unwrap(),
            CameraModel::canonical()
        );
    }

    #[test]
    fn round_trip_with_skew_and_distortion_is_bit_exact() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("camera.yaml");
        let camera = distorted();
        write_camera_yaml(&path, &camera).unwrap();
        let back = read_camera_yaml(&path).unwrap();
        assert_eq!(back, camera);
        let (a, b) = (back.intrinsics, camera.intrinsics);
        assert_eq!(a.cx_px.to_bits(), b.cx_px.to_bits());
        assert_eq!(
            back.distortion
                .coefficients()
                .into_iter()
                .map(f64::to_bits)
                .collect::<Vec<_>>(),
            camera
                .distortion
                .coefficients()
                .into_iter()
                .map(f64::to_bits)
                .collect::<Vec<_>>()
        );
    }

    #[test]
    fn awkward_names_round_trip() {
        for name in [
            "",
            "null",
            "123",
            "a \"b\"\n\tc\\",
            "  x",
            "日本 カメラ",
            "yes",
            "#x",
            "-",
        ] {
            let mut camera = CameraModel::canonical();
            camera.name = name.to_string();
            let back = parse_camera_yaml(&camera_yaml_string(&camera), "c.yaml").unwrap();
            assert_eq!(back.name, name);
        }
    }

    #[test]
    fn extreme_floats_round_trip() {
        let mut camera = distorted();
        camera.distortion =
            PlumbBob::from_coefficients([-0.28, 0.12, -2.5e-17, -8e-4, 1e-300]).into();
        // Every digit of an f64, within the focal lengths a camera may have.
        camera.intrinsics.fx_px = 1_234.567_890_123_456_7;
        camera.intrinsics.cy_px = -0.0;
        let back = parse_camera_yaml(&camera_yaml_string(&camera), "c.yaml").unwrap();
        assert_eq!(back, camera);
        assert!(back.intrinsics.cy_px.is_sign_negative());
    }

    #[test]
    fn ros_variants_are_accepted() {
        // Integers for floats, no distortion at all, extra keys, flow style, comments.
        let text = "# calibration\nimage_width: 640\nimage_height: 480\ncamera_matrix: {rows: 3, cols: 3, \
                    data: [500, 0, 320, 0, 500, 240, 0, 0, 1]}\nbinning_x: 0\n";
        let c = parse_camera_yaml(text, "c.yaml").unwrap();
        assert_eq!(c.name, "");
        assert_eq!(c.intrinsics.fx_px, 500.0);
        assert!(c.distortion.is_identity());
        let text = canonical_with(
            "  rows: 1\n  cols: 5\n  data: [0.0, 0.0, 0.0, 0.0, 0.0]",
            "  rows: 1\n  cols: 0\n  data: []",
        );
        assert!(
            parse_camera_yaml(&text, "c.yaml")
                .unwrap()
                .distortion
                .is_identity()
        );
        let text = text.replace("distortion_model: plumb_bob", "distortion_model: \"\"");
        assert!(parse_camera_yaml(&text, "c.yaml").is_ok());
    }

    #[test]
    fn syntax_error_mentions_the_line() {
        let text = canonical_with("  data: [1500.0, 0.0", "  data: [1500.0, 0.0}");
        let e = parse_camera_yaml(&text, "camera.yaml").unwrap_err();
        assert_eq!(e.line(), Some(7), "{e}");
        assert!(e.to_string().starts_with("camera.yaml:7: "), "{e}");
        let e = parse_err("image_width: 5\nimage_height: 6: 7\n");
        assert!(e.starts_with("camera.yaml:2: "), "{e}");
    }

    #[test]
    fn focal_length_zero_negative_nan() {
        let e = parse_err(&canonical_with(
            "data: [1500.0, 0.0, 512.0",
            "data: [0, 0.0, 512.0",
        ));
        assert_eq!(
            e,
            "camera.yaml:7: field 'camera_matrix.data[0] (fx)': fx must be positive, got 0 (column 10)"
        );
        let e = parse_err(&canonical_with("0.0, 1500.0, 512.0", "0.0, -1500.0, 512.0"));
        assert!(
            e.starts_with(
                "camera.yaml:7: field 'camera_matrix.data[4] (fy)': fy must be positive, got -1500"
            ),
            "{e}"
        );
        let e = parse_err(&canonical_with(
            "data: [1500.0, 0.0, 512.0",
            "data: [.nan, 0.0, 512.0",
        ));
        assert!(
            e.starts_with("camera.yaml:7: field 'camera_matrix.data[0] (fx)': must be a finite number, got NaN"),
            "{e}"
        );
        let e = parse_err(&canonical_with(
            "data: [0.0, 0.0, 0.0, 0.0, 0.0]",
            "data: [0.0, .inf, 0.0, 0.0, 0.0]",
        ));
        assert!(
            e.starts_with("camera.yaml:12: field 'distortion_coefficients.data[1] (k2)': "),
            "{e}"
        );
        let e = parse_err(&canonical_with(
            "data: [1500.0, 0.0, 512.0",
            "data: [fast, 0.0, 512.0",
        ));
        assert!(
            e.starts_with("camera.yaml:7: field 'camera_matrix.data[0] (fx)': invalid type"),
            "{e}"
        );
    }

    #[test]
    fn camera_matrix_shape_and_structure() {
        let e = parse_err(&canonical_with(
            "0.0, 0.0, 1.0]\ndistortion",
            "0.0, 0.0]\ndistortion",
        ));
        assert!(
            e.starts_with("camera.yaml:7: field 'camera_matrix.data': expected 9 numbers"),
            "{e}"
        );
        assert!(e.contains("got 8"), "{e}");
        let e = parse_err(&canonical_with(
            "0.0, 0.0, 1.0]\ndistortion",
            "0.0, 0.0, 2.0]\ndistortion",
        ));
        assert!(
            e.starts_with("camera.yaml:7: field 'camera_matrix.data[8]': must be 1"),
            "{e}"
        );
        let e = parse_err(&canonical_with("512.0, 0.0, 1500.0", "512.0, 3.0, 1500.0"));
        assert!(
            e.starts_with("camera.yaml:7: field 'camera_matrix.data[3]': must be 0"),
            "{e}"
        );
        let e = parse_err(&canonical_with(
            "  rows: 3\n  cols: 3\n  data: [1500",
            "  rows: 3\n  cols: 4\n  data: [1500",
        ));
        assert!(
            e.starts_with("camera.yaml:5: field 'camera_matrix': the camera matrix must be 3 x 3, got rows x cols = 3 x 4"),
            "{e}"
        );
        let e = parse_err(&canonical_with(
            "  rows: 3\n  cols: 3\n  data: [1500",
            "  rows: 3\n  data: [1500",
        ));
        assert!(
            e.starts_with("camera.yaml:5: field 'camera_matrix.cols': missing"),
            "{e}"
        );
        let e = parse_err(&canonical_with("camera_matrix:", "camera_matrx:"));
        assert!(
            e.starts_with("camera.yaml:1: field 'camera_matrix': missing"),
            "{e}"
        );
    }

    #[test]
    fn distortion_model_and_coefficients() {
        let e = parse_err(&canonical_with(
            "distortion_model: plumb_bob",
            "distortion_model: rational_polynomial",
        ));
        assert!(
            e.starts_with("camera.yaml: field 'distortion_coefficients.data': rational_polynomial takes 8 numbers"),
            "{e}"
        );
        let e = parse_err(&canonical_with(
            "distortion_model: plumb_bob",
            "distortion_model: omni",
        ));
        assert!(
            e.starts_with(
                "camera.yaml:8: field 'distortion_model': unsupported distortion model \"omni\""
            ),
            "{e}"
        );
        let e = parse_err(&canonical_with("distortion_model: plumb_bob\n", ""));
        assert!(
            e.starts_with("camera.yaml: field 'distortion_model': missing"),
            "{e}"
        );
        // Four plumb_bob coefficients are k1, k2, p1, p2 with k3 = 0.
        let four = canonical_with(
            "  cols: 5\n  data: [0.0, 0.0, 0.0, 0.0, 0.0]",
            "  cols: 4\n  data: [-0.1, 0.01, 0.001, 0.002]",
        );
        let c = parse_camera_yaml(&four, "c.yaml").unwrap();
        assert_eq!(
            c.distortion,
            PlumbBob::from_coefficients([-0.1, 0.01, 0.001, 0.002, 0.0]).into()
        );
        let e = parse_err(
            &four
                .replace("plumb_bob", "equidistant")
                .replace("cols: 4", "cols: 5")
                .replace("0.002]", "0.002, 0.0]"),
        );
        assert!(
            e.contains("field 'distortion_coefficients.data': equidistant takes 4 numbers"),
            "{e}"
        );
        let e = parse_err(&canonical_with(
            "  cols: 5\n  data: [0.0, 0.0, 0.0, 0.0, 0.0]",
            "  cols: 3\n  data: [0.0, 0.0, 0.0]",
        ));
        assert!(
            e.starts_with(
                "camera.yaml:12: field 'distortion_coefficients.data': expected 4, 5 or 8 numbers"
            ),
            "{e}"
        );
        let e = parse_err(&canonical_with(
            "  rows: 1\n  cols: 5",
            "  rows: 2\n  cols: 5",
        ));
        assert!(
            e.starts_with("camera.yaml:10: field 'distortion_coefficients': rows x cols"),
            "{e}"
        );
    }

    #[test]
    fn every_model_round_trips_bit_exactly() {
        use roitrack_core::camera::{Equidistant, RationalPolynomial};
        for distortion in [
            Distortion::None,
            PlumbBob::from_coefficients([-0.28, 0.12, 1.2e-3, -8e-4, 0.1 + 0.2]).into(),
            RationalPolynomial::from_coefficients([
                0.42, -0.11, 7e-4, -4e-4, 0.013, 0.71, -0.05, 1e-300,
            ])
            .into(),
            Equidistant::from_coefficients([-0.013, 0.021, -0.011, 0.0023]).into(),
        ] {
            let mut camera = distorted();
            camera.distortion = distortion;
            let text = camera_yaml_string(&camera);
            assert!(
                text.contains(&format!(
                    "distortion_model: {}",
                    match distortion {
                        Distortion::None => "plumb_bob",
                        d => d.model_name(),
                    }
                )),
                "{text}"
            );
            assert_eq!(
                parse_camera_yaml(&text, "c.yaml").unwrap(),
                camera,
                "{text}"
            );
        }
    }

    #[test]
    fn image_size_and_document_shape() {
        let e = parse_err(&canonical_with("image_width: 1024", "image_width: 0"));
        assert!(
            e.starts_with("camera.yaml:1: field 'image_width': invalid value"),
            "{e}"
        );
        let e = parse_err(&canonical_with("image_height: 1024", "image_height: -3"));
        assert!(
            e.starts_with("camera.yaml:2: field 'image_height': "),
            "{e}"
        );
        let e = parse_err(&canonical_with("image_height: 1024", "image_height: 1e12"));
        assert!(
            e.starts_with("camera.yaml:2: field 'image_height': "),
            "{e}"
        );
        let e = parse_err(&canonical_with(
            "image_height: 1024",
            "image_height: 1024\nimage_width: 5",
        ));
        assert!(e.contains("field 'image_width': given twice"), "{e}");
        assert!(parse_err("").starts_with("camera.yaml: empty file"));
        assert!(parse_err("just a string\n").starts_with("camera.yaml:1: "));
        assert!(parse_err("- 1\n- 2\n").starts_with("camera.yaml:1: "));
        assert!(parse_err("a: 1\n---\nb: 2\n").starts_with("camera.yaml"));
    }

    #[test]
    fn writer_refuses_invalid_cameras_and_missing_directories() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("camera.yaml");
        let mut camera = CameraModel::canonical();
        camera.intrinsics.fy_px = 0.0;
        let e = write_camera_yaml(&path, &camera).unwrap_err();
        assert!(
            e.to_string().contains("field 'camera_matrix.data[4] (fy)'"),
            "{e}"
        );
        assert!(!path.exists());
        let e = write_camera_yaml(dir.path().join("no/camera.yaml"), &CameraModel::canonical())
            .unwrap_err();
        assert!(e.to_string().contains("camera.yaml"), "{e}");
        let e = read_camera_yaml(dir.path().join("absent.yaml")).unwrap_err();
        assert!(e.to_string().contains("absent.yaml"), "{e}");
    }
}
