//! Command-line definitions (clap derive). Each subcommand's arguments live beside the others
//! here; what they do lives in [`crate::cli::commands`].

use clap::builder::RangedU64ValueParser;
use clap::{Args, CommandFactory, FromArgMatches, Parser, Subcommand, ValueEnum};
use mvpcc::app::eval::{GroundTruth, Metric, Normalize};
use mvpcc::complete::filter::{SorParams, MAX_K};
use mvpcc::complete::orient::OrientMode;
use mvpcc::complete::orient::OrienterConfig;
use mvpcc::complete::{Method, Options, Roll, DEFAULT_MODEL};
use mvpcc::core::camera::{parse_view_set, DEFAULT_VIEWS};
use mvpcc::core::frame::UpAxis;
use mvpcc::datagen::data::CloudPolicy;
use mvpcc::datagen::mesh::{Forward, SignedAxis};
use mvpcc::datagen::scan::{PartialKinds, PartialParams};
use mvpcc::datagen::synth::street::StreetParams;
use mvpcc::datagen::synth::Draw;
use mvpcc::io::batch::{default_jobs, Shard, MAX_JOBS};
use mvpcc::io::{Encoding, Format};
use mvpcc::model::device::{built_backends, DeviceChoice};
use mvpcc::model::loss::{Adversarial, FeaturePlanes, TvScale};
use mvpcc::model::weights::{read_config, Network};
use mvpcc::model::{Channels, Dilation, Formulation, Fusion, Padding};
use mvpcc::scene::stream::StreamParams;
use mvpcc::train::loader::{MAX_PREFETCH, MAX_WORKERS};
use mvpcc::train::orient::OrientSettings;
use mvpcc::train::TrainSettings;
use mvpcc::views::reprojection::{ReprojectOptions, MAX_WINDOW};
use std::path::PathBuf;

#[derive(Debug, Parser)]
#[command(
    name = "mvpcc",
    version,
    about = "Multi-view point cloud completion (MVPCC-Net) for mobile laser scans of street objects"
)]
pub struct Cli {
    /// Print nothing but errors and results.
    #[arg(short, long, global = true)]
    pub quiet: bool,
    #[command(subcommand)]
    pub command: Command,
}

/// A count from `min` to `max`; clap names the range when refusing one outside it.
fn counts(min: usize, max: usize) -> RangedU64ValueParser<usize> {
    RangedU64ValueParser::new().range(min as u64..=max as u64)
}

impl Cli {
    /// The command line, every option's value allowed to be a negative number: `--tau -1`
    /// reaches the option's own check ("thresholds must be positive numbers") where clap alone
    /// would answer "unexpected argument '-1' found".
    pub fn parse_negatives() -> Cli {
        let command = Cli::command()
            .long_version(long_version())
            .mut_subcommands(|sub| {
                sub.mut_args(|arg| {
                    let takes_values = arg.get_num_args().is_none_or(|n| n.takes_values());
                    if takes_values && arg.get_action().takes_values() {
                        arg.allow_negative_numbers(true)
                    } else {
                        arg
                    }
                })
            });
        Cli::from_arg_matches(&command.get_matches()).unwrap_or_else(|e| e.exit())
    }
}

/// `--version`'s long form: besides the version, the model `complete` runs and the devices the
/// build can use, which a reported result also depends on.
fn long_version() -> String {
    let model = read_config(DEFAULT_MODEL, Network::Generator).map_or_else(
        |e| format!("unreadable ({e})"),
        |c| {
            let threshold = c.occupancy.map(|o| format!(", occupancy threshold {o}"));
            format!("{}{}", c.describe(), threshold.unwrap_or_default())
        },
    );
    format!(
        "{}\nbuilt-in model: {model}\nbackends: {}",
        env!("CARGO_PKG_VERSION"),
        built_backends().join(", ")
    )
}

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Complete a partial scan: the measured points are kept and the missing surface is added
    /// (flagged `synthetic`), in the input's coordinates. The default model is built in.
    Complete(Box<CompleteArgs>),
    /// Score predicted clouds against ground truth (Chamfer distances, F-score), or predicted
    /// view images against ground-truth views (PSNR, SSIM, MAE).
    Eval(EvalArgs),
    /// Normalize a cloud and project it into view images (the original dataset's PNG pairs).
    Project(ProjectArgs),
    /// Turn view images back into a cloud: erode, merge, de-duplicate, remove outliers.
    Reproject(ReprojectArgs),
    /// Statistical outlier removal (PCL's StatisticalOutlierRemoval) as a tool of its own.
    Filter(FilterArgs),
    /// Time the network's forward pass on random input, by layer kind.
    Profile(ProfileArgs),
    /// Make training data from meshes: ground truth, partial scans and their view images in
    /// the original dataset's layout.
    Prepare(PrepareArgs),
    /// Generate street-object meshes (cars, buses, trucks, trains, motorcycles) as OBJ + MTL.
    Synth(SynthArgs),
    /// Train the inpainting GAN on a "shapenet-views" directory (from `mvpcc prepare` or the
    /// original MVPCC data).
    Train(Box<TrainArgs>),
    /// Train the orientation network (the paper's STN) on the partial samples of a
    /// "shapenet-views" directory turned by random yaws.
    TrainOrient(TrainOrientArgs),
}

/// How an input file is read.
#[derive(Debug, Args)]
pub struct InputOptions {
    /// Input format, overriding the file extension.
    #[arg(long, value_enum)]
    pub format: Option<Format>,
}

/// How an output cloud is written.
#[derive(Debug, Args)]
pub struct OutputOptions {
    /// Output format, overriding the file extension.
    #[arg(long, value_enum)]
    pub out_format: Option<Format>,
    /// Body encoding for PLY and PCD outputs.
    #[arg(long, value_enum, default_value_t = Encoding::Binary)]
    pub encoding: Encoding,
}

