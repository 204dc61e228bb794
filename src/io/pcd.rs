//! PCD v0.7 (ascii, binary, binary_compressed). Packed colour (`rgb`/`rgba`, F or U) holds the
//! bits 0x00RRGGBB: the bits are reinterpreted, never the float value converted.

use super::{check_points, fits_f32, Encoding, Problem};
use crate::core::cloud::{Attribute, PointCloud, ScalarKind};
use std::io::Write;
use std::path::Path;

#[derive(Debug, Clone)]
struct Field {
    name: String,
    size: usize,
    kind: char,
    count: usize,
}

impl Field {
    fn scalar_kind(&self) -> Option<ScalarKind> {
        Some(match (self.kind, self.size) {
            ('I', 1) => ScalarKind::I8,
            ('U', 1) => ScalarKind::U8,
            ('I', 2) => ScalarKind::I16,
            ('U', 2) => ScalarKind::U16,
            ('I', 4) => ScalarKind::I32,
            ('U', 4) => ScalarKind::U32,
            ('F', 4) => ScalarKind::F32,
            ('F', 8) => ScalarKind::F64,
            _ => return None,
        })
    }

    fn bytes(&self) -> usize {
        self.size * self.count
    }

    fn is_color(&self) -> bool {
        (self.name == "rgb" || self.name == "rgba") && self.size == 4 && self.count == 1
    }

    /// The value of one element of this field from little-endian bytes.
    fn value(&self, b: &[u8]) -> f64 {
        match self.scalar_kind() {
            Some(ScalarKind::I8) => b[0] as i8 as f64,
            Some(ScalarKind::U8) => b[0] as f64,
            Some(ScalarKind::I16) => i16::from_le_bytes([b[0], b[1]]) as f64,
            Some(ScalarKind::U16) => u16::from_le_bytes([b[0], b[1]]) as f64,
            Some(ScalarKind::I32) => i32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
            Some(ScalarKind::U32) => u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
            Some(ScalarKind::F32) => f32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
            Some(ScalarKind::F64) => {
                f64::from_le_bytes([b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]])
            }
            None => f64::NAN,
        }
    }
}

#[derive(Debug, PartialEq)]
enum Data {
    Ascii,
    Binary,
    Compressed,
}

struct Header {
    fields: Vec<Field>,
    viewpoint: Option<[f64; 7]>,
    points: usize,
    data: Data,
    /// Byte offset of the body.
    body: usize,
}

fn malformed(msg: impl Into<String>) -> Problem {
    Problem::Malformed(msg.into())
}

/// What the header lines before `DATA` declared.
#[derive(Default)]
struct Declared {
    names: Option<Vec<String>>,
    sizes: Option<Vec<usize>>,
    kinds: Option<Vec<char>>,
    counts: Option<Vec<usize>>,
    width: Option<usize>,
    height: Option<usize>,
    points: Option<usize>,
    viewpoint: Option<[f64; 7]>,
}

/// The pose PCD files declare when they have none.
const IDENTITY: [f64; 7] = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0];

fn parse_header(bytes: &[u8]) -> Result<Header, Problem> {
    let mut declared = Declared::default();
    let mut pos = 0;
    let mut line_no = 0;
    while pos < bytes.len() {
        line_no += 1;
        let end = bytes[pos..]
            .iter()
            .position(|&b| b == b'\n')
            .map_or(bytes.len(), |e| pos + e);
        let line = std::str::from_utf8(&bytes[pos..end])
            .map_err(|_| malformed(format!("header line {line_no} is not text")))?;
        pos = (end + 1).min(bytes.len());
        let line = line.split('#').next().unwrap_or("").trim();
        if line.is_empty() {
            continue;
        }
        if let Some(data) = declared.line(line, line_no)? {
            return declared.header(data, pos);
        }
    }
    Err(malformed("header has no DATA line"))
}

