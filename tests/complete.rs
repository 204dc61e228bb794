//! `mvpcc complete` end to end on a tiny untrained model (and on the built-in one): the output
//! lands in the input's frame, keeps every input point exactly and flags what it added; batch
//! mode survives bad files and says so.

use assert_cmd::Command;
use burn::tensor::Device;
use mvpcc::core::cloud::{PointCloud, SYNTHETIC};
use mvpcc::datagen::shapes;
use mvpcc::io::{read_cloud, write_cloud, Encoding};
use mvpcc::model::weights::generator_to_bytes;
use mvpcc::model::Preset;
use predicates::prelude::*;
use std::path::{Path, PathBuf};
use tempfile::TempDir;

fn mvpcc() -> Command {
    Command::cargo_bin("mvpcc").unwrap()
}

/// `mvpcc complete` over the folder `inputs` into `outputs`.
fn complete_dir(inputs: &Path, outputs: &Path) -> Command {
    let mut cmd = mvpcc();
    cmd.arg("complete")
        .arg("--input-dir")
        .arg(inputs)
        .arg("--output-dir")
        .arg(outputs);
    cmd
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// An untrained tiny generator, written where `--model` can read it.
fn tiny_model(dir: &TempDir) -> PathBuf {
    let config = Preset::Tiny.config();
    let generator = config.init_generator(&Device::flex()).unwrap();
    let path = dir.path().join("tiny.safetensors");
    std::fs::write(&path, generator_to_bytes(&generator, &config).unwrap()).unwrap();
    path
}

/// A scanner's view of one side of a car, in georeferenced metres (UTM-sized coordinates).
fn scan(seed: u64) -> PointCloud {
    let mut cloud = shapes::scanned_side(&shapes::car(8000, seed));
    for p in &mut cloud.positions {
        p[0] += 650_123.25;
        p[1] += 112.5;
        p[2] += 5_270_456.75;
    }
    cloud
}

fn write(dir: &TempDir, name: &str, cloud: &PointCloud) -> PathBuf {
    let path = dir.path().join(name);
    write_cloud(&path, cloud, None, Encoding::Binary).unwrap();
    path
}

/// Completes `input` into `name` in `dir` with the extra arguments and reads the output.
fn completed(dir: &TempDir, input: &Path, name: &str, args: &[&str]) -> PointCloud {
    let output = dir.path().join(name);
    mvpcc()
        .args(["complete", s(input), s(&output)])
        .args(args)
        .assert()
        .success();
    read_cloud(&output, None).unwrap().cloud
}

fn flags(cloud: &PointCloud) -> Vec<f64> {
    cloud
        .attribute(SYNTHETIC)
        .expect("completed clouds carry the flag")
        .values
        .clone()
}

/// Per axis, how far `points` reach beyond the box of `reference`.
fn overshoot(points: &[[f64; 3]], reference: &[[f64; 3]]) -> f64 {
    let mut worst: f64 = 0.0;
    for axis in 0..3 {
        let lo = reference.iter().map(|p| p[axis]).fold(f64::MAX, f64::min);
        let hi = reference.iter().map(|p| p[axis]).fold(f64::MIN, f64::max);
        for p in points {
            worst = worst.max(lo - p[axis]).max(p[axis] - hi);
        }
    }
    worst
}

#[test]
fn completes_in_the_input_frame_keeping_every_input_point() {
    let dir = TempDir::new().unwrap();
    let model = tiny_model(&dir);
    let input_cloud = scan(3);
    let input = write(&dir, "scan.ply", &input_cloud);
    let (output, preview) = (dir.path().join("done.ply"), dir.path().join("done.png"));
    let assert = mvpcc()
        .args(["complete", s(&input), s(&output), "--model", s(&model)])
        .args(["--preview", s(&preview), "--timings", "--json"])
        .assert()
        .success();
    let report: serde_json::Value = serde_json::from_slice(&assert.get_output().stdout).unwrap();

    let out = read_cloud(&output, None).unwrap().cloud;
    let n = input_cloud.len();
    assert_eq!(report["input_points"], n);
    assert_eq!(report["output_points"], out.len());
    assert_eq!(report["added"], out.len() - n);
    assert!(out.len() > n, "the mirror images alone add the far flank");
    assert_eq!(&out.positions[..n], &input_cloud.positions[..]);
    assert_eq!(
        out.colors.as_ref().unwrap()[..n],
        input_cloud.colors.unwrap()[..]
    );
    let f = flags(&out);
    assert!(f[..n].iter().all(|&v| v == 0.0));
    assert!(f[n..].iter().all(|&v| v == 1.0));
    // The frame is restored: the added points are near the scan, not near the origin 650 km
    // away. The untrained model puts points anywhere in the model's box, a cube one car length
    // (4.4 m) on a side around the car; snapped onto the 64² rig cameras' pixel rays at depths
    // within that box they stay within 1.4 box sides of its centre (6.2 m).
    let reach = overshoot(&out.positions[n..], &out.positions[..n]);
    assert!(reach < 6.2, "added points reach {reach} m beyond the scan");
    // The mirror images come first among the added points; the network's follow them.
    let mirrored = report["mirrored"].as_u64().unwrap() as usize;
    assert!(mirrored > 0);
    let far_flank = out.positions[n..n + mirrored]
        .iter()
        .map(|p| p[0] - 650_123.25)
        .fold(f64::MAX, f64::min);
    assert!((far_flank + 0.9).abs() < 0.1, "far flank at {far_flank} m");
    // The plane is reported in the input's coordinates too: across the car, through its middle.
    let plane = &report["symmetry_plane"];
    let coordinate = |key: &str, i: usize| plane[key][i].as_f64().unwrap();
    assert!(coordinate("normal", 0).abs() > 0.99, "{plane}");
    assert!((coordinate("point", 0) - 650_123.25).abs() < 0.1, "{plane}");
    assert!(
        ["supported", "refined", "pairs", "held-back"].contains(&plane["fit"].as_str().unwrap()),
        "{plane}"
    );
    // Each cue is reported on its own, in the plane's `x`; a car scanned from one side has its
    // mirror pairs and the extent of its slices, and they agree, so the plane is vouched for.
    assert_eq!(plane["vouched"], true, "{plane}");
    let x = plane["x"].as_f64().unwrap();
    for cue in ["pairs", "extent"] {
        let at = plane["cues"][cue].as_f64().unwrap_or(f64::NAN);
        assert!(
            (at - x).abs() < 0.02,
            "{cue} at {at}, the plane at {x}: {plane}"
        );
    }

    let png = image::open(&preview).unwrap();
    assert!(png.width() > 300 && png.height() > 300);
    for stage in [
        "projection",
        "encoder",
        "fusion",
        "decoder",
        "filter",
        "total",
    ] {
        assert!(report["seconds"][stage].as_f64().unwrap() >= 0.0, "{stage}");
    }
}

/// The network completes the mirror image too unless `--no-mirror-pass`, and says so in the
/// report; the mirror method runs no network.
#[test]
fn the_mirror_pass_is_reported() {
    let dir = TempDir::new().unwrap();
    let model = tiny_model(&dir);
    let input = write(&dir, "scan.ply", &scan(3));
    let passes = |extra: &[&str]| {
        let output = dir.path().join("done.ply");
        let assert = mvpcc()
            .args(["complete", s(&input), s(&output)])
            .args(["--model", s(&model), "--json"])
            .args(extra)
            .assert()
            .success();
        let report: serde_json::Value =
            serde_json::from_slice(&assert.get_output().stdout).unwrap();
        assert!(
            report["warnings"].as_array().unwrap().is_empty(),
            "{report}"
        );
        assert!(report["seconds"]["mirror pass"].as_f64().unwrap() >= 0.0);
        report["network_passes"].as_u64().unwrap()
    };
    assert_eq!(passes(&[]), 2);
    assert_eq!(passes(&["--no-mirror-pass"]), 1);
    assert_eq!(passes(&["--no-mirror-pass", "--mirror-pass"]), 2);
    assert_eq!(passes(&["--method", "mirror"]), 0);
    mvpcc()
        .args(["complete", "--paper", "--mirror-pass", "a.ply", "b.ply"])
        .assert()
        .failure()
        .stderr(predicate::str::contains("cannot be used with"));
}

#[test]
fn timings_table_and_las_synthetic_flag() {
    let dir = TempDir::new().unwrap();
    let model = tiny_model(&dir);
    let input_cloud = scan(4);
    let input = write(&dir, "scan.ply", &input_cloud);
    let output = dir.path().join("done.las");
    mvpcc()
        .args([
            "complete",
            s(&input),
            s(&output),
            "--model",
            s(&model),
            "--timings",
        ])
        .assert()
        .success()
        .stderr(predicate::str::contains("encoder").and(predicate::str::contains("total")));
    let out = read_cloud(&output, None).unwrap().cloud;
    let n = input_cloud.len();
    let f = flags(&out);
    assert!(f[..n].iter().all(|&v| v == 0.0) && f[n..].iter().all(|&v| v == 1.0));
    assert!(out.len() > n);
}

/// A georeferenced LAS scan keeps what it was read with: the coordinate system, the scale and
/// offset, what its header says of the points (the GPS time type), its points' GPS times and
/// its extra bytes, stored as they were (the added points take their nearest measured point's
/// values).
#[test]
fn a_las_scan_keeps_its_coordinate_system_and_record_fields() {
    let dir = TempDir::new().unwrap();
    let mut cloud = scan(6);
    for p in &mut cloud.positions {
        *p = [p[0] + 651_234.5, 5_234_567.25 - p[2], p[1] + 103.25];
    }
    let n = cloud.len();
    cloud.attributes.push(mvpcc::core::cloud::Attribute {
        name: "gps_time".into(),
        kind: mvpcc::core::cloud::ScalarKind::F64,
        values: (0..n).map(|i| 401_234.5 + i as f64 * 1e-5).collect(),
    });
    cloud.attributes.push(mvpcc::core::cloud::Attribute {
        name: "Reflectance".into(),
        kind: mvpcc::core::cloud::ScalarKind::F64,
        values: (0..n).map(|i| 0.01 * (i % 3000) as f64 - 15.0).collect(),
    });
    cloud.crs = vec![mvpcc::core::cloud::CrsRecord {
        record_id: 2112,
        description: "OGC WKT".into(),
        data: b"PROJCS[\"ETRS89 / UTM zone 33N\"]\0".to_vec(),
    }];
    cloud.las_source = mvpcc::core::cloud::LasSource {
        standard_gps_time: true,
        file_source_id: 3,
        system_identifier: "MLS van".into(),
        ..Default::default()
    };
    cloud.extra_bytes = vec![mvpcc::core::cloud::StoredField {
        name: "Reflectance".into(),
        data_type: 4,
        scale: 0.01,
        offset: -15.0,
        no_data: None,
        description: "dB".into(),
    }];
    let input = dir.path().join("scan.las");
    write_cloud(&input, &cloud, None, Encoding::Binary).unwrap();
    let read = read_cloud(&input, None).unwrap().cloud;
    let done = completed(&dir, &input, "done.las", &["--method", "mirror"]);
    assert!(done.len() > n);
    assert_eq!(done.crs, cloud.crs);
    assert_eq!(done.quantization, read.quantization);
    assert_eq!(&done.positions[..n], &read.positions[..]);
    assert_eq!(done.extra_bytes, cloud.extra_bytes);
    assert_eq!(done.las_source, cloud.las_source);
    // A PLY output has no place for the coordinate system, XYZ text none for attributes either
    // (nor for which points were completed), and each says so.
    for (command, output, lost) in [
        ("complete", "done.ply", ""),
        ("filter", "done.ply", ""),
        (
            "complete",
            "done.xyz",
            "attributes intensity, classification, gps_time, Reflectance and synthetic are",
        ),
        (
            "filter",
            "done.xyz",
            "attributes intensity, classification, gps_time and Reflectance are",
        ),
    ] {
        mvpcc()
            .args([command, s(&input), s(&dir.path().join(output))])
            .args(
                ["--method", "mirror"]
                    .iter()
                    .filter(|_| command == "complete"),
            )
            .assert()
            .success()
            .stderr(
                predicate::str::contains(
                    "scan.las: its coordinate reference system is not written",
                )
                .and(predicate::str::contains(format!("scan.las: {lost}"))),
            );
    }
    for name in ["gps_time", "Reflectance"] {
        let values = &done.attribute(name).unwrap().values;
        assert_eq!(values[..n], read.attribute(name).unwrap().values[..]);
        let measured: std::collections::HashSet<u64> =
            values[..n].iter().map(|t| t.to_bits()).collect();
        assert!(values[n..].iter().all(|t| measured.contains(&t.to_bits())));
    }
}

#[test]
fn baselines_need_no_model_and_the_network_alone_replaces_the_input() {
    let dir = TempDir::new().unwrap();
    let input_cloud = scan(5);
    let input = write(&dir, "scan.pcd", &input_cloud);
    let same = completed(&dir, &input, "identity.pcd", &["--method", "identity"]);
    assert_eq!(same.positions, input_cloud.positions);
    assert!(flags(&same).iter().all(|&v| v == 0.0));

    let mirror = completed(&dir, &input, "mirror.pcd", &["--method", "mirror"]);
    assert!(mirror.len() > input_cloud.len());

    let model = tiny_model(&dir);
    // An untrained model's occupancy is noise that erosion would remove entirely.
    let untrained = ["--model", s(&model), "--no-keep-input", "--erode", "0"];
    let alone = completed(&dir, &input, "alone.ply", &untrained);
    assert!(flags(&alone).iter().all(|&v| v == 1.0));
    assert!(overshoot(&alone.positions, &input_cloud.positions) < 6.2);

    // Unsnapped, the points sit where the network put them, off their pixels' rays but inside
    // the model's box: within half a car length of the scan's box.
    let unsnapped = completed(
        &dir,
        &input,
        "unsnapped.ply",
        &[&untrained[..], &["--no-snap"]].concat(),
    );
    assert!(!unsnapped.is_empty());
    assert_ne!(unsnapped.positions, alone.positions);
    assert!(overshoot(&unsnapped.positions, &input_cloud.positions) < 2.2);
}

/// `--vehicle-width`: the plane of a one-sided scan is kept half the width from the scanned
/// flank, so a car said to be 1.9 m wide (it is 1.8 m) has its far flank drawn 1.9 m from the
/// near one; refused when not a positive length.
#[test]
fn a_known_width_puts_the_far_flank_that_far_from_the_near_one() {
    let dir = TempDir::new().unwrap();
    // One flank, and the roof seen sparsely to 0.7 m beyond the middle, as a scan of a vehicle
    // a little taller than the scanner sees it: most points on the scanned side.
    let mut input_cloud = scan(5);
    let keep: Vec<bool> = input_cloud
        .positions
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let across = p[0] - 650_123.25;
            across > 0.5 || (across > -0.7 && i % 4 == 0)
        })
        .collect();
    input_cloud = input_cloud.filter(&keep);
    let input = write(&dir, "scan.ply", &input_cloud);
    let output = dir.path().join("wide.ply");
    let assert = mvpcc()
        .args(["complete", s(&input), s(&output), "--method", "mirror"])
        .args(["--vehicle-width", "1.9", "--json"])
        .assert()
        .success();
    let report: serde_json::Value = serde_json::from_slice(&assert.get_output().stdout).unwrap();
    assert_eq!(report["symmetry_plane"]["fit"], "width", "{report}");
    let out = read_cloud(&output, None).unwrap().cloud;
    let across = |p: &[f64; 3]| p[0] - 650_123.25;
    let near = input_cloud
        .positions
        .iter()
        .map(across)
        .fold(f64::MIN, f64::max);
    let far = out.positions.iter().map(across).fold(f64::MAX, f64::min);
    assert!(
        (near - far - 1.9).abs() < 0.02,
        "near flank {near} m, far {far} m"
    );

    for width in ["0", "-1", "wide"] {
        let refused = dir.path().join(format!("refused{width}.ply"));
        mvpcc()
            .args(["complete", s(&input), s(&refused), "--method", "mirror"])
            .args(["--vehicle-width", width])
            .assert()
            .failure()
            .stderr(predicates::str::contains(format!(
                "{width} is not a positive length"
            )));
        assert!(!refused.exists());
    }
}

