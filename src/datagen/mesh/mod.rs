//! Coloured triangle meshes: what `mvpcc prepare` renders its training data from. Readers for
//! OBJ + MTL (ShapeNet's format), PLY meshes and glTF/GLB; an OBJ writer for `mvpcc synth`.

mod gltf;
mod obj;
mod ply;

pub use obj::write_obj;

use image::RgbImage;
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use thiserror::Error;

/// Extensions `read_mesh` understands.
pub const MESH_EXTENSIONS: [&str; 4] = ["obj", "ply", "gltf", "glb"];

#[derive(Debug, Error)]
pub enum MeshError {
    #[error("{}: {problem}", path.display())]
    Read { path: PathBuf, problem: String },
    #[error("{}: texture {} is missing or unreadable ({problem})", path.display(), texture.display())]
    Texture {
        path: PathBuf,
        texture: PathBuf,
        problem: String,
    },
    #[error("{}: material library is missing or unreadable ({problem})", path.display())]
    Materials { path: PathBuf, problem: String },
    #[error("{}: no triangles", path.display())]
    NoFaces { path: PathBuf },
    #[error("{}: {count} vertices have NaN or infinite coordinates", path.display())]
    NonFinite { path: PathBuf, count: usize },
    #[error("{}: {triangles} triangles, more than the limit of {limit}", path.display())]
    TooLarge {
        path: PathBuf,
        triangles: usize,
        limit: usize,
    },
    #[error("{}: all triangles are degenerate (zero area)", path.display())]
    Degenerate { path: PathBuf },
    #[error("{}: unsupported mesh extension (expected obj, ply, gltf or glb)", path.display())]
    Unsupported { path: PathBuf },
}

/// A surface material: a colour, optionally modulated by a texture.
#[derive(Debug, Clone)]
pub struct Material {
    pub name: String,
    /// sRGB in [0, 1].
    pub color: [f32; 3],
    pub texture: Option<Arc<RgbImage>>,
}

impl Material {
    pub fn plain(name: &str, rgb: [u8; 3]) -> Material {
        Material {
            name: name.to_string(),
            color: rgb.map(|c| c as f32 / 255.0),
            texture: None,
        }
    }
}

/// Triangles with a material each, optional texture coordinates per triangle corner (OBJ's
/// convention: v = 0 at the image's bottom) and optional per-vertex colours.
#[derive(Debug, Clone, Default)]
pub struct Mesh {
    pub positions: Vec<[f32; 3]>,
    pub triangles: Vec<[u32; 3]>,
    /// Index into `materials`, one per triangle.
    pub material_of: Vec<u32>,
    pub materials: Vec<Material>,
    pub corner_uv: Option<Vec<[[f32; 2]; 3]>>,
    /// sRGB in [0, 1], one per vertex.
    pub vertex_colors: Option<Vec<[f32; 3]>>,
}

/// What `check` found besides errors, reported per model in the manifest.
#[derive(Debug, Clone, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct MeshStats {
    pub vertices: usize,
    pub triangles: usize,
    /// Zero-area triangles (they never cover a pixel).
    pub degenerate: usize,
    /// Edges with one triangle: openings in the surface.
    pub boundary_edges: usize,
    /// Edges with three or more triangles. Common in ShapeNet and harmless for rendering, so
    /// reported rather than refused.
    pub non_manifold_edges: usize,
}

/// One of the six axis directions, as typed on the command line (`y`, `+y`, `-z`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SignedAxis {
    pub axis: usize,
    pub negative: bool,
}

impl SignedAxis {
    pub const PLUS_Y: SignedAxis = SignedAxis {
        axis: 1,
        negative: false,
    };
    pub const MINUS_Z: SignedAxis = SignedAxis {
        axis: 2,
        negative: true,
    };

    fn vector(self) -> [f32; 3] {
        let mut v = [0.0; 3];
        v[self.axis] = if self.negative { -1.0 } else { 1.0 };
        v
    }
}

impl std::str::FromStr for SignedAxis {
    type Err = String;
    fn from_str(text: &str) -> Result<Self, String> {
        let (negative, name) = match text.strip_prefix('-') {
            Some(rest) => (true, rest),
            None => (false, text.strip_prefix('+').unwrap_or(text)),
        };
        let axis = match name {
            "x" => 0,
            "y" => 1,
            "z" => 2,
            _ => return Err(format!("'{text}' is not an axis (x, y, z, -x, -y, -z)")),
        };
        Ok(SignedAxis { axis, negative })
    }
}

