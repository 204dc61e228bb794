//! Closed primitives (boxes, cylinders, spheres, lofts) with one material each, assembled into
//! a [`Mesh`]. Every primitive is watertight on its own: each edge has exactly two triangles.

use crate::datagen::mesh::{Material, Mesh};

pub type V3 = [f32; 3];

#[derive(Default)]
pub struct Builder {
    mesh: Mesh,
}

impl Builder {
    /// The index of material `name`, created with `rgb` on first use.
    pub fn material(&mut self, name: &str, rgb: [u8; 3]) -> u32 {
        if let Some(i) = self.mesh.materials.iter().position(|m| m.name == name) {
            return i as u32;
        }
        self.mesh.materials.push(Material::plain(name, rgb));
        self.mesh.materials.len() as u32 - 1
    }

    fn vertex(&mut self, p: V3) -> u32 {
        self.mesh.positions.push(p);
        self.mesh.positions.len() as u32 - 1
    }

    fn tri(&mut self, a: u32, b: u32, c: u32, material: u32) {
        self.mesh.triangles.push([a, b, c]);
        self.mesh.material_of.push(material);
    }

    fn quad(&mut self, a: u32, b: u32, c: u32, d: u32, material: u32) {
        self.tri(a, b, c, material);
        self.tri(a, c, d, material);
    }

