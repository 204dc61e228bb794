//! A training run in progress, in the pieces Burn's Learner has: open (or resume) the run, take
//! a step, validate, advance the learning-rate stage, checkpoint, and finish.

use super::checkpoint::{self, TrainState, DISCRIMINATOR_WEIGHTS, GENERATOR_WEIGHTS};
use super::dataset::Cache;
use super::loader::{HostBatch, Loader, LoaderPlan};
use super::validate::{self, Scores};
use super::{
    advance_on_validation, io_err, samples, write_json, Interval, Job, LogRecord, Monitor, Outcome,
    RunLog, Summary, TrainError, Validated, Validator, CONFIG_FILE, SETTINGS_FILE,
};
use crate::core::camera::Camera;
use crate::io::atomic_write;
use crate::model::gan::{Batch, Gan};
use crate::model::loss::depth_axes;
use crate::model::vgg::Vgg19;
use burn::tensor::Device;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;

/// Everything the loop reads and changes between steps.
pub(super) struct Session<'a> {
    job: &'a Job,
    autodiff: Device,
    /// The other replicas' devices, recording gradients.
    replicas: Vec<Device>,
    gan: Gan,
    state: TrainState,
    log: RunLog,
    validator: Option<Validator>,
    loader: Loader,
    /// The partial inputs' own scores on the validation samples.
    baseline: Option<Scores>,
    last_checkpoint: Option<PathBuf>,
    last: Option<Validated>,
    interval: Interval,
}

/// Warns when the data's views (`data_size`²) are smaller than the model's (`model_size`²).
fn warn_if_smaller(data_size: usize, model_size: usize, monitor: &mut dyn Monitor) {
    if data_size < model_size {
        monitor.warn(&format!(
            "the data's views are {data_size}² and the model's {model_size}²: views rendered \
             larger than they were made leave holes in the ground truth; prepare the data with \
             --size {model_size}"
        ));
    }
}

/// What the loader makes for `job`, from step `first_step` on.
fn loader_plan(job: &Job, first_step: u64) -> LoaderPlan {
    let settings = &job.settings;
    LoaderPlan {
        seed: settings.seed,
        batch: settings.batch,
        accumulate: settings.accumulate,
        first_step,
        augment: settings.augment,
        channels: job.model.channels,
        prefetch: job.prefetch,
        workers: job.workers,
    }
}

