//! Orientation and cleaning through the real binary: a real scan turned to an arbitrary heading
//! in map coordinates is completed in place, `--orient` modes and `--clean` report what they
//! did, and `train-orient` writes weights `complete` can use.

use assert_cmd::Command;
use burn::tensor::Device;
use mvpcc::complete::orient::angle_between;
use mvpcc::complete::orient::OrienterConfig;
use mvpcc::core::cloud::{PointCloud, SYNTHETIC};
use mvpcc::io::{read_cloud, write_cloud, Encoding};
use mvpcc::train::orient::{train_orienter, OrientData, OrientSettings, OrientTrainError};
use predicates::prelude::*;
use serde_json::Value;
use std::path::{Path, PathBuf};
use tempfile::TempDir;

mod common;

fn mvpcc() -> Command {
    Command::cargo_bin("mvpcc").unwrap()
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

const OFFSET: [f64; 3] = [650_123.25, 5_270_456.75, 112.5];

/// A y-up cloud in the canonical pose (front at −z) as a z-up map cloud facing `heading`
/// degrees, scaled by `scale`, at UTM-sized coordinates.
fn to_map(cloud: &PointCloud, heading: f64, scale: f64) -> PointCloud {
    // y-up → z-up: (x, y, z) → (x, −z, y) puts the front at +y, heading 90°.
    let (s, c) = (heading - 90.0).to_radians().sin_cos();
    PointCloud {
        positions: cloud
            .positions
            .iter()
            .map(|p| {
                let (x, y, z) = (p[0] * scale, -p[2] * scale, p[1] * scale);
                [
                    OFFSET[0] + c * x - s * y,
                    OFFSET[1] + s * x + c * y,
                    OFFSET[2] + z,
                ]
            })
            .collect(),
        ..cloud.clone()
    }
}

/// The inverse of [`to_map`].
fn from_map(p: [f64; 3], heading: f64, scale: f64) -> [f64; 3] {
    let (s, c) = (heading - 90.0).to_radians().sin_cos();
    let (x, y, z) = (p[0] - OFFSET[0], p[1] - OFFSET[1], p[2] - OFFSET[2]);
    let (x, y) = (c * x + s * y, -s * x + c * y);
    [x / scale, z / scale, -y / scale]
}

fn reference_scan() -> PointCloud {
    let path =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/reference/clouds/mls/CAR175.pcd");
    read_cloud(&path, None)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .cloud
}

fn json_of(stdout: &[u8]) -> Value {
    serde_json::from_slice(stdout).unwrap()
}

#[ignore = "needs ../shared/reference"]
#[test]
fn a_turned_reference_scan_is_completed_in_place() {
    let canonical = reference_scan();
    let dir = TempDir::new().unwrap();
    let (heading, scale) = (213.0, 4.4);
    let map = to_map(&canonical, heading, scale);
    let input = dir.path().join("scan.ply");
    write_cloud(&input, &map, None, Encoding::Binary).unwrap();
    let output = dir.path().join("done.ply");
    let assert = mvpcc()
        .args(["complete", s(&input), s(&output), "--up", "z", "--json"])
        .assert()
        .success();
    let report = json_of(&assert.get_output().stdout);
    let found = report["orientation"]["heading"].as_f64().unwrap();
    assert!(angle_between(found, heading) < 10.0, "heading {found}");

    let done = read_cloud(&output, None).unwrap().cloud;
    assert_eq!(done.positions[..map.len()], map.positions[..]);
    let flags = &done.attribute(SYNTHETIC).unwrap().values;
    assert!(flags[map.len()..].iter().all(|&f| f == 1.0));
    assert!(done.len() > map.len() + 1000, "{} points", done.len());
    // Turned back into the canonical pose, the added points fill the scan's own box (the
    // reference car is about 1 long, 0.4 wide, 0.35 high).
    let lo = [-0.3, -0.25, -0.55];
    let hi = [0.3, 0.25, 0.55];
    let outside = done.positions[map.len()..]
        .iter()
        .map(|&p| from_map(p, heading, scale))
        .filter(|q| (0..3).any(|i| q[i] < lo[i] || q[i] > hi[i]))
        .count();
    assert!(
        outside * 100 < done.len() - map.len(),
        "{outside} added points outside the car's box"
    );
}

#[ignore = "needs ../shared/reference"]
#[test]
fn a_turned_scan_completes_to_the_same_points_to_1e6() {
    let canonical = reference_scan();
    let dir = TempDir::new().unwrap();
    let as_is = dir.path().join("as_is.ply");
    write_cloud(&as_is, &canonical, None, Encoding::Binary).unwrap();
    let (heading, scale) = (213.0, 4.4);
    let map = dir.path().join("map.ply");
    write_cloud(
        &map,
        &to_map(&canonical, heading, scale),
        None,
        Encoding::Binary,
    )
    .unwrap();
    let (out_as_is, out_map) = (dir.path().join("a.ply"), dir.path().join("m.ply"));
    // The mirror method is deterministic, so the two runs differ only by the frame.
    mvpcc()
        .args([
            "complete",
            s(&as_is),
            s(&out_as_is),
            "--method",
            "mirror",
            "--orient",
            "90",
        ])
        .assert()
        .success();
    mvpcc()
        .args([
            "complete",
            s(&map),
            s(&out_map),
            "--method",
            "mirror",
            "--up",
            "z",
        ])
        .args(["--orient", "213"])
        .assert()
        .success();
    let a = read_cloud(&out_as_is, None).unwrap().cloud;
    let m = read_cloud(&out_map, None).unwrap().cloud;
    assert_eq!(a.len(), m.len());
    assert!(a.len() > canonical.len() + 1000, "{} points", a.len());
    for (p, q) in a.positions.iter().zip(&m.positions) {
        let back = from_map(*q, heading, scale);
        for i in 0..3 {
            assert!((back[i] - p[i]).abs() < 1e-6, "{p:?} vs {back:?}");
        }
    }
}

#[ignore = "needs ../shared/reference"]
#[test]
fn orient_modes_are_reported_and_bad_ones_refused() {
    let canonical = reference_scan();
    let dir = TempDir::new().unwrap();
    let input = dir.path().join("scan.ply");
    write_cloud(
        &input,
        &to_map(&canonical, 30.0, 4.4),
        None,
        Encoding::Binary,
    )
    .unwrap();
    let output = dir.path().join("done.ply");
    for (mode, method, heading) in [
        ("none", "none", None),
        ("-330", "given", Some(30.0)),
        ("geometric", "geometric", None),
        ("learned", "learned", None),
    ] {
        let assert = mvpcc()
            .args(["complete", s(&input), s(&output), "--up", "z", "--json"])
            .args(["--method", "mirror", "--orient", mode])
            .assert()
            .success();
        let report = json_of(&assert.get_output().stdout);
        assert_eq!(report["orientation"]["method"], method, "{mode}");
        let refinement = &report["orientation"]["refinement"];
        match heading {
            Some(h) => {
                assert_eq!(report["orientation"]["heading"].as_f64(), Some(h));
                assert!(refinement.is_null(), "a given heading is not refined");
                assert!(report["orientation"]["refined_by"].is_null());
            }
            None if mode == "none" => assert!(report["orientation"]["heading"].is_null()),
            None => {
                assert!(report["orientation"]["heading"].as_f64().is_some());
                let turn = refinement.as_f64().expect("a car scan is symmetric");
                // The wheels' line may turn an estimate by up to 20°, the symmetry by 8°.
                let most = match report["orientation"]["refined_by"].as_str() {
                    Some("wheels") => 20.0,
                    Some("symmetry") => 8.0,
                    other => panic!("{mode}: refined by {other:?}"),
                };
                assert!(turn.abs() <= most, "{mode}: refined by {turn}°");
            }
        }
    }
    // The identity method's output does not depend on the heading, so none is estimated.
    let assert = mvpcc()
        .args(["complete", s(&input), s(&output), "--up", "z", "--json"])
        .args(["--method", "identity"])
        .assert()
        .success();
    let report = json_of(&assert.get_output().stdout);
    assert_eq!(report["orientation"]["method"], "none");
    mvpcc()
        .args(["complete", s(&input), s(&output), "--orient", "sideways"])
        .assert()
        .failure()
        .stderr(predicate::str::contains("sideways"));
    let bogus = dir.path().join("bogus.safetensors");
    std::fs::write(&bogus, b"not weights").unwrap();
    mvpcc()
        .args(["complete", s(&input), s(&output), "--orienter", s(&bogus)])
        .assert()
        .failure()
        .stderr(predicate::str::contains("bogus.safetensors"));
}

#[ignore = "needs ../shared/reference"]
#[test]
fn clean_removes_ground_and_reports_it() {
    let canonical = reference_scan();
    let dir = TempDir::new().unwrap();
    let mut map = to_map(&canonical, 75.0, 4.4);
    let car = map.len();
    let floor = map.positions.iter().map(|p| p[2]).fold(f64::MAX, f64::min) - 0.02;
    let colors = map.colors.as_mut().unwrap();
    for i in -40..=40 {
        for j in -40..=40 {
            map.positions.push([
                OFFSET[0] + 0.08 * i as f64,
                OFFSET[1] + 0.08 * j as f64,
                floor,
            ]);
            colors.push([90, 90, 90]);
        }
    }
    let input = dir.path().join("scene.ply");
    write_cloud(&input, &map, None, Encoding::Binary).unwrap();
    let output = dir.path().join("done.ply");
    let assert = mvpcc()
        .args([
            "complete",
            s(&input),
            s(&output),
            "--up",
            "z",
            "--clean",
            "--json",
        ])
        .args(["--method", "identity"])
        .assert()
        .success()
        .stderr(predicate::str::contains("--clean removed"));
    let report = json_of(&assert.get_output().stdout);
    let ground = report["cleaned"]["ground"].as_u64().unwrap() as usize;
    assert!(ground >= 81 * 81, "{report}");
    assert!(ground < 81 * 81 + car / 50, "{report}");
    let done = read_cloud(&output, None).unwrap().cloud;
    assert!(done.positions.iter().all(|p| p[2] > floor + 1e-9));
}

fn tiny_data(dir: &TempDir) -> PathBuf {
    let data = dir.path().join("data");
    common::prepare_tiny_data(&data);
    data
}

/// `--seed` fixes the whole run, the network's first weights included (they were drawn afresh
/// by every run before).
#[test]
fn train_orient_repeats_a_run_with_its_seed() {
    let dir = TempDir::new().unwrap();
    let data = tiny_data(&dir);
    let log = |name: &str, seed: &str| {
        let run = dir.path().join(name);
        mvpcc()
            .args(["train-orient", "--data", s(&data), "--out", s(&run)])
            .args(["--steps", "2", "--batch", "2", "--points", "64"])
            .args(["--val-every", "2", "--seed", seed])
            .assert()
            .success();
        std::fs::read_to_string(run.join("log.jsonl")).unwrap()
    };
    let first = log("a", "5");
    assert_eq!(first, log("b", "5"));
    assert_ne!(first, log("c", "6"));
}

#[test]
fn train_orient_writes_weights_that_complete_reads() {
    let dir = TempDir::new().unwrap();
    let data = tiny_data(&dir);
    let run = dir.path().join("orient");
    mvpcc()
        .args(["train-orient", "--data", s(&data), "--out", s(&run)])
        .args([
            "--steps",
            "4",
            "--batch",
            "4",
            "--points",
            "128",
            "--val-every",
            "2",
        ])
        .assert()
        .success()
        .stderr(predicate::str::contains("best validation median"));
    for file in [
        "orienter.safetensors",
        "config.json",
        "train-orient.json",
        "log.jsonl",
    ] {
        assert!(run.join(file).is_file(), "{file}");
    }
    let log = std::fs::read_to_string(run.join("log.jsonl")).unwrap();
    assert_eq!(log.lines().count(), 4);
    // A step that cannot be recorded stops the run with the recorder's error.
    let samples = OrientData::scan(&data).unwrap();
    let settings = OrientSettings {
        steps: 4,
        batch: 2,
        ..OrientSettings::default()
    };
    let config = OrienterConfig::new().with_points(64);
    let failed = train_orienter(
        &samples,
        &config,
        &settings,
        &Device::flex(),
        1 << 20,
        |r| match r.step {
            2 => Err(std::io::Error::other("disk full")),
            _ => Ok(()),
        },
    );
    assert!(
        matches!(failed, Err(OrientTrainError::Monitor { step: 2, .. })),
        "{:?}",
        failed.err()
    );
    let input = dir.path().join("scan.ply");
    let cloud = read_cloud(
        &std::fs::read_dir(data.join("clouds/test"))
            .unwrap()
            .flat_map(|c| std::fs::read_dir(c.unwrap().path()).unwrap())
            .map(|m| m.unwrap().path().join("partial_1.ply"))
            .next()
            .unwrap(),
        None,
    )
    .unwrap()
    .cloud;
    write_cloud(&input, &cloud, None, Encoding::Binary).unwrap();
    let assert = mvpcc()
        .args([
            "complete",
            s(&input),
            s(&dir.path().join("o.ply")),
            "--json",
        ])
        .args(["--method", "mirror", "--orient", "learned"])
        .args(["--orienter", s(&run.join("orienter.safetensors"))])
        .assert()
        .success();
    let report = json_of(&assert.get_output().stdout);
    assert_eq!(report["orientation"]["method"], "learned");
    mvpcc()
        .args(["train-orient", "--data", s(&data), "--out", s(&run)])
        .assert()
        .failure()
        .stderr(predicate::str::contains(
            "already holds orienter.safetensors",
        ));
    mvpcc()
        .current_dir(dir.path())
        .args(["train-orient", "--data", "nothing"])
        .assert()
        .failure()
        .stderr(predicate::str::contains("nothing"));
    assert!(
        !dir.path().join("runs").exists(),
        "a refused run leaves no directory behind"
    );
}
