use criterion::{criterion_group, criterion_main, Criterion};
use mvpcc::complete::filter::{inliers, SorParams};
use std::time::Duration;

mod common;

fn filter(c: &mut Criterion) {
    let (car, name) = common::mls_car();
    let big = common::normalized_car(1_000_000, 4);
    let mut group = c.benchmark_group("sor k=20 σ=5");
    group
        .sample_size(10)
        .measurement_time(Duration::from_secs(10));
    group.bench_function(format!("{} points ({name})", car.len()), |b| {
        b.iter(|| inliers(&car.positions, SorParams::default()))
    });
    group.bench_function(format!("{} points (generated car)", big.len()), |b| {
        b.iter(|| inliers(&big.positions, SorParams::default()))
    });
    group.finish();
}

criterion_group!(benches, filter);
criterion_main!(benches);
