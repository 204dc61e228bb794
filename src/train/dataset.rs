//! Training samples from a "shapenet-views" directory: every model of `GT/<split>` paired with
//! each of its partial samples `in/<split>/<category>/<model>/<k>`, decoded once into compact
//! occupied-pixel lists (cached within a memory budget) and rendered at the model's image size,
//! optionally through a geometric augmentation.

use crate::core::camera::Camera;
use crate::core::rng::{derive_seed, Lcg};
use crate::datagen::data::GT_FINE;
use crate::io::read_cloud;
use crate::views::projection::{project, ViewImages, CHANNELS};
use crate::views::{read_views, ViewError};
use serde::{Deserialize, Serialize};
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use thiserror::Error;

#[derive(Debug, Error)]
pub enum DataError {
    #[error("{}: not a shapenet-views directory (no GT/{split} folder)", root.display())]
    NotViews { root: PathBuf, split: String },
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{}: no model of GT/{split} has partial samples under in/{split}", root.display())]
    Empty { root: PathBuf, split: String },
    #[error(transparent)]
    View(#[from] ViewError),
    #[error("{}: views are {found}×{found} pixels, the others {expected}×{expected}", path.display())]
    MixedSizes {
        path: PathBuf,
        found: usize,
        expected: usize,
    },
}

/// One training pair: a model's ground-truth views and one partial sample's views.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct SampleRef {
    pub category: String,
    pub name: String,
    /// The sample folder's name (`1`, `2`, … in the original).
    pub sample: String,
    pub gt: PathBuf,
    pub input: PathBuf,
    /// `clouds/<split>/<category>/<model>` when `prepare` wrote the model's `gt.ply` there.
    pub clouds: Option<PathBuf>,
}

impl SampleRef {
    pub fn label(&self) -> String {
        format!("{}/{}/{}", self.category, self.name, self.sample)
    }
}

