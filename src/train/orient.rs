//! Training the orientation network (`mvpcc train-orient`): partial samples of a
//! "shapenet-views" directory, decoded back to points (they are in the canonical pose, heading
//! 90°), turned by a random yaw, and the network learns the turned heading.

use crate::complete::orient::net::{sample_points, target, Orienter, OrienterConfig, OrienterNet};
use crate::complete::orient::{angle_between, heading_of_turn};
use crate::core::rng::{derive_seed, Lcg};
use crate::model::gan::value;
use crate::model::weights::WeightsError;
use crate::train::dataset::{hold_back, scan_split, Cache, DataError, SampleRef};
use burn::module::Module;
use burn::optim::{AdamConfig, GradientsParams, ModuleOptimizer};
use burn::tensor::{Device, Tensor, TensorData};
use serde::{Deserialize, Serialize};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use thiserror::Error;

#[derive(Debug, Error)]
pub enum OrientTrainError {
    #[error(transparent)]
    Data(#[from] DataError),
    #[error("{}: no validation samples: no test split and too few models to hold back", .0.display())]
    NoValidation(PathBuf),
    /// The monitor could not record a step (its log cannot be written): the run stops.
    #[error("cannot record step {step}: {source}")]
    Monitor { step: u64, source: std::io::Error },
}

/// What shapes a run; saved beside the weights as `train-orient.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct OrientSettings {
    /// Rig cameras whose view images are decoded into the partial's points.
    pub views: Vec<usize>,
    pub batch: usize,
    pub steps: u64,
    pub learning_rate: f64,
    /// Validation samples (each at a fixed random yaw).
    pub val_samples: usize,
    pub val_every: u64,
    /// Standard deviation of the noise added to every coordinate (normalized units).
    pub noise: f64,
    pub seed: u64,
}

impl Default for OrientSettings {
    fn default() -> Self {
        OrientSettings {
            views: crate::core::camera::DEFAULT_VIEWS.to_vec(),
            batch: 32,
            steps: 4000,
            learning_rate: 1e-3,
            val_samples: 256,
            val_every: 250,
            noise: 0.003,
            seed: 0,
        }
    }
}

impl OrientSettings {
    /// Refuses settings no run can train with: a batch of 0 crashed the process, one of 10⁸
    /// aborted it on an allocation.
    pub fn validate(&self) -> Result<(), String> {
        if self.batch == 0 || self.batch > crate::model::MAX_BATCH {
            return Err(format!(
                "batch {} (1 to {} expected)",
                self.batch,
                crate::model::MAX_BATCH
            ));
        }
        if !(self.learning_rate.is_finite() && self.learning_rate > 0.0) {
            return Err(format!(
                "learning rate {} (a positive number expected)",
                self.learning_rate
            ));
        }
        if self.views.is_empty() {
            return Err("no views".into());
        }
        Ok(())
    }
}

/// Heading errors on the validation samples.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct OrientScores {
    /// Degrees.
    pub median: f64,
    pub p95: f64,
    /// Share with the front and back swapped (error over 90°).
    pub flips: f64,
}

impl OrientScores {
    pub fn of(errors: &mut [f64]) -> OrientScores {
        errors.sort_by(f64::total_cmp);
        let at = |q: f64| {
            errors
                .get(((errors.len() as f64 - 1.0) * q).round() as usize)
                .copied()
                .unwrap_or(f64::NAN)
        };
        OrientScores {
            median: at(0.5),
            p95: at(0.95),
            flips: errors.iter().filter(|&&e| e > 90.0).count() as f64 / errors.len().max(1) as f64,
        }
    }
}

/// One line of progress.
#[derive(Debug, Clone, Serialize)]
pub struct OrientRecord {
    pub step: u64,
    pub loss: f32,
    pub validation: Option<OrientScores>,
}

