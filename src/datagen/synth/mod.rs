//! Procedural street-object meshes, so a model can be trained with no dataset at all: cars of
//! six body styles, single and articulated buses, trucks, trains and trams, motorcycles with and
//! without riders. Deterministic per seed; written as OBJ + MTL for `mvpcc prepare`.

mod builder;
pub mod street;
mod vehicles;

use crate::core::camera::Camera;
use crate::core::rng::{derive_seed, Lcg};
use crate::datagen::mesh::{Mesh, SignedAxis};
use crate::datagen::raster::{rasterize, EMPTY};
use image::RgbImage;
use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum Category {
    Car,
    Bus,
    Truck,
    Train,
    Motorcycle,
}

impl Category {
    pub const ALL: [Category; 5] = [
        Category::Car,
        Category::Bus,
        Category::Truck,
        Category::Train,
        Category::Motorcycle,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Category::Car => "car",
            Category::Bus => "bus",
            Category::Truck => "truck",
            Category::Train => "train",
            Category::Motorcycle => "motorcycle",
        }
    }

    /// Relative frequency when several categories are asked for: cars are most of what a
    /// mobile mapping car drives past.
    pub fn default_weight(self) -> f64 {
        match self {
            Category::Car => 4.0,
            _ => 1.0,
        }
    }

    fn named(name: &str) -> Option<Category> {
        Category::ALL.into_iter().find(|c| c.name() == name)
    }
}

/// A category and how often it is drawn, relative to the others of a run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Draw {
    pub category: Category,
    pub weight: f64,
}

impl From<Category> for Draw {
    fn from(category: Category) -> Draw {
        Draw {
            category,
            weight: category.default_weight(),
        }
    }
}

/// `NAME` (its default weight) or `NAME=WEIGHT`, the weight positive and finite.
impl std::str::FromStr for Draw {
    type Err = String;

    fn from_str(s: &str) -> Result<Draw, String> {
        let (name, weight) = match s.split_once('=') {
            Some((name, weight)) => (name, Some(weight)),
            None => (s, None),
        };
        let names = Category::ALL.map(Category::name).join(", ");
        let category = Category::named(name.trim())
            .ok_or_else(|| format!("unknown category '{name}' (one of {names})"))?;
        let Some(weight) = weight else {
            return Ok(category.into());
        };
        match weight.trim().parse::<f64>() {
            Ok(w) if w > 0.0 && w.is_finite() => Ok(Draw {
                category,
                weight: w,
            }),
            _ => Err(format!(
                "{name}'s weight must be a positive number, got '{weight}'"
            )),
        }
    }
}

/// One generated object.
pub struct Synthesized {
    pub category: Category,
    /// `<category>_<index>`, zero-padded so names sort in generation order.
    pub name: String,
    /// Body style or variant (`sedan`, `articulated`, `tank`, `tram`, `with_rider`…).
    pub variant: String,
    pub seed: u64,
    /// In metres: ground at y = 0, +y up, front towards −z.
    pub mesh: Mesh,
}

/// The most objects one run makes: they are named CATEGORY_NNNNN, and at about 100 kB a mesh
/// that many fill 10 GB, where a mistyped count would write until the disk is full.
pub const MAX_OBJECTS: usize = 100_000;

/// Object `index` of a run with `seed` drawing from `draws` by their weights. Depends only on
/// these three, not on how many objects the run makes.
pub fn synthesize(index: usize, seed: u64, draws: &[Draw]) -> Synthesized {
    let object_seed = derive_seed(seed, &format!("synth/{index}"));
    let mut rng = Lcg::new(object_seed);
    let total: f64 = draws.iter().map(|d| d.weight).sum();
    let mut x = rng.next_f64() * total;
    let mut category = draws[draws.len() - 1].category;
    for d in draws {
        if x < d.weight {
            category = d.category;
            break;
        }
        x -= d.weight;
    }
    let (builder, variant) = match category {
        Category::Car => vehicles::car(&mut rng),
        Category::Bus => vehicles::bus(&mut rng),
        Category::Truck => vehicles::truck(&mut rng),
        Category::Train => vehicles::train(&mut rng),
        Category::Motorcycle => vehicles::motorcycle(&mut rng),
    };
    Synthesized {
        category,
        name: format!("{}_{index:05}", category.name()),
        variant,
        seed: object_seed,
        mesh: builder.finish(),
    }
}