#[derive(Debug, Args)]
pub struct SorOptions {
    #[arg(
        long,
        default_value_t = SorParams::DEFAULT.k,
        value_parser = counts(0, MAX_K),
        help = format!(
            "Neighbours per point for the outlier filter, excluding the point itself (PCL's \
             mean_k; Open3D's nb_neighbors is this + 1), at most {MAX_K}. 0 turns the filter off"
        )
    )]
    pub sor_k: usize,
    /// Points whose mean neighbour distance exceeds mean + this × std are removed.
    #[arg(long, default_value_t = SorParams::DEFAULT.std_mul, value_parser = non_negative)]
    pub sor_std: f64,
}

impl SorOptions {
    pub fn params(&self) -> SorParams {
        SorParams {
            k: self.sor_k,
            std_mul: self.sor_std,
        }
    }
}

#[derive(Debug, Args)]
pub struct EvalArgs {
    /// Metrics to compute.
    #[arg(long, value_enum, value_delimiter = ',', default_value = "cd,f1")]
    pub metrics: Vec<Metric>,
    /// Predicted cloud.
    #[arg(long, requires = "gt", conflicts_with_all = ["pred_dir", "pred_views"])]
    pub pred: Option<PathBuf>,
    /// Ground-truth cloud.
    #[arg(long, requires = "pred")]
    pub gt: Option<PathBuf>,
    /// Directory of predicted clouds, matched to --gt-dir's by path without the extension
    /// (subfolders included, hidden files skipped), or to --data's test samples as
    /// CATEGORY/MODEL/partial_K.*.
    #[arg(long, conflicts_with = "pred_views")]
    pub pred_dir: Option<PathBuf>,
    /// A data directory from `mvpcc prepare`: score --pred-dir's completions of its test
    /// partials against their ground truth (scanner partials turned back into the object's
    /// frame), with means per category, per partial protocol, per category × protocol cell
    /// (`cell car / scanner`) and overall.
    #[arg(long, requires = "pred_dir", conflicts_with = "gt_dir")]
    pub data: Option<PathBuf>,
    /// With --data: the fine ground truth (gt.ply, every point the rig saw) or the paper's
    /// coarse one (gt_coarse.ply: 16,384 of them by farthest point sampling; computed when an
    /// older data directory lacks it).
    #[arg(long, value_enum, default_value_t = GroundTruth::Fine, requires = "data")]
    pub ground_truth: GroundTruth,
    /// Directory of ground-truth clouds.
    #[arg(long, requires = "pred_dir")]
    pub gt_dir: Option<PathBuf>,
    /// Directory of predicted view images (locations_NNN.png, color_NNN.png).
    #[arg(long, requires = "gt_views")]
    pub pred_views: Option<PathBuf>,
    /// Directory of ground-truth view images.
    #[arg(long, requires = "pred_views")]
    pub gt_views: Option<PathBuf>,
    /// F-score thresholds (strict <), in the clouds' units.
    #[arg(long, value_delimiter = ',', default_value = "0.01,0.005")]
    pub tau: Vec<f64>,
    /// Coordinate normalization applied before scoring.
    #[arg(long, value_enum, default_value_t = Normalize::None)]
    pub normalize: Normalize,
    /// Print results as JSON on stdout instead of a table.
    #[arg(long)]
    pub json: bool,
    #[command(flatten)]
    pub input: InputOptions,
}

/// The decoded-sample cache of `train` and `train-orient`, MiB.
const DEFAULT_CACHE_MB: usize = 2048;

/// A list of rig cameras as typed on the command line (`5,6,7,8`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ViewList(pub Vec<usize>);

impl std::str::FromStr for ViewList {
    type Err = String;
    fn from_str(text: &str) -> Result<Self, String> {
        parse_view_set(text)
            .map(ViewList)
            .map_err(|e| e.to_string())
    }
}

impl std::fmt::Display for ViewList {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let parts: Vec<String> = self.0.iter().map(|v| v.to_string()).collect();
        f.write_str(&parts.join(","))
    }
}

