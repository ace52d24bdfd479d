//! The PnP benchmark (`roitrack pnp-bench`): times our static pose solver ([`solve_static_pose`]) on a stored PnP
//! problem, the same file the OpenCV peer comparison (`bench/opencv_compare.sh`) reads, and reports its accuracy
//! against the true poses; or solves a suite of one-instance problems (`bench/pnp_families.py`) and reports, problem by
//! problem, every pose it returns and its time.
//!
//! The problem file is JSON (format `roitrack-pnp-problem/1`, written by `bench/opencv_compare.py`):
//!
//! ```json
//! {
//!   "format": "roitrack-pnp-problem/1",
//!   "intrinsics": {"fx_px": 1500, "fy_px": 1500, "skew_px": 0, "cx_px": 512, "cy_px": 512},
//!   "model_points": [{"id": 0, "xyz_m": [-0.03, -0.03, 0.0]}, ...],
//!   "instances": [
//!     {"cam_r_obj": [[r00, r01, r02], [r10, r11, r12], [r20, r21, r22]], "cam_t_obj_m": [x, y, z],
//!      "pixels": [[u0, v0], [u1, v1], ...]},
//!     ...
//!   ]
//! }
//! ```
//!
//! `pixels[i]` is the noisy ideal (undistorted) pixel of `model_points[i]`; `cam_r_obj`, `cam_t_obj_m` is the true pose
//! (object to camera, row-major rotation). An optional `"noise_px"` gives the pixels' noise (px per coordinate; the
//! tracker's default noise when absent), which the solver judges ambiguity against. Other keys are ignored.
//!
//! The suite file (format `roitrack-pnp-suite/1`, written by `bench/pnp_families.py`) holds many problems, each of
//! exactly one instance and with its `noise_px`, each tagged with the family it was drawn from:
//!
//! ```json
//! {"format": "roitrack-pnp-suite/1",
//!  "problems": [{"family": "4-5 planar", "problem": {"format": "roitrack-pnp-problem/1", "noise_px": 0.2, ...}}, ...]}
//! ```
//!
//! Every refusal names the field, as a path from the file's top (`instances[0].pixels[3]`,
//! `problems[7].problem.intrinsics.fx_px`), and [`PnpSuite::read`] also names the file.

use std::hint::black_box;
use std::path::Path;
use std::time::Instant;

use nalgebra::{Matrix3, Rotation3, Vector2, Vector3};
use roitrack_core::stats::{mean, median, quantile, rms, sorted};
use roitrack_core::{
    MotionState, PinholeIntrinsics, SpatioTemporalModel, Target, TargetPoint, so3,
};
use roitrack_estimators::{Observation, PoseFit, solve_static_pose};
use serde_json::{Map, Value, json};
use thiserror::Error;

/// The format tag a problem file must carry.
pub const FORMAT: &str = "roitrack-pnp-problem/1";

/// The format tag a suite file must carry.
pub const SUITE_FORMAT: &str = "roitrack-pnp-suite/1";

/// Why a problem was refused: the message names the instance and field where it applies.
#[derive(Debug, Clone, PartialEq, Error)]
#[error("{message}")]
pub struct PnpError {
    /// What is wrong, naming the instance and field where it applies.
    pub message: String,
}

impl PnpError {
    fn new(message: impl Into<String>) -> Self {
        Self {
            message: message.into(),
        }
    }
}

/// `parent.key`, or `key` at the top.
fn join(parent: &str, key: &str) -> String {
    if parent.is_empty() {
        key.to_owned()
    } else {
        format!("{parent}.{key}")
    }
}

/// What a JSON value is, for "expected X, got Y".
fn kind(value: &Value) -> String {
    match value {
        Value::Null => "null".to_owned(),
        Value::Bool(b) => b.to_string(),
        Value::Number(n) => format!("the number {n}"),
        Value::String(s) if s.chars().count() <= 40 => format!("the string {s:?}"),
        Value::String(_) => "a string".to_owned(),
        Value::Array(a) => format!("an array of {}", a.len()),
        Value::Object(_) => "an object".to_owned(),
    }
}

fn expected(path: &str, what: &str, value: &Value) -> PnpError {
    let at = if path.is_empty() { "the file" } else { path };
    PnpError::new(format!("{at}: expected {what}, got {}", kind(value)))
}

