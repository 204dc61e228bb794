//! LAS and LAZ through the `las` crate: scaled integer coordinates (scale and offset kept for
//! writing back), RGB (16-bit scaled to 8), the point record's fields ([`FIELDS`], the synthetic
//! flag as the [`SYNTHETIC`] attribute), the extra bytes ([`extra_bytes`]) and the coordinate
//! reference system's records.

mod extra_bytes;
pub mod stream;

use super::{check_fields, check_points, Problem};
use crate::core::cloud::{
    Attribute, CrsRecord, LasSource, PointCloud, Quantization, ScalarKind, SYNTHETIC,
};
use crate::core::guard::guarded;
use las::point::{Classification, Format};
use las::{Builder, Color, Point, Transform, Vector, Vlr, Writer};
use std::io::{BufReader, BufWriter};
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

/// Bytes of point records read at a time: a header may declare records of up to 64 KiB, so the
/// batch is sized in bytes, not points.
const BATCH_BYTES: u64 = 16 << 20;

fn las_problem(e: las::Error) -> Problem {
    match e {
        las::Error::Io(io) if io.kind() == std::io::ErrorKind::UnexpectedEof => {
            Problem::Malformed("file ends before all the points its header declares".into())
        }
        las::Error::Io(io) => Problem::Io(io),
        other => Problem::Malformed(other.to_string().replace('\n', " ")),
    }
}

/// Checks what a LAS/LAZ header claims against the file before the las and laz crates act on
/// it: they allocate claimed sizes up front and panic on some inconsistencies. One read of the
/// header (at most 375 bytes) serves every check; anything else odd is left for the las crate
/// to report.
fn check_claims(path: &Path) -> Result<(), Problem> {
    use std::io::Read;
    let mut file = std::fs::File::open(path)?;
    let size = file.metadata()?.len();
    let mut header = Vec::with_capacity(375);
    (&mut file).take(375).read_to_end(&mut header)?;
    if !header.starts_with(b"LASF") || header.len() < 107 {
        return Ok(());
    }
    // LASzip marks compressed point formats with the top bit.
    if header[104] & 0x80 != 0 {
        check_laszip_items(&mut file, &header)?;
        check_chunk_table(&mut file, &header, size)?;
    }
    if header[25] >= 4 && header.len() >= 247 {
        check_evlrs(&mut file, &header, size)?;
    }
    Ok(())
}

/// Reads `bytes.len()` bytes at `at`; false where the file ends first.
fn read_at(file: &mut std::fs::File, at: std::io::SeekFrom, bytes: &mut [u8]) -> bool {
    use std::io::{Read, Seek};
    file.seek(at).and_then(|_| file.read_exact(bytes)).is_ok()
}

fn u16_at(b: &[u8], at: usize) -> u16 {
    u16::from_le_bytes([b[at], b[at + 1]])
}

fn u32_at(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]])
}

fn u64_at(b: &[u8], at: usize) -> u64 {
    u64::from_le_bytes(b[at..at + 8].try_into().expect("eight bytes"))
}

/// A LAZ chunk table must not claim more chunks than the file has bytes: the laz crate sizes a
/// table for the claimed count (up to 2³² entries, 64 GiB) before decoding it.
fn check_chunk_table(file: &mut std::fs::File, header: &[u8], size: u64) -> Result<(), Problem> {
    use std::io::SeekFrom;
    let data_start = u64::from(u32_at(header, 96));
    let mut word = [0u8; 8];
    if !read_at(file, SeekFrom::Start(data_start), &mut word) {
        return Ok(());
    }
    // A writer that could not seek back leaves the table's offset at the end of the file.
    let mut table = i64::from_le_bytes(word);
    if table <= data_start as i64 {
        if !read_at(file, SeekFrom::End(-8), &mut word) {
            return Ok(());
        }
        table = i64::from_le_bytes(word);
    }
    let mut count = [0u8; 4];
    if table <= data_start as i64 || !read_at(file, SeekFrom::Start(table as u64 + 4), &mut count) {
        return Ok(());
    }
    let chunks = u32::from_le_bytes(count);
    if u64::from(chunks) > size {
        return Err(Problem::Malformed(format!(
            "LAZ chunk table declares {chunks} chunks, more than the file's {size} bytes hold"
        )));
    }
    Ok(())
}

