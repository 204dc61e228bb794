//! Point cloud files: PLY, PCD, LAS/LAZ and XYZ text, all read into and written from one
//! [`PointCloud`]. Writes are atomic: a temporary file beside the output, renamed over it (a
//! device or pipe is written into instead). `-` is standard input or output ([`stdio`]). A
//! command stopped by Ctrl-C deletes the temporary files it was writing
//! ([`remove_unfinished_then`]).

pub mod batch;
mod las;
pub use las::stream;
mod pcd;
pub(crate) mod ply;
pub mod stdio;
mod unfinished;
mod xyz;

use crate::core::cloud::PointCloud;
use crate::core::frame::UpAxis;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use stdio::{is_stdio, is_stream, spooled, write_stdout, write_whole_into};
use tempfile::NamedTempFile;
use thiserror::Error;
pub use unfinished::remove_unfinished_then;
pub(crate) use unfinished::track;
pub(crate) use unfinished::Scratch;

/// Point cloud file formats.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Format {
    Ply,
    Pcd,
    Las,
    Laz,
    Xyz,
}

impl Format {
    /// The extension outputs in this format are given.
    pub fn extension(self) -> &'static str {
        match self {
            Format::Ply => "ply",
            Format::Pcd => "pcd",
            Format::Las => "las",
            Format::Laz => "laz",
            Format::Xyz => "xyz",
        }
    }

    /// The format an extension names (case-insensitive); `.txt` and `.csv` are XYZ text.
    pub fn from_path(path: &Path) -> Result<Format, Problem> {
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(|e| e.to_ascii_lowercase())
            .unwrap_or_default();
        match ext.as_str() {
            "ply" => Ok(Format::Ply),
            "pcd" => Ok(Format::Pcd),
            "las" => Ok(Format::Las),
            "laz" => Ok(Format::Laz),
            "xyz" | "txt" | "csv" | "pts" => Ok(Format::Xyz),
            _ => Err(Problem::UnsupportedExtension(ext)),
        }
    }

    /// The format an input cloud is read in: `given` (`--format`), else the extension's, else
    /// for standard input or another stream what its first bytes show.
    pub fn of_input(path: &Path, given: Option<Format>) -> Result<Format, Problem> {
        if let Some(format) = given {
            return Ok(format);
        }
        match Format::from_path(path) {
            Ok(format) if !is_stdio(path) => Ok(format),
            _ if is_stream(path) => Ok(spooled(path)?.1),
            named => named,
        }
    }

    /// The format a cloud is written in: `given` (`--out-format`), else the extension's. Checked
    /// before the work, so that a mistyped extension fails at once instead of after it.
    pub fn of_output(path: &Path, given: Option<Format>) -> Result<Format, Problem> {
        match given {
            Some(format) => Ok(format),
            None if is_stdio(path) => Err(Problem::StdoutFormat),
            None => Format::from_path(path).map_err(|problem| match problem {
                Problem::UnsupportedExtension(ext) => Problem::UnsupportedOutputExtension(ext),
                other => other,
            }),
        }
    }
}

/// How PLY and PCD bodies are written (LAS and XYZ have one encoding each).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum Encoding {
    #[default]
    Binary,
    Ascii,
    /// PCD `binary_compressed` (LZF); PLY falls back to binary.
    Compressed,
}

/// What went wrong with one file.
#[derive(Debug, Error)]
pub enum Problem {
    #[error("no such file")]
    NotFound,
    #[error("is a directory, not a point cloud file")]
    IsDirectory,
    #[error("is a directory; name the output file")]
    OutputIsDirectory,
    #[error("file is empty")]
    EmptyFile,
    #[error("contains no points")]
    NoPoints,
    #[error("{} NaN or infinite coordinates", if *.0 == 1 { "its one point has".to_string() } else { format!("all {} points have", .0) })]
    AllNonFinite(usize),
    #[error("unsupported file extension {0:?} (expected ply, pcd, las, laz, xyz, txt, csv or pts; or pass --format)")]
    UnsupportedExtension(String),
    #[error("unsupported output extension {0:?} (expected ply, pcd, las, laz, xyz, txt, csv or pts; or pass --out-format)")]
    UnsupportedOutputExtension(String),
    #[error("standard output has no extension to tell the format: pass --out-format")]
    StdoutFormat,
    #[error("header declares {declared} points but the file holds only {found}")]
    Truncated { declared: usize, found: usize },
    #[error(
        "has {points} points or more, above the {limit} one input may have (about {} GiB in \
         memory); split it into tiles, or raise {MAX_POINTS_VAR}",
        limit.saturating_mul(BYTES_PER_POINT) >> 30
    )]
    TooManyPoints { points: usize, limit: usize },
    #[error(
        "its {points} points with {fields} extra-bytes fields take the memory of {as_many} \
         points, above the {limit} one input may have; raise {MAX_POINTS_VAR}"
    )]
    TooManyFields {
        points: usize,
        fields: usize,
        as_many: usize,
        limit: usize,
    },
    #[error("{0}")]
    Malformed(String),
    #[error("output would overwrite the input file")]
    OverwritesInput,
    #[error("output directory {} does not exist", .0.display())]
    NoOutputDirectory(PathBuf),
    #[error("cannot write: {0}")]
    Write(std::io::Error),
    #[error("{0}")]
    Io(#[from] std::io::Error),
}

/// The environment variable that raises (or lowers) [`max_points`].
pub const MAX_POINTS_VAR: &str = "MVPCC_MAX_POINTS";
const DEFAULT_MAX_POINTS: usize = 200_000_000;
/// Memory a read point takes with colour and the LAS point record's fields (f64 each).
const BYTES_PER_POINT: usize = 72;

/// The most points one input may have: 200 million (about 13 GiB once read) unless
/// `MVPCC_MAX_POINTS` says otherwise. Readers check a header's count against it before reading
/// the points, and text formats as they go, so an input over it is an error, not an abort.
pub fn max_points() -> usize {
    std::env::var(MAX_POINTS_VAR)
        .ok()
        .and_then(|v| v.trim().parse().ok())
        .unwrap_or(DEFAULT_MAX_POINTS)
}

