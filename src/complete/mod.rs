//! The completion pipeline: a partial cloud in, the completed cloud in the same coordinates out.
//!
//! read → frame → project → inpaint → re-project (eroded) → outlier filter → the network's box →
//! merge with the measured points → back to the input's frame. The measured points are kept
//! exactly; completed points are added only where no measured point lies within
//! `merge_distance` (in the network's box, so the same for every view size), and within
//! `near_distance` only where the network is sure of them; they carry a `synthetic` flag so a
//! user can tell them apart.
//!
//! Two baselines run through the same code: `identity` (the partial as it is) and `mirror` (the
//! partial united with its mirror image across the vehicle's long vertical plane).

pub mod clean;
pub mod filter;
mod network;
pub mod orient;
pub mod preview;
pub mod symmetry;
pub mod thin;
pub mod upright;

use crate::complete::clean::{clean, CleanParams, CleanReport};
use crate::complete::filter::SorParams;
use crate::complete::network::{run_network, NetworkOutput};
use crate::complete::orient::{orient, OrientMode, OrientParams, Orientation, Orienter};
use crate::complete::symmetry::{find_plane, find_roll, mirror, Plane, SymmetryParams, Width};
use crate::core::camera::CameraError;
use crate::core::cloud::{Aabb, Attribute, PointCloud, ScalarKind};
use crate::core::frame::{Frame, FrameError, UpAxis};
use crate::core::knn::{KnnIndex, MatchGrid};
use crate::io::{read_bytes, Problem};
use crate::model::inpaint::{InpaintError, Inpainter};
use crate::model::weights::{generator_in, read_config, Network, NoGenerator, WeightsError};
use crate::model::{ConfigError, ModelConfig, Preset};
use crate::views::projection::ViewImages;
use crate::views::reprojection::ReprojectOptions;
use burn::tensor::Device;
use nalgebra::{Matrix3, SymmetricEigen};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};
use thiserror::Error;

/// Fewer measured points than this are refused: there is nothing to complete from.
pub const MIN_POINTS: usize = 50;
/// Below this many points the result is unreliable and a warning says so.
const SPARSE_POINTS: usize = 500;
/// The built-in generator (see README, *The default model*, for how it was trained).
///
/// A `static`, not a `const`: a constant's bytes are copied into every place that names it, and
/// the binary carried this 15 MB file three times (71 MB instead of 41 MB).
pub static DEFAULT_MODEL: &[u8] = include_bytes!("../../assets/model.safetensors");

/// The built-in generator's shape, for a network trained or timed afresh: its config without
/// the occupancy threshold, which was chosen for its weights.
pub fn builtin_shape() -> Result<ModelConfig, WeightsError> {
    let config = read_config(DEFAULT_MODEL, Network::Generator)?;
    Ok(ModelConfig {
        occupancy: None,
        ..config
    })
}

pub use crate::core::cloud::SYNTHETIC;

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum Method {
    /// The inpainting network.
    Network,
    /// The partial unchanged (a baseline).
    Identity,
    /// The partial and its mirror image across the vehicle's long vertical plane (a baseline).
    Mirror,
}

/// The vehicle's lean across its width, about its length axis (see [`find_roll`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Roll {
    /// Found from the cloud's symmetry.
    Auto,
    /// Given, in degrees; 0 takes the vehicle as upright as the input's up axis.
    Given(f64),
}

/// Most a given roll may be, degrees: beyond it the input's up axis is wrong, not the road.
pub const MAX_GIVEN_ROLL: f64 = 45.0;

impl std::str::FromStr for Roll {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match (s, s.parse::<f64>()) {
            ("auto", _) => Ok(Roll::Auto),
            (_, Ok(deg)) if deg.abs() <= MAX_GIVEN_ROLL => Ok(Roll::Given(deg)),
            _ => Err(format!(
                "`{s}` is not auto or a roll in degrees within ±{MAX_GIVEN_ROLL}"
            )),
        }
    }
}

#[derive(Debug, Clone, PartialEq)]
pub struct Options {
    pub method: Method,
    pub up: UpAxis,
    /// Which way the input's front faces (see [`crate::core::frame`]); `None` keeps the input's
    /// axes, turning only its longer horizontal side onto the length.
    pub heading: Option<f64>,
    /// How far the vehicle leans across its width; upright as read unless asked, since on upright
    /// vehicles a roll found costs a little (docs/pipeline.md, *3. Heading, roll and the network's
    /// pose*).
    pub roll: Roll,
    /// Rig cameras the model's views come from.
    pub views: Vec<usize>,
    /// Erosion element side for the inpainted views.
    pub erode: usize,
    /// Median window side over the inpainted views' XYZ.
    pub smooth: usize,
    /// Re-projected points closer than this (in the network's unit box) to an earlier one are
    /// dropped; 0 keeps every pixel's point, as the paper re-projects them all.
    pub dedup: f64,
    /// Move each inpainted pixel's XYZ onto its pixel's ray (see
    /// [`snap_to_rays`](crate::views::reprojection::snap_to_rays)).
    pub snap: bool,
    pub sor: SorParams,
    /// Keep the measured points and add completed points where they are missing; otherwise
    /// the output is the network's re-projected cloud alone (the paper's output).
    pub keep_input: bool,
    /// A completed point within this distance of a measured or mirrored point is not added, in
    /// the network's unit box: a distance, not pixels, so that models of every view size fill
    /// the same gaps.
    pub merge_distance: f64,
    /// A completed point nearer than this to a measured or mirrored point (and beyond
    /// `merge_distance`) is added only where the network is sure of it, its occupancy above
    /// `near_occupancy`: next to what was measured a wrong point costs precision and fills
    /// little (docs/pipeline.md, *7. Merge*). In the network's unit box; at or
    /// below `merge_distance` every completed point passes the model's threshold alone.
    pub near_distance: f64,
    /// The occupancy (a probability) a completed point within `near_distance` needs.
    pub near_occupancy: f64,
    /// The network's points further than this above or below the measured points, or beyond
    /// the width they and their mirror images span, are dropped (in the network's unit box;
    /// infinite keeps them all).
    pub box_margin: f64,
    /// The network's added points are thinned to one per cube of this side (in the network's
    /// unit box; 0 keeps them all), so that every view size adds them at the same density.
    pub thin: f64,
    /// Also add the measured points' mirror images (network method; the mirror method always
    /// does).
    pub symmetry: bool,
    /// Also let the network complete the measured points' mirror image and keep what it makes
    /// of it, mirrored back, beside its first output (needs a plane; docs/pipeline.md,
    /// *6. The network*).
    pub mirror_pass: bool,
    /// Fit the network's box to the measured points and their mirror images, centred on the
    /// symmetry plane as the training objects are; otherwise the measured points' own box.
    pub symmetric_frame: bool,
    /// Return the network's input and output views in the [`Completion`].
    pub keep_views: bool,
    /// The vehicle's width in the input's units, when the user knows it: the plane of a scan
    /// of one side is then kept at least half of it from the scanned flank (see [`find_plane`]).
    pub vehicle_width: Option<f64>,
    /// The narrowest the vehicle can be, in the input's units (`complete --scene` knows it from
    /// the vehicle's size in metres): the plane of a scan of one side is kept at least half of
    /// it from the scanned flank, whatever the plane found. `vehicle_width` overrides it.
    pub min_vehicle_width: Option<f64>,
    /// The heuristics' tunables.
    pub tuning: Tuning,
}