fn object<'a>(value: &'a Value, path: &str) -> Result<&'a Map<String, Value>, PnpError> {
    value
        .as_object()
        .ok_or_else(|| expected(path, "an object", value))
}

/// The field `key` of `object` (at `path`), which must be there (null counts as missing).
fn field<'a>(object: &'a Map<String, Value>, path: &str, key: &str) -> Result<&'a Value, PnpError> {
    match object.get(key) {
        Some(Value::Null) | None => Err(PnpError::new(format!("{} is missing", join(path, key)))),
        Some(value) => Ok(value),
    }
}

fn array<'a>(value: &'a Value, path: &str) -> Result<&'a [Value], PnpError> {
    value
        .as_array()
        .map(Vec::as_slice)
        .ok_or_else(|| expected(path, "an array", value))
}

fn number(value: &Value, path: &str) -> Result<f64, PnpError> {
    value
        .as_f64()
        .ok_or_else(|| expected(path, "a number", value))
}

/// A fixed-length array of numbers (a pixel, a point, a matrix row).
fn numbers<const N: usize>(value: &Value, path: &str) -> Result<[f64; N], PnpError> {
    let items = array(value, path)?;
    if items.len() != N {
        return Err(expected(path, &format!("an array of {N} numbers"), value));
    }
    let mut out = [0.0; N];
    for (k, (slot, item)) in out.iter_mut().zip(items).enumerate() {
        *slot = number(item, &format!("{path}[{k}]"))?;
    }
    Ok(out)
}

/// A problem file as written, every field checked for its JSON type (values are checked by [`validate`]).
struct ProblemFile {
    intrinsics: PinholeIntrinsics,
    model_points: Vec<TargetPoint>,
    instances: Vec<InstanceJson>,
    noise_px: Option<f64>,
}

struct InstanceJson {
    cam_r_obj: [[f64; 3]; 3],
    cam_t_obj_m: [f64; 3],
    pixels: Vec<[f64; 2]>,
}

