//! Rig files: several cameras, each with its calibration file, its pose in the rig and its clock.
//!
//! ```yaml
//! cameras:
//!   - name: left
//!     calibration: left.yaml        # any calibration file roitrack reads, relative to the rig file
//!     camera_T_rig: [0, 0, 0, 0, 0, 0, 1]   # tx ty tz qx qy qz qw (TUM order): x_camera = R x_rig + t
//!   - name: right
//!     calibration: right.yaml
//!     camera_T_rig: [-0.3, 0, 0.05, 0, 0.1305, 0, 0.9914]
//!     clock_offset_s: 0.0123        # optional; absent = to be estimated
//!     clock_drift_ppm: 40           # optional; absent = to be estimated
//! ```
//!
//! The clock model is `t_rig = clock_offset_s + t_camera / (1 + clock_drift_ppm * 1e-6)`; the first camera's clock is
//! the rig's (offset 0, drift 0) unless the file gives it. A camera's `camera_T_rig` may be left out for
//! calibrate-rig to find (the first camera's frame is then the rig's). A written rig may also carry the standard
//! deviations of learnt poses and clocks (`camera_T_rig_sigma_m`, `camera_T_rig_sigma_deg`, `clock_offset_sigma_s`,
//! `clock_drift_sigma_ppm`), which the reader takes as comments on the values.

use std::fmt::Write as _;
use std::io::Write as _;
use std::path::{Path, PathBuf};

use nalgebra::{Quaternion, Translation3, UnitQuaternion, Vector3};
use roitrack_estimators::rig::{
    CameraMount, ClockEstimate, ClockModel, Rig, RigCalibration, RigCamera,
};
use serde::Deserialize;

use crate::limits::{check_yaml_depth, read_text_file};
use crate::{
    AtomicFile, CameraFileOptions, FormatError, MAX_CAMERA_FILE_BYTES, QUATERNION_NORM_TOLERANCE,
    read_camera_file,
};

