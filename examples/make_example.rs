//! Writes the example shipped in `assets/example/`: a generated car (ground truth) and the
//! partial scan a sensor driving past on one side would get of it.
//!
//! `cargo run --example make_example` regenerates both files bit for bit.

use mvpcc::datagen::shapes::{example_car, scanned_side};
use mvpcc::io::{write_cloud, Encoding};
use std::path::Path;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/example");
    std::fs::create_dir_all(&dir)?;
    let car = example_car();
    let partial = scanned_side(&car);
    write_cloud(&dir.join("car_gt.ply"), &car.cloud, None, Encoding::Binary)?;
    write_cloud(
        &dir.join("car_partial.ply"),
        &partial,
        None,
        Encoding::Binary,
    )?;
    println!(
        "{}: car_gt.ply ({} points), car_partial.ply ({} points)",
        dir.display(),
        car.cloud.len(),
        partial.len()
    );
    Ok(())
}
