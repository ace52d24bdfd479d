//! The PnP benchmark (`roitrack pnp-bench`): times our static pose solver ([`solve_static_pose`]) on a stored PnP
//! problem, the same file the OpenCV peer comparison (`bench/opencv_compare.sh`) reads, and reports its accuracy
//! against the true poses.
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

use std::hint::black_box;
use std::time::Instant;

use nalgebra::{Matrix3, Rotation3, Vector2, Vector3};
use roitrack_core::estimator::{Observation, solve_static_pose};
use roitrack_core::stats::{mean, quantile, rms, sorted};
use roitrack_core::{
    MotionState, PinholeIntrinsics, SpatioTemporalModel, Target, TargetPoint, so3,
};
use serde::Deserialize;
use serde_json::json;
use thiserror::Error;

/// The format tag a problem file must carry.
pub const FORMAT: &str = "roitrack-pnp-problem/1";

/// Why a problem was refused: the message names the instance and field where it applies.
#[derive(Debug, Clone, PartialEq, Error)]
#[error("{message}")]
pub struct PnpError {
    pub message: String,
}

impl PnpError {
    fn new(message: impl Into<String>) -> Self {
        Self {
            message: message.into(),
        }
    }
}

#[derive(Debug, Deserialize)]
struct ProblemFile {
    format: String,
    intrinsics: IntrinsicsJson,
    model_points: Vec<ModelPointJson>,
    instances: Vec<InstanceJson>,
    noise_px: Option<f64>,
}

#[derive(Debug, Deserialize)]
struct IntrinsicsJson {
    fx_px: f64,
    fy_px: f64,
    #[serde(default)]
    skew_px: f64,
    cx_px: f64,
    cy_px: f64,
}

#[derive(Debug, Deserialize)]
struct ModelPointJson {
    id: u32,
    xyz_m: [f64; 3],
}

#[derive(Debug, Deserialize)]
struct InstanceJson {
    cam_r_obj: [[f64; 3]; 3],
    cam_t_obj_m: [f64; 3],
    pixels: Vec<[f64; 2]>,
}

/// One problem instance, validated: the true pose and the observations.
#[derive(Debug, Clone)]
pub struct PnpInstance {
    pub truth: MotionState,
    pub observations: Vec<Observation>,
}

/// A validated PnP problem: the camera's pinhole model, the target, and the instances.
#[derive(Debug, Clone)]
pub struct PnpProblem {
    pub model: SpatioTemporalModel,
    pub target: Target,
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
        let file: ProblemFile = serde_json::from_str(text)
            .map_err(|e| PnpError::new(format!("not a valid PnP problem: {e}")))?;
        validate(file)
    }
}

fn validate(file: ProblemFile) -> Result<PnpProblem, PnpError> {
    if file.format != FORMAT {
        return Err(PnpError::new(format!(
            "format is {:?}, expected {FORMAT:?}",
            file.format
        )));
    }
    let intrinsics = PinholeIntrinsics {
        fx_px: file.intrinsics.fx_px,
        fy_px: file.intrinsics.fy_px,
        skew_px: file.intrinsics.skew_px,
        cx_px: file.intrinsics.cx_px,
        cy_px: file.intrinsics.cy_px,
    };
    intrinsics
        .validate()
        .map_err(|e| PnpError::new(format!("intrinsics: {e}")))?;
    let points = file
        .model_points
        .iter()
        .map(|p| TargetPoint {
            id: p.id,
            point_in_obj_m: Vector3::from(p.xyz_m),
            diameter_m: None,
        })
        .collect();
    let target = Target::new(points).map_err(|e| PnpError::new(format!("model_points: {e}")))?;
    if file.instances.is_empty() {
        return Err(PnpError::new("the problem has no instances"));
    }
    let instances = file
        .instances
        .iter()
        .enumerate()
        .map(|(k, instance)| {
            validate_instance(instance, target.len())
                .map_err(|e| PnpError::new(format!("instance {k}: {}", e.message)))
        })
        .collect::<Result<Vec<_>, _>>()?;
    let noise_px = file
        .noise_px
        .unwrap_or(roitrack_core::estimator::TrackerConfig::default().noise_px);
    if !(noise_px.is_finite() && noise_px > 0.0) {
        return Err(PnpError::new(format!(
            "noise_px must be a positive number, got {noise_px}"
        )));
    }
    Ok(PnpProblem {
        model: SpatioTemporalModel::new(intrinsics),
        target,
        instances,
        noise_px,
    })
}

fn validate_instance(instance: &InstanceJson, point_count: usize) -> Result<PnpInstance, PnpError> {
    if instance.pixels.len() != point_count {
        return Err(PnpError::new(format!(
            "{} pixels for {point_count} model points",
            instance.pixels.len()
        )));
    }
    let r = Matrix3::from_fn(|i, j| instance.cam_r_obj[i][j]);
    let t = Vector3::from(instance.cam_t_obj_m);
    if !r.iter().chain(t.iter()).all(|v| v.is_finite()) {
        return Err(PnpError::new("the true pose is not finite"));
    }
    let orthonormality = (r.transpose() * r - Matrix3::identity()).amax();
    if orthonormality > 1e-6 || r.determinant() < 0.0 {
        return Err(PnpError::new(format!(
            "cam_r_obj is not a rotation matrix (|RᵀR - I| = {orthonormality:.1e}, det = {:.6})",
            r.determinant()
        )));
    }
    let observations = instance
        .pixels
        .iter()
        .enumerate()
        .map(|(i, &[u, v])| {
            if !(u.is_finite() && v.is_finite()) {
                return Err(PnpError::new(format!("pixel {i} is not finite ({u}, {v})")));
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
    pub pose: Option<MotionState>,
    pub error: Option<String>,
    pub position_error_mm: f64,
    pub rotation_error_deg: f64,
    pub reprojection_rms_px: f64,
    pub iterations: usize,
    pub converged: bool,
}

/// The benchmark's result: every instance solved once for accuracy, and every timed solve.
#[derive(Debug, Clone)]
pub struct PnpReport {
    pub solved: Vec<Solved>,
    /// Every timed solve (µs), in order.
    pub times_us: Vec<f64>,
    pub points: usize,
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
            "solver": "roitrack_core::estimator::solve_static_pose",
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
        assert!(
            message.contains("instance 0") && message.contains("15 pixels"),
            "{message}"
        );
    }
}