/// The most cameras a rig file may list.
pub const MAX_RIG_CAMERAS: usize = 64;

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RigYaml {
    cameras: Vec<CameraYaml>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct CameraYaml {
    name: String,
    calibration: String,
    #[serde(rename = "camera_T_rig")]
    camera_t_rig: Option<Vec<f64>>,
    #[serde(rename = "camera_T_rig_sigma_m")]
    camera_t_rig_sigma_m: Option<Vec<f64>>,
    #[serde(rename = "camera_T_rig_sigma_deg")]
    camera_t_rig_sigma_deg: Option<Vec<f64>>,
    clock_offset_s: Option<f64>,
    clock_drift_ppm: Option<f64>,
    clock_offset_sigma_s: Option<f64>,
    clock_drift_sigma_ppm: Option<f64>,
}

/// A rig as read from its file: the rig (calibrations read), and each camera's calibration path as the file wrote
/// it and as resolved against the rig file's folder.
#[derive(Debug, Clone, PartialEq)]
pub struct RigFile {
    /// The rig, its cameras' calibrations read.
    pub rig: Rig,
    /// Per camera, the `calibration` entry as written.
    pub calibrations_as_written: Vec<String>,
    /// Per camera, its calibration file's path (relative to the rig file's folder when written so).
    pub calibration_paths: Vec<PathBuf>,
    /// The rig file's own path, as given to the reader.
    pub path: PathBuf,
}

impl RigFile {
    /// The `calibration` entries of a rig file written to `out` from this one: as this file wrote them when `out` is
    /// in the same folder, else absolute paths (so that the written rig still finds its calibrations).
    ///
    /// ```
    /// use roitrack_formats::{CameraFileOptions, read_rig_yaml, write_camera_yaml};
    /// use roitrack_core::CameraModel;
    ///
    /// let dir = tempfile::tempdir().unwrap();
    /// write_camera_yaml(dir.path().join("left.yaml"), &CameraModel::canonical()).unwrap();
    /// std::fs::write(dir.path().join("rig.yaml"), "cameras:\n  - name: left\n    calibration: left.yaml\n").unwrap();
    /// let file = read_rig_yaml(dir.path().join("rig.yaml"), &CameraFileOptions::default()).unwrap();
    /// assert_eq!(file.calibrations_for_output(dir.path().join("out.yaml")), ["left.yaml"]);
    /// ```
    pub fn calibrations_for_output(&self, out: impl AsRef<Path>) -> Vec<String> {
        let folder = |p: &Path| {
            let parent = p.parent().unwrap_or(Path::new(""));
            std::fs::canonicalize(if parent.as_os_str().is_empty() {
                Path::new(".")
            } else {
                parent
            })
            .ok()
        };
        let here = folder(&self.path);
        if here.is_some() && here == folder(out.as_ref()) {
            return self.calibrations_as_written.clone();
        }
        self.calibration_paths
            .iter()
            .map(|p| {
                std::fs::canonicalize(p)
                    .unwrap_or_else(|_| p.clone())
                    .to_string_lossy()
                    .into_owned()
            })
            .collect()
    }
}

/// Reads a rig file (YAML: `cameras:`, each with `name`, `calibration`, and optionally `camera_T_rig` as tx ty tz qx
/// qy qz qw (left out: to be found, [`RigCamera::mount_known`]), `clock_offset_s` and `clock_drift_ppm`; docs/rig.md) and every calibration it names (relative paths from the
/// rig file's folder), with `options` for the calibrations.
///
/// Errors name the rig file and the camera: a name given twice, a calibration missing or unreadable (its own error
/// follows), a `camera_T_rig` that is not 7 finite numbers or whose quaternion is not of unit norm (within
/// [`QUATERNION_NORM_TOLERANCE`]), a clock that is not finite, an unknown key.
///
/// ```
/// use roitrack_formats::{CameraFileOptions, read_rig_yaml, write_camera_yaml};
/// use roitrack_core::CameraModel;
///
/// let dir = tempfile::tempdir().unwrap();
/// write_camera_yaml(dir.path().join("left.yaml"), &CameraModel::canonical()).unwrap();
/// std::fs::write(dir.path().join("rig.yaml"), "cameras:\n  - name: left\n    calibration: left.yaml\n    \
///     camera_T_rig: [0, 0, 0, 0, 0, 0, 1]\n  - name: right\n    calibration: left.yaml\n    \
///     camera_T_rig: [-0.3, 0, 0.05, 0, 0.1305, 0, 0.9914]\n    clock_offset_s: 0.0123\n").unwrap();
/// let file = read_rig_yaml(dir.path().join("rig.yaml"), &CameraFileOptions::default()).unwrap();
/// let right = &file.rig.cameras()[1];
/// assert_eq!((right.name.as_str(), right.offset_known, right.drift_known), ("right", true, false));
///
/// std::fs::write(dir.path().join("bad.yaml"), "cameras:\n  - name: left\n    calibration: nope.yaml\n    \
///     camera_T_rig: [0, 0, 0, 0, 0, 0, 1]\n").unwrap();
/// let e = read_rig_yaml(dir.path().join("bad.yaml"), &CameraFileOptions::default()).unwrap_err().to_string();
/// assert!(e.contains("bad.yaml") && e.contains("camera 'left'") && e.contains("nope.yaml"), "{e}");
/// ```
pub fn read_rig_yaml(
    path: impl AsRef<Path>,
    options: &CameraFileOptions,
) -> Result<RigFile, FormatError> {
    let path = path.as_ref();
    let text = read_text_file(path, "a rig file (YAML)", MAX_CAMERA_FILE_BYTES)?;
    parse_rig_yaml(&text, path, options)
}

/// Parses rig file text; `path` names it in errors and its folder is where relative calibration paths start.
pub fn parse_rig_yaml(
    text: &str,
    path: impl AsRef<Path>,
    options: &CameraFileOptions,
) -> Result<RigFile, FormatError> {
    let path = path.as_ref();
    let doc = parse_rig_document(text, path)?;
    let folder = path.parent().unwrap_or(Path::new(""));
    let mut cameras = Vec::with_capacity(doc.cameras.len());
    let mut written = Vec::with_capacity(doc.cameras.len());
    let mut paths = Vec::with_capacity(doc.cameras.len());
    for (index, c) in doc.cameras.iter().enumerate() {
        let entry = CameraEntry {
            path,
            index,
            yaml: c,
        };
        let calibration = folder.join(&c.calibration);
        cameras.push(entry.rig_camera(&doc.cameras[..index], &calibration, options)?);
        written.push(c.calibration.clone());
        paths.push(calibration);
    }
    let rig = Rig::new(cameras).map_err(|e| FormatError::new(path, e.to_string()))?;
    Ok(RigFile {
        rig,
        calibrations_as_written: written,
        calibration_paths: paths,
        path: path.to_path_buf(),
    })
}

/// The rig file's document: not empty, not nested too deep, valid YAML of the rig's shape (a syntax error at its
/// line), with between 1 and [`MAX_RIG_CAMERAS`] cameras.
fn parse_rig_document(text: &str, path: &Path) -> Result<RigYaml, FormatError> {
    if text.trim().is_empty() {
        return Err(FormatError::new(
            path,
            "empty file: expected a rig YAML document with a list 'cameras'",
        ));
    }
    check_yaml_depth(text, path)?;
    let doc: RigYaml = serde_yaml_ng::from_str(text).map_err(|e| {
        let mut message = e.to_string();
        let line = e.location().map(|l| l.line() as u64);
        if let Some(loc) = e.location() {
            let suffix = format!(" at line {} column {}", loc.line(), loc.column());
            if let Some(stripped) = message.strip_suffix(&suffix) {
                message = stripped.to_string();
            }
        }
        FormatError::new(path, message).with_line(line)
    })?;
    if doc.cameras.is_empty() {
        return Err(FormatError::new(path, "no camera: the list is empty").with_field("cameras"));
    }
    if doc.cameras.len() > MAX_RIG_CAMERAS {
        return Err(FormatError::new(
            path,
            format!(
                "{} cameras, more than the {MAX_RIG_CAMERAS} a rig may have",
                doc.cameras.len()
            ),
        )
        .with_field("cameras"));
    }
    Ok(doc)
}

/// Camera `index` of the rig file at `path`, as written: its errors name the file, the camera and the field.
struct CameraEntry<'a> {
    path: &'a Path,
    index: usize,
    yaml: &'a CameraYaml,
}

