//! The estimate handle: no torn read under a publishing thread, newest-first, and no allocation to publish or read.

use std::sync::atomic::{AtomicBool, Ordering};

use nalgebra::Vector3;
use roitrack_core::MotionState;
use roitrack_estimators::{Estimate, Matrix12, TrackStatus};
use roitrack_servo::handle::estimate_channel;
use roitrack_testkit::alloc::{CountingAllocator, allocations_on_this_thread};

#[global_allocator]
static GLOBAL: CountingAllocator = CountingAllocator;

/// An estimate every field of which is a function of `k`: a torn read mixes two `k`s.
fn estimate(k: u64) -> Estimate {
    let x = k as f64;
    let mut state = MotionState::bench();
    state.cam_t_obj_m = Vector3::new(x, x + 1.0, x + 2.0);
    state.velocity_mps = Vector3::repeat(-x);
    state.angular_velocity_radps = Vector3::repeat(2.0 * x);
    Estimate {
        t_ref_s: x,
        state,
        residual_rms_px: 0.0,
        inverse_condition: 1.0,
        measurements_used: 16,
        iterations: 1,
        status: TrackStatus::Tracking,
        covariance: Some(Matrix12::from_fn(|i, j| {
            x + (i.min(j) * 12 + i.max(j)) as f64
        })),
        noise_px: 0.1,
        acceleration: None,
    }
}

#[test]
fn reads_under_a_publishing_thread_are_never_torn_and_never_go_back() {
    let (mut publisher, reader) = estimate_channel();
    let done = AtomicBool::new(false);
    std::thread::scope(|scope| {
        scope.spawn(|| {
            for k in 1..=200_000u64 {
                publisher.publish(&estimate(k));
            }
            done.store(true, Ordering::Release);
        });
        for _ in 0..2 {
            let reader = reader.clone();
            let done = &done;
            scope.spawn(move || {
                let (mut last, mut reads) = (0.0, 0u64);
                while !done.load(Ordering::Acquire) || reads < 1000 {
                    let Some(s) = reader.read() else { continue };
                    reads += 1;
                    let k = s.t_ref_s;
                    let expected = estimate(k as u64);
                    assert_eq!(
                        s.state.cam_t_obj_m, expected.state.cam_t_obj_m,
                        "torn at {k}"
                    );
                    assert_eq!(
                        s.state.velocity_mps, expected.state.velocity_mps,
                        "torn at {k}"
                    );
                    assert_eq!(
                        s.state.angular_velocity_radps, expected.state.angular_velocity_radps,
                        "torn at {k}"
                    );
                    assert_eq!(s.covariance, expected.covariance, "torn at {k}");
                    assert_eq!(s.sequence, k as u64, "sequence at {k}");
                    assert!(k >= last, "went back from {last} to {k}");
                    last = k;
                }
            });
        }
    });
    assert_eq!(reader.read().unwrap().t_ref_s, 200_000.0);
}

#[test]
fn publishing_reading_and_predicting_allocate_nothing() {
    let (mut publisher, reader) = estimate_channel();
    let e = estimate(7);
    let before = allocations_on_this_thread();
    for k in 0..1000 {
        publisher.publish(&e);
        let (t_ref, state, covariance) = reader.predicted_to(7.0 + k as f64 * 1e-4).unwrap();
        assert_eq!(t_ref, 7.0);
        assert!(state.is_finite() && covariance.is_some());
    }
    assert_eq!(allocations_on_this_thread(), before);
}

/// The prediction is the estimate's own: `Estimate::state_at` and `F P Fᵀ`.
#[test]
fn the_prediction_is_the_estimates_own() {
    let (mut publisher, reader) = estimate_channel();
    let e = estimate(3);
    publisher.publish(&e);
    let (_, state, covariance) = reader.predicted_to(3.004).unwrap();
    let expected = e.state_at(0.004);
    assert!((state.cam_t_obj_m - expected.cam_t_obj_m).norm() < 1e-12);
    assert!((state.cam_r_obj.matrix() - expected.cam_r_obj.matrix()).norm() < 1e-12);
    let f = e.state.transition_jacobian(0.004);
    let p = e.covariance.unwrap();
    assert!((covariance.unwrap() - f * p * f.transpose()).norm() < 1e-9);
}
