//! # roitrack-sim
//!
//! Ground-truth motions ([`scenario`]) and a measurement-level simulator of a camera that reads one ROI at a time
//! ([`measurements`]): every centroid is the projection of the true pose at its own exposure-midpoint time, with
//! Gaussian noise, dropped ROIs and outliers as options.

pub mod measurements;
pub mod scenario;

pub use measurements::{SimError, SimulatedRun, SimulationOptions, simulate};
pub use scenario::{Scenario, ScenarioKind, bench_rotation};
