//! Tiles too large to hold in memory, completed in chunks: a LAS/LAZ tile of 50 million points
//! read whole would take some 6 GB (72 bytes a point, and the search for vehicles as much
//! again). Instead the tile is read three times, a batch at a time:
//!
//! 1. each point's position, colour and class go to the scratch file of the square chunk of the
//!    ground plan it lies in, and to those of the chunks whose margin it lies in;
//! 2. each chunk with its margins is searched for vehicles as a whole scene is
//!    (`find_in_chunk`), and the vehicles whose footprint's centre lies in the chunk
//!    itself are completed (`complete_vehicles`): a vehicle crossing a border is whole
//!    in the margins of the chunk that holds its centre, and completed there alone;
//! 3. the tile is copied into the output record by record, and the completed points appended.
//!
//! Memory is then bounded by the densest chunk with its margins, not by the tile.

use super::{
    complete_vehicles, find_in_chunk, split, Object, SceneError, SceneParams, Selection,
    VehicleReport, Verdict, CLASSIFICATION, VEHICLE,
};
use crate::complete::{Completer, Settings};
use crate::core::cloud::{Attribute, PointCloud, ScalarKind};
use crate::core::frame::UpAxis;
use crate::io::stream::{self, Appended, ScanPoint, TileHeader};
use crate::io::{CloudIoError, Problem};
use crate::scene::preview::PlanView;
use std::collections::{BTreeSet, HashMap};
use std::io::{BufReader, Read, Write};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};
use thiserror::Error;

/// When and how a tile is streamed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StreamParams {
    /// Tiles of at least this many points are streamed: read whole, 20 million points take
    /// about 2.5 GB with the search for vehicles; below it one pass in memory is faster.
    pub from_points: usize,
    /// A chunk's side, metres: with its margins a 150 m square, a few million points of a
    /// dense MLS street.
    pub chunk: f64,
    /// How far around its chunk a chunk's search sees, metres: more than half the longest
    /// vehicle (20 m) with the clustering gap, so that a vehicle whose centre lies in a chunk
    /// lies whole within its margins, and an object cut at a margin's edge has its centre
    /// outside the chunk unless it is longer than any vehicle.
    pub margin: f64,
}

impl Default for StreamParams {
    fn default() -> Self {
        StreamParams {
            from_points: 20_000_000,
            chunk: 100.0,
            margin: 25.0,
        }
    }
}

