//! The lab harness of `complete --scene`'s vehicle detection: generated streets
//! (`mvpcc::datagen::synth::street`) of the given seeds, their objects found as `complete
//! --scene` finds them, scored against the streets' ground truth (`mvpcc::scene::score`).
//! Prints one CSV line per street and the totals; the numbers docs/scenes.md quotes come from
//! here.
//!
//! `cargo run --release --example scene_detection -- SEED... [--length METRES] [--why]
//! [--complete]` (`--why`: on stderr, where each missed vehicle's points went and what each
//! false vehicle is; `--complete`: also completes each street as `complete --scene` does and
//! counts the completed points given to objects that are no vehicle)
//!
//! Seeds 1–20 are for choices; the report's figures are measured once on seeds 101–110.

use burn::tensor::Device;
use mvpcc::complete::orient::OrientMode;
use mvpcc::complete::{Completer, Options, Settings};
use mvpcc::core::frame::UpAxis;
use mvpcc::datagen::synth::street::{street, Kind, StreetParams, OBJECT};
use mvpcc::scene::score::{detection, Detection};
use mvpcc::scene::{complete_scene, find_objects, SceneParams, Selection, VEHICLE};

/// Vehicles with fewer scanned points are not counted: [`SceneParams::min_points`], under which
/// `--scene` does not look at an object.
const MIN_POINTS: usize = 200;

/// The true object most of `indices` belong to.
fn majority(indices: &[usize], labels: &[u32]) -> u32 {
    let mut held = std::collections::HashMap::<u32, usize>::new();
    for &i in indices {
        *held.entry(labels[i]).or_default() += 1;
    }
    held.into_iter()
        .max_by_key(|&(l, n)| (n, std::cmp::Reverse(l)))
        .map_or(0, |(l, _)| l)
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let mut params = StreetParams::default();
    let mut seeds = Vec::new();
    let mut why = false;
    let mut complete = false;
    let mut i = 0;
    while i < args.len() {
        match args[i].as_str() {
            "--why" => why = true,
            "--complete" => complete = true,
            "--length" => {
                params.length = args[i + 1].parse().expect("--length METRES");
                i += 1;
            }
            seed => seeds.push(seed.parse::<u64>().expect("a seed")),
        }
        i += 1;
    }
    println!("seed,points,vehicles,found,false_vehicles,merged,completed,completed_astray,missed");
    let mut total = Detection::default();
    let (mut total_added, mut total_astray) = (0, 0);
    let completer =
        complete.then(|| Completer::builtin(Device::flex()).expect("the built-in model"));
    for seed in seeds {
        let scene = street(seed, &params);
        let labels: Vec<u32> = scene
            .cloud
            .attribute(OBJECT)
            .expect("a generated street labels its points")
            .values
            .iter()
            .map(|&o| o as u32)
            .collect();
        let objects = find_objects(
            &scene.cloud,
            UpAxis::Z,
            &Selection::Detect,
            &SceneParams::default(),
        )
        .expect("detection needs no attribute");
        let is_vehicle = |l: u32| scene.objects[l as usize].kind == Kind::Vehicle;
        let d = detection(&objects, &labels, is_vehicle, MIN_POINTS);
        let missed: Vec<String> = d
            .missed
            .iter()
            .map(|&l| {
                let o = &scene.objects[l as usize];
                format!(
                    "{}{}",
                    o.category.map_or("?", |c| c.name()),
                    if o.driving { " driving" } else { "" }
                )
            })
            .collect();
        if why {
            // For each missed vehicle, the object that holds most of its points and its verdict.
            for &l in &d.missed {
                let mut best: Option<(usize, &mvpcc::scene::Object)> = None;
                for o in &objects.objects {
                    let n = o.indices.iter().filter(|&&i| labels[i] == l).count();
                    if n > best.map_or(0, |b| b.0) {
                        best = Some((n, o));
                    }
                }
                let t = &scene.objects[l as usize];
                eprintln!(
                    "seed {seed} missed {:?} {:?} size {:?}: {}",
                    t.category,
                    t.kind,
                    t.size.map(|v| (v * 10.0).round() / 10.0),
                    best.map_or("in no object".to_string(), |(n, o)| format!(
                        "{n} points in an object of {} ({:?}, {:.1} × {:.1} × {:.1} m)",
                        o.indices.len(),
                        o.verdict,
                        o.footprint.length,
                        o.footprint.width,
                        o.footprint.height
                    ))
                );
            }
        }
        if why {
            for o in objects.vehicles() {
                let t = &scene.objects[majority(&o.indices, &labels) as usize];
                if t.kind != Kind::Vehicle {
                    eprintln!(
                        "seed {seed} false vehicle: mostly {:?} (size {:?}), {:.1} × {:.1} × {:.1} m",
                        t.kind,
                        t.size.map(|v| (v * 10.0).round() / 10.0),
                        o.footprint.length,
                        o.footprint.width,
                        o.footprint.height
                    );
                }
            }
        }
        // The completed points given to objects that are no vehicle.
        let (added, astray) = match &completer {
            Some(completer) => {
                let settings = Settings {
                    clean: false,
                    orient: OrientMode::Auto,
                    options: Options {
                        up: UpAxis::Z,
                        ..Options::default()
                    },
                };
                let done = complete_scene(&scene.cloud, &objects, completer, &settings)
                    .expect("a generated street has no vehicle attribute");
                // Vehicle k + 1 is the k-th object taken for one; it is astray when most of
                // its points are no vehicle's.
                let astray_ids: Vec<f64> = objects
                    .vehicles()
                    .enumerate()
                    .filter(|(_, o)| !is_vehicle(majority(&o.indices, &labels)))
                    .map(|(k, _)| (k + 1) as f64)
                    .collect();
                let n = scene.cloud.len();
                let ids = &done.cloud.attribute(VEHICLE).expect("numbered").values[n..];
                (
                    ids.len(),
                    ids.iter().filter(|id| astray_ids.contains(id)).count(),
                )
            }
            None => (0, 0),
        };
        total_added += added;
        total_astray += astray;
        println!(
            "{seed},{},{},{},{},{},{added},{astray},{}",
            scene.cloud.len(),
            d.vehicles,
            d.found,
            d.false_vehicles,
            d.merged,
            missed.join(" ")
        );
        total.vehicles += d.vehicles;
        total.found += d.found;
        total.false_vehicles += d.false_vehicles;
        total.merged += d.merged;
    }
    println!(
        "all,,{},{},{},{},{total_added},{total_astray},found {:.1} %; completed points astray {:.2} %",
        total.vehicles,
        total.found,
        total.false_vehicles,
        total.merged,
        100.0 * total.found as f64 / total.vehicles.max(1) as f64,
        100.0 * total_astray as f64 / total_added.max(1) as f64
    );
}