/// Refuses a cloud of `points` points when it exceeds [`max_points`].
pub(crate) fn check_points(points: usize) -> Result<(), Problem> {
    let limit = max_points();
    if points > limit {
        return Err(Problem::TooManyPoints { points, limit });
    }
    Ok(())
}

/// Refuses a cloud of `points` points with `fields` attribute columns beyond those
/// [`BYTES_PER_POINT`] counts when they would take more memory than [`max_points`] points do: a
/// compressed file can describe many times its size in such columns.
pub(crate) fn check_fields(points: usize, fields: usize) -> Result<(), Problem> {
    let as_many = points.saturating_mul(BYTES_PER_POINT + 8 * fields) / BYTES_PER_POINT;
    let limit = max_points();
    if as_many > limit {
        return Err(Problem::TooManyFields {
            points,
            fields,
            as_many,
            limit,
        });
    }
    Ok(())
}

/// A write error without the temporary file's name, which means nothing to the user.
pub(crate) fn write_problem(e: std::io::Error) -> Problem {
    Problem::Write(match (e.raw_os_error(), e.get_ref()) {
        (Some(code), _) => std::io::Error::from_raw_os_error(code),
        // tempfile wraps OS errors with its own path; the kind says the same without it.
        (None, Some(_)) => std::io::Error::from(e.kind()),
        (None, None) => e,
    })
}

/// A problem with a named file; displays as `path: problem` on one line.
#[derive(Debug, Error)]
#[error("{}: {problem}", path.display())]
pub struct CloudIoError {
    pub path: PathBuf,
    pub problem: Problem,
}

impl CloudIoError {
    pub fn new(path: &Path, problem: Problem) -> Self {
        CloudIoError {
            path: path.to_path_buf(),
            problem,
        }
    }
}

/// A loaded cloud and what was dropped on the way in.
#[derive(Debug)]
pub struct Loaded {
    pub cloud: PointCloud,
    /// Points with NaN or infinite coordinates, dropped (organized PCD files use NaN for
    /// "no return", so these are common and not an error).
    pub non_finite_dropped: usize,
}

/// What reading dropped, when it dropped points with NaN or infinite coordinates.
pub fn non_finite_warning(dropped: usize) -> Option<String> {
    (dropped > 0).then(|| {
        let s = if dropped == 1 { "" } else { "s" };
        format!("dropped {dropped} point{s} with NaN or infinite coordinates")
    })
}

/// The up axis of a file that does not say: MLS formats (LAS/LAZ) are z-up, the dataset's own
/// formats y-up.
pub fn default_up(input: &Path, format: Option<Format>) -> UpAxis {
    match Format::of_input(input, format).ok() {
        Some(Format::Las | Format::Laz) => UpAxis::Z,
        _ => UpAxis::Y,
    }
}

/// A whole file's bytes (weights), a missing file said in the words the cloud readers use.
pub fn read_bytes(path: &Path) -> Result<Vec<u8>, Problem> {
    std::fs::read(path).map_err(|e| match e.kind() {
        std::io::ErrorKind::NotFound => Problem::NotFound,
        _ => Problem::Io(e),
    })
}

/// Why a directory cannot be listed, the usual cases in the words the cloud readers use rather
/// than the OS's.
#[derive(Debug, Error)]
pub enum DirProblem {
    #[error("no such directory")]
    NotFound,
    #[error("not a directory")]
    NotADirectory,
    #[error("cannot list: {0}")]
    Io(std::io::Error),
}

/// Lists a directory; see [`DirProblem`].
pub fn read_dir(path: &Path) -> Result<std::fs::ReadDir, DirProblem> {
    std::fs::read_dir(path).map_err(|e| match e.kind() {
        std::io::ErrorKind::NotFound => DirProblem::NotFound,
        std::io::ErrorKind::NotADirectory => DirProblem::NotADirectory,
        _ => DirProblem::Io(e),
    })
}

/// Reads a cloud; the format comes from the extension unless `format` is given. `-` reads
/// standard input, and a pipe or device is read like it (see [`stdio`]).
///
/// ```
/// use mvpcc::io::read_cloud;
/// use std::path::Path;
///
/// let loaded = read_cloud(Path::new("assets/example/car_partial.ply"), None)?;
/// assert!(loaded.cloud.len() > 1000 && loaded.cloud.colors.is_some());
/// # Ok::<(), mvpcc::io::CloudIoError>(())
/// ```
pub fn read_cloud(path: &Path, format: Option<Format>) -> Result<Loaded, CloudIoError> {
    let err = |problem| CloudIoError::new(path, problem);
    if is_stream(path) {
        let format = Format::of_input(path, format).map_err(err)?;
        let (copy, _) = spooled(path).map_err(err)?;
        return read_cloud(&copy, Some(format)).map_err(|e| err(e.problem));
    }
    // Before the extension: a folder or a missing file is said as such whatever its name.
    let meta = std::fs::metadata(path).map_err(|e| {
        err(if e.kind() == std::io::ErrorKind::NotFound {
            Problem::NotFound
        } else {
            Problem::Io(e)
        })
    })?;
    if meta.is_dir() {
        return Err(err(Problem::IsDirectory));
    }
    let format = match format {
        Some(f) => f,
        None => Format::from_path(path).map_err(err)?,
    };
    if meta.len() == 0 {
        return Err(err(Problem::EmptyFile));
    }
    let mut cloud = match format {
        Format::Ply => ply::read(path),
        Format::Pcd => pcd::read(path),
        Format::Las | Format::Laz => las::read(path),
        Format::Xyz => xyz::read(path),
    }
    .map_err(err)?;
    debug_assert!(cloud.is_consistent());
    if cloud.is_empty() {
        return Err(err(Problem::NoPoints));
    }
    let total = cloud.len();
    let non_finite_dropped = cloud.drop_non_finite();
    if cloud.is_empty() {
        return Err(err(Problem::AllNonFinite(total)));
    }
    Ok(Loaded {
        cloud,
        non_finite_dropped,
    })
}

/// [`Format::of_output`], the error naming `path`.
pub fn output_format(path: &Path, given: Option<Format>) -> Result<Format, CloudIoError> {
    Format::of_output(path, given).map_err(|problem| CloudIoError::new(path, problem))
}

