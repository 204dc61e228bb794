//! `-` as a cloud's path, and inputs that are streams rather than files.
//!
//! The readers take paths (LAZ must seek), so standard input (`-`), or a pipe or device named
//! as an input (`<(…)`, `/dev/stdin`), is read to its end into a temporary file the first time
//! a command asks for it, and every later read of it reads that copy; its format comes from its
//! first bytes unless its name has a known extension. A cloud for standard output is written
//! whole to a temporary file first and then copied out, so a write that fails sends nothing
//! rather than half a file.

use super::unfinished::Scratch;
use super::{write_cloud, CloudIoError, Encoding, Format, Problem};
use crate::core::cloud::PointCloud;
use std::fs::File;
use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::sync::{Mutex, PoisonError};
use tempfile::{NamedTempFile, TempPath};

/// The path that names standard input or standard output.
pub const STDIO: &str = "-";

/// Bytes of a stream looked at to tell its format.
const HEAD: u64 = 4096;

/// Whether `path` names standard input or output rather than a file.
pub fn is_stdio(path: &Path) -> bool {
    path.as_os_str() == STDIO
}

/// Whether an input `path` is read as a stream: standard input, or a pipe, device or socket.
pub(super) fn is_stream(path: &Path) -> bool {
    is_stdio(path) || std::fs::metadata(path).is_ok_and(|meta| !meta.is_file() && !meta.is_dir())
}

/// A stream's copy, once made.
struct Spooled {
    source: PathBuf,
    copy: Scratch<TempPath>,
    format: Format,
}

static SPOOLED: Mutex<Vec<Spooled>> = Mutex::new(Vec::new());

/// The temporary copy of the stream `path` names and the format its first bytes show, made on
/// the first call for that path.
pub(super) fn spooled(path: &Path) -> Result<(PathBuf, Format), Problem> {
    let mut spools = SPOOLED.lock().unwrap_or_else(PoisonError::into_inner);
    if let Some(s) = spools.iter().find(|s| s.source == path) {
        return Ok((s.copy.to_path_buf(), s.format));
    }
    let mut file = Scratch::new(NamedTempFile::new()?);
    if is_stdio(path) {
        std::io::copy(&mut std::io::stdin().lock(), &mut *file)?;
    } else {
        std::io::copy(&mut File::open(path)?, &mut *file)?;
    }
    file.flush()?;
    let mut head = Vec::new();
    File::open(file.path())?.take(HEAD).read_to_end(&mut head)?;
    let format = Format::sniff(&head);
    let copy = file.map(NamedTempFile::into_temp_path);
    let found = (copy.to_path_buf(), format);
    spools.push(Spooled {
        source: path.to_path_buf(),
        copy,
        format,
    });
    Ok(found)
}

/// Deletes the streams' temporary copies (statics are never dropped, so `main` calls this
/// before it exits).
pub fn release_spooled() {
    SPOOLED
        .lock()
        .unwrap_or_else(PoisonError::into_inner)
        .clear();
}

/// Writes `cloud` to standard output in `format`, which must be given: `-` has no extension.
pub(super) fn write_stdout(
    cloud: &PointCloud,
    format: Option<Format>,
    encoding: Encoding,
) -> Result<(), CloudIoError> {
    let err = |problem| CloudIoError::new(Path::new(STDIO), problem);
    let format = format.ok_or_else(|| err(Problem::StdoutFormat))?;
    match write_whole_into(&mut std::io::stdout().lock(), cloud, format, encoding) {
        Err(Problem::Io(e)) if super::reader_left(&e) => Ok(()),
        written => written.map_err(err),
    }
}

/// Writes `cloud` whole to a temporary file, then copies it into `out` (standard output, or a
/// pipe that LAS's writer cannot seek in), so a write that fails sends nothing.
pub(super) fn write_whole_into(
    out: &mut impl Write,
    cloud: &PointCloud,
    format: Format,
    encoding: Encoding,
) -> Result<(), Problem> {
    let dir = Scratch::new(tempfile::tempdir()?);
    let whole = dir.path().join("cloud");
    write_cloud(&whole, cloud, Some(format), encoding).map_err(|e| e.problem)?;
    std::io::copy(&mut File::open(&whole)?, out)?;
    out.flush()?;
    Ok(())
}

impl Format {
    /// The format a file's first bytes show: PLY and LAS by their magic (LAZ by LASzip's bit in
    /// the point format), PCD by a `VERSION` or `FIELDS` header line, anything else XYZ text.
    pub fn sniff(head: &[u8]) -> Format {
        const LAS_POINT_FORMAT: usize = 104;
        if head.starts_with(b"ply") {
            return Format::Ply;
        }
        if head.starts_with(b"LASF") {
            let compressed = head.get(LAS_POINT_FORMAT).is_some_and(|&id| id & 0x80 != 0);
            return if compressed { Format::Laz } else { Format::Las };
        }
        let pcd_header = String::from_utf8_lossy(head).lines().any(|line| {
            let line = line.trim_start();
            line.starts_with("VERSION") || line.starts_with("FIELDS")
        });
        if pcd_header {
            Format::Pcd
        } else {
            Format::Xyz
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn formats_are_told_by_their_first_bytes() {
        assert_eq!(Format::sniff(b"ply\nformat ascii 1.0\n"), Format::Ply);
        assert_eq!(
            Format::sniff(b"# .PCD v0.7\nVERSION 0.7\nFIELDS x y z\n"),
            Format::Pcd
        );
        assert_eq!(Format::sniff(b"FIELDS x y z\n"), Format::Pcd);
        assert_eq!(Format::sniff(b"# x y z\n1 2 3\n"), Format::Xyz);
        assert_eq!(Format::sniff(b"1,2,3\n"), Format::Xyz);
        let mut las = b"LASF".to_vec();
        las.resize(227, 0);
        assert_eq!(Format::sniff(&las), Format::Las);
        las[104] = 0x83;
        assert_eq!(Format::sniff(&las), Format::Laz);
        assert_eq!(Format::sniff(b"LASF"), Format::Las);
    }

    #[test]
    fn only_a_lone_dash_is_standard_io() {
        assert!(is_stdio(Path::new("-")));
        assert!(!is_stdio(Path::new("./-")));
        assert!(!is_stdio(Path::new("-.ply")));
    }
}
