use super::Log;
use crate::cli::args::SynthArgs;
use anyhow::{bail, Context};
use mvpcc::datagen::mesh::{write_obj, Mesh};
use mvpcc::datagen::synth::{contact_sheet, synthesize, Category, Draw, MAX_OBJECTS};
use mvpcc::io::atomic_write;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

pub(super) const SYNTH_FILE: &str = "synth.json";
const PREVIEW_OBJECTS: usize = 16;

/// `synth.json`: how a mesh directory was generated.
#[derive(Debug, Serialize, Deserialize, PartialEq)]
pub(super) struct SynthManifest {
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
pub(super) struct SynthEntry {
    /// Generation index: with the run's seed and draws it gives the object back.
    pub index: usize,
    pub name: String,
    pub category: Category,
    pub variant: String,
    pub seed: u64,
    pub path: PathBuf,
    pub triangles: usize,
}

pub(super) fn run(args: SynthArgs, log: Log) -> anyhow::Result<()> {
    check_count(args.count, "--count")?;
    generate(
        &args.out,
        args.count,
        &args.synth_options.category,
        args.synth_options.seed,
        args.preview,
        log,
    )?;
    Ok(())
}

/// Refuses an object count outside 1..=[`MAX_OBJECTS`], naming the option it came from.
pub(super) fn check_count(count: usize, option: &str) -> anyhow::Result<()> {
    if !(1..=MAX_OBJECTS).contains(&count) {
        bail!("{option} must lie in 1..={MAX_OBJECTS}, got {count}");
    }
    Ok(())
}

/// Writes `count` objects into `out` (skipping the work when `out` already holds exactly this
/// run) and returns its manifest.
pub(super) fn generate(
    out: &Path,
    count: usize,
    draws: &[Draw],
    seed: u64,
    preview: bool,
    log: Log,
) -> anyhow::Result<SynthManifest> {
    super::check_out_dir(out)?;
    check_draws(draws)?;
    let manifest_path = out.join(SYNTH_FILE);
    if let Some(done) = already_generated(&manifest_path, count, draws, seed) {
        log.info(format!(
            "{}: {count} objects already generated",
            out.display()
        ));
        if preview {
            write_preview(out, &done, log)?;
        }
        return Ok(done);
    }
    std::fs::create_dir_all(out).with_context(|| format!("{}: cannot create", out.display()))?;
    let bar = super::progress(count, "synth", log);
    let started = std::time::Instant::now();
    let objects = (0..count)
        .into_par_iter()
        .map(|i| {
            let entry = write_object(out, i, seed, draws)?;
            bar.inc(1);
            Ok(entry)
        })
        .collect::<anyhow::Result<Vec<_>>>()?;
    bar.finish_and_clear();
    let manifest = SynthManifest {
        mvpcc_version: env!("CARGO_PKG_VERSION").to_string(),
        seed,
        categories: draws.iter().map(|d| d.category).collect(),
        weights: draws.iter().map(|d| d.weight).collect(),
        objects,
    };
    atomic_write(&manifest_path, |w| {
        serde_json::to_writer_pretty(&mut *w, &manifest).map_err(std::io::Error::other)
    })
    .with_context(|| format!("{}: cannot write", manifest_path.display()))?;
    log.info(format!(
        "wrote {count} objects to {} in {:.1} s",
        out.display(),
        started.elapsed().as_secs_f64()
    ));
    if preview {
        write_preview(out, &manifest, log)?;
    }
    Ok(manifest)
}

/// Refuses a category given twice: which of its weights was meant is not known.
fn check_draws(draws: &[Draw]) -> anyhow::Result<()> {
    for (i, d) in draws.iter().enumerate() {
        if draws[..i].iter().any(|e| e.category == d.category) {
            bail!("--category: {} given twice", d.category.name());
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
fn write_object(out: &Path, index: usize, seed: u64, draws: &[Draw]) -> anyhow::Result<SynthEntry> {
    let s = synthesize(index, seed, draws);
    let dir = out.join(s.category.name());
    std::fs::create_dir_all(&dir).with_context(|| format!("{}: cannot create", dir.display()))?;
    let path = dir.join(format!("{}.obj", s.name));
    write_obj(&path, &s.mesh).with_context(|| format!("{}: cannot write", path.display()))?;
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

fn write_preview(out: &Path, manifest: &SynthManifest, log: Log) -> anyhow::Result<()> {
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
    .with_context(|| format!("{}: cannot write", path.display()))?;
    log.info(format!("preview: {}", path.display()));
    Ok(())
}
