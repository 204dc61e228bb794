//! Measures the symmetry plane (docs/completing.md, *How well the plane is placed*): every test
//! partial of a `prepare` data directory is completed with `--method mirror` (everything
//! estimated, as `mvpcc complete --method mirror` does), the estimated plane is compared with
//! the true one (the generated objects are symmetric about x = 0 of their own frame), and the
//! mirror completion is scored next to the mirror about the true plane, by partial kind,
//! category and how the plane was found (`fit`). With `--true-width` every partial is
//! completed as `complete --vehicle-width W` would with its object's true width (the ground
//! truth's x extent), which measures what knowing the width is worth.
//!
//! Real scans given with `--mls DIR` (PCD, y up) are completed the same way, as they are and
//! turned by five random headings: the plane's fit, the far side's measured extent against
//! the mirrored near flank (metres; above zero, measured far points stick out beyond the
//! mirror image, so the plane sits too near the scanned side), and how far the planes found
//! on the turned scans, turned back, lie from the plane of the scan as it is.
//!
//! `cargo run --release --example symmetry -- --data DATA [--true-width] [--limit N]
//! [--json FILE] [--mls DIR] [--seed N]`
//!
//! Choices are made on the validation split (`scripts/judge-leg.sh` makes it in target/valset;
//! small gains are checked on three more seeds, docs/completing.md); the test split is measured
//! once, for the report.

use burn::tensor::Device;
use mvpcc::complete::orient::OrientMode;
use mvpcc::complete::symmetry::mirror;
use mvpcc::complete::{Completer, Completion, Method, Options, Settings};
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
    /// F1@0.01 of the partial alone, of the mirror completion and of the mirror about the
    /// true plane.
    f1_partial: f64,
    f1_mirror: f64,
    f1_true: f64,
}

