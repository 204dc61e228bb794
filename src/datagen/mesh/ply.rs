//! PLY meshes: `vertex` (x, y, z, optional red/green/blue) and `face` (`vertex_indices` or
//! `vertex_index` lists, polygons fanned into triangles).

use super::{Material, Mesh, MeshError};
use crate::io::ply::scalar_value;
use ply_rs_bw::parser::Parser;
use ply_rs_bw::ply::{DefaultElement, Property};
use std::io::BufReader;
use std::path::Path;

fn indices(p: &Property) -> Option<Vec<i64>> {
    Some(match p {
        Property::ListChar(v) => v.iter().map(|&i| i as i64).collect(),
        Property::ListUChar(v) => v.iter().map(|&i| i as i64).collect(),
        Property::ListShort(v) => v.iter().map(|&i| i as i64).collect(),
        Property::ListUShort(v) => v.iter().map(|&i| i as i64).collect(),
        Property::ListInt(v) => v.iter().map(|&i| i as i64).collect(),
        Property::ListUInt(v) => v.iter().map(|&i| i as i64).collect(),
        _ => return None,
    })
}

pub fn read(path: &Path) -> Result<Mesh, MeshError> {
    let fail = |problem: String| MeshError::Read {
        path: path.to_path_buf(),
        problem,
    };
    let file = std::fs::File::open(path).map_err(|e| fail(e.to_string()))?;
    let ply = Parser::<DefaultElement>::new()
        .read_ply(&mut BufReader::new(file))
        .map_err(|e| {
            fail(format!(
                "not a valid PLY file ({})",
                e.to_string()
                    .split_whitespace()
                    .collect::<Vec<_>>()
                    .join(" ")
            ))
        })?;
    let vertices = ply
        .payload
        .get("vertex")
        .ok_or_else(|| fail("no vertex element".into()))?;
    let mut mesh = Mesh {
        materials: vec![Material {
            name: "default".into(),
            color: [1.0; 3],
            texture: None,
        }],
        ..Mesh::default()
    };
    add_vertices(&mut mesh, vertices);
    let faces = ply.payload.get("face").map(Vec::as_slice).unwrap_or(&[]);
    add_faces(&mut mesh, faces).map_err(|problem| fail(problem.into()))?;
    Ok(mesh)
}

/// The `vertices`' positions into `mesh`, with their colours when they all have red, green
/// and blue; without colours the one material is a mid grey.
fn add_vertices(mesh: &mut Mesh, vertices: &[DefaultElement]) {
    let colored = vertices.first().is_some_and(|v| {
        v.contains_key("red") && v.contains_key("green") && v.contains_key("blue")
    });
    let mut colors = Vec::new();
    for v in vertices {
        let get = |name: &str| {
            v.get(name)
                .and_then(scalar_value)
                .map_or(f32::NAN, |x| x as f32)
        };
        mesh.positions.push([get("x"), get("y"), get("z")]);
        if colored {
            colors.push(["red", "green", "blue"].map(|c| {
                v.get(c)
                    .and_then(|p| p.to_u8_color_lossy())
                    .map_or(1.0, |c| c as f32 / 255.0)
            }));
        }
    }
    if colored {
        mesh.vertex_colors = Some(colors);
    } else {
        mesh.materials[0].color = [0.6; 3];
    }
}

/// The `faces` into `mesh` as triangles (polygons fanned from their first corner), all of the
/// first material; refused when a face has no index list or names a missing vertex.
fn add_faces(mesh: &mut Mesh, faces: &[DefaultElement]) -> Result<(), &'static str> {
    let n = mesh.positions.len() as i64;
    for face in faces {
        let Some(list) = face
            .get("vertex_indices")
            .or_else(|| face.get("vertex_index"))
            .and_then(indices)
        else {
            return Err("faces have no vertex_indices list");
        };
        if list.iter().any(|&i| i < 0 || i >= n) {
            return Err("a face refers to a vertex that does not exist");
        }
        for k in 1..list.len().saturating_sub(1) {
            mesh.triangles
                .push([list[0] as u32, list[k] as u32, list[k + 1] as u32]);
            mesh.material_of.push(0);
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::super::{read_mesh, ReadOptions};

    #[test]
    fn reads_faces_fans_quads_and_keeps_vertex_colours() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("q.ply");
        std::fs::write(
            &path,
            "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n\
             property uchar red\nproperty uchar green\nproperty uchar blue\n\
             element face 1\nproperty list uchar int vertex_indices\nend_header\n\
             0 0 0 255 0 0\n1 0 0 255 0 0\n1 1 0 255 0 0\n0 1 0 255 0 0\n4 0 1 2 3\n",
        )
        .unwrap();
        let options = ReadOptions {
            allow_missing_materials: false,
        };
        let mesh = read_mesh(&path, options).unwrap();
        assert_eq!(mesh.triangles, vec![[0, 1, 2], [0, 2, 3]]);
        assert_eq!(mesh.color_at(1, [0.2, 0.3, 0.5]), [255, 0, 0]);
        std::fs::write(
            &path,
            "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\n\
             element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n3 0 1 5\n",
        )
        .unwrap();
        let err = read_mesh(&path, options).unwrap_err();
        assert!(err.to_string().contains("does not exist"), "{err}");
    }
}
