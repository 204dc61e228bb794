//! Whole street scans: the vehicles of an MLS tile found and each completed in its own frame by
//! the normal pipeline ([`Completer::run`]), the completed points appended to the scene, whose
//! own points stay as they were, in their order.
//!
//! Finding vehicles: where the input labels its points (`--vehicle-class`, LAS classification
//! codes), the labelled points; otherwise the points above the ground ([`ground`]). Either way
//! they are cut into objects by Euclidean clustering ([`cluster`]) and each object's footprint
//! (length, width, height over the ground) is tested against the sizes of street vehicles
//! ([`VehicleSizes`]). Coordinates are metres, as MLS tiles are: the sizes are the reason.

pub mod cluster;
pub mod ground;
pub mod preview;
pub mod score;
pub mod stream;

use crate::complete::symmetry::PlaneReport;
use crate::complete::{Completer, Settings};
use crate::core::cloud::{Attribute, PointCloud, ScalarKind, SYNTHETIC};
use crate::core::frame::UpAxis;
use ground::{Ground, GroundParams};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use thiserror::Error;

/// The attribute that numbers the vehicle each completed point belongs to (1, 2, …); 0 on the
/// scene's own points.
pub const VEHICLE: &str = "vehicle";

/// The LAS classification attribute, which `--vehicle-class` selects on.
pub const CLASSIFICATION: &str = "classification";

/// The size range of street vehicles, metres, in which a found object counts as one.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct VehicleSizes {
    /// Along the footprint's long axis: from a motorcycle (1.5 m, less what one side shows) to
    /// an articulated bus (18 m) and a little more.
    pub length: [f64; 2],
    /// Across it: from a motorcycle seen from one side to the widest road vehicle (2.6 m).
    pub width: [f64; 2],
    /// Over the ground: from a low sports car (1.1 m, less the scan's reach under it) to a
    /// double-decker bus (4.4 m).
    pub height: [f64; 2],
    /// The smallest length and height of an object narrower than `width` allows that may still
    /// be a vehicle's flank: a van taller than the scanner shows its flank alone (4 m long, 2 m
    /// high, less what the scan misses at its ends and at the ground); garden walls and fences
    /// are rarely that high.
    pub flank: [f64; 2],
    /// The least such a flank is across, metres: mirrors, wheel arches and a rounded roof edge
    /// stand out of a bus's or a lorry's side (0.30–0.47 m across on the generated streets 1–20),
    /// where a wall's face seen from the street is a few centimetres deep (façade pieces seen
    /// between parked vehicles there: 0.06–0.08 m).
    pub flank_depth: f64,
}

impl Default for VehicleSizes {
    fn default() -> Self {
        VehicleSizes {
            length: [1.4, 20.0],
            width: [0.5, 3.0],
            height: [0.9, 4.6],
            flank: [4.0, 1.9],
            flank_depth: 0.15,
        }
    }
}

/// An object whose top is within this of [`SceneParams::max_height`] is cut off there, metres:
/// the range noise of one return.
const CUT_OFF: f64 = 0.05;

/// How objects are found and which count as vehicles.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SceneParams {
    pub ground: GroundParams,
    /// Points closer than this are one object, metres: below the gap between cars parked in a
    /// row (half a metre or more), above the spacing of returns on a flank 10–20 m from an MLS
    /// scanner.
    pub gap: f64,
    /// Objects of fewer points are not looked at: too few to tell or to complete.
    pub min_points: usize,
    /// Points higher than this over the ground join no object, metres: above the tallest
    /// vehicle, so tree crowns and balconies do not join what stands under them.
    pub max_height: f64,
    /// Points the ground filter took that lie at least this far above the ground surface (the
    /// lowest returns, opened) and inside a vehicle's footprint are given back to it, metres: its
    /// tyres' lower parts, and some road returns with them (a real car completes in a street
    /// closer to how it does alone: lab/2026-12-07-scene-detection).
    pub lift: f64,
    pub sizes: VehicleSizes,
    pub narrowest: Narrowest,
}