/// `complete --method mirror` with everything estimated.
fn mirrored(
    completer: &Completer,
    cloud: &PointCloud,
    vehicle_width: Option<f64>,
) -> Result<Completion, Error> {
    let settings = Settings {
        clean: false,
        orient: OrientMode::Auto,
        options: Options {
            method: Method::Mirror,
            vehicle_width,
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
    given_width: bool,
) -> Result<Sample, Error> {
    let cloud = read_cloud(partial, None)?.cloud;
    let bounds = Aabb::of(gt).ok_or("empty ground truth")?;
    let width = given_width.then(|| bounds.max[0] - bounds.min[0]);
    let completion = mirrored(completer, &cloud, width)?;
    let measured = spec.points_to_object_frame(&cloud.positions);
    let completed = spec.points_to_object_frame(&completion.cloud.positions);
    let length = bounds.longest_side();
    let seen_side = measured.iter().map(|p| p[0]).sum::<f64>().signum();
    let (offset, angle, towards_scanner, towards_seen) = match completion.plane {
        Some(plane) => {
            let frame = &completion.frame;
            let [on, ahead] = [plane.offset, plane.offset + 1.0]
                .map(|x| frame.to_input([x, 0.0, 0.0]))
                .map(|p| spec.points_to_object_frame(&[p])[0]);
            let n = [0, 1, 2].map(|i| ahead[i] - on[i]);
            let norm = n.iter().map(|v| v * v).sum::<f64>().sqrt();
            let n = n.map(|v| v / norm);
            let centre = [0.0, bounds.center()[1], bounds.center()[2]];
            let distance = (0..3).map(|i| n[i] * (centre[i] - on[i])).sum::<f64>();
            let angle = n[0].abs().min(1.0).acos().to_degrees();
            let x = on[0] - (n[1] * (centre[1] - on[1]) + n[2] * (centre[2] - on[2])) / n[0];
            let side = match spec {
                PartialSpec::Scanner { side, .. } => Some(f64::from(*side)),
                PartialSpec::Cameras { .. } => None,
            };
            (
                Some(distance.abs() / length),
                Some(angle),
                side.map(|s| s * x / length),
                Some(seen_side * x / length),
            )
        }
        None => (None, None, None, None),
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
        f1_partial: f1(&measured, gt),
        f1_mirror: f1(&completed, gt),
        f1_true: f1(&true_mirror(&measured, tolerance), gt),
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

/// A completion's plane in the input's coordinates (a point on it and its unit normal), its
/// fit, and the far side's measured extent beyond the mirrored near flank, in input units.
struct FoundPlane {
    point: [f64; 3],
    normal: [f64; 3],
    fit: String,
    far_beyond_mirror: f64,
}

fn plane_of(completer: &Completer, cloud: &PointCloud) -> Result<Option<FoundPlane>, Error> {
    let done = mirrored(completer, cloud, None)?;
    let Some(plane) = done.plane else {
        return Ok(None);
    };
    let c = plane.offset;
    let xs: Vec<f64> = done.input_normalized.iter().map(|p| p[0] - c).collect();
    let mean = xs.iter().sum::<f64>() / xs.len() as f64;
    let side = mean.signum();
    let mut near: Vec<f64> = xs.iter().map(|x| x * side).filter(|x| *x > 0.0).collect();
    let mut far: Vec<f64> = xs.iter().map(|x| -x * side).filter(|x| *x > 0.0).collect();
    let far_beyond_mirror =
        (quantile(&mut far, 0.98) - quantile(&mut near, 0.98)) * done.frame.extent;
    let point = done.frame.to_input([c, 0.0, 0.0]);
    let ahead = done.frame.to_input([c + 1.0, 0.0, 0.0]);
    let n = [0, 1, 2].map(|i| ahead[i] - point[i]);
    let norm = n.iter().map(|v| v * v).sum::<f64>().sqrt();
    Ok(Some(FoundPlane {
        point,
        normal: n.map(|v| v / norm),
        fit: format!("{:?}", plane.fit),
        far_beyond_mirror,
    }))
}

fn real_scans(completer: &Completer, dir: &str, seed: u64) -> Result<(), Error> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "pcd"))
        .collect();
    files.sort();
    let mut rng = Lcg::new(seed);
    for path in &files {
        let cloud = read_cloud(path, None)?.cloud;
        let name = path.file_name().unwrap_or_default().to_string_lossy();
        let Some(own) = plane_of(completer, &cloud)? else {
            println!("{name:<12} no plane");
            continue;
        };
        let pivot = cloud.bounds().map_or([0.0; 3], |b| b.center());
        let mut apart: Vec<f64> = Vec::new();
        let mut angles: Vec<f64> = Vec::new();
        for _ in 0..5 {
            let turn = rng.range(-180.0, 180.0);
            let rotated = PointCloud {
                positions: cloud
                    .positions
                    .iter()
                    .map(|&p| turned(p, turn, pivot))
                    .collect(),
                ..cloud.clone()
            };
            let Some(found) = plane_of(completer, &rotated)? else {
                apart.push(f64::INFINITY);
                continue;
            };
            let point = turned(found.point, -turn, pivot);
            let normal = turned(found.normal, -turn, [0.0; 3]);
            let dot = (0..3).map(|i| normal[i] * own.normal[i]).sum::<f64>();
            angles.push(dot.abs().min(1.0).acos().to_degrees());
            apart.push(
                (0..3)
                    .map(|i| own.normal[i] * (point[i] - own.point[i]))
                    .sum::<f64>()
                    .abs(),
            );
        }
        let worst = |v: &[f64]| v.iter().copied().fold(0.0, f64::max);
        println!(
            "{name:<12} fit {:<9} far side beyond the mirrored near flank {:>6.3} m; turned ×5: planes within {:.4} m, {:.3}°",
            own.fit,
            own.far_beyond_mirror,
            worst(&apart),
            worst(&angles)
        );
    }
    Ok(())
}

fn main() -> Result<(), Error> {
    if let Some(dir) = arg("--mls") {
        let completer = Completer::builtin(Device::flex())?;
        let seed = arg("--seed").map_or(Ok(1), |s| s.parse())?;
        return real_scans(&completer, &dir, seed);
    }
    let data = PathBuf::from(arg("--data").ok_or("--data DIR is required")?);
    let given_width = std::env::args().any(|a| a == "--true-width");
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
            measure(&completer, names, &partial, &gt, &sample.spec, given_width)
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
