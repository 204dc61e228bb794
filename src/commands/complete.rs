use super::project::default_up;
use super::{load, progress, Log};
use crate::clean::clean;
use crate::cli::CompleteArgs;
use crate::cloud::PointCloud;
use crate::complete::{complete, Completion, Method, Options, DEFAULT_MODEL, SYNTHETIC};
use crate::device::{open, DeviceChoice};
use crate::filter::SorParams;
use crate::frame::UpAxis;
use crate::inpaint::Inpainter;
use crate::io::{atomic_write, check_output, write_cloud, Format};
use crate::orient::{orient, OrientMode, Orienter, DEFAULT_ORIENTER};
use crate::preview::{render, Layer};
use crate::views::write_views;
use anyhow::{anyhow, bail, Context};
use burn::tensor::Device;
use serde_json::{json, Value};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;
use std::time::{Duration, Instant};

/// The networks a run needs, loaded once for all its files.
struct Models {
    inpainter: Option<Inpainter>,
    orienter: Option<Orienter>,
}

pub(super) fn run(args: Box<CompleteArgs>, log: Log) -> anyhow::Result<()> {
    let inpainter = match args.method {
        Method::Network => Some(load_model(args.model.as_deref(), args.device, log)?),
        Method::Identity | Method::Mirror => None,
    };
    let orienter = if orient_mode(&args).needs_network() {
        Some(load_orienter(args.orienter.as_deref())?)
    } else {
        None
    };
    let models = Models {
        inpainter,
        orienter,
    };
    match (&args.input, &args.output, &args.input_dir, &args.output_dir) {
        (Some(input), Some(output), _, _) => {
            let views = args.save_views.clone();
            let report = complete_file(input, output, views, &args, &models, log)?;
            if args.json {
                println!("{}", serde_json::to_string_pretty(&report)?);
            }
            Ok(())
        }
        (_, _, Some(input_dir), Some(output_dir)) => {
            batch(input_dir, output_dir, &args, &models, log)
        }
        _ => bail!("give IN and OUT, or --input-dir and --output-dir"),
    }
}

