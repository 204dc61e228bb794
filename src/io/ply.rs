//! PLY: headers and binary bodies through ply-rs-bw; ASCII bodies, which its digits-only
//! grammar would refuse where they hold `nan` or `.5`, read here. Files are written directly.

use super::{check_points, fits_f32, Encoding, Problem};
use crate::core::cloud::{Attribute, PointCloud, ScalarKind};
use ply_rs_bw::parser::{Parser, Reader};
use ply_rs_bw::ply::{
    ElementDef, Encoding as PlyEncoding, Property, PropertyAccess, PropertyAccessResult,
    PropertyType, ScalarType,
};
use std::io::{BufRead, BufReader, Write};
use std::path::Path;

#[derive(Clone, Copy, PartialEq)]
enum Role {
    Coordinate(usize),
    Color(usize),
    Other,
}

/// What a property holds, by its name in any case (some writers name coordinates `X`).
fn role(name: &str) -> Role {
    match name {
        "x" => Role::Coordinate(0),
        "y" => Role::Coordinate(1),
        "z" => Role::Coordinate(2),
        "red" | "r" | "diffuse_red" => Role::Color(0),
        "green" | "g" | "diffuse_green" => Role::Color(1),
        "blue" | "b" | "diffuse_blue" => Role::Color(2),
        // Called for every property of every vertex: lowercase names, nearly all, need no copy.
        _ if name.bytes().any(|b| b.is_ascii_uppercase()) => role(&name.to_ascii_lowercase()),
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
        Some(bad) if bad.starts_with("format") => Problem::Malformed(format!(
            "{line}unknown format line {bad:?} (expected ascii, binary_little_endian or binary_big_endian)"
        )),
        Some(bad) => Problem::Malformed(format!("{line}cannot parse header line {bad:?}")),
        None => Problem::Malformed(format!("{line}{text}")),
    }
}

/// One value of an ASCII body. Rust's float syntax takes `nan`, `inf`, `.5` and `1.`, which
/// scanners and PCL write (`nan` for a missing return) and ply-rs's digits-only grammar refuses.
fn ascii_scalar(token: &str, t: &ScalarType) -> Option<Property> {
    Some(match t {
        ScalarType::Char => Property::Char(token.parse().ok()?),
        ScalarType::UChar => Property::UChar(token.parse().ok()?),
        ScalarType::Short => Property::Short(token.parse().ok()?),
        ScalarType::UShort => Property::UShort(token.parse().ok()?),
        ScalarType::Int => Property::Int(token.parse().ok()?),
        ScalarType::UInt => Property::UInt(token.parse().ok()?),
        ScalarType::Float => Property::Float(token.parse().ok()?),
        ScalarType::Double => Property::Double(token.parse().ok()?),
    })
}

/// The `def.count` lines of an ASCII element, one element per line, the first of them line
/// `*line` of the file (advanced past them); list properties are read past (no caller keeps
/// them).
fn read_ascii<E: PropertyAccess, R: BufRead>(
    reader: &mut Reader<R>,
    def: &ElementDef,
    line: &mut usize,
) -> Result<Vec<E>, Problem> {
    let mut out = Vec::with_capacity(def.count.min(1 << 20));
    let mut text = String::new();
    for i in 0..def.count {
        text.clear();
        if reader.get_mut().read_line(&mut text)? == 0 {
            return Err(Problem::Truncated {
                declared: def.count,
                found: i,
            });
        }
        let bad = || {
            // A hostile file's "line" may be megabytes long; the message stays one short line.
            let shown: String = text.trim().chars().take(80).collect();
            Problem::Malformed(format!(
                "line {}: values {shown:?} do not match the header's properties",
                *line
            ))
        };
        let mut tokens = text.split_whitespace();
        let mut element = E::new();
        for property in def.properties.values() {
            match &property.data_type {
                PropertyType::Scalar(t) => {
                    let value = tokens
                        .next()
                        .and_then(|s| ascii_scalar(s, t))
                        .ok_or_else(bad)?;
                    element.set_property(&property.name, value);
                }
                PropertyType::List(..) => {
                    let n: usize = tokens.next().and_then(|s| s.parse().ok()).ok_or_else(bad)?;
                    if tokens.by_ref().take(n).count() < n {
                        return Err(bad());
                    }
                }
            }
        }
        if tokens.next().is_some() {
            return Err(bad());
        }
        out.push(element);
        *line += 1;
    }
    Ok(out)
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
    let (has_color, attribute_defs) = vertex_layout(vertex_def)?;

    let ascii = header.encoding == PlyEncoding::Ascii;
    // After the header, ply-rs's tracker already names the next line (the first of the body).
    let mut line = reader.line();
    let mut vertices = Vec::new();
    for (name, def) in &header.elements {
        match (name == "vertex", ascii) {
            (true, true) => vertices = read_ascii(&mut reader, def, &mut line)?,
            (true, false) => {
                vertices = vertex_parser
                    .read_payload_for_element(&mut reader, def, &header)
                    .map_err(|e| one_line(&e))?
            }
            (false, true) => drop(read_ascii::<Skipped, _>(&mut reader, def, &mut line)?),
            (false, false) => drop(
                Parser::<Skipped>::new()
                    .read_payload_for_element(&mut reader, def, &header)
                    .map_err(|e| one_line(&e))?,
            ),
        }
    }

    Ok(into_cloud(&vertices, has_color, attribute_defs))
}

