//! Completion metrics. Geometry: Chamfer distance as the paper's Eq. 5 writes it (squared
//! distances, each direction halved: `cd_l2_half`), PCN's `cd_l1` (mean distances, halved: the
//! scale the paper's tables print, as scoring clouds at known noise shows, docs/paper.md) and
//! PoinTr's un-halved `cd_l2`; precision, recall and F1 at thresholds τ with a strict `<`. Colour on view
//! images: PSNR, SSIM and MAE.

use crate::core::cloud::Aabb;
use crate::core::knn::knn_distances;
use serde::Serialize;

/// Precision, recall and F1 at one threshold.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct FScore {
    pub tau: f64,
    pub precision: f64,
    pub recall: f64,
    pub f1: f64,
}

/// Everything that compares a predicted cloud with a ground-truth cloud.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CloudMetrics {
    pub pred_points: usize,
    pub gt_points: usize,
    /// `1/(2|P|)·Σ d(p,G)² + 1/(2|G|)·Σ d(g,P)²` (the paper's Eq. 5).
    pub cd_l2_half: f64,
    /// `(mean d(p,G) + mean d(g,P)) / 2` (PCN): the scale of the CD the paper's tables print.
    pub cd_l1: f64,
    /// `mean d(p,G)² + mean d(g,P)²` (PoinTr's CD-L2, twice the paper's).
    pub cd_l2: f64,
    pub fscores: Vec<FScore>,
}

/// Distances from every predicted point to the ground truth and back.
pub struct Correspondence {
    pub pred_to_gt: Vec<f64>,
    pub gt_to_pred: Vec<f64>,
}

impl Correspondence {
    /// Both clouds must be non-empty.
    pub fn new(pred: &[[f64; 3]], gt: &[[f64; 3]]) -> Correspondence {
        let (pred_to_gt, gt_to_pred) =
            rayon::join(|| knn_distances(gt, pred, 1), || knn_distances(pred, gt, 1));
        Correspondence {
            pred_to_gt,
            gt_to_pred,
        }
    }

    pub fn metrics(&self, taus: &[f64]) -> CloudMetrics {
        let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
        let mean_sq = |v: &[f64]| v.iter().map(|d| d * d).sum::<f64>() / v.len() as f64;
        let (a2, b2) = (mean_sq(&self.pred_to_gt), mean_sq(&self.gt_to_pred));
        CloudMetrics {
            pred_points: self.pred_to_gt.len(),
            gt_points: self.gt_to_pred.len(),
            cd_l2_half: 0.5 * (a2 + b2),
            cd_l1: 0.5 * (mean(&self.pred_to_gt) + mean(&self.gt_to_pred)),
            cd_l2: a2 + b2,
            fscores: taus.iter().map(|&tau| self.fscore(tau)).collect(),
        }
    }

    pub fn fscore(&self, tau: f64) -> FScore {
        let frac = |v: &[f64]| v.iter().filter(|&&d| d < tau).count() as f64 / v.len() as f64;
        let precision = frac(&self.pred_to_gt);
        let recall = frac(&self.gt_to_pred);
        let f1 = if precision + recall > 0.0 {
            2.0 * precision * recall / (precision + recall)
        } else {
            0.0
        };
        FScore {
            tau,
            precision,
            recall,
            f1,
        }
    }
}

/// Geometry metrics of `pred` against `gt` (both non-empty).
pub fn compare_clouds(pred: &[[f64; 3]], gt: &[[f64; 3]], taus: &[f64]) -> CloudMetrics {
    Correspondence::new(pred, gt).metrics(taus)
}

/// Colour metrics over planar RGB images in [0, 1].
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ImageMetrics {
    pub psnr: f64,
    pub ssim: f64,
    pub mae: f64,
}

/// Mean absolute error over all samples.
/// Points of the paper's coarse ground truth (Tables 1–2).
pub const COARSE_POINTS: usize = 16_384;