/// Reads a `roitrack-pnp-problem/1` object found at `path` (empty at the file's top).
fn parse_problem(value: &Value, path: &str) -> Result<ProblemFile, PnpError> {
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
    /// Parses and validates a problem file's text (JSON, see the [module documentation](self)).
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
fn validate(file: ProblemFile, path: &str) -> Result<PnpProblem, PnpError> {
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

/// RMS (per coordinate) of the reprojection residual of `state` on `observations`, in pixels.
fn reprojection_rms_px(
    model: &SpatioTemporalModel,
    target: &Target,
    state: &MotionState,
    observations: &[Observation],
) -> f64 {
    let mut sum = 0.0;
    for o in observations {
        match model.project(state, &target.points()[o.point_index].point_in_obj_m, 0.0) {
            Some(px) => sum += (px - o.ideal_px).norm_squared(),
            None => return f64::INFINITY,
        }
    }
    (sum / (2 * observations.len()).max(1) as f64).sqrt()
}

/// What one instance gave: the pose found (or the error) and its accuracy.
#[derive(Debug, Clone)]
pub struct Solved {
    /// The pose found; `None` when the solver refused the instance.
    pub pose: Option<MotionState>,
    /// The solver's error when it found no pose.
    pub error: Option<String>,
    /// Distance from the true position of the target's origin (mm; NaN without a pose).
    pub position_error_mm: f64,
    /// Angle of the rotation from the true orientation (degrees; NaN without a pose).
    pub rotation_error_deg: f64,
    /// RMS reprojection error of the pose against the observed pixels, per coordinate (px; NaN without a pose).
    pub reprojection_rms_px: f64,
    /// Iterations the solver took (0 without a pose).
    pub iterations: usize,
    /// Whether the solver reached its convergence test.
    pub converged: bool,
}

/// The benchmark's result: every instance solved once for accuracy, and every timed solve.
#[derive(Debug, Clone)]
pub struct PnpReport {
    /// Each instance's accuracy, in the problem's order.
    pub solved: Vec<Solved>,
    /// Every timed solve (µs), in order.
    pub times_us: Vec<f64>,
    /// Points of the target.
    pub points: usize,
    /// Times every instance was timed.
    pub repeats: usize,
}

/// Solves every instance once (accuracy), then times every instance in turn, `repeats` times over, each solve on its
/// own.
///
/// ```
/// use roitrack_bench::pnp::{PnpProblem, run};
/// let text = r#"{"format": "roitrack-pnp-problem/1",
///   "intrinsics": {"fx_px": 1500, "fy_px": 1500, "cx_px": 512, "cy_px": 512},
///   "model_points": [{"id": 0, "xyz_m": [0, 0, 0]}, {"id": 1, "xyz_m": [0.02, 0, 0]},
///                    {"id": 2, "xyz_m": [0, 0.02, 0]}, {"id": 3, "xyz_m": [0.02, 0.02, 0]}],
///   "instances": [{"cam_r_obj": [[1, 0, 0], [0, 1, 0], [0, 0, 1]], "cam_t_obj_m": [0, 0, 0.5],
///                  "pixels": [[512, 512], [572, 512], [512, 572], [572, 572]]}]}"#;
/// let report = run(&PnpProblem::from_json(text).unwrap(), 3);
/// assert_eq!((report.times_us.len(), report.failures()), (3, 0));
/// assert!(report.solved[0].position_error_mm < 1e-6);
/// ```
pub fn run(problem: &PnpProblem, repeats: usize) -> PnpReport {
    let PnpProblem {
        model,
        target,
        instances,
        noise_px,
    } = problem;
    let solved: Vec<Solved> = instances
        .iter()
        .map(|instance| {
            match solve_static_pose(model, target, &instance.observations, *noise_px)
                .map(|poses| *poses.best())
            {
                Ok(fit) => Solved {
                    pose: Some(fit.state),
                    error: None,
                    position_error_mm: (fit.state.cam_t_obj_m - instance.truth.cam_t_obj_m).norm()
                        * 1e3,
                    rotation_error_deg: so3::angle_between(
                        &fit.state.cam_r_obj,
                        &instance.truth.cam_r_obj,
                    )
                    .to_degrees(),
                    reprojection_rms_px: reprojection_rms_px(
                        model,
                        target,
                        &fit.state,
                        &instance.observations,
                    ),
                    iterations: fit.iterations,
                    converged: fit.converged,
                },
                Err(error) => Solved {
                    pose: None,
                    error: Some(error.to_string()),
                    position_error_mm: f64::NAN,
                    rotation_error_deg: f64::NAN,
                    reprojection_rms_px: f64::NAN,
                    iterations: 0,
                    converged: false,
                },
            }
        })
        .collect();
    let mut times_us = Vec::with_capacity(instances.len() * repeats);
    for _ in 0..repeats {
        for instance in instances {
            let observations = black_box(instance.observations.as_slice());
            let start = Instant::now();
            let result = solve_static_pose(
                black_box(model),
                black_box(target),
                observations,
                black_box(*noise_px),
            );
            let elapsed = start.elapsed();
            black_box(&result);
            times_us.push(elapsed.as_secs_f64() * 1e6);
        }
    }
    PnpReport {
        solved,
        times_us,
        points: target.len(),
        repeats,
    }
}

impl PnpReport {
    fn ok(&self) -> Vec<&Solved> {
        self.solved.iter().filter(|s| s.pose.is_some()).collect()
    }

    /// Instances the solver failed on.
    pub fn failures(&self) -> usize {
        self.solved.len() - self.ok().len()
    }

    fn errors(&self) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
        let ok = self.ok();
        (
            ok.iter().map(|s| s.position_error_mm).collect(),
            ok.iter().map(|s| s.rotation_error_deg).collect(),
            ok.iter().map(|s| s.reprojection_rms_px).collect(),
        )
    }

    /// The whole report as JSON: summary, the pose found for each instance, every solve's time.
    pub fn to_json(&self, problem_name: &str) -> String {
        let times = sorted(&self.times_us);
        let (position, rotation, reprojection) = self.errors();
        let (position_sorted, rotation_sorted, reprojection_sorted) =
            (sorted(&position), sorted(&rotation), sorted(&reprojection));
        let poses: Vec<_> = self
            .solved
            .iter()
            .map(|s| match s.pose {
                Some(state) => {
                    let r = state.cam_r_obj.matrix();
                    json!({
                        "ok": true,
                        "cam_r_obj": [
                            [r[(0, 0)], r[(0, 1)], r[(0, 2)]],
                            [r[(1, 0)], r[(1, 1)], r[(1, 2)]],
                            [r[(2, 0)], r[(2, 1)], r[(2, 2)]],
                        ],
                        "cam_t_obj_m": [state.cam_t_obj_m.x, state.cam_t_obj_m.y, state.cam_t_obj_m.z],
                        "position_error_mm": s.position_error_mm,
                        "rotation_error_deg": s.rotation_error_deg,
                        "reprojection_rms_px": s.reprojection_rms_px,
                        "iterations": s.iterations,
                        "converged": s.converged,
                    })
                }
                None => json!({ "ok": false, "error": s.error }),
            })
            .collect();
        let report = json!({
            "solver": "roitrack_estimators::solve_static_pose",
            "problem": problem_name,
            "instances": self.solved.len(),
            "points": self.points,
            "repeats": self.repeats,
            "solves_timed": times.len(),
            "failures": self.failures(),
            "time_us": {
                "median": quantile(&times, 0.5),
                "p99": quantile(&times, 0.99),
                "mean": mean(&times),
                "min": quantile(&times, 0.0),
            },
            "position_error_mm": {
                "rms": rms(&position),
                "median": quantile(&position_sorted, 0.5),
                "max": quantile(&position_sorted, 1.0),
            },
            "rotation_error_deg": {
                "rms": rms(&rotation),
                "median": quantile(&rotation_sorted, 0.5),
                "max": quantile(&rotation_sorted, 1.0),
            },
            "reprojection_rms_px": {
                "mean": mean(&reprojection),
                "median": quantile(&reprojection_sorted, 0.5),
                "max": quantile(&reprojection_sorted, 1.0),
            },
            "poses": poses,
            "solve_times_us": self.times_us,
        });
        serde_json::to_string_pretty(&report).expect("the report holds only numbers and strings")
    }

    /// The summary as a few lines of text.
    pub fn to_table(&self, problem_name: &str) -> String {
        let times = sorted(&self.times_us);
        let (position, rotation, reprojection) = self.errors();
        let (position_sorted, rotation_sorted, reprojection_sorted) =
            (sorted(&position), sorted(&rotation), sorted(&reprojection));
        format!(
            "solve_static_pose on {problem_name} ({} instances x {} points, {} timed solves)\n\
             \x20 time per solve:        median {:.2} us, p99 {:.2} us, min {:.2} us\n\
             \x20 position error:        RMS {:.4} mm, max {:.4} mm\n\
             \x20 rotation error:        RMS {:.4} deg, max {:.4} deg\n\
             \x20 reprojection RMS:      mean {:.4} px, max {:.4} px\n\
             \x20 failures:              {}\n",
            self.solved.len(),
            self.points,
            times.len(),
            quantile(&times, 0.5),
            quantile(&times, 0.99),
            quantile(&times, 0.0),
            rms(&position),
            quantile(&position_sorted, 1.0),
            rms(&rotation),
            quantile(&rotation_sorted, 1.0),
            mean(&reprojection),
            quantile(&reprojection_sorted, 1.0),
            self.failures()
        )
    }
}

/// One problem of a suite: the family it was drawn from and the problem (one instance, its noise given).
#[derive(Debug, Clone)]
pub struct SuiteProblem {
    /// The family's name, as the suite file gives it.
    pub family: String,
    /// The problem: one instance.
    pub problem: PnpProblem,
}

/// A validated suite of one-instance PnP problems (format `roitrack-pnp-suite/1`, see the
/// [module documentation](self)).
#[derive(Debug, Clone)]
pub struct PnpSuite {
    /// The problems, in the file's order.
    pub problems: Vec<SuiteProblem>,
}

impl PnpSuite {
    /// Parses and validates a suite file's text; every refusal names the problem (`problems[k]`, with its family
    /// once known) and the field.
    ///
    /// ```
    /// use roitrack_bench::pnp::PnpSuite;
    /// let error = PnpSuite::from_json(r#"{"format": "roitrack-pnp-suite/1", "problems": [{"problem": {}}]}"#)
    ///     .unwrap_err();
    /// assert_eq!(error.message, "problems[0].family is missing");
    /// ```
    pub fn from_json(text: &str) -> Result<Self, PnpError> {
        let value: Value = serde_json::from_str(text)
            .map_err(|e| PnpError::new(format!("not a valid PnP suite: {e}")))?;
        let top = object(&value, "")?;
        let format = field(top, "", "format")?;
        if format.as_str() != Some(SUITE_FORMAT) {
            return Err(PnpError::new(format!(
                "format is {format}, expected {SUITE_FORMAT:?}"
            )));
        }
        let entries = array(field(top, "", "problems")?, "problems")?;
        if entries.is_empty() {
            return Err(PnpError::new("problems: the suite has no problems"));
        }
        let problems = entries
            .iter()
            .enumerate()
            .map(|(k, entry)| suite_problem(entry, &format!("problems[{k}]")))
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Self { problems })
    }

    /// Reads and validates a suite file; every refusal names the file, then as [`PnpSuite::from_json`].
    pub fn read(path: &Path) -> Result<Self, PnpError> {
        let text = std::fs::read_to_string(path).map_err(|e| {
            PnpError::new(format!(
                "cannot read the suite file {}: {e}",
                path.display()
            ))
        })?;
        Self::from_json(&text)
            .map_err(|e| PnpError::new(format!("suite file {}: {}", path.display(), e.message)))
    }
}