impl Declared {
    /// Takes one header line; the body's encoding once the line is `DATA`.
    fn line(&mut self, line: &str, line_no: usize) -> Result<Option<Data>, Problem> {
        let mut words = line.split_whitespace();
        let key = words.next().unwrap_or("").to_ascii_uppercase();
        let rest: Vec<&str> = words.collect();
        let numbers = |what: &str| -> Result<Vec<usize>, Problem> {
            rest.iter()
                .map(|w| {
                    w.parse::<usize>().map_err(|_| {
                        malformed(format!("header line {line_no}: bad {what} value {w:?}"))
                    })
                })
                .collect()
        };
        let single = |what: &str| -> Result<usize, Problem> {
            match numbers(what)?.as_slice() {
                [n] => Ok(*n),
                _ => Err(malformed(format!(
                    "header line {line_no}: {what} needs one number"
                ))),
            }
        };
        match key.as_str() {
            "VERSION" => {}
            "VIEWPOINT" => self.viewpoint = viewpoint(&rest),
            "FIELDS" | "COLUMNS" => self.names = Some(rest.iter().map(|s| s.to_string()).collect()),
            "SIZE" => self.sizes = Some(numbers("SIZE")?),
            "COUNT" => self.counts = Some(numbers("COUNT")?),
            "TYPE" => self.kinds = Some(kinds(&rest, line_no)?),
            "WIDTH" => self.width = Some(single("WIDTH")?),
            "HEIGHT" => self.height = Some(single("HEIGHT")?),
            "POINTS" => self.points = Some(single("POINTS")?),
            "DATA" => {
                return match rest.first().map(|s| s.to_ascii_lowercase()).as_deref() {
                    Some("ascii") => Ok(Some(Data::Ascii)),
                    Some("binary") => Ok(Some(Data::Binary)),
                    Some("binary_compressed") => Ok(Some(Data::Compressed)),
                    other => Err(malformed(format!(
                        "unknown DATA encoding {:?} (expected ascii, binary or binary_compressed)",
                        other.unwrap_or("")
                    ))),
                }
            }
            _ => {
                return Err(malformed(format!(
                    "header line {line_no}: unknown keyword {key:?}"
                )))
            }
        }
        Ok(None)
    }

    /// The header the lines declared, its body starting at byte `body`, once checked: fields
    /// of known types, x, y and z single floats, and a point count within the stated limit.
    fn header(self, data: Data, body: usize) -> Result<Header, Problem> {
        let names = self
            .names
            .ok_or_else(|| malformed("header has no FIELDS line"))?;
        let n = names.len();
        let sizes = self.sizes.unwrap_or_else(|| vec![4; n]);
        let kinds = self.kinds.unwrap_or_else(|| vec!['F'; n]);
        let counts = self.counts.unwrap_or_else(|| vec![1; n]);
        if sizes.len() != n || kinds.len() != n || counts.len() != n {
            return Err(malformed(
                "FIELDS, SIZE, TYPE and COUNT list different numbers of fields",
            ));
        }
        let fields: Vec<Field> = (0..n)
            .map(|i| Field {
                name: names[i].clone(),
                size: sizes[i],
                kind: kinds[i],
                count: counts[i],
            })
            .collect();
        for f in &fields {
            if f.scalar_kind().is_none() && f.name != "_" {
                return Err(malformed(format!(
                    "field {:?} has unsupported TYPE {} SIZE {}",
                    f.name, f.kind, f.size
                )));
            }
        }
        for axis in ["x", "y", "z"] {
            match fields.iter().find(|f| f.name == axis) {
                None => return Err(malformed(format!("no '{axis}' field"))),
                Some(f) if f.kind != 'F' || f.count != 1 => {
                    return Err(malformed(format!("field '{axis}' must be a single float")))
                }
                Some(_) => {}
            }
        }
        let points = match (self.points, self.width, self.height) {
            (Some(p), _, _) => p,
            (None, Some(w), Some(h)) => w.saturating_mul(h),
            _ => return Err(malformed("header has neither POINTS nor WIDTH and HEIGHT")),
        };
        check_points(points)?;
        Ok(Header {
            fields,
            viewpoint: self.viewpoint,
            points,
            data,
            body,
        })
    }
}

/// A `VIEWPOINT` line's pose; none for the identity, and for a line that is not 7 finite
/// numbers (which no reader needs: the points do not depend on it).
fn viewpoint(rest: &[&str]) -> Option<[f64; 7]> {
    let numbers: Vec<f64> = rest
        .iter()
        .map(|w| w.parse::<f64>().ok().filter(|v| v.is_finite()))
        .collect::<Option<_>>()?;
    let pose: [f64; 7] = numbers.try_into().ok()?;
    (pose != IDENTITY).then_some(pose)
}