/// What a vertex element carries: whether it has all three colours, and its other scalar
/// properties (name and type) in the file's order.
type VertexLayout = (bool, Vec<(String, ScalarKind)>);

/// The layout of `vertex_def`, refused without x, y and z.
fn vertex_layout(vertex_def: &ElementDef) -> Result<VertexLayout, Problem> {
    let names: Vec<&String> = vertex_def.properties.keys().collect();
    for (k, axis) in ["x", "y", "z"].iter().enumerate() {
        let named: Vec<&str> = names
            .iter()
            .filter(|n| role(n) == Role::Coordinate(k))
            .map(|n| n.as_str())
            .collect();
        match named[..] {
            [_] => {}
            [] => {
                return Err(Problem::Malformed(format!(
                    "vertex element has no '{axis}' property"
                )))
            }
            _ => {
                return Err(Problem::Malformed(format!(
                    "vertex element has {} properties for '{axis}' ({})",
                    named.len(),
                    named.join(", ")
                )))
            }
        }
    }
    let has_color = (0..3).all(|c| names.iter().any(|n| role(n) == Role::Color(c)));
    let attribute_defs = vertex_def
        .properties
        .values()
        .filter(|p| role(&p.name) == Role::Other)
        .filter_map(|p| match &p.data_type {
            PropertyType::Scalar(t) => Some((p.name.clone(), kind_of(t))),
            PropertyType::List(..) => None,
        })
        .collect();
    Ok((has_color, attribute_defs))
}

/// The cloud of the `vertices` read, with colours when `has_color` and the attributes
/// `attribute_defs` names.
fn into_cloud(
    vertices: &[Vertex],
    has_color: bool,
    attribute_defs: Vec<(String, ScalarKind)>,
) -> PointCloud {
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
    cloud
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
    let names = super::attribute_names(cloud, |n| role(n) != Role::Other);
    for (a, name) in cloud.attributes.iter().zip(names) {
        writeln!(w, "property {} {name}", type_name(a.kind))?;
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

    /// `property double X` was refused ("no 'x' property"); a vertex with both `x` and `X`
    /// is ambiguous and says so.
    #[test]
    fn coordinates_and_colours_are_named_in_any_case() {
        let header = |names: &str| {
            let properties: String = names
                .split(' ')
                .map(|n| match n.len() {
                    1 => format!("property double {n}\n"),
                    _ => format!("property uchar {n}\n"),
                })
                .collect();
            format!("ply\nformat ascii 1.0\nelement vertex 1\n{properties}end_header\n")
        };
        let c = read_str(format!("{}1 2 3 4 5 6\n", header("X Y Z Red Green Blue")).as_bytes());
        let c = c.unwrap();
        assert_eq!(c.positions, [[1.0, 2.0, 3.0]]);
        assert_eq!(c.colors.as_deref(), Some(&[[4, 5, 6]][..]));
        let both = read_str(format!("{}1 2 3 4\n", header("x y z X")).as_bytes());
        let error = both.unwrap_err().to_string();
        assert!(error.contains("2 properties for 'x' (x, X)"), "{error}");
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
    fn ascii_takes_the_float_spellings_scanners_write() {
        let text = "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\n\
            property float y\nproperty double z\nend_header\n\
            nan 1 1\n.5 2. -inf\n1e-3 NaN 4\r\n  7\t8   9  \n";
        let c = read_str(text.as_bytes()).unwrap();
        let p = &c.positions;
        assert!(p[0][0].is_nan() && p[2][1].is_nan());
        assert_eq!(p[1], [0.5, 2.0, f64::NEG_INFINITY]);
        assert_eq!([p[2][0] as f32, p[2][2] as f32], [1e-3, 4.0]);
        assert_eq!(p[3], [7.0, 8.0, 9.0]);
    }

    #[test]
    fn ascii_errors_name_the_line_that_is_wrong() {
        let header = "ply\nformat ascii 1.0\nelement face 1\nproperty list uchar int idx\n\
            element vertex 2\nproperty float x\nproperty float y\nproperty float z\n\
            property uchar red\nend_header\n3 0 1 2\n";
        for (body, bad) in [
            ("1 2 3 4\n1 2 3 4 5\n", "line 13: values \"1 2 3 4 5\""),
            ("1 2 3 4\n1 2 3\n", "line 13: values \"1 2 3\""),
            ("1 2 3 256\n1 2 3 4\n", "line 12: values \"1 2 3 256\""),
        ] {
            let e = read_str(format!("{header}{body}").as_bytes())
                .unwrap_err()
                .to_string();
            assert!(e.contains(bad), "{e}");
        }
        let short = read_str(format!("{header}1 2 3 4\n").as_bytes()).unwrap_err();
        assert!(matches!(
            short,
            Problem::Truncated {
                declared: 2,
                found: 1
            }
        ));
        let list_short = "ply\nformat ascii 1.0\nelement face 1\nproperty list uchar int idx\nend_header\n3 0 1\n";
        assert!(read_str(list_short.as_bytes()).is_err());
        let long = format!("{header}1 2 3 4\n{}\n", "9 ".repeat(100_000));
        let e = read_str(long.as_bytes()).unwrap_err().to_string();
        assert!(
            e.starts_with("line 13: values \"9 9 ") && e.len() < 200,
            "{e}"
        );
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
