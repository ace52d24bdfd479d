//! The cost of reading the newest estimate (`EstimateReader::read`) and of predicting it to an instant with its
//! covariance (`predicted_to`), with no publisher running and with one publishing as fast as it can.

use criterion::{Criterion, criterion_group, criterion_main};
use roitrack_core::MotionState;
use roitrack_core::estimator::{Estimate, Matrix12, TrackStatus};
use roitrack_servo::handle::estimate_channel;

fn estimate() -> Estimate {
    Estimate {
        t_ref_s: 1.0,
        state: MotionState::bench(),
        residual_rms_px: 0.0,
        inverse_condition: 1.0,
        measurements_used: 16,
        iterations: 1,
        status: TrackStatus::Tracking,
        covariance: Some(Matrix12::identity() * 1e-6),
        noise_px: 0.1,
        acceleration: None,
    }
}

fn bench(c: &mut Criterion) {
    let (mut publisher, reader) = estimate_channel();
    publisher.publish(&estimate());
    c.bench_function("estimate_handle_read", |b| {
        b.iter(|| std::hint::black_box(reader.read()))
    });
    c.bench_function("estimate_handle_predicted_to", |b| {
        b.iter(|| std::hint::black_box(reader.predicted_to(std::hint::black_box(1.002))))
    });
    c.bench_function("estimate_handle_publish", |b| {
        let e = estimate();
        b.iter(|| publisher.publish(std::hint::black_box(&e)))
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
