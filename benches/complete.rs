//! `complete` end to end on a ~35K-point car scan (the README's speed table): read, complete with
//! the built-in model, write; and the parts users can switch off.

use criterion::{criterion_group, criterion_main, Criterion};
use mvpcc::complete::{complete, Method, Options, DEFAULT_MODEL};
use mvpcc::filter::SorParams;
use mvpcc::frame::UpAxis;
use mvpcc::inpaint::Inpainter;
use mvpcc::io::{read_cloud, write_cloud, Encoding};
use std::time::Duration;

mod common;

fn end_to_end(c: &mut Criterion) {
    let inpainter = Inpainter::from_bytes(DEFAULT_MODEL, burn::tensor::Device::flex()).unwrap();
    let options = |method| Options {
        method,
        up: UpAxis::Y,
        views: mvpcc::camera::DEFAULT_VIEWS.to_vec(),
        erode: 3,
        smooth: 0,
        sor: SorParams::default(),
        keep_input: true,
        merge_pixels: 8.0,
        symmetry: true,
    };
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("scan.ply");
    let output = dir.path().join("done.ply");
    let (real, name) = common::mls_car();
    let generated = common::normalized_car(35_000, 1);
    for (car, name) in [(real, name), (generated, "generated car".to_string())] {
        write_cloud(&input, &car, None, Encoding::Binary).unwrap();
        let mut group = c.benchmark_group(format!("complete {} points ({name})", car.len()));
        group
            .sample_size(10)
            .measurement_time(Duration::from_secs(10));
        for method in [Method::Network, Method::Mirror] {
            let options = options(method);
            group.bench_function(format!("{method:?}: read, complete, write"), |b| {
                b.iter(|| {
                    let cloud = read_cloud(&input, None).unwrap().cloud;
                    let done = complete(&cloud, Some(&inpainter), &options).unwrap();
                    write_cloud(&output, &done.cloud, None, Encoding::Binary).unwrap();
                })
            });
        }
        group.finish();
    }
}

criterion_group!(benches, end_to_end);
criterion_main!(benches);