/// The narrowest road vehicle of each [`Guess`] without its mirrors, metres. A scene is in
/// metres, so each vehicle's symmetry plane is told the least its width can be: a one-sided
/// scan's plane is then kept at least half of it from the outermost point of the scanned flank,
/// where the scan alone of a vehicle taller than the scanner puts it far too near
/// (docs/scenes.md, *Metres*). A value of 0 leaves the plane to the scan alone.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Narrowest {
    /// A motorcycle's body with its footrests is 0.4–0.6 m across; its handlebar (0.65–0.9 m)
    /// may be the part a one-sided scan misses.
    pub motorcycle: f64,
    /// Japanese kei cars are at most 1.48 m wide, a Smart Fortwo 1.56 m.
    pub car: f64,
    /// Small vans (Caddy, Berlingo) are 1.79–1.85 m wide, a large car 1.9 m.
    pub van: f64,
    /// Buses and lorries are 2.55 m wide in the EU, light trucks and narrow trams about 2.2 m.
    pub large: f64,
}

impl Default for Narrowest {
    fn default() -> Self {
        Narrowest {
            motorcycle: 0.4,
            car: 1.45,
            van: 1.7,
            large: 2.2,
        }
    }
}

impl Narrowest {
    /// The width given to the plane of a vehicle guessed `guess`; none where it is 0.
    pub fn of(&self, guess: Guess) -> Option<f64> {
        let width = match guess {
            Guess::Motorcycle => self.motorcycle,
            Guess::Car => self.car,
            Guess::Van => self.van,
            Guess::Large => self.large,
        };
        (width > 0.0).then_some(width)
    }
}

impl Default for SceneParams {
    fn default() -> Self {
        SceneParams {
            ground: GroundParams::default(),
            gap: 0.3,
            min_points: 200,
            max_height: 4.6,
            lift: 0.02,
            sizes: VehicleSizes::default(),
            narrowest: Narrowest::default(),
        }
    }
}

/// Which points may be vehicles.
#[derive(Debug, Clone, PartialEq)]
pub enum Selection {
    /// The points whose LAS classification is one of these codes.
    Classes(Vec<u8>),
    /// Every point above the ground.
    Detect,
}

/// An object's footprint: a box about the vertical, in the input's coordinates and units.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Footprint {
    /// The middle of the box's bottom face (on the ground).
    pub centre: [f64; 3],
    pub length: f64,
    pub width: f64,
    /// From the ground to the object's highest point.
    pub height: f64,
    /// Direction of the long axis in the horizontal plane, degrees from the first horizontal
    /// axis towards the second, in [0, 180).
    pub axis_deg: f64,
}

/// What the size test made of an object.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Verdict {
    Vehicle,
    TooShort,
    TooLong,
    TooNarrow,
    TooWide,
    TooLow,
    TooTall,
}

/// A rough category from the footprint, for the report.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Guess {
    Motorcycle,
    Car,
    Van,
    /// A truck, bus or tram: longer than 7 m.
    Large,
}

/// One object of the scene.
#[derive(Debug, Clone)]
pub struct Object {
    /// Its points, as indices into the scene.
    pub indices: Vec<usize>,
    pub footprint: Footprint,
    pub verdict: Verdict,
}

/// The share of an object's length, in metre-long slices along its axis, whose highest point
/// reaches the height above which points join no object: a façade's whole length, a tram's
/// pantograph alone.
fn cut_off_share(
    indices: &[usize],
    split_all: &[([f64; 2], f64)],
    f: &Footprint,
    base: f64,
    top: f64,
) -> f64 {
    let angle = f.axis_deg.to_radians();
    let axis = [angle.cos(), angle.sin()];
    let along: Vec<f64> = indices
        .iter()
        .map(|&i| split_all[i].0[0] * axis[0] + split_all[i].0[1] * axis[1])
        .collect();
    let start = along.iter().copied().fold(f64::INFINITY, f64::min);
    let slices = (f.length.ceil() as usize).max(1);
    let mut highest = vec![f64::NEG_INFINITY; slices];
    for (&i, &t) in indices.iter().zip(&along) {
        let s = ((t - start) as usize).min(slices - 1);
        highest[s] = highest[s].max(split_all[i].1 - base);
    }
    let seen: Vec<&f64> = highest.iter().filter(|h| h.is_finite()).collect();
    let reaching = seen.iter().filter(|&&&h| h >= top - CUT_OFF).count();
    reaching as f64 / seen.len().max(1) as f64
}

impl Object {
    /// From the footprint alone: a motorcycle is under 1.2 m wide and 2.8 m long, a car under
    /// 5.4 m and 2.1 m high (a van is either), a truck, bus or tram over 7 m.
    pub fn guess(&self) -> Guess {
        let f = &self.footprint;
        if f.width < 1.2 && f.length < 2.8 {
            Guess::Motorcycle
        } else if f.length > 7.0 {
            Guess::Large
        } else if f.height > 2.1 || f.length > 5.4 {
            Guess::Van
        } else {
            Guess::Car
        }
    }
}

