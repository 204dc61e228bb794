//! Nearest-neighbour queries over a static cloud, batched over rayon.
//!
//! [`knn_distances`] is the fast path: a uniform grid whose cell size is fitted to the cloud's
//! density, queries processed cell by cell against the points of the 3×3×3 block around the
//! cell. A result is exact whenever its k-th distance is within the block; the few queries where
//! it is not (sparse regions, isolated points) go to kiddo's k-d tree ([`KnnIndex`]).

use crate::core::cloud::Aabb;
use kiddo::{ImmutableKdTree, SquaredEuclidean};
use rayon::prelude::*;
use std::num::NonZero;
use std::sync::OnceLock;

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

    /// For each query, the Euclidean distances to its `k` nearest indexed points, ascending,
    /// written into `out[q * k..(q + 1) * k]`; fewer than `k` indexed points leave the tail
    /// as `f64::NAN`.
    pub fn k_nearest_distances(&self, queries: &[[f64; 3]], k: usize) -> Vec<f64> {
        self.k_nearest_rows(queries, k, f64::NAN, |row, found| {
            for (slot, &(d2, _)) in row.iter_mut().zip(found) {
                *slot = d2.sqrt();
            }
        })
    }

    /// For each query, the indices of its `k` nearest indexed points, nearest first, written
    /// into `out[q * k..(q + 1) * k]`; fewer than `k` indexed points repeat the farthest.
    pub fn k_nearest(&self, queries: &[[f64; 3]], k: usize) -> Vec<usize> {
        self.k_nearest_rows(queries, k, 0, |row, found| {
            let mut last = 0;
            for (i, slot) in row.iter_mut().enumerate() {
                last = found.get(i).map_or(last, |&(_, item)| item);
                *slot = last;
            }
        })
    }

    /// A row of `k` values per query, each filled by `fill` from the query's nearest indexed
    /// points as (squared distance, index), nearest first, fewer than `k` when the index holds
    /// fewer; rows start as `empty`.
    fn k_nearest_rows<T: Copy + Send + Sync>(
        &self,
        queries: &[[f64; 3]],
        k: usize,
        empty: T,
        fill: impl Fn(&mut [T], &[(f64, usize)]) + Sync,
    ) -> Vec<T> {
        let mut out = vec![empty; queries.len() * k];
        let Some(k_nz) = NonZero::new(k.min(self.len)) else {
            return out;
        };
        out.par_chunks_mut(k)
            .zip(queries.par_iter())
            .with_min_len(256)
            // One buffer per worker, so the results cost no allocation beyond kiddo's own.
            .for_each_init(Vec::new, |found, (row, q)| {
                found.clear();
                found.extend(
                    self.tree
                        .query(q)
                        .nearest_n::<SquaredEuclidean<f64>>(k_nz)
                        .execute()
                        .into_iter()
                        .map(|r| (r.distance, r.item as usize)),
                );
                fill(row, found);
            });
        out
    }

    /// For each query, the index of its nearest indexed point and the distance to it.
    pub fn nearest(&self, queries: &[[f64; 3]]) -> Vec<(usize, f64)> {
        queries
            .par_iter()
            .with_min_len(256)
            .map(|q| {
                let found = self
                    .tree
                    .query(q)
                    .nearest_n::<SquaredEuclidean<f64>>(NonZero::<usize>::MIN)
                    .execute();
                let r = found.into_iter().next().expect("the index is not empty");
                (r.item as usize, r.distance.sqrt())
            })
            .collect()
    }
}

/// Most cells a grid may have per point before the k-d tree is used for everything (a cloud
/// with far outliers has a huge, mostly empty box); keeps the grid under ~64 bytes a point.
const MAX_CELLS_PER_POINT: usize = 16;
/// Below this many points the grid does not pay for itself.
const MIN_GRID_POINTS: usize = 4096;