/// A partial's points turned about the vertical by `turn` degrees (heading 90° + `turn`), with
/// noise.
fn turned(points: &[[f64; 3]], turn: f64, noise: f64, rng: &mut Lcg) -> Vec<[f64; 3]> {
    let (s, c) = turn.to_radians().sin_cos();
    points
        .iter()
        .map(|&[x, y, z]| {
            let mut p = [c * x + s * z, y, -s * x + c * z];
            for v in &mut p {
                *v += noise * rng.gauss();
            }
            p
        })
        .collect()
}

/// The training and validation samples: the test split when the data has one, else held-back
/// models.
pub struct OrientData {
    root: PathBuf,
    train: Vec<SampleRef>,
    validation: Vec<SampleRef>,
}

impl OrientData {
    /// Lists the samples without decoding any, so a command can refuse bad data before it
    /// creates its run directory.
    pub fn scan(data: &Path) -> Result<OrientData, OrientTrainError> {
        let train = scan_split(data, "train")?.samples;
        match scan_split(data, "test") {
            Ok(test) => Ok(OrientData {
                root: data.to_path_buf(),
                train,
                validation: test.samples,
            }),
            Err(DataError::NotViews { .. }) | Err(DataError::Empty { .. }) => {
                let (train, validation) = hold_back(train, 0.05);
                if validation.is_empty() {
                    return Err(OrientTrainError::NoValidation(data.to_path_buf()));
                }
                Ok(OrientData {
                    root: data.to_path_buf(),
                    train,
                    validation,
                })
            }
            Err(e) => Err(e.into()),
        }
    }
}

/// Trains an orientation network, decoding samples into a cache of `cache_bytes`; `monitor`
/// records each step, and an error from it stops the run with that error. Returns the network
/// with the best validation median.
pub fn train_orienter(
    data: &OrientData,
    config: &OrienterConfig,
    settings: &OrientSettings,
    device: &Device,
    cache_bytes: usize,
    mut monitor: impl FnMut(&OrientRecord) -> std::io::Result<()>,
) -> Result<(Orienter, OrientScores), OrientTrainError> {
    let (train, validation) = (&data.train, &data.validation);
    let cache = Arc::new(Cache::new(cache_bytes));
    let load = |s: &SampleRef| -> Result<Vec<[f64; 3]>, DataError> {
        Ok(cache.get(&s.input, &settings.views)?.points())
    };
    let val_set = validation_set(validation, settings, &load)?;
    if val_set.is_empty() {
        return Err(OrientTrainError::NoValidation(data.root.clone()));
    }

    let autodiff = device.clone().autodiff();
    // The weights' initial draw too, so that a seed repeats a run.
    autodiff.seed(settings.seed);
    let mut net = OrienterNet::new(config, &autodiff);
    let mut optim = AdamConfig::new().init();
    let n = config.points;
    let mut best: Option<(OrienterNet, OrientScores)> = None;
    let score = |net: &OrienterNet| scores_on(net, config, device, &val_set);
    let mut draw = Lcg::new(derive_seed(settings.seed, "orient draws"));
    for step in 1..=settings.steps {
        let batch = draw_batch(train, settings, n, &mut draw, &load)?;
        let value;
        (net, value) = fit_step(net, &mut optim, batch, settings, n, &autodiff);

        let validation = (settings.val_every > 0
            && (step % settings.val_every == 0 || step == settings.steps))
            .then(|| score(&net));
        if let Some(scores) = validation {
            if best.as_ref().is_none_or(|(_, b)| scores.median < b.median) {
                best = Some((net.clone(), scores));
            }
        }
        monitor(&OrientRecord {
            step,
            loss: value,
            validation,
        })
        .map_err(|source| OrientTrainError::Monitor { step, source })?;
    }
    let (net, scores) = match best {
        Some(b) => b,
        None => {
            let scores = score(&net);
            (net, scores)
        }
    };
    Ok((
        Orienter::new(net.valid(), config.clone(), device.clone()),
        scores,
    ))
}

