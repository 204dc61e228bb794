//! Measures the symmetry plane (docs/pipeline.md, *4. The symmetry plane*): every test
//! partial of a `prepare` data directory is completed with `--method mirror` (everything
//! estimated, as `mvpcc complete --method mirror` does), the estimated plane is compared with
//! the true one (the generated objects are symmetric about x = 0 of their own frame), and the
//! mirror completion is scored next to the mirror about the true plane, by partial kind,
//! category and how the plane was found (`fit`). With `--true-width` every partial is
//! completed as `complete --vehicle-width W` would with its object's true width (the ground
//! truth's x extent), which measures what knowing the width is worth.
//!
//! With `--true-heading` the partials are laid in their object's frame and completed with
//! `--orient none`, so the plane alone is measured.
//!
//! Real scans given with `--mls DIR` (PCD, y up) are turned by `--turns` (8) random headings
//! each and completed as `mvpcc complete` does (the network method, everything estimated):
//! the output's width over its length and how far it reaches beyond the scan's own extent
//! across the width (a plane off the middle draws the far flank outside the vehicle), the
//! warnings, and how far the mirror method's plane, turned back, lies from the plane of the
//! scan as it is.
//!
//! `cargo run --release --example symmetry -- --data DATA [--true-width] [--true-heading]
//! [--kind scanner|cameras] [--network] [--limit N] [--json FILE] [--tuning FILE]` or
//! `-- --mls DIR [--seed N] [--turns N] [--json FILE] [--tuning FILE]`. `--network` also scores
//! `complete`'s default (the network method); `--tuning` reads `complete --tuning`'s file.
//!
//! Choices are made on the validation split (`scripts/judge-leg.sh` makes it in target/valset;
//! small gains are checked on three more seeds, docs/quality.md, *The splits*); the test split is
//! measured once, for the report.

use burn::tensor::Device;
use mvpcc::complete::orient::OrientMode;
use mvpcc::complete::symmetry::mirror;
use mvpcc::complete::{Completer, Completion, Method, Options, Settings, Tuning};
use mvpcc::core::cloud::{Aabb, PointCloud};
use mvpcc::core::knn::KnnIndex;
use mvpcc::core::rng::Lcg;
use mvpcc::datagen::data::{Layout, Manifest, GT_FINE, TEST};
use mvpcc::datagen::scan::PartialSpec;
use mvpcc::io::read_cloud;
use mvpcc::metrics::compare_clouds;
use rayon::prelude::*;
use serde::Serialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

type Error = Box<dyn std::error::Error + Send + Sync>;

fn arg(name: &str) -> Option<String> {
    let args: Vec<String> = std::env::args().collect();
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1).cloned())
}

/// What the measurement is told of the truth instead of estimating it.
#[derive(Debug, Clone, Copy)]
struct Given {
    /// The object's width (`--true-width`).
    width: bool,
    /// The object's heading (`--true-heading`).
    heading: bool,
}

/// How every partial is completed besides the truth given.
#[derive(Debug, Clone)]
struct Run {
    given: Given,
    /// `--tuning FILE`'s tunables, as `complete --tuning` reads them.
    tuning: Tuning,
    /// Whether the network method (`complete`'s default) is also scored (`--network`).
    network: bool,
}

/// Where each cue of the plane put it across the object's centre line, over its length,
/// positive towards the side holding more of the measured points.
#[derive(Debug, Clone, Serialize)]
struct CueErrors {
    pairs: Option<f64>,
    extent: Option<f64>,
    tyres: Option<f64>,
    width: Option<f64>,
}

/// One partial's plane errors and mirror scores.
#[derive(Debug, Clone, Serialize)]
struct Sample {
    name: String,
    category: String,
    kind: &'static str,
    /// Distance of the estimated plane from the true one at the object's centre, over the
    /// object's length; `None` when no plane was found.
    offset: Option<f64>,
    /// Angle between the planes, degrees.
    angle: Option<f64>,
    /// Where the estimated plane crosses the object's centre line, over its length, positive
    /// towards the scanned side (scanner partials; the cameras' side is not one side).
    towards_scanner: Option<f64>,
    /// The same, positive towards the side of the true plane holding more of the measured
    /// points (every partial).
    towards_seen: Option<f64>,
    /// How the plane was found (`PlaneFit`), `None` when it was not.
    fit: Option<String>,
    /// Where each cue put the plane, as `towards_seen`.
    cues: CueErrors,
    /// F1@0.01 of the partial alone, of the mirror completion and of the mirror about the
    /// true plane.
    f1_partial: f64,
    f1_mirror: f64,
    f1_true: f64,
    /// Whether the cues vouch for the plane (else `complete` warns and the network fills the
    /// far side).
    vouched: Option<bool>,
    /// F1@0.01 of `complete`'s default (the network method), with `--network`.
    f1_network: Option<f64>,
}