/// Indices of `n` of `points` chosen by farthest point sampling: starting from the first point,
/// each next one is the point farthest from those already chosen (ties to the lower index). All
/// of them, in order, when there are no more than `n`. Deterministic, so a coarse ground truth
/// is the same wherever it is computed.
///
/// Exact, but not quadratic in practice: the points are bucketed in a grid, and a chosen point
/// only visits the cells it can bring nearer, which shrink as the sampling proceeds.
pub fn farthest_point_sample(points: &[[f64; 3]], n: usize) -> Vec<usize> {
    if points.len() <= n {
        return (0..points.len()).collect();
    }
    let mut grid = FpsGrid::new(points);
    let mut chosen = Vec::with_capacity(n);
    let mut next = 0;
    while chosen.len() < n {
        chosen.push(next);
        next = grid.add_center(points[next]);
    }
    chosen
}

/// One grid cell: its box (lower and upper corner), the range of `order` it holds, and its
/// farthest point as (squared distance, index).
type FpsCell = ([f64; 3], [f64; 3], std::ops::Range<usize>, (f64, usize));

/// Points sorted into grid cells, each point's squared distance to the nearest chosen centre,
/// and each cell's farthest point.
struct FpsGrid {
    cells: Vec<FpsCell>,
    order: Vec<usize>,
    sorted: Vec<[f64; 3]>,
    nearest: Vec<f64>,
}

impl FpsGrid {
    fn new(points: &[[f64; 3]]) -> FpsGrid {
        let Some(Aabb { min: lo, max: hi }) = Aabb::of(points) else {
            return FpsGrid {
                cells: Vec::new(),
                order: Vec::new(),
                sorted: Vec::new(),
                nearest: Vec::new(),
            };
        };
        // About 32 points per cell.
        let side = ((points.len() / 32).max(1) as f64).cbrt().ceil() as usize;
        let cell_of = |p: &[f64; 3]| {
            let at = |k: usize| {
                let span = hi[k] - lo[k];
                let t = if span > 0.0 {
                    (p[k] - lo[k]) / span
                } else {
                    0.0
                };
                ((t * side as f64) as usize).min(side - 1)
            };
            (at(0) * side + at(1)) * side + at(2)
        };
        let mut order: Vec<usize> = (0..points.len()).collect();
        order.sort_by_key(|&i| (cell_of(&points[i]), i));
        let mut cells = Vec::new();
        let mut start = 0;
        while start < order.len() {
            let cell = cell_of(&points[order[start]]);
            let end = start
                + order[start..]
                    .iter()
                    .take_while(|&&i| cell_of(&points[i]) == cell)
                    .count();
            let cell_box = Aabb::of_iter(order[start..end].iter().map(|&i| points[i]))
                .expect("a cell holds at least its first point");
            cells.push((
                cell_box.min,
                cell_box.max,
                start..end,
                (f64::INFINITY, order[start]),
            ));
            start = end;
        }
        let sorted = order.iter().map(|&i| points[i]).collect();
        FpsGrid {
            cells,
            order,
            sorted,
            nearest: vec![f64::INFINITY; points.len()],
        }
    }

    /// Takes `c` as a chosen centre; the index of the point now farthest from all centres.
    fn add_center(&mut self, c: [f64; 3]) -> usize {
        let mut best = (f64::NEG_INFINITY, usize::MAX);
        for (lo, hi, range, far) in &mut self.cells {
            // No point of the cell is nearer to c than its box; if that is no nearer than its
            // farthest point's distance, c changes nothing there.
            let gap: f64 = (0..3)
                .map(|k| (lo[k] - c[k]).max(c[k] - hi[k]).max(0.0).powi(2))
                .sum();
            if gap < far.0 {
                *far = (f64::NEG_INFINITY, usize::MAX);
                for j in range.clone() {
                    let p = self.sorted[j];
                    let (x, y, z) = (p[0] - c[0], p[1] - c[1], p[2] - c[2]);
                    let d = &mut self.nearest[j];
                    *d = d.min(x * x + y * y + z * z);
                    *far = later_if_farther(*far, (*d, self.order[j]));
                }
            }
            best = later_if_farther(best, *far);
        }
        best.1
    }
}