/// A car leaning 2° across its width (a cambered road) under a plumb-line up axis: `--roll
/// auto` finds the lean and tilts the plane with it; by default the plane stands upright.
#[test]
fn roll_auto_tilts_the_plane_with_a_leaning_car() {
    let dir = TempDir::new().unwrap();
    let (s2, c2) = 2.0_f64.to_radians().sin_cos();
    let car = PointCloud::from_positions(
        shapes::car(8000, 4)
            .cloud
            .positions
            .iter()
            .map(|p| {
                [
                    p[0] * c2 - p[1] * s2 + 650_000.0,
                    p[0] * s2 + p[1] * c2,
                    p[2],
                ]
            })
            .collect(),
    );
    let input = write(&dir, "leaning.ply", &car);
    let report = |roll: Option<&str>| -> serde_json::Value {
        let output = dir.path().join("done.ply");
        let mut cmd = mvpcc();
        cmd.args([
            "complete",
            s(&input),
            s(&output),
            "--method",
            "mirror",
            "--json",
        ]);
        if let Some(roll) = roll {
            cmd.args(["--roll", roll]);
        }
        serde_json::from_slice(&cmd.assert().success().get_output().stdout).unwrap()
    };
    let upright = report(None);
    assert_eq!(upright["orientation"]["roll"], 0.0);
    assert_eq!(upright["symmetry_plane"]["normal"][1], 0.0);
    let found = report(Some("auto"));
    let roll = found["orientation"]["roll"].as_f64().unwrap();
    assert!((roll.abs() - 2.0).abs() <= 0.3, "found {roll}°");
    // The plane's normal in the input's coordinates leans by as much, whichever way it points.
    let lean = found["symmetry_plane"]["normal"][1].as_f64().unwrap().abs();
    assert!((lean - s2).abs() < 0.005, "normal's up component {lean}");

    for (roll, text) in [("50", "not auto or a roll"), ("up", "not auto or a roll")] {
        refuses(
            &input,
            &dir.path().join("x.ply"),
            &format!("--roll={roll}"),
            text,
        );
    }
}

