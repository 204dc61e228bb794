//! LAS extra bytes: per-point fields after the point format's own, named and typed by the Extra
//! Bytes VLR (user `LASF_Spec`, record 4). MLS scanners store their own measurements there
//! (RIEGL's reflectance, amplitude and deviation, for example); read as attributes, they are
//! written back the way they were stored, and any other attribute is written as a field of its
//! own kind.

use crate::core::cloud::{Attribute, PointCloud, ScalarKind, StoredField};
use las::Vlr;
use std::borrow::Cow;

const USER: &str = "LASF_Spec";
const RECORD: u16 = 4;

/// Bytes of one field's description in the VLR.
const DESCRIPTION: usize = 192;

/// The most fields one VLR (at most 65,535 bytes) describes.
pub(super) const MAX_FIELDS: usize = u16::MAX as usize / DESCRIPTION;

/// Whether `vlr` is the Extra Bytes VLR.
pub(super) fn is_description(vlr: &Vlr) -> bool {
    vlr.user_id == USER && vlr.record_id == RECORD
}

/// An Extra Bytes VLR that describes `header`'s extra bytes as this module reads them
/// ([`described`]: each element of a deprecated array a field of its own, named as it is read),
/// then a u16 field `name` after them. The bytes no field describes are described as
/// undocumented (type 0), so that every field, the new one too, stays where it was.
pub(super) fn with_u16_after(header: &las::Header, name: &str) -> Vlr {
    let room = usize::from(header.point_format().extra_bytes);
    let mut data = Vec::new();
    let mut at = 0;
    for field in described(header) {
        pad(&mut data, field.at - at);
        data.extend(description(&field.stored));
        at = field.at + field.raw.size();
    }
    pad(&mut data, room - at);
    data.extend(description(&StoredField {
        name: name.into(),
        data_type: Raw::U16 as u8,
        scale: 1.0,
        offset: 0.0,
        no_data: None,
        description: String::new(),
    }));
    Vlr {
        user_id: USER.into(),
        record_id: RECORD,
        description: "Extra Bytes Record".into(),
        data,
    }
}

/// Descriptions of `n` undocumented bytes (type 0, at most 255 each).
fn pad(data: &mut Vec<u8>, mut n: usize) {
    while n > 0 {
        let bytes = n.min(usize::from(u8::MAX));
        let mut d = vec![0u8; DESCRIPTION];
        d[3] = bytes as u8;
        data.extend(d);
        n -= bytes;
    }
}

/// Where a description's parts lie: name (32 bytes), no-data value, scale and offset (three
/// 8-byte slots each, one per element of the deprecated arrays), description (32 bytes).
const NAME: usize = 4;
/// The bytes a description holds of a field's name.
const NAME_LEN: usize = 32;
const NO_DATA: usize = 40;
const SCALE: usize = 112;
const OFFSET: usize = 136;
const TEXT: usize = 160;
const TEXT_LEN: usize = 32;

/// The description's option bits that say a no-data value, a scale and an offset are given.
const HAS_NO_DATA: u8 = 1;
const HAS_SCALE: u8 = 8;
const HAS_OFFSET: u8 = 16;

/// LAS's scalar data types, numbered as its data type codes.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Raw {
    U8 = 1,
    I8,
    U16,
    I16,
    U32,
    I32,
    U64,
    I64,
    F32,
    F64,
}

impl Raw {
    fn from_code(code: u8) -> Option<Raw> {
        use Raw::*;
        [U8, I8, U16, I16, U32, I32, U64, I64, F32, F64]
            .get(usize::from(code).checked_sub(1)?)
            .copied()
    }

    fn of_kind(kind: ScalarKind) -> Raw {
        match kind {
            ScalarKind::U8 => Raw::U8,
            ScalarKind::I8 => Raw::I8,
            ScalarKind::U16 => Raw::U16,
            ScalarKind::I16 => Raw::I16,
            ScalarKind::U32 => Raw::U32,
            ScalarKind::I32 => Raw::I32,
            ScalarKind::F32 => Raw::F32,
            ScalarKind::F64 => Raw::F64,
        }
    }

