//! Training data in the original dataset's layout ("shapenet-views"), made from meshes:
//! [`discover`] finds and names the meshes, [`prepare_model`] turns one into ground truth, partial
//! samples and their view images, and [`Manifest`] records what was made and how.

mod prepare;

pub use prepare::{finished, prepare_model, PrepareError};

use crate::core::cloud::PointCloud;
use crate::core::rng::derive_seed;
use crate::datagen::mesh::{MeshStats, MESH_EXTENSIONS};
use crate::datagen::scan::{PartialParams, PartialSpec};
use crate::io::batch::{walk, BatchError};
use crate::metrics::{farthest_point_sample, COARSE_POINTS};
use serde::{Deserialize, Serialize};
use std::collections::hash_map::Entry;
use std::collections::HashMap;
use std::path::{Path, PathBuf};

pub const TRAIN: &str = "train";
pub const TEST: &str = "test";
/// Written into a model's cloud directory last; a model without it is redone.
pub const DONE_FILE: &str = "done.json";
/// The ground truth beside a model's partials: every point the rig saw, one per voxel.
pub const GT_FINE: &str = "gt.ply";
/// The paper's coarse ground truth: [`crate::metrics::COARSE_POINTS`] of the fine one by
/// farthest point sampling.
pub const GT_COARSE: &str = "gt_coarse.ply";

/// The coarse ground truth of a fine one (see [`GT_COARSE`]).
pub fn coarse(fine: &PointCloud) -> PointCloud {
    fine.select(&farthest_point_sample(&fine.positions, COARSE_POINTS))
}
pub const MANIFEST_FILE: &str = "manifest.json";
/// The parameters a data directory was started with, so a resumed run cannot mix settings.
pub const PARAMS_FILE: &str = "prepare.json";

/// Paths of one data directory.
#[derive(Debug, Clone)]
pub struct Layout {
    pub root: PathBuf,
}

impl Layout {
    pub fn gt_views(&self, split: &str, category: &str, name: &str) -> PathBuf {
        self.root.join("GT").join(split).join(category).join(name)
    }

    /// Sample `k` (1-based, as the original names them).
    pub fn input_views(&self, split: &str, category: &str, name: &str, k: usize) -> PathBuf {
        self.inputs(split, category, name).join(k.to_string())
    }

    pub fn inputs(&self, split: &str, category: &str, name: &str) -> PathBuf {
        self.root.join("in").join(split).join(category).join(name)
    }

    /// `gt.ply`, `partial_k.ply` and the model's done marker.
    pub fn clouds(&self, split: &str, category: &str, name: &str) -> PathBuf {
        self.root
            .join("clouds")
            .join(split)
            .join(category)
            .join(name)
    }
}

/// A mesh file and the names it gets in the dataset.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Source {
    pub path: PathBuf,
    pub category: String,
    pub name: String,
}

/// A file `prepare` did not use, and why.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Skipped {
    pub path: PathBuf,
    pub problem: String,
}

/// File stems that name a format rather than a model (ShapeNet v1 `model.obj`, v2
/// `models/model_normalized.obj`): such a model is named after its directory.
const GENERIC_STEMS: [&str; 3] = ["model", "model_normalized", "mesh"];

/// Finds meshes under `dir` (recursively, in sorted order, hidden entries skipped) and names
/// them: `DIR/<category>/<name>.obj`, ShapeNet's `DIR/<synset>/<id>/models/model_normalized.obj`
/// (or, given a synset folder, `DIR/<id>/models/…` with DIR's name as the category). Two files
/// that would get the same category and name keep the first.
pub fn discover(dir: &Path) -> Result<(Vec<Source>, Vec<Skipped>), BatchError> {
    let files: Vec<PathBuf> = walk(dir, |path| {
        path.extension()
            .and_then(|e| e.to_str())
            .is_some_and(|e| MESH_EXTENSIONS.contains(&e.to_ascii_lowercase().as_str()))
    })?
    .into_iter()
    .map(|relative| dir.join(relative))
    .collect();
    let root_name = dir
        .canonicalize()
        .ok()
        .and_then(|d| d.file_name().map(|n| n.to_string_lossy().into_owned()))
        .unwrap_or_else(|| "objects".to_string());
    let mut sources: Vec<Source> = Vec::new();
    let mut skipped = Vec::new();
    // Each (category, name) pair and the source that took it first.
    let mut taken: HashMap<(String, String), usize> = HashMap::new();
    for path in files {
        let (category, name) = category_and_name(dir, &path, &root_name);
        match taken.entry((category, name)) {
            Entry::Occupied(first) => {
                let (category, name) = first.key();
                skipped.push(Skipped {
                    problem: format!(
                        "same category and name ({category}/{name}) as {}",
                        sources[*first.get()].path.display()
                    ),
                    path,
                });
            }
            Entry::Vacant(slot) => {
                let (category, name) = slot.key().clone();
                slot.insert(sources.len());
                sources.push(Source {
                    path,
                    category,
                    name,
                });
            }
        }
    }
    Ok((sources, skipped))
}

