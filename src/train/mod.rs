//! The GAN training loop behind `mvpcc train`: samples from a "shapenet-views" directory
//! ([`dataset`]) assembled ahead of time on worker threads ([`loader`]), Adam on both networks
//! through three learning-rate stages, validation of images and of the completed clouds
//! ([`validate`]), checkpoints that resume exactly ([`checkpoint`]) and the pictures a person
//! watches ([`plot`]).

pub mod checkpoint;
pub mod dataset;
pub mod loader;
pub mod orient;
pub mod plot;
mod report;
pub mod resume;
mod session;
pub mod validate;

use crate::io::atomic_write;
use crate::model::gan::{Gan, GanOptimConfig, StepLosses};
use crate::model::inpaint::Inpainter;
use crate::model::loss::LossWeights;
use crate::model::{weights, widen, Channels, ModelConfig};
use burn::module::Module;
use burn::tensor::Device;
use checkpoint::{CheckpointError, TrainState, DISCRIMINATOR_WEIGHTS};
use dataset::{hold_back, scan_split, AugmentSettings, DataError, SampleRef};
use serde::{Deserialize, Serialize};
use session::Session;
use std::io::Write;
use std::path::{Path, PathBuf};
use thiserror::Error;
use validate::{Scores, ValItem};

pub const LOG_FILE: &str = "log.jsonl";
pub const LOSSES_PNG: &str = "losses.png";
pub const SAMPLES_DIR: &str = "samples";
pub const SETTINGS_FILE: &str = "train.json";
pub const CONFIG_FILE: &str = "config.json";

/// Everything that shapes a run's result besides the model config; saved as `train.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrainSettings {
    pub views: Vec<usize>,
    /// Objects per micro-batch.
    pub batch: usize,
    /// Micro-batches whose gradients are summed into one step.
    pub accumulate: usize,
    /// Generator learning rate of each stage, in order.
    pub stage_rates: Vec<f64>,
    /// Most steps a stage runs.
    pub stage_steps: u64,
    /// Validations without a better CD after which a stage ends.
    pub patience: usize,
    pub val_every: u64,
    pub val_samples: usize,
    /// Training samples scored as the validation samples are, at each validation and without
    /// augmentation: the gap between the two scores is what the network memorized.
    #[serde(default)]
    pub seen_samples: usize,
    /// Fraction of the training models held back for validation when the data has no test
    /// split.
    pub val_fraction: f64,
    pub checkpoint_every: u64,
    /// Checkpoints kept (the best is kept apart in `best/`).
    pub keep: usize,
    pub log_every: u64,
    pub seed: u64,
    pub augment: AugmentSettings,
    pub loss: LossWeights,
    pub optim: GanOptimConfig,
    /// torchvision VGG19 weights for the perceptual and style terms (the discriminator's
    /// features without).
    #[serde(default)]
    pub vgg19: Option<PathBuf>,
    /// The weights the run started from (`--init`); a fresh initialization when absent.
    #[serde(default)]
    pub init: Option<InitWeights>,
    /// The first stage (1-based) whose loss has the total-variation term.
    #[serde(default = "default_tv_from_stage")]
    pub tv_from_stage: usize,
    /// Steps over which the run's learning rate rises linearly to the first stage's, since
    /// fresh Adam moves every weight by about the rate from its first step (docs/training.md
    /// measures it on a widened network).
    #[serde(default)]
    pub warmup_steps: u64,
}

/// The original adds total variation from its second stage on.
fn default_tv_from_stage() -> usize {
    2
}

/// Trained weights a new run starts from, with fresh optimizers.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct InitWeights {
    pub generator: PathBuf,
    /// A fresh discriminator when absent.
    pub discriminator: Option<PathBuf>,
    /// The generator is narrower than the run's and is widened ([`widen`]).
    #[serde(default)]
    pub widen: bool,
}

