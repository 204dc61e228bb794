//! Statistical outlier removal, with PCL's semantics: for each point the mean distance to its
//! `k` nearest neighbours *excluding itself* (PCL `setMeanK(k)`; Open3D's `nb_neighbors = k+1`);
//! a point is kept when that mean is at most `μ + σ·std` over the cloud (std with n − 1).

use crate::core::knn::KnnSearch;

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SorParams {
    /// Neighbours per point, excluding the point itself.
    pub k: usize,
    /// Multiple of the standard deviation above the mean that is still an inlier.
    pub std_mul: f64,
}

impl SorParams {
    /// PCL's usual settings, the paper's: 20 neighbours, 5 standard deviations.
    pub const DEFAULT: SorParams = SorParams {
        k: 20,
        std_mul: 5.0,
    };
}

impl Default for SorParams {
    fn default() -> Self {
        SorParams::DEFAULT
    }
}

/// The most neighbours a point is judged by. PCL's examples use 50; a `--sor-k` of 100,000 on a
/// 69,000-point cloud asked for 39 GB of distances and aborted the process.
pub const MAX_K: usize = 1000;

/// Distances held at once while the means are taken (2²² of them, 32 MiB): the queries go in
/// blocks of that many distances, so a 10-million-point cloud needs no 1.7 GB table.
const DISTANCES_AT_ONCE: usize = 1 << 22;

/// Mean distance from each point to its `k` nearest other points (a duplicate counts as a
/// neighbour at distance 0). Clouds with at most `k` points use all the others.
pub fn mean_neighbor_distances(points: &[[f64; 3]], k: usize) -> Vec<f64> {
    mean_distances_in_blocks(points, k, DISTANCES_AT_ONCE)
}

/// [`mean_neighbor_distances`], the queries in blocks of at most `budget` distances.
fn mean_distances_in_blocks(points: &[[f64; 3]], k: usize, budget: usize) -> Vec<f64> {
    if points.len() < 2 || k == 0 {
        return vec![0.0; points.len()];
    }
    let k = k.min(points.len() - 1);
    let rows = (budget / (k + 1)).max(1);
    let search = KnnSearch::new(points, k + 1);
    points
        .chunks(rows)
        .flat_map(|queries| {
            // The first neighbour is at distance 0: the point itself, or a duplicate of it,
            // which is the same distance either way; drop one zero.
            let d = search.distances(queries);
            d.chunks_exact(k + 1)
                .map(|row| row[1..].iter().sum::<f64>() / k as f64)
                .collect::<Vec<_>>()
        })
        .collect()
}

