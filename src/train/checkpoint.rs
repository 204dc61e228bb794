//! Checkpoints: `checkpoints/step-NNNNNNNN/` holds both networks and both optimizers in Burn's
//! burnpack format (which keeps parameter ids, so the optimizers' moments find their
//! parameters again) and the loop's state. A checkpoint is written into a hidden folder and
//! renamed into place, and `checkpoints/latest` names the newest, so an interrupted write never
//! leaves a half checkpoint behind.

use crate::io::atomic_write;
use crate::model::gan::{Gan, GanOptimConfig};
use crate::model::loss::LossWeights;
use crate::model::weights::{discriminator_to_bytes, generator_to_bytes};
use crate::model::ModelConfig;
use burn::module::Module;
use burn::store::ModuleRecord;
use burn::tensor::{Bytes, Device};
use serde::{Deserialize, Serialize};
use std::io::Write;
use std::path::{Path, PathBuf};
use thiserror::Error;

pub const CHECKPOINTS: &str = "checkpoints";
const LATEST: &str = "latest";
const STATE: &str = "state.json";
const GENERATOR: &str = "generator.bpk";
const DISCRIMINATOR: &str = "discriminator.bpk";
const GENERATOR_OPTIM: &str = "generator_optim.bpk";
const DISCRIMINATOR_OPTIM: &str = "discriminator_optim.bpk";
/// The generator alone as a self-describing weights file, what `complete --model` reads.
pub const GENERATOR_WEIGHTS: &str = "generator.safetensors";
/// The discriminator as a self-describing weights file, so that `train --init` can continue
/// a run's adversarial game in a new run.
pub const DISCRIMINATOR_WEIGHTS: &str = "discriminator.safetensors";

#[derive(Debug, Error)]
pub enum CheckpointError {
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{}: {problem}", path.display())]
    Invalid { path: PathBuf, problem: String },
}

/// Where the training loop stands; together with the networks and optimizers it determines
/// every later step.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrainState {
    /// Completed optimizer steps.
    pub step: u64,
    /// Learning-rate stage, 0-based.
    pub stage: usize,
    pub stage_start: u64,
    pub best_cd: Option<f64>,
    pub best_step: Option<u64>,
    pub stage_best_cd: Option<f64>,
    pub validations_without_improvement: usize,
    /// Every stage ran out of patience or budget.
    pub finished: bool,
}

impl TrainState {
    pub fn new() -> TrainState {
        TrainState {
            step: 0,
            stage: 0,
            stage_start: 0,
            best_cd: None,
            best_step: None,
            stage_best_cd: None,
            validations_without_improvement: 0,
            finished: false,
        }
    }
}

impl Default for TrainState {
    fn default() -> Self {
        TrainState::new()
    }
}

fn io_error(path: &Path) -> impl FnOnce(std::io::Error) -> CheckpointError + '_ {
    move |source| CheckpointError::Io {
        path: path.to_path_buf(),
        source,
    }
}

fn invalid(path: &Path, problem: impl ToString) -> CheckpointError {
    CheckpointError::Invalid {
        path: path.to_path_buf(),
        problem: problem.to_string(),
    }
}

fn write(path: &Path, bytes: &[u8]) -> Result<(), CheckpointError> {
    std::fs::write(path, bytes).map_err(io_error(path))
}

fn module_bytes<M: Module>(module: &M, path: &Path) -> Result<Vec<u8>, CheckpointError> {
    let bytes = module
        .clone()
        .into_record()
        .into_bytes()
        .map_err(|e| invalid(path, e))?;
    Ok(bytes.to_vec())
}

/// Writes a checkpoint of `gan` at `state.step` and keeps the newest `keep` of them.
pub fn save(
    run: &Path,
    gan: &Gan,
    state: &TrainState,
    keep: usize,
) -> Result<PathBuf, CheckpointError> {
    let root = run.join(CHECKPOINTS);
    std::fs::create_dir_all(&root).map_err(io_error(&root))?;
    let name = format!("step-{:08}", state.step);
    let dir = root.join(&name);
    let tmp = root.join(format!(".tmp-{name}"));
    if tmp.exists() {
        std::fs::remove_dir_all(&tmp).map_err(io_error(&tmp))?;
    }
    std::fs::create_dir_all(&tmp).map_err(io_error(&tmp))?;
    let [g_optim, d_optim] = gan.optimizer_bytes().map_err(|e| invalid(&tmp, e))?;
    write(&tmp.join(GENERATOR), &module_bytes(&gan.generator, &tmp)?)?;
    write(
        &tmp.join(DISCRIMINATOR),
        &module_bytes(&gan.discriminator, &tmp)?,
    )?;
    write(&tmp.join(GENERATOR_OPTIM), &g_optim)?;
    write(&tmp.join(DISCRIMINATOR_OPTIM), &d_optim)?;
    let weights = generator_to_bytes(&gan.generator, &gan.config).map_err(|e| invalid(&tmp, e))?;
    write(&tmp.join(GENERATOR_WEIGHTS), &weights)?;
    let weights =
        discriminator_to_bytes(&gan.discriminator, &gan.config).map_err(|e| invalid(&tmp, e))?;
    write(&tmp.join(DISCRIMINATOR_WEIGHTS), &weights)?;
    let json = serde_json::to_vec_pretty(state).map_err(|e| invalid(&tmp, e))?;
    write(&tmp.join(STATE), &json)?;
    if dir.exists() {
        std::fs::remove_dir_all(&dir).map_err(io_error(&dir))?;
    }
    std::fs::rename(&tmp, &dir).map_err(io_error(&dir))?;
    let latest = root.join(LATEST);
    atomic_write(&latest, |w| w.write_all(name.as_bytes())).map_err(io_error(&latest))?;
    prune(run, keep.max(1))?;
    Ok(dir)
}

