use super::{load, Log};
use crate::cli::args::{EvalArgs, GroundTruth, Metric, Normalize};
use crate::cli::streams::say;
use anyhow::{bail, Context};
use mvpcc::core::cloud::PointCloud;
use mvpcc::core::frame::{Frame, UpAxis};
use mvpcc::datagen::data::{coarse, Layout, Manifest, GT_COARSE, GT_FINE, MANIFEST_FILE, TEST};
use mvpcc::datagen::scan::PartialSpec;
use mvpcc::io::batch::{self, walk};
use mvpcc::io::Format;
use mvpcc::metrics::{compare_clouds, compare_images, CloudMetrics, FScore, ImageMetrics};
use mvpcc::views::projection::CHANNELS;
use mvpcc::views::{find_views, read_views};
use serde::Serialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

struct Pair {
    name: String,
    pred: PathBuf,
    gt: PathBuf,
}

/// The clouds under `dir` (walked as `complete --input-dir` walks), keyed by their path
/// relative to `dir` without the extension, so a batch's output tree pairs with its ground
/// truth's; those under `other` (the other side's folder) are left out where it lies inside
/// `dir`, as a batch's outputs inside its inputs do.
fn cloud_files(
    dir: &Path,
    other: &Path,
    format: Option<Format>,
) -> anyhow::Result<BTreeMap<String, PathBuf>> {
    let nested = batch::nested_dir(dir, other);
    let relative = walk(dir, |path| {
        (format.is_some() || Format::from_path(path).is_ok())
            && nested.as_ref().is_none_or(|n| !batch::lies_in(path, n))
    })?;
    let mut files = BTreeMap::new();
    for path in relative {
        let key = path.with_extension("").to_string_lossy().into_owned();
        let path = dir.join(path);
        if let Some(other) = files.insert(key.clone(), path.clone()) {
            bail!(
                "{}: two clouds share the name '{key}' ({} and {})",
                dir.display(),
                other.display(),
                path.display()
            );
        }
    }
    Ok(files)
}

/// How many `names` there are and the first few, so a whole tree that does not match is still
/// one readable line.
fn some_of(names: &[&str]) -> String {
    const SHOWN: usize = 5;
    let shown = names[..names.len().min(SHOWN)].join(", ");
    match names.len() {
        0 => "none".to_string(),
        n if n <= SHOWN => format!("{n} [{shown}]"),
        n => format!("{n} [{shown}, …]"),
    }
}

fn matched_pairs(
    pred_dir: &Path,
    gt_dir: &Path,
    format: Option<Format>,
) -> anyhow::Result<Vec<Pair>> {
    let preds = cloud_files(pred_dir, gt_dir, format)?;
    let gts = cloud_files(gt_dir, pred_dir, format)?;
    let only_pred: Vec<&str> = preds
        .keys()
        .filter(|k| !gts.contains_key(*k))
        .map(|s| s.as_str())
        .collect();
    let only_gt: Vec<&str> = gts
        .keys()
        .filter(|k| !preds.contains_key(*k))
        .map(|s| s.as_str())
        .collect();
    if !only_pred.is_empty() || !only_gt.is_empty() {
        bail!(
            "{} and {}: unmatched file stems: only in predictions: {}; only in ground truth: {}",
            pred_dir.display(),
            gt_dir.display(),
            some_of(&only_pred),
            some_of(&only_gt)
        );
    }
    if preds.is_empty() {
        bail!("{}: no point cloud files", pred_dir.display());
    }
    Ok(preds
        .into_iter()
        .map(|(name, pred)| {
            let gt = gts[&name].clone();
            Pair { name, pred, gt }
        })
        .collect())
}

fn score(pair: &Pair, args: &EvalArgs, log: Log) -> anyhow::Result<CloudMetrics> {
    let mut pred = load(&pair.pred, args.input.format, log)?;
    let mut gt = load(&pair.gt, args.input.format, log)?;
    if args.normalize == Normalize::GtBox {
        let frame = Frame::fit(&gt, UpAxis::Y).with_context(|| pair.gt.display().to_string())?;
        let map = |c: &PointCloud| PointCloud::from_positions(frame.normalize(c).positions);
        pred = map(&pred);
        gt = map(&gt);
    }
    Ok(compare_clouds(&pred.positions, &gt.positions, &args.tau))
}