#[test]
fn the_built_in_model_completes_out_of_the_box() {
    let dir = TempDir::new().unwrap();
    let input_cloud = scan(6);
    let input = write(&dir, "scan.ply", &input_cloud);
    let output = dir.path().join("done.ply");
    mvpcc()
        .args(["complete", s(&input), s(&output)])
        .assert()
        .success()
        .stderr(predicate::str::contains("completed"));
    let out = read_cloud(&output, None).unwrap().cloud;
    assert!(out.len() > input_cloud.len());
    assert_eq!(
        &out.positions[..input_cloud.len()],
        &input_cloud.positions[..]
    );

    // The built-in model's own threshold lies below one half: a stricter one adds less.
    let strict = completed(&dir, &input, "strict.ply", &["--occupancy", "0.9"]);
    assert!(strict.len() < out.len());
    let refused = dir.path().join("refused.ply");
    let probability = "1.5 is not a probability between 0 and 1";
    refuses(&input, &refused, "--occupancy=1.5", probability);
    // Next to the measured and mirrored points only what the network is sure of fills; with
    // the near band off (no wider than the merge distance) the doubtful points come back.
    let doubtful = completed(&dir, &input, "doubtful.ply", &["--near-distance", "0"]);
    assert!(doubtful.len() > out.len());
    refuses(&input, &refused, "--near-occupancy=1.5", probability);
    // A NaN or negative σ made the outlier filter remove every point or most of them.
    for sigma in ["nan", "-1"] {
        let option = format!("--sor-std={sigma}");
        refuses(
            &input,
            &refused,
            &option,
            &format!("{sigma} is not a number of 0 or more"),
        );
    }

    // Every completed point lies within the box's side of a measured or mirrored one, so a
    // merge distance that wide leaves the mirror's output.
    let merged_away = completed(&dir, &input, "merged_away.ply", &["--merge-distance", "2"]);
    let mirror = completed(&dir, &input, "mirror.ply", &["--method", "mirror"]);
    assert_eq!(merged_away.positions, mirror.positions);
    assert!(merged_away.len() < out.len());

    // Thinning and the network's box only drop points: unthinned, the output keeps every point
    // of the default, and with the box left open too, every point of that.
    let unthinned = completed(&dir, &input, "unthinned.ply", &["--thin", "0"]);
    assert!(unthinned.len() > out.len());
    assert!(out
        .positions
        .iter()
        .all(|p| unthinned.positions.contains(p)));
    let open = completed(
        &dir,
        &input,
        "open.ply",
        &["--thin", "0", "--box-margin", "inf"],
    );
    assert!(unthinned
        .positions
        .iter()
        .all(|p| open.positions.contains(p)));
    let distance = "-0.1 is not a distance of 0 or more";
    refuses(&input, &refused, "--merge-distance=-0.1", distance);
}

