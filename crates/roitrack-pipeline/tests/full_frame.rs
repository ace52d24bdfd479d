//! Initialisation from a rendered full frame: detect, match, pose.

use roitrack_image::{CentroidOptions, RoiRenderer, SensorModel, detect_blobs};
use roitrack_pipeline::matching::{DetectedBlob, match_full_frame};
use roitrack_sim::{Scenario, ScenarioKind};

#[test]
fn initialises_from_a_rendered_full_frame() {
    for (kind, t) in [
        (ScenarioKind::Orthoglide, 0.2),
        (ScenarioKind::Random, 1.0),
        (ScenarioKind::Spin, 0.5),
    ] {
        let scenario = Scenario::new(kind, 1);
        let renderer = RoiRenderer::new(
            scenario.camera.clone(),
            scenario.target.clone(),
            SensorModel::default(),
        )
        .unwrap();
        let mut rng = <rand_chacha::ChaCha8Rng as rand::SeedableRng>::seed_from_u64(3);
        let start = std::time::Instant::now();
        let mut frame = roitrack_image::Frame::default();
        renderer.render_frame(
            &|t| scenario.state_at(t),
            t,
            &mut rng,
            &mut roitrack_image::RenderScratch::new(),
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