fn sorted_dirs(path: &Path) -> Result<Vec<String>, DataError> {
    let entries = std::fs::read_dir(path).map_err(|source| DataError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let mut names = Vec::new();
    for entry in entries {
        let entry = entry.map_err(|source| DataError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        let name = entry.file_name().to_string_lossy().into_owned();
        if !name.starts_with('.') && entry.path().is_dir() {
            names.push(name);
        }
    }
    // Numeric sample folders in numeric order (2 before 10), everything else by name.
    names.sort_by(|a, b| match (a.parse::<u64>(), b.parse::<u64>()) {
        (Ok(x), Ok(y)) => x.cmp(&y),
        _ => a.cmp(b),
    });
    Ok(names)
}

/// What [`scan_split`] found.
#[derive(Debug, Clone, PartialEq)]
pub struct Split {
    pub samples: Vec<SampleRef>,
    pub models: usize,
    /// Models with ground truth but no partial sample folder.
    pub without_samples: usize,
}

/// Every (model, sample) pair of `root/GT/<split>`, in a fixed order.
pub fn scan_split(root: &Path, split: &str) -> Result<Split, DataError> {
    let gt_root = root.join("GT").join(split);
    if !gt_root.is_dir() {
        return Err(DataError::NotViews {
            root: root.to_path_buf(),
            split: split.to_string(),
        });
    }
    let mut out = Split {
        samples: Vec::new(),
        models: 0,
        without_samples: 0,
    };
    for category in sorted_dirs(&gt_root)? {
        for name in sorted_dirs(&gt_root.join(&category))? {
            out.models += 1;
            let gt = gt_root.join(&category).join(&name);
            let inputs = root.join("in").join(split).join(&category).join(&name);
            let samples = if inputs.is_dir() {
                sorted_dirs(&inputs)?
            } else {
                Vec::new()
            };
            if samples.is_empty() {
                out.without_samples += 1;
                continue;
            }
            let clouds = root.join("clouds").join(split).join(&category).join(&name);
            let clouds = clouds.join(GT_FINE).is_file().then_some(clouds);
            for sample in samples {
                out.samples.push(SampleRef {
                    category: category.clone(),
                    name: name.clone(),
                    input: inputs.join(&sample),
                    sample,
                    gt: gt.clone(),
                    clouds: clouds.clone(),
                });
            }
        }
    }
    if out.samples.is_empty() {
        return Err(DataError::Empty {
            root: root.to_path_buf(),
            split: split.to_string(),
        });
    }
    Ok(out)
}

/// Splits `samples` by model into (training, held back), holding back about `fraction` of the
/// models by a hash of their name, so a model's samples never straddle the two.
pub fn hold_back(samples: Vec<SampleRef>, fraction: f64) -> (Vec<SampleRef>, Vec<SampleRef>) {
    samples.into_iter().partition(|s| {
        let h = derive_seed(0, &format!("validation {}/{}", s.category, s.name));
        (h >> 11) as f64 / (1u64 << 53) as f64 >= fraction
    })
}

/// An occupied pixel of a view image.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pixel {
    pub at: u32,
    pub xyz: [f32; 3],
    pub rgb: [u8; 3],
}

/// The occupied pixels of each view of one view folder: a few times smaller than the images.
#[derive(Debug, Clone, PartialEq)]
pub struct Decoded {
    pub size: usize,
    pub cameras: Vec<usize>,
    pub has_color: bool,
    pub views: Vec<Vec<Pixel>>,
}

impl Decoded {
    pub fn from_images(images: &ViewImages) -> Decoded {
        let plane = images.size * images.size;
        let views = (0..images.views())
            .map(|v| {
                let px = images.view_pixels(v);
                let color = |x: f32| (x * 255.0).round().clamp(0.0, 255.0) as u8;
                images
                    .view_occupancy(v)
                    .iter()
                    .enumerate()
                    .filter(|(_, &o)| o)
                    .map(|(at, _)| Pixel {
                        at: at as u32,
                        xyz: [0, 1, 2].map(|c| px[c * plane + at]),
                        rgb: [3, 4, 5].map(|c| color(px[c * plane + at])),
                    })
                    .collect()
            })
            .collect();
        Decoded {
            size: images.size,
            cameras: images.cameras.clone(),
            has_color: images.has_color,
            views,
        }
    }

    fn bytes(&self) -> usize {
        self.views.iter().map(Vec::len).sum::<usize>() * std::mem::size_of::<Pixel>()
    }

    /// Every view's points merged (points seen by several views appear once per view).
    pub fn points(&self) -> Vec<[f64; 3]> {
        self.views
            .iter()
            .flatten()
            .map(|p| p.xyz.map(f64::from))
            .collect()
    }

    /// The views as images again, at their own size.
    pub fn images(&self) -> ViewImages {
        let mut out = ViewImages::empty(self.cameras.clone(), self.size, self.has_color);
        let plane = self.size * self.size;
        for (v, pixels) in self.views.iter().enumerate() {
            for p in pixels {
                let at = p.at as usize;
                out.occupancy[v * plane + at] = true;
                let px = &mut out.pixels[v * CHANNELS * plane..(v + 1) * CHANNELS * plane];
                for c in 0..3 {
                    px[c * plane + at] = p.xyz[c];
                    if self.has_color {
                        px[(3 + c) * plane + at] = p.rgb[c] as f32 / 255.0;
                    }
                }
            }
        }
        out
    }
}

/// Geometric and colour augmentation of one drawn sample; the same transform applies to its
/// input and its ground truth.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Augment {
    /// Mirror x ↔ −x: vehicles are left-right symmetric, their scans are not.
    pub mirror: bool,
    /// Rotation about the up axis, degrees.
    pub yaw_deg: f32,
    /// Per-channel colour gain and a common offset.
    pub gain: [f32; 3],
    pub offset: f32,
}