impl CameraEntry<'_> {
    /// `cameras[index].key`.
    fn field(&self, key: &str) -> String {
        format!("cameras[{}].{key}", self.index)
    }

    fn error(&self, key: &str, message: String) -> FormatError {
        FormatError::new(self.path, format!("camera '{}': {message}", self.yaml.name))
            .with_field(self.field(key))
    }

    /// Refuses a camera without a name or with the name of one `before` it.
    fn check_name(&self, before: &[CameraYaml]) -> Result<(), FormatError> {
        let c = self.yaml;
        if c.name.trim().is_empty() {
            return Err(
                FormatError::new(self.path, "a camera needs a name").with_field(self.field("name"))
            );
        }
        if before.iter().any(|o| o.name == c.name) {
            return Err(self.error("name", "listed twice: camera names must be unique".into()));
        }
        Ok(())
    }

    /// Refuses sigmas that are not 3 finite numbers of at least 0, clock values that are not finite, and a drift
    /// beyond what a clock may have (likely another unit).
    fn check_sigmas_and_clock(&self) -> Result<(), FormatError> {
        let c = self.yaml;
        for (key, values) in [
            ("camera_T_rig_sigma_m", &c.camera_t_rig_sigma_m),
            ("camera_T_rig_sigma_deg", &c.camera_t_rig_sigma_deg),
        ] {
            if let Some(values) = values
                && (values.len() != 3 || values.iter().any(|v| !v.is_finite() || *v < 0.0))
            {
                return Err(self.error(
                    key,
                    format!("expected 3 finite numbers of at least 0 (x y z), got {values:?}"),
                ));
            }
        }
        for (key, value) in [
            ("clock_offset_s", c.clock_offset_s),
            ("clock_drift_ppm", c.clock_drift_ppm),
            ("clock_offset_sigma_s", c.clock_offset_sigma_s),
            ("clock_drift_sigma_ppm", c.clock_drift_sigma_ppm),
        ] {
            if let Some(v) = value
                && !v.is_finite()
            {
                return Err(self.error(key, format!("not a finite number: {v}")));
            }
        }
        if let Some(d) = c.clock_drift_ppm
            && d.abs() > roitrack_estimators::rig::MAX_DRIFT_PPM
        {
            return Err(self.error(
                "clock_drift_ppm",
                format!(
                    "{d} ppm is beyond ±{} ppm: check the unit (parts per million)",
                    roitrack_estimators::rig::MAX_DRIFT_PPM
                ),
            ));
        }
        Ok(())
    }

    /// The camera as the rig holds it, checked (its name against those `before` it), its calibration read from
    /// `calibration`. A pose left out is to be found by calibrate-rig (the tracker refuses the rig until then), but
    /// the first camera's, whose frame is then the rig's; the first camera's clock is the rig's unless the file
    /// says otherwise, the others' absent values are estimated.
    fn rig_camera(
        &self,
        before: &[CameraYaml],
        calibration: &Path,
        options: &CameraFileOptions,
    ) -> Result<RigCamera, FormatError> {
        let c = self.yaml;
        self.check_name(before)?;
        let first = self.index == 0;
        let mount_known = first || c.camera_t_rig.is_some();
        let mount = match &c.camera_t_rig {
            Some(values) => mount_from(values).map_err(|m| self.error("camera_T_rig", m))?,
            None => CameraMount::IDENTITY,
        };
        self.check_sigmas_and_clock()?;
        let camera = read_camera_file(calibration, options).map_err(|e| {
            self.error(
                "calibration",
                format!("calibration '{}': {e}", calibration.display()),
            )
        })?;
        Ok(RigCamera {
            name: c.name.clone(),
            camera,
            mount,
            mount_known,
            clock: ClockModel {
                offset_s: c.clock_offset_s.unwrap_or(0.0),
                drift_ppm: c.clock_drift_ppm.unwrap_or(0.0),
            },
            offset_known: first || c.clock_offset_s.is_some(),
            drift_known: first || c.clock_drift_ppm.is_some(),
        })
    }
}

