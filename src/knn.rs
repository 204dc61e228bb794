//! Nearest-neighbour queries over a static cloud (kiddo's immutable k-d tree), batched over
//! rayon.

use kiddo::{ImmutableKdTree, SquaredEuclidean};
use rayon::prelude::*;
use std::num::NonZero;

/// A k-d tree over a fixed set of points.
pub struct KnnIndex {
    tree: ImmutableKdTree<f64, 3>,
    len: usize,
}

impl KnnIndex {
    /// Builds the index; `points` must not be empty.
    pub fn new(points: &[[f64; 3]]) -> KnnIndex {
        assert!(!points.is_empty(), "a k-d tree needs at least one point");
        let tree = ImmutableKdTree::new_from_slice(points)
            .expect("a k-d tree builds from any finite, non-empty point set");
        KnnIndex {
            tree,
            len: points.len(),
        }
    }

    pub fn len(&self) -> usize {
        self.len
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Euclidean distance from each query to its nearest indexed point.
    pub fn nearest_distances(&self, queries: &[[f64; 3]]) -> Vec<f64> {
        queries
            .par_iter()
            .with_min_len(1024)
            .map(|q| {
                self.tree
                    .query(q)
                    .nearest_one::<SquaredEuclidean<f64>>()
                    .execute()
                    .distance
                    .sqrt()
            })
            .collect()
    }

    /// For each query, the Euclidean distances to its `k` nearest indexed points, ascending,
    /// written into `out[q * k..(q + 1) * k]`; fewer than `k` indexed points leave the tail
    /// as `f64::NAN`.
    pub fn k_nearest_distances(&self, queries: &[[f64; 3]], k: usize) -> Vec<f64> {
        let mut out = vec![f64::NAN; queries.len() * k];
        let Some(k_nz) = NonZero::new(k.min(self.len)) else {
            return out;
        };
        out.par_chunks_mut(k)
            .zip(queries.par_iter())
            .with_min_len(256)
            .for_each(|(row, q)| {
                let found = self
                    .tree
                    .query(q)
                    .nearest_n::<SquaredEuclidean<f64>>(k_nz)
                    .execute();
                for (slot, r) in row.iter_mut().zip(found) {
                    *slot = r.distance.sqrt();
                }
            });
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nearest_and_k_nearest_match_brute_force() {
        let points: Vec<[f64; 3]> = (0..500)
            .map(|i| {
                let t = i as f64 * 0.618;
                [t.sin(), (t * 1.3).cos(), (t * 0.7).sin() * 0.5]
            })
            .collect();
        let queries: Vec<[f64; 3]> = (0..50).map(|i| [i as f64 * 0.01, 0.1, -0.2]).collect();
        let index = KnnIndex::new(&points);
        let nearest = index.nearest_distances(&queries);
        let knn = index.k_nearest_distances(&queries, 7);
        for (qi, q) in queries.iter().enumerate() {
            let mut d: Vec<f64> = points
                .iter()
                .map(|p| ((0..3).map(|i| (p[i] - q[i]).powi(2)).sum::<f64>()).sqrt())
                .collect();
            d.sort_by(f64::total_cmp);
            assert!((nearest[qi] - d[0]).abs() < 1e-12);
            for j in 0..7 {
                assert!((knn[qi * 7 + j] - d[j]).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn fewer_points_than_k_leaves_nan() {
        let index = KnnIndex::new(&[[0.0; 3], [1.0, 0.0, 0.0]]);
        let d = index.k_nearest_distances(&[[0.0; 3]], 3);
        assert_eq!(&d[..2], &[0.0, 1.0]);
        assert!(d[2].is_nan());
    }
}
