//! What real segmentation leaves around a vehicle, removed before completion (`--clean`):
//! ground under the wheels, isolated noise points and pieces of other objects at the edge.
//!
//! Sizes are relative to the cloud's longest side, so metres and normalized clouds behave alike.

use crate::complete::orient::upright_points;
use crate::core::cloud::{Aabb, PointCloud};
use crate::core::frame::UpAxis;
use crate::core::knn::KnnIndex;
use serde::{Deserialize, Serialize};
use std::collections::HashMap;

/// The tunables of cleaning; sizes are shares of the cloud's longest side. A file may give some
/// of them (`complete --tuning`); the rest keep these defaults.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CleanParams {
    /// Ground candidates lie this far above the lowest point.
    pub ground_band: f64,
    /// Points this close to the fitted ground plane, or below it, are ground.
    pub ground_distance: f64,
    /// A plane steeper than this (rise over run) is no ground.
    pub ground_slope: f64,
    /// Ground covers at least this share of the footprint grid's cells (wheels' contact
    /// patches cover a few).
    pub ground_cover: f64,
    /// Cells along each side of the footprint grid the ground cover is counted on.
    pub grid: usize,
    /// The neighbour whose distance is a point's spacing.
    pub spacing_neighbour: usize,
    /// A point whose spacing exceeds this multiple of the median is isolated.
    pub isolated: f64,
    /// Points join one object within this multiple of the median spacing, or `link_share` of
    /// the longest side, whichever is larger.
    pub link_spacings: f64,
    pub link_share: f64,
    /// Another object is kept when it has this share of the largest one's points.
    pub keep_share: f64,
}

impl Default for CleanParams {
    fn default() -> Self {
        CleanParams {
            ground_band: 0.04,
            ground_distance: 0.012,
            ground_slope: 0.15,
            ground_cover: 0.12,
            grid: 20,
            spacing_neighbour: 4,
            isolated: 6.0,
            // The middle of the reach a plain voxel grid of 8 had, which parted sparse cars
            // (lab/2026-12-06-clean-clutter).
            link_spacings: 12.0,
            link_share: 0.02,
            keep_share: 0.25,
        }
    }
}

/// How many points each step removed.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct CleanReport {
    pub ground: usize,
    pub isolated: usize,
    pub other_objects: usize,
}

impl CleanReport {
    pub fn total(&self) -> usize {
        self.ground + self.isolated + self.other_objects
    }
}

/// The cloud without its ground, isolated points and other objects.
pub fn clean(cloud: &PointCloud, up: UpAxis, tune: &CleanParams) -> (PointCloud, CleanReport) {
    let mut report = CleanReport::default();
    if cloud.len() < 10 {
        return (cloud.clone(), report);
    }
    let points = upright_points(cloud, up);
    let mut keep = vec![true; points.len()];

    // Isolated points first: one stray return below the wheels or far to the side would
    // otherwise set the ground band and the sizes.
    let index = KnnIndex::new(&points);
    let k = tune.spacing_neighbour + 1;
    let spacing: Vec<f64> = index
        .k_nearest_distances(&points, k)
        .chunks(k)
        .map(|d| d[k - 1])
        .collect();
    let median = median(&spacing);
    for (k, &s) in keep.iter_mut().zip(&spacing) {
        if s > tune.isolated * median {
            *k = false;
            report.isolated += 1;
        }
    }

    let remaining: Vec<usize> = (0..points.len()).filter(|&i| keep[i]).collect();
    let subset: Vec<[f64; 3]> = remaining.iter().map(|&i| points[i]).collect();
    let extent = Aabb::of(&subset).map_or(0.0, |b| b.longest_side());
    if let Some(ground) = ground_points(&subset, extent, tune) {
        for (&i, g) in remaining.iter().zip(&ground) {
            if *g {
                keep[i] = false;
                report.ground += 1;
            }
        }
    }

    let remaining: Vec<usize> = (0..points.len()).filter(|&i| keep[i]).collect();
    let link = (tune.link_spacings * median).max(tune.link_share * extent);
    for i in other_objects(&points, &remaining, link, tune.keep_share) {
        keep[i] = false;
        report.other_objects += 1;
    }
    (cloud.filter(&keep), report)
}

fn median(values: &[f64]) -> f64 {
    let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return 0.0;
    }
    let mid = v.len() / 2;
    *v.select_nth_unstable_by(mid, f64::total_cmp).1
}

