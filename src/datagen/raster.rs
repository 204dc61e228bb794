//! A z-buffered triangle rasterizer for the rig's pinhole cameras: which triangle each pixel
//! centre sees first, and where on it. Ground truth, the paper's camera partials, the dense
//! ground-truth views and the synth preview all come from here.

use crate::core::camera::Camera;
use crate::datagen::mesh::Mesh;
use crate::views::projection::{render_each_view, ViewImages};

/// `triangle` value of a pixel no triangle covers.
pub const EMPTY: u32 = u32::MAX;

/// What one camera sees of a mesh: per pixel (row-major), the nearest triangle and the
/// perspective-correct barycentric weights of the pixel centre's ray hit on it.
#[derive(Debug, Clone)]
pub struct Raster {
    pub size: usize,
    /// 1 / camera-space depth (along the optical axis); 0 where empty.
    pub inv_depth: Vec<f32>,
    pub triangle: Vec<u32>,
    /// Weights of the triangle's second and third vertex (the first is 1 − both).
    pub bary: Vec<[f32; 2]>,
}

/// Surface points with colours.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Surface {
    pub points: Vec<[f32; 3]>,
    pub colors: Vec<[u8; 3]>,
}

impl Surface {
    pub fn len(&self) -> usize {
        self.points.len()
    }

    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    pub fn extend(&mut self, other: Surface) {
        self.points.extend(other.points);
        self.colors.extend(other.colors);
    }
}

#[inline]
fn edge(a: [f32; 2], b: [f32; 2], p: [f32; 2]) -> f32 {
    (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0])
}

/// Renders `mesh` (in normalized coordinates) from `camera`. Pixel `(row, col)` samples its
/// centre `(col + 0.5, row + 0.5)`, the pixel a point at that spot projects into, so a surface
/// point read back from the raster projects into the pixel it came from. Both windings are
/// drawn: ShapeNet's are inconsistent.
pub fn rasterize(mesh: &Mesh, camera: &Camera) -> Raster {
    let s = camera.size;
    let r = camera.rotation.map(|v| v as f32);
    let t = camera.translation.map(|v| v as f32);
    let f = camera.focal as f32;
    let c = camera.principal as f32;
    // [x_screen, y_screen, depth] per vertex.
    let screen: Vec<[f32; 3]> = mesh
        .positions
        .iter()
        .map(|p| {
            let q: [f32; 3] = std::array::from_fn(|i| {
                r[(i, 0)] * p[0] + r[(i, 1)] * p[1] + r[(i, 2)] * p[2] + t[i]
            });
            [f * q[0] / q[2] + c, f * q[1] / q[2] + c, q[2]]
        })
        .collect();
    let mut raster = Raster {
        size: s,
        inv_depth: vec![0.0; s * s],
        triangle: vec![EMPTY; s * s],
        bary: vec![[0.0; 2]; s * s],
    };
    let limit = s as f32 - 1.0;
    for (ti, tri) in mesh.triangles.iter().enumerate() {
        let [v0, v1, v2] = tri.map(|i| screen[i as usize]);
        // The rig looks at the unit box from 2.08 away, so nothing reaches the camera plane;
        // anything that does is not drawn rather than drawn wrapped around.
        if v0[2] <= 1e-4 || v1[2] <= 1e-4 || v2[2] <= 1e-4 {
            continue;
        }
        let (a, b, cc) = ([v0[0], v0[1]], [v1[0], v1[1]], [v2[0], v2[1]]);
        let area = edge(a, b, cc);
        if area.abs() < 1e-12 {
            continue;
        }
        let inv_area = 1.0 / area;
        let min_x = (v0[0].min(v1[0]).min(v2[0]) - 0.5).ceil().max(0.0);
        let max_x = (v0[0].max(v1[0]).max(v2[0]) - 0.5).floor().min(limit);
        let min_y = (v0[1].min(v1[1]).min(v2[1]) - 0.5).ceil().max(0.0);
        let max_y = (v0[1].max(v1[1]).max(v2[1]) - 0.5).floor().min(limit);
        if min_x > max_x || min_y > max_y {
            continue;
        }
        let iz = [1.0 / v0[2], 1.0 / v1[2], 1.0 / v2[2]];
        // Barycentric weights are affine in the pixel position: w = a·x + b·y + c per vertex,
        // stepped along each row instead of re-evaluated.
        let coef = |p: [f32; 2], q: [f32; 2]| {
            let a = -(q[1] - p[1]) * inv_area;
            let b = (q[0] - p[0]) * inv_area;
            let c = -(a * p[0] + b * p[1]);
            (a, b, c)
        };
        let e = [coef(b, cc), coef(cc, a), coef(a, b)];
        for row in min_y as usize..=max_y as usize {
            let py = row as f32 + 0.5;
            let x0 = min_x + 0.5;
            let mut w = e.map(|(a, b, c)| a * x0 + b * py + c);
            for col in min_x as usize..=max_x as usize {
                if w[0] >= 0.0 && w[1] >= 0.0 && w[2] >= 0.0 {
                    let l = [w[0] * iz[0], w[1] * iz[1], w[2] * iz[2]];
                    let inv_depth = l[0] + l[1] + l[2];
                    let at = row * s + col;
                    if inv_depth > raster.inv_depth[at] {
                        raster.inv_depth[at] = inv_depth;
                        raster.triangle[at] = ti as u32;
                        let depth = 1.0 / inv_depth;
                        raster.bary[at] = [l[1] * depth, l[2] * depth];
                    }
                }
                for k in 0..3 {
                    w[k] += e[k].0;
                }
            }
        }
    }
    raster
}