/// One entry of a suite's `problems`, found at `path`.
fn suite_problem(entry: &Value, path: &str) -> Result<SuiteProblem, PnpError> {
    let fields = object(entry, path)?;
    let family_value = field(fields, path, "family")?;
    let family = family_value
        .as_str()
        .ok_or_else(|| expected(&join(path, "family"), "a string", family_value))?
        .to_owned();
    // From here on the family is named too: the generator's tables are by family.
    let named = |e: PnpError| PnpError::new(format!("{} (family {family:?})", e.message));
    let problem_path = join(path, "problem");
    let file = parse_problem(field(fields, path, "problem")?, &problem_path).map_err(named)?;
    // A suite gives each problem's noise and one instance: its report is one pose and one time per problem.
    if file.noise_px.is_none() {
        return Err(named(PnpError::new(format!(
            "{problem_path}.noise_px is missing (a suite problem gives its pixels' noise)"
        ))));
    }
    if file.instances.len() != 1 {
        return Err(named(PnpError::new(format!(
            "{problem_path}.instances: a suite problem has exactly one instance, got {}",
            file.instances.len()
        ))));
    }
    let problem = validate(file, &problem_path).map_err(named)?;
    Ok(SuiteProblem { family, problem })
}

/// What the solver gave on one problem of a suite.
#[derive(Debug, Clone)]
pub struct SuiteSolve {
    /// The problem's family.
    pub family: String,
    /// Every pose returned, best first (empty when the solver refused the problem).
    pub poses: Vec<PoseFit>,
    /// Whether the solver said the poses cannot be told apart ([`roitrack_estimators::StaticPoses::is_ambiguous`]).
    pub ambiguous: bool,
    /// The solver's error, if it found no pose.
    pub error: Option<String>,
    /// Median over the timed solves (µs).
    pub median_time_us: f64,
}

