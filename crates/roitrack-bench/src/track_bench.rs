//! Tracking a whole recording through the library, in memory: the orthoglide scenario's simulated measurements (seed
//! 1, 0.1 px, 4 kHz, 19,655 measurements over 4.9 s) through [`track`] with the default Kalman filter and an estimate
//! every 10 measurements, every estimate collected. This is the call the Python package's `roitrack.track` makes (the
//! same tracker, the same stream, the estimates kept), so its rate is the Rust figure the Python binding is compared
//! with (`roitrack bench --json`: `track_library_meas_per_s`; `bench/python_bench.py`).
//!
//! ```
//! use roitrack_bench::track_bench::TrackLibraryBench;
//! let bench = TrackLibraryBench::orthoglide().unwrap();
//! let figures = bench.measure(1);
//! assert_eq!(figures.measurements, 19_655);
//! assert!(figures.estimates > 1_900 && figures.meas_per_s > 0.0);
//! ```

use std::hint::black_box;
use std::time::Instant;

use roitrack_core::{CameraModel, Measurement, Target};
use roitrack_estimators::{Estimate, Tracker, TrackerConfig, track};
use roitrack_sim::{Scenario, ScenarioKind, SimError, SimulationOptions, simulate};

/// The scenario's seed.
pub const SEED: u64 = 1;

/// The measurements of the orthoglide scenario, held in memory, and the tracker's inputs.
#[derive(Debug, Clone)]
pub struct TrackLibraryBench {
    /// The scenario's camera.
    pub camera: CameraModel,
    /// The scenario's target.
    pub target: Target,
    /// The simulated measurements, in time order.
    pub measurements: Vec<Measurement>,
}

/// What [`TrackLibraryBench::measure`] found.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackFigures {
    /// Measurements tracked per second of wall time, the best of the runs.
    pub meas_per_s: f64,
    /// Measurements tracked in a run.
    pub measurements: usize,
    /// Estimates a run gave.
    pub estimates: usize,
}

impl TrackLibraryBench {
    /// Simulates the orthoglide scenario (default options: seed 1, 0.1 px, 4 kHz, bit-reversed order).
    pub fn orthoglide() -> Result<Self, SimError> {
        let run = simulate(
            &Scenario::new(ScenarioKind::Orthoglide, SEED),
            &SimulationOptions::default(),
        )?;
        Ok(Self {
            camera: run.camera,
            target: run.target,
            measurements: run.measurements,
        })
    }

    /// One run: a new default tracker (Kalman, every 10) over every measurement, the estimates collected.
    pub fn run(&self) -> Vec<Estimate> {
        let mut tracker = Tracker::new(
            self.camera.clone(),
            self.target.clone(),
            TrackerConfig::default(),
        )
        .expect("the default configuration is valid");
        let mut estimates = Vec::with_capacity(self.measurements.len() / 10 + 1);
        track(
            &mut tracker,
            self.measurements.iter().map(|m| Ok::<_, ()>(*m)),
            |e: &Estimate| {
                estimates.push(*e);
                Ok::<_, ()>(())
            },
        )
        .expect("the simulated measurements are valid");
        estimates
    }

    /// The best rate over `runs` runs (at least one), building the tracker included.
    pub fn measure(&self, runs: usize) -> TrackFigures {
        let mut best_s = f64::INFINITY;
        let mut estimates = 0;
        for _ in 0..runs.max(1) {
            let start = Instant::now();
            let out = black_box(self.run());
            best_s = best_s.min(start.elapsed().as_secs_f64());
            estimates = out.len();
        }
        TrackFigures {
            meas_per_s: self.measurements.len() as f64 / best_s,
            measurements: self.measurements.len(),
            estimates,
        }
    }
}
