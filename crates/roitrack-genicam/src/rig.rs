//! A rig of live GenICam cameras, real or fake, in one loop: one acquisition thread per camera, one fused track of
//! the target in the rig's frame on the rig's clock ([`roitrack_pipeline::run_rig_loop`]).

use std::sync::Arc;
use std::sync::atomic::AtomicBool;

use roitrack_core::Target;
use roitrack_estimators::rig::{Rig, RigEstimate, RigTrackerConfig};
use roitrack_pipeline::{RigLoopReport, run_rig_loop};
use roitrack_sim::SensorModel;
use roitrack_sim::multi_camera::CameraRigScene;

use crate::live::{fake_camera_options, loop_config};
use crate::{
    CameraStats, FakeGigeCamera, GenicamCamera, GenicamError, GenicamOptions, LiveOptions,
};

/// The most cameras of a fake rig: each listens on a loopback address of its own, 127.0.0.1 to 127.0.0.8.
pub const MAX_FAKE_RIG_CAMERAS: usize = 8;

/// What a live run of a rig did: the rig loop's report (fused estimates, each camera's acquisition, the clocks
/// learnt) and each camera's own.
#[derive(Debug, Clone)]
pub struct RigLiveReport {
    /// The rig loop's report.
    pub loop_report: RigLoopReport,
    /// Per camera (the rig's order): what it did.
    pub cameras: Vec<CameraStats>,
    /// Per camera: the camera as opened ([`GenicamCamera::description`]).
    pub descriptions: Vec<String>,
}

impl RigLiveReport {
    /// The end-of-run summary: per camera its ROIs, measurements, starts and clock; then the fused estimates.
    ///
    /// ```
    /// use roitrack_genicam::RigLiveReport;
    /// use roitrack_pipeline::{AcquisitionCounts, RigLoopReport};
    /// let report = RigLiveReport {
    ///     loop_report: RigLoopReport {
    ///         estimates: vec![], latencies_us: vec![], cameras: vec![AcquisitionCounts::default()], refused: 0,
    ///         tracker: Default::default(), clocks: vec![], wall_s: 1.0,
    ///     },
    ///     cameras: vec![Default::default()],
    ///     descriptions: vec!["fake".into()],
    /// };
    /// assert!(report.summary(&["left".to_string()]).contains("left: fake"));
    /// ```
    pub fn summary(&self, names: &[String]) -> String {
        let r = &self.loop_report;
        let mut text = String::new();
        for (c, ((counts, stats), description)) in r
            .cameras
            .iter()
            .zip(&self.cameras)
            .zip(&self.descriptions)
            .enumerate()
        {
            let name = names.get(c).map_or("?", String::as_str);
            text.push_str(&format!(
                "{name}: {description}\n  ROIs grabbed {}, lost {}, incomplete {}; {} measurements, {} rejected \
                 blobs (absent {}, touching the border {}, too small {}, too large {}, asymmetric {}), {} \
                 initialisations ({} failed), {} dropped measurements",
                stats.rois,
                stats.lost,
                stats.incomplete,
                counts.measurements,
                counts.rejections.total(),
                counts.rejections.absent,
                counts.rejections.touches_border,
                counts.rejections.too_small,
                counts.rejections.too_large,
                counts.rejections.asymmetric,
                counts.initialisations,
                counts.failed_initialisations,
                counts.dropped,
            ));
            if let Some(clock) = r.clocks.get(c)
                && c > 0
            {
                text.push_str(&format!(
                    "; clock offset {:.6} s ± {:.1} us, drift {:.2} ± {:.2} ppm{}",
                    clock.offset_s,
                    clock.offset_sigma_s * 1e6,
                    clock.drift_ppm,
                    clock.drift_sigma_ppm,
                    if clock.synced { "" } else { " (not found)" }
                ));
            }
            if let Some(e) = &counts.stopped_by {
                text.push_str(&format!("; stopped early: {e}"));
            }
            text.push('\n');
        }
        let latency = roitrack_core::stats::sorted(
            &r.latencies_us
                .iter()
                .copied()
                .filter(|l| l.is_finite())
                .collect::<Vec<_>>(),
        );
        text.push_str(&format!(
            "{} fused estimates over {:.2} s, latency from grab p50/p99 {:.0}/{:.0} us (the reorder buffer's); fused \
             {}, rejected by the gate {}, fused tracks started {}, refused {}",
            r.estimates.len(),
            r.wall_s,
            roitrack_core::stats::quantile(&latency, 0.5),
            roitrack_core::stats::quantile(&latency, 0.99),
            r.tracker.fused,
            r.tracker.gated,
            r.tracker.starts,
            r.refused,
        ));
        text
    }
}

/// Runs the rig loop on `cameras` (opened, in the rig's order) for `options.duration_s`: each camera's full-frame
/// start and ROIs on a thread of its own, one fused track; `paced`: slots at their wall-clock times (real cameras),
/// otherwise as fast as each camera delivers. `on_estimate` gets each fused estimate as it is made; it must not
/// block. See [`run_fake_rig`] for an example.
pub fn run_rig_live(
    cameras: &mut [GenicamCamera],
    rig: &Rig,
    target: &Target,
    options: &LiveOptions,
    paced: bool,
    on_estimate: &mut (dyn FnMut(&RigEstimate) + Send),
) -> Result<RigLiveReport, GenicamError> {
    // Every ROI is a camera's window: the scheduler places windows of the smallest camera's.
    let side = cameras
        .iter()
        .map(|c| {
            let (w, h) = c.window();
            w.min(h)
        })
        .min()
        .unwrap_or(options.camera.roi_size_px);
    let config = loop_config(options, side, paced);
    let tracker = RigTrackerConfig {
        tracker: options.tracker,
        ..RigTrackerConfig::default()
    };
    let loop_report = run_rig_loop(cameras, rig, target, tracker, &config, on_estimate)?;
    Ok(RigLiveReport {
        loop_report,
        cameras: cameras.iter().map(GenicamCamera::stats).collect(),
        descriptions: cameras
            .iter()
            .map(|c| c.description().to_string())
            .collect(),
    })
}