/// The suite's result, problem by problem in the file's order.
#[derive(Debug, Clone)]
pub struct SuiteReport {
    /// One result per problem, in the file's order.
    pub solves: Vec<SuiteSolve>,
    /// Times each problem was solved in a row for its median time.
    pub repeats: usize,
}

/// Solves every problem of the suite once (the poses), then times it `repeats` times in a row (as the OpenCV side
/// times its calls: the same problem repeated, warm in the cache), keeping the median.
///
/// ```
/// use roitrack_bench::pnp::{PnpSuite, run_suite};
/// let text = r#"{"format": "roitrack-pnp-suite/1", "problems": [{"family": "4-5 planar", "problem": {
///   "format": "roitrack-pnp-problem/1", "noise_px": 0.1,
///   "intrinsics": {"fx_px": 1500, "fy_px": 1500, "cx_px": 512, "cy_px": 512},
///   "model_points": [{"id": 0, "xyz_m": [0, 0, 0]}, {"id": 1, "xyz_m": [0.02, 0, 0]},
///                    {"id": 2, "xyz_m": [0, 0.02, 0]}, {"id": 3, "xyz_m": [0.02, 0.02, 0]}],
///   "instances": [{"cam_r_obj": [[1, 0, 0], [0, 1, 0], [0, 0, 1]], "cam_t_obj_m": [0, 0, 0.5],
///                  "pixels": [[512, 512], [572, 512], [512, 572], [572, 572]]}]}}]}"#;
/// let report = run_suite(&PnpSuite::from_json(text).unwrap(), 3);
/// let solve = &report.solves[0];
/// assert!(solve.error.is_none() && !solve.ambiguous);
/// assert!((solve.poses[0].state.cam_t_obj_m.z - 0.5).abs() < 1e-9);
/// ```
pub fn run_suite(suite: &PnpSuite, repeats: usize) -> SuiteReport {
    let solves = suite
        .problems
        .iter()
        .map(|SuiteProblem { family, problem }| {
            let PnpProblem {
                model,
                target,
                instances,
                noise_px,
            } = problem;
            let observations = instances[0].observations.as_slice();
            let (poses, ambiguous, error) =
                match solve_static_pose(model, target, observations, *noise_px) {
                    Ok(poses) => (poses.as_slice().to_vec(), poses.is_ambiguous(), None),
                    Err(error) => (Vec::new(), false, Some(error.to_string())),
                };
            let times_us: Vec<f64> = (0..repeats)
                .map(|_| {
                    let start = Instant::now();
                    let result = solve_static_pose(
                        black_box(model),
                        black_box(target),
                        black_box(observations),
                        black_box(*noise_px),
                    );
                    let elapsed = start.elapsed();
                    black_box(&result);
                    elapsed.as_secs_f64() * 1e6
                })
                .collect();
            SuiteSolve {
                family: family.clone(),
                poses,
                ambiguous,
                error,
                median_time_us: median(&times_us),
            }
        })
        .collect();
    SuiteReport { solves, repeats }
}

