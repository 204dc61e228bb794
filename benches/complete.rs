//! `complete` end to end on a ~35K-point car scan (the speed table of docs/speed.md): read, orient
//! and complete with the built-in models, write; and the parts users can switch on or off. A dense
//! scan of one side (half a million points, as a survey-grade scanner gives a bus) is timed with
//! the mirror alone: the network's time does not depend on the points, the geometric stages do.
//! With `MVPCC_BENCH_MODEL=FILE` (a generator's weights, such as a relay leg's) the network method
//! is timed with that model too, in the same run, so a candidate's cost is compared with the
//! built-in model's on the same machine state (lab/2026-12-04-widening).

use criterion::{criterion_group, criterion_main, Criterion};
use mvpcc::app;
use mvpcc::app::complete::{FileOptions, Job};
use mvpcc::complete::orient::OrientMode;
use mvpcc::complete::{Completer, Method, Options, Settings, Source};
use mvpcc::datagen::shapes;
use mvpcc::io::{write_cloud, Encoding};
use std::path::Path;
use std::time::Duration;

mod common;

/// The built-in models, and the generator `MVPCC_BENCH_MODEL` names beside them.
fn completers() -> Vec<(String, Completer)> {
    let device = burn::tensor::Device::flex();
    let mut all = vec![(String::new(), Completer::builtin(device.clone()).unwrap())];
    if let Some(path) = std::env::var_os("MVPCC_BENCH_MODEL") {
        let model = Source::File(Path::new(&path));
        let completer = Completer::load(model, Source::Builtin, device, None).unwrap();
        all.push((format!(", {}", path.to_string_lossy()), completer));
    }
    all
}

fn end_to_end(c: &mut Criterion) {
    let completers = completers();
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
        let network = |mirror_pass| Options {
            mirror_pass,
            ..Options::default()
        };
        let mirror = Options {
            method: Method::Mirror,
            ..Options::default()
        };
        let builtin = &completers[0].1;
        let runs = completers
            .iter()
            .map(|(model, c)| (model.clone(), c, network(true)))
            .chain([
                (", --no-mirror-pass".to_string(), builtin, network(false)),
                (String::new(), builtin, mirror),
            ]);
        for (label, completer, options) in runs {
            let label = format!("{:?}{label}: read, orient, complete, write", options.method);
            group.bench_function(label, |b| {
                b.iter(|| complete_file(&input, &output, completer, &options))
            });
        }
        group.finish();
    }
    dense_side(c, &completers[0].1);
}

fn dense_side(c: &mut Criterion, completer: &Completer) {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("scan.ply");
    let output = dir.path().join("done.ply");
    let side = shapes::scanned_side(&shapes::car(1_000_000, 2));
    write_cloud(&input, &side, None, Encoding::Binary).unwrap();
    let mut group = c.benchmark_group(format!(
        "complete {} points (one side of a generated car)",
        side.len()
    ));
    group
        .sample_size(10)
        .measurement_time(Duration::from_secs(10));
    let mirror = Options {
        method: Method::Mirror,
        ..Options::default()
    };
    group.bench_function("Mirror: read, orient, complete, write", |b| {
        b.iter(|| complete_file(&input, &output, completer, &mirror))
    });
    group.finish();
}

/// What `mvpcc complete IN OUT` does with `options`: the command's own file step.
fn complete_file(input: &Path, output: &Path, completer: &Completer, options: &Options) {
    let settings = |_: &Path| Settings {
        clean: false,
        orient: OrientMode::Auto,
        options: options.clone(),
    };
    let job = Job {
        completer,
        settings: &settings,
        files: FileOptions::default(),
        scene: None,
    };
    app::complete::complete_file(input, output, None, &job).unwrap();
}

criterion_group!(benches, end_to_end);
criterion_main!(benches);