/// The category and name of the mesh at `path` under `dir` (see [`discover`]); `root_name`
/// is the category of meshes lying directly in `dir`.
fn category_and_name(dir: &Path, path: &Path, root_name: &str) -> (String, String) {
    let rel: Vec<String> = path
        .strip_prefix(dir)
        .unwrap_or(path)
        .components()
        .map(|c| c.as_os_str().to_string_lossy().into_owned())
        .collect();
    let stem = path
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    // Index (in `rel`) of the component that names the model.
    let mut name_at = rel.len() - 1;
    if GENERIC_STEMS.contains(&stem.as_str()) && name_at > 0 {
        name_at -= 1;
        if rel[name_at] == "models" && name_at > 0 {
            name_at -= 1;
        }
    }
    let name = if name_at == rel.len() - 1 {
        stem
    } else {
        rel[name_at].clone()
    };
    let category = if name_at > 0 {
        rel[0].clone()
    } else {
        root_name.to_string()
    };
    (category, name)
}

/// The split of a model: a hash of its category and name, so it does not depend on the seed,
/// on which other models exist, or on the order they are processed in.
pub fn split_of(category: &str, name: &str, train_fraction: f64) -> &'static str {
    let h = derive_seed(0, &format!("{category}/{name}"));
    if ((h >> 11) as f64 / (1u64 << 53) as f64) < train_fraction {
        TRAIN
    } else {
        TEST
    }
}

/// Which splits get their partial clouds written as PLY besides their view images.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum CloudPolicy {
    /// Every partial of every model.
    All,
    /// Partials of the test split, which `mvpcc eval` scores; `gt.ply` for every model.
    Test,
    /// Only `gt.ply`.
    Gt,
}

/// The most partial samples `prepare` makes of one model, fifty times the default: each is a
/// scan and its views on disk, and a mistyped count would write until the disk is full.
pub const MAX_SAMPLES: usize = 1000;

/// Everything that determines a data directory's content.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PrepareParams {
    pub views: Vec<usize>,
    pub size: usize,
    pub gt_size: usize,
    pub gt_voxel: f32,
    pub samples: usize,
    pub train_fraction: f64,
    pub partial: PartialParams,
    pub up: String,
    pub forward: String,
    pub seed: u64,
    pub clouds: CloudPolicy,
    pub allow_missing_materials: bool,
    pub max_triangles: usize,
    /// The frame of the scanner partials' views; absent (the path's) in directories made
    /// before 2026-12-02.
    #[serde(default)]
    pub views_frame: ViewsFrame,
}

/// Where a scanner partial's views are drawn. `complete` turns a scan onto its estimated
/// heading before the network sees it, so the network learns from views in the object's frame,
/// aligned with the ground truth's; views in the path's frame, turned by up to the yaw error
/// against the ground truth's, asked the network to undo a turn it cannot see.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ViewsFrame {
    #[default]
    Path,
    Object,
}

/// One partial sample of a model.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SampleEntry {
    pub k: usize,
    pub seed: u64,
    pub points: usize,
    pub spec: PartialSpec,
}

/// One prepared model.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ModelEntry {
    pub category: String,
    pub name: String,
    pub split: String,
    pub source: PathBuf,
    pub seed: u64,
    /// Mesh units per normalized unit (the longest side of the mesh's box).
    pub source_scale: f32,
    pub mesh: MeshStats,
    pub gt_points: usize,
    pub samples: Vec<SampleEntry>,
}

/// `manifest.json`: what a data directory holds and every setting and seed it was made with.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Manifest {
    pub mvpcc_version: String,
    pub params: PrepareParams,
    pub models: Vec<ModelEntry>,
    pub skipped: Vec<Skipped>,
}

#[cfg(test)]
mod tests {
    use super::*;

    fn touch(path: &Path) {
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        std::fs::write(path, "").unwrap();
    }

    #[test]
    fn discovery_names_flat_and_shapenet_layouts() {
        let dir = tempfile::tempdir().unwrap();
        let root = dir.path().join("02958343");
        touch(&root.join("abc/models/model_normalized.obj"));
        touch(&root.join("abc/models/model_normalized.mtl"));
        touch(&root.join("def/model.obj"));
        touch(&root.join("car/xyz.glb"));
        touch(&root.join("car/xyz.ply"));
        touch(&root.join("loose.PLY"));
        touch(&root.join(".hidden/h.obj"));
        let (sources, skipped) = discover(&root).unwrap();
        let named: Vec<(&str, &str)> = sources
            .iter()
            .map(|s| (s.category.as_str(), s.name.as_str()))
            .collect();
        assert_eq!(
            named,
            vec![
                ("02958343", "abc"),
                ("car", "xyz"),
                ("02958343", "def"),
                ("02958343", "loose")
            ]
        );
        assert_eq!(skipped.len(), 1);
        assert!(skipped[0].path.ends_with("car/xyz.ply"));
        // From ShapeNetCore's root the synset folder is the category.
        let (sources, _) = discover(dir.path()).unwrap();
        assert_eq!(sources[0].category, "02958343");
        assert_eq!(sources[0].name, "abc");
    }

    #[test]
    fn splits_follow_the_fraction_and_are_stable() {
        let names: Vec<String> = (0..2000).map(|i| format!("m{i}")).collect();
        let train = names
            .iter()
            .filter(|n| split_of("car", n, 0.93) == TRAIN)
            .count();
        assert!((1800..1920).contains(&train), "{train}");
        assert_eq!(split_of("car", "m1", 0.93), split_of("car", "m1", 0.93));
        assert_eq!(split_of("car", "m1", 1.0), TRAIN);
        assert_eq!(split_of("car", "m1", 0.0), TEST);
    }
}