#[derive(Debug, Args)]
pub struct CompleteArgs {
    /// Partial cloud (PLY, PCD, LAS/LAZ, XYZ; `-`: standard input).
    #[arg(required_unless_present_any = ["input_dir", "list", "print_tuning"], conflicts_with_all = ["input_dir", "list"])]
    pub input: Option<PathBuf>,
    /// Completed cloud; its extension picks the format (the input's format when it names none;
    /// `-`: standard output).
    #[arg(required_unless_present_any = ["input_dir", "list", "print_tuning"])]
    pub output: Option<PathBuf>,
    /// Complete every cloud file under this directory (recursively; hidden files skipped, each
    /// file once however many links lead to it).
    #[arg(long, requires = "output_dir")]
    pub input_dir: Option<PathBuf>,
    /// Where batch results go, at the same relative paths (created if missing).
    #[arg(long)]
    pub output_dir: Option<PathBuf>,
    /// Batch: complete the files this text file lists, one per line, relative to --input-dir
    /// (or to the current directory without one) or absolute under --input-dir.
    #[arg(long, requires = "output_dir")]
    pub list: Option<PathBuf>,
    /// Batch: only files whose name matches this pattern (`*` and `?` wildcards).
    #[arg(long, requires = "input_dir", conflicts_with = "list")]
    pub include: Option<String>,
    /// Batch: take only part I of N (I from 0 to N-1), chosen by a hash of each file's relative
    /// path, so N jobs with 0/N … N-1/N complete every file exactly once.
    #[arg(long, value_name = "I/N", requires = "output_dir")]
    pub shard: Option<Shard>,
    /// Batch: leave files whose output already exists (outputs are written whole or not at
    /// all, so an existing one is complete).
    #[arg(long, requires = "output_dir")]
    pub skip_existing: bool,
    /// Batch: files completed at once (1–256), by default one per core this process may use
    /// (each file's reading, orientation and symmetry run on one core while the network
    /// takes them all).
    #[arg(long, default_value_t = default_jobs(), value_parser = counts(1, MAX_JOBS))]
    pub jobs: usize,
    /// network, or a baseline: identity (the partial as it is) or mirror (the partial and its
    /// mirror image across the vehicle's long vertical plane).
    #[arg(long, value_enum, default_value_t = Method::Network)]
    pub method: Method,
    /// Generator weights (a run's generator.safetensors, its run directory, or a folder holding
    /// model.safetensors as assets/ does) [default: the built-in model].
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Probability above which a pixel of the network's output becomes a point; lower adds
    /// more of what the network is unsure of [default: the threshold saved with the model's
    /// weights, chosen on validation; one half for weights saved without one].
    #[arg(long, value_name = "P", value_parser = probability)]
    pub occupancy: Option<f64>,
    /// Where the network runs (GPUs: docs/gpu.md).
    #[arg(long, value_enum, default_value_t = DeviceChoice::Cpu)]
    pub device: DeviceChoice,
    /// Rig cameras of the model's views (those it was trained with).
    #[arg(long, default_value_t = ViewList(DEFAULT_VIEWS.to_vec()))]
    pub views: ViewList,
    /// Input's up axis [default: z for LAS/LAZ, y otherwise].
    #[arg(long, value_enum)]
    pub up: Option<UpAxis>,
    /// Which way the vehicle faces: auto (the best measured estimator, see docs/pipeline.md, *3.
    /// Heading, roll and the network's pose*), geometric (footprint rectangle + height heuristic),
    /// learned (the orientation network), combined (rectangle axis, network's front), none (keep
    /// the input's axes), or the heading in degrees (the front's direction, counter-clockwise from
    /// +x seen from above). [default: auto; none with --paper]
    #[arg(long, allow_negative_numbers = true)]
    pub orient: Option<OrientMode>,
    /// How far the vehicle leans across its width (a cambered road, a kerb), degrees about its
    /// length: auto (found from the cloud's symmetry, within ±4°, where it shows enough) or a
    /// number, positive when the plane of symmetry's normal tilts up from +x of the vehicle's
    /// frame. [default: 0, upright as the input's up axis]
    #[arg(long, allow_negative_numbers = true, conflicts_with = "paper")]
    pub roll: Option<Roll>,
    /// Orientation network weights (train-orient's orienter.safetensors) [default: built in].
    #[arg(long)]
    pub orienter: Option<PathBuf>,
    /// Remove ground points (a plane fit under the object), isolated points and points of
    /// other objects before completing; the counts are reported.
    #[arg(long)]
    pub clean: bool,
    /// The paper's pipeline exactly, for its tables: the input's own box, projection into the
    /// model's views, inpainting, 3×3 erosion, re-projection, outlier filter (k 20, σ 5), back
    /// to the input's frame. No cleaning, no orientation unless --orient names one, no
    /// symmetric frame, no mirror images, no snapping, the measured points not kept.
    #[arg(long, conflicts_with_all = ["clean", "keep_input", "symmetry", "no_snap", "method", "mirror_pass"])]
    pub paper: bool,
    /// Write the network's input and inpainted views in the dataset's format (`DIR/input/`,
    /// `DIR/output/`; with --input-dir, `DIR/<relative path without extension>/…`), for
    /// `eval --pred-views/--gt-views`.
    #[arg(long)]
    pub save_views: Option<PathBuf>,
    /// Keep the measured points and add completed points only where they are missing (the
    /// default).
    #[arg(long, overrides_with = "no_keep_input")]
    pub keep_input: bool,
    /// Output the network's re-projected cloud alone, as the paper does.
    #[arg(long, overrides_with = "keep_input")]
    pub no_keep_input: bool,
    /// Also add the measured points' mirror images across the vehicle's plane of symmetry
    /// (the default).
    #[arg(long, overrides_with = "no_symmetry")]
    pub symmetry: bool,
    /// Let the network alone complete the far side.
    #[arg(long, overrides_with = "symmetry")]
    pub no_symmetry: bool,
    /// The network also completes the measured points' mirror image, and what it makes of it,
    /// mirrored back, joins its output (the default; the two passes run side by side).
    #[arg(long, overrides_with = "no_mirror_pass")]
    pub mirror_pass: bool,
    /// One network pass, on the measured points alone: half the network's work.
    #[arg(long, overrides_with = "mirror_pass")]
    pub no_mirror_pass: bool,
    /// The vehicle's width in the input's units, when known (buses and lorries: 2.55 m in the
    /// EU): on a scan of one side the symmetry plane is kept at least half of it from the
    /// scanned flank, so the mirrored far flank is not drawn inside the vehicle.
    #[arg(
        long,
        value_name = "W",
        value_parser = positive_length,
        allow_negative_numbers = true,
        conflicts_with_all = ["paper", "scene"]
    )]
    pub vehicle_width: Option<f64>,
    /// The input is a whole street scan in metres (an MLS tile): find its vehicles, complete
    /// each one in its own frame, and write the scene back with every input point unchanged
    /// and in its order, the completed points appended with the synthetic flag and a `vehicle`
    /// number (docs/scenes.md).
    #[arg(long, conflicts_with_all = ["paper", "save_views"])]
    pub scene: bool,
    /// With --scene: the vehicles are the points of these LAS classification codes (e.g. 10,64)
    /// instead of what stands on the ground and has a vehicle's size.
    #[arg(long, value_name = "CODES", value_delimiter = ',', requires = "scene")]
    pub vehicle_class: Option<Vec<u8>>,
    /// With --scene: a LAS/LAZ tile of at least this many points, written as LAS/LAZ, is
    /// streamed in chunks (memory bounded by the densest chunk, not the tile; docs/scenes.md).
    #[arg(long, value_name = "POINTS", requires = "scene", default_value_t = StreamParams::default().from_points)]
    pub stream_from: usize,
    /// With --scene, streamed: each chunk's side in metres (each is searched with 25 m around it).
    #[arg(long, value_name = "METRES", requires = "scene", value_parser = chunk_side, default_value_t = StreamParams::default().chunk)]
    pub chunk: f64,
    /// A JSON file of the heuristics' tunables to change (`{"orient": {"flank_band": 0.004}}`;
    /// the names and today's values: `mvpcc complete --print-tuning`), for experiments.
    #[arg(long, value_name = "FILE", conflicts_with = "paper")]
    pub tuning: Option<PathBuf>,
    /// Print the heuristics' tunables with their values as JSON (with --tuning, as that file
    /// sets them) and exit.
    #[arg(long, conflicts_with_all = ["input", "output", "input_dir", "list"])]
    pub print_tuning: bool,
    /// Erosion element side for the inpainted views (pixels, odd); 0 = off. A model that keeps
    /// its input's pixels (the built-in one) has them spared.
    #[arg(long, default_value_t = Options::default().erode, value_parser = window_side)]
    pub erode: usize,
    /// Median window side over each inpainted view's XYZ before re-projection (pixels, odd);
    /// 0 = off. A model that keeps its input's pixels (the built-in one) has them spared.
    #[arg(long, default_value_t = Options::default().smooth, value_parser = window_side)]
    pub smooth: usize,
    /// Keep the network's XYZ as it predicts them, instead of moving each onto its pixel's ray
    /// at the predicted depth (a model that keeps its input's pixels leaves those where they
    /// were measured either way).
    #[arg(long)]
    pub no_snap: bool,
    #[command(flatten)]
    pub sor: SorOptions,
    /// A completed point within this distance of a measured or mirrored one is not added; a
    /// share of the object's size (the side of the network's box: 0.05 is 3.2 pixels of a 64²
    /// view, 6.4 of a 128² one).
    #[arg(
        long,
        value_name = "D",
        value_parser = distance,
        default_value_t = Options::default().merge_distance
    )]
    pub merge_distance: f64,
    /// A completed point nearer than this to a measured or mirrored one (and beyond the merge
    /// distance) is added only where the network is sure of it (--near-occupancy): next to
    /// what was measured a doubtful point costs more than it fills. A share of the object's
    /// size; the merge distance or less turns it off.
    #[arg(
        long,
        value_name = "D",
        value_parser = distance,
        default_value_t = Options::default().near_distance
    )]
    pub near_distance: f64,
    /// The occupancy (a probability) a completed point within --near-distance needs.
    #[arg(
        long,
        value_name = "P",
        value_parser = probability,
        default_value_t = Options::default().near_occupancy
    )]
    pub near_occupancy: f64,
    /// The network's points further than this above or below the measured points, or beyond
    /// the width they and their mirror images span, are dropped; a share of the object's size,
    /// `inf` keeps them all.
    #[arg(
        long,
        value_name = "M",
        value_parser = distance,
        default_value_t = Options::default().box_margin
    )]
    pub box_margin: f64,
    /// The network's added points are thinned to one per cube of this side (a share of the
    /// object's size: 0.025 is 3.2 pixels of a 128² view); 0 keeps them all.
    #[arg(
        long,
        value_name = "D",
        value_parser = distance,
        default_value_t = Options::default().thin
    )]
    pub thin: f64,
    /// Write a PNG (JPEG for .jpg/.jpeg; other extensions are refused) of input and output
    /// from three viewpoints, completed points tinted.
    #[arg(long, conflicts_with = "output_dir")]
    pub preview: Option<PathBuf>,
    /// Print the time of each stage (the paper's Table 4 breakdown).
    #[arg(long)]
    pub timings: bool,
    /// Print the results as JSON on stdout.
    #[arg(long)]
    pub json: bool,
    #[command(flatten)]
    pub input_options: InputOptions,
    #[command(flatten)]
    pub output_options: OutputOptions,
}