/// `camera_T_rig` from `tx ty tz qx qy qz qw`.
fn mount_from(values: &[f64]) -> Result<CameraMount, String> {
    let &[tx, ty, tz, qx, qy, qz, qw] = values else {
        return Err(format!(
            "expected 7 numbers (tx ty tz qx qy qz qw), got {}",
            values.len()
        ));
    };
    if let Some(v) = values.iter().find(|v| !v.is_finite()) {
        return Err(format!("not a finite number: {v}"));
    }
    let q = Quaternion::new(qw, qx, qy, qz);
    let norm = q.norm();
    if (norm - 1.0).abs() > QUATERNION_NORM_TOLERANCE {
        return Err(format!(
            "not a unit quaternion (qx qy qz qw): its norm is {norm}, more than {QUATERNION_NORM_TOLERANCE} away \
             from 1"
        ));
    }
    let rotation = UnitQuaternion::from_quaternion(q);
    Ok(CameraMount::from_isometry(
        &nalgebra::Isometry3::from_parts(Translation3::from(Vector3::new(tx, ty, tz)), rotation),
    ))
}

/// The shortest decimal that reads back to the same `f64`.
fn number(v: f64) -> String {
    let s = format!("{v}");
    if s == "-0" { "0".to_string() } else { s }
}