impl Options {
    /// The paper's pipeline and nothing else: the measured points' own box, projection,
    /// inpainting, 3×3 erosion, re-projection of every pixel, SOR (k 20, σ 5), back to the
    /// input's frame; no mirror images, no snapping, no merging of near-duplicate points, the
    /// measured points not kept.
    pub fn paper(up: UpAxis, heading: Option<f64>) -> Options {
        Options {
            up,
            heading,
            roll: Roll::Given(0.0),
            dedup: 0.0,
            snap: false,
            keep_input: false,
            symmetry: false,
            mirror_pass: false,
            symmetric_frame: false,
            box_margin: f64::INFINITY,
            ..Options::default()
        }
    }
}

/// What `mvpcc complete IN OUT` does for a y-up input without options.
impl Default for Options {
    fn default() -> Self {
        Options {
            method: Method::Network,
            up: UpAxis::Y,
            heading: None,
            roll: Roll::Given(0.0),
            views: crate::core::camera::DEFAULT_VIEWS.to_vec(),
            erode: 3,
            smooth: 0,
            dedup: ReprojectOptions::default().dedup_tolerance,
            snap: true,
            sor: SorParams::default(),
            keep_input: true,
            merge_distance: 0.05,
            near_distance: 0.12,
            near_occupancy: 0.5,
            box_margin: 0.025,
            thin: 0.025,
            symmetry: true,
            mirror_pass: true,
            symmetric_frame: true,
            keep_views: false,
            vehicle_width: None,
            min_vehicle_width: None,
            tuning: Tuning::default(),
        }
    }
}

/// The tunables of the pipeline's heuristics, stage by stage, today's values as their
/// defaults. A JSON file may give any of them (`complete --tuning FILE`); the lab harness
/// sweeps them over the validation sets.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Tuning {
    pub clean: CleanParams,
    pub orient: OrientParams,
    pub symmetry: SymmetryParams,
}