#[derive(Debug, Args)]
pub struct ProjectArgs {
    /// Input cloud (PLY, PCD, LAS/LAZ, XYZ; `-`: standard input).
    pub input: PathBuf,
    /// Directory for the view images and frame.json (created if missing).
    pub outdir: PathBuf,
    /// Rig cameras (1–20) to render.
    #[arg(long, default_value_t = ViewList(DEFAULT_VIEWS.to_vec()))]
    pub views: ViewList,
    /// Image side in pixels.
    #[arg(long, default_value_t = 256)]
    pub size: usize,
    /// Input's up axis [default: z for LAS/LAZ, y otherwise].
    #[arg(long, value_enum)]
    pub up: Option<UpAxis>,
    #[command(flatten)]
    pub input_options: InputOptions,
}

#[derive(Debug, Args)]
pub struct ReprojectArgs {
    /// Directory of view images (as written by `mvpcc project`, or the original dataset's).
    pub viewdir: PathBuf,
    /// Output cloud (`-`: standard output, with --out-format).
    pub output: PathBuf,
    /// Rig cameras to use [default: every locations_NNN.png found].
    #[arg(long)]
    pub views: Option<ViewList>,
    /// Erosion element side in pixels (odd) before re-projection; 0 = off. Meant for dense
    /// (inpainted) views: it removes most of a raw sparse scan.
    #[arg(long, default_value_t = ReprojectOptions::default().erode, value_parser = window_side)]
    pub erode: usize,
    /// Median window side over each view's XYZ before re-projection (pixels, odd); 0 = off.
    #[arg(long, default_value_t = ReprojectOptions::default().smooth, value_parser = window_side)]
    pub smooth: usize,
    /// Points closer than this (normalized units) to an earlier point are dropped; 0 = off.
    #[arg(long, default_value_t = ReprojectOptions::default().dedup_tolerance, value_parser = distance)]
    pub dedup: f64,
    /// Write normalized coordinates even when the directory has a frame.json.
    #[arg(long)]
    pub normalized: bool,
    #[command(flatten)]
    pub sor: SorOptions,
    #[command(flatten)]
    pub output_options: OutputOptions,
}

