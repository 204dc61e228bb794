use criterion::{criterion_group, criterion_main, Criterion};
use mvpcc::core::rng::Lcg;
use mvpcc::metrics::compare_clouds;

mod common;

fn metrics(c: &mut Criterion) {
    let (scan, name) = common::mls_car();
    // A prediction close to the truth, as a completion is: the scan with ~2 mm of noise.
    let mut rng = Lcg::new(9);
    let other: Vec<[f64; 3]> = scan
        .positions
        .iter()
        .map(|p| p.map(|v| v + rng.range(-0.002, 0.002)))
        .collect();
    c.bench_function(
        &format!(
            "cd + f1@0.01,0.005 of {} vs {} points ({name} and a noisy copy)",
            scan.len(),
            other.len()
        ),
        |b| b.iter(|| compare_clouds(&scan.positions, &other, &[0.01, 0.005])),
    );
}

criterion_group!(benches, metrics);
criterion_main!(benches);