/// LAS 1.4 extended VLRs must not claim more bytes than the file holds: the las crate
/// allocates an EVLR's claimed length (a u64) before reading it.
fn check_evlrs(file: &mut std::fs::File, header: &[u8], size: u64) -> Result<(), Problem> {
    const EVLR_HEADER: u64 = 60;
    let mut at = u64_at(header, 235);
    let mut evlr = [0u8; EVLR_HEADER as usize];
    for k in 0..u32_at(header, 243) {
        if !read_at(file, std::io::SeekFrom::Start(at), &mut evlr) {
            return Ok(());
        }
        let length = u64_at(&evlr, 20);
        let end = at.saturating_add(EVLR_HEADER).saturating_add(length);
        if end > size {
            return Err(Problem::Malformed(format!(
                "extended VLR {} declares {length} bytes past the end of the file",
                k + 1
            )));
        }
        at = end;
    }
    Ok(())
}

/// A LASzip description must list point items that add up to the header's point record: the
/// laz crate panics otherwise. Only the VLRs are read.
fn check_laszip_items(file: &mut std::fs::File, header: &[u8]) -> Result<(), Problem> {
    use std::io::Read;
    const VLR_HEADER: usize = 54;
    let record = u16_at(header, 105);
    let mut at = u64::from(u16_at(header, 94));
    let mut vlr = [0u8; VLR_HEADER];
    for _ in 0..u32_at(header, 100) {
        if !read_at(file, std::io::SeekFrom::Start(at), &mut vlr) {
            return Ok(());
        }
        let length = u16_at(&vlr, 20);
        if vlr[2..16].starts_with(b"laszip encoded") && u16_at(&vlr, 18) == 22204 {
            let mut data = vec![0u8; usize::from(length)];
            if file.read_exact(&mut data).is_err() {
                return Ok(());
            }
            return check_items(&data, record);
        }
        at += VLR_HEADER as u64 + u64::from(length);
    }
    Ok(())
}

/// The LASzip description's point items must exist and add up to the header's point record
/// length.
fn check_items(data: &[u8], record: u16) -> Result<(), Problem> {
    // The item count follows 32 bytes of versions, options and sizes; each item is 6 bytes.
    let Some(count) = data.get(32..34).map(|b| usize::from(u16_at(b, 0))) else {
        return Ok(());
    };
    if count == 0 {
        return Err(Problem::Malformed(
            "its LASzip description lists no point items".into(),
        ));
    }
    let sizes: Option<u32> = (0..count)
        .map(|i| data.get(34 + 6 * i + 2..34 + 6 * i + 4))
        .map(|b| b.map(|b| u32::from(u16_at(b, 0))))
        .sum();
    match sizes {
        Some(total) if total != u32::from(record) => Err(Problem::Malformed(format!(
            "its LASzip items describe {total}-byte points, its header {record}-byte ones"
        ))),
        _ => Ok(()),
    }
}

pub(super) fn read(path: &Path) -> Result<PointCloud, Problem> {
    on_decoder_thread(path, read_checked)
}

/// Runs `f` on a LAS/LAZ reader of `path` (its claims checked first), on a thread of its own
/// with a deep stack: the laz crate's GPS-time decoder recurses once per "switch sequence"
/// symbol, and a damaged file of 1,248 bytes (a fuzz finding) asks for about 300 MiB of stack
/// in a release build, several GiB in a debug one, before its data runs out. Stack pages cost
/// memory only when touched; where the address space is limited, smaller stacks are tried.
/// [`StackGuard`] ends such a descent with an error before the stack does, and a panic in the
/// decoder becomes an error.
fn on_decoder_thread<T: Send>(
    path: &Path,
    f: impl FnOnce(&mut GuardedReader) -> Result<T, Problem> + Send,
) -> Result<T, Problem> {
    check_claims(path)?;
    // Held apart from each try, so that a thread that could not be started leaves it for the
    // next one.
    let f = std::sync::Mutex::new(Some(f));
    let decoded = DECODER_STACKS.iter().find_map(|&stack| {
        std::thread::scope(|scope| {
            std::thread::Builder::new()
                .name("las".into())
                .stack_size(stack)
                .spawn_scoped(scope, || {
                    let floor = stack_floor(stack);
                    let f = f
                        .lock()
                        .unwrap_or_else(std::sync::PoisonError::into_inner)
                        .take()
                        .expect("one thread takes the decoding");
                    guarded(|| {
                        let mut reader = GuardedReader::open(path, floor)?;
                        f(&mut reader).map_err(|p| reader.problem_of(p))
                    })
                })
                .ok()
                .map(|thread| {
                    thread
                        .join()
                        .unwrap_or_else(|_| Err("the decoder thread died".into()))
                })
        })
    });
    match decoded {
        Some(Ok(result)) => result,
        Some(Err(message)) => Err(Problem::Malformed(format!(
            "the LAS/LAZ decoder failed on it ({message})"
        ))),
        None => Err(Problem::Malformed(
            "no thread could be started to decode it".into(),
        )),
    }
}

