//! LAS/LAZ tiles too large to hold in memory (`complete --scene` on a 50-million-point tile):
//! read a batch at a time, and copied into an output with points appended. The copy keeps the
//! input's header, point format and records as they are, adding one extra-bytes field, so that
//! every input point comes back bit for bit whatever the reader makes of its fields.

use super::extra_bytes;
use super::{field_values, on_decoder_thread, GuardedReader, Problem};
use las::point::Classification;
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
    /// with the rule of reading a tile whole once every point is seen).
    pub color: Option<[u16; 3]>,
    /// The classification code (LAS 1.4's byte as it is).
    pub class: u8,
}

/// A point to append after the input's: a completed point of vehicle `id`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Appended {
    pub position: [f64; 3],
    pub color: Option<[u8; 3]>,
    /// The classification code (that of the nearest scanned point, as read whole).
    pub class: u8,
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
/// as reading the tile whole does.
pub fn eight_bit(color: [u16; 3], sixteen_bit: bool) -> [u8; 3] {
    super::eight_bit_of(color, sixteen_bit)
}

/// Writes `input`'s points, their records byte for byte and in their order, into `output` (LAZ
/// when `compressed`) with one more extra-bytes field, `field` (u16, 0 on them; none where no
/// field is named, and then nothing is appended), then the `appended` points (the synthetic
/// flag set, `field` their id, one return of one, grey where the format has colour and they
/// have none, their colour on the tile's scale: 16-bit where `sixteen_bit`). `seen` sees each
/// point written: its position and, for an appended one, its id. Written into a temporary file
/// that takes the output's name at the end.
pub fn copy_appending(
    input: &Path,
    output: &Path,
    compressed: bool,
    field: Option<&str>,
    sixteen_bit: bool,
    appended: impl Iterator<Item = Result<Appended, Problem>> + Send,
    mut seen: impl FnMut([f64; 3], Option<u16>) + Send,
) -> Result<usize, Problem> {
    let tmp = crate::io::temp_file_beside(output).map_err(crate::io::write_problem)?;
    let file = tmp.reopen()?;
    let written = on_decoder_thread(input, |reader| {
        let header = appending_header(reader.header(), compressed, field)?;
        let writer = Writer::new(BufWriter::new(file), header).map_err(super::las_problem)?;
        // Dropped unclosed, the las crate's writer closes itself and panics where that fails
        // (a full disk): it is closed here, and forgotten where even that fails.
        let mut writer = std::mem::ManuallyDrop::new(writer);
        let written = copy_into(reader, &mut writer, field, sixteen_bit, appended, &mut seen)
            .and_then(|n| writer.close().map_err(super::las_problem).map(|()| n));
        if written.is_ok() || writer.close().is_ok() {
            drop(std::mem::ManuallyDrop::into_inner(writer));
        }
        written
    })?;
    crate::io::persist(tmp, output).map_err(crate::io::write_problem)?;
    Ok(written)
}

