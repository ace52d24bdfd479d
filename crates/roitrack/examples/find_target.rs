//! Find the target in a full frame with no prior: detect the blobs, identify which is which, solve the static pose,
//! and time each blob with the camera's time model (here a rolling shutter, whose rows are read one after another).
//!
//! ```sh
//! cargo run --release -p roitrack --example find_target
//! ```
//!
//! The frame is rendered by roitrack's simulated camera (perspective disks, blur, noise) from a known pose, so the
//! pose found can be checked against the truth.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use roitrack::core::so3;
use roitrack::detect::find_target;
use roitrack::image::CentroidOptions;
use roitrack::nalgebra::{Rotation3, Vector3};
use roitrack::sim::{RenderScratch, RoiRenderer, SensorModel};
use roitrack::{CameraModel, Frame, MotionState, Readout, Target, TimeModel};

type Result<T> = std::result::Result<T, Box<dyn std::error::Error>>;

fn main() -> Result<()> {
    // A rolling-shutter camera reading its 1024 rows in 10 ms, 1 ms exposure.
    let camera = CameraModel::canonical().with_time_model(TimeModel {
        readout: Readout::RollingShutter {
            line_delay_s: 10e-3 / 1024.0,
        },
        exposure_s: 1e-3,
    })?;
    let target = Target::grid4x4();
    let truth = MotionState::at_rest(
        Rotation3::from_euler_angles(0.3, -0.2, 2.5),
        Vector3::new(-0.03, 0.02, 0.55),
    );

    let renderer = RoiRenderer::new(camera.clone(), target.clone(), SensorModel::default())?;
    let mut frame = Frame::default();
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    renderer.render_frame(
        &|_t| truth,
        1.0,
        &mut rng,
        &mut RenderScratch::new(),
        &mut frame,
    );

    let found = find_target(&camera, &target, &frame, &CentroidOptions::default())?;
    println!(
        "{} blobs detected, {} identified; reprojection residual {:.3} px",
        found.blobs_detected,
        found.measurements.len(),
        found.residual_rms_px
    );
    for m in &found.measurements {
        println!(
            "  point {:>2} at ({:7.2}, {:7.2}) px, taken at t = {:.6} s",
            m.id, m.u_px, m.v_px, m.t_s
        );
    }
    let position_error_mm = (found.state.cam_t_obj_m - truth.cam_t_obj_m).norm() * 1e3;
    let rotation_error_deg =
        so3::angle_between(&found.state.cam_r_obj, &truth.cam_r_obj).to_degrees();
    println!(
        "pose at t = {:.6} s: position error {position_error_mm:.3} mm, rotation error {rotation_error_deg:.3} deg",
        found.t_s
    );
    if position_error_mm > 2.0 || rotation_error_deg > 0.5 {
        return Err("the pose found is off the truth".into());
    }
    Ok(())
}