/// ```no_run
/// use std::sync::{Arc, atomic::AtomicBool};
/// use roitrack_genicam::{LiveOptions, run_fake_rig};
/// use roitrack_sim::multi_camera::CameraRigScene;
/// use roitrack_sim::{Scenario, ScenarioKind};
/// // Two cameras (127.0.0.2 added to the loopback), the second's clock to learn.
/// let scene = CameraRigScene::random(Scenario::new(ScenarioKind::Orthoglide, 1), 2, 1);
/// let options = LiveOptions { duration_s: 2.0, ..LiveOptions::default() };
/// let report = run_fake_rig(&scene, &scene.rig_with_clocks_unknown(), &options, 1, Arc::new(AtomicBool::new(false)),
///     &mut |_| {}).unwrap();
/// println!("{}", report.summary(&["cam0".into(), "cam1".into()]));
/// ```
///
/// Starts one of Aravis' fake cameras per camera of `scene.rig` (camera `c` on 127.0.0.`c+1`, each but the first
/// needing that address on the loopback), each rendering the scenario through its camera's calibration, mount and
/// clock ([`CameraRigScene::camera_state_at`]; noise seeded with `seed + c`); opens each through the protocol like a
/// real camera and runs the rig loop free on them for `options.duration_s` of their clocks (at most the scenario's),
/// told the rig `told` (clocks it leaves out are learnt). `stop` ends the run early (Ctrl-C).
pub fn run_fake_rig(
    scene: &CameraRigScene,
    told: &Rig,
    options: &LiveOptions,
    seed: u64,
    stop: Arc<AtomicBool>,
    on_estimate: &mut (dyn FnMut(&RigEstimate) + Send),
) -> Result<RigLiveReport, GenicamError> {
    let count = scene.rig.len();
    if count > MAX_FAKE_RIG_CAMERAS {
        return Err(GenicamError::Fake(format!(
            "a fake rig of {count} cameras: at most {MAX_FAKE_RIG_CAMERAS} (one loopback address each)"
        )));
    }
    let mut fakes = Vec::with_capacity(count);
    let mut cameras = Vec::with_capacity(count);
    for (c, rig_camera) in scene.rig.cameras().iter().enumerate() {
        let truth = scene.clone();
        let fake = FakeGigeCamera::start_rendering_at(
            &format!("127.0.0.{}", c + 1),
            &rig_camera.camera,
            &scene.scenario.target,
            move |t_s| truth.camera_state_at(c, t_s),
            SensorModel::default(),
            seed.wrapping_add(c as u64),
        )
        .map_err(|e| GenicamError::Fake(format!("camera '{}': {e}", rig_camera.name)))?;
        let full_size = (rig_camera.camera.width_px, rig_camera.camera.height_px);
        let camera = GenicamCamera::open(&fake_camera_options(&fake, &options.camera), full_size)?
            .with_scene_clock(fake.clock())
            .with_stop_flag(stop.clone());
        fakes.push(fake);
        cameras.push(camera);
    }
    let options = LiveOptions {
        duration_s: options.duration_s.min(scene.scenario.duration_s),
        ..options.clone()
    };
    let report = run_rig_live(
        &mut cameras,
        told,
        &scene.scenario.target,
        &options,
        false,
        on_estimate,
    );
    drop(cameras);
    for fake in &fakes {
        fake.stop();
    }
    report
}

/// ```no_run
/// use std::sync::{Arc, atomic::AtomicBool};
/// use roitrack_core::{CameraModel, Target};
/// use roitrack_estimators::rig::{CameraMount, ClockModel, Rig, RigCamera};
/// use roitrack_genicam::{GenicamOptions, LiveOptions, run_device_rig};
/// let camera = |name: &str| RigCamera::known(name, CameraModel::canonical(), CameraMount::IDENTITY, ClockModel::REFERENCE);
/// let rig = Rig::new(vec![camera("left"), camera("right")]).unwrap();
/// let addresses = ["192.168.1.20", "192.168.1.21"]
///     .map(|a| GenicamOptions { address: a.into(), ..GenicamOptions::default() });
/// let options = LiveOptions { rate_hz: 1000.0, ..LiveOptions::default() };
/// let report = run_device_rig(&rig, &addresses, &Target::grid4x4(), &options, Arc::new(AtomicBool::new(false)),
///     &mut |_| {}).unwrap();
/// println!("{}", report.summary(&["left".into(), "right".into()]));
/// ```
///
/// Opens camera `c` of `rig` at `cameras[c]` (its address, no scan; one per camera of the rig) and runs the rig loop
/// on them, each paced at `options.rate_hz` on the host's clock, for `options.duration_s`; `stop` ends it early.
pub fn run_device_rig(
    rig: &Rig,
    cameras: &[GenicamOptions],
    target: &Target,
    options: &LiveOptions,
    stop: Arc<AtomicBool>,
    on_estimate: &mut (dyn FnMut(&RigEstimate) + Send),
) -> Result<RigLiveReport, GenicamError> {
    let mut opened = Vec::with_capacity(cameras.len());
    for (camera_options, rig_camera) in cameras.iter().zip(rig.cameras()) {
        let full_size = (rig_camera.camera.width_px, rig_camera.camera.height_px);
        opened.push(GenicamCamera::open(camera_options, full_size)?.with_stop_flag(stop.clone()));
    }
    run_rig_live(&mut opened, rig, target, options, true, on_estimate)
}