/// A cloud's scores as `--json` prints them: the metrics `--metrics` asked for.
#[derive(Debug, Serialize)]
struct Scores {
    #[serde(skip_serializing_if = "Option::is_none")]
    cd_l2_half: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    cd_l1: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    cd_l2: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    fscore: Option<Vec<FScore>>,
}

impl Scores {
    fn of(m: &CloudMetrics, metrics: &[Metric]) -> Scores {
        let cd = metrics.contains(&Metric::Cd);
        Scores {
            cd_l2_half: cd.then_some(m.cd_l2_half),
            cd_l1: cd.then_some(m.cd_l1),
            cd_l2: cd.then_some(m.cd_l2),
            fscore: metrics.contains(&Metric::F1).then(|| m.fscores.clone()),
        }
    }
}

/// One pair of clouds of `--pred`/`--gt` or `--pred-dir`/`--gt-dir`.
#[derive(Debug, Serialize)]
struct PairReport {
    name: String,
    pred: PathBuf,
    gt: PathBuf,
    pred_points: usize,
    gt_points: usize,
    #[serde(flatten)]
    scores: Scores,
}

/// View-image scores: the metrics `--metrics` asked for.
#[derive(Debug, Serialize)]
struct ImageScores {
    #[serde(skip_serializing_if = "Option::is_none")]
    psnr_db: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    ssim: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    mae: Option<f64>,
}

impl ImageScores {
    fn of(m: &ImageMetrics, metrics: &[Metric]) -> ImageScores {
        ImageScores {
            psnr_db: metrics.contains(&Metric::Psnr).then_some(m.psnr),
            ssim: metrics.contains(&Metric::Ssim).then_some(m.ssim),
            mae: metrics.contains(&Metric::Mae).then_some(m.mae),
        }
    }
}

#[derive(Debug, Serialize)]
struct ViewsReport {
    #[serde(flatten)]
    mean: ImageScores,
    pred: PathBuf,
    gt: PathBuf,
    cameras: Vec<usize>,
    per_view: Vec<ImageScores>,
}

/// What `eval --json` prints for clouds and views.
#[derive(Debug, Serialize)]
struct EvalReport {
    normalization: Normalize,
    thresholds: Vec<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pairs: Option<Vec<PairReport>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    mean: Option<Scores>,
    #[serde(skip_serializing_if = "Option::is_none")]
    views: Option<ViewsReport>,
}

#[derive(Debug, Serialize)]
struct GroupReport {
    #[serde(flatten)]
    scores: Scores,
    samples: usize,
}

#[derive(Debug, Serialize)]
struct SampleReport {
    #[serde(flatten)]
    scores: Scores,
    name: String,
    protocol: &'static str,
}

/// What `eval --data --json` prints.
#[derive(Debug, Serialize)]
struct DatasetReport {
    data: PathBuf,
    pred_dir: PathBuf,
    ground_truth: GroundTruth,
    thresholds: Vec<f64>,
    groups: BTreeMap<String, GroupReport>,
    samples: Vec<SampleReport>,
}

/// The text tables `eval` prints without `--json`: a left-aligned name column, the others
/// right-aligned.
#[derive(Default)]
struct Table {
    lines: Vec<String>,
}

/// A threshold as a column's label: as written where that is short, in exponent form where
/// it is not (`--tau 1e308` made three 310-character labels).
fn tau_label(tau: f64) -> String {
    let plain = tau.to_string();
    if plain.len() <= 8 {
        plain
    } else {
        format!("{tau:e}")
    }
}

impl Table {
    fn row(&mut self, name: &str, cells: &[String]) {
        let mut line = format!("{name:<24}");
        for c in cells {
            line += &format!(" {c:>12}");
        }
        self.lines.push(line);
    }

    fn blank(&mut self) {
        if !self.lines.is_empty() {
            self.lines.push(String::new());
        }
    }