/// One Adam step on the squared error between the net's output and the batch's targets; the
/// updated net and the loss before the step.
///
/// # Shapes
/// - `batch.0`: `[batch, n, 3]` points, flattened
/// - `batch.1`: `[batch, 4]` targets, flattened
fn fit_step(
    net: OrienterNet,
    optim: &mut ModuleOptimizer,
    (inputs, targets): (Vec<f32>, Vec<f32>),
    settings: &OrientSettings,
    n: usize,
    device: &Device,
) -> (OrienterNet, f32) {
    let b = settings.batch;
    // [batch, N, 3]
    let x = Tensor::<3>::from_data(TensorData::new(inputs, [b, n, 3]), device);
    // [batch, 4]
    let y = Tensor::<2>::from_data(TensorData::new(targets, [b, 4]), device);
    let loss = (net.forward(x) - y).powi_scalar(2).mean();
    let value = value(loss.clone());
    let grads = GradientsParams::from_grads(loss.backward(), &net);
    (optim.step(settings.learning_rate, net, grads), value)
}

/// The heading errors of `net` (degrees) over the validation partials `val_set`.
fn scores_on(
    net: &OrienterNet,
    config: &OrienterConfig,
    device: &Device,
    val_set: &[Turned],
) -> OrientScores {
    let orienter = Orienter::new(net.valid(), config.clone(), device.clone());
    let mut errors: Vec<f64> = val_set
        .iter()
        .map(|(points, heading)| angle_between(orienter.heading(points), *heading))
        .collect();
    OrientScores::of(&mut errors)
}

/// Partials with fewer points say nothing about a heading.
const MIN_POINTS: usize = 10;

/// A partial's points turned to a heading, and that heading (degrees).
type Turned = (Vec<[f64; 3]>, f64);

/// About `settings.val_samples` validation partials spread over `validation`, each turned
/// to a random heading (the same ones in every run of a seed), with that heading.
fn validation_set(
    validation: &[SampleRef],
    settings: &OrientSettings,
    load: &impl Fn(&SampleRef) -> Result<Vec<[f64; 3]>, DataError>,
) -> Result<Vec<Turned>, DataError> {
    let mut rng = Lcg::new(derive_seed(settings.seed, "orient validation"));
    let stride = validation
        .len()
        .div_ceil(settings.val_samples.max(1))
        .max(1);
    let mut set = Vec::new();
    for s in validation.iter().step_by(stride) {
        let points = load(s)?;
        if points.len() < MIN_POINTS {
            continue;
        }
        let turn = rng.range(-180.0, 180.0);
        set.push((turned(&points, turn, 0.0, &mut rng), heading_of_turn(turn)));
    }
    Ok(set)
}

/// A training batch drawn from `train`: `settings.batch` partials turned to random headings
/// with noise, `n` points each (`[batch, n, 3]` flattened), and their heading targets
/// (`[batch, 4]` flattened).
fn draw_batch(
    train: &[SampleRef],
    settings: &OrientSettings,
    n: usize,
    draw: &mut Lcg,
    load: &impl Fn(&SampleRef) -> Result<Vec<[f64; 3]>, DataError>,
) -> Result<(Vec<f32>, Vec<f32>), DataError> {
    let mut inputs = Vec::with_capacity(settings.batch * n * 3);
    let mut targets = Vec::with_capacity(settings.batch * 4);
    let mut filled = 0;
    while filled < settings.batch {
        let points = load(&train[draw.below(train.len())])?;
        if points.len() < MIN_POINTS {
            continue;
        }
        let turn = draw.range(-180.0, 180.0);
        let points = turned(&points, turn, settings.noise, draw);
        inputs.extend(sample_points(&points, n, draw));
        targets.extend(target(heading_of_turn(turn)));
        filled += 1;
    }
    Ok((inputs, targets))
}

/// The weights file of a trained orientation run.
pub const WEIGHTS_FILE: &str = "orienter.safetensors";