/// A contact sheet: each mesh normalized and rendered from rig camera 7 (front right, above),
/// shaded by how squarely each face meets the view, on white, `columns` per row.
pub fn contact_sheet(meshes: &[&Mesh], tile: usize, columns: usize) -> RgbImage {
    let columns = columns.max(1);
    let rows = meshes.len().div_ceil(columns).max(1);
    let mut sheet = RgbImage::from_pixel(
        (columns * tile) as u32,
        (rows * tile) as u32,
        image::Rgb([255, 255, 255]),
    );
    let camera = Camera::rig(7, tile).expect("rig camera 7 exists");
    let eye = camera.center().map(|v| v as f32);
    for (i, mesh) in meshes.iter().enumerate() {
        let mut m = (*mesh).clone();
        if m.normalize(SignedAxis::PLUS_Y, SignedAxis::MINUS_Z)
            .is_err()
        {
            continue;
        }
        let raster = rasterize(&m, &camera);
        let (ox, oy) = ((i % columns) * tile, (i / columns) * tile);
        for at in 0..tile * tile {
            let t = raster.triangle[at];
            if t == EMPTY {
                continue;
            }
            let Some((p, rgb)) = raster.hit(&m, at) else {
                continue;
            };
            let [a, b, c] = m.triangles[t as usize].map(|v| m.positions[v as usize]);
            let n = builder::cross(
                [b[0] - a[0], b[1] - a[1], b[2] - a[2]],
                [c[0] - a[0], c[1] - a[1], c[2] - a[2]],
            );
            let view = [eye[0] - p[0], eye[1] - p[1], eye[2] - p[2]];
            let cos = builder::dot(n, view).abs()
                / (builder::dot(n, n).sqrt() * builder::dot(view, view).sqrt()).max(1e-12);
            let shade = 0.35 + 0.65 * cos;
            let px = rgb.map(|v| (v as f32 * shade).round() as u8);
            sheet.put_pixel(
                (ox + at % tile) as u32,
                (oy + at / tile) as u32,
                image::Rgb(px),
            );
        }
    }
    sheet
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::datagen::scan::ground_truth;
    use std::path::Path;

    fn all() -> [Draw; 5] {
        Category::ALL.map(Draw::from)
    }

    #[test]
    fn categories_are_drawn_by_their_weights() {
        let draws: Vec<Draw> = ["car", "motorcycle=3"]
            .iter()
            .map(|s| s.parse().unwrap())
            .collect();
        let n = 400;
        let motorcycles = (0..n)
            .filter(|&i| synthesize(i, 4, &draws).category == Category::Motorcycle)
            .count();
        // 3 against car's 4: 3/7 of the draws, 171 of 400 (binomial sd 10).
        assert!((141..=201).contains(&motorcycles), "{motorcycles}");
    }

    #[test]
    fn a_draw_is_a_name_and_a_positive_weight() {
        assert_eq!("bus".parse(), Ok(Draw::from(Category::Bus)));
        assert_eq!(
            " truck = 0.5".parse(),
            Ok(Draw {
                category: Category::Truck,
                weight: 0.5
            })
        );
        for (bad, says) in [
            (
                "boat",
                "unknown category 'boat' (one of car, bus, truck, train, motorcycle)",
            ),
            ("car=0", "car's weight must be a positive number, got '0'"),
            ("car=-1", "car's weight must be a positive number, got '-1'"),
            (
                "car=inf",
                "car's weight must be a positive number, got 'inf'",
            ),
            ("car=", "car's weight must be a positive number, got ''"),
        ] {
            assert_eq!(bad.parse::<Draw>(), Err(says.to_string()));
        }
    }

    #[test]
    fn same_seed_same_object_other_seed_other_object() {
        let a = synthesize(3, 7, &all());
        let b = synthesize(3, 7, &all());
        assert_eq!(a.mesh.positions, b.mesh.positions);
        assert_eq!(a.name, b.name);
        let c = synthesize(3, 8, &all());
        assert_ne!(a.mesh.positions, c.mesh.positions);
    }

    #[test]
    fn every_category_is_closed_and_vehicle_sized() {
        for (i, &category) in Category::ALL.iter().enumerate() {
            for k in 0..4 {
                let s = synthesize(i * 10 + k, 1, &[category.into()]);
                assert_eq!(s.category, category);
                let stats = s.mesh.check(Path::new(&s.name), usize::MAX).unwrap();
                assert_eq!(stats.boundary_edges, 0, "{} {}", s.name, s.variant);
                assert_eq!(stats.non_manifold_edges, 0, "{} {}", s.name, s.variant);
                let (lo, hi) = s.mesh.bounds();
                let (w, h, l) = (hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]);
                let (length, height) = match category {
                    Category::Car => (3.5..5.8, 1.3..2.4),
                    Category::Bus => (9.9..20.0, 2.9..3.7),
                    Category::Truck => (7.0..11.0, 2.8..4.2),
                    // A raised pantograph reaches 5.5–6 m.
                    Category::Train => (17.0..45.0, 3.4..6.2),
                    Category::Motorcycle => (1.9..2.5, 1.0..1.9),
                };
                assert!(length.contains(&l), "{} length {l}", s.name);
                assert!(height.contains(&h), "{} height {h}", s.name);
                assert!(w < l, "{} is longer than wide", s.name);
                assert!(
                    lo[1].abs() < 1e-3,
                    "{} stands on the ground: {}",
                    s.name,
                    lo[1]
                );
            }
        }
    }

    /// Holes in the surface would show up as ground-truth gaps: render each category's ground
    /// truth, splat it back into the training views and compare with the mesh's own coverage.
    #[test]
    fn ground_truth_of_synthetic_objects_has_no_holes() {
        for (i, &category) in Category::ALL.iter().enumerate() {
            let mut m = synthesize(i, 5, &[category.into()]).mesh;
            m.normalize(SignedAxis::PLUS_Y, SignedAxis::MINUS_Z)
                .unwrap();
            let gt = ground_truth(&m, 256, 1.0 / 256.0).unwrap();
            let cams = Camera::set(&[5, 6, 7, 8], 96).unwrap();
            let splat = crate::views::projection::project(&gt.points, None, &cams);
            let dense = crate::datagen::raster::render_views(&m, &cams);
            let (mut covered, mut missed) = (0, 0);
            for (o, d) in splat.occupancy.iter().zip(&dense.occupancy) {
                covered += *d as usize;
                missed += (*d && !*o) as usize;
            }
            let frac = missed as f64 / covered as f64;
            assert!(
                frac < 0.02,
                "{category:?}: {missed} of {covered} pixels missed"
            );
        }
    }

    #[test]
    fn contact_sheet_draws_each_object_in_its_tile() {
        let objects: Vec<Synthesized> = (0..3).map(|i| synthesize(i, 2, &all())).collect();
        let meshes: Vec<&Mesh> = objects.iter().map(|o| &o.mesh).collect();
        let sheet = contact_sheet(&meshes, 64, 2);
        assert_eq!(sheet.dimensions(), (128, 128));
        for (ox, oy, drawn) in [(0, 0, true), (64, 0, true), (0, 64, true), (64, 64, false)] {
            let mut non_white = 0;
            for y in oy..oy + 64 {
                for x in ox..ox + 64 {
                    non_white += (sheet.get_pixel(x, y).0 != [255, 255, 255]) as usize;
                }
            }
            assert_eq!(non_white > 200, drawn, "tile at ({ox}, {oy}): {non_white}");
        }
    }
}
