//! Generated street scans with per-object ground truth, for `complete --scene`: a road with
//! parking lanes, kerbs and pavements, façades with gaps, poles, bins, bushes and hedges, rows
//! of parked vehicles of every road category on both sides and a few driving ones, scanned by a
//! mobile scanner driving along the road ([`scan_street`]). Each point knows the object it hit.

use super::builder::Builder;
use super::{synthesize, Category, Draw};
use crate::core::cloud::{Attribute, PointCloud, ScalarKind};
use crate::core::rng::{derive_seed, Lcg};
use crate::datagen::mesh::Mesh;
use crate::datagen::scan::{scan_street, StreetScanner};
use serde::{Deserialize, Serialize};

/// The street's layout and its scanner.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct StreetParams {
    /// Along the road, metres.
    pub length: f32,
    /// Half the road's width, kerb to kerb: a parking lane (2.5 m) and a driving lane (3.25 m)
    /// each side.
    pub half_road: f32,
    pub pavement: f32,
    pub kerb: f32,
    pub scanner: StreetScanner,
}

impl Default for StreetParams {
    fn default() -> Self {
        StreetParams {
            length: 60.0,
            half_road: 5.75,
            pavement: 2.5,
            kerb: 0.12,
            // In the middle of the right driving lane at a van's roof, 100 lines a second at 10 m/s, 0.25°
            // between returns and 1 cm of range noise: a common MLS setting.
            scanner: StreetScanner {
                x: 1.6,
                height: 2.4,
                line_spacing: 0.1,
                angle_step_deg: 0.25,
                noise: 0.01,
            },
        }
    }
}

/// What an object of the scene is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Kind {
    Ground,
    Building,
    Pole,
    Bin,
    Bush,
    Hedge,
    Vehicle,
}

impl Kind {
    /// The ASPRS LAS classification code the scan's points of this kind carry (vehicles: 64,
    /// the first user-definable code, since LAS 1.4 has none for them).
    pub fn class(self) -> u8 {
        match self {
            Kind::Ground => 2,
            Kind::Bush | Kind::Hedge => 4,
            Kind::Building => 6,
            Kind::Pole | Kind::Bin => 1,
            Kind::Vehicle => 64,
        }
    }
}

/// One object of the scene, its box in the scan's coordinates (z up).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TruthObject {
    /// The value of the `object` attribute on its points.
    pub id: u32,
    pub kind: Kind,
    pub category: Option<Category>,
    /// Parked, or driving (a vehicle in a driving lane).
    pub driving: bool,
    pub centre: [f64; 3],
    /// Length, width, height.
    pub size: [f64; 3],
}

/// A scanned street: the cloud (z up, metres, offset into UTM; classification and `object`
/// attributes) and its objects.
pub struct Street {
    pub cloud: PointCloud,
    pub objects: Vec<TruthObject>,
}

impl Street {
    /// Each point's object (its [`TruthObject::id`]), from the [`OBJECT`] attribute.
    pub fn labels(&self) -> Vec<u32> {
        self.cloud
            .attribute(OBJECT)
            .expect("a generated street labels its points")
            .values
            .iter()
            .map(|&o| o as u32)
            .collect()
    }
}

/// Where a generated street lies, as MLS tiles do: UTM-sized coordinates.
pub const STREET_OFFSET: [f64; 3] = [652_000.0, 5_280_000.0, 110.0];

/// The attribute holding each point's object (its [`TruthObject::id`]).
pub const OBJECT: &str = "object";

/// Builds the scene mesh object by object: its triangles' owners and the truth.
struct Scene {
    mesh: Mesh,
    owner: Vec<u32>,
    objects: Vec<TruthObject>,
}

impl Scene {
    fn add(&mut self, kind: Kind, category: Option<Category>, driving: bool, mesh: Mesh) {
        let id = self.objects.len() as u32;
        let (lo, hi) = crate::datagen::mesh::bounds_of(&mesh.positions);
        // y up, z along the road → z up, x along the road.
        let centre = [(lo[2] + hi[2]) / 2.0, (lo[0] + hi[0]) / 2.0, lo[1]].map(f64::from);
        let size = [hi[2] - lo[2], hi[0] - lo[0], hi[1] - lo[1]].map(f64::from);
        self.owner
            .extend(std::iter::repeat_n(id, mesh.triangles.len()));
        self.mesh.append(mesh);
        self.objects.push(TruthObject {
            id,
            kind,
            category,
            driving,
            centre: [0, 1, 2].map(|k| centre[k] + STREET_OFFSET[k]),
            size,
        });
    }
}

