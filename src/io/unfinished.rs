//! Temporary files and folders still being written, so that a command stopped by Ctrl-C can
//! delete them: tempfile deletes its files when they are dropped, and nothing is dropped when
//! the process exits.

use std::path::{Path, PathBuf};
use std::sync::{Mutex, MutexGuard, PoisonError};

static UNFINISHED: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

fn unfinished() -> MutexGuard<'static, Vec<PathBuf>> {
    UNFINISHED.lock().unwrap_or_else(PoisonError::into_inner)
}

/// A temporary file or folder that [`remove_unfinished`] deletes until this is dropped.
#[must_use]
pub(crate) struct Tracked(PathBuf);

pub(crate) fn track(path: &Path) -> Tracked {
    unfinished().push(path.to_path_buf());
    Tracked(path.to_path_buf())
}

impl Drop for Tracked {
    fn drop(&mut self) {
        let mut paths = unfinished();
        if let Some(i) = paths.iter().rposition(|p| *p == self.0) {
            paths.swap_remove(i);
        }
    }
}

/// Deletes every temporary file and folder still being written (a half-written output's
/// temporary file beside it, a copy of standard input); for a signal handler, just before the
/// process exits. Best effort: what cannot be deleted is left.
pub fn remove_unfinished() {
    for path in unfinished().drain(..) {
        let removed = if path.is_dir() {
            std::fs::remove_dir_all(&path)
        } else {
            std::fs::remove_file(&path)
        };
        drop(removed);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn what_is_still_being_written_is_removed_and_nothing_else() {
        let dir = tempfile::tempdir().unwrap();
        let (file, folder, done) = (
            dir.path().join("file.tmp"),
            dir.path().join("folder"),
            dir.path().join("done.tmp"),
        );
        std::fs::write(&file, b"half").unwrap();
        std::fs::create_dir(&folder).unwrap();
        std::fs::write(folder.join("inside"), b"x").unwrap();
        std::fs::write(&done, b"whole").unwrap();
        let (_file, _folder) = (track(&file), track(&folder));
        drop(track(&done));
        remove_unfinished();
        assert!(!file.exists() && !folder.exists());
        assert!(done.exists());
    }
}