/// Which points are ground: a plane `y = a·x + b·z + c` fitted (least squares, twice trimmed)
/// to the lowest band, accepted when nearly level and spread under much of the footprint.
fn ground_points(points: &[[f64; 3]], extent: f64, tune: &CleanParams) -> Option<Vec<bool>> {
    let lowest = points.iter().map(|p| p[1]).fold(f64::MAX, f64::min);
    let mut band: Vec<[f64; 3]> = points
        .iter()
        .copied()
        .filter(|p| p[1] < lowest + tune.ground_band * extent)
        .collect();
    let mut plane = None;
    for _ in 0..3 {
        let fitted = fit_plane(&band)?;
        band.retain(|p| (p[1] - height(fitted, p)).abs() < tune.ground_distance * extent / 2.0);
        plane = Some(fitted);
    }
    let plane = plane?;
    if plane[0].abs() > tune.ground_slope || plane[1].abs() > tune.ground_slope || band.len() < 10 {
        return None;
    }
    let (lo, hi) = points
        .iter()
        .fold(([f64::MAX; 2], [f64::MIN; 2]), |(lo, hi), p| {
            (
                [lo[0].min(p[0]), lo[1].min(p[2])],
                [hi[0].max(p[0]), hi[1].max(p[2])],
            )
        });
    let cell = |v: f64, i: usize| {
        (((v - lo[i]) / (hi[i] - lo[i]).max(f64::MIN_POSITIVE) * tune.grid as f64) as usize)
            .min(tune.grid - 1)
    };
    let mut covered = vec![false; tune.grid * tune.grid];
    for p in &band {
        covered[cell(p[0], 0) * tune.grid + cell(p[2], 1)] = true;
    }
    let cover = covered.iter().filter(|&&c| c).count() as f64 / (tune.grid * tune.grid) as f64;
    if cover < tune.ground_cover {
        return None;
    }
    Some(
        points
            .iter()
            .map(|p| p[1] - height(plane, p) < tune.ground_distance * extent)
            .collect(),
    )
}

fn height(plane: [f64; 3], p: &[f64; 3]) -> f64 {
    plane[0] * p[0] + plane[1] * p[2] + plane[2]
}

/// Least-squares `y = a·x + b·z + c`; `None` when the points do not fix a plane.
fn fit_plane(points: &[[f64; 3]]) -> Option<[f64; 3]> {
    if points.len() < 3 {
        return None;
    }
    let mut ata = nalgebra::Matrix3::<f64>::zeros();
    let mut aty = nalgebra::Vector3::<f64>::zeros();
    for p in points {
        let row = nalgebra::Vector3::new(p[0], p[2], 1.0);
        ata += row * row.transpose();
        aty += row * p[1];
    }
    let solved = ata.lu().solve(&aty)?;
    solved
        .iter()
        .all(|v| v.is_finite())
        .then(|| [solved[0], solved[1], solved[2]])
}

/// Indices (of `points`, among `candidates`) outside the main object: connected components of
/// the points within `link` of each other, keeping the largest and those of at least a quarter
/// its size. Points share a voxel of side `link` as one; two neighbouring voxels join only where
/// a point of each lies within `link` of the other, so that how far apart two objects may stand
/// and still join does not hang on where the grid falls (neighbouring voxels alone join points
/// from one to two `link` apart along an axis).
fn other_objects(
    points: &[[f64; 3]],
    candidates: &[usize],
    link: f64,
    keep_share: f64,
) -> Vec<usize> {
    if candidates.is_empty() || link <= 0.0 {
        return Vec::new();
    }
    let key = |p: &[f64; 3]| p.map(|v| (v / link).floor() as i64);
    let mut voxels: HashMap<[i64; 3], (usize, Vec<usize>)> = HashMap::new();
    for &i in candidates {
        let n = voxels.len();
        voxels
            .entry(key(&points[i]))
            .or_insert((n, Vec::new()))
            .1
            .push(i);
    }
    let mut parent: Vec<usize> = (0..voxels.len()).collect();
    fn root(parent: &mut [usize], mut i: usize) -> usize {
        while parent[i] != i {
            parent[i] = parent[parent[i]];
            i = parent[i];
        }
        i
    }
    for (v, (id, members)) in &voxels {
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    let Some((other, theirs)) = voxels.get(&[v[0] + dx, v[1] + dy, v[2] + dz])
                    else {
                        continue;
                    };
                    let (a, b) = (root(&mut parent, *id), root(&mut parent, *other));
                    if a != b && any_within(points, members, theirs, link) {
                        parent[a] = b;
                    }
                }
            }
        }
    }
    let component: Vec<usize> = candidates
        .iter()
        .map(|&i| root(&mut parent, voxels[&key(&points[i])].0))
        .collect();
    let mut sizes: HashMap<usize, usize> = HashMap::new();
    for &c in &component {
        *sizes.entry(c).or_default() += 1;
    }
    let largest = sizes.values().copied().max().unwrap_or(0);
    candidates
        .iter()
        .zip(&component)
        .filter(|(_, c)| (sizes[c] as f64) < keep_share * largest as f64)
        .map(|(&i, _)| i)
        .collect()
}