/// Why a tuning file could not be used.
#[derive(Debug, Error)]
pub enum TuningError {
    #[error("{}: {source}", path.display())]
    Read {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{}: not a tuning file: {source}", path.display())]
    Parse {
        path: PathBuf,
        source: serde_json::Error,
    },
}

impl Tuning {
    /// The tunables a JSON file gives, today's values for the rest; an unknown name is refused.
    pub fn read(path: &Path) -> Result<Tuning, TuningError> {
        let text = std::fs::read_to_string(path).map_err(|source| TuningError::Read {
            path: path.to_path_buf(),
            source,
        })?;
        serde_json::from_str(&text).map_err(|source| TuningError::Parse {
            path: path.to_path_buf(),
            source,
        })
    }
}

#[derive(Debug, Error)]
pub enum CompleteError {
    #[error("too few points to complete: {0}, at least {MIN_POINTS} needed")]
    TooFewPoints(usize),
    #[error(transparent)]
    Frame(#[from] FrameError),
    #[error(transparent)]
    Inpaint(#[from] InpaintError),
    #[error(transparent)]
    Camera(#[from] CameraError),
    #[error("the model takes {model} views, --views names {given}")]
    Views { model: usize, given: usize },
    #[error("the network method needs a model")]
    NoModel,
}

/// Where one of a [`Completer`]'s networks comes from.
#[derive(Debug, Clone, Copy)]
pub enum Source<'a> {
    /// None: the settings never run it.
    Unused,
    /// The one built into the binary.
    Builtin,
    /// A weights file; for the generator also a run directory or `assets/` holding one.
    File(&'a Path),
}

/// Why a network could not be loaded.
#[derive(Debug, Error)]
pub enum LoadError {
    #[error("{}: {source}", path.display())]
    Read { path: PathBuf, source: Problem },
    #[error(transparent)]
    NoGenerator(#[from] NoGenerator),
    #[error("{}: {source}", path.display())]
    Weights { path: PathBuf, source: WeightsError },
    #[error("the built-in {what}: {source}")]
    Builtin {
        what: &'static str,
        source: WeightsError,
    },
    #[error(transparent)]
    Occupancy(#[from] ConfigError),
}

fn read_weights(path: &Path) -> Result<Vec<u8>, LoadError> {
    read_bytes(path).map_err(|source| LoadError::Read {
        path: path.to_path_buf(),
        source,
    })
}

/// The name of the built-in model's shape where a model shape is named (`--config`).
pub const BUILTIN_SHAPE: &str = "builtin";

/// Why a named model shape could not be had.
#[derive(Debug, Error)]
pub enum ShapeError {
    #[error("the built-in model: {0}")]
    Builtin(#[source] WeightsError),
    #[error("--config {name}: neither {BUILTIN_SHAPE}, a preset (cpu, paper, original, small, tiny) nor a readable file: {source}")]
    Unreadable {
        name: String,
        source: std::io::Error,
    },
    #[error("{}: not a model config: {source}", path.display())]
    NotAConfig {
        path: PathBuf,
        source: serde_json::Error,
    },
}

/// The model shape `name` names: [`BUILTIN_SHAPE`], a preset (`cpu`, `paper`, `original`, `small`, `tiny`)
/// or a JSON file holding a model config (as a run's config.json).
pub fn named_shape(name: &str) -> Result<ModelConfig, ShapeError> {
    if name.eq_ignore_ascii_case(BUILTIN_SHAPE) {
        return builtin_shape().map_err(ShapeError::Builtin);
    }
    if let Ok(preset) = <Preset as clap::ValueEnum>::from_str(name, true) {
        return Ok(preset.config());
    }
    let path = Path::new(name);
    let text = std::fs::read_to_string(path).map_err(|source| ShapeError::Unreadable {
        name: name.to_string(),
        source,
    })?;
    serde_json::from_str(&text).map_err(|source| ShapeError::NotAConfig {
        path: path.to_path_buf(),
        source,
    })
}

/// Wall time of each stage (the paper's Table 4 rows, and ours). Reading and writing are
/// measured by whoever does them (the command); the rest by [`Completer::run`] and [`complete`].
#[derive(Debug, Clone, Copy, Default)]
pub struct Timings {
    pub read: Duration,
    pub clean: Duration,
    pub orientation: Duration,
    /// Frame, symmetry plane and mirror images.
    pub symmetry: Duration,
    pub projection: Duration,
    pub encoder: Duration,
    pub fusion: Duration,
    pub decoder: Duration,
    pub reprojection: Duration,
    pub filter: Duration,
    /// How long the mirrored pass ([`Options::mirror_pass`]), run beside the first, went on
    /// after it: its cost on the clock (the other stages are the first pass's).
    pub mirror_pass: Duration,
    pub write: Duration,
}

impl Timings {
    /// Every stage with its name, in pipeline order (what `--timings` prints).
    pub fn stages(&self) -> [(&'static str, Duration); 13] {
        [
            ("read", self.read),
            ("clean", self.clean),
            ("orientation", self.orientation),
            ("symmetry", self.symmetry),
            ("projection", self.projection),
            ("encoder", self.encoder),
            ("fusion", self.fusion),
            ("decoder", self.decoder),
            ("re-projection", self.reprojection),
            ("filter", self.filter),
            ("mirror pass", self.mirror_pass),
            ("write", self.write),
            ("total", self.total()),
        ]
    }

    pub fn total(&self) -> Duration {
        self.read
            + self.clean
            + self.orientation
            + self.symmetry
            + self.projection
            + self.encoder
            + self.fusion
            + self.decoder
            + self.reprojection
            + self.filter
            + self.mirror_pass
            + self.write
    }
}

/// What a [`Completer`] does around [`complete`]: whether it cleans the input first and how it
/// finds the heading (which it then puts in `options.heading`).
#[derive(Debug, Clone, PartialEq)]
pub struct Settings {
    pub clean: bool,
    pub orient: OrientMode,
    pub options: Options,
}

/// A whole completion run.
#[derive(Debug, Clone)]
pub struct Run {
    /// The cleaned input and what cleaning removed, when it ran.
    pub cleaned: Option<(PointCloud, CleanReport)>,
    pub orientation: Orientation,
    pub completion: Completion,
}

/// The completion pipeline with its networks loaded once, for any number of clouds:
/// clean → orient → frame → symmetry and mirror images → network → merge.
///
/// ```
/// use burn::tensor::Device;
/// use mvpcc::complete::{Completer, Options, Settings};
/// use mvpcc::complete::orient::OrientMode;
/// use mvpcc::io::read_cloud;
///
/// let scan = read_cloud("assets/example/car_partial.ply".as_ref(), None)?.cloud;
/// let completer = Completer::builtin(Device::flex())?;
/// let settings = Settings {
///     clean: false,
///     orient: OrientMode::Auto,
///     options: Options::default(),
/// };
/// let run = completer.run(&scan, &settings)?;
/// // Every measured point is kept, and completed ones are added after them.
/// assert_eq!(run.completion.input_points, scan.len());
/// assert!(run.completion.cloud.len() > scan.len());
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub struct Completer {
    inpainter: Option<Inpainter>,
    orienter: Option<Orienter>,
}

impl Completer {
    /// `inpainter` is needed by the network method, `orienter` by the orientation modes that
    /// run the orientation network.
    pub fn new(inpainter: Option<Inpainter>, orienter: Option<Orienter>) -> Completer {
        Completer {
            inpainter,
            orienter,
        }
    }

    /// The networks `generator` and `orienter` name, the generator on `device` (with its
    /// occupancy threshold replaced by `occupancy`, when given); the orientation network is
    /// small and runs on the CPU.
    pub fn load(
        generator: Source,
        orienter: Source,
        device: Device,
        occupancy: Option<f64>,
    ) -> Result<Completer, LoadError> {
        let inpainter = match generator {
            Source::Unused => None,
            Source::Builtin => Some(Inpainter::from_bytes(DEFAULT_MODEL, device).map_err(
                |source| LoadError::Builtin {
                    what: "model",
                    source,
                },
            )?),
            Source::File(path) => {
                let file = if path.is_dir() {
                    generator_in(path)?
                } else {
                    path.to_path_buf()
                };
                let bytes = read_weights(&file)?;
                let inpainter = Inpainter::from_bytes(&bytes, device)
                    .map_err(|source| LoadError::Weights { path: file, source })?;
                Some(inpainter)
            }
        };
        let inpainter = match (inpainter, occupancy) {
            (Some(i), Some(p)) => Some(i.with_occupancy(p)?),
            (i, _) => i,
        };
        let orienter = match orienter {
            Source::Unused => None,
            Source::Builtin => Some(Orienter::builtin().map_err(|source| LoadError::Builtin {
                what: "orientation network",
                source,
            })?),
            Source::File(path) => {
                let bytes = read_weights(path)?;
                let orienter = Orienter::from_bytes(&bytes, Device::flex());
                Some(orienter.map_err(|source| LoadError::Weights {
                    path: path.to_path_buf(),
                    source,
                })?)
            }
        };
        Ok(Completer::new(inpainter, orienter))
    }

    /// The built-in generator on `device` and the built-in orientation network.
    pub fn builtin(device: Device) -> Result<Completer, WeightsError> {
        Ok(Completer::new(
            Some(Inpainter::from_bytes(DEFAULT_MODEL, device)?),
            Some(Orienter::builtin()?),
        ))
    }

    pub fn inpainter(&self) -> Option<&Inpainter> {
        self.inpainter.as_ref()
    }

    pub fn orienter(&self) -> Option<&Orienter> {
        self.orienter.as_ref()
    }

    /// Completes `cloud` as `settings` say.
    pub fn run(&self, cloud: &PointCloud, settings: &Settings) -> Result<Run, CompleteError> {
        let up = settings.options.up;
        let start = Instant::now();
        let tuning = &settings.options.tuning;
        let cleaned = settings.clean.then(|| clean(cloud, up, &tuning.clean));
        let clean_time = start.elapsed();
        let input = cleaned.as_ref().map_or(cloud, |(c, _)| c);
        let start = Instant::now();
        let orienter = self.orienter.as_ref();
        let orientation = orient(
            input,
            up,
            settings.orient,
            orienter,
            &tuning.orient,
            &tuning.symmetry,
        );
        let orient_time = start.elapsed();
        let options = Options {
            heading: orientation.heading,
            ..settings.options.clone()
        };
        let mut completion = complete(input, self.inpainter.as_ref(), &options)?;
        completion.timings.clean = clean_time;
        completion.timings.orientation = orient_time;
        Ok(Run {
            cleaned,
            orientation,
            completion,
        })
    }
}

/// A completed cloud and what happened on the way.
#[derive(Debug, Clone)]
pub struct Completion {
    /// In the input's coordinates: the measured points first (unless `keep_input` was off),
    /// then the added ones, with the [`SYNTHETIC`] attribute.
    pub cloud: PointCloud,
    /// The same points in the network's unit box (for previews).
    pub normalized: Vec<[f64; 3]>,
    /// The measured points in the network's unit box.
    pub input_normalized: Vec<[f64; 3]>,
    pub frame: Frame,
    pub input_points: usize,
    /// Completed points in the output, of which `mirrored` are mirror images.
    pub added: usize,
    pub mirrored: usize,
    /// Re-projected network points removed by the outlier filter.
    pub filtered_out: usize,
    /// How many objects the network completed: 0 without it, 2 with [`Options::mirror_pass`]
    /// and a plane.
    pub network_passes: usize,
    pub plane: Option<Plane>,
    /// The vehicle's lean across its width that the frame takes out, degrees ([`Options::roll`]).
    pub roll: f64,
    /// Why the input looks unlike what the model was trained on.
    pub warnings: Vec<String>,
    pub timings: Timings,
    /// The views the network read and wrote, when [`Options::keep_views`] asked for them.
    pub views: Option<NetworkViews>,
}

/// The network's views of one object, in the dataset's format once written.
#[derive(Debug, Clone)]
pub struct NetworkViews {
    /// The measured points projected into the model's cameras.
    pub input: ViewImages,
    /// What the generator made of them, before snapping.
    pub output: ViewImages,
}

/// Completes `input`. `inpainter` is needed by the network method only.
pub fn complete(
    input: &PointCloud,
    inpainter: Option<&Inpainter>,
    options: &Options,
) -> Result<Completion, CompleteError> {
    if input.len() < MIN_POINTS {
        return Err(CompleteError::TooFewPoints(input.len()));
    }
    let symmetry_start = Instant::now();
    let Framed {
        frame,
        roll,
        measured,
        plane,
    } = framed(input, options)?;
    let mut warnings = distribution_warnings(&measured);
    warnings.extend(
        plane
            .filter(|p| !p.vouched)
            .map(|p| unvouched_warning(&p, options)),
    );
    // The network fills the far side itself rather than mirror a plane the cues disagree on.
    let plane_for_network = plane.filter(|p| p.vouched || options.method != Method::Network);
    warnings.extend(
        options
            .vehicle_width
            .and_then(|width| width_warning(width, frame.extent)),
    );
    let mut timings = Timings::default();

    // Mirror images first: they come from measured points, so they are trusted over the network.
    let measured_index = KnnIndex::new(&measured);
    let seen_width = plane
        .filter(|p| p.both_sides)
        .map(|_| across_seen(&measured));
    let mut added = mirror_plane(plane_for_network, options, &mut warnings)
        .map_or_else(Vec::new, |plane| mirror_images(&measured, plane));
    within_seen_width(&mut added, seen_width);
    timings.symmetry = symmetry_start.elapsed();

    let keep_input = options.keep_input || options.method != Method::Network;
    let mirrored = if keep_input { added.len() } else { 0 };
    let mut filtered_out = 0;
    let mut network_passes = 0;
    let mut views = None;
    if options.method == Method::Network {
        let inpainter = inpainter.ok_or(CompleteError::NoModel)?;
        let mut network = run_network(
            input,
            &measured,
            plane_for_network,
            inpainter,
            options,
            &mut timings,
        )?;
        filtered_out = network.filtered_out;
        network_passes = network.passes;
        if options.mirror_pass && network_passes < 2 && plane.is_none() {
            warnings.push(
                "no symmetry plane found, so the network ran once, without the mirrored pass"
                    .into(),
            );
        }
        views = network.views.take();
        let start = Instant::now();
        added = with_network(&measured, &measured_index, added, &network, options);
        within_seen_width(&mut added, seen_width);
        timings.reprojection += start.elapsed();
    }

    let cloud = assemble(input, &frame, &added, keep_input);
    let kept: &[[f64; 3]] = if keep_input { &measured } else { &[] };
    let normalized = kept
        .iter()
        .copied()
        .chain(added.iter().map(|a| a.position))
        .collect();
    Ok(Completion {
        cloud,
        normalized,
        input_normalized: measured,
        frame,
        input_points: input.len(),
        added: added.len(),
        mirrored,
        filtered_out,
        network_passes,
        plane,
        roll,
        warnings,
        timings,
        views,
    })
}

/// The plane the measured points are mirrored about: none for `identity`, nor for the network
/// with `--no-symmetry`; a `mirror` run without one says so in `warnings`.
fn mirror_plane(
    plane: Option<Plane>,
    options: &Options,
    warnings: &mut Vec<String>,
) -> Option<Plane> {
    match options.method {
        Method::Identity => None,
        Method::Mirror => {
            if plane.is_none() {
                warnings.push("no symmetry plane found; nothing is mirrored".to_string());
            }
            plane
        }
        Method::Network => plane.filter(|_| options.symmetry),
    }
}

/// How far beyond the measured extent across the width a completed point may lie on a scan
/// that shows both flanks, as its outermost returns may fall short of a flank seen at a grazing
/// angle. Chosen among 0.01, 0.015 and 0.02 on the three validation sets (lab/): at 0.01 the
/// third-party camera partials' mirror F1 fell by 0.0019, at 0.015 by 0.0008, and the real
/// scans' completions reach at most 1.5 % of the length beyond them.
const SEEN_WIDTH_MARGIN: f64 = 0.015;

/// The measured points' extent across the width (x), widened by [`SEEN_WIDTH_MARGIN`].
fn across_seen(measured: &[[f64; 3]]) -> (f64, f64) {
    let (lo, hi) = measured
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
            (lo.min(p[0]), hi.max(p[0]))
        });
    (lo - SEEN_WIDTH_MARGIN, hi + SEEN_WIDTH_MARGIN)
}

/// Drops the completed points outside `seen` across the width: where both flanks were scanned,
/// the scanner saw through the space beyond them, so a mirror image there (of a wing mirror
/// the far side lacks, say) or a network point is no part of the vehicle (free space).
fn within_seen_width(added: &mut Vec<Added>, seen: Option<(f64, f64)>) {
    if let Some((lo, hi)) = seen {
        added.retain(|a| (lo..=hi).contains(&a.position[0]));
    }
}

/// The points added to the measured ones once the network has run: the mirror images `added`
/// and the network's points in the gaps they leave, or, without `keep_input`, the network's
/// cloud alone (the paper's output).
fn with_network(
    measured: &[[f64; 3]],
    measured_index: &KnnIndex,
    mut added: Vec<Added>,
    network: &NetworkOutput,
    options: &Options,
) -> Vec<Added> {
    if !options.keep_input {
        return network_points(&network.predicted, measured_index);
    }
    let sure = network.sure.as_ref();
    let fill = gap_fill(measured, &added, &network.predicted, sure, options);
    added.extend(network_points(&fill, measured_index));
    added
}

/// The network's frame for an input, the measured points in it, and the symmetry plane.
struct Framed {
    frame: Frame,
    /// The roll the frame takes out, degrees.
    roll: f64,
    measured: Vec<[f64; 3]>,
    plane: Option<Plane>,
}

/// Fits the frame (in the heading's pose), finds the symmetry plane when anything needs it, and
/// refits the frame around the plane when `symmetric_frame` asks.
fn framed(input: &PointCloud, options: &Options) -> Result<Framed, CompleteError> {
    let posed = match options.heading {
        Some(heading) => Frame::fit_heading(input, options.up, heading)?,
        None => Frame::fit(input, options.up)?,
    };
    let normalized = |frame: &Frame| -> Vec<[f64; 3]> {
        input
            .positions
            .iter()
            .map(|&p| frame.to_normalized(p))
            .collect()
    };
    let roll = match options.roll {
        Roll::Given(roll) => roll,
        Roll::Auto => find_roll(&normalized(&posed), &options.tuning.symmetry).unwrap_or(0.0),
    };
    let fitted = if roll == 0.0 {
        posed
    } else {
        posed.rolled(input, roll)?
    };
    let fitted_points = normalized(&fitted);
    let wants_plane = options.symmetric_frame
        || options.method == Method::Mirror
        || (options.method == Method::Network && options.symmetry);
    let width = match (options.vehicle_width, options.min_vehicle_width) {
        (Some(w), _) => Some(Width::Known(w / fitted.extent)),
        (None, Some(w)) => Some(Width::AtLeast(w / fitted.extent)),
        (None, None) => None,
    };
    let plane = wants_plane
        .then(|| find_plane(&fitted_points, width, &options.tuning.symmetry))
        .flatten();
    let frame = if options.symmetric_frame {
        symmetric_frame(&fitted, &fitted_points, plane)
    } else {
        fitted.clone()
    };
    let measured = input
        .positions
        .iter()
        .map(|&p| frame.to_normalized(p))
        .collect();
    let moved = |offset: f64| frame.to_normalized(fitted.to_input([offset, 0.0, 0.0]))[0];
    let plane = plane.map(|p| Plane {
        offset: moved(p.offset),
        tolerance: p.tolerance * fitted.extent / frame.extent,
        cues: p.cues.map(moved),
        ..p
    });
    Ok(Framed {
        frame,
        roll,
        measured,
        plane,
    })
}

/// Mirror images of the measured points across `plane`, where no measured point lies within
/// the plane's tolerance. Asked of a grid, not the k-d tree: most images of a one-sided scan
/// land far from every measured point, where each tree query walks far (on a 500K-point bus,
/// 1.2 s of the 2.1 s `complete` took; lab/2026-12-04-complete-bench-history).
fn mirror_images(measured: &[[f64; 3]], plane: Plane) -> Vec<Added> {
    let grid = MatchGrid::new(measured, plane.tolerance);
    measured
        .par_iter()
        .enumerate()
        .map(|(i, &p)| (i, mirror(p, plane.offset)))
        .filter(|&(_, image)| grid.nearest_within(image).is_none())
        .map(|(source, position)| Added {
            position,
            color: None,
            source,
        })
        .collect()
}

/// The network's points in the gaps the measured points and the added mirror images leave:
/// beyond the merge distance of every one of them, and within the near distance only those of
/// `sure` (when the near band is on; see [`Options::near_distance`]); thinned to one per cube
/// of side `thin` (see [`thin::one_per_cube`]).
fn gap_fill(
    measured: &[[f64; 3]],
    added: &[Added],
    predicted: &PointCloud,
    sure: Option<&PointCloud>,
    options: &Options,
) -> PointCloud {
    let mut covered = measured.to_vec();
    covered.extend(added.iter().map(|a| a.position));
    let index = KnnIndex::new(&covered);
    // The points whose nearest covered point lies further than `near` and at most `far`.
    let between = |cloud: &PointCloud, near: f64, far: f64| {
        let keep: Vec<bool> = index
            .nearest(&cloud.positions)
            .into_iter()
            .map(|(_, d)| d > near && d <= far)
            .collect();
        cloud.filter(&keep)
    };
    let merge = options.merge_distance;
    let gaps = match sure {
        None => between(predicted, merge, f64::INFINITY),
        Some(sure) => {
            let mut gaps = between(predicted, options.near_distance, f64::INFINITY);
            gaps.append(between(sure, merge, options.near_distance));
            gaps
        }
    };
    gaps.select(&thin::one_per_cube(&gaps.positions, options.thin))
}

/// The network's points, each taking its attributes from its nearest measured point.
fn network_points(predicted: &PointCloud, measured_index: &KnnIndex) -> Vec<Added> {
    let sources = measured_index.nearest(&predicted.positions);
    predicted
        .positions
        .iter()
        .zip(sources)
        .enumerate()
        .map(|(i, (&position, (source, _)))| Added {
            position,
            color: predicted.colors.as_ref().map(|c| c[i]),
            source,
        })
        .collect()
}

/// A completed point in the network's frame; `source` is the measured point it takes its
/// attributes (and, without a colour of its own, its colour) from.
struct Added {
    position: [f64; 3],
    color: Option<[u8; 3]>,
    source: usize,
}

/// The frame the network expects: the training objects' boxes are centred on their symmetry
/// plane and hold the whole object, so the box is fitted to the measured points together with
/// their mirror images. Without a plane, the measured points' own box.
fn symmetric_frame(fitted: &Frame, points: &[[f64; 3]], plane: Option<Plane>) -> Frame {
    let both = plane
        .and_then(|plane| Aabb::of_iter(points.iter().flat_map(|&p| [p, mirror(p, plane.offset)])));
    let Some(both) = both else {
        return fitted.clone();
    };
    let center = both.center();
    let extent = both.longest_side();
    Frame {
        center: fitted.to_input(center),
        extent: fitted.extent * extent,
        rotation: fitted.rotation,
    }
}

/// The output cloud in the input's coordinates: the measured points exactly as read (when
/// kept), then the added points, with [`SYNTHETIC`] marking them.
fn assemble(input: &PointCloud, frame: &Frame, added: &[Added], keep_input: bool) -> PointCloud {
    let sources: Vec<usize> = added.iter().map(|a| a.source).collect();
    let mut extra = input.select(&sources);
    for (p, a) in extra.positions.iter_mut().zip(added) {
        *p = frame.to_input(a.position);
    }
    if let Some(colors) = extra.colors.as_mut() {
        for (c, a) in colors.iter_mut().zip(added) {
            if let Some(own) = a.color {
                *c = own;
            }
        }
    }
    let flag_of_input = |i: usize| {
        input
            .attribute(SYNTHETIC)
            .map_or(0.0, |attribute| attribute.values[i])
    };
    let mut out = if keep_input {
        let mut out = input.clone();
        out.positions.extend(extra.positions);
        if let (Some(c), Some(e)) = (out.colors.as_mut(), extra.colors) {
            c.extend(e);
        }
        for (a, e) in out.attributes.iter_mut().zip(extra.attributes) {
            a.values.extend(e.values);
        }
        out
    } else {
        extra
    };
    let mut flags: Vec<f64> = if keep_input {
        (0..input.len()).map(flag_of_input).collect()
    } else {
        Vec::new()
    };
    flags.extend(std::iter::repeat_n(1.0, added.len()));
    out.attributes.retain(|a| a.name != SYNTHETIC);
    out.attributes.push(Attribute {
        name: SYNTHETIC.to_string(),
        kind: ScalarKind::U8,
        values: flags,
    });
    out
}

/// Warnings for inputs far from the street vehicles the model learned: too few points, a thin
/// (pole- or wire-like) shape, or points in one plane (a single scan line, a wall).
/// A vehicle width this far from the cloud's size (its box's largest side) is more likely in
/// other units than the cloud's: below a fiftieth (a 60 m train is 20 times its width) or
/// above twice (a partial shorter than the vehicle is wide). Such a width bounds no plane
/// found, and misplaces one where none is.
const WIDTH_RATIOS: (f64, f64) = (0.02, 2.0);

/// The warning for a vehicle `width` outside [`WIDTH_RATIOS`] of the cloud's `extent`.
/// The warning for a plane the cues do not vouch for, saying what was done instead.
fn unvouched_warning(plane: &Plane, options: &Options) -> String {
    let instead = match options.method {
        Method::Network => "nothing is mirrored, the network completes the far side",
        _ => "mirrored about the middle of the scan's extent",
    };
    let pairs = plane.cues.pairs.map_or(String::new(), |c| {
        format!(" (the mirror pairs put it at x = {c:.3})")
    });
    format!(
        "symmetry plane uncertain: the plane found{pairs} would make the vehicle wider than \
         any road vehicle for its length; {instead}"
    )
}

fn width_warning(width: f64, extent: f64) -> Option<String> {
    let ratio = width / extent;
    (!(WIDTH_RATIOS.0..=WIDTH_RATIOS.1).contains(&ratio)).then(|| {
        format!(
            "the vehicle width given ({width}) is {ratio:.3} times the cloud's size \
             ({extent:.3}): is it in the cloud's units?"
        )
    })
}

fn distribution_warnings(points: &[[f64; 3]]) -> Vec<String> {
    let mut warnings = Vec::new();
    if points.len() < SPARSE_POINTS {
        warnings.push(format!(
            "only {} points: completion from so few is unreliable",
            points.len()
        ));
    }
    // The shape's spreads below would describe the strays' box, not the vehicle.
    if let Some(strays) = stray_points(points) {
        warnings.push(format!(
            "{strays} point(s) lie far from the rest (stray returns?) and set the cloud's box, so \
             the vehicle fills a small part of the model's: --clean drops isolated points"
        ));
        return warnings;
    }
    let n = points.len() as f64;
    let mean = points.iter().fold([0.0; 3], |m, p| {
        [m[0] + p[0] / n, m[1] + p[1] / n, m[2] + p[2] / n]
    });
    let mut cov = Matrix3::<f64>::zeros();
    for p in points {
        let d = nalgebra::Vector3::new(p[0] - mean[0], p[1] - mean[1], p[2] - mean[2]);
        cov += d * d.transpose() / n;
    }
    let mut spread: Vec<f64> = SymmetricEigen::new(cov)
        .eigenvalues
        .iter()
        .map(|v| v.max(0.0).sqrt())
        .collect();
    spread.sort_by(f64::total_cmp);
    // Spreads are standard deviations in the unit box: a car's are about 0.1, 0.15 and 0.3.
    if spread[1] < 0.02 {
        warnings.push(
            "the points form a thin line (a pole, a wire, a single scan line?), not a vehicle"
                .to_string(),
        );
    } else if spread[0] < 0.003 {
        warnings.push(
            "the points lie in one plane (a wall, one side only?): the model expects a 3D vehicle"
                .to_string(),
        );
    }
    warnings
}

/// Share of the points at each end of every axis left out of the cloud's bulk.
const BULK_TRIM: f64 = 0.01;

/// How many points lie far from the cloud's bulk (the box of its points from the 1st to the
/// 99th percentile along each axis), when they stretch the whole box to more than twice the
/// bulk's longest side: a vehicle's ends and mirrors never do, one stray return kilometres away
/// (a bird, a reflection) does, and then normalizing shrinks the vehicle to a speck.
fn stray_points(points: &[[f64; 3]]) -> Option<usize> {
    let whole = Aabb::of(points)?.longest_side();
    let bulk = |axis: usize| {
        let mut values: Vec<f64> = points.iter().map(|p| p[axis]).collect();
        let last = values.len() - 1;
        let trim = (BULK_TRIM * last as f64) as usize;
        let lo = *values.select_nth_unstable_by(trim, f64::total_cmp).1;
        let hi = *values.select_nth_unstable_by(last - trim, f64::total_cmp).1;
        (lo, hi)
    };
    let bulk = [bulk(0), bulk(1), bulk(2)];
    let side = bulk.iter().map(|(lo, hi)| hi - lo).fold(0.0, f64::max);
    if whole <= 2.0 * side {
        return None;
    }
    // Far: more than the bulk's own longest side beyond it.
    let far = |p: &[f64; 3]| (0..3).any(|a| p[a] < bulk[a].0 - side || p[a] > bulk[a].1 + side);
    Some(points.iter().filter(|p| far(p)).count())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::complete::filter::inliers;
    use crate::core::camera::Camera;
    use crate::datagen::shapes::{example_car, scanned_side};
    use crate::model::weights::generator_to_bytes;
    use crate::model::{ModelConfig, Preset};
    use crate::views::projection::project;
    use crate::views::reprojection::{dedup_indices, reproject, reproject_keeping};
    use burn::tensor::Device;

    fn options(method: Method) -> Options {
        Options {
            method,
            smooth: 5,
            symmetry: false,
            ..Options::default()
        }
    }

    /// The example car's scanned side, moved to georeferenced coordinates.
    fn partial() -> PointCloud {
        let mut cloud = scanned_side(&example_car());
        for p in &mut cloud.positions {
            p[0] += 650_000.0;
            p[2] += 5_270_000.0;
        }
        cloud
    }

    /// A width in other units than the cloud's (millimetres for a cloud in metres) is named.
    #[test]
    fn a_vehicle_width_in_other_units_is_warned_about() {
        let input = partial();
        let with = |width| {
            let options = Options {
                vehicle_width: Some(width),
                ..options(Method::Mirror)
            };
            complete(&input, None, &options).unwrap().warnings
        };
        assert!(with(1.8).iter().all(|w| !w.contains("vehicle width")));
        for width in [1800.0, 0.0018] {
            assert!(
                with(width)
                    .iter()
                    .any(|w| w.contains("the vehicle width given") && w.contains("units")),
                "{width}"
            );
        }
    }

    fn tiny_inpainter() -> Inpainter {
        inpainter_for(Preset::Tiny.config())
    }

    fn inpainter_for(config: ModelConfig) -> Inpainter {
        let device = Device::flex();
        let g = config.init_generator(&device).unwrap();
        Inpainter::from_bytes(&generator_to_bytes(&g, &config).unwrap(), device).unwrap()
    }

    fn flags(cloud: &PointCloud) -> &[f64] {
        &cloud.attribute(SYNTHETIC).unwrap().values
    }

    /// The paper's first steps composed by hand: the frame, the input's views and what
    /// `inpainter` makes of them.
    fn paper_views(
        input: &PointCloud,
        inpainter: &Inpainter,
        options: &Options,
    ) -> (Frame, ViewImages, ViewImages) {
        let frame = Frame::fit(input, UpAxis::Y).unwrap();
        let points: Vec<[f32; 3]> = input
            .positions
            .iter()
            .map(|&p| frame.to_normalized(p).map(|c| c as f32))
            .collect();
        let cameras = Camera::set(&options.views, inpainter.config().size).unwrap();
        let views = project(&points, input.colors.as_deref(), &cameras);
        let inpainted = inpainter
            .inpaint(std::slice::from_ref(&views))
            .unwrap()
            .pop()
            .unwrap();
        (frame, views, inpainted)
    }

    /// `--paper` is the paper's steps in the paper's order and nothing else: the same stage
    /// functions composed by hand give the same points, to the bit.
    #[test]
    fn the_paper_pipeline_is_its_steps_and_nothing_else() {
        let input = partial();
        let inpainter = tiny_inpainter();
        let options = Options::paper(UpAxis::Y, None);
        let done = complete(&input, Some(&inpainter), &options).unwrap();

        let (frame, _, inpainted) = paper_views(&input, &inpainter, &options);
        let eroded = reproject(&inpainted, every_pixel());
        let kept = eroded.filter(&inliers(&eroded.positions, SorParams::default()));
        let expected: Vec<[f64; 3]> = kept.positions.iter().map(|&p| frame.to_input(p)).collect();

        assert_eq!(done.cloud.positions, expected);
        assert!(
            done.plane.is_none() && done.mirrored == 0,
            "no symmetry search"
        );
        assert!(
            flags(&done.cloud).iter().all(|&f| f == 1.0),
            "no measured point kept"
        );
        assert_eq!(ReprojectOptions::default().erode, 3);
        assert_eq!((options.sor.k, options.sor.std_mul), (20, 5.0));
    }

    /// The paper re-projects every pixel of every view: the 3×3 erosion, no merging of
    /// near-duplicate points.
    fn every_pixel() -> ReprojectOptions {
        ReprojectOptions {
            dedup_tolerance: 0.0,
            ..ReprojectOptions::default()
        }
    }

    /// With a model that keeps its input's pixels, the erosion spares them: the paper's steps
    /// with [`reproject_keeping`] in place of [`reproject`], and more points than eroding all.
    #[test]
    fn a_copying_models_measured_pixels_are_not_eroded() {
        let input = partial();
        let inpainter = inpainter_for(Preset::Tiny.config().with_input_copy_kind(true));
        let options = Options::paper(UpAxis::Y, None);
        let done = complete(&input, Some(&inpainter), &options).unwrap();

        let (frame, views, inpainted) = paper_views(&input, &inpainter, &options);
        let filtered = |cloud: PointCloud| cloud.filter(&inliers(&cloud.positions, options.sor));
        let kept = filtered(reproject_keeping(&inpainted, every_pixel(), Some(&views)));
        let expected: Vec<[f64; 3]> = kept.positions.iter().map(|&p| frame.to_input(p)).collect();
        assert_eq!(done.cloud.positions, expected);
        // A measured point that two views copy is re-projected twice, as the paper does.
        let distinct = dedup_indices(&kept.positions, 1e-9).len();
        assert!(distinct < kept.len(), "{distinct} of {}", kept.len());
        let eroded = filtered(reproject(&inpainted, every_pixel()));
        assert!(
            eroded.len() < kept.len(),
            "{} vs {}",
            eroded.len(),
            kept.len()
        );
    }

    #[test]
    fn identity_keeps_the_input_and_flags_nothing() {
        let input = partial();
        let done = complete(&input, None, &options(Method::Identity)).unwrap();
        assert_eq!(done.cloud.positions, input.positions);
        assert_eq!(done.added, 0);
        assert!(flags(&done.cloud).iter().all(|&f| f == 0.0));
    }

    #[test]
    fn mirror_adds_the_far_side_in_the_input_frame() {
        let input = partial();
        let done = complete(&input, None, &options(Method::Mirror)).unwrap();
        assert_eq!(&done.cloud.positions[..input.len()], &input.positions[..]);
        // The mirror adds the far flank, as many points as the near flank (x > 0.7 m) has.
        let near = input
            .positions
            .iter()
            .filter(|p| p[0] - 650_000.0 > 0.7)
            .count();
        assert!(
            done.added.abs_diff(near) < near / 4,
            "{} added for a near flank of {near}",
            done.added
        );
        let f = flags(&done.cloud);
        assert!(f[..input.len()].iter().all(|&v| v == 0.0));
        assert!(f[input.len()..].iter().all(|&v| v == 1.0));
        // The car spans x ∈ [−0.9, 0.9] m; the scan sees x > −0.6 m only; its mirror images
        // reach the far flank, in the input's georeferenced coordinates.
        let min_x = done.cloud.positions[input.len()..]
            .iter()
            .map(|p| p[0] - 650_000.0)
            .fold(f64::MAX, f64::min);
        assert!((min_x + 0.9).abs() < 0.05, "far flank at {min_x}");
        assert_eq!(done.cloud.colors.as_ref().unwrap().len(), done.cloud.len());
    }

    #[test]
    fn a_scan_of_both_flanks_gets_no_mirror_image_beyond_them() {
        // The whole example car (x within ±0.91 m, 4.4 m long), its +x flank seen more sparsely,
        // with a wing mirror 0.25 m out on the better scanned side (−x) only: its image would
        // stick out beyond the other flank, where the scanner saw nothing, so it is dropped;
        // the scan's own points stay.
        let car = example_car().cloud;
        let keep: Vec<bool> = car
            .positions
            .iter()
            .enumerate()
            .map(|(i, p)| p[0] < 0.3 || i % 3 == 0)
            .collect();
        let mut input = car.filter(&keep);
        let n = input.len();
        for i in 0..40 {
            input.positions.push([-1.15, 0.9 + 0.002 * i as f64, 0.8]);
        }
        input.colors.as_mut().unwrap().extend([[0u8; 3]; 40]);
        let done = complete(&input, None, &options(Method::Mirror)).unwrap();
        let plane = done.plane.unwrap();
        assert!(
            plane.both_sides && plane.fit != crate::complete::symmetry::PlaneFit::HeldBack,
            "{plane:?}"
        );
        assert_eq!(&done.cloud.positions[..n + 40], &input.positions[..]);
        let reach = done.cloud.positions[n + 40..]
            .iter()
            .map(|p| p[0])
            .fold(f64::MIN, f64::max);
        let flank = input
            .positions
            .iter()
            .map(|p| p[0])
            .fold(f64::MIN, f64::max);
        assert!(
            reach <= flank + SEEN_WIDTH_MARGIN * 4.4 + 1e-9,
            "an image {reach} m out, the flank at {flank} m"
        );
    }

    #[test]
    fn network_output_lands_in_the_input_frame_with_input_points_exact() {
        let input = partial();
        let inpainter = tiny_inpainter();
        let opts = options(Method::Network);
        let done = complete(&input, Some(&inpainter), &opts).unwrap();
        assert_eq!(&done.cloud.positions[..input.len()], &input.positions[..]);
        assert_eq!(done.cloud.len(), input.len() + done.added);
        assert_eq!(done.normalized.len(), done.cloud.len());
        for (p, q) in done
            .cloud
            .positions
            .iter()
            .zip(&done.normalized)
            .skip(input.len())
        {
            let back = done.frame.to_input(*q);
            for i in 0..3 {
                assert!((p[i] - back[i]).abs() < 1e-6);
            }
        }
        let opts = Options {
            keep_input: false,
            ..opts
        };
        let alone = complete(&input, Some(&inpainter), &opts).unwrap();
        assert!(flags(&alone.cloud).iter().all(|&v| v == 1.0));
    }

    /// Thinning keeps one of the network's added points per cube and adds none of its own. The
    /// untrained model's every pixel is made a point, so that it adds some whatever its weights.
    #[test]
    fn thinning_keeps_one_added_point_per_cube() {
        let inpainter = inpainter_for(ModelConfig {
            occupancy: Some(1e-6),
            ..Preset::Tiny.config()
        });
        let input = partial();
        let added = |thin| {
            let options = Options {
                thin,
                ..options(Method::Network)
            };
            let run = complete(&input, Some(&inpainter), &options).unwrap();
            run.normalized[run.input_points..].to_vec()
        };
        let all = added(0.0);
        let thinned = added(0.1);
        assert!(!thinned.is_empty() && thinned.len() < all.len());
        let mut cubes = std::collections::HashSet::new();
        for p in &thinned {
            assert!(all.contains(p));
            assert!(cubes.insert(p.map(|c| (c / 0.1).floor() as i64)));
        }
    }

    /// The mirrored pass is what the network makes of the mirror image on its own, mirrored
    /// back and after the first pass's points, in the near band too; without a plane the
    /// network runs once.
    #[test]
    fn the_mirrored_pass_is_the_mirror_images_completion_mirrored_back() {
        let input = partial();
        // An untrained model's occupancies fall either side of 0.5 by chance: a low threshold
        // leaves both passes points to compare.
        let inpainter = inpainter_for(Preset::Tiny.config().with_occupancy(Some(0.01)));
        let frame = Frame::fit(&input, UpAxis::Y).unwrap();
        let measured: Vec<[f64; 3]> = input
            .positions
            .iter()
            .map(|&p| frame.to_normalized(p))
            .collect();
        let plane = Plane {
            offset: 0.02,
            support: 0.5,
            tolerance: 0.01,
            fit: crate::complete::symmetry::PlaneFit::Refined,
            cues: Default::default(),
            vouched: true,
            both_sides: false,
        };
        let options = Options {
            near_occupancy: 0.3,
            ..options(Method::Network)
        };
        let run = |points: &[[f64; 3]], plane: Option<Plane>, mirror_pass: bool| {
            let options = Options {
                mirror_pass,
                ..options.clone()
            };
            let mut timings = Timings::default();
            run_network(&input, points, plane, &inpainter, &options, &mut timings).unwrap()
        };
        let once = run(&measured, Some(plane), false);
        let twice = run(&measured, Some(plane), true);
        let images: Vec<[f64; 3]> = measured.iter().map(|&p| mirror(p, 0.02)).collect();
        let of_images = run(&images, Some(plane), false);
        assert_eq!((once.passes, twice.passes), (1, 2));
        let sure = |output: &NetworkOutput| output.sure.clone().expect("a near band");
        let joined = |first: &PointCloud, second: &PointCloud| -> Vec<[f64; 3]> {
            let back = second.positions.iter().map(|&p| mirror(p, 0.02));
            first.positions.iter().copied().chain(back).collect()
        };
        assert!(!of_images.predicted.is_empty() && !sure(&of_images).is_empty());
        assert_eq!(
            twice.predicted.positions,
            joined(&once.predicted, &of_images.predicted)
        );
        assert_eq!(
            sure(&twice).positions,
            joined(&sure(&once), &sure(&of_images))
        );
        assert_eq!(
            twice.filtered_out,
            once.filtered_out + of_images.filtered_out
        );
        assert_eq!(run(&measured, None, true).passes, 1);
    }

    #[test]
    fn near_the_covered_points_only_sure_points_fill() {
        let measured = [[0.0, 0.0, 0.0]];
        let at =
            |xs: &[f64]| PointCloud::from_positions(xs.iter().map(|&x| [x, 0.0, 0.0]).collect());
        // Within the merge distance, in the near band, beyond it.
        let predicted = at(&[0.03, 0.07, 0.12]);
        let sure = at(&[0.03, 0.08, 0.12]);
        let options = Options {
            merge_distance: 0.05,
            near_distance: 0.09,
            thin: 0.0,
            ..options(Method::Network)
        };
        let xs = |cloud: PointCloud| cloud.positions.iter().map(|p| p[0]).collect::<Vec<_>>();
        let fill = gap_fill(&measured, &[], &predicted, Some(&sure), &options);
        assert_eq!(xs(fill), [0.12, 0.08]);
        let fill = gap_fill(&measured, &[], &predicted, None, &options);
        assert_eq!(xs(fill), [0.07, 0.12]);
    }

    #[test]
    fn refusals_and_warnings() {
        let few = PointCloud::from_positions((0..20).map(|i| [i as f64, 0.0, 0.0]).collect());
        assert!(matches!(
            complete(&few, None, &options(Method::Identity)),
            Err(CompleteError::TooFewPoints(20))
        ));
        let line = PointCloud::from_positions(
            (0..300)
                .map(|i| [i as f64 * 0.01, (i % 3) as f64 * 1e-4, 0.0])
                .collect(),
        );
        let done = complete(&line, None, &options(Method::Identity)).unwrap();
        assert_eq!(done.warnings.len(), 2, "{:?}", done.warnings);
        assert!(done.warnings[1].contains("thin line"));
        let car = complete(&partial(), None, &options(Method::Identity)).unwrap();
        assert!(car.warnings.is_empty(), "{:?}", car.warnings);
        // One stray return a kilometre off: named as such, not taken for a thin line.
        let mut stray = partial();
        let far = stray.positions[0].map(|v| v + 1000.0);
        stray.positions.push(far);
        let done = complete(&stray, None, &options(Method::Identity)).unwrap();
        assert_eq!(done.warnings.len(), 1, "{:?}", done.warnings);
        assert!(
            done.warnings[0].starts_with("1 point(s) lie far from the rest"),
            "{:?}",
            done.warnings
        );
        let inpainter = tiny_inpainter();
        let mut three = options(Method::Network);
        three.views = vec![5, 6, 7];
        assert!(matches!(
            complete(&partial(), Some(&inpainter), &three),
            Err(CompleteError::Views { model: 4, given: 3 })
        ));
    }
}
