//! Euclidean clustering of the points above the ground: points closer than a gap belong to one
//! object. Written over a voxel grid of the gap's side, whose occupied voxels are joined to
//! their 26 neighbours by union-find: linear in the points, where a k-d tree's radius search
//! per point is not, and close enough at MLS densities: objects closer than one gap always join,
//! objects further than 2·√3 gaps (the farthest two points of neighbouring voxels) never do.

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
    for (k, &v) in &voxels {
        for d in neighbours() {
            if let Some(&w) = voxels.get(&[k[0] + d[0], k[1] + d[1], k[2] + d[2]]) {
                let (a, b) = (root(&mut parent, v), root(&mut parent, w));
                if a != b {
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

    #[test]
    fn a_chain_of_close_points_is_one_object() {
        let points: Vec<[f64; 3]> = (0..100).map(|i| [i as f64 * 0.2, 0.0, 0.0]).collect();
        assert_eq!(clusters(&points, 0.3, 1).len(), 1);
        assert_eq!(clusters(&points, 0.05, 1).len(), 100);
    }
}