/// The objects of a scene.
#[derive(Debug, Clone)]
pub struct Objects {
    pub objects: Vec<Object>,
    /// Points taken for ground (none when the input's classes said where vehicles are).
    pub ground_points: usize,
}

impl Objects {
    pub fn vehicles(&self) -> impl Iterator<Item = &Object> {
        self.objects
            .iter()
            .filter(|o| o.verdict == Verdict::Vehicle)
    }
}

#[derive(Debug, Error)]
pub enum SceneError {
    #[error("the scene has a `{VEHICLE}` attribute already (a completed scene?); completing it again would overwrite it")]
    AlreadyCompleted,
    #[error("--vehicle-class needs a `{CLASSIFICATION}` attribute (LAS), which the scene has not")]
    NoClassification,
    #[error("the scene spans {0:.0} × {1:.0} in its units, more than a tile of street (at most {MAX_SPAN} m a side): is it in metres, one tile, and free of stray far points?")]
    TooLarge(f64, f64),
}

/// The widest scene the ground filter takes, metres a side: MLS tiles are 50–500 m; at 0.5 m a
/// cell its grid then holds at most 16 million cells.
pub const MAX_SPAN: f64 = 2000.0;

/// A point as (horizontal position, height) relative to `origin`, for the up axis.
fn split(p: [f64; 3], origin: [f64; 3], up: UpAxis) -> ([f64; 2], f64) {
    let d = [0, 1, 2].map(|k| p[k] - origin[k]);
    match up {
        UpAxis::Z => ([d[0], d[1]], d[2]),
        UpAxis::Y => ([d[0], d[2]], d[1]),
    }
}

/// The inverse of [`split`].
fn join(horizontal: [f64; 2], height: f64, origin: [f64; 3], up: UpAxis) -> [f64; 3] {
    let local = match up {
        UpAxis::Z => [horizontal[0], horizontal[1], height],
        UpAxis::Y => [horizontal[0], height, horizontal[1]],
    };
    [0, 1, 2].map(|k| origin[k] + local[k])
}

/// Finds the objects of `cloud` that may be vehicles and tests each one's size.
pub fn find_objects(
    cloud: &PointCloud,
    up: UpAxis,
    selection: &Selection,
    params: &SceneParams,
) -> Result<Objects, SceneError> {
    find(cloud, up, selection, params, None)
}

/// [`find_objects`] in one chunk of a tile streamed a chunk at a time ([`stream`]), whose
/// first `core` points are the chunk's own and the rest its margin: only those count as ground,
/// and the chunk is never taken for one cut-out vehicle.
pub(crate) fn find_in_chunk(
    cloud: &PointCloud,
    up: UpAxis,
    selection: &Selection,
    params: &SceneParams,
    core: usize,
) -> Result<Objects, SceneError> {
    find(cloud, up, selection, params, Some(core))
}

