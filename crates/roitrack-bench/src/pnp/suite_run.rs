//! The suite solved problem by problem ([`run_suite`]): every pose returned and the median time, and its report.

use std::hint::black_box;
use std::time::Instant;

use roitrack_core::MotionState;
use roitrack_core::stats::median;
use roitrack_estimators::{PoseFit, solve_static_pose};
use serde_json::json;

use super::problem::PnpProblem;
use super::suite::{PnpSuite, SuiteProblem};

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
    use nalgebra::{Matrix3, Rotation3};
    use roitrack_core::so3;
    use serde_json::{Value, json};

    use super::*;
    use crate::pnp::fixtures::suite_value;

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
}