    fn cloud_header(&mut self, metrics: &[Metric], taus: &[f64]) {
        let mut cells = vec!["pred_pts".to_string(), "gt_pts".to_string()];
        if metrics.contains(&Metric::Cd) {
            cells.extend(["cd_l2_half", "cd_l1", "cd_l2"].map(String::from));
        }
        if metrics.contains(&Metric::F1) {
            for t in taus.iter().map(|&t| tau_label(t)) {
                cells.extend([format!("f1@{t}"), format!("prec@{t}"), format!("rec@{t}")]);
            }
        }
        self.row("name", &cells);
    }

    fn cloud_row(&mut self, name: &str, m: &CloudMetrics, metrics: &[Metric]) {
        let mut cells = vec![m.pred_points.to_string(), m.gt_points.to_string()];
        if metrics.contains(&Metric::Cd) {
            cells.extend([m.cd_l2_half, m.cd_l1, m.cd_l2].map(|v| format!("{v:.6e}")));
        }
        if metrics.contains(&Metric::F1) {
            for f in &m.fscores {
                cells.extend([f.f1, f.precision, f.recall].map(|v| format!("{v:.6}")));
            }
        }
        self.row(name, &cells);
    }
}

fn mean_metrics(all: &[CloudMetrics]) -> CloudMetrics {
    let n = all.len() as f64;
    let avg = |f: &dyn Fn(&CloudMetrics) -> f64| all.iter().map(f).sum::<f64>() / n;
    let mut mean = all[0].clone();
    mean.cd_l2_half = avg(&|m| m.cd_l2_half);
    mean.cd_l1 = avg(&|m| m.cd_l1);
    mean.cd_l2 = avg(&|m| m.cd_l2);
    for (i, f) in mean.fscores.iter_mut().enumerate() {
        f.precision = avg(&|m| m.fscores[i].precision);
        f.recall = avg(&|m| m.fscores[i].recall);
        f.f1 = avg(&|m| m.fscores[i].f1);
    }
    mean.pred_points = all.iter().map(|m| m.pred_points).sum::<usize>() / all.len();
    mean.gt_points = all.iter().map(|m| m.gt_points).sum::<usize>() / all.len();
    mean
}

/// One test partial of a data directory and its completion.
struct DataSample {
    category: String,
    protocol: &'static str,
    name: String,
    pred: PathBuf,
    gt: PathBuf,
    spec: PartialSpec,
}

/// The completion of `<category>/<model>/partial_<k>` in `pred_dir`, whatever its extension.
fn find_prediction(dir: &Path, k: usize) -> Option<PathBuf> {
    let stem = format!("partial_{k}");
    std::fs::read_dir(dir)
        .ok()?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .find(|p| {
            p.file_stem().and_then(|s| s.to_str()) == Some(&stem) && Format::from_path(p).is_ok()
        })
}

/// A model's ground truth; a coarse one that an older `prepare` did not write is sampled from
/// the fine one beside it.
fn load_ground_truth(path: &Path, log: Log) -> anyhow::Result<PointCloud> {
    if path.ends_with(GT_COARSE) && !path.exists() {
        return Ok(coarse(&load(&path.with_file_name(GT_FINE), None, log)?));
    }
    load(path, None, log)
}

fn eval_dataset(data: &Path, pred_dir: &Path, args: &EvalArgs, log: Log) -> anyhow::Result<()> {
    let samples = dataset_samples(data, pred_dir, args.ground_truth)?;
    let bar = super::progress(samples.len(), "eval", log);
    let results = samples
        .iter()
        .map(|s| {
            let scored = score_sample(s, &args.tau, log);
            bar.inc(1);
            scored
        })
        .collect::<anyhow::Result<Vec<CloudMetrics>>>()?;
    bar.finish_and_clear();
    let (report, table) = dataset_report(data, pred_dir, args, &samples, &results);
    print_results(args.json, &report, &table)
}