/// `complete INPUT OUTPUT OPTION` fails saying `text` and writes nothing.
fn refuses(input: &Path, output: &Path, option: &str, text: &str) {
    mvpcc()
        .args(["complete", s(input), s(output), option])
        .assert()
        .failure()
        .stderr(predicate::str::contains(text));
    assert!(!output.exists());
}

#[test]
fn batch_completes_the_good_files_and_reports_the_bad_ones() {
    let dir = TempDir::new().unwrap();
    let model = tiny_model(&dir);
    let inputs = dir.path().join("in");
    std::fs::create_dir_all(inputs.join("street")).unwrap();
    write_cloud(&inputs.join("a.ply"), &scan(7), None, Encoding::Binary).unwrap();
    write_cloud(
        &inputs.join("street/b.pcd"),
        &scan(8),
        None,
        Encoding::Ascii,
    )
    .unwrap();
    std::fs::write(inputs.join("broken.ply"), b"ply\nformat nonsense\n").unwrap();
    let few = PointCloud {
        positions: (0..20).map(|i| [i as f64, 0.0, 1.0]).collect(),
        ..Default::default()
    };
    write_cloud(&inputs.join("few.ply"), &few, None, Encoding::Binary).unwrap();
    // A stray return and a NaN point: each said once, after the progress bar, and in the JSON.
    let mut odd = PointCloud::from_positions(scan(9).positions);
    odd.positions
        .extend([[500.0, 0.0, 0.0], [f64::NAN, 0.0, 0.0]]);
    write_cloud(&inputs.join("odd.ply"), &odd, None, Encoding::Binary).unwrap();
    // A link back to the top of the tree: followed once, its files not taken twice.
    #[cfg(unix)]
    std::os::unix::fs::symlink(&inputs, inputs.join("street/loop")).unwrap();
    let outputs = dir.path().join("out");
    let assert = complete_dir(&inputs, &outputs)
        .args(["--model", s(&model), "--jobs", "2", "--json"])
        .assert()
        .failure()
        .stderr(predicate::str::contains("2 of 5 files failed"))
        .stderr(predicate::str::contains("broken.ply"))
        .stderr(
            predicate::str::contains("few.ply")
                .and(predicate::str::contains("too few points to complete: 20,")),
        )
        .stderr(predicate::str::contains("panicked").not());
    let report: serde_json::Value = serde_json::from_slice(&assert.get_output().stdout).unwrap();
    assert_eq!(report["results"].as_array().unwrap().len(), 5);
    assert_eq!(
        (&report["completed"], &report["failed"]),
        (&3.into(), &2.into())
    );
    let odd = report["results"]
        .as_array()
        .unwrap()
        .iter()
        .find(|r| r["input"].as_str().unwrap().ends_with("odd.ply"))
        .unwrap();
    let warnings: Vec<&str> = odd["warnings"]
        .as_array()
        .unwrap()
        .iter()
        .map(|w| w.as_str().unwrap())
        .collect();
    assert!(warnings.contains(&"dropped 1 point with NaN or infinite coordinates"));
    assert!(warnings.iter().any(|w| w.starts_with("1 point(s) lie far")));
    let stderr = String::from_utf8_lossy(&assert.get_output().stderr);
    for warning in warnings {
        let line = format!("warning: {}: {warning}\n", odd["input"].as_str().unwrap());
        assert_eq!(stderr.matches(&line).count(), 1, "{line}: {stderr}");
    }
    let failed: Vec<&str> = report["results"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|r| r["status"] == "failed")
        .map(|r| r["input"].as_str().unwrap())
        .collect();
    assert!(
        failed.iter().any(|f| f.ends_with("broken.ply")),
        "{failed:?}"
    );
    assert!(
        read_cloud(&outputs.join("a.ply"), None)
            .unwrap()
            .cloud
            .len()
            > 1000
    );
    assert!(
        read_cloud(&outputs.join("street/b.pcd"), None)
            .unwrap()
            .cloud
            .len()
            > 1000
    );
    assert!(!outputs.join("broken.ply").exists());
    assert!(!outputs.join("few.ply").exists());
    let leftovers: Vec<_> = std::fs::read_dir(&outputs)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(leftovers.len(), 3, "no temp files left: {leftovers:?}");
}