    /// An axis-aligned box.
    pub fn cuboid(&mut self, min: V3, max: V3, material: u32) {
        let c = [0, 1, 2].map(|i| (min[i] + max[i]) / 2.0);
        let h = [0, 1, 2].map(|i| (max[i] - min[i]).abs() / 2.0);
        self.oriented_box(
            c,
            [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            h,
            material,
        );
    }

    /// A box with centre `c`, orthonormal `axes` and half sizes `h`.
    pub fn oriented_box(&mut self, c: V3, axes: [V3; 3], h: V3, material: u32) {
        let corner = |sx: f32, sy: f32, sz: f32| -> V3 {
            [0, 1, 2].map(|k| {
                c[k] + sx * h[0] * axes[0][k] + sy * h[1] * axes[1][k] + sz * h[2] * axes[2][k]
            })
        };
        let v: Vec<u32> = (0..8)
            .map(|i| {
                let s = |bit: usize| if i & bit == 0 { -1.0 } else { 1.0 };
                let p = corner(s(1), s(2), s(4));
                self.vertex(p)
            })
            .collect();
        // Faces as corner-index quads, counter-clockwise seen from outside.
        for [a, b, cc, d] in [
            [0, 2, 6, 4],
            [1, 5, 7, 3],
            [0, 4, 5, 1],
            [2, 3, 7, 6],
            [0, 1, 3, 2],
            [4, 6, 7, 5],
        ] {
            self.quad(v[a], v[b], v[cc], v[d], material);
        }
    }

    /// A box from `a` to `b` (its long axis), `half_width` across and `half_depth` along
    /// `side` (made perpendicular to the long axis).
    pub fn beam(
        &mut self,
        a: V3,
        b: V3,
        half_width: f32,
        half_depth: f32,
        side: V3,
        material: u32,
    ) {
        let d = [0, 1, 2].map(|k| b[k] - a[k]);
        let len = norm(d);
        let x = d.map(|c| c / len);
        let s = sub(side, scale(x, dot(side, x)));
        let y = scale(s, 1.0 / norm(s));
        let z = cross(x, y);
        let c = [0, 1, 2].map(|k| (a[k] + b[k]) / 2.0);
        self.oriented_box(c, [x, y, z], [len / 2.0, half_width, half_depth], material);
    }

    /// A cylinder along `axis` (0 = x, 1 = y, 2 = z) with capped ends; `[side, caps]`
    /// materials.
    pub fn cylinder(
        &mut self,
        c: V3,
        axis: usize,
        radius: f32,
        half_length: f32,
        segments: usize,
        [side, caps]: [u32; 2],
    ) {
        let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
        let ring = |s: f32| -> Vec<V3> {
            (0..segments)
                .map(|i| {
                    let a = i as f32 / segments as f32 * std::f32::consts::TAU;
                    let mut p = c;
                    p[axis] += s * half_length;
                    p[u] += radius * a.cos();
                    p[v] += radius * a.sin();
                    p
                })
                .collect()
        };
        self.loft(&[ring(-1.0), ring(1.0)], |_, _| side, caps);
    }

    /// A UV sphere.
    pub fn sphere(&mut self, c: V3, radius: f32, material: u32) {
        let (lat, lon) = (8, 14);
        let rings: Vec<Vec<V3>> = (1..lat)
            .map(|i| {
                let t = i as f32 / lat as f32 * std::f32::consts::PI;
                (0..lon)
                    .map(|j| {
                        let p = j as f32 / lon as f32 * std::f32::consts::TAU;
                        [
                            c[0] + radius * t.sin() * p.cos(),
                            c[1] - radius * t.cos(),
                            c[2] + radius * t.sin() * p.sin(),
                        ]
                    })
                    .collect()
            })
            .collect();
        self.loft_with_apexes(
            &rings,
            |_, _| material,
            material,
            Some(([c[0], c[1] - radius, c[2]], [c[0], c[1] + radius, c[2]])),
        );
    }

    /// A tube through `rings` (each the same number of points, in order around), closed at
    /// both ends by fans from the ring centroids. `material(ring, segment)` colours the strip
    /// between ring `ring` and `ring + 1` along segment `segment` (from point `segment` to the
    /// next).
    pub fn loft(&mut self, rings: &[Vec<V3>], material: impl Fn(usize, usize) -> u32, caps: u32) {
        self.loft_with_apexes(rings, material, caps, None);
    }

    fn loft_with_apexes(
        &mut self,
        rings: &[Vec<V3>],
        material: impl Fn(usize, usize) -> u32,
        caps: u32,
        apexes: Option<(V3, V3)>,
    ) {
        let n = rings[0].len();
        assert!(
            rings.iter().all(|r| r.len() == n),
            "rings of one loft have one size"
        );
        let ids: Vec<Vec<u32>> = rings
            .iter()
            .map(|r| r.iter().map(|&p| self.vertex(p)).collect())
            .collect();
        for r in 0..rings.len() - 1 {
            for s in 0..n {
                let (a, b) = (ids[r][s], ids[r][(s + 1) % n]);
                let (c, d) = (ids[r + 1][(s + 1) % n], ids[r + 1][s]);
                self.quad(a, b, c, d, material(r, s));
            }
        }
        let centroid = |r: &Vec<V3>| -> V3 {
            let mut c = [0.0; 3];
            for p in r {
                for k in 0..3 {
                    c[k] += p[k] / r.len() as f32;
                }
            }
            c
        };
        let (first, last) = match apexes {
            Some(a) => a,
            None => (centroid(&rings[0]), centroid(&rings[rings.len() - 1])),
        };
        let f = self.vertex(first);
        let l = self.vertex(last);
        let end = ids.len() - 1;
        for s in 0..n {
            self.tri(f, ids[0][(s + 1) % n], ids[0][s], caps);
            self.tri(l, ids[end][s], ids[end][(s + 1) % n], caps);
        }
    }

    pub fn finish(self) -> Mesh {
        self.mesh
    }
}

pub fn dot(a: V3, b: V3) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

pub fn cross(a: V3, b: V3) -> V3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn sub(a: V3, b: V3) -> V3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn scale(a: V3, s: f32) -> V3 {
    a.map(|c| c * s)
}

fn norm(a: V3) -> f32 {
    dot(a, a).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    #[test]
    fn every_primitive_is_closed() {
        let mut b = Builder::default();
        let m = b.material("m", [1, 2, 3]);
        b.cuboid([0.0; 3], [1.0, 2.0, 3.0], m);
        b.cylinder([0.0; 3], 0, 0.5, 0.1, 12, [m, m]);
        b.sphere([1.0; 3], 0.3, m);
        b.beam([0.0; 3], [1.0, 1.0, 0.0], 0.05, 0.1, [0.0, 0.0, 1.0], m);
        let mesh = b.finish();
        let stats = mesh.check(Path::new("b"), usize::MAX).unwrap();
        assert_eq!(
            (
                stats.boundary_edges,
                stats.non_manifold_edges,
                stats.degenerate
            ),
            (0, 0, 0)
        );
        assert_eq!(mesh.materials.len(), 1);
    }
}