/// Per-thread scratch: the block's candidates (structure of arrays, so distances vectorize)
/// and one query's distances.
#[derive(Default)]
struct Scratch {
    xs: Vec<f64>,
    ys: Vec<f64>,
    zs: Vec<f64>,
    d2: Vec<f64>,
    near: Vec<f64>,
}

struct Grid {
    origin: [f64; 3],
    cell: f64,
    dims: [usize; 3],
    /// Points sorted by cell.
    sorted: Vec<[f64; 3]>,
    /// `starts[c]..starts[c + 1]` are cell `c`'s points in `sorted`.
    starts: Vec<u32>,
}

impl Grid {
    fn cell_coords(&self, p: &[f64; 3]) -> Option<[usize; 3]> {
        let mut c = [0; 3];
        for a in 0..3 {
            let f = ((p[a] - self.origin[a]) / self.cell).floor();
            if f.is_nan() || f < 0.0 || f as usize > self.dims[a] {
                return None;
            }
            c[a] = (f as usize).min(self.dims[a] - 1);
        }
        Some(c)
    }

    fn index(&self, c: [usize; 3]) -> usize {
        (c[0] * self.dims[1] + c[1]) * self.dims[2] + c[2]
    }

    /// A grid over `points` whose cells hold about `per_cell` points as seen from a point (the
    /// occupancy of a point's own cell, averaged over points, so that dense scan lines count
    /// as much as they are queried), assuming the points sample surfaces (occupancy grows with
    /// the square of the cell size).
    fn build(points: &[[f64; 3]], per_cell: f64) -> Option<Grid> {
        let max_cells = MAX_CELLS_PER_POINT * points.len();
        let b = Aabb::of(points)?;
        let e = b.extent();
        let volume: f64 = e.iter().map(|v| v.max(1e-9)).product();
        let coarse = 4.0 * (volume / points.len() as f64).cbrt();
        let dims_for = |cell: f64| e.map(|v| (v / cell).floor() as usize + 1);
        let seen_occupancy = |cell: f64| -> Option<f64> {
            let dims = dims_for(cell);
            let total = dims.iter().try_fold(1usize, |acc, &d| acc.checked_mul(d))?;
            if total > max_cells {
                return None;
            }
            let mut counts = vec![0u32; total];
            for p in points {
                let c = [0, 1, 2].map(|a| (((p[a] - b.min[a]) / cell) as usize).min(dims[a] - 1));
                counts[(c[0] * dims[1] + c[1]) * dims[2] + c[2]] += 1;
            }
            let squares: f64 = counts.iter().map(|&m| (m as f64).powi(2)).sum();
            Some(squares / points.len() as f64)
        };
        let mean = seen_occupancy(coarse)?;
        let cell = coarse * (per_cell / mean).sqrt();
        let dims = dims_for(cell);
        let total = dims.iter().try_fold(1usize, |acc, &d| acc.checked_mul(d))?;
        if total > max_cells || cell.is_nan() || cell <= 0.0 {
            return None;
        }
        let mut grid = Grid {
            origin: b.min,
            cell,
            dims,
            sorted: Vec::new(),
            starts: vec![0; total + 1],
        };
        let cells: Vec<usize> = points
            .iter()
            .map(|p| grid.index(grid.cell_coords(p).expect("inside its own box")))
            .collect();
        for &c in &cells {
            grid.starts[c + 1] += 1;
        }
        for c in 0..total {
            grid.starts[c + 1] += grid.starts[c];
        }
        let mut fill = grid.starts.clone();
        grid.sorted = vec![[0.0; 3]; points.len()];
        for (p, &c) in points.iter().zip(&cells) {
            grid.sorted[fill[c] as usize] = *p;
            fill[c] += 1;
        }
        Some(grid)
    }