#[derive(Debug, Error)]
pub enum StreamError {
    #[error(transparent)]
    Cloud(#[from] CloudIoError),
    #[error("{}: {source}", path.display())]
    Scene { path: PathBuf, source: SceneError },
    #[error("{}: cannot use the scratch folder beside the output for its chunks: {source}", path.display())]
    Scratch {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{}: more than {} vehicles, the most the `{VEHICLE}` field numbers", path.display(), u16::MAX)]
    TooManyVehicles { path: PathBuf },
}

/// What completing a streamed tile did.
#[derive(Debug)]
pub struct StreamedScene {
    pub input_points: usize,
    pub output_points: usize,
    /// Points taken for ground, each counted once.
    pub ground_points: usize,
    /// The verdict on each object whose centre lies in the tile, vehicles included.
    pub verdicts: Vec<Verdict>,
    pub vehicles: Vec<VehicleReport>,
    /// The classification codes the tile's points use.
    pub classes: BTreeSet<u8>,
    pub chunks: usize,
    /// Points of the largest chunk with its margins: what bounds the memory.
    pub largest_chunk: usize,
    pub preview: Option<image::RgbImage>,
    pub passes: Passes,
}

/// How long each pass over a streamed tile took.
#[derive(Debug, Clone, Copy, Default)]
pub struct Passes {
    /// Reading the tile into its chunks.
    pub spill: Duration,
    /// Finding and completing the vehicles, chunk by chunk.
    pub vehicles: Duration,
    /// Copying the tile with the completed points appended.
    pub copy: Duration,
}

/// Everything [`complete_tile`] needs besides its files.
pub struct TileJob<'a> {
    pub up: UpAxis,
    pub selection: &'a Selection,
    pub params: &'a SceneParams,
    pub stream: StreamParams,
    pub completer: &'a Completer,
    pub settings: &'a Settings,
    /// Draw a plan view of the completed tile.
    pub preview: bool,
}

/// The header of a LAS/LAZ tile, to tell whether it is streamed.
pub fn tile_header(path: &Path) -> Result<TileHeader, CloudIoError> {
    stream::tile_header(path).map_err(|p| CloudIoError::new(path, p))
}

/// Completes the vehicles of the LAS/LAZ tile `input` into `output` (LAZ when `compressed`) a
/// chunk at a time: the output as [`super::complete_scene`]'s, every input point as it was and
/// in its order, then each vehicle's completed points.
pub fn complete_tile(
    input: &Path,
    output: &Path,
    compressed: bool,
    job: &TileJob,
) -> Result<StreamedScene, StreamError> {
    let read_err = |p: Problem| StreamError::Cloud(CloudIoError::new(input, p));
    let header = stream::tile_header(input).map_err(read_err)?;
    if header.extra_fields.iter().any(|f| f == VEHICLE) {
        return Err(StreamError::Scene {
            path: input.to_path_buf(),
            source: SceneError::AlreadyCompleted,
        });
    }
    let scratch = crate::io::scratch_dir_beside(output).map_err(|source| StreamError::Scratch {
        path: output.to_path_buf(),
        source,
    })?;
    let scratch_err = |source| StreamError::Scratch {
        path: output.to_path_buf(),
        source,
    };
    let grid = Grid {
        origin: header.min,
        up: job.up,
        side: job.stream.chunk,
        margin: job.stream.margin,
    };
    let start = Instant::now();
    let mut spill = Spill::new(scratch.path());
    let mut tile = TileStats::default();
    let mut index = 0u64;
    let spilled: Result<usize, Problem> = stream::scan(input, |batch| {
        for p in batch {
            tile.see(p);
            spill.put(&grid, p, index).map_err(Problem::Io)?;
            index += 1;
        }
        Ok(())
    });
    let input_points = spilled.map_err(|p| match p {
        Problem::Io(e) if spill.failed => scratch_err(e),
        p => read_err(p),
    })?;
    spill.flush().map_err(scratch_err)?;
    let mut done = StreamedScene {
        input_points,
        output_points: 0,
        ground_points: 0,
        verdicts: Vec::new(),
        vehicles: Vec::new(),
        classes: tile.classes.clone(),
        chunks: spill.chunks.len(),
        largest_chunk: 0,
        preview: None,
        passes: Passes {
            spill: start.elapsed(),
            ..Passes::default()
        },
    };
    let start = Instant::now();
    let appended_path = scratch.path().join("appended");
    let mut appended =
        std::io::BufWriter::new(std::fs::File::create(&appended_path).map_err(scratch_err)?);
    let (mut low, mut high) = (tile.min, tile.max);
    let mut claimed = Claimed::new(input_points);
    for &key in &spill.chunks {
        let mut chunk = spill.load(key, &tile).map_err(scratch_err)?;
        let core = chunk.core;
        let cloud = chunk.cloud();
        done.largest_chunk = done.largest_chunk.max(cloud.len());
        let objects =
            find_in_chunk(&cloud, job.up, job.selection, job.params, core).map_err(|source| {
                StreamError::Scene {
                    path: input.to_path_buf(),
                    source,
                }
            })?;
        done.ground_points += objects.ground_points;
        let mut vehicles: Vec<&Object> = Vec::new();
        for o in &objects.objects {
            let centre = grid.key(o.footprint.centre);
            if o.verdict != Verdict::Vehicle {
                if centre == key {
                    done.verdicts.push(o.verdict);
                }
                continue;
            }
            let tile_indices = o.indices.iter().map(|&i| chunk.indices[i]);
            let owned = centre == key
                || ((centre < key || !spill.chunks.contains(&centre))
                    && grid.holds_whole(key, o.indices.iter().map(|&i| cloud.positions[i])));
            if owned && !claimed.mostly(tile_indices) {
                done.verdicts.push(o.verdict);
                vehicles.push(o);
            }
        }
        for o in &vehicles {
            claimed.claim(o.indices.iter().map(|&i| chunk.indices[i]));
        }
        let params = &job.params;
        for (mut report, added) in complete_vehicles(
            &cloud,
            &vehicles,
            job.completer,
            job.settings,
            &params.narrowest,
        ) {
            report.id = done.vehicles.len() + 1;
            let id = u16::try_from(report.id).map_err(|_| StreamError::TooManyVehicles {
                path: input.to_path_buf(),
            })?;
            if let Some(added) = &added {
                let classes = added.attribute(CLASSIFICATION).map(|a| &a.values);
                for (i, &p) in added.positions.iter().enumerate() {
                    let point = Appended {
                        position: p,
                        color: added.colors.as_ref().map(|c| c[i]),
                        class: classes.map_or(0, |c| c[i] as u8),
                        id,
                    };
                    write_appended(&mut appended, &point).map_err(scratch_err)?;
                    for k in 0..3 {
                        low[k] = low[k].min(p[k]);
                        high[k] = high[k].max(p[k]);
                    }
                }
            }
            done.vehicles.push(report);
        }
    }
    appended.flush().map_err(scratch_err)?;
    drop(appended);
    done.passes.vehicles = start.elapsed();
    let start = Instant::now();
    let mut preview = job.preview.then(|| PlanView::new(low, high, job.up));
    let reader = BufReader::new(std::fs::File::open(&appended_path).map_err(scratch_err)?);
    let field = (!done.vehicles.is_empty()).then_some(VEHICLE);
    done.output_points = stream::copy_appending(
        input,
        output,
        compressed,
        field,
        tile.sixteen_bit,
        AppendedPoints { reader },
        |p, id| {
            if let Some(view) = &mut preview {
                view.add(p, id.is_some());
            }
        },
    )
    .map_err(|p| StreamError::Cloud(CloudIoError::new(output, p)))?;
    done.preview = preview.map(PlanView::finish);
    done.passes.copy = start.elapsed();
    Ok(done)
}

/// The square chunks of the ground plan.
struct Grid {
    origin: [f64; 3],
    up: UpAxis,
    side: f64,
    margin: f64,
}

type Key = (i64, i64);

impl Grid {
    fn key(&self, p: [f64; 3]) -> Key {
        let (h, _) = split(p, self.origin, self.up);
        (
            (h[0] / self.side).floor() as i64,
            (h[1] / self.side).floor() as i64,
        )
    }

