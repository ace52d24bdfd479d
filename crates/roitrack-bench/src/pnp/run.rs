//! The problem's benchmark: every instance solved once for its accuracy, then timed ([`run`]), and its report.

use std::hint::black_box;
use std::time::Instant;

use roitrack_core::stats::{mean, quantile, rms, sorted};
use roitrack_core::{MotionState, SpatioTemporalModel, Target, so3};
use roitrack_estimators::{Observation, solve_static_pose};
use serde_json::json;

use super::problem::PnpProblem;

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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pnp::fixtures::problem_json;

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
}
