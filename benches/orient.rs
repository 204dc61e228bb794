use criterion::{criterion_group, criterion_main, Criterion};
use mvpcc::complete::clean::{clean, CleanParams};
use mvpcc::complete::orient::{orient, OrientMode, OrientParams, Orienter};
use mvpcc::complete::symmetry::SymmetryParams;
use mvpcc::core::frame::UpAxis;
use std::time::Duration;

mod common;

fn orientation(c: &mut Criterion) {
    let (car, name) = common::mls_car();
    let orienter = Orienter::builtin().unwrap();
    let mut group = c.benchmark_group(format!("orientation, {} points ({name})", car.len()));
    group
        .sample_size(20)
        .measurement_time(Duration::from_secs(5));
    for (label, mode) in [
        ("geometric", OrientMode::Geometric),
        ("learned", OrientMode::Learned),
        ("combined", OrientMode::Combined),
    ] {
        group.bench_function(label, |b| {
            b.iter(|| {
                orient(
                    &car,
                    UpAxis::Y,
                    mode,
                    Some(&orienter),
                    &OrientParams::default(),
                    &SymmetryParams::default(),
                )
            })
        });
    }
    group.bench_function("clean", |b| {
        b.iter(|| clean(&car, UpAxis::Y, &CleanParams::default()))
    });
    group.finish();
}

criterion_group!(benches, orientation);
criterion_main!(benches);
