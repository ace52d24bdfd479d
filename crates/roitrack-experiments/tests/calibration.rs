//! The default filter's covariance means what it says where it was hardest to get right: random 6-dof motion at
//! 1 px of noise, whose sustained accelerations in depth (13 m/s² for 50-80 ms) the filter follows with a lag. With a
//! trend of the corrections fixed at two cycles, the process noise wandered down during them and the estimates fell
//! 6-9 mm behind while claiming 1.7 mm: 94.6 % of the positions and 94.9 % of the velocities inside their 99 % bound
//! on seed 1, 94.7 % of the velocities on seed 2. Each seed is checked on its own (pooled, one could hide the other).

use roitrack_experiments::adaptive::{Goal, SweepOptions, sweep};

#[test]
fn random_motion_at_1_px_is_calibrated_on_several_seeds() {
    let mut options = SweepOptions::full();
    options.cases.retain(|c| c.name == "random, 1 px");
    assert_eq!(options.cases.len(), 1, "the calibration case exists");
    for seed in [1, 2, 3] {
        let result = sweep(&options.clone().with_seeds(&[seed]), None).unwrap();
        let case = &result.cases[0];
        let c = &case.default.consistency;
        assert!(c.count > 1000, "seed {seed}: {c:?}");
        assert!(case.holds(Goal::Calibrated), "seed {seed}: {c:?}");
    }
}