fn find(
    cloud: &PointCloud,
    up: UpAxis,
    selection: &Selection,
    params: &SceneParams,
    core: Option<usize>,
) -> Result<Objects, SceneError> {
    let origin = cloud.positions.first().copied().unwrap_or_default();
    let split_all: Vec<([f64; 2], f64)> = cloud
        .positions
        .iter()
        .map(|&p| split(p, origin, up))
        .collect();
    // A cloud no larger than the largest vehicle is one cut out already: one object, no ground
    // (where the input's classes say which points are vehicles, they decide).
    let whole = match selection {
        Selection::Detect if core.is_none() => cut_out(&split_all, origin, up, params),
        _ => None,
    };
    if let Some(whole) = whole {
        return Ok(Objects {
            objects: vec![whole],
            ground_points: 0,
        });
    }
    // The candidates, the ground (None: each object's lowest point is its base) with the points
    // just above it that a vehicle may take back, and how many points are ground.
    let (candidates, ground, ground_points) = match selection {
        Selection::Classes(codes) => {
            let classes = cloud
                .attribute(CLASSIFICATION)
                .ok_or(SceneError::NoClassification)?;
            let picked: Vec<usize> = (0..cloud.len())
                .filter(|&i| codes.contains(&(classes.values[i] as u8)))
                .collect();
            (picked, None, 0)
        }
        Selection::Detect => {
            let [lo, hi] = ground::horizontal_bounds(&split_all);
            let span = [hi[0] - lo[0], hi[1] - lo[1]];
            if span[0] > MAX_SPAN || span[1] > MAX_SPAN {
                return Err(SceneError::TooLarge(span[0], span[1]));
            }
            let ground = Ground::fit(&split_all, &params.ground);
            let (mut picked, mut low) = (Vec::new(), Vec::new());
            let mut on_ground = 0;
            for (i, &(p, h)) in split_all.iter().enumerate() {
                let above = h - ground.height_at(p);
                if above <= params.ground.height {
                    on_ground += usize::from(core.is_none_or(|core| i < core));
                    if above >= params.lift {
                        low.push(i);
                    }
                } else if above <= params.max_height {
                    picked.push(i);
                }
            }
            (picked, Some((ground, low)), on_ground)
        }
    };
    let local: Vec<[f64; 3]> = candidates
        .iter()
        .map(|&i| {
            let (p, h) = split_all[i];
            [p[0], p[1], h]
        })
        .collect();
    let mut objects: Vec<Object> = cluster::clusters(&local, params.gap, params.min_points)
        .into_iter()
        .map(|members| {
            let indices: Vec<usize> = members.iter().map(|&k| candidates[k]).collect();
            let footprint = footprint(
                &indices,
                &split_all,
                ground.as_ref().map(|g| &g.0),
                origin,
                up,
            );
            let (_, base) = split(footprint.centre, origin, up);
            let cut = cut_off_share(&indices, &split_all, &footprint, base, params.max_height);
            let verdict = verdict(&footprint, cut, params);
            Object {
                indices,
                footprint,
                verdict,
            }
        })
        .collect();
    if let Some((_, low)) = &ground {
        give_back_lowest(&mut objects, &split_all, low, origin, up);
    }
    Ok(Objects {
        objects,
        ground_points,
    })
}

/// The whole cloud as one vehicle when its footprint fits the largest one's: a cut-out vehicle
/// given to `--scene` is completed as one (in metres or smaller units: the size test is not
/// made).
fn cut_out(
    split_all: &[([f64; 2], f64)],
    origin: [f64; 3],
    up: UpAxis,
    params: &SceneParams,
) -> Option<Object> {
    let all: Vec<usize> = (0..split_all.len()).collect();
    let whole = footprint(&all, split_all, None, origin, up);
    let sizes = &params.sizes;
    let fits = whole.length <= sizes.length[1]
        && whole.width <= sizes.width[1]
        && whole.height <= sizes.height[1];
    (fits && !all.is_empty()).then_some(Object {
        indices: all,
        footprint: whole,
        verdict: Verdict::Vehicle,
    })
}

/// Gives each vehicle the points the ground filter took from it: those of `low` (at least
/// [`SceneParams::lift`] above the ground) inside its footprint. Its points
/// then run down to its tyres' contact instead of stopping at the ground threshold.
fn give_back_lowest(
    objects: &mut [Object],
    split_all: &[([f64; 2], f64)],
    low: &[usize],
    origin: [f64; 3],
    up: UpAxis,
) {
    for object in objects.iter_mut().filter(|o| o.verdict == Verdict::Vehicle) {
        let f = object.footprint;
        let (centre, _) = split(f.centre, origin, up);
        let angle = f.axis_deg.to_radians();
        let (axis, across) = ([angle.cos(), angle.sin()], [-angle.sin(), angle.cos()]);
        let inside = |p: [f64; 2]| {
            let d = [p[0] - centre[0], p[1] - centre[1]];
            let along = (d[0] * axis[0] + d[1] * axis[1]).abs();
            let side = (d[0] * across[0] + d[1] * across[1]).abs();
            along <= f.length / 2.0 && side <= f.width / 2.0
        };
        object
            .indices
            .extend(low.iter().filter(|&&i| inside(split_all[i].0)));
        object.indices.sort_unstable();
    }
}

