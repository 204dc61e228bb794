//! PLY (ascii, binary little and big endian) through ply-rs-bw; bodies are written directly.

use super::{check_points, fits_f32, Encoding, Problem};
use crate::core::cloud::{Attribute, PointCloud, ScalarKind};
use ply_rs_bw::parser::{Parser, Reader};
use ply_rs_bw::ply::{Property, PropertyAccess, PropertyAccessResult, PropertyType, ScalarType};
use std::io::{BufReader, Write};
use std::path::Path;

#[derive(Clone, Copy, PartialEq)]
enum Role {
    Coordinate(usize),
    Color(usize),
    Other,
}

fn role(name: &str) -> Role {
    match name {
        "x" => Role::Coordinate(0),
        "y" => Role::Coordinate(1),
        "z" => Role::Coordinate(2),
        "red" | "r" | "diffuse_red" => Role::Color(0),
        "green" | "g" | "diffuse_green" => Role::Color(1),
        "blue" | "b" | "diffuse_blue" => Role::Color(2),
        _ => Role::Other,
    }
}

pub(crate) fn scalar_value(p: &Property) -> Option<f64> {
    Some(match *p {
        Property::Char(v) => v as f64,
        Property::UChar(v) => v as f64,
        Property::Short(v) => v as f64,
        Property::UShort(v) => v as f64,
        Property::Int(v) => v as f64,
        Property::UInt(v) => v as f64,
        Property::Float(v) => v as f64,
        Property::Double(v) => v,
        _ => return None,
    })
}

fn kind_of(t: &ScalarType) -> ScalarKind {
    match t {
        ScalarType::Char => ScalarKind::I8,
        ScalarType::UChar => ScalarKind::U8,
        ScalarType::Short => ScalarKind::I16,
        ScalarType::UShort => ScalarKind::U16,
        ScalarType::Int => ScalarKind::I32,
        ScalarType::UInt => ScalarKind::U32,
        ScalarType::Float => ScalarKind::F32,
        ScalarType::Double => ScalarKind::F64,
    }
}

fn type_name(k: ScalarKind) -> &'static str {
    match k {
        ScalarKind::I8 => "char",
        ScalarKind::U8 => "uchar",
        ScalarKind::I16 => "short",
        ScalarKind::U16 => "ushort",
        ScalarKind::I32 => "int",
        ScalarKind::U32 => "uint",
        ScalarKind::F32 => "float",
        ScalarKind::F64 => "double",
    }
}

struct Vertex {
    xyz: [f64; 3],
    rgb: [u8; 3],
    /// Scalar properties that are neither coordinates nor colours, in header order.
    extra: Vec<f64>,
}

impl PropertyAccess for Vertex {
    fn new() -> Self {
        Vertex {
            xyz: [0.0; 3],
            rgb: [0; 3],
            extra: Vec::new(),
        }
    }

    fn set_property(&mut self, name: &str, property: Property) -> PropertyAccessResult {
        match role(name) {
            Role::Coordinate(i) => self.xyz[i] = scalar_value(&property).unwrap_or(f64::NAN),
            Role::Color(i) => self.rgb[i] = property.to_u8_color_lossy().unwrap_or(0),
            Role::Other => match scalar_value(&property) {
                Some(v) => self.extra.push(v),
                None => return PropertyAccessResult::Ignored,
            },
        }
        PropertyAccessResult::Set
    }
}

/// Elements other than `vertex` (faces, edges…) are read past and dropped.
struct Skipped;

impl PropertyAccess for Skipped {
    fn new() -> Self {
        Skipped
    }
}

/// The text between `String: '` and the next `'` of a ply-rs message: the offending line.
fn quoted_line(text: &str) -> Option<&str> {
    let start = text.find("String: '")? + "String: '".len();
    let len = text[start..].find('\'')?;
    Some(text[start..start + len].trim())
}

/// `(expected N, got M)` of a ply-rs end-of-file message.
fn expected_got(text: &str) -> Option<(usize, usize)> {
    let start = text.find("(expected ")? + "(expected ".len();
    let (expected, rest) = text[start..].split_once(", got ")?;
    let got = rest.split(')').next()?;
    Some((expected.trim().parse().ok()?, got.trim().parse().ok()?))
}

