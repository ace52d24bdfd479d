//! Initialisation from a rendered full frame: detect, match, pose.

use roitrack_detect::matching::{DetectedBlob, match_full_frame};
use roitrack_image::{CentroidOptions, detect_blobs};
use roitrack_sim::{RoiRenderer, Scenario, ScenarioKind, SensorModel};

#[test]
fn initialises_from_a_rendered_full_frame() {
    for (kind, t) in [
        (ScenarioKind::Orthoglide, 0.2),
        (ScenarioKind::Random, 1.0),
        (ScenarioKind::Spin, 0.5),
    ] {
        let scenario = Scenario::new(kind, 1);
        let renderer = scenario.roi_renderer().unwrap();
        let mut rng = <rand_chacha::ChaCha8Rng as rand::SeedableRng>::seed_from_u64(3);
        let start = std::time::Instant::now();
        let mut frame = roitrack_image::Frame::default();
        renderer.render_frame(
            &|t| scenario.state_at(t),
            t,
            &mut rng,
            &mut roitrack_sim::RenderScratch::new(),
            &mut frame,
        );
        let frame = frame.pixels;
        let render_s = start.elapsed().as_secs_f64();
        let blobs: Vec<DetectedBlob> =
            detect_blobs(&frame, 1024, 1024, &CentroidOptions::default())
                .iter()
                .map(DetectedBlob::from)
                .collect();
        assert_eq!(blobs.len(), 16, "{kind:?}: {} blobs", blobs.len());
        let m = match_full_frame(&scenario.camera, &scenario.target, &blobs).unwrap();
        let truth = scenario.state_at(t);
        let err_mm = 1e3 * (m.state.cam_t_obj_m - truth.cam_t_obj_m).norm();
        let err_deg =
            roitrack_core::so3::angle_between(&m.state.cam_r_obj, &truth.cam_r_obj).to_degrees();
        eprintln!("{kind:?}: render {render_s:.3} s, pose error {err_mm:.3} mm {err_deg:.3} deg");
        assert!(
            err_mm < 3.0 && err_deg < 1.0,
            "{kind:?}: {err_mm} mm {err_deg} deg"
        );
    }
}

/// A rolling shutter reads row v at t0 + v * line delay: a moving target's blobs appear where the target was when
/// their row was read. The renderer draws that, and `find_target` times each blob by its row: each blob's centre is
/// where the truth puts it at its own time, and far from where it was at the frame's time.
#[test]
fn rolling_shutter_blobs_are_where_the_target_was_when_their_row_was_read() {
    use roitrack_core::{MotionState, Readout, TimeModel};
    use roitrack_detect::find_target;
    use roitrack_image::Frame;
    use roitrack_sim::RenderScratch;

    let line_delay_s = 20e-6;
    let scenario = Scenario::new(ScenarioKind::Static, 1);
    let camera = scenario
        .camera
        .clone()
        .with_time_model(TimeModel {
            readout: Readout::RollingShutter { line_delay_s },
            exposure_s: 100e-6,
        })
        .unwrap();
    // Moving at 0.5 m/s to the right: 0.5 mm (1.25 px) between two rows 50 apart.
    let start = scenario.state_at(0.0);
    let truth = move |t: f64| MotionState {
        cam_t_obj_m: start.cam_t_obj_m + nalgebra::Vector3::new(0.5, 0.0, 0.0) * t,
        velocity_mps: nalgebra::Vector3::new(0.5, 0.0, 0.0),
        ..start
    };
    let renderer = RoiRenderer::new(
        camera.clone(),
        scenario.target.clone(),
        SensorModel::default(),
    )
    .unwrap();
    let mut frame = Frame::default();
    let mut rng = <rand_chacha::ChaCha8Rng as rand::SeedableRng>::seed_from_u64(4);
    renderer.render_frame(&truth, 0.0, &mut rng, &mut RenderScratch::new(), &mut frame);
    let found = find_target(
        &camera,
        &scenario.target,
        &frame,
        &CentroidOptions::default(),
    )
    .unwrap();
    assert_eq!(found.measurements.len(), 16);
    let (mut worst_own, mut worst_frame) = (0.0f64, f64::INFINITY);
    for m in &found.measurements {
        assert!((m.t_s - m.v_px * line_delay_s).abs() < 1e-12);
        let index = scenario.target.index_of(m.id).unwrap();
        let centre = |t: f64| renderer.disk_image_centre_px(&truth(t), index).unwrap();
        let measured = nalgebra::Vector2::new(m.u_px, m.v_px);
        worst_own = worst_own.max((centre(m.t_s) - measured).norm());
        worst_frame = worst_frame.min((centre(0.0) - measured).norm());
    }
    assert!(
        worst_own < 0.1,
        "{worst_own} px from the truth at the blob's own time"
    );
    assert!(
        worst_frame > 4.0,
        "{worst_frame} px from the truth at the frame's time"
    );
}