impl InitWeights {
    /// The files `path` names: a generator's weights file, or a folder holding one
    /// ([`weights::generator_in`]), with the discriminator's file beside it when there;
    /// `discriminator` overrides that one. With `widen` the one beside is not taken: it was
    /// made for the narrower network.
    pub fn find(
        path: &Path,
        discriminator: Option<PathBuf>,
        widen: bool,
    ) -> Result<InitWeights, TrainError> {
        let generator = if path.is_dir() {
            weights::generator_in(path)?
        } else {
            path.to_path_buf()
        };
        let beside = (path.is_dir() && !widen).then(|| path.join(DISCRIMINATOR_WEIGHTS));
        Ok(InitWeights {
            generator,
            discriminator: discriminator.or(beside.filter(|p| p.is_file())),
            widen,
        })
    }

    /// The model config the generator's file declares.
    pub fn config(&self) -> Result<ModelConfig, TrainError> {
        let bytes = read_file(&self.generator)?;
        weights::read_config(&bytes, weights::Network::Generator).map_err(|source| {
            TrainError::Weights {
                path: self.generator.clone(),
                context: "",
                source,
            }
        })
    }

    /// Refuses files that are unreadable or do not fit `config`, before a run starts.
    pub fn check(&self, config: &ModelConfig) -> Result<(), TrainError> {
        let files = [
            (Some(&self.generator), weights::Network::Generator),
            (self.discriminator.as_ref(), weights::Network::Discriminator),
        ];
        for (path, network) in files {
            let Some(path) = path else { continue };
            let generator = network == weights::Network::Generator;
            weights::read_config(&read_file(path)?, network)
                .and_then(|found| match (generator, self.widen) {
                    (true, true) => widen::widenable(&found, config),
                    (true, false) if drops_colour(&found, config) => {
                        widen::colour_droppable(&found, config)
                    }
                    _ => weights::compatible(&found, config),
                })
                .map_err(|source| TrainError::Weights {
                    path: path.clone(),
                    context: "--init: ",
                    source,
                })?;
        }
        Ok(())
    }

    /// Both networks for `config`, the discriminator fresh when no file is named.
    fn load(&self, job: &Job, device: &Device) -> Result<Gan, TrainError> {
        let config = &job.model;
        let fail = |path: &Path| {
            let path = path.to_path_buf();
            move |source| TrainError::Weights {
                path,
                context: "--init: ",
                source,
            }
        };
        let bytes = read_file(&self.generator)?;
        let found = weights::read_config(&bytes, weights::Network::Generator)
            .map_err(fail(&self.generator))?;
        let generator = match self.widen {
            true => widen::generator_widened(&bytes, config, device),
            false if drops_colour(&found, config) => {
                widen::generator_without_colour(&bytes, config, device)
            }
            false => weights::generator_for(&bytes, config, device),
        }
        .map_err(fail(&self.generator))?;
        let discriminator = match &self.discriminator {
            Some(path) => {
                weights::discriminator_for(&read_file(path)?, config, device).map_err(fail(path))?
            }
            None => config
                .init_discriminator(device)
                .map_err(|source| TrainError::Config {
                    path: self.generator.clone(),
                    source,
                })?,
        };
        Ok(Gan::from_parts(
            generator,
            discriminator,
            config.clone(),
            job.settings.loss.clone(),
            job.settings.optim.clone(),
        ))
    }
}

/// Whether a run of `config` starting from weights of `found` leaves their colour behind
/// (`train --init COLOUR_MODEL --channels xyz`, [`widen::generator_without_colour`]).
pub fn drops_colour(found: &ModelConfig, config: &ModelConfig) -> bool {
    found.channels == Channels::Xyzrgb && config.channels == Channels::Xyz
}

fn read_file(path: &Path) -> Result<Vec<u8>, TrainError> {
    crate::io::read_bytes(path).map_err(|source| TrainError::Read {
        path: path.to_path_buf(),
        source,
    })
}

impl Default for TrainSettings {
    /// The original schedule (lr 1e-4 → 1e-5 → 1e-6) on the rig's default views.
    fn default() -> TrainSettings {
        TrainSettings {
            views: crate::core::camera::DEFAULT_VIEWS.to_vec(),
            batch: 4,
            accumulate: 1,
            stage_rates: vec![1e-4, 1e-5, 1e-6],
            stage_steps: 100_000,
            patience: 5,
            val_every: 500,
            val_samples: 16,
            seen_samples: 16,
            val_fraction: 0.05,
            checkpoint_every: 500,
            keep: 3,
            log_every: 10,
            seed: 0,
            augment: AugmentSettings {
                mirror: true,
                max_yaw_deg: 5.0,
                color_jitter: 0.1,
            },
            loss: LossWeights::new(),
            optim: GanOptimConfig::new(),
            vgg19: None,
            init: None,
            tv_from_stage: default_tv_from_stage(),
            warmup_steps: 0,
        }
    }
}

