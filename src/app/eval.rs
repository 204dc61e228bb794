//! Scoring completions: pairs of clouds matched by name, a prepared dataset's test partials
//! against their ground truth, and view images; means per group; typed reports.

use super::table::{Report, Table};
use super::Progress;
use crate::core::cloud::PointCloud;
use crate::core::frame::{Frame, FrameError, UpAxis};
use crate::datagen::data::{coarse, Layout, Manifest, GT_COARSE, GT_FINE, MANIFEST_FILE, TEST};
use crate::datagen::scan::PartialSpec;
use crate::io::batch::{self, walk, BatchError};
use crate::io::{non_finite_warning, read_cloud, CloudIoError, Format};
use crate::metrics::{compare_clouds, compare_images, CloudMetrics, FScore, ImageMetrics};
use crate::views::projection::{ViewImages, CHANNELS};
use crate::views::{find_views, read_views, ViewError};
use serde::Serialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use thiserror::Error;

/// F-scores at a threshold under this share of the ground truth's longest side count only
/// near-exact points: the paper's τ = 0.01 is 1 % of its unit box, half a percent is already
/// strict, and 1 cm on a 4.5 m car (0.2 %) is what a user scoring metres by mistake gets.
pub const SMALL_TAU_SHARE: f64 = 0.005;

#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Metric {
    /// Chamfer distances: cd_l2_half (the paper's Eq. 5, squared), cd_l1 (PCN; the scale the
    /// paper's tables print, docs/paper.md), cd_l2 (PoinTr).
    Cd,
    /// Precision, recall and F1 at each --tau.
    F1,
    /// PSNR of view colours (needs --pred-views/--gt-views).
    Psnr,
    /// SSIM of view colours.
    Ssim,
    /// Mean absolute error of view colours.
    Mae,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Normalize {
    /// Coordinates as stored.
    None,
    /// Both clouds mapped by the ground truth's box: centred, longest side 1.
    GtBox,
}

/// Which ground truth a dataset's completions are scored against.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum GroundTruth {
    Fine,
    Coarse,
}