/// A LAS/LAZ reader whose input is read through a [`StackGuard`].
pub(super) struct GuardedReader {
    reader: las::Reader,
    tripped: Arc<AtomicBool>,
}

impl GuardedReader {
    fn open(path: &Path, stack_floor: usize) -> Result<GuardedReader, Problem> {
        let file = std::fs::File::open(path)?;
        let tripped = Arc::new(AtomicBool::new(false));
        let guarded = StackGuard {
            inner: BufReader::new(file),
            floor: stack_floor,
            tripped: tripped.clone(),
        };
        let reader = las::Reader::new(guarded).map_err(|e| problem(e, &tripped))?;
        Ok(GuardedReader { reader, tripped })
    }

    fn header(&self) -> &las::Header {
        self.reader.header()
    }

    /// Up to `n` more point records; none at the end.
    fn read_points(&mut self, n: u64) -> Result<las::PointData, Problem> {
        let tripped = &self.tripped;
        self.reader.read_points(n).map_err(|e| problem(e, tripped))
    }

    /// A problem met while decoding, said as a too-deep nesting where the guard stopped it.
    fn problem_of(&self, p: Problem) -> Problem {
        if self.tripped.load(Ordering::Relaxed) {
            nested()
        } else {
            p
        }
    }

    /// The points a batch of record bytes holds for this file's format.
    fn batch(&self) -> u64 {
        (BATCH_BYTES / u64::from(self.header().point_format().len()).max(1)).max(1)
    }
}

fn nested() -> Problem {
    Problem::Malformed(
        "its compressed points nest deeper than any valid LAZ file (damaged data)".into(),
    )
}

fn problem(e: las::Error, tripped: &AtomicBool) -> Problem {
    if tripped.load(Ordering::Relaxed) {
        nested()
    } else {
        las_problem(e)
    }
}

/// A reader that refuses to be read from below a stack address. The LAZ decoder reads its
/// input a byte at a time from inside its recursion, so a descent that has used up half of
/// the thread's stack meets an I/O error, which unwinds it through the decoder's own `?`s;
/// between two reads it recurses at most about 50,000 times (the adaptive model's largest
/// probability leaves each symbol at least 1.5e-4 bits), far less than the half kept free.
/// It raises `tripped` too, since the laz crate's errors keep the I/O error's text but not
/// the error itself.
#[derive(Debug)]
struct StackGuard<R> {
    inner: R,
    floor: usize,
    tripped: Arc<AtomicBool>,
}

/// The lowest address a [`StackGuard`] lets reads come from on the current thread, whose
/// stack is `stack` bytes: half of it below the caller's frame. Stacks grow downwards on every
/// platform this builds for.
fn stack_floor(stack: usize) -> usize {
    stack_address().saturating_sub(stack / 2)
}

fn stack_address() -> usize {
    let marker = 0u8;
    std::hint::black_box(&marker) as *const u8 as usize
}

impl<R: std::io::Read> std::io::Read for StackGuard<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        if stack_address() < self.floor {
            self.tripped.store(true, Ordering::Relaxed);
            return Err(std::io::ErrorKind::InvalidData.into());
        }
        self.inner.read(buf)
    }
}

