//! Small procedural street objects for tests, benchmarks and the shipped example: surface
//! samples of a car-like body (boxes and wheels) with colours and outward normals, and the
//! partial view a scanner on one side would get of it.

use crate::core::cloud::PointCloud;
use crate::core::rng::Lcg;

/// Surface samples with their outward normals.
pub struct Sampled {
    pub cloud: PointCloud,
    pub normals: Vec<[f64; 3]>,
}

struct Part {
    min: [f64; 3],
    max: [f64; 3],
    color: [u8; 3],
}

/// A car about 4.4 m long (along z), 1.8 m wide (x) and 1.45 m high (y, up), in metres, with
/// about `n` points spread over its surface by area.
pub fn car(n: usize, seed: u64) -> Sampled {
    let mut rng = Lcg::new(seed);
    let paint = [
        [
            rng.range(20.0, 230.0) as u8,
            rng.range(20.0, 230.0) as u8,
            rng.range(20.0, 230.0) as u8,
        ],
        [40, 50, 60],
    ];
    let boxes = [
        Part {
            min: [-0.9, 0.3, -2.2],
            max: [0.9, 0.95, 2.2],
            color: paint[0],
        },
        Part {
            min: [-0.8, 0.95, -1.1],
            max: [0.8, 1.45, 0.9],
            color: paint[1],
        },
    ];
    // (centre z, side x) of each wheel; radius 0.33, width 0.22.
    let wheels = [(-1.4, -0.8), (-1.4, 0.8), (1.4, -0.8), (1.4, 0.8)];
    let (radius, width) = (0.33, 0.22);
    let box_area = |b: &Part| {
        let e = [0, 1, 2].map(|i| b.max[i] - b.min[i]);
        2.0 * (e[0] * e[1] + e[1] * e[2] + e[0] * e[2])
    };
    let wheel_area =
        2.0 * std::f64::consts::PI * radius * width + std::f64::consts::PI * radius * radius;
    let total = boxes.iter().map(box_area).sum::<f64>() + 4.0 * wheel_area;

    let mut out = Surface::with_capacity(n);
    for b in &boxes {
        let count = (n as f64 * box_area(b) / total).round() as usize;
        sample_box(b, count, &mut rng, &mut out);
    }
    let per_wheel = (n as f64 * wheel_area / total).round() as usize;
    for &(cz, cx) in &wheels {
        let wheel = Wheel {
            centre: [cx, radius, cz],
            radius,
            width,
        };
        sample_wheel(&wheel, per_wheel, &mut rng, &mut out);
    }
    Sampled {
        cloud: PointCloud {
            positions: out.positions,
            colors: Some(out.colors),
            ..Default::default()
        },
        normals: out.normals,
    }
}

/// Surface samples as they are drawn: positions, colours and outward normals.
struct Surface {
    positions: Vec<[f64; 3]>,
    colors: Vec<[u8; 3]>,
    normals: Vec<[f64; 3]>,
}

impl Surface {
    fn with_capacity(n: usize) -> Surface {
        Surface {
            positions: Vec::with_capacity(n),
            colors: Vec::with_capacity(n),
            normals: Vec::with_capacity(n),
        }
    }

    fn push(&mut self, position: [f64; 3], color: [u8; 3], normal: [f64; 3]) {
        self.positions.push(position);
        self.colors.push(color);
        self.normals.push(normal);
    }
}

/// `count` points on the faces of box `b`, each face drawn by its area.
fn sample_box(b: &Part, count: usize, rng: &mut Lcg, out: &mut Surface) {
    let e = [0, 1, 2].map(|i| b.max[i] - b.min[i]);
    let faces = [
        e[1] * e[2],
        e[1] * e[2],
        e[0] * e[2],
        e[0] * e[2],
        e[0] * e[1],
        e[0] * e[1],
    ];
    let face_total: f64 = faces.iter().sum();
    for _ in 0..count {
        let mut pick = rng.next_f64() * face_total;
        let mut face = 0;
        while face < 5 && pick >= faces[face] {
            pick -= faces[face];
            face += 1;
        }
        let axis = face / 2;
        let mut p = [0, 1, 2].map(|i| rng.range(b.min[i], b.max[i]));
        let mut normal = [0.0; 3];
        if face % 2 == 0 {
            p[axis] = b.min[axis];
            normal[axis] = -1.0;
        } else {
            p[axis] = b.max[axis];
            normal[axis] = 1.0;
        }
        out.push(p, b.color, normal);
    }
}