/// Whether some point of `a` lies within `link` of some point of `b` (indices of `points`).
fn any_within(points: &[[f64; 3]], a: &[usize], b: &[usize], link: f64) -> bool {
    a.iter().any(|&i| {
        b.iter().any(|&j| {
            let d: f64 = (0..3).map(|k| (points[i][k] - points[j][k]).powi(2)).sum();
            d <= link * link
        })
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::complete::upright::fixtures::car_block;

    /// A car-like block (metres, z up) standing on a ground patch, with noise points around
    /// and below it and a piece of a second object 3 m away.
    fn scene() -> (PointCloud, usize, [usize; 3]) {
        let car: Vec<[f64; 3]> = car_block(20.0, [0.0, 0.0, 0.0])
            .into_iter()
            .map(|[x, y, z]| [x, -z, y + 0.3])
            .collect();
        let mut positions = car.clone();
        let mut ground = 0;
        for i in -30..=30 {
            for j in -30..=30 {
                positions.push([0.1 * i as f64, 0.1 * j as f64, 0.005 * ((i + j) % 2) as f64]);
                ground += 1;
            }
        }
        // One stray return 1.5 m below the ground: the lowest point must not set the ground.
        let noise = [
            [0.5, 0.2, 4.0],
            [-1.0, 1.5, 3.5],
            [2.9, -2.9, 2.5],
            [1.0, -1.0, -1.5],
        ];
        positions.extend(noise);
        let mut other = 0;
        for i in 0..10 {
            for k in 0..10 {
                positions.push([5.5 + 0.05 * i as f64, 0.0, 0.3 + 0.1 * k as f64]);
                other += 1;
            }
        }
        (
            PointCloud::from_positions(positions),
            car.len(),
            [ground, noise.len(), other],
        )
    }

    #[test]
    fn ground_noise_and_neighbours_are_removed_and_the_car_kept() {
        let (cloud, car, [ground, noise, other]) = scene();
        let (cleaned, report) = clean(&cloud, UpAxis::Z, &CleanParams::default());
        assert_eq!(report.ground, ground, "{report:?}");
        assert_eq!(report.isolated, noise, "{report:?}");
        assert_eq!(report.other_objects, other, "{report:?}");
        assert_eq!(cleaned.len(), car);
        assert_eq!(cleaned.positions[..], cloud.positions[..car]);
    }

    /// A wall of 40 × 40 points 0.01 apart at x = `x0`, and one of 10 × 10 at `x0 + gap`.
    fn two_walls(x0: f64, gap: f64) -> Vec<[f64; 3]> {
        let wall = |x: f64, n: usize| {
            (0..n * n).map(move |i| [x, 0.01 * (i / n) as f64, 0.01 * (i % n) as f64])
        };
        wall(x0, 40).chain(wall(x0 + gap, 10)).collect()
    }

    #[test]
    fn objects_join_within_the_link_wherever_the_grid_falls() {
        let link = 0.1;
        for shift in [0.0, 0.03, 0.06, 0.09, 0.099] {
            let apart = two_walls(shift, 1.5 * link);
            let all: Vec<usize> = (0..apart.len()).collect();
            assert_eq!(
                other_objects(&apart, &all, link, CleanParams::default().keep_share),
                (1600..1700).collect::<Vec<_>>(),
                "shift {shift}"
            );
            let close = two_walls(shift, 0.9 * link);
            assert!(
                other_objects(&close, &all, link, CleanParams::default().keep_share).is_empty(),
                "shift {shift}"
            );
        }
    }

    #[test]
    fn a_clean_car_loses_nothing() {
        let cloud = PointCloud::from_positions(car_block(75.0, [3.0, 0.3, -2.0]));
        let (cleaned, report) = clean(&cloud, UpAxis::Y, &CleanParams::default());
        assert_eq!(report, CleanReport::default());
        assert_eq!(cleaned.len(), cloud.len());
    }
}
