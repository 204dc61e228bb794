//! Wavefront OBJ + MTL: read through tobj (ShapeNet's layout, textures relative to the OBJ),
//! written directly for `mvpcc synth` (one `usemtl` group per material, `Kd` colours).

use super::{Material, Mesh, MeshError, ReadOptions, TextureCache};
use crate::core::guard::guarded;
use crate::io::atomic_write;
use std::io::Write;
use std::path::Path;

const GREY: [f32; 3] = [0.6, 0.6, 0.6];

/// An MTL file through tobj, after refusing what tobj would panic on: a colour line (`Ka`, `Kd`,
/// `Ks`, `Ke`) with fewer than three values.
fn load_mtl(path: &Path) -> tobj::MTLLoadResult {
    let text = std::fs::read(path).map_err(|_| tobj::LoadError::OpenFileFailed)?;
    let short_colour = String::from_utf8_lossy(&text).lines().any(|line| {
        let mut words = line.split_whitespace();
        matches!(words.next(), Some("Ka" | "Kd" | "Ks" | "Ke")) && words.count() < 3
    });
    if short_colour {
        return Err(tobj::LoadError::MaterialParseError);
    }
    tobj::load_mtl_buf(&mut text.as_slice())
}

pub fn read(path: &Path, options: ReadOptions) -> Result<Mesh, MeshError> {
    let load = tobj::LoadOptions {
        triangulate: true,
        single_index: false,
        ignore_points: true,
        ignore_lines: true,
    };
    let dir = path.parent().unwrap_or(Path::new("."));
    let read_error = |problem: String| MeshError::Read {
        path: path.to_path_buf(),
        problem,
    };
    let file = std::fs::File::open(path).map_err(|_| read_error("cannot open the file".into()))?;
    let loaded = guarded(|| {
        tobj::load_obj_buf(&mut std::io::BufReader::new(file), &load, |mtl| {
            load_mtl(&dir.join(mtl))
        })
    })
    .map_err(|message| read_error(format!("the OBJ decoder failed on it ({message})")))?;
    let (models, materials) =
        loaded.map_err(|e| read_error(format!("not a valid OBJ file ({e})")))?;
    let materials = match materials {
        Ok(m) => m,
        Err(e) if !options.allow_missing_materials => {
            return Err(MeshError::Materials {
                path: path.to_path_buf(),
                problem: e.to_string(),
            })
        }
        Err(_) => Vec::new(),
    };
    let mut cache = TextureCache::default();
    let mut mesh = Mesh {
        materials: vec![Material {
            name: "default".into(),
            color: GREY,
            texture: None,
        }],
        ..Mesh::default()
    };
    for m in &materials {
        mesh.materials
            .push(material(m, path, dir, &mut cache, options)?);
    }
    let textured = mesh.materials.iter().any(|m| m.texture.is_some());
    let mut uv = Vec::new();
    for model in &models {
        append(&mut mesh, &mut uv, &model.mesh, materials.len(), textured)
            .map_err(|problem| read_error(problem.into()))?;
    }
    if textured {
        mesh.corner_uv = Some(uv);
    }
    Ok(mesh)
}

/// The material `m` of the OBJ file `path` (its textures named relative to `dir`).
fn material(
    m: &tobj::Material,
    path: &Path,
    dir: &Path,
    cache: &mut TextureCache,
    options: ReadOptions,
) -> Result<Material, MeshError> {
    let texture = match m.diffuse_texture.as_deref().map(str::trim) {
        Some(name) if !name.is_empty() => {
            // MTL options such as `-s 1 1 1` precede the file name, which comes last.
            let file = name.split_whitespace().last().unwrap_or(name);
            let texture_path = dir.join(file.replace('\\', "/"));
            match cache.load(&texture_path) {
                Ok(t) => Some(t),
                Err(_) if options.allow_missing_materials => None,
                Err(problem) => {
                    return Err(MeshError::Texture {
                        path: path.to_path_buf(),
                        texture: texture_path,
                        problem,
                    })
                }
            }
        }
        _ => None,
    };
    // A texture replaces Kd (ShapeNet's MTLs pair textures with an arbitrary Kd).
    let color = match (&texture, m.diffuse) {
        (Some(_), _) => [1.0; 3],
        (None, Some(kd)) => kd,
        (None, None) => GREY,
    };
    Ok(Material {
        name: m.name.clone(),
        color,
        texture,
    })
}

/// Appends one OBJ object's vertices and triangles to `mesh` (materials after the default
/// one, of which the file has `materials`), and with `textured` its corners' texture
/// coordinates to `uv`.
fn append(
    mesh: &mut Mesh,
    uv: &mut Vec<[[f32; 2]; 3]>,
    m: &tobj::Mesh,
    materials: usize,
    textured: bool,
) -> Result<(), &'static str> {
    let base = mesh.positions.len() as u32;
    let count = m.positions.len() / 3;
    mesh.positions
        .extend(m.positions.chunks_exact(3).map(|c| [c[0], c[1], c[2]]));
    let material = m
        .material_id
        .filter(|&i| i < materials)
        .map_or(0, |i| i as u32 + 1);
    let has_uv = !m.texcoords.is_empty() && m.texcoord_indices.len() == m.indices.len();
    for (t, tri) in m.indices.chunks_exact(3).enumerate() {
        if tri.iter().any(|&i| i as usize >= count) {
            return Err("a face refers to a vertex that does not exist");
        }
        mesh.triangles
            .push([tri[0] + base, tri[1] + base, tri[2] + base]);
        mesh.material_of.push(material);
        if textured {
            uv.push(std::array::from_fn(|k| {
                if !has_uv {
                    return [0.0; 2];
                }
                let i = m.texcoord_indices[3 * t + k] as usize;
                match m.texcoords.get(2 * i..2 * i + 2) {
                    Some(c) => [c[0], c[1]],
                    None => [0.0; 2],
                }
            }));
        }
    }
    Ok(())
}

