//! The real-time loop benchmark of `roitrack bench`: free-running on pre-rendered ROIs of the orthoglide scenario (so
//! that rendering does not count), ROI throughput with an estimate every 10 ROIs and at every ROI, and the
//! ROI-to-estimate latency with the camera paced at 20 kHz.

use roitrack_core::roi_order::bit_reversed_indices;
use roitrack_core::stats::{quantile, sorted};
use roitrack_estimators::TrackerConfig;
use roitrack_image::ReplayCamera;
use roitrack_pipeline::{LoopConfig, LoopReport, PipelineError, run_loop};
use roitrack_sim::camera::prerendered_replay;
use roitrack_sim::{Scenario, ScenarioKind};

/// The scenario time of the first ROI slot (s).
pub const START_S: f64 = 0.2;
/// Trigger rate of the latency measurement (Hz): 5x the paper, below the loop's capacity, so latencies do not include
/// queueing.
pub const PACED_HZ: f64 = 20_000.0;
/// Side of the pre-rendered ROIs (px).
pub const ROI_SIZE_PX: u32 = 32;

/// Figures of a loop configuration over its repeated runs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LoopFigures {
    /// The best throughput (ROIs per second of wall time).
    pub rois_per_s: f64,
    /// Median over the runs of each run's median ROI-to-estimate latency (µs).
    pub latency_p50_us: f64,
    /// Median over the runs of each run's 99th-percentile ROI-to-estimate latency (µs).
    pub latency_p99_us: f64,
    /// Of the best run: measurements dropped because the queue was full.
    pub dropped: usize,
    /// Of the best run: triggers sent after their slot's time (paced camera).
    pub late: usize,
    /// Of the best run: blobs the centroid rejected.
    pub rejected: usize,
}

/// Pre-rendered ROIs of the orthoglide scenario and the scene they come from.
///
/// ```
/// use roitrack_bench::loop_bench::LoopBench;
/// let bench = LoopBench::new(400).unwrap();
/// let figures = bench.measure(10, None, 1).unwrap();
/// assert!(figures.rois_per_s > 0.0 && figures.dropped == 0);
/// ```
pub struct LoopBench {
    scenario: Scenario,
    replay: ReplayCamera,
}

impl LoopBench {
    /// Renders `rois` ROIs (32 x 32, default sensor) of orthoglide in the scheduler's bit-reversed order: ROI k is
    /// exposed at slot k + 1 (slot 0 is the full frame).
    pub fn new(rois: usize) -> Result<Self, roitrack_sim::SensorError> {
        let scenario = Scenario::new(ScenarioKind::Orthoglide, 1);
        let renderer = scenario.roi_renderer()?;
        let truth = |t: f64| scenario.state_at(t);
        // Replayed at the rate of each run (4 kHz free-running, 20 kHz paced): the ROIs are stamped with the slots'
        // times, as a live camera triggered at that rate would stamp them.
        let replay = prerendered_replay(
            &renderer,
            &truth,
            &bit_reversed_indices(scenario.target.len()),
            ROI_SIZE_PX,
            START_S + 1.0 / 4000.0,
            4000.0,
            rois,
            1,
        )
        .with_trigger_times();
        Ok(Self { scenario, replay })
    }

    /// ROIs per run.
    pub fn rois(&self) -> usize {
        self.replay.len()
    }

    /// Runs the loop `repeats` times (at least once) with an estimate every `every` ROIs; `paced_hz` paces the camera
    /// at that trigger rate, otherwise it runs free.
    pub fn measure(
        &self,
        every: usize,
        paced_hz: Option<f64>,
        repeats: usize,
    ) -> Result<LoopFigures, PipelineError> {
        let mut best: Option<LoopReport> = None;
        let mut p50s = Vec::new();
        let mut p99s = Vec::new();
        for _ in 0..repeats.max(1) {
            let config = LoopConfig {
                roi_slots: self.replay.len() + 1,
                t_start_s: START_S,
                full_frame_slots: 1,
                paced: paced_hz.is_some(),
                rate_hz: paced_hz.unwrap_or(4000.0),
                ..LoopConfig::default()
            };
            let tracker = TrackerConfig {
                every,
                ..TrackerConfig::default()
            };
            let mut camera = self.replay.clone();
            camera.rewind();
            let report = run_loop(
                &mut camera,
                &self.scenario.camera,
                &self.scenario.target,
                tracker,
                &config,
            )?;
            p50s.push(report.latency_quantile_us(0.5));
            p99s.push(report.latency_quantile_us(0.99));
            if best
                .as_ref()
                .is_none_or(|b| report.rois_per_s() > b.rois_per_s())
            {
                best = Some(report);
            }
        }
        let best = best.expect("at least one run");
        Ok(LoopFigures {
            rois_per_s: best.rois_per_s(),
            latency_p50_us: quantile(&sorted(&p50s), 0.5),
            latency_p99_us: quantile(&sorted(&p99s), 0.5),
            dropped: best.acquisition.dropped,
            late: best.acquisition.late,
            rejected: best.acquisition.rejections.total(),
        })
    }
}
