//! The problem file (`roitrack-pnp-problem/1`): read field by field, then validated into a [`PnpProblem`].

use nalgebra::{Matrix3, Rotation3, Vector2, Vector3};
use roitrack_core::{MotionState, PinholeIntrinsics, SpatioTemporalModel, Target, TargetPoint};
use roitrack_estimators::Observation;
use serde_json::Value;

use super::json::{array, expected, field, join, number, numbers, object};
use super::{FORMAT, PnpError};

/// A problem file as written, every field checked for its JSON type (values are checked by [`validate`]).
pub(super) struct ProblemFile {
    intrinsics: PinholeIntrinsics,
    model_points: Vec<TargetPoint>,
    pub(super) instances: Vec<InstanceJson>,
    pub(super) noise_px: Option<f64>,
}

pub(super) struct InstanceJson {
    cam_r_obj: [[f64; 3]; 3],
    cam_t_obj_m: [f64; 3],
    pixels: Vec<[f64; 2]>,
}

/// Reads a `roitrack-pnp-problem/1` object found at `path` (empty at the file's top).
pub(super) fn parse_problem(value: &Value, path: &str) -> Result<ProblemFile, PnpError> {
    let top = object(value, path)?;
    let format_path = join(path, "format");
    let format = field(top, path, "format")?;
    if format.as_str() != Some(FORMAT) {
        return Err(PnpError::new(format!(
            "{format_path} is {format}, expected {FORMAT:?}"
        )));
    }
    let intrinsics_path = join(path, "intrinsics");
    let intrinsics = object(field(top, path, "intrinsics")?, &intrinsics_path)?;
    let intrinsic = |key: &str| {
        number(
            field(intrinsics, &intrinsics_path, key)?,
            &join(&intrinsics_path, key),
        )
    };
    // skew_px may be left out (zero), as the earlier reader allowed.
    let skew_px = match intrinsics.get("skew_px") {
        None | Some(Value::Null) => 0.0,
        Some(value) => number(value, &join(&intrinsics_path, "skew_px"))?,
    };
    let intrinsics = PinholeIntrinsics {
        fx_px: intrinsic("fx_px")?,
        fy_px: intrinsic("fy_px")?,
        skew_px,
        cx_px: intrinsic("cx_px")?,
        cy_px: intrinsic("cy_px")?,
    };
    let points_path = join(path, "model_points");
    let model_points = array(field(top, path, "model_points")?, &points_path)?
        .iter()
        .enumerate()
        .map(|(k, point)| {
            let point_path = format!("{points_path}[{k}]");
            let fields = object(point, &point_path)?;
            let id_path = join(&point_path, "id");
            let id_value = field(fields, &point_path, "id")?;
            let id = id_value
                .as_u64()
                .and_then(|id| u32::try_from(id).ok())
                .ok_or_else(|| expected(&id_path, "an integer from 0 to 4294967295", id_value))?;
            let xyz_path = join(&point_path, "xyz_m");
            let xyz_m = numbers::<3>(field(fields, &point_path, "xyz_m")?, &xyz_path)?;
            Ok(TargetPoint {
                id,
                point_in_obj_m: Vector3::from(xyz_m),
                diameter_m: None,
            })
        })
        .collect::<Result<Vec<_>, PnpError>>()?;
    let instances_path = join(path, "instances");
    let instances = array(field(top, path, "instances")?, &instances_path)?
        .iter()
        .enumerate()
        .map(|(k, instance)| parse_instance(instance, &format!("{instances_path}[{k}]")))
        .collect::<Result<Vec<_>, PnpError>>()?;
    let noise_px = match top.get("noise_px") {
        None | Some(Value::Null) => None,
        Some(value) => Some(number(value, &join(path, "noise_px"))?),
    };
    Ok(ProblemFile {
        intrinsics,
        model_points,
        instances,
        noise_px,
    })
}

fn parse_instance(value: &Value, path: &str) -> Result<InstanceJson, PnpError> {
    let fields = object(value, path)?;
    let r_path = join(path, "cam_r_obj");
    let rows = array(field(fields, path, "cam_r_obj")?, &r_path)?;
    if rows.len() != 3 {
        return Err(PnpError::new(format!(
            "{r_path}: expected 3 rows of 3 numbers, got {} rows",
            rows.len()
        )));
    }
    let mut cam_r_obj = [[0.0; 3]; 3];
    for (i, row) in rows.iter().enumerate() {
        cam_r_obj[i] = numbers::<3>(row, &format!("{r_path}[{i}]"))?;
    }
    let cam_t_obj_m = numbers::<3>(
        field(fields, path, "cam_t_obj_m")?,
        &join(path, "cam_t_obj_m"),
    )?;
    let pixels_path = join(path, "pixels");
    let pixels = array(field(fields, path, "pixels")?, &pixels_path)?
        .iter()
        .enumerate()
        .map(|(i, pixel)| numbers::<2>(pixel, &format!("{pixels_path}[{i}]")))
        .collect::<Result<Vec<_>, PnpError>>()?;
    Ok(InstanceJson {
        cam_r_obj,
        cam_t_obj_m,
        pixels,
    })
}

/// One problem instance, validated: the true pose and the observations.
#[derive(Debug, Clone)]
pub struct PnpInstance {
    /// The true pose of the target in the camera (at rest).
    pub truth: MotionState,
    /// One noisy pixel per target point.
    pub observations: Vec<Observation>,
}

/// A validated PnP problem: the camera's pinhole model, the target, and the instances.
#[derive(Debug, Clone)]
pub struct PnpProblem {
    /// The camera's pinhole model as a projection model (every pixel taken at one time).
    pub model: SpatioTemporalModel,
    /// The target's points (m, object frame).
    pub target: Target,
    /// The instances, in the file's order.
    pub instances: Vec<PnpInstance>,
    /// The pixels' noise (px per coordinate).
    pub noise_px: f64,
}

