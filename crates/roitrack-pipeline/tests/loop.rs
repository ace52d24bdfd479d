//! The loop end to end on rendered ROIs: it initialises from a full frame, tracks, drops nothing.

use roitrack_estimators::{TrackStatus, TrackerConfig};
use roitrack_image::RoiCamera;
use roitrack_pipeline::PipelineError;
use roitrack_pipeline::realtime::{LoopConfig, LoopReport, run_loop};
use roitrack_sim::{Scenario, ScenarioKind, SimulatedCamera};

/// The orthoglide scenario (seed 1).
fn orthoglide() -> Scenario {
    Scenario::new(ScenarioKind::Orthoglide, 1)
}

/// [`run_loop`] of `camera` with the scenario's camera model and target and the default tracker.
fn run_scenario<C: RoiCamera>(
    scenario: &Scenario,
    camera: &mut C,
    config: &LoopConfig,
) -> Result<LoopReport, PipelineError> {
    run_loop(
        camera,
        &scenario.camera,
        &scenario.target,
        TrackerConfig::default(),
        config,
    )
}

#[test]
fn tracks_orthoglide_from_rendered_rois() {
    let scenario = orthoglide();
    let mut camera = scenario.simulated_camera(7).unwrap();
    // 0.3 s from the start of the first line (0.25 s): the target is at rest, then accelerates.
    let config = LoopConfig {
        roi_slots: 2400,
        t_start_s: 0.2,
        ..Default::default()
    };
    let report = run_scenario(&scenario, &mut camera, &config).unwrap();
    assert_eq!(report.acquisition.initialisations, 1);
    assert_eq!(report.acquisition.dropped, 0);
    assert_eq!(report.refused, 0);
    assert!(
        report.acquisition.rejections.total() == 0,
        "{:?}",
        report.acquisition.rejections
    );
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

#[test]
fn reflections_add_a_spot_that_moves_the_centroid_and_nothing_else() {
    use roitrack_image::{CentroidOptions, Roi, RoiImage, RoiTrigger, measure_blob};
    use roitrack_sim::ReflectionFault;
    let scenario = orthoglide();
    let renderer = scenario.roi_renderer().unwrap();
    let state = scenario.state_at(0.1);
    let p = scenario.target.points()[5].point_in_obj_m;
    let px = scenario
        .camera
        .intrinsics
        .pixel_from_cam(&state.point_in_cam_at(&p, 0.0))
        .unwrap();
    let roi = Roi::new(px.x as u32 - 16, px.y as u32 - 16, 32, 32);
    let truth = move |_t: f64| state;
    let mut clean = SimulatedCamera::new(renderer.clone(), truth, 3);
    let always = ReflectionFault {
        fraction: 1.0,
        relative_peak: (2.0, 2.0),
        ..ReflectionFault::default()
    };
    let mut faulty = SimulatedCamera::new(renderer.clone(), truth, 3).with_reflections(always);
    let never = ReflectionFault {
        fraction: 0.0,
        ..ReflectionFault::default()
    };
    let mut unaffected = SimulatedCamera::new(renderer, truth, 3).with_reflections(never);
    let (mut a, mut b, mut c) = (
        RoiImage::default(),
        RoiImage::default(),
        RoiImage::default(),
    );
    for k in 0..20 {
        let t = 0.1 + k as f64 * 250e-6;
        let trigger = RoiTrigger {
            point_id: 5,
            roi,
            t_s: t,
        };
        clean.grab_roi(&trigger, &mut a).unwrap();
        faulty.grab_roi(&trigger, &mut b).unwrap();
        unaffected.grab_roi(&trigger, &mut c).unwrap();
        assert_eq!((a.t_s, a.roi, a.point_id), (t, roi, 5));
        // The fault draws from its own generator: without reflections the pixels are the clean camera's.
        assert_eq!(a, c);
        assert_ne!(a, b);
        let opts = CentroidOptions::default();
        let clean_centroid = measure_blob(&a.pixels, &roi, &opts).unwrap();
        // Twice as bright as the blob, the spot takes the centroid (or the blob is rejected when it reaches the border).
        if let Ok(faulty_centroid) = measure_blob(&b.pixels, &roi, &opts) {
            let moved = ((faulty_centroid.u_px - clean_centroid.u_px).powi(2)
                + (faulty_centroid.v_px - clean_centroid.v_px).powi(2))
            .sqrt();
            assert!(moved > 0.2, "ROI {k}: the centroid moved {moved} px");
        }
    }
}

/// A camera that fails now and then, then goes away: the loop counts the transient failures, stops at the end, and
/// keeps every estimate made until then.
struct Flaky<C> {
    inner: C,
    grabs: usize,
    disconnect_after: usize,
}

impl<C: roitrack_image::RoiCamera> roitrack_image::RoiCamera for Flaky<C> {
    fn grab_roi(
        &mut self,
        trigger: &roitrack_image::RoiTrigger,
        image: &mut roitrack_image::RoiImage,
    ) -> Result<(), roitrack_image::GrabError> {
        self.grabs += 1;
        if self.grabs > self.disconnect_after {
            return Err(roitrack_image::GrabError::Disconnected {
                reason: "unplugged".to_string(),
            });
        }
        if self.grabs.is_multiple_of(50) {
            return Err(roitrack_image::GrabError::Timeout { timeout_s: 0.01 });
        }
        self.inner.grab_roi(trigger, image)
    }

    fn grab_full_frame(
        &mut self,
        t_s: f64,
        frame: &mut roitrack_image::Frame,
    ) -> Result<(), roitrack_image::GrabError> {
        self.inner.grab_full_frame(t_s, frame)
    }
}

#[test]
fn a_failing_camera_is_survived_and_its_end_keeps_the_estimates() {
    let scenario = orthoglide();
    let inner = scenario.simulated_camera(5).unwrap();
    let mut camera = Flaky {
        inner,
        grabs: 0,
        disconnect_after: 1500,
    };
    let config = LoopConfig {
        roi_slots: 4000,
        ..Default::default()
    };
    let report = run_scenario(&scenario, &mut camera, &config).unwrap();
    assert_eq!(report.acquisition.camera_errors, 30, "{report:?}");
    assert!(matches!(
        report.acquisition.stopped_by,
        Some(roitrack_image::GrabError::Disconnected { .. })
    ));
    // Every ROI read before the end was measured and tracked.
    assert_eq!(report.acquisition.rois, 1470);
    assert!(report.estimates.len() >= 140, "{}", report.estimates.len());
    assert!(
        report
            .estimates
            .iter()
            .skip(10)
            .all(|e| e.status == TrackStatus::Tracking || e.status == TrackStatus::Disputed)
    );
    // The camera is the caller's again.
    assert_eq!(camera.grabs, 1501);
}

#[test]
fn invalid_loop_options_and_wrong_frames_are_refused() {
    let scenario = orthoglide();
    let mut camera = scenario.simulated_camera(5).unwrap();
    let bad = LoopConfig {
        rate_hz: 0.0,
        ..Default::default()
    };
    let error = run_scenario(&scenario, &mut camera, &bad).unwrap_err();
    assert!(error.to_string().contains("rate_hz"), "{error}");
    // A camera model of another size than the camera's frames: the run stops at once, saying so.
    let mut small = scenario.camera.clone();
    small.width_px = 640;
    let report = run_loop(
        &mut camera,
        &small,
        &scenario.target,
        TrackerConfig::default(),
        &LoopConfig::default(),
    )
    .unwrap();
    assert!(
        matches!(
            report.acquisition.stopped_by,
            Some(roitrack_image::GrabError::FrameSize {
                width: 1024,
                expected_width: 640,
                ..
            })
        ),
        "{:?}",
        report.acquisition.stopped_by
    );
    assert!(report.estimates.is_empty());
}

/// A camera that takes 1 ms per ROI: slower than a 4 kHz slot.
struct Slow<C> {
    inner: C,
}

impl<C: roitrack_image::RoiCamera> roitrack_image::RoiCamera for Slow<C> {
    fn grab_roi(
        &mut self,
        trigger: &roitrack_image::RoiTrigger,
        image: &mut roitrack_image::RoiImage,
    ) -> Result<(), roitrack_image::GrabError> {
        std::thread::sleep(std::time::Duration::from_millis(1));
        self.inner.grab_roi(trigger, image)
    }

    fn grab_full_frame(
        &mut self,
        t_s: f64,
        frame: &mut roitrack_image::Frame,
    ) -> Result<(), roitrack_image::GrabError> {
        self.inner.grab_full_frame(t_s, frame)
    }
}

#[test]
fn a_paced_loop_that_skips_late_slots_reads_fewer_rois_all_of_the_present() {
    // A target at rest: wherever the skipping lands, the blobs are where the last estimate put them.
    let scenario = Scenario::new(ScenarioKind::Static, 3);
    let mut camera = Slow {
        inner: scenario.simulated_camera(3).unwrap(),
    };
    // 3 s at 4 kHz (the full frame that starts it can take a second on a loaded machine): a camera at 1 ms a ROI
    // cannot hold it.
    let config = LoopConfig {
        roi_slots: 12_000,
        paced: true,
        skip_late_slots: true,
        ..Default::default()
    };
    let report = run_scenario(&scenario, &mut camera, &config).unwrap();
    let counts = &report.acquisition;
    // At most one ROI a millisecond: most slots skipped, counted; every slot accounted for.
    assert!(
        (counts.rois as f64) <= report.wall_s * 1000.0 + 10.0,
        "{} ROIs in {} s",
        counts.rois,
        report.wall_s
    );
    assert!(counts.skipped > 2 * counts.rois, "{report:?}");
    assert!(counts.rois + counts.skipped + 4 * counts.initialisations >= 12_000 - 4);
    assert!(report.estimates.len() >= 5, "{report:?}");
}