impl Augment {
    pub const NONE: Augment = Augment {
        mirror: false,
        yaw_deg: 0.0,
        gain: [1.0; 3],
        offset: 0.0,
    };

    fn is_geometric(&self) -> bool {
        self.mirror || self.yaw_deg != 0.0
    }

    /// The point transform: mirror, then yaw.
    fn transform(&self) -> impl Fn([f32; 3]) -> [f32; 3] {
        let mirror = self.mirror;
        let (sin, cos) = self.yaw_deg.to_radians().sin_cos();
        move |p| {
            let x = if mirror { -p[0] } else { p[0] };
            [cos * x + sin * p[2], p[1], -sin * x + cos * p[2]]
        }
    }
}

/// How augmentations are drawn.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct AugmentSettings {
    pub mirror: bool,
    /// Largest yaw, degrees (uniform in ±this).
    pub max_yaw_deg: f32,
    /// Largest relative colour gain change (uniform in ±this per channel; offset ±half).
    pub color_jitter: f32,
}

impl AugmentSettings {
    pub fn draw(&self, rng: &mut Lcg) -> Augment {
        let jitter = self.color_jitter as f64;
        Augment {
            mirror: self.mirror && rng.chance(0.5),
            yaw_deg: rng.range(-1.0, 1.0) as f32 * self.max_yaw_deg,
            gain: [0; 3].map(|_| 1.0 + rng.range(-jitter, jitter) as f32),
            offset: rng.range(-jitter / 2.0, jitter / 2.0) as f32,
        }
    }
}

/// Renders decoded views into `cameras` (the model's image size). Without a geometric
/// transform each view keeps its own pixels (copied as they are at the same size, otherwise
/// re-projected with the depth test); with one, all views' points are transformed and every
/// camera sees their union, as a camera would see the moved object.
pub fn render(src: &Decoded, cameras: &[Camera], augment: &Augment) -> ViewImages {
    let size = cameras[0].size;
    let colors = |pixels: &[Pixel]| -> Vec<[u8; 3]> { pixels.iter().map(|p| p.rgb).collect() };
    let mut out = if !augment.is_geometric() && size == src.size {
        src.images()
    } else if !augment.is_geometric() {
        let mut out = ViewImages::empty(src.cameras.clone(), size, src.has_color);
        let n = CHANNELS * size * size;
        for (v, pixels) in src.views.iter().enumerate() {
            let points: Vec<[f32; 3]> = pixels.iter().map(|p| p.xyz).collect();
            let c = colors(pixels);
            let one = project(&points, Some(&c), std::slice::from_ref(&cameras[v]));
            out.pixels[v * n..(v + 1) * n].copy_from_slice(&one.pixels);
            out.occupancy[v * size * size..(v + 1) * size * size].copy_from_slice(&one.occupancy);
        }
        out
    } else {
        let all: Vec<Pixel> = src.views.iter().flatten().copied().collect();
        let transform = augment.transform();
        let points: Vec<[f32; 3]> = all.iter().map(|p| transform(p.xyz)).collect();
        let mut out = project(&points, Some(&colors(&all)), cameras);
        out.has_color = src.has_color;
        out
    };
    if !src.has_color {
        let plane = size * size;
        for v in 0..out.views() {
            out.pixels[(v * CHANNELS + 3) * plane..(v + 1) * CHANNELS * plane].fill(0.0);
        }
    } else if augment.gain != [1.0; 3] || augment.offset != 0.0 {
        jitter_colors(&mut out, augment);
    }
    out
}

fn jitter_colors(images: &mut ViewImages, augment: &Augment) {
    let plane = images.size * images.size;
    for v in 0..images.views() {
        for c in 0..3 {
            let start = (v * CHANNELS + 3 + c) * plane;
            let occupied = &images.occupancy[v * plane..(v + 1) * plane];
            for (x, &o) in images.pixels[start..start + plane].iter_mut().zip(occupied) {
                if o {
                    *x = (*x * augment.gain[c] + augment.offset).clamp(0.0, 1.0);
                }
            }
        }
    }
}