impl<R: std::io::Seek> std::io::Seek for StackGuard<R> {
    fn seek(&mut self, pos: std::io::SeekFrom) -> std::io::Result<u64> {
        self.inner.seek(pos)
    }
}

/// Stack sizes tried, in order, for the thread LAS/LAZ files are decoded on.
const DECODER_STACKS: [usize; 3] = [1 << 30, 256 << 20, 16 << 20];

fn read_checked(reader: &mut GuardedReader) -> Result<PointCloud, Problem> {
    let header = reader.header().clone();
    let declared = header.number_of_points() as usize;
    check_points(declared)?;
    let t = header.transforms();
    let quantization = Quantization {
        scale: [t.x.scale, t.y.scale, t.z.scale],
        offset: [t.x.offset, t.y.offset, t.z.offset],
    };
    let described = extra_bytes::described(&header);
    check_fields(declared, described.len())?;
    let mut points = Points::new(&header, described);
    let batch = reader.batch();
    // In batches, so memory follows the points the file holds, not the count its header claims
    // (the las crate sizes one buffer for the whole declared count).
    loop {
        let data = reader.read_points(batch)?;
        if data.is_empty() {
            break;
        }
        let records = data.raw_bytes().chunks_exact(data.record_len());
        for (p, record) in data.points().zip(records) {
            points.push(&p.map_err(las_problem)?, record, data.format().is_extended);
        }
    }
    let found = points.positions.len();
    if found < declared {
        return Err(Problem::Truncated { declared, found });
    }
    Ok(points.into_cloud(&header, quantization))
}

/// What the points read so far hold, column by column.
struct Points {
    positions: Vec<[f64; 3]>,
    colors16: Vec<[u16; 3]>,
    fields: Columns,
    extra: extra_bytes::Columns,
    waveform: bool,
}

impl Points {
    fn new(header: &las::Header, described: Vec<extra_bytes::Field>) -> Points {
        let has_nir = header.point_format().has_nir;
        Points {
            positions: Vec::new(),
            colors16: Vec::new(),
            fields: Columns::new(),
            extra: extra_bytes::Columns::new(described, &record_fields(has_nir)),
            waveform: false,
        }
    }

    fn push(&mut self, p: &Point, record: &[u8], extended: bool) {
        self.positions.push([p.x, p.y, p.z]);
        if let Some(c) = p.color {
            self.colors16.push([c.red, c.green, c.blue]);
        }
        self.fields.push(field_values(p, record, extended));
        self.extra.push(&p.extra_bytes);
        // Index 0 says the point has no waveform packet.
        self.waveform |= p
            .waveform
            .is_some_and(|w| w.wave_packet_descriptor_index != 0);
    }

    fn into_cloud(self, header: &las::Header, quantization: Quantization) -> PointCloud {
        let n = self.positions.len();
        let has_color = header.point_format().has_color;
        let colors = (has_color && self.colors16.len() == n).then(|| eight_bit(&self.colors16));
        let mut attributes = self.fields.into_attributes();
        let (more, extra_bytes) = self.extra.into_attributes();
        attributes.extend(more);
        PointCloud {
            positions: self.positions,
            colors,
            attributes,
            quantization: Some(quantization),
            crs: crs_records(header),
            extra_bytes,
            las_source: LasSource {
                standard_gps_time: header.gps_time_type().is_standard(),
                file_source_id: header.file_source_id(),
                system_identifier: header.system_identifier().to_string(),
                waveform: self.waveform,
            },
            viewpoint: None,
        }
    }
}

/// The user ID of the VLRs that hold a LAS file's coordinate reference system.
const CRS_USER: &str = "LASF_Projection";

/// The header's CRS records, VLRs and EVLRs alike.
fn crs_records(header: &las::Header) -> Vec<CrsRecord> {
    header
        .all_vlrs()
        .filter(|v| v.is_crs())
        .map(|v| CrsRecord {
            record_id: v.record_id,
            description: v.description.clone(),
            data: v.data.clone(),
        })
        .collect()
}

