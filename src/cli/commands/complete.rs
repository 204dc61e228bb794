use super::project::default_up;
use super::{non_finite_warning, progress, Log};
use crate::cli::args::CompleteArgs;
use crate::cli::count;
use crate::cli::streams::{say, tell};
use anyhow::{anyhow, bail, Context};
use burn::tensor::Device;
use mvpcc::complete::clean::CleanReport;
use mvpcc::complete::orient::{OrientMode, Orienter};
use mvpcc::complete::preview::{render, Layer};
use mvpcc::complete::symmetry::{Cues, Plane, PlaneFit};
use mvpcc::complete::{
    Completer, Completion, Method, Options, Run, Settings, Timings, DEFAULT_MODEL, SYNTHETIC,
};
use mvpcc::core::cloud::PointCloud;
use mvpcc::core::frame::{Frame, UpAxis};
use mvpcc::io::batch::{self, read_list, walk};
use mvpcc::io::stdio::is_stdio;
use mvpcc::io::{
    atomic_write, check_output, read_bytes, read_cloud, same_file, unwritten, write_cloud, Format,
};
use mvpcc::model::device::DeviceChoice;
use mvpcc::model::inpaint::Inpainter;
use mvpcc::model::weights::generator_in;
use mvpcc::views::write_views;
use serde::Serialize;
use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;
use std::time::Instant;

pub(super) fn run(args: Box<CompleteArgs>, log: Log) -> anyhow::Result<()> {
    let inpainter = match args.method {
        Method::Network => {
            let inpainter = load_model(args.model.as_deref(), args.device, log)?;
            Some(match args.occupancy {
                Some(p) => inpainter.with_occupancy(p)?,
                None => inpainter,
            })
        }
        Method::Identity | Method::Mirror => None,
    };
    let orienter = if orient_mode(&args).needs_network() {
        Some(load_orienter(args.orienter.as_deref())?)
    } else {
        None
    };
    let completer = Completer::new(inpainter, orienter);
    match (&args.input, &args.output, &args.input_dir, &args.output_dir) {
        (Some(input), Some(output), _, _) => {
            let views = args.save_views.clone();
            let report = complete_file(input, output, views, &args, &completer, log)?;
            if args.json {
                say(serde_json::to_string_pretty(&report)?)?;
            }
            Ok(())
        }
        (None, None, _, Some(_)) => batch(&args, &completer, log),
        _ => bail!("give IN and OUT, or --input-dir (or --list) and --output-dir"),
    }
}

/// The generator from `--model` (a weights file, a run directory or assets/) or the built-in
/// one.
fn load_model(path: Option<&Path>, device: DeviceChoice, log: Log) -> anyhow::Result<Inpainter> {
    let opened = super::open_device(device, log)?;
    let inpainter = match path {
        Some(path) => {
            let file = if path.is_dir() {
                generator_in(path)?
            } else {
                path.to_path_buf()
            };
            let bytes = read_bytes(&file).map_err(|p| anyhow!("{}: {p}", file.display()))?;
            Inpainter::from_bytes(&bytes, opened.device)
                .with_context(|| format!("{}", file.display()))?
        }
        None => {
            Inpainter::from_bytes(DEFAULT_MODEL, opened.device).context("the built-in model")?
        }
    };
    Ok(inpainter)
}

/// The orientation network from `--orienter` or the built-in one; it is small and runs on the
/// CPU.
fn load_orienter(path: Option<&Path>) -> anyhow::Result<Orienter> {
    match path {
        Some(path) => {
            let bytes = read_bytes(path).map_err(|p| anyhow!("{}: {p}", path.display()))?;
            Orienter::from_bytes(&bytes, Device::flex())
                .with_context(|| format!("{}", path.display()))
        }
        None => Orienter::builtin().context("the built-in orientation network"),
    }
}

/// `--orient` (auto by default, none with `--paper`), except for the identity method, whose
/// output does not depend on the frame.
fn orient_mode(args: &CompleteArgs) -> OrientMode {
    let default = if args.paper {
        OrientMode::None
    } else {
        OrientMode::Auto
    };
    match args.method {
        Method::Identity => OrientMode::None,
        Method::Mirror | Method::Network => args.orient.unwrap_or(default),
    }
}

fn up_axis(args: &CompleteArgs, input: &Path) -> UpAxis {
    args.up
        .unwrap_or_else(|| default_up(input, args.input_options.format))
}

