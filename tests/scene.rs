//! `mvpcc complete --scene` end to end on a small street in UTM coordinates (LAS, z up): two
//! scanned cars, a pole and the road; every input point comes back unchanged and in its order,
//! each car gains completed points numbered with its vehicle.

use assert_cmd::Command;
use mvpcc::core::cloud::{Attribute, PointCloud, ScalarKind, SYNTHETIC};
use mvpcc::datagen::shapes;
use mvpcc::io::{read_cloud, write_cloud, Encoding};
use predicates::prelude::*;
use std::path::{Path, PathBuf};
use tempfile::TempDir;

const OFFSET: [f64; 3] = [651_234.5, 5_234_567.25, 103.25];
const CLASS_GROUND: f64 = 2.0;
const CLASS_POLE: f64 = 5.0;
const CLASS_CAR: f64 = 10.0;

fn mvpcc() -> Command {
    Command::cargo_bin("mvpcc").unwrap()
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// A 40 × 12 m road (a point every 10 cm), a scanned car at x = 10 m and another, turned the
/// other way, at x = 25 m, and a pole at x = 33 m; z up, offset into UTM, classified.
fn street(with_cars: bool) -> PointCloud {
    let mut positions = Vec::new();
    let mut classes = Vec::new();
    for i in 0..400 {
        for j in 0..120 {
            positions.push([i as f64 * 0.1, j as f64 * 0.1, 0.0]);
            classes.push(CLASS_GROUND);
        }
    }
    if with_cars {
        for (seed, x, y, turn) in [(3, 10.0, 4.0, 1.0), (4, 25.0, 8.0, -1.0)] {
            // The generator's cars are y up, their length along z: length along x here.
            let car = shapes::scanned_side(&shapes::car(8000, seed)).positions;
            for p in car {
                positions.push([x + turn * p[2], y + turn * p[0], p[1]]);
                classes.push(CLASS_CAR);
            }
        }
    }
    for k in 0..100 {
        for (dx, dy) in [(0.0, 0.0), (0.05, 0.0), (0.0, 0.05), (0.05, 0.05)] {
            positions.push([33.0 + dx, 3.0 + dy, k as f64 * 0.05]);
            classes.push(CLASS_POLE);
        }
    }
    let mut cloud = PointCloud::from_positions(
        positions
            .into_iter()
            .map(|p| [0, 1, 2].map(|k| p[k] + OFFSET[k]))
            .collect(),
    );
    let n = cloud.len();
    cloud.attributes.push(Attribute {
        name: "classification".into(),
        kind: ScalarKind::U8,
        values: classes,
    });
    cloud.attributes.push(Attribute {
        name: "intensity".into(),
        kind: ScalarKind::U16,
        values: (0..n).map(|i| (i % 4000) as f64).collect(),
    });
    cloud
}

fn write(dir: &TempDir, name: &str, cloud: &PointCloud) -> PathBuf {
    let path = dir.path().join(name);
    write_cloud(&path, cloud, None, Encoding::Binary).unwrap();
    path
}

fn read(path: &Path) -> PointCloud {
    read_cloud(path, None).unwrap().cloud
}

/// The input's points and attributes are the output's first, to the bit and in order.
fn unchanged_then_appended(input: &PointCloud, output: &PointCloud) {
    let n = input.len();
    assert_eq!(output.positions[..n], input.positions[..]);
    for a in &input.attributes {
        let out = output.attribute(&a.name).unwrap();
        assert_eq!(out.values[..n], a.values[..], "{}", a.name);
    }
    assert_eq!(output.quantization, input.quantization);
}

/// The points of `cloud` in LAS class `class`.
fn count_class(cloud: &PointCloud, class: f64) -> usize {
    let classes = &cloud.attribute("classification").unwrap().values;
    classes.iter().filter(|&&c| c == class).count()
}

fn report(output: &std::process::Output) -> serde_json::Value {
    serde_json::from_slice(&output.stdout).unwrap()
}

#[test]
fn a_street_comes_back_unchanged_with_each_cars_completion_appended() {
    let dir = TempDir::new().unwrap();
    let input = write(&dir, "street.las", &street(true));
    let output = dir.path().join("done.las");
    let run = mvpcc()
        .args(["complete", "--scene", s(&input), s(&output), "--json"])
        .output()
        .unwrap();
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(
        stderr.contains("completed for 2 vehicles of 3 objects"),
        "{stderr}"
    );
    let (scanned, done) = (read(&input), read(&output));
    unchanged_then_appended(&scanned, &done);
    let n = scanned.len();
    assert!(done.len() > n + 1000, "{} after {n}", done.len());
    let flags = &done.attribute(SYNTHETIC).unwrap().values;
    let vehicles = &done.attribute("vehicle").unwrap().values;
    assert!(flags[..n].iter().all(|&f| f == 0.0) && vehicles[..n].iter().all(|&v| v == 0.0));
    assert!(flags[n..].iter().all(|&f| f == 1.0));
    let mut ids: Vec<f64> = vehicles[n..].to_vec();
    ids.dedup();
    assert_eq!(ids, [1.0, 2.0], "each car's points together, in its number");
    // Each car's completed points lie about it, out to the far flank the scan did not see.
    let json = report(&run);
    for car in json["scene"]["vehicles"].as_array().unwrap() {
        let id = car["id"].as_f64().unwrap();
        let centre: Vec<f64> = (0..3)
            .map(|k| car["footprint"]["centre"][k].as_f64().unwrap() - OFFSET[k])
            .collect();
        let nearest = [(10.0, 4.0), (25.0, 8.0)]
            .into_iter()
            .find(|(x, y)| (centre[0] - x).abs() < 1.0 && (centre[1] - y).abs() < 1.5);
        let (x, y) = nearest.unwrap_or_else(|| panic!("{car}"));
        let added: Vec<[f64; 3]> = (n..done.len())
            .filter(|&i| vehicles[i] == id)
            .map(|i| [0, 1, 2].map(|k| done.positions[i][k] - OFFSET[k]))
            .collect();
        let far = added.iter().fold([0.0f64; 2], |m, p| {
            [m[0].max((p[0] - x).abs()), m[1].max((p[1] - y).abs())]
        });
        // Half the car (2.2 m by 0.9) and at most 0.6 m beyond: no point strays to another object.
        assert!(far[0] < 2.8 && far[1] < 1.5, "{id}: {far:?}");
        assert!(far[1] > 0.6, "{id}: the far flank is drawn: {far:?}");
    }
    let scene = &json["scene"];
    assert_eq!(scene["vehicles"].as_array().unwrap().len(), 2);
    // The pole (5 m, higher than any vehicle: it reaches the height cut).
    assert_eq!(scene["rejected"]["too_tall"], 1, "the pole: {scene}");
    let car = &scene["vehicles"][0];
    assert_eq!(car["guess"], "car");
    let length = car["footprint"]["length"].as_f64().unwrap();
    assert!((3.5..5.0).contains(&length), "{car}");
}

#[test]
fn classes_name_the_vehicles_and_a_class_the_file_lacks_is_said() {
    let dir = TempDir::new().unwrap();
    let input = write(&dir, "street.las", &street(true));
    let output = dir.path().join("done.las");
    let run = mvpcc()
        .args(["complete", "--scene", "--vehicle-class", "10,64", "--json"])
        .args([s(&input), s(&output)])
        .output()
        .unwrap();
    assert!(run.status.success());
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(
        stderr.contains("street.las: --vehicle-class 64: no point has this class"),
        "{stderr}"
    );
    let json = report(&run);
    let cars = json["scene"]["vehicles"].as_array().unwrap();
    assert_eq!(cars.len(), 2);
    // The labelled cars alone: none of the road, nothing rejected.
    assert_eq!(json["scene"]["objects"], 2);
    let scanned = read(&input);
    let car_points = count_class(&scanned, CLASS_CAR);
    let counted: u64 = cars.iter().map(|c| c["points"].as_u64().unwrap()).sum();
    assert_eq!(counted as usize, car_points);
    unchanged_then_appended(&scanned, &read(&output));
}

#[test]
fn a_street_without_vehicles_comes_back_unchanged_and_says_so() {
    let dir = TempDir::new().unwrap();
    let input = write(&dir, "empty.las", &street(false));
    let output = dir.path().join("done.las");
    mvpcc()
        .args(["complete", "--scene", s(&input), s(&output)])
        .assert()
        .success()
        .stderr(predicate::str::contains(
            "empty.las: no vehicle found among 1 object; the scan is written unchanged",
        ));
    let (scanned, done) = (read(&input), read(&output));
    assert_eq!(done, scanned);
    // Streamed as read whole, and a class no point has is said.
    mvpcc()
        .args(["complete", "--scene", s(&input), s(&output)])
        .args(["--stream-from", "0", "--vehicle-class", "10,64"])
        .assert()
        .success()
        .stderr(predicate::str::contains(
            "--vehicle-class 64: no point has this class",
        ))
        .stderr(predicate::str::contains(
            "no vehicle found among 0 objects; the scan is written unchanged",
        ));
    assert_eq!(read(&output), scanned);
}

#[test]
fn a_cut_out_vehicle_given_as_a_scene_is_completed_as_one() {
    let dir = TempDir::new().unwrap();
    let mut car = shapes::scanned_side(&shapes::car(8000, 5));
    for p in &mut car.positions {
        *p = [p[0] + OFFSET[0], p[1] + OFFSET[2], p[2] + OFFSET[1]];
    }
    let input = write(&dir, "car.ply", &car);
    let (alone, in_scene) = (dir.path().join("alone.ply"), dir.path().join("scene.ply"));
    mvpcc()
        .args(["complete", s(&input), s(&alone)])
        .assert()
        .success();
    mvpcc()
        .args(["complete", "--scene", s(&input), s(&in_scene)])
        .assert()
        .success()
        .stderr(predicate::str::contains("for 1 vehicle of 1 object)"));
    let (alone, in_scene) = (read(&alone), read(&in_scene));
    assert_eq!(alone.positions, in_scene.positions);
    assert_eq!(
        in_scene.attribute("vehicle").unwrap().values[car.len()..],
        vec![1.0; alone.len() - car.len()][..]
    );
}

#[test]
fn a_completed_scene_is_not_completed_again() {
    let dir = TempDir::new().unwrap();
    let input = write(&dir, "street.las", &street(true));
    let once = dir.path().join("once.las");
    mvpcc()
        .args([
            "complete",
            "--scene",
            "--method",
            "mirror",
            s(&input),
            s(&once),
        ])
        .assert()
        .success();
    let twice = dir.path().join("twice.las");
    mvpcc()
        .args(["complete", "--scene", s(&once), s(&twice)])
        .assert()
        .failure()
        .stderr(
            predicate::str::is_match(
                r"(?m)^error: .*once\.las: the scene has a `vehicle` attribute already",
            )
            .unwrap(),
        );
    assert!(!twice.exists());
}

/// A 30 m street of `synth --scene --seed SEED` in `dir`: its LAS file and its truth.
fn generated_street(dir: &TempDir, seed: u64) -> (PathBuf, serde_json::Value) {
    let out = dir.path().join("streets");
    mvpcc()
        .args(["synth", "--scene", "--count", "1", "--length", "30"])
        .args(["--seed", &seed.to_string(), "--out", s(&out)])
        .assert()
        .success()
        .stderr(predicate::str::contains("wrote 1 street of 30 m"));
    let truth =
        serde_json::from_slice(&std::fs::read(out.join("street_00000.json")).unwrap()).unwrap();
    (out.join("street_00000.las"), truth)
}

/// `synth --scene` writes a classified street with each point's object and the objects' truth,
/// which `complete --scene --vehicle-class 64` completes vehicle by vehicle.
#[test]
fn a_generated_street_carries_its_truth_and_completes() {
    let dir = TempDir::new().unwrap();
    let (las, truth) = generated_street(&dir, 3);
    let street = read(&las);
    let objects = truth["objects"].as_array().unwrap();
    let ids = &street.attribute("object").unwrap().values;
    let classes = &street.attribute("classification").unwrap().values;
    for (id, class) in ids.iter().zip(classes) {
        let kind = objects[*id as usize]["kind"].as_str().unwrap();
        assert_eq!(kind == "vehicle", *class == 64.0, "{kind} {class}");
    }
    let vehicles = objects.iter().filter(|o| o["kind"] == "vehicle").count();
    assert!(vehicles >= 4, "{vehicles}");
    let done = dir.path().join("done.las");
    let run = mvpcc()
        .args([
            "complete",
            "--scene",
            "--vehicle-class",
            "64",
            "--method",
            "mirror",
            "--json",
        ])
        .args([s(&las), s(&done)])
        .output()
        .unwrap();
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    // Each vehicle the scan saw well (200 points or more) has a reported vehicle whose
    // footprint centre lies inside its box.
    let reported = report(&run)["scene"]["vehicles"]
        .as_array()
        .unwrap()
        .clone();
    let seen = |id: f64| ids.iter().filter(|&&o| o == id).count();
    let mut well_seen = 0;
    for (id, o) in objects.iter().enumerate() {
        if o["kind"] != "vehicle" || seen(id as f64) < 200 {
            continue;
        }
        well_seen += 1;
        let (centre, size) = (&o["centre"], &o["size"]);
        let f = |v: &serde_json::Value, k: usize| v[k].as_f64().unwrap();
        let inside = reported.iter().any(|r| {
            let c = &r["footprint"]["centre"];
            (f(c, 0) - f(centre, 0)).abs() < f(size, 0) / 2.0
                && (f(c, 1) - f(centre, 1)).abs() < f(size, 1) / 2.0
        });
        assert!(inside, "vehicle {id} {o} not reported");
    }
    assert!(well_seen >= vehicles / 2, "{well_seen} of {vehicles}");
    unchanged_then_appended(&street, &read(&done));
}

/// With `--vehicle-class`, the classes decide even for a clip no larger than a vehicle: the
/// road in it stays out of the completion. Without classes the option is refused in one line.
#[test]
fn classes_decide_in_a_small_clip_and_are_needed() {
    let dir = TempDir::new().unwrap();
    let full = street(true);
    let classes = &full.attribute("classification").unwrap().values;
    // The first car and the road within a metre of it: a clip 6 m long.
    let keep: Vec<bool> = full
        .positions
        .iter()
        .zip(classes)
        .map(|(p, &c)| {
            let (x, y) = (p[0] - OFFSET[0], p[1] - OFFSET[1]);
            (7.0..13.0).contains(&x)
                && (2.5..5.5).contains(&y)
                && (c == CLASS_CAR || c == CLASS_GROUND)
        })
        .collect();
    let clip = full.filter(&keep);
    let cars = count_class(&clip, CLASS_CAR);
    let input = write(&dir, "clip.las", &clip);
    let run = mvpcc()
        .args([
            "complete",
            "--scene",
            "--vehicle-class",
            "10",
            "--method",
            "mirror",
            "--json",
        ])
        .args([s(&input), s(&dir.path().join("done.las"))])
        .output()
        .unwrap();
    assert!(run.status.success());
    let vehicles = report(&run)["scene"]["vehicles"].clone();
    assert_eq!(
        vehicles[0]["points"].as_u64().unwrap() as usize,
        cars,
        "{vehicles}"
    );

    let mut unlabelled = clip.clone();
    unlabelled.attributes.retain(|a| a.name != "classification");
    let input = write(&dir, "unlabelled.ply", &unlabelled);
    mvpcc()
        .args(["complete", "--scene", "--vehicle-class", "10"])
        .args([s(&input), s(&dir.path().join("done.ply"))])
        .assert()
        .failure()
        .stderr(predicate::str::is_match(r"(?m)^error: .*unlabelled\.ply: --vehicle-class needs a `classification` attribute").unwrap());
}

/// A scan whose own points carry the synthetic flag (an earlier completion, a processed tile):
/// those points stay where they are and only what each vehicle gains is appended.
#[test]
fn points_flagged_synthetic_in_the_input_are_not_appended_again() {
    let dir = TempDir::new().unwrap();
    let mut scan = street(true);
    let n = scan.len();
    scan.attributes.push(Attribute {
        name: SYNTHETIC.into(),
        kind: ScalarKind::U8,
        values: (0..n).map(|i| (i % 2) as f64).collect(),
    });
    let input = write(&dir, "flagged.las", &scan);
    let output = dir.path().join("done.las");
    let run = mvpcc()
        .args([
            "complete",
            "--scene",
            "--method",
            "mirror",
            "--json",
            s(&input),
            s(&output),
        ])
        .output()
        .unwrap();
    assert!(run.status.success());
    let added: u64 = report(&run)["scene"]["vehicles"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v["added"].as_u64().unwrap())
        .sum();
    let (scanned, done) = (read(&input), read(&output));
    assert!(added > 0);
    assert_eq!(done.len(), n + added as usize);
    unchanged_then_appended(&scanned, &done);
}

/// A scene is in metres, so each vehicle's plane is kept at least half the narrowest width of
/// its kind from the scanned flank: the buses of a generated street, scanned from a lane beside
/// them at 2.4 m, had their planes 0.8–1.0 m off their centre lines from the scan alone.
#[test]
fn a_large_vehicles_plane_in_a_street_is_kept_off_its_scanned_flank() {
    let dir = TempDir::new().unwrap();
    let (las, truth) = generated_street(&dir, 2);
    let run = mvpcc()
        .args(["complete", "--scene", "--vehicle-class", "64"])
        .args(["--method", "mirror", "--json"])
        .arg(&las)
        .arg(dir.path().join("done.las"))
        .output()
        .unwrap();
    assert!(run.status.success());
    let f = |v: &serde_json::Value, k: usize| v[k].as_f64().unwrap();
    let mut buses = 0;
    for vehicle in report(&run)["scene"]["vehicles"].as_array().unwrap() {
        let c = &vehicle["footprint"]["centre"];
        // The true bus whose box holds the footprint's centre (the vehicles stand along x).
        let Some(bus) = truth["objects"].as_array().unwrap().iter().find(|o| {
            o["category"] == "bus"
                && (f(c, 0) - f(&o["centre"], 0)).abs() < f(&o["size"], 0) / 2.0
                && (f(c, 1) - f(&o["centre"], 1)).abs() < f(&o["size"], 1) / 2.0
        }) else {
            continue;
        };
        buses += 1;
        let plane = &vehicle["plane"];
        let off: f64 = (0..3)
            .map(|i| f(&plane["normal"], i) * (f(&bus["centre"], i) - f(&plane["point"], i)))
            .sum();
        // The narrowest large vehicle (2.2 m) against a 2.55 m bus: 0.175 m at most.
        assert!(off.abs() < 0.25, "{vehicle} {bus}: {off} m off");
    }
    assert_eq!(buses, 2);
}

/// Runs `complete --scene INPUT OUTPUT ARGS --json`, which must succeed: its report.
fn completed_scene(input: &Path, output: &Path, args: &[&str]) -> serde_json::Value {
    let run = mvpcc()
        .args(["complete", "--scene", s(input), s(output), "--json"])
        .args(args)
        .output()
        .unwrap();
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    report(&run)
}

/// A tile streamed in chunks (`--stream-from 0`) of 24 m, so that the second car (22.8–27.2 m)
/// crosses a border: every input point comes back to the bit, and each car is found and
/// completed once, as when the tile is read whole. LAZ in and out.
#[test]
fn a_tile_streamed_in_chunks_completes_each_vehicle_once_as_read_whole() {
    let dir = TempDir::new().unwrap();
    let input = write(&dir, "street.laz", &street(true));
    let (whole, streamed) = (
        dir.path().join("whole.laz"),
        dir.path().join("streamed.laz"),
    );
    let preview = dir.path().join("streamed.png");
    let read_whole = completed_scene(&input, &whole, &[]);
    let chunked = completed_scene(
        &input,
        &streamed,
        &[
            "--stream-from",
            "0",
            "--chunk",
            "24",
            "--preview",
            s(&preview),
        ],
    );
    let image = image::open(&preview).unwrap().to_rgb8();
    let red = image.pixels().filter(|p| p.0 == [230, 60, 30]).count();
    assert!(red > 1000, "the completed points are drawn: {red} pixels");
    assert_eq!(chunked["scene"]["chunks"], 2, "{chunked}");
    assert!(read_whole["scene"].get("chunks").is_none());
    let (scanned, done) = (read(&input), read(&streamed));
    unchanged_then_appended(&scanned, &done);
    let n = scanned.len();
    let ids = &done.attribute("vehicle").unwrap().values;
    assert!(ids[..n].iter().all(|&v| v == 0.0));
    let mut appended: Vec<f64> = ids[n..].to_vec();
    appended.dedup();
    assert_eq!(
        appended,
        [1.0, 2.0],
        "each car completed once, its points together"
    );
    let flags = &done.attribute(SYNTHETIC).unwrap().values;
    assert!(flags[n..].iter().all(|&f| f == 1.0) && flags[..n].iter().all(|&f| f == 0.0));
    let vehicles = |r: &serde_json::Value| {
        let mut v: Vec<(i64, i64, u64)> = r["scene"]["vehicles"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| {
                let c = &v["footprint"]["centre"];
                let cm = |k: usize| (c[k].as_f64().unwrap() * 100.0).round() as i64;
                (cm(0), cm(1), v["points"].as_u64().unwrap())
            })
            .collect();
        v.sort();
        v
    };
    assert_eq!(vehicles(&chunked), vehicles(&read_whole));
    assert_eq!(
        chunked["scene"]["rejected"],
        read_whole["scene"]["rejected"]
    );
    assert_eq!(
        chunked["scene"]["ground_points"],
        read_whole["scene"]["ground_points"]
    );
    // The same points completed alike: the appended counts within a few per cent.
    let added = |r: &serde_json::Value| r["added"].as_f64().unwrap();
    let (a, b) = (added(&chunked), added(&read_whole));
    assert!((a - b).abs() <= 0.05 * b, "{a} streamed, {b} read whole");
    assert_eq!(done.len(), n + a as usize);
}