/// Which way a mesh's front points: an axis, or `auto` (the longer horizontal side of its box
/// is the length, which end is the front left undecided) for collections that mix conventions.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Forward {
    Axis(SignedAxis),
    Auto,
}

impl Forward {
    /// The axis the front points along in `mesh` whose up axis is `up`: for `auto` the longer
    /// of the two horizontal sides of its box, as its negative direction (ShapeNet's −z is
    /// negative too).
    pub fn resolve(self, mesh: &Mesh, up: SignedAxis) -> SignedAxis {
        match self {
            Forward::Axis(axis) => axis,
            Forward::Auto => {
                let (lo, hi) = mesh.bounds();
                let axis = (0..3)
                    .filter(|&a| a != up.axis)
                    .max_by(|&a, &b| (hi[a] - lo[a]).total_cmp(&(hi[b] - lo[b])))
                    .unwrap_or((up.axis + 1) % 3);
                SignedAxis {
                    axis,
                    negative: true,
                }
            }
        }
    }
}

impl std::str::FromStr for Forward {
    type Err = String;
    fn from_str(text: &str) -> Result<Self, String> {
        match text {
            "auto" => Ok(Forward::Auto),
            _ => text
                .parse()
                .map(Forward::Axis)
                .map_err(|e: String| format!("{e}, or auto")),
        }
    }
}

impl std::fmt::Display for Forward {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Forward::Axis(axis) => axis.fmt(f),
            Forward::Auto => f.write_str("auto"),
        }
    }
}

impl std::fmt::Display for SignedAxis {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let sign = if self.negative { "-" } else { "" };
        write!(f, "{sign}{}", ["x", "y", "z"][self.axis])
    }
}

/// Reading options a user can change.
#[derive(Debug, Clone, Copy)]
pub struct ReadOptions {
    /// Missing MTL files or textures fall back to the material colour (grey without an MTL)
    /// instead of failing the mesh.
    pub allow_missing_materials: bool,
}

/// Reads a mesh; the format comes from the extension.
pub fn read_mesh(path: &Path, options: ReadOptions) -> Result<Mesh, MeshError> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(|e| e.to_ascii_lowercase());
    match ext.as_deref() {
        Some("obj") => obj::read(path, options),
        Some("ply") => ply::read(path),
        Some("gltf") | Some("glb") => gltf::read(path),
        _ => Err(MeshError::Unsupported {
            path: path.to_path_buf(),
        }),
    }
}

/// Decodes a texture once per file, however many materials use it.
#[derive(Default)]
struct TextureCache(HashMap<PathBuf, Arc<RgbImage>>);

impl TextureCache {
    fn load(&mut self, path: &Path) -> Result<Arc<RgbImage>, String> {
        if let Some(t) = self.0.get(path) {
            return Ok(t.clone());
        }
        let image = image::ImageReader::open(path)
            .map_err(|e| e.to_string())?
            .with_guessed_format()
            .map_err(|e| e.to_string())?
            .decode()
            .map_err(|e| e.to_string())?
            .into_rgb8();
        if image.width() == 0 || image.height() == 0 {
            return Err("empty image".into());
        }
        let image = Arc::new(image);
        self.0.insert(path.to_path_buf(), image.clone());
        Ok(image)
    }
}

fn edge_key(a: u32, b: u32) -> u64 {
    let (lo, hi) = if a < b { (a, b) } else { (b, a) };
    ((lo as u64) << 32) | hi as u64
}