/// Decoded view folders kept in memory up to a byte budget; past it, folders are decoded
/// again each time they are drawn.
pub struct Cache {
    budget: usize,
    state: Mutex<(usize, HashMap<PathBuf, Arc<Decoded>>)>,
}

impl Cache {
    pub fn new(budget_bytes: usize) -> Cache {
        Cache {
            budget: budget_bytes,
            state: Mutex::new((0, HashMap::new())),
        }
    }

    /// Bytes held.
    pub fn used(&self) -> usize {
        self.state.lock().map_or(0, |s| s.0)
    }

    /// The views `cameras` of `dir`, all of one size.
    pub fn get(&self, dir: &Path, cameras: &[usize]) -> Result<Arc<Decoded>, DataError> {
        if let Some(hit) = self.state.lock().ok().and_then(|s| s.1.get(dir).cloned()) {
            return Ok(hit);
        }
        let decoded = Arc::new(Decoded::from_images(&read_views(dir, Some(cameras))?));
        if let Ok(mut state) = self.state.lock() {
            let bytes = decoded.bytes();
            if state.0 + bytes <= self.budget && !state.1.contains_key(dir) {
                state.0 += bytes;
                state.1.insert(dir.to_path_buf(), decoded.clone());
            }
        }
        Ok(decoded)
    }
}

/// A sample rendered for the network.
#[derive(Debug, Clone)]
pub struct Rendered {
    pub input: ViewImages,
    pub target: ViewImages,
}

/// Reads and renders one sample at the model's image size.
pub fn load_sample(
    sample: &SampleRef,
    cameras: &[Camera],
    augment: &Augment,
    cache: &Cache,
) -> Result<Rendered, DataError> {
    let indices: Vec<usize> = cameras.iter().map(|c| c.index).collect();
    let gt = cache.get(&sample.gt, &indices)?;
    let input = cache.get(&sample.input, &indices)?;
    Ok(Rendered {
        input: render(&input, cameras, augment),
        target: render(&gt, cameras, augment),
    })
}

/// The ground-truth cloud of a validation sample: `gt.ply` when `prepare` wrote one, else the
/// union of the ground-truth views' points.
pub fn gt_cloud(
    sample: &SampleRef,
    cache: &Cache,
    cameras: &[usize],
) -> Result<Vec<[f64; 3]>, DataError> {
    if let Some(dir) = &sample.clouds {
        let path = dir.join(GT_FINE);
        let loaded = read_cloud(&path, None).map_err(|e| DataError::Io {
            path: path.clone(),
            source: std::io::Error::other(e.to_string()),
        })?;
        return Ok(loaded.cloud.positions);
    }
    Ok(cache.get(&sample.gt, cameras)?.points())
}

/// The order samples are drawn in: a fresh shuffle per pass over the data, a pure function of
/// the seed, so a resumed run draws exactly what an uninterrupted one would.
pub struct DrawOrder {
    seed: u64,
    len: usize,
    epoch: Option<(u64, Vec<usize>)>,
}

impl DrawOrder {
    pub fn new(seed: u64, len: usize) -> DrawOrder {
        DrawOrder {
            seed,
            len,
            epoch: None,
        }
    }

