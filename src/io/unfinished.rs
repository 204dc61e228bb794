//! Temporary files and folders still being written, so that a command stopped by Ctrl-C can
//! delete them: tempfile deletes its files when they are dropped, and nothing is dropped when
//! the process exits.

use std::path::{Path, PathBuf};
use std::sync::{Mutex, MutexGuard, PoisonError};

/// Paths still being written. One per process; tests keep their own, because deleting what the
/// process-wide one holds would pull files from under tests running beside them.
struct Registry(Mutex<Vec<PathBuf>>);

static UNFINISHED: Registry = Registry::new();

impl Registry {
    const fn new() -> Self {
        Self(Mutex::new(Vec::new()))
    }

    fn paths(&self) -> MutexGuard<'_, Vec<PathBuf>> {
        self.0.lock().unwrap_or_else(PoisonError::into_inner)
    }

    fn track(&'static self, path: &Path) -> Tracked {
        self.paths().push(path.to_path_buf());
        Tracked {
            registry: self,
            path: path.to_path_buf(),
        }
    }

    /// Deletes every path and hands back the list, empty and still locked.
    fn remove_all(&self) -> MutexGuard<'_, Vec<PathBuf>> {
        let mut paths = self.paths();
        for path in paths.drain(..) {
            let removed = if path.is_dir() {
                std::fs::remove_dir_all(&path)
            } else {
                std::fs::remove_file(&path)
            };
            drop(removed);
        }
        paths
    }
}

/// A temporary file or folder that [`remove_unfinished_then`] deletes until this is dropped.
/// What deletes itself on drop is better held as a [`Scratch`].
#[must_use]
pub(crate) struct Tracked {
    registry: &'static Registry,
    path: PathBuf,
}

pub(crate) fn track(path: &Path) -> Tracked {
    UNFINISHED.track(path)
}

impl Drop for Tracked {
    fn drop(&mut self) {
        let mut paths = self.registry.paths();
        if let Some(i) = paths.iter().rposition(|p| *p == self.path) {
            paths.swap_remove(i);
        }
    }
}

/// A temporary file or folder that deletes itself when dropped (tempfile's `TempDir`,
/// `NamedTempFile`, `TempPath`), tracked until then. It is deleted before it is forgotten (the
/// fields drop in order), so that a signal caught while a finished command deletes it still
/// finds it, rather than ending the process halfway through the deletion.
pub(crate) struct Scratch<T> {
    value: T,
    tracked: Tracked,
}

impl<T: AsRef<Path>> Scratch<T> {
    pub(crate) fn new(value: T) -> Self {
        let tracked = UNFINISHED.track(value.as_ref());
        Scratch { value, tracked }
    }
}

impl<T> Scratch<T> {
    /// The same file held another way (a `NamedTempFile` as its `TempPath`), tracked on.
    pub(crate) fn map<U>(self, f: impl FnOnce(T) -> U) -> Scratch<U> {
        Scratch {
            value: f(self.value),
            tracked: self.tracked,
        }
    }

    /// Hands the file to `keep` (which renames it into place) and forgets it only afterwards.
    pub(crate) fn keep<R>(self, keep: impl FnOnce(T) -> R) -> R {
        let kept = keep(self.value);
        drop(self.tracked);
        kept
    }
}

impl<T> std::ops::Deref for Scratch<T> {
    type Target = T;
    fn deref(&self) -> &T {
        &self.value
    }
}

impl<T> std::ops::DerefMut for Scratch<T> {
    fn deref_mut(&mut self) -> &mut T {
        &mut self.value
    }
}

/// Deletes every temporary file and folder still being written (a half-written output's
/// temporary file beside it, a copy of standard input), then runs `stop`, which is to end the
/// process; for a signal handler. Best effort: what cannot be deleted is left. The list stays
/// locked through `stop`, because a thread whose file is deleted under it fails, and would
/// otherwise exit with its own error first: it lets go of that file on its way out, and waits
/// there.
pub fn remove_unfinished_then<T>(stop: impl FnOnce() -> T) -> T {
    let _held = UNFINISHED.remove_all();
    stop()
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
        static OWN: Registry = Registry::new();
        let (_file, _folder) = (OWN.track(&file), OWN.track(&folder));
        drop(OWN.track(&done));
        let held = OWN.remove_all();
        assert!(held.is_empty() && OWN.0.try_lock().is_err());
        drop(held);
        assert!(!file.exists() && !folder.exists());
        assert!(done.exists());
    }
}