/// The farther of two (squared distance, index) pairs; the lower index on a tie.
fn later_if_farther(a: (f64, usize), b: (f64, usize)) -> (f64, usize) {
    if b.0 > a.0 || (b.0 == a.0 && b.1 < a.1) {
        b
    } else {
        a
    }
}

pub fn mae(a: &[f32], b: &[f32]) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs() as f64)
        .sum::<f64>()
        / a.len() as f64
}

/// PSNR in dB for signals in [0, 1]; identical images give infinity.
pub fn psnr(a: &[f32], b: &[f32]) -> f64 {
    assert_eq!(a.len(), b.len());
    let mse = a
        .iter()
        .zip(b)
        .map(|(x, y)| ((x - y) as f64).powi(2))
        .sum::<f64>()
        / a.len() as f64;
    -10.0 * mse.log10()
}

/// SSIM of two `size`×`size` single-channel images in [0, 1]: 11×11 Gaussian window, σ = 1.5,
/// K1 = 0.01, K2 = 0.03 (Wang et al. 2004), averaged over the positions where the window fits.
pub fn ssim(a: &[f32], b: &[f32], size: usize) -> f64 {
    assert_eq!(a.len(), size * size);
    assert_eq!(b.len(), size * size);
    const R: usize = 5;
    if size < 2 * R + 1 {
        return if a == b { 1.0 } else { f64::NAN };
    }
    let g: Vec<f64> = (0..=2 * R)
        .map(|i| (-((i as f64 - R as f64).powi(2)) / (2.0 * 1.5 * 1.5)).exp())
        .collect();
    let gsum: f64 = g.iter().sum();
    let g: Vec<f64> = g.iter().map(|v| v / gsum).collect();
    let (c1, c2) = (0.01f64.powi(2), 0.03f64.powi(2));
    let inner = size - 2 * R;
    // Separable filtering of the five moment images: rows first, then columns.
    let moments = |f: &dyn Fn(usize) -> f64| -> Vec<f64> {
        let mut rows = vec![0.0; size * inner];
        for r in 0..size {
            for c in 0..inner {
                rows[r * inner + c] = (0..=2 * R).map(|k| g[k] * f(r * size + c + k)).sum();
            }
        }
        let mut out = vec![0.0; inner * inner];
        for r in 0..inner {
            for c in 0..inner {
                out[r * inner + c] = (0..=2 * R).map(|k| g[k] * rows[(r + k) * inner + c]).sum();
            }
        }
        out
    };
    let mu_a = moments(&|i| a[i] as f64);
    let mu_b = moments(&|i| b[i] as f64);
    let aa = moments(&|i| (a[i] as f64).powi(2));
    let bb = moments(&|i| (b[i] as f64).powi(2));
    let ab = moments(&|i| a[i] as f64 * b[i] as f64);
    let total: f64 = (0..inner * inner)
        .map(|i| {
            let (ma, mb) = (mu_a[i], mu_b[i]);
            let va = aa[i] - ma * ma;
            let vb = bb[i] - mb * mb;
            let cov = ab[i] - ma * mb;
            ((2.0 * ma * mb + c1) * (2.0 * cov + c2)) / ((ma * ma + mb * mb + c1) * (va + vb + c2))
        })
        .sum();
    total / (inner * inner) as f64
}