#[derive(Debug, Error)]
pub enum OrientRunError {
    #[error("{}: exists and is not a directory", .0.display())]
    NotADirectory(PathBuf),
    #[error("{}: already holds {WEIGHTS_FILE}; choose another --out", .0.display())]
    AlreadyTrained(PathBuf),
    #[error("{}: {source}", path.display())]
    Write {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{}: {source}", path.display())]
    Log {
        path: PathBuf,
        source: OrientTrainError,
    },
    #[error(transparent)]
    Train(#[from] OrientTrainError),
    #[error(transparent)]
    Weights(#[from] WeightsError),
}

/// Refuses a run directory whose name a file holds, or that holds a trained network already.
pub fn check_run_dir(out: &Path) -> Result<(), OrientRunError> {
    if out.exists() && !out.is_dir() {
        return Err(OrientRunError::NotADirectory(out.to_path_buf()));
    }
    if out.join(WEIGHTS_FILE).exists() {
        return Err(OrientRunError::AlreadyTrained(out.to_path_buf()));
    }
    Ok(())
}

/// Trains into the run directory `out`: `config.json` and `train-orient.json` first, each
/// step's record appended to `log.jsonl` (and passed to `on_record`), the weights last. The
/// weights file and the best validation scores.
pub fn train_orienter_in(
    out: &Path,
    data: &OrientData,
    config: &OrienterConfig,
    settings: &OrientSettings,
    device: &Device,
    cache_bytes: usize,
    mut on_record: impl FnMut(&OrientRecord),
) -> Result<(PathBuf, OrientScores), OrientRunError> {
    std::fs::create_dir_all(out).map_err(|source| OrientRunError::Write {
        path: out.to_path_buf(),
        source,
    })?;
    write_file(&out.join("config.json"), |w| to_json(w, config))?;
    write_file(&out.join("train-orient.json"), |w| to_json(w, settings))?;
    let log_path = out.join("log.jsonl");
    let mut log = std::fs::File::create(&log_path).map_err(|source| OrientRunError::Write {
        path: log_path.clone(),
        source,
    })?;
    let monitor = |record: &OrientRecord| {
        on_record(record);
        let line = serde_json::to_string(record).map_err(std::io::Error::other)?;
        writeln!(log, "{line}")
    };
    let (orienter, scores) = train_orienter(data, config, settings, device, cache_bytes, monitor)
        .map_err(|e| match e {
        OrientTrainError::Monitor { .. } => OrientRunError::Log {
            path: log_path.clone(),
            source: e,
        },
        e => e.into(),
    })?;
    let weights = out.join(WEIGHTS_FILE);
    let bytes = orienter.to_bytes()?;
    write_file(&weights, |w| w.write_all(&bytes))?;
    Ok((weights, scores))
}

fn write_file(
    path: &Path,
    body: impl FnOnce(&mut std::io::BufWriter<&std::fs::File>) -> std::io::Result<()>,
) -> Result<(), OrientRunError> {
    crate::io::atomic_write(path, body).map_err(|source| OrientRunError::Write {
        path: path.to_path_buf(),
        source,
    })
}

fn to_json(w: &mut impl std::io::Write, value: &impl Serialize) -> std::io::Result<()> {
    serde_json::to_writer_pretty(w, value).map_err(std::io::Error::other)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scores_count_flips_and_quantiles() {
        let mut errors = vec![1.0, 2.0, 3.0, 170.0, 4.0];
        let s = OrientScores::of(&mut errors);
        assert_eq!(s.median, 3.0);
        assert_eq!(s.p95, 170.0);
        assert!((s.flips - 0.2).abs() < 1e-12);
    }

    #[test]
    fn turning_moves_the_front() {
        // The canonical front (−z) turned a quarter counter-clockwise faces −x: heading 180°.
        let p = turned(&[[0.0, 0.0, -1.0]], 90.0, 0.0, &mut Lcg::new(0))[0];
        assert!((p[0] + 1.0).abs() < 1e-12 && p[2].abs() < 1e-12, "{p:?}");
        assert_eq!(heading_of_turn(90.0), 180.0);
    }
}
