//! Measures the orientation stage (docs/pipeline.md, *3. Heading, roll and the network's pose*):
//! every partial of a `prepare` test split is turned by a random yaw, the estimators' heading errors are collected, and the
//! completion of the turned partial (`--orient auto`, turned back) is scored like `mvpcc eval
//! --data` next to the completions of the partial as it is (`--orient none`, the pipeline
//! before orientation existed, and `--orient auto`). Real scans given with `--mls` are turned by random yaws too, and their completions,
//! turned back, are compared with the completion of the scan as it is; then cluttered with what
//! segmentation leaves (ground, noise points, a piece of a neighbour) to measure orientation with
//! and without `--clean`, and what `--clean` removes.
//!
//! `cargo run --release --example orientation -- --data EVALSET [--mls DIR] [--seed N]
//! [--limit N] [--orienter FILE] [--model FILE] [--headings-only]`

use burn::tensor::Device;
use mvpcc::complete::clean::{clean, CleanParams};
use mvpcc::complete::orient::{
    angle_between, orient, OrientMode, OrientParams, Orientation, Orienter,
};
use mvpcc::complete::symmetry::SymmetryParams;
use mvpcc::complete::{Completer, Options, Settings, Source};
use mvpcc::core::cloud::PointCloud;
use mvpcc::core::frame::{Frame, UpAxis};
use mvpcc::core::rng::Lcg;
use mvpcc::datagen::data::{Layout, Manifest, ModelEntry, SampleEntry, TEST};
use mvpcc::datagen::scan::PartialSpec;
use mvpcc::io::read_cloud;
use mvpcc::metrics::compare_clouds;
use mvpcc::train::orient::OrientScores;
use std::collections::{BTreeMap, HashSet};
use std::path::{Path, PathBuf};

type Error = Box<dyn std::error::Error>;

/// A car's length in metres, for the clutter's sizes around the unit-length real scans.
const CAR_LENGTH: f64 = 4.5;

const MODES: [(&str, OrientMode); 3] = [
    ("geometric", OrientMode::Geometric),
    ("learned", OrientMode::Learned),
    ("combined", OrientMode::Combined),
];

/// [`orient`] of an upright (y up) cloud with the default tunables.
fn orient_y(cloud: &PointCloud, mode: OrientMode, orienter: Option<&Orienter>) -> Orientation {
    let defaults = (OrientParams::default(), SymmetryParams::default());
    orient(cloud, UpAxis::Y, mode, orienter, &defaults.0, &defaults.1)
}

fn arg(name: &str) -> Option<String> {
    let args: Vec<String> = std::env::args().collect();
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1).cloned())
}

/// The cloud turned counter-clockwise (seen from above, y up) by `turn` degrees about the
/// vertical through `pivot`.
fn turned(cloud: &PointCloud, turn: f64, pivot: [f64; 3]) -> PointCloud {
    let (s, c) = turn.to_radians().sin_cos();
    PointCloud {
        positions: cloud
            .positions
            .iter()
            .map(|p| {
                let (x, z) = (p[0] - pivot[0], p[2] - pivot[2]);
                [pivot[0] + c * x + s * z, p[1], pivot[2] - s * x + c * z]
            })
            .collect(),
        ..cloud.clone()
    }
}

/// What a segmentation leaves around a y-up scan of `n` points: a ground patch under it
/// reaching 0.6 m past its footprint (0.3·n points, ±1 cm), 15 noise points up to 2 m around
/// it, and a 1 × 1.5 m piece of a neighbouring vehicle's side 0.4 m past its +x end (0.05·n
/// points), uniformly random. Returns the counts added. The scans are of cars normalized to
/// about unit length, so a metre is taken as [`CAR_LENGTH`]'s share of the scan's longest side.
fn clutter(cloud: &PointCloud, rng: &mut Lcg) -> (PointCloud, [usize; 3]) {
    let b = cloud.bounds().expect("a scan has points");
    let metre = b.longest_side() / CAR_LENGTH;
    let n = cloud.len();
    let mut positions = cloud.positions.clone();
    let ground = 3 * n / 10;
    for _ in 0..ground {
        positions.push([
            rng.range(b.min[0] - 0.6 * metre, b.max[0] + 0.6 * metre),
            b.min[1] + (-0.02 + 0.01 * rng.gauss()) * metre,
            rng.range(b.min[2] - 0.6 * metre, b.max[2] + 0.6 * metre),
        ]);
    }
    let noise = 15;
    for _ in 0..noise {
        positions
            .push([0, 1, 2].map(|i| rng.range(b.min[i] - 2.0 * metre, b.max[i] + 2.0 * metre)));
    }
    let other = n / 20;
    let zc = rng.range(b.min[2], b.max[2]);
    for _ in 0..other {
        positions.push([
            b.max[0] + 0.4 * metre,
            b.min[1] + rng.range(0.0, 1.5) * metre,
            zc + rng.range(0.0, 1.0) * metre,
        ]);
    }
    let colors = cloud.colors.as_ref().map(|c| {
        let mut c = c.clone();
        c.resize(positions.len(), [90, 90, 90]);
        c
    });
    (
        PointCloud {
            positions,
            colors,
            ..PointCloud::default()
        },
        [ground, noise, other],
    )
}

