//! Inputs shared by the benches (each bench compiles this module and uses part of it): the largest real MLS car of the reference set when it is
//! present, a generated car of the same size otherwise.

use mvpcc::core::cloud::PointCloud;
use mvpcc::core::frame::{Frame, UpAxis};
use mvpcc::datagen::shapes;
use mvpcc::io::read_cloud;
use std::path::PathBuf;

/// A normalized car scan of about 35K points, and where it came from.
#[allow(dead_code)]
pub fn mls_car() -> (PointCloud, String) {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/reference/clouds/mls");
    let largest = std::fs::read_dir(&dir).ok().and_then(|entries| {
        entries
            .filter_map(|e| e.ok())
            .map(|e| e.path())
            .filter_map(|p| read_cloud(&p, None).ok().map(|l| (p, l.cloud)))
            .max_by_key(|(_, c)| c.len())
    });
    match largest {
        Some((path, cloud)) => {
            let name = path.file_name().unwrap().to_string_lossy().into_owned();
            (cloud, name)
        }
        None => (normalized_car(35_000, 1), "generated car".into()),
    }
}

/// A generated car with about `n` points in the unit box.
pub fn normalized_car(n: usize, seed: u64) -> PointCloud {
    let cloud = shapes::car(n, seed).cloud;
    Frame::fit(&cloud, UpAxis::Y).unwrap().normalize(&cloud)
}