/// The rig as rig-file text, each camera's calibration written as `calibrations[i]`; with `clocks` (a
/// [`roitrack_estimators::rig::RigTracker`]'s), each camera's learnt offset and drift and their standard deviations
/// (`clock_offset_sigma_s`, `clock_drift_sigma_ppm`; 0 for a clock that was known), else its clock if known.
///
/// ```
/// use roitrack_estimators::rig::Rig;
/// use roitrack_core::CameraModel;
/// use roitrack_formats::rig_yaml_string;
///
/// let text = rig_yaml_string(&Rig::single("cam", CameraModel::canonical()), &["camera.yaml".into()], None);
/// assert!(text.contains("name: cam") && text.contains("camera_T_rig: [0, 0, 0, 0, 0, 0, 1]"));
/// ```
pub fn rig_yaml_string(
    rig: &Rig,
    calibrations: &[String],
    clocks: Option<&[ClockEstimate]>,
) -> String {
    rig_text(rig, calibrations, clocks, None)
}

/// A rig found by calibration ([`roitrack_estimators::rig::RigCalibrator`]) as rig-file text: every camera's pose and
/// clock, with their standard deviations (`camera_T_rig_sigma_m`, `camera_T_rig_sigma_deg` about the camera's axes,
/// `clock_offset_sigma_s`, `clock_drift_sigma_ppm`; 0 for what was known), each camera's calibration written as
/// `calibrations[i]`.
///
/// ```
/// use roitrack_estimators::rig::{CameraCalibration, CameraMount, ClockModel, Rig, RigCalibration};
/// use roitrack_core::CameraModel;
/// use roitrack_formats::calibrated_rig_yaml_string;
///
/// let rig = Rig::single("cam", CameraModel::canonical());
/// let camera = CameraCalibration {
///     mount: CameraMount::IDENTITY,
///     mount_sigma_m: nalgebra::Vector3::zeros(),
///     mount_sigma_rad: nalgebra::Vector3::zeros(),
///     clock: ClockModel::REFERENCE,
///     offset_sigma_s: 0.0,
///     drift_sigma_ppm: 0.0,
///     placed_against: None,
///     samples: 0,
///     rms_residual_m: 0.0,
///     covariance: nalgebra::DMatrix::zeros(0, 0),
/// };
/// let text = calibrated_rig_yaml_string(&RigCalibration { rig, cameras: vec![camera] }, &["camera.yaml".into()]);
/// assert!(text.contains("camera_T_rig_sigma_m: [0, 0, 0]") && text.contains("clock_offset_sigma_s: 0"));
/// ```
pub fn calibrated_rig_yaml_string(calibration: &RigCalibration, calibrations: &[String]) -> String {
    let clocks: Vec<ClockEstimate> = calibration
        .cameras
        .iter()
        .map(|c| ClockEstimate {
            offset_s: c.clock.offset_s,
            drift_ppm: c.clock.drift_ppm,
            offset_sigma_s: c.offset_sigma_s,
            drift_sigma_ppm: c.drift_sigma_ppm,
            synced: true,
        })
        .collect();
    let sigmas: Vec<[f64; 6]> = calibration
        .cameras
        .iter()
        .map(|c| {
            let m = c.mount_sigma_m;
            let r = c.mount_sigma_rad.map(f64::to_degrees);
            [m.x, m.y, m.z, r.x, r.y, r.z]
        })
        .collect();
    rig_text(&calibration.rig, calibrations, Some(&clocks), Some(&sigmas))
}