/// What the options ask of the pipeline for `input`.
fn settings(args: &CompleteArgs, input: &Path) -> Settings {
    Settings {
        clean: args.clean,
        orient: orient_mode(args),
        options: options(args, input),
    }
}

fn options(args: &CompleteArgs, input: &Path) -> Options {
    let up = up_axis(args, input);
    let sor = args.sor.params();
    if args.paper {
        return Options {
            views: args.views.0.clone(),
            erode: args.erode,
            sor,
            keep_views: args.save_views.is_some(),
            ..Options::paper(up, None)
        };
    }
    Options {
        method: args.method,
        up,
        heading: None,
        roll: args.roll.unwrap_or(Options::default().roll),
        views: args.views.0.clone(),
        erode: args.erode,
        smooth: args.smooth,
        snap: !args.no_snap,
        sor,
        keep_input: !args.no_keep_input,
        merge_distance: args.merge_distance,
        near_distance: args.near_distance,
        near_occupancy: args.near_occupancy,
        box_margin: args.box_margin,
        thin: args.thin,
        symmetry: !args.no_symmetry,
        mirror_pass: !args.no_mirror_pass,
        symmetric_frame: true,
        keep_views: args.save_views.is_some(),
        vehicle_width: args.vehicle_width,
    }
}

/// The output format: `--out-format`, else OUT's extension, else (standard output or no
/// extension) the input's format. An extension no format has is refused rather than read as
/// none: `out.plyy` written as the input's PCD would be a surprise.
fn output_format(args: &CompleteArgs, input: &Path, output: &Path) -> anyhow::Result<Format> {
    let given = args.output_options.out_format;
    let named = output.extension().is_some() && !is_stdio(output);
    let format = if given.is_some() || named {
        Format::of_output(output, given)
    } else {
        Format::of_input(input, args.input_options.format)
    };
    format.map_err(|e| anyhow!("{}: {e}", output.display()))
}

/// What `complete --json` reports for one file.
#[derive(Debug, Serialize)]
struct FileReport {
    input: PathBuf,
    output: PathBuf,
    method: Method,
    input_points: usize,
    output_points: usize,
    added: usize,
    mirrored: usize,
    filtered_out: usize,
    /// Objects the network completed: 2 with the mirrored pass (and a plane), 1 with
    /// `--no-mirror-pass`, 0 without the network.
    network_passes: usize,
    symmetry_plane: Option<PlaneReport>,
    orientation: OrientationReport,
    cleaned: Option<CleanReport>,
    warnings: Vec<String>,
    /// Seconds per stage, as `--timings` prints them.
    seconds: BTreeMap<String, f64>,
}

/// The symmetry plane: `x = x` in the normalized frame, a point on it and its unit normal in
/// the input's coordinates, the share of points it mirrors onto others, and how it was placed.
#[derive(Debug, Serialize)]
struct PlaneReport {
    x: f64,
    point: [f64; 3],
    normal: [f64; 3],
    support: f64,
    fit: PlaneFit,
    /// Where each cue put the plane, as `x`.
    cues: Cues,
    /// Whether the cues agree well enough for the mirror image to be drawn.
    vouched: bool,
}

impl PlaneReport {
    fn of(plane: &Plane, frame: &Frame) -> PlaneReport {
        let point = frame.to_input([plane.offset, 0.0, 0.0]);
        let ahead = frame.to_input([plane.offset + 1.0, 0.0, 0.0]);
        // One normalized unit is `extent` input units.
        let normal = [0, 1, 2].map(|i| (ahead[i] - point[i]) / frame.extent);
        PlaneReport {
            x: plane.offset,
            point,
            normal,
            support: plane.support,
            fit: plane.fit,
            cues: plane.cues,
            vouched: plane.vouched,
        }
    }
}

#[derive(Debug, Serialize)]
struct OrientationReport {
    heading: Option<f64>,
    method: &'static str,
    refinement: Option<f64>,
    refined_by: Option<&'static str>,
    /// The lean across the width the frame took out, degrees (`--roll`).
    roll: f64,
}