impl<'a> Session<'a> {
    /// Checks the data, creates (or resumes) the run directory and starts the loader.
    pub(super) fn open(job: &'a Job, monitor: &mut dyn Monitor) -> Result<Session<'a>, TrainError> {
        let settings = &job.settings;
        let run = &job.run;
        let autodiff = job.device.clone().autodiff();
        let vgg = load_vgg(job, &autodiff, monitor)?;
        let (train_samples, val_samples, what) = samples(&job.data, settings.val_fraction)?;
        monitor.message(&what);
        let cameras =
            Camera::set(&settings.views, job.model.size).map_err(|source| TrainError::Camera {
                path: job.data.clone(),
                source,
            })?;
        let cache = Arc::new(Cache::new(job.cache_bytes));
        let data_size = cache.get(&train_samples[0].gt, &settings.views)?.size;
        warn_if_smaller(data_size, job.model.size, monitor);
        let val_items = validate::build(
            &validate::pick(&val_samples, settings.val_samples),
            &cameras,
            &cache,
        )?;
        let seen_items = validate::build(
            &validate::pick(&train_samples, settings.seen_samples),
            &cameras,
            &cache,
        )?;
        // Only now: data that is refused must leave no run directory behind.
        std::fs::create_dir_all(run).map_err(io_err(run))?;
        let (mut gan, state) = open_or_resume(job, &autodiff, monitor)?;
        gan.vgg = vgg;
        if settings.loss.depth > 0.0 {
            gan.depth_axes = Some(depth_axes(&cameras, &autodiff));
        }
        let replicas: Vec<Device> = job.replicas.iter().map(|d| d.clone().autodiff()).collect();
        gan.replicate_on(&replicas);
        write_json(&run.join(CONFIG_FILE), &job.model)?;
        write_json(&run.join(SETTINGS_FILE), settings)?;

        let mut log = RunLog::open(run, state.step)?;
        let validator = (!val_items.is_empty()).then(|| Validator {
            items: val_items,
            seen: seen_items,
            device: job.device.clone(),
            batch: settings.batch,
        });
        let baseline = log_baseline(validator.as_ref(), &mut log, monitor)?;
        let loader = Loader::spawn(
            Arc::new(train_samples),
            cameras,
            cache,
            loader_plan(job, state.step),
        );
        Ok(Session {
            job,
            autodiff,
            replicas,
            gan,
            state,
            log,
            validator,
            loader,
            baseline,
            last_checkpoint: checkpoint::latest(run)?,
            last: None,
            interval: Interval::new(),
        })
    }

    /// The step the run stands at, and the most steps it will reach.
    pub(super) fn plan(&self) -> (u64, u64) {
        let settings = &self.job.settings;
        let planned = self.job.max_steps.map_or(settings.planned_steps(), |m| {
            m.min(settings.planned_steps())
        });
        (self.state.step, planned)
    }

    /// Why the run stops before its next step, if it does.
    pub(super) fn stop(&self, monitor: &dyn Monitor) -> Option<Outcome> {
        if self.state.finished {
            Some(Outcome::Finished)
        } else if self.job.max_steps.is_some_and(|m| self.state.step >= m) {
            Some(Outcome::StepLimit)
        } else if monitor.interrupted() {
            Some(Outcome::Interrupted)
        } else {
            None
        }
    }

    /// One optimizer step of both networks, logged every `log_every` steps; a loss that is
    /// not finite ends the run, naming the last good checkpoint.
    pub(super) fn step(mut self, monitor: &mut dyn Monitor) -> Result<Session<'a>, TrainError> {
        let settings = &self.job.settings;
        let waited = Instant::now();
        let data = self.loader.next()?;
        debug_assert_eq!(data.step, self.state.step);
        let started = Instant::now();
        self.interval.wait += (started - waited).as_secs_f64();
        let rate = settings.rate(self.state.stage, self.state.step);
        // The total-variation term joins from stage `tv_from_stage` (1-based) on.
        self.gan.weights.tv = if self.state.stage + 1 < settings.tv_from_stage {
            0.0
        } else {
            settings.loss.tv
        };
        let (gan, losses) = match self.job.replicas.is_empty() {
            true => {
                let batches: Vec<_> = data
                    .micro
                    .into_iter()
                    .map(|b| b.to_device(&self.autodiff))
                    .collect();
                self.gan.step(&batches, rate)
            }
            false => {
                let parts = self.parts(data.micro);
                match self.gan.step_replicated(&parts, rate) {
                    Ok(stepped) => stepped,
                    Err(failed) => {
                        let (gan, source) = *failed;
                        self.gan = gan;
                        let checkpoint =
                            checkpoint::save(&self.job.run, &self.gan, &self.state, settings.keep)?;
                        let device = self.job.device_names.get(source.index).cloned();
                        return Err(TrainError::Replica {
                            device: device.unwrap_or_else(|| "an unnamed device".to_string()),
                            source,
                            step: self.state.step + 1,
                            checkpoint,
                        });
                    }
                }
            }
        };
        self.gan = gan;
        if let Some((term, value)) = losses.first_non_finite() {
            return Err(TrainError::NonFinite {
                term,
                value,
                step: self.state.step + 1,
                last_good: self.last_checkpoint,
            });
        }
        self.state.step += 1;
        self.interval.add(&losses, started.elapsed().as_secs_f64());
        monitor.stepped(self.state.step, &losses);
        if self.state.step.is_multiple_of(settings.log_every.max(1)) {
            let record = self
                .interval
                .record(self.state.step, self.state.stage, rate);
            monitor.record(&record);
            self.log.push(record)?;
        }
        Ok(self)
    }