/// The most micro-batches one optimizer step accumulates: with the largest batch that is a
/// million samples a step, where a mistyped count would run one step for days.
pub const MAX_ACCUMULATE: usize = 1024;

impl TrainSettings {
    /// Refuses settings no run can train with.
    pub fn validate(&self) -> Result<(), SettingsError> {
        let problem = if self.batch == 0 || self.accumulate == 0 {
            "batch and accumulate must be at least 1"
        } else if self.accumulate > MAX_ACCUMULATE {
            return Err(SettingsError(format!(
                "accumulate {} is above the largest this build accepts ({MAX_ACCUMULATE})",
                self.accumulate
            )));
        } else if self.batch > crate::model::MAX_BATCH {
            return Err(SettingsError(format!(
                "batch {} is above the largest this build accepts ({})",
                self.batch,
                crate::model::MAX_BATCH
            )));
        } else if !(0.0..1.0).contains(&self.val_fraction) {
            "the validation fraction must lie in [0, 1)"
        } else if self.stage_rates.is_empty()
            || self.stage_rates.iter().any(|r| !r.is_finite() || *r <= 0.0)
        {
            "the learning rates must be positive numbers"
        } else if self.stage_steps == 0 {
            "a stage must have at least 1 step"
        } else if self.views.is_empty() {
            "at least one view is needed"
        } else if self.tv_from_stage == 0 {
            "stages are counted from 1"
        } else if let Some(problem) = self.unusable_weight_or_augmentation() {
            return Err(SettingsError(problem));
        } else {
            return Ok(());
        };
        Err(SettingsError(problem.to_string()))
    }

    /// A loss weight or augmentation amplitude that is negative or not a number: a negative
    /// weight trains the network away from its target, and a NaN weight or jitter gave no word
    /// until the losses went NaN a step later (or never, for a term not yet in use).
    fn unusable_weight_or_augmentation(&self) -> Option<String> {
        let l = &self.loss;
        let weights = [
            ("l1", l.l1),
            ("adversarial", l.adversarial),
            ("perceptual", l.perceptual),
            ("style", l.style),
            ("bce", l.occupancy),
            ("tv", l.tv),
            ("depth", l.depth),
        ];
        let amplitudes = [
            ("max yaw", self.augment.max_yaw_deg as f64),
            ("colour jitter", self.augment.color_jitter as f64),
        ];
        let bad = |x: f64| !(x.is_finite() && x >= 0.0);
        if let Some((name, w)) = weights.iter().find(|(_, w)| bad(*w)) {
            return Some(format!(
                "loss weight {name} {w}: a number of 0 or more expected"
            ));
        }
        let (name, a) = amplitudes.iter().find(|(_, a)| bad(*a))?;
        Some(format!("{name} {a}: a number of 0 or more expected"))
    }

    /// The generator's learning rate for the step after `step` in `stage`.
    pub fn rate(&self, stage: usize, step: u64) -> f64 {
        let warm = match self.warmup_steps {
            0 => 1.0,
            n => ((step + 1) as f64 / n as f64).min(1.0),
        };
        self.stage_rates[stage] * warm
    }

    /// The most steps the stages can take together.
    pub fn planned_steps(&self) -> u64 {
        self.stage_steps * self.stage_rates.len() as u64
    }
}

/// What [`TrainSettings::validate`] refuses.
#[derive(Debug, Error)]
#[error("{0}")]
pub struct SettingsError(String);