/// The box about the vertical that holds the points, its long axis the horizontal principal
/// axis of their positions.
fn footprint(
    indices: &[usize],
    split_all: &[([f64; 2], f64)],
    ground: Option<&Ground>,
    origin: [f64; 3],
    up: UpAxis,
) -> Footprint {
    let n = indices.len() as f64;
    let mean = indices.iter().fold([0.0; 2], |m, &i| {
        let p = split_all[i].0;
        [m[0] + p[0] / n, m[1] + p[1] / n]
    });
    let (mut sxx, mut sxy, mut syy) = (0.0, 0.0, 0.0);
    for &i in indices {
        let p = split_all[i].0;
        let (dx, dy) = (p[0] - mean[0], p[1] - mean[1]);
        sxx += dx * dx;
        sxy += dx * dy;
        syy += dy * dy;
    }
    let angle = 0.5 * (2.0 * sxy).atan2(sxx - syy);
    let (axis, across) = ([angle.cos(), angle.sin()], [-angle.sin(), angle.cos()]);
    let mut range = [[f64::INFINITY, f64::NEG_INFINITY]; 2];
    let (mut top, mut bottom) = (f64::NEG_INFINITY, f64::INFINITY);
    let mut grounds = Vec::new();
    for &i in indices {
        let (p, h) = split_all[i];
        for (k, dir) in [axis, across].iter().enumerate() {
            let t = p[0] * dir[0] + p[1] * dir[1];
            range[k] = [range[k][0].min(t), range[k][1].max(t)];
        }
        top = top.max(h);
        bottom = bottom.min(h);
        if let Some(g) = ground.map(|g| g.height_at(p)).filter(|g| g.is_finite()) {
            grounds.push(g);
        }
    }
    // The ground under the object: the median of the surface under its points (the object's
    // lowest point where the surface is unknown or the input's classes found the object).
    let base = if grounds.is_empty() {
        bottom
    } else {
        grounds.sort_by(f64::total_cmp);
        grounds[grounds.len() / 2].min(bottom)
    };
    let mid = [0, 1].map(|k| (range[k][0] + range[k][1]) / 2.0);
    let centre = [0, 1].map(|c| mid[0] * axis[c] + mid[1] * across[c]);
    Footprint {
        centre: join(centre, base, origin, up),
        length: range[0][1] - range[0][0],
        width: range[1][1] - range[1][0],
        height: top - base,
        // rem_euclid of a tiny negative angle rounds to 180 itself.
        axis_deg: Some(angle.to_degrees().rem_euclid(180.0)).map_or(0.0, |a| {
            if a < 180.0 {
                a
            } else {
                0.0
            }
        }),
    }
}

/// The size test. Two cases the plain ranges would get wrong: a van, truck or bus taller than
/// the scanner shows it its flank alone, a few decimetres across (mirrors, wheel arches), so a
/// long and tall object may be narrow, though not as flat as a wall's face; and an object reaching the height above which points join no object
/// along most of its length (`cut`, [`cut_off_share`]: a façade) is taller than any vehicle,
/// whatever its cut-off points say.
fn verdict(f: &Footprint, cut: f64, params: &SceneParams) -> Verdict {
    let sizes = &params.sizes;
    let flank =
        f.length >= sizes.flank[0] && f.height >= sizes.flank[1] && f.width >= sizes.flank_depth;
    let checks = [
        (cut > 0.5, Verdict::TooTall),
        (f.length < sizes.length[0], Verdict::TooShort),
        (f.length > sizes.length[1], Verdict::TooLong),
        (f.width < sizes.width[0] && !flank, Verdict::TooNarrow),
        (f.width > sizes.width[1], Verdict::TooWide),
        (f.height < sizes.height[0], Verdict::TooLow),
        (f.height > sizes.height[1], Verdict::TooTall),
    ];
    checks
        .into_iter()
        .find_map(|(fails, v)| fails.then_some(v))
        .unwrap_or(Verdict::Vehicle)
}

/// What became of one vehicle.
#[derive(Debug, Clone, Serialize)]
pub struct VehicleReport {
    /// The value of [`VEHICLE`] on its completed points.
    pub id: usize,
    pub guess: Guess,
    pub footprint: Footprint,
    pub points: usize,
    /// Completed points appended for it.
    pub added: usize,
    pub mirrored: usize,
    /// The heading the pipeline found, degrees, in the vehicle's own normalized frame.
    pub heading: Option<f64>,
    /// The symmetry plane in the scene's coordinates (none: no plane), with whether its cues
    /// agreed.
    pub plane: Option<PlaneReport>,
    pub warnings: Vec<String>,
    /// Why it was left as scanned, when its completion failed.
    pub failed: Option<String>,
}

/// The completed scene and what became of each vehicle.
#[derive(Debug, Clone)]
pub struct SceneCompletion {
    /// The scene's points as they were, in their order, then the completed points, with the
    /// [`SYNTHETIC`] and [`VEHICLE`] attributes.
    pub cloud: PointCloud,
    pub vehicles: Vec<VehicleReport>,
}