/// The test partials of the data directory `data` (from `mvpcc prepare`), each with its
/// completion in `pred_dir` and its `ground_truth`; an error when any has no completion.
fn dataset_samples(
    data: &Path,
    pred_dir: &Path,
    ground_truth: GroundTruth,
) -> anyhow::Result<Vec<DataSample>> {
    let manifest = read_manifest(data)?;
    let layout = Layout {
        root: data.to_path_buf(),
    };
    let mut samples = Vec::new();
    let mut missing = Vec::new();
    for model in manifest.models.iter().filter(|m| m.split == TEST) {
        let clouds = layout.clouds(&model.split, &model.category, &model.name);
        let gt = match ground_truth {
            GroundTruth::Fine => clouds.join(GT_FINE),
            GroundTruth::Coarse => clouds.join(GT_COARSE),
        };
        let dir = pred_dir.join(&model.category).join(&model.name);
        for sample in &model.samples {
            let name = format!("{}/{}/partial_{}", model.category, model.name, sample.k);
            match find_prediction(&dir, sample.k) {
                Some(pred) => samples.push(DataSample {
                    category: model.category.clone(),
                    protocol: sample.spec.protocol(),
                    name,
                    pred,
                    gt: gt.clone(),
                    spec: sample.spec.clone(),
                }),
                None => missing.push(name),
            }
        }
    }
    if !missing.is_empty() {
        bail!(
            "{}: no completion for {} of {} test partials (first: {})",
            pred_dir.display(),
            missing.len(),
            missing.len() + samples.len(),
            missing[0]
        );
    }
    if samples.is_empty() {
        bail!("{}: the data has no test partials", data.display());
    }
    Ok(samples)
}

/// The manifest of the data directory `data`, which only a finished `mvpcc prepare` writes.
fn read_manifest(data: &Path) -> anyhow::Result<Manifest> {
    let manifest_path = data.join(MANIFEST_FILE);
    let text = match std::fs::read_to_string(&manifest_path) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => bail!(
            "{}: not a data directory from `mvpcc prepare` (no manifest.json; an interrupted \
             prepare writes it when run again to the end)",
            data.display()
        ),
        read => read.with_context(|| format!("{}: cannot read", manifest_path.display()))?,
    };
    serde_json::from_str(&text)
        .with_context(|| format!("{}: unreadable manifest", manifest_path.display()))
}

/// A completion scored against its ground truth, in the object's frame (a scanner partial is
/// written in its path's).
fn score_sample(sample: &DataSample, tau: &[f64], log: Log) -> anyhow::Result<CloudMetrics> {
    let pred = load(&sample.pred, None, log)?;
    let gt = load_ground_truth(&sample.gt, log)?;
    let turned = sample.spec.points_to_object_frame(&pred.positions);
    Ok(compare_clouds(&turned, &gt.positions, tau))
}

/// The groups a sample's scores are averaged in: its category, its protocol and their cell (the
/// unit the quality criteria compare per), keyed so that a sorted table lists the three kinds
/// apart.
fn group_keys(category: &str, protocol: &str) -> [String; 3] {
    [
        format!("category {category}"),
        format!("cell {category} / {protocol}"),
        format!("protocol {protocol}"),
    ]
}

/// The report and table of a data directory's scores: every sample, the mean of each category,
/// protocol and category × protocol cell, and of all.
fn dataset_report(
    data: &Path,
    pred_dir: &Path,
    args: &EvalArgs,
    samples: &[DataSample],
    results: &[CloudMetrics],
) -> (DatasetReport, Table) {
    let mut groups: BTreeMap<String, Vec<CloudMetrics>> = BTreeMap::new();
    for (s, m) in samples.iter().zip(results) {
        for key in group_keys(&s.category, s.protocol) {
            groups.entry(key).or_default().push(m.clone());
        }
    }
    let mut table = Table::default();
    table.cloud_header(&args.metrics, &args.tau);
    let mut report = DatasetReport {
        data: data.to_path_buf(),
        pred_dir: pred_dir.to_path_buf(),
        ground_truth: args.ground_truth,
        thresholds: args.tau.clone(),
        groups: BTreeMap::new(),
        samples: samples
            .iter()
            .zip(results)
            .map(|(s, m)| SampleReport {
                scores: Scores::of(m, &args.metrics),
                name: s.name.clone(),
                protocol: s.protocol,
            })
            .collect(),
    };
    let groups = groups.iter().map(|(key, ms)| (key.as_str(), ms.as_slice()));
    for (key, ms) in groups.chain([("all", results)]) {
        let mean = mean_metrics(ms);
        table.cloud_row(&format!("{key} ({})", ms.len()), &mean, &args.metrics);
        let group = GroupReport {
            scores: Scores::of(&mean, &args.metrics),
            samples: ms.len(),
        };
        report.groups.insert(key.to_string(), group);
    }
    (report, table)
}

