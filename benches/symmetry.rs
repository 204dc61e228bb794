//! The symmetry plane's search, the heart of `complete`'s symmetry stage: on the largest real
//! car scan turned onto its heading, and on a generated bus driven past on one side, without
//! and with a known width. The two bus rows run in the same process, so their difference is
//! what the width costs even on a busy machine.

use criterion::{criterion_group, criterion_main, Criterion};
use mvpcc::complete::orient::{orient, OrientMode, OrientParams, Orienter};
use mvpcc::complete::symmetry::{find_plane, SymmetryParams, Width};
use mvpcc::core::frame::{Frame, UpAxis};
use mvpcc::core::rng::Lcg;
use mvpcc::datagen::mesh::SignedAxis;
use mvpcc::datagen::scan::{scan, PartialSpec};
use mvpcc::datagen::synth::{synthesize, Category};
use std::time::Duration;

mod common;

/// The real car in `complete`'s frame: turned onto the heading `--orient auto` finds, boxed.
fn car_in_pose() -> (Vec<[f64; 3]>, String) {
    let (car, name) = common::mls_car();
    let orienter = Orienter::builtin().unwrap();
    let heading = orient(
        &car,
        UpAxis::Y,
        OrientMode::Combined,
        Some(&orienter),
        &OrientParams::default(),
        &SymmetryParams::default(),
    )
    .heading
    .unwrap();
    let frame = Frame::fit_heading(&car, UpAxis::Y, heading).unwrap();
    let points = car
        .positions
        .iter()
        .map(|&p| frame.to_normalized(p))
        .collect();
    (points, name)
}

/// A generated bus scanned from a path on its +x side, the sensor below its roof (one flank
/// and the ends, as in the validation split's drive-bys), and the bus's width.
fn bus_driven_past() -> (Vec<[f64; 3]>, f64) {
    let mut mesh = synthesize(0, 3, &[Category::Bus.into()]).mesh;
    mesh.normalize(SignedAxis::PLUS_Y, SignedAxis::MINUS_Z)
        .unwrap();
    let (lo, hi) = mesh.bounds();
    let spec = PartialSpec::Scanner {
        side: 1.0,
        distance: 0.8,
        height: 0.2,
        yaw_deg: 0.0,
        line_spacing: 0.008,
        angle_step_deg: 0.25,
        noise: 0.001,
    };
    let part = scan(&mesh, &spec, &mut Lcg::new(3));
    let points = part.points.iter().map(|p| p.map(f64::from)).collect();
    (points, f64::from(hi[0] - lo[0]))
}

fn symmetry(c: &mut Criterion) {
    let (car, name) = car_in_pose();
    let (bus, width) = bus_driven_past();
    let mut group = c.benchmark_group("symmetry plane");
    group
        .sample_size(20)
        .measurement_time(Duration::from_secs(5));
    group.bench_function(format!("{} points ({name}, in pose)", car.len()), |b| {
        b.iter(|| find_plane(&car, None, &SymmetryParams::default()))
    });
    group.bench_function(format!("{} points (bus driven past)", bus.len()), |b| {
        b.iter(|| find_plane(&bus, None, &SymmetryParams::default()))
    });
    group.bench_function(
        format!("{} points (bus driven past), width given", bus.len()),
        |b| b.iter(|| find_plane(&bus, Some(Width::Known(width)), &SymmetryParams::default())),
    );
    group.finish();
}

criterion_group!(benches, symmetry);
criterion_main!(benches);