#[derive(Debug, Args)]
pub struct FilterArgs {
    /// Input cloud (`-`: standard input).
    pub input: PathBuf,
    /// Output cloud (inliers, with all their attributes; `-`: standard output, with --out-format).
    pub output: PathBuf,
    #[command(flatten)]
    pub sor: SorOptions,
    #[command(flatten)]
    pub input_options: InputOptions,
    #[command(flatten)]
    pub output_options: OutputOptions,
}

#[derive(Debug, Args)]
pub struct ProfileArgs {
    /// Model shape: `builtin` (the one `complete` runs), a preset (cpu, paper, original, small,
    /// tiny) or a JSON file holding a model config (as a run's config.json); the options below
    /// override its fields [default: builtin].
    #[arg(long)]
    pub config: Option<String>,
    /// Where the network runs (GPUs: docs/gpu.md).
    #[arg(long, value_enum, default_value_t = DeviceChoice::Cpu)]
    pub device: DeviceChoice,
    /// View image side in pixels.
    #[arg(long)]
    pub size: Option<usize>,
    /// Channels after the first convolution.
    #[arg(long)]
    pub width: Option<usize>,
    /// Residual blocks in the encoder.
    #[arg(long)]
    pub res_blocks: Option<usize>,
    /// Views per object.
    #[arg(long)]
    pub views: Option<usize>,
    /// Image channels the model reads and writes.
    #[arg(long, value_enum)]
    pub channels: Option<Channels>,
    /// How the convolutions see past the image border.
    #[arg(long, value_enum)]
    pub padding: Option<Padding>,
    /// Objects per forward pass (per training step with --train).
    #[arg(long, default_value_t = 1)]
    pub batch: usize,
    /// Time whole GAN training steps (both networks' forward, backward and Adam updates, every
    /// loss term) instead of the generator's forward.
    #[arg(long)]
    pub train: bool,
    /// How layers with two formulations run: sliced on the CPU and plain elsewhere (auto), or
    /// one of them everywhere, to measure one against the other.
    #[arg(long, value_enum, default_value_t = Formulation::Auto)]
    pub layers: Formulation,
    /// Timed runs; the per-layer or per-phase breakdown takes as many more.
    #[arg(long, default_value_t = 5)]
    pub runs: usize,
    /// Untimed runs first: GPU autotuning benchmarks each new kernel shape in them.
    #[arg(long, default_value_t = 2)]
    pub warmup: usize,
    /// Print the results as JSON.
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, Args)]
pub struct PrepareArgs {
    /// Directory of meshes (OBJ+MTL, PLY, glTF/GLB), as DIR/CATEGORY/NAME.* or ShapeNet's
    /// DIR/SYNSET/ID/models/model_normalized.obj.
    #[arg(long, required_unless_present = "synth", conflicts_with = "synth")]
    pub meshes: Option<PathBuf>,
    /// Generate this many street objects into OUT/meshes first and prepare those.
    #[arg(long)]
    pub synth: Option<usize>,
    /// Prepare only part I of N of the meshes (I from 0 to N-1, chosen by a hash of category
    /// and name), so N jobs sharing OUT prepare each mesh once; a last run without --shard
    /// finds them all prepared and writes the manifest.
    #[arg(long, value_name = "I/N", requires = "meshes")]
    pub shard: Option<Shard>,
    #[command(flatten)]
    pub synth_options: SynthOptions,
    /// Output data directory (created if missing; an interrupted run resumes in it).
    #[arg(long)]
    pub out: PathBuf,
    /// Fraction of models in the train split; the rest is test.
    #[arg(long, default_value_t = 0.93)]
    pub split: f64,
    /// Partial samples per model.
    #[arg(long, default_value_t = 20)]
    pub samples: usize,
    /// Rig cameras of the training views.
    #[arg(long, default_value_t = ViewList(DEFAULT_VIEWS.to_vec()))]
    pub views: ViewList,
    /// Training view side in pixels.
    #[arg(long, default_value_t = 256)]
    pub size: usize,
    /// Render size of the 20 rig cameras the ground truth is sampled with.
    #[arg(long, default_value_t = 512)]
    pub gt_size: usize,
    /// Ground-truth voxel (normalized units): one point is kept per voxel.
    #[arg(long, default_value_t = 1.0 / 256.0)]
    pub gt_voxel: f32,
    /// Which partial scans to make.
    #[arg(long, value_enum, default_value_t = PartialParams::default().kinds)]
    pub partial: PartialKinds,
    /// Fewest points a partial is aimed at (drawn log-uniformly up to --max-points).
    #[arg(long, default_value_t = PartialParams::default().min_points)]
    pub min_points: usize,
    /// Most points a partial is aimed at.
    #[arg(long, default_value_t = PartialParams::default().max_points)]
    pub max_points: usize,
    /// Largest angle (degrees) between the simulated scanner's path and the object's axis.
    #[arg(long, default_value_t = PartialParams::default().max_yaw_deg)]
    pub yaw_error: f32,
    /// Largest range-noise standard deviation of the scanner (normalized units).
    #[arg(long, default_value_t = PartialParams::default().max_noise)]
    pub noise: f32,
    /// The meshes' up axis (x, y, z, -x, -y, -z).
    #[arg(long, default_value = "y", allow_hyphen_values = true)]
    pub up: SignedAxis,
    /// The axis the meshes' fronts point along (ShapeNet: -z), or auto: the longer horizontal
    /// side of each mesh's box is its length, which end is the front left undecided.
    #[arg(long, default_value = "-z", allow_hyphen_values = true)]
    pub forward: Forward,
    /// Which partial clouds are written as PLY beside the views (gt.ply always is).
    #[arg(long, value_enum, default_value_t = CloudPolicy::Test)]
    pub clouds: CloudPolicy,
    /// Use the material colour where an MTL file or a texture is missing, instead of skipping
    /// the mesh.
    #[arg(long)]
    pub allow_missing_materials: bool,
    /// Meshes with more triangles are skipped.
    #[arg(long, default_value_t = 5_000_000)]
    pub max_triangles: usize,
    /// Print the run's summary as JSON on stdout.
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, Args)]
pub struct SynthArgs {
    /// Number of objects (with --scene: of streets).
    #[arg(long)]
    pub count: usize,
    /// Output directory; objects go to OUT/CATEGORY/CATEGORY_NNNNN.obj.
    #[arg(long)]
    pub out: PathBuf,
    /// Whole scanned streets instead of objects, for `complete --scene`: OUT/street_NNNNN.las
    /// (z up, in UTM-sized metres, classified; each point's object in the `object` attribute;
    /// vehicles are class 64) and the objects' truth in OUT/street_NNNNN.json (docs/scenes.md).
    #[arg(long, conflicts_with_all = ["preview", "category"])]
    pub scene: bool,
    /// With --scene: each street's length in metres.
    #[arg(long, requires = "scene", default_value_t = StreetParams::default().length)]
    pub length: f32,
    #[command(flatten)]
    pub synth_options: SynthOptions,
    /// Also write OUT/preview.png: the first 16 objects rendered from one camera.
    #[arg(long)]
    pub preview: bool,
}