impl Raster {
    pub fn covered(&self) -> usize {
        self.triangle.iter().filter(|&&t| t != EMPTY).count()
    }

    /// The surface point and colour pixel `at` sees, if any.
    #[inline]
    pub fn hit(&self, mesh: &Mesh, at: usize) -> Option<([f32; 3], [u8; 3])> {
        let t = self.triangle[at];
        if t == EMPTY {
            return None;
        }
        let [b1, b2] = self.bary[at];
        let b = [1.0 - b1 - b2, b1, b2];
        let [p0, p1, p2] = mesh.triangles[t as usize].map(|i| mesh.positions[i as usize]);
        let point = std::array::from_fn(|k| b[0] * p0[k] + b[1] * p1[k] + b[2] * p2[k]);
        Some((point, mesh.color_at(t as usize, b)))
    }

    /// Every visible surface point, row-major.
    pub fn surface(&self, mesh: &Mesh) -> Surface {
        let mut out = Surface::default();
        for at in 0..self.triangle.len() {
            if let Some((p, c)) = self.hit(mesh, at) {
                out.points.push(p);
                out.colors.push(c);
            }
        }
        out
    }
}

/// Dense view images of a mesh: each pixel holds the surface point its centre sees, as the
/// original dataset's ground-truth views do.
pub fn render_views(mesh: &Mesh, cameras: &[Camera]) -> ViewImages {
    render_each_view(cameras, true, |camera, pixels, occupancy| {
        let plane = camera.size * camera.size;
        let raster = rasterize(mesh, camera);
        for at in 0..plane {
            if let Some((p, rgb)) = raster.hit(mesh, at) {
                occupancy[at] = true;
                for k in 0..3 {
                    pixels[k * plane + at] = p[k];
                    pixels[(3 + k) * plane + at] = rgb[k] as f32 / 255.0;
                }
            }
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::datagen::mesh::Material;

    /// The unit cube [-0.5, 0.5]³ as 12 triangles, one material per face.
    pub(crate) fn unit_cube() -> Mesh {
        let mut m = Mesh::default();
        for axis in 0..3 {
            for sign in [-0.5f32, 0.5] {
                let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
                let base = m.positions.len() as u32;
                for (a, b) in [(-0.5, -0.5), (0.5, -0.5), (0.5, 0.5), (-0.5, 0.5)] {
                    let mut p = [0.0; 3];
                    p[axis] = sign;
                    p[u] = a;
                    p[v] = b;
                    m.positions.push(p);
                }
                m.triangles.push([base, base + 1, base + 2]);
                m.triangles.push([base, base + 2, base + 3]);
                let id = m.materials.len() as u32;
                m.material_of.extend([id, id]);
                let mut rgb = [0u8; 3];
                rgb[axis] = if sign > 0.0 { 255 } else { 100 };
                m.materials.push(Material::plain("face", rgb));
            }
        }
        m
    }

    #[test]
    fn cube_from_camera_6_covers_the_pixels_its_projected_silhouette_covers() {
        let cube = unit_cube();
        let cam = Camera::rig(6, 64).unwrap();
        let raster = rasterize(&cube, &cam);
        // Camera 6 sits at (1.2, 1.2, 1.2): it sees the +x, +y and +z faces, never the others.
        let mut seen = [false; 6];
        for at in 0..64 * 64 {
            if raster.triangle[at] != EMPTY {
                seen[cube.material_of[raster.triangle[at] as usize] as usize] = true;
            }
        }
        assert_eq!(seen, [false, true, false, true, false, true]);
        // The silhouette is the hexagon of the six projected outline corners; count pixel
        // centres inside the convex hull of all eight projected corners.
        let corners: Vec<[f64; 2]> = (0..8)
            .map(|i| {
                let p = nalgebra::Vector3::new(
                    if i & 1 == 0 { -0.5 } else { 0.5 },
                    if i & 2 == 0 { -0.5 } else { 0.5 },
                    if i & 4 == 0 { -0.5 } else { 0.5 },
                );
                let q = cam.rotation * p + cam.translation;
                [
                    cam.focal * q.x / q.z + cam.principal,
                    cam.focal * q.y / q.z + cam.principal,
                ]
            })
            .collect();
        let hull = convex_hull(corners);
        let mut expected = 0;
        for row in 0..64 {
            for col in 0..64 {
                let p = [col as f64 + 0.5, row as f64 + 0.5];
                let inside = (0..hull.len()).all(|k| {
                    let (a, b) = (hull[k], hull[(k + 1) % hull.len()]);
                    (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0]) >= 0.0
                });
                expected += inside as usize;
                assert_eq!(
                    raster.triangle[row * 64 + col] != EMPTY,
                    inside,
                    "pixel ({row}, {col})"
                );
            }
        }
        assert!(expected > 500, "{expected}");
    }

    fn convex_hull(mut p: Vec<[f64; 2]>) -> Vec<[f64; 2]> {
        p.sort_by(|a, b| a.partial_cmp(b).unwrap());
        let cross = |o: [f64; 2], a: [f64; 2], b: [f64; 2]| {
            (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])
        };
        let mut hull: Vec<[f64; 2]> = Vec::new();
        for pass in 0..2 {
            let start = hull.len();
            let iter: Vec<[f64; 2]> = if pass == 0 {
                p.clone()
            } else {
                p.iter().rev().copied().collect()
            };
            for q in iter {
                while hull.len() >= start + 2
                    && cross(hull[hull.len() - 2], hull[hull.len() - 1], q) <= 0.0
                {
                    hull.pop();
                }
                hull.push(q);
            }
            hull.pop();
        }
        hull
    }

    #[test]
    fn depth_test_keeps_the_near_face_in_either_draw_order() {
        // Two parallel squares facing camera 19 (at +x): the large one at x = 0.3 hides the
        // small one at x = -0.3 completely, whichever is drawn first.
        let square = |x: f32, rgb: [u8; 3]| {
            let h = if x > 0.0 { 0.45 } else { 0.15 };
            Mesh {
                positions: vec![[x, -h, -h], [x, h, -h], [x, h, h], [x, -h, h]],
                triangles: vec![[0, 1, 2], [0, 2, 3]],
                material_of: vec![0, 0],
                materials: vec![Material::plain("s", rgb)],
                ..Mesh::default()
            }
        };
        let cam = Camera::rig(19, 32).unwrap();
        for near_first in [true, false] {
            let (mut m, other) = if near_first {
                (square(0.3, [255, 0, 0]), square(-0.3, [0, 0, 255]))
            } else {
                (square(-0.3, [0, 0, 255]), square(0.3, [255, 0, 0]))
            };
            m.append(other);
            let raster = rasterize(&m, &cam);
            let surface = raster.surface(&m);
            assert!(!surface.is_empty());
            assert!(surface.colors.iter().all(|c| *c == [255, 0, 0]));
            assert!(surface.points.iter().all(|p| (p[0] - 0.3).abs() < 1e-5));
        }
    }

    #[test]
    fn surface_points_lie_on_the_mesh_and_project_back_into_their_pixel() {
        let cube = unit_cube();
        let cam = Camera::rig(5, 48).unwrap();
        let raster = rasterize(&cube, &cam);
        let proj = cam.projector();
        for at in 0..48 * 48 {
            if let Some((p, _)) = raster.hit(&cube, at) {
                let on_face = p.iter().any(|c| (c.abs() - 0.5).abs() < 1e-5);
                assert!(on_face && p.iter().all(|c| c.abs() <= 0.5 + 1e-5), "{p:?}");
                let (row, col, _) = proj.project(p).unwrap();
                assert_eq!(row * 48 + col, at);
            }
        }
    }

    #[test]
    fn rendered_views_are_dense_inside_the_silhouette() {
        let cube = unit_cube();
        let cams = Camera::set(&[5, 6, 7, 8], 32).unwrap();
        let views = render_views(&cube, &cams);
        for (v, cam) in cams.iter().enumerate() {
            let raster = rasterize(&cube, cam);
            assert_eq!(
                views.view_occupancy(v).iter().filter(|o| **o).count(),
                raster.covered()
            );
        }
        assert!(views.has_color);
    }
}
