//! Simulated cameras the real-time loop drives: one that renders each ROI it is asked for from the true motion
//! ([`SimulatedCamera`]), and a replay of ROIs rendered beforehand ([`prerendered_replay`]), for benchmarks where
//! rendering must not count. The camera trait and the replay camera themselves are roitrack-image's.

mod prerendered;
mod simulated;

pub use prerendered::prerendered_replay;
pub use simulated::SimulatedCamera;
