//! The default Kalman filter allocates nothing per measurement on a running track: pushing measurements of the bench
//! stream (the `kalman_update` item's input) makes no heap allocation, with no estimate due and with an estimate every
//! 10 measurements (the default period). Allocations are counted per thread, so other tests running at the same time
//! do not count.

use roitrack_bench::{KalmanStream, SEED, scene};
use roitrack_estimators::{Estimator, KalmanTuning, MotionModel};
use roitrack_testkit::alloc::{CountingAllocator, allocations_on_this_thread as allocations};

#[global_allocator]
static GLOBAL: CountingAllocator = CountingAllocator;

/// Pushes `n` measurements into `stream`; returns the allocations made and the estimates returned.
fn push(stream: &mut KalmanStream, n: usize) -> (usize, usize) {
    let mut estimates = 0;
    let before = allocations();
    for _ in 0..n {
        if stream
            .push()
            .expect("bench measurements are valid")
            .is_some()
        {
            estimates += 1;
        }
    }
    (allocations() - before, estimates)
}

#[test]
fn the_counter_counts_this_threads_allocations() {
    let before = allocations();
    let v: Vec<u8> = Vec::with_capacity(std::hint::black_box(64));
    drop(std::hint::black_box(v));
    assert_eq!(allocations(), before + 1);
}

#[test]
fn kalman_push_on_a_running_track_does_not_allocate() {
    // The bench configuration: no estimate due, only predict, update and the window.
    let mut stream = KalmanStream::new(&scene(), SEED, usize::MAX);
    let (allocated, estimates) = push(&mut stream, 1000);
    assert_eq!(estimates, 0);
    assert_eq!(
        allocated, 0,
        "allocations in 1,000 pushes without estimates"
    );
    assert_eq!(stream.estimator().report().initialisations, 1);
}

#[test]
fn kalman_push_with_estimates_does_not_allocate() {
    // The default period: an estimate (a control step, the window's conditioning) every 10 measurements.
    let mut stream = KalmanStream::new(&scene(), SEED, 10);
    let (allocated, estimates) = push(&mut stream, 1000);
    assert_eq!(estimates, 100);
    assert_eq!(
        allocated, 0,
        "allocations in 1,000 pushes with 100 estimates"
    );
    let report = stream.estimator().report();
    assert_eq!(report.initialisations, 1, "{report:?}");
}

#[test]
fn the_constant_acceleration_filter_does_not_allocate_either() {
    let tuning = KalmanTuning {
        motion_model: MotionModel::constant_acceleration(),
        ..KalmanTuning::default()
    };
    let mut stream = KalmanStream::with_tuning(&scene(), SEED, 10, tuning);
    let (allocated, estimates) = push(&mut stream, 1000);
    assert_eq!(estimates, 100);
    assert_eq!(
        allocated, 0,
        "allocations in 1,000 pushes with 100 estimates"
    );
    assert_eq!(stream.estimator().report().initialisations, 1);
}