/// A `TYPE` line's letters.
fn kinds(rest: &[&str], line_no: usize) -> Result<Vec<char>, Problem> {
    rest.iter()
        .map(|t| match t.to_ascii_uppercase().as_str() {
            "I" => Ok('I'),
            "U" => Ok('U'),
            "F" => Ok('F'),
            _ => Err(malformed(format!(
                "header line {line_no}: unknown TYPE {t:?}"
            ))),
        })
        .collect()
}

/// Collects one point's fields (given as little-endian byte slices) into the cloud.
struct Collector {
    coord: [usize; 3],
    color: Option<usize>,
    attributes: Vec<usize>,
    cloud: PointCloud,
}

impl Collector {
    fn new(header: &Header) -> Collector {
        let find = |name: &str| {
            header
                .fields
                .iter()
                .position(|f| f.name == name)
                .expect("the header parser requires x, y and z")
        };
        let color = header.fields.iter().position(Field::is_color);
        let attributes: Vec<usize> = (0..header.fields.len())
            .filter(|&i| {
                let f = &header.fields[i];
                !["x", "y", "z"].contains(&f.name.as_str())
                    && Some(i) != color
                    && f.count == 1
                    && f.name != "_"
            })
            .collect();
        let cap = header.points.min(1 << 24);
        Collector {
            coord: [find("x"), find("y"), find("z")],
            color,
            cloud: PointCloud {
                positions: Vec::with_capacity(cap),
                colors: color.map(|_| Vec::with_capacity(cap)),
                attributes: attributes
                    .iter()
                    .map(|&i| Attribute {
                        name: header.fields[i].name.clone(),
                        kind: header.fields[i]
                            .scalar_kind()
                            .expect("the header parser accepts only known scalar kinds"),
                        values: Vec::with_capacity(cap),
                    })
                    .collect(),
                quantization: None,
                crs: Vec::new(),
                extra_bytes: Vec::new(),
                las_source: Default::default(),
                viewpoint: header.viewpoint,
            },
            attributes,
        }
    }

    fn push(
        &mut self,
        fields: &[Field],
        value: impl Fn(usize) -> f64,
        color_bits: impl Fn(usize) -> u32,
    ) {
        self.cloud.positions.push(self.coord.map(&value));
        if let (Some(i), Some(colors)) = (self.color, self.cloud.colors.as_mut()) {
            let bits = color_bits(i);
            colors.push([(bits >> 16) as u8, (bits >> 8) as u8, bits as u8]);
        }
        for (a, &i) in self.cloud.attributes.iter_mut().zip(&self.attributes) {
            debug_assert!(fields[i].count == 1);
            a.values.push(value(i));
        }
    }
}

pub(super) fn read(path: &Path) -> Result<PointCloud, Problem> {
    let bytes = std::fs::read(path)?;
    let header = parse_header(&bytes)?;
    let body = &bytes[header.body..];
    let fields = &header.fields;
    let mut collector = Collector::new(&header);
    let offsets: Vec<usize> = fields
        .iter()
        .scan(0, |acc, f| {
            let o = *acc;
            *acc += f.bytes();
            Some(o)
        })
        .collect();
    let record: usize = fields.iter().map(Field::bytes).sum();
    match header.data {
        Data::Ascii => read_ascii(body, &header, &mut collector)?,
        Data::Binary => {
            let found = body.len() / record.max(1);
            if found < header.points {
                return Err(Problem::Truncated {
                    declared: header.points,
                    found,
                });
            }
            for rec in body.chunks_exact(record).take(header.points) {
                collector.push(
                    fields,
                    |i| fields[i].value(&rec[offsets[i]..]),
                    |i| le_u32(&rec[offsets[i]..]),
                );
            }
        }
        Data::Compressed => {
            let columns = decompress(body, header.points, record)?;
            // Column-major: all points' values of field 0, then of field 1, …
            let starts: Vec<usize> = offsets.iter().map(|o| o * header.points).collect();
            for p in 0..header.points {
                let at = |i: usize| starts[i] + p * fields[i].bytes();
                collector.push(
                    fields,
                    |i| fields[i].value(&columns[at(i)..]),
                    |i| le_u32(&columns[at(i)..]),
                );
            }
        }
    }
    Ok(collector.cloud)
}

