use super::{synth, Log};
use crate::cli::args::PrepareArgs;
use crate::cli::streams::say;
use anyhow::{bail, Context};
use mvpcc::core::camera::{check_view_set, MAX_IMAGE_SIZE, MIN_IMAGE_SIZE};
use mvpcc::datagen::data::{
    discover, finished, prepare_model, Layout, Manifest, ModelEntry, PrepareParams, Skipped,
    Source, ViewsFrame, MANIFEST_FILE, MAX_SAMPLES, PARAMS_FILE, TEST, TRAIN,
};
use mvpcc::datagen::mesh::Forward;
use mvpcc::datagen::scan::{PartialParams, MAX_PARTIAL_POINTS};
use mvpcc::io::atomic_write;
use mvpcc::io::batch::lies_in;
use rayon::prelude::*;
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Mutex;

/// What `--json` prints.
#[derive(Debug, Serialize)]
struct Summary {
    models: usize,
    resumed: usize,
    train: usize,
    test: usize,
    samples: usize,
    skipped: usize,
    seconds: f64,
    models_per_second: f64,
    /// `i/n` when the run prepared one shard of the meshes.
    shard: Option<String>,
    /// The manifest written, by a run without `--shard`.
    manifest: Option<String>,
}

/// What one run of `prepare` did: models made now, models found made before, its seconds.
struct Finished {
    new: usize,
    resumed: usize,
    seconds: f64,
}

/// The run's summary over every model prepared so far (`done`, in any order) and every mesh
/// skipped; writes the manifest when `manifest` names the output folder (a run without
/// `--shard`).
fn summarize(
    mut done: Vec<ModelEntry>,
    mut skipped: Vec<Skipped>,
    run: &Finished,
    shard: Option<String>,
    manifest: Option<(&Path, PrepareParams)>,
) -> anyhow::Result<Summary> {
    done.sort_by(|a, b| (&a.category, &a.name).cmp(&(&b.category, &b.name)));
    skipped.sort_by(|a, b| a.path.cmp(&b.path));
    Ok(Summary {
        models: done.len(),
        resumed: run.resumed,
        train: done.iter().filter(|m| m.split == TRAIN).count(),
        test: done.iter().filter(|m| m.split == TEST).count(),
        samples: done.iter().map(|m| m.samples.len()).sum(),
        skipped: skipped.len(),
        seconds: run.seconds,
        models_per_second: if run.seconds > 0.0 {
            run.new as f64 / run.seconds
        } else {
            0.0
        },
        shard,
        manifest: match manifest {
            Some((out, params)) => Some(write_manifest(out, params, done, skipped)?),
            None => None,
        },
    })
}

/// The meshes to prepare: `--meshes`, or `--synth` objects generated into OUT/meshes.
fn meshes_dir(args: &PrepareArgs, log: Log) -> anyhow::Result<PathBuf> {
    match (&args.meshes, args.synth) {
        (Some(dir), _) => {
            if !dir.is_dir() {
                bail!("{}: not a directory", dir.display());
            }
            Ok(dir.clone())
        }
        (None, Some(count)) => {
            let dir = args.out.join("meshes");
            synth::generate(
                &dir,
                count,
                &args.synth_options.category,
                args.synth_options.seed,
                true,
                log,
            )?;
            Ok(dir)
        }
        (None, None) => unreachable!("clap requires --meshes or --synth"),
    }
}

/// Prepares `todo` in parallel with a progress bar: the models made and the meshes skipped
/// for a problem of their own; any other error (a full disk) stops the run.
fn prepare_all(
    todo: &[&Source],
    params: &PrepareParams,
    layout: &Layout,
    log: Log,
) -> anyhow::Result<(Vec<ModelEntry>, Vec<Skipped>)> {
    let bar = super::progress(todo.len(), "prepare", log);
    let stop = AtomicBool::new(false);
    let failed = Mutex::new(Vec::new());
    let fatal = Mutex::new(None);
    let made: Vec<ModelEntry> = todo
        .par_iter()
        .filter_map(|source| {
            if stop.load(Ordering::Relaxed) {
                return None;
            }
            let result = prepare_model(source, params, layout);
            bar.inc(1);
            match result {
                Ok(entry) => Some(entry),
                Err(e) if e.is_input_problem() => {
                    bar.suspend(|| log.warn(format!("skipped {e}")));
                    failed.lock().expect("not poisoned").push(Skipped {
                        path: source.path.clone(),
                        problem: e.to_string(),
                    });
                    None
                }
                Err(e) => {
                    stop.store(true, Ordering::Relaxed);
                    fatal.lock().expect("not poisoned").get_or_insert(e);
                    None
                }
            }
        })
        .collect();
    bar.finish_and_clear();
    if let Some(e) = fatal.into_inner().expect("not poisoned") {
        return Err(e.into());
    }
    Ok((made, failed.into_inner().expect("not poisoned")))
}

