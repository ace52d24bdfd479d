//! `roitrack pnp-bench`: times our static pose solver ([`solve_static_pose`]) on a stored PnP problem, the same file
//! the OpenCV peer comparison (`bench/opencv_compare.sh`) reads, and reports its accuracy against the true poses.
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
//! (object to camera, row-major rotation). Other keys are ignored.

use std::hint::black_box;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result, bail, ensure};
use clap::Args;
use nalgebra::{Matrix3, Rotation3, Vector2, Vector3};
use roitrack_core::estimator::{Observation, solve_static_pose};
use roitrack_core::{
    MotionState, PinholeIntrinsics, SpatioTemporalModel, Target, TargetPoint, so3,
};
use serde::Deserialize;
use serde_json::json;

/// The format tag a problem file must carry.
const FORMAT: &str = "roitrack-pnp-problem/1";

/// Time the static pose solver on a stored PnP problem (the file the OpenCV comparison reads).
#[derive(Debug, Args)]
pub struct PnpBenchArgs {
    /// Problem file (JSON, format roitrack-pnp-problem/1, as written by bench/opencv_compare.py).
    #[arg(long)]
    pub problem: PathBuf,
    /// Timed solves of each instance (all instances are solved once per repetition, in turn).
    #[arg(long, default_value_t = 20)]
    pub repeats: usize,
    /// Print one JSON object (summary, the pose found for each instance, every solve's time) instead of a table.
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, Deserialize)]
struct ProblemFile {
    format: String,
    intrinsics: IntrinsicsJson,
    model_points: Vec<ModelPointJson>,
    instances: Vec<InstanceJson>,
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
#[derive(Debug)]
struct Instance {
    truth: MotionState,
    observations: Vec<Observation>,
}

/// The validated problem.
#[derive(Debug)]
struct Problem {
    model: SpatioTemporalModel,
    target: Target,
    instances: Vec<Instance>,
}

/// Reads and validates a problem file; every error names the file and, where it applies, the instance.
fn load_problem(path: &Path) -> Result<Problem> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("cannot read the problem file {}", path.display()))?;
    let file: ProblemFile = serde_json::from_str(&text)
        .with_context(|| format!("problem file {} is not a valid PnP problem", path.display()))?;
    validate(file).with_context(|| format!("problem file {}", path.display()))
}

fn validate(file: ProblemFile) -> Result<Problem> {
    ensure!(
        file.format == FORMAT,
        "format is {:?}, expected {FORMAT:?}",
        file.format
    );
    let intrinsics = PinholeIntrinsics {
        fx_px: file.intrinsics.fx_px,
        fy_px: file.intrinsics.fy_px,
        skew_px: file.intrinsics.skew_px,
        cx_px: file.intrinsics.cx_px,
        cy_px: file.intrinsics.cy_px,
    };
    intrinsics.validate().context("intrinsics")?;
    let points = file
        .model_points
        .iter()
        .map(|p| TargetPoint {
            id: p.id,
            point_in_obj_m: Vector3::from(p.xyz_m),
            diameter_m: None,
        })
        .collect();
    let target = Target::new(points).context("model_points")?;
    ensure!(!file.instances.is_empty(), "the problem has no instances");
    let instances = file
        .instances
        .iter()
        .enumerate()
        .map(|(k, instance)| {
            validate_instance(instance, target.len()).with_context(|| format!("instance {k}"))
        })
        .collect::<Result<Vec<_>>>()?;
    Ok(Problem {
        model: SpatioTemporalModel::new(intrinsics),
        target,
        instances,
    })
}

fn validate_instance(instance: &InstanceJson, point_count: usize) -> Result<Instance> {
    ensure!(
        instance.pixels.len() == point_count,
        "{} pixels for {point_count} model points",
        instance.pixels.len()
    );
    let r = Matrix3::from_fn(|i, j| instance.cam_r_obj[i][j]);
    let t = Vector3::from(instance.cam_t_obj_m);
    ensure!(
        r.iter().chain(t.iter()).all(|v| v.is_finite()),
        "the true pose is not finite"
    );
    let orthonormality = (r.transpose() * r - Matrix3::identity()).amax();
    if orthonormality > 1e-6 || r.determinant() < 0.0 {
        bail!(
            "cam_r_obj is not a rotation matrix (|RᵀR - I| = {orthonormality:.1e}, det = {:.6})",
            r.determinant()
        );
    }
    let observations = instance
        .pixels
        .iter()
        .enumerate()
        .map(|(i, &[u, v])| {
            ensure!(
                u.is_finite() && v.is_finite(),
                "pixel {i} is not finite ({u}, {v})"
            );
            Ok(Observation {
                t_s: 0.0,
                point_index: i,
                ideal_px: Vector2::new(u, v),
            })
        })
        .collect::<Result<Vec<_>>>()?;
    Ok(Instance {
        truth: MotionState::at_rest(Rotation3::from_matrix(&r), t),
        observations,
    })
}

/// Quantile of a sorted slice (nearest rank).
fn quantile(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    sorted[((sorted.len() - 1) as f64 * q).round() as usize]
}

