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
const BEST: &str = "best";
const STATE: &str = "state.json";
const GENERATOR: &str = "generator.bpk";
const DISCRIMINATOR: &str = "discriminator.bpk";
const GENERATOR_OPTIM: &str = "generator_optim.bpk";
const DISCRIMINATOR_OPTIM: &str = "discriminator_optim.bpk";
/// The generator alone as a self-describing weights file, what `complete --model` reads.
pub const GENERATOR_WEIGHTS: &str = crate::model::weights::GENERATOR_FILE;
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
    remove_leftovers(&root)?;
    let name = format!("step-{:08}", state.step);
    let dir = root.join(&name);
    let tmp = root.join(format!(".tmp-{name}"));
    std::fs::create_dir_all(&tmp).map_err(io_error(&tmp))?;
    // A second Ctrl-C while it is written deletes it; only a kill leaves it to `--resume`.
    let _unfinished = crate::io::track(&tmp);
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
    replace_dir(&tmp, &dir)?;
    let latest = root.join(LATEST);
    atomic_write(&latest, |w| w.write_all(name.as_bytes())).map_err(io_error(&latest))?;
    prune(run, keep.max(1))?;
    Ok(dir)
}

/// Puts folder `tmp` in the place of `dir`. An existing `dir` is first renamed aside, so a
/// process killed in between leaves either folder whole, never a half-deleted one under the
/// name a resume would read.
fn replace_dir(tmp: &Path, dir: &Path) -> Result<(), CheckpointError> {
    let name = dir.file_name().expect("a named folder").to_string_lossy();
    let old = dir.with_file_name(format!(".old-{name}"));
    if dir.exists() {
        std::fs::rename(dir, &old).map_err(io_error(dir))?;
    }
    std::fs::rename(tmp, dir).map_err(io_error(dir))?;
    discard(&old)
}

/// Removes folder `dir` if it exists, renaming it to a hidden name first so that a removal
/// cut short leaves nothing a resume would take for a checkpoint.
fn discard(dir: &Path) -> Result<(), CheckpointError> {
    if !dir.exists() {
        return Ok(());
    }
    let name = dir.file_name().expect("a named folder").to_string_lossy();
    let hidden = if name.starts_with('.') {
        dir.to_path_buf()
    } else {
        dir.with_file_name(format!(".old-{name}"))
    };
    if hidden != dir {
        std::fs::rename(dir, &hidden).map_err(io_error(dir))?;
    }
    std::fs::remove_dir_all(&hidden).map_err(io_error(&hidden))
}

/// What a killed save or prune left behind (`.tmp-*`, `.old-*`).
fn remove_leftovers(root: &Path) -> Result<(), CheckpointError> {
    for entry in std::fs::read_dir(root).map_err(io_error(root))? {
        let path = entry.map_err(io_error(root))?.path();
        let name = path.file_name().unwrap_or_default().to_string_lossy();
        if path.is_dir() && (name.starts_with(".tmp-") || name.starts_with(".old-")) {
            std::fs::remove_dir_all(&path).map_err(io_error(&path))?;
        }
    }
    Ok(())
}

/// Whether checkpoint folder `dir` holds every file a resume reads.
fn is_whole(dir: &Path) -> bool {
    [
        STATE,
        GENERATOR,
        DISCRIMINATOR,
        GENERATOR_OPTIM,
        DISCRIMINATOR_OPTIM,
    ]
    .iter()
    .all(|f| dir.join(f).is_file())
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
        discard(old)?;
    }
    Ok(())
}