    /// The attribute kind that holds this type's values once scaled: its own where one exists
    /// and nothing scales it, f64 otherwise.
    fn kind(self, scaled: bool) -> ScalarKind {
        match self {
            _ if scaled => ScalarKind::F64,
            Raw::U8 => ScalarKind::U8,
            Raw::I8 => ScalarKind::I8,
            Raw::U16 => ScalarKind::U16,
            Raw::I16 => ScalarKind::I16,
            Raw::U32 => ScalarKind::U32,
            Raw::I32 => ScalarKind::I32,
            Raw::F32 => ScalarKind::F32,
            Raw::U64 | Raw::I64 | Raw::F64 => ScalarKind::F64,
        }
    }

    fn size(self) -> usize {
        match self {
            Raw::U8 | Raw::I8 => 1,
            Raw::U16 | Raw::I16 => 2,
            Raw::U32 | Raw::I32 | Raw::F32 => 4,
            Raw::U64 | Raw::I64 | Raw::F64 => 8,
        }
    }

    fn is_integer(self) -> bool {
        !matches!(self, Raw::F32 | Raw::F64)
    }

    /// The stored value in `b` (at least [`Raw::size`] bytes, little-endian).
    fn decode(self, b: &[u8]) -> f64 {
        let mut word = [0u8; 8];
        word[..self.size()].copy_from_slice(&b[..self.size()]);
        match self {
            Raw::U8 => f64::from(word[0]),
            Raw::I8 => f64::from(word[0] as i8),
            Raw::U16 => f64::from(u16::from_le_bytes([word[0], word[1]])),
            Raw::I16 => f64::from(i16::from_le_bytes([word[0], word[1]])),
            Raw::U32 => f64::from(u32::from_le_bytes([word[0], word[1], word[2], word[3]])),
            Raw::I32 => f64::from(i32::from_le_bytes([word[0], word[1], word[2], word[3]])),
            Raw::U64 => u64::from_le_bytes(word) as f64,
            Raw::I64 => i64::from_le_bytes(word) as f64,
            Raw::F32 => f64::from(f32::from_le_bytes([word[0], word[1], word[2], word[3]])),
            Raw::F64 => f64::from_le_bytes(word),
        }
    }

    /// `stored` in this type (integers saturate), little-endian in the first [`Raw::size`]
    /// bytes.
    fn encode(self, stored: f64) -> [u8; 8] {
        let mut word = [0u8; 8];
        let mut put = |bytes: &[u8]| word[..bytes.len()].copy_from_slice(bytes);
        match self {
            Raw::U8 => put(&[stored as u8]),
            Raw::I8 => put(&(stored as i8).to_le_bytes()),
            Raw::U16 => put(&(stored as u16).to_le_bytes()),
            Raw::I16 => put(&(stored as i16).to_le_bytes()),
            Raw::U32 => put(&(stored as u32).to_le_bytes()),
            Raw::I32 => put(&(stored as i32).to_le_bytes()),
            Raw::U64 => put(&(stored as u64).to_le_bytes()),
            Raw::I64 => put(&(stored as i64).to_le_bytes()),
            Raw::F32 => put(&(stored as f32).to_le_bytes()),
            Raw::F64 => put(&stored.to_le_bytes()),
        }
        word
    }
}

/// One field of the extra bytes: how it is stored, and where in a point's extra bytes.
#[derive(Debug, Clone)]
pub(super) struct Field {
    stored: StoredField,
    raw: Raw,
    at: usize,
}

impl Field {
    pub(super) fn name(&self) -> &str {
        &self.stored.name
    }

    fn value(&self, extra: &[u8]) -> f64 {
        let raw = self.raw.decode(&extra[self.at..self.at + self.raw.size()]);
        self.stored.offset + self.stored.scale * raw
    }

    /// The stored value that reads back as `value` exactly, if there is one.
    fn stored_value(&self, value: f64) -> Option<f64> {
        let s = &self.stored;
        let mut stored = (value - s.offset) / s.scale;
        stored = match self.raw {
            raw if raw.is_integer() => stored.round(),
            Raw::F32 => f64::from(stored as f32),
            _ => stored,
        };
        let back = s.offset + s.scale * self.raw.decode(&self.raw.encode(stored));
        (back == value || (back.is_nan() && value.is_nan())).then_some(stored)
    }
}