fn rotation_rows(state: &MotionState) -> [[f64; 3]; 3] {
    let r = state.cam_r_obj.matrix();
    [0, 1, 2].map(|i| [r[(i, 0)], r[(i, 1)], r[(i, 2)]])
}

impl SuiteReport {
    /// Per problem: family, ok or the error, the best pose (row-major rotation, translation), every pose returned
    /// (best first), their number, whether ambiguous, the median solve time.
    pub fn to_json(&self, suite_name: &str) -> String {
        let problems: Vec<_> = self
            .solves
            .iter()
            .enumerate()
            .map(|(index, s)| {
                let poses: Vec<_> = s
                    .poses
                    .iter()
                    .map(|fit| {
                        json!({
                            "cam_r_obj": rotation_rows(&fit.state),
                            "cam_t_obj_m": fit.state.cam_t_obj_m.as_slice(),
                            "cost_px2": fit.cost_px2,
                            "residual_rms_px": fit.residual_rms_px,
                            "converged": fit.converged,
                        })
                    })
                    .collect();
                let best = s.poses.first();
                json!({
                    "index": index,
                    "family": s.family,
                    "ok": s.error.is_none(),
                    "error": s.error,
                    "cam_r_obj": best.map(|fit| rotation_rows(&fit.state)),
                    "cam_t_obj_m": best.map(|fit| fit.state.cam_t_obj_m.as_slice().to_vec()),
                    "pose_count": s.poses.len(),
                    "ambiguous": s.ambiguous,
                    "poses": poses,
                    "median_time_us": s.median_time_us,
                })
            })
            .collect();
        let report = json!({
            "solver": "roitrack_estimators::solve_static_pose",
            "suite": suite_name,
            "repeats": self.repeats,
            "problems": problems,
        });
        serde_json::to_string_pretty(&report).expect("the report holds only numbers and strings")
    }

