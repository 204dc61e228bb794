//! Procedural meshes written to a folder (`synth`, and `prepare --synth`): the objects as OBJ
//! under `OUT/<category>/`, their manifest `synth.json`, and a contact sheet.

use super::{create_dir, write_json, PathError, Progress};
use crate::core::rng::derive_seed;
use crate::datagen::mesh::{write_obj, Mesh};
use crate::datagen::synth::street::{street, Kind, StreetParams, TruthObject};
use crate::datagen::synth::{contact_sheet, synthesize, Category, Draw, MAX_OBJECTS};
use crate::io::{atomic_write, write_cloud, Encoding};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use thiserror::Error;

pub const SYNTH_FILE: &str = "synth.json";
/// Objects on the contact sheet: a 4 × 4 grid stays legible at 192 px a tile.
const PREVIEW_OBJECTS: usize = 16;

#[derive(Debug, Error)]
pub enum SynthError {
    #[error(transparent)]
    Path(#[from] PathError),
    #[error("{option} must lie in 1..={MAX_OBJECTS}, got {count}")]
    Count { option: &'static str, count: usize },
    #[error("--category: {0} given twice")]
    CategoryTwice(&'static str),
    #[error("{}: exists and is not a directory", .0.display())]
    NotADirectory(PathBuf),
    #[error(transparent)]
    Cloud(#[from] crate::io::CloudIoError),
    #[error("--length must lie in 10..=1000 metres, got {0}")]
    Length(f32),
}

/// The truth beside each generated street (`street_NNNNN.json`).
#[derive(Debug, Serialize)]
pub struct StreetTruth {
    pub mvpcc_version: String,
    pub seed: u64,
    pub params: StreetParams,
    /// The LAS classification codes its points carry, by kind of object.
    pub classes: Vec<(Kind, u8)>,
    /// Each object, its id the value of the `object` attribute on its points.
    pub objects: Vec<TruthObject>,
}

/// `synth --scene`: `count` generated streets (`street_NNNNN.las`, z up, UTM-sized coordinates,
/// classified, each point's object in the `object` attribute) with their truth beside them
/// (`street_NNNNN.json`). Street `k` of a run with `seed` depends on these two alone.
pub fn generate_streets(
    out: &Path,
    count: usize,
    seed: u64,
    params: &StreetParams,
    progress: &dyn Progress,
) -> Result<Vec<PathBuf>, SynthError> {
    if out.exists() && !out.is_dir() {
        return Err(SynthError::NotADirectory(out.to_path_buf()));
    }
    if !(10.0..=1000.0).contains(&params.length) {
        return Err(SynthError::Length(params.length));
    }
    create_dir(out)?;
    progress.start(count, "streets");
    let written = (0..count)
        .into_par_iter()
        .map(|k| {
            let street_seed = derive_seed(seed, &format!("street/{k}"));
            let scene = street(street_seed, params);
            let path = out.join(format!("street_{k:05}.las"));
            write_cloud(&path, &scene.cloud, None, Encoding::Binary)?;
            let kinds = [
                Kind::Ground,
                Kind::Building,
                Kind::Pole,
                Kind::Bin,
                Kind::Bush,
                Kind::Hedge,
                Kind::Vehicle,
            ];
            let truth = StreetTruth {
                mvpcc_version: env!("CARGO_PKG_VERSION").to_string(),
                seed: street_seed,
                params: *params,
                classes: kinds.iter().map(|&k| (k, k.class())).collect(),
                objects: scene.objects,
            };
            write_json(&path.with_extension("json"), &truth)?;
            progress.done(&path.display().to_string());
            Ok(path)
        })
        .collect::<Result<Vec<_>, SynthError>>()?;
    progress.finish();
    Ok(written)
}

/// `synth.json`: how a mesh directory was generated.
#[derive(Debug, Serialize, Deserialize, PartialEq)]
pub struct SynthManifest {
    pub mvpcc_version: String,
    pub seed: u64,
    pub categories: Vec<Category>,
    /// How often each of `categories` was drawn, relative to the others; absent from manifests
    /// written before weights could be given, whose categories had their default weights.
    #[serde(default)]
    pub weights: Vec<f64>,
    pub objects: Vec<SynthEntry>,
}

impl SynthManifest {
    fn draws(&self) -> Vec<Draw> {
        if self.weights.len() != self.categories.len() {
            return self.categories.iter().map(|&c| c.into()).collect();
        }
        let pairs = self.categories.iter().zip(&self.weights);
        pairs
            .map(|(&category, &weight)| Draw { category, weight })
            .collect()
    }
}

#[derive(Debug, Serialize, Deserialize, PartialEq)]
pub struct SynthEntry {
    /// Generation index: with the run's seed and draws it gives the object back.
    pub index: usize,
    pub name: String,
    pub category: Category,
    pub variant: String,
    pub seed: u64,
    pub path: PathBuf,
    pub triangles: usize,
}

/// What a generation did.
#[derive(Debug)]
pub struct Generated {
    pub manifest: SynthManifest,
    /// The folder already held exactly this run, so nothing was written.
    pub already: bool,
    pub seconds: f64,
    pub preview: Option<PathBuf>,
}

/// Refuses an object count outside 1..=[`MAX_OBJECTS`], naming the option it came from.
pub fn check_count(count: usize, option: &'static str) -> Result<(), SynthError> {
    if !(1..=MAX_OBJECTS).contains(&count) {
        return Err(SynthError::Count { option, count });
    }
    Ok(())
}

/// Writes `count` objects drawn from `draws` with `seed` into `out` (skipping the work when
/// `out` already holds exactly this run), and with `preview` their contact sheet.
pub fn generate(
    out: &Path,
    count: usize,
    draws: &[Draw],
    seed: u64,
    preview: bool,
    progress: &dyn Progress,
) -> Result<Generated, SynthError> {
    if out.exists() && !out.is_dir() {
        return Err(SynthError::NotADirectory(out.to_path_buf()));
    }
    check_draws(draws)?;
    let manifest_path = out.join(SYNTH_FILE);
    let started = std::time::Instant::now();
    let (manifest, already) = match already_generated(&manifest_path, count, draws, seed) {
        Some(done) => (done, true),
        None => (write_objects(out, count, draws, seed, progress)?, false),
    };
    if !already {
        write_json(&manifest_path, &manifest)?;
    }
    let preview = if preview {
        Some(write_preview(out, &manifest)?)
    } else {
        None
    };
    Ok(Generated {
        manifest,
        already,
        seconds: started.elapsed().as_secs_f64(),
        preview,
    })
}

fn write_objects(
    out: &Path,
    count: usize,
    draws: &[Draw],
    seed: u64,
    progress: &dyn Progress,
) -> Result<SynthManifest, SynthError> {
    create_dir(out)?;
    progress.start(count, "synth");
    let objects = (0..count)
        .into_par_iter()
        .map(|i| {
            let entry = write_object(out, i, seed, draws)?;
            progress.done(&entry.name);
            Ok(entry)
        })
        .collect::<Result<Vec<_>, SynthError>>()?;
    progress.finish();
    Ok(SynthManifest {
        mvpcc_version: env!("CARGO_PKG_VERSION").to_string(),
        seed,
        categories: draws.iter().map(|d| d.category).collect(),
        weights: draws.iter().map(|d| d.weight).collect(),
        objects,
    })
}

/// Refuses a category given twice: which of its weights was meant is not known.
fn check_draws(draws: &[Draw]) -> Result<(), SynthError> {
    for (i, d) in draws.iter().enumerate() {
        if draws[..i].iter().any(|e| e.category == d.category) {
            return Err(SynthError::CategoryTwice(d.category.name()));
        }
    }
    Ok(())
}

/// The manifest at `path` when it records exactly this run: `count` objects from `draws`
/// with `seed`.
fn already_generated(
    path: &Path,
    count: usize,
    draws: &[Draw],
    seed: u64,
) -> Option<SynthManifest> {
    let text = std::fs::read_to_string(path).ok()?;
    let done = serde_json::from_str::<SynthManifest>(&text).ok()?;
    (done.seed == seed && done.draws() == draws && done.objects.len() == count).then_some(done)
}

/// Synthesizes object `index` of the run and writes it to OUT/CATEGORY/NAME.obj.
fn write_object(
    out: &Path,
    index: usize,
    seed: u64,
    draws: &[Draw],
) -> Result<SynthEntry, SynthError> {
    let s = synthesize(index, seed, draws);
    let dir = out.join(s.category.name());
    create_dir(&dir)?;
    let path = dir.join(format!("{}.obj", s.name));
    write_obj(&path, &s.mesh).map_err(PathError::write(&path))?;
    Ok(SynthEntry {
        index,
        name: s.name,
        category: s.category,
        variant: s.variant,
        seed: s.seed,
        path: path.strip_prefix(out).unwrap_or(&path).to_path_buf(),
        triangles: s.mesh.triangles.len(),
    })
}

/// The contact sheet of the first objects as `OUT/preview.png`; its path.
fn write_preview(out: &Path, manifest: &SynthManifest) -> Result<PathBuf, SynthError> {
    let meshes: Vec<Mesh> = manifest
        .objects
        .iter()
        .take(PREVIEW_OBJECTS)
        .map(|o| synthesize(o.index, manifest.seed, &manifest.draws()).mesh)
        .collect();
    let refs: Vec<&Mesh> = meshes.iter().collect();
    let sheet = contact_sheet(&refs, 192, 4);
    let path = out.join("preview.png");
    atomic_write(&path, |w| {
        sheet
            .write_to(w, image::ImageFormat::Png)
            .map_err(std::io::Error::other)
    })
    .map_err(PathError::write(&path))?;
    Ok(path)
}