/// Writes `mesh` as `path` (OBJ) and a material library beside it with the same stem.
/// Textures are not written: synthetic meshes carry colours only.
pub fn write_obj(path: &Path, mesh: &Mesh) -> std::io::Result<()> {
    let mtl_path = path.with_extension("mtl");
    let mtl_name = mtl_path
        .file_name()
        .and_then(|n| n.to_str())
        .unwrap_or("materials.mtl")
        .to_string();
    atomic_write(&mtl_path, |w| {
        for m in &mesh.materials {
            writeln!(w, "newmtl {}", m.name)?;
            writeln!(
                w,
                "Kd {:.4} {:.4} {:.4}\n",
                m.color[0], m.color[1], m.color[2]
            )?;
        }
        Ok(())
    })?;
    atomic_write(path, |w| {
        writeln!(w, "# written by mvpcc {}", env!("CARGO_PKG_VERSION"))?;
        writeln!(w, "mtllib {mtl_name}")?;
        for p in &mesh.positions {
            writeln!(w, "v {:.5} {:.5} {:.5}", p[0], p[1], p[2])?;
        }
        let mut order: Vec<usize> = (0..mesh.triangles.len()).collect();
        order.sort_by_key(|&t| mesh.material_of[t]);
        let mut current = None;
        for t in order {
            let m = mesh.material_of[t];
            if current != Some(m) {
                writeln!(w, "usemtl {}", mesh.materials[m as usize].name)?;
                current = Some(m);
            }
            let [a, b, c] = mesh.triangles[t];
            writeln!(w, "f {} {} {}", a + 1, b + 1, c + 1)?;
        }
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::super::{read_mesh, ReadOptions};
    use super::*;

    const STRICT: ReadOptions = ReadOptions {
        allow_missing_materials: false,
    };
    const LENIENT: ReadOptions = ReadOptions {
        allow_missing_materials: true,
    };

    #[test]
    fn written_obj_reads_back_with_colours() {
        let dir = tempfile::tempdir().unwrap();
        let mesh = Mesh {
            positions: vec![
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [0.0, 1.0, 0.0],
                [0.0, 0.0, 1.0],
            ],
            triangles: vec![[0, 1, 2], [0, 2, 3], [0, 3, 1]],
            material_of: vec![1, 0, 1],
            materials: vec![
                Material::plain("paint", [200, 20, 20]),
                Material::plain("glass", [30, 40, 50]),
            ],
            ..Mesh::default()
        };
        let path = dir.path().join("car.obj");
        write_obj(&path, &mesh).unwrap();
        let back = read_mesh(&path, STRICT).unwrap();
        // tobj gives each material group its own copy of the vertices it uses.
        assert_eq!(back.triangles.len(), 3);
        let mut colours: Vec<[u8; 3]> = (0..3).map(|t| back.color_at(t, [1.0 / 3.0; 3])).collect();
        colours.sort();
        assert_eq!(colours, vec![[30, 40, 50], [30, 40, 50], [200, 20, 20]]);
    }

    #[test]
    fn textures_resolve_beside_the_obj_and_missing_ones_are_errors_unless_allowed() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::create_dir(dir.path().join("images")).unwrap();
        let obj = dir.path().join("m.obj");
        std::fs::write(
            &obj,
            "mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0.1 0.1\nvt 0.9 0.1\nvt 0.1 0.9\nusemtl t\nf 1/1 2/2 3/3\n",
        )
        .unwrap();
        std::fs::write(
            dir.path().join("m.mtl"),
            "newmtl t\nKd 0.2 0.2 0.2\nmap_Kd images/tex.png\n",
        )
        .unwrap();
        let err = read_mesh(&obj, STRICT).unwrap_err();
        assert!(matches!(err, MeshError::Texture { .. }), "{err}");
        assert!(err.to_string().contains("tex.png"), "{err}");
        let lenient = read_mesh(&obj, LENIENT).unwrap();
        assert_eq!(lenient.color_at(0, [1.0, 0.0, 0.0]), [51, 51, 51]);
        image::RgbImage::from_pixel(4, 4, image::Rgb([10, 200, 30]))
            .save(dir.path().join("images/tex.png"))
            .unwrap();
        let textured = read_mesh(&obj, STRICT).unwrap();
        assert_eq!(textured.color_at(0, [1.0, 0.0, 0.0]), [10, 200, 30]);
    }

    #[test]
    fn missing_material_library_and_garbage_are_errors() {
        let dir = tempfile::tempdir().unwrap();
        let obj = dir.path().join("m.obj");
        std::fs::write(
            &obj,
            "mtllib gone.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl a\nf 1 2 3\n",
        )
        .unwrap();
        assert!(matches!(
            read_mesh(&obj, STRICT),
            Err(MeshError::Materials { .. })
        ));
        assert_eq!(read_mesh(&obj, LENIENT).unwrap().triangles.len(), 1);
        std::fs::write(&obj, "v 0 0 0\nf 1 2 7\n").unwrap();
        let err = read_mesh(&obj, STRICT).unwrap_err();
        assert!(
            err.to_string().starts_with(&obj.display().to_string()),
            "{err}"
        );
    }
}