/// LZF spends at least 3 bytes on every 264 it reproduces (its longest back reference), so no
/// block expands more than this: a larger claim is refused before anything is allocated for it.
const LZF_MAX_EXPANSION: usize = 89;

/// The little-endian u32 `bytes` starts with (callers slice at least four bytes).
fn le_u32(bytes: &[u8]) -> u32 {
    u32::from_le_bytes([bytes[0], bytes[1], bytes[2], bytes[3]])
}

fn decompress(body: &[u8], points: usize, record: usize) -> Result<Vec<u8>, Problem> {
    if body.len() < 8 {
        return Err(malformed(
            "binary_compressed body is shorter than its 8-byte size prefix",
        ));
    }
    let compressed = le_u32(body) as usize;
    let uncompressed = le_u32(&body[4..]) as usize;
    let expected = points.saturating_mul(record);
    if uncompressed != expected {
        return Err(malformed(format!(
            "binary_compressed body holds {uncompressed} bytes but the header's {points} points need {expected}"
        )));
    }
    if body.len() - 8 < compressed {
        return Err(malformed(format!(
            "binary_compressed body is truncated: {} of {compressed} bytes present",
            body.len() - 8
        )));
    }
    if uncompressed == 0 {
        return Ok(Vec::new());
    }
    if uncompressed / LZF_MAX_EXPANSION > compressed {
        return Err(malformed(format!(
            "binary_compressed body of {compressed} bytes cannot hold the {uncompressed} it declares"
        )));
    }
    lzf::decompress(&body[8..8 + compressed], uncompressed)
        .map_err(|e| malformed(format!("binary_compressed body does not decompress: {e:?}")))
        .and_then(|d| {
            if d.len() == uncompressed {
                Ok(d)
            } else {
                Err(malformed(
                    "binary_compressed body decompresses to the wrong size",
                ))
            }
        })
}

fn read_ascii(body: &[u8], header: &Header, collector: &mut Collector) -> Result<(), Problem> {
    let text = std::str::from_utf8(body).map_err(|_| malformed("ascii body is not text"))?;
    let fields = &header.fields;
    // Token index of each field's first element.
    let first: Vec<usize> = fields
        .iter()
        .scan(0, |acc, f| {
            let o = *acc;
            *acc += f.count;
            Some(o)
        })
        .collect();
    let per_line: usize = fields.iter().map(|f| f.count).sum();
    let mut found = 0;
    let mut tokens: Vec<&str> = Vec::with_capacity(per_line);
    for (line_no, line) in text.lines().enumerate() {
        if found == header.points {
            break;
        }
        let line = line.trim();
        if line.is_empty() {
            continue;
        }
        tokens.clear();
        tokens.extend(line.split_whitespace());
        if tokens.len() != per_line {
            return Err(malformed(format!(
                "body line {}: {} values, expected {per_line}",
                line_no + 1,
                tokens.len()
            )));
        }
        let mut values = vec![0.0; fields.len()];
        let mut bits = vec![0u32; fields.len()];
        for (i, f) in fields.iter().enumerate() {
            if f.count != 1 && !["x", "y", "z"].contains(&f.name.as_str()) {
                continue;
            }
            let tok = tokens[first[i]];
            let bad = || {
                malformed(format!(
                    "body line {}: {tok:?} is not a number",
                    line_no + 1
                ))
            };
            if f.is_color() {
                bits[i] = if f.kind == 'F' {
                    tok.parse::<f32>().map_err(|_| bad())?.to_bits()
                } else {
                    tok.parse::<f64>().map_err(|_| bad())? as u32
                };
            } else {
                values[i] = match tok {
                    "nan" | "NaN" | "-nan" => f64::NAN,
                    _ => tok.parse::<f64>().map_err(|_| bad())?,
                };
            }
        }
        collector.push(fields, |i| values[i], |i| bits[i]);
        found += 1;
    }
    if found < header.points {
        return Err(Problem::Truncated {
            declared: header.points,
            found,
        });
    }
    Ok(())
}

fn type_and_size(k: ScalarKind) -> (char, usize) {
    let t = match k {
        ScalarKind::I8 | ScalarKind::I16 | ScalarKind::I32 => 'I',
        ScalarKind::U8 | ScalarKind::U16 | ScalarKind::U32 => 'U',
        ScalarKind::F32 | ScalarKind::F64 => 'F',
    };
    (t, k.size())
}