/// [`crs_records`] undone: records too long for a VLR (over 64 KiB, which only a long WKT
/// reaches) go into EVLRs, which need LAS 1.4 ([`header_for`] chooses it then).
fn add_crs(builder: &mut Builder, crs: &[CrsRecord]) {
    for record in crs {
        let vlr = Vlr {
            user_id: CRS_USER.into(),
            record_id: record.record_id,
            description: record.description.clone(),
            data: record.data.clone(),
        };
        if record.data.len() > usize::from(u16::MAX) {
            builder.evlrs.push(vlr);
        } else {
            builder.vlrs.push(vlr);
        }
    }
}

/// The input's GPS time type, file source ID and system identifier, where it had them.
fn add_source(builder: &mut Builder, source: &LasSource) {
    if source.standard_gps_time {
        builder.gps_time_type = las::GpsTimeType::Standard;
    }
    builder.file_source_id = source.file_source_id;
    if !source.system_identifier.is_empty() {
        builder.system_identifier = source.system_identifier.clone();
    }
}

/// LAS colours as 8-bit: most writers scale 8-bit colour to 16 bits; some store 8-bit values
/// as they are, which no value above 255 betrays.
fn eight_bit(colors16: &[[u16; 3]]) -> Vec<[u8; 3]> {
    let sixteen_bit = colors16.iter().flatten().any(|&v| v > 255);
    colors16
        .iter()
        .map(|&c| eight_bit_of(c, sixteen_bit))
        .collect()
}

/// One colour as [`eight_bit`] makes it, where `sixteen_bit` says whether it scales.
fn eight_bit_of(color: [u16; 3], sixteen_bit: bool) -> [u8; 3] {
    color.map(|v| {
        if sixteen_bit {
            ((v as u32 + 128) / 257) as u8
        } else {
            v as u8
        }
    })
}

/// The point record's fields kept as attributes, with their storage kinds, in the order the
/// cloud holds them ([`field_values`] reads them from a point, [`write`] back).
const FIELDS: [(&str, ScalarKind); 12] = [
    ("intensity", ScalarKind::U16),
    ("classification", ScalarKind::U8),
    (SYNTHETIC, ScalarKind::U8),
    ("return_number", ScalarKind::U8),
    ("number_of_returns", ScalarKind::U8),
    ("scan_angle", ScalarKind::F32),
    ("user_data", ScalarKind::U8),
    ("point_source_id", ScalarKind::U16),
    ("gps_time", ScalarKind::F64),
    ("scanner_channel", ScalarKind::U8),
    (NIR, ScalarKind::U16),
    ("overlap", ScalarKind::U8),
];

const NIR: &str = "nir";

/// The [`FIELDS`] a point record holds: NIR only in the formats that also hold colour, so that
/// a cloud with NIR and no colour keeps it in extra bytes rather than gaining black colours.
fn record_fields(has_nir: bool) -> Vec<&'static str> {
    (FIELDS.iter().map(|f| f.0))
        .filter(|&name| has_nir || name != NIR)
        .collect()
}

/// One point's [`FIELDS`] from the point and its `record`'s bytes; the scan angle in degrees,
/// GPS time and NIR 0 where the format has none. LAS 1.4's formats (`extended`) keep the
/// overlap flag apart from the class, and their class byte is read as it is: the las crate
/// reads a byte of 12 (a reserved code there) as class 1.
fn field_values(p: &Point, record: &[u8], extended: bool) -> [f64; 12] {
    let (class, overlap) = if extended {
        (record[EXTENDED_CLASS_AT], p.is_overlap)
    } else {
        (class_code(p), false)
    };
    [
        p.intensity as f64,
        class as f64,
        if p.is_synthetic { 1.0 } else { 0.0 },
        p.return_number as f64,
        p.number_of_returns as f64,
        p.scan_angle as f64,
        p.user_data as f64,
        p.point_source_id as f64,
        p.gps_time.unwrap_or(0.0),
        p.scanner_channel as f64,
        p.nir.map_or(0.0, f64::from),
        if overlap { 1.0 } else { 0.0 },
    ]
}