/// A wheel standing on the ground with its axle along x: `centre` is the axle's middle.
struct Wheel {
    centre: [f64; 3],
    radius: f64,
    width: f64,
}

/// `count` points on a wheel: its outer side (a grey rim inside the black tyre) and its tread,
/// each drawn by its area; the inner side is hidden.
fn sample_wheel(wheel: &Wheel, count: usize, rng: &mut Lcg, out: &mut Surface) {
    let Wheel {
        centre: [cx, cy, cz],
        radius,
        width,
    } = *wheel;
    let outward: f64 = if cx < 0.0 { -1.0 } else { 1.0 };
    let wheel_area =
        2.0 * std::f64::consts::PI * radius * width + std::f64::consts::PI * radius * radius;
    let side_share = std::f64::consts::PI * radius * radius / wheel_area;
    for _ in 0..count {
        let angle = rng.range(0.0, std::f64::consts::TAU);
        if rng.next_f64() < side_share {
            let r = radius * rng.next_f64().sqrt();
            let color = if r < 0.6 * radius {
                [170, 170, 175]
            } else {
                [25, 25, 25]
            };
            let side = [
                cx + outward * width / 2.0,
                cy + r * angle.sin(),
                cz + r * angle.cos(),
            ];
            out.push(side, color, [outward, 0.0, 0.0]);
        } else {
            let x = cx + rng.range(-width / 2.0, width / 2.0);
            let tread = [x, cy + radius * angle.sin(), cz + radius * angle.cos()];
            out.push(tread, [25, 25, 25], [0.0, angle.sin(), angle.cos()]);
        }
    }
}

/// The car shipped as `assets/example/car_gt.ply` (its partial is [`scanned_side`] of it).
pub fn example_car() -> Sampled {
    car(16_000, 2026)
}

/// [`example_car`] normalized and projected into the default rig's views at `size`².
pub fn example_car_views(size: usize) -> crate::views::projection::ViewImages {
    let car = example_car();
    let frame = crate::core::frame::Frame::fit(&car.cloud, crate::core::frame::UpAxis::Y)
        .expect("the example car has an extent");
    let normalized = frame.normalize(&car.cloud);
    let cameras = crate::core::camera::Camera::set(&crate::core::camera::DEFAULT_VIEWS, size)
        .expect("the default rig is valid");
    crate::views::projection::project(
        &normalized.positions_f32(),
        normalized.colors.as_deref(),
        &cameras,
    )
}

/// What a scanner on a mast higher than the roof, driving past on the +x side, sees: surfaces
/// facing it and the whole roof, nothing of the far flank or the underside; the body hides the
/// far side's sloping surfaces beyond x = −0.6 m.
pub fn scanned_side(sampled: &Sampled) -> PointCloud {
    let view = [0.8, 0.6, 0.0];
    let keep: Vec<bool> = sampled
        .normals
        .iter()
        .zip(&sampled.cloud.positions)
        .map(|(n, p)| {
            n[0] * view[0] + n[1] * view[1] + n[2] * view[2] > 0.05 && (p[0] > -0.6 || n[1] > 0.9)
        })
        .collect();
    sampled.cloud.filter(&keep)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn car_is_reproducible_and_car_sized() {
        let a = car(5000, 1);
        assert_eq!(a.cloud, car(5000, 1).cloud);
        assert_ne!(a.cloud.positions, car(5000, 2).cloud.positions);
        assert!((a.cloud.len() as i64 - 5000).abs() < 20);
        let e = a.cloud.bounds().unwrap().extent();
        assert!(
            (e[2] - 4.4).abs() < 1e-9 && e[1] > 1.4 && e[0] > 1.8,
            "{e:?}"
        );
        let side = scanned_side(&a);
        assert!(side.len() > 1000 && side.len() < 4000, "{}", side.len());
        assert!(side.positions.iter().all(|p| p[0] > -0.6 || p[1] > 0.6));
    }
}
