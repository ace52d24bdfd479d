//! The tracker's steady state allocates nothing: every estimator, once initialised, pushes measurements and emits
//! estimates without touching the heap (counted through a counting global allocator).

use roitrack_core::JacobianKind;
use roitrack_estimators::{Estimator, EstimatorConfig, Tracker, TrackerConfig, VvsSettings};
use roitrack_sim::{Scenario, ScenarioKind, SimulationOptions, simulate};
use roitrack_testkit::alloc::{CountingAllocator, allocations_in_all_threads as allocations};

#[global_allocator]
static GLOBAL: CountingAllocator = CountingAllocator;

#[test]
fn steady_state_tracking_does_not_allocate() {
    let scenario = Scenario::new(ScenarioKind::Orthoglide, 1);
    let data = simulate(&scenario, &SimulationOptions::default()).unwrap();
    let base = TrackerConfig::default();
    for (name, config) in [
        ("kalman", base),
        (
            "vvs-paper",
            TrackerConfig {
                estimator: EstimatorConfig::Vvs(VvsSettings {
                    jacobian: JacobianKind::Paper,
                    ..VvsSettings::default()
                }),
                ..base
            },
        ),
        (
            "vvs-exact-gn",
            TrackerConfig {
                estimator: EstimatorConfig::Vvs(VvsSettings {
                    iterations: 3,
                    ..VvsSettings::default()
                }),
                ..base
            },
        ),
        (
            "batch",
            TrackerConfig {
                estimator: EstimatorConfig::Batch,
                ..base
            },
        ),
        (
            "static",
            TrackerConfig {
                estimator: EstimatorConfig::Static,
                ..base
            },
        ),
    ] {
        let mut tracker = Tracker::new(data.camera.clone(), data.target.clone(), config).unwrap();
        let (warm_up, steady) = data.measurements.split_at(200);
        for m in warm_up {
            tracker.push(m).unwrap();
        }
        assert!(
            tracker.state().is_some(),
            "{name}: initialised during warm-up"
        );
        let before = allocations();
        let mut estimates = 0;
        for m in steady {
            if tracker.push(m).unwrap().is_some() {
                estimates += 1;
            }
        }
        let allocations = allocations() - before;
        assert!(estimates > 1900, "{name}: {estimates} estimates");
        assert_eq!(
            allocations,
            0,
            "{name}: {allocations} allocations over {} measurements",
            steady.len()
        );
    }
}
