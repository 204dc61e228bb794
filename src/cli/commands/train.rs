//! `mvpcc train`: options → settings (or a run's saved settings on `--resume`), the device,
//! Ctrl-C, and a progress bar over the training loop.

use super::Log;
use crate::cli::args::TrainArgs;
use crate::cli::streams::{say, tell};
use mvpcc::complete::{named_shape, BUILTIN_SHAPE};

use clap::ValueEnum;
use indicatif::ProgressBar;
use mvpcc::model::device::{open_list, Backend};
use mvpcc::model::gan::StepLosses;
use mvpcc::model::{Dilation, ModelConfig, Preset};
use mvpcc::train::dataset::scan_split;
use mvpcc::train::{
    drops_colour, resume, train, InitWeights, Job, LogRecord, Monitor, Summary, TrainSettings,
};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

/// The options given on the command line applied over `base`.
fn apply(args: &TrainArgs, mut s: TrainSettings) -> TrainSettings {
    if let Some(v) = &args.views {
        s.views = v.0.clone();
    }
    macro_rules! set {
        ($($field:ident <- $arg:ident),*) => {
            $(if let Some(v) = args.$arg { s.$field = v; })*
        };
    }
    set!(batch <- batch, accumulate <- accumulate, stage_steps <- stage_steps,
        patience <- patience, val_every <- val_every, val_samples <- val_samples,
        seen_samples <- seen_samples, val_fraction <- val_fraction, checkpoint_every <- checkpoint_every, keep <- keep,
        log_every <- log_every, seed <- seed, tv_from_stage <- tv_from_stage,
        warmup_steps <- warmup_steps);
    let loss = &mut s.loss;
    for (weight, arg) in [
        (&mut loss.l1, args.loss_l1),
        (&mut loss.adversarial, args.loss_adversarial),
        (&mut loss.perceptual, args.loss_perceptual),
        (&mut loss.style, args.loss_style),
        (&mut loss.occupancy, args.loss_bce),
        (&mut loss.tv, args.loss_tv),
        (&mut loss.depth, args.loss_depth),
    ] {
        *weight = arg.unwrap_or(*weight);
    }
    loss.adversarial_kind = args.adversarial.unwrap_or(loss.adversarial_kind);
    loss.tv_scale = args.tv_scale.unwrap_or(loss.tv_scale);
    loss.feature_planes = args.feature_planes.unwrap_or(loss.feature_planes);
    if let Some(lr) = args.lr {
        s.stage_rates = vec![lr, lr / 10.0, lr / 100.0];
    }
    if let Some(path) = &args.vgg19 {
        s.vgg19 = Some(path.clone());
    }
    if args.no_mirror {
        s.augment.mirror = false;
    }
    if let Some(y) = args.max_yaw {
        s.augment.max_yaw_deg = y;
    }
    if let Some(j) = args.color_jitter {
        s.augment.color_jitter = j;
    }
    s
}

/// The preset `--config` names, if it names one.
fn preset(config: Option<&str>) -> Option<Preset> {
    config.and_then(|name| <Preset as ValueEnum>::from_str(name, true).ok())
}

/// The defaults of a new run: a preset's loss where `--config` names one.
fn preset_settings(config: Option<&str>) -> TrainSettings {
    let mut settings = TrainSettings::default();
    if let Some(preset) = preset(config) {
        settings.loss = preset.loss();
    }
    settings
}

fn check(settings: &TrainSettings, model: &ModelConfig) -> anyhow::Result<()> {
    model.validate()?;
    Ok(settings.validate()?)
}

/// The settings and model config of the run: from the options on a new run, from the run's
/// files on `--resume` (options that would change them are refused).
fn resolve(args: &TrainArgs, run: &Path) -> anyhow::Result<(TrainSettings, ModelConfig)> {
    let fresh_model = |mut base: ModelConfig| {
        base.channels = args.channels.unwrap_or(base.channels);
        base.size = args.size.unwrap_or(base.size);
        let base = match args.fusion {
            Some(fusion) => base.with_fusion_kind(fusion),
            None => base,
        };
        let base = match args.occupancy {
            Some(p) => base.with_occupancy(Some(p)),
            None => base,
        };
        let base = match args.dilation {
            // Written as `None` when the original's, as `with_fusion_kind` does.
            Some(d) => base.with_dilation((d == Dilation::Decoder).then_some(d)),
            None => base,
        };
        let base = match args.fusion_norm {
            Some(norm) => base.with_fusion_norm((!norm).then_some(false)),
            None => base,
        };
        if args.input_copy {
            base.with_input_copy_kind(true)
        } else {
            base
        }
    };
    let (mut settings, mut model) = if args.resume {
        let saved = resume::saved(run)?;
        let settings = apply(args, saved.0.clone());
        let model = match &args.config {
            Some(name) => fresh_model(named_shape(name)?),
            None => fresh_model(saved.1.clone()),
        }
        .with_views(saved.1.views);
        resume::check_unchanged(run, &saved, &settings, &model)?;
        (settings, model)
    } else {
        let mut settings = apply(args, preset_settings(args.config.as_deref()));
        settings.init = args
            .init
            .as_deref()
            .map(|path| {
                InitWeights::find(path, args.init_discriminator.clone(), args.widen.is_some())
            })
            .transpose()?;
        let base = match (&args.config, &settings.init) {
            (Some(name), _) => named_shape(name)?,
            (None, Some(init)) => {
                let own = init.config()?;
                ModelConfig {
                    width: args.widen.unwrap_or(own.width),
                    ..own
                }
            }
            (None, None) => named_shape(BUILTIN_SHAPE)?,
        };
        (settings, fresh_model(base))
    };
    model.views = settings.views.len();
    check(&settings, &model)?;
    if let Some(init) = settings.init.as_mut().filter(|_| !args.resume) {
        // The discriminator beside colour weights judges colour: a geometry-only run starts a
        // fresh one unless --init-discriminator names one.
        if args.init_discriminator.is_none() && drops_colour(&init.config()?, &model) {
            init.discriminator = None;
        }
        init.check(&model)?;
    }
    Ok((settings, model))
}