    /// Whether `points` lie within chunk `key`'s margins and at least the clustering gap from
    /// their outer edge (taken as 1 m): an object cut there is not whole.
    fn holds_whole(&self, key: Key, points: impl Iterator<Item = [f64; 3]>) -> bool {
        let inner = self.margin - 1.0;
        let lo = [key.0, key.1].map(|k| k as f64 * self.side - inner);
        let hi = [key.0, key.1].map(|k| (k + 1) as f64 * self.side + inner);
        points.into_iter().all(|p| {
            let (h, _) = split(p, self.origin, self.up);
            (0..2).all(|k| lo[k] <= h[k] && h[k] < hi[k])
        })
    }

    /// The chunks whose margins hold `p`, besides its own.
    fn margins(&self, p: [f64; 3], own: Key) -> impl Iterator<Item = Key> {
        let (h, _) = split(p, self.origin, self.up);
        let range = |v: f64| {
            let lo = ((v - self.margin) / self.side).floor() as i64;
            let hi = ((v + self.margin) / self.side).floor() as i64;
            lo..=hi
        };
        let (xs, ys) = (range(h[0]), range(h[1]));
        xs.flat_map(move |x| ys.clone().map(move |y| (x, y)))
            .filter(move |&k| k != own)
    }
}

/// Points of the tile that belong to a vehicle completed already, one bit each (6 MB for 50
/// million points).
struct Claimed(Vec<u64>);

impl Claimed {
    fn new(points: usize) -> Claimed {
        Claimed(vec![0; points.div_ceil(64)])
    }

    fn get(&self, i: u64) -> bool {
        self.0
            .get((i / 64) as usize)
            .is_some_and(|w| w & (1 << (i % 64)) != 0)
    }

    fn claim(&mut self, points: impl Iterator<Item = u64>) {
        for i in points {
            if let Some(w) = self.0.get_mut((i / 64) as usize) {
                *w |= 1 << (i % 64);
            }
        }
    }