/// PSNR, SSIM (mean over channels) and MAE of two planar `[channels, size, size]` images.
pub fn compare_images(a: &[f32], b: &[f32], size: usize) -> ImageMetrics {
    let plane = size * size;
    let channels = a.len() / plane;
    let ssim_mean = (0..channels)
        .map(|c| {
            ssim(
                &a[c * plane..(c + 1) * plane],
                &b[c * plane..(c + 1) * plane],
                size,
            )
        })
        .sum::<f64>()
        / channels as f64;
    ImageMetrics {
        psnr: psnr(a, b),
        ssim: ssim_mean,
        mae: mae(a, b),
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn farthest_point_sampling_spreads_over_the_cloud() {
        // A dense cluster of 1000 points at the origin and the 8 corners of a unit cube: the
        // first 9 picks are one cluster point and the corners, whatever the cluster's size.
        let mut points: Vec<[f64; 3]> = (0..1000).map(|i| [i as f64 * 1e-6, 0.0, 0.0]).collect();
        for c in 0..8 {
            points.push([0, 1, 2].map(|k| if c >> k & 1 == 1 { 2.0 } else { -2.0 }));
        }
        let picked = super::farthest_point_sample(&points, 9);
        assert_eq!(picked[0], 0);
        let mut corners = picked[1..].to_vec();
        corners.sort();
        assert_eq!(corners, (1000..1008).collect::<Vec<_>>());
        assert_eq!(
            super::farthest_point_sample(&points[..5], 9),
            [0, 1, 2, 3, 4]
        );
    }

    #[test]
    fn farthest_point_sampling_with_a_grid_equals_the_plain_definition() {
        let mut rng = crate::core::rng::Lcg::new(3);
        let points: Vec<[f64; 3]> = (0..3000)
            .map(|_| [rng.next_f64(), rng.next_f64() * 0.3, rng.next_f64() * 2.0])
            .collect();
        let n = 400;
        let mut plain = vec![0];
        let mut nearest = vec![f64::INFINITY; points.len()];
        while plain.len() < n {
            let c = points[*plain.last().unwrap()];
            let mut best = (f64::NEG_INFINITY, 0);
            for (i, p) in points.iter().enumerate() {
                let e: f64 = (0..3).map(|k| (p[k] - c[k]).powi(2)).sum();
                nearest[i] = nearest[i].min(e);
                if nearest[i] > best.0 {
                    best = (nearest[i], i);
                }
            }
            plain.push(best.1);
        }
        assert_eq!(super::farthest_point_sample(&points, n), plain);
    }

    use super::*;

    #[test]
    fn hand_checkable_fixture_of_the_reference_readme() {
        let p = [
            [0.0, 0.0, 0.0],
            [0.006, 0.0, 0.0],
            [1.0, 1.0, 1.0],
            [0.0, 0.0, 0.01],
        ];
        let g = [[0.0, 0.0, 0.0], [0.0, 0.008, 0.0]];
        let m = compare_clouds(&p, &g, &[0.01, 0.005]);
        assert!((m.cd_l2_half - 0.373041).abs() < 1e-12, "{}", m.cd_l2_half);
        assert!((m.cd_l1 - 0.219930544).abs() < 1e-9, "{}", m.cd_l1);
        assert!((m.cd_l2 - 2.0 * 0.373041).abs() < 1e-12);
        let f = m.fscores[0];
        assert_eq!((f.precision, f.recall), (0.5, 1.0));
        assert!((f.f1 - 0.666666667).abs() < 1e-9);
        assert!((m.fscores[1].f1 - 0.333333333).abs() < 1e-9);
        assert_eq!((m.pred_points, m.gt_points), (4, 2));
    }

    #[test]
    fn identical_clouds_score_perfectly() {
        let p: Vec<[f64; 3]> = (0..100).map(|i| [i as f64 * 0.01, 0.0, 0.0]).collect();
        let m = compare_clouds(&p, &p, &[0.001]);
        assert_eq!(m.cd_l2_half, 0.0);
        assert_eq!(m.fscores[0].f1, 1.0);
    }

    #[test]
    fn image_metrics() {
        let size = 16;
        let a: Vec<f32> = (0..size * size)
            .map(|i| ((i * 37) % 101) as f32 / 100.0)
            .collect();
        assert_eq!(psnr(&a, &a), f64::INFINITY);
        assert!((ssim(&a, &a, size) - 1.0).abs() < 1e-12);
        let b: Vec<f32> = a.iter().map(|v| v + 0.1).collect();
        assert!((mae(&a, &b) - 0.1).abs() < 1e-6);
        assert!((psnr(&a, &b) - 20.0).abs() < 1e-4);
        let inverted: Vec<f32> = a.iter().map(|v| 1.0 - v).collect();
        assert!(ssim(&a, &inverted, size) < 0.0);
        let m = compare_images(
            &[a.clone(), a.clone()].concat(),
            &[a.clone(), b].concat(),
            size,
        );
        assert!(m.ssim < 1.0 && m.ssim > 0.5, "{m:?}");
    }
}
