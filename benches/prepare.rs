//! Training-data generation per stage, on a synthetic car (the target: ≥ 10 objects/s
//! for 20 samples × 4 views at 256², ground truth at 512², on 2 cores).

use criterion::{criterion_group, criterion_main, Criterion};
use mvpcc::core::camera::{Camera, DEFAULT_VIEWS};
use mvpcc::core::rng::Lcg;
use mvpcc::datagen::data::{prepare_model, CloudPolicy, Layout, PrepareParams, Source, ViewsFrame};
use mvpcc::datagen::mesh::{write_obj, SignedAxis};
use mvpcc::datagen::raster::render_views;
use mvpcc::datagen::scan::{ground_truth, partial, scan, PartialParams, PartialSpec};
use mvpcc::datagen::synth::{synthesize, Category};
use mvpcc::views::projection::project;
use mvpcc::views::write_views;

fn stages(c: &mut Criterion) {
    let mut mesh = synthesize(0, 1, &[Category::Car.into()]).mesh;
    mesh.normalize(SignedAxis::PLUS_Y, SignedAxis::MINUS_Z)
        .unwrap();
    let tris = mesh.triangles.len();
    let mut g = c.benchmark_group("prepare");
    g.sample_size(10);
    g.bench_function(format!("synthesize a car ({tris} triangles)"), |b| {
        b.iter(|| synthesize(0, 1, &[Category::Car.into()]))
    });
    g.bench_function("ground truth: 20 cameras at 512², voxel 1/256", |b| {
        b.iter(|| ground_truth(&mesh, 512, 1.0 / 256.0))
    });
    let cameras = Camera::set(&DEFAULT_VIEWS, 256).unwrap();
    g.bench_function("dense ground-truth views: 4 at 256²", |b| {
        b.iter(|| render_views(&mesh, &cameras))
    });
    let scanner = PartialSpec::Scanner {
        side: 1.0,
        distance: 0.9,
        height: 0.45,
        yaw_deg: 5.0,
        line_spacing: 0.004,
        angle_step_deg: 0.15,
        noise: 0.001,
    };
    let scanned = scan(&mesh, &scanner, &mut Lcg::new(0));
    g.bench_function(format!("profile scan ({} points)", scanned.len()), |b| {
        b.iter(|| scan(&mesh, &scanner, &mut Lcg::new(0)))
    });
    g.bench_function("8 partials with default settings (seeds 0–7)", |b| {
        b.iter(|| {
            for seed in 0..8 {
                partial(&mesh, &PartialParams::default(), 0, &mut Lcg::new(seed));
            }
        })
    });
    let views = project(&scanned.points, Some(&scanned.colors), &cameras);
    let dir = tempfile::tempdir().unwrap();
    g.bench_function("write one partial's 4 view pairs (PNG)", |b| {
        b.iter(|| write_views(dir.path(), &views).unwrap())
    });
    let dense = render_views(&mesh, &cameras);
    g.bench_function("write the 4 dense ground-truth view pairs (PNG)", |b| {
        b.iter(|| write_views(dir.path(), &dense).unwrap())
    });
    let obj = dir.path().join("car.obj");
    write_obj(&obj, &synthesize(0, 1, &[Category::Car.into()]).mesh).unwrap();
    let source = Source {
        path: obj,
        category: "car".into(),
        name: "car".into(),
    };
    let params = PrepareParams {
        views: DEFAULT_VIEWS.to_vec(),
        size: 256,
        gt_size: 512,
        gt_voxel: 1.0 / 256.0,
        samples: 20,
        train_fraction: 1.0,
        partial: PartialParams::default(),
        up: "y".into(),
        forward: "-z".into(),
        seed: 0,
        clouds: CloudPolicy::Test,
        allow_missing_materials: false,
        max_triangles: 5_000_000,
        views_frame: ViewsFrame::Object,
    };
    let layout = Layout {
        root: dir.path().join("data"),
    };
    g.bench_function(
        "prepare one model: 20 samples × 4 views at 256², GT at 512²",
        |b| b.iter(|| prepare_model(&source, &params, &layout).unwrap()),
    );
    g.finish();
}

criterion_group!(benches, stages);
criterion_main!(benches);