#[derive(Debug, Error)]
pub enum EvalError {
    #[error(transparent)]
    Cloud(#[from] CloudIoError),
    #[error(transparent)]
    Batch(#[from] BatchError),
    #[error(transparent)]
    Views(#[from] ViewError),
    #[error("{}: {source}", path.display())]
    Frame { path: PathBuf, source: FrameError },
    #[error("{}: is a directory; score folders with --pred-dir and --gt-dir (this one as {flag})", path.display())]
    IsDirectory { path: PathBuf, flag: &'static str },
    #[error("{}: two clouds share the name '{key}' ({} and {})", dir.display(), first.display(), second.display())]
    SharedName {
        dir: PathBuf,
        key: String,
        first: PathBuf,
        second: PathBuf,
    },
    #[error("{} and {}: unmatched file stems: only in predictions: {only_pred}; only in ground truth: {only_gt}", pred_dir.display(), gt_dir.display())]
    Unmatched {
        pred_dir: PathBuf,
        gt_dir: PathBuf,
        only_pred: String,
        only_gt: String,
    },
    #[error("{}: no point cloud files", .0.display())]
    NoClouds(PathBuf),
    #[error("{}: not a data directory from `mvpcc prepare` (no manifest.json; an interrupted prepare writes it when run again to the end)", .0.display())]
    NoManifest(PathBuf),
    #[error("{}: cannot read: {source}", path.display())]
    ManifestRead {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{}: unreadable manifest: {source}", path.display())]
    ManifestParse {
        path: PathBuf,
        source: serde_json::Error,
    },
    #[error("{}: no completion for {missing} of {total} test partials (first: {first})", dir.display())]
    MissingCompletions {
        dir: PathBuf,
        missing: usize,
        total: usize,
        first: String,
    },
    #[error("{}: the data has no test partials", .0.display())]
    NoTestPartials(PathBuf),
    #[error("{}: no color_NNN.png images to compare", .0.display())]
    NoColor(PathBuf),
    #[error("{}: views are {pred} px but the ground truth's are {gt} px", dir.display())]
    ViewSize {
        dir: PathBuf,
        pred: usize,
        gt: usize,
    },
}

/// What cloud scores are computed and how.
#[derive(Debug, Clone)]
pub struct CloudEval {
    pub metrics: Vec<Metric>,
    /// F-score thresholds, in the clouds' units (after `normalize`).
    pub tau: Vec<f64>,
    pub normalize: Normalize,
    /// The clouds' format, overriding their extensions.
    pub format: Option<Format>,
}

/// A predicted cloud and its ground truth.
#[derive(Debug, Clone)]
pub struct Pair {
    pub name: String,
    pub pred: PathBuf,
    pub gt: PathBuf,
}

impl Pair {
    /// Two files named by the user; a folder is meant for the directory form.
    pub fn of_files(pred: &Path, gt: &Path) -> Result<Pair, EvalError> {
        for (path, flag) in [(pred, "--pred-dir"), (gt, "--gt-dir")] {
            if path.is_dir() {
                return Err(EvalError::IsDirectory {
                    path: path.to_path_buf(),
                    flag,
                });
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
}

/// The clouds under `dir` (walked as a batch walks its inputs), keyed by their path relative
/// to `dir` without the extension, so a batch's output tree pairs with its ground truth's;
/// those under `other` (the other side's folder) are left out where it lies inside `dir`, as a
/// batch's outputs inside its inputs do.
fn cloud_files(
    dir: &Path,
    other: &Path,
    format: Option<Format>,
) -> Result<BTreeMap<String, PathBuf>, EvalError> {
    let nested = batch::nested_dir(dir, other);
    let relative = walk(dir, |path| {
        (format.is_some() || Format::from_path(path).is_ok())
            && nested.as_ref().is_none_or(|n| !batch::lies_in(path, n))
    })?;
    let mut files = BTreeMap::new();
    for path in relative {
        let key = path.with_extension("").to_string_lossy().into_owned();
        let path = dir.join(path);
        if let Some(first) = files.insert(key.clone(), path.clone()) {
            return Err(EvalError::SharedName {
                dir: dir.to_path_buf(),
                key,
                first,
                second: path,
            });
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

/// The clouds of two folders paired by relative path without the extension; every file must
/// have its partner.
pub fn matched_pairs(
    pred_dir: &Path,
    gt_dir: &Path,
    format: Option<Format>,
) -> Result<Vec<Pair>, EvalError> {
    let preds = cloud_files(pred_dir, gt_dir, format)?;
    let gts = cloud_files(gt_dir, pred_dir, format)?;
    let only = |a: &BTreeMap<String, PathBuf>, b: &BTreeMap<String, PathBuf>| {
        let names: Vec<&str> = a
            .keys()
            .filter(|k| !b.contains_key(*k))
            .map(|s| s.as_str())
            .collect();
        (!names.is_empty()).then(|| some_of(&names))
    };
    let (only_pred, only_gt) = (only(&preds, &gts), only(&gts, &preds));
    if only_pred.is_some() || only_gt.is_some() {
        let none = || "none".to_string();
        return Err(EvalError::Unmatched {
            pred_dir: pred_dir.to_path_buf(),
            gt_dir: gt_dir.to_path_buf(),
            only_pred: only_pred.unwrap_or_else(none),
            only_gt: only_gt.unwrap_or_else(none),
        });
    }
    if preds.is_empty() {
        return Err(EvalError::NoClouds(pred_dir.to_path_buf()));
    }
    Ok(preds
        .into_iter()
        .map(|(name, pred)| {
            let gt = gts[&name].clone();
            Pair { name, pred, gt }
        })
        .collect())
}

/// Reads a cloud; what reading dropped goes to `warnings`.
fn load(
    path: &Path,
    format: Option<Format>,
    warnings: &mut Vec<String>,
) -> Result<PointCloud, EvalError> {
    let loaded = read_cloud(path, format)?;
    if let Some(w) = non_finite_warning(loaded.non_finite_dropped) {
        warnings.push(format!("{}: {w}", path.display()));
    }
    Ok(loaded.cloud)
}

/// The warning for thresholds too small for the ground truth's size: clouds in metres scored
/// with the paper's unit-box τ.
pub fn small_tau_warning(tau: &[f64], gt: &PointCloud, name: &Path) -> Option<String> {
    let smallest = tau.iter().copied().fold(f64::INFINITY, f64::min);
    let b = gt.bounds()?;
    let longest = (0..3).map(|i| b.max[i] - b.min[i]).fold(0.0, f64::max);
    (smallest < SMALL_TAU_SHARE * longest).then(|| {
        format!(
            "{}: τ = {smallest} is {:.2} % of the ground truth's longest side ({longest:.3}), \
             so the F-scores count only near-exact points; the paper's τ = 0.01 is 1 % of a \
             unit box: score with --normalize gt-box",
            name.display(),
            100.0 * smallest / longest
        )
    })
}

/// One pair's scores, in the ground truth's box when `settings` say so; the small-threshold
/// warning is given once, for the first pair it concerns.
fn score(
    pair: &Pair,
    settings: &CloudEval,
    warnings: &mut Vec<String>,
    tau_warned: &mut bool,
) -> Result<CloudMetrics, EvalError> {
    let mut pred = load(&pair.pred, settings.format, warnings)?;
    let mut gt = load(&pair.gt, settings.format, warnings)?;
    match settings.normalize {
        Normalize::GtBox => {
            let frame = Frame::fit(&gt, UpAxis::Y).map_err(|source| EvalError::Frame {
                path: pair.gt.clone(),
                source,
            })?;
            let map = |c: &PointCloud| PointCloud::from_positions(frame.normalize(c).positions);
            pred = map(&pred);
            gt = map(&gt);
        }
        Normalize::None if !*tau_warned => {
            if let Some(w) = small_tau_warning(&settings.tau, &gt, &pair.gt) {
                warnings.push(w);
                *tau_warned = true;
            }
        }
        Normalize::None => {}
    }
    Ok(compare_clouds(
        &pred.positions,
        &gt.positions,
        &settings.tau,
    ))
}

/// A cloud's scores as reports carry them: the metrics asked for.
#[derive(Debug, Serialize)]
pub struct Scores {
    #[serde(skip_serializing_if = "Option::is_none")]
    pub cd_l2_half: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub cd_l1: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub cd_l2: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fscore: Option<Vec<FScore>>,
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

    /// The table cells of these scores: the point counts, then what was asked for.
    fn cells(&self, pred_points: usize, gt_points: usize) -> Vec<String> {
        let mut cells = vec![pred_points.to_string(), gt_points.to_string()];
        for v in [self.cd_l2_half, self.cd_l1, self.cd_l2]
            .into_iter()
            .flatten()
        {
            cells.push(format!("{v:.6e}"));
        }
        for f in self.fscore.iter().flatten() {
            cells.extend([f.f1, f.precision, f.recall].map(|v| format!("{v:.6}")));
        }
        cells
    }
}

/// One pair of clouds.
#[derive(Debug, Serialize)]
pub struct PairReport {
    pub name: String,
    pub pred: PathBuf,
    pub gt: PathBuf,
    pub pred_points: usize,
    pub gt_points: usize,
    #[serde(flatten)]
    pub scores: Scores,
}

/// View-image scores: the metrics asked for.
#[derive(Debug, Serialize)]
pub struct ImageScores {
    #[serde(skip_serializing_if = "Option::is_none")]
    pub psnr_db: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ssim: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mae: Option<f64>,
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
pub struct ViewsReport {
    #[serde(flatten)]
    pub mean: ImageScores,
    pub pred: PathBuf,
    pub gt: PathBuf,
    pub cameras: Vec<usize>,
    pub per_view: Vec<ImageScores>,
    /// Every image metric, for the table (which shows all three).
    #[serde(skip)]
    table: Vec<(String, ImageMetrics)>,
}

/// Scores of clouds and views, as `eval` prints them.
#[derive(Debug, Serialize)]
pub struct EvalReport {
    pub normalization: Normalize,
    pub thresholds: Vec<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub pairs: Option<Vec<PairReport>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mean: Option<Scores>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub views: Option<ViewsReport>,
    /// Said on stderr as the scores were made; not part of the JSON.
    #[serde(skip)]
    pub warnings: Vec<String>,
    #[serde(skip)]
    metrics: Vec<Metric>,
    #[serde(skip)]
    mean_points: (usize, usize),
}

impl EvalReport {
    pub fn new(settings: &CloudEval) -> EvalReport {
        EvalReport {
            normalization: settings.normalize,
            thresholds: settings.tau.clone(),
            pairs: None,
            mean: None,
            views: None,
            warnings: Vec::new(),
            metrics: settings.metrics.clone(),
            mean_points: (0, 0),
        }
    }

    /// Scores `pairs` into the report, with their mean when there are several.
    pub fn score_pairs(
        &mut self,
        pairs: Vec<Pair>,
        settings: &CloudEval,
        progress: &dyn Progress,
    ) -> Result<(), EvalError> {
        progress.start(pairs.len(), "eval");
        let mut results = Vec::with_capacity(pairs.len());
        let mut tau_warned = false;
        for pair in &pairs {
            results.push(score(pair, settings, &mut self.warnings, &mut tau_warned)?);
            progress.done(&pair.name);
        }
        progress.finish();
        if results.len() > 1 {
            let mean = mean_metrics(&results);
            self.mean_points = (mean.pred_points, mean.gt_points);
            self.mean = Some(Scores::of(&mean, &settings.metrics));
        }
        self.pairs = Some(
            pairs
                .into_iter()
                .zip(&results)
                .map(|(pair, m)| PairReport {
                    name: pair.name,
                    pred: pair.pred,
                    gt: pair.gt,
                    pred_points: m.pred_points,
                    gt_points: m.gt_points,
                    scores: Scores::of(m, &settings.metrics),
                })
                .collect(),
        );
        Ok(())
    }

    /// PSNR, SSIM and MAE of the views in `pred_dir` against `gt_dir`'s, per view and averaged.
    pub fn score_views(&mut self, pred_dir: &Path, gt_dir: &Path) -> Result<(), EvalError> {
        let (cameras, per_view) = eval_views(pred_dir, gt_dir)?;
        let n = per_view.len() as f64;
        let mean = ImageMetrics {
            psnr: per_view.iter().map(|m| m.psnr).sum::<f64>() / n,
            ssim: per_view.iter().map(|m| m.ssim).sum::<f64>() / n,
            mae: per_view.iter().map(|m| m.mae).sum::<f64>() / n,
        };
        let metrics = &self.metrics;
        let table = cameras
            .iter()
            .map(|c| format!("{c:03}"))
            .zip(per_view.iter().copied())
            .chain([("mean".to_string(), mean)])
            .collect();
        self.views = Some(ViewsReport {
            mean: ImageScores::of(&mean, metrics),
            pred: pred_dir.to_path_buf(),
            gt: gt_dir.to_path_buf(),
            cameras,
            per_view: per_view
                .iter()
                .map(|m| ImageScores::of(m, metrics))
                .collect(),
            table,
        });
        Ok(())
    }
}

/// The header row of a clouds table.
fn cloud_header(table: &mut Table, metrics: &[Metric], taus: &[f64]) {
    let mut cells = vec!["pred_pts".to_string(), "gt_pts".to_string()];
    if metrics.contains(&Metric::Cd) {
        cells.extend(["cd_l2_half", "cd_l1", "cd_l2"].map(String::from));
    }
    if metrics.contains(&Metric::F1) {
        for t in taus.iter().map(|&t| tau_label(t)) {
            cells.extend([format!("f1@{t}"), format!("prec@{t}"), format!("rec@{t}")]);
        }
    }
    table.row("name", &cells);
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

impl Report for EvalReport {
    fn table(&self) -> Table {
        let mut table = Table::default();
        if let Some(pairs) = &self.pairs {
            cloud_header(&mut table, &self.metrics, &self.thresholds);
            for p in pairs {
                table.row(&p.name, &p.scores.cells(p.pred_points, p.gt_points));
            }
            if let Some(mean) = &self.mean {
                let (pred, gt) = self.mean_points;
                table.row(&format!("mean of {}", pairs.len()), &mean.cells(pred, gt));
            }
        }
        if let Some(views) = &self.views {
            table.blank();
            table.row("view", &["psnr_db", "ssim", "mae"].map(String::from));
            for (name, m) in &views.table {
                let cells = [
                    format!("{:.4}", m.psnr),
                    format!("{:.6}", m.ssim),
                    format!("{:.6}", m.mae),
                ];
                table.row(name, &cells);
            }
        }
        table
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

fn eval_views(
    pred_dir: &Path,
    gt_dir: &Path,
) -> Result<(Vec<usize>, Vec<ImageMetrics>), EvalError> {
    let cameras = find_views(gt_dir)?;
    let gt = read_views(gt_dir, Some(&cameras))?;
    let pred = read_views(pred_dir, Some(&cameras))?;
    for (dir, v) in [(gt_dir, &gt), (pred_dir, &pred)] {
        if !v.has_color {
            return Err(EvalError::NoColor(dir.to_path_buf()));
        }
    }
    if pred.size != gt.size {
        return Err(EvalError::ViewSize {
            dir: pred_dir.to_path_buf(),
            pred: pred.size,
            gt: gt.size,
        });
    }
    let plane = gt.size * gt.size;
    let per_view = (0..gt.views())
        .map(|v| {
            let rgb = |img: &ViewImages| img.view_pixels(v)[3 * plane..CHANNELS * plane].to_vec();
            compare_images(&rgb(&pred), &rgb(&gt), gt.size)
        })
        .collect();
    Ok((cameras, per_view))
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
fn load_ground_truth(path: &Path, warnings: &mut Vec<String>) -> Result<PointCloud, EvalError> {
    if path.ends_with(GT_COARSE) && !path.exists() {
        return Ok(coarse(&load(
            &path.with_file_name(GT_FINE),
            None,
            warnings,
        )?));
    }
    load(path, None, warnings)
}

/// The test partials of the data directory `data` (from `mvpcc prepare`), each with its
/// completion in `pred_dir` and its `ground_truth`; an error when any has no completion.
fn dataset_samples(
    data: &Path,
    pred_dir: &Path,
    ground_truth: GroundTruth,
) -> Result<Vec<DataSample>, EvalError> {
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
    if let Some(first) = missing.first() {
        return Err(EvalError::MissingCompletions {
            dir: pred_dir.to_path_buf(),
            missing: missing.len(),
            total: missing.len() + samples.len(),
            first: first.clone(),
        });
    }
    if samples.is_empty() {
        return Err(EvalError::NoTestPartials(data.to_path_buf()));
    }
    Ok(samples)
}

/// The manifest of the data directory `data`, which only a finished `mvpcc prepare` writes.
fn read_manifest(data: &Path) -> Result<Manifest, EvalError> {
    let path = data.join(MANIFEST_FILE);
    let text = match std::fs::read_to_string(&path) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            return Err(EvalError::NoManifest(data.to_path_buf()))
        }
        read => read.map_err(|source| EvalError::ManifestRead {
            path: path.clone(),
            source,
        })?,
    };
    serde_json::from_str(&text).map_err(|source| EvalError::ManifestParse { path, source })
}

/// A completion scored against its ground truth, in the object's frame (a scanner partial is
/// written in its path's).
fn score_sample(
    sample: &DataSample,
    tau: &[f64],
    warnings: &mut Vec<String>,
) -> Result<CloudMetrics, EvalError> {
    let pred = load(&sample.pred, None, warnings)?;
    let gt = load_ground_truth(&sample.gt, warnings)?;
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

#[derive(Debug, Serialize)]
pub struct GroupReport {
    #[serde(flatten)]
    pub scores: Scores,
    pub samples: usize,
    #[serde(skip)]
    points: (usize, usize),
}

#[derive(Debug, Serialize)]
pub struct SampleReport {
    #[serde(flatten)]
    pub scores: Scores,
    pub name: String,
    pub protocol: &'static str,
}

/// A data directory's scores: every sample, and the mean of each category, protocol, category
/// × protocol cell, and of all (the group `all`).
#[derive(Debug, Serialize)]
pub struct DatasetReport {
    pub data: PathBuf,
    pub pred_dir: PathBuf,
    pub ground_truth: GroundTruth,
    pub thresholds: Vec<f64>,
    pub groups: BTreeMap<String, GroupReport>,
    pub samples: Vec<SampleReport>,
    #[serde(skip)]
    pub warnings: Vec<String>,
    #[serde(skip)]
    metrics: Vec<Metric>,
}

impl Report for DatasetReport {
    fn table(&self) -> Table {
        let mut table = Table::default();
        cloud_header(&mut table, &self.metrics, &self.thresholds);
        let groups = self.groups.iter().filter(|(k, _)| k.as_str() != "all");
        let all = self.groups.get("all").map(|g| ("all", g));
        for (key, g) in groups.map(|(k, g)| (k.as_str(), g)).chain(all) {
            let (pred, gt) = g.points;
            table.row(&format!("{key} ({})", g.samples), &g.scores.cells(pred, gt));
        }
        table
    }
}

/// Scores `pred_dir`'s completions of the test partials of `data` against `ground_truth`.
pub fn eval_dataset(
    data: &Path,
    pred_dir: &Path,
    ground_truth: GroundTruth,
    metrics: &[Metric],
    tau: &[f64],
    progress: &dyn Progress,
) -> Result<DatasetReport, EvalError> {
    let samples = dataset_samples(data, pred_dir, ground_truth)?;
    let mut warnings = Vec::new();
    progress.start(samples.len(), "eval");
    let results = samples
        .iter()
        .map(|s| {
            let scored = score_sample(s, tau, &mut warnings);
            progress.done(&s.name);
            scored
        })
        .collect::<Result<Vec<CloudMetrics>, EvalError>>()?;
    progress.finish();
    let mut groups: BTreeMap<String, Vec<CloudMetrics>> = BTreeMap::new();
    for (s, m) in samples.iter().zip(&results) {
        for key in group_keys(&s.category, s.protocol) {
            groups.entry(key).or_default().push(m.clone());
        }
    }
    groups.insert("all".to_string(), results.clone());
    let groups = groups
        .into_iter()
        .map(|(key, ms)| {
            let mean = mean_metrics(&ms);
            let group = GroupReport {
                scores: Scores::of(&mean, metrics),
                samples: ms.len(),
                points: (mean.pred_points, mean.gt_points),
            };
            (key, group)
        })
        .collect();
    Ok(DatasetReport {
        data: data.to_path_buf(),
        pred_dir: pred_dir.to_path_buf(),
        ground_truth,
        thresholds: tau.to_vec(),
        groups,
        samples: samples
            .iter()
            .zip(&results)
            .map(|(s, m)| SampleReport {
                scores: Scores::of(m, metrics),
                name: s.name.clone(),
                protocol: s.protocol,
            })
            .collect(),
        warnings,
        metrics: metrics.to_vec(),
    })
}