/// The [`FIELDS`] of the points read so far, as attribute columns: intensity and
/// classification always, the others only from the first point that holds a value other than
/// 0 (with zeros for the points before it). A file that leaves them unset (LAS 1.4's formats
/// always have a GPS time, most writers leave the rest) adds no columns of zeros to every
/// output, and takes no memory for them while it is read: at the 200-million-point input
/// limit each column is 1.6 GB.
struct Columns {
    columns: [Option<Vec<f64>>; 12],
    points: usize,
}

impl Columns {
    fn new() -> Columns {
        Columns {
            columns: FIELDS
                .map(|(name, _)| matches!(name, "intensity" | "classification").then(Vec::new)),
            points: 0,
        }
    }

    fn push(&mut self, values: [f64; 12]) {
        for (column, value) in self.columns.iter_mut().zip(values) {
            match column {
                Some(column) => column.push(value),
                None if value != 0.0 => {
                    let mut started = vec![0.0; self.points];
                    started.push(value);
                    *column = Some(started);
                }
                None => {}
            }
        }
        self.points += 1;
    }

    fn into_attributes(self) -> Vec<Attribute> {
        FIELDS
            .iter()
            .zip(self.columns)
            .filter_map(|((name, kind), column)| {
                column.map(|values| Attribute {
                    name: (*name).into(),
                    kind: *kind,
                    values,
                })
            })
            .collect()
    }
}

/// The input's quantization when every point fits its 32-bit range; otherwise a fresh one
/// centred on the cloud with a resolution of 1e-7 of its extent (a power of ten).
fn quantization_for(cloud: &PointCloud) -> Quantization {
    let fits = |q: &Quantization| {
        cloud.positions.iter().all(|p| {
            (0..3).all(|i| ((p[i] - q.offset[i]) / q.scale[i]).round().abs() <= i32::MAX as f64)
        })
    };
    if let Some(q) = cloud.quantization.filter(fits) {
        return q;
    }
    let b = cloud
        .bounds()
        .expect("writers are not called with empty clouds");
    let extent = b.longest_side().max(f64::MIN_POSITIVE);
    let scale = 10f64.powf((extent * 1e-7).log10().floor());
    Quantization {
        scale: [scale; 3],
        offset: b.center(),
    }
}

/// A point's classification as LAS 1.0–1.3 code it (point formats 0–5): the las crate reads
/// code 12 ("overlap points") as class 1 with the overlap flag, which LAS 1.4's formats keep
/// apart.
fn class_code(p: &Point) -> u8 {
    if p.is_overlap && p.classification == Classification::Unclassified {
        OVERLAP_CLASS
    } else {
        u8::from(p.classification)
    }
}

/// [`class_code`] undone for writing formats 0–5: code 12, and the overlap flag of an
/// unclassified point, become class 1 with the flag, which the las crate writes as 12; codes
/// outside a byte are clamped into it.
fn legacy_class(code: f64, overlap: bool) -> (Classification, bool) {
    match Classification::new(code as u8) {
        Ok(class) => (class, overlap && class == Classification::Unclassified),
        Err(_) => (Classification::Unclassified, true),
    }
}

/// A class byte of formats 6–10 as the las crate writes it: 12 is reserved there, and only
/// `Reserved` carries it.
fn extended_class(code: f64) -> Classification {
    let code = code as u8;
    Classification::new(code).unwrap_or(Classification::Reserved(code))
}

const OVERLAP_CLASS: u8 = 12;

/// Where the class byte lies in a record of formats 6–10: after the coordinates, intensity,
/// returns and flags.
const EXTENDED_CLASS_AT: usize = 16;

/// The largest classification code point formats 0–5 hold (five bits); LAS 1.4's formats 6–10
/// hold a byte, and MLS data uses codes above 31 for its own classes.
const MAX_LEGACY_CLASS: f64 = 31.0;

/// The most returns of a pulse point formats 0–5 count (three bits); formats 6–10 count 15.
const MAX_LEGACY_RETURNS: f64 = 7.0;

/// The highest scanner channel formats 6–10 number (two bits; the older formats have none):
/// multi-scanner MLS systems tell their scanners apart by it.
const MAX_CHANNEL: u8 = 3;