    /// Loads the points of the 3×3×3 block around cell `c` into the scratch.
    fn load_block(&self, c: [usize; 3], s: &mut Scratch) {
        s.xs.clear();
        s.ys.clear();
        s.zs.clear();
        let lo = c.map(|v| v.saturating_sub(1));
        let hi = [0, 1, 2].map(|a| (c[a] + 1).min(self.dims[a] - 1));
        for x in lo[0]..=hi[0] {
            for y in lo[1]..=hi[1] {
                let row = self.index([x, y, 0]);
                let range =
                    self.starts[row + lo[2]] as usize..self.starts[row + hi[2] + 1] as usize;
                for p in &self.sorted[range] {
                    s.xs.push(p[0]);
                    s.ys.push(p[1]);
                    s.zs.push(p[2]);
                }
            }
        }
    }

    /// Squared distance from `q` in cell `c` to the nearest face of its block that has cells
    /// beyond it: no point outside the block is nearer.
    fn guard2(&self, q: &[f64; 3], c: [usize; 3]) -> f64 {
        let mut guard = f64::INFINITY;
        for a in 0..3 {
            if c[a] > 0 {
                guard = guard.min(q[a] - (self.origin[a] + (c[a] - 1) as f64 * self.cell));
            }
            if c[a] + 1 < self.dims[a] - 1 {
                guard = guard.min(self.origin[a] + (c[a] + 2) as f64 * self.cell - q[a]);
            }
        }
        guard * guard
    }

    /// The k smallest distances from `q` to the loaded block, ascending, into `out`, when they
    /// are provably the k smallest of the whole cloud; otherwise `out` is left as it was.
    fn block_knn(&self, q: &[f64; 3], c: [usize; 3], k: usize, s: &mut Scratch, out: &mut [f64]) {
        let n = s.xs.len();
        s.d2.resize(n, 0.0);
        for i in 0..n {
            s.d2[i] =
                (s.xs[i] - q[0]).powi(2) + (s.ys[i] - q[1]).powi(2) + (s.zs[i] - q[2]).powi(2);
        }
        let guard2 = self.guard2(q, c);
        s.near.clear();
        s.near.extend(s.d2.iter().copied().filter(|&d| d <= guard2));
        if s.near.len() < k {
            return;
        }
        if s.near.len() > k {
            s.near.select_nth_unstable_by(k - 1, f64::total_cmp);
        }
        s.near[..k].sort_unstable_by(f64::total_cmp);
        for (o, d) in out.iter_mut().zip(&s.near[..k]) {
            *o = d.sqrt();
        }
    }
}

/// For each query, the Euclidean distances to its `k` nearest points, ascending, in
/// `out[q * k..(q + 1) * k]` (NaN where there are fewer than `k` points). Exact: the same
/// values as a brute-force search.
pub fn knn_distances(points: &[[f64; 3]], queries: &[[f64; 3]], k: usize) -> Vec<f64> {
    KnnSearch::new(points, k).distances(queries)
}

/// [`knn_distances`] from one set of points for any number of sets of queries: the grid (and,
/// where the grid cannot settle a query, the k-d tree) is built once, so that queries can go in
/// blocks whose distances fit in memory.
pub struct KnnSearch<'a> {
    points: &'a [[f64; 3]],
    k: usize,
    grid: Option<Grid>,
    tree: OnceLock<KnnIndex>,
}