/// What `synth` draws from, shared with `prepare --synth`.
#[derive(Debug, Args)]
pub struct SynthOptions {
    /// Categories to draw from (with --synth): car, bus, truck, train, motorcycle, each as NAME
    /// or NAME=WEIGHT, how often it is drawn relative to the others (by default car 4, the
    /// others 1: cars are most of what a mapping car drives past), e.g. car,motorcycle=2.
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "car,bus,truck,train,motorcycle"
    )]
    pub category: Vec<Draw>,
    /// Seed of everything random: objects, samples, noise.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
}

/// `mvpcc train`. Options left out take their defaults on a new run and the run's saved
/// values (train.json, config.json) on `--resume`, where giving a different value is an error
/// for everything but the operational options (steps, device, workers, prefetch, cache, log
/// interval, checkpoints kept).
#[derive(Debug, Args)]
pub struct TrainArgs {
    /// Data: DIR/GT/train/CATEGORY/MODEL/ with DIR/in/train/CATEGORY/MODEL/K/; GT/test
    /// validates when present, else a share of the training models is held back.
    #[arg(long)]
    pub data: PathBuf,
    /// Run directory: checkpoints/, best/, generator.safetensors, log.jsonl, losses.png,
    /// samples/ [default: runs/DATA, DATA the data directory's name].
    #[arg(long)]
    pub out: Option<PathBuf>,
    #[arg(long, help = defaulted("Rig cameras the model sees", ViewList(train().views)))]
    pub views: Option<ViewList>,
    /// Image channels the model reads and writes [default: xyzrgb].
    #[arg(long, value_enum)]
    pub channels: Option<Channels>,
    /// Model shape: `builtin` (the built-in model's, with fresh weights), a preset (cpu, paper,
    /// original, small, tiny) or a JSON file holding a model config (as a run's config.json).
    /// `paper` follows the paper's text where it and the original code differ, in the network
    /// and the loss; `original` follows the original code (docs/paper.md, *The presets*)
    /// [default: builtin].
    #[arg(long)]
    pub config: Option<String>,
    /// View image side in pixels, over the config's (e.g. a 64² model's weights at 128²).
    #[arg(long)]
    pub size: Option<usize>,
    /// Where the views meet: late (the bottleneck features, the paper's network) or early (the
    /// input images, before the shared encoder; the paper's Table 6) [default: the config's].
    #[arg(long, value_enum)]
    pub fusion: Option<Fusion>,
    /// Which convolutions are dilated: the encoder's residual blocks (the original code) or the
    /// decoder's upsampling (the paper's text) [default: the config's].
    #[arg(long, value_enum)]
    pub dilation: Option<Dilation>,
    /// Instance norm after the fusion convolution (the original code: true; the paper's text:
    /// false) [default: the config's].
    #[arg(long, value_name = "BOOL")]
    pub fusion_norm: Option<bool>,
    /// Keep the input's pixels: the generator's output is the input wherever the input has a pixel,
    /// so it learns only the pixels it completes (docs/pipeline.md, *6. The network*) [default: the
    /// config's]
    #[arg(long)]
    pub input_copy: bool,
    /// The occupancy threshold saved with the weights, which `complete` uses unless told otherwise:
    /// chosen on the validation split (lab/2026-12-02-occupancy-threshold). `--init W --steps 0`
    /// writes W's weights with it [default: the config's]
    #[arg(long, value_name = "P")]
    pub occupancy: Option<f64>,
    /// Start a new run from trained weights, with fresh optimizers: a generator's weights file,
    /// a run directory (its generator.safetensors, and discriminator.safetensors when there) or
    /// a folder holding model.safetensors and, when there, discriminator.safetensors (as
    /// assets/). The model config is the weights' own unless --config gives one; only --size
    /// and --input-copy may differ from it, and --channels xyz from a colour model's (its colour
    /// weights dropped, a fresh discriminator).
    #[arg(long, conflicts_with = "resume")]
    pub init: Option<PathBuf>,
    /// The discriminator's weights to start from with --init, over the one --init finds.
    #[arg(long, requires = "init")]
    pub init_discriminator: Option<PathBuf>,
    /// Widen --init's generator to this width: its channels keep their weights and the new ones
    /// start without effect, so the run starts from its output (docs/training.md, *Starting from
    /// trained weights*). The discriminator starts fresh unless --init-discriminator names one for
    /// the new width.
    #[arg(long, requires = "init", conflicts_with = "config")]
    pub widen: Option<usize>,
    /// Where training runs (GPUs: docs/gpu.md).
    #[arg(long, value_enum, default_value_t = DeviceChoice::Cpu)]
    pub device: DeviceChoice,
    /// Train data-parallel on several devices: `cuda:0,cuda:1`, `all` (every CUDA device), or
    /// `cpu,cpu` (replicas sharing the cores, for tests). Each takes its share of every
    /// micro-batch; their gradients are summed into one step on the first, which keeps the
    /// weights, validates and checkpoints (docs/training.md, *Several devices*).
    #[arg(long, value_name = "LIST", conflicts_with = "device")]
    pub devices: Option<String>,
    #[arg(long, help = defaulted("Objects per micro-batch", train().batch))]
    pub batch: Option<usize>,
    #[arg(long, help = defaulted("Micro-batches accumulated into one optimizer step", train().accumulate))]
    pub accumulate: Option<usize>,
    /// Stop after this many steps in all (a resumed run counts its earlier steps).
    #[arg(long)]
    pub steps: Option<u64>,
    /// Continue the run in --out from its latest checkpoint.
    #[arg(long)]
    pub resume: bool,
    #[arg(long, help = defaulted(
        "Generator learning rate of the first stage; the second and third use 1/10 and 1/100 of it",
        train().stage_rates[0],
    ))]
    pub lr: Option<f64>,
    #[arg(long, help = defaulted("Most steps per stage", train().stage_steps))]
    pub stage_steps: Option<u64>,
    #[arg(long, help = defaulted(
        "Validations without a better CD after which a stage ends",
        train().patience,
    ))]
    pub patience: Option<usize>,
    #[arg(long, help = defaulted("Steps between validations; 0 = never", train().val_every))]
    pub val_every: Option<u64>,
    #[arg(long, help = defaulted(
        "Validation samples (spread over the validation models)",
        train().val_samples,
    ))]
    pub val_samples: Option<usize>,
    #[arg(long, help = defaulted(
        "Training samples scored beside the validation samples, to show what the network \
         memorized; 0 = none",
        train().seen_samples,
    ))]
    pub seen_samples: Option<usize>,
    #[arg(long, help = defaulted(
        "Share of training models held back for validation when the data has no test split",
        train().val_fraction,
    ))]
    pub val_fraction: Option<f64>,
    #[arg(long, help = defaulted("Steps between checkpoints", train().checkpoint_every))]
    pub checkpoint_every: Option<u64>,
    #[arg(long, help = defaulted("Checkpoints kept besides best/", train().keep))]
    pub keep: Option<usize>,
    #[arg(long, help = defaulted("Steps between lines of log.jsonl", train().log_every))]
    pub log_every: Option<u64>,
    #[arg(long, help = defaulted(
        "Seed of initialization, sample order and augmentation",
        train().seed,
    ))]
    pub seed: Option<u64>,
    /// Do not mirror samples x ↔ −x.
    #[arg(long)]
    pub no_mirror: bool,
    #[arg(long, help = defaulted(
        "Largest random yaw of a sample, degrees; 0 = off",
        train().augment.max_yaw_deg,
    ))]
    pub max_yaw: Option<f32>,
    #[arg(long, help = defaulted(
        "Largest relative colour gain change; 0 = off",
        train().augment.color_jitter,
    ))]
    pub color_jitter: Option<f32>,
    /// torchvision's VGG19 weights (vgg19-dcbd0d2f.pth, or safetensors with its keys): the
    /// perceptual and style terms then use VGG19 features as the paper does, instead of the
    /// discriminator's.
    #[arg(long)]
    pub vgg19: Option<PathBuf>,
    #[arg(long, help = defaulted(
        "Weight of the smooth L1 term (the defaults of all six are the original code's)",
        train().loss.l1,
    ))]
    pub loss_l1: Option<f64>,
    #[arg(long, help = defaulted("Weight of the adversarial term", train().loss.adversarial))]
    pub loss_adversarial: Option<f64>,
    #[arg(long, help = defaulted(
        "Weight of the perceptual term (the paper's text: 250)",
        train().loss.perceptual,
    ))]
    pub loss_perceptual: Option<f64>,
    #[arg(long, help = defaulted(
        "Weight of the style term (the paper's text: 0.1)",
        train().loss.style,
    ))]
    pub loss_style: Option<f64>,
    #[arg(long, help = defaulted("Weight of the occupancy BCE term", train().loss.occupancy))]
    pub loss_bce: Option<f64>,
    #[arg(long, help = defaulted(
        "Weight of the total-variation term, further divided by the image side",
        train().loss.tv,
    ))]
    pub loss_tv: Option<f64>,
    #[arg(long, help = defaulted(
        "Weight of the depth term: smooth L1 on each occupied pixel's depth along its view's \
         camera axis, the part of its XYZ `complete` keeps (not in the original)",
        train().loss.depth,
    ))]
    pub loss_depth: Option<f64>,
    #[arg(long, value_enum, help = defaulted(
        "Adversarial loss",
        train().loss.adversarial_kind.to_possible_value().map_or_else(String::new, |v| v.get_name().to_owned()),
    ))]
    pub adversarial: Option<Adversarial>,
    /// What the total-variation weight is divided by: side (the original code's S) or pixels
    /// (the paper's text: S²) [default: side; pixels with --config paper].
    #[arg(long, value_enum)]
    pub tv_scale: Option<TvScale>,
    /// The planes the perceptual and style terms compare through VGG19 (--vgg19): all, or
    /// colour alone (the paper's text; geometry for a model without colour) [default: all;
    /// colour with --config paper].
    #[arg(long, value_enum)]
    pub feature_planes: Option<FeaturePlanes>,
    #[arg(long, help = defaulted(
        "First learning-rate stage (1-based) with the total-variation term, the original's by default",
        train().tv_from_stage,
    ))]
    pub tv_from_stage: Option<usize>,
    #[arg(long, help = defaulted(
        "Steps over which the learning rate rises linearly from zero to --lr's",
        train().warmup_steps,
    ))]
    pub warmup_steps: Option<u64>,
    /// Threads that load and render samples while the network trains (1–256).
    #[arg(long, default_value_t = 1, value_parser = counts(1, MAX_WORKERS))]
    pub workers: usize,
    /// Steps of data prepared ahead (0–256).
    #[arg(long, default_value_t = 4, value_parser = counts(0, MAX_PREFETCH))]
    pub prefetch: usize,
    /// Memory for decoded samples, MiB; past it samples are decoded again when drawn.
    #[arg(long, default_value_t = DEFAULT_CACHE_MB)]
    pub cache_mb: usize,
    /// Print the run's summary as JSON on stdout.
    #[arg(long)]
    pub json: bool,
}