/// LAS 1.2 with point format 0 (1 with GPS time, 2 with colour, 3 with both), which every reader
/// takes; LAS 1.4 with format 6 (or 7 with colour; both with GPS time) where a classification
/// code, a return number, a scan angle or a scanner channel needs more than the older formats
/// give it, and format 8 (colour and NIR) for a near-infrared channel beside colour.
fn version_and_format(color: bool, gps_time: bool, wide: bool, nir: bool) -> (Builder, Format) {
    let (version, number) = if nir {
        ((1, 4), 8)
    } else if wide {
        ((1, 4), 6 + u8::from(color))
    } else {
        ((1, 2), u8::from(gps_time) + 2 * u8::from(color))
    };
    let format = Format::new(number).expect("formats 0–3 and 6–8 exist");
    (Builder::from(version), format)
}

/// Whether a scan angle needs LAS 1.4's 0.006° steps: the older formats hold whole degrees
/// from −128 to 127.
fn finer_than_degrees(cloud: &PointCloud) -> bool {
    cloud.attribute("scan_angle").is_some_and(|a| {
        a.values
            .iter()
            .any(|&v| v.fract() != 0.0 || !(-128.0..=127.0).contains(&v))
    })
}

/// Whether a value of the attribute `name` exceeds `max`.
fn exceeds(cloud: &PointCloud, name: &str, max: f64) -> bool {
    cloud
        .attribute(name)
        .is_some_and(|a| a.values.iter().any(|&v| v > max))
}

/// The header for `cloud`: its quantization, the oldest version and smallest point format that
/// hold its colour and its [`FIELDS`], and room for its other attributes as `extra` lays them out.
fn header_for(
    cloud: &PointCloud,
    extra: &extra_bytes::Layout,
    compressed: bool,
) -> Result<las::Header, Problem> {
    let q = quantization_for(cloud);
    let wide = exceeds(cloud, "classification", MAX_LEGACY_CLASS)
        || exceeds(cloud, "return_number", MAX_LEGACY_RETURNS)
        || exceeds(cloud, "number_of_returns", MAX_LEGACY_RETURNS)
        || finer_than_degrees(cloud)
        || exceeds(cloud, "scanner_channel", 0.0)
        || exceeds(cloud, "overlap", 0.0)
        || cloud
            .crs
            .iter()
            .any(|r| r.data.len() > usize::from(u16::MAX));
    let gps_time = cloud.attribute("gps_time").is_some();
    let nir = cloud.colors.is_some() && cloud.attribute(NIR).is_some();
    let (mut builder, mut format) = version_and_format(cloud.colors.is_some(), gps_time, wide, nir);
    format.is_compressed = compressed;
    if extra.fields() > extra_bytes::MAX_FIELDS
        || usize::from(format.len()) + extra.len() > usize::from(u16::MAX)
    {
        return Err(Problem::Malformed(format!(
            "its {} attributes besides the point record's fields need {} bytes a point; a LAS \
             file describes at most {} such fields in records of at most 65,535 bytes",
            extra.fields(),
            extra.len(),
            extra_bytes::MAX_FIELDS
        )));
    }
    format.extra_bytes = extra.len() as u16;
    builder.point_format = format;
    builder.vlrs.extend(extra.vlr());
    builder.generating_software = format!("mvpcc {}", env!("CARGO_PKG_VERSION"));
    add_source(&mut builder, &cloud.las_source);
    add_crs(&mut builder, &cloud.crs);
    let axis = |k: usize| Transform {
        scale: q.scale[k],
        offset: q.offset[k],
    };
    builder.transforms = Vector {
        x: axis(0),
        y: axis(1),
        z: axis(2),
    };
    builder.into_header().map_err(las_problem)
}

/// The scan angle the las crate is given for `degrees` read from a record: it stores degrees /
/// 0.006 truncated, so `n · 0.006` computed in f32 may come back as `n − 1`; the step's middle
/// (`n ± 0.5` steps, away from zero) truncates to `n`. Older formats store whole degrees, which
/// it rounds, and the middle rounds to them too.
fn scan_angle(degrees: f64) -> f32 {
    const STEP: f64 = 0.006;
    let steps = (degrees / STEP).round();
    ((steps + 0.5f64.copysign(steps)) * STEP) as f32
}

