//! Point clouds a normalized mesh yields: the fine ground truth (what the 20 rig cameras see,
//! merged on a voxel grid), and partial scans that look like mobile laser scans — the paper's
//! way (a few cameras at or above the object) and a simulated profile scanner driving past.

use crate::core::camera::{Camera, CameraError, RIG_SIZE};
use crate::core::rng::Lcg;
use crate::datagen::mesh::{bounds_of, Mesh};
use crate::datagen::raster::{rasterize, Surface};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Rig cameras at or above the object: the paper draws partials from these, never from below.
pub const PARTIAL_CAMERAS: [usize; 12] = [5, 6, 7, 8, 10, 12, 14, 16, 17, 18, 19, 20];

/// The paper's real-MLS protocol (Table 3) scans each object from four fixed cameras: in front
/// (12, on −z, 21° up), behind (10, on +z), left (17, on −x) and right (19, its mirror image
/// across the symmetry plane; the rig has no camera straight from either side).
pub const FOUR_CAMERAS: [usize; 4] = [12, 10, 17, 19];

/// Surface points seen by all 20 rig cameras at `size`², merged and thinned to one point per
/// `voxel`-sized cube. Inner structure no camera sees is never sampled. Fails on a `size` the
/// cameras do not render.
pub fn ground_truth(mesh: &Mesh, size: usize, voxel: f32) -> Result<Surface, CameraError> {
    let cameras = (1..=RIG_SIZE)
        .map(|i| Camera::rig(i, size))
        .collect::<Result<Vec<_>, _>>()?;
    let parts: Vec<Surface> = cameras
        .par_iter()
        .map(|camera| rasterize(mesh, camera).surface(mesh))
        .collect();
    let mut all = Surface::default();
    for p in parts {
        all.extend(p);
    }
    Ok(voxel_thin(&all, voxel))
}

/// Keeps the first point (in input order) of every occupied voxel, in input order.
pub fn voxel_thin(surface: &Surface, voxel: f32) -> Surface {
    if voxel <= 0.0 || surface.is_empty() {
        return surface.clone();
    }
    let (lo, hi) = bounds_of(&surface.points);
    // Cells counted from the grid's origin (a multiple of the voxel), so the partition does
    // not depend on where the points happen to start.
    let origin = lo.map(|c| (c / voxel).floor());
    let dims: [u64; 3] = std::array::from_fn(|k| ((hi[k] / voxel).floor() - origin[k]) as u64 + 1);
    let cell = |p: &[f32; 3]| -> u64 {
        let c: [u64; 3] = std::array::from_fn(|k| {
            (((p[k] / voxel).floor() - origin[k]).max(0.0) as u64).min(dims[k] - 1)
        });
        (c[0] * dims[1] + c[1]) * dims[2] + c[2]
    };
    let mut out = Surface::default();
    let keep = |i: usize, out: &mut Surface| {
        out.points.push(surface.points[i]);
        out.colors.push(surface.colors[i]);
    };
    let cells = dims[0].saturating_mul(dims[1]).saturating_mul(dims[2]);
    // A bit per cell while that stays small (the unit box at 1/256: 2 MiB), a hash set beyond.
    if cells <= 1 << 27 {
        let mut seen = vec![0u64; cells.div_ceil(64) as usize];
        for (i, p) in surface.points.iter().enumerate() {
            let c = cell(p);
            let (word, bit) = ((c / 64) as usize, 1u64 << (c % 64));
            if seen[word] & bit == 0 {
                seen[word] |= bit;
                keep(i, &mut out);
            }
        }
    } else {
        let mut seen = std::collections::HashSet::new();
        for (i, p) in surface.points.iter().enumerate() {
            if seen.insert(cell(p)) {
                keep(i, &mut out);
            }
        }
    }
    out
}