fn boxed(min: [f32; 3], max: [f32; 3], name: &str, rgb: [u8; 3]) -> Mesh {
    let mut b = Builder::default();
    let m = b.material(name, rgb);
    b.cuboid(min, max, m);
    b.finish()
}

/// `mesh` turned about the vertical by half a turn when `back`, then moved by `by`.
fn placed(mut mesh: Mesh, back: bool, by: [f32; 3]) -> Mesh {
    for p in &mut mesh.positions {
        if back {
            p[0] = -p[0];
            p[2] = -p[2];
        }
        for k in 0..3 {
            p[k] += by[k];
        }
    }
    mesh
}

/// Street `seed`: the same seed gives the same street.
pub fn street(seed: u64, params: &StreetParams) -> Street {
    let mut rng = Lcg::new(derive_seed(seed, "street"));
    let mut scene = Scene {
        mesh: Mesh::default(),
        owner: Vec::new(),
        objects: Vec::new(),
    };
    let (length, road, kerb) = (params.length, params.half_road, params.kerb);
    let outer = road + params.pavement;
    // The road in two halves about the scanner's path, so no triangle straddles it.
    let x = params.scanner.x;
    let mut ground = boxed(
        [-road, -0.2, 0.0],
        [x, 0.0, length],
        "asphalt",
        [60, 60, 64],
    );
    ground.append(boxed(
        [x, -0.2, 0.0],
        [road, 0.0, length],
        "asphalt",
        [60, 60, 64],
    ));
    for side in [-1.0f32, 1.0] {
        let (a, b) = (side * road, side * outer);
        ground.append(boxed(
            [a.min(b), -0.2, 0.0],
            [a.max(b), kerb, length],
            "pavement",
            [150, 148, 140],
        ));
    }
    scene.add(Kind::Ground, None, false, ground);

    for side in [-1.0f32, 1.0] {
        // Façades: blocks 8–25 m long with gaps of 0–6 m, 5–12 m high.
        let mut z = rng.range(-5.0, 2.0) as f32;
        while z < length {
            let long = rng.range(8.0, 25.0) as f32;
            let high = rng.range(5.0, 12.0) as f32;
            let (a, b) = (side * outer, side * (outer + 1.0));
            let block = boxed(
                [a.min(b), 0.0, z.max(0.0)],
                [a.max(b), high, (z + long).min(length)],
                "facade",
                [190, 170, 150],
            );
            if (z + long).min(length) > z.max(0.0) + 1.0 {
                scene.add(Kind::Building, None, false, block);
            }
            z += long + rng.range(0.0, 6.0) as f32;
        }
        // Street furniture on the pavement: poles, bins, bushes and hedges.
        let mut z = rng.range(2.0, 10.0) as f32;
        while z < length - 1.0 {
            let at = side * (road + 0.4);
            match rng.next_f64() {
                r if r < 0.4 => {
                    let mut b = Builder::default();
                    let m = b.material("pole", [120, 120, 125]);
                    let high = rng.range(3.0, 8.0) as f32;
                    let radius = rng.range(0.05, 0.15) as f32;
                    b.cylinder(
                        [at, kerb + high / 2.0, z],
                        1,
                        radius,
                        high / 2.0,
                        10,
                        [m, m],
                    );
                    scene.add(Kind::Pole, None, false, b.finish());
                }
                r if r < 0.6 => {
                    let s = rng.range(0.25, 0.4) as f32;
                    let high = rng.range(0.8, 1.2) as f32;
                    let bin = boxed(
                        [at - s, kerb, z - s],
                        [at + s, kerb + high, z + s],
                        "bin",
                        [40, 90, 40],
                    );
                    scene.add(Kind::Bin, None, false, bin);
                }
                r if r < 0.8 => {
                    let mut b = Builder::default();
                    let m = b.material("bush", [40, 110, 30]);
                    let radius = rng.range(0.4, 1.0) as f32;
                    let by = side * (outer - radius - 0.1);
                    b.sphere([by, kerb + radius * 0.9, z], radius, m);
                    scene.add(Kind::Bush, None, false, b.finish());
                }
                _ => {
                    let long = rng.range(2.0, 8.0) as f32;
                    let high = rng.range(0.8, 1.6) as f32;
                    let (a, b) = (side * (outer - 0.9), side * (outer - 0.1));
                    let hedge = boxed(
                        [a.min(b), kerb, z],
                        [a.max(b), kerb + high, (z + long).min(length)],
                        "hedge",
                        [30, 100, 35],
                    );
                    scene.add(Kind::Hedge, None, false, hedge);
                    z += long;
                }
            }
            z += rng.range(4.0, 14.0) as f32;
        }
        // Parked vehicles in the parking lane, facing the traffic of their side.
        let parked = [
            Category::Car.into(),
            Draw {
                category: Category::Bus,
                weight: 0.5,
            },
            Draw {
                category: Category::Truck,
                weight: 0.7,
            },
            Draw {
                category: Category::Motorcycle,
                weight: 0.6,
            },
        ];
        let mut z = rng.range(0.5, 4.0) as f32;
        let mut index = if side < 0.0 { 0 } else { 1000 };
        loop {
            let v = synthesize(index, seed, &parked);
            index += 1;
            let (lo, hi) = crate::datagen::mesh::bounds_of(&v.mesh.positions);
            let (long, wide) = (hi[2] - lo[2], hi[0] - lo[0]);
            if z + long > length {
                break;
            }
            let centre_x = side * (road - 0.3 - wide / 2.0);
            let back = side > 0.0;
            let mid = [(lo[0] + hi[0]) / 2.0, 0.0, (lo[2] + hi[2]) / 2.0];
            let turned_mid = if back { [-mid[0], 0.0, -mid[2]] } else { mid };
            let by = [
                centre_x - turned_mid[0],
                -lo[1],
                z + long / 2.0 - turned_mid[2],
            ];
            scene.add(
                Kind::Vehicle,
                Some(v.category),
                false,
                placed(v.mesh, back, by),
            );
            z += long + rng.range(0.6, 4.0) as f32;
        }
    }
    // A few vehicles driving in the middle of the opposite lane, a tram among them now and then.
    let driving = [
        Category::Car.into(),
        Draw {
            category: Category::Train,
            weight: 0.4,
        },
        Draw {
            category: Category::Bus,
            weight: 0.4,
        },
    ];
    let mut z = rng.range(5.0, 25.0) as f32;
    let mut index = 2000;
    loop {
        let v = synthesize(index, seed, &driving);
        index += 1;
        let (lo, hi) = crate::datagen::mesh::bounds_of(&v.mesh.positions);
        let long = hi[2] - lo[2];
        if z + long > length {
            break;
        }
        let mid = [(lo[0] + hi[0]) / 2.0, 0.0, (lo[2] + hi[2]) / 2.0];
        let by = [-params.scanner.x - mid[0], -lo[1], z + long / 2.0 - mid[2]];
        scene.add(
            Kind::Vehicle,
            Some(v.category),
            true,
            placed(v.mesh, false, by),
        );
        z += long + rng.range(15.0, 40.0) as f32;
    }

    let scan = scan_street(&scene.mesh, &params.scanner, &mut rng);
    let positions = scan
        .points
        .iter()
        .map(|p| {
            let zup = [p[2], p[0], p[1]].map(f64::from);
            [0, 1, 2].map(|k| zup[k] + STREET_OFFSET[k])
        })
        .collect();
    let owners: Vec<u32> = scan.triangles.iter().map(|&t| scene.owner[t]).collect();
    let mut cloud = PointCloud::from_positions(positions);
    cloud.colors = Some(scan.colors);
    cloud.attributes = vec![
        Attribute {
            name: "classification".into(),
            kind: ScalarKind::U8,
            values: owners
                .iter()
                .map(|&o| f64::from(scene.objects[o as usize].kind.class()))
                .collect(),
        },
        Attribute {
            name: OBJECT.into(),
            kind: ScalarKind::U32,
            values: owners.iter().map(|&o| f64::from(o)).collect(),
        },
    ];
    Street {
        cloud,
        objects: scene.objects,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_street_has_its_objects_scanned_and_labelled() {
        let params = StreetParams {
            length: 30.0,
            ..StreetParams::default()
        };
        let a = street(3, &params);
        let b = street(3, &params);
        assert_eq!(a.cloud, b.cloud, "one seed, one street");
        let objects = &a.cloud.attribute(OBJECT).unwrap().values;
        let vehicles: Vec<&TruthObject> = a
            .objects
            .iter()
            .filter(|o| o.kind == Kind::Vehicle)
            .collect();
        assert!(vehicles.len() >= 4, "{}", vehicles.len());
        // Every vehicle on the scanner's side is seen; the ground holds most points.
        for v in vehicles
            .iter()
            .filter(|v| v.centre[1] - STREET_OFFSET[1] > 1.6)
        {
            let seen = objects.iter().filter(|&&o| o == f64::from(v.id)).count();
            assert!(seen > 500, "{v:?}: {seen}");
        }
        let ground = objects.iter().filter(|&&o| o == 0.0).count();
        assert!(ground > objects.len() / 4, "{ground} of {}", objects.len());
        assert!(a.cloud.is_consistent());
    }
}