/// `complete --method mirror` with everything estimated, or the heading taken as the input's
/// axes (`orient`).
fn mirrored(
    completer: &Completer,
    cloud: &PointCloud,
    vehicle_width: Option<f64>,
    orient: OrientMode,
    tuning: &Tuning,
) -> Result<Completion, Error> {
    completed(
        completer,
        cloud,
        vehicle_width,
        orient,
        Method::Mirror,
        tuning,
    )
}

/// `complete --method METHOD` with the given orientation.
fn completed(
    completer: &Completer,
    cloud: &PointCloud,
    vehicle_width: Option<f64>,
    orient: OrientMode,
    method: Method,
    tuning: &Tuning,
) -> Result<Completion, Error> {
    let settings = Settings {
        clean: false,
        orient,
        options: Options {
            method,
            vehicle_width,
            tuning: *tuning,
            ..Options::default()
        },
    };
    Ok(completer.run(cloud, &settings)?.completion)
}

fn f1(points: &[[f64; 3]], gt: &[[f64; 3]]) -> f64 {
    compare_clouds(points, gt, &[0.01]).fscores[0].f1
}

/// The measured points and their mirror images across `x = 0` of the object's frame, images
/// within `tolerance` of a measured point left out as the pipeline leaves them out.
fn true_mirror(measured: &[[f64; 3]], tolerance: f64) -> Vec<[f64; 3]> {
    let index = KnnIndex::new(measured);
    let images: Vec<[f64; 3]> = measured.iter().map(|&p| mirror(p, 0.0)).collect();
    let kept = images
        .iter()
        .zip(index.nearest(&images))
        .filter(|(_, (_, d))| *d > tolerance)
        .map(|(p, _)| *p);
    measured.iter().copied().chain(kept).collect()
}