/// How a partial sample was made; saved in the manifest so every sample can be reproduced and
/// mapped back onto its ground truth.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum PartialSpec {
    /// The union of what these rig cameras see at `size`².
    Cameras { cameras: Vec<usize>, size: usize },
    /// A profile scanner on a straight path beside the object.
    Scanner {
        /// +1: the path runs on the object's +x side, −1: on its −x side.
        side: f32,
        /// From the object's centre line to the path, in normalized units.
        distance: f32,
        /// Sensor height above the object's lowest point.
        height: f32,
        /// Angle between the path and the object's length axis. The partial is written in the
        /// path's frame, so it is the object turned by −yaw: the orientation error real scans
        /// have once aligned with the road.
        yaw_deg: f32,
        /// Distance between scan lines along the path.
        line_spacing: f32,
        /// Angle between two returns of one scan line.
        angle_step_deg: f32,
        /// Standard deviation of the range noise.
        noise: f32,
    },
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum PartialKinds {
    /// Half of the samples each way.
    Both,
    /// The paper's camera subsets only.
    Cameras,
    /// The profile scanner only.
    Scanner,
    /// What one camera sees, the protocol of the paper's real-MLS experiment (Table 3): sample
    /// k through camera k mod 4 of the front, behind, left and right ones.
    SingleCamera,
    /// What one camera sees, drawn from the 12 at or above the object for each sample.
    RandomCamera,
}

/// The most points a partial sample is scanned for, about 75 times the largest default draw.
/// The scan's resolution grows with the points asked, and `--max-points 1e11` made the scanner
/// ask for 311 GB at once; [`partial`] holds its draw to this whatever the params say.
pub const MAX_PARTIAL_POINTS: usize = 10_000_000;

/// The ranges partial samples are drawn from.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PartialParams {
    pub kinds: PartialKinds,
    /// Points per partial are drawn log-uniformly from this range (approximately met).
    pub min_points: usize,
    pub max_points: usize,
    pub max_yaw_deg: f32,
    /// Range noise standard deviations are drawn from [0, this].
    pub max_noise: f32,
}

impl Default for PartialParams {
    fn default() -> Self {
        PartialParams {
            kinds: PartialKinds::Both,
            min_points: 2_000,
            max_points: 130_000,
            max_yaw_deg: 10.0,
            max_noise: 0.002,
        }
    }
}

/// Resolution a first render is made at to learn how many points a setting gives.
const PROBE_SIZE: usize = 128;

/// Draws partial sample `sample`'s settings from `rng` and scans it (the index picks the camera
/// of [`PartialKinds::SingleCamera`]).
pub fn partial(
    mesh: &Mesh,
    params: &PartialParams,
    sample: usize,
    rng: &mut Lcg,
) -> (PartialSpec, Surface) {
    let target = rng
        .log_range(
            params.min_points as f64,
            params.max_points.max(params.min_points) as f64,
        )
        .min(MAX_PARTIAL_POINTS as f64);
    let use_cameras = match params.kinds {
        PartialKinds::Cameras | PartialKinds::SingleCamera | PartialKinds::RandomCamera => true,
        PartialKinds::Scanner => false,
        PartialKinds::Both => rng.chance(0.5),
    };
    let (mut spec, probe) = if use_cameras {
        let cameras: Vec<usize> = match params.kinds {
            PartialKinds::SingleCamera => vec![FOUR_CAMERAS[sample % FOUR_CAMERAS.len()]],
            kinds => {
                let count = match kinds {
                    PartialKinds::RandomCamera => 1,
                    _ => 1 + rng.below(3),
                };
                let mut pool = PARTIAL_CAMERAS.to_vec();
                (0..count)
                    .map(|_| pool.remove(rng.below(pool.len())))
                    .collect()
            }
        };
        let spec = PartialSpec::Cameras {
            cameras,
            size: PROBE_SIZE,
        };
        let probe = scan(mesh, &spec, rng).len();
        (spec, probe)
    } else {
        let (lo, hi) = mesh.bounds();
        let side = if rng.chance(0.5) { 1.0 } else { -1.0 };
        let yaw_deg = rng.range(-1.0, 1.0) as f32 * params.max_yaw_deg;
        let yaw = yaw_deg.to_radians();
        let across = lateral([yaw.sin(), 0.0, yaw.cos()]);
        let reach = mesh
            .positions
            .iter()
            .map(|p| side * (p[0] * across[0] + p[2] * across[2]))
            .fold(0.0f32, f32::max);
        let spec = PartialSpec::Scanner {
            side,
            distance: reach + rng.range(0.3, 1.5) as f32,
            // Sensor heights of 2–3 m put it just above a car's roof and near a bus's.
            height: rng.range(0.8, 1.8) as f32 * (hi[1] - lo[1]),
            yaw_deg,
            line_spacing: 0.02,
            angle_step_deg: 0.5,
            noise: rng.range(0.0, params.max_noise as f64) as f32,
        };
        let probe = scan(mesh, &spec, rng).len();
        (spec, probe)
    };
    // Points grow with the square of the resolution.
    let k = (probe.max(1) as f64 / target).sqrt();
    match &mut spec {
        PartialSpec::Cameras { size, .. } => {
            *size = ((PROBE_SIZE as f64 / k).round() as usize).clamp(16, 2048);
        }
        PartialSpec::Scanner {
            line_spacing,
            angle_step_deg,
            ..
        } => {
            *line_spacing = (*line_spacing as f64 * k) as f32;
            *angle_step_deg = (*angle_step_deg as f64 * k) as f32;
        }
    }
    let surface = scan(mesh, &spec, rng);
    (spec, surface)
}