/// `cloud` completed with the default options and the heading `orient` finds.
fn completed(
    completer: &Completer,
    cloud: &PointCloud,
    orient: OrientMode,
) -> Result<PointCloud, Error> {
    let settings = Settings {
        clean: false,
        orient,
        options: Options::default(),
    };
    Ok(completer.run(cloud, &settings)?.completion.cloud)
}

/// Heading of the object's front (−z in its ground truth's frame) in a partial's own frame:
/// scanner partials are stored in the simulated drive's frame, up to ±10° off the object's axis.
fn heading_in_partial(spec: &PartialSpec) -> f64 {
    let columns =
        [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]].map(|e| spec.to_object_frame(e));
    // The partial-frame direction of the front: the transposed map applied to (0, 0, −1).
    let front = columns.map(|c| -f64::from(c[2]));
    (-front[2]).atan2(front[0]).to_degrees().rem_euclid(360.0)
}

fn summary(label: &str, errors: &mut [f64]) {
    let s = OrientScores::of(errors);
    println!(
        "{label:<28} n {:>4}  median {:>6.2}°  p95 {:>7.2}°  flips {:>5.1} %",
        errors.len(),
        s.median,
        s.p95,
        100.0 * s.flips
    );
}

/// One generated partial turned by a random yaw about its box's centre.
struct Turned<'a> {
    model: &'a ModelEntry,
    sample: &'a SampleEntry,
    cloud: PointCloud,
    rotated: PointCloud,
    turn: f64,
    pivot: [f64; 3],
}

/// What the generated partials measured: heading errors and (cd_l2_half, F1@0.01) of
/// completions, each under the labels it is summarized by.
#[derive(Default)]
struct Generated {
    count: usize,
    errors: BTreeMap<String, Vec<f64>>,
    quality: BTreeMap<String, Vec<(f64, f64)>>,
}

impl Generated {
    /// Each estimator's heading error on the turned partial, with and without its refinement.
    fn headings(&mut self, p: &Turned, orienter: &Orienter) {
        let truth = (heading_in_partial(&p.sample.spec) + p.turn).rem_euclid(360.0);
        let protocol = p.sample.spec.protocol();
        for (name, mode) in MODES {
            let found = orient_y(&p.rotated, mode, Some(orienter));
            let heading = found.heading.unwrap_or(f64::NAN);
            let unrefined = heading - found.refinement.unwrap_or(0.0);
            for (name, e) in [
                (name.to_string(), angle_between(heading, truth)),
                (
                    format!("{name}, unrefined"),
                    angle_between(unrefined, truth),
                ),
            ] {
                for key in [
                    name.clone(),
                    format!("{name} {}", p.model.category),
                    format!("{name} ({protocol})"),
                ] {
                    self.errors.entry(key).or_default().push(e);
                }
            }
        }
    }

    /// The partial completed as it is (each heading source) and turned, scored as `mvpcc eval
    /// --data` scores: back in the object's frame, against its ground truth.
    fn completions(
        &mut self,
        p: &Turned,
        gt: &PointCloud,
        completer: &Completer,
    ) -> Result<(), Error> {
        let spec = &p.sample.spec;
        let protocol = spec.protocol();
        let score = |completed: &PointCloud| {
            let pred = spec.points_to_object_frame(&completed.positions);
            let m = compare_clouds(&pred, &gt.positions, &[0.01]);
            (m.cd_l2_half, m.fscores[0].f1)
        };
        let mut record = |label: &str, value: (f64, f64)| {
            for key in [label.to_string(), format!("{label} ({protocol})")] {
                self.quality.entry(key).or_default().push(value);
            }
        };
        let plain = completed(completer, &p.cloud, OrientMode::None)?;
        record("as is, --orient none", score(&plain));
        for (label, mode) in [("auto", OrientMode::Auto), ("learned", OrientMode::Learned)] {
            let done = completed(completer, &p.cloud, mode)?;
            record(&format!("as is, --orient {label}"), score(&done));
        }
        let truth = OrientMode::Heading(heading_in_partial(spec));
        let exact = completed(completer, &p.cloud, truth)?;
        record("as is, the true heading", score(&exact));
        let auto = completed(completer, &p.rotated, OrientMode::Auto)?;
        let back = turned(&auto, -p.turn, p.pivot);
        record("turned, --orient auto", score(&back));
        Ok(())
    }

