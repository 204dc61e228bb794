//! Application services: what each command does, without parsing arguments or printing —
//! completing files and batches ([`complete`]), scoring ([`eval`]), making training data
//! ([`prepare`], [`synth`]), timing the network ([`profile`]), view folders ([`views`]) and the
//! typed reports' export as a table or JSON ([`table`]). The command line and the examples call
//! these.

pub mod complete;
pub mod eval;
pub mod prepare;
pub mod profile;
pub mod synth;
pub mod table;
pub mod views;

use std::path::{Path, PathBuf};
use thiserror::Error;

/// A file or folder the services could not create or write.
#[derive(Debug, Error)]
#[error("{}: cannot {action}: {source}", path.display())]
pub struct PathError {
    pub path: PathBuf,
    /// "create" or "write".
    pub action: &'static str,
    pub source: std::io::Error,
}

impl PathError {
    fn at(path: &Path, action: &'static str) -> impl FnOnce(std::io::Error) -> PathError {
        let path = path.to_path_buf();
        move |source| PathError {
            path,
            action,
            source,
        }
    }

    /// For a folder that could not be created.
    pub fn create(path: &Path) -> impl FnOnce(std::io::Error) -> PathError {
        PathError::at(path, "create")
    }

    /// For a file that could not be written.
    pub fn write(path: &Path) -> impl FnOnce(std::io::Error) -> PathError {
        PathError::at(path, "write")
    }
}

/// Creates `dir` and the folders above it.
fn create_dir(dir: &Path) -> Result<(), PathError> {
    std::fs::create_dir_all(dir).map_err(PathError::create(dir))
}

/// Writes `value` as pretty JSON to `path`, whole or not at all.
fn write_json(path: &Path, value: &impl serde::Serialize) -> Result<(), PathError> {
    crate::io::atomic_write(path, |w| {
        serde_json::to_writer_pretty(&mut *w, value).map_err(std::io::Error::other)
    })
    .map_err(PathError::write(path))
}

/// What a long service tells its caller as it goes, for a progress bar; callers without one
/// pass [`Quiet`]. Called from worker threads.
pub trait Progress: Sync {
    /// `total` items are about to be worked on.
    fn start(&self, _total: usize, _label: &str) {}
    /// One item is done.
    fn done(&self, _item: &str) {}
    /// All are done.
    fn finish(&self) {}
    /// Something worth a warning happened to one item; the work goes on.
    fn warn(&self, _message: &str) {}
    /// Something the person running it would want to know, not a problem.
    fn note(&self, _message: &str) {}
}

/// No progress shown.
pub struct Quiet;

impl Progress for Quiet {}