/// Point `i` of `cloud` as a record of `format`: its [`FIELDS`] from the attributes `columns`
/// (0 where the cloud has none), each cast into the record's field.
fn record(
    cloud: &PointCloud,
    columns: &[Option<&Attribute>; 12],
    i: usize,
    format: &Format,
) -> Point {
    let [intensity, class, synthetic, ret, returns, angle, user, source, time, channel, nir, overlap] =
        columns.map(|c| c.map_or(0.0, |a| a.values[i]));
    let max_returns = if format.is_extended { 15 } else { 7 };
    let (classification, is_overlap) = if format.is_extended {
        (extended_class(class), overlap != 0.0)
    } else {
        legacy_class(class, overlap != 0.0)
    };
    let [x, y, z] = cloud.positions[i];
    Point {
        x,
        y,
        z,
        intensity: intensity as u16,
        classification,
        is_overlap,
        is_synthetic: synthetic != 0.0,
        return_number: (ret as u8).min(max_returns),
        number_of_returns: (returns as u8).min(max_returns),
        scan_angle: scan_angle(angle),
        user_data: user as u8,
        point_source_id: source as u16,
        gps_time: format.has_gps_time.then_some(time),
        scanner_channel: if format.is_extended {
            (channel as u8).min(MAX_CHANNEL)
        } else {
            0
        },
        nir: format.has_nir.then_some(nir as u16),
        color: format.has_color.then(|| {
            cloud.colors.as_ref().map_or(Color::default(), |c| Color {
                red: c[i][0] as u16 * 257,
                green: c[i][1] as u16 * 257,
                blue: c[i][2] as u16 * 257,
            })
        }),
        ..Default::default()
    }
}

/// The record fields of `cloud` that a LAS record holds as whole numbers from 0 to a bound and
/// whose values are not all such numbers, one warning each: they are written clipped and cut
/// to whole numbers. PTS intensities run from −2048 to 2047, and a PLY's or a text file's often
/// from 0 to 1, which would all become 0 or 1.
pub(super) fn clipped(cloud: &PointCloud) -> Vec<String> {
    let bounded = [
        ("intensity", u16::MAX),
        ("user_data", 255),
        ("point_source_id", u16::MAX),
    ];
    // Without colour, NIR goes to extra bytes (`record_fields`).
    let nir = cloud.colors.is_some().then_some((NIR, u16::MAX));
    (bounded.into_iter().chain(nir))
        .filter_map(|(name, max)| {
            let values = &cloud.attribute(name)?.values;
            let fits = |&v: &f64| (0.0..=f64::from(max)).contains(&v) && v.fract() == 0.0;
            if values.iter().all(fits) {
                return None;
            }
            let low = values.iter().copied().fold(f64::INFINITY, f64::min);
            let high = values.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            Some(format!(
                "{name} is written as a whole number from 0 to {max} in LAS: its values, from {} \
                 to {}, are clipped and cut to whole numbers (rescale it, or write PLY or PCD)",
                shown(low),
                shown(high)
            ))
        })
        .collect()
}

/// `v` as it is where it is whole, else to three decimals.
fn shown(v: f64) -> String {
    if v.fract() == 0.0 {
        format!("{v}")
    } else {
        format!("{v:.3}")
    }
}

pub(super) fn write(path: &Path, cloud: &PointCloud, compressed: bool) -> Result<(), Problem> {
    if cloud.is_empty() {
        return Err(Problem::NoPoints);
    }
    let extra = extra_bytes::Layout::new(cloud, &record_fields(cloud.colors.is_some()));
    let header = header_for(cloud, &extra, compressed)?;
    let format = *header.point_format();
    let columns = FIELDS.map(|(name, _)| cloud.attribute(name));
    let tmp = super::temp_file_beside(path).map_err(super::write_problem)?;
    {
        let file = tmp.reopen()?;
        let mut writer = Writer::new(BufWriter::new(file), header).map_err(las_problem)?;
        for i in 0..cloud.len() {
            let point = Point {
                extra_bytes: extra.bytes(i),
                ..record(cloud, &columns, i, &format)
            };
            writer.write_point(point).map_err(las_problem)?;
        }
        writer.close().map_err(las_problem)?;
    }
    super::persist(tmp, path).map_err(super::write_problem)
}