    fn print(&mut self) {
        println!(
            "heading error on {} generated partials, random yaw:",
            self.count
        );
        for (label, e) in self.errors.iter_mut() {
            summary(label, e);
        }
        println!("completion quality against the ground truth (cd_l2_half, F1@0.01):");
        for (label, q) in &self.quality {
            let n = q.len() as f64;
            let cd = q.iter().map(|v| v.0).sum::<f64>() / n;
            let f1 = q.iter().map(|v| v.1).sum::<f64>() / n;
            println!("{label:<40} n {:>4}  CD {cd:.3e}  F1 {f1:.4}", q.len());
        }
    }
}

/// The first `limit` test partials of `data`, each turned by a random yaw.
fn generated(
    data: &Path,
    completer: &Completer,
    rng: &mut Lcg,
    limit: usize,
    headings_only: bool,
) -> Result<Generated, Error> {
    let orienter = completer.orienter().expect("the example loads one");
    let manifest: Manifest =
        serde_json::from_str(&std::fs::read_to_string(data.join("manifest.json"))?)?;
    let layout = Layout {
        root: data.to_path_buf(),
    };
    let mut measured = Generated::default();
    for model in manifest.models.iter().filter(|m| m.split == TEST) {
        let dir = layout.clouds(&model.split, &model.category, &model.name);
        let gt = read_cloud(&dir.join("gt.ply"), None)?.cloud;
        for sample in &model.samples {
            if measured.count == limit {
                break;
            }
            measured.count += 1;
            let cloud = read_cloud(&dir.join(format!("partial_{}.ply", sample.k)), None)?.cloud;
            let turn = rng.range(-180.0, 180.0);
            let pivot = cloud.bounds().map_or([0.0; 3], |b| b.center());
            let rotated = turned(&cloud, turn, pivot);
            let partial = Turned {
                model,
                sample,
                cloud,
                rotated,
                turn,
                pivot,
            };
            measured.headings(&partial, orienter);
            if !headings_only {
                measured.completions(&partial, &gt, completer)?;
            }
        }
    }
    Ok(measured)
}

fn file_name(path: &Path) -> std::borrow::Cow<'_, str> {
    path.file_name().unwrap_or_default().to_string_lossy()
}

/// Each real scan turned by five random yaws: the heading against the scan's own, turned, and
/// the completion, turned back, against the completion of the scan as it is.
fn real_turned(files: &[PathBuf], completer: &Completer, rng: &mut Lcg) -> Result<(), Error> {
    let orienter = completer.orienter().expect("the example loads one");
    println!("real scans turned by random yaws (CD between turned-back and as-is completions):");
    let mut mls_errors = Vec::new();
    for path in files {
        let cloud = read_cloud(path, None)?.cloud;
        let pivot = cloud.bounds().map_or([0.0; 3], |b| b.center());
        let heading = orient_y(&cloud, OrientMode::Auto, Some(orienter)).heading;
        let plain = completed(completer, &cloud, OrientMode::Auto)?;
        // The scans are only roughly in the canonical pose (heading 90°), so the turned
        // scans' headings are checked against the scan's own estimate, turned.
        let own = heading.unwrap_or(90.0);
        println!(
            "{:<12} as is: heading {own:.2}° ({:.2}° from the canonical 90°)",
            file_name(path),
            angle_between(own, 90.0)
        );
        for _ in 0..5 {
            let turn = rng.range(-180.0, 180.0);
            let rotated = turned(&cloud, turn, pivot);
            let found = orient_y(&rotated, OrientMode::Auto, Some(orienter)).heading;
            let e = angle_between(found.unwrap_or(f64::NAN), own + turn);
            mls_errors.push(e);
            let done = completed(completer, &rotated, OrientMode::Auto)?;
            let back = turned(&done, -turn, pivot);
            let frame = Frame::fit(&cloud, UpAxis::Y)?;
            let m = compare_clouds(
                &frame.normalize(&back).positions,
                &frame.normalize(&plain).positions,
                &[0.01],
            );
            println!(
                "{:<12} turn {turn:>7.1}°  heading vs as is + turn {e:>6.2}°  CD {:.3e}  F1@0.01 {:.4}  points {} vs {}",
                file_name(path),
                m.cd_l2_half,
                m.fscores[0].f1,
                back.len(),
                plain.len()
            );
        }
    }
    summary("real scans, auto vs as is + turn", &mut mls_errors);
    Ok(())
}

