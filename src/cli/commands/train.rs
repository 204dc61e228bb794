//! `mvpcc train`: options → settings (or a run's saved settings on `--resume`), the device,
//! Ctrl-C, and a progress bar over the training loop.

use super::{model_shape, Log, BUILTIN};
use crate::cli::args::TrainArgs;
use crate::cli::streams::{say, tell};
use anyhow::{bail, Context};
use indicatif::ProgressBar;
use mvpcc::model::gan::StepLosses;
use mvpcc::model::ModelConfig;
use mvpcc::train::dataset::scan_split;
use mvpcc::train::{
    train, InitWeights, Job, LogRecord, Monitor, Outcome, Summary, TrainSettings, CONFIG_FILE,
    SETTINGS_FILE,
};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

/// Settings a resumed run may change: they decide how the run is carried out and reported, not
/// what it computes (the training samples scored beside the validation decide nothing).
const OPERATIONAL: [&str; 3] = ["log_every", "keep", "seen_samples"];

fn read_saved<T: serde::de::DeserializeOwned>(path: &Path) -> anyhow::Result<T> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("{}: cannot resume without it", path.display()))?;
    serde_json::from_str(&text).with_context(|| format!("{}: unreadable", path.display()))
}

/// The run's settings, those it was saved without at their defaults: a run started before a
/// setting existed ran as its default (the depth term's weight, for one, was 0 before it could
/// be set).
fn read_saved_settings(path: &Path) -> anyhow::Result<TrainSettings> {
    let mut saved: Value = read_saved(path)?;
    fill_missing(&mut saved, &serde_json::to_value(TrainSettings::default())?);
    serde_json::from_value(saved).with_context(|| format!("{}: unreadable", path.display()))
}

fn fill_missing(saved: &mut Value, defaults: &Value) {
    let (Value::Object(saved), Value::Object(defaults)) = (saved, defaults) else {
        return;
    };
    for (key, default) in defaults {
        match saved.get_mut(key) {
            Some(value) => fill_missing(value, default),
            None => {
                saved.insert(key.clone(), default.clone());
            }
        }
    }
}

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

/// The first field of `new` that differs from `saved`, ignoring `except`, named down to the
/// innermost field (`loss.style`).
fn first_difference<T: serde::Serialize>(saved: &T, new: &T, except: &[&str]) -> Option<String> {
    let (Ok(a), Ok(b)) = (serde_json::to_value(saved), serde_json::to_value(new)) else {
        return None;
    };
    differing_field(&a, &b, except, "")
}

