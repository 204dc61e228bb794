//! Validation: the generator on held-out samples, scored as images (PSNR, SSIM, MAE of the
//! geometry planes and of the colour) and through the whole 3D path a user's cloud takes:
//! re-projection with erosion, the statistical outlier filter, then Chamfer distance and F1
//! against the ground-truth cloud.

use super::dataset::{gt_cloud, load_sample, Augment, Cache, DataError, SampleRef};
use crate::complete::filter::{inliers, SorParams};
use crate::core::camera::Camera;
use crate::metrics::{compare_clouds, compare_images, ImageMetrics};
use crate::model::inpaint::Inpainter;
use crate::views::projection::ViewImages;
use crate::views::reprojection::{reproject_keeping, ReprojectOptions};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// F1's distance threshold in normalized units (1 % of the object's length).
pub const F1_TAU: f64 = 0.01;
/// PSNR of identical images is infinite; averages cap it here.
const PSNR_CAP: f64 = 99.0;

/// One validation sample, rendered once.
pub struct ValItem {
    pub label: String,
    pub input: ViewImages,
    pub target: ViewImages,
    pub gt_cloud: Vec<[f64; 3]>,
}

/// Up to `count` samples spread evenly over `samples` (which lists each model's samples
/// together, so the picks fall on different models while there are enough).
pub fn pick(samples: &[SampleRef], count: usize) -> Vec<SampleRef> {
    if samples.is_empty() || count == 0 {
        return Vec::new();
    }
    let stride = samples.len() as f64 / count.min(samples.len()) as f64;
    (0..count.min(samples.len()))
        .map(|i| samples[(i as f64 * stride) as usize].clone())
        .collect()
}

pub fn build(
    samples: &[SampleRef],
    cameras: &[Camera],
    cache: &Cache,
) -> Result<Vec<ValItem>, DataError> {
    let indices: Vec<usize> = cameras.iter().map(|c| c.index).collect();
    samples
        .par_iter()
        .map(|s| {
            let rendered = load_sample(s, cameras, &Augment::NONE, cache)?;
            Ok(ValItem {
                label: s.label(),
                input: rendered.input,
                target: rendered.target,
                gt_cloud: gt_cloud(s, cache, &indices)?,
            })
        })
        .collect()
}

/// Scores of one validation pass, averaged over the samples.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Scores {
    /// The geometry planes (XYZ shifted into [0, 1]) as images.
    pub geometry: ImageScores,
    /// The colour planes, for a model that predicts colour.
    pub color: Option<ImageScores>,
    /// Mean paper-convention Chamfer distance (`cd_l2_half`) over samples with a non-empty
    /// completed cloud; `None` when every one was empty.
    pub cd: Option<f64>,
    pub f1: f64,
    pub precision: f64,
    pub recall: f64,
    /// Samples whose completed cloud was empty (they score F1 = 0 and no CD).
    pub empty: usize,
    pub mean_points: f64,
    pub samples: usize,
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ImageScores {
    pub psnr: f64,
    pub ssim: f64,
    pub mae: f64,
}

fn planes(views: &ViewImages, v: usize, first: usize) -> Vec<f32> {
    let plane = views.size * views.size;
    let px = views.view_pixels(v);
    let occ = views.view_occupancy(v);
    let shift = if first == 0 { 0.5 } else { 0.0 };
    (first..first + 3)
        .flat_map(|c| {
            px[c * plane..(c + 1) * plane]
                .iter()
                .zip(occ)
                .map(move |(&x, &o)| if o { x + shift } else { 0.0 })
        })
        .collect()
}

fn mean_images(scores: &[ImageMetrics]) -> ImageScores {
    let n = scores.len().max(1) as f64;
    ImageScores {
        psnr: scores.iter().map(|m| m.psnr.min(PSNR_CAP)).sum::<f64>() / n,
        ssim: scores.iter().map(|m| m.ssim).sum::<f64>() / n,
        mae: scores.iter().map(|m| m.mae).sum::<f64>() / n,
    }
}

/// Per-sample 3D scores of a cloud against the ground truth.
struct Cloud3d {
    cd: Option<f64>,
    precision: f64,
    recall: f64,
    f1: f64,
    points: usize,
}

fn score_cloud(points: &[[f64; 3]], gt: &[[f64; 3]]) -> Cloud3d {
    if points.is_empty() || gt.is_empty() {
        return Cloud3d {
            cd: None,
            precision: 0.0,
            recall: 0.0,
            f1: 0.0,
            points: 0,
        };
    }
    let m = compare_clouds(points, gt, &[F1_TAU]);
    Cloud3d {
        cd: Some(m.cd_l2_half),
        precision: m.fscores[0].precision,
        recall: m.fscores[0].recall,
        f1: m.fscores[0].f1,
        points: points.len(),
    }
}

