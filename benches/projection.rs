use criterion::{criterion_group, criterion_main, Criterion};
use mvpcc::core::camera::{Camera, DEFAULT_VIEWS};
use mvpcc::views::projection::project;

mod common;

fn projection(c: &mut Criterion) {
    let (cloud, name) = common::mls_car();
    let points = cloud.positions_f32();
    let cameras = Camera::set(&DEFAULT_VIEWS, 256).unwrap();
    c.bench_function(
        &format!(
            "project {} points ({name}) into 4 views of 256²",
            points.len()
        ),
        |b| b.iter(|| project(&points, cloud.colors.as_deref(), &cameras)),
    );
}

criterion_group!(benches, projection);
criterion_main!(benches);
