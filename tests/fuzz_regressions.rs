//! Every input the fuzzers (fuzz/, see docs/fuzzing.md) found a crash, hang or oversized
//! allocation with, kept in `tests/fuzz/<target>/` and replayed the way its target reads it: each
//! must now be refused with an error.

use burn::tensor::Device;
use mvpcc::datagen::mesh::{read_mesh, ReadOptions};
use std::path::{Path, PathBuf};

/// Splits at the first `\n%%\n`, as the fuzz targets do for a file and its companion.
fn halves(data: &[u8]) -> (&[u8], &[u8]) {
    const MARK: &[u8] = b"\n%%\n";
    match data.windows(MARK.len()).position(|w| w == MARK) {
        Some(at) => (&data[..at], &data[at + MARK.len()..]),
        None => (data, &[]),
    }
}

fn write(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, bytes).unwrap();
    path
}

/// Whether the target's readers refused `data` (all of them, where a target runs several).
fn refused(target: &str, data: &[u8]) -> bool {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let options = |allow_missing_materials| ReadOptions {
        allow_missing_materials,
    };
    match target {
        "cloud_ply" | "cloud_pcd" | "cloud_las" | "cloud_laz" | "cloud_xyz" => {
            let ext = &target["cloud_".len()..];
            let path = write(d, &format!("input.{ext}"), data);
            mvpcc::io::read_cloud(&path, None).is_err()
        }
        "mesh_obj" => {
            let (obj, mtl) = halves(data);
            write(d, "m.mtl", mtl);
            let path = write(d, "mesh.obj", obj);
            [false, true]
                .iter()
                .all(|&allow| read_mesh(&path, options(allow)).is_err())
        }
        "mesh_gltf" => {
            let glb = write(d, "mesh.glb", data);
            let (gltf, bin) = halves(data);
            write(d, "b.bin", bin);
            let gltf = write(d, "mesh.gltf", gltf);
            read_mesh(&glb, options(true)).is_err() && read_mesh(&gltf, options(true)).is_err()
        }
        "mesh_ply" => read_mesh(&write(d, "mesh.ply", data), options(true)).is_err(),
        "views" => {
            let (locations, color) = halves(data);
            write(d, "locations_001.png", locations);
            if !color.is_empty() {
                write(d, "color_001.png", color);
            }
            mvpcc::views::read_views(d, None).is_err()
        }
        "weights" => {
            mvpcc::model::weights::generator_from_bytes(data, &Device::flex()).is_err()
                && mvpcc::complete::orient::Orienter::from_bytes(data, Device::flex()).is_err()
        }
        "run_files" => mvpcc::views::ViewsInfo::from_json(data).is_err(),
        other => panic!("no fuzz target {other}"),
    }
}

/// Replays every finding; set by the test below for the copy of this binary it runs.
const REPLAY: &str = "MVPCC_FUZZ_REPLAY";

#[test]
fn every_fuzz_finding_is_refused_within_1_gib() {
    if std::env::var_os(REPLAY).is_some() {
        replay_all();
        return;
    }
    // Run again under a 1 GiB address-space limit, so a finding that once made a reader
    // allocate what a header claimed fails here too, not only under the fuzzer.
    let status = std::process::Command::new("sh")
        .arg("-c")
        .arg("ulimit -v 1048576 && exec \"$0\" \"$@\"")
        .arg(std::env::current_exe().unwrap())
        .args(["--exact", "every_fuzz_finding_is_refused_within_1_gib"])
        .env(REPLAY, "1")
        .status()
        .unwrap();
    assert!(status.success(), "the replay under 1 GiB failed: {status}");
}

fn replay_all() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fuzz");
    let mut replayed = 0;
    for target in std::fs::read_dir(&root).unwrap() {
        let target = target.unwrap().path();
        let name = target.file_name().unwrap().to_string_lossy().into_owned();
        for finding in std::fs::read_dir(&target).unwrap() {
            let finding = finding.unwrap().path();
            let data = std::fs::read(&finding).unwrap();
            assert!(refused(&name, &data), "{} was read", finding.display());
            replayed += 1;
        }
    }
    assert!(
        replayed >= 4,
        "only {replayed} findings under {}",
        root.display()
    );
}