#[derive(Debug, Error)]
pub enum TrainError {
    #[error(transparent)]
    Data(#[from] DataError),
    #[error(transparent)]
    Checkpoint(#[from] CheckpointError),
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{}: {problem}", path.display())]
    Run { path: PathBuf, problem: String },
    #[error("{}: {source}", path.display())]
    Read {
        path: PathBuf,
        source: crate::io::Problem,
    },
    #[error("--init: {0}")]
    NoGenerator(#[from] weights::NoGenerator),
    /// A weights file (`--init`, `--vgg19`) that cannot be used; `context` names the option.
    #[error("{}: {context}{source}", path.display())]
    Weights {
        path: PathBuf,
        context: &'static str,
        source: weights::WeightsError,
    },
    #[error("{}: {source}", path.display())]
    Config {
        path: PathBuf,
        source: crate::model::ConfigError,
    },
    #[error("{}: {source}", path.display())]
    Camera {
        path: PathBuf,
        source: crate::core::camera::CameraError,
    },
    #[error(
        "the {term} loss is {value} at step {step}; stopped without saving, {}",
        last_good.as_ref().map_or("no checkpoint was written yet".to_string(),
            |p| format!("the last good checkpoint is {}", p.display()))
    )]
    NonFinite {
        term: &'static str,
        value: f32,
        step: u64,
        last_good: Option<PathBuf>,
    },
    #[error(
        "{source} (on {device}) in step {step}; stopped with a checkpoint of step {}, {}: \
         continue with --resume",
        step - 1, checkpoint.display()
    )]
    Replica {
        source: crate::model::gan::ReplicaFailure,
        device: String,
        step: u64,
        checkpoint: PathBuf,
    },
}

fn io_err(path: &Path) -> impl FnOnce(std::io::Error) -> TrainError + '_ {
    move |source| TrainError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// One line of `log.jsonl`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum LogRecord {
    /// Losses averaged over the steps since the previous record.
    Train {
        step: u64,
        stage: usize,
        learning_rate: f64,
        losses: StepLosses,
        steps_per_second: f64,
        /// Share of the interval's time the loop waited for data.
        data_wait: f64,
    },
    Validation {
        step: u64,
        stage: usize,
        scores: Scores,
        /// The same scores on training samples (`seen_samples`); absent from runs without.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        seen: Option<Scores>,
    },
    /// The partial inputs scored as if they were the output, once per run.
    Baseline { scores: Scores },
}

impl LogRecord {
    fn step(&self) -> u64 {
        match self {
            LogRecord::Train { step, .. } | LogRecord::Validation { step, .. } => *step,
            LogRecord::Baseline { .. } => 0,
        }
    }
}

/// What a run needs besides its settings.
pub struct Job {
    pub data: PathBuf,
    pub run: PathBuf,
    pub model: ModelConfig,
    pub settings: TrainSettings,
    /// Stop once this many steps are done (counting those before a resume).
    pub max_steps: Option<u64>,
    /// Where the networks run; gradients are recorded on top of it.
    pub device: burn::tensor::Device,
    /// Further devices of a data-parallel run, each taking its share of every micro-batch
    /// (`--devices`); empty for one device.
    pub replicas: Vec<burn::tensor::Device>,
    /// What the log calls each device of a data-parallel run, `device`'s first.
    pub device_names: Vec<String>,
    pub resume: bool,
    pub workers: usize,
    pub prefetch: usize,
    pub cache_bytes: usize,
}