/// `complete` over a folder with `--json`: the inputs of the files it completed and skipped.
fn batch_run(args: &[&str]) -> (Vec<String>, Vec<String>) {
    let assert = mvpcc()
        .args(["complete", "--method", "mirror", "--json"])
        .args(args)
        .assert()
        .success();
    let report: serde_json::Value = serde_json::from_slice(&assert.get_output().stdout).unwrap();
    let inputs = |status: &str| -> Vec<String> {
        report["results"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|r| r["status"] == status)
            .map(|r| r["input"].as_str().unwrap().to_string())
            .collect()
    };
    (inputs("completed"), inputs("skipped"))
}

#[test]
fn shards_split_a_folder_exactly_and_skip_existing_redoes_nothing() {
    let dir = TempDir::new().unwrap();
    let inputs = dir.path().join("in");
    let outputs = dir.path().join("out");
    std::fs::create_dir_all(inputs.join("block")).unwrap();
    let names = [
        "a.ply",
        "b.ply",
        "c.ply",
        "block/d.ply",
        "block/e.ply",
        "block/f.ply",
    ];
    for (i, name) in names.iter().enumerate() {
        let cloud = shapes::scanned_side(&shapes::car(3000, i as u64));
        write_cloud(&inputs.join(name), &cloud, None, Encoding::Binary).unwrap();
    }
    let dirs = ["--input-dir", s(&inputs), "--output-dir", s(&outputs)];
    let mut taken = Vec::new();
    for shard in ["0/3", "1/3", "2/3"] {
        let (completed, skipped) = batch_run(&[&dirs[..], &["--shard", shard]].concat());
        assert!(skipped.is_empty());
        taken.extend(completed);
    }
    taken.sort();
    let mut all: Vec<String> = names
        .iter()
        .map(|n| s(&inputs.join(n)).to_string())
        .collect();
    all.sort();
    assert_eq!(taken, all, "the shards together take each file once");

    let (completed, skipped) = batch_run(&[&dirs[..], &["--skip-existing"]].concat());
    assert!(completed.is_empty(), "{completed:?}");
    assert_eq!(skipped.len(), names.len());
    std::fs::remove_file(outputs.join("block/e.ply")).unwrap();
    let (completed, _) = batch_run(&[&dirs[..], &["--skip-existing"]].concat());
    assert_eq!(completed, [s(&inputs.join("block/e.ply"))]);

    let list = dir.path().join("list.txt");
    let listed = dir.path().join("listed");
    let absolute = inputs.join("c.ply");
    std::fs::write(
        &list,
        format!("# two of them\nblock/d.ply\n{}\n", s(&absolute)),
    )
    .unwrap();
    let (completed, _) = batch_run(&[
        "--list",
        s(&list),
        "--input-dir",
        s(&inputs),
        "--output-dir",
        s(&listed),
    ]);
    assert_eq!(completed.len(), 2);
    assert!(listed.join("block/d.ply").is_file() && listed.join("c.ply").is_file());

    complete_dir(&inputs, &outputs)
        .args(["--shard", "3/3"])
        .assert()
        .failure()
        .stderr(predicate::str::contains("counted from 0"));
}

/// A batch written to XYZ said for every file that the `synthetic` flag is lost; a warning the
/// files share is said once, naming them, and the JSON keeps each file's.
#[test]
fn a_warning_shared_by_a_batch_is_said_once() {
    let dir = TempDir::new().unwrap();
    let model = tiny_model(&dir);
    let inputs = dir.path().join("in");
    std::fs::create_dir(&inputs).unwrap();
    for (i, name) in ["a", "b", "c", "d"].into_iter().enumerate() {
        let path = inputs.join(format!("{name}.ply"));
        write_cloud(&path, &scan(i as u64), None, Encoding::Binary).unwrap();
    }
    let outputs = dir.path().join("out");
    let assert = complete_dir(&inputs, &outputs)
        .args(["--model", s(&model), "--out-format", "xyz", "--json"])
        .assert()
        .success();
    let stderr = String::from_utf8_lossy(&assert.get_output().stderr);
    let lost = "attribute synthetic is not written";
    let lines: Vec<&str> = stderr.lines().filter(|l| l.contains(lost)).collect();
    let first_two = format!("{}, {}", s(&inputs.join("a.ply")), s(&inputs.join("b.ply")));
    assert_eq!(lines.len(), 1, "{stderr}");
    assert!(
        lines[0].starts_with(&format!("warning: {first_two} and 2 more files: {lost}")),
        "{stderr}"
    );
    let report: serde_json::Value = serde_json::from_slice(&assert.get_output().stdout).unwrap();
    for result in report["results"].as_array().unwrap() {
        let warnings = result["warnings"].as_array().unwrap();
        assert!(warnings.iter().any(|w| w.as_str().unwrap().contains(lost)));
    }
}