impl<'a> KnnSearch<'a> {
    pub fn new(points: &'a [[f64; 3]], k: usize) -> KnnSearch<'a> {
        let grid = if k > 0 && points.len() >= MIN_GRID_POINTS && k < points.len() {
            // About k/2 points per cell puts ~1.5k within one cell size of a query on a
            // surface, so the k nearest nearly always lie inside the block.
            Grid::build(points, (0.5 * (k + 1) as f64).max(2.0))
        } else {
            None
        };
        KnnSearch {
            points,
            k,
            grid,
            tree: OnceLock::new(),
        }
    }

    fn tree(&self) -> &KnnIndex {
        self.tree.get_or_init(|| KnnIndex::new(self.points))
    }

    /// As [`knn_distances`] for these `queries`.
    pub fn distances(&self, queries: &[[f64; 3]]) -> Vec<f64> {
        let k = self.k;
        if k == 0 || self.points.is_empty() {
            return vec![f64::NAN; queries.len() * k];
        }
        let Some(grid) = &self.grid else {
            return self.tree().k_nearest_distances(queries, k);
        };
        self.on_grid(grid, queries)
    }

    fn on_grid(&self, grid: &Grid, queries: &[[f64; 3]]) -> Vec<f64> {
        let k = self.k;
        // Queries grouped by cell: each group shares one block of candidates.
        let mut order: Vec<(u32, u32)> = queries
            .iter()
            .enumerate()
            .map(|(i, q)| {
                (
                    grid.cell_coords(q)
                        .map_or(u32::MAX, |c| grid.index(c) as u32),
                    i as u32,
                )
            })
            .collect();
        order.sort_unstable();
        let groups: Vec<&[(u32, u32)]> = order.chunk_by(|a, b| a.0 == b.0).collect();
        // Results in query-sorted order, one disjoint slice per group, so the parallel pass writes
        // straight into one buffer; a slot left NaN is a query the block could not settle (the grid
        // is only used when there are at least k points, so NaN means nothing else).
        let mut by_order = vec![f64::NAN; queries.len() * k];
        let mut slices = Vec::with_capacity(groups.len());
        let mut rest = by_order.as_mut_slice();
        for group in &groups {
            let (head, tail) = rest.split_at_mut(group.len() * k);
            slices.push(head);
            rest = tail;
        }
        groups
            .par_iter()
            .zip(slices.into_par_iter())
            .with_min_len(16)
            .for_each_init(Scratch::default, |scratch, (group, found)| {
                let Some(c) = (group[0].0 != u32::MAX)
                    .then(|| grid.cell_coords(&queries[group[0].1 as usize]))
                    .flatten()
                else {
                    return;
                };
                grid.load_block(c, scratch);
                for (j, &(_, i)) in group.iter().enumerate() {
                    let q = &queries[i as usize];
                    grid.block_knn(q, c, k, scratch, &mut found[j * k..(j + 1) * k]);
                }
            });
        let mut out = vec![f64::NAN; queries.len() * k];
        let mut missed = Vec::new();
        for (j, &(_, i)) in order.iter().enumerate() {
            let (i, found) = (i as usize, &by_order[j * k..(j + 1) * k]);
            if found[0].is_nan() {
                missed.push(i);
            } else {
                out[i * k..(i + 1) * k].copy_from_slice(found);
            }
        }
        if !missed.is_empty() {
            let qs: Vec<[f64; 3]> = missed.iter().map(|&i| queries[i]).collect();
            let d = self.tree().k_nearest_distances(&qs, k);
            for (j, &i) in missed.iter().enumerate() {
                out[i * k..(i + 1) * k].copy_from_slice(&d[j * k..(j + 1) * k]);
            }
        }
        out
    }
}

/// Points bucketed in cubic cells at least as large as a match distance, so "the nearest point
/// closer than it" reads the 3×3×3 cells around a query. Where most queries have nothing that
/// close (the mirror images of a one-sided scan, the symmetry search's candidates), a k-d tree
/// walks far from each before it can say so: that took most of `complete`'s symmetry time.
pub struct MatchGrid {
    origin: [f64; 3],
    cell: f64,
    distance: f64,
    dims: [usize; 3],
    /// `points[starts[i]..starts[i + 1]]` lie in cell `i`.
    starts: Vec<u32>,
    points: Vec<[f64; 3]>,
}

/// Cells a [`MatchGrid`] may have; points spread over more (far outliers) get coarser cells,
/// which only costs time.
const MAX_MATCH_CELLS: usize = 1 << 22;

impl MatchGrid {
    /// The grid over `points` (not empty) for matches closer than `distance`; a distance that
    /// is not positive matches nothing.
    pub fn new(points: &[[f64; 3]], distance: f64) -> MatchGrid {
        let Aabb { min: lo, max: hi } = Aabb::of(points).expect("a grid needs at least one point");
        // A zero cell would never grow below; NaN and zero distances find no match either way.
        let mut cell = if distance > 0.0 {
            distance
        } else {
            f64::MIN_POSITIVE
        };
        let dims = loop {
            let dims = [0, 1, 2]
                .map(|i| ((hi[i] - lo[i]) / cell).min(MAX_MATCH_CELLS as f64) as usize + 1);
            // In floats: three sides of up to MAX_MATCH_CELLS overflow a usize product.
            if dims.iter().map(|&d| d as f64).product::<f64>() <= MAX_MATCH_CELLS as f64 {
                break dims;
            }
            cell *= 2.0;
        };
        let mut grid = MatchGrid {
            origin: lo,
            cell,
            distance: distance.max(0.0),
            dims,
            starts: vec![0; dims.iter().product::<usize>() + 1],
            points: Vec::with_capacity(points.len()),
        };
        let cells: Vec<usize> = points
            .iter()
            .map(|p| grid.cell_of(p).expect("a point lies in its own box"))
            .collect();
        for &c in &cells {
            grid.starts[c + 1] += 1;
        }
        for i in 1..grid.starts.len() {
            grid.starts[i] += grid.starts[i - 1];
        }
        let mut order: Vec<usize> = (0..points.len()).collect();
        order.sort_by_key(|&i| cells[i]);
        grid.points = order.into_iter().map(|i| points[i]).collect();
        grid
    }