    /// Whether at least half of `points` are claimed: the object is a vehicle another chunk
    /// completed, seen again.
    fn mostly(&self, points: impl Iterator<Item = u64>) -> bool {
        let (mut claimed, mut all) = (0, 0);
        for i in points {
            claimed += usize::from(self.get(i));
            all += 1;
        }
        2 * claimed >= all && all > 0
    }
}

/// Bytes of a spilled point: position (3 × f64), colour (3 × u16), class, its index in the
/// tile (u64).
const RECORD: usize = 39;

/// Bytes held in memory for the chunks' files before they are written out.
const SPILL_BUFFER: usize = 64 << 20;

/// The chunks' scratch files, each chunk's own points apart from its margins'.
struct Spill {
    dir: PathBuf,
    buffers: HashMap<(Key, bool), Vec<u8>>,
    buffered: usize,
    /// Chunks holding points of their own, in order.
    chunks: BTreeSet<Key>,
    /// Whether an error came from the scratch files rather than the input.
    failed: bool,
}

impl Spill {
    fn new(dir: &Path) -> Spill {
        Spill {
            dir: dir.to_path_buf(),
            buffers: HashMap::new(),
            buffered: 0,
            chunks: BTreeSet::new(),
            failed: false,
        }
    }

    fn path(&self, key: Key, own: bool) -> PathBuf {
        chunk_path(&self.dir, key, own)
    }

    fn put(&mut self, grid: &Grid, p: &ScanPoint, index: u64) -> std::io::Result<()> {
        let own = grid.key(p.position);
        let mut record = [0u8; RECORD];
        for (k, v) in p.position.iter().enumerate() {
            record[8 * k..8 * k + 8].copy_from_slice(&v.to_le_bytes());
        }
        for (k, v) in p.color.unwrap_or_default().iter().enumerate() {
            record[24 + 2 * k..26 + 2 * k].copy_from_slice(&v.to_le_bytes());
        }
        record[30] = p.class;
        record[31..39].copy_from_slice(&index.to_le_bytes());
        self.chunks.insert(own);
        self.buffers
            .entry((own, true))
            .or_default()
            .extend_from_slice(&record);
        let mut added = RECORD;
        for key in grid.margins(p.position, own) {
            self.buffers
                .entry((key, false))
                .or_default()
                .extend_from_slice(&record);
            added += RECORD;
        }
        self.buffered += added;
        if self.buffered >= SPILL_BUFFER {
            self.flush()?;
        }
        Ok(())
    }

    /// Appends every buffer to its file.
    fn flush(&mut self) -> std::io::Result<()> {
        let written = self.write_out();
        self.failed |= written.is_err();
        written
    }

    fn write_out(&mut self) -> std::io::Result<()> {
        for (&(key, own), buffer) in &mut self.buffers {
            if buffer.is_empty() {
                continue;
            }
            let mut file = std::fs::OpenOptions::new()
                .create(true)
                .append(true)
                .open(chunk_path(&self.dir, key, own))?;
            file.write_all(buffer)?;
            buffer.clear();
        }
        self.buffers.retain(|_, b| b.capacity() <= RECORD * 4096);
        self.buffered = 0;
        Ok(())
    }

