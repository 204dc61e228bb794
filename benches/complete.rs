//! `complete` end to end on a ~35K-point car scan (the speed table of docs/speed.md): read, orient and
//! complete with the built-in models, write; and the parts users can switch off.

use criterion::{criterion_group, criterion_main, Criterion};
use mvpcc::complete::orient::OrientMode;
use mvpcc::complete::{Completer, Method, Options, Settings};
use mvpcc::io::{read_cloud, write_cloud, Encoding};
use std::time::Duration;

mod common;

fn end_to_end(c: &mut Criterion) {
    let completer = Completer::builtin(burn::tensor::Device::flex()).unwrap();
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
                    let settings = Settings {
                        clean: false,
                        orient: OrientMode::Auto,
                        options: Options {
                            method,
                            ..Options::default()
                        },
                    };
                    let run = completer.run(&cloud, &settings).unwrap();
                    write_cloud(&output, &run.completion.cloud, None, Encoding::Binary).unwrap();
                })
            });
        }
        group.finish();
    }
}

criterion_group!(benches, end_to_end);
criterion_main!(benches);