/// Completes each vehicle of `objects` in `cloud` with `completer` (`settings` as for one
/// cut-out vehicle, each given the `narrowest` width of its guess as the least it can be)
/// and appends what each one gains. A vehicle whose completion fails is left as scanned and
/// reported so; the scene is never lost for it.
pub fn complete_scene(
    cloud: &PointCloud,
    objects: &Objects,
    completer: &Completer,
    settings: &Settings,
    narrowest: &Narrowest,
) -> Result<SceneCompletion, SceneError> {
    if cloud.attribute(VEHICLE).is_some() {
        return Err(SceneError::AlreadyCompleted);
    }
    let vehicles: Vec<&Object> = objects.vehicles().collect();
    if vehicles.is_empty() {
        // Unchanged to the attribute: no flag or vehicle number is added to a scene without one.
        return Ok(SceneCompletion {
            cloud: cloud.clone(),
            vehicles: Vec::new(),
        });
    }
    let mut out = cloud.clone();
    if out.attribute(SYNTHETIC).is_none() {
        out.attributes
            .push(zeros(SYNTHETIC, ScalarKind::U8, cloud.len()));
    }
    out.attributes
        .push(zeros(VEHICLE, ScalarKind::U16, cloud.len()));
    let mut reports = Vec::new();
    for (k, (mut report, added)) in
        complete_vehicles(cloud, &vehicles, completer, settings, narrowest)
            .into_iter()
            .enumerate()
    {
        report.id = k + 1;
        if let Some(added) = added {
            append(&mut out, &added, report.id);
        }
        reports.push(report);
    }
    Ok(SceneCompletion {
        cloud: out,
        vehicles: reports,
    })
}

/// Completes each of `vehicles` (objects of `cloud`) in parallel: what became of it (its `id`
/// left 0 for the caller to number) and the points its completion added, none where it failed.
pub(crate) fn complete_vehicles(
    cloud: &PointCloud,
    vehicles: &[&Object],
    completer: &Completer,
    settings: &Settings,
    narrowest: &Narrowest,
) -> Vec<(VehicleReport, Option<PointCloud>)> {
    vehicles
        .par_iter()
        .map(|vehicle| {
            let mut settings = settings.clone();
            settings.options.min_vehicle_width = narrowest.of(vehicle.guess());
            let run = completer.run(&cloud.select(&vehicle.indices), &settings);
            let mut report = VehicleReport {
                id: 0,
                guess: vehicle.guess(),
                footprint: vehicle.footprint,
                points: vehicle.indices.len(),
                added: 0,
                mirrored: 0,
                heading: None,
                plane: None,
                warnings: Vec::new(),
                failed: None,
            };
            let added = match run {
                Ok(run) => {
                    let done = run.completion;
                    // The completion holds the vehicle's own points, then the ones it added (a
                    // scene point may carry the synthetic flag already, so the flag cannot tell).
                    let n = done.cloud.len();
                    let added_points: Vec<usize> = (n - done.added..n).collect();
                    let added = done.cloud.select(&added_points);
                    report.added = added.len();
                    report.mirrored = done.mirrored;
                    report.heading = run.orientation.heading;
                    report.plane = done.plane.map(|p| p.report(&done.frame));
                    report.warnings = done.warnings;
                    Some(added)
                }
                Err(e) => {
                    report.failed = Some(e.to_string());
                    None
                }
            };
            (report, added)
        })
        .collect()
}

fn zeros(name: &str, kind: ScalarKind, n: usize) -> Attribute {
    Attribute {
        name: name.to_string(),
        kind,
        values: vec![0.0; n],
    }
}

