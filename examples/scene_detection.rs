//! The lab harness of `complete --scene`'s vehicle detection: generated streets
//! (`mvpcc::datagen::synth::street`) of the given seeds, their objects found as `complete
//! --scene` finds them, scored against the streets' ground truth (`mvpcc::scene::score`).
//! Prints one CSV line per street and the totals; the numbers docs/scenes.md quotes come from
//! here.
//!
//! `cargo run --release --example scene_detection -- SEED... [--length METRES] [--why]
//! [--complete]` (`--why`: on stderr, where each missed vehicle's points went, what each
//! false vehicle is, and what each object taken for a vehicle by the flank rule alone or
//! shorter than 2.5 m is; `--complete`: also completes each street as `complete --scene` does and
//! counts the completed points given to objects that are no vehicle; `--real DIR
//! [--real-seeds 201,202]`: each scan in DIR, scaled to a car's length, put in place of a
//! parked vehicle of each street, completed there and alone, and the two compared by F1 at 1 %
//! of its length; `--vehicles FILE`: with `--complete`, one CSV line per vehicle found: how far
//! its symmetry plane lies from the true centre line, and the F1 at 1 % of its length between
//! its completion in the street and the completion of its own points alone, cut out by their
//! labels; `--no-width-prior`: each plane from its scan alone, as for a cut-out vehicle in
//! unknown units; `--dump DIR`: with `--vehicles`, each found vehicle's points as cut from
//! the street and as labelled, `SEED-ID-street.ply` and `SEED-ID-alone.ply`, for a closer look)
//!
//! Seeds 1–20 are for choices; the report's figures are measured once on seeds 101–110.

use burn::tensor::Device;
use mvpcc::complete::orient::OrientMode;
use mvpcc::complete::{Completer, Options, Settings};
use mvpcc::core::cloud::PointCloud;
use mvpcc::core::frame::UpAxis;
use mvpcc::datagen::synth::street::{street, Kind, StreetParams};
use mvpcc::datagen::synth::Category;
use mvpcc::io::{read_cloud, write_cloud, Encoding};
use mvpcc::metrics::compare_clouds;
use mvpcc::scene::score::{detection, Detection};
use mvpcc::scene::{complete_scene, find_objects, Narrowest, SceneParams, Selection, VEHICLE};

/// A real scan (y up, any scale) in place of the parked car nearest the right kerb of
/// `street`: scaled to 4.5 m long, its length along the road, on the ground where that vehicle
/// stood; the vehicle's points removed. Returns the street, the scan as placed and the labels of
/// the street's points left.
fn with_real_car(
    street: &mvpcc::datagen::synth::street::Street,
    labels: &[u32],
    real: &PointCloud,
) -> (PointCloud, PointCloud, Vec<u32>) {
    let spot = street
        .objects
        .iter()
        .filter(|o| o.category == Some(Category::Car) && !o.driving)
        .max_by(|a, b| a.centre[1].total_cmp(&b.centre[1]))
        .expect("a parked car");
    let keep: Vec<bool> = labels.iter().map(|&l| l != spot.id).collect();
    let mut scene = street.cloud.filter(&keep);
    let kept = labels.iter().copied().filter(|&l| l != spot.id).collect();
    let bounds = real.bounds().expect("a scan has points");
    let scale = 4.5 / bounds.extent()[2];
    let mid = bounds.center();
    let mut car = real.clone();
    for p in &mut car.positions {
        *p = [
            spot.centre[0] + (p[2] - mid[2]) * scale,
            spot.centre[1] + (p[0] - mid[0]) * scale,
            spot.centre[2] + (p[1] - bounds.min[1]) * scale,
        ];
    }
    car.attributes.clear();
    scene.colors = None;
    car.colors = None;
    scene.attributes.clear();
    scene.append(car.clone());
    (scene, car, kept)
}

/// What `complete --scene` runs each vehicle with on a generated street (LAS: z up).
fn street_settings() -> Settings {
    Settings {
        clean: false,
        orient: OrientMode::Auto,
        options: Options {
            up: UpAxis::Z,
            ..Options::default()
        },
    }
}

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

