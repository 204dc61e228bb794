//! `mvpcc train-orient`: options → settings, the device, a progress bar over the loop, and the
//! run's files (weights, config, settings, log).

use super::Log;
use crate::cli::args::TrainOrientArgs;
use indicatif::ProgressBar;
use mvpcc::complete::orient::OrienterConfig;
use mvpcc::train::orient::{
    check_run_dir, train_orienter_in, OrientData, OrientRecord, OrientSettings,
};
use std::path::PathBuf;

pub(super) fn run(args: TrainOrientArgs, log: Log) -> anyhow::Result<()> {
    let (config, settings) = settings(&args)?;
    let out = args.out.clone().unwrap_or_else(|| {
        let name = args
            .data
            .file_name()
            .map_or("data".into(), |n| n.to_string_lossy().into_owned());
        PathBuf::from("runs").join(format!("orient-{name}"))
    });
    check_run_dir(&out)?;
    let data = OrientData::scan(&args.data)?;
    let opened = super::open_device(args.device, log)?;
    log.info(format!(
        "training the orientation network on {} ({}), {} steps of {}",
        args.data.display(),
        opened.description,
        settings.steps,
        settings.batch
    ));
    let bar = super::step_bar(settings.steps, log);
    let cache = args.cache_mb << 20;
    let (weights, scores) = train_orienter_in(
        &out,
        &data,
        &config,
        &settings,
        &opened.device,
        cache,
        show(&bar),
    )?;
    bar.finish_and_clear();
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
/// steps, and the last validation) and prints each validation above it.
fn show(bar: &ProgressBar) -> impl FnMut(&OrientRecord) + '_ {
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
    }
}
