//! # roitrack-demo
//!
//! The main job end to end from pixels, on a simulated scenario (`roitrack demo`): a simulated ROI camera renders each
//! ROI the scheduler asks for, the acquisition thread centroids it and the estimation thread tracks it, joined by
//! lock-free queues; the target is found in a first full frame with no prior. The same scenario is also tracked from
//! ideal centroids with the image side's measured noise, to show what the image side costs.
//!
//! [`Demo::new`] simulates the scenario and measures the centroid noise; [`Demo::from_images`] and
//! [`Demo::from_centroids`] run one estimator each way. The caller writes the files and shows the progress. Every
//! run is tracked and scored against its truth by [`scoring`], which the studies of `roitrack-experiments` share.
#![deny(missing_docs)]

use std::sync::atomic::AtomicUsize;

use roitrack_core::JacobianKind;
use roitrack_core::Measurement;
use roitrack_estimators::{
    Estimate, EstimatorConfig, KalmanTuning, TrackStatus, TrackerConfig, VvsSettings,
};
use roitrack_image::camera::ObservedCamera;
use roitrack_image::{CentroidOptions, RoiImage, measure_roi};
use roitrack_pipeline::{LoopConfig, LoopReport, ScheduleOrder, run_loop_with_sink};
use roitrack_plot::{TrackSeries, TruthSeries};
use roitrack_sim::{
    CentroidAccuracy, RoiRenderer, Scenario, ScenarioKind, SimulatedCamera, SimulatedRun,
    SimulationOptions, centroid_accuracy, simulate,
};
use thiserror::Error;

/// What [`Demo::from_images_observed`] hands each ROI the camera grabs: the image, and the centroid the loop measures
/// in it (`None`: its blob was rejected).
pub type RoiObserver<'a> = dyn FnMut(&RoiImage, Option<&Measurement>) + Send + 'a;
pub mod scoring;

use scoring::{Scored, score, track_and_score};

/// ROIs rendered to measure the image side's centroid noise, and their side (px).
const ACCURACY_ROIS: usize = 2000;
const ACCURACY_ROI_SIZE_PX: u32 = 32;

/// An estimator of the demo: its label, the stem of its files, and its configuration.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DemoEstimator {
    /// Its name in the tables (`kalman (default)`).
    pub label: &'static str,
    /// The stem of its files (`kalman` for `kalman_poses.tum`).
    pub stem: &'static str,
    /// Its configuration.
    pub estimator: EstimatorConfig,
}

/// The estimators the demo compares: the default Kalman filter, the paper's loop (gain 0.5) and the static baseline.
pub fn lineup() -> [DemoEstimator; 3] {
    [
        DemoEstimator {
            label: "kalman (default)",
            stem: "kalman",
            estimator: EstimatorConfig::Kalman(KalmanTuning::default()),
        },
        DemoEstimator {
            label: "paper, gain 0.5",
            stem: "paper",
            estimator: EstimatorConfig::Vvs(VvsSettings {
                jacobian: JacobianKind::Paper,
                gain: 0.5,
                iterations: 1,
            }),
        },
        DemoEstimator {
            label: "static baseline",
            stem: "static",
            estimator: EstimatorConfig::Static,
        },
    ]
}

/// Where a run's measurements came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Source {
    /// Rendered ROIs through the two-thread loop.
    Images,
    /// Ideal centroids with the image side's noise.
    Centroids,
}

impl Source {
    /// Its name in the tables and the JSON lines.
    pub fn name(&self) -> &'static str {
        match self {
            Self::Images => "images",
            Self::Centroids => "centroids",
        }
    }
}

/// One estimator's run, scored.
#[derive(Debug, Clone)]
pub struct DemoRun {
    /// The estimator that ran.
    pub estimator: DemoEstimator,
    /// What it was fed.
    pub source: Source,
    /// Its estimates and their errors.
    pub scored: Scored,
    /// What the loop did, for a run from images.
    pub loop_report: Option<LoopReport>,
}