/// Writes a cloud atomically; the format comes from the extension unless `format` is given.
/// `-` writes standard output, which needs `format`.
pub fn write_cloud(
    path: &Path,
    cloud: &PointCloud,
    format: Option<Format>,
    encoding: Encoding,
) -> Result<(), CloudIoError> {
    if is_stdio(path) {
        return write_stdout(cloud, format, encoding);
    }
    let err = |problem| CloudIoError::new(path, problem);
    let format = output_format(path, format)?;
    match format {
        Format::Las | Format::Laz => write_las(path, cloud, format == Format::Laz),
        Format::Ply => {
            atomic_write(path, |w| ply::write(w, cloud, encoding)).map_err(write_problem)
        }
        Format::Pcd => {
            atomic_write(path, |w| pcd::write(w, cloud, encoding)).map_err(write_problem)
        }
        Format::Xyz => {
            atomic_write(path, |w| xyz::write(w, cloud, xyz::is_pts(path))).map_err(write_problem)
        }
    }
    .map_err(err)
}

/// `base`, or the first of `base_2`, `base_3`… that `taken` does not hold.
pub(crate) fn free_name(base: &str, taken: impl Fn(&str) -> bool) -> String {
    let mut name = base.to_string();
    for n in 2.. {
        if !taken(&name) {
            break;
        }
        name = format!("{base}_{n}");
    }
    name
}

/// The names a writer gives `cloud`'s attributes: their own, but a name the format would read
/// as something else (`taken`: a coordinate or a colour channel) or one already given gets
/// `_2`, `_3`… (none another attribute has), so that the file reads back with every attribute
/// apart.
pub(crate) fn attribute_names(cloud: &PointCloud, taken: impl Fn(&str) -> bool) -> Vec<String> {
    let mut names: Vec<String> = Vec::with_capacity(cloud.attributes.len());
    for a in &cloud.attributes {
        let another_own = |name: &str| name != a.name && cloud.attribute(name).is_some();
        let name = free_name(&a.name, |n| {
            taken(n) || names.iter().any(|m| m == n) || another_own(n)
        });
        names.push(name);
    }
    names
}

/// What `cloud` holds that a `format` file at `output` has no place for, one warning each: a LAS
/// input's coordinate reference system (only LAS and LAZ store one) and full-waveform packets
/// (none), a PCD input's viewpoint (only PCD), record fields whose values LAS cannot hold (an
/// intensity from 0 to 1), and attributes in XYZ text, which holds coordinates and colours only
/// (and PTS the intensity; completed points lose their `synthetic` flag there).
pub fn unwritten(cloud: &PointCloud, format: Format, output: &Path) -> Vec<String> {
    let mut lost = Vec::new();
    if !cloud.crs.is_empty() && !matches!(format, Format::Las | Format::Laz) {
        lost.push(
            "its coordinate reference system is not written: only a LAS or LAZ output holds one"
                .to_string(),
        );
    }
    if cloud.las_source.waveform {
        lost.push(
            "its waveform packets are not written: mvpcc writes no waveform data".to_string(),
        );
    }
    if cloud.viewpoint.is_some() && format != Format::Pcd {
        lost.push("its viewpoint is not written: only a PCD output holds one".to_string());
    }
    if matches!(format, Format::Las | Format::Laz) {
        lost.extend(las::clipped(cloud));
    }
    if format != Format::Xyz {
        return lost;
    }
    let pts = xyz::is_pts(output);
    let dropped: Vec<&str> = (cloud.attributes.iter().map(|a| a.name.as_str()))
        .filter(|&name| !(pts && name == xyz::INTENSITY))
        .collect();
    if !dropped.is_empty() {
        lost.push(format!(
            "{} not written: XYZ text holds coordinates and colours only{} (PLY, PCD or LAS \
             keep them)",
            named_list(dropped.into_iter()),
            if pts { ", and PTS the intensity" } else { "" }
        ));
    }
    lost
}

/// "attribute intensity is" or "attributes a, b, c, d and 4 more are" ("and 1 more" never).
fn named_list<'a>(names: impl ExactSizeIterator<Item = &'a str>) -> String {
    const SHOWN: usize = 4;
    let count = names.len();
    let mut shown: Vec<&str> = names
        .take(if count > SHOWN + 1 { SHOWN } else { count })
        .collect();
    let rest = count - shown.len();
    match (count, rest) {
        (1, _) => format!("attribute {} is", shown[0]),
        (_, 0) => {
            let last = shown.pop().unwrap_or_default();
            format!("attributes {} and {last} are", shown.join(", "))
        }
        _ => format!("attributes {} and {rest} more are", shown.join(", ")),
    }
}

/// Refuses an output that is one of the inputs (also through symbolic links), a directory, and an
/// output whose directory does not exist; standard output (`-`) is none of them.
pub fn check_output(output: &Path, inputs: &[&Path]) -> Result<(), CloudIoError> {
    if is_stdio(output) {
        return Ok(());
    }
    let err = |problem| CloudIoError::new(output, problem);
    if output.is_dir() {
        return Err(err(Problem::OutputIsDirectory));
    }
    let parent = parent_dir(output);
    if !parent.is_dir() {
        return Err(err(Problem::NoOutputDirectory(parent)));
    }
    if inputs.iter().any(|input| same_file(input, output)) {
        return Err(err(Problem::OverwritesInput));
    }
    Ok(())
}

/// Whether two paths name one file, following symbolic links; neither file need exist yet.
pub fn same_file(a: &Path, b: &Path) -> bool {
    resolved(a) == resolved(b)
}

fn parent_dir(path: &Path) -> PathBuf {
    match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    }
}

/// `path` with its links followed: the deepest part of it that exists resolved, the rest
/// appended (none of it need exist yet).
pub fn resolved(path: &Path) -> PathBuf {
    if let Ok(whole) = path.canonicalize() {
        return whole;
    }
    match path.file_name() {
        Some(name) if path.parent().is_some() => resolved(&parent_dir(path)).join(name),
        _ => path.to_path_buf(),
    }
}