impl Mesh {
    /// Refuses meshes nothing useful can be rendered from, and counts the defects that do not
    /// stop rendering.
    pub fn check(&self, path: &Path, max_triangles: usize) -> Result<MeshStats, MeshError> {
        let path = path.to_path_buf();
        if self.triangles.is_empty() {
            return Err(MeshError::NoFaces { path });
        }
        if self.triangles.len() > max_triangles {
            return Err(MeshError::TooLarge {
                path,
                triangles: self.triangles.len(),
                limit: max_triangles,
            });
        }
        let non_finite = self
            .positions
            .iter()
            .filter(|p| p.iter().any(|c| !c.is_finite()))
            .count();
        if non_finite > 0 {
            return Err(MeshError::NonFinite {
                path,
                count: non_finite,
            });
        }
        let degenerate = (0..self.triangles.len())
            .filter(|&t| self.area(t) <= 0.0)
            .count();
        if degenerate == self.triangles.len() {
            return Err(MeshError::Degenerate { path });
        }
        let mut edges: Vec<u64> = self
            .triangles
            .iter()
            .flat_map(|t| {
                [
                    edge_key(t[0], t[1]),
                    edge_key(t[1], t[2]),
                    edge_key(t[2], t[0]),
                ]
            })
            .collect();
        edges.sort_unstable();
        let (mut boundary_edges, mut non_manifold_edges) = (0, 0);
        for run in edges.chunk_by(|a, b| a == b) {
            match run.len() {
                1 => boundary_edges += 1,
                2 => {}
                _ => non_manifold_edges += 1,
            }
        }
        Ok(MeshStats {
            vertices: self.positions.len(),
            triangles: self.triangles.len(),
            degenerate,
            boundary_edges,
            non_manifold_edges,
        })
    }