    /// Cell coordinates, clamped just outside the grid so neighbours of far queries stay in
    /// range.
    fn coords(&self, p: &[f64; 3]) -> [i64; 3] {
        [0, 1, 2].map(|i| {
            let c = ((p[i] - self.origin[i]) / self.cell).floor();
            c.clamp(-2.0, self.dims[i] as f64 + 1.0) as i64
        })
    }

    fn cell_of(&self, p: &[f64; 3]) -> Option<usize> {
        self.index(self.coords(p))
    }

    fn index(&self, c: [i64; 3]) -> Option<usize> {
        let inside = (0..3).all(|i| c[i] >= 0 && (c[i] as usize) < self.dims[i]);
        inside
            .then(|| (c[0] as usize * self.dims[1] + c[1] as usize) * self.dims[2] + c[2] as usize)
    }

    /// The squared distance from `q` to its nearest point when that is strictly closer than
    /// the grid's match distance. Cells are at least that large, so the ball around `q` lies
    /// in the 3×3×3 cells around the one `q` is in.
    pub fn nearest_within(&self, q: [f64; 3]) -> Option<f64> {
        let mut best = self.distance * self.distance;
        let mut found = false;
        let c = self.coords(&q);
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    let Some(i) = self.index([c[0] + dx, c[1] + dy, c[2] + dz]) else {
                        continue;
                    };
                    for p in &self.points[self.starts[i] as usize..self.starts[i + 1] as usize] {
                        let d = [0, 1, 2].map(|k| p[k] - q[k]);
                        let d2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
                        if d2 < best {
                            best = d2;
                            found = true;
                        }
                    }
                }
            }
        }
        found.then_some(best)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nearest_names_the_closest_point() {
        let points = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 2.0, 0.0]];
        let index = KnnIndex::new(&points);
        let found = index.nearest(&[[0.9, 0.1, 0.0], [0.1, 1.5, 0.0], [-1.0, 0.0, 0.0]]);
        assert_eq!(found.iter().map(|f| f.0).collect::<Vec<_>>(), [1, 2, 0]);
        assert!((found[2].1 - 1.0).abs() < 1e-12);
    }

    #[test]
    fn grid_search_is_exact_on_surfaces_with_outliers_and_duplicates() {
        let mut rng = crate::core::rng::Lcg::new(11);
        let mut rnd = || rng.next_f64();
        // A curved sheet, a dense blob, duplicates and a few far points.
        let mut points: Vec<[f64; 3]> = (0..6000)
            .map(|_| {
                let (u, v) = (rnd(), rnd());
                [u, 0.2 * (6.0 * u).sin() + 0.05 * v, v * 0.6]
            })
            .collect();
        points.extend((0..500).map(|_| [0.5 + 0.001 * rnd(), 0.5, 0.3 + 0.001 * rnd()]));
        let dups: Vec<[f64; 3]> = (0..200).map(|i| points[i * 7]).collect();
        points.extend(dups);
        points.extend([[3.0, 3.0, 3.0], [-2.0, 0.0, 1.0]]);
        let queries: Vec<[f64; 3]> = points
            .iter()
            .step_by(13)
            .cloned()
            .chain([[10.0, 0.0, 0.0]])
            .collect();
        for k in [1, 5, 21] {
            let fast = knn_distances(&points, &queries, k);
            let slow = KnnIndex::new(&points).k_nearest_distances(&queries, k);
            for (qi, q) in queries.iter().enumerate() {
                let mut d: Vec<f64> = points
                    .iter()
                    .map(|p| {
                        ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2))
                            .sqrt()
                    })
                    .collect();
                d.sort_by(f64::total_cmp);
                assert_eq!(&fast[qi * k..(qi + 1) * k], &d[..k], "k = {k}, query {qi}");
                for j in 0..k {
                    assert!((slow[qi * k + j] - d[j]).abs() < 1e-12);
                }
            }
        }
    }

    #[test]
    fn match_grid_finds_exactly_the_points_closer_than_its_distance() {
        let mut rng = crate::core::rng::Lcg::new(5);
        let mut rnd = || rng.next_f64();
        let mut points: Vec<[f64; 3]> = (0..3000).map(|_| [rnd(), 0.3 * rnd(), rnd()]).collect();
        let queries: Vec<[f64; 3]> = (0..400)
            .map(|_| [2.0 * rnd() - 0.5, rnd() - 0.3, 2.0 * rnd() - 0.5])
            .chain([[50.0, 0.0, 0.0], [-3.0, 7.0, 0.5]])
            .collect();
        let brute = |points: &[[f64; 3]], q: &[f64; 3], distance: f64| {
            points
                .iter()
                .map(|p| (0..3).map(|i| (p[i] - q[i]).powi(2)).sum::<f64>())
                .filter(|&d2| d2 < distance * distance)
                .min_by(f64::total_cmp)
        };
        // Far points coarsen the cells past the match distance; it must not change an answer.
        for far in [false, true] {
            if far {
                points.extend([[1e4, 0.0, 0.0], [0.0, -1e4, 1e4]]);
            }
            for distance in [0.004, 0.03, 0.2] {
                let grid = MatchGrid::new(&points, distance);
                for q in &queries {
                    assert_eq!(
                        grid.nearest_within(*q),
                        brute(&points, q, distance),
                        "{q:?}"
                    );
                }
            }
        }
        for distance in [0.0, -1.0, f64::NAN] {
            let grid = MatchGrid::new(&points, distance);
            assert_eq!(grid.nearest_within(points[0]), None, "distance {distance}");
        }
    }

    #[test]
    fn k_nearest_matches_brute_force() {
        let points: Vec<[f64; 3]> = (0..500)
            .map(|i| {
                let t = i as f64 * 0.618;
                [t.sin(), (t * 1.3).cos(), (t * 0.7).sin() * 0.5]
            })
            .collect();
        let queries: Vec<[f64; 3]> = (0..50).map(|i| [i as f64 * 0.01, 0.1, -0.2]).collect();
        let index = KnnIndex::new(&points);
        let knn = index.k_nearest_distances(&queries, 7);
        for (qi, q) in queries.iter().enumerate() {
            let mut d: Vec<f64> = points
                .iter()
                .map(|p| ((0..3).map(|i| (p[i] - q[i]).powi(2)).sum::<f64>()).sqrt())
                .collect();
            d.sort_by(f64::total_cmp);
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
