//! Euclidean clustering of the points above the ground: points closer than a gap belong to one
//! object. Written over a voxel grid of the gap's side: the points of one voxel join, and two
//! neighbouring voxels (of the 26) join when any of their points lie within the gap of each
//! other, by union-find. Neighbouring voxels of one surface join at their first pair of points
//! checked; only voxels of two objects near each other are compared pair by pair. Two objects
//! closer than the gap always join; two further apart join only through a voxel they share
//! (at most √3 gaps across).

use std::collections::HashMap;

/// Clusters of `points` (metres, any frame), each a list of indices into `points`, largest
/// first; points in clusters of fewer than `min_points` are left out.
pub fn clusters(points: &[[f64; 3]], gap: f64, min_points: usize) -> Vec<Vec<usize>> {
    let key = |p: &[f64; 3]| p.map(|c| (c / gap).floor() as i64);
    let mut voxels: HashMap<[i64; 3], usize> = HashMap::new();
    let mut voxel_of = Vec::with_capacity(points.len());
    for p in points {
        let next = voxels.len();
        voxel_of.push(*voxels.entry(key(p)).or_insert(next));
    }
    let mut parent: Vec<usize> = (0..voxels.len()).collect();
    fn root(parent: &mut [usize], mut v: usize) -> usize {
        while parent[v] != v {
            parent[v] = parent[parent[v]];
            v = parent[v];
        }
        v
    }
    let mut inside: Vec<Vec<usize>> = vec![Vec::new(); voxels.len()];
    for (i, &v) in voxel_of.iter().enumerate() {
        inside[v].push(i);
    }
    let near = |a: &[usize], b: &[usize]| {
        a.iter().any(|&i| {
            b.iter().any(|&j| {
                let d = [0, 1, 2].map(|k| points[i][k] - points[j][k]);
                d[0] * d[0] + d[1] * d[1] + d[2] * d[2] <= gap * gap
            })
        })
    };
    for (k, &v) in &voxels {
        for d in neighbours() {
            if let Some(&w) = voxels.get(&[k[0] + d[0], k[1] + d[1], k[2] + d[2]]) {
                let (a, b) = (root(&mut parent, v), root(&mut parent, w));
                if a != b && near(&inside[v], &inside[w]) {
                    parent[a.max(b)] = a.min(b);
                }
            }
        }
    }
    let mut members: HashMap<usize, Vec<usize>> = HashMap::new();
    for (i, &v) in voxel_of.iter().enumerate() {
        members.entry(root(&mut parent, v)).or_default().push(i);
    }
    let mut out: Vec<Vec<usize>> = members
        .into_values()
        .filter(|m| m.len() >= min_points)
        .collect();
    // Largest first, then by first point, so the order does not depend on the hash map's.
    out.sort_by_key(|m| (std::cmp::Reverse(m.len()), m[0]));
    out
}

/// The 13 neighbour offsets of one half of the 26-neighbourhood: each pair of neighbours is
/// joined once, from the voxel that sees the other in this half.
fn neighbours() -> impl Iterator<Item = [i64; 3]> {
    (-1..=1)
        .flat_map(|x| (-1..=1).flat_map(move |y| (-1..=1).map(move |z| [x, y, z])))
        .filter(|d| *d > [0, 0, 0])
}

#[cfg(test)]
mod tests {
    use super::*;

    fn blob(centre: [f64; 3], n: usize) -> Vec<[f64; 3]> {
        (0..n)
            .map(|i| {
                let t = i as f64 * 0.61803;
                [
                    centre[0] + (t.fract() - 0.5),
                    centre[1] + ((t * 7.0).fract() - 0.5),
                    centre[2] + ((t * 13.0).fract() - 0.5) * 0.5,
                ]
            })
            .collect()
    }

    #[test]
    fn objects_apart_are_separate_and_small_ones_left_out() {
        let mut points = blob([0.0, 0.0, 1.0], 400);
        points.extend(blob([3.0, 0.0, 1.0], 300));
        points.extend(blob([20.0, 5.0, 1.0], 10));
        let found = clusters(&points, 0.3, 50);
        assert_eq!(found.len(), 2);
        assert_eq!(found[0], (0..400).collect::<Vec<_>>());
        assert_eq!(found[1], (400..700).collect::<Vec<_>>());
    }

    /// Two walls 0.5 m apart (more than the gap, less than two voxels) stay apart.
    #[test]
    fn objects_in_neighbouring_voxels_join_only_when_closer_than_the_gap() {
        let wall = |x: f64| -> Vec<[f64; 3]> {
            (0..400)
                .map(|i| [x, (i % 20) as f64 * 0.1, (i / 20) as f64 * 0.1])
                .collect()
        };
        let mut points = wall(0.05);
        points.extend(wall(0.55));
        assert_eq!(clusters(&points, 0.3, 1).len(), 2);
        let mut touching = wall(0.05);
        touching.extend(wall(0.3));
        assert_eq!(clusters(&touching, 0.3, 1).len(), 1);
    }

    #[test]
    fn a_chain_of_close_points_is_one_object() {
        let points: Vec<[f64; 3]> = (0..100).map(|i| [i as f64 * 0.2, 0.0, 0.0]).collect();
        assert_eq!(clusters(&points, 0.3, 1).len(), 1);
        assert_eq!(clusters(&points, 0.05, 1).len(), 100);
    }
}