fn le_bytes(k: ScalarKind, v: f64, out: &mut Vec<u8>) {
    match k {
        ScalarKind::I8 => out.extend_from_slice(&(v as i8).to_le_bytes()),
        ScalarKind::U8 => out.extend_from_slice(&(v as u8).to_le_bytes()),
        ScalarKind::I16 => out.extend_from_slice(&(v as i16).to_le_bytes()),
        ScalarKind::U16 => out.extend_from_slice(&(v as u16).to_le_bytes()),
        ScalarKind::I32 => out.extend_from_slice(&(v as i32).to_le_bytes()),
        ScalarKind::U32 => out.extend_from_slice(&(v as u32).to_le_bytes()),
        ScalarKind::F32 => out.extend_from_slice(&(v as f32).to_le_bytes()),
        ScalarKind::F64 => out.extend_from_slice(&v.to_le_bytes()),
    }
}

fn packed(rgb: [u8; 3]) -> u32 {
    ((rgb[0] as u32) << 16) | ((rgb[1] as u32) << 8) | rgb[2] as u32
}

/// LZF stream of literal runs only: valid for every reader, used when the data does not
/// compress (the LZF compressor refuses such input).
fn lzf_literals(data: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(data.len() + data.len() / 32 + 1);
    for run in data.chunks(32) {
        out.push((run.len() - 1) as u8);
        out.extend_from_slice(run);
    }
    out
}

pub(super) fn write(
    w: &mut impl Write,
    cloud: &PointCloud,
    encoding: Encoding,
) -> std::io::Result<()> {
    let coord = if fits_f32(cloud) {
        ScalarKind::F32
    } else {
        ScalarKind::F64
    };
    write_header(w, cloud, coord, encoding)?;
    match encoding {
        Encoding::Ascii => write_ascii(w, cloud, coord),
        Encoding::Binary => write_binary(w, cloud, coord),
        Encoding::Compressed => write_compressed(w, cloud, coord),
    }
}

/// The header up to and including its `DATA` line: x, y, z as `coord`, then the colours and
/// the attributes.
fn write_header(
    w: &mut impl Write,
    cloud: &PointCloud,
    coord: ScalarKind,
    encoding: Encoding,
) -> std::io::Result<()> {
    let mut names = vec!["x".to_string(), "y".into(), "z".into()];
    let mut types: Vec<(char, usize)> = vec![type_and_size(coord); 3];
    if cloud.colors.is_some() {
        names.push("rgb".into());
        // PCL's own convention is F for binary; ascii is clearer as the integer.
        let ascii = encoding == Encoding::Ascii;
        types.push((if ascii { 'U' } else { 'F' }, 4));
    }
    let taken = |n: &str| ["x", "y", "z", "rgb", "rgba", "_"].contains(&n);
    names.extend(super::attribute_names(cloud, taken));
    types.extend(cloud.attributes.iter().map(|a| type_and_size(a.kind)));
    let n = cloud.len();
    let join = |v: Vec<String>| v.join(" ");
    writeln!(
        w,
        "# .PCD v0.7 - Point Cloud Data file format (written by mvpcc)"
    )?;
    writeln!(w, "VERSION 0.7")?;
    writeln!(w, "FIELDS {}", names.join(" "))?;
    writeln!(
        w,
        "SIZE {}",
        join(types.iter().map(|t| t.1.to_string()).collect())
    )?;
    writeln!(
        w,
        "TYPE {}",
        join(types.iter().map(|t| t.0.to_string()).collect())
    )?;
    writeln!(w, "COUNT {}", join(vec!["1".to_string(); names.len()]))?;
    writeln!(
        w,
        "WIDTH {n}\nHEIGHT 1\nVIEWPOINT {}\nPOINTS {n}",
        join(
            cloud
                .viewpoint
                .unwrap_or(IDENTITY)
                .map(|v| v.to_string())
                .to_vec()
        )
    )?;
    let data = match encoding {
        Encoding::Ascii => "ascii",
        Encoding::Binary => "binary",
        Encoding::Compressed => "binary_compressed",
    };
    writeln!(w, "DATA {data}")
}