#[test]
fn odd_inputs_warn_and_tiny_ones_fail_cleanly() {
    let dir = TempDir::new().unwrap();
    let model = tiny_model(&dir);
    // A single scan line: 300 points along a 5 m pole.
    let line = PointCloud {
        positions: (0..300).map(|i| [0.0, i as f64 / 60.0, 0.0]).collect(),
        ..Default::default()
    };
    let input = write(&dir, "pole.ply", &line);
    let output = dir.path().join("pole_done.ply");
    mvpcc()
        .args(["complete", s(&input), s(&output), "--model", s(&model)])
        .assert()
        .success()
        .stderr(predicate::str::contains("warning").and(predicate::str::contains("pole.ply")));
    assert!(output.exists());

    // One stray return far off: the warning names it and the way out, and --clean takes it.
    let mut stray = PointCloud::from_positions(scan(9).positions);
    stray.positions.push([500.0, 0.0, 0.0]);
    let input = write(&dir, "stray.ply", &stray);
    let output = dir.path().join("stray_done.ply");
    let base = ["complete", s(&input), s(&output), "--method", "mirror"];
    mvpcc().args(base).assert().success().stderr(
        predicate::str::contains("stray.ply: 1 point(s) lie far from the rest")
            .and(predicate::str::contains("--clean")),
    );
    mvpcc()
        .args(base)
        .arg("--clean")
        .assert()
        .success()
        .stderr(predicate::str::contains("far from the rest").not());

    let few = PointCloud {
        positions: (0..20).map(|i| [i as f64, 0.0, 1.0]).collect(),
        ..Default::default()
    };
    let input = write(&dir, "few.ply", &few);
    let output = dir.path().join("few_done.ply");
    let assert = mvpcc()
        .args(["complete", s(&input), s(&output), "--model", s(&model)])
        .assert()
        .failure();
    let stderr = String::from_utf8(assert.get_output().stderr.clone()).unwrap();
    assert_eq!(stderr.lines().count(), 1, "{stderr}");
    assert!(
        stderr.starts_with("error: ") && stderr.contains("few.ply"),
        "{stderr}"
    );
    assert!(!output.exists());

    let input = write(&dir, "scan.ply", &scan(9));
    let output = dir.path().join("x.ply");
    mvpcc()
        .args([
            "complete",
            s(&input),
            s(&output),
            "--model",
            s(&dir.path().join("none")),
        ])
        .assert()
        .failure()
        .stderr(predicate::str::contains("none"));
    assert!(!output.exists());
}

/// `--paper` on the real MLS scans with the built-in model: the paper's pipeline alone (no
/// orientation, no plane, no mirror images, only the network's points), in the scan's frame.
#[ignore = "needs ../shared/reference"]
#[test]
fn the_paper_pipeline_runs_on_the_reference_scans() {
    let mls = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/reference/clouds/mls");
    assert!(mls.is_dir(), "{} is absent", mls.display());
    let dir = TempDir::new().unwrap();
    let out = dir.path().join("out");
    let assert = complete_dir(&mls, &out)
        .args(["--paper", "--up", "z", "--json"])
        .assert()
        .success();
    let report: serde_json::Value = serde_json::from_slice(&assert.get_output().stdout).unwrap();
    let reports = report["results"].as_array().unwrap();
    assert_eq!(reports.len(), 4);
    for r in reports {
        assert_eq!(r["status"], "completed", "{r}");
        assert_eq!(r["orientation"]["method"], "none", "{r}");
        assert!(r["symmetry_plane"].is_null() && r["mirrored"] == 0, "{r}");
        assert_eq!(
            r["added"], r["output_points"],
            "only the network's points: {r}"
        );
        assert!(r["output_points"].as_u64().unwrap() > 1000, "{r}");
    }
    let input = read_cloud(&mls.join("CAR175.pcd"), None).unwrap().cloud;
    let output = read_cloud(&out.join("CAR175.pcd"), None).unwrap().cloud;
    let b = input.bounds().unwrap();
    let (lo, hi) = (b.min, b.max);
    let near = output
        .positions
        .iter()
        .filter(|p| (0..3).all(|i| p[i] > lo[i] - 1.0 && p[i] < hi[i] + 1.0))
        .count();
    assert!(
        near * 10 >= output.len() * 9,
        "{near} of {} near the scan",
        output.len()
    );
    mvpcc()
        .args(["complete", "--paper", "--clean", "a.ply", "b.ply"])
        .assert()
        .failure()
        .stderr(predicate::str::contains("cannot be used with"));
}

#[test]
fn saved_views_are_the_datasets_format_and_eval_scores_them() {
    let dir = TempDir::new().unwrap();
    let model = tiny_model(&dir);
    let input = write(&dir, "scan.ply", &scan(3));
    let views = dir.path().join("views");
    mvpcc()
        .args(["complete", s(&input), s(&dir.path().join("out.ply"))])
        .args(["--model", s(&model), "--save-views", s(&views)])
        .assert()
        .success();
    for side in ["input", "output"] {
        for view in [5, 6, 7, 8] {
            for kind in ["locations", "color"] {
                let png = views.join(side).join(format!("{kind}_{view:03}.png"));
                assert!(png.is_file(), "{} missing", png.display());
            }
        }
    }
    let scores = mvpcc()
        .args(["eval", "--metrics", "psnr,ssim,mae", "--json"])
        .args(["--pred-views", s(&views.join("output"))])
        .args(["--gt-views", s(&views.join("input"))])
        .assert()
        .success()
        .get_output()
        .stdout
        .clone();
    let scores = String::from_utf8(scores).unwrap();
    assert!(scores.contains("psnr"), "{scores}");
    // The mirror method runs no network: said, not failed.
    mvpcc()
        .args(["complete", s(&input), s(&dir.path().join("m.ply"))])
        .args([
            "--method",
            "mirror",
            "--save-views",
            s(&dir.path().join("none")),
        ])
        .assert()
        .success()
        .stderr(predicate::str::contains("no views to save"));
}