/// What the person running the loop sees; the command layer draws it.
pub trait Monitor {
    fn message(&mut self, text: &str);
    /// Shown even to a quiet run.
    fn warn(&mut self, text: &str);
    /// Called once before the first step with the step to start from and the most steps planned.
    fn start(&mut self, first_step: u64, planned: u64);
    fn stepped(&mut self, step: u64, losses: &StepLosses);
    fn record(&mut self, record: &LogRecord);
    /// Polled before each step: a true stops the run after a checkpoint.
    fn interrupted(&self) -> bool;
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Outcome {
    /// Every stage ended.
    Finished,
    /// `max_steps` reached.
    StepLimit,
    Interrupted,
}

#[derive(Debug)]
pub struct Summary {
    pub outcome: Outcome,
    pub state: TrainState,
    pub checkpoint: PathBuf,
    pub baseline: Option<Scores>,
    pub last: Option<Scores>,
    /// The last validation's scores on training samples.
    pub last_seen: Option<Scores>,
}

fn write_json<T: Serialize>(path: &Path, value: &T) -> Result<(), TrainError> {
    atomic_write(path, |w| {
        serde_json::to_writer_pretty(&mut *w, value).map_err(std::io::Error::other)
    })
    .map_err(io_err(path))
}

/// Reads back `log.jsonl`, keeping what happened up to `step` (a crash may have logged past the
/// checkpoint a resume starts from).
fn read_log(path: &Path, step: u64) -> Result<Vec<LogRecord>, TrainError> {
    let text = match std::fs::read_to_string(path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
        Err(e) => return Err(io_err(path)(e)),
    };
    Ok(parse_log(&text, step))
}

/// The records of a `log.jsonl` up to `step`; a line that does not parse (the torn last line
/// of a killed run) is dropped.
pub fn parse_log(text: &str, step: u64) -> Vec<LogRecord> {
    text.lines()
        .filter_map(|l| serde_json::from_str::<LogRecord>(l).ok())
        .filter(|r| r.step() <= step)
        .collect()
}

struct RunLog {
    path: PathBuf,
    records: Vec<LogRecord>,
}

impl RunLog {
    fn open(run: &Path, step: u64) -> Result<RunLog, TrainError> {
        let path = run.join(LOG_FILE);
        let records = read_log(&path, step)?;
        atomic_write(&path, |w| {
            for r in &records {
                serde_json::to_writer(&mut *w, r).map_err(std::io::Error::other)?;
                w.write_all(b"\n")?;
            }
            Ok(())
        })
        .map_err(io_err(&path))?;
        Ok(RunLog { path, records })
    }

    fn push(&mut self, record: LogRecord) -> Result<(), TrainError> {
        let mut line = serde_json::to_vec(&record).map_err(|e| io_err(&self.path)(e.into()))?;
        line.push(b'\n');
        std::fs::OpenOptions::new()
            .append(true)
            .open(&self.path)
            .and_then(|mut f| f.write_all(&line))
            .map_err(io_err(&self.path))?;
        self.records.push(record);
        Ok(())
    }

