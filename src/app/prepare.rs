//! Training data from a folder of meshes (or procedural ones): every model prepared in
//! parallel, resumable, sharded over machines, the bad meshes skipped and listed, and the
//! manifest written by the run that covers them all.

use super::synth::{generate, SynthError};
use super::{create_dir, write_json, PathError, Progress};
use crate::datagen::data::{
    discover, finished, prepare_model, Layout, Manifest, ModelEntry, PrepareError, PrepareParams,
    Skipped, Source, MANIFEST_FILE, PARAMS_FILE, TEST, TRAIN,
};
use crate::datagen::synth::Draw;
use crate::io::batch::{lies_in, BatchError, Shard};
use rayon::prelude::*;
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Mutex;
use thiserror::Error;

#[derive(Debug, Error)]
pub enum PrepareRunError {
    #[error(transparent)]
    Path(#[from] PathError),
    #[error(transparent)]
    Synth(#[from] SynthError),
    #[error(transparent)]
    Batch(#[from] BatchError),
    #[error(transparent)]
    Model(#[from] PrepareError),
    #[error("{}: not a directory", .0.display())]
    NotADirectory(PathBuf),
    #[error("{}: exists and is not a directory", .0.display())]
    OutputNotADirectory(PathBuf),
    #[error("{}: --out lies in the --meshes folder {}, whose next scan would read its clouds as meshes", out.display(), meshes.display())]
    OutInMeshes { out: PathBuf, meshes: PathBuf },
    #[error("{}: no meshes found (.obj, .ply, .gltf, .glb)", .0.display())]
    NoMeshes(PathBuf),
    #[error("{}: none of the meshes could be used", .0.display())]
    NoneUsable(PathBuf),
    #[error("{}: was prepared with other settings ({changed}); use another --out directory", out.display())]
    OtherSettings { out: PathBuf, changed: String },
    #[error("{}: unreadable settings file: {source}", path.display())]
    Settings {
        path: PathBuf,
        source: serde_json::Error,
    },
}

/// Where the meshes come from.
#[derive(Debug, Clone)]
pub enum Meshes {
    /// A folder of mesh files, read as they are.
    Folder(PathBuf),
    /// Procedural objects generated into `OUT/meshes`.
    Synth {
        count: usize,
        draws: Vec<Draw>,
        seed: u64,
    },
}

/// One `prepare` run.
#[derive(Debug, Clone)]
pub struct Preparation {
    pub meshes: Meshes,
    pub out: PathBuf,
    pub params: PrepareParams,
    /// This machine's share of the meshes; the run without it writes the manifest.
    pub shard: Option<Shard>,
}

/// What `prepare --json` prints.
#[derive(Debug, Serialize)]
pub struct PrepareReport {
    pub models: usize,
    pub resumed: usize,
    pub train: usize,
    pub test: usize,
    pub samples: usize,
    pub skipped: usize,
    pub seconds: f64,
    pub models_per_second: f64,
    /// `i/n` when the run prepared one shard of the meshes.
    pub shard: Option<String>,
    /// The manifest written, by a run without a shard.
    pub manifest: Option<String>,
    /// Models prepared by this run.
    #[serde(skip)]
    pub new: usize,
}

impl PrepareReport {
    /// The run's closing line.
    pub fn summary(&self) -> String {
        format!(
            "prepared {} models ({} train, {} test; {} new at {:.2}/s, {} resumed), {} samples; {}",
            self.models,
            self.train,
            self.test,
            self.new,
            self.models_per_second,
            self.resumed,
            self.samples,
            match (&self.manifest, &self.shard) {
                (Some(path), _) => format!("{} skipped — see {path}", self.skipped),
                (None, Some(shard)) => format!(
                    "shard {shard}: once every shard is done, run the same command without \
                     --shard to write the manifest"
                ),
                (None, None) => unreachable!("a run without a shard writes the manifest"),
            }
        )
    }
}

impl Preparation {
    /// Prepares every mesh not prepared before; an error when none could be used.
    /// `on_synth` is told what generating procedural meshes did.
    pub fn run(
        &self,
        progress: &dyn Progress,
        on_synth: &dyn Fn(&super::synth::Generated),
    ) -> Result<PrepareReport, PrepareRunError> {
        let out = &self.out;
        if out.exists() && !out.is_dir() {
            return Err(PrepareRunError::OutputNotADirectory(out.clone()));
        }
        let meshes = self.meshes_dir(progress, on_synth)?;
        let (mut sources, mut skipped) = self.find_meshes(&meshes)?;
        create_dir(out)?;
        self.claim()?;
        if let Some(shard) = self.shard {
            sources.retain(|s| shard.owns(&format!("{}/{}", s.category, s.name)));
            // The run without a shard that writes the manifest lists them.
            skipped.clear();
        }
        let layout = Layout { root: out.clone() };
        let (mut done, todo) = resume(&layout, &sources, &self.params);
        let resumed = done.len();
        if resumed > 0 {
            progress.note(&format!(
                "{resumed} of {} models already prepared",
                sources.len()
            ));
        }
        let started = std::time::Instant::now();
        let (made, failed) = prepare_all(&todo, &self.params, &layout, progress)?;
        let seconds = started.elapsed().as_secs_f64();
        let new = made.len();
        done.extend(made);
        skipped.extend(failed);
        let report = self.report(done, skipped, new, resumed, seconds)?;
        if report.models == 0 && self.shard.is_none() {
            return Err(PrepareRunError::NoneUsable(meshes));
        }
        Ok(report)
    }

    /// The meshes folder: the given one, or procedural objects generated into OUT/meshes.
    fn meshes_dir(
        &self,
        progress: &dyn Progress,
        on_synth: &dyn Fn(&super::synth::Generated),
    ) -> Result<PathBuf, PrepareRunError> {
        match &self.meshes {
            Meshes::Folder(dir) => {
                if !dir.is_dir() {
                    return Err(PrepareRunError::NotADirectory(dir.clone()));
                }
                Ok(dir.clone())
            }
            Meshes::Synth { count, draws, seed } => {
                let dir = self.out.join("meshes");
                on_synth(&generate(&dir, *count, draws, *seed, true, progress)?);
                Ok(dir)
            }
        }
    }

    /// What the meshes folder holds: the meshes to prepare and the files skipped. A folder of
    /// meshes is read before anything is written under the output, so one without meshes
    /// leaves no output behind; an output inside it is refused.
    fn find_meshes(&self, meshes: &Path) -> Result<(Vec<Source>, Vec<Skipped>), PrepareRunError> {
        // Links followed (a link to the meshes folder is that folder); the output need not
        // exist yet.
        let out_inside = meshes
            .canonicalize()
            .is_ok_and(|meshes| lies_in(&self.out, &meshes));
        if matches!(self.meshes, Meshes::Folder(_)) && out_inside {
            return Err(PrepareRunError::OutInMeshes {
                out: self.out.clone(),
                meshes: meshes.to_path_buf(),
            });
        }
        let (sources, skipped) = discover(meshes)?;
        if sources.is_empty() {
            return Err(PrepareRunError::NoMeshes(meshes.to_path_buf()));
        }
        Ok((sources, skipped))
    }

    /// Records the settings on first use; a resumed run must use the same ones, or the
    /// directory would mix data made in two ways.
    fn claim(&self) -> Result<(), PrepareRunError> {
        let path = self.out.join(PARAMS_FILE);
        let Ok(text) = std::fs::read_to_string(&path) else {
            return Ok(write_json(&path, &self.params)?);
        };
        let before: PrepareParams = serde_json::from_str(&text)
            .map_err(|source| PrepareRunError::Settings { path, source })?;
        if before == self.params {
            return Ok(());
        }
        let json = |p: &PrepareParams| serde_json::to_value(p).unwrap_or_default();
        let (now, then) = (json(&self.params), json(&before));
        let changed: Vec<String> = now
            .as_object()
            .into_iter()
            .flatten()
            .filter(|(k, v)| then.get(k.as_str()) != Some(v))
            .map(|(k, v)| {
                let was = then.get(k.as_str()).unwrap_or(&serde_json::Value::Null);
                format!("{k} {was} → {v}")
            })
            .collect();
        Err(PrepareRunError::OtherSettings {
            out: self.out.clone(),
            changed: changed.join(", "),
        })
    }

    /// The report over every model prepared so far (`done`, in any order) and every mesh
    /// skipped; writes the manifest when the run covers every mesh (no shard).
    fn report(
        &self,
        mut done: Vec<ModelEntry>,
        mut skipped: Vec<Skipped>,
        new: usize,
        resumed: usize,
        seconds: f64,
    ) -> Result<PrepareReport, PrepareRunError> {
        done.sort_by(|a, b| (&a.category, &a.name).cmp(&(&b.category, &b.name)));
        skipped.sort_by(|a, b| a.path.cmp(&b.path));
        let mut report = PrepareReport {
            models: done.len(),
            resumed,
            train: done.iter().filter(|m| m.split == TRAIN).count(),
            test: done.iter().filter(|m| m.split == TEST).count(),
            samples: done.iter().map(|m| m.samples.len()).sum(),
            skipped: skipped.len(),
            seconds,
            models_per_second: if seconds > 0.0 {
                new as f64 / seconds
            } else {
                0.0
            },
            shard: self.shard.map(|s| s.to_string()),
            manifest: None,
            new,
        };
        if self.shard.is_none() {
            let manifest = Manifest {
                mvpcc_version: env!("CARGO_PKG_VERSION").to_string(),
                params: self.params.clone(),
                models: done,
                skipped,
            };
            let path = self.out.join(MANIFEST_FILE);
            write_json(&path, &manifest)?;
            report.manifest = Some(path.display().to_string());
        }
        Ok(report)
    }
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

/// Prepares `todo` in parallel: the models made and the meshes skipped for a problem of their
/// own; any other error (a full disk) stops the run.
fn prepare_all(
    todo: &[&Source],
    params: &PrepareParams,
    layout: &Layout,
    progress: &dyn Progress,
) -> Result<(Vec<ModelEntry>, Vec<Skipped>), PrepareRunError> {
    progress.start(todo.len(), "prepare");
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
            progress.done(&source.name);
            match result {
                Ok(entry) => Some(entry),
                Err(e) if e.is_input_problem() => {
                    progress.warn(&format!("skipped {e}"));
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
    progress.finish();
    if let Some(e) = fatal.into_inner().expect("not poisoned") {
        return Err(e.into());
    }
    Ok((made, failed.into_inner().expect("not poisoned")))
}
