//! The loop's camera: the ROI camera with its scheduler and tracker, or the frame camera with its frame tracker.

use nalgebra::Vector3;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use roitrack_core::time::TimeModel;
use roitrack_core::{MotionState, Target};
use roitrack_estimators::{Estimate, Estimator, Tracker};
use roitrack_image::{CentroidOptions, Frame, RoiImage, measure_roi};
use roitrack_pipeline::{
    FrameTracker, FrameTrackerConfig, Predictor, RoiScheduler, SchedulerConfig,
};
use roitrack_sim::{RenderScratch, RoiRenderer, SensorModel};

use super::{CameraKind, ServoConfig, ServoError};

/// The camera side of a run.
pub(super) enum CameraSide {
    Truth,
    Roi(Box<RoiSide>),
    Frames(Box<FrameSide>),
}

pub(super) struct RoiSide {
    renderer: RoiRenderer,
    scheduler: RoiScheduler,
    tracker: Tracker,
    predictor: Predictor,
    centroid: CentroidOptions,
    time: TimeModel,
    image: RoiImage,
    scratch: RenderScratch,
    rng: ChaCha8Rng,
    extra_noise: Option<rand_distr::Normal<f64>>,
}

pub(super) struct FrameSide {
    renderer: RoiRenderer,
    tracker: FrameTracker,
    frame: Frame,
    scratch: RenderScratch,
    rng: ChaCha8Rng,
    rate_hz: f64,
    exposure_s: f64,
    next_frame: usize,
}

impl CameraSide {
    pub(super) fn new(config: &ServoConfig) -> Result<Self, ServoError> {
        let target = Target::grid4x4();
        let timing = config.camera_timing();
        let (rotation, home) = config.path.home_in_camera();
        let rng = ChaCha8Rng::seed_from_u64(config.seed);
        let Some(camera) = config.camera_model() else {
            return Ok(Self::Truth);
        };
        match config.camera {
            CameraKind::Truth => Ok(Self::Truth),
            CameraKind::Roi => {
                let renderer =
                    RoiRenderer::new(camera.clone(), target.clone(), SensorModel::default())?;
                let scheduler = RoiScheduler::new(
                    camera.clone(),
                    target.clone(),
                    SchedulerConfig::default(),
                    config.tracker.noise_px,
                );
                let tracker = Tracker::new(camera.clone(), target, config.tracker)
                    .map_err(|e| ServoError::Tracker(e.to_string()))?;
                Ok(Self::Roi(Box::new(RoiSide {
                    renderer,
                    scheduler,
                    tracker,
                    // The robot starts at rest at home, where the first ROIs are placed.
                    predictor: Predictor {
                        t_ref_s: 0.0,
                        state: MotionState::at_rest(rotation, home),
                        covariance: None,
                    },
                    centroid: CentroidOptions::default(),
                    time: camera.time,
                    image: RoiImage::default(),
                    scratch: RenderScratch::new(),
                    rng,
                    extra_noise: (config.extra_centroid_noise_px > 0.0)
                        .then(|| rand_distr::Normal::new(0.0, config.extra_centroid_noise_px))
                        .transpose()
                        .map_err(|_| ServoError::Invalid {
                            field: "extra_centroid_noise_px",
                            value: config.extra_centroid_noise_px,
                        })?,
                })))
            }
            CameraKind::Frames120 | CameraKind::Frames30 => {
                let renderer =
                    RoiRenderer::new(camera.clone(), target.clone(), SensorModel::default())?;
                let frame_config = FrameTrackerConfig {
                    tracker: FrameTrackerConfig::frame_estimator(config.tracker, None, None),
                    ..FrameTrackerConfig::default()
                };
                let tracker = FrameTracker::new(camera, target, frame_config)
                    .map_err(|e| ServoError::Tracker(e.to_string()))?;
                Ok(Self::Frames(Box::new(FrameSide {
                    renderer,
                    tracker,
                    frame: Frame::default(),
                    scratch: RenderScratch::new(),
                    rng,
                    rate_hz: timing.rate_hz,
                    exposure_s: timing.exposure_s,
                    next_frame: 0,
                })))
            }
        }
    }

    /// Tells the tracker the target's acceleration (camera frame) from `t_s` on, as the controller believes it
    /// (ROI camera only: the frame tracker predicts with its own motion model).
    pub(super) fn tell_acceleration(
        &mut self,
        t_s: f64,
        linear_mps2: &Vector3<f64>,
    ) -> Result<(), ServoError> {
        if let Self::Roi(side) = self {
            let known = roitrack_core::Acceleration {
                linear_mps2: *linear_mps2,
                angular_radps2: Vector3::zeros(),
            };
            side.tracker
                .set_known_acceleration(t_s, known)
                .map_err(|e| ServoError::Tracker(e.to_string()))?;
        }
        Ok(())
    }

    /// Exposes what is due by `t_now_s` (the robot's motion is known up to it): the ROI of the tick `t_tick_s`, or the
    /// frames whose exposure has ended. Returns the estimates made.
    pub(super) fn expose(
        &mut self,
        t_tick_s: f64,
        t_now_s: f64,
        state_at: &impl Fn(f64) -> MotionState,
        out: &mut Vec<Estimate>,
    ) -> Result<(), ServoError> {
        match self {
            Self::Truth => Ok(()),
            Self::Roi(side) => {
                let Some(request) = side.scheduler.next(&side.predictor, t_tick_s) else {
                    return Ok(());
                };
                let point_id = side.tracker.target().points()[request.point_index].id;
                let bit_depth = side.renderer.sensor().bit_depth as u8;
                side.image.set(t_tick_s, point_id, request.roi, bit_depth);
                side.renderer.render_readout(
                    state_at,
                    &request.roi,
                    t_tick_s,
                    &mut side.rng,
                    &mut side.scratch,
                    &mut side.image.pixels,
                );
                let mut measured = measure_roi(&side.image, &side.centroid, &side.time);
                side.scheduler.report(request.point_index, measured.is_ok());
                if let (Ok(m), Some(noise)) = (&mut measured, &side.extra_noise) {
                    use rand_distr::Distribution as _;
                    m.u_px += noise.sample(&mut side.rng);
                    m.v_px += noise.sample(&mut side.rng);
                }
                if let Ok(measurement) = measured
                    && let Some(estimate) = side.tracker.push(&measurement)?
                {
                    if estimate.status.is_vouched_for() {
                        side.predictor = Predictor {
                            t_ref_s: estimate.t_ref_s,
                            state: estimate.state,
                            covariance: estimate.covariance,
                        };
                    }
                    out.push(estimate);
                }
                Ok(())
            }
            Self::Frames(side) => loop {
                let t_frame = side.next_frame as f64 / side.rate_hz;
                if t_frame + side.exposure_s / 2.0 > t_now_s {
                    return Ok(());
                }
                side.next_frame += 1;
                side.renderer.render_frame(
                    state_at,
                    t_frame,
                    &mut side.rng,
                    &mut side.scratch,
                    &mut side.frame,
                );
                let outcome = side.tracker.process(&side.frame)?;
                if let Some(estimate) = outcome.estimate {
                    out.push(estimate);
                }
            },
        }
    }
}