/// Completes one file; the report of what happened.
fn complete_file(
    input: &Path,
    output: &Path,
    views: Option<PathBuf>,
    args: &CompleteArgs,
    completer: &Completer,
    log: Log,
) -> anyhow::Result<FileReport> {
    check_paths(input, output, views.as_deref(), args)?;
    let format = output_format(args, input, output)?;
    let start = Instant::now();
    let loaded = read_cloud(input, args.input_options.format)?;
    let cloud = loaded.cloud;
    let read = start.elapsed();
    let mut run = completer
        .run(&cloud, &settings(args, input))
        .map_err(|e| anyhow!("{}: {e}", input.display()))?;
    let saved = match &views {
        Some(dir) => save_views(dir, &run.completion)?,
        None => None,
    };
    let lost = unwritten(&run.completion.cloud, format, output);
    let warnings = &mut run.completion.warnings;
    warnings.splice(0..0, non_finite_warning(loaded.non_finite_dropped));
    warnings.extend(saved);
    warnings.extend(lost);
    if let Some((_, report)) = &run.cleaned {
        log.info(format!(
            "{}: --clean removed {} ground, {} isolated and {} other-object points",
            input.display(),
            report.ground,
            report.isolated,
            report.other_objects
        ));
    }
    let done = &run.completion;
    for w in &done.warnings {
        log.warn(format!("{}: {w}", input.display()));
    }
    let start = Instant::now();
    write_cloud(
        output,
        &done.cloud,
        Some(format),
        args.output_options.encoding,
    )?;
    let timings = Timings {
        read,
        write: start.elapsed(),
        ..done.timings
    };
    if let Some(path) = &args.preview {
        let measured = run.cleaned.as_ref().map_or(&cloud, |(c, _)| c);
        write_preview(path, measured, done)?;
    }
    log.info(summary(output, &run, &timings));
    if args.timings && !args.json {
        for (name, d) in timings.stages() {
            tell(format_args!("{name:>14} {:9.1} ms", d.as_secs_f64() * 1e3));
        }
    }
    Ok(report(input, output, args, run, &timings))
}

/// Refuses, before anything is read, an output or `--preview` that would take the place of the
/// input, a preview over the output or in a format it cannot be written in, and `--save-views`
/// naming a file or an output.
fn check_paths(
    input: &Path,
    output: &Path,
    views: Option<&Path>,
    args: &CompleteArgs,
) -> anyhow::Result<()> {
    if input.is_dir() {
        bail!(
            "{}: is a directory; complete a folder with --input-dir {0} --output-dir OUT",
            input.display()
        );
    }
    check_output(output, &[input])?;
    if is_stdio(output) && args.json {
        bail!("-: --json and the completed cloud cannot both go to standard output");
    }
    if let Some(preview) = &args.preview {
        check_output(preview, &[input])?;
        if same_file(preview, output) {
            bail!("{}: --preview names the output cloud", preview.display());
        }
        preview_format(preview)?;
    }
    if let Some(dir) = views {
        if dir.exists() && !dir.is_dir() {
            bail!("{}: --save-views needs a directory", dir.display());
        }
        let preview = args.preview.as_deref();
        if same_file(dir, output) || preview.is_some_and(|p| same_file(dir, p)) {
            bail!("{}: --save-views names an output file", dir.display());
        }
    }
    Ok(())
}

/// The preview's image format, by its extension: JPEG for `.jpg`/`.jpeg`, PNG for `.png` or
/// none; any other is refused before the work rather than written as PNG under its name.
fn preview_format(path: &Path) -> anyhow::Result<image::ImageFormat> {
    let extension = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase());
    match extension.as_deref() {
        None | Some("png") => Ok(image::ImageFormat::Png),
        Some("jpg" | "jpeg") => Ok(image::ImageFormat::Jpeg),
        Some(other) => bail!(
            "{}: unsupported preview extension \"{other}\" (expected png, jpg or jpeg)",
            path.display()
        ),
    }
}

/// The line logged for one completed file.
fn summary(output: &Path, run: &Run, timings: &Timings) -> String {
    let done = &run.completion;
    format!(
        "{}: {} points → {} ({} completed{}{}) in {:.2} s",
        output.display(),
        done.input_points,
        done.cloud.len(),
        done.added,
        if done.mirrored > 0 {
            format!(", {} of them mirrored", done.mirrored)
        } else {
            String::new()
        },
        run.orientation.heading.map_or(String::new(), |h| format!(
            "; heading {h:.1}° ({})",
            run.orientation.method
        )),
        timings.total().as_secs_f64()
    )
}