/// What writing to a path means.
enum Destination {
    /// A file replaced whole: the path itself, or through links the file they name (the links
    /// stay).
    File(PathBuf),
    /// A device, pipe or socket (`/dev/null`, `/dev/stdout`, a shell's `>(…)`): written into,
    /// never replaced by a file.
    Stream,
}

fn destination(path: &Path) -> Destination {
    match std::fs::metadata(path) {
        Ok(meta) if meta.is_file() => {
            Destination::File(std::fs::canonicalize(path).unwrap_or_else(|_| path.to_path_buf()))
        }
        Ok(meta) if !meta.is_dir() => Destination::Stream,
        _ => Destination::File(path.to_path_buf()),
    }
}

/// Writes through `body` into a temporary file beside `path`, then renames it over `path`, so a
/// failed or interrupted write never leaves a half-written output. A device, pipe or socket is
/// written into instead.
pub fn atomic_write<F>(path: &Path, body: F) -> std::io::Result<()>
where
    F: FnOnce(&mut BufWriter<&File>) -> std::io::Result<()>,
{
    let file = match destination(path) {
        Destination::File(file) => file,
        Destination::Stream => {
            let stream = File::options().write(true).open(path)?;
            let mut w = BufWriter::with_capacity(1 << 20, &stream);
            return match body(&mut w).and_then(|()| w.flush()) {
                Err(e) if reader_left(&e) => Ok(()),
                written => written,
            };
        }
    };
    let tmp = temp_file_beside(&file)?;
    {
        let mut w = BufWriter::with_capacity(1 << 20, tmp.as_file());
        body(&mut w)?;
        w.flush()?;
    }
    persist(tmp, &file)
}

/// Renames a finished temporary file over `file`, which keeps the permissions it had (a new
/// file gets those of an ordinary new file).
pub(crate) fn persist(tmp: Scratch<NamedTempFile>, file: &Path) -> std::io::Result<()> {
    if let Ok(meta) = std::fs::metadata(file) {
        tmp.as_file().set_permissions(meta.permissions())?;
    }
    tmp.keep(|tmp| tmp.persist(file).map(drop).map_err(|e| e.error))
}

/// LAS/LAZ, whose writer seeks back to its header: into a device, pipe or socket it is written
/// whole to a temporary file first and then copied.
fn write_las(path: &Path, cloud: &PointCloud, compressed: bool) -> Result<(), Problem> {
    match destination(path) {
        Destination::File(file) => las::write(&file, cloud, compressed),
        Destination::Stream => {
            let format = if compressed { Format::Laz } else { Format::Las };
            let mut stream = File::options().write(true).open(path)?;
            match write_whole_into(&mut stream, cloud, format, Encoding::Binary) {
                Err(Problem::Io(e)) if reader_left(&e) => Ok(()),
                written => written,
            }
        }
    }
}

/// Whether a write into a stream failed because its reader went away (`| head`): what it did
/// not read it did not want, so that is no error.
fn reader_left(e: &std::io::Error) -> bool {
    e.kind() == std::io::ErrorKind::BrokenPipe
}

/// A temporary file in `path`'s directory (so the final rename stays on one file system),
/// created with the permissions of an ordinary new file rather than tempfile's private 0600,
/// and deleted if the process is stopped before it is renamed.
pub(crate) fn temp_file_beside(path: &Path) -> std::io::Result<Scratch<NamedTempFile>> {
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    let mut builder = tempfile::Builder::new();
    builder.prefix(".mvpcc-").suffix(".tmp");
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        builder.permissions(std::fs::Permissions::from_mode(0o666));
    }
    Ok(Scratch::new(builder.tempfile_in(dir)?))
}

/// A scratch folder beside `path` (on the output's file system, which has room for what is
/// written there), deleted when dropped or when the process is stopped.
pub(crate) fn scratch_dir_beside(path: &Path) -> std::io::Result<Scratch<tempfile::TempDir>> {
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    let made = tempfile::Builder::new().prefix(".mvpcc-").tempdir_in(dir)?;
    Ok(Scratch::new(made))
}

