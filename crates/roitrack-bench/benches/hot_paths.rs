//! Criterion benchmarks of roitrack's hot paths on the built-in scene (docs/model.md); the inputs are those of
//! `roitrack bench` ([`roitrack_bench::HotPaths`]). Benchmark ids are the items' JSON keys.
//!
//! `cargo bench -p roitrack-bench` takes about 30 s (1 s warm-up and 2 s of measurement per item, set below for a
//! shared 2-core machine); `cargo bench -p roitrack-bench -- --quick` about 5 s; `-- control_step` runs only the
//! ids containing `control_step`.

use std::time::Duration;

use criterion::{Criterion, criterion_group, criterion_main};
use roitrack_bench::{HotPaths, Item};

fn hot_paths(c: &mut Criterion) {
    let mut hot = HotPaths::new();
    c.bench_function(Item::JacobianResidualW16.key(), |b| {
        b.iter(|| hot.jacobian_residual(16))
    });
    c.bench_function(Item::ControlStepW16.key(), |b| {
        b.iter(|| hot.control_step(16))
    });
    c.bench_function(Item::ControlStepW32.key(), |b| {
        b.iter(|| hot.control_step(32))
    });
    c.bench_function(Item::GaussNewtonSolve.key(), |b| {
        b.iter(|| hot.gauss_newton_solve(32))
    });
    c.bench_function(Item::StaticPose.key(), |b| b.iter(|| hot.static_pose()));
    c.bench_function(Item::Centroid24.key(), |b| b.iter(|| hot.centroid()));
    c.bench_function(Item::RenderRoi.key(), |b| b.iter(|| hot.render_roi()));
    c.bench_function(Item::KalmanUpdate.key(), |b| b.iter(|| hot.kalman_update()));
    c.bench_function(Item::KalmanUpdateConstantAcceleration.key(), |b| {
        b.iter(|| hot.kalman_update_constant_acceleration())
    });
}

fn config() -> Criterion {
    Criterion::default()
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(2))
        .sample_size(50)
}

criterion_group! {
    name = benches;
    config = config();
    targets = hot_paths
}
criterion_main!(benches);