/// The `--json` report of one completed file.
fn report(input: &Path, output: &Path, args: &CompleteArgs, run: Run, t: &Timings) -> FileReport {
    let done = run.completion;
    FileReport {
        input: input.to_path_buf(),
        output: output.to_path_buf(),
        method: args.method,
        input_points: done.input_points,
        output_points: done.cloud.len(),
        added: done.added,
        mirrored: done.mirrored,
        filtered_out: done.filtered_out,
        network_passes: done.network_passes,
        symmetry_plane: done.plane.map(|p| PlaneReport::of(&p, &done.frame)),
        orientation: OrientationReport {
            heading: run.orientation.heading,
            method: run.orientation.method,
            refinement: run.orientation.refinement,
            refined_by: run.orientation.refined_by,
            roll: done.roll,
        },
        cleaned: run.cleaned.map(|(_, report)| report),
        warnings: done.warnings,
        seconds: t
            .stages()
            .iter()
            .map(|(name, d)| (name.replace('-', ""), d.as_secs_f64()))
            .collect(),
    }
}

/// The network's views as `DIR/input/` and `DIR/output/`; a warning when the method ran none.
fn save_views(dir: &Path, done: &Completion) -> anyhow::Result<Option<String>> {
    let Some(views) = &done.views else {
        return Ok(Some(
            "--save-views: the method ran no network, so there are no views to save".into(),
        ));
    };
    for (name, images) in [("input", &views.input), ("output", &views.output)] {
        let dir = dir.join(name);
        std::fs::create_dir_all(&dir)
            .with_context(|| format!("{}: cannot create", dir.display()))?;
        write_views(&dir, images)?;
    }
    Ok(None)
}

fn write_preview(path: &Path, input: &PointCloud, done: &Completion) -> anyhow::Result<()> {
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
    let img = render(&left, &right);
    let format = preview_format(path)?;
    atomic_write(path, |w| {
        img.write_to(w, format).map_err(std::io::Error::other)
    })
    .with_context(|| format!("{}: cannot write the preview", path.display()))
}

/// `*` any run of characters, `?` one character. Only the last `*` is ever backtracked to (a
/// later star can take whatever an earlier one would have), so the work stays within
/// pattern × name: trying every split at every star took exponential time, and
/// `--include '*a*a*a*a*a*a*a*a*a*a*a*a*b'` over a name of sixty `a`s ran past 30 s.
fn matches(pattern: &[char], name: &[char]) -> bool {
    let (mut p, mut n) = (0, 0);
    // The last star seen and the name position its run currently ends at.
    let mut star: Option<(usize, usize)> = None;
    while n < name.len() {
        match pattern.get(p) {
            Some('*') => {
                star = Some((p, n));
                p += 1;
            }
            Some(&c) if c == '?' || c == name[n] => {
                p += 1;
                n += 1;
            }
            _ => match star {
                Some((at, end)) => {
                    star = Some((at, end + 1));
                    p = at + 1;
                    n = end + 1;
                }
                None => return false,
            },
        }
    }
    pattern[p..].iter().all(|&c| c == '*')
}

/// What `complete --json` reports for a batch.
#[derive(Debug, Serialize)]
struct BatchReport {
    /// `i/n` when the run took one shard of the files.
    shard: Option<String>,
    /// Files this run took (its shard's, when sharded).
    files: usize,
    completed: usize,
    skipped: usize,
    failed: usize,
    results: Vec<BatchEntry>,
}

#[derive(Debug, Serialize)]
#[serde(tag = "status", rename_all = "snake_case")]
enum BatchEntry {
    Completed(Box<FileReport>),
    /// `--skip-existing` found the output.
    Skipped {
        input: PathBuf,
        output: PathBuf,
    },
    Failed {
        input: PathBuf,
        error: String,
    },
}