    /// Twice the area of triangle `t`.
    pub fn area(&self, t: usize) -> f32 {
        let [a, b, c] = self.triangles[t].map(|i| self.positions[i as usize]);
        let u = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
        let v = [c[0] - a[0], c[1] - a[1], c[2] - a[2]];
        let n = [
            u[1] * v[2] - u[2] * v[1],
            u[2] * v[0] - u[0] * v[2],
            u[0] * v[1] - u[1] * v[0],
        ];
        (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt()
    }

    /// Rotates the mesh so `up` becomes +y and `forward` −z (the dataset's convention: length
    /// along z, bonnet towards −z), then centres its box and scales its longest side to 1.
    /// Returns the scale applied.
    pub fn normalize(&mut self, up: SignedAxis, forward: SignedAxis) -> Result<f32, String> {
        if up.axis == forward.axis {
            return Err(format!(
                "--up {up} and --forward {forward} must be different axes"
            ));
        }
        let u = up.vector();
        let f = forward.vector();
        let uxf = [
            u[1] * f[2] - u[2] * f[1],
            u[2] * f[0] - u[0] * f[2],
            u[0] * f[1] - u[1] * f[0],
        ];
        // Rows map u to +y and f to −z; the first row keeps the rotation proper.
        let rows = [uxf.map(|c| -c), u, f.map(|c| -c)];
        for p in &mut self.positions {
            *p = rows.map(|r| r[0] * p[0] + r[1] * p[1] + r[2] * p[2]);
        }
        let (lo, hi) = self.bounds();
        let longest = (0..3).map(|i| hi[i] - lo[i]).fold(0.0, f32::max);
        if !(longest > 0.0 && longest.is_finite()) {
            return Err("the mesh has no extent".into());
        }
        let center: [f32; 3] = std::array::from_fn(|i| (lo[i] + hi[i]) / 2.0);
        let scale = 1.0 / longest;
        for p in &mut self.positions {
            *p = std::array::from_fn(|i| (p[i] - center[i]) * scale);
        }
        Ok(scale)
    }

    /// Bounding box `(min, max)`.
    pub fn bounds(&self) -> ([f32; 3], [f32; 3]) {
        bounds_of(&self.positions)
    }

    /// The surface colour of triangle `t` at barycentric weights `b` (texture, else vertex
    /// colours, times the material colour), as 8-bit sRGB.
    pub fn color_at(&self, t: usize, b: [f32; 3]) -> [u8; 3] {
        let material = &self.materials[self.material_of[t] as usize];
        let mut rgb = material.color;
        if let (Some(texture), Some(uv)) = (&material.texture, &self.corner_uv) {
            let c = uv[t];
            let u = b[0] * c[0][0] + b[1] * c[1][0] + b[2] * c[2][0];
            let v = b[0] * c[0][1] + b[1] * c[1][1] + b[2] * c[2][1];
            let (w, h) = texture.dimensions();
            // Repeat wrapping, nearest texel; v runs upwards.
            let x = ((u - u.floor()) * w as f32) as u32;
            let y = ((1.0 - (v - v.floor())) * h as f32) as u32;
            let texel = texture.get_pixel(x.min(w - 1), y.min(h - 1)).0;
            for i in 0..3 {
                rgb[i] *= texel[i] as f32 / 255.0;
            }
        } else if let Some(colors) = &self.vertex_colors {
            let [i, j, k] = self.triangles[t].map(|v| colors[v as usize]);
            for c in 0..3 {
                rgb[c] *= b[0] * i[c] + b[1] * j[c] + b[2] * k[c];
            }
        }
        rgb.map(|c| (c * 255.0).round().clamp(0.0, 255.0) as u8)
    }

    /// Appends `other`, keeping its materials.
    pub fn append(&mut self, other: Mesh) {
        let base = self.positions.len() as u32;
        let material_base = self.materials.len() as u32;
        let had_uv = self.corner_uv.is_some() || other.corner_uv.is_some();
        let had_colors = self.vertex_colors.is_some() || other.vertex_colors.is_some();
        if had_uv {
            let own = self.triangles.len();
            let uv = self.corner_uv.get_or_insert_with(Vec::new);
            uv.resize(own, [[0.0; 2]; 3]);
            match other.corner_uv {
                Some(o) => uv.extend(o),
                None => uv.extend(std::iter::repeat_n([[0.0; 2]; 3], other.triangles.len())),
            }
        }
        if had_colors {
            let own = self.positions.len();
            let colors = self.vertex_colors.get_or_insert_with(Vec::new);
            colors.resize(own, [1.0; 3]);
            match other.vertex_colors {
                Some(o) => colors.extend(o),
                None => colors.extend(std::iter::repeat_n([1.0; 3], other.positions.len())),
            }
        }
        self.positions.extend(other.positions);
        self.triangles
            .extend(other.triangles.iter().map(|t| t.map(|i| i + base)));
        self.material_of
            .extend(other.material_of.iter().map(|m| m + material_base));
        self.materials.extend(other.materials);
    }
}

/// Bounding box `(min, max)` of points (infinite and inverted when there are none).
pub fn bounds_of(points: &[[f32; 3]]) -> ([f32; 3], [f32; 3]) {
    let mut lo = [f32::INFINITY; 3];
    let mut hi = [f32::NEG_INFINITY; 3];
    for p in points {
        for i in 0..3 {
            lo[i] = lo[i].min(p[i]);
            hi[i] = hi[i].max(p[i]);
        }
    }
    (lo, hi)
}

/// Linear-light value (glTF colours and factors) → sRGB.
fn linear_to_srgb(c: f32) -> f32 {
    let c = c.clamp(0.0, 1.0);
    if c <= 0.003_130_8 {
        12.92 * c
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn quad() -> Mesh {
        Mesh {
            positions: vec![
                [0.0, 0.0, 0.0],
                [2.0, 0.0, 0.0],
                [2.0, 1.0, 0.0],
                [0.0, 1.0, 0.0],
            ],
            triangles: vec![[0, 1, 2], [0, 2, 3]],
            material_of: vec![0, 0],
            materials: vec![Material::plain("m", [200, 100, 50])],
            ..Mesh::default()
        }
    }

    #[test]
    fn signed_axes_parse_and_print() {
        for text in ["x", "-x", "y", "-y", "z", "-z"] {
            assert_eq!(text.parse::<SignedAxis>().unwrap().to_string(), text);
        }
        assert_eq!("+z".parse::<SignedAxis>().unwrap().to_string(), "z");
        assert!("w".parse::<SignedAxis>().is_err());
    }

    #[test]
    fn normalize_rotates_into_the_dataset_convention() {
        // A "car" 4 long along +x (its front), 1 high along +z (up), 2 wide along y.
        let mut m = Mesh {
            positions: vec![[0.0, 0.0, 0.0], [4.0, 2.0, 1.0], [4.0, 0.0, 0.0]],
            triangles: vec![[0, 1, 2]],
            material_of: vec![0],
            materials: vec![Material::plain("m", [1, 2, 3])],
            ..Mesh::default()
        };
        let scale = m
            .normalize("z".parse().unwrap(), "x".parse().unwrap())
            .unwrap();
        assert_eq!(scale, 0.25);
        let (lo, hi) = m.bounds();
        // Length along z, up along y, front (old +x) at −z.
        assert_eq!(
            (hi[2] - lo[2], hi[1] - lo[1], hi[0] - lo[0]),
            (1.0, 0.25, 0.5)
        );
        assert_eq!(m.positions[2][2], -0.5, "the old front end is at -z");
        assert_eq!(m.positions[0][2], 0.5);
        assert_eq!(m.positions[1][1], 0.125, "the old top is at +y");
        assert!(m
            .normalize(SignedAxis::PLUS_Y, "-y".parse().unwrap())
            .is_err());
    }

    #[test]
    fn forward_auto_takes_the_longer_horizontal_side_as_the_length() {
        // 4 long along x, 2 wide along z, 1 high along y: auto must lay x along z.
        let mut m = Mesh {
            positions: vec![[0.0, 0.0, 0.0], [4.0, 1.0, 2.0], [4.0, 0.0, 0.0]],
            triangles: vec![[0, 1, 2]],
            material_of: vec![0],
            materials: vec![Material::plain("m", [1, 2, 3])],
            ..Mesh::default()
        };
        let forward: Forward = "auto".parse().unwrap();
        let axis = forward.resolve(&m, SignedAxis::PLUS_Y);
        assert_eq!(axis.axis, 0);
        m.normalize(SignedAxis::PLUS_Y, axis).unwrap();
        let (lo, hi) = m.bounds();
        assert_eq!((hi[2] - lo[2], hi[0] - lo[0]), (1.0, 0.5));
        // Now 1 long along z, 0.5 along x, 0.25 along y: with x up, z is the longer of y and z.
        assert_eq!(forward.resolve(&m, "x".parse().unwrap()).axis, 2);
        assert_eq!(forward.to_string(), "auto");
        assert!("sideways".parse::<Forward>().is_err());
    }

    #[test]
    fn check_counts_boundary_and_non_manifold_edges_and_refuses_bad_meshes() {
        let p = Path::new("m.obj");
        let stats = quad().check(p, 10).unwrap();
        assert_eq!((stats.boundary_edges, stats.non_manifold_edges), (4, 0));
        let mut fan = quad();
        fan.positions.push([1.0, 1.0, 1.0]);
        fan.triangles.push([0, 2, 4]);
        fan.material_of.push(0);
        assert_eq!(fan.check(p, 10).unwrap().non_manifold_edges, 1);
        assert!(matches!(
            quad().check(p, 1),
            Err(MeshError::TooLarge { .. })
        ));
        let mut nan = quad();
        nan.positions[1][0] = f32::NAN;
        assert!(matches!(
            nan.check(p, 10),
            Err(MeshError::NonFinite { count: 1, .. })
        ));
        let mut flat = quad();
        flat.positions = vec![[0.0; 3]; 4];
        assert!(matches!(
            flat.check(p, 10),
            Err(MeshError::Degenerate { .. })
        ));
        assert!(matches!(
            Mesh::default().check(p, 10),
            Err(MeshError::NoFaces { .. })
        ));
    }

    #[test]
    fn colours_come_from_texture_then_vertex_colours_then_material() {
        let mut m = quad();
        assert_eq!(m.color_at(0, [1.0, 0.0, 0.0]), [200, 100, 50]);
        m.vertex_colors = Some(vec![[1.0, 1.0, 1.0], [0.0; 3], [0.0; 3], [0.5; 3]]);
        assert_eq!(m.color_at(1, [0.0, 0.0, 1.0]), [100, 50, 25]);
        let mut texture = RgbImage::new(2, 2);
        texture.put_pixel(0, 1, image::Rgb([255, 0, 0]));
        texture.put_pixel(1, 0, image::Rgb([0, 0, 255]));
        m.materials[0] = Material {
            name: "t".into(),
            color: [1.0; 3],
            texture: Some(Arc::new(texture)),
        };
        m.corner_uv = Some(vec![[[0.1, 0.1], [0.9, 0.9], [0.1, 0.9]]; 2]);
        // uv (0.1, 0.1) is the bottom-left texel, (0.9, 0.9) the top-right one.
        assert_eq!(m.color_at(0, [1.0, 0.0, 0.0]), [255, 0, 0]);
        assert_eq!(m.color_at(0, [0.0, 1.0, 0.0]), [0, 0, 255]);
    }

    #[test]
    fn append_offsets_indices_and_materials() {
        let mut a = quad();
        let mut b = quad();
        b.vertex_colors = Some(vec![[0.5; 3]; 4]);
        a.append(b);
        assert_eq!(a.triangles[3], [4, 6, 7]);
        assert_eq!(a.material_of, vec![0, 0, 1, 1]);
        assert_eq!(a.vertex_colors.as_ref().unwrap().len(), 8);
        assert_eq!(a.vertex_colors.as_ref().unwrap()[0], [1.0; 3]);
    }
}