/// The extra-bytes fields a header describes, in the order a point holds them: those of LAS's
/// ten scalar types and the elements of its deprecated 2- and 3-element arrays (as `name_0`…).
/// Bytes without a description, or of an undocumented layout, are skipped; a field that does
/// not fit in the point's extra bytes, and everything after a type LAS does not define, is left
/// out.
pub(super) fn described(header: &las::Header) -> Vec<Field> {
    let room = usize::from(header.point_format().extra_bytes);
    let Some(vlr) = header
        .all_vlrs()
        .find(|v| v.user_id == USER && v.record_id == RECORD)
    else {
        return Vec::new();
    };
    let mut fields = Vec::new();
    let mut at = 0;
    for (k, d) in vlr.data.chunks_exact(DESCRIPTION).enumerate() {
        let (data_type, options) = (d[2], d[3]);
        if data_type == 0 {
            at += usize::from(options);
            continue;
        }
        let count = usize::from((data_type - 1) / 10 + 1);
        let Some(raw) = Raw::from_code((data_type - 1) % 10 + 1).filter(|_| count <= 3) else {
            break;
        };
        let name = field_name(&d[NAME..NAME + NAME_LEN], k);
        for j in 0..count {
            if at + raw.size() > room {
                return fields;
            }
            let name = if count == 1 {
                name.clone()
            } else {
                format!("{name}_{j}")
            };
            fields.push(element(d, raw, name, j, at));
            at += raw.size();
        }
    }
    fields
}

/// Element `j` of the field description `d` (0 unless it describes an array), stored as `raw`
/// from byte `at` of a point's extra bytes.
fn element(d: &[u8], raw: Raw, name: String, j: usize, at: usize) -> Field {
    let options = d[3];
    let slot = |base: usize| -> [u8; 8] {
        d[base + 8 * j..base + 8 * j + 8]
            .try_into()
            .expect("eight bytes")
    };
    let given = |bit: u8, base: usize| (options & bit != 0).then(|| f64::from_le_bytes(slot(base)));
    let scale = given(HAS_SCALE, SCALE).filter(|s| s.is_finite() && *s != 0.0);
    let offset = given(HAS_OFFSET, OFFSET).filter(|o| o.is_finite());
    Field {
        stored: StoredField {
            name,
            data_type: raw as u8,
            scale: scale.unwrap_or(1.0),
            offset: offset.unwrap_or(0.0),
            no_data: (options & HAS_NO_DATA != 0).then(|| slot(NO_DATA)),
            description: c_string(&d[TEXT..TEXT + TEXT_LEN]),
        },
        raw,
        at,
    }
}

/// A description's name as an attribute name: PLY and PCD headers separate names by spaces,
/// so spaces and control characters become `_`; a field without a name is named by its place.
fn field_name(bytes: &[u8], k: usize) -> String {
    let name: String = c_string(bytes)
        .trim()
        .chars()
        .map(|c| {
            if c.is_whitespace() || c.is_control() {
                '_'
            } else {
                c
            }
        })
        .collect();
    if name.is_empty() {
        format!("extra_{k}")
    } else {
        name
    }
}

/// The text before the first NUL.
fn c_string(bytes: &[u8]) -> String {
    let end = bytes.iter().position(|&b| b == 0).unwrap_or(bytes.len());
    String::from_utf8_lossy(&bytes[..end]).into_owned()
}

/// The values of `fields` read so far, a column each, the fields named apart from `taken` (the
/// point format's own fields) and from each other.
pub(super) struct Columns {
    fields: Vec<Field>,
    values: Vec<Vec<f64>>,
}

impl Columns {
    pub(super) fn new(mut fields: Vec<Field>, taken: &[&str]) -> Columns {
        let mut names: Vec<String> = taken.iter().map(|s| s.to_string()).collect();
        for field in &mut fields {
            let name = &mut field.stored.name;
            *name = crate::io::free_name(name, |n| names.iter().any(|m| m == n));
            names.push(name.clone());
        }
        let values = vec![Vec::new(); fields.len()];
        Columns { fields, values }
    }

    pub(super) fn push(&mut self, extra: &[u8]) {
        for (field, column) in self.fields.iter().zip(&mut self.values) {
            column.push(field.value(extra));
        }
    }

    /// The columns as attributes, and how each was stored.
    pub(super) fn into_attributes(self) -> (Vec<Attribute>, Vec<StoredField>) {
        let attributes = self
            .fields
            .iter()
            .zip(self.values)
            .map(|(field, values)| {
                let s = &field.stored;
                Attribute {
                    name: s.name.clone(),
                    kind: field.raw.kind(s.scale != 1.0 || s.offset != 0.0),
                    values,
                }
            })
            .collect();
        let stored = self.fields.into_iter().map(|f| f.stored).collect();
        (attributes, stored)
    }
}