/// The rig file's text; with `mount_sigmas` (per camera: translation m, rotation deg, about its axes) their lines.
fn rig_text(
    rig: &Rig,
    calibrations: &[String],
    clocks: Option<&[ClockEstimate]>,
    mount_sigmas: Option<&[[f64; 6]]>,
) -> String {
    let mut text = String::from("cameras:\n");
    for (i, c) in rig.cameras().iter().enumerate() {
        let iso = c.mount.to_isometry();
        let t = iso.translation.vector;
        let q = iso.rotation.quaternion();
        let _ = writeln!(text, "  - name: {}", yaml_string(&c.name));
        let calibration = calibrations.get(i).map_or("", String::as_str);
        let _ = writeln!(text, "    calibration: {}", yaml_string(calibration));
        if c.mount_known {
            let _ = writeln!(
                text,
                "    camera_T_rig: [{}]",
                [t.x, t.y, t.z, q.i, q.j, q.k, q.w].map(number).join(", ")
            );
        }
        if let Some(s) = mount_sigmas.and_then(|s| s.get(i)) {
            let _ = writeln!(
                text,
                "    camera_T_rig_sigma_m: [{}]",
                s[..3]
                    .iter()
                    .map(|v| number(*v))
                    .collect::<Vec<_>>()
                    .join(", ")
            );
            let _ = writeln!(
                text,
                "    camera_T_rig_sigma_deg: [{}]",
                s[3..]
                    .iter()
                    .map(|v| number(*v))
                    .collect::<Vec<_>>()
                    .join(", ")
            );
        }
        match clocks.and_then(|clocks| clocks.get(i)) {
            Some(clock) => {
                if clock.synced {
                    let _ = writeln!(text, "    clock_offset_s: {}", number(clock.offset_s));
                    let _ = writeln!(
                        text,
                        "    clock_offset_sigma_s: {}",
                        number(clock.offset_sigma_s)
                    );
                }
                if clock.synced || c.drift_known {
                    let _ = writeln!(text, "    clock_drift_ppm: {}", number(clock.drift_ppm));
                    let _ = writeln!(
                        text,
                        "    clock_drift_sigma_ppm: {}",
                        number(clock.drift_sigma_ppm)
                    );
                }
            }
            None => {
                if c.offset_known && (i > 0 || c.clock.offset_s != 0.0) {
                    let _ = writeln!(text, "    clock_offset_s: {}", number(c.clock.offset_s));
                }
                if c.drift_known && (i > 0 || c.clock.drift_ppm != 0.0) {
                    let _ = writeln!(text, "    clock_drift_ppm: {}", number(c.clock.drift_ppm));
                }
            }
        }
    }
    text
}

/// A YAML scalar for a name or a path: quoted when plain YAML would read it otherwise.
fn yaml_string(s: &str) -> String {
    let plain = !s.is_empty()
        && s.chars()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '.' | '/'))
        && s.parse::<f64>().is_err()
        && !matches!(
            s,
            "true" | "false" | "null" | "yes" | "no" | "on" | "off" | "~"
        );
    if plain {
        s.to_string()
    } else {
        format!("\"{}\"", s.replace('\\', "\\\\").replace('"', "\\\""))
    }
}

/// Writes a rig file atomically ([`rig_yaml_string`]).
pub fn write_rig_yaml(
    path: impl AsRef<Path>,
    rig: &Rig,
    calibrations: &[String],
    clocks: Option<&[ClockEstimate]>,
) -> Result<(), FormatError> {
    let mut file = AtomicFile::create(path.as_ref())?;
    file.write_all(rig_yaml_string(rig, calibrations, clocks).as_bytes())
        .map_err(|e| file.write_error(e))?;
    file.finish()
}

/// Writes a calibrated rig file atomically ([`calibrated_rig_yaml_string`]).
pub fn write_calibrated_rig_yaml(
    path: impl AsRef<Path>,
    calibration: &RigCalibration,
    calibrations: &[String],
) -> Result<(), FormatError> {
    let mut file = AtomicFile::create(path.as_ref())?;
    file.write_all(calibrated_rig_yaml_string(calibration, calibrations).as_bytes())
        .map_err(|e| file.write_error(e))?;
    file.finish()
}

#[cfg(test)]
mod tests {
    use super::*;
    use roitrack_core::CameraModel;

    fn dir_with_camera() -> tempfile::TempDir {
        let dir = tempfile::tempdir().unwrap();
        crate::write_camera_yaml(dir.path().join("cam.yaml"), &CameraModel::canonical()).unwrap();
        dir
    }

