//! The loop end to end on rendered ROIs: it initialises from a full frame, tracks, drops nothing.

use roitrack_core::estimator::{TrackStatus, TrackerConfig};
use roitrack_image::{RoiRenderer, SensorModel};
use roitrack_pipeline::cameras::SimulatedCamera;
use roitrack_pipeline::realtime::{LoopConfig, run_loop};
use roitrack_sim::{Scenario, ScenarioKind};

#[test]
fn tracks_orthoglide_from_rendered_rois() {
    let scenario = Scenario::new(ScenarioKind::Orthoglide, 1);
    let renderer = RoiRenderer::new(
        scenario.camera.clone(),
        scenario.target.clone(),
        SensorModel::default(),
    )
    .unwrap();
    let truth = {
        let s = scenario.clone();
        move |t: f64| s.state_at(t)
    };
    let camera = SimulatedCamera::new(renderer, truth, 7);
    // 0.3 s from the start of the first line (0.25 s): the target is at rest, then accelerates.
    let config = LoopConfig {
        roi_slots: 2400,
        t_start_s: 0.2,
        ..Default::default()
    };
    let report = run_loop(
        camera,
        &scenario.camera,
        &scenario.target,
        TrackerConfig::default(),
        &config,
    )
    .unwrap();
    assert_eq!(report.initialisations, 1);
    assert_eq!(report.dropped, 0);
    assert_eq!(report.refused, 0);
    assert!(report.rejections.total() == 0, "{:?}", report.rejections);
    assert!(
        report.estimates.len() > 200,
        "{} estimates",
        report.estimates.len()
    );
    let mut worst_mm: f64 = 0.0;
    for e in report.estimates.iter().skip(10) {
        assert_ne!(e.status, TrackStatus::Lost);
        let truth = scenario.state_at(e.t_ref_s);
        worst_mm = worst_mm.max(1e3 * (e.state.cam_t_obj_m - truth.cam_t_obj_m).norm());
    }
    assert!(worst_mm < 2.0, "worst position error {worst_mm} mm");
}