/// One CSV line per vehicle found in a street (`--vehicles`): its plane's distance from the
/// true centre line (metres and share of its length) and the F1 at 1 % of its length between
/// its completion in the street and that of its labelled points alone.
#[allow(clippy::too_many_arguments)]
fn vehicle_rows(
    seed: u64,
    scene: &mvpcc::datagen::synth::street::Street,
    labels: &[u32],
    objects: &mvpcc::scene::Objects,
    done: &mvpcc::scene::SceneCompletion,
    completer: &Completer,
    settings: &Settings,
    narrowest: &Narrowest,
    dump: Option<&std::path::Path>,
) -> Vec<String> {
    let ids = &done.cloud.attribute(VEHICLE).expect("numbered").values;
    let n = scene.cloud.len();
    objects
        .vehicles()
        .zip(&done.vehicles)
        .filter_map(|(o, report)| {
            let truth = &scene.objects[majority(&o.indices, labels) as usize];
            if truth.kind != Kind::Vehicle {
                return None;
            }
            let length = truth.size[0];
            // The vehicles stand along the street (x), so the true plane is y = centre's y.
            let off = report.plane.map(|p| {
                let d: f64 = (0..3)
                    .map(|i| p.normal[i] * (truth.centre[i] - p.point[i]))
                    .sum();
                d.abs()
            });
            let own: Vec<usize> = (0..n).filter(|&i| labels[i] == truth.id).collect();
            if let Some(dir) = dump {
                for (what, indices) in [("street", &o.indices), ("alone", &own)] {
                    let path = dir.join(format!("{seed}-{}-{what}.ply", report.id));
                    let cloud = scene.cloud.select(indices);
                    write_cloud(&path, &cloud, None, Encoding::Binary).expect("--dump DIR");
                }
            }
            let mut alone_settings = settings.clone();
            alone_settings.options.min_vehicle_width = narrowest.of(o.guess());
            let alone = completer
                .run(&scene.cloud.select(&own), &alone_settings)
                .ok()?
                .completion
                .cloud;
            let id = report.id as f64;
            let mut street: Vec<[f64; 3]> = o
                .indices
                .iter()
                .map(|&i| scene.cloud.positions[i])
                .collect();
            street.extend(
                (n..done.cloud.len())
                    .filter(|&i| ids[i] == id)
                    .map(|i| done.cloud.positions[i]),
            );
            let f1 = compare_clouds(&street, &alone.positions, &[0.01 * length]).fscores[0].f1;
            let shared = o.indices.iter().filter(|&&i| labels[i] == truth.id).count();
            let fit = report
                .plane
                .map_or("none".to_string(), |p| format!("{:?}", p.fit));
            let vouched = report
                .plane
                .map_or(String::new(), |p| p.vouched.to_string());
            Some(format!(
                "{seed},{},{},{length:.2},{:?},{fit},{vouched},{},{},{f1:.4},{},{},{shared}",
                report.id,
                truth.category.map_or("?", |c| c.name()),
                o.guess(),
                off.map_or(String::new(), |d| format!("{d:.4}")),
                off.map_or(String::new(), |d| format!("{:.5}", d / length)),
                o.indices.len(),
                own.len(),
            ))
        })
        .collect()
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let mut params = StreetParams::default();
    let mut seeds = Vec::new();
    let mut why = false;
    let mut reals: Vec<(String, PointCloud)> = Vec::new();
    let mut real_seeds: Vec<u64> = vec![201];
    let mut complete = false;
    let mut narrowest = Narrowest::default();
    let mut vehicles_csv: Option<String> = None;
    let mut dump: Option<std::path::PathBuf> = None;
    let mut i = 0;
    while i < args.len() {
        match args[i].as_str() {
            "--why" => why = true,
            "--real" => {
                for entry in std::fs::read_dir(&args[i + 1]).expect("--real DIR") {
                    let path = entry.expect("a listing").path();
                    let cloud = read_cloud(&path, None).expect("a readable scan").cloud;
                    let name = path
                        .file_stem()
                        .map_or(String::new(), |n| n.to_string_lossy().into_owned());
                    reals.push((name, cloud));
                }
                reals.sort_by(|a, b| a.0.cmp(&b.0));
                i += 1;
            }
            "--real-seeds" => {
                real_seeds = args[i + 1]
                    .split(',')
                    .map(|v| v.parse().expect("seeds"))
                    .collect();
                i += 1;
            }
            "--complete" => complete = true,
            "--no-width-prior" => {
                narrowest = Narrowest {
                    motorcycle: 0.0,
                    car: 0.0,
                    van: 0.0,
                    large: 0.0,
                }
            }
            "--dump" => {
                dump = Some(args[i + 1].clone().into());
                i += 1;
            }
            "--vehicles" => {
                vehicles_csv = Some(args[i + 1].clone());
                i += 1;
            }
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
    let mut per_vehicle: Vec<String> = Vec::new();
    for seed in seeds {
        let scene = street(seed, &params);
        let labels = scene.labels();
        let objects = find_objects(
            &scene.cloud,
            UpAxis::Z,
            &Selection::Detect,
            &SceneParams::default(),
        )
        .expect("detection needs no attribute");
        let is_vehicle = |l: u32| scene.objects[l as usize].kind == Kind::Vehicle;
        // Vehicles with fewer scanned points than `--scene` looks at are not counted.
        let d = detection(
            &objects,
            &labels,
            is_vehicle,
            SceneParams::default().min_points,
        );
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
            // Objects taken for vehicles by the flank rule alone (narrower than a vehicle),
            // with what they are: how thin a real flank is against a façade piece.
            let narrowest_width = SceneParams::default().sizes.width[0];
            // And those as short as a motorcycle: what they are, and how round.
            for o in objects.vehicles().filter(|o| o.footprint.length < 2.5) {
                let t = &scene.objects[majority(&o.indices, &labels) as usize];
                eprintln!(
                    "seed {seed} short: mostly {:?} {:?}, {:.2} × {:.2} × {:.2} m, length/width {:.2}",
                    t.kind,
                    t.category,
                    o.footprint.length,
                    o.footprint.width,
                    o.footprint.height,
                    o.footprint.length / o.footprint.width
                );
            }
            for o in objects
                .vehicles()
                .filter(|o| o.footprint.width < narrowest_width)
            {
                let t = &scene.objects[majority(&o.indices, &labels) as usize];
                eprintln!(
                    "seed {seed} flank: mostly {:?} {:?}, {:.1} × {:.2} × {:.1} m, {} points",
                    t.kind,
                    t.category,
                    o.footprint.length,
                    o.footprint.width,
                    o.footprint.height,
                    o.indices.len()
                );
            }
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
                let settings = street_settings();
                let done = complete_scene(&scene.cloud, &objects, completer, &settings, &narrowest)
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
                if vehicles_csv.is_some() {
                    per_vehicle.extend(vehicle_rows(
                        seed,
                        &scene,
                        &labels,
                        &objects,
                        &done,
                        completer,
                        &settings,
                        &narrowest,
                        dump.as_deref(),
                    ));
                }
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
    for (name, real) in &reals {
        let completer = completer.as_ref().expect("--real needs --complete");
        let settings = street_settings();
        for &seed in &real_seeds {
            let scene = street(seed, &params);
            let labels = scene.labels();
            let (cloud, car, kept) = with_real_car(&scene, &labels, real);
            let alone = completer
                .run(&car, &settings)
                .expect("the real car completes")
                .completion
                .cloud;
            let objects = find_objects(
                &cloud,
                UpAxis::Z,
                &Selection::Detect,
                &SceneParams::default(),
            )
            .expect("no attribute needed");
            let done = complete_scene(&cloud, &objects, completer, &settings, &narrowest)
                .expect("completes");
            let first = cloud.len() - car.len();
            // The vehicle holding most of the real car's points, its points and its completion.
            let best = objects
                .vehicles()
                .enumerate()
                .max_by_key(|(_, o)| o.indices.iter().filter(|&&i| i >= first).count());
            let f1 = best.map_or(0.0, |(k, o)| {
                let id = (k + 1) as f64;
                let ids = &done.cloud.attribute(VEHICLE).expect("numbered").values;
                let mut points: Vec<[f64; 3]> =
                    o.indices.iter().map(|&i| cloud.positions[i]).collect();
                points.extend(
                    (cloud.len()..done.cloud.len())
                        .filter(|&i| ids[i] == id)
                        .map(|i| done.cloud.positions[i]),
                );
                compare_clouds(&points, &alone.positions, &[0.045]).fscores[0].f1
            });
            if why {
                if let Some((_, o)) = best {
                    let mut kinds = std::collections::BTreeMap::<String, usize>::new();
                    for &i in o.indices.iter().filter(|&&i| i < first) {
                        *kinds
                            .entry(format!("{:?}", scene.objects[kept[i] as usize].kind))
                            .or_default() += 1;
                    }
                    eprintln!("others in the real car's object: {kinds:?}");
                }
            }
            let (own, other) = best.map_or((0, 0), |(_, o)| {
                let own = o.indices.iter().filter(|&&i| i >= first).count();
                (own, o.indices.len() - own)
            });
            println!(
                "real {name} in street {seed}: F1@1 % of its length between its completion in the street and alone {f1:.4} ({own} of its {} points in the object, {other} others)",
                car.len()
            );
        }
    }
    if let Some(path) = &vehicles_csv {
        let mut text = String::from(
            "seed,vehicle,category,length,guess,fit,vouched,plane_off_m,plane_off_share,f1_street_vs_cut_out,object_points,own_points,shared_points\n",
        );
        for row in &per_vehicle {
            text.push_str(row);
            text.push('\n');
        }
        std::fs::write(path, text).expect("--vehicles FILE is writable");
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