/// Checkpoint folders, oldest first.
pub fn list(run: &Path) -> Result<Vec<PathBuf>, CheckpointError> {
    let root = run.join(CHECKPOINTS);
    if !root.is_dir() {
        return Ok(Vec::new());
    }
    let mut dirs: Vec<PathBuf> = std::fs::read_dir(&root)
        .map_err(io_error(&root))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            p.is_dir()
                && p.file_name()
                    .and_then(|n| n.to_str())
                    .is_some_and(|n| n.starts_with("step-"))
        })
        .collect();
    dirs.sort();
    Ok(dirs)
}

fn prune(run: &Path, keep: usize) -> Result<(), CheckpointError> {
    let dirs = list(run)?;
    for old in dirs.iter().take(dirs.len().saturating_sub(keep)) {
        std::fs::remove_dir_all(old).map_err(io_error(old))?;
    }
    Ok(())
}

/// The checkpoint `checkpoints/latest` names, if the run has one.
pub fn latest(run: &Path) -> Result<Option<PathBuf>, CheckpointError> {
    let path = run.join(CHECKPOINTS).join(LATEST);
    match std::fs::read_to_string(&path) {
        Ok(name) => {
            let dir = run.join(CHECKPOINTS).join(name.trim());
            if dir.join(STATE).is_file() {
                Ok(Some(dir))
            } else {
                Err(invalid(
                    &path,
                    format!("names {}, which is missing", name.trim()),
                ))
            }
        }
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
        Err(source) => Err(CheckpointError::Io { path, source }),
    }
}

fn read(path: &Path) -> Result<Vec<u8>, CheckpointError> {
    std::fs::read(path).map_err(io_error(path))
}

fn load_module<M: Module>(module: M, path: &Path) -> Result<M, CheckpointError> {
    let record = ModuleRecord::from_bytes(Bytes::from_bytes_vec(read(path)?))
        .map_err(|e| invalid(path, e))?;
    module.try_load_record(record).map_err(|e| invalid(path, e))
}

/// Restores the networks, optimizers and loop state of checkpoint `dir` onto `device` (which
/// records gradients).
pub fn load(
    dir: &Path,
    config: ModelConfig,
    weights: LossWeights,
    optim: GanOptimConfig,
    device: &Device,
) -> Result<(Gan, TrainState), CheckpointError> {
    let state_path = dir.join(STATE);
    let state: TrainState =
        serde_json::from_slice(&read(&state_path)?).map_err(|e| invalid(&state_path, e))?;
    let generator = load_module(
        config.init_generator(device).map_err(|e| invalid(dir, e))?,
        &dir.join(GENERATOR),
    )?;
    let discriminator = load_module(
        config
            .init_discriminator(device)
            .map_err(|e| invalid(dir, e))?,
        &dir.join(DISCRIMINATOR),
    )?;
    let gan = Gan::from_parts(generator, discriminator, config, weights, optim)
        .load_optimizers(
            &read(&dir.join(GENERATOR_OPTIM))?,
            &read(&dir.join(DISCRIMINATOR_OPTIM))?,
        )
        .map_err(|e| invalid(dir, e))?;
    Ok((gan, state))
}

/// Copies checkpoint `dir` to `run/best` (replacing the previous best in one rename).
pub fn keep_as_best(run: &Path, dir: &Path) -> Result<PathBuf, CheckpointError> {
    let best = run.join("best");
    let tmp = run.join(".tmp-best");
    if tmp.exists() {
        std::fs::remove_dir_all(&tmp).map_err(io_error(&tmp))?;
    }
    std::fs::create_dir_all(&tmp).map_err(io_error(&tmp))?;
    for entry in std::fs::read_dir(dir).map_err(io_error(dir))? {
        let from = entry.map_err(io_error(dir))?.path();
        if let Some(name) = from.file_name() {
            std::fs::copy(&from, tmp.join(name)).map_err(io_error(&from))?;
        }
    }
    if best.exists() {
        std::fs::remove_dir_all(&best).map_err(io_error(&best))?;
    }
    std::fs::rename(&tmp, &best).map_err(io_error(&best))?;
    Ok(best)
}