/// The checkpoint a resume starts from: the one `checkpoints/latest` names, or, should a kill
/// have caught that one being replaced, the newest whole one; `None` before the first.
pub fn latest(run: &Path) -> Result<Option<PathBuf>, CheckpointError> {
    let path = run.join(CHECKPOINTS).join(LATEST);
    let named = match std::fs::read_to_string(&path) {
        Ok(name) => name.trim().to_string(),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(source) => return Err(CheckpointError::Io { path, source }),
    };
    let dir = run.join(CHECKPOINTS).join(&named);
    if is_whole(&dir) {
        return Ok(Some(dir));
    }
    match list(run)?.into_iter().rev().find(|d| is_whole(d)) {
        Some(dir) => Ok(Some(dir)),
        None => Err(invalid(
            &path,
            format!("names {named}, which is missing, and no other checkpoint is whole"),
        )),
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
    let best = run.join(BEST);
    let tmp = run.join(".tmp-best");
    discard(&tmp)?;
    std::fs::create_dir_all(&tmp).map_err(io_error(&tmp))?;
    for entry in std::fs::read_dir(dir).map_err(io_error(dir))? {
        let from = entry.map_err(io_error(dir))?.path();
        if let Some(name) = from.file_name() {
            std::fs::copy(&from, tmp.join(name)).map_err(io_error(&from))?;
        }
    }
    replace_dir(&tmp, &best)?;
    Ok(best)
}

/// The step of the checkpoint copied to `run/best`, if it is there whole.
fn best_step(run: &Path) -> Option<u64> {
    let best = run.join(BEST);
    if !is_whole(&best) {
        return None;
    }
    let state: TrainState = serde_json::from_slice(&std::fs::read(best.join(STATE)).ok()?).ok()?;
    Some(state.step)
}

/// Makes `run/best` the checkpoint of `state.best_step` again where a kill between saving that
/// checkpoint and copying it left an older best (or none); a no-op otherwise.
pub fn restore_best(run: &Path, state: &TrainState) -> Result<(), CheckpointError> {
    let Some(step) = state.best_step else {
        return Ok(());
    };
    let dir = run.join(CHECKPOINTS).join(format!("step-{step:08}"));
    if best_step(run) != Some(step) && is_whole(&dir) {
        keep_as_best(run, &dir)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A checkpoint folder with every file (their contents do not matter here) at `step`.
    fn fake(run: &Path, step: u64) -> PathBuf {
        let dir = run.join(CHECKPOINTS).join(format!("step-{step:08}"));
        std::fs::create_dir_all(&dir).unwrap();
        for f in [
            GENERATOR,
            DISCRIMINATOR,
            GENERATOR_OPTIM,
            DISCRIMINATOR_OPTIM,
        ] {
            std::fs::write(dir.join(f), b"x").unwrap();
        }
        let state = TrainState {
            step,
            ..TrainState::new()
        };
        std::fs::write(dir.join(STATE), serde_json::to_vec(&state).unwrap()).unwrap();
        dir
    }

    fn point_latest_at(run: &Path, name: &str) {
        std::fs::write(run.join(CHECKPOINTS).join(LATEST), name).unwrap();
    }

    #[test]
    fn a_resume_takes_the_newest_whole_checkpoint_when_latest_was_caught_mid_replace() {
        let dir = tempfile::tempdir().unwrap();
        let run = dir.path();
        assert_eq!(latest(run).unwrap(), None);
        let four = fake(run, 4);
        let eight = fake(run, 8);
        point_latest_at(run, "step-00000008");
        assert_eq!(latest(run).unwrap(), Some(eight.clone()));
        // Killed between renaming step 8 aside and renaming its replacement into place.
        std::fs::rename(&eight, eight.with_file_name(".old-step-00000008")).unwrap();
        assert_eq!(latest(run).unwrap(), Some(four.clone()));
        // A removal cut short leaves a folder without some files: not taken.
        std::fs::remove_file(four.join(GENERATOR_OPTIM)).unwrap();
        let message = latest(run).unwrap_err().to_string();
        assert!(
            message.contains("no other checkpoint is whole"),
            "{message}"
        );
        remove_leftovers(&run.join(CHECKPOINTS)).unwrap();
        assert!(!eight.with_file_name(".old-step-00000008").exists());
    }

    #[test]
    fn best_is_restored_when_a_kill_came_between_checkpoint_and_copy() {
        let dir = tempfile::tempdir().unwrap();
        let run = dir.path();
        keep_as_best(run, &fake(run, 4)).unwrap();
        fake(run, 8);
        let state = TrainState {
            step: 8,
            best_step: Some(8),
            ..TrainState::new()
        };
        assert_eq!(best_step(run), Some(4));
        restore_best(run, &state).unwrap();
        assert_eq!(best_step(run), Some(8));
        std::fs::remove_dir_all(run.join(BEST)).unwrap();
        restore_best(run, &state).unwrap();
        assert_eq!(best_step(run), Some(8));
    }
}