/// Options of `mvpcc train-orient`.
#[derive(Debug, Args)]
pub struct TrainOrientArgs {
    /// Data: a "shapenet-views" directory (`mvpcc prepare`); its partial samples are used.
    #[arg(long)]
    pub data: PathBuf,
    /// Where orienter.safetensors, config.json, train-orient.json and log.jsonl go [default:
    /// runs/orient-DATA, DATA the data directory's name].
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Training steps.
    #[arg(long, default_value_t = OrientSettings::default().steps)]
    pub steps: u64,
    /// Clouds per step.
    #[arg(long, default_value_t = OrientSettings::default().batch)]
    pub batch: usize,
    /// Adam's learning rate.
    #[arg(long, default_value_t = OrientSettings::default().learning_rate)]
    pub lr: f64,
    /// Points the network reads from a cloud.
    #[arg(long, default_value_t = OrienterConfig::new().points)]
    pub points: usize,
    /// Steps between validations.
    #[arg(long, default_value_t = OrientSettings::default().val_every)]
    pub val_every: u64,
    /// Validation clouds, each turned by a fixed random yaw.
    #[arg(long, default_value_t = OrientSettings::default().val_samples)]
    pub val_samples: usize,
    /// Seed of the samples, yaws, points and noise drawn for training and validation.
    #[arg(long, default_value_t = OrientSettings::default().seed)]
    pub seed: u64,
    /// Where training runs (GPUs: docs/gpu.md).
    #[arg(long, value_enum, default_value_t = DeviceChoice::Cpu)]
    pub device: DeviceChoice,
    /// Memory for decoded samples, MiB; past it samples are decoded again when drawn.
    #[arg(long, default_value_t = DEFAULT_CACHE_MB)]
    pub cache_mb: usize,
}