impl DemoRun {
    /// The loop's counts and latencies, for the table (empty for a run from centroids).
    pub fn loop_notes(&self) -> String {
        let Some(r) = &self.loop_report else {
            return String::new();
        };
        format!(
            "{} ROIs, {} rejected, {} dropped, {} init, latency p50/p99 {:.0}/{:.0} us",
            r.acquisition.rois,
            r.acquisition.rejections.total(),
            r.acquisition.dropped,
            r.acquisition.initialisations,
            r.latency_quantile_us(0.5),
            r.latency_quantile_us(0.99)
        )
    }

    /// The run as a series of the figures.
    pub fn track_series(&self) -> TrackSeries {
        TrackSeries::from_estimates(
            self.estimator.label,
            &self.scored.estimates,
            &self.scored.errors,
            self.scored.metrics.clone(),
        )
    }
}

/// Options of the demo.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DemoOptions {
    /// The simulated motion.
    pub scenario: ScenarioKind,
    /// Seed of the simulation (motion, pixel noise).
    pub seed: u64,
    /// Pace the camera at the ROI rate (real time) instead of running free.
    pub paced: bool,
    /// The order in which the scheduler reads the points.
    pub order: ScheduleOrder,
}

impl Default for DemoOptions {
    fn default() -> Self {
        Self {
            scenario: ScenarioKind::Orthoglide,
            seed: 1,
            paced: false,
            order: ScheduleOrder::BitReversed,
        }
    }
}

/// A prepared demo: the scenario simulated with the image side's measured centroid noise.
///
/// ```
/// use roitrack_demo::{Demo, DemoOptions, lineup, table};
/// use roitrack_sim::ScenarioKind;
///
/// let demo = Demo::new(DemoOptions { scenario: ScenarioKind::Static, ..DemoOptions::default() }).unwrap();
/// let kalman = &lineup()[0];
/// let runs = [demo.from_images(kalman, None).unwrap(), demo.from_centroids(kalman).unwrap()];
/// // A still target seen through rendered ROIs: sub-millimetre from the first full frame on.
/// assert!(runs[0].scored.metrics.position_rmse_mm < 0.2, "{}", table(&runs));
/// ```
#[derive(Debug, Clone)]
pub struct Demo {
    /// The options it was made with.
    pub options: DemoOptions,
    /// The scenario simulated (camera, target, motion).
    pub scenario: Scenario,
    /// The simulation's options (rates, noise).
    pub simulation: SimulationOptions,
    /// The ideal-centroid run with its ground truth (also the truth of the image runs).
    pub run: SimulatedRun,
    /// The centroid error of the image side on rendered ROIs.
    pub accuracy: CentroidAccuracy,
    renderer: RoiRenderer,
}

impl Demo {
    /// Simulates the scenario; the ideal centroids get the image side's noise, measured on rendered ROIs, so that the
    /// two runs of an estimator compare the image side with a perfect one of equal precision.
    pub fn new(options: DemoOptions) -> Result<Self, DemoError> {
        Self::with_scenario(options, Scenario::new(options.scenario, options.seed))
    }

    /// [`Self::new`] on a scenario of one's own (another camera, target, distance or speed: see
    /// [`Scenario::with_camera`] and the others); `options.scenario` is then only its name.
    pub fn with_scenario(options: DemoOptions, scenario: Scenario) -> Result<Self, DemoError> {
        let (renderer, accuracy) = image_side(&scenario, ACCURACY_ROIS, options.seed)?;
        let simulation = SimulationOptions {
            seed: options.seed,
            noise_px: image_noise_px(&accuracy),
            ..SimulationOptions::default()
        };
        let run = simulate(&scenario, &simulation)?;
        Ok(Self {
            options,
            scenario,
            simulation,
            run,
            accuracy,
            renderer,
        })
    }

    /// ROI slots of a loop run (one per ROI time of the scenario).
    pub fn slots(&self) -> usize {
        self.run.truth_poses.len()
    }

    /// The tracker configuration of an estimator: told the image side's noise.
    pub fn config(&self, estimator: &DemoEstimator) -> TrackerConfig {
        TrackerConfig {
            estimator: estimator.estimator,
            noise_px: self.simulation.noise_px,
            ..TrackerConfig::default()
        }
    }

