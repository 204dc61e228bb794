//! One mesh → ground truth, partial samples, their view images and clouds.

use super::{
    coarse, split_of, CloudPolicy, Layout, ModelEntry, PrepareParams, SampleEntry, Source,
    ViewsFrame, DONE_FILE, GT_COARSE, GT_FINE, TEST,
};
use crate::core::camera::{Camera, CameraError};
use crate::core::cloud::PointCloud;
use crate::core::rng::{derive_seed, Lcg};
use crate::datagen::mesh::{
    read_mesh, Forward, Mesh, MeshError, MeshStats, ReadOptions, SignedAxis,
};
use crate::datagen::raster::{render_views, Surface};
use crate::datagen::scan::{ground_truth, partial};
use crate::io::{atomic_write, write_cloud, CloudIoError, Encoding, Format};
use crate::views::projection::project;
use crate::views::{write_views, ViewError};
use rayon::prelude::*;
use std::path::{Path, PathBuf};
use thiserror::Error;

#[derive(Debug, Error)]
pub enum PrepareError {
    /// The mesh itself is unusable: reported and skipped.
    #[error(transparent)]
    Mesh(#[from] MeshError),
    #[error("{}: {problem}", path.display())]
    Normalize { path: PathBuf, problem: String },
    /// Writing failed: the run stops, since the next model would fail the same way.
    #[error("{}: {source}", path.display())]
    Write {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error(transparent)]
    Views(#[from] ViewError),
    #[error(transparent)]
    Cloud(#[from] CloudIoError),
}

impl PrepareError {
    /// Whether the problem lies in the input file (skip it) rather than in the output.
    pub fn is_input_problem(&self) -> bool {
        matches!(self, PrepareError::Mesh(_) | PrepareError::Normalize { .. })
    }
}

fn cloud_of(surface: Surface) -> PointCloud {
    let mut cloud =
        PointCloud::from_positions(surface.points.iter().map(|p| p.map(|c| c as f64)).collect());
    cloud.colors = Some(surface.colors);
    cloud
}

fn create_dir(path: &Path) -> Result<(), PrepareError> {
    std::fs::create_dir_all(path).map_err(|source| PrepareError::Write {
        path: path.to_path_buf(),
        source,
    })
}

/// A finished model's entry, read from its done marker; `None` when the model is not done.
pub fn finished(layout: &Layout, source: &Source, params: &PrepareParams) -> Option<ModelEntry> {
    let split = split_of(&source.category, &source.name, params.train_fraction);
    let marker = layout
        .clouds(split, &source.category, &source.name)
        .join(DONE_FILE);
    let text = std::fs::read_to_string(marker).ok()?;
    serde_json::from_str(&text).ok()
}

/// Removes whatever an interrupted run left of a model.
fn clear(layout: &Layout, split: &str, source: &Source) -> Result<(), PrepareError> {
    for dir in [
        layout.gt_views(split, &source.category, &source.name),
        layout.inputs(split, &source.category, &source.name),
        layout.clouds(split, &source.category, &source.name),
    ] {
        if dir.exists() {
            std::fs::remove_dir_all(&dir).map_err(|source| PrepareError::Write {
                path: dir.clone(),
                source,
            })?;
        }
    }
    Ok(())
}

/// Prepares one model: normalizes the mesh, samples its ground truth, scans `samples`
/// partials, writes every view pair and cloud, and finally the done marker.
pub fn prepare_model(
    source: &Source,
    params: &PrepareParams,
    layout: &Layout,
) -> Result<ModelEntry, PrepareError> {
    let split = split_of(&source.category, &source.name, params.train_fraction);
    // Whatever an interrupted run left goes first, so a mesh that now fails leaves nothing.
    clear(layout, split, source)?;
    let path = &source.path;
    let (mesh, stats, scale) = normalized_mesh(path, params)?;
    let seed = derive_seed(params.seed, &format!("{}/{}", source.category, source.name));
    let camera_error = |e: CameraError| PrepareError::Normalize {
        path: path.clone(),
        problem: e.to_string(),
    };
    let cameras = Camera::set(&params.views, params.size).map_err(camera_error)?;

    let gt = ground_truth(&mesh, params.gt_size, params.gt_voxel).map_err(camera_error)?;
    let gt_dir = layout.gt_views(split, &source.category, &source.name);
    create_dir(&gt_dir)?;
    write_views(&gt_dir, &render_views(&mesh, &cameras))?;

    let clouds_dir = layout.clouds(split, &source.category, &source.name);
    create_dir(&clouds_dir)?;
    let keep_partials = keeps_partials(params.clouds, split);
    let samples = (1..=params.samples)
        .into_par_iter()
        .map(|k| {
            let sample_seed = derive_seed(seed, &k.to_string());
            let views_dir = layout.input_views(split, &source.category, &source.name, k);
            let cloud = keep_partials.then(|| clouds_dir.join(format!("partial_{k}.ply")));
            let sample = Sample {
                k,
                seed: sample_seed,
                views_dir: &views_dir,
                cloud: cloud.as_deref(),
            };
            write_sample(&mesh, params, &cameras, sample)
        })
        .collect::<Result<Vec<_>, PrepareError>>()?;
    let gt_points = gt.len();
    write_ground_truth(&clouds_dir, cloud_of(gt), keep_partials)?;
    let entry = ModelEntry {
        category: source.category.clone(),
        name: source.name.clone(),
        split: split.to_string(),
        source: source.path.clone(),
        seed,
        source_scale: 1.0 / scale,
        mesh: stats,
        gt_points,
        samples,
    };
    write_done(&clouds_dir, &entry)?;
    Ok(entry)
}

/// Whether `policy` writes the partial clouds of a model in `split`.
fn keeps_partials(policy: CloudPolicy, split: &str) -> bool {
    match policy {
        CloudPolicy::All => true,
        CloudPolicy::Test => split == TEST,
        CloudPolicy::Gt => false,
    }
}

/// The done marker, written last: a model whose folder has it is finished (a resumed run
/// skips it).
fn write_done(clouds_dir: &Path, entry: &ModelEntry) -> Result<(), PrepareError> {
    let marker = clouds_dir.join(DONE_FILE);
    atomic_write(&marker, |w| {
        serde_json::to_writer_pretty(&mut *w, entry).map_err(std::io::Error::other)
    })
    .map_err(|source| PrepareError::Write {
        path: marker,
        source,
    })
}

/// The mesh at `path`, checked and turned into the normalized pose `params` asks for; its
/// statistics and the scale it was shrunk by.
fn normalized_mesh(
    path: &Path,
    params: &PrepareParams,
) -> Result<(Mesh, MeshStats, f32), PrepareError> {
    let normalize_error = |problem| PrepareError::Normalize {
        path: path.to_path_buf(),
        problem,
    };
    let mut mesh = read_mesh(
        path,
        ReadOptions {
            allow_missing_materials: params.allow_missing_materials,
        },
    )?;
    let stats = mesh.check(path, params.max_triangles)?;
    let up: SignedAxis = params.up.parse().map_err(normalize_error)?;
    let forward: Forward = params.forward.parse().map_err(normalize_error)?;
    let forward = forward.resolve(&mesh, up);
    let scale = mesh.normalize(up, forward).map_err(normalize_error)?;
    Ok((mesh, stats, scale))
}

/// Where one partial sample goes: its number `k`, its seed, its views' directory and, when
/// kept, its cloud's file.
struct Sample<'a> {
    k: usize,
    seed: u64,
    views_dir: &'a Path,
    cloud: Option<&'a Path>,
}

/// Scans one partial of `mesh` and writes its views (in the frame `params` asks for) and,
/// where asked, its cloud.
fn write_sample(
    mesh: &Mesh,
    params: &PrepareParams,
    cameras: &[Camera],
    sample: Sample,
) -> Result<SampleEntry, PrepareError> {
    let mut rng = Lcg::new(sample.seed);
    // Samples are numbered from 1; the first single-camera sample is the front camera.
    let (spec, surface) = partial(mesh, &params.partial, sample.k - 1, &mut rng);
    create_dir(sample.views_dir)?;
    let views = match params.views_frame {
        ViewsFrame::Path => project(&surface.points, Some(&surface.colors), cameras),
        ViewsFrame::Object => {
            let aligned: Vec<[f32; 3]> = surface
                .points
                .iter()
                .map(|&p| spec.to_object_frame(p))
                .collect();
            project(&aligned, Some(&surface.colors), cameras)
        }
    };
    write_views(sample.views_dir, &views)?;
    let points = surface.len();
    if let Some(path) = sample.cloud {
        write_cloud(
            path,
            &cloud_of(surface),
            Some(Format::Ply),
            Encoding::Binary,
        )?;
    }
    Ok(SampleEntry {
        k: sample.k,
        seed: sample.seed,
        points,
        spec,
    })
}

/// Writes the fine ground truth and, beside kept partials (the ones `eval` scores), the
/// coarse one: its sampling is quadratic, so not for models nobody scores.
fn write_ground_truth(dir: &Path, gt: PointCloud, with_coarse: bool) -> Result<(), PrepareError> {
    write_cloud(&dir.join(GT_FINE), &gt, Some(Format::Ply), Encoding::Binary)?;
    if with_coarse {
        write_cloud(
            &dir.join(GT_COARSE),
            &coarse(&gt),
            Some(Format::Ply),
            Encoding::Binary,
        )?;
    }
    Ok(())
}