/// The plane's errors and the mirror's scores of one partial; `name` and `category` are
/// copied into the result.
fn measure(
    completer: &Completer,
    (name, category): (String, String),
    partial: &Path,
    gt: &[[f64; 3]],
    spec: &PartialSpec,
    run: &Run,
) -> Result<Sample, Error> {
    let given = run.given;
    let mut cloud = read_cloud(partial, None)?.cloud;
    let bounds = Aabb::of(gt).ok_or("empty ground truth")?;
    let width = given.width.then(|| bounds.max[0] - bounds.min[0]);
    // With the true heading the partial is laid in the object's frame, whose axes are the
    // vehicle's, and `--orient none` keeps them.
    let orient = if given.heading {
        cloud.positions = spec.points_to_object_frame(&cloud.positions);
        OrientMode::None
    } else {
        OrientMode::Auto
    };
    let to_object = |points: &[[f64; 3]]| {
        if given.heading {
            points.to_vec()
        } else {
            spec.points_to_object_frame(points)
        }
    };
    let completion = mirrored(completer, &cloud, width, orient, &run.tuning)?;
    let f1_network = if run.network {
        let done = completed(
            completer,
            &cloud,
            width,
            orient,
            Method::Network,
            &run.tuning,
        )?;
        Some(f1(&to_object(&done.cloud.positions), gt))
    } else {
        None
    };
    let measured = to_object(&cloud.positions);
    let completed = to_object(&completion.cloud.positions);
    let length = bounds.longest_side();
    let seen_side = measured.iter().map(|p| p[0]).sum::<f64>().signum();
    let frame = &completion.frame;
    // A plane `x = c` of the completion's frame in the object's: its distance from the
    // object's centre, the angle between the planes, and where it crosses the centre line.
    let locate = |c: f64| {
        let [on, ahead] = [c, c + 1.0]
            .map(|x| frame.to_input([x, 0.0, 0.0]))
            .map(|p| to_object(&[p])[0]);
        let n = [0, 1, 2].map(|i| ahead[i] - on[i]);
        let norm = n.iter().map(|v| v * v).sum::<f64>().sqrt();
        let n = n.map(|v| v / norm);
        let centre = [0.0, bounds.center()[1], bounds.center()[2]];
        let distance = (0..3).map(|i| n[i] * (centre[i] - on[i])).sum::<f64>();
        let angle = n[0].abs().min(1.0).acos().to_degrees();
        let x = on[0] - (n[1] * (centre[1] - on[1]) + n[2] * (centre[2] - on[2])) / n[0];
        (distance.abs() / length, angle, x / length)
    };
    let (offset, angle, towards_scanner, towards_seen) = match completion.plane {
        Some(plane) => {
            let (distance, angle, x) = locate(plane.offset);
            let side = match spec {
                PartialSpec::Scanner { side, .. } => Some(f64::from(*side)),
                PartialSpec::Cameras { .. } => None,
            };
            (
                Some(distance),
                Some(angle),
                side.map(|s| s * x),
                Some(seen_side * x),
            )
        }
        None => (None, None, None, None),
    };
    let cues = completion.plane.map(|p| p.cues).unwrap_or_default();
    let cue = |c: Option<f64>| c.map(|c| seen_side * locate(c).2);
    let cues = CueErrors {
        pairs: cue(cues.pairs),
        extent: cue(cues.extent),
        tyres: cue(cues.tyres),
        width: cue(cues.width),
    };
    let tolerance = completion
        .plane
        .map_or(0.0, |p| p.tolerance * completion.frame.extent);
    Ok(Sample {
        name,
        category,
        kind: spec.protocol(),
        offset,
        angle,
        towards_scanner,
        towards_seen,
        fit: completion.plane.map(|p| format!("{:?}", p.fit)),
        cues,
        f1_partial: f1(&measured, gt),
        f1_mirror: f1(&completed, gt),
        f1_true: f1(&true_mirror(&measured, tolerance), gt),
        vouched: completion.plane.map(|p| p.vouched),
        f1_network,
    })
}

fn quantile(values: &mut [f64], q: f64) -> f64 {
    values.sort_by(f64::total_cmp);
    values
        .get(((values.len() as f64 - 1.0) * q).round() as usize)
        .copied()
        .unwrap_or(f64::NAN)
}

#[derive(Debug, Serialize)]
struct Group {
    samples: usize,
    /// Partials without a plane.
    no_plane: usize,
    offset_median: f64,
    offset_p95: f64,
    angle_median: f64,
    angle_p95: f64,
    f1_partial: f64,
    f1_mirror: f64,
    f1_true: f64,
}

fn group(samples: &[&Sample]) -> Group {
    let mut offsets: Vec<f64> = samples.iter().filter_map(|s| s.offset).collect();
    let mut angles: Vec<f64> = samples.iter().filter_map(|s| s.angle).collect();
    let mean =
        |f: fn(&Sample) -> f64| samples.iter().map(|s| f(s)).sum::<f64>() / samples.len() as f64;
    Group {
        samples: samples.len(),
        no_plane: samples.len() - offsets.len(),
        offset_median: quantile(&mut offsets, 0.5),
        offset_p95: quantile(&mut offsets, 0.95),
        angle_median: quantile(&mut angles, 0.5),
        angle_p95: quantile(&mut angles, 0.95),
        f1_partial: mean(|s| s.f1_partial),
        f1_mirror: mean(|s| s.f1_mirror),
        f1_true: mean(|s| s.f1_true),
    }
}

/// The cloud turned counter-clockwise (seen from above, y up) by `turn` degrees about the
/// vertical through `pivot`.
fn turned(p: [f64; 3], turn: f64, pivot: [f64; 3]) -> [f64; 3] {
    let (s, c) = turn.to_radians().sin_cos();
    let (x, z) = (p[0] - pivot[0], p[2] - pivot[2]);
    [pivot[0] + c * x + s * z, p[1], pivot[2] - s * x + c * z]
}

/// A completion's plane in the input's coordinates: a point on it and its unit normal.
struct FoundPlane {
    point: [f64; 3],
    normal: [f64; 3],
}