    /// The run's curves (`losses.png`): three training losses, and three validation scores
    /// (red) each beside the partial inputs' own (grey) and the same score on training samples
    /// (blue, as the training losses).
    fn draw(&self, run: &Path) -> Result<(), TrainError> {
        let Curves {
            train,
            val,
            seen,
            base,
            max_x,
        } = Curves::of(&self.records);
        let baselines: Vec<[(f64, f64); 2]> = base
            .iter()
            .map(|b| {
                let v = b.unwrap_or(f64::NAN);
                [(0.0, v), (max_x, v)]
            })
            .collect();
        let mut panels: Vec<plot::Panel> = ["G LOSS", "D LOSS", "L1"]
            .into_iter()
            .zip(&train)
            .map(|(title, points)| plot::Panel {
                title,
                series: vec![plot::Series {
                    points,
                    color: plot::TRAIN,
                }],
                log: title == "L1",
            })
            .collect();
        for (i, title) in ["VAL CD", "VAL F1", "VAL PSNR"].into_iter().enumerate() {
            panels.push(plot::Panel {
                title,
                series: vec![
                    plot::Series {
                        points: &baselines[i],
                        color: plot::BASELINE,
                    },
                    plot::Series {
                        points: &seen[i],
                        color: plot::TRAIN,
                    },
                    plot::Series {
                        points: &val[i],
                        color: plot::VALIDATION,
                    },
                ],
                log: i == 0,
            });
        }
        let img = plot::panels(&panels, max_x);
        save_png(&run.join(LOSSES_PNG), &img)
    }
}

/// What a run's log holds for its plot: the generator's loss, the discriminator's and L1 per
/// step, the validation CD, F1 and PSNR per validation and the same on training samples, the
/// partial inputs' three scores, and the last step.
struct Curves {
    train: [Vec<(f64, f64)>; 3],
    val: [Vec<(f64, f64)>; 3],
    seen: [Vec<(f64, f64)>; 3],
    base: [Option<f64>; 3],
    max_x: f64,
}

impl Curves {
    fn of(records: &[LogRecord]) -> Curves {
        let mut c = Curves {
            train: Default::default(),
            val: Default::default(),
            seen: Default::default(),
            base: [None; 3],
            max_x: 1.0,
        };
        for r in records {
            match r {
                LogRecord::Train { step, losses, .. } => {
                    let x = *step as f64;
                    c.max_x = c.max_x.max(x);
                    c.train[0].push((x, losses.generator as f64));
                    c.train[1].push((x, losses.discriminator as f64));
                    c.train[2].push((x, losses.l1 as f64));
                }
                LogRecord::Validation {
                    step, scores, seen, ..
                } => {
                    let x = *step as f64;
                    c.max_x = c.max_x.max(x);
                    push_scores(&mut c.val, x, scores);
                    if let Some(seen) = seen {
                        push_scores(&mut c.seen, x, seen);
                    }
                }
                LogRecord::Baseline { scores } => {
                    c.base = [scores.cd, Some(scores.f1), Some(scores.geometry.psnr)];
                }
            }
        }
        c
    }
}

/// The plotted scores (CD, F1, geometry PSNR) of one validation at step `x`.
fn push_scores(curves: &mut [Vec<(f64, f64)>; 3], x: f64, scores: &Scores) {
    curves[0].push((x, scores.cd.unwrap_or(f64::NAN)));
    curves[1].push((x, scores.f1));
    curves[2].push((x, scores.geometry.psnr));
}

fn save_png(path: &Path, img: &image::RgbImage) -> Result<(), TrainError> {
    atomic_write(path, |w| {
        let mut bytes = Vec::new();
        img.write_to(
            &mut std::io::Cursor::new(&mut bytes),
            image::ImageFormat::Png,
        )
        .map_err(std::io::Error::other)?;
        w.write_all(&bytes)
    })
    .map_err(io_err(path))
}

/// Training and validation samples: the data's test split when it has one, else a held-back
/// share of the training models.
pub fn samples(
    data: &Path,
    val_fraction: f64,
) -> Result<(Vec<SampleRef>, Vec<SampleRef>, String), TrainError> {
    let train = scan_split(data, "train")?;
    if data.join("GT").join("test").is_dir() {
        let test = scan_split(data, "test")?;
        let what = format!(
            "{} samples of {} models for training, {} of {} test models for validation",
            train.samples.len(),
            train.models,
            test.samples.len(),
            test.models
        );
        return Ok((train.samples, test.samples, what));
    }
    let (train_samples, val) = hold_back(train.samples, val_fraction);
    if train_samples.is_empty() {
        return Err(TrainError::Run {
            path: data.to_path_buf(),
            problem: "holding back the validation models leaves nothing to train on".into(),
        });
    }
    let what = format!(
        "{} samples for training, {} held back for validation (no test split)",
        train_samples.len(),
        val.len()
    );
    Ok((train_samples, val, what))
}

struct Validator {
    items: Vec<ValItem>,
    /// Training samples, scored beside the validation ones (`seen_samples`).
    seen: Vec<ValItem>,
    device: burn::tensor::Device,
    batch: usize,
}

/// One validation's scores: on the validation samples, and on the training samples when asked.
struct Validated {
    scores: Scores,
    seen: Option<Scores>,
}

impl Validator {
    /// [`Validator::run`], with the scores shown and appended to the log as `(step, stage)`'s.
    fn run_logged(
        &self,
        gan: &Gan,
        run: &Path,
        (step, stage): (u64, usize),
        monitor: &mut dyn Monitor,
        log: &mut RunLog,
    ) -> Result<Validated, TrainError> {
        let validated = self.run(gan, run, step)?;
        let record = LogRecord::Validation {
            step,
            stage,
            scores: validated.scores.clone(),
            seen: validated.seen.clone(),
        };
        monitor.record(&record);
        log.push(record)?;
        Ok(validated)
    }