    /// Chunk `key`'s points, its own first.
    fn load(&self, key: Key, tile: &TileStats) -> std::io::Result<Chunk> {
        let mut chunk = Chunk {
            positions: Vec::new(),
            colors: tile.has_color.then(Vec::new),
            classes: Vec::new(),
            indices: Vec::new(),
            core: 0,
        };
        for own in [true, false] {
            let path = self.path(key, own);
            let bytes = match std::fs::read(&path) {
                Ok(bytes) => bytes,
                Err(e) if e.kind() == std::io::ErrorKind::NotFound && !own => Vec::new(),
                Err(e) => return Err(e),
            };
            for r in bytes.chunks_exact(RECORD) {
                let f = |k: usize| {
                    f64::from_le_bytes(r[8 * k..8 * k + 8].try_into().expect("eight bytes"))
                };
                chunk.positions.push([f(0), f(1), f(2)]);
                if let Some(colors) = &mut chunk.colors {
                    let c = |k: usize| u16::from_le_bytes([r[24 + 2 * k], r[25 + 2 * k]]);
                    colors.push(stream::eight_bit([c(0), c(1), c(2)], tile.sixteen_bit));
                }
                chunk.classes.push(r[30]);
                chunk.indices.push(u64::from_le_bytes(
                    r[31..39].try_into().expect("eight bytes"),
                ));
            }
            if own {
                chunk.core = chunk.positions.len();
            }
        }
        Ok(chunk)
    }
}

fn chunk_path(dir: &Path, key: Key, own: bool) -> PathBuf {
    let kind = if own { "own" } else { "margin" };
    dir.join(format!("{}_{}.{kind}", key.0, key.1))
}

/// What the first pass learns of the whole tile.
#[derive(Debug)]
struct TileStats {
    min: [f64; 3],
    max: [f64; 3],
    has_color: bool,
    /// Whether a colour value above 255 says the colours are 16-bit.
    sixteen_bit: bool,
    classes: BTreeSet<u8>,
}

impl Default for TileStats {
    fn default() -> Self {
        TileStats {
            min: [f64::INFINITY; 3],
            max: [f64::NEG_INFINITY; 3],
            has_color: false,
            sixteen_bit: false,
            classes: BTreeSet::new(),
        }
    }
}

impl TileStats {
    fn see(&mut self, p: &ScanPoint) {
        for k in 0..3 {
            self.min[k] = self.min[k].min(p.position[k]);
            self.max[k] = self.max[k].max(p.position[k]);
        }
        if let Some(c) = p.color {
            self.has_color = true;
            self.sixteen_bit |= c.iter().any(|&v| v > 255);
        }
        self.classes.insert(p.class);
    }
}

/// One chunk with its margins.
struct Chunk {
    positions: Vec<[f64; 3]>,
    colors: Option<Vec<[u8; 3]>>,
    classes: Vec<u8>,
    /// Each point's index in the tile.
    indices: Vec<u64>,
    /// How many of the points are the chunk's own (they come first).
    core: usize,
}

impl Chunk {
    /// The chunk as a cloud with its classes, which its completed points take from their
    /// nearest scanned points as when the tile is read whole.
    fn cloud(&mut self) -> PointCloud {
        let mut cloud = PointCloud::from_positions(std::mem::take(&mut self.positions));
        cloud.colors = self.colors.take();
        cloud.attributes.push(Attribute {
            name: CLASSIFICATION.into(),
            kind: ScalarKind::U8,
            values: self.classes.iter().map(|&c| f64::from(c)).collect(),
        });
        cloud
    }
}

/// Bytes of an appended point: position (3 × f64), whether it has a colour, the colour, class,
/// id.
const APPENDED: usize = 31;

fn write_appended(w: &mut impl Write, a: &Appended) -> std::io::Result<()> {
    let mut record = [0u8; APPENDED];
    for (k, v) in a.position.iter().enumerate() {
        record[8 * k..8 * k + 8].copy_from_slice(&v.to_le_bytes());
    }
    record[24] = u8::from(a.color.is_some());
    record[25..28].copy_from_slice(&a.color.unwrap_or_default());
    record[28] = a.class;
    record[29..31].copy_from_slice(&a.id.to_le_bytes());
    w.write_all(&record)
}

/// The appended points read back from their scratch file.
struct AppendedPoints<R> {
    reader: R,
}

impl<R: Read> Iterator for AppendedPoints<R> {
    type Item = Result<Appended, Problem>;