/// Writes the dataset's manifest; its path.
fn write_manifest(
    out: &Path,
    params: PrepareParams,
    models: Vec<ModelEntry>,
    skipped: Vec<Skipped>,
) -> anyhow::Result<String> {
    let manifest = Manifest {
        mvpcc_version: env!("CARGO_PKG_VERSION").to_string(),
        params,
        models,
        skipped,
    };
    let path = out.join(MANIFEST_FILE);
    atomic_write(&path, |w| {
        serde_json::to_writer_pretty(&mut *w, &manifest).map_err(std::io::Error::other)
    })
    .with_context(|| format!("{}: cannot write", path.display()))?;
    Ok(path.display().to_string())
}

/// The settings the options give, checked ([`check`]).
fn params(args: &PrepareArgs) -> anyhow::Result<PrepareParams> {
    check(args)?;
    Ok(PrepareParams {
        views: args.views.0.clone(),
        size: args.size,
        gt_size: args.gt_size,
        gt_voxel: args.gt_voxel,
        samples: args.samples,
        train_fraction: args.split,
        partial: PartialParams {
            kinds: args.partial,
            min_points: args.min_points,
            max_points: args.max_points,
            max_yaw_deg: args.yaw_error,
            max_noise: args.noise,
        },
        up: args.up.to_string(),
        forward: args.forward.to_string(),
        seed: args.synth_options.seed,
        clouds: args.clouds,
        allow_missing_materials: args.allow_missing_materials,
        max_triangles: args.max_triangles,
        views_frame: ViewsFrame::Object,
    })
}

/// Refuses options no data can be made with, before anything is written.
fn check(args: &PrepareArgs) -> anyhow::Result<()> {
    if !(0.0..=1.0).contains(&args.split) {
        bail!("--split must lie in [0, 1], got {}", args.split);
    }
    if !(1..=MAX_SAMPLES).contains(&args.samples) {
        bail!(
            "--samples must lie in 1..={MAX_SAMPLES}, got {}",
            args.samples
        );
    }
    if let Some(count) = args.synth {
        synth::check_count(count, "--synth")?;
    }
    if args.size.min(args.gt_size) < MIN_IMAGE_SIZE {
        bail!("--size and --gt-size must be at least {MIN_IMAGE_SIZE} pixels");
    }
    if args.size.max(args.gt_size) > MAX_IMAGE_SIZE {
        bail!("--size and --gt-size must be at most {MAX_IMAGE_SIZE} pixels");
    }
    if args.min_points == 0 || args.min_points > args.max_points {
        bail!(
            "--min-points ({}) must be at least 1 and at most --max-points ({})",
            args.min_points,
            args.max_points
        );
    }
    if args.max_points > MAX_PARTIAL_POINTS {
        bail!(
            "--max-points {} is above the largest partial this build scans ({MAX_PARTIAL_POINTS})",
            args.max_points
        );
    }
    if !(args.gt_voxel >= 0.0 && args.noise >= 0.0 && args.yaw_error >= 0.0) {
        bail!("--gt-voxel, --noise and --yaw-error must not be negative");
    }
    if matches!(args.forward, Forward::Axis(f) if f.axis == args.up.axis) {
        bail!(
            "--up {} and --forward {} must be different axes",
            args.up,
            args.forward
        );
    }
    check_view_set(&args.views.0)?;
    Ok(())
}

/// Records the settings on first use; a resumed run must use the same ones, or the
/// directory would mix data made in two ways.
fn claim(out: &Path, params: &PrepareParams) -> anyhow::Result<()> {
    let path = out.join(PARAMS_FILE);
    match std::fs::read_to_string(&path) {
        Ok(text) => {
            let before: PrepareParams = serde_json::from_str(&text)
                .with_context(|| format!("{}: unreadable settings file", path.display()))?;
            if &before != params {
                let now = serde_json::to_value(params)?;
                let then = serde_json::to_value(&before)?;
                let changed: Vec<String> = now
                    .as_object()
                    .into_iter()
                    .flatten()
                    .filter(|(k, v)| then.get(k.as_str()) != Some(v))
                    .map(|(k, v)| {
                        format!(
                            "{k} {} → {v}",
                            then.get(k.as_str()).unwrap_or(&serde_json::Value::Null)
                        )
                    })
                    .collect();
                bail!(
                    "{}: was prepared with other settings ({}); use another --out directory",
                    out.display(),
                    changed.join(", ")
                );
            }
            Ok(())
        }
        Err(_) => atomic_write(&path, |w| {
            serde_json::to_writer_pretty(&mut *w, params).map_err(std::io::Error::other)
        })
        .with_context(|| format!("{}: cannot write", path.display())),
    }
}