    fn read(dir: &tempfile::TempDir, text: &str) -> Result<RigFile, FormatError> {
        let path = dir.path().join("rig.yaml");
        std::fs::write(&path, text).unwrap();
        read_rig_yaml(&path, &CameraFileOptions::default())
    }

    const TWO: &str = "cameras:\n  - name: left\n    calibration: cam.yaml\n    camera_T_rig: [0, 0, 0, 0, 0, 0, 1]\n  \
        - name: right\n    calibration: cam.yaml\n    camera_T_rig: [-0.3, 0, 0.05, 0, 0.1305, 0, 0.9914]\n";

    #[test]
    fn a_rig_reads_back_as_written() {
        let dir = dir_with_camera();
        let file = read(&dir, TWO).unwrap();
        let clocks = [
            ClockEstimate {
                offset_s: 0.0,
                drift_ppm: 0.0,
                offset_sigma_s: 0.0,
                drift_sigma_ppm: 0.0,
                synced: true,
            },
            ClockEstimate {
                offset_s: 0.0123,
                drift_ppm: 40.5,
                offset_sigma_s: 2e-6,
                drift_sigma_ppm: 1.5,
                synced: true,
            },
        ];
        let text = rig_yaml_string(&file.rig, &file.calibrations_as_written, Some(&clocks));
        let again = read(&dir, &text).unwrap();
        let right = &again.rig.cameras()[1];
        assert_eq!(right.clock.offset_s, 0.0123);
        assert_eq!(right.clock.drift_ppm, 40.5);
        assert!(right.offset_known && right.drift_known);
        let before = file.rig.cameras()[1].mount.to_isometry();
        let after = right.mount.to_isometry();
        assert!((before.translation.vector - after.translation.vector).norm() < 1e-15);
        assert!(before.rotation.angle_to(&after.rotation) < 1e-12);
    }

    #[test]
    fn bad_rigs_name_the_file_and_the_camera() {
        let dir = dir_with_camera();
        let cases = [
            (TWO.replace("right", "left"), "camera 'left': listed twice"),
            (
                TWO.replace("0.9914]", "0.5]"),
                "camera 'right': not a unit quaternion",
            ),
            (
                TWO.replace("[-0.3, 0, 0.05, ", "[0.05, "),
                "camera 'right': expected 7 numbers",
            ),
            (
                TWO.replacen("cam.yaml", "missing.yaml", 1),
                "camera 'left': calibration",
            ),
            (
                format!("{TWO}    clock_offset_s: .nan\n"),
                "camera 'right': not a finite number",
            ),
            (format!("{TWO}    colour: blue\n"), "unknown field `colour`"),
            ("cameras: []\n".to_string(), "no camera"),
        ];
        for (text, expected) in cases {
            let e = read(&dir, &text).unwrap_err().to_string();
            assert!(e.contains("rig.yaml"), "{e}");
            assert!(e.contains(expected), "{expected}: {e}");
        }
    }

    /// Every truncation of a rig file and every byte of it replaced by a few others: an error or a rig, never a panic,
    /// and every error names the file.
    #[test]
    fn mutated_rig_files_are_refused_without_panicking() {
        let dir = dir_with_camera();
        let path = dir.path().join("rig.yaml");
        let text = format!("{TWO}    clock_offset_s: 0.0123\n    clock_drift_ppm: 40\n");
        let bytes = text.as_bytes();
        let options = CameraFileOptions::default();
        let check = |mutated: &[u8]| {
            let Ok(mutated) = std::str::from_utf8(mutated) else {
                return;
            };
            if let Err(e) = parse_rig_yaml(mutated, &path, &options) {
                assert!(
                    e.to_string().contains("rig.yaml") || e.to_string().contains("cam.yaml"),
                    "{e}"
                );
            }
        };
        for end in 0..bytes.len() {
            check(&bytes[..end]);
        }
        for i in 0..bytes.len() {
            for b in [b' ', b'-', b':', b'9', b'[', b'\n', b'.', b'e'] {
                let mut mutated = bytes.to_vec();
                mutated[i] = b;
                check(&mutated);
            }
        }
    }
}
