//! How well the objects found match a scene's ground truth: which true vehicles were found
//! whole, which found "vehicles" are something else, and which hold several vehicles at once.

use super::{Objects, Verdict};
use serde::Serialize;
use std::collections::HashMap;

/// Detection figures of one scene.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct Detection {
    /// True vehicles with at least the scored minimum of scanned points.
    pub vehicles: usize,
    /// Of those, found: one object taken for a vehicle holds at least half of its points and
    /// is at least half made of them.
    pub found: usize,
    /// The true vehicles not found.
    pub missed: Vec<u32>,
    /// Objects taken for vehicles that are mostly something else.
    pub false_vehicles: usize,
    /// Objects taken for vehicles that hold at least a fifth of two or more true vehicles'
    /// points (a row of cars taken as one).
    pub merged: usize,
}

/// Scores `objects` against `labels` (each point's true object) where `is_vehicle` says which
/// true objects are vehicles; vehicles with fewer than `min_points` scanned points are not
/// counted (a scan that barely touched them cannot be asked to find them).
pub fn detection(
    objects: &Objects,
    labels: &[u32],
    is_vehicle: impl Fn(u32) -> bool,
    min_points: usize,
) -> Detection {
    let mut scanned: HashMap<u32, usize> = HashMap::new();
    for &l in labels {
        *scanned.entry(l).or_default() += 1;
    }
    let mut truth: Vec<u32> = scanned
        .iter()
        .filter(|&(&l, &n)| is_vehicle(l) && n >= min_points)
        .map(|(&l, _)| l)
        .collect();
    truth.sort_unstable();
    let mut score = Detection {
        vehicles: truth.len(),
        ..Detection::default()
    };
    let mut found_ids = Vec::new();
    for object in objects
        .objects
        .iter()
        .filter(|o| o.verdict == Verdict::Vehicle)
    {
        let mut held: HashMap<u32, usize> = HashMap::new();
        for &i in &object.indices {
            *held.entry(labels[i]).or_default() += 1;
        }
        let (&major, &count) = held
            .iter()
            .max_by_key(|&(&l, &n)| (n, std::cmp::Reverse(l)))
            .expect("an object has points");
        if !is_vehicle(major) {
            score.false_vehicles += 1;
            continue;
        }
        let share = |l: u32, n: usize| n as f64 / scanned[&l] as f64;
        let several = held
            .iter()
            .filter(|&(&l, &n)| is_vehicle(l) && share(l, n) >= 0.2)
            .count();
        if several >= 2 {
            score.merged += 1;
        }
        if 2 * count >= object.indices.len() && share(major, count) >= 0.5 {
            found_ids.push(major);
        }
    }
    found_ids.sort_unstable();
    found_ids.dedup();
    score.found = truth.iter().filter(|l| found_ids.contains(l)).count();
    score.missed = truth
        .into_iter()
        .filter(|l| !found_ids.contains(l))
        .collect();
    score
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{Footprint, Object};

    fn object(indices: std::ops::Range<usize>, verdict: Verdict) -> Object {
        Object {
            indices: indices.collect(),
            footprint: Footprint {
                centre: [0.0; 3],
                length: 4.0,
                width: 1.8,
                height: 1.5,
                axis_deg: 0.0,
            },
            verdict,
        }
    }

    #[test]
    fn found_missed_false_and_merged_are_told_apart() {
        // Points: 0–99 ground (0), 100–199 vehicle 1, 200–299 vehicle 2, 300–399 vehicle 3,
        // 400–499 a hedge (4).
        let labels: Vec<u32> = (0..500).map(|i| (i / 100) as u32).collect();
        let is_vehicle = |l: u32| (1..=3).contains(&l);
        let objects = Objects {
            objects: vec![
                object(100..200, Verdict::Vehicle),
                object(200..400, Verdict::Vehicle),
                object(400..500, Verdict::Vehicle),
                object(0..100, Verdict::TooLong),
            ],
            ground_points: 0,
        };
        let score = detection(&objects, &labels, is_vehicle, 50);
        assert_eq!(score.vehicles, 3);
        // Vehicles 2 and 3 as one object: it is half of each, so one of them counts as found.
        assert_eq!(score.found, 2);
        assert_eq!(score.missed, [3]);
        assert_eq!((score.false_vehicles, score.merged), (1, 1));
    }
}