/// Appends `added` (one vehicle's completed points) to `scene`: each of the scene's attributes
/// takes the added points' values of the same name, zero where they have none, so that the
/// scene keeps every attribute it had.
fn append(scene: &mut PointCloud, added: &PointCloud, id: usize) {
    let n = added.len();
    scene.positions.extend(&added.positions);
    if let Some(colors) = &mut scene.colors {
        match &added.colors {
            Some(more) => colors.extend(more),
            None => colors.extend(std::iter::repeat_n([128, 128, 128], n)),
        }
    }
    for a in &mut scene.attributes {
        match (a.name.as_str(), added.attribute(&a.name)) {
            (VEHICLE, _) => a.values.extend(std::iter::repeat_n(id as f64, n)),
            (SYNTHETIC, _) => a.values.extend(std::iter::repeat_n(1.0, n)),
            (_, Some(values)) => a.values.extend(&values.values),
            (_, None) => a.values.extend(std::iter::repeat_n(0.0, n)),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A flat street with a box-shaped car (4.5 × 1.8 × 1.5 m, its flank and roof scanned), a
    /// pole, a low wall and a long façade: the car alone passes the size test.
    fn street() -> PointCloud {
        let mut points = Vec::new();
        for i in 0..400 {
            for j in 0..100 {
                points.push([i as f64 * 0.1, j as f64 * 0.1, 0.0]);
            }
        }
        let car = |x: f64, y: f64| {
            let mut p = Vec::new();
            for i in 0..45 {
                for k in 0..13 {
                    p.push([x + i as f64 * 0.1, y, 0.2 + k as f64 * 0.1]);
                }
                for j in 0..18 {
                    p.push([x + i as f64 * 0.1, y + j as f64 * 0.1, 1.5]);
                }
            }
            p
        };
        points.extend(car(5.0, 3.0));
        for k in 0..60 {
            for (dx, dy) in [
                (0.0, 0.0),
                (0.05, 0.0),
                (0.0, 0.05),
                (0.05, 0.05),
                (0.1, 0.1),
            ] {
                points.push([20.0 + dx, 3.0 + dy, 0.1 * k as f64]);
            }
        }
        for i in 0..60 {
            for k in 0..4 {
                points.push([24.0 + i as f64 * 0.1, 5.0, 0.3 + k as f64 * 0.1]);
            }
        }
        for i in 0..300 {
            for k in 0..40 {
                points.push([5.0 + i as f64 * 0.1, 9.9, 0.3 + k as f64 * 0.1]);
            }
        }
        // In UTM, as MLS tiles are.
        let offset = [652_000.0, 5_280_000.0, 120.0];
        PointCloud::from_positions(
            points
                .into_iter()
                .map(|p| [0, 1, 2].map(|k| p[k] + offset[k]))
                .collect(),
        )
    }

    #[test]
    fn on_a_street_the_car_alone_is_a_vehicle() {
        let found = find_objects(
            &street(),
            UpAxis::Z,
            &Selection::Detect,
            &SceneParams::default(),
        )
        .unwrap();
        let vehicles: Vec<&Object> = found.vehicles().collect();
        assert_eq!(
            vehicles.len(),
            1,
            "{:?}",
            found
                .objects
                .iter()
                .map(|o| (o.verdict, o.footprint))
                .collect::<Vec<_>>()
        );
        let car = vehicles[0].footprint;
        assert!((car.length - 4.4).abs() < 0.15, "{car:?}");
        assert!((car.width - 1.7).abs() < 0.15, "{car:?}");
        assert!((car.height - 1.5).abs() < 0.15, "{car:?}");
        assert!(car.axis_deg < 2.0 || car.axis_deg > 178.0, "{car:?}");
        assert_eq!(vehicles[0].guess(), Guess::Car);
        let verdicts: Vec<Verdict> = found.objects.iter().map(|o| o.verdict).collect();
        // The façade, the wall (0.6 m high, too narrow before too low) and the pole (6 m: it
        // reaches the height above which points join no object).
        assert_eq!(
            verdicts,
            [
                Verdict::TooLong,
                Verdict::Vehicle,
                Verdict::TooNarrow,
                Verdict::TooTall
            ]
        );
        assert!(found.ground_points >= 40_000);
    }

    #[test]
    fn classes_select_the_vehicles_when_the_input_has_them() {
        let mut cloud = street();
        let classes: Vec<f64> = (0..cloud.len())
            .map(|i| {
                if (40_000..40_000 + 45 * 31).contains(&i) {
                    10.0
                } else {
                    2.0
                }
            })
            .collect();
        cloud.attributes.push(Attribute {
            name: CLASSIFICATION.into(),
            kind: ScalarKind::U8,
            values: classes,
        });
        let params = SceneParams::default();
        let found =
            find_objects(&cloud, UpAxis::Z, &Selection::Classes(vec![10]), &params).unwrap();
        assert_eq!(found.vehicles().count(), 1);
        assert_eq!(found.objects[0].indices.len(), 45 * 31);
        let none = find_objects(&cloud, UpAxis::Z, &Selection::Classes(vec![64]), &params).unwrap();
        assert_eq!(none.objects.len(), 0);
        let unlabelled = find_objects(&street(), UpAxis::Z, &Selection::Classes(vec![10]), &params);
        assert!(matches!(unlabelled, Err(SceneError::NoClassification)));
    }

    /// A vehicle whose completion fails (here: no model for the network) is listed with why,
    /// and the scene comes back whole.
    #[test]
    fn a_vehicle_that_fails_is_left_as_scanned_and_the_scene_kept() {
        let cloud = street();
        let params = SceneParams::default();
        let found = find_objects(&cloud, UpAxis::Z, &Selection::Detect, &params).unwrap();
        let settings = Settings {
            clean: false,
            orient: crate::complete::orient::OrientMode::None,
            options: crate::complete::Options {
                up: UpAxis::Z,
                ..Default::default()
            },
        };
        let done = complete_scene(
            &cloud,
            &found,
            &Completer::new(None, None),
            &settings,
            &Narrowest::default(),
        )
        .unwrap();
        assert_eq!(done.vehicles.len(), 1);
        let failed = done.vehicles[0].failed.as_deref().unwrap();
        assert!(failed.contains("model"), "{failed}");
        assert_eq!(done.cloud.positions, cloud.positions);
    }

    /// A generated street (a seed no choice was made on): its vehicles found, few other
    /// objects taken for one. Guards the detection the lab harness measures
    /// (`examples/scene_detection.rs`).
    #[test]
    fn the_vehicles_of_a_generated_street_are_found() {
        use crate::datagen::synth::street::{street, Kind, StreetParams};
        let params = StreetParams {
            length: 40.0,
            ..StreetParams::default()
        };
        let scene = street(31, &params);
        let labels = scene.labels();
        let found = find_objects(
            &scene.cloud,
            UpAxis::Z,
            &Selection::Detect,
            &SceneParams::default(),
        )
        .unwrap();
        let is_vehicle = |l: u32| scene.objects[l as usize].kind == Kind::Vehicle;
        let score = score::detection(&found, &labels, is_vehicle, 200);
        assert!(score.vehicles >= 6, "{score:?}");
        assert!(score.found * 10 >= score.vehicles * 9, "{score:?}");
        assert!(score.false_vehicles <= 1 && score.merged == 0, "{score:?}");
    }

    /// A bus taller than the scanner shows its flank alone, a few decimetres across; a piece of
    /// façade seen between parked vehicles is as long and tall but flat: it was taken for a
    /// vehicle and given a completion.
    #[test]
    fn a_flank_is_a_vehicle_and_a_flat_wall_of_its_size_is_not() {
        let params = SceneParams::default();
        let object = |length, width, height| Footprint {
            centre: [0.0; 3],
            length,
            width,
            height,
            axis_deg: 0.0,
        };
        assert_eq!(
            verdict(&object(12.1, 0.45, 3.2), 0.0, &params),
            Verdict::Vehicle
        );
        assert_eq!(
            verdict(&object(7.0, 0.30, 3.8), 0.0, &params),
            Verdict::Vehicle
        );
        assert_eq!(
            verdict(&object(10.9, 0.06, 4.4), 0.0, &params),
            Verdict::TooNarrow
        );
    }

    /// Two points 10 km apart would ask the ground grid for 4·10⁸ cells: refused in words.
    #[test]
    fn a_scene_wider_than_a_tile_is_refused() {
        let mut cloud = street();
        cloud.positions.push([
            cloud.positions[0][0] + 10_000.0,
            cloud.positions[0][1],
            120.0,
        ]);
        let found = find_objects(
            &cloud,
            UpAxis::Z,
            &Selection::Detect,
            &SceneParams::default(),
        );
        let error = found.err().unwrap().to_string();
        assert!(error.contains("spans 10000 × 10"), "{error}");
    }

    #[test]
    fn appended_points_keep_every_attribute_of_the_scene() {
        let mut scene = PointCloud::from_positions(vec![[0.0; 3]; 3]);
        scene.attributes.push(Attribute {
            name: "intensity".into(),
            kind: ScalarKind::U16,
            values: vec![7.0; 3],
        });
        scene.attributes.push(zeros(SYNTHETIC, ScalarKind::U8, 3));
        scene.attributes.push(zeros(VEHICLE, ScalarKind::U16, 3));
        let added = PointCloud::from_positions(vec![[1.0; 3]; 2]);
        append(&mut scene, &added, 4);
        assert_eq!(scene.len(), 5);
        assert!(scene.is_consistent());
        assert_eq!(
            scene.attribute("intensity").unwrap().values,
            [7.0, 7.0, 7.0, 0.0, 0.0]
        );
        assert_eq!(
            scene.attribute(SYNTHETIC).unwrap().values,
            [0.0, 0.0, 0.0, 1.0, 1.0]
        );
        assert_eq!(
            scene.attribute(VEHICLE).unwrap().values,
            [0.0, 0.0, 0.0, 4.0, 4.0]
        );
    }
}
