//! Thinning the network's added points to one per cube of a grid.
//!
//! A 128² model re-projects four points where a 64² one re-projects one, each with its own depth
//! noise; inside `complete` that density buys nothing (the metrics score points against the
//! surface) and the extra noisy layers cost Chamfer distance (docs/pipeline.md, *7. Merge*).

use std::collections::HashMap;

/// One point per occupied cube of side `side` (cubes aligned at the origin): the point nearest
/// the mean of the cube's points, in the order the cubes are first met. A side of 0 (or one
/// that is not finite) keeps every point.
pub fn one_per_cube(points: &[[f64; 3]], side: f64) -> Vec<usize> {
    if !(side > 0.0 && side.is_finite()) {
        return (0..points.len()).collect();
    }
    let mut cubes: HashMap<[i64; 3], usize> = HashMap::new();
    let mut members: Vec<Vec<usize>> = Vec::new();
    for (i, p) in points.iter().enumerate() {
        let key = p.map(|c| (c / side).floor() as i64);
        let cube = *cubes.entry(key).or_insert_with(|| {
            members.push(Vec::new());
            members.len() - 1
        });
        members[cube].push(i);
    }
    members
        .iter()
        .map(|cube| {
            let n = cube.len() as f64;
            let mean = [0, 1, 2].map(|a| cube.iter().map(|&i| points[i][a]).sum::<f64>() / n);
            cube.iter()
                .copied()
                .min_by(|&i, &j| distance2(points[i], mean).total_cmp(&distance2(points[j], mean)))
                .expect("a cube holds at least the point that made it")
        })
        .collect()
}

fn distance2(a: [f64; 3], b: [f64; 3]) -> f64 {
    (0..3).map(|k| (a[k] - b[k]).powi(2)).sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_point_per_cube_the_most_central() {
        let points = [
            [0.01, 0.01, 0.01],
            [0.05, 0.05, 0.05],
            [0.09, 0.09, 0.09],
            [0.15, 0.0, 0.0],
            [-0.01, 0.0, 0.0],
        ];
        assert_eq!(
            one_per_cube(&points, 0.1),
            vec![1, 3, 4],
            "the middle of three, then the two alone"
        );
    }

    #[test]
    fn no_side_keeps_everything() {
        let points = [[0.0; 3], [0.0; 3], [1.0, 2.0, 3.0]];
        for side in [0.0, f64::INFINITY] {
            assert_eq!(one_per_cube(&points, side), vec![0, 1, 2]);
        }
        assert!(one_per_cube(&[], 0.1).is_empty());
    }
}
