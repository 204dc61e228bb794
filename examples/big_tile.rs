//! A large LAZ tile for measuring `complete --scene`'s streamed path (docs/speed.md, *Street
//! tiles*): generated streets (`mvpcc::datagen::synth::street`, each of its own seed) laid side
//! by side in rows, in UTM coordinates, classified as `synth --scene` classifies them. Written a
//! street at a time, so the tile never sits in memory.
//!
//! `cargo run --release --example big_tile -- OUT.laz [--points 50000000] [--seed 1]`

use las::point::{Classification, Format};
use las::{Builder, Point, Transform, Vector, Writer};
use mvpcc::datagen::synth::street::{street, Kind, StreetParams};
use mvpcc::scene::CLASSIFICATION;

/// Streets per row of the tile.
const PER_ROW: usize = 8;
/// Gap between neighbouring streets, metres: wider than a streamed chunk's margins would need
/// to tell them apart, narrower than a real block, which does not matter here.
const GAP: f64 = 10.0;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let value = |name: &str| {
        args.iter()
            .position(|a| a == name)
            .and_then(|i| args.get(i + 1))
            .map(|v| v.parse::<u64>().expect("a whole number"))
    };
    let out = args
        .iter()
        .find(|a| a.ends_with(".laz") || a.ends_with(".las"))
        .expect("usage: big_tile OUT.laz [--points N] [--seed S]");
    let target = value("--points").unwrap_or(50_000_000) as usize;
    let seed = value("--seed").unwrap_or(1);
    let params = StreetParams::default();
    let base = [650_000.0, 5_230_000.0, 100.0];
    // LAS 1.4's format 6: vehicles are class 64, beyond the older formats' 31.
    let mut builder = Builder::from((1, 4));
    let mut format = Format::new(6).expect("format 6");
    format.is_compressed = out.ends_with(".laz");
    builder.point_format = format;
    let axis = |offset: f64| Transform {
        scale: 0.001,
        offset,
    };
    builder.transforms = Vector {
        x: axis(base[0]),
        y: axis(base[1]),
        z: axis(base[2]),
    };
    let header = builder.into_header().expect("a valid header");
    let mut writer = Writer::from_path(out, header).expect("the output opens");
    let (mut written, mut streets, mut vehicles) = (0, 0, 0);
    let mut row_width = 0.0f64;
    let mut at = [0.0f64; 2];
    while written < target {
        let scene = street(seed * 1000 + streets as u64, &params);
        let bounds = scene.cloud.bounds().expect("a street has points");
        let size = [0, 1].map(|k| bounds.max[k] - bounds.min[k]);
        let classes = &scene
            .cloud
            .attribute(CLASSIFICATION)
            .expect("classes")
            .values;
        vehicles += scene
            .objects
            .iter()
            .filter(|o| o.kind == Kind::Vehicle)
            .count();
        for (i, (p, &class)) in scene.cloud.positions.iter().zip(classes).enumerate() {
            let point = Point {
                x: base[0] + at[0] + p[0] - bounds.min[0],
                y: base[1] + at[1] + p[1] - bounds.min[1],
                z: base[2] + p[2] - bounds.min[2],
                classification: Classification::new(class as u8).expect("a LAS class"),
                // The scan's time, a microsecond a point.
                gps_time: Some((written + i) as f64 * 1e-6),
                ..Default::default()
            };
            writer.write_point(point).expect("the point is written");
        }
        written += scene.cloud.len();
        streets += 1;
        row_width = row_width.max(size[1]);
        at[0] += size[0] + GAP;
        if streets % PER_ROW == 0 {
            at = [0.0, at[1] + row_width + GAP];
            row_width = 0.0;
        }
    }
    writer.close().expect("the output is finished");
    eprintln!("{out}: {written} points, {streets} streets, {vehicles} vehicles");
}
