use criterion::{criterion_group, criterion_main, BatchSize, Criterion};
use mvpcc::complete::filter::{inliers, SorParams};
use mvpcc::core::camera::{Camera, DEFAULT_VIEWS};
use mvpcc::views::projection::project;
use mvpcc::views::reprojection::{reproject, snap_to_rays, ReprojectOptions};

mod common;

fn reprojection(c: &mut Criterion) {
    // Dense views like an inpainted ground truth: a densely sampled object fills its silhouette.
    let dense = common::normalized_car(600_000, 2);
    let cameras = Camera::set(&DEFAULT_VIEWS, 256).unwrap();
    let views = project(&dense.positions_f32(), dense.colors.as_deref(), &cameras);
    let options = ReprojectOptions::default();
    let merged = reproject(&views, options);
    eprintln!(
        "dense views: {} occupied pixels, {} points after erosion and de-duplication",
        views.occupied(),
        merged.len()
    );
    let mut group = c.benchmark_group("reprojection");
    group.sample_size(20);
    group.bench_function("erode + merge + dedup, 4 dense views of 256²", |b| {
        b.iter(|| reproject(&views, options))
    });
    group.bench_function("snap onto pixel rays, 4 dense views of 256²", |b| {
        b.iter_batched_ref(
            || views.clone(),
            |v| snap_to_rays(v, &cameras, None),
            BatchSize::LargeInput,
        )
    });
    group.bench_function("erode + merge + dedup + SOR, 4 dense views of 256²", |b| {
        b.iter(|| {
            let cloud = reproject(&views, options);
            let keep = inliers(&cloud.positions, SorParams::default());
            cloud.filter(&keep)
        })
    });
    group.finish();
}

criterion_group!(benches, reprojection);
criterion_main!(benches);