/// A probability strictly between 0 and 1.
fn probability(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(p) if p > 0.0 && p < 1.0 => Ok(p),
        _ => Err(format!("{text} is not a probability between 0 and 1")),
    }
}

fn positive_length(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(w) if w.is_finite() && w > 0.0 => Ok(w),
        _ => Err(format!("{text} is not a positive length")),
    }
}

/// A streamed tile's chunk side: at least 20 m, since each chunk also reads 25 m around it and a
/// narrower one copies each point into a dozen chunks and more; at most what leaves a chunk
/// with its margins within the widest scene searched at once.
fn chunk_side(text: &str) -> Result<f64, String> {
    let widest = mvpcc::scene::MAX_SPAN - 2.0 * StreamParams::default().margin;
    match text.parse::<f64>() {
        Ok(w) if (20.0..=widest).contains(&w) => Ok(w),
        _ => Err(format!(
            "{text} is not a chunk side from 20 to {widest} metres"
        )),
    }
}

fn non_negative(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(x) if x >= 0.0 => Ok(x),
        _ => Err(format!("{text} is not a number of 0 or more")),
    }
}

/// An erosion element's or median window's side: 0 (off) or odd, so that it centres on its
/// pixel (an even side was silently taken as the next odd one), at most [`MAX_WINDOW`].
fn window_side(text: &str) -> Result<usize, String> {
    match text.parse::<usize>() {
        Ok(k) if k > MAX_WINDOW => Err(format!("{k} is wider than {MAX_WINDOW} pixels")),
        Ok(k) if k > 0 && k % 2 == 0 => Err(format!(
            "{k} is even; a window centred on its pixel has an odd side (0 turns it off)"
        )),
        Ok(k) => Ok(k),
        Err(_) => Err(format!("{text} is not a window side in pixels")),
    }
}

fn distance(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(d) if d >= 0.0 => Ok(d),
        _ => Err(format!("{text} is not a distance of 0 or more")),
    }
}

/// The training defaults, written once in the library.
fn train() -> TrainSettings {
    TrainSettings::default()
}

/// `text` followed by its default as clap shows defaults: for options kept as `Option`s, so a
/// resumed run can tell the options given from the ones left out.
fn defaulted(text: &str, value: impl std::fmt::Display) -> String {
    format!("{text} [default: {value}]")
}