/// Scans `mesh` as `spec` says; `rng` draws the range noise.
pub fn scan(mesh: &Mesh, spec: &PartialSpec, rng: &mut Lcg) -> Surface {
    match spec {
        PartialSpec::Cameras { cameras, size } => {
            let mut out = Surface::default();
            for &i in cameras {
                let camera = Camera::rig(i, *size).expect("partial cameras are rig cameras");
                out.extend(rasterize(mesh, &camera).surface(mesh));
            }
            out
        }
        PartialSpec::Scanner { .. } => profile_scan(mesh, spec, rng),
    }
}

/// The scanner's path frame: `along` the path, `out` horizontal from the path towards the
/// object, `origin` the sensor where the path passes the object's centre.
struct ScanPath {
    origin: [f32; 3],
    along: [f32; 3],
    out: [f32; 3],
}

impl ScanPath {
    fn of(spec: &PartialSpec, mesh: &Mesh) -> Option<ScanPath> {
        let PartialSpec::Scanner {
            side,
            distance,
            height,
            yaw_deg,
            ..
        } = *spec
        else {
            return None;
        };
        let yaw = yaw_deg.to_radians();
        let along = [yaw.sin(), 0.0, yaw.cos()];
        let across = lateral(along);
        let bottom = mesh.bounds().0[1];
        Some(ScanPath {
            origin: [
                side * distance * across[0],
                bottom + height,
                side * distance * across[2],
            ],
            along,
            out: across.map(|c| -side * c),
        })
    }

    /// (along-track position, elevation angle) of a point.
    fn coordinates(&self, p: [f32; 3]) -> (f32, f32) {
        let d = [0, 1, 2].map(|i| p[i] - self.origin[i]);
        let u = dot(d, self.along);
        let a = dot(d, self.out);
        let b = d[1];
        (u, b.atan2(a))
    }

    /// The point in the path's frame: x across the path, y up, z along it (a turn about y).
    fn to_path_frame(&self, p: [f32; 3]) -> [f32; 3] {
        [dot(p, lateral(self.along)), p[1], dot(p, self.along)]
    }
}

/// The horizontal unit vector across a path running along `along`.
fn lateral(along: [f32; 3]) -> [f32; 3] {
    [along[2], 0.0, -along[0]]
}

impl PartialSpec {
    /// The protocol's name in reports: "cameras" or "scanner".
    pub fn protocol(&self) -> &'static str {
        match self {
            PartialSpec::Cameras { .. } => "cameras",
            PartialSpec::Scanner { .. } => "scanner",
        }
    }

    /// Maps a point of this partial back into the object's (ground truth's) frame.
    pub fn to_object_frame(&self, q: [f32; 3]) -> [f32; 3] {
        match *self {
            PartialSpec::Cameras { .. } => q,
            PartialSpec::Scanner { yaw_deg, .. } => {
                let yaw = yaw_deg.to_radians();
                let along = [yaw.sin(), 0.0, yaw.cos()];
                let across = lateral(along);
                [0, 1, 2]
                    .map(|k| q[0] * across[k] + q[2] * along[k] + if k == 1 { q[1] } else { 0.0 })
            }
        }
    }

    /// A cloud completed from this partial, in the object's frame at the precision the
    /// dataset stores (`f32`), as `mvpcc eval --data` scores it.
    pub fn points_to_object_frame(&self, points: &[[f64; 3]]) -> Vec<[f64; 3]> {
        points
            .iter()
            .map(|p| self.to_object_frame(p.map(|c| c as f32)).map(f64::from))
            .collect()
    }
}

