//! Completing files: one file end to end (read, complete, write, preview, saved views) and a
//! batch of files (a tree, a list, a shard of either) on a pool of workers, where one bad file
//! never stops the others.

use super::{create_dir, PathError, Progress};
use crate::complete::clean::CleanReport;
use crate::complete::preview::{render, Layer};
use crate::complete::symmetry::PlaneReport;
use crate::complete::{CompleteError, Completer, Completion, Method, Settings, Timings, SYNTHETIC};
use crate::core::cloud::PointCloud;
use crate::io::batch::{self, read_list, walk, BatchError, Shard};
use crate::io::stdio::is_stdio;
use crate::io::{
    atomic_write, check_output, non_finite_warning, read_cloud, same_file, unwritten, write_cloud,
    CloudIoError, Encoding, Format, Problem,
};
use crate::scene::preview::plan_view;
use crate::scene::stream::{complete_tile, tile_header, StreamError, StreamParams, TileJob};
use crate::scene::{
    complete_scene, find_objects, SceneError, SceneParams, Selection, VehicleReport, Verdict,
    CLASSIFICATION,
};
use crate::views::{write_views, ViewError};
use serde::Serialize;
use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;
use std::time::Instant;
use thiserror::Error;

#[derive(Debug, Error)]
pub enum FileError {
    #[error(transparent)]
    Path(#[from] PathError),
    #[error(transparent)]
    Cloud(#[from] CloudIoError),
    #[error(transparent)]
    Views(#[from] ViewError),
    #[error("{}: {source}", path.display())]
    Complete {
        path: PathBuf,
        source: CompleteError,
    },
    #[error("{}: {source}", path.display())]
    OutputFormat { path: PathBuf, source: Problem },
    #[error("{path}: is a directory; complete a folder with --input-dir {path} --output-dir OUT", path = .0.display())]
    InputIsDirectory(PathBuf),
    #[error("-: --json and the completed cloud cannot both go to standard output")]
    ReportAndCloudOnStdout,
    #[error("{}: --preview names the output cloud", .0.display())]
    PreviewIsOutput(PathBuf),
    #[error("{}: unsupported preview extension \"{extension}\" (expected png, jpg or jpeg)", path.display())]
    PreviewExtension { path: PathBuf, extension: String },
    #[error("{}: cannot write the preview: {source}", path.display())]
    Preview {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{}: --save-views needs a directory", .0.display())]
    ViewsNotADirectory(PathBuf),
    #[error("{}: --save-views names an output file", .0.display())]
    ViewsIsOutput(PathBuf),
    #[error("{}: {source}", path.display())]
    Scene { path: PathBuf, source: SceneError },
    #[error(transparent)]
    Tile(#[from] StreamError),
}

#[derive(Debug, Error)]
pub enum BatchRunError {
    #[error(transparent)]
    Path(#[from] PathError),
    #[error(transparent)]
    Batch(#[from] BatchError),
    #[error(transparent)]
    File(#[from] FileError),
    #[error("{}: not a directory", .0.display())]
    NotADirectory(PathBuf),
    #[error("{}: exists and is not a directory", .0.display())]
    OutputNotADirectory(PathBuf),
    #[error("{}: no file matches --include '{include}'", root.display())]
    NoMatch { root: PathBuf, include: String },
    #[error("{}: no point cloud files", .0.display())]
    NoClouds(PathBuf),
    #[error("{} and {} would both be written to {}; rename one or complete them apart", first.display(), second.display(), target.display())]
    SameOutput {
        first: PathBuf,
        second: PathBuf,
        target: PathBuf,
    },
}

/// How files are read and written around the pipeline.
#[derive(Debug, Clone, Default)]
pub struct FileOptions {
    /// The inputs' format, overriding their extensions.
    pub input_format: Option<Format>,
    /// The outputs' format, overriding their extensions.
    pub out_format: Option<Format>,
    pub encoding: Encoding,
    /// A picture of the input beside the completion (one file only).
    pub preview: Option<PathBuf>,
    /// The caller writes its report to standard output, so the cloud may not go there.
    pub report_on_stdout: bool,
}

/// What completes each file: the loaded networks, the pipeline's settings for an input (its
/// up axis depends on its format), and the file options.
pub struct Job<'a> {
    pub completer: &'a Completer,
    pub settings: &'a (dyn Fn(&Path) -> Settings + Sync),
    pub files: FileOptions,
    /// Each file is a whole street scan whose vehicles are completed in place (`--scene`).
    pub scene: Option<SceneJob>,
}

/// How the vehicles of a street scan are found (`complete --scene`).
#[derive(Debug, Clone)]
pub struct SceneJob {
    pub selection: Selection,
    pub params: SceneParams,
    pub stream: StreamParams,
}

/// What `complete --scene` reports of one scan besides [`FileReport`]'s totals.
#[derive(Debug, Serialize)]
pub struct SceneReport {
    pub ground_points: usize,
    /// Objects the size test looked at, vehicles or not.
    pub objects: usize,
    pub vehicles: Vec<VehicleReport>,
    /// Objects that are no vehicle, by why.
    pub rejected: BTreeMap<String, usize>,
    /// Chunks a tile too large to hold was streamed in (`StreamParams::from_points`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub chunks: Option<usize>,
    /// Points of the largest chunk with its margins, which bounds the memory.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub largest_chunk: Option<usize>,
}

/// What `complete --json` reports for one file.
#[derive(Debug, Serialize)]
pub struct FileReport {
    pub input: PathBuf,
    pub output: PathBuf,
    pub method: Method,
    pub input_points: usize,
    pub output_points: usize,
    pub added: usize,
    pub mirrored: usize,
    pub filtered_out: usize,
    /// Objects the network completed: 2 with the mirrored pass (and a plane), 1 with
    /// `--no-mirror-pass`, 0 without the network.
    pub network_passes: usize,
    pub symmetry_plane: Option<PlaneReport>,
    pub orientation: OrientationReport,
    pub cleaned: Option<CleanReport>,
    pub warnings: Vec<String>,
    /// Seconds per stage, as `timings` lists them.
    pub seconds: BTreeMap<String, f64>,
    #[serde(skip)]
    pub timings: Timings,
    /// Each vehicle of a street scan (`--scene`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub scene: Option<SceneReport>,
}

impl FileReport {
    /// The line said for one completed file.
    pub fn summary(&self) -> String {
        if let Some(scene) = &self.scene {
            let completed = scene.vehicles.iter().filter(|v| v.failed.is_none()).count();
            return format!(
                "{}: {} points → {} ({} completed for {} of {}{}) in {:.2} s",
                self.output.display(),
                self.input_points,
                self.output_points,
                self.added,
                count(completed, "vehicle"),
                count(scene.objects, "object"),
                scene.chunks.map_or(String::new(), |n| format!(
                    "; streamed in {}",
                    count(n, "chunk")
                )),
                self.seconds.get("total").copied().unwrap_or_default()
            );
        }
        format!(
            "{}: {} points → {} ({} completed{}{}) in {:.2} s",
            self.output.display(),
            self.input_points,
            self.output_points,
            self.added,
            if self.mirrored > 0 {
                format!(", {} of them mirrored", self.mirrored)
            } else {
                String::new()
            },
            self.orientation.heading.map_or(String::new(), |h| format!(
                "; heading {h:.1}° ({})",
                self.orientation.method
            )),
            self.timings.total().as_secs_f64()
        )
    }
}

#[derive(Debug, Serialize)]
pub struct OrientationReport {
    pub heading: Option<f64>,
    pub method: &'static str,
    pub refinement: Option<f64>,
    pub refined_by: Option<&'static str>,
    /// The lean across the width the frame took out, degrees.
    pub roll: f64,
}

/// The output format: `out_format`, else the output's extension, else (standard output or no
/// extension) the input's format. An extension no format has is refused rather than read as
/// none: `out.plyy` written as the input's PCD would be a surprise.
fn output_format(opts: &FileOptions, input: &Path, output: &Path) -> Result<Format, FileError> {
    let named = output.extension().is_some() && !is_stdio(output);
    let format = if opts.out_format.is_some() || named {
        Format::of_output(output, opts.out_format)
    } else {
        Format::of_input(input, opts.input_format)
    };
    format.map_err(|source| FileError::OutputFormat {
        path: output.to_path_buf(),
        source,
    })
}

/// Completes `input` into `output` (and the network's views into `views`, when given).
pub fn complete_file(
    input: &Path,
    output: &Path,
    views: Option<&Path>,
    job: &Job,
) -> Result<FileReport, FileError> {
    let opts = &job.files;
    check_paths(input, output, views, opts)?;
    let format = output_format(opts, input, output)?;
    if let Some(scene) = &job.scene {
        if let Some(compressed) = streamed(input, output, format, opts, scene)? {
            let settings = (job.settings)(input);
            return complete_tile_file(input, output, compressed, scene, &settings, job);
        }
    }
    let start = Instant::now();
    let loaded = read_cloud(input, opts.input_format)?;
    let cloud = loaded.cloud;
    let read = start.elapsed();
    let settings = (job.settings)(input);
    if let Some(scene) = &job.scene {
        let dropped = loaded.non_finite_dropped;
        return complete_scene_file(
            input, output, format, cloud, dropped, read, scene, &settings, job,
        );
    }
    let mut run = job
        .completer
        .run(&cloud, &settings)
        .map_err(|source| FileError::Complete {
            path: input.to_path_buf(),
            source,
        })?;
    let saved = match views {
        Some(dir) => save_views(dir, &run.completion)?,
        None => None,
    };
    let lost = unwritten(&run.completion.cloud, format, output);
    let warnings = &mut run.completion.warnings;
    warnings.splice(0..0, non_finite_warning(loaded.non_finite_dropped));
    warnings.extend(saved);
    warnings.extend(lost);
    let done = &run.completion;
    let start = Instant::now();
    write_cloud(output, &done.cloud, Some(format), opts.encoding)?;
    let timings = Timings {
        read,
        write: start.elapsed(),
        ..done.timings
    };
    if let Some(path) = &opts.preview {
        let measured = run.cleaned.as_ref().map_or(&cloud, |(c, _)| c);
        write_preview(path, measured, done)?;
    }
    let done = run.completion;
    Ok(FileReport {
        input: input.to_path_buf(),
        output: output.to_path_buf(),
        method: settings.options.method,
        input_points: done.input_points,
        output_points: done.cloud.len(),
        added: done.added,
        mirrored: done.mirrored,
        filtered_out: done.filtered_out,
        network_passes: done.network_passes,
        symmetry_plane: done.plane.map(|p| p.report(&done.frame)),
        orientation: OrientationReport {
            heading: run.orientation.heading,
            method: run.orientation.method,
            refinement: run.orientation.refinement,
            refined_by: run.orientation.refined_by,
            roll: done.roll,
        },
        cleaned: run.cleaned.map(|(_, report)| report),
        warnings: done.warnings,
        seconds: timings
            .stages()
            .iter()
            .map(|(name, d)| (name.replace('-', ""), d.as_secs_f64()))
            .collect(),
        timings,
        scene: None,
    })
}

/// [`complete_file`] for a whole street scan (`--scene`): every vehicle found completed in
/// place, the scan written back with the completed points appended.
#[allow(clippy::too_many_arguments)]
fn complete_scene_file(
    input: &Path,
    output: &Path,
    format: Format,
    cloud: PointCloud,
    non_finite_dropped: usize,
    read: std::time::Duration,
    scene: &SceneJob,
    settings: &Settings,
    job: &Job,
) -> Result<FileReport, FileError> {
    let fail = |source| FileError::Scene {
        path: input.to_path_buf(),
        source,
    };
    let start = Instant::now();
    let objects =
        find_objects(&cloud, settings.options.up, &scene.selection, &scene.params).map_err(fail)?;
    let done = complete_scene(
        &cloud,
        &objects,
        job.completer,
        settings,
        &scene.params.narrowest,
    )
    .map_err(fail)?;
    let mut warnings: Vec<String> = non_finite_warning(non_finite_dropped).into_iter().collect();
    let classes = cloud.attribute(CLASSIFICATION).map(|a| &a.values);
    let used = |code: u8| classes.is_some_and(|v| v.iter().any(|&c| c == f64::from(code)));
    warnings.extend(scene_warnings(
        scene,
        used,
        objects.objects.len(),
        &done.vehicles,
    ));
    warnings.extend(unwritten(&done.cloud, format, output));
    let completing = start.elapsed();
    let start = Instant::now();
    write_cloud(output, &done.cloud, Some(format), job.files.encoding)?;
    if let Some(path) = &job.files.preview {
        write_image(
            path,
            &plan_view(&done.cloud, cloud.len(), settings.options.up),
        )?;
    }
    let timings = Timings {
        read,
        write: start.elapsed(),
        ..Timings::default()
    };
    let outcome = SceneOutcome {
        input_points: cloud.len(),
        output_points: done.cloud.len(),
        ground_points: objects.ground_points,
        verdicts: objects.objects.iter().map(|o| o.verdict).collect(),
        vehicles: done.vehicles,
        chunks: None,
    };
    Ok(scene_file_report(
        input, output, settings, outcome, warnings, timings, completing,
    ))
}

/// Whether `input` is completed as a tile streamed in chunks: a LAS/LAZ file into a LAS/LAZ
/// file, with at least [`StreamParams::from_points`] points; then whether the output is LAZ.
fn streamed(
    input: &Path,
    output: &Path,
    format: Format,
    opts: &FileOptions,
    scene: &SceneJob,
) -> Result<Option<bool>, FileError> {
    let las = |f: Format| matches!(f, Format::Las | Format::Laz);
    let input_format = Format::of_input(input, opts.input_format).ok();
    if !las(format) || !input_format.is_some_and(las) || is_stdio(input) || is_stdio(output) {
        return Ok(None);
    }
    let header = tile_header(input)?;
    Ok((header.points >= scene.stream.from_points).then_some(format == Format::Laz))
}

/// [`complete_scene_file`] for a tile too large to hold: streamed in chunks
/// ([`crate::scene::stream`]).
fn complete_tile_file(
    input: &Path,
    output: &Path,
    compressed: bool,
    scene: &SceneJob,
    settings: &Settings,
    job: &Job,
) -> Result<FileReport, FileError> {
    let tile = TileJob {
        up: settings.options.up,
        selection: &scene.selection,
        params: &scene.params,
        stream: scene.stream,
        completer: job.completer,
        settings,
        preview: job.files.preview.is_some(),
    };
    let done = complete_tile(input, output, compressed, &tile)?;
    let mut warnings = Vec::new();
    let used = |code: u8| done.classes.contains(&code);
    warnings.extend(scene_warnings(
        scene,
        used,
        done.verdicts.len(),
        &done.vehicles,
    ));
    if let (Some(path), Some(image)) = (&job.files.preview, &done.preview) {
        write_image(path, image)?;
    }
    let passes = done.passes;
    let outcome = SceneOutcome {
        input_points: done.input_points,
        output_points: done.output_points,
        ground_points: done.ground_points,
        verdicts: done.verdicts,
        vehicles: done.vehicles,
        chunks: Some((done.chunks, done.largest_chunk)),
    };
    Ok(scene_file_report(
        input,
        output,
        settings,
        outcome,
        warnings,
        Timings {
            read: passes.spill,
            write: passes.copy,
            ..Timings::default()
        },
        passes.vehicles,
    ))
}

/// The warnings of a completed scene: `--vehicle-class` codes no point uses (`used` says
/// which are), a scene without vehicles, and each vehicle's own.
fn scene_warnings(
    scene: &SceneJob,
    used: impl Fn(u8) -> bool,
    objects: usize,
    vehicles: &[VehicleReport],
) -> Vec<String> {
    let mut warnings = Vec::new();
    if let Selection::Classes(codes) = &scene.selection {
        for &code in codes.iter().filter(|&&c| !used(c)) {
            warnings.push(format!("--vehicle-class {code}: no point has this class"));
        }
    }
    if vehicles.is_empty() {
        warnings.push(format!(
            "no vehicle found among {}; the scan is written unchanged",
            count(objects, "object")
        ));
    }
    for v in vehicles {
        match &v.failed {
            Some(why) => warnings.push(format!("vehicle {} left as scanned: {why}", v.id)),
            None => warnings.extend(v.warnings.iter().map(|w| format!("vehicle {}: {w}", v.id))),
        }
    }
    warnings
}

/// Writes a preview image in the format its extension names.
fn write_image(path: &Path, image: &image::RgbImage) -> Result<(), FileError> {
    let format = preview_format(path)?;
    atomic_write(path, |w| {
        image.write_to(w, format).map_err(std::io::Error::other)
    })
    .map_err(|source| FileError::Preview {
        path: path.to_path_buf(),
        source,
    })
}

/// What completing a scene came to, in memory or streamed.
struct SceneOutcome {
    input_points: usize,
    output_points: usize,
    ground_points: usize,
    /// The size test's verdict on each object, vehicles included.
    verdicts: Vec<Verdict>,
    vehicles: Vec<VehicleReport>,
    /// Chunks the tile was streamed in and the points of the largest with its margins; none
    /// when it was read whole.
    chunks: Option<(usize, usize)>,
}

fn scene_file_report(
    input: &Path,
    output: &Path,
    settings: &Settings,
    outcome: SceneOutcome,
    warnings: Vec<String>,
    timings: Timings,
    completing: std::time::Duration,
) -> FileReport {
    let mut rejected = BTreeMap::new();
    for verdict in outcome.verdicts.iter().filter(|&&v| v != Verdict::Vehicle) {
        let why = serde_json::to_value(verdict).map_or_else(
            |_| String::new(),
            |v| v.as_str().unwrap_or_default().to_string(),
        );
        *rejected.entry(why).or_insert(0) += 1;
    }
    let mut seconds: BTreeMap<String, f64> = timings
        .stages()
        .iter()
        .map(|(name, d)| (name.replace('-', ""), d.as_secs_f64()))
        .collect();
    seconds.insert("vehicles".into(), completing.as_secs_f64());
    // The stages' total counts reading and writing only; the vehicles' time is apart from it.
    let total = timings.total() + completing;
    seconds.insert("total".into(), total.as_secs_f64());
    let vehicles = outcome.vehicles;
    FileReport {
        input: input.to_path_buf(),
        output: output.to_path_buf(),
        method: settings.options.method,
        input_points: outcome.input_points,
        output_points: outcome.output_points,
        added: vehicles.iter().map(|v| v.added).sum(),
        mirrored: vehicles.iter().map(|v| v.mirrored).sum(),
        filtered_out: 0,
        network_passes: 0,
        symmetry_plane: None,
        orientation: OrientationReport {
            heading: None,
            method: "per vehicle",
            refinement: None,
            refined_by: None,
            roll: 0.0,
        },
        cleaned: None,
        warnings,
        seconds,
        timings,
        scene: Some(SceneReport {
            ground_points: outcome.ground_points,
            objects: outcome.verdicts.len(),
            vehicles,
            rejected,
            chunks: outcome.chunks.map(|(n, _)| n),
            largest_chunk: outcome.chunks.map(|(_, largest)| largest),
        }),
    }
}

/// `n` and the noun, plural unless one.
fn count(n: usize, noun: &str) -> String {
    format!("{n} {noun}{}", if n == 1 { "" } else { "s" })
}

/// Refuses, before anything is read, an output or preview that would take the place of the
/// input, a preview over the output or in a format it cannot be written in, and a views folder
/// naming a file or an output.
fn check_paths(
    input: &Path,
    output: &Path,
    views: Option<&Path>,
    opts: &FileOptions,
) -> Result<(), FileError> {
    if input.is_dir() {
        return Err(FileError::InputIsDirectory(input.to_path_buf()));
    }
    check_output(output, &[input])?;
    if is_stdio(output) && opts.report_on_stdout {
        return Err(FileError::ReportAndCloudOnStdout);
    }
    if let Some(preview) = &opts.preview {
        check_output(preview, &[input])?;
        if same_file(preview, output) {
            return Err(FileError::PreviewIsOutput(preview.clone()));
        }
        preview_format(preview)?;
    }
    if let Some(dir) = views {
        if dir.exists() && !dir.is_dir() {
            return Err(FileError::ViewsNotADirectory(dir.to_path_buf()));
        }
        let preview = opts.preview.as_deref();
        if same_file(dir, output) || preview.is_some_and(|p| same_file(dir, p)) {
            return Err(FileError::ViewsIsOutput(dir.to_path_buf()));
        }
    }
    Ok(())
}

/// The preview's image format, by its extension: JPEG for `.jpg`/`.jpeg`, PNG for `.png` or
/// none; any other is refused before the work rather than written as PNG under its name.
fn preview_format(path: &Path) -> Result<image::ImageFormat, FileError> {
    let extension = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase());
    match extension.as_deref() {
        None | Some("png") => Ok(image::ImageFormat::Png),
        Some("jpg" | "jpeg") => Ok(image::ImageFormat::Jpeg),
        Some(other) => Err(FileError::PreviewExtension {
            path: path.to_path_buf(),
            extension: other.to_string(),
        }),
    }
}

/// The network's views as `DIR/input/` and `DIR/output/`; a warning when the method ran none.
fn save_views(dir: &Path, done: &Completion) -> Result<Option<String>, FileError> {
    let Some(views) = &done.views else {
        return Ok(Some(
            "--save-views: the method ran no network, so there are no views to save".into(),
        ));
    };
    for (name, images) in [("input", &views.input), ("output", &views.output)] {
        let dir = dir.join(name);
        create_dir(&dir)?;
        write_views(&dir, images)?;
    }
    Ok(None)
}

fn write_preview(path: &Path, input: &PointCloud, done: &Completion) -> Result<(), FileError> {
    let flags: Vec<bool> = done
        .cloud
        .attribute(SYNTHETIC)
        .expect("complete flags its points")
        .values
        .iter()
        .map(|&v| v != 0.0)
        .collect();
    let none = vec![false; done.input_normalized.len()];
    let left = Layer {
        points: &done.input_normalized,
        colors: input.colors.as_deref(),
        added: &none,
        title: format!("INPUT {}", done.input_points),
        plane: None,
    };
    let right = Layer {
        points: &done.normalized,
        colors: done.cloud.colors.as_deref(),
        added: &flags,
        title: format!("OUTPUT {} +{}", done.cloud.len(), done.added),
        plane: done.plane.map(|p| p.offset),
    };
    write_image(path, &render(&left, &right))
}

/// A batch: which files, where their outputs go, and how many workers complete them.
#[derive(Debug, Clone)]
pub struct Batch {
    /// The inputs' folder (list entries are relative to it too).
    pub root: PathBuf,
    pub output_dir: PathBuf,
    /// A file listing the inputs, one per line, instead of walking `root`.
    pub list: Option<PathBuf>,
    /// Only the files whose names match this pattern (`*`, `?`).
    pub include: Option<String>,
    pub shard: Option<Shard>,
    /// Leave a file whose output exists.
    pub skip_existing: bool,
    /// Each file's network views under this folder, at its relative path.
    pub save_views: Option<PathBuf>,
    pub jobs: usize,
}

/// What `complete --json` reports for a batch.
#[derive(Debug, Serialize)]
pub struct BatchReport {
    /// `i/n` when the run took one shard of the files.
    pub shard: Option<String>,
    /// Files this run took (its shard's, when sharded).
    pub files: usize,
    pub completed: usize,
    pub skipped: usize,
    pub failed: usize,
    pub results: Vec<BatchEntry>,
}

#[derive(Debug, Serialize)]
#[serde(tag = "status", rename_all = "snake_case")]
pub enum BatchEntry {
    Completed(Box<FileReport>),
    /// `skip_existing` found the output.
    Skipped {
        input: PathBuf,
        output: PathBuf,
    },
    Failed {
        input: PathBuf,
        error: String,
    },
}

impl Batch {
    /// The batch's inputs relative to its root, this shard's only: the list's, or the cloud
    /// files (or those `include` matches) under the root, those under the output folder left
    /// out where it lies inside the root (a second run would complete the first one's outputs
    /// again, a folder deeper each time).
    pub fn files(&self) -> Result<Vec<PathBuf>, BatchRunError> {
        let root = &self.root;
        let files = match &self.list {
            Some(list) => read_list(list, root)?,
            None => {
                if !root.is_dir() {
                    return Err(BatchRunError::NotADirectory(root.clone()));
                }
                let pattern: Option<Vec<char>> = self.include.as_ref().map(|p| p.chars().collect());
                let outputs = batch::nested_dir(root, &self.output_dir);
                let files = walk(root, |path| {
                    let wanted = match &pattern {
                        Some(p) => {
                            let name = path.file_name().unwrap_or_default().to_string_lossy();
                            batch::matches(p, &name.chars().collect::<Vec<_>>())
                        }
                        None => Format::from_path(path).is_ok(),
                    };
                    wanted
                        && outputs
                            .as_ref()
                            .is_none_or(|out| !batch::lies_in(path, out))
                })?;
                if files.is_empty() {
                    return Err(match &self.include {
                        Some(include) => BatchRunError::NoMatch {
                            root: root.clone(),
                            include: include.clone(),
                        },
                        None => BatchRunError::NoClouds(root.clone()),
                    });
                }
                files
            }
        };
        Ok(match self.shard {
            Some(shard) => files
                .into_iter()
                .filter(|f| shard.owns(&batch::key(f)))
                .collect(),
            None => files,
        })
    }

    /// Where the output of `relative` goes.
    fn output(&self, relative: &Path, opts: &FileOptions) -> PathBuf {
        let mut output = self.output_dir.join(relative);
        if let Some(format) = opts.out_format {
            output.set_extension(format.extension());
        }
        output
    }

    fn views(&self, relative: &Path) -> Option<PathBuf> {
        let views = self.save_views.as_ref();
        views.map(|d| d.join(relative.with_extension("")))
    }

    /// Refuses a batch in which two inputs would be written to the same output or views folder
    /// (`a.las` and `a.ply` written as PLY): the later one would replace the earlier one's
    /// without a word.
    fn check_distinct(&self, files: &[PathBuf], opts: &FileOptions) -> Result<(), BatchRunError> {
        let mut written: BTreeMap<PathBuf, &Path> = BTreeMap::new();
        for relative in files {
            let output = self.output(relative, opts);
            for target in std::iter::once(output).chain(self.views(relative)) {
                if let Some(first) = written.insert(target.clone(), relative) {
                    return Err(BatchRunError::SameOutput {
                        first: self.root.join(first),
                        second: self.root.join(relative),
                        target,
                    });
                }
            }
        }
        Ok(())
    }

    /// Completes, skips or fails one file.
    fn entry(&self, relative: &Path, job: &Job) -> BatchEntry {
        let input = self.root.join(relative);
        let output = self.output(relative, &job.files);
        if self.skip_existing && output.exists() {
            return BatchEntry::Skipped { input, output };
        }
        let result = output
            .parent()
            .map_or(Ok(()), create_dir)
            .map_err(FileError::from)
            .and_then(|()| complete_file(&input, &output, self.views(relative).as_deref(), job));
        match result {
            Ok(report) => BatchEntry::Completed(Box::new(report)),
            Err(e) => BatchEntry::Failed {
                input,
                error: e.to_string().replace('\n', " "),
            },
        }
    }

    /// Completes every file of the batch on `jobs` workers, in the files' order in the report.
    pub fn run(&self, job: &Job, progress: &dyn Progress) -> Result<BatchReport, BatchRunError> {
        if self.output_dir.exists() && !self.output_dir.is_dir() {
            return Err(BatchRunError::OutputNotADirectory(self.output_dir.clone()));
        }
        let files = self.files()?;
        self.check_distinct(&files, &job.files)?;
        create_dir(&self.output_dir)?;
        progress.start(files.len(), "completing");
        let next = AtomicUsize::new(0);
        let results: Mutex<Vec<(usize, BatchEntry)>> = Mutex::new(Vec::new());
        let jobs = self.jobs.min(files.len()).max(1);
        std::thread::scope(|scope| {
            for _ in 0..jobs {
                scope.spawn(|| loop {
                    let i = next.fetch_add(1, Ordering::Relaxed);
                    let Some(relative) = files.get(i) else {
                        break;
                    };
                    let entry = self.entry(relative, job);
                    results.lock().expect("no worker panics").push((i, entry));
                    progress.done(&relative.to_string_lossy());
                });
            }
        });
        progress.finish();
        let mut results = results.into_inner().expect("no worker panics");
        results.sort_by_key(|(i, _)| *i);
        let results: Vec<BatchEntry> = results.into_iter().map(|(_, e)| e).collect();
        let count = |f: fn(&BatchEntry) -> bool| results.iter().filter(|e| f(e)).count();
        Ok(BatchReport {
            shard: self.shard.map(|s| s.to_string()),
            files: results.len(),
            completed: count(|e| matches!(e, BatchEntry::Completed(_))),
            skipped: count(|e| matches!(e, BatchEntry::Skipped { .. })),
            failed: count(|e| matches!(e, BatchEntry::Failed { .. })),
            results,
        })
    }
}

impl BatchReport {
    /// Each warning of the completed files once, naming the files it concerns: a batch written
    /// to XYZ would otherwise say for every file that the `synthetic` flag is lost. The report
    /// keeps each file's own.
    pub fn grouped_warnings(&self) -> Vec<String> {
        let mut groups: Vec<(&str, Vec<&Path>)> = Vec::new();
        let mut index: HashMap<&str, usize> = HashMap::new();
        for entry in &self.results {
            let BatchEntry::Completed(report) = entry else {
                continue;
            };
            for warning in &report.warnings {
                let i = *index.entry(warning.as_str()).or_insert_with(|| {
                    groups.push((warning.as_str(), Vec::new()));
                    groups.len() - 1
                });
                groups[i].1.push(&report.input);
            }
        }
        groups
            .into_iter()
            .map(|(warning, files)| format!("{}: {warning}", files_named(&files)))
            .collect()
    }
}

/// "a.ply", "a.ply and b.ply", "a.ply, b.ply and c.ply", "a.ply, b.ply and 5 more files".
fn files_named(files: &[&Path]) -> String {
    let name = |i: usize| files[i].display().to_string();
    match files.len() {
        0..=2 => (0..files.len()).map(name).collect::<Vec<_>>().join(" and "),
        3 => format!("{}, {} and {}", name(0), name(1), name(2)),
        n => format!("{}, {} and {} more files", name(0), name(1), n - 2),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn files_are_named_up_to_two_then_counted() {
        let paths = ["a", "b", "c", "d", "e"].map(Path::new);
        let named = |n: usize| files_named(&paths[..n]);
        assert_eq!(named(1), "a");
        assert_eq!(named(2), "a and b");
        assert_eq!(named(3), "a, b and c");
        assert_eq!(named(5), "a, b and 3 more files");
    }
}