/// The generator from `--model` (a weights file or a run directory) or the built-in one.
fn load_model(path: Option<&Path>, device: DeviceChoice, log: Log) -> anyhow::Result<Inpainter> {
    let opened = open(device)?;
    if let Some(why) = &opened.fallback {
        log.warn(why);
    }
    let inpainter = match path {
        Some(path) => {
            let file = if path.is_dir() {
                path.join("generator.safetensors")
            } else {
                path.to_path_buf()
            };
            let bytes = std::fs::read(&file).with_context(|| format!("{}", file.display()))?;
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
            let bytes = std::fs::read(path).with_context(|| format!("{}", path.display()))?;
            Orienter::from_bytes(&bytes, Device::flex())
                .with_context(|| format!("{}", path.display()))
        }
        None => Orienter::from_bytes(DEFAULT_ORIENTER, Device::flex())
            .context("the built-in orientation network"),
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

fn options(args: &CompleteArgs, input: &Path, heading: Option<f64>) -> Options {
    if args.paper {
        return Options {
            views: args.views.0.clone(),
            erode: args.erode,
            sor: SorParams {
                k: args.sor.sor_k,
                std_mul: args.sor.sor_std,
            },
            keep_views: args.save_views.is_some(),
            ..Options::paper(up_axis(args, input), heading)
        };
    }
    Options {
        method: args.method,
        up: up_axis(args, input),
        heading,
        views: args.views.0.clone(),
        erode: args.erode,
        smooth: args.smooth,
        snap: !args.no_snap,
        sor: SorParams {
            k: args.sor.sor_k,
            std_mul: args.sor.sor_std,
        },
        keep_input: !args.no_keep_input,
        merge_pixels: args.merge_pixels,
        symmetry: !args.no_symmetry,
        symmetric_frame: true,
        keep_views: args.save_views.is_some(),
    }
}

/// The output format: `--out-format`, else OUT's extension, else the input's format.
fn output_format(args: &CompleteArgs, input: &Path, output: &Path) -> anyhow::Result<Format> {
    if let Some(f) = args.output_options.out_format {
        return Ok(f);
    }
    Format::from_path(output)
        .or_else(|_| match args.input_options.format {
            Some(f) => Ok(f),
            None => Format::from_path(input),
        })
        .map_err(|e| anyhow!("{}: {e}", output.display()))
}

fn seconds(d: Duration) -> f64 {
    d.as_secs_f64()
}

/// Completes one file; the JSON report of what happened.
fn complete_file(
    input: &Path,
    output: &Path,
    views: Option<PathBuf>,
    args: &CompleteArgs,
    models: &Models,
    log: Log,
) -> anyhow::Result<Value> {
    let total = Instant::now();
    check_output(output, &[input])?;
    let format = output_format(args, input, output)?;
    let start = Instant::now();
    let cloud = load(input, args.input_options.format, log)?;
    let read = start.elapsed();
    let up = up_axis(args, input);
    let start = Instant::now();
    let (cloud, cleaned) = if args.clean {
        let (cleaned, report) = clean(&cloud, up);
        log.info(format!(
            "{}: --clean removed {} ground, {} isolated and {} other-object points",
            input.display(),
            report.ground,
            report.isolated,
            report.other_objects
        ));
        (cleaned, Some(report))
    } else {
        (cloud, None)
    };
    let cleaning = start.elapsed();
    let start = Instant::now();
    let orientation = orient(&cloud, up, orient_mode(args), models.orienter.as_ref());
    let orienting = start.elapsed();
    let done = complete(
        &cloud,
        models.inpainter.as_ref(),
        &options(args, input, orientation.heading),
    )
    .map_err(|e| anyhow!("{}: {e}", input.display()))?;
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
    let write = start.elapsed();
    if let Some(path) = &args.preview {
        write_preview(path, &cloud, &done)?;
    }
    if let Some(dir) = &views {
        save_views(dir, input, &done, log)?;
    }
    let total = total.elapsed();
    log.info(format!(
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
        orientation.heading.map_or(String::new(), |h| format!(
            "; heading {h:.1}° ({})",
            orientation.method
        )),
        total.as_secs_f64()
    ));
    let t = &done.timings;
    let rows = [
        ("read", read),
        ("clean", cleaning),
        ("orientation", orienting),
        ("symmetry", t.symmetry),
        ("projection", t.projection),
        ("encoder", t.encoder),
        ("fusion", t.fusion),
        ("decoder", t.decoder),
        ("re-projection", t.reprojection),
        ("filter", t.filter),
        ("write", write),
        ("total", total),
    ];
    if args.timings && !args.json {
        for (name, d) in rows {
            eprintln!("{name:>14} {:9.1} ms", d.as_secs_f64() * 1e3);
        }
    }
    let timings: serde_json::Map<String, Value> = rows
        .iter()
        .map(|(name, d)| (name.replace('-', ""), json!(seconds(*d))))
        .collect();
    Ok(json!({
            "input": input,
            "output": output,
            "method": args.method,
            "input_points": done.input_points,
            "output_points": done.cloud.len(),
            "added": done.added,
            "mirrored": done.mirrored,
            "filtered_out": done.filtered_out,
            "symmetry_plane": done.plane.map(|p| json!({"x": p.offset, "support": p.support})),
            "orientation": {
                "heading": orientation.heading,
                "method": orientation.method,
                "refinement": orientation.refinement,
            },
            "cleaned": cleaned,
            "warnings": done.warnings,
            "seconds": timings,
    }))
}

/// The network's views as `DIR/input/` and `DIR/output/`; said so when the method ran none.
fn save_views(dir: &Path, input: &Path, done: &Completion, log: Log) -> anyhow::Result<()> {
    let Some(views) = &done.views else {
        log.warn(format!(
            "{}: --save-views: the method ran no network, so there are no views to save",
            input.display()
        ));
        return Ok(());
    };
    for (name, images) in [("input", &views.input), ("output", &views.output)] {
        let dir = dir.join(name);
        std::fs::create_dir_all(&dir)
            .with_context(|| format!("{}: cannot create", dir.display()))?;
        write_views(&dir, images)?;
    }
    Ok(())
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
    };
    let right = Layer {
        points: &done.normalized,
        colors: done.cloud.colors.as_deref(),
        added: &flags,
        title: format!("OUTPUT {} +{}", done.cloud.len(), done.added),
    };
    let img = render(&left, &right);
    atomic_write(path, |w| {
        img.write_to(w, image::ImageFormat::Png)
            .map_err(std::io::Error::other)
    })
    .with_context(|| format!("{}: cannot write the preview", path.display()))
}

/// `*` any run of characters, `?` one character.
fn matches(pattern: &[char], name: &[char]) -> bool {
    match (pattern.first(), name.first()) {
        (None, None) => true,
        (Some('*'), _) => {
            matches(&pattern[1..], name) || (!name.is_empty() && matches(pattern, &name[1..]))
        }
        (Some('?'), Some(_)) => matches(&pattern[1..], &name[1..]),
        (Some(p), Some(n)) => p == n && matches(&pattern[1..], &name[1..]),
        _ => false,
    }
}

/// Cloud files under `dir`, sorted, as paths relative to it.
fn cloud_files(dir: &Path, include: Option<&str>) -> anyhow::Result<Vec<PathBuf>> {
    let pattern: Option<Vec<char>> = include.map(|p| p.chars().collect());
    let mut found = Vec::new();
    let mut pending = vec![dir.to_path_buf()];
    // Links are followed, but every directory and file is taken once: a link back into the
    // tree (or to its parent) would otherwise repeat it down to the path-length limit.
    let mut seen = std::collections::HashSet::new();
    while let Some(d) = pending.pop() {
        if !seen.insert(d.canonicalize().unwrap_or_else(|_| d.clone())) {
            continue;
        }
        let entries =
            std::fs::read_dir(&d).with_context(|| format!("{}: cannot list", d.display()))?;
        for entry in entries {
            let path = entry.with_context(|| d.display().to_string())?.path();
            if path.is_dir() {
                pending.push(path);
                continue;
            }
            if !seen.insert(path.canonicalize().unwrap_or_else(|_| path.clone())) {
                continue;
            }
            let name: Vec<char> = path
                .file_name()
                .and_then(|n| n.to_str())
                .unwrap_or_default()
                .chars()
                .collect();
            let wanted = match &pattern {
                Some(p) => matches(p, &name),
                None => Format::from_path(&path).is_ok(),
            };
            if wanted {
                let relative = path
                    .strip_prefix(dir)
                    .expect("found under dir")
                    .to_path_buf();
                found.push(relative);
            }
        }
    }
    found.sort();
    Ok(found)
}

fn batch(
    input_dir: &Path,
    output_dir: &Path,
    args: &CompleteArgs,
    models: &Models,
    log: Log,
) -> anyhow::Result<()> {
    if !input_dir.is_dir() {
        bail!("{}: not a directory", input_dir.display());
    }
    let files = cloud_files(input_dir, args.include.as_deref())?;
    if files.is_empty() {
        bail!("{}: no point cloud files", input_dir.display());
    }
    std::fs::create_dir_all(output_dir)
        .with_context(|| format!("{}: cannot create", output_dir.display()))?;
    let bar = progress(files.len(), "completing", log);
    let next = AtomicUsize::new(0);
    let results: Mutex<Vec<(usize, anyhow::Result<Value>)>> = Mutex::new(Vec::new());
    // Each file's own messages would tear the bar; they are summarized at the end instead.
    let quiet_file = Log { quiet: true };
    let jobs = args.jobs.clamp(1, files.len());
    std::thread::scope(|scope| {
        for _ in 0..jobs {
            scope.spawn(|| loop {
                let i = next.fetch_add(1, Ordering::Relaxed);
                let Some(relative) = files.get(i) else {
                    break;
                };
                let input = input_dir.join(relative);
                let mut output = output_dir.join(relative);
                if let Some(format) = args.output_options.out_format {
                    output.set_extension(extension(format));
                }
                let result = output
                    .parent()
                    .map_or(Ok(()), std::fs::create_dir_all)
                    .with_context(|| format!("{}: cannot create", output.display()))
                    .and_then(|()| {
                        let views = args
                            .save_views
                            .as_ref()
                            .map(|d| d.join(relative.with_extension("")));
                        complete_file(&input, &output, views, args, models, quiet_file)
                    });
                results.lock().expect("no worker panics").push((i, result));
                bar.inc(1);
            });
        }
    });
    bar.finish_and_clear();
    let mut results = results.into_inner().expect("no worker panics");
    results.sort_by_key(|(i, _)| *i);
    let mut failed = Vec::new();
    let mut reports = Vec::new();
    for (i, result) in results {
        match result {
            Ok(report) => {
                for w in report["warnings"].as_array().into_iter().flatten() {
                    log.warn(format!(
                        "{}: {}",
                        input_dir.join(&files[i]).display(),
                        w.as_str().unwrap_or_default()
                    ));
                }
                reports.push(report);
            }
            Err(e) => {
                let message = format!("{e:#}").replace('\n', " ");
                eprintln!("failed: {message}");
                reports.push(json!({"input": input_dir.join(&files[i]), "error": message}));
                failed.push(message);
            }
        }
    }
    let done = files.len() - failed.len();
    log.info(format!(
        "{done} of {} files completed into {}, {} failed",
        files.len(),
        output_dir.display(),
        failed.len()
    ));
    if args.json {
        println!("{}", serde_json::to_string_pretty(&reports)?);
    }
    if !failed.is_empty() {
        bail!("{} of {} files failed", failed.len(), files.len());
    }
    Ok(())
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
    use crate::cli::{Cli, Command};
    use clap::Parser;

    #[test]
    fn the_library_defaults_are_the_commands() {
        let cli = Cli::try_parse_from(["mvpcc", "complete", "in.ply", "out.ply"]).unwrap();
        let Command::Complete(args) = cli.command else {
            panic!("parsed as another command");
        };
        assert_eq!(
            options(&args, Path::new("in.ply"), None),
            Options::default()
        );
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
    }
}
