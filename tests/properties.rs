//! Properties that hold for any input, checked on random ones: frames and mirrors undo
//! themselves, every format gives back what it was given, and the outlier filter never empties
//! a cloud.

use mvpcc::complete::filter::{inliers, SorParams};
use mvpcc::complete::symmetry::mirror;
use mvpcc::core::cloud::PointCloud;
use mvpcc::core::frame::{Frame, UpAxis};
use mvpcc::io::{read_cloud, write_cloud, Encoding, Format};
use proptest::prelude::*;

/// A coordinate as scans have them: metres, possibly far from the origin (UTM-like offsets).
fn coordinate() -> impl Strategy<Value = f64> {
    (-1.0e5f64..1.0e5, -50.0f64..50.0).prop_map(|(offset, local)| offset.round() + local)
}

/// A cloud of 3–200 points around one offset, with or without colours.
fn cloud() -> impl Strategy<Value = PointCloud> {
    let offset = prop::array::uniform3(coordinate());
    let local = prop::collection::vec(prop::array::uniform3(-5.0f64..5.0), 3..200);
    (offset, local, any::<bool>(), any::<u64>()).prop_map(|(o, local, colored, seed)| {
        let positions: Vec<[f64; 3]> = local
            .iter()
            .map(|p| [o[0] + p[0], o[1] + p[1], o[2] + p[2]])
            .collect();
        let mut cloud = PointCloud::from_positions(positions);
        if colored {
            let n = cloud.len() as u64;
            let colors = (0..n).map(|i| {
                let v = seed.wrapping_mul(i + 1).to_le_bytes();
                [v[0], v[1], v[2]]
            });
            cloud.colors = Some(colors.collect());
        }
        cloud
    })
}

fn spread(cloud: &PointCloud) -> f64 {
    let b = cloud.bounds().unwrap();
    (0..3).map(|i| b.max[i] - b.min[i]).fold(0.0, f64::max)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn a_frame_maps_points_back_where_they_were(cloud in cloud(), z_up in any::<bool>()) {
        let up = if z_up { UpAxis::Z } else { UpAxis::Y };
        let Ok(frame) = Frame::fit(&cloud, up) else {
            return Ok(());
        };
        let back = frame.denormalize(&frame.normalize(&cloud));
        let tolerance = 1e-9 * (1.0 + 1e5);
        for (a, b) in cloud.positions.iter().zip(&back.positions) {
            for i in 0..3 {
                prop_assert!((a[i] - b[i]).abs() < tolerance, "{a:?} came back as {b:?}");
            }
        }
        for q in frame.normalize(&cloud).positions {
            prop_assert!(q.iter().all(|c| c.abs() <= 0.5 + 1e-9), "{q:?} outside the unit box");
        }
    }

    #[test]
    fn mirroring_twice_is_the_identity(p in prop::array::uniform3(-10.0f64..10.0), x in -1.0f64..1.0) {
        let back = mirror(mirror(p, x), x);
        for i in 0..3 {
            prop_assert!((back[i] - p[i]).abs() < 1e-12, "{p:?} → {back:?}");
        }
        // The plane's own points stay put.
        prop_assert_eq!(mirror([x, p[1], p[2]], x), [x, p[1], p[2]]);
    }

    #[test]
    fn every_format_reads_back_what_it_wrote(cloud in cloud(), which in 0usize..5, ascii in any::<bool>()) {
        let format = [Format::Ply, Format::Pcd, Format::Las, Format::Laz, Format::Xyz][which];
        let encoding = if ascii { Encoding::Ascii } else { Encoding::Binary };
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join(format!("cloud.{}", format.extension()));
        write_cloud(&path, &cloud, None, encoding).unwrap();
        let back = read_cloud(&path, None).unwrap().cloud;
        prop_assert_eq!(back.len(), cloud.len());
        // LAS stores millimetres; the others at least single precision near the offset.
        let tolerance = 1e-3 + 1e-7 * 1.0e5;
        for (a, b) in cloud.positions.iter().zip(&back.positions) {
            for i in 0..3 {
                prop_assert!((a[i] - b[i]).abs() <= tolerance, "{format:?}: {a:?} read back as {b:?}");
            }
        }
        prop_assert_eq!(back.colors.is_some(), cloud.colors.is_some(), "{:?} colours", format);
        if let (Some(a), Some(b)) = (&cloud.colors, &back.colors) {
            prop_assert_eq!(a, b);
        }
        prop_assert!(spread(&back) > 0.0);
    }

    #[test]
    fn the_outlier_filter_never_empties_a_cloud(
        cloud in cloud(),
        k in 1usize..40,
        std_mul in 0.0f64..6.0,
        copies in 1usize..4,
    ) {
        // Repeated points give equal neighbour distances, where rounding is closest to the edge.
        let mut points = cloud.positions.clone();
        for _ in 1..copies {
            points.extend_from_slice(&cloud.positions);
        }
        let kept = inliers(&points, SorParams { k, std_mul });
        prop_assert_eq!(kept.len(), points.len());
        prop_assert!(kept.iter().any(|&k| k), "all {} points dropped", points.len());
    }
}
