//! LAS/LAZ tiles too large to hold in memory (`complete --scene` on a 50-million-point tile):
//! read a batch at a time, and copied into an output with points appended. The copy keeps the
//! input's header, point format and records as they are, adding one extra-bytes field, so that
//! every input point comes back bit for bit whatever the reader makes of its fields.

use super::extra_bytes;
use super::{field_values, on_decoder_thread, GuardedReader, Problem};
use las::{Color, Point, Writer};
use std::io::BufWriter;
use std::path::Path;

/// What a tile's header says, read without its points.
#[derive(Debug, Clone)]
pub struct TileHeader {
    /// Point records the header declares.
    pub points: usize,
    /// The bounds the header declares (a writer may have left them wrong; nothing depends on
    /// them but where a grid starts).
    pub min: [f64; 3],
    pub max: [f64; 3],
    /// The names of the fields its extra bytes describe.
    pub extra_fields: Vec<String>,
}

/// One point as a scene's search for vehicles needs it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScanPoint {
    pub position: [f64; 3],
    /// 16-bit colour as stored (some writers store 8-bit values as they are: the caller decides
    /// with [`super::eight_bit`]'s rule once every point is seen).
    pub color: Option<[u16; 3]>,
    /// The classification code (LAS 1.4's byte as it is).
    pub class: u8,
}

/// A point to append after the input's: a completed point of vehicle `id`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Appended {
    pub position: [f64; 3],
    pub color: Option<[u8; 3]>,
    pub id: u16,
}

/// The header of the LAS/LAZ file `path`.
pub fn tile_header(path: &Path) -> Result<TileHeader, Problem> {
    on_decoder_thread(path, |reader| {
        let header = reader.header();
        let bounds = header.bounds();
        Ok(TileHeader {
            points: header.number_of_points() as usize,
            min: [bounds.min.x, bounds.min.y, bounds.min.z],
            max: [bounds.max.x, bounds.max.y, bounds.max.z],
            extra_fields: extra_bytes::described(header)
                .into_iter()
                .map(|f| f.name().to_string())
                .collect(),
        })
    })
}

/// Reads every point of `path` in batches, handing each batch to `each`; the number of points.
pub fn scan(
    path: &Path,
    mut each: impl FnMut(&[ScanPoint]) -> Result<(), Problem> + Send,
) -> Result<usize, Problem> {
    on_decoder_thread(path, |reader| {
        let declared = reader.header().number_of_points() as usize;
        let mut seen = 0;
        let mut points = Vec::new();
        while let Some(data) = next_batch(reader)? {
            points.clear();
            let records = data.raw_bytes().chunks_exact(data.record_len());
            for (p, record) in data.points().zip(records) {
                let p = p.map_err(super::las_problem)?;
                let class = field_values(&p, record, data.format().is_extended)[1] as u8;
                points.push(ScanPoint {
                    position: [p.x, p.y, p.z],
                    color: p.color.map(|c| [c.red, c.green, c.blue]),
                    class,
                });
            }
            seen += points.len();
            each(&points)?;
        }
        if seen < declared {
            return Err(Problem::Truncated {
                declared,
                found: seen,
            });
        }
        Ok(seen)
    })
}

fn next_batch(reader: &mut GuardedReader) -> Result<Option<las::PointData>, Problem> {
    let batch = reader.batch();
    let data = reader.read_points(batch)?;
    Ok((!data.is_empty()).then_some(data))
}

/// `color` as 8-bit: scaled down where `sixteen_bit` (some value of the tile's is above 255),
/// as [`super::read`] does.
pub fn eight_bit(color: [u16; 3], sixteen_bit: bool) -> [u8; 3] {
    super::eight_bit_of(color, sixteen_bit)
}