/// ply-rs messages span lines and embed parser internals; the CLI promises one clear line.
fn one_line(e: &ply_rs_bw::parser::ParseError) -> Problem {
    let text = e
        .to_string()
        .split_whitespace()
        .collect::<Vec<_>>()
        .join(" ");
    let line = e.line().map_or(String::new(), |l| format!("line {l}: "));
    if e.kind() == std::io::ErrorKind::UnexpectedEof {
        return match expected_got(&text) {
            Some((declared, found)) => Problem::Truncated { declared, found },
            None => Problem::Malformed(format!("{line}file ends early")),
        };
    }
    match quoted_line(&text) {
        Some(bad) if text.contains("element line") => Problem::Malformed(format!(
            "{line}values {bad:?} do not match the header's properties"
        )),
        Some(bad) if bad.starts_with("format") => Problem::Malformed(format!(
            "{line}unknown format line {bad:?} (expected ascii, binary_little_endian or binary_big_endian)"
        )),
        Some(bad) => Problem::Malformed(format!("{line}cannot parse header line {bad:?}")),
        None => Problem::Malformed(format!("{line}{text}")),
    }
}

pub(super) fn read(path: &Path) -> Result<PointCloud, Problem> {
    let file = std::fs::File::open(path)?;
    let mut reader = Reader::new(BufReader::with_capacity(1 << 20, file));
    let vertex_parser = Parser::<Vertex>::new();
    let header = vertex_parser
        .read_header(&mut reader)
        .map_err(|e| one_line(&e))?;
    let Some(vertex_def) = header.elements.get("vertex") else {
        return Err(Problem::Malformed(
            "no 'vertex' element in the header".into(),
        ));
    };
    check_points(vertex_def.count)?;
    let names: Vec<&String> = vertex_def.properties.keys().collect();
    for axis in ["x", "y", "z"] {
        if !names.iter().any(|n| n.as_str() == axis) {
            return Err(Problem::Malformed(format!(
                "vertex element has no '{axis}' property"
            )));
        }
    }
    let has_color = (0..3).all(|c| names.iter().any(|n| role(n) == Role::Color(c)));
    let attribute_defs: Vec<(String, ScalarKind)> = vertex_def
        .properties
        .values()
        .filter(|p| role(&p.name) == Role::Other)
        .filter_map(|p| match &p.data_type {
            PropertyType::Scalar(t) => Some((p.name.clone(), kind_of(t))),
            PropertyType::List(..) => None,
        })
        .collect();

    let mut vertices = Vec::new();
    for (name, def) in &header.elements {
        if name == "vertex" {
            vertices = vertex_parser
                .read_payload_for_element(&mut reader, def, &header)
                .map_err(|e| one_line(&e))?;
        } else {
            Parser::<Skipped>::new()
                .read_payload_for_element(&mut reader, def, &header)
                .map_err(|e| one_line(&e))?;
        }
    }

    let mut cloud = PointCloud {
        positions: vertices.iter().map(|v| v.xyz).collect(),
        colors: has_color.then(|| vertices.iter().map(|v| v.rgb).collect()),
        ..Default::default()
    };
    cloud.attributes = attribute_defs
        .into_iter()
        .enumerate()
        .map(|(k, (name, kind))| Attribute {
            name,
            kind,
            values: vertices.iter().map(|v| v.extra[k]).collect(),
        })
        .collect();
    Ok(cloud)
}

fn put_scalar(w: &mut impl Write, kind: ScalarKind, v: f64, big: bool) -> std::io::Result<()> {
    macro_rules! put {
        ($t:ty) => {{
            let x = v as $t;
            w.write_all(&if big {
                x.to_be_bytes()
            } else {
                x.to_le_bytes()
            })
        }};
    }
    match kind {
        ScalarKind::I8 => put!(i8),
        ScalarKind::U8 => put!(u8),
        ScalarKind::I16 => put!(i16),
        ScalarKind::U16 => put!(u16),
        ScalarKind::I32 => put!(i32),
        ScalarKind::U32 => put!(u32),
        ScalarKind::F32 => put!(f32),
        ScalarKind::F64 => put!(f64),
    }
}

