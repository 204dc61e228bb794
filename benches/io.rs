use criterion::{criterion_group, criterion_main, Criterion};
use mvpcc::io::{read_cloud, stream, write_cloud, Encoding};
use std::time::Duration;

mod common;

fn io(c: &mut Criterion) {
    let dir = tempfile::tempdir().unwrap();
    let cloud = common::normalized_car(1_000_000, 3);
    let mut group = c.benchmark_group("io");
    group
        .sample_size(10)
        .measurement_time(Duration::from_secs(8));
    for (name, encoding) in [
        ("ply", Encoding::Binary),
        ("ply", Encoding::Ascii),
        ("pcd", Encoding::Binary),
        ("xyz", Encoding::Ascii),
        ("las", Encoding::Binary),
        ("laz", Encoding::Binary),
    ] {
        let path = dir.path().join(format!("car-{encoding:?}.{name}"));
        write_cloud(&path, &cloud, None, encoding).unwrap();
        group.bench_function(format!("read 1M-point {name} ({encoding:?})"), |b| {
            b.iter(|| read_cloud(&path, None).unwrap())
        });
    }
    // A street tile's streamed passes (`complete --scene` from 20M points): every point read
    // a batch at a time, and copied record by record with a vehicle field added.
    for name in ["las", "laz"] {
        let path = dir.path().join(format!("car-Binary.{name}"));
        group.bench_function(format!("stream-read 1M-point {name}"), |b| {
            b.iter(|| stream::scan(&path, |_| Ok(())).unwrap())
        });
        let out = dir.path().join(format!("copy.{name}"));
        group.bench_function(format!("stream-copy 1M-point {name}"), |b| {
            b.iter(|| {
                let none = std::iter::empty();
                stream::copy_appending(
                    &path,
                    &out,
                    name == "laz",
                    Some("vehicle"),
                    true,
                    none,
                    |_, _| {},
                )
                .unwrap()
            })
        });
    }
    let path = dir.path().join("write.ply");
    group.bench_function("write 1M-point binary ply", |b| {
        b.iter(|| write_cloud(&path, &cloud, None, Encoding::Binary).unwrap())
    });
    group.finish();
}

criterion_group!(benches, io);
criterion_main!(benches);