struct Progress {
    bar: ProgressBar,
    log: Log,
    stop: Arc<AtomicBool>,
}

impl Monitor for Progress {
    fn message(&mut self, text: &str) {
        if !self.log.quiet() {
            self.bar.suspend(|| tell(text));
        }
    }

    fn warn(&mut self, text: &str) {
        self.bar.suspend(|| self.log.warn(text));
    }

    fn start(&mut self, first_step: u64, planned: u64) {
        self.bar.set_length(planned);
        self.bar.set_position(first_step);
        self.bar.reset_eta();
    }

    fn stepped(&mut self, step: u64, losses: &StepLosses) {
        self.bar.set_position(step);
        self.bar.set_message(format!(
            "G {:.3} D {:.3} L1 {:.4}",
            losses.generator, losses.discriminator, losses.l1
        ));
    }

    fn record(&mut self, record: &LogRecord) {
        if let Some(line) = record.said().filter(|_| !self.log.quiet()) {
            self.bar.suspend(|| tell(line));
        }
    }

    fn interrupted(&self) -> bool {
        self.stop.load(Ordering::SeqCst)
    }
}

/// Measured on lavapipe (tests/wgpu.rs), where the rest of the discriminator and a generator
/// step agree with the CPU. The `cuda` feature fuses too, but no GPU has measured it.
const WGPU_DISCRIMINATOR: &str = "on wgpu the discriminator's last layer learns from a wrong \
     gradient (apparently a Burn 0.22 fusion fault, docs/gpu.md): the adversarial term (and \
     without --vgg19 the perceptual and style terms) trains it; set them to 0, or train on the CPU";

fn default_run(data: &Path) -> PathBuf {
    let name = data
        .canonicalize()
        .ok()
        .and_then(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
        .unwrap_or_else(|| "run".to_string());
    Path::new("runs").join(name)
}

pub fn run(args: TrainArgs, log: Log) -> anyhow::Result<()> {
    let run = args.out.clone().unwrap_or_else(|| default_run(&args.data));
    super::check_out_dir(&run)?;
    let (settings, model) = resolve(&args, &run)?;
    // Before anything is said, so that a wrong path gets its one error line alone.
    scan_split(&args.data, "train")?;
    let (opened, replicas, device_names) = match &args.devices {
        Some(list) => {
            let mut all = open_list(list)?;
            if settings.batch < all.len() {
                anyhow::bail!(
                    "--devices {list}: {} replicas need --batch {} or more (each takes a share \
                     of every micro-batch)",
                    all.len(),
                    all.len()
                );
            }
            let names = all.iter().map(|o| o.description.clone()).collect();
            let others: Vec<_> = all.drain(1..).map(|o| o.device).collect();
            (all.remove(0), others, names)
        }
        None => (
            super::open_device(args.device, log)?,
            Vec::new(),
            Vec::new(),
        ),
    };
    let on = match replicas.len() {
        0 => opened.description.clone(),
        n => format!("{} replicas, the first on {}", n + 1, opened.description),
    };
    log.info(format!(
        "training {} ({}) on {on} into {}",
        args.data.display(),
        model.describe(),
        run.display()
    ));

    let features_terms = settings.loss.perceptual != 0.0 || settings.loss.style != 0.0;
    if let Some(p) = preset(args.config.as_deref()).filter(|p| p.wants_vgg19()) {
        if settings.vgg19.is_none() && features_terms && !args.resume {
            log.warn(format!(
                "--config {}: its perceptual and style terms are VGG19's, which mvpcc does not \
                 ship; without --vgg19 FILE they compare the discriminator's features of every \
                 plane (docs/paper.md, *The presets*)",
                p.to_possible_value()
                    .map_or_else(String::new, |v| v.get_name().to_owned())
            ));
        }
    }

    if opened.backend == Backend::Wgpu
        && settings.loss.needs_discriminator(settings.vgg19.is_some())
    {
        log.warn(WGPU_DISCRIMINATOR);
    }

    // The first Ctrl-C asks the loop to checkpoint and stop; a second one stops at once.
    let stop = crate::cli::interrupt::graceful();

    let bar = super::step_bar(0, log);
    let mut monitor = Progress { bar, log, stop };
    let job = Job {
        data: args.data.clone(),
        run: run.clone(),
        model,
        settings: settings.clone(),
        max_steps: args.steps,
        device: opened.device,
        replicas,
        device_names,
        resume: args.resume,
        workers: args.workers,
        prefetch: args.prefetch,
        cache_bytes: args.cache_mb << 20,
    };
    let result = train(job, &mut monitor);
    monitor.bar.finish_and_clear();
    report(&result?, &settings, &run, args.json, log)
}

/// How the run ended and its best validation on stderr; with `json`, the report on stdout.
fn report(
    summary: &Summary,
    settings: &TrainSettings,
    run: &Path,
    json: bool,
    log: Log,
) -> anyhow::Result<()> {
    for line in summary.said(settings.stage_rates.len(), run) {
        log.info(line);
    }
    if json {
        say(serde_json::to_string_pretty(&summary.report(run))?)?;
    }
    Ok(())
}
