//! The one point cloud type every stage shares.

/// Storage type of a per-point attribute, remembered so writers can keep the input's types.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ScalarKind {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl ScalarKind {
    pub fn size(self) -> usize {
        match self {
            ScalarKind::I8 | ScalarKind::U8 => 1,
            ScalarKind::I16 | ScalarKind::U16 => 2,
            ScalarKind::I32 | ScalarKind::U32 | ScalarKind::F32 => 4,
            ScalarKind::F64 => 8,
        }
    }
}

/// The per-point attribute that marks completed points (1) against measured ones (0); LAS
/// stores it as the point's synthetic flag.
pub const SYNTHETIC: &str = "synthetic";

/// A scalar per-point attribute the pipeline does not interpret (intensity, normals, labels…),
/// carried from input to output. Values are held as f64, which is exact for every kind.
#[derive(Debug, Clone, PartialEq)]
pub struct Attribute {
    pub name: String,
    pub kind: ScalarKind,
    pub values: Vec<f64>,
}

/// LAS-style integer quantization of coordinates (`x = offset + scale · X`), kept so that a
/// LAS file is written back with its input's scale and offset.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Quantization {
    pub scale: [f64; 3],
    pub offset: [f64; 3],
}

/// One record of a LAS file's coordinate reference system (a `LASF_Projection` VLR: GeoTIFF
/// keys, their parameters, or WKT), kept as read so that a LAS output names the input's CRS.
#[derive(Debug, Clone, PartialEq)]
pub struct CrsRecord {
    pub record_id: u16,
    pub description: String,
    pub data: Vec<u8>,
}

/// What a LAS input's header says of its points besides their coordinate system, kept so that
/// a LAS output says the same; the defaults for other inputs.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct LasSource {
    /// Whether `gps_time` counts adjusted standard GPS time (GPS seconds − 10⁹) rather than
    /// seconds of the GPS week: the header's global encoding, bit 0.
    pub standard_gps_time: bool,
    /// The file source ID: the flight line or trajectory the points come from.
    pub file_source_id: u16,
    /// The system identifier: the hardware or process that produced the points.
    pub system_identifier: String,
    /// Whether its points point into full-waveform data (formats 4, 5, 9 and 10), which no
    /// output carries.
    pub waveform: bool,
}

/// How a LAS input stored one of its extra-bytes fields (the attribute of the same name), kept
/// so that a LAS output stores it alike: a scaled integer stays a scaled integer of its width.
#[derive(Debug, Clone, PartialEq)]
pub struct StoredField {
    pub name: String,
    /// LAS's data type code, 1–10: u8, i8, u16, i16, u32, i32, u64, i64, f32, f64.
    pub data_type: u8,
    /// The value is `offset + scale · stored`.
    pub scale: f64,
    pub offset: f64,
    /// The stored value that marks "no data", as the field's description holds it.
    pub no_data: Option<[u8; 8]>,
    pub description: String,
}

/// Positions in f64 (MLS files carry georeferenced coordinates in the hundreds of kilometres),
/// optional 8-bit RGB, and the input's other attributes.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PointCloud {
    pub positions: Vec<[f64; 3]>,
    pub colors: Option<Vec<[u8; 3]>>,
    pub attributes: Vec<Attribute>,
    pub quantization: Option<Quantization>,
    /// The coordinate reference system the positions are in, where the input named one; empty
    /// otherwise, and for normalized clouds.
    pub crs: Vec<CrsRecord>,
    /// How a LAS input stored the attributes it held as extra bytes; empty otherwise.
    pub extra_bytes: Vec<StoredField>,
    pub las_source: LasSource,
    /// The sensor's pose a PCD input declared (`VIEWPOINT`: the translation, then the rotation
    /// as a quaternion w x y z), kept so that a PCD output declares it; none where it was the
    /// identity or there was none, and for normalized clouds.
    pub viewpoint: Option<[f64; 7]>,
}