fn eval_views(pred_dir: &Path, gt_dir: &Path) -> anyhow::Result<(Vec<usize>, Vec<ImageMetrics>)> {
    let cameras = find_views(gt_dir)?;
    let gt = read_views(gt_dir, Some(&cameras))?;
    let pred = read_views(pred_dir, Some(&cameras))?;
    for (dir, v) in [(gt_dir, &gt), (pred_dir, &pred)] {
        if !v.has_color {
            bail!("{}: no color_NNN.png images to compare", dir.display());
        }
    }
    if pred.size != gt.size {
        bail!(
            "{}: views are {} px but the ground truth's are {} px",
            pred_dir.display(),
            pred.size,
            gt.size
        );
    }
    let plane = gt.size * gt.size;
    let per_view = (0..gt.views())
        .map(|v| {
            let rgb = |img: &mvpcc::views::projection::ViewImages| {
                img.view_pixels(v)[3 * plane..CHANNELS * plane].to_vec()
            };
            compare_images(&rgb(&pred), &rgb(&gt), gt.size)
        })
        .collect();
    Ok((cameras, per_view))
}

pub(super) fn run(args: EvalArgs, log: Log) -> anyhow::Result<()> {
    if let (Some(data), Some(pred_dir)) = (&args.data, &args.pred_dir) {
        return eval_dataset(data, pred_dir, &args, log);
    }
    let (geometry, color) = check(&args)?;
    let mut report = EvalReport {
        normalization: args.normalize,
        thresholds: args.tau.clone(),
        pairs: None,
        mean: None,
        views: None,
    };
    let mut table = Table::default();
    if geometry {
        eval_clouds(&args, log, &mut report, &mut table)?;
    }
    if color {
        table.blank();
        eval_view_dirs(&args, &mut report, &mut table)?;
    }
    print_results(args.json, &report, &table)
}

/// Which kinds of metric the options ask for (geometry, colour), after checking that they
/// name what those need.
fn check(args: &EvalArgs) -> anyhow::Result<(bool, bool)> {
    let geometry = args
        .metrics
        .iter()
        .any(|m| matches!(m, Metric::Cd | Metric::F1));
    let color = args
        .metrics
        .iter()
        .any(|m| matches!(m, Metric::Psnr | Metric::Ssim | Metric::Mae));
    if args.pred_dir.is_some() && args.gt_dir.is_none() {
        bail!("--pred-dir needs --gt-dir or --data");
    }
    let have_clouds = args.pred.is_some() || args.pred_dir.is_some();
    if geometry && !have_clouds {
        bail!("cd and f1 compare clouds: pass --pred and --gt, or --pred-dir and --gt-dir");
    }
    if color && args.pred_views.is_none() {
        bail!("psnr, ssim and mae compare view images: pass --pred-views and --gt-views");
    }
    if let Some(t) = args.tau.iter().find(|t| !(t.is_finite() && **t > 0.0)) {
        bail!("--tau {t}: thresholds must be positive numbers");
    }
    if let Some((_, t)) = args
        .tau
        .iter()
        .enumerate()
        .find(|(i, t)| args.tau[..*i].contains(t))
    {
        bail!("--tau: {t} given twice");
    }
    Ok((geometry, color))
}