/// Each real scan turned by five random yaws and cluttered: the heading with and without
/// `--clean`, and what the cleaning removed of the clutter and of the scan.
fn real_cluttered(files: &[PathBuf], orienter: &Orienter, rng: &mut Lcg) -> Result<(), Error> {
    println!(
        "the same scans with clutter (ground, noise, a neighbour), auto heading vs as is + turn:"
    );
    let mut raw_errors = Vec::new();
    let mut clean_errors = Vec::new();
    for path in files {
        let cloud = read_cloud(path, None)?.cloud;
        let pivot = cloud.bounds().map_or([0.0; 3], |b| b.center());
        let own = orient_y(&cloud, OrientMode::Auto, Some(orienter))
            .heading
            .unwrap_or(90.0);
        for _ in 0..5 {
            let turn = rng.range(-180.0, 180.0);
            let rotated = turned(&cloud, turn, pivot);
            let (cluttered, added) = clutter(&rotated, rng);
            let raw = orient_y(&cluttered, OrientMode::Auto, Some(orienter));
            let (cleaned, report) = clean(&cluttered, UpAxis::Y, &CleanParams::default());
            let after = orient_y(&cleaned, OrientMode::Auto, Some(orienter));
            let (e_raw, e_clean) = [raw, after]
                .map(|o| angle_between(o.heading.unwrap_or(f64::NAN), own + turn))
                .into();
            raw_errors.push(e_raw);
            clean_errors.push(e_clean);
            let kept = kept_of(&rotated, &cleaned);
            println!(
                "{:<12} turn {turn:>7.1}°  error {e_raw:>6.2}° as is, {e_clean:>6.2}° cleaned;  removed ground {}/{}  isolated {}/{}  other objects {}/{}  clutter left {}  scan points lost {}/{}",
                file_name(path),
                report.ground,
                added[0],
                report.isolated,
                added[1],
                report.other_objects,
                added[2],
                cleaned.len() - kept,
                rotated.len() - kept,
                rotated.len()
            );
        }
    }
    summary("cluttered scans, auto", &mut raw_errors);
    summary("cluttered scans, --clean, auto", &mut clean_errors);
    Ok(())
}

/// How many of `scan`'s points `cleaned` still holds, exactly.
fn kept_of(scan: &PointCloud, cleaned: &PointCloud) -> usize {
    let scan: HashSet<[u64; 3]> = scan.positions.iter().map(|p| p.map(f64::to_bits)).collect();
    cleaned
        .positions
        .iter()
        .filter(|p| scan.contains(&p.map(f64::to_bits)))
        .count()
}

/// The built-in models, or the files `--model` and `--orienter` name.
fn load_completer() -> Result<Completer, Error> {
    let (model, orienter) = (arg("--model"), arg("--orienter"));
    fn source(path: &Option<String>) -> Source<'_> {
        path.as_ref()
            .map_or(Source::Builtin, |p| Source::File(Path::new(p)))
    }
    let completer = Completer::load(source(&model), source(&orienter), Device::flex(), None)?;
    Ok(completer)
}

fn pcd_files(dir: &str) -> Result<Vec<PathBuf>, Error> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "pcd"))
        .collect();
    files.sort();
    Ok(files)
}

fn main() -> Result<(), Error> {
    let data = PathBuf::from(arg("--data").ok_or("--data EVALSET is required")?);
    let seed: u64 = arg("--seed").map_or(Ok(1), |s| s.parse())?;
    let limit: usize = arg("--limit").map_or(Ok(usize::MAX), |s| s.parse())?;
    let headings_only = std::env::args().any(|a| a == "--headings-only");
    let completer = load_completer()?;
    let mut rng = Lcg::new(seed);
    generated(&data, &completer, &mut rng, limit, headings_only)?.print();
    if let Some(mls) = arg("--mls") {
        let files = pcd_files(&mls)?;
        real_turned(&files, &completer, &mut rng)?;
        let orienter = completer.orienter().expect("the example loads one");
        real_cluttered(&files, orienter, &mut rng)?;
    }
    Ok(())
}
