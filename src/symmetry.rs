//! The vehicle's long vertical plane of symmetry, found in the normalized frame (length along z,
//! up along y), where it is a plane `x = c`.
//!
//! Street vehicles are left–right symmetric, so a scan of one side and the roof already holds the
//! roof's two halves: the plane that maps most points onto other points is the symmetry plane.
//! Points close to a candidate plane map onto themselves whatever the candidate, so they are not
//! counted; otherwise a flat side would always be "symmetric" about itself.

use crate::knn::KnnIndex;

/// Points used to find the plane; a stride over the cloud keeps the search ~1 ms a candidate.
const SAMPLE: usize = 4000;
/// A point within this distance (normalized units) of a candidate plane does not vote for it.
const MIN_LEVER: f64 = 0.03;
/// A mirrored point counts as matched within this distance of a measured one, or within 1.5
/// point spacings of a sparser cloud.
const MATCH: f64 = 0.01;
/// Below this fraction of matched points the cloud shows no symmetry to speak of.
const MIN_SCORE: f64 = 0.05;

/// The symmetry plane found, and how much of the cloud supports it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Plane {
    /// The plane is `x = offset`.
    pub offset: f64,
    /// Fraction of the sampled points whose mirror image lands on another point.
    pub support: f64,
    /// How close a mirror image must come to a measured point to count as landing on it.
    pub tolerance: f64,
}

/// Searches `x = c` for `c` across the cloud's x range, coarse to fine. `None` when the cloud
/// shows no symmetry (for example, one flat side).
pub fn find_plane(points: &[[f64; 3]]) -> Option<Plane> {
    if points.len() < 2 {
        return None;
    }
    let stride = points.len().div_ceil(SAMPLE);
    let sample: Vec<[f64; 3]> = points.iter().step_by(stride).copied().collect();
    let index = KnnIndex::new(&sample);
    let mut spacing: Vec<f64> = index
        .k_nearest_distances(&sample, 2)
        .chunks(2)
        .map(|d| d[1])
        .filter(|d| d.is_finite())
        .collect();
    spacing.sort_by(f64::total_cmp);
    let tolerance = spacing
        .get(spacing.len() / 2)
        .map_or(MATCH, |&s| MATCH.max(1.5 * s));
    let (lo, hi) = sample.iter().fold((f64::MAX, f64::MIN), |(lo, hi), p| {
        (lo.min(p[0]), hi.max(p[0]))
    });
    let score = |c: f64| {
        let movers: Vec<[f64; 3]> = sample
            .iter()
            .filter(|p| (p[0] - c).abs() > MIN_LEVER)
            .map(|p| [2.0 * c - p[0], p[1], p[2]])
            .collect();
        let matched = index
            .k_nearest_distances(&movers, 1)
            .iter()
            .filter(|&&d| d < tolerance)
            .count();
        matched as f64 / sample.len() as f64
    };
    let best_of = |candidates: Vec<f64>| {
        candidates
            .into_iter()
            .map(|c| (c, score(c)))
            .fold((0.0, -1.0), |best, s| if s.1 > best.1 { s } else { best })
    };
    let coarse = 40;
    let step = (hi - lo) / coarse as f64;
    let (c, _) = best_of((0..=coarse).map(|i| lo + step * i as f64).collect());
    let fine = 20;
    let (offset, support) = best_of(
        (0..=fine)
            .map(|i| c - step + 2.0 * step * i as f64 / fine as f64)
            .collect(),
    );
    (support >= MIN_SCORE).then_some(Plane {
        offset,
        support,
        tolerance,
    })
}

/// `p` mirrored across `x = offset`.
pub fn mirror(p: [f64; 3], offset: f64) -> [f64; 3] {
    [2.0 * offset - p[0], p[1], p[2]]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shapes::{example_car, scanned_side};

    #[test]
    fn finds_the_plane_of_a_one_sided_car_scan() {
        // Seen from +x and above: one side and the roof; the car's plane is x = 0 before the
        // shift. The example car is 4.4 m long: divided by that, it is in normalized units.
        let side = scanned_side(&example_car());
        for shift in [0.0, 0.07, -0.12] {
            let points: Vec<[f64; 3]> = side
                .positions
                .iter()
                .map(|p| [p[0] / 4.4 + shift, p[1] / 4.4, p[2] / 4.4])
                .collect();
            let plane = find_plane(&points).expect("a car scan is symmetric");
            assert!(
                (plane.offset - shift).abs() < 0.01,
                "plane at {} for a car centred at {shift}",
                plane.offset
            );
            assert!(plane.support > 0.1, "support {}", plane.support);
        }
    }

    #[test]
    fn a_flat_wall_has_no_plane() {
        let wall: Vec<[f64; 3]> = (0..2000)
            .map(|i| [0.2, (i / 50) as f64 * 0.01, (i % 50) as f64 * 0.01])
            .collect();
        assert_eq!(find_plane(&wall), None);
    }

    #[test]
    fn mirroring_twice_is_the_identity() {
        let p = [0.3, -0.1, 0.25];
        assert_eq!(mirror(mirror(p, 0.05), 0.05), p);
        assert!((mirror(p, 0.05)[0] - -0.2).abs() < 1e-12);
    }
}