/// `--preview` once wrote its PNG over the input cloud it was given as a path, a `.gif` preview
/// was a PNG under that name, and `--save-views` naming the output made a folder there and then
/// failed; a preview or views path that cannot be written is now refused before anything is.
#[test]
fn a_preview_or_views_path_never_takes_the_place_of_a_cloud() {
    let dir = TempDir::new().unwrap();
    let model = tiny_model(&dir);
    let input = write(&dir, "scan.ply", &scan(3));
    let before = std::fs::read(&input).unwrap();
    let output = dir.path().join("done.ply");
    let missing = dir.path().join("missing").join("p.png");
    let gif = dir.path().join("p.gif");
    let png = dir.path().join("p.png");
    let cases: [(&[&str], &str); 7] = [
        (
            &["--preview", s(&input)],
            "output would overwrite the input file",
        ),
        (
            &["--preview", s(&output)],
            "--preview names the output cloud",
        ),
        (&["--preview", s(&missing)], "does not exist"),
        (
            &["--save-views", s(&input)],
            "--save-views needs a directory",
        ),
        (
            &["--preview", s(&gif)],
            "unsupported preview extension \"gif\" (expected png, jpg or jpeg)",
        ),
        (
            &["--save-views", s(&output)],
            "--save-views names an output file",
        ),
        (
            &["--save-views", s(&png), "--preview", s(&png)],
            "--save-views names an output file",
        ),
    ];
    for (extra, problem) in cases {
        mvpcc()
            .args(["complete", s(&input), s(&output), "--model", s(&model)])
            .args(extra)
            .assert()
            .failure()
            .stderr(predicate::str::contains(problem));
        assert!(!output.exists(), "{extra:?} wrote the output");
        assert!(
            !gif.exists() && !png.exists(),
            "{extra:?} wrote a preview or views"
        );
        assert_eq!(std::fs::read(&input).unwrap(), before, "{extra:?}");
    }
}

/// `--model` takes the folder `train --init` takes: a run's or one laid out as assets/; a
/// folder without a generator and a missing file are named.
#[test]
fn a_model_folder_laid_out_as_assets_is_read() {
    let dir = TempDir::new().unwrap();
    let input = write(&dir, "scan.ply", &scan(3));
    let assets = dir.path().join("assets");
    std::fs::create_dir(&assets).unwrap();
    let empty = dir.path().join("empty");
    std::fs::create_dir(&empty).unwrap();
    std::fs::copy(tiny_model(&dir), assets.join("model.safetensors")).unwrap();
    let output = dir.path().join("done.ply");
    mvpcc()
        .args(["complete", s(&input), s(&output), "--model", s(&assets)])
        .assert()
        .success();
    assert!(output.exists());
    let refused = dir.path().join("refused.ply");
    mvpcc()
        .args(["complete", s(&input), s(&refused), "--model", s(&empty)])
        .assert()
        .failure()
        .stderr(predicate::str::contains(
            "empty: holds neither generator.safetensors nor model.safetensors",
        ));
    let missing = dir.path().join("missing.safetensors");
    mvpcc()
        .args(["complete", s(&input), s(&refused), "--model", s(&missing)])
        .assert()
        .failure()
        .stderr(predicate::str::contains(
            "missing.safetensors: no such file",
        ));
    assert!(!refused.exists());
}

/// An `--include` that matches nothing says so; one of many stars over a long name is answered
/// at once (the recursive match it replaced ran past 30 s on this one).
#[test]
fn an_include_pattern_that_matches_nothing_is_named() {
    let dir = TempDir::new().unwrap();
    let inputs = dir.path().join("in");
    std::fs::create_dir(&inputs).unwrap();
    write_cloud(
        &inputs.join(format!("{}.ply", "a".repeat(60))),
        &scan(3),
        None,
        Encoding::Binary,
    )
    .unwrap();
    let outputs = dir.path().join("out");
    let stars = "*a*a*a*a*a*a*a*a*a*a*a*a*b";
    mvpcc()
        .args([
            "complete",
            "--input-dir",
            s(&inputs),
            "--output-dir",
            s(&outputs),
        ])
        .args(["--method", "mirror", "--include", stars])
        .assert()
        .failure()
        .stderr(predicate::str::contains(format!(
            "no file matches --include '{stars}'"
        )));
    assert!(!outputs.exists());
}

/// `--jobs 0` was taken as one job without a word; jobs past the bound would only queue for the
/// cores. Both are refused before the output folder is made.
#[test]
fn batch_jobs_are_bounded() {
    let dir = TempDir::new().unwrap();
    let inputs = dir.path().join("in");
    std::fs::create_dir(&inputs).unwrap();
    let outputs = dir.path().join("out");
    for jobs in ["0", "257"] {
        complete_dir(&inputs, &outputs)
            .args(["--method", "mirror", "--jobs", jobs])
            .assert()
            .code(2)
            .stderr(predicate::str::contains(format!(
                "{jobs} is not in 1..=256"
            )));
        assert!(!outputs.exists());
    }
}