/// The completed cloud of inpainted views: re-projected with the default 3×3 erosion (which
/// spares the pixels of `measured`, the input's views, when the generator kept them), then
/// filtered (20 neighbours, σ = 5), as `complete --no-snap --no-keep-input` makes it. The XYZ
/// stay as the network predicts them: these scores end stages and pick the best checkpoint, and
/// the recorded training recipe (README, *The default model*) was run with them so.
pub fn completed_cloud(views: &ViewImages, measured: Option<&ViewImages>) -> Vec<[f64; 3]> {
    let cloud = reproject_keeping(views, ReprojectOptions::default(), measured);
    let keep = inliers(&cloud.positions, SorParams::default());
    cloud
        .positions
        .into_iter()
        .zip(keep)
        .filter_map(|(p, k)| k.then_some(p))
        .collect()
}

fn summarize(
    items: &[ValItem],
    outputs: &[ViewImages],
    clouds: Vec<Cloud3d>,
    color: bool,
) -> Scores {
    let mut geometry = Vec::new();
    let mut colors = Vec::new();
    for (item, out) in items.iter().zip(outputs) {
        for v in 0..out.views() {
            let size = out.size;
            geometry.push(compare_images(
                &planes(out, v, 0),
                &planes(&item.target, v, 0),
                size,
            ));
            if color {
                colors.push(compare_images(
                    &planes(out, v, 3),
                    &planes(&item.target, v, 3),
                    size,
                ));
            }
        }
    }
    let n = clouds.len().max(1) as f64;
    let cds: Vec<f64> = clouds.iter().filter_map(|c| c.cd).collect();
    Scores {
        geometry: mean_images(&geometry),
        color: color.then(|| mean_images(&colors)),
        cd: (!cds.is_empty()).then(|| cds.iter().sum::<f64>() / cds.len() as f64),
        f1: clouds.iter().map(|c| c.f1).sum::<f64>() / n,
        precision: clouds.iter().map(|c| c.precision).sum::<f64>() / n,
        recall: clouds.iter().map(|c| c.recall).sum::<f64>() / n,
        empty: clouds.iter().filter(|c| c.points == 0).count(),
        mean_points: clouds.iter().map(|c| c.points as f64).sum::<f64>() / n,
        samples: clouds.len(),
    }
}

/// Runs the generator over `items` (`batch` objects per forward) and scores its output.
/// Returns the scores and the completed views, in the items' order.
pub fn validate(
    inpainter: &Inpainter,
    items: &[ValItem],
    batch: usize,
) -> (Scores, Vec<ViewImages>) {
    let mut outputs = Vec::with_capacity(items.len());
    for chunk in items.chunks(batch.max(1)) {
        let inputs: Vec<ViewImages> = chunk.iter().map(|i| i.input.clone()).collect();
        outputs.extend(
            inpainter
                .inpaint(&inputs)
                .expect("validation views are rendered at the model's size and view count"),
        );
    }
    let copied = inpainter.config().copies_input();
    let clouds = items
        .par_iter()
        .zip(&outputs)
        .map(|(item, out)| {
            let measured = copied.then_some(&item.input);
            score_cloud(&completed_cloud(out, measured), &item.gt_cloud)
        })
        .collect();
    let color = inpainter.config().channels == crate::model::Channels::Xyzrgb
        && items.iter().all(|i| i.target.has_color);
    let scores = summarize(items, &outputs, clouds, color);
    (scores, outputs)
}

/// The same scores for the partial inputs themselves (their views as the "output" and their
/// points as the cloud): what the network has to beat.
pub fn baseline(items: &[ValItem]) -> Scores {
    let inputs: Vec<ViewImages> = items.iter().map(|i| i.input.clone()).collect();
    let clouds = items
        .par_iter()
        .map(|item| {
            let plane = item.input.size * item.input.size;
            let points: Vec<[f64; 3]> = (0..item.input.views())
                .flat_map(|v| {
                    let px = item.input.view_pixels(v);
                    item.input
                        .view_occupancy(v)
                        .iter()
                        .enumerate()
                        .filter(|(_, &o)| o)
                        .map(move |(at, _)| [0, 1, 2].map(|c| px[c * plane + at] as f64))
                        .collect::<Vec<_>>()
                })
                .collect();
            score_cloud(&points, &item.gt_cloud)
        })
        .collect();
    let color = items
        .iter()
        .all(|i| i.target.has_color && i.input.has_color);
    summarize(items, &inputs, clouds, color)
}

/// Channels of a view image as 8-bit RGB tiles: geometry as pseudo-colour (x, y, z → r, g, b
/// over the unit box), colour as itself; empty pixels dark grey.
pub fn tile(views: &ViewImages, v: usize, color: bool) -> image::RgbImage {
    let s = views.size;
    let plane = s * s;
    let px = views.view_pixels(v);
    let occ = views.view_occupancy(v);
    image::RgbImage::from_fn(s as u32, s as u32, |c, r| {
        let at = r as usize * s + c as usize;
        if !occ[at] {
            return image::Rgb([40, 40, 40]);
        }
        let (first, shift) = if color { (3, 0.0) } else { (0, 0.5) };
        image::Rgb([0, 1, 2].map(|k| {
            ((px[(first + k) * plane + at] + shift) * 255.0)
                .round()
                .clamp(0.0, 255.0) as u8
        }))
    })
}
