//! What the fuzz targets share: the readers take paths, so each input is written to a file of
//! this process's own in memory-backed storage and read back from there.

use std::path::PathBuf;
use std::sync::OnceLock;

/// A directory of this process's own, on tmpfs when the machine has one.
pub fn scratch() -> &'static PathBuf {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let base = if std::path::Path::new("/dev/shm").is_dir() {
            PathBuf::from("/dev/shm")
        } else {
            std::env::temp_dir()
        };
        let dir = base.join(format!("mvpcc-fuzz-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("scratch directory");
        dir
    })
}

/// Writes `bytes` as `name` in the scratch directory.
pub fn file(name: &str, bytes: &[u8]) -> PathBuf {
    let path = scratch().join(name);
    std::fs::write(&path, bytes).expect("scratch file");
    path
}

/// Splits an input at the first `\n%%\n` into two files' bytes (the second empty without one),
/// so one input can hold a file and its companion (an OBJ and its MTL, two PNGs).
pub fn halves(data: &[u8]) -> (&[u8], &[u8]) {
    const MARK: &[u8] = b"\n%%\n";
    match data.windows(MARK.len()).position(|w| w == MARK) {
        Some(at) => (&data[..at], &data[at + MARK.len()..]),
        None => (data, &[]),
    }
}
