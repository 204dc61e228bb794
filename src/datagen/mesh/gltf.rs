//! glTF 2.0 / GLB: every triangle primitive of the default scene, placed by its node
//! transforms, with base-colour factors, base-colour textures and COLOR_0.

use super::{linear_to_srgb, Material, Mesh, MeshError};
use crate::core::guard::guarded;
use image::RgbImage;
use nalgebra::{Matrix4, Point3};
use std::path::Path;
use std::sync::Arc;

fn to_rgb(data: &::gltf::image::Data) -> Option<RgbImage> {
    use ::gltf::image::Format;
    let channels = match data.format {
        Format::R8 => 1,
        Format::R8G8 => 2,
        Format::R8G8B8 => 3,
        Format::R8G8B8A8 => 4,
        _ => return None,
    };
    let pixels: Vec<u8> = data
        .pixels
        .chunks_exact(channels)
        .flat_map(|p| match channels {
            1 | 2 => [p[0]; 3],
            _ => [p[0], p[1], p[2]],
        })
        .collect();
    RgbImage::from_raw(data.width, data.height, pixels)
}

/// Refuses a GLB whose header claims more bytes than the file holds: the gltf crate allocates
/// the claimed length (up to 4 GiB) before reading.
fn check_glb_length(path: &Path) -> Result<(), String> {
    use std::io::Read;
    let mut header = [0u8; 12];
    let mut file = std::fs::File::open(path).map_err(|e| e.to_string())?;
    let size = file.metadata().map_err(|e| e.to_string())?.len();
    if file.read_exact(&mut header).is_err() || &header[..4] != b"glTF" {
        return Ok(());
    }
    let declared = u32::from_le_bytes(header[8..12].try_into().expect("4 bytes"));
    if declared < 12 {
        return Err(format!(
            "GLB header declares {declared} bytes, fewer than the header itself"
        ));
    }
    if u64::from(declared) > size {
        return Err(format!(
            "GLB header declares {declared} bytes but the file holds only {size}"
        ));
    }
    Ok(())
}

pub fn read(path: &Path) -> Result<Mesh, MeshError> {
    let fail = |problem: String| MeshError::Read {
        path: path.to_path_buf(),
        problem,
    };
    check_glb_length(path).map_err(fail)?;
    guarded(|| read_checked(path))
        .unwrap_or_else(|message| Err(fail(format!("the glTF decoder failed on it ({message})"))))
}

fn read_checked(path: &Path) -> Result<Mesh, MeshError> {
    let fail = |problem: String| MeshError::Read {
        path: path.to_path_buf(),
        problem,
    };
    let (document, buffers, images) =
        ::gltf::import(path).map_err(|e| fail(format!("not a readable glTF file ({e})")))?;
    let textures: Vec<Option<Arc<RgbImage>>> =
        images.iter().map(|i| to_rgb(i).map(Arc::new)).collect();
    let mut mesh = Mesh::default();
    let scene = document
        .default_scene()
        .or_else(|| document.scenes().next())
        .ok_or_else(|| fail("no scene".into()))?;
    let mut stack: Vec<(::gltf::Node, Matrix4<f32>)> =
        scene.nodes().map(|n| (n, Matrix4::identity())).collect();
    while let Some((node, parent)) = stack.pop() {
        let local = Matrix4::from_column_slice(node.transform().matrix().as_flattened());
        let world = parent * local;
        stack.extend(node.children().map(|c| (c, world)));
        let Some(gmesh) = node.mesh() else { continue };
        for primitive in gmesh.primitives() {
            if let Some(part) =
                primitive_mesh(&primitive, &buffers, &textures, &world).map_err(fail)?
            {
                mesh.append(part);
            }
        }
    }
    Ok(mesh)
}

/// One primitive's triangles placed by its node's `world` transform, with its material;
/// `None` for primitives of other modes or without positions.
fn primitive_mesh(
    primitive: &::gltf::Primitive,
    buffers: &[::gltf::buffer::Data],
    textures: &[Option<Arc<RgbImage>>],
    world: &Matrix4<f32>,
) -> Result<Option<Mesh>, String> {
    if primitive.mode() != ::gltf::mesh::Mode::Triangles {
        return Ok(None);
    }
    let reader = primitive.reader(|b| buffers.get(b.index()).map(|d| &d.0[..]));
    let Some(positions) = reader.read_positions() else {
        return Ok(None);
    };
    let positions: Vec<[f32; 3]> = positions
        .map(|p| {
            let q = world.transform_point(&Point3::from(p));
            [q.x, q.y, q.z]
        })
        .collect();
    let indices = triangle_indices(primitive, &reader, positions.len() as u32)?;
    let pbr = primitive.material().pbr_metallic_roughness();
    let factor = pbr.base_color_factor();
    let texture_info = pbr.base_color_texture();
    let texture = texture_info.as_ref().and_then(|t| {
        textures
            .get(t.texture().source().index())
            .cloned()
            .flatten()
    });
    let uv_set = texture_info.as_ref().map_or(0, |t| t.tex_coord());
    let uvs: Option<Vec<[f32; 2]>> = texture
        .as_ref()
        .and_then(|_| reader.read_tex_coords(uv_set))
        .map(|t| t.into_f32().collect());
    let colors: Option<Vec<[f32; 3]>> = reader
        .read_colors(0)
        .map(|c| c.into_rgb_f32().map(|c| c.map(linear_to_srgb)).collect());
    let triangles: Vec<[u32; 3]> = indices
        .chunks_exact(3)
        .map(|t| [t[0], t[1], t[2]])
        .collect();
    Ok(Some(Mesh {
        materials: vec![Material {
            name: format!("material_{}", primitive.material().index().unwrap_or(0)),
            color: [factor[0], factor[1], factor[2]].map(linear_to_srgb),
            texture: uvs.as_ref().and(texture),
        }],
        vertex_colors: colors,
        corner_uv: uvs.map(|uvs| corner_uvs(&triangles, &uvs)),
        material_of: vec![0; triangles.len()],
        triangles,
        positions,
    }))
}

