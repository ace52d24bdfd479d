//! The unit tests' data: the 16-point problem as JSON, and suites of it.

use nalgebra::{Rotation3, Vector3};
use roitrack_core::{MotionState, SpatioTemporalModel};
use serde_json::{Value, json};

use super::{FORMAT, SUITE_FORMAT};

pub(super) fn problem_json(pixels_per_instance: usize) -> String {
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

/// A suite of `problems` copies of the 16-point problem, each with its noise, in families "a", "b", "a", ...
pub(super) fn suite_value(problems: usize) -> Value {
    let entries: Vec<Value> = (0..problems)
        .map(|k| {
            let mut problem: Value = serde_json::from_str(&problem_json(16)).unwrap();
            problem["noise_px"] = json!(0.1);
            json!({"family": if k % 2 == 0 { "a" } else { "b" }, "problem": problem})
        })
        .collect();
    json!({"format": SUITE_FORMAT, "problems": entries})
}