/// The batch's inputs relative to its root, this shard's only: the list's, or the cloud files
/// (or those `--include` matches) under the root, those under `output_dir` left out where it
/// lies inside the root (a second run would complete the first one's outputs again, a folder
/// deeper each time).
fn batch_files(
    root: &Path,
    output_dir: &Path,
    args: &CompleteArgs,
) -> anyhow::Result<Vec<PathBuf>> {
    let files = match &args.list {
        Some(list) => read_list(list, root)?,
        None => {
            if !root.is_dir() {
                bail!("{}: not a directory", root.display());
            }
            let pattern: Option<Vec<char>> = args.include.as_ref().map(|p| p.chars().collect());
            let outputs = batch::nested_dir(root, output_dir);
            let files = walk(root, |path| {
                let wanted = match &pattern {
                    Some(p) => {
                        let name = path.file_name().unwrap_or_default().to_string_lossy();
                        matches(p, &name.chars().collect::<Vec<_>>())
                    }
                    None => Format::from_path(path).is_ok(),
                };
                wanted
                    && outputs
                        .as_ref()
                        .is_none_or(|out| !batch::lies_in(path, out))
            })?;
            match (&args.include, files.is_empty()) {
                (Some(include), true) => {
                    bail!("{}: no file matches --include '{include}'", root.display())
                }
                (None, true) => bail!("{}: no point cloud files", root.display()),
                _ => {}
            }
            files
        }
    };
    Ok(match args.shard {
        Some(shard) => files
            .into_iter()
            .filter(|f| shard.owns(&batch::key(f)))
            .collect(),
        None => files,
    })
}

/// Where the output of `relative` goes.
fn batch_output(output_dir: &Path, relative: &Path, args: &CompleteArgs) -> PathBuf {
    let mut output = output_dir.join(relative);
    if let Some(format) = args.output_options.out_format {
        output.set_extension(extension(format));
    }
    output
}

/// Refuses a batch in which two inputs would be written to the same output or views folder
/// (`a.las` and `a.ply` with `--out-format ply`, or with `--save-views`): the later one would
/// replace the earlier one's without a word.
fn check_distinct(
    root: &Path,
    files: &[PathBuf],
    output_dir: &Path,
    args: &CompleteArgs,
) -> anyhow::Result<()> {
    let mut written: BTreeMap<PathBuf, &Path> = BTreeMap::new();
    for relative in files {
        let views = args
            .save_views
            .as_ref()
            .map(|d| d.join(relative.with_extension("")));
        for target in std::iter::once(batch_output(output_dir, relative, args)).chain(views) {
            if let Some(first) = written.insert(target.clone(), relative) {
                bail!(
                    "{} and {} would both be written to {}; rename one or complete them apart",
                    root.join(first).display(),
                    root.join(relative).display(),
                    target.display()
                );
            }
        }
    }
    Ok(())
}

/// Completes, skips or fails one file of a batch.
fn batch_entry(
    root: &Path,
    relative: &Path,
    output_dir: &Path,
    args: &CompleteArgs,
    completer: &Completer,
) -> BatchEntry {
    let input = root.join(relative);
    let output = batch_output(output_dir, relative, args);
    if args.skip_existing && output.exists() {
        return BatchEntry::Skipped { input, output };
    }
    // Each file's own messages would tear the progress bar; the batch summarizes them.
    let quiet = Log::silent();
    let result = output
        .parent()
        .map_or(Ok(()), std::fs::create_dir_all)
        .with_context(|| format!("{}: cannot create", output.display()))
        .and_then(|()| {
            let views = args
                .save_views
                .as_ref()
                .map(|d| d.join(relative.with_extension("")));
            complete_file(&input, &output, views, args, completer, quiet)
        });
    match result {
        Ok(report) => BatchEntry::Completed(Box::new(report)),
        Err(e) => BatchEntry::Failed {
            input,
            error: crate::cli::one_line(&e),
        },
    }
}

fn batch(args: &CompleteArgs, completer: &Completer, log: Log) -> anyhow::Result<()> {
    let output_dir = args.output_dir.as_deref().expect("clap requires it");
    let root = args.input_dir.clone().unwrap_or_else(|| PathBuf::from("."));
    super::check_out_dir(output_dir)?;
    let files = batch_files(&root, output_dir, args)?;
    check_distinct(&root, &files, output_dir, args)?;
    std::fs::create_dir_all(output_dir)
        .with_context(|| format!("{}: cannot create", output_dir.display()))?;
    let bar = progress(files.len(), "completing", log);
    let next = AtomicUsize::new(0);
    let results: Mutex<Vec<(usize, BatchEntry)>> = Mutex::new(Vec::new());
    let jobs = args.jobs.min(files.len()).max(1);
    std::thread::scope(|scope| {
        for _ in 0..jobs {
            scope.spawn(|| loop {
                let i = next.fetch_add(1, Ordering::Relaxed);
                let Some(relative) = files.get(i) else {
                    break;
                };
                let entry = batch_entry(&root, relative, output_dir, args, completer);
                results.lock().expect("no worker panics").push((i, entry));
                bar.inc(1);
            });
        }
    });
    bar.finish_and_clear();
    let mut results = results.into_inner().expect("no worker panics");
    results.sort_by_key(|(i, _)| *i);
    let results: Vec<BatchEntry> = results.into_iter().map(|(_, e)| e).collect();
    let report = summarize(args, results, log);
    log.info(format!(
        "{} of {} completed into {}{}, {} skipped, {} failed",
        report.completed,
        count(report.files, "file"),
        output_dir.display(),
        report
            .shard
            .as_ref()
            .map_or(String::new(), |s| format!(" (shard {s})")),
        report.skipped,
        report.failed
    ));
    if args.json {
        say(serde_json::to_string_pretty(&report)?)?;
    }
    if report.failed > 0 {
        bail!(
            "{} of {} failed",
            report.failed,
            count(report.files, "file")
        );
    }
    Ok(())
}