/// How a LAS output stores the attributes that are not fields of its point format: as the
/// input stored the attribute of the same name where that reads back every value exactly, else
/// unscaled in the attribute's own kind.
pub(super) struct Layout<'a> {
    /// Each field and its stored values.
    fields: Vec<(Field, Cow<'a, [f64]>)>,
}

impl<'a> Layout<'a> {
    /// The layout for `cloud`'s attributes other than those named in `standard`.
    pub(super) fn new(cloud: &'a PointCloud, standard: &[&str]) -> Layout<'a> {
        let mut at = 0;
        let mut fields = Vec::new();
        let mut given: Vec<String> = (cloud.attributes.iter())
            .map(|a| a.name.clone())
            .filter(|name| name.len() <= NAME_LEN)
            .collect();
        for attribute in &cloud.attributes {
            if !standard.contains(&attribute.name.as_str()) {
                let (mut field, stored) = stored_as(cloud, attribute, at);
                if field.stored.name.len() > NAME_LEN {
                    field.stored.name = fitting(&field.stored.name, &given);
                    given.push(field.stored.name.clone());
                }
                at += field.raw.size();
                fields.push((field, stored));
            }
        }
        Layout { fields }
    }

    /// How many fields the layout has.
    pub(super) fn fields(&self) -> usize {
        self.fields.len()
    }

    /// Bytes of extra bytes per point.
    pub(super) fn len(&self) -> usize {
        self.fields.iter().map(|(f, _)| f.raw.size()).sum()
    }

    /// The Extra Bytes VLR that describes the layout; none for a layout without fields.
    pub(super) fn vlr(&self) -> Option<Vlr> {
        (!self.fields.is_empty()).then(|| Vlr {
            user_id: USER.into(),
            record_id: RECORD,
            description: "Extra Bytes Record".into(),
            data: self
                .fields
                .iter()
                .flat_map(|(f, _)| description(&f.stored))
                .collect(),
        })
    }

    /// Point `i`'s extra bytes.
    pub(super) fn bytes(&self, i: usize) -> Vec<u8> {
        let mut out = Vec::with_capacity(self.len());
        for (field, stored) in &self.fields {
            out.extend_from_slice(&field.raw.encode(stored[i])[..field.raw.size()]);
        }
        out
    }
}

/// The field `attribute` is written as, starting at byte `at`, and its stored values.
fn stored_as<'a>(
    cloud: &PointCloud,
    attribute: &'a Attribute,
    at: usize,
) -> (Field, Cow<'a, [f64]>) {
    let kept = cloud
        .extra_bytes
        .iter()
        .filter(|s| s.name == attribute.name)
        .find_map(|s| {
            let field = Field {
                stored: s.clone(),
                raw: Raw::from_code(s.data_type)?,
                at,
            };
            let stored: Option<Vec<f64>> = attribute
                .values
                .iter()
                .map(|&v| field.stored_value(v))
                .collect();
            Some((field, Cow::Owned(stored?)))
        });
    kept.unwrap_or_else(|| {
        let raw = Raw::of_kind(attribute.kind);
        let field = Field {
            stored: StoredField {
                name: attribute.name.clone(),
                data_type: raw as u8,
                scale: 1.0,
                offset: 0.0,
                no_data: None,
                description: String::new(),
            },
            raw,
            at,
        };
        (field, Cow::Borrowed(&attribute.values[..]))
    })
}

/// The 192-byte description of a field; names and texts longer than their 32 bytes are cut at a
/// character's end.
fn description(s: &StoredField) -> Vec<u8> {
    let mut d = vec![0u8; DESCRIPTION];
    d[2] = s.data_type;
    let mut options = 0;
    if let Some(no_data) = s.no_data {
        options |= HAS_NO_DATA;
        d[NO_DATA..NO_DATA + 8].copy_from_slice(&no_data);
    }
    if s.scale != 1.0 {
        options |= HAS_SCALE;
        d[SCALE..SCALE + 8].copy_from_slice(&s.scale.to_le_bytes());
    }
    if s.offset != 0.0 {
        options |= HAS_OFFSET;
        d[OFFSET..OFFSET + 8].copy_from_slice(&s.offset.to_le_bytes());
    }
    d[3] = options;
    put_text(&mut d[NAME..NAME + NAME_LEN], &s.name);
    put_text(&mut d[TEXT..TEXT + TEXT_LEN], &s.description);
    d
}