fn differing_field(a: &Value, b: &Value, except: &[&str], path: &str) -> Option<String> {
    let (Value::Object(a), Value::Object(b)) = (a, b) else {
        return (a != b).then(|| format!("{path}: the run has {a}, the options give {b}"));
    };
    a.iter()
        .filter(|(k, _)| !except.contains(&k.as_str()))
        .find_map(|(k, v)| {
            let inner = if path.is_empty() {
                k.clone()
            } else {
                format!("{path}.{k}")
            };
            differing_field(v, b.get(k).unwrap_or(&Value::Null), &[], &inner)
        })
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
        if args.input_copy {
            base.with_input_copy_kind(true)
        } else {
            base
        }
    };
    let (settings, mut model) = if args.resume {
        let saved = read_saved_settings(&run.join(SETTINGS_FILE))?;
        let saved_model: ModelConfig = read_saved(&run.join(CONFIG_FILE))?;
        let settings = apply(args, saved.clone());
        if let Some(diff) = first_difference(&saved, &settings, &OPERATIONAL) {
            bail!(
                "{}: a resumed run keeps its settings ({diff})",
                run.display()
            );
        }
        let model = match &args.config {
            Some(name) => fresh_model(model_shape(name)?),
            None => fresh_model(saved_model.clone()),
        }
        .with_views(saved_model.views);
        if let Some(diff) = first_difference(&saved_model, &model, &[]) {
            bail!("{}: a resumed run keeps its model ({diff})", run.display());
        }
        (settings, model)
    } else {
        let mut settings = apply(args, TrainSettings::default());
        settings.init = args
            .init
            .as_deref()
            .map(|path| {
                InitWeights::find(path, args.init_discriminator.clone(), args.widen.is_some())
            })
            .transpose()?;
        let base = match (&args.config, &settings.init) {
            (Some(name), _) => model_shape(name)?,
            (None, Some(init)) => {
                let own = init.config()?;
                ModelConfig {
                    width: args.widen.unwrap_or(own.width),
                    ..own
                }
            }
            (None, None) => model_shape(BUILTIN)?,
        };
        (settings, fresh_model(base))
    };
    model.views = settings.views.len();
    check(&settings, &model)?;
    if let Some(init) = settings.init.as_ref().filter(|_| !args.resume) {
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
        let line = match record {
            LogRecord::Train { .. } => return,
            LogRecord::Validation {
                step, scores, seen, ..
            } => format!(
                "step {step}: validation CD {} F1@0.01 {:.3} (P {:.3} R {:.3}), geometry PSNR {:.2} dB SSIM {:.3}{}{}",
                cd_text(scores.cd),
                scores.f1,
                scores.precision,
                scores.recall,
                scores.geometry.psnr,
                scores.geometry.ssim,
                scores.color.map_or(String::new(), |c| format!(", colour PSNR {:.2} dB", c.psnr)),
                seen.as_ref().map_or(String::new(), |s| format!(
                    "; training samples CD {} F1@0.01 {:.3}",
                    cd_text(s.cd),
                    s.f1
                )),
            ),
            LogRecord::Baseline { scores } => format!(
                "partial inputs of the {} validation samples: CD {} F1@0.01 {:.3}",
                scores.samples,
                scores.cd.map_or("-".to_string(), |c| format!("{c:.3e}")),
                scores.f1
            ),
        };
        if !self.log.quiet() {
            self.bar.suspend(|| tell(line));
        }
    }

    fn interrupted(&self) -> bool {
        self.stop.load(Ordering::SeqCst)
    }
}

fn cd_text(cd: Option<f64>) -> String {
    cd.map_or("- (empty output)".to_string(), |c| format!("{c:.3e}"))
}

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
    let opened = super::open_device(args.device, log)?;
    log.info(format!(
        "training {} ({}) on {} into {}",
        args.data.display(),
        model.describe(),
        opened.description,
        run.display()
    ));

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
        resume: args.resume,
        workers: args.workers,
        prefetch: args.prefetch,
        cache_bytes: args.cache_mb << 20,
    };
    let result = train(job, &mut monitor);
    monitor.bar.finish_and_clear();
    report(&result?, &settings, &run, args.json, log)
}

/// How the run ended and its best validation on stderr; with `json`, the summary on stdout.
fn report(
    summary: &Summary,
    settings: &TrainSettings,
    run: &Path,
    json: bool,
    log: Log,
) -> anyhow::Result<()> {
    match summary.outcome {
        Outcome::Interrupted => log.info(format!(
            "interrupted at step {}: checkpoint {} (continue with --resume)",
            summary.state.step,
            summary.checkpoint.display()
        )),
        Outcome::StepLimit => log.info(format!(
            "stopped at step {} (--steps): checkpoint {}",
            summary.state.step,
            summary.checkpoint.display()
        )),
        Outcome::Finished => log.info(format!(
            "all {} stages done at step {}: checkpoint {}",
            settings.stage_rates.len(),
            summary.state.step,
            summary.checkpoint.display()
        )),
    }
    if let (Some(cd), Some(step)) = (summary.state.best_cd, summary.state.best_step) {
        log.info(format!(
            "best validation CD {cd:.3e} at step {step}: {}",
            run.join("best").display()
        ));
    }
    if json {
        let json = serde_json::json!({
            "run": run,
            "outcome": format!("{:?}", summary.outcome).to_lowercase(),
            "step": summary.state.step,
            "stage": summary.state.stage + 1,
            "checkpoint": summary.checkpoint,
            "best_cd": summary.state.best_cd,
            "best_step": summary.state.best_step,
            "baseline": summary.baseline,
            "validation": summary.last,
            "seen": summary.last_seen,
        });
        say(serde_json::to_string_pretty(&json)?)?;
    }
    Ok(())
}