/// [`copy_appending`]'s points into `writer`; how many.
fn copy_into<W: std::io::Write + std::io::Seek + Send + Sync + std::fmt::Debug>(
    reader: &mut GuardedReader,
    writer: &mut Writer<W>,
    field: Option<&str>,
    sixteen_bit: bool,
    appended: impl Iterator<Item = Result<Appended, Problem>>,
    seen: &mut impl FnMut([f64; 3], Option<u16>),
) -> Result<usize, Problem> {
    let extra = if field.is_some() { 2 } else { 0 };
    let format = *writer.header().point_format();
    let slab = las::PointDataBuilder::new().for_header(writer.header());
    let t = *reader.header().transforms();
    let mut written = 0;
    while let Some(data) = next_batch(reader)? {
        let record = data.record_len();
        let mut bytes = Vec::with_capacity(data.len() * (record + extra));
        for r in data.raw_bytes().chunks_exact(record) {
            // Every point format starts with the scaled integer coordinates.
            let int = |k: usize| {
                f64::from(i32::from_le_bytes(
                    r[4 * k..4 * k + 4].try_into().expect("4 bytes"),
                ))
            };
            seen(
                [
                    t.x.offset + t.x.scale * int(0),
                    t.y.offset + t.y.scale * int(1),
                    t.z.offset + t.z.scale * int(2),
                ],
                None,
            );
            bytes.extend_from_slice(r);
            bytes.resize(bytes.len() + extra, 0);
        }
        let points = slab
            .clone()
            .build_from_bytes(bytes)
            .map_err(super::las_problem)?;
        writer.write_points(&points).map_err(super::las_problem)?;
        written += points.len();
    }
    let scale = if sixteen_bit { 257 } else { 1 };
    for a in appended.take_while(|_| field.is_some()) {
        let a = a?;
        seen(a.position, Some(a.id));
        let [x, y, z] = a.position;
        let mut extra_bytes = vec![0; usize::from(format.extra_bytes) - 2];
        extra_bytes.extend_from_slice(&a.id.to_le_bytes());
        // Formats 0–5 hold codes up to 31, which a class taken from the tile's own points is.
        let class = match Classification::new(a.class) {
            Ok(class) if format.is_extended || a.class <= 31 => class,
            _ if format.is_extended => Classification::Reserved(a.class),
            _ => Classification::Unclassified,
        };
        let point = Point {
            x,
            y,
            z,
            classification: class,
            is_synthetic: true,
            return_number: 1,
            number_of_returns: 1,
            gps_time: format.has_gps_time.then_some(0.0),
            nir: format.has_nir.then_some(0),
            color: format.has_color.then(|| {
                let c = a.color.unwrap_or([128; 3]).map(|v| u16::from(v) * scale);
                Color {
                    red: c[0],
                    green: c[1],
                    blue: c[2],
                }
            }),
            waveform: format.has_waveform.then(Default::default),
            extra_bytes,
            ..Default::default()
        };
        writer.write_point(point).map_err(super::las_problem)?;
        written += 1;
    }
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
    if usize::from(input.point_format().len()) + 2 > usize::from(u16::MAX) {
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

#[cfg(test)]
mod tests {
    use super::*;
    use las::point::Format;
    use las::Builder;

    /// A LAS 1.4 file of point format `n`: scan angles at LAS 1.4's finest steps, class 12
    /// (reserved in formats 6–10, "overlap" before), 8-bit colours.
    fn tile(path: &Path, n: u8) {
        let mut builder = Builder::from((1, 4));
        builder.point_format = Format::new(n).unwrap();
        let header = builder.into_header().unwrap();
        let format = *header.point_format();
        let mut writer = Writer::from_path(path, header).unwrap();
        for i in 0..200 {
            let point = Point {
                x: f64::from(i) * 0.01,
                y: 2.0,
                z: 3.0,
                scan_angle: if format.is_extended {
                    (i as f32 - 100.0) * 0.006
                } else {
                    (i as f32 - 100.0) * 0.5
                },
                classification: Classification::new(12).unwrap_or(Classification::Reserved(12)),
                gps_time: format.has_gps_time.then_some(f64::from(i)),
                color: format.has_color.then_some(Color {
                    red: 200,
                    green: 7,
                    blue: 0,
                }),
                nir: format.has_nir.then_some(9),
                waveform: format.has_waveform.then(Default::default),
                ..Default::default()
            };
            writer.write_point(point).unwrap();
        }
        writer.close().unwrap();
    }

    fn records(path: &Path) -> (Vec<Vec<u8>>, las::PointData) {
        let data = las::Reader::from_path(path).unwrap().read_all().unwrap();
        let records = data
            .raw_bytes()
            .chunks_exact(data.record_len())
            .map(<[u8]>::to_vec)
            .collect();
        (records, data)
    }

    /// Decoded into points and encoded again, records moved: the las crate reads a scan angle
    /// of LAS 1.4's formats back up to a step lower and their class 12 as class 1 with the
    /// overlap flag. Copied as bytes they stay; appended points fit every format, those with
    /// waveform packets too, and take the tile's colour scale (8-bit here).
    #[test]
    fn records_are_copied_byte_for_byte_and_points_appended_in_any_format() {
        let dir = tempfile::tempdir().unwrap();
        for n in [0, 1, 3, 4, 6, 7, 8, 9] {
            let (input, output) = (dir.path().join("in.las"), dir.path().join("out.laz"));
            tile(&input, n);
            let appended = Appended {
                position: [1.0, 2.0, 3.0],
                color: Some([10, 20, 30]),
                class: 64,
                id: 5,
            };
            let written = copy_appending(
                &input,
                &output,
                true,
                Some("vehicle"),
                false,
                std::iter::once(Ok(appended)),
                |_, _| {},
            )
            .unwrap();
            assert_eq!(written, 201, "format {n}");
            let ((before, _), (after, data)) = (records(&input), records(&output));
            for (b, a) in before.iter().zip(&after) {
                assert_eq!(&a[..b.len()], &b[..], "format {n}");
                assert_eq!(&a[b.len()..], &[0, 0], "format {n}");
            }
            let last = data.points().last().unwrap().unwrap();
            assert!(last.is_synthetic && last.extra_bytes.ends_with(&5u16.to_le_bytes()));
            assert_eq!((last.return_number, last.number_of_returns), (1, 1));
            if let Some(c) = last.color {
                assert_eq!([c.red, c.green, c.blue], [10, 20, 30], "format {n}");
            }
        }
    }
}