    /// Each micro-batch split into one part per replica, on that replica's device.
    fn parts(&self, micro: Vec<HostBatch>) -> Vec<Vec<Batch>> {
        let devices: Vec<&Device> = std::iter::once(&self.autodiff)
            .chain(&self.replicas)
            .collect();
        let mut parts: Vec<Vec<Batch>> = devices.iter().map(|_| Vec::new()).collect();
        for batch in micro {
            for ((part, device), list) in batch
                .split(devices.len())
                .into_iter()
                .zip(&devices)
                .zip(&mut parts)
            {
                list.push(part.to_device(device));
            }
        }
        parts
    }

    /// Validates every `val_every` steps; true when the CD is the run's best.
    pub(super) fn validate(&mut self, monitor: &mut dyn Monitor) -> Result<bool, TrainError> {
        let every = self.job.settings.val_every;
        let Some(v) = self
            .validator
            .as_ref()
            .filter(|_| every > 0 && self.state.step.is_multiple_of(every))
        else {
            return Ok(false);
        };
        let at = (self.state.step, self.state.stage);
        let validated = v.run_logged(&self.gan, &self.job.run, at, monitor, &mut self.log)?;
        let improved = advance_on_validation(&mut self.state, &validated.scores);
        self.log.draw(&self.job.run)?;
        self.last = Some(validated);
        Ok(improved)
    }

    /// Moves to the next learning-rate stage when this one's budget or patience is spent; the
    /// run is finished after the last.
    pub(super) fn advance_stage(&mut self, monitor: &mut dyn Monitor) {
        let settings = &self.job.settings;
        let state = &mut self.state;
        let budget_spent = state.step - state.stage_start >= settings.stage_steps;
        if !budget_spent && state.validations_without_improvement < settings.patience.max(1) {
            return;
        }
        state.stage += 1;
        state.stage_start = state.step;
        state.stage_best_cd = None;
        state.validations_without_improvement = 0;
        if state.stage >= settings.stage_rates.len() {
            state.finished = true;
        } else {
            monitor.message(&format!(
                "step {}: stage {} (learning rate {:e})",
                state.step,
                state.stage + 1,
                settings.stage_rates[state.stage]
            ));
        }
    }

    /// A checkpoint every `checkpoint_every` steps and at every new best (kept as `best/`).
    pub(super) fn checkpoint(&mut self, improved: bool) -> Result<(), TrainError> {
        let settings = &self.job.settings;
        if improved
            || self
                .state
                .step
                .is_multiple_of(settings.checkpoint_every.max(1))
        {
            let dir = checkpoint::save(&self.job.run, &self.gan, &self.state, settings.keep)?;
            if improved {
                checkpoint::keep_as_best(&self.job.run, &dir)?;
            }
            self.last_checkpoint = Some(dir);
        }
        Ok(())
    }

    /// Checkpoints the last step and writes the run's weights, then validates it (however the
    /// run ended, so a short run still shows where it got to) and draws the curves.
    pub(super) fn finish(
        mut self,
        outcome: Outcome,
        monitor: &mut dyn Monitor,
    ) -> Result<Summary, TrainError> {
        let (settings, run) = (&self.job.settings, &self.job.run);
        let state = &self.state;
        // Saved before the last validation: a scheduler's SIGKILL may follow its SIGTERM soon.
        let dir = match &self.last_checkpoint {
            Some(dir) if dir.ends_with(format!("step-{:08}", state.step)) => dir.clone(),
            _ => checkpoint::save(run, &self.gan, state, settings.keep)?,
        };
        for name in [GENERATOR_WEIGHTS, DISCRIMINATOR_WEIGHTS] {
            let weights = run.join(name);
            // Copied whole or not at all, so a kill here leaves no cut-off weights file.
            atomic_write(&weights, |w| {
                std::io::copy(&mut std::fs::File::open(dir.join(name))?, w).map(|_| ())
            })
            .map_err(io_err(&weights))?;
        }
        let validated = self
            .log
            .records
            .iter()
            .any(|r| matches!(r, LogRecord::Validation { step, .. } if *step == state.step));
        // Logged, but it leaves stage and patience alone: a run stopped and resumed continues
        // exactly as one that never stopped.
        if let Some(v) = self
            .validator
            .as_ref()
            .filter(|_| state.step > 0 && !validated)
        {
            let stage = state
                .stage
                .min(settings.stage_rates.len().saturating_sub(1));
            let at = (state.step, stage);
            self.last = Some(v.run_logged(&self.gan, run, at, monitor, &mut self.log)?);
        }
        self.log.draw(run)?;
        Ok(Summary {
            outcome,
            state: self.state,
            checkpoint: dir,
            baseline: self.baseline,
            last: self.last.as_ref().map(|v| v.scores.clone()),
            last_seen: self.last.and_then(|v| v.seen),
        })
    }
}

