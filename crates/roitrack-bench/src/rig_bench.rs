//! Fusing several asynchronous cameras, in memory: a random rig of ROI cameras around the random scenario (each at
//! 4 kHz, 0.1 px, every clock but the first unknown: `roitrack simulate --scenario random --rig-cameras N`), every
//! measurement pushed to one [`RigTracker`] in the order of the cameras' own clocks, as `track --rig` does once it
//! has read its files. The rate counts every measurement of every camera on one thread; it is given over the whole
//! run and over the running part alone (the measurements from [`RUNNING_AFTER_S`] on, by the cameras' own clocks:
//! every camera's own track has started and its clock has been found by then), since the start's search for a pose
//! and for the clocks is paid once per track (`roitrack lab bench --json`: `rig4_meas_per_s`, `rig4_running_meas_per_s`).
//!
//! ```
//! use roitrack_bench::rig_bench::RigBench;
//! let bench = RigBench::random(2, 1, 1.3).unwrap();
//! let figures = bench.measure(1);
//! assert_eq!(figures.measurements, bench.measurements.len());
//! assert!(figures.running_measurements > 0 && figures.running_meas_per_s > 0.0 && figures.estimates > 0);
//! ```

use std::hint::black_box;
use std::time::{Duration, Instant};

use roitrack_core::Target;
use roitrack_estimators::rig::{Rig, RigMeasurement, RigTracker, RigTrackerConfig};
use roitrack_sim::multi_camera::{CameraRigScene, simulate_rig};
use roitrack_sim::{Scenario, ScenarioKind, SimError};

/// Each camera's ROI rate (Hz).
pub const ROI_RATE_HZ: f64 = 4000.0;
/// The centroids' noise (px per axis).
pub const NOISE_PX: f64 = 0.1;
/// Where the running part starts, on each camera's own clock (s).
pub const RUNNING_AFTER_S: f64 = 1.0;

/// A simulated rig's measurements, held in memory and merged, and the rig the tracker is told.
#[derive(Debug, Clone)]
pub struct RigBench {
    /// The rig as the tracker is told it: the first camera's clock known, the others to be learnt.
    pub rig: Rig,
    /// The scenario's target.
    pub target: Target,
    /// Every camera's measurements in the order of their own clocks' times.
    pub measurements: Vec<RigMeasurement>,
    /// Index of the first measurement of the running part.
    pub running_from: usize,
}

/// What [`RigBench::measure`] found (the best of the runs, building the tracker included).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RigFigures {
    /// Measurements fused per second of wall time over the whole run.
    pub meas_per_s: f64,
    /// The same over the running part alone.
    pub running_meas_per_s: f64,
    /// Measurements of a run, of every camera.
    pub measurements: usize,
    /// Of them, in the running part.
    pub running_measurements: usize,
    /// Fused estimates a run gave.
    pub estimates: usize,
}

impl RigBench {
    /// The random scenario of `duration_s` seen by `cameras` cameras drawn from `seed` (the scenario's seed too).
    pub fn random(cameras: usize, seed: u64, duration_s: f64) -> Result<Self, SimError> {
        let scenario = Scenario::new(ScenarioKind::Random, seed).with_duration_s(duration_s);
        let scene = CameraRigScene::random(scenario, cameras, seed);
        let run = simulate_rig(&scene, ROI_RATE_HZ, NOISE_PX, seed)?;
        let measurements = run.merged_by_own_clocks();
        let running_from = measurements.partition_point(|m| m.measurement.t_s < RUNNING_AFTER_S);
        Ok(Self {
            rig: scene.rig_with_clocks_unknown(),
            target: scene.scenario.target.clone(),
            measurements,
            running_from,
        })
    }

    /// The rig of 4 cameras of the figures (`rig4_*`): seed 2 (the one `roitrack simulate --scenario random --seed 2
    /// --rig-cameras 4` writes), the scenario's 4 s.
    pub fn four_cameras() -> Result<Self, SimError> {
        Self::random(4, 2, Scenario::new(ScenarioKind::Random, 2).duration_s)
    }

    /// One run: a new tracker (default settings) over every measurement; the fused estimates, and the wall time of
    /// the start and of the running part.
    pub fn run(&self) -> (usize, Duration, Duration) {
        let mut tracker = RigTracker::new(
            self.rig.clone(),
            self.target.clone(),
            RigTrackerConfig::default(),
        )
        .expect("the simulated rig is valid");
        let mut estimates = 0;
        let mut push = |m: &RigMeasurement| {
            estimates += black_box(
                tracker
                    .push(m)
                    .expect("the simulated measurements are valid"),
            )
            .len();
        };
        let start = Instant::now();
        self.measurements[..self.running_from]
            .iter()
            .for_each(&mut push);
        let started = start.elapsed();
        let running = Instant::now();
        self.measurements[self.running_from..]
            .iter()
            .for_each(&mut push);
        estimates += black_box(tracker.finish()).len();
        (estimates, started, running.elapsed())
    }

    /// The best rates over `runs` runs (at least one).
    pub fn measure(&self, runs: usize) -> RigFigures {
        let (mut best_s, mut best_running_s, mut estimates) = (f64::INFINITY, f64::INFINITY, 0);
        for _ in 0..runs.max(1) {
            let (count, start, running) = self.run();
            best_s = best_s.min((start + running).as_secs_f64());
            best_running_s = best_running_s.min(running.as_secs_f64());
            estimates = count;
        }
        let running_measurements = self.measurements.len() - self.running_from;
        RigFigures {
            meas_per_s: self.measurements.len() as f64 / best_s,
            running_meas_per_s: running_measurements as f64 / best_running_s,
            measurements: self.measurements.len(),
            running_measurements,
            estimates,
        }
    }
}