fn write_ascii(w: &mut impl Write, cloud: &PointCloud, coord: ScalarKind) -> std::io::Result<()> {
    for (i, p) in cloud.positions.iter().enumerate() {
        if coord == ScalarKind::F32 {
            write!(w, "{} {} {}", p[0] as f32, p[1] as f32, p[2] as f32)?;
        } else {
            write!(w, "{} {} {}", p[0], p[1], p[2])?;
        }
        if let Some(colors) = &cloud.colors {
            write!(w, " {}", packed(colors[i]))?;
        }
        for a in &cloud.attributes {
            write!(w, " {}", a.values[i])?;
        }
        writeln!(w)?;
    }
    Ok(())
}

/// One little-endian record per point.
fn write_binary(w: &mut impl Write, cloud: &PointCloud, coord: ScalarKind) -> std::io::Result<()> {
    let mut rec = Vec::new();
    for (i, p) in cloud.positions.iter().enumerate() {
        rec.clear();
        for &c in p {
            le_bytes(coord, c, &mut rec);
        }
        if let Some(colors) = &cloud.colors {
            rec.extend_from_slice(&packed(colors[i]).to_le_bytes());
        }
        for a in &cloud.attributes {
            le_bytes(a.kind, a.values[i], &mut rec);
        }
        w.write_all(&rec)?;
    }
    Ok(())
}

