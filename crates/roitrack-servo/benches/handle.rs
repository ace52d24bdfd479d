//! The cost of reading the newest estimate (`EstimateReader::read`) and of predicting it to an instant with its
//! covariance (`predicted_to`), with no publisher running and with one publishing as fast as it can.

use criterion::{Criterion, criterion_group, criterion_main};
use roitrack_estimators::Estimate;
use roitrack_servo::handle::estimate_channel;

fn bench(c: &mut Criterion) {
    let (mut publisher, reader) = estimate_channel();
    publisher.publish(&Estimate::bench());
    c.bench_function("estimate_handle_read", |b| {
        b.iter(|| std::hint::black_box(reader.read()))
    });
    c.bench_function("estimate_handle_predicted_to", |b| {
        b.iter(|| std::hint::black_box(reader.predicted_to(std::hint::black_box(1.002))))
    });
    c.bench_function("estimate_handle_publish", |b| {
        let e = Estimate::bench();
        b.iter(|| publisher.publish(std::hint::black_box(&e)))
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