    fn run(&self, gan: &Gan, run: &Path, step: u64) -> Result<Validated, TrainError> {
        let inpainter = Inpainter::new(
            gan.generator.valid(),
            gan.config.clone(),
            self.device.clone(),
        );
        let (scores, outputs) = validate::validate(&inpainter, &self.items, self.batch);
        let seen = (!self.seen.is_empty())
            .then(|| validate::validate(&inpainter, &self.seen, self.batch).0);
        let first = &self.items[0];
        let color = scores.color.is_some();
        let grid = plot::sample_grid(&first.input, &outputs[0], &first.target, color);
        let dir = run.join(SAMPLES_DIR);
        std::fs::create_dir_all(&dir).map_err(io_err(&dir))?;
        save_png(&dir.join(format!("{step:08}.png")), &grid)?;
        Ok(Validated { scores, seen })
    }
}

/// Runs (or resumes) training until every stage ends, `max_steps` is reached or the monitor
/// interrupts; a checkpoint is written in each case.
pub fn train(job: Job, monitor: &mut dyn Monitor) -> Result<Summary, TrainError> {
    let mut session = Session::open(&job, monitor)?;
    let (first, planned) = session.plan();
    monitor.start(first, planned);
    let outcome = loop {
        if let Some(outcome) = session.stop(monitor) {
            break outcome;
        }
        session = session.step(monitor)?;
        let improved = session.validate(monitor)?;
        session.advance_stage(monitor);
        session.checkpoint(improved)?;
    };
    session.finish(outcome, monitor)
}

/// Updates the best scores and the patience counter; true when the CD is the run's best.
fn advance_on_validation(state: &mut TrainState, scores: &Scores) -> bool {
    let Some(cd) = scores.cd else {
        state.validations_without_improvement += 1;
        return false;
    };
    if state.stage_best_cd.is_none_or(|b| cd < b) {
        state.stage_best_cd = Some(cd);
        state.validations_without_improvement = 0;
    } else {
        state.validations_without_improvement += 1;
    }
    if state.best_cd.is_none_or(|b| cd < b) {
        state.best_cd = Some(cd);
        state.best_step = Some(state.step);
        return true;
    }
    false
}

/// Loss sums and timings since the last log record.
struct Interval {
    sum: StepLosses,
    steps: u32,
    busy: f64,
    wait: f64,
}

impl Interval {
    fn new() -> Interval {
        Interval {
            sum: StepLosses::default(),
            steps: 0,
            busy: 0.0,
            wait: 0.0,
        }
    }

    fn add(&mut self, losses: &StepLosses, seconds: f64) {
        self.sum = self.sum.plus(losses);
        self.steps += 1;
        self.busy += seconds;
    }