pub(super) fn run(args: PrepareArgs, log: Log) -> anyhow::Result<()> {
    let params = params(&args)?;
    let out = &args.out;
    super::check_out_dir(out)?;
    let (meshes, mut sources, mut skipped) = find_meshes(&args, log)?;
    std::fs::create_dir_all(out).with_context(|| format!("{}: cannot create", out.display()))?;
    claim(out, &params)?;
    if let Some(shard) = args.shard {
        sources.retain(|s| shard.owns(&format!("{}/{}", s.category, s.name)));
        // The run without --shard that writes the manifest lists them.
        skipped.clear();
    }
    let layout = Layout { root: out.clone() };
    let (mut done, todo) = resume(&layout, &sources, &params);
    let resumed = done.len();
    if resumed > 0 {
        log.info(format!(
            "{resumed} of {} models already prepared",
            sources.len()
        ));
    }
    let started = std::time::Instant::now();
    let (made, failed) = prepare_all(&todo, &params, &layout, log)?;
    let run = Finished {
        new: made.len(),
        resumed,
        seconds: started.elapsed().as_secs_f64(),
    };
    done.extend(made);
    skipped.extend(failed);
    let manifest = args.shard.is_none().then_some((out.as_path(), params));
    let summary = summarize(
        done,
        skipped,
        &run,
        args.shard.map(|s| s.to_string()),
        manifest,
    )?;
    log.info(summary_line(&summary, run.new));
    if args.json {
        say(serde_json::to_string_pretty(&summary)?)?;
    }
    if summary.models == 0 && args.shard.is_none() {
        bail!("{}: none of the meshes could be used", meshes.display());
    }
    Ok(())
}

/// The meshes folder and what it holds: the meshes to prepare and the files skipped. A
/// `--meshes` folder is read before anything is written under `--out`, so one without meshes
/// leaves no output behind; an `--out` inside it is refused.
fn find_meshes(
    args: &PrepareArgs,
    log: Log,
) -> anyhow::Result<(PathBuf, Vec<Source>, Vec<Skipped>)> {
    let meshes = meshes_dir(args, log)?;
    // Links followed (a link to the meshes folder is that folder); `--out` need not exist yet.
    let out_inside = meshes
        .canonicalize()
        .is_ok_and(|meshes| lies_in(&args.out, &meshes));
    if args.meshes.is_some() && out_inside {
        bail!(
            "{}: --out lies in the --meshes folder {}, whose next scan would read its clouds as meshes",
            args.out.display(),
            meshes.display()
        );
    }
    let (sources, skipped) = discover(&meshes)?;
    if sources.is_empty() {
        bail!(
            "{}: no meshes found (.obj, .ply, .gltf, .glb)",
            meshes.display()
        );
    }
    Ok((meshes, sources, skipped))
}

/// The models of `sources` a previous run finished (their entries) and those still to do.
fn resume<'a>(
    layout: &Layout,
    sources: &'a [Source],
    params: &PrepareParams,
) -> (Vec<ModelEntry>, Vec<&'a Source>) {
    let mut done = Vec::new();
    let mut todo = Vec::new();
    for s in sources {
        match finished(layout, s, params) {
            Some(entry) => done.push(entry),
            None => todo.push(s),
        }
    }
    (done, todo)
}

/// The run's closing line on stderr; `new` models were prepared by this run.
fn summary_line(summary: &Summary, new: usize) -> String {
    format!(
        "prepared {} models ({} train, {} test; {} new at {:.2}/s, {} resumed), {} samples; {}",
        summary.models,
        summary.train,
        summary.test,
        new,
        summary.models_per_second,
        summary.resumed,
        summary.samples,
        match (&summary.manifest, &summary.shard) {
            (Some(path), _) => format!("{} skipped — see {path}", summary.skipped),
            (None, Some(shard)) => format!(
                "shard {shard}: once every shard is done, run the same command without --shard \
                 to write the manifest"
            ),
            (None, None) => unreachable!("a run without --shard writes the manifest"),
        }
    )
}