/// An output folder inside the input folder is not read as input: a second run completed the
/// first one's outputs again, into a folder one level deeper each time.
#[test]
fn an_output_folder_inside_the_inputs_is_not_completed_again() {
    let dir = TempDir::new().unwrap();
    let inputs = dir.path().join("in");
    std::fs::create_dir_all(inputs.join("street")).unwrap();
    for name in ["a.ply", "street/b.ply"] {
        write_cloud(&inputs.join(name), &scan(3), None, Encoding::Binary).unwrap();
    }
    let outputs = inputs.join("completed");
    for _ in 0..2 {
        let assert = complete_dir(&inputs, &outputs)
            .args(["--method", "mirror", "--json"])
            .assert()
            .success();
        let report: serde_json::Value =
            serde_json::from_slice(&assert.get_output().stdout).unwrap();
        assert_eq!(
            (&report["files"], &report["completed"]),
            (&2.into(), &2.into())
        );
    }
    assert!(outputs.join("street/b.ply").exists());
    assert!(!outputs.join("completed").exists());
}

#[test]
fn a_dash_reads_standard_input_and_writes_standard_output() {
    let dir = TempDir::new().unwrap();
    let input = Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/example/car_partial.ply");
    let bytes = std::fs::read(&input).unwrap();
    let file_out = dir.path().join("out.ply");
    mvpcc()
        .args(["complete", s(&input), s(&file_out), "--method", "mirror"])
        .assert()
        .success();
    // Through the pipes: the format told by the first bytes and kept for the output, the log on
    // stderr, the cloud alone on stdout.
    let piped = mvpcc()
        .args(["complete", "-", "-", "--method", "mirror"])
        .write_stdin(bytes.clone())
        .assert()
        .success()
        .stderr(predicate::str::starts_with("-: "))
        .get_output()
        .stdout
        .clone();
    assert_eq!(piped, std::fs::read(&file_out).unwrap());
    mvpcc()
        .args(["complete", s(&input), "-", "--json"])
        .assert()
        .failure()
        .stdout("")
        .stderr(predicate::str::contains(
            "-: --json and the completed cloud cannot both go to standard output",
        ));
    let refused = dir.path().join("refused.ply");
    mvpcc()
        .args(["complete", "-", s(&refused)])
        .write_stdin(Vec::<u8>::new())
        .assert()
        .failure()
        .stderr("error: -: file is empty\n");
    mvpcc()
        .args(["filter", s(&input), "-"])
        .assert()
        .failure()
        .stdout("")
        .stderr(predicate::str::contains(
            "-: standard output has no extension to tell the format: pass --out-format",
        ));
    // A file named `-` is `./-`.
    mvpcc()
        .current_dir(dir.path())
        .args([
            "complete",
            s(&input),
            "./-",
            "--out-format",
            "ply",
            "--method",
            "mirror",
        ])
        .assert()
        .success();
    assert_eq!(std::fs::read(dir.path().join("-")).unwrap(), piped);
    assert!(!refused.exists());
}

#[cfg(unix)]
#[test]
fn pipes_are_read_and_written_a_link_keeps_its_file_and_a_folder_is_refused() {
    use std::os::unix::fs::FileTypeExt;
    let dir = TempDir::new().unwrap();
    let input = Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/example/car_partial.ply");
    let mirror = |output: &Path, extra: &[&str]| {
        mvpcc()
            .args(["complete", s(&input), s(output), "--method", "mirror"])
            .args(extra)
            .assert()
            .success();
    };
    // Renaming a finished file over a pipe (or, run as root, over /dev/null) would replace it.
    let fifo = dir.path().join("fifo");
    assert!(std::process::Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .unwrap()
        .success());
    let reader = {
        let fifo = fifo.clone();
        std::thread::spawn(move || std::fs::read(fifo).unwrap())
    };
    mirror(&fifo, &["--out-format", "las"]);
    // Before joining: had the pipe been replaced, its reader would wait for ever.
    assert!(std::fs::metadata(&fifo).unwrap().file_type().is_fifo());
    let through_pipe = reader.join().unwrap();
    let file = dir.path().join("file.las");
    mirror(&file, &[]);
    assert_eq!(through_pipe, std::fs::read(&file).unwrap());
    // A pipe as the input (a shell's `<(…)`), its format told by its first bytes.
    let writer = {
        let fifo = fifo.clone();
        std::thread::spawn(move || std::fs::write(fifo, through_pipe).unwrap())
    };
    let from_pipe = dir.path().join("from_pipe.las");
    mvpcc()
        .args(["complete", s(&fifo), s(&from_pipe), "--method", "identity"])
        .assert()
        .success();
    writer.join().unwrap();
    assert_eq!(
        read_cloud(&from_pipe, None).unwrap().cloud.positions,
        read_cloud(&file, None).unwrap().cloud.positions
    );

    let target = dir.path().join("target.ply");
    std::fs::write(&target, b"old").unwrap();
    let link = dir.path().join("link.ply");
    std::os::unix::fs::symlink(&target, &link).unwrap();
    mirror(&link, &[]);
    assert!(std::fs::symlink_metadata(&link)
        .unwrap()
        .file_type()
        .is_symlink());
    assert!(!read_cloud(&target, None).unwrap().cloud.is_empty());

    mvpcc()
        .args(["complete", s(&input), s(dir.path())])
        .assert()
        .failure()
        .stderr(format!(
            "error: {}: is a directory; name the output file\n",
            dir.path().display()
        ));
}

#[test]
fn a_preview_is_a_jpeg_when_its_name_says_so() {
    let dir = TempDir::new().unwrap();
    let input = Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/example/car_partial.ply");
    for (name, magic) in [
        ("p.png", &b"\x89PNG"[..]),
        ("p.JPG", &b"\xFF\xD8\xFF"[..]),
        ("p.jpeg", &b"\xFF\xD8\xFF"[..]),
    ] {
        let preview = dir.path().join(name);
        mvpcc()
            .args(["complete", s(&input), s(&dir.path().join("o.ply"))])
            .args(["--method", "mirror", "--preview", s(&preview)])
            .assert()
            .success();
        assert!(
            std::fs::read(&preview).unwrap().starts_with(magic),
            "{name}"
        );
    }
}