/// A primitive's vertex indices, three per triangle (its vertices in order when it has none),
/// each checked against the `n` vertices.
fn triangle_indices<'a, 's, F>(
    primitive: &::gltf::Primitive,
    reader: &::gltf::mesh::Reader<'a, 's, F>,
    n: u32,
) -> Result<Vec<u32>, String>
where
    F: Clone + Fn(::gltf::Buffer<'a>) -> Option<&'s [u8]>,
{
    // The gltf crate panics on indices that are not unsigned integers.
    if let Some(accessor) = primitive.indices() {
        use ::gltf::accessor::DataType;
        let kind = accessor.data_type();
        if !matches!(kind, DataType::U8 | DataType::U16 | DataType::U32) {
            return Err(format!(
                "triangle indices stored as {kind:?}, not unsigned integers"
            ));
        }
    }
    let indices: Vec<u32> = match reader.read_indices() {
        Some(i) => i.into_u32().collect(),
        None => (0..n).collect(),
    };
    if indices.iter().any(|&i| i >= n) {
        return Err("a triangle refers to a vertex that does not exist".into());
    }
    Ok(indices)
}

/// Each triangle corner's texture coordinate; glTF's v runs downwards, `Mesh` keeps OBJ's
/// upward v.
fn corner_uvs(triangles: &[[u32; 3]], uvs: &[[f32; 2]]) -> Vec<[[f32; 2]; 3]> {
    triangles
        .iter()
        .map(|t| {
            t.map(|i| {
                let [u, v] = uvs.get(i as usize).copied().unwrap_or([0.0; 2]);
                [u, 1.0 - v]
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::super::{read_mesh, ReadOptions};

    /// A one-triangle glTF with its buffer inline, translated by its node and coloured by its
    /// material's base-colour factor.
    #[test]
    fn reads_an_embedded_gltf_with_node_transform_and_base_colour() {
        let dir = tempfile::tempdir().unwrap();
        let mut bytes = Vec::new();
        for v in [[0f32, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]] {
            for c in v {
                bytes.extend(c.to_le_bytes());
            }
        }
        let b64 = base64(&bytes);
        let json = format!(
            r#"{{"asset":{{"version":"2.0"}},"scene":0,"scenes":[{{"nodes":[0]}}],
            "nodes":[{{"mesh":0,"translation":[0,0,5]}}],
            "meshes":[{{"primitives":[{{"attributes":{{"POSITION":0}},"material":0}}]}}],
            "materials":[{{"pbrMetallicRoughness":{{"baseColorFactor":[1,0,0,1]}}}}],
            "buffers":[{{"byteLength":36,"uri":"data:application/octet-stream;base64,{b64}"}}],
            "bufferViews":[{{"buffer":0,"byteLength":36}}],
            "accessors":[{{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[1,1,0]}}]}}"#
        );
        let path = dir.path().join("t.gltf");
        std::fs::write(&path, json).unwrap();
        let mesh = read_mesh(
            &path,
            ReadOptions {
                allow_missing_materials: false,
            },
        )
        .unwrap();
        assert_eq!(mesh.triangles, vec![[0, 1, 2]]);
        assert_eq!(mesh.positions[1], [1.0, 0.0, 5.0]);
        assert_eq!(mesh.color_at(0, [1.0, 0.0, 0.0]), [255, 0, 0]);
    }

    fn base64(bytes: &[u8]) -> String {
        const A: &[u8] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
        let mut out = String::new();
        for chunk in bytes.chunks(3) {
            let b = [
                chunk[0],
                *chunk.get(1).unwrap_or(&0),
                *chunk.get(2).unwrap_or(&0),
            ];
            let n = (b[0] as u32) << 16 | (b[1] as u32) << 8 | b[2] as u32;
            for k in 0..4 {
                if k <= chunk.len() {
                    out.push(A[(n >> (18 - 6 * k) & 63) as usize] as char);
                } else {
                    out.push('=');
                }
            }
        }
        out
    }
}