fn put_text(slot: &mut [u8], text: &str) {
    let cut = cut(text, slot.len());
    slot[..cut.len()].copy_from_slice(cut.as_bytes());
}

/// `text`'s first `len` bytes at most, ending at a character's end.
fn cut(text: &str, len: usize) -> &str {
    let mut end = text.len().min(len);
    while !text.is_char_boundary(end) {
        end -= 1;
    }
    &text[..end]
}

/// A name longer than a description holds, cut to fit and numbered (`…_2`) where the cut makes
/// it one of the names `given`: two attributes that differ only past their 32nd byte were
/// described under one name, and read back as one.
fn fitting(name: &str, given: &[String]) -> String {
    let fits = |candidate: &String| !given.contains(candidate);
    let mut candidate = cut(name, NAME_LEN).to_string();
    let mut n = 1;
    while !fits(&candidate) {
        n += 1;
        let suffix = format!("_{n}");
        candidate = format!("{}{suffix}", cut(name, NAME_LEN - suffix.len()));
    }
    candidate
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::{read_cloud, write_cloud, Encoding};
    use las::{Builder, Point, Writer};

    /// A description as a scanner's software writes one.
    fn described_as(
        data_type: u8,
        name: &str,
        scale: Option<f64>,
        no_data: Option<i64>,
    ) -> Vec<u8> {
        description(&StoredField {
            name: name.into(),
            data_type,
            scale: scale.unwrap_or(1.0),
            offset: 0.0,
            no_data: no_data.map(i64::to_le_bytes),
            description: format!("{name} as measured"),
        })
    }

    /// Reflectance (i16, 0.01 dB), deviation (u16), an unnamed f32 with a space in its name,
    /// two undescribed bytes and a deprecated 3-element u8 array: 2 + 2 + 4 + 2 + 3 bytes.
    fn scanner_file(path: &std::path::Path, ext_len: u16) {
        let mut undescribed = vec![0u8; DESCRIPTION];
        undescribed[3] = 2;
        let data = [
            described_as(4, "Reflectance", Some(0.01), Some(-32768)),
            described_as(3, "Deviation", None, None),
            described_as(9, "Amplitude ratio", None, None),
            undescribed,
            described_as(21, "triple", None, None),
        ]
        .concat();
        let mut builder = Builder::from((1, 4));
        builder.point_format = las::point::Format::new(6).unwrap();
        builder.point_format.extra_bytes = ext_len;
        builder.vlrs.push(Vlr {
            user_id: USER.into(),
            record_id: RECORD,
            description: "Extra Bytes Record".into(),
            data,
        });
        let header = builder.into_header().unwrap();
        let mut writer = Writer::from_path(path, header).unwrap();
        for i in 0..5i16 {
            let extra = [
                (-250 + 100 * i).to_le_bytes().to_vec(),
                (7u16 * i as u16).to_le_bytes().to_vec(),
                (0.5f32 * f32::from(i)).to_le_bytes().to_vec(),
                vec![0xAB, 0xCD],
                vec![i as u8, 2 * i as u8, 255],
            ]
            .concat();
            let point = Point {
                x: f64::from(i),
                y: 1.0,
                z: 2.0,
                gps_time: Some(0.0),
                extra_bytes: extra[..usize::from(ext_len)].to_vec(),
                ..Default::default()
            };
            writer.write_point(point).unwrap();
        }
        writer.close().unwrap();
    }

    /// `cloud` written to `path` and read back, every attribute checked to come back as it was.
    fn written_back(cloud: &PointCloud, path: &std::path::Path) -> PointCloud {
        write_cloud(path, cloud, None, Encoding::Binary).unwrap();
        let back = read_cloud(path, None).unwrap().cloud;
        for a in &cloud.attributes {
            let want = (a.kind, a.values.clone());
            assert_eq!(
                values(&back, &a.name),
                want,
                "{} {}",
                a.name,
                path.display()
            );
        }
        back
    }

    fn values(cloud: &PointCloud, name: &str) -> (ScalarKind, Vec<f64>) {
        let a = cloud
            .attribute(name)
            .unwrap_or_else(|| panic!("{name} missing"));
        (a.kind, a.values.clone())
    }

    /// Extra bytes were dropped, so `complete scan.las out.las` lost a scanner's reflectance,
    /// deviation and the like. They are read as attributes in their units and written back as
    /// they were stored: the scaled i16 stays a scaled i16.
    #[test]
    fn a_scanners_extra_bytes_are_read_and_written_back_as_stored() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("scan.las");
        scanner_file(&path, 13);
        let cloud = read_cloud(&path, None).unwrap().cloud;
        let reflectance = [-2.5, -1.5, -0.5, 0.5, 1.5].map(|k: f64| 0.01 * (k * 100.0).round());
        assert_eq!(
            values(&cloud, "Reflectance"),
            (ScalarKind::F64, reflectance.to_vec())
        );
        assert_eq!(
            values(&cloud, "Deviation"),
            (ScalarKind::U16, vec![0.0, 7.0, 14.0, 21.0, 28.0])
        );
        assert_eq!(
            values(&cloud, "Amplitude_ratio"),
            (ScalarKind::F32, vec![0.0, 0.5, 1.0, 1.5, 2.0])
        );
        assert_eq!(values(&cloud, "triple_1").1, [0.0, 2.0, 4.0, 6.0, 8.0]);
        assert_eq!(values(&cloud, "triple_2").1, [255.0; 5]);
        assert_eq!(
            cloud.extra_bytes[0].no_data,
            Some((-32768i64).to_le_bytes())
        );
        for ext in ["las", "laz", "ply"] {
            let out = dir.path().join(format!("out.{ext}"));
            let back = written_back(&cloud, &out);
            if ext != "ply" {
                // The undescribed bytes are not kept: 2 + 2 + 4 + 3 · 1.
                let header = las::Reader::from_path(&out).unwrap().header().clone();
                assert_eq!(header.point_format().extra_bytes, 11, "{ext}");
                assert_eq!(back.extra_bytes, cloud.extra_bytes, "{ext}");
            }
        }
    }

    /// The Extra Bytes VLR describes at most 341 fields and a point record holds at most 65,535
    /// bytes: more attributes are an error that says so, and nothing is written (342 u8
    /// attributes failed with "feature Evlrs is not supported by version 1.2"); 341 f64 ones
    /// are written.
    #[test]
    fn attributes_past_what_a_las_file_describes_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("wide.las");
        let wide = |count: usize, kind| PointCloud {
            positions: vec![[0.0, 1.0, 2.0]],
            attributes: (0..count)
                .map(|k| Attribute {
                    name: format!("a{k}"),
                    kind,
                    values: vec![k as f64],
                })
                .collect(),
            ..PointCloud::default()
        };
        let error = write_cloud(&path, &wide(342, ScalarKind::U8), None, Encoding::Binary);
        let error = error.unwrap_err().to_string();
        assert!(error.contains("its 342 attributes besides"), "{error}");
        assert!(!path.exists());
        written_back(&wide(341, ScalarKind::F64), &path);
    }

    /// A field the point's bytes cannot hold is left out, not read past the record's end.
    #[test]
    fn fields_past_the_points_extra_bytes_are_left_out() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("short.las");
        scanner_file(&path, 5);
        let cloud = read_cloud(&path, None).unwrap().cloud;
        assert!(cloud.attribute("Deviation").is_some());
        assert!(cloud.attribute("Amplitude_ratio").is_none());
        assert!(cloud.attribute("triple_0").is_none());
    }

    /// Attributes from other formats (a PLY's normals and labels) were dropped by LAS output;
    /// now each is a field of its own kind. A kept description that no longer holds the values
    /// exactly gives way to the attribute's kind, and names do not collide with the point
    /// format's own fields.
    #[test]
    fn other_attributes_become_extra_bytes_of_their_kind() {
        let n = 4;
        let column = |name: &str, kind, values: Vec<f64>| Attribute {
            name: name.into(),
            kind,
            values,
        };
        let cloud = PointCloud {
            positions: (0..n).map(|i| [i as f64, 0.5, -1.0]).collect(),
            attributes: vec![
                column("nx", ScalarKind::F32, vec![0.25, -0.5, 1.0, 0.0]),
                column("label", ScalarKind::I32, vec![-7.0, 0.0, 70_000.0, 3.0]),
                column(
                    "Reflectance",
                    ScalarKind::F64,
                    vec![0.123_456, -3.0, 0.0, 1e-9],
                ),
            ],
            extra_bytes: vec![StoredField {
                name: "Reflectance".into(),
                data_type: 4,
                scale: 0.01,
                offset: 0.0,
                no_data: None,
                description: String::new(),
            }],
            ..PointCloud::default()
        };
        let dir = tempfile::tempdir().unwrap();
        written_back(&cloud, &dir.path().join("out.las"));
        let taken = Columns::new(
            vec![Field {
                stored: StoredField {
                    name: "intensity".into(),
                    ..cloud.extra_bytes[0].clone()
                },
                raw: Raw::U8,
                at: 0,
            }],
            &["intensity", "intensity_2"],
        );
        assert_eq!(taken.into_attributes().0[0].name, "intensity_3");
    }

    /// Names past a description's 32 bytes are cut; two that differ only beyond them were
    /// described under one name and read back as one attribute (the second's values lost).
    #[test]
    fn long_names_cut_to_fit_stay_apart() {
        let long = "return_echo_amplitude_of_channel_";
        let names = [format!("{long}1"), format!("{long}2"), format!("{long}3")];
        let mut attributes: Vec<Attribute> = (names.iter().enumerate())
            .map(|(k, name)| Attribute {
                name: name.clone(),
                kind: ScalarKind::U16,
                values: vec![k as f64; 3],
            })
            .collect();
        attributes.push(Attribute {
            name: "return_echo_amplitude_of_chann_2".into(),
            kind: ScalarKind::U8,
            values: vec![9.0; 3],
        });
        let cloud = PointCloud {
            positions: vec![[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
            attributes,
            ..PointCloud::default()
        };
        let dir = tempfile::tempdir().unwrap();
        write_cloud(&dir.path().join("out.las"), &cloud, None, Encoding::Binary).unwrap();
        let back = read_cloud(&dir.path().join("out.las"), None).unwrap().cloud;
        let read_as = |name: &str| values(&back, name).1[0];
        assert_eq!(read_as("return_echo_amplitude_of_channel"), 0.0);
        assert_eq!(read_as("return_echo_amplitude_of_chann_3"), 1.0);
        assert_eq!(read_as("return_echo_amplitude_of_chann_4"), 2.0);
        assert_eq!(read_as("return_echo_amplitude_of_chann_2"), 9.0);
    }

    /// A tile streamed through `complete --scene` keeps a scanner's extra bytes as they were,
    /// described or not, and the new `vehicle` field after them: with every description
    /// fitting the records (13 bytes) and with the last one past them (11).
    #[test]
    fn a_streamed_copy_keeps_every_extra_byte_and_adds_the_vehicle_after_them() {
        use super::super::stream::{copy_appending, Appended};
        for ext_len in [13u16, 11] {
            let dir = tempfile::tempdir().unwrap();
            let (path, out) = (dir.path().join("scan.las"), dir.path().join("out.laz"));
            scanner_file(&path, ext_len);
            let appended = Appended {
                position: [9.0, 1.0, 2.0],
                color: None,
                class: 0,
                id: 3,
            };
            let mut seen = Vec::new();
            let written = copy_appending(
                &path,
                &out,
                true,
                Some("vehicle"),
                true,
                std::iter::once(Ok(appended)),
                |p, id| seen.push((p[0], id)),
            )
            .unwrap();
            assert_eq!(written, 6);
            assert_eq!(seen.last(), Some(&(9.0, Some(3))));
            let (input, output) = (
                read_cloud(&path, None).unwrap().cloud,
                read_cloud(&out, None).unwrap().cloud,
            );
            assert_eq!(output.positions[..5], input.positions[..]);
            for a in &input.attributes {
                let (kind, values) = values(&output, &a.name);
                assert_eq!((kind, &values[..5]), (a.kind, &a.values[..]), "{}", a.name);
            }
            assert_eq!(
                values(&output, "vehicle"),
                (ScalarKind::U16, vec![0.0, 0.0, 0.0, 0.0, 0.0, 3.0])
            );
            let synthetic = &output
                .attribute(crate::core::cloud::SYNTHETIC)
                .unwrap()
                .values;
            assert_eq!(synthetic, &[0.0, 0.0, 0.0, 0.0, 0.0, 1.0]);
            let raw = |path: &std::path::Path| -> Vec<Vec<u8>> {
                let data = las::Reader::from_path(path).unwrap().read_all().unwrap();
                data.points().map(|p| p.unwrap().extra_bytes).collect()
            };
            let (before, after) = (raw(&path), raw(&out));
            for (b, a) in before.iter().zip(&after) {
                assert_eq!(&a[..b.len()], &b[..], "{ext_len} bytes");
                assert_eq!(a.len(), b.len() + 2);
            }
        }
    }
}