    fn record(&mut self, step: u64, stage: usize, learning_rate: f64) -> LogRecord {
        let total = self.busy + self.wait;
        let record = LogRecord::Train {
            step,
            stage,
            learning_rate,
            losses: self.sum.scaled(1.0 / self.steps.max(1) as f32),
            steps_per_second: self.steps as f64 / total.max(1e-9),
            data_wait: self.wait / total.max(1e-9),
        };
        *self = Interval::new();
        record
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use validate::ImageScores;

    #[test]
    fn default_settings_are_valid_and_broken_ones_are_refused() {
        assert!(TrainSettings::default().validate().is_ok());
        let broken: [fn(&mut TrainSettings); 12] = [
            |s| s.loss.l1 = -1.0,
            |s| s.loss.tv = f64::NAN,
            |s| s.augment.max_yaw_deg = f32::NAN,
            |s| s.augment.color_jitter = -0.1,
            |s| s.batch = 0,
            |s| s.batch = crate::model::MAX_BATCH + 1,
            |s| s.accumulate = 0,
            |s| s.accumulate = MAX_ACCUMULATE + 1,
            |s| s.val_fraction = 1.0,
            |s| s.stage_rates = vec![1e-4, f64::NAN],
            |s| s.stage_steps = 0,
            |s| s.tv_from_stage = 0,
        ];
        for (i, breaks) in broken.iter().enumerate() {
            let mut settings = TrainSettings::default();
            breaks(&mut settings);
            assert!(settings.validate().is_err(), "case {i}");
        }
    }

    /// The relay starts every leg with `train --init assets`: a file left beside a replaced
    /// generator (a discriminator made for another width) must fail here, not a GPU lease later.
    #[test]
    fn the_shipped_assets_start_a_run() {
        let assets = Path::new(env!("CARGO_MANIFEST_DIR")).join("assets");
        let init = InitWeights::find(&assets, None, false).unwrap();
        init.check(&init.config().unwrap()).unwrap();
    }

    #[test]
    fn the_rate_rises_over_the_warmup_then_follows_the_stages() {
        let settings = TrainSettings {
            stage_rates: vec![1e-4, 1e-5],
            warmup_steps: 4,
            ..TrainSettings::default()
        };
        let rates: Vec<f64> = (0..6).map(|step| settings.rate(0, step)).collect();
        let expected = [0.25e-4, 0.5e-4, 0.75e-4, 1e-4, 1e-4, 1e-4];
        for (rate, expected) in rates.iter().zip(expected) {
            assert!((rate - expected).abs() < 1e-12, "{rates:?}");
        }
        assert_eq!(settings.rate(1, 100), 1e-5);
        assert_eq!(TrainSettings::default().rate(0, 0), 1e-4);
    }

    fn scores(cd: Option<f64>) -> Scores {
        let image = ImageScores {
            psnr: 20.0,
            ssim: 0.5,
            mae: 0.1,
        };
        Scores {
            geometry: image,
            color: None,
            cd,
            f1: 0.5,
            precision: 0.5,
            recall: 0.5,
            empty: usize::from(cd.is_none()),
            mean_points: 100.0,
            samples: 1,
        }
    }

    #[test]
    fn seen_scores_are_logged_when_measured_and_plotted_beside_the_validation() {
        let validation = |step, seen| LogRecord::Validation {
            step,
            stage: 0,
            scores: scores(Some(2.0)),
            seen,
        };
        // Runs without training samples to score (and runs older than them) log no `seen`.
        let without = serde_json::to_string(&validation(10, None)).unwrap();
        assert!(!without.contains("seen"), "{without}");
        let with = serde_json::to_string(&validation(20, Some(scores(Some(1.0))))).unwrap();
        let records = parse_log(&format!("{without}\n{with}\n"), 20);
        assert_eq!(records.len(), 2);
        let curves = Curves::of(&records);
        assert_eq!(curves.val[0], [(10.0, 2.0), (20.0, 2.0)]);
        assert_eq!(curves.seen[0], [(20.0, 1.0)]);
    }

    #[test]
    fn patience_counts_validations_without_a_better_cd() {
        let mut state = TrainState::new();
        state.step = 10;
        assert!(advance_on_validation(&mut state, &scores(Some(2.0))));
        state.step = 20;
        assert!(!advance_on_validation(&mut state, &scores(Some(3.0))));
        assert!(!advance_on_validation(&mut state, &scores(None)));
        assert_eq!(state.validations_without_improvement, 2);
        state.step = 30;
        assert!(advance_on_validation(&mut state, &scores(Some(1.0))));
        assert_eq!(state.validations_without_improvement, 0);
        assert_eq!((state.best_cd, state.best_step), (Some(1.0), Some(30)));
        // A new stage starts its own patience but a CD worse than the run's best is no new best.
        state.stage_best_cd = None;
        assert!(!advance_on_validation(&mut state, &scores(Some(1.5))));
        assert_eq!(state.stage_best_cd, Some(1.5));
    }

    #[test]
    fn a_resumed_log_forgets_what_came_after_its_checkpoint() {
        let dir = tempfile::tempdir().unwrap();
        let mut log = RunLog::open(dir.path(), 0).unwrap();
        log.push(LogRecord::Baseline {
            scores: scores(Some(1.0)),
        })
        .unwrap();
        for step in [10, 20, 30] {
            log.push(LogRecord::Validation {
                step,
                stage: 0,
                scores: scores(Some(1.0 / step as f64)),
                seen: None,
            })
            .unwrap();
        }
        let resumed = RunLog::open(dir.path(), 20).unwrap();
        assert_eq!(resumed.records.len(), 3);
        let text = std::fs::read_to_string(dir.path().join(LOG_FILE)).unwrap();
        assert_eq!(text.lines().count(), 3);
        assert!(!text.contains("\"step\":30"));
        resumed.draw(dir.path()).unwrap();
        assert!(dir.path().join(LOSSES_PNG).is_file());
    }
}