fn plane_of(
    completer: &Completer,
    cloud: &PointCloud,
    tuning: &Tuning,
) -> Result<Option<FoundPlane>, Error> {
    let done = mirrored(completer, cloud, None, OrientMode::Auto, tuning)?;
    let Some(plane) = done.plane else {
        return Ok(None);
    };
    let point = done.frame.to_input([plane.offset, 0.0, 0.0]);
    let ahead = done.frame.to_input([plane.offset + 1.0, 0.0, 0.0]);
    let n = [0, 1, 2].map(|i| ahead[i] - point[i]);
    let norm = n.iter().map(|v| v * v).sum::<f64>().sqrt();
    Ok(Some(FoundPlane {
        point,
        normal: n.map(|v| v / norm),
    }))
}

/// What `complete` (the network method, everything estimated) made of one turned real scan,
/// across the vehicle's width in the completion's own frame.
#[derive(Debug, Serialize)]
struct Turned {
    scan: String,
    turn: f64,
    /// The output's extent across the width over the scan's length.
    width_over_length: f64,
    /// The same for the 0.5–99.5 % of its points across the width.
    body_width_over_length: f64,
    /// How far the output reaches beyond the scan's own extent across the width, either side,
    /// over the scan's length.
    beyond_scan: f64,
    /// Distance of this plane, turned back, from the plane of the scan as it is (input units).
    plane_apart: Option<f64>,
    fit: Option<String>,
    warnings: Vec<String>,
}

fn extent(points: &[[f64; 3]], axis: usize) -> (f64, f64) {
    points
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
            (lo.min(p[axis]), hi.max(p[axis]))
        })
}

/// `completion`'s width over length (its whole extent across, and that of the 0.5–99.5 % of
/// its points, which leaves out a wing mirror's few points and stray ones) and its reach
/// beyond the scan, in its own frame.
fn across(completion: &Completion) -> (f64, f64, f64) {
    let (in_lo, in_hi) = extent(&completion.input_normalized, 0);
    let (out_lo, out_hi) = extent(&completion.normalized, 0);
    let (z_lo, z_hi) = extent(&completion.input_normalized, 2);
    let length = z_hi - z_lo;
    let beyond = (out_hi - in_hi).max(in_lo - out_lo).max(0.0);
    let mut xs: Vec<f64> = completion.normalized.iter().map(|p| p[0]).collect();
    let body = quantile(&mut xs, 0.995) - quantile(&mut xs, 0.005);
    ((out_hi - out_lo) / length, body / length, beyond / length)
}

fn real_scans(
    completer: &Completer,
    dir: &str,
    seed: u64,
    turns: usize,
    tuning: &Tuning,
) -> Result<Vec<Turned>, Error> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "pcd"))
        .collect();
    files.sort();
    let mut rng = Lcg::new(seed);
    let mut rows = Vec::new();
    println!(
        "{:<12} {:>7} {:>6} {:>6} {:>7} {:>9} {:<9} warnings",
        "scan", "turn", "w/l", "body", "beyond", "apart m", "fit"
    );
    for path in &files {
        let cloud = read_cloud(path, None)?.cloud;
        let name = path.file_name().unwrap_or_default().to_string_lossy();
        let own = plane_of(completer, &cloud, tuning)?;
        let pivot = cloud.bounds().map_or([0.0; 3], |b| b.center());
        for _ in 0..turns {
            let turn = rng.range(-180.0, 180.0);
            let rotated = PointCloud {
                positions: cloud
                    .positions
                    .iter()
                    .map(|&p| turned(p, turn, pivot))
                    .collect(),
                ..cloud.clone()
            };
            let found = plane_of(completer, &rotated, tuning)?;
            let plane_apart = match (&own, &found) {
                (Some(own), Some(found)) => {
                    let point = turned(found.point, -turn, pivot);
                    Some(
                        (0..3)
                            .map(|i| own.normal[i] * (point[i] - own.point[i]))
                            .sum::<f64>()
                            .abs(),
                    )
                }
                _ => None,
            };
            let done = completed(
                completer,
                &rotated,
                None,
                OrientMode::Auto,
                Method::Network,
                tuning,
            )?;
            let (width_over_length, body_width_over_length, beyond_scan) = across(&done);
            let row = Turned {
                scan: name.to_string(),
                turn,
                width_over_length,
                body_width_over_length,
                beyond_scan,
                plane_apart,
                fit: done.plane.map(|p| format!("{:?}", p.fit)),
                warnings: done.warnings.clone(),
            };
            println!(
                "{:<12} {:>6.1}° {:>6.3} {:>6.3} {:>6.2}% {:>9} {:<9} {}",
                row.scan,
                row.turn,
                row.width_over_length,
                row.body_width_over_length,
                100.0 * row.beyond_scan,
                row.plane_apart.map_or("-".into(), |d| format!("{d:.4}")),
                row.fit.as_deref().unwrap_or("none"),
                row.warnings.join(" | ")
            );
            rows.push(row);
        }
    }
    Ok(rows)
}