/// Axis-aligned bounding box.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Aabb {
    pub min: [f64; 3],
    pub max: [f64; 3],
}

impl Aabb {
    pub fn extent(&self) -> [f64; 3] {
        [0, 1, 2].map(|i| self.max[i] - self.min[i])
    }

    pub fn center(&self) -> [f64; 3] {
        [0, 1, 2].map(|i| 0.5 * (self.max[i] + self.min[i]))
    }

    /// The longest of the three sides.
    pub fn longest_side(&self) -> f64 {
        self.extent().into_iter().fold(0.0, f64::max)
    }

    pub fn of(points: &[[f64; 3]]) -> Option<Aabb> {
        Aabb::of_iter(points.iter().copied())
    }

    /// The box of points as they come, e.g. transformed on the way; `None` when there are none.
    pub fn of_iter(points: impl IntoIterator<Item = [f64; 3]>) -> Option<Aabb> {
        let mut points = points.into_iter();
        let first = points.next()?;
        Some(points.fold(
            Aabb {
                min: first,
                max: first,
            },
            |b, p| Aabb {
                min: [0, 1, 2].map(|i| b.min[i].min(p[i])),
                max: [0, 1, 2].map(|i| b.max[i].max(p[i])),
            },
        ))
    }
}

impl PointCloud {
    pub fn from_positions(positions: Vec<[f64; 3]>) -> Self {
        PointCloud {
            positions,
            ..Default::default()
        }
    }