/// The fields column after column, LZF-compressed, behind the two sizes.
fn write_compressed(
    w: &mut impl Write,
    cloud: &PointCloud,
    coord: ScalarKind,
) -> std::io::Result<()> {
    let mut columns = Vec::new();
    for axis in 0..3 {
        for p in &cloud.positions {
            le_bytes(coord, p[axis], &mut columns);
        }
    }
    if let Some(colors) = &cloud.colors {
        for c in colors {
            columns.extend_from_slice(&packed(*c).to_le_bytes());
        }
    }
    for a in &cloud.attributes {
        for &v in &a.values {
            le_bytes(a.kind, v, &mut columns);
        }
    }
    let compressed = if columns.is_empty() {
        Vec::new()
    } else {
        lzf::compress(&columns).unwrap_or_else(|_| lzf_literals(&columns))
    };
    w.write_all(&(compressed.len() as u32).to_le_bytes())?;
    w.write_all(&(columns.len() as u32).to_le_bytes())?;
    w.write_all(&compressed)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::PathBuf;

    fn read_bytes(bytes: &[u8]) -> Result<PointCloud, Problem> {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.pcd");
        std::fs::write(&path, bytes).unwrap();
        read(&path)
    }

    const HEADER: &str =
        "VERSION .7\nFIELDS x y z rgb intensity\nSIZE 4 4 4 4 2\nTYPE F F F U U\nCOUNT 1 1 1 1 1\n\
        WIDTH 2\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 2\n";

    #[test]
    fn ascii_with_integer_rgb_and_nan_points() {
        let text = format!("{HEADER}DATA ascii\n1 2 3 16711680 7\nnan nan nan 255 9\n");
        let c = read_bytes(text.as_bytes()).unwrap();
        assert_eq!(c.positions[0], [1.0, 2.0, 3.0]);
        assert!(c.positions[1][0].is_nan());
        assert_eq!(c.colors.unwrap(), vec![[255, 0, 0], [0, 0, 255]]);
        assert_eq!(c.attributes[0].name, "intensity");
        assert_eq!(c.attributes[0].values, vec![7.0, 9.0]);
    }

    /// The sensor pose a PCD declares was written back as the identity; it is kept through
    /// every encoding, and a VIEWPOINT that is not seven numbers is not an error.
    #[test]
    fn the_viewpoint_is_kept() {
        let pose = [1.5, -2.0, 0.25, 0.5, 0.5, -0.5, 0.5];
        let words = pose.map(|v| v.to_string()).join(" ");
        let header = HEADER.replace("VIEWPOINT 0 0 0 1 0 0 0", &format!("VIEWPOINT {words}"));
        let c = read_bytes(format!("{header}DATA ascii\n1 2 3 0 7\n4 5 6 0 9\n").as_bytes());
        let c = c.unwrap();
        assert_eq!(c.viewpoint, Some(pose));
        for encoding in [Encoding::Ascii, Encoding::Binary, Encoding::Compressed] {
            let mut written = Vec::new();
            write(&mut written, &c, encoding).unwrap();
            assert_eq!(
                read_bytes(&written).unwrap().viewpoint,
                Some(pose),
                "{encoding:?}"
            );
        }
        let odd = HEADER.replace("VIEWPOINT 0 0 0 1 0 0 0", "VIEWPOINT 0 0 0 1");
        let c = read_bytes(format!("{odd}DATA ascii\n1 2 3 0 7\n4 5 6 0 9\n").as_bytes());
        assert_eq!(c.unwrap().viewpoint, None);
    }

    #[test]
    fn float_rgb_is_read_as_bits_not_as_value() {
        let mut bytes = "FIELDS x y z rgb\nSIZE 4 4 4 4\nTYPE F F F F\nWIDTH 1\nHEIGHT 1\nPOINTS 1\nDATA binary\n"
            .as_bytes()
            .to_vec();
        for v in [0.5f32, -0.25, 0.125] {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
        bytes.extend_from_slice(&f32::from_bits(0x0012_34AB).to_le_bytes());
        let c = read_bytes(&bytes).unwrap();
        assert_eq!(c.colors.unwrap(), vec![[0x12, 0x34, 0xAB]]);
    }

    #[test]
    fn short_bodies_are_reported_as_truncated() {
        let text = format!("{HEADER}DATA ascii\n1 2 3 0 7\n");
        assert!(matches!(
            read_bytes(text.as_bytes()),
            Err(Problem::Truncated {
                declared: 2,
                found: 1
            })
        ));
        let mut bytes = format!("{HEADER}DATA binary\n").into_bytes();
        bytes.extend_from_slice(&[0u8; 18 + 5]);
        assert!(matches!(
            read_bytes(&bytes),
            Err(Problem::Truncated {
                declared: 2,
                found: 1
            })
        ));
        let mut bytes = format!("{HEADER}DATA binary_compressed\n").into_bytes();
        bytes.extend_from_slice(&100u32.to_le_bytes());
        bytes.extend_from_slice(&36u32.to_le_bytes());
        bytes.extend_from_slice(&[0u8; 10]);
        assert!(read_bytes(&bytes).is_err());
    }

    #[test]
    fn a_compressed_size_no_lzf_block_can_reach_is_refused_before_allocating() {
        // 150,000,000 points of 12 bytes (under the point limit): a 1.8 GB block claimed by 10
        // compressed bytes.
        let header = "# .PCD v0.7\nVERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\n\
                      COUNT 1 1 1\nWIDTH 150000000\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\n\
                      POINTS 150000000\nDATA binary_compressed\n";
        let mut bytes = header.as_bytes().to_vec();
        bytes.extend_from_slice(&10u32.to_le_bytes());
        bytes.extend_from_slice(&1_800_000_000u32.to_le_bytes());
        bytes.extend_from_slice(&[0u8; 10]);
        let err = read_bytes(&bytes).unwrap_err().to_string();
        assert!(err.contains("cannot hold"), "{err}");
    }

    #[test]
    fn incompressible_data_still_writes_valid_binary_compressed() {
        let data: Vec<u8> = (0..1000u32)
            .map(|i| (i.wrapping_mul(2654435761) >> 13) as u8)
            .collect();
        assert_eq!(
            lzf::decompress(&lzf_literals(&data), data.len()).unwrap(),
            data
        );
    }

    #[ignore = "needs ../shared/reference"]
    #[test]
    fn reference_clouds_read_with_their_colors() {
        let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/reference/clouds/mls");
        assert!(dir.is_dir(), "{} is absent", dir.display());
        let mut files = 0;
        for entry in std::fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            let c = read(&path).unwrap();
            files += 1;
            assert!(
                (10_000..=35_000).contains(&c.len()),
                "{}: {}",
                path.display(),
                c.len()
            );
            let b = c.bounds().unwrap();
            for i in 0..3 {
                assert!(b.min[i] >= -0.52 && b.max[i] <= 0.52, "{b:?}");
            }
            // Real colours vary: a float-converted rgb would collapse to a few values.
            let colors = c.colors.unwrap();
            let distinct: std::collections::HashSet<_> = colors.iter().collect();
            assert!(distinct.len() > 100, "{} distinct colours", distinct.len());
        }
        assert_eq!(files, 4);
    }
}