fn dot(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn cross(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// Scan lines perpendicular to the path, one every `line_spacing`, each sweeping the elevation
/// angle in `angle_step_deg` steps; every ray returns its first hit, moved along the ray by
/// Gaussian range noise. Surfaces facing away from the path (the far flank) and the underside
/// are never hit.
fn profile_scan(mesh: &Mesh, spec: &PartialSpec, rng: &mut Lcg) -> Surface {
    let PartialSpec::Scanner {
        line_spacing,
        angle_step_deg,
        noise,
        ..
    } = *spec
    else {
        unreachable!("profile_scan is called for scanner specs")
    };
    let path = ScanPath::of(spec, mesh).expect("a scanner spec");
    let coords: Vec<(f32, f32)> = mesh
        .positions
        .iter()
        .map(|&p| path.coordinates(p))
        .collect();
    let rays = RayGrid::spanning(&coords, &path, line_spacing, angle_step_deg.to_radians());
    let hits = rays.first_hits(mesh, &coords, &path);
    let mut out = Surface::default();
    for j in 0..rays.lines {
        for (i, dir) in rays.dirs.iter().enumerate() {
            let Some(hit) = hits[j * rays.angles + i] else {
                continue;
            };
            let range = hit.t + noise * rng.gauss() as f32;
            let origin = rays.origin(&path, j);
            let p = [0, 1, 2].map(|k| origin[k] + range * dir[k]);
            let [b1, b2] = hit.bary;
            out.points.push(path.to_path_frame(p));
            out.colors
                .push(mesh.color_at(hit.triangle, [1.0 - b1 - b2, b1, b2]));
        }
    }
    out
}

/// A mobile scanner driving a straight street: a profile scanner on a path along +z at `x`,
/// `height` above y = 0, each scan line a vertical sweep across the path to both sides.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct StreetScanner {
    pub x: f32,
    pub height: f32,
    /// Distance between scan lines along the path.
    pub line_spacing: f32,
    /// Angle between two returns of one scan line.
    pub angle_step_deg: f32,
    /// Standard deviation of the range noise.
    pub noise: f32,
}

/// What a street scan returns: each point, its colour and the triangle it hit.
#[derive(Debug, Clone, Default)]
pub struct StreetScan {
    pub points: Vec<[f32; 3]>,
    pub colors: Vec<[u8; 3]>,
    pub triangles: Vec<usize>,
}

/// Scans `mesh` (y up) with `scanner`: each side of the path is swept as the profile scanner
/// sweeps one side of an object, so the nearest surface along each ray occludes the rest.
pub fn scan_street(mesh: &Mesh, scanner: &StreetScanner, rng: &mut Lcg) -> StreetScan {
    let mut out = StreetScan::default();
    for side in [1.0f32, -1.0] {
        let kept: Vec<usize> = (0..mesh.triangles.len())
            .filter(|&t| {
                let centroid: f32 = mesh.triangles[t]
                    .iter()
                    .map(|&v| mesh.positions[v as usize][0])
                    .sum::<f32>()
                    / 3.0;
                (centroid - scanner.x) * side > 0.0
            })
            .collect();
        if kept.is_empty() {
            continue;
        }
        let part = subset(mesh, &kept);
        let path = ScanPath {
            origin: [scanner.x, scanner.height, 0.0],
            along: [0.0, 0.0, 1.0],
            out: [side, 0.0, 0.0],
        };
        let coords: Vec<(f32, f32)> = part
            .positions
            .iter()
            .map(|&p| path.coordinates(p))
            .collect();
        let rays = RayGrid::spanning(
            &coords,
            &path,
            scanner.line_spacing,
            scanner.angle_step_deg.to_radians(),
        );
        let hits = rays.first_hits(&part, &coords, &path);
        for j in 0..rays.lines {
            for (i, dir) in rays.dirs.iter().enumerate() {
                let Some(hit) = hits[j * rays.angles + i] else {
                    continue;
                };
                let range = hit.t + scanner.noise * rng.gauss() as f32;
                let origin = rays.origin(&path, j);
                let [b1, b2] = hit.bary;
                out.points
                    .push([0, 1, 2].map(|k| origin[k] + range * dir[k]));
                out.colors
                    .push(part.color_at(hit.triangle, [1.0 - b1 - b2, b1, b2]));
                out.triangles.push(kept[hit.triangle]);
            }
        }
    }
    out
}

/// The triangles `kept` of `mesh` with the vertices they use, their materials and colours.
fn subset(mesh: &Mesh, kept: &[usize]) -> Mesh {
    let mut index = vec![u32::MAX; mesh.positions.len()];
    let mut part = Mesh {
        materials: mesh.materials.clone(),
        ..Mesh::default()
    };
    for &t in kept {
        let tri = mesh.triangles[t].map(|v| {
            let v = v as usize;
            if index[v] == u32::MAX {
                index[v] = part.positions.len() as u32;
                part.positions.push(mesh.positions[v]);
            }
            index[v]
        });
        part.triangles.push(tri);
        part.material_of.push(mesh.material_of[t]);
    }
    part.corner_uv = mesh
        .corner_uv
        .as_ref()
        .map(|uv| kept.iter().map(|&t| uv[t]).collect());
    part.vertex_colors = mesh.vertex_colors.as_ref().map(|colors| {
        let mut out = vec![[1.0; 3]; part.positions.len()];
        for (v, &at) in index.iter().enumerate() {
            if at != u32::MAX {
                out[at as usize] = colors[v];
            }
        }
        out
    });
    part
}

/// The scanner's rays over the mesh's extent: `lines` scan lines along the path (`u`), each
/// with one ray per elevation step (`t`), centred in their cells.
struct RayGrid {
    u0: f32,
    t0: f32,
    line_spacing: f32,
    step: f32,
    lines: usize,
    angles: usize,
    /// One ray direction per elevation step, shared by every line and triangle.
    dirs: Vec<[f32; 3]>,
}

/// A ray's nearest hit: its distance along the ray, the triangle and the barycentric
/// coordinates of the second and third corners.
#[derive(Clone, Copy)]
struct Hit {
    t: f32,
    triangle: usize,
    bary: [f32; 2],
}

impl RayGrid {
    fn spanning(coords: &[(f32, f32)], path: &ScanPath, line_spacing: f32, step: f32) -> Self {
        let (mut u0, mut u1, mut t0, mut t1) = (
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::INFINITY,
            f32::NEG_INFINITY,
        );
        for &(u, t) in coords {
            u0 = u0.min(u);
            u1 = u1.max(u);
            t0 = t0.min(t);
            t1 = t1.max(t);
        }
        let lines = (((u1 - u0) / line_spacing).ceil() as usize).max(1);
        let angles = (((t1 - t0) / step).ceil() as usize).max(1);
        let up = [0.0, 1.0, 0.0];
        let dirs = (0..angles)
            .map(|i| {
                let (sin, cos) = (t0 + (i as f32 + 0.5) * step).sin_cos();
                [0, 1, 2].map(|k| cos * path.out[k] + sin * up[k])
            })
            .collect();
        RayGrid {
            u0,
            t0,
            line_spacing,
            step,
            lines,
            angles,
            dirs,
        }
    }

    /// Where scan line `j` leaves the path.
    fn origin(&self, path: &ScanPath, j: usize) -> [f32; 3] {
        let u = self.u0 + (j as f32 + 0.5) * self.line_spacing;
        [0, 1, 2].map(|k| path.origin[k] + u * path.along[k])
    }

    /// The nearest hit of every ray (line-major), none where a ray hits nothing. Each triangle
    /// is tried only against the rays whose centres lie within its extent in (u, t).
    fn first_hits(&self, mesh: &Mesh, coords: &[(f32, f32)], path: &ScanPath) -> Vec<Option<Hit>> {
        let mut hits: Vec<Option<Hit>> = vec![None; self.lines * self.angles];
        for (ti, tri) in mesh.triangles.iter().enumerate() {
            let corners = tri.map(|i| coords[i as usize]);
            // The rays of one axis whose centres lie within the corners' values on it.
            let span = |values: [f32; 3], origin: f32, cell: f32, count: usize| {
                let lo = values[0].min(values[1]).min(values[2]);
                let hi = values[0].max(values[1]).max(values[2]);
                let first = ((lo - origin) / cell - 0.5).ceil().max(0.0) as usize;
                let last = (((hi - origin) / cell - 0.5).floor() as isize).min(count as isize - 1);
                (last >= first as isize).then_some(first..=last as usize)
            };
            let lines = span(corners.map(|c| c.0), self.u0, self.line_spacing, self.lines);
            let angles = span(corners.map(|c| c.1), self.t0, self.step, self.angles);
            let (Some(lines), Some(angles)) = (lines, angles) else {
                continue;
            };
            let [p0, p1, p2] = tri.map(|i| mesh.positions[i as usize]);
            let e1 = [0, 1, 2].map(|k| p1[k] - p0[k]);
            let e2 = [0, 1, 2].map(|k| p2[k] - p0[k]);
            for j in lines {
                let o = self.origin(path, j);
                let s = [0, 1, 2].map(|k| o[k] - p0[k]);
                for i in angles.clone() {
                    let Some((t, bary)) = ray_triangle(self.dirs[i], s, e1, e2) else {
                        continue;
                    };
                    let best = &mut hits[j * self.angles + i];
                    if best.map_or(t < f32::INFINITY, |b| t < b.t) {
                        *best = Some(Hit {
                            t,
                            triangle: ti,
                            bary,
                        });
                    }
                }
            }
        }
        hits
    }
}

/// Möller–Trumbore: the distance along `dir` at which a ray from a triangle's first corner
/// offset by `s` (origin − corner) meets the triangle with edges `e1`, `e2`, and the hit's
/// barycentric coordinates; none behind the origin, outside the triangle or parallel to it.
fn ray_triangle(dir: [f32; 3], s: [f32; 3], e1: [f32; 3], e2: [f32; 3]) -> Option<(f32, [f32; 2])> {
    let pv = cross(dir, e2);
    let det = dot(e1, pv);
    if det.abs() < 1e-12 {
        return None;
    }
    let inv = 1.0 / det;
    let b1 = dot(s, pv) * inv;
    if !(0.0..=1.0).contains(&b1) {
        return None;
    }
    let qv = cross(s, e1);
    let b2 = dot(dir, qv) * inv;
    if b2 < 0.0 || b1 + b2 > 1.0 {
        return None;
    }
    let t = dot(e2, qv) * inv;
    (t > 0.0).then_some((t, [b1, b2]))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::datagen::mesh::Material;
    use crate::datagen::synth::{synthesize, Category};

    /// A UV sphere of radius `r` with `n`×2n facets.
    fn sphere(r: f32, n: usize) -> Mesh {
        let mut m = Mesh {
            materials: vec![Material::plain("s", [10, 200, 30])],
            ..Mesh::default()
        };
        for i in 0..=n {
            let t = i as f32 / n as f32 * std::f32::consts::PI;
            for j in 0..2 * n {
                let p = j as f32 / (2 * n) as f32 * std::f32::consts::TAU;
                m.positions
                    .push([r * t.sin() * p.cos(), r * t.cos(), r * t.sin() * p.sin()]);
            }
        }
        for i in 0..n {
            for j in 0..2 * n {
                let a = (i * 2 * n + j) as u32;
                let b = (i * 2 * n + (j + 1) % (2 * n)) as u32;
                let (c, d) = (a + 2 * n as u32, b + 2 * n as u32);
                m.triangles.push([a, b, d]);
                m.triangles.push([a, d, c]);
                m.material_of.extend([0, 0]);
            }
        }
        m
    }

    fn normalized_car(seed: u64) -> Mesh {
        let mut m = synthesize(0, seed, &[Category::Car.into()]).mesh;
        m.normalize(
            crate::datagen::mesh::SignedAxis::PLUS_Y,
            crate::datagen::mesh::SignedAxis::MINUS_Z,
        )
        .unwrap();
        m
    }

    #[test]
    fn ground_truth_of_a_sphere_lies_on_it_and_covers_it() {
        let n = 64;
        let m = sphere(0.4, n);
        let gt = ground_truth(&m, 128, 0.01).unwrap();
        // Facets span π/n in latitude and longitude: a facet's middle dips at most
        // r(1 − cos²(π/2n)) inside the sphere.
        let half = (std::f32::consts::PI / (2 * n) as f32).cos();
        let sag = 0.4 * (1.0 - half * half) + 1e-5;
        for p in &gt.points {
            let r = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
            assert!(r <= 0.4 + 1e-5 && r >= 0.4 - sag, "{r}");
        }
        assert!(gt.colors.iter().all(|c| *c == [10, 200, 30]));
        // One point per 1 cm voxel over the sphere's area: ≈ 4πr² / voxel², within a factor.
        let expected = 4.0 * std::f32::consts::PI * 0.16 / 1e-4;
        assert!(
            (gt.len() as f32) > 0.8 * expected && (gt.len() as f32) < 2.0 * expected,
            "{} vs {expected}",
            gt.len()
        );
        // Every direction is covered: no 10° cap without points.
        for k in 0..200 {
            let (t, p) = ((k as f32 * 0.618).fract() * 2.0 - 1.0, k as f32 * 2.4);
            let d = [
                (1.0 - t * t).sqrt() * p.cos(),
                t,
                (1.0 - t * t).sqrt() * p.sin(),
            ];
            let best = gt
                .points
                .iter()
                .map(|q| (q[0] * d[0] + q[1] * d[1] + q[2] * d[2]) / 0.4)
                .fold(-1.0f32, f32::max);
            assert!(best > 10f32.to_radians().cos(), "no point near {d:?}");
        }
    }

    #[test]
    fn voxel_thinning_keeps_one_point_per_voxel() {
        let s = Surface {
            points: vec![
                [0.001, 0.0, 0.0],
                [0.002, 0.0, 0.0],
                [0.02, 0.0, 0.0],
                [-0.001, 0.0, 0.0],
            ],
            colors: vec![[1; 3], [2; 3], [3; 3], [4; 3]],
        };
        let t = voxel_thin(&s, 0.01);
        assert_eq!(t.colors, vec![[1; 3], [3; 3], [4; 3]]);
        assert_eq!(voxel_thin(&s, 0.0), s);
        // A grid too large for the bitset (5·10⁹ cells) goes through the hash set.
        let wide = Surface {
            points: vec![[0.00102, 0.0, 0.0], [0.00108, 0.0, 0.0], [0.02, 0.5, 0.5]],
            colors: vec![[1; 3], [2; 3], [3; 3]],
        };
        assert_eq!(voxel_thin(&wide, 1e-4).colors, vec![[1; 3], [3; 3]]);
    }

    /// The distance from each partial point to the nearest ground-truth point.
    fn distances_to(gt: &Surface, points: &[[f32; 3]]) -> Vec<f32> {
        let gt: Vec<[f64; 3]> = gt.points.iter().map(|p| p.map(|c| c as f64)).collect();
        let queries: Vec<[f64; 3]> = points.iter().map(|p| p.map(|c| c as f64)).collect();
        crate::core::knn::knn_distances(&gt, &queries, 1)
            .into_iter()
            .map(|d| d as f32)
            .collect()
    }

    #[test]
    fn camera_partials_are_subsets_of_the_ground_truth() {
        let m = normalized_car(3);
        let gt = ground_truth(&m, 512, 1.0 / 256.0).unwrap();
        let spec = PartialSpec::Cameras {
            cameras: vec![6, 19],
            size: 128,
        };
        let part = scan(&m, &spec, &mut Lcg::new(0));
        assert!(part.len() > 3000, "{}", part.len());
        let d = distances_to(&gt, &part.points);
        let far = d.iter().filter(|&&d| d > 0.01).count();
        assert!(
            far == 0,
            "{far} of {} partial points are > 1 cm from the ground truth",
            d.len()
        );
    }

    #[test]
    fn scanner_partials_see_one_side_and_match_the_ground_truth_within_noise() {
        let m = normalized_car(4);
        let gt = ground_truth(&m, 512, 1.0 / 256.0).unwrap();
        let noise = 0.002;
        let spec = PartialSpec::Scanner {
            side: 1.0,
            distance: 0.9,
            height: 0.4,
            yaw_deg: 8.0,
            line_spacing: 0.006,
            angle_step_deg: 0.3,
            noise,
        };
        let part = scan(&m, &spec, &mut Lcg::new(1));
        assert!(part.len() > 2000, "{}", part.len());
        let back: Vec<[f32; 3]> = part
            .points
            .iter()
            .map(|&q| spec.to_object_frame(q))
            .collect();
        let d = distances_to(&gt, &back);
        let mean = d.iter().sum::<f32>() / d.len() as f32;
        let far = d.iter().filter(|&&d| d > 5.0 * noise + 0.006).count();
        assert!(mean < 2.0 * noise + 0.003, "mean distance {mean}");
        assert!(
            far * 1000 < d.len(),
            "{far} of {} points far from the ground truth",
            d.len()
        );
        // The far flank (its lower half: the roof is seen across) and the underside stay unseen.
        let (lo, hi) = m.bounds();
        let far_flank = back
            .iter()
            .filter(|p| p[0] < lo[0] + 0.04 && p[1] < (lo[1] + hi[1]) / 2.0)
            .count();
        let underside = back
            .iter()
            .filter(|p| p[1] < lo[1] + 0.01 && p[0].abs() < 0.05)
            .count();
        assert!(far_flank * 100 < back.len(), "{far_flank} on the far flank");
        assert_eq!(underside, 0);
        // In the path's frame the object is turned by the yaw: its side is not parallel to z.
        assert_ne!(back, part.points);
    }

    #[test]
    fn partials_hit_their_point_targets_and_reproduce_from_their_seed() {
        let m = normalized_car(5);
        let params = PartialParams::default();
        let mut counts = Vec::new();
        for seed in 0..6 {
            let (spec, a) = partial(&m, &params, 0, &mut Lcg::new(seed));
            let (spec_b, b) = partial(&m, &params, 0, &mut Lcg::new(seed));
            assert_eq!((&spec, &a), (&spec_b, &b));
            counts.push((spec, a.len()));
        }
        assert!(counts
            .iter()
            .any(|c| matches!(c.0, PartialSpec::Cameras { .. })));
        assert!(counts
            .iter()
            .any(|c| matches!(c.0, PartialSpec::Scanner { .. })));
        for (spec, n) in &counts {
            assert!((1_000..200_000).contains(n), "{spec:?}: {n} points");
        }
        // A narrow target range is met within a factor of 1.5.
        let narrow = PartialParams {
            min_points: 10_000,
            max_points: 10_000,
            ..PartialParams::default()
        };
        for seed in 0..4 {
            let (spec, s) = partial(&m, &narrow, 0, &mut Lcg::new(seed));
            assert!((6_600..15_000).contains(&s.len()), "{spec:?}: {}", s.len());
        }
    }

    #[test]
    fn the_single_camera_protocol_takes_front_behind_left_and_right_in_turn() {
        let m = normalized_car(5);
        let params = PartialParams {
            kinds: PartialKinds::SingleCamera,
            ..PartialParams::default()
        };
        let cameras: Vec<Vec<usize>> = (0..8)
            .map(
                |k| match partial(&m, &params, k, &mut Lcg::new(k as u64)).0 {
                    PartialSpec::Cameras { cameras, .. } => cameras,
                    spec => panic!("{spec:?}"),
                },
            )
            .collect();
        let turn = FOUR_CAMERAS.map(|c| vec![c]);
        assert_eq!(cameras, [turn.clone(), turn].concat());
        // Front and behind on the length's axis, left and right mirror images across x = 0.
        let centre = |i| Camera::rig(i, 64).unwrap().center();
        let [front, behind, left, right] = FOUR_CAMERAS.map(centre);
        assert!(
            front[0].abs() < 1e-9 && front[2] < 0.0 && behind[0].abs() < 1e-9 && behind[2] > 0.0
        );
        assert!(left[0] < 0.0 && (left[0] + right[0]).abs() < 1e-9 && left[2] == right[2]);
    }

    #[test]
    fn the_random_camera_protocol_sees_through_one_camera_of_the_rig() {
        let m = normalized_car(5);
        let params = PartialParams {
            kinds: PartialKinds::RandomCamera,
            ..PartialParams::default()
        };
        let mut seen = std::collections::BTreeSet::new();
        for seed in 0..8 {
            let (spec, points) = partial(&m, &params, 0, &mut Lcg::new(seed));
            let PartialSpec::Cameras { cameras, .. } = spec else {
                panic!("{spec:?}");
            };
            assert_eq!(cameras.len(), 1);
            assert!(PARTIAL_CAMERAS.contains(&cameras[0]) && !points.is_empty());
            seen.insert(cameras[0]);
        }
        assert!(seen.len() > 2, "cameras drawn: {seen:?}");
    }
}