/// Inlier flags for a cloud. `k = 0` keeps everything.
pub fn inliers(points: &[[f64; 3]], params: SorParams) -> Vec<bool> {
    if params.k == 0 || points.len() < 3 {
        return vec![true; points.len()];
    }
    let mean_d = mean_neighbor_distances(points, params.k);
    let n = mean_d.len() as f64;
    let sum: f64 = mean_d.iter().sum();
    let sq_sum: f64 = mean_d.iter().map(|d| d * d).sum();
    let mean = sum / n;
    let variance = ((sq_sum - sum * sum / n) / (n - 1.0)).max(0.0);
    let threshold = mean + params.std_mul * variance.sqrt();
    mean_d.iter().map(|&d| d <= threshold).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The definition, by brute force.
    fn reference(points: &[[f64; 3]], params: SorParams) -> Vec<bool> {
        let k = params.k.min(points.len() - 1);
        let mean_d: Vec<f64> = points
            .iter()
            .enumerate()
            .map(|(i, p)| {
                let mut d: Vec<f64> = points
                    .iter()
                    .enumerate()
                    .filter(|(j, _)| *j != i)
                    .map(|(_, q)| ((0..3).map(|a| (p[a] - q[a]).powi(2)).sum::<f64>()).sqrt())
                    .collect();
                d.select_nth_unstable_by(k - 1, f64::total_cmp);
                d[..k].sort_by(f64::total_cmp);
                d[..k].iter().sum::<f64>() / k as f64
            })
            .collect();
        let n = mean_d.len() as f64;
        let mean = mean_d.iter().sum::<f64>() / n;
        let var = mean_d.iter().map(|d| (d - mean).powi(2)).sum::<f64>() / (n - 1.0);
        mean_d
            .iter()
            .map(|&d| d <= mean + params.std_mul * var.sqrt())
            .collect()
    }

    #[test]
    fn matches_brute_force_with_ties_duplicates_and_outliers() {
        let mut rng = crate::core::rng::Lcg::new(7);
        for trial in 0..6 {
            let mut points: Vec<[f64; 3]> = (0..400)
                .map(|_| [rng.next_f64(), rng.next_f64(), rng.next_f64() * 0.1])
                .collect();
            // Exact duplicates, grid points with tied distances, and far outliers.
            for i in 0..40 {
                points.push(points[i * 3]);
            }
            for i in 0..5 {
                for j in 0..5 {
                    points.push([i as f64 * 0.05, j as f64 * 0.05, 0.5]);
                }
            }
            for i in 0..8 {
                points.push([3.0 + i as f64 * (1.0 + rng.next_f64()), -2.0, 1.0]);
            }
            let params = SorParams {
                k: [1, 5, 20, 20, 50, 8][trial],
                std_mul: [1.0, 2.0, 5.0, 0.5, 1.0, 0.0][trial],
            };
            let got = inliers(&points, params);
            let want = reference(&points, params);
            assert_eq!(got, want, "trial {trial}");
            if params.std_mul >= 1.0 {
                assert!(!got[got.len() - 1], "a far outlier is removed");
            }
        }
    }

    /// Blocks of queries give the same means as one table of every distance, on the grid's
    /// path (enough points) and on the k-d tree's (k past the cloud's size).
    #[test]
    fn blocks_of_queries_change_nothing() {
        let mut rng = crate::core::rng::Lcg::new(3);
        let mut cloud = |n: usize| -> Vec<[f64; 3]> {
            (0..n)
                .map(|_| [rng.next_f64(), rng.next_f64(), 0.05 * rng.next_f64()])
                .collect()
        };
        let (large, small) = (cloud(5000), cloud(300));
        for (points, k, budgets) in [
            (&large, 20, [21 * 700, 1000]),
            (&large, 1, [2 * 3000, 1]),
            (&small, 5000, [1, 301 * 7]),
        ] {
            let whole = mean_distances_in_blocks(points, k, usize::MAX);
            for budget in budgets {
                assert_eq!(mean_distances_in_blocks(points, k, budget), whole, "k {k}");
            }
        }
    }

    #[test]
    fn matches_brute_force_on_a_scan_sized_surface() {
        // Large enough for the grid search, with scan-line density changes and outliers.
        let mut rng = crate::core::rng::Lcg::new(5);
        let mut points: Vec<[f64; 3]> = (0..6000)
            .map(|i| {
                let line = (i % 60) as f64 / 60.0;
                [
                    rng.next_f64(),
                    0.3 * line + 0.002 * rng.next_f64(),
                    0.2 * rng.next_f64(),
                ]
            })
            .collect();
        let dups: Vec<[f64; 3]> = points.iter().step_by(50).cloned().collect();
        points.extend(dups);
        points.extend([[2.0, 2.0, 2.0], [1.5, -1.0, 0.0], [0.5, 0.15, 0.6]]);
        let params = SorParams::default();
        let got = inliers(&points, params);
        assert_eq!(got, reference(&points, params));
        assert!(!got[got.len() - 3] && !got[got.len() - 2]);
    }

    #[test]
    fn small_and_degenerate_clouds() {
        assert_eq!(inliers(&[], SorParams::default()), Vec::<bool>::new());
        assert_eq!(inliers(&[[0.0; 3]; 2], SorParams::default()), vec![true; 2]);
        // All identical: every mean distance is 0, nothing is an outlier.
        assert_eq!(
            inliers(&[[1.0; 3]; 30], SorParams::default()),
            vec![true; 30]
        );
        // Fewer points than k: all the others are the neighbours.
        let pts = [
            [0.0, 0.0, 0.0],
            [0.1, 0.0, 0.0],
            [0.2, 0.0, 0.0],
            [5.0, 0.0, 0.0],
        ];
        let params = SorParams {
            k: 20,
            std_mul: 1.0,
        };
        assert_eq!(inliers(&pts, params), reference(&pts, params));
    }
}