fn main() -> Result<(), Error> {
    let tuning = match arg("--tuning") {
        Some(path) => Tuning::read(Path::new(&path))?,
        None => Tuning::default(),
    };
    if let Some(dir) = arg("--mls") {
        let completer = Completer::builtin(Device::flex())?;
        let seed = arg("--seed").map_or(Ok(1), |s| s.parse())?;
        let turns = arg("--turns").map_or(Ok(8), |s| s.parse())?;
        let rows = real_scans(&completer, &dir, seed, turns, &tuning)?;
        if let Some(path) = arg("--json") {
            std::fs::write(path, serde_json::to_string_pretty(&rows)?)?;
        }
        return Ok(());
    }
    let data = PathBuf::from(arg("--data").ok_or("--data DIR is required")?);
    let flag = |name: &str| std::env::args().any(|a| a == name);
    let run = Run {
        given: Given {
            width: flag("--true-width"),
            heading: flag("--true-heading"),
        },
        tuning,
        network: flag("--network"),
    };
    let kind = arg("--kind");
    let limit: usize = arg("--limit").map_or(Ok(usize::MAX), |l| l.parse())?;
    let manifest: Manifest =
        serde_json::from_str(&std::fs::read_to_string(data.join("manifest.json"))?)?;
    let layout = Layout { root: data.clone() };
    let completer = Completer::builtin(Device::flex())?;
    let jobs: Vec<_> = manifest
        .models
        .iter()
        .filter(|m| m.split == TEST)
        .flat_map(|m| m.samples.iter().map(move |s| (m, s)))
        .filter(|(_, s)| kind.as_deref().is_none_or(|k| k == s.spec.protocol()))
        .take(limit)
        .collect();
    let samples: Vec<Sample> = jobs
        .par_iter()
        .map(|(model, sample)| {
            let clouds = layout.clouds(&model.split, &model.category, &model.name);
            let gt = read_cloud(&clouds.join(GT_FINE), None)?.cloud.positions;
            let partial = clouds.join(format!("partial_{}.ply", sample.k));
            let name = format!("{}/{}/partial_{}", model.category, model.name, sample.k);
            let names = (name, model.category.clone());
            measure(&completer, names, &partial, &gt, &sample.spec, &run)
        })
        .collect::<Result<_, Error>>()?;

    let mut groups: BTreeMap<String, Vec<&Sample>> = BTreeMap::new();
    for s in &samples {
        for key in [
            format!("kind {}", s.kind),
            format!("category {}", s.category),
            format!("fit {}", s.fit.as_deref().unwrap_or("none")),
            "all".into(),
        ] {
            groups.entry(key).or_default().push(s);
        }
    }
    println!(
        "{:<22} {:>5} {:>4} {:>8} {:>8} {:>7} {:>7} {:>8} {:>8} {:>8}",
        "group",
        "n",
        "none",
        "off med",
        "off p95",
        "ang med",
        "ang p95",
        "F1 part",
        "F1 mirr",
        "F1 true"
    );
    let report: BTreeMap<&String, Group> = groups.iter().map(|(k, v)| (k, group(v))).collect();
    for (key, g) in &report {
        println!(
            "{:<22} {:>5} {:>4} {:>7.2}% {:>7.2}% {:>6.2}° {:>6.2}° {:>8.4} {:>8.4} {:>8.4}",
            key,
            g.samples,
            g.no_plane,
            100.0 * g.offset_median,
            100.0 * g.offset_p95,
            g.angle_median,
            g.angle_p95,
            g.f1_partial,
            g.f1_mirror,
            g.f1_true
        );
    }
    if let Some(path) = arg("--json") {
        let json = serde_json::json!({ "groups": report, "samples": samples });
        std::fs::write(path, serde_json::to_string_pretty(&json)?)?;
    }
    Ok(())
}