/// True when every coordinate survives a round trip through f32, so writing f32 loses nothing.
fn fits_f32(cloud: &PointCloud) -> bool {
    cloud
        .positions
        .iter()
        .all(|p| p.iter().all(|&c| (c as f32) as f64 == c))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::cloud::{Attribute, ScalarKind};

    #[cfg(unix)]
    #[test]
    fn a_replaced_output_keeps_its_permissions() {
        use std::os::unix::fs::PermissionsExt;
        let dir = tempfile::tempdir().unwrap();
        let cloud = colored_cloud(false);
        for name in ["kept.ply", "kept.las"] {
            let path = dir.path().join(name);
            std::fs::write(&path, b"old").unwrap();
            std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o640)).unwrap();
            write_cloud(&path, &cloud, None, Encoding::Binary).unwrap();
            let mode = std::fs::metadata(&path).unwrap().permissions().mode();
            assert_eq!(mode & 0o777, 0o640, "{name}");
            assert_eq!(read_cloud(&path, None).unwrap().cloud.len(), cloud.len());
        }
    }

    /// Each thing a format has no place for is named once, and only for that format.
    #[test]
    fn what_a_format_cannot_hold_is_named() {
        let mut cloud = colored_cloud(false);
        let flag = |name: &str| Attribute {
            name: name.into(),
            kind: ScalarKind::U8,
            values: vec![0.0; cloud.len()],
        };
        let attributes: Vec<Attribute> = ["synthetic", "intensity", "a", "b", "c", "d"]
            .into_iter()
            .map(flag)
            .collect();
        let lost = |cloud: &PointCloud, format| {
            unwritten(cloud, format, Path::new("cloud.xyz")).join(" | ")
        };
        cloud.attributes.clear();
        assert_eq!(lost(&cloud, Format::Xyz), "");
        cloud.attributes = attributes[..1].to_vec();
        assert!(lost(&cloud, Format::Xyz).starts_with("attribute synthetic is not written"));
        assert_eq!(lost(&cloud, Format::Ply), "");
        cloud.attributes = attributes[..2].to_vec();
        assert!(lost(&cloud, Format::Xyz).starts_with("attributes synthetic and intensity are"));
        cloud.attributes = attributes[..5].to_vec();
        assert!(
            lost(&cloud, Format::Xyz).starts_with("attributes synthetic, intensity, a, b and c")
        );
        let pts = unwritten(&cloud, Format::Xyz, Path::new("cloud.PTS")).join(" | ");
        assert!(
            pts.starts_with("attributes synthetic, a, b and c are not written"),
            "{pts}"
        );
        assert!(pts.contains("PTS the intensity"), "{pts}");
        cloud.attributes = attributes;
        assert!(lost(&cloud, Format::Xyz)
            .starts_with("attributes synthetic, intensity, a, b and 2 more are not written"));
        cloud.attributes.clear();
        cloud.viewpoint = Some([1.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0]);
        cloud.crs = vec![crate::core::cloud::CrsRecord {
            record_id: 2112,
            description: "OGC WKT".into(),
            data: b"GEOGCS[\"WGS 84\"]\0".to_vec(),
        }];
        assert_eq!(lost(&cloud, Format::Pcd).matches("not written").count(), 1);
        assert_eq!(lost(&cloud, Format::Las).matches("not written").count(), 1);
        assert_eq!(lost(&cloud, Format::Ply).matches("not written").count(), 2);
    }

    fn colored_cloud(georeferenced: bool) -> PointCloud {
        let base = if georeferenced {
            [650_000.125, 5_270_000.5, 110.0]
        } else {
            [0.0; 3]
        };
        let n = 257;
        PointCloud {
            positions: (0..n)
                .map(|i| {
                    let t = i as f64;
                    [
                        base[0] + 0.001 * t,
                        base[1] - 0.25 * t,
                        base[2] + (t * 0.37).sin(),
                    ]
                })
                .collect(),
            colors: Some(
                (0..n)
                    .map(|i| [i as u8, (i * 7) as u8, 255 - i as u8])
                    .collect(),
            ),
            attributes: vec![
                Attribute {
                    name: "intensity".into(),
                    kind: ScalarKind::U16,
                    values: (0..n).map(|i| (i * 100 % 65536) as f64).collect(),
                },
                Attribute {
                    name: "classification".into(),
                    kind: ScalarKind::U8,
                    // Standard ASPRS classes; 12 ("overlap") is not a class in LAS 1.4 writers.
                    values: (0..n).map(|i| (i % 10) as f64).collect(),
                },
            ],
            quantization: None,
            crs: Vec::new(),
            extra_bytes: Vec::new(),
            las_source: Default::default(),
            viewpoint: None,
        }
    }

    fn round_trip(ext: &str, encoding: Encoding, cloud: &PointCloud) -> PointCloud {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join(format!("cloud.{ext}"));
        write_cloud(&path, cloud, None, encoding).unwrap();
        read_cloud(&path, None).unwrap().cloud
    }

    /// `cloud` written as LAS or LAZ and read back, with the version and the point format its
    /// header declares.
    fn las_round_trip(ext: &str, cloud: &PointCloud) -> (PointCloud, (u8, u8), u8) {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join(format!("cloud.{ext}"));
        write_cloud(&path, cloud, None, Encoding::Binary).unwrap();
        let header = ::las::Reader::from_path(&path).unwrap().header().clone();
        let version = header.version();
        let format = header.point_format().to_u8().unwrap();
        let back = read_cloud(&path, None).unwrap().cloud;
        (back, (version.major, version.minor), format)
    }

    #[test]
    fn ply_and_pcd_round_trip_exactly_in_every_encoding() {
        for geo in [false, true] {
            let cloud = colored_cloud(geo);
            for ext in ["ply", "pcd"] {
                for enc in [Encoding::Binary, Encoding::Ascii, Encoding::Compressed] {
                    let back = round_trip(ext, enc, &cloud);
                    assert_eq!(back.positions, cloud.positions, "{ext} {enc:?} geo={geo}");
                    assert_eq!(back.colors, cloud.colors, "{ext} {enc:?}");
                    assert_eq!(back.attributes, cloud.attributes, "{ext} {enc:?}");
                }
            }
        }
    }

    /// Attributes named like a coordinate or colour of the output's format (`X` from a text
    /// header, `red` or `rgb` from another format) were written under those names, and read
    /// back as the coordinate or colour (or refused: "2 properties for 'x'"); they are renamed.
    #[test]
    fn attributes_named_like_coordinates_or_colours_stay_attributes() {
        let mut cloud = colored_cloud(false);
        let n = cloud.len();
        for (k, name) in ["X", "red", "rgb", "red_2"].into_iter().enumerate() {
            cloud.attributes.push(Attribute {
                name: name.into(),
                kind: ScalarKind::F32,
                values: vec![k as f32 as f64 + 0.5; n],
            });
        }
        let renamed = [
            ("ply", ["X_2", "red_3", "rgb", "red_2"]),
            ("pcd", ["X", "red", "rgb_2", "red_2"]),
        ];
        for (ext, names) in renamed {
            for encoding in [Encoding::Binary, Encoding::Ascii] {
                let back = round_trip(ext, encoding, &cloud);
                assert_eq!(back.positions, cloud.positions, "{ext}");
                assert_eq!(back.colors, cloud.colors, "{ext}");
                let got: Vec<(&str, f64)> = back.attributes[2..]
                    .iter()
                    .map(|a| (a.name.as_str(), a.values[0]))
                    .collect();
                let want: Vec<(&str, f64)> = names.into_iter().zip([0.5, 1.5, 2.5, 3.5]).collect();
                assert_eq!(got, want, "{ext} {encoding:?}");
            }
        }
    }

    #[test]
    fn xyz_round_trips_positions_and_colors() {
        let cloud = colored_cloud(true);
        let back = round_trip("xyz", Encoding::Binary, &cloud);
        assert_eq!(back.positions, cloud.positions);
        assert_eq!(back.colors, cloud.colors);
    }

    #[test]
    fn las_and_laz_keep_colors_intensity_classification_and_quantization() {
        let cloud = colored_cloud(true);
        for ext in ["las", "laz"] {
            let back = round_trip(ext, Encoding::Binary, &cloud);
            let q = back.quantization.expect("LAS carries its quantization");
            for (a, b) in cloud.positions.iter().zip(&back.positions) {
                for i in 0..3 {
                    assert!(
                        (a[i] - b[i]).abs() <= q.scale[i] / 2.0 + 1e-9,
                        "{a:?} vs {b:?}"
                    );
                }
            }
            assert_eq!(back.colors, cloud.colors, "{ext}");
            assert_eq!(back.attribute("intensity"), cloud.attribute("intensity"));
            assert_eq!(
                back.attribute("classification"),
                cloud.attribute("classification")
            );
            assert_eq!(
                back.attribute(crate::core::cloud::SYNTHETIC),
                None,
                "no flag set"
            );
            // Written again, the file keeps the scale and offset it was read with.
            let again = round_trip(ext, Encoding::Binary, &back);
            assert_eq!(again.quantization, back.quantization);
            assert_eq!(again.positions, back.positions);
        }
    }

    /// A header claiming 10⁹ points in a file of a few: refused from the points that are
    /// there, without first allocating for the claim (the las crate's `read_all` asked for
    /// ~19 GiB here).
    #[test]
    fn a_las_header_claiming_a_billion_points_is_refused_without_allocating_for_them() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("cloud.las");
        write_cloud(&path, &colored_cloud(true), None, Encoding::Binary).unwrap();
        let mut bytes = std::fs::read(&path).unwrap();
        // LAS 1.2's legacy point count, a u32 at byte 107 of the header.
        bytes[107..111].copy_from_slice(&1_000_000_000u32.to_le_bytes());
        std::fs::write(&path, &bytes).unwrap();
        let err = read_cloud(&path, None).unwrap_err().to_string();
        assert!(
            err.contains("1000000000") || err.contains("file ends before"),
            "{err}"
        );
    }

    /// LAS 1.4's point formats (6–10, as current MLS data comes) hold classification codes
    /// above 31, which LAS 1.2's cannot: such a cloud failed to write ("invalid classification:
    /// 64"). Code 12 ("overlap points"), which the las crate reads as class 1 with a flag,
    /// came back as 1 and was written as 0.
    #[test]
    fn las_keeps_every_classification_code() {
        for (codes, version, format) in [
            ([1.0, 12.0, 2.0, 31.0], (1, 2), 2),
            ([64.0, 12.0, 2.0, 255.0], (1, 4), 7),
        ] {
            let mut cloud = colored_cloud(true);
            let n = cloud.len();
            let classes = (0..n).map(|i| codes[i % codes.len()]).collect();
            cloud.attributes[1].values = classes;
            for ext in ["las", "laz"] {
                let (back, written, written_format) = las_round_trip(ext, &cloud);
                assert_eq!(
                    (written, written_format),
                    (version, format),
                    "{codes:?} {ext}"
                );
                assert_eq!(
                    back.attribute("classification"),
                    cloud.attribute("classification"),
                    "{codes:?} {ext}"
                );
                assert_eq!(back.colors, cloud.colors);
            }
        }
    }

    /// A LAS file's returns, scan angle, user data, point source and GPS time were dropped on
    /// reading, so `complete in.las out.las` lost them even for the measured points. They come
    /// back as they were in both generations of point formats (the scan angle in 1.4's 0.006°
    /// steps), and a cloud without them gains no columns.
    #[test]
    fn las_keeps_the_point_records_fields() {
        let names = |cloud: &PointCloud| -> Vec<String> {
            let attributes = las_round_trip("las", cloud).0.attributes;
            attributes.into_iter().map(|a| a.name).collect()
        };
        let mut wide = colored_cloud(true);
        wide.attributes[1].values[0] = 64.0;
        // LAS 1.4's formats have a GPS time whether or not the cloud had one.
        for plain in [colored_cloud(true), wide] {
            assert_eq!(names(&plain), ["intensity", "classification"]);
        }
        // Whole degrees in LAS 1.2; 1.4's steps as the las crate turns them into degrees (these
        // two came back one step smaller when written as read), which alone need LAS 1.4.
        let steps = |n: [f32; 2]| n.map(|n| (n * 0.006) as f64);
        for (classes, angles, format) in [
            ([2.0, 6.0], [-15.0, 3.0], 3),
            ([1.0, 2.0], steps([-2995.0, 2925.0]), 7),
        ] {
            let mut cloud = colored_cloud(true);
            let n = cloud.len();
            let column = |name: &str, kind, value: &dyn Fn(usize) -> f64| Attribute {
                name: name.into(),
                kind,
                values: (0..n).map(value).collect(),
            };
            cloud.attributes[1].values = (0..n).map(|i| classes[i % 2]).collect();
            cloud.attributes.extend([
                column("return_number", ScalarKind::U8, &|i| (1 + i % 3) as f64),
                column("number_of_returns", ScalarKind::U8, &|_| 3.0),
                column("scan_angle", ScalarKind::F32, &|i| angles[i % 2]),
                column("user_data", ScalarKind::U8, &|i| (i % 256) as f64),
                column("point_source_id", ScalarKind::U16, &|i| (7 * i) as f64),
                column("gps_time", ScalarKind::F64, &|i| {
                    401_234.567_891 + i as f64 * 1e-6
                }),
            ]);
            for ext in ["las", "laz"] {
                let (back, _, written_format) = las_round_trip(ext, &cloud);
                assert_eq!(written_format, format, "{ext}");
                for want in &cloud.attributes {
                    let got = back.attribute(&want.name);
                    let got = got.unwrap_or_else(|| panic!("{} lost ({ext})", want.name));
                    assert_eq!(
                        (got.kind, &got.values),
                        (want.kind, &want.values),
                        "{}",
                        want.name
                    );
                }
            }
        }
    }

    /// LAS 1.4's formats keep the overlap flag apart from the class byte, in which 12 is an
    /// ordinary (reserved) code: the las crate reads a byte of 12 as class 1, so a file written
    /// elsewhere lost its class 12, and the flag of a classified point was dropped.
    #[test]
    fn las_1_4_keeps_class_12_and_the_overlap_flag_apart() {
        use ::las::point::Classification;
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("elsewhere.las");
        let mut builder = ::las::Builder::from((1, 4));
        builder.point_format = ::las::point::Format::new(6).unwrap();
        let header = builder.into_header().unwrap();
        let mut writer = ::las::Writer::from_path(&path, header).unwrap();
        let points = [
            (Classification::Reserved(12), false),
            (Classification::Ground, true),
            (Classification::Unclassified, true),
            (Classification::Unclassified, false),
        ];
        for (k, (classification, is_overlap)) in points.into_iter().enumerate() {
            let point = ::las::Point {
                x: k as f64,
                classification,
                is_overlap,
                gps_time: Some(0.0),
                ..Default::default()
            };
            writer.write_point(point).unwrap();
        }
        writer.close().unwrap();
        let cloud = read_cloud(&path, None).unwrap().cloud;
        let values = |c: &PointCloud, name| c.attribute(name).map(|a| a.values.clone());
        assert_eq!(
            values(&cloud, "classification"),
            Some(vec![12.0, 2.0, 1.0, 1.0])
        );
        assert_eq!(values(&cloud, "overlap"), Some(vec![0.0, 1.0, 1.0, 0.0]));
        for ext in ["las", "laz"] {
            let (back, version, _) = las_round_trip(ext, &cloud);
            assert_eq!(version, (1, 4));
            for name in ["classification", "overlap"] {
                assert_eq!(values(&back, name), values(&cloud, name), "{name} {ext}");
            }
        }
    }

    /// A PLY's float intensity from 0 to 1, or PTS's from −2048 to 2047, became 0 and 1 (or 0) in
    /// a LAS output's 16-bit field without a word.
    #[test]
    fn record_fields_las_cannot_hold_are_named() {
        let mut cloud = colored_cloud(false);
        let n = cloud.len();
        let lost = |cloud: &PointCloud| unwritten(cloud, Format::Las, Path::new("out.las"));
        for (values, clipped) in [
            (
                (0..n).map(|i| i as f64 / n as f64).collect::<Vec<_>>(),
                true,
            ),
            ((0..n).map(|i| i as f64 - 2048.0).collect(), true),
            (vec![65_536.0; n], true),
            ((0..n).map(|i| (i * 7) as f64).collect(), false),
        ] {
            cloud.attributes = vec![Attribute {
                name: "intensity".into(),
                kind: ScalarKind::F32,
                values,
            }];
            let warnings = lost(&cloud).join(" | ");
            assert_eq!(
                warnings.contains("intensity is written as a whole number from 0 to 65535"),
                clipped,
                "{warnings}"
            );
            assert!(unwritten(&cloud, Format::Ply, Path::new("out.ply")).is_empty());
        }
        cloud.attributes[0].name = "user_data".into();
        cloud.attributes[0].values = vec![300.0; n];
        let warnings = lost(&cloud).join(" | ");
        let says = "user_data is written as a whole number from 0 to 255 in LAS: its values, \
                    from 300 to 300, are clipped";
        assert!(warnings.contains(says), "{warnings}");
    }

    /// Full-waveform scans (formats 4, 5, 9, 10) point each return into waveform packets that no
    /// output carries: the loss was silent.
    #[test]
    fn waveform_packets_are_said_to_be_lost() {
        let dir = tempfile::tempdir().unwrap();
        for (format, index) in [(4, 1), (9, 1), (4, 0)] {
            let path = dir.path().join(format!("waveform{format}-{index}.las"));
            let mut builder = ::las::Builder::from((1, 4));
            builder.point_format = ::las::point::Format::new(format).unwrap();
            let header = builder.into_header().unwrap();
            let mut writer = ::las::Writer::from_path(&path, header).unwrap();
            for k in 0..3 {
                let point = ::las::Point {
                    x: k as f64,
                    gps_time: Some(0.0),
                    waveform: Some(::las::raw::point::Waveform {
                        wave_packet_descriptor_index: index,
                        byte_offset_to_waveform_data: 100 * k,
                        waveform_packet_size_in_bytes: 100,
                        ..Default::default()
                    }),
                    ..Default::default()
                };
                writer.write_point(point).unwrap();
            }
            writer.close().unwrap();
            let cloud = read_cloud(&path, None).unwrap().cloud;
            let lost = unwritten(&cloud, Format::Las, Path::new("out.las")).join(" | ");
            assert_eq!(lost.contains("waveform"), index != 0, "{format}: {lost}");
        }
    }

    /// The header's GPS time type says what `gps_time` counts (week seconds or adjusted
    /// standard time); it was written as week seconds whatever the input said, so an MLS scan's
    /// standard times changed meaning. It, the file source ID (the trajectory) and the system
    /// identifier are kept.
    #[test]
    fn las_keeps_what_its_header_says_of_the_points() {
        let source = crate::core::cloud::LasSource {
            standard_gps_time: true,
            file_source_id: 7,
            system_identifier: "RIEGL VMX-2HA".into(),
            ..Default::default()
        };
        let mut cloud = PointCloud {
            las_source: source.clone(),
            ..colored_cloud(true)
        };
        let times = (0..cloud.len()).map(|i| 3.2e8 + i as f64).collect();
        cloud.attributes.push(Attribute {
            name: "gps_time".into(),
            kind: ScalarKind::F64,
            values: times,
        });
        for ext in ["las", "laz"] {
            let (back, _, _) = las_round_trip(ext, &cloud);
            assert_eq!(back.las_source, source, "{ext}");
        }
        let plain = las_round_trip("las", &colored_cloud(true)).0;
        assert!(!plain.las_source.standard_gps_time);
        assert_eq!(plain.las_source.file_source_id, 0);
    }

    /// Multi-scanner MLS systems number their scanners in LAS 1.4's scanner channel, and
    /// four-band ones add near infrared (format 8): both were dropped on reading. A channel
    /// needs LAS 1.4 (format 6/7), NIR beside colour format 8; a cloud with NIR and no colour
    /// keeps it as extra bytes (it was given black colours in format 8).
    #[test]
    fn las_keeps_the_scanner_channel_and_near_infrared() {
        let n = colored_cloud(true).len();
        let column = |name: &str, kind, value: &dyn Fn(usize) -> f64| Attribute {
            name: name.into(),
            kind,
            values: (0..n).map(value).collect(),
        };
        let channel = column("scanner_channel", ScalarKind::U8, &|i| (i % 4) as f64);
        let nir = column("nir", ScalarKind::U16, &|i| (i * 211 % 65536) as f64);
        let cases = [
            (vec![channel.clone()], true, (1, 4), 7),
            (vec![nir.clone()], true, (1, 4), 8),
            (vec![channel.clone(), nir.clone()], false, (1, 4), 6),
            (vec![nir], false, (1, 2), 0),
        ];
        for (extra, colored, version, format) in cases {
            let mut cloud = colored_cloud(true);
            if !colored {
                cloud.colors = None;
            }
            cloud.attributes.extend(extra.iter().cloned());
            for ext in ["las", "laz"] {
                let (back, written_version, written_format) = las_round_trip(ext, &cloud);
                let written = (written_version, written_format);
                assert_eq!(written, (version, format), "{ext}");
                for want in &extra {
                    assert_eq!(back.attribute(&want.name), Some(want), "{ext}");
                }
                assert_eq!(back.colors, cloud.colors, "{ext}");
            }
        }
    }

    /// The CRS records of a LAS input were dropped, so a georeferenced scan came out of
    /// `complete` with no coordinate system. GeoTIFF keys stay in LAS 1.2; a WKT too long for a
    /// VLR goes into an EVLR of LAS 1.4.
    #[test]
    fn las_keeps_the_coordinate_reference_system() {
        let record = |record_id, data: Vec<u8>| crate::core::cloud::CrsRecord {
            record_id,
            description: format!("record {record_id}"),
            data,
        };
        let geotiff = vec![
            record(
                34735,
                [1u16, 1, 0, 1, 3072, 0, 1, 25833]
                    .map(u16::to_le_bytes)
                    .concat(),
            ),
            record(34737, b"ETRS89 / UTM zone 33N|\0".to_vec()),
        ];
        let long_wkt = vec![record(2112, vec![b'W'; 70_000])];
        for (crs, version) in [(geotiff, (1, 2)), (long_wkt, (1, 4))] {
            let cloud = PointCloud {
                crs: crs.clone(),
                ..colored_cloud(true)
            };
            for ext in ["las", "laz"] {
                let (back, written, _) = las_round_trip(ext, &cloud);
                assert_eq!((back.crs, written), (crs.clone(), version), "{ext}");
            }
        }
        let ply = round_trip("ply", Encoding::Binary, &colored_cloud(true));
        assert!(ply.crs.is_empty());
    }

    #[test]
    fn las_carries_the_synthetic_flag() {
        let mut cloud = colored_cloud(true);
        let flags: Vec<f64> = (0..cloud.len()).map(|i| (i % 2) as f64).collect();
        cloud.attributes.push(crate::core::cloud::Attribute {
            name: crate::core::cloud::SYNTHETIC.into(),
            kind: crate::core::cloud::ScalarKind::U8,
            values: flags.clone(),
        });
        let back = round_trip("las", Encoding::Binary, &cloud);
        assert_eq!(
            back.attribute(crate::core::cloud::SYNTHETIC)
                .unwrap()
                .values,
            flags
        );
    }

    #[test]
    fn format_follows_the_extension() {
        assert_eq!(Format::from_path(Path::new("a.PLY")).unwrap(), Format::Ply);
        assert_eq!(Format::from_path(Path::new("a.laz")).unwrap(), Format::Laz);
        assert_eq!(Format::from_path(Path::new("a.csv")).unwrap(), Format::Xyz);
        assert!(matches!(
            Format::from_path(Path::new("a.obj")),
            Err(Problem::UnsupportedExtension(e)) if e == "obj"
        ));
    }

    #[test]
    fn an_output_format_is_given_or_named_and_its_error_points_to_out_format() {
        let ply = Some(Format::Ply);
        assert_eq!(
            Format::of_output(Path::new("a.obj"), ply).unwrap(),
            Format::Ply
        );
        assert_eq!(Format::of_output(Path::new("-"), ply).unwrap(), Format::Ply);
        assert_eq!(
            Format::of_output(Path::new("a.pcd"), None).unwrap(),
            Format::Pcd
        );
        assert!(matches!(
            Format::of_output(Path::new("-"), None),
            Err(Problem::StdoutFormat)
        ));
        let typo = Format::of_output(Path::new("a.plyy"), None).unwrap_err();
        assert!(
            typo.to_string().ends_with("or pass --out-format)"),
            "{typo}"
        );
    }

    #[cfg(unix)]
    #[test]
    fn outputs_get_ordinary_file_permissions() {
        use std::os::unix::fs::PermissionsExt;
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("out.xyz");
        write_cloud(&path, &colored_cloud(false), None, Encoding::Binary).unwrap();
        let mode = std::fs::metadata(&path).unwrap().permissions().mode() & 0o777;
        let status = std::fs::read_to_string("/proc/self/status").unwrap();
        let umask = status
            .lines()
            .find_map(|l| l.strip_prefix("Umask:"))
            .map(|m| u32::from_str_radix(m.trim(), 8).unwrap())
            .unwrap();
        assert_eq!(mode, 0o666 & !umask, "{mode:o} with umask {umask:o}");
    }

    #[test]
    fn a_failed_write_leaves_no_file_behind() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("out.ply");
        let result = atomic_write(&path, |w| {
            w.write_all(b"partial")?;
            Err(std::io::Error::other("interrupted"))
        });
        assert!(result.is_err());
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
    }

    #[test]
    fn output_equal_to_input_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let input = dir.path().join("in.ply");
        std::fs::write(&input, b"x").unwrap();
        let err = check_output(&dir.path().join("./in.ply"), &[&input]).unwrap_err();
        assert!(matches!(err.problem, Problem::OverwritesInput));
        assert!(check_output(&dir.path().join("out.ply"), &[&input]).is_ok());
        let err = check_output(&dir.path().join("missing/out.ply"), &[&input]).unwrap_err();
        assert!(matches!(err.problem, Problem::NoOutputDirectory(_)));
    }
}