    /// Sample index and augmentation RNG of draw `i`.
    pub fn draw(&mut self, i: u64) -> (usize, Lcg) {
        let epoch = i / self.len as u64;
        if self.epoch.as_ref().is_none_or(|(e, _)| *e != epoch) {
            let mut rng = Lcg::new(derive_seed(self.seed, &format!("epoch {epoch}")));
            let mut order: Vec<usize> = (0..self.len).collect();
            for k in (1..order.len()).rev() {
                order.swap(k, rng.below(k + 1));
            }
            self.epoch = Some((epoch, order));
        }
        let order = &self.epoch.as_ref().expect("set above").1;
        let index = order[(i % self.len as u64) as usize];
        (
            index,
            Lcg::new(derive_seed(self.seed, &format!("augment {i}"))),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::datagen::shapes::example_car_views;
    use crate::views::write_views;

    #[test]
    fn decoded_views_give_back_their_images() {
        let views = example_car_views(64);
        let decoded = Decoded::from_images(&views);
        let back = decoded.images();
        assert_eq!(back.occupancy, views.occupancy);
        for (a, b) in views.pixels.iter().zip(&back.pixels) {
            assert!((a - b).abs() <= 0.5 / 255.0 + 1e-6, "{a} vs {b}");
        }
        let cameras = Camera::set(&crate::core::camera::DEFAULT_VIEWS, 64).unwrap();
        assert_eq!(render(&decoded, &cameras, &Augment::NONE), back);
    }

    #[test]
    fn half_size_rendering_matches_projecting_at_half_size() {
        // A 2×2 block of the full-size image maps onto one pixel of the half-size one, so the
        // re-projected views cover what projecting the cloud at half size covers.
        let full = Decoded::from_images(&example_car_views(128));
        let cameras = Camera::set(&crate::core::camera::DEFAULT_VIEWS, 64).unwrap();
        let half = render(&full, &cameras, &Augment::NONE);
        let direct = example_car_views(64);
        let (a, b) = (half.occupied(), direct.occupied());
        let both = half
            .occupancy
            .iter()
            .zip(&direct.occupancy)
            .filter(|(x, y)| **x && **y)
            .count();
        assert!(both as f64 > 0.97 * b as f64 && a <= b, "{a} {b} {both}");
    }

    #[test]
    fn mirroring_swaps_the_sides_of_the_rig() {
        // Cameras 5–8 sit at (±1.2, 1.2, ±1.2); mirrored in x, the object seen by one camera is
        // the column-flipped original seen by its partner across x = 0.
        let views = example_car_views(64);
        let decoded = Decoded::from_images(&views);
        let cameras = Camera::set(&crate::core::camera::DEFAULT_VIEWS, 64).unwrap();
        let mirror = Augment {
            mirror: true,
            ..Augment::NONE
        };
        let mirrored = render(&decoded, &cameras, &mirror);
        let partner = |v: usize| {
            let c = cameras[v].center();
            (0..4)
                .find(|&u| {
                    (cameras[u].center() - nalgebra::Vector3::new(-c.x, c.y, c.z)).norm() < 1e-9
                })
                .unwrap()
        };
        let s = 64;
        for v in 0..4 {
            let u = partner(v);
            assert_ne!(u, v);
            let (mut agree, mut total) = (0, 0);
            for r in 0..s {
                for c in 0..s {
                    let a = mirrored.view_occupancy(v)[r * s + c];
                    let b = views.view_occupancy(u)[r * s + s - 1 - c];
                    total += usize::from(a || b);
                    agree += usize::from(a && b);
                    if a && b {
                        let x = mirrored.view_pixels(v)[r * s + c];
                        let x0 = views.view_pixels(u)[r * s + s - 1 - c];
                        assert!((x + x0).abs() < 0.05, "x {x} vs mirrored {x0}");
                    }
                }
            }
            assert!(
                agree as f64 > 0.9 * total as f64,
                "view {v}: {agree}/{total}"
            );
        }
    }

    #[test]
    fn scan_pairs_models_with_their_samples_and_holds_back_whole_models() {
        let dir = tempfile::tempdir().unwrap();
        let views = example_car_views(32);
        for (cat, name, samples) in [("bus", "b1", 2), ("car", "c1", 3), ("car", "c2", 0)] {
            let gt = dir.path().join("GT/train").join(cat).join(name);
            std::fs::create_dir_all(&gt).unwrap();
            write_views(&gt, &views).unwrap();
            for k in [1, 2, 10].iter().take(samples) {
                let input = dir
                    .path()
                    .join("in/train")
                    .join(cat)
                    .join(name)
                    .join(k.to_string());
                std::fs::create_dir_all(&input).unwrap();
                write_views(&input, &views).unwrap();
            }
        }
        let split = scan_split(dir.path(), "train").unwrap();
        assert_eq!((split.models, split.without_samples), (3, 1));
        let labels: Vec<String> = split.samples.iter().map(SampleRef::label).collect();
        assert_eq!(
            labels,
            ["bus/b1/1", "bus/b1/2", "car/c1/1", "car/c1/2", "car/c1/10"]
        );
        assert!(matches!(
            scan_split(dir.path(), "test"),
            Err(DataError::NotViews { .. })
        ));
        let (train, held) = hold_back(split.samples.clone(), 0.5);
        assert_eq!(train.len() + held.len(), 5);
        for s in &held {
            assert!(train.iter().all(|t| t.name != s.name));
        }
        let (all, none) = hold_back(split.samples, 0.0);
        assert_eq!((all.len(), none.len()), (5, 0));
    }

    #[test]
    fn cache_keeps_within_its_budget() {
        let dir = tempfile::tempdir().unwrap();
        let views = example_car_views(32);
        for k in 0..3 {
            let sub = dir.path().join(k.to_string());
            std::fs::create_dir_all(&sub).unwrap();
            write_views(&sub, &views).unwrap();
        }
        let one = Decoded::from_images(&views).bytes();
        let cache = Cache::new(2 * one + 1);
        for k in 0..3 {
            let a = cache
                .get(&dir.path().join(k.to_string()), &[5, 6, 7, 8])
                .unwrap();
            assert_eq!(a.views.len(), 4);
        }
        assert_eq!(cache.used(), 2 * one);
    }

    #[test]
    fn draw_order_visits_every_sample_once_per_pass_and_repeats_from_its_seed() {
        let mut order = DrawOrder::new(3, 7);
        let mut seen: Vec<usize> = (0..7).map(|i| order.draw(i).0).collect();
        seen.sort_unstable();
        assert_eq!(seen, (0..7).collect::<Vec<_>>());
        let second: Vec<usize> = (7..14).map(|i| order.draw(i).0).collect();
        let mut again = DrawOrder::new(3, 7);
        assert_eq!((7..14).map(|i| again.draw(i).0).collect::<Vec<_>>(), second);
        assert_eq!(order.draw(3).1.next_f64(), again.draw(3).1.next_f64());
    }

    #[ignore = "needs ../shared/reference"]
    #[test]
    fn reference_bus_views_load_as_a_training_sample() {
        let root =
            std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/reference/views");
        assert!(root.is_dir(), "{} is absent", root.display());
        let split = scan_split(&root, "train").unwrap();
        assert_eq!(split.samples.len(), 1);
        assert_eq!(split.samples[0].category, "02924116");
        let cameras = Camera::set(&crate::core::camera::DEFAULT_VIEWS, 128).unwrap();
        let cache = Cache::new(1 << 30);
        let sample = load_sample(&split.samples[0], &cameras, &Augment::NONE, &cache).unwrap();
        assert_eq!((sample.target.size, sample.target.views()), (128, 4));
        assert!(sample.target.has_color && sample.input.has_color);
        // The partial covers less than the ground truth and (nearly) lies inside it.
        let (gt, input) = (sample.target.occupied(), sample.input.occupied());
        let inside = sample
            .input
            .occupancy
            .iter()
            .zip(&sample.target.occupancy)
            .filter(|(i, g)| **i && **g)
            .count();
        assert!(
            gt > input && inside as f64 > 0.95 * input as f64,
            "{gt} {input} {inside}"
        );
        assert!(sample.input.occupied() > 500);
    }
}
