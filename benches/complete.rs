//! `complete` end to end on a ~35K-point car scan (the speed table of docs/speed.md): read, orient and
//! complete with the built-in models, write; and the parts users can switch off.

use criterion::{criterion_group, criterion_main, Criterion};
use mvpcc::complete::{complete, Method, Options, DEFAULT_MODEL};
use mvpcc::frame::UpAxis;
use mvpcc::inpaint::Inpainter;
use mvpcc::io::{read_cloud, write_cloud, Encoding};
use mvpcc::orient::{orient, OrientMode, Orienter, DEFAULT_ORIENTER};
use std::time::Duration;

mod common;

fn end_to_end(c: &mut Criterion) {
    let inpainter = Inpainter::from_bytes(DEFAULT_MODEL, burn::tensor::Device::flex()).unwrap();
    let orienter = Orienter::from_bytes(DEFAULT_ORIENTER, burn::tensor::Device::flex()).unwrap();
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
            group.bench_function(format!("{method:?}: read, orient, complete, write"), |b| {
                b.iter(|| {
                    let cloud = read_cloud(&input, None).unwrap().cloud;
                    let heading =
                        orient(&cloud, UpAxis::Y, OrientMode::Auto, Some(&orienter)).heading;
                    let options = Options {
                        method,
                        heading,
                        ..Options::default()
                    };
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
