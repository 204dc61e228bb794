use criterion::{criterion_group, criterion_main, Criterion};
use mvpcc::metrics::compare_clouds;

mod common;

fn metrics(c: &mut Criterion) {
    let (scan, name) = common::mls_car();
    let other = common::normalized_car(scan.len(), 9);
    c.bench_function(
        &format!(
            "cd + f1@0.01,0.005 of {} vs {} points ({name})",
            scan.len(),
            other.len()
        ),
        |b| b.iter(|| compare_clouds(&scan.positions, &other.positions, &[0.01, 0.005])),
    );
}

criterion_group!(benches, metrics);
criterion_main!(benches);