/// Counts the outcomes and says what went wrong with each file on stderr.
fn summarize(args: &CompleteArgs, results: Vec<BatchEntry>, log: Log) -> BatchReport {
    warn_once(&results, log);
    let (mut completed, mut skipped, mut failed) = (0, 0, 0);
    for entry in &results {
        match entry {
            BatchEntry::Completed(_) => completed += 1,
            BatchEntry::Skipped { .. } => skipped += 1,
            BatchEntry::Failed { error, .. } => {
                failed += 1;
                tell(format_args!("failed: {error}"));
            }
        }
    }
    BatchReport {
        shard: args.shard.map(|s| s.to_string()),
        files: results.len(),
        completed,
        skipped,
        failed,
        results,
    }
}

/// Each warning of the completed files once, naming the files it concerns: a batch written to
/// XYZ would otherwise say for every file that the `synthetic` flag is lost. The JSON report
/// keeps each file's own.
fn warn_once(results: &[BatchEntry], log: Log) {
    let mut groups: Vec<(&str, Vec<&Path>)> = Vec::new();
    let mut index: HashMap<&str, usize> = HashMap::new();
    for entry in results {
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
    for (warning, files) in groups {
        log.warn(format!("{}: {warning}", files_named(&files)));
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

fn extension(format: Format) -> &'static str {
    match format {
        Format::Ply => "ply",
        Format::Pcd => "pcd",
        Format::Las => "las",
        Format::Laz => "laz",
        Format::Xyz => "xyz",
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cli::args::{Cli, Command};
    use clap::Parser;

    #[test]
    fn the_library_defaults_are_the_commands() {
        let cli = Cli::try_parse_from(["mvpcc", "complete", "in.ply", "out.ply"]).unwrap();
        let Command::Complete(args) = cli.command else {
            panic!("parsed as another command");
        };
        assert_eq!(options(&args, Path::new("in.ply")), Options::default());
    }

    #[test]
    fn files_are_named_up_to_two_then_counted() {
        let paths = ["a", "b", "c", "d", "e"].map(Path::new);
        let named = |n: usize| files_named(&paths[..n]);
        assert_eq!(named(1), "a");
        assert_eq!(named(2), "a and b");
        assert_eq!(named(3), "a, b and c");
        assert_eq!(named(5), "a, b and 3 more files");
    }

    #[test]
    fn wildcards() {
        let m = |p: &str, n: &str| {
            matches(
                &p.chars().collect::<Vec<_>>(),
                &n.chars().collect::<Vec<_>>(),
            )
        };
        assert!(m("partial_*.ply", "partial_12.ply"));
        assert!(!m("partial_*.ply", "gt.ply"));
        assert!(m("*", "anything"));
        assert!(m("a?c", "abc"));
        assert!(!m("a?c", "ac"));
        assert!(m("*.p*", "x.pcd"));
        assert!(m("", ""));
        assert!(m("*", ""));
        assert!(m("**", "ab"));
        assert!(!m("?", ""));
        assert!(!m("", "a"));
        assert!(m("a*b*c", "abbbc"));
        assert!(!m("a*b*c", "acb"));
        assert!(m("*ab", "aab"));
        assert!(m("*a?", "xaab"));
        assert!(!m("*a", "ab"));
        // Many stars against a long name that almost matches: answered at once.
        assert!(!m("*a*a*a*a*a*a*a*a*a*a*a*a*b", &"a".repeat(60)));
        assert!(m(
            "*a*a*a*a*a*a*a*a*a*a*a*a*b",
            &format!("{}b", "a".repeat(60))
        ));
    }
}