/// Writes `input`'s points, as they are and in their order, into `output` (LAZ when
/// `compressed`) with one more extra-bytes field, `field` (u16, 0 on them; none where no field
/// is named, and then nothing is appended), then the
/// `appended` points (the synthetic flag set, `field` their id, grey where the format has
/// colour and they have none). `seen` sees each point written: its position and, for an
/// appended one, its id. Written into a temporary file that takes the output's name at the end.
pub fn copy_appending(
    input: &Path,
    output: &Path,
    compressed: bool,
    field: Option<&str>,
    appended: impl Iterator<Item = Result<Appended, Problem>> + Send,
    mut seen: impl FnMut([f64; 3], Option<u16>) + Send,
) -> Result<usize, Problem> {
    let tmp = crate::io::temp_file_beside(output).map_err(crate::io::write_problem)?;
    let file = tmp.reopen()?;
    let written = on_decoder_thread(input, |reader| {
        let header = appending_header(reader.header(), compressed, field)?;
        let extra = if field.is_some() { 2 } else { 0 };
        let format = *header.point_format();
        let mut writer = Writer::new(BufWriter::new(file), header).map_err(super::las_problem)?;
        let mut written = 0;
        while let Some(data) = next_batch(reader)? {
            for p in data.points() {
                let mut p = p.map_err(super::las_problem)?;
                seen([p.x, p.y, p.z], None);
                p.extra_bytes.resize(p.extra_bytes.len() + extra, 0);
                writer.write_point(p).map_err(super::las_problem)?;
                written += 1;
            }
        }
        for a in appended.take_while(|_| field.is_some()) {
            let a = a?;
            seen(a.position, Some(a.id));
            let [x, y, z] = a.position;
            let mut extra_bytes = vec![0; usize::from(format.extra_bytes) - 2];
            extra_bytes.extend_from_slice(&a.id.to_le_bytes());
            let point = Point {
                x,
                y,
                z,
                is_synthetic: true,
                gps_time: format.has_gps_time.then_some(0.0),
                nir: format.has_nir.then_some(0),
                color: format.has_color.then(|| {
                    let c = a.color.unwrap_or([128; 3]);
                    Color {
                        red: u16::from(c[0]) * 257,
                        green: u16::from(c[1]) * 257,
                        blue: u16::from(c[2]) * 257,
                    }
                }),
                extra_bytes,
                ..Default::default()
            };
            writer.write_point(point).map_err(super::las_problem)?;
            written += 1;
        }
        writer.close().map_err(super::las_problem)?;
        Ok(written)
    })?;
    crate::io::persist(tmp, output).map_err(crate::io::write_problem)?;
    Ok(written)
}

/// `input`'s header with room for a u16 extra-bytes field `field` after its own extra bytes,
/// without the records that describe how the input itself was compressed or indexed.
fn appending_header(
    input: &las::Header,
    compressed: bool,
    field: Option<&str>,
) -> Result<las::Header, Problem> {
    let mut builder = las::Builder::from(input.clone());
    builder.point_format.is_compressed = compressed;
    builder.vlrs.retain(|v| !is_storage(v));
    builder.evlrs.retain(|v| !is_storage(v));
    builder.generating_software = format!("mvpcc {}", env!("CARGO_PKG_VERSION"));
    let Some(field) = field else {
        return builder.into_header().map_err(super::las_problem);
    };
    let own = usize::from(input.point_format().extra_bytes);
    if own + 2 > usize::from(u16::MAX) - usize::from(input.point_format().len()) {
        return Err(Problem::Malformed(
            "its point records leave no room for one more extra-bytes field".into(),
        ));
    }
    builder.point_format.extra_bytes += 2;
    let described = extra_bytes::with_u16_after(input, field);
    builder.vlrs.retain(|v| !extra_bytes::is_description(v));
    builder.evlrs.retain(|v| !extra_bytes::is_description(v));
    builder.vlrs.push(described);
    builder.into_header().map_err(super::las_problem)
}

/// Records about how the input's points were stored (LASzip's, COPC's index), which the
/// output's writer makes anew where they apply.
fn is_storage(vlr: &las::Vlr) -> bool {
    matches!(vlr.user_id.as_str(), "laszip encoded" | "copc")
}