impl PnpProblem {
    /// Parses and validates a problem file's text (JSON, see the [module documentation](super)).
    ///
    /// ```
    /// use roitrack_bench::pnp::PnpProblem;
    /// let error = PnpProblem::from_json("{ not json").unwrap_err();
    /// assert!(error.message.contains("not a valid PnP problem"), "{error}");
    /// ```
    pub fn from_json(text: &str) -> Result<Self, PnpError> {
        let value: Value = serde_json::from_str(text)
            .map_err(|e| PnpError::new(format!("not a valid PnP problem: {e}")))?;
        validate(parse_problem(&value, "")?, "")
    }
}

/// Checks the values of a problem found at `path` (empty at the file's top).
pub(super) fn validate(file: ProblemFile, path: &str) -> Result<PnpProblem, PnpError> {
    file.intrinsics
        .validate()
        .map_err(|e| PnpError::new(format!("{}: {e}", join(path, "intrinsics"))))?;
    let target = Target::new(file.model_points)
        .map_err(|e| PnpError::new(format!("{}: {e}", join(path, "model_points"))))?;
    let instances_path = join(path, "instances");
    if file.instances.is_empty() {
        return Err(PnpError::new(format!(
            "{instances_path}: the problem has no instances"
        )));
    }
    let instances = file
        .instances
        .iter()
        .enumerate()
        .map(|(k, instance)| {
            validate_instance(instance, target.len(), &format!("{instances_path}[{k}]"))
        })
        .collect::<Result<Vec<_>, _>>()?;
    let noise_px = file
        .noise_px
        .unwrap_or(roitrack_estimators::TrackerConfig::default().noise_px);
    if !(noise_px.is_finite() && noise_px > 0.0) {
        return Err(PnpError::new(format!(
            "{} must be a positive number, got {noise_px}",
            join(path, "noise_px")
        )));
    }
    Ok(PnpProblem {
        model: SpatioTemporalModel::new(file.intrinsics),
        target,
        instances,
        noise_px,
    })
}

fn validate_instance(
    instance: &InstanceJson,
    point_count: usize,
    path: &str,
) -> Result<PnpInstance, PnpError> {
    if instance.pixels.len() != point_count {
        return Err(PnpError::new(format!(
            "{path}.pixels: {} pixels for {point_count} model points",
            instance.pixels.len()
        )));
    }
    let r = Matrix3::from_fn(|i, j| instance.cam_r_obj[i][j]);
    let t = Vector3::from(instance.cam_t_obj_m);
    if !r.iter().chain(t.iter()).all(|v| v.is_finite()) {
        return Err(PnpError::new(format!(
            "{path}: the true pose (cam_r_obj, cam_t_obj_m) is not finite"
        )));
    }
    let orthonormality = (r.transpose() * r - Matrix3::identity()).amax();
    if orthonormality > 1e-6 || r.determinant() < 0.0 {
        return Err(PnpError::new(format!(
            "{path}.cam_r_obj is not a rotation matrix (|RᵀR - I| = {orthonormality:.1e}, det = {:.6})",
            r.determinant()
        )));
    }
    let observations = instance
        .pixels
        .iter()
        .enumerate()
        .map(|(i, &[u, v])| {
            if !(u.is_finite() && v.is_finite()) {
                return Err(PnpError::new(format!(
                    "{path}.pixels[{i}] is not finite ({u}, {v})"
                )));
            }
            Ok(Observation {
                t_s: 0.0,
                point_index: i,
                ideal_px: Vector2::new(u, v),
            })
        })
        .collect::<Result<Vec<_>, PnpError>>()?;
    Ok(PnpInstance {
        truth: MotionState::at_rest(Rotation3::from_matrix(&r), t),
        observations,
    })
}

#[cfg(test)]
mod tests {
    use serde_json::json;

    use super::*;
    use crate::pnp::fixtures::problem_json;

    #[test]
    fn bad_problems_are_refused_with_the_instance() {
        let message = PnpProblem::from_json(&problem_json(15))
            .unwrap_err()
            .message;
        assert_eq!(
            message,
            "instances[0].pixels: 15 pixels for 16 model points"
        );
    }

    #[test]
    fn problem_fields_are_named() {
        let mut value: Value = serde_json::from_str(&problem_json(16)).unwrap();
        value["intrinsics"].as_object_mut().unwrap().remove("fy_px");
        let message = PnpProblem::from_json(&value.to_string())
            .unwrap_err()
            .message;
        assert_eq!(message, "intrinsics.fy_px is missing");
        let mut value: Value = serde_json::from_str(&problem_json(16)).unwrap();
        value["model_points"][2]["xyz_m"] = json!([0.0, "x", 0.0]);
        let message = PnpProblem::from_json(&value.to_string())
            .unwrap_err()
            .message;
        assert_eq!(
            message,
            "model_points[2].xyz_m[1]: expected a number, got the string \"x\""
        );
        let mut value: Value = serde_json::from_str(&problem_json(16)).unwrap();
        value["format"] = json!("roitrack-pnp-problem/2");
        let message = PnpProblem::from_json(&value.to_string())
            .unwrap_err()
            .message;
        assert!(
            message.starts_with("format is \"roitrack-pnp-problem/2\""),
            "{message}"
        );
        // No noise given: the tracker's default, as before suites existed.
        let problem = PnpProblem::from_json(&problem_json(16)).unwrap();
        assert_eq!(
            problem.noise_px,
            roitrack_estimators::TrackerConfig::default().noise_px
        );
    }
}