fn rms(values: &[f64]) -> f64 {
    (values.iter().map(|v| v * v).sum::<f64>() / values.len().max(1) as f64).sqrt()
}

fn sorted(values: &[f64]) -> Vec<f64> {
    let mut s = values.to_vec();
    s.sort_by(f64::total_cmp);
    s
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
struct Solved {
    pose: Option<MotionState>,
    error: Option<String>,
    position_error_mm: f64,
    rotation_error_deg: f64,
    reprojection_rms_px: f64,
    iterations: usize,
    converged: bool,
}

pub fn run(args: &PnpBenchArgs) -> Result<()> {
    ensure!(args.repeats >= 1, "--repeats must be at least 1");
    let problem = load_problem(&args.problem)?;
    let Problem {
        model,
        target,
        instances,
    } = &problem;

    // Accuracy: one untimed solve of each instance.
    let solved: Vec<Solved> = instances
        .iter()
        .map(
            |instance| match solve_static_pose(model, target, &instance.observations) {
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
            },
        )
        .collect();

    // Timing: every instance in turn, `repeats` times over, each solve timed on its own.
    let mut times_us = Vec::with_capacity(instances.len() * args.repeats);
    for _ in 0..args.repeats {
        for instance in instances {
            let observations = black_box(instance.observations.as_slice());
            let start = Instant::now();
            let result = solve_static_pose(black_box(model), black_box(target), observations);
            let elapsed = start.elapsed();
            black_box(&result);
            times_us.push(elapsed.as_secs_f64() * 1e6);
        }
    }
    let times = sorted(&times_us);

    let ok: Vec<&Solved> = solved.iter().filter(|s| s.pose.is_some()).collect();
    let failures = solved.len() - ok.len();
    let position: Vec<f64> = ok.iter().map(|s| s.position_error_mm).collect();
    let rotation: Vec<f64> = ok.iter().map(|s| s.rotation_error_deg).collect();
    let reprojection: Vec<f64> = ok.iter().map(|s| s.reprojection_rms_px).collect();
    let (position_sorted, rotation_sorted, reprojection_sorted) =
        (sorted(&position), sorted(&rotation), sorted(&reprojection));
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;

    if args.json {
        let poses: Vec<_> = solved
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
            "problem": args.problem.display().to_string(),
            "instances": instances.len(),
            "points": target.len(),
            "repeats": args.repeats,
            "solves_timed": times.len(),
            "failures": failures,
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
            "solve_times_us": times_us,
        });
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        println!(
            "solve_static_pose on {} ({} instances x {} points, {} timed solves)",
            args.problem.display(),
            instances.len(),
            target.len(),
            times.len()
        );
        println!(
            "  time per solve:        median {:.2} us, p99 {:.2} us, min {:.2} us",
            quantile(&times, 0.5),
            quantile(&times, 0.99),
            quantile(&times, 0.0)
        );
        println!(
            "  position error:        RMS {:.4} mm, max {:.4} mm",
            rms(&position),
            quantile(&position_sorted, 1.0)
        );
        println!(
            "  rotation error:        RMS {:.4} deg, max {:.4} deg",
            rms(&rotation),
            quantile(&rotation_sorted, 1.0)
        );
        println!(
            "  reprojection RMS:      mean {:.4} px, max {:.4} px",
            mean(&reprojection),
            quantile(&reprojection_sorted, 1.0)
        );
        println!("  failures:              {failures}");
    }
    Ok(())
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

    fn write(text: &str) -> (tempfile::TempDir, PathBuf) {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("problem.json");
        std::fs::write(&path, text).unwrap();
        (dir, path)
    }

    #[test]
    fn exact_problem_is_solved_exactly() {
        let (_dir, path) = write(&problem_json(16));
        let problem = load_problem(&path).unwrap();
        let instance = &problem.instances[0];
        let fit =
            solve_static_pose(&problem.model, &problem.target, &instance.observations).unwrap();
        assert!((fit.state.cam_t_obj_m - instance.truth.cam_t_obj_m).norm() < 1e-9);
        assert!(so3::angle_between(&fit.state.cam_r_obj, &instance.truth.cam_r_obj) < 1e-9);
        let args = PnpBenchArgs {
            problem: path,
            repeats: 2,
            json: true,
        };
        run(&args).unwrap();
    }

    #[test]
    fn bad_files_are_refused_with_the_file_name() {
        let (_dir, path) = write(&problem_json(15));
        let message = format!("{:#}", load_problem(&path).unwrap_err());
        assert!(
            message.contains("problem.json") && message.contains("instance 0"),
            "{message}"
        );
        let (_dir, path) = write("{ not json");
        let message = format!("{:#}", load_problem(&path).unwrap_err());
        assert!(message.contains("problem.json"), "{message}");
        let missing = PathBuf::from("/nonexistent/problem.json");
        let message = format!("{:#}", load_problem(&missing).unwrap_err());
        assert!(message.contains("/nonexistent/problem.json"), "{message}");
    }
}