    pub fn len(&self) -> usize {
        self.positions.len()
    }

    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }

    pub fn bounds(&self) -> Option<Aabb> {
        Aabb::of(&self.positions)
    }

    pub fn attribute(&self, name: &str) -> Option<&Attribute> {
        self.attributes.iter().find(|a| a.name == name)
    }

    /// The points at `indices`, in that order, with all their colours and attributes.
    pub fn select(&self, indices: &[usize]) -> PointCloud {
        PointCloud {
            positions: indices.iter().map(|&i| self.positions[i]).collect(),
            colors: self
                .colors
                .as_ref()
                .map(|c| indices.iter().map(|&i| c[i]).collect()),
            attributes: self
                .attributes
                .iter()
                .map(|a| Attribute {
                    name: a.name.clone(),
                    kind: a.kind,
                    values: indices.iter().map(|&i| a.values[i]).collect(),
                })
                .collect(),
            quantization: self.quantization,
            crs: self.crs.clone(),
            extra_bytes: self.extra_bytes.clone(),
            las_source: self.las_source.clone(),
            viewpoint: self.viewpoint,
        }
    }

    /// Adds `other`'s points after this cloud's. Colours and attributes stay where both clouds
    /// have them (attributes matched by name); an empty cloud takes `other`'s as they are.
    pub fn append(&mut self, other: PointCloud) {
        if self.is_empty() {
            *self = other;
            return;
        }
        self.positions.extend(other.positions);
        self.colors = match (self.colors.take(), other.colors) {
            (Some(mut colors), Some(more)) => {
                colors.extend(more);
                Some(colors)
            }
            _ => None,
        };
        let mut more = other.attributes;
        self.attributes.retain_mut(|a| {
            let Some(at) = more
                .iter()
                .position(|b| b.name == a.name && b.kind == a.kind)
            else {
                return false;
            };
            a.values.extend(more.swap_remove(at).values);
            true
        });
    }

    /// The points for which `keep` is true.
    pub fn filter(&self, keep: &[bool]) -> PointCloud {
        let indices: Vec<usize> = (0..self.len()).filter(|&i| keep[i]).collect();
        self.select(&indices)
    }

    /// Drops points with a NaN or infinite coordinate and returns how many were dropped.
    pub fn drop_non_finite(&mut self) -> usize {
        let keep: Vec<bool> = self
            .positions
            .iter()
            .map(|p| p.iter().all(|c| c.is_finite()))
            .collect();
        let dropped = keep.iter().filter(|k| !**k).count();
        if dropped > 0 {
            *self = self.filter(&keep);
        }
        dropped
    }

    /// Positions as f32, the precision the view images and the network work in. Only meaningful
    /// for normalized clouds.
    pub fn positions_f32(&self) -> Vec<[f32; 3]> {
        self.positions.iter().map(|p| p.map(|c| c as f32)).collect()
    }

    /// Checks that every per-point array has one entry per point.
    pub fn is_consistent(&self) -> bool {
        let n = self.len();
        self.colors.as_ref().is_none_or(|c| c.len() == n)
            && self.attributes.iter().all(|a| a.values.len() == n)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Colours and attributes follow the points where both clouds have them; an empty cloud
    /// becomes the other.
    #[test]
    fn appending_keeps_what_both_clouds_carry() {
        let intensity = |values: Vec<f64>| Attribute {
            name: "intensity".into(),
            kind: ScalarKind::U16,
            values,
        };
        let mut cloud = PointCloud {
            positions: vec![[0.0; 3]],
            colors: Some(vec![[1, 2, 3]]),
            attributes: vec![intensity(vec![7.0])],
            quantization: None,
            crs: Vec::new(),
            extra_bytes: Vec::new(),
            las_source: Default::default(),
            viewpoint: None,
        };
        let other = PointCloud {
            positions: vec![[1.0; 3], [2.0; 3]],
            colors: Some(vec![[4, 5, 6], [7, 8, 9]]),
            attributes: vec![intensity(vec![8.0, 9.0])],
            quantization: None,
            crs: Vec::new(),
            extra_bytes: Vec::new(),
            las_source: Default::default(),
            viewpoint: None,
        };
        cloud.append(other.clone());
        assert_eq!(cloud.positions, [[0.0; 3], [1.0; 3], [2.0; 3]]);
        assert_eq!(
            cloud.colors.as_deref(),
            Some(&[[1, 2, 3], [4, 5, 6], [7, 8, 9]][..])
        );
        assert_eq!(cloud.attributes, [intensity(vec![7.0, 8.0, 9.0])]);

        cloud.append(PointCloud::from_positions(vec![[3.0; 3]]));
        assert_eq!(cloud.len(), 4);
        assert!(cloud.colors.is_none() && cloud.attributes.is_empty());

        let mut empty = PointCloud::default();
        empty.append(other.clone());
        assert_eq!(empty, other);
    }

    fn sample() -> PointCloud {
        PointCloud {
            positions: vec![[0.0, 0.0, 0.0], [f64::NAN, 1.0, 1.0], [2.0, -1.0, 3.0]],
            colors: Some(vec![[1, 2, 3], [4, 5, 6], [7, 8, 9]]),
            attributes: vec![Attribute {
                name: "intensity".into(),
                kind: ScalarKind::U16,
                values: vec![10.0, 20.0, 30.0],
            }],
            quantization: None,
            crs: Vec::new(),
            extra_bytes: Vec::new(),
            las_source: Default::default(),
            viewpoint: None,
        }
    }

    #[test]
    fn drop_non_finite_keeps_attributes_aligned() {
        let mut c = sample();
        assert_eq!(c.drop_non_finite(), 1);
        assert_eq!(c.positions, vec![[0.0, 0.0, 0.0], [2.0, -1.0, 3.0]]);
        assert_eq!(c.colors.as_ref().unwrap(), &vec![[1, 2, 3], [7, 8, 9]]);
        assert_eq!(c.attributes[0].values, vec![10.0, 30.0]);
        assert!(c.is_consistent());
    }

    #[test]
    fn bounds_cover_all_points() {
        let mut c = sample();
        c.drop_non_finite();
        let b = c.bounds().unwrap();
        assert_eq!(b.min, [0.0, -1.0, 0.0]);
        assert_eq!(b.max, [2.0, 0.0, 3.0]);
        assert_eq!(b.center(), [1.0, -0.5, 1.5]);
        assert!(PointCloud::default().bounds().is_none());
    }
}