    fn next(&mut self) -> Option<Self::Item> {
        let mut r = [0u8; APPENDED];
        match self.reader.read_exact(&mut r) {
            Ok(()) => {}
            Err(e) if e.kind() == std::io::ErrorKind::UnexpectedEof => return None,
            Err(e) => return Some(Err(Problem::Io(e))),
        }
        let f = |k: usize| f64::from_le_bytes(r[8 * k..8 * k + 8].try_into().expect("eight bytes"));
        Some(Ok(Appended {
            position: [f(0), f(1), f(2)],
            color: (r[24] != 0).then(|| [r[25], r[26], r[27]]),
            class: r[28],
            id: u16::from_le_bytes([r[29], r[30]]),
        }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid() -> Grid {
        Grid {
            origin: [1000.0, 2000.0, 50.0],
            up: UpAxis::Z,
            side: 100.0,
            margin: 25.0,
        }
    }

    fn at(x: f64, y: f64) -> [f64; 3] {
        [1000.0 + x, 2000.0 + y, 51.0]
    }

    #[test]
    fn a_point_goes_to_its_chunk_and_to_the_margins_that_reach_it() {
        let g = grid();
        let margins = |x, y| {
            let own = g.key(at(x, y));
            let mut m: Vec<Key> = g.margins(at(x, y), own).collect();
            m.sort();
            (own, m)
        };
        assert_eq!(margins(50.0, 50.0), ((0, 0), vec![]));
        assert_eq!(margins(10.0, 50.0), ((0, 0), vec![(-1, 0)]));
        assert_eq!(margins(90.0, 80.0), ((0, 0), vec![(0, 1), (1, 0), (1, 1)]));
        assert_eq!(margins(-0.5, 130.0), ((-1, 1), vec![(0, 1)]));
    }

    #[test]
    fn a_chunk_comes_back_with_its_own_points_first() {
        let dir = tempfile::tempdir().unwrap();
        let g = grid();
        let mut spill = Spill::new(dir.path());
        let points = [
            (at(110.0, 10.0), 3),
            (at(90.0, 10.0), 7),
            (at(150.0, 50.0), 9),
        ];
        let mut tile = TileStats::default();
        for (index, &(position, class)) in points.iter().enumerate() {
            let p = ScanPoint {
                position,
                color: Some([300, 0, 65535]),
                class,
            };
            tile.see(&p);
            spill.put(&g, &p, index as u64).unwrap();
        }
        spill.flush().unwrap();
        assert_eq!(
            spill.chunks.iter().copied().collect::<Vec<_>>(),
            [(0, 0), (1, 0)]
        );
        let chunk = spill.load((1, 0), &tile).unwrap();
        assert_eq!(chunk.core, 2);
        assert_eq!(chunk.positions, [points[0].0, points[2].0, points[1].0]);
        assert_eq!(chunk.classes, [3, 9, 7]);
        assert_eq!(chunk.indices, [0, 2, 1]);
        // 16-bit colours scaled to 8 bits, as reading the tile whole does.
        assert_eq!(chunk.colors.as_deref(), Some(&[[1, 0, 255]; 3][..]));
        let own = spill.load((0, 0), &tile).unwrap();
        assert_eq!((own.core, own.positions.len()), (1, 2));
    }

    #[test]
    fn appended_points_read_back_as_written() {
        let points = [
            Appended {
                position: [1.5, -2.25, 1e6],
                color: Some([1, 2, 3]),
                class: 64,
                id: 7,
            },
            Appended {
                position: [0.0; 3],
                color: None,
                class: 0,
                id: 65535,
            },
        ];
        let mut bytes = Vec::new();
        for p in &points {
            write_appended(&mut bytes, p).unwrap();
        }
        let back: Vec<Appended> = AppendedPoints { reader: &bytes[..] }
            .collect::<Result<_, _>>()
            .unwrap();
        assert_eq!(back, points);
    }

    /// A vehicle near a border is seen by both chunks, each cutting it a little differently:
    /// the chunk that completes it claims its points, and the other sees it claimed.
    #[test]
    fn a_vehicle_completed_once_is_claimed_for_the_chunks_after() {
        let mut claimed = Claimed::new(200);
        claimed.claim(10..110);
        assert!(claimed.mostly(20..150), "90 of 130 claimed");
        assert!(!claimed.mostly(100..150), "10 of 50 claimed");
        assert!(!claimed.mostly(std::iter::empty()));
    }

    #[test]
    fn an_object_cut_at_the_margins_edge_is_not_whole() {
        let g = grid();
        // Chunk (0, 0) sees from −25 m to 125 m; an object within 1 m of that edge may go on.
        assert!(g.holds_whole((0, 0), [at(-20.0, 5.0), at(120.0, 50.0)].into_iter()));
        assert!(!g.holds_whole((0, 0), [at(-24.5, 5.0)].into_iter()));
        assert!(!g.holds_whole((0, 0), [at(50.0, 124.5)].into_iter()));
    }
}