/// Binary little-endian unless `Ascii` is asked for; coordinates as float when that is
/// lossless, double otherwise.
pub(super) fn write(
    w: &mut impl Write,
    cloud: &PointCloud,
    encoding: Encoding,
) -> std::io::Result<()> {
    let ascii = encoding == Encoding::Ascii;
    let coord = if fits_f32(cloud) {
        ScalarKind::F32
    } else {
        ScalarKind::F64
    };
    writeln!(w, "ply")?;
    writeln!(
        w,
        "format {} 1.0",
        if ascii {
            "ascii"
        } else {
            "binary_little_endian"
        }
    )?;
    writeln!(w, "comment written by mvpcc {}", env!("CARGO_PKG_VERSION"))?;
    writeln!(w, "element vertex {}", cloud.len())?;
    for axis in ["x", "y", "z"] {
        writeln!(w, "property {} {axis}", type_name(coord))?;
    }
    if cloud.colors.is_some() {
        for c in ["red", "green", "blue"] {
            writeln!(w, "property uchar {c}")?;
        }
    }
    for a in &cloud.attributes {
        writeln!(w, "property {} {}", type_name(a.kind), a.name)?;
    }
    writeln!(w, "end_header")?;
    for i in 0..cloud.len() {
        let p = cloud.positions[i];
        if ascii {
            if coord == ScalarKind::F32 {
                write!(w, "{} {} {}", p[0] as f32, p[1] as f32, p[2] as f32)?;
            } else {
                write!(w, "{} {} {}", p[0], p[1], p[2])?;
            }
            if let Some(c) = &cloud.colors {
                write!(w, " {} {} {}", c[i][0], c[i][1], c[i][2])?;
            }
            for a in &cloud.attributes {
                write!(w, " {}", a.values[i])?;
            }
            writeln!(w)?;
        } else {
            for c in p {
                put_scalar(w, coord, c, false)?;
            }
            if let Some(c) = &cloud.colors {
                w.write_all(&c[i])?;
            }
            for a in &cloud.attributes {
                put_scalar(w, a.kind, a.values[i], false)?;
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn read_str(bytes: &[u8]) -> Result<PointCloud, Problem> {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.ply");
        std::fs::write(&path, bytes).unwrap();
        read(&path)
    }

    #[test]
    fn ascii_with_faces_short_color_names_and_unknown_properties() {
        let text = "ply\nformat ascii 1.0\ncomment made by hand\nelement vertex 3\n\
            property double x\nproperty double y\nproperty double z\nproperty float nx\n\
            property uchar r\nproperty uchar g\nproperty uchar b\nproperty list uchar int idx\n\
            element face 1\nproperty list uchar int vertex_indices\nend_header\n\
            1 2 3 0.5 10 20 30 2 7 8\n4 5 6 -0.5 40 50 60 0\n650000.125 -7 8 1 70 80 90 1 3\n3 0 1 2\n";
        let c = read_str(text.as_bytes()).unwrap();
        assert_eq!(
            c.positions,
            vec![[1.0, 2.0, 3.0], [4.0, 5.0, 6.0], [650000.125, -7.0, 8.0]]
        );
        assert_eq!(
            c.colors.unwrap(),
            vec![[10, 20, 30], [40, 50, 60], [70, 80, 90]]
        );
        assert_eq!(c.attributes.len(), 1);
        assert_eq!(c.attributes[0].name, "nx");
        assert_eq!(c.attributes[0].values, vec![0.5, -0.5, 1.0]);
    }

    #[test]
    fn big_endian_float_with_diffuse_colors() {
        let mut bytes = b"ply\nformat binary_big_endian 1.0\nelement vertex 2\nproperty float x\n\
            property float y\nproperty float z\nproperty uchar diffuse_red\n\
            property uchar diffuse_green\nproperty uchar diffuse_blue\nend_header\n"
            .to_vec();
        for (p, c) in [
            ([1.5f32, -2.0, 0.25], [1u8, 2, 3]),
            ([0.0, 8.0, -1.0], [4, 5, 6]),
        ] {
            for v in p {
                bytes.extend_from_slice(&v.to_be_bytes());
            }
            bytes.extend_from_slice(&c);
        }
        let c = read_str(&bytes).unwrap();
        assert_eq!(c.positions, vec![[1.5, -2.0, 0.25], [0.0, 8.0, -1.0]]);
        assert_eq!(c.colors.unwrap(), vec![[1, 2, 3], [4, 5, 6]]);
    }

    #[test]
    fn malformed_files_give_one_line_errors() {
        let cases: [&[u8]; 4] = [
            b"ply\nformat binary_middle_endian 1.0\nelement vertex 1\nproperty float x\nend_header\n",
            b"ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nend_header\n1 2 3\n",
            b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\n1 two 3\n",
            b"ply\nformat binary_little_endian 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nend_header\n\0\0\0\0\0\0\0\0\0\0\0\0\0\0",
        ];
        for bytes in cases {
            let e = read_str(bytes).unwrap_err().to_string();
            assert!(!e.contains('\n') && !e.is_empty(), "{e:?}");
        }
        let e =
            read_str(b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nend_header\n1\n")
                .unwrap_err()
                .to_string();
        assert!(e.contains("'y'"), "{e}");
    }
}