fn load_vgg(
    job: &Job,
    autodiff: &Device,
    monitor: &mut dyn Monitor,
) -> Result<Option<Vgg19>, TrainError> {
    let Some(path) = &job.settings.vgg19 else {
        return Ok(None);
    };
    let vgg = Vgg19::load(path, autodiff).map_err(|source| TrainError::Weights {
        path: path.clone(),
        context: "",
        source,
    })?;
    monitor.message(&format!(
        "perceptual and style terms on VGG19 features from {}",
        path.display()
    ));
    Ok(Some(vgg))
}

/// The networks and loop state to start from: the latest checkpoint on `--resume`, else fresh
/// (or `--init`) networks; a directory that already holds a run is refused without `--resume`.
fn open_or_resume(
    job: &Job,
    autodiff: &Device,
    monitor: &mut dyn Monitor,
) -> Result<(Gan, TrainState), TrainError> {
    let (settings, run) = (&job.settings, &job.run);
    match checkpoint::latest(run)? {
        Some(dir) if job.resume => {
            let (gan, state) = checkpoint::load(
                &dir,
                job.model.clone(),
                settings.loss.clone(),
                settings.optim.clone(),
                autodiff,
            )?;
            checkpoint::restore_best(run, &state)?;
            monitor.message(&format!(
                "resuming from {} (step {})",
                dir.display(),
                state.step
            ));
            Ok((gan, state))
        }
        Some(dir) => Err(TrainError::Run {
            path: run.clone(),
            problem: format!(
                "already holds a training run ({}); pass --resume to continue it or choose \
                 another --out",
                dir.display()
            ),
        }),
        None => {
            if job.resume {
                // Killed before its first checkpoint: nothing was kept, so it starts over.
                monitor.message("no checkpoint yet: starting from step 0");
            }
            Ok((fresh_gan(job, autodiff, monitor)?, TrainState::new()))
        }
    }
}

/// New networks, or those `--init` names, seeded by the run's seed.
fn fresh_gan(job: &Job, autodiff: &Device, monitor: &mut dyn Monitor) -> Result<Gan, TrainError> {
    let settings = &job.settings;
    autodiff.seed(settings.seed);
    let Some(init) = &settings.init else {
        return Gan::new(
            job.model.clone(),
            settings.loss.clone(),
            settings.optim.clone(),
            autodiff,
        )
        .map_err(|source| TrainError::Config {
            path: job.run.clone(),
            source,
        });
    };
    let gan = init.load(job, autodiff)?;
    monitor.message(&format!(
        "starting from {}{}",
        init.generator.display(),
        init.discriminator
            .as_ref()
            .map_or(" and a fresh discriminator".to_string(), |d| format!(
                " and {}",
                d.display()
            ))
    ));
    Ok(gan)
}

/// The partial inputs' scores on the validation samples, logged once per run.
fn log_baseline(
    validator: Option<&Validator>,
    log: &mut RunLog,
    monitor: &mut dyn Monitor,
) -> Result<Option<Scores>, TrainError> {
    let Some(v) = validator else {
        monitor.message("no validation samples: stages end by their step budget only");
        return Ok(None);
    };
    let scores = validate::baseline(&v.items);
    let logged = log
        .records
        .iter()
        .any(|r| matches!(r, LogRecord::Baseline { .. }));
    if !logged {
        let record = LogRecord::Baseline {
            scores: scores.clone(),
        };
        monitor.record(&record);
        log.push(record)?;
    }
    Ok(Some(scores))
}