    /// Runs `estimator` from rendered ROIs through the two-thread loop, publishing the ROI slots done to `progress`.
    pub fn from_images(
        &self,
        estimator: &DemoEstimator,
        progress: Option<&AtomicUsize>,
    ) -> Result<DemoRun, DemoError> {
        self.from_images_with(estimator, progress, &mut |_| {})
    }

    /// [`from_images`](Self::from_images), handing each estimate to `on_estimate` as the loop makes it (a live
    /// view); it must not block.
    pub fn from_images_with(
        &self,
        estimator: &DemoEstimator,
        progress: Option<&AtomicUsize>,
        on_estimate: &mut (dyn FnMut(&Estimate) + Send),
    ) -> Result<DemoRun, DemoError> {
        self.from_images_observed(estimator, progress, on_estimate, None)
    }

    /// [`from_images_with`](Self::from_images_with), also handing every ROI the camera grabs to `on_roi`, with the
    /// centroid the loop measures in it (the same options and time model: `None` for a rejected blob), on the
    /// camera's thread as it is grabbed (the ROI images of `demo --mcap --mcap-rois`).
    pub fn from_images_observed(
        &self,
        estimator: &DemoEstimator,
        progress: Option<&AtomicUsize>,
        on_estimate: &mut (dyn FnMut(&Estimate) + Send),
        on_roi: Option<&mut RoiObserver<'_>>,
    ) -> Result<DemoRun, DemoError> {
        let config = self.config(estimator);
        let camera = SimulatedCamera::new(
            self.renderer.clone(),
            {
                let s = self.scenario.clone();
                move |t: f64| s.state_at(t)
            },
            self.options.seed,
        );
        let mut loop_config = LoopConfig {
            rate_hz: self.simulation.rate_hz,
            paced: self.options.paced,
            roi_slots: self.slots(),
            // The measurements go to the run's ROS 2 bag (`demo --mcap`).
            keep_measurements: true,
            ..LoopConfig::default()
        };
        loop_config.scheduler.order = self.options.order;
        let report = match on_roi {
            None => run_loop_with_sink(
                &mut { camera },
                &self.scenario.camera,
                &self.scenario.target,
                config,
                &loop_config,
                progress,
                on_estimate,
            )?,
            Some(on_roi) => {
                let (centroid, time) = (loop_config.centroid, self.scenario.camera.time);
                let mut observed = ObservedCamera::new(camera, |image: &RoiImage| {
                    let measured = measure_roi(image, &centroid, &time).ok();
                    on_roi(image, measured.as_ref());
                });
                run_loop_with_sink(
                    &mut observed,
                    &self.scenario.camera,
                    &self.scenario.target,
                    config,
                    &loop_config,
                    progress,
                    on_estimate,
                )?
            }
        };
        if report.estimates.is_empty() {
            return Err(DemoError::NeverStarted {
                attempts: report.acquisition.failed_initialisations,
            });
        }
        let scored = score(&self.run, report.estimates.clone(), report.wall_s)?;
        Ok(DemoRun {
            estimator: *estimator,
            source: Source::Images,
            scored,
            loop_report: Some(report),
        })
    }

    /// Runs `estimator` on the ideal centroids.
    pub fn from_centroids(&self, estimator: &DemoEstimator) -> Result<DemoRun, DemoError> {
        Ok(DemoRun {
            estimator: *estimator,
            source: Source::Centroids,
            scored: track_and_score(&self.run, self.config(estimator))?,
            loop_report: None,
        })
    }

    /// The true motion, for the figures.
    pub fn truth_series(&self) -> TruthSeries {
        TruthSeries {
            t_s: self.run.truth_poses.iter().map(|p| p.t_s).collect(),
            position_m: self
                .run
                .truth_poses
                .iter()
                .map(|p| p.cam_from_obj.translation.vector.into())
                .collect(),
            velocity_mps: self
                .run
                .truth_twists
                .iter()
                .map(|w| w.velocity_mps.into())
                .collect(),
        }
    }
}