/// `--pred` and `--gt`, which name files: a folder is meant for `--pred-dir` / `--gt-dir`.
fn one_pair(pred: &Path, gt: &Path) -> anyhow::Result<Pair> {
    for (path, flag) in [(pred, "--pred-dir"), (gt, "--gt-dir")] {
        if path.is_dir() {
            bail!(
                "{}: is a directory; score folders with --pred-dir and --gt-dir (this one as \
                 {flag})",
                path.display()
            );
        }
    }
    Ok(Pair {
        name: pred
            .file_stem()
            .map_or("pred".into(), |s| s.to_string_lossy().into_owned()),
        pred: pred.to_path_buf(),
        gt: gt.to_path_buf(),
    })
}

/// CD and F-scores of `--pred`/`--gt` or of matched files in `--pred-dir`/`--gt-dir`.
fn eval_clouds(
    args: &EvalArgs,
    log: Log,
    report: &mut EvalReport,
    table: &mut Table,
) -> anyhow::Result<()> {
    let pairs = match (&args.pred, &args.gt, &args.pred_dir, &args.gt_dir) {
        (Some(pred), Some(gt), _, _) => vec![one_pair(pred, gt)?],
        (_, _, Some(pd), Some(gd)) => matched_pairs(pd, gd, args.input.format)?,
        _ => unreachable!("checked: clouds were given"),
    };
    let bar = super::progress(pairs.len(), "eval", log);
    let mut results = Vec::with_capacity(pairs.len());
    for pair in &pairs {
        bar.set_message(pair.name.clone());
        results.push(score(pair, args, log)?);
        bar.inc(1);
    }
    bar.finish_and_clear();
    table.cloud_header(&args.metrics, &args.tau);
    for (pair, m) in pairs.iter().zip(&results) {
        table.cloud_row(&pair.name, m, &args.metrics);
    }
    report.pairs = Some(
        pairs
            .into_iter()
            .zip(&results)
            .map(|(pair, m)| PairReport {
                name: pair.name,
                pred: pair.pred,
                gt: pair.gt,
                pred_points: m.pred_points,
                gt_points: m.gt_points,
                scores: Scores::of(m, &args.metrics),
            })
            .collect(),
    );
    if results.len() > 1 {
        let mean = mean_metrics(&results);
        table.cloud_row(&format!("mean of {}", results.len()), &mean, &args.metrics);
        report.mean = Some(Scores::of(&mean, &args.metrics));
    }
    Ok(())
}

/// PSNR, SSIM and MAE of `--pred-views` against `--gt-views`, per view and averaged.
fn eval_view_dirs(
    args: &EvalArgs,
    report: &mut EvalReport,
    table: &mut Table,
) -> anyhow::Result<()> {
    let (Some(pred_dir), Some(gt_dir)) = (&args.pred_views, &args.gt_views) else {
        unreachable!("checked: clap requires both");
    };
    let (cameras, per_view) = eval_views(pred_dir, gt_dir)?;
    let n = per_view.len() as f64;
    let mean = ImageMetrics {
        psnr: per_view.iter().map(|m| m.psnr).sum::<f64>() / n,
        ssim: per_view.iter().map(|m| m.ssim).sum::<f64>() / n,
        mae: per_view.iter().map(|m| m.mae).sum::<f64>() / n,
    };
    table.row("view", &["psnr_db", "ssim", "mae"].map(String::from));
    let cells = |m: &ImageMetrics| {
        [
            format!("{:.4}", m.psnr),
            format!("{:.6}", m.ssim),
            format!("{:.6}", m.mae),
        ]
    };
    for (c, m) in cameras.iter().zip(&per_view) {
        table.row(&format!("{c:03}"), &cells(m));
    }
    table.row("mean", &cells(&mean));
    report.views = Some(ViewsReport {
        mean: ImageScores::of(&mean, &args.metrics),
        pred: pred_dir.clone(),
        gt: gt_dir.clone(),
        cameras,
        per_view: per_view
            .iter()
            .map(|m| ImageScores::of(m, &args.metrics))
            .collect(),
    });
    Ok(())
}

/// The results on stdout: the report as JSON with `--json`, the table otherwise.
fn print_results(json: bool, report: &impl Serialize, table: &Table) -> anyhow::Result<()> {
    if json {
        say(serde_json::to_string_pretty(report)?)?;
    } else {
        for line in &table.lines {
            say(line)?;
        }
    }
    Ok(())
}