    /// One line per problem.
    pub fn to_table(&self, suite_name: &str) -> String {
        let mut out = format!(
            "solve_static_pose on {suite_name} ({} problems, median of {} timed solves each)\n\
             {:>5}  {:<24} {:>5} {:>9}  {:>12} {:>12} {:>12}  {:>9}\n",
            self.solves.len(),
            self.repeats,
            "#",
            "family",
            "poses",
            "ambiguous",
            "tx m",
            "ty m",
            "tz m",
            "median us"
        );
        for (index, s) in self.solves.iter().enumerate() {
            let line = match (&s.error, s.poses.first()) {
                (None, Some(best)) => {
                    let t = best.state.cam_t_obj_m;
                    format!(
                        "{:>5}  {:<24} {:>5} {:>9}  {:>12.6} {:>12.6} {:>12.6}  {:>9.2}\n",
                        index,
                        s.family,
                        s.poses.len(),
                        if s.ambiguous { "yes" } else { "no" },
                        t.x,
                        t.y,
                        t.z,
                        s.median_time_us
                    )
                }
                (error, _) => format!(
                    "{:>5}  {:<24} error: {}\n",
                    index,
                    s.family,
                    error.as_deref().unwrap_or("no pose")
                ),
            };
            out.push_str(&line);
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn problem_json(pixels_per_instance: usize) -> String {
        let points: Vec<_> = (0..16)
            .map(|id| {
                let (r, c) = ((id / 4) as f64, (id % 4) as f64);
                json!({"id": id, "xyz_m": [(c - 1.5) * 0.02, (r - 1.5) * 0.02, 0.0]})
            })
            .collect();
        let model = SpatioTemporalModel::new(roitrack_core::CameraModel::canonical().intrinsics);
        let truth = MotionState::at_rest(
            Rotation3::from_euler_angles(0.1, -0.2, 0.05),
            Vector3::new(0.02, -0.01, 0.6),
        );
        let pixels: Vec<_> = (0..pixels_per_instance)
            .map(|id| {
                let (r, c) = ((id / 4) as f64, (id % 4) as f64);
                let p = model
                    .project(
                        &truth,
                        &Vector3::new((c - 1.5) * 0.02, (r - 1.5) * 0.02, 0.0),
                        0.0,
                    )
                    .unwrap();
                json!([p.x, p.y])
            })
            .collect();
        let m = truth.cam_r_obj.matrix();
        json!({
            "format": FORMAT,
            "intrinsics": {"fx_px": 1500.0, "fy_px": 1500.0, "skew_px": 0.0, "cx_px": 512.0, "cy_px": 512.0},
            "model_points": points,
            "instances": [{
                "cam_r_obj": [[m[(0, 0)], m[(0, 1)], m[(0, 2)]], [m[(1, 0)], m[(1, 1)], m[(1, 2)]],
                              [m[(2, 0)], m[(2, 1)], m[(2, 2)]]],
                "cam_t_obj_m": [0.02, -0.01, 0.6],
                "pixels": pixels,
            }],
        })
        .to_string()
    }

    #[test]
    fn exact_problem_is_solved_exactly() {
        let problem = PnpProblem::from_json(&problem_json(16)).unwrap();
        let instance = &problem.instances[0];
        let fit = *solve_static_pose(
            &problem.model,
            &problem.target,
            &instance.observations,
            problem.noise_px,
        )
        .unwrap()
        .best();
        assert!((fit.state.cam_t_obj_m - instance.truth.cam_t_obj_m).norm() < 1e-9);
        assert!(so3::angle_between(&fit.state.cam_r_obj, &instance.truth.cam_r_obj) < 1e-9);
        let report = run(&problem, 2);
        assert_eq!((report.times_us.len(), report.failures()), (2, 0));
        let json: serde_json::Value = serde_json::from_str(&report.to_json("p.json")).unwrap();
        assert_eq!(json["failures"], 0);
        assert!(
            report
                .to_table("p.json")
                .contains("failures:              0")
        );
    }

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

    /// A suite of `problems` copies of the 16-point problem, each with its noise, in families "a", "b", "a", ...
    fn suite_value(problems: usize) -> Value {
        let entries: Vec<Value> = (0..problems)
            .map(|k| {
                let mut problem: Value = serde_json::from_str(&problem_json(16)).unwrap();
                problem["noise_px"] = json!(0.1);
                json!({"family": if k % 2 == 0 { "a" } else { "b" }, "problem": problem})
            })
            .collect();
        json!({"format": SUITE_FORMAT, "problems": entries})
    }

    fn suite_error(value: &Value) -> String {
        PnpSuite::from_json(&value.to_string()).unwrap_err().message
    }

    #[test]
    fn suite_is_solved_problem_by_problem() {
        let suite = PnpSuite::from_json(&suite_value(3).to_string()).unwrap();
        assert_eq!(suite.problems.len(), 3);
        assert_eq!(suite.problems[1].family, "b");
        let report = run_suite(&suite, 4);
        let json: Value = serde_json::from_str(&report.to_json("s.json")).unwrap();
        assert_eq!(json["repeats"], 4);
        let first = &json["problems"][0];
        assert_eq!(
            (
                &first["family"],
                &first["ok"],
                &first["ambiguous"],
                &first["pose_count"]
            ),
            (&json!("a"), &json!(true), &json!(false), &json!(1))
        );
        let t: Vec<f64> = serde_json::from_value(first["cam_t_obj_m"].clone()).unwrap();
        assert!(
            (t[0] - 0.02).abs() < 1e-9 && (t[1] + 0.01).abs() < 1e-9 && (t[2] - 0.6).abs() < 1e-9
        );
        let r: [[f64; 3]; 3] = serde_json::from_value(first["cam_r_obj"].clone()).unwrap();
        let truth = &suite.problems[0].problem.instances[0].truth;
        let found = Rotation3::from_matrix_unchecked(Matrix3::from_fn(|i, j| r[i][j]));
        assert!(so3::angle_between(&found, &truth.cam_r_obj) < 1e-9);
        assert!(first["median_time_us"].as_f64().unwrap() > 0.0);
        assert!(report.to_table("s.json").lines().count() == 5);
    }

    #[test]
    fn suite_refusals_name_the_problem_and_field() {
        let mut value = suite_value(3);
        value["format"] = json!("roitrack-pnp-problem/1");
        assert_eq!(
            suite_error(&value),
            "format is \"roitrack-pnp-problem/1\", expected \"roitrack-pnp-suite/1\""
        );
        assert_eq!(
            suite_error(&json!({"format": SUITE_FORMAT, "problems": []})),
            "problems: the suite has no problems"
        );
        assert_eq!(
            suite_error(&json!({"format": SUITE_FORMAT})),
            "problems is missing"
        );

        let mut value = suite_value(3);
        value["problems"][1]["problem"]
            .as_object_mut()
            .unwrap()
            .remove("noise_px");
        assert_eq!(
            suite_error(&value),
            "problems[1].problem.noise_px is missing (a suite problem gives its pixels' noise) (family \"b\")"
        );

        let mut value = suite_value(3);
        let instance = value["problems"][0]["problem"]["instances"][0].clone();
        value["problems"][0]["problem"]["instances"] = json!([instance.clone(), instance]);
        assert_eq!(
            suite_error(&value),
            "problems[0].problem.instances: a suite problem has exactly one instance, got 2 (family \"a\")"
        );

        let mut value = suite_value(3);
        value["problems"][2]["problem"]["intrinsics"]["fx_px"] = json!("1500");
        assert_eq!(
            suite_error(&value),
            "problems[2].problem.intrinsics.fx_px: expected a number, got the string \"1500\" (family \"a\")"
        );

        let mut value = suite_value(3);
        value["problems"][1]["problem"]["instances"][0]["pixels"][3] = json!([1.0]);
        assert_eq!(
            suite_error(&value),
            "problems[1].problem.instances[0].pixels[3]: expected an array of 2 numbers, got an array of 1 \
             (family \"b\")"
        );

        let mut value = suite_value(2);
        value["problems"][1]["problem"]["instances"][0]["pixels"]
            .as_array_mut()
            .unwrap()
            .pop();
        assert_eq!(
            suite_error(&value),
            "problems[1].problem.instances[0].pixels: 15 pixels for 16 model points (family \"b\")"
        );

        let mut value = suite_value(2);
        value["problems"][0]["problem"]["noise_px"] = json!(-0.5);
        assert_eq!(
            suite_error(&value),
            "problems[0].problem.noise_px must be a positive number, got -0.5 (family \"a\")"
        );

        let mut value = suite_value(2);
        value["problems"][1]["family"] = json!(3);
        assert_eq!(
            suite_error(&value),
            "problems[1].family: expected a string, got the number 3"
        );
        assert!(
            PnpSuite::from_json("[1, 2")
                .unwrap_err()
                .message
                .starts_with("not a valid PnP suite")
        );
    }

    #[test]
    fn suite_file_is_named() {
        let dir = tempfile::tempdir().unwrap();
        let missing = dir.path().join("missing.json");
        let message = PnpSuite::read(&missing).unwrap_err().message;
        assert!(
            message.starts_with(&format!(
                "cannot read the suite file {}: ",
                missing.display()
            )),
            "{message}"
        );
        let bad = dir.path().join("bad.json");
        let mut value = suite_value(2);
        value["problems"][1]["problem"]["instances"][0]["cam_r_obj"][0][0] = json!(2.0);
        std::fs::write(&bad, value.to_string()).unwrap();
        let message = PnpSuite::read(&bad).unwrap_err().message;
        assert!(
            message.starts_with(&format!(
                "suite file {}: problems[1].problem.instances[0].cam_r_obj is not a rotation matrix",
                bad.display()
            )) && message.ends_with("(family \"b\")"),
            "{message}"
        );
        let good = dir.path().join("good.json");
        std::fs::write(&good, suite_value(1).to_string()).unwrap();
        assert_eq!(PnpSuite::read(&good).unwrap().problems.len(), 1);
    }
}