/// The simulated camera of a scenario (default sensor) and the accuracy of the default centroid on `rois` of its
/// rendered 32 x 32 ROIs.
pub fn image_side(
    scenario: &Scenario,
    rois: usize,
    seed: u64,
) -> Result<(RoiRenderer, CentroidAccuracy), DemoError> {
    let renderer = scenario.roi_renderer()?;
    let accuracy = centroid_accuracy(
        &renderer,
        &CentroidOptions::default(),
        ACCURACY_ROI_SIZE_PX,
        rois,
        seed,
    );
    Ok((renderer, accuracy))
}

/// The centroid noise (px per axis) the trackers are told for rendered ROIs: the measured spread, at least 0.005 px.
pub fn image_noise_px(accuracy: &CentroidAccuracy) -> f64 {
    (0.5 * (accuracy.std_u_px.powi(2) + accuracy.std_v_px.powi(2)))
        .sqrt()
        .max(0.005)
}

/// The runs as a table with a header line.
pub fn table(runs: &[DemoRun]) -> String {
    let mut out = format!(
        "{:<18} {:<9} {:>8} {:>15} {:>8} {:>9} {:>9} {:>12} {:>5} {:>8}  {}\n",
        "estimator",
        "from",
        "pos mm",
        "pos x/y mm",
        "rot deg",
        "vel mm/s",
        "w deg/s",
        "lag smp(ms)",
        "degen",
        "us/step",
        "loop"
    );
    for r in runs {
        let m = &r.scored.metrics;
        out += &format!(
            "{:<18} {:<9} {:>8.4} {:>7.4}/{:<7.4} {:>8.4} {:>9.2} {:>9.2} {:>5} ({:>4.1}) {:>5} {:>8.2}  {}\n",
            r.estimator.label,
            r.source.name(),
            m.position_rmse_mm,
            m.position_rmse_xyz_mm[0],
            m.position_rmse_xyz_mm[1],
            m.rotation_rmse_deg,
            m.velocity_rmse_mm_s.unwrap_or(f64::NAN),
            m.angular_velocity_rmse_deg_s.unwrap_or(f64::NAN),
            m.velocity_lag_samples.unwrap_or(0),
            m.velocity_lag_ms.unwrap_or(f64::NAN),
            r.scored.count(TrackStatus::Degenerate),
            r.scored.us_per_estimate(),
            r.loop_notes()
        );
    }
    out
}

/// One run as a JSON object: label, source, time per step and metrics.
pub fn json(run: &DemoRun) -> String {
    format!(
        "{{\"estimator\":\"{}\",\"source\":\"{}\",\"us_per_estimate\":{},\"metrics\":{}}}",
        run.estimator.label,
        run.source.name(),
        run.scored.us_per_estimate(),
        run.scored.metrics.to_json()
    )
}

/// Why the demo (or a run scored against its truth) could not run.
#[derive(Debug, Error)]
pub enum DemoError {
    /// The scenario could not be simulated.
    #[error("simulation failed: {0}")]
    Simulation(#[from] roitrack_sim::SimError),
    /// The ROIs or frames could not be rendered.
    #[error("rendering failed: {0}")]
    Rendering(#[from] roitrack_sim::RenderError),
    /// The sensor model is invalid.
    #[error("invalid sensor model: {0}")]
    Sensor(#[from] roitrack_sim::SensorError),
    /// The estimator refused the run.
    #[error("tracking failed: {0}")]
    Tracking(#[from] roitrack_estimators::TrackAllError),
    /// The real-time loop failed.
    #[error("the real-time loop failed: {0}")]
    Loop(#[from] roitrack_pipeline::PipelineError),
    /// The estimates could not be scored against the truth.
    #[error("evaluation failed: {0}")]
    Evaluation(#[from] roitrack_eval::EvalError),
    /// The real-time loop ran but never started a track.
    #[error(
        "the real-time loop made no estimate: the target was never identified in a full frame ({attempts} \
         attempts; a target whose views are ambiguous, such as a plain symmetric grid, needs a marked point, e.g. one \
         larger blob, for the loop to start)"
    )]
    NeverStarted {
        /// The full-frame identifications tried.
        attempts: usize,
    },
}
