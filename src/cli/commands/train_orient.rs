//! `mvpcc train-orient`: options → settings, the device, a progress bar over the loop, and the
//! run's files (weights, config, settings, log).

use super::Log;
use crate::cli::args::TrainOrientArgs;
use anyhow::Context;
use indicatif::ProgressBar;
use mvpcc::complete::orient::OrienterConfig;
use mvpcc::io::atomic_write;
use mvpcc::train::orient::{
    train_orienter, OrientData, OrientRecord, OrientSettings, OrientTrainError,
};
use std::fs::File;
use std::io::Write;
use std::path::{Path, PathBuf};

pub const WEIGHTS_FILE: &str = "orienter.safetensors";

pub(super) fn run(args: TrainOrientArgs, log: Log) -> anyhow::Result<()> {
    let (config, settings) = settings(&args)?;
    let out = output_dir(&args)?;
    let data = OrientData::scan(&args.data)?;
    std::fs::create_dir_all(&out).with_context(|| out.display().to_string())?;
    write_file(
        &out.join("config.json"),
        serde_json::to_string_pretty(&config)?.as_bytes(),
    )?;
    write_file(
        &out.join("train-orient.json"),
        serde_json::to_string_pretty(&settings)?.as_bytes(),
    )?;
    let opened = super::open_device(args.device, log)?;
    log.info(format!(
        "training the orientation network on {} ({}), {} steps of {}",
        args.data.display(),
        opened.description,
        settings.steps,
        settings.batch
    ));
    let log_path = out.join("log.jsonl");
    let log_file =
        std::fs::File::create(&log_path).with_context(|| log_path.display().to_string())?;
    let bar = super::step_bar(settings.steps, log);
    let cache = args.cache_mb << 20;
    let monitor = monitor(&bar, log_file);
    let (orienter, scores) =
        train_orienter(&data, &config, &settings, &opened.device, cache, monitor).map_err(|e| {
            match e {
                OrientTrainError::Monitor { .. } => {
                    anyhow::Error::new(e).context(log_path.display().to_string())
                }
                e => e.into(),
            }
        })?;
    bar.finish_and_clear();
    let weights = out.join(WEIGHTS_FILE);
    write_file(&weights, &orienter.to_bytes()?)?;
    log.info(format!(
        "{}: best validation median {:.2}°, p95 {:.2}°, flips {:.2} %",
        weights.display(),
        scores.median,
        scores.p95,
        100.0 * scores.flips
    ));
    Ok(())
}

/// The network's config and the loop's settings the options give, refused when invalid.
fn settings(args: &TrainOrientArgs) -> anyhow::Result<(OrienterConfig, OrientSettings)> {
    let config = OrienterConfig::new().with_points(args.points);
    let settings = OrientSettings {
        batch: args.batch,
        steps: args.steps,
        learning_rate: args.lr,
        val_samples: args.val_samples,
        val_every: args.val_every,
        seed: args.seed,
        ..OrientSettings::default()
    };
    config
        .validate()
        .map_err(|e| anyhow::anyhow!("--points: {e}"))?;
    settings
        .validate()
        .map_err(|e| anyhow::anyhow!("invalid settings: {e}"))?;
    Ok((config, settings))
}

/// What each step's record does: moves `bar` (its message the loss smoothed over about 50
/// steps, and the last validation), prints each validation above it, and appends the record
/// to the run's `log.jsonl`.
fn monitor(
    bar: &ProgressBar,
    mut log_file: File,
) -> impl FnMut(&OrientRecord) -> std::io::Result<()> + '_ {
    let mut smoothed = None;
    move |record| {
        let loss = f64::from(record.loss);
        let s = smoothed.map_or(loss, |s: f64| 0.98 * s + 0.02 * loss);
        smoothed = Some(s);
        bar.set_position(record.step);
        if let Some(v) = &record.validation {
            bar.set_message(format!(
                "loss {s:.4}  val median {:.1}° p95 {:.1}° flips {:.1} %",
                v.median,
                v.p95,
                100.0 * v.flips
            ));
            bar.println(format!(
                "step {}: validation median {:.2}°, p95 {:.2}°, flips {:.2} %",
                record.step,
                v.median,
                v.p95,
                100.0 * v.flips
            ));
        }
        let line = serde_json::to_string(record).map_err(std::io::Error::other)?;
        writeln!(log_file, "{line}")
    }
}

/// The run's directory (`--out`, or `runs/orient-<data>`); refused when a file holds its name
/// or it already holds a trained network.
fn output_dir(args: &TrainOrientArgs) -> anyhow::Result<PathBuf> {
    let out = args.out.clone().unwrap_or_else(|| {
        let name = args
            .data
            .file_name()
            .map_or("data".into(), |n| n.to_string_lossy().into_owned());
        PathBuf::from("runs").join(format!("orient-{name}"))
    });
    super::check_out_dir(&out)?;
    if out.join(WEIGHTS_FILE).exists() {
        anyhow::bail!(
            "{}: already holds {WEIGHTS_FILE}; choose another --out",
            out.display()
        );
    }
    Ok(out)
}

fn write_file(path: &Path, bytes: &[u8]) -> anyhow::Result<()> {
    atomic_write(path, |w| w.write_all(bytes)).with_context(|| path.display().to_string())
}
