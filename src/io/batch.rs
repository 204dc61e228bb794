//! Runs over many files: which files a run takes (a folder walk or a list of paths), and which
//! of them belong to one shard of a run split across machines or scheduler jobs.
//!
//! A shard is chosen by a hash of the file's path relative to the run's root, so it depends on
//! nothing but that path: `n` jobs given `--shard 0/n` … `--shard n-1/n` over the same folder
//! take every file exactly once, whatever order they list it in and whichever files are added
//! to the folder later.

use super::{read_dir, DirProblem, Problem};
use std::collections::HashSet;
use std::io::ErrorKind;
use std::path::{Component, Path, PathBuf};
use thiserror::Error;

/// Most files one run completes at once: each job is a thread holding a cloud and its views,
/// and past the cores they only queue for them.
pub const MAX_JOBS: usize = 256;

/// Files completed at once when not told: one per core this process may use (its affinity and
/// cgroup quota counted), at most [`MAX_JOBS`]. Outputs do not depend on it.
pub fn default_jobs() -> usize {
    std::thread::available_parallelism()
        .map_or(1, |n| n.get())
        .min(MAX_JOBS)
}

#[derive(Debug, Error)]
pub enum BatchError {
    #[error("{}: {source}", path.display())]
    List { path: PathBuf, source: DirProblem },
    #[error("{}: {source}", path.display())]
    ListFile { path: PathBuf, source: Problem },
    #[error("{}:{line}: {problem}", path.display())]
    ListEntry {
        path: PathBuf,
        line: usize,
        problem: String,
    },
}

/// Part `index` of `count` of a batch (`i/n`, `i` counted from 0, as Slurm's
/// `SLURM_ARRAY_TASK_ID` with `--array=0-(n-1)` and Kubernetes' `JOB_COMPLETION_INDEX` count).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Shard {
    pub index: u64,
    pub count: u64,
}

impl std::str::FromStr for Shard {
    type Err = String;

    fn from_str(text: &str) -> Result<Shard, String> {
        let (i, n) = text
            .split_once('/')
            .ok_or_else(|| format!("'{text}' is not i/n (e.g. 0/4)"))?;
        let number = |s: &str| {
            s.trim()
                .parse::<u64>()
                .map_err(|_| format!("'{text}' is not i/n (e.g. 0/4)"))
        };
        let (index, count) = (number(i)?, number(n)?);
        if count == 0 {
            return Err(format!("'{text}': the number of shards must be at least 1"));
        }
        if index >= count {
            return Err(format!(
                "'{text}': shards are counted from 0, so the index must be below {count}"
            ));
        }
        Ok(Shard { index, count })
    }
}

impl std::fmt::Display for Shard {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

impl Shard {
    /// Whether this shard takes the item named `key` (see [`key`]).
    pub fn owns(&self, key: &str) -> bool {
        fnv1a(key.as_bytes()) % self.count == self.index
    }
}

/// The name a relative path is sharded by: its components joined by `/`, so that the same
/// file gets the same shard on every platform and however it was spelled (`./a//b.ply`).
pub fn key(relative: &Path) -> String {
    relative
        .components()
        .filter_map(|c| match c {
            Component::Normal(part) => Some(part.to_string_lossy()),
            _ => None,
        })
        .collect::<Vec<_>>()
        .join("/")
}

/// 64-bit FNV-1a: fixed by its definition, unlike std's hasher, which may change between Rust
/// releases and so between the machines of one run.
fn fnv1a(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325, |h, &b| {
        (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3)
    })
}

/// `inner` with its links followed, when it lies inside `root` and is not `root` itself: a
/// folder (a batch's outputs) whose files a walk of `root` should leave out.
pub fn nested_dir(root: &Path, inner: &Path) -> Option<PathBuf> {
    let root = root.canonicalize().ok()?;
    let inner = super::resolved(inner);
    (inner != root && inner.starts_with(&root)).then_some(inner)
}

/// Whether `path`, its links followed, lies in the folder `dir` (as [`nested_dir`] gives it).
pub fn lies_in(path: &Path, dir: &Path) -> bool {
    super::resolved(path).starts_with(dir)
}

/// Files under `dir` that `wanted` accepts, as sorted paths relative to `dir`. Hidden entries
/// (a leading `.`, such as the temporary files of an interrupted write) are skipped. Links are
/// followed, but each directory and file is taken once: a link back into the tree (or to its
/// parent) would otherwise repeat it down to the path-length limit.
pub fn walk(dir: &Path, wanted: impl Fn(&Path) -> bool) -> Result<Vec<PathBuf>, BatchError> {
    let mut found = Vec::new();
    let mut pending = vec![dir.to_path_buf()];
    let mut seen = HashSet::new();
    let canonical = |p: &Path| p.canonicalize().unwrap_or_else(|_| p.to_path_buf());
    while let Some(d) = pending.pop() {
        if !seen.insert(canonical(&d)) {
            continue;
        }
        let list_error = |source| BatchError::List {
            path: d.clone(),
            source,
        };
        for entry in read_dir(&d).map_err(list_error)? {
            let entry = entry.map_err(|e| list_error(DirProblem::Io(e)))?;
            if entry.file_name().to_string_lossy().starts_with('.') {
                continue;
            }
            let path = entry.path();
            if path.is_dir() {
                pending.push(path);
            } else if wanted(&path) && seen.insert(canonical(&path)) {
                found.push(path.strip_prefix(dir).expect("under dir").to_path_buf());
            }
        }
    }
    found.sort();
    Ok(found)
}

/// The inputs a list file names, one path per line (blank lines and `#` comments skipped), as
/// paths relative to `base`: a relative line is taken as relative to `base`, an absolute one
/// must lie under it. A line that climbs out (`..`) is refused, since its output would land
/// outside the output folder; a path listed twice is taken once.
pub fn read_list(list: &Path, base: &Path) -> Result<Vec<PathBuf>, BatchError> {
    let text = std::fs::read_to_string(list).map_err(|e| BatchError::ListFile {
        path: list.to_path_buf(),
        source: match e.kind() {
            ErrorKind::NotFound => Problem::NotFound,
            ErrorKind::IsADirectory => {
                Problem::Malformed("is a directory, not a list of paths".into())
            }
            ErrorKind::InvalidData => Problem::Malformed("not UTF-8 text".into()),
            _ => Problem::Io(e),
        },
    })?;
    let mut seen = HashSet::new();
    let mut files = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let entry = line.trim();
        if entry.is_empty() || entry.starts_with('#') {
            continue;
        }
        let problem = |problem: String| BatchError::ListEntry {
            path: list.to_path_buf(),
            line: i + 1,
            problem,
        };
        let path = Path::new(entry);
        let relative = if path.is_absolute() {
            path.strip_prefix(base).map_err(|_| {
                problem(format!(
                    "{entry} is not under {}, so it has no place in the output folder",
                    base.display()
                ))
            })?
        } else {
            path
        };
        if relative
            .components()
            .any(|c| matches!(c, Component::ParentDir))
        {
            return Err(problem(format!(
                "{entry} climbs out of its folder (..), so it has no place in the output folder"
            )));
        }
        let relative: PathBuf = relative
            .components()
            .filter(|c| matches!(c, Component::Normal(_)))
            .collect();
        if relative.as_os_str().is_empty() {
            return Err(problem(format!("{entry} names a folder, not a file")));
        }
        if seen.insert(relative.clone()) {
            files.push(relative);
        }
    }
    Ok(files)
}

/// `*` any run of characters, `?` one character. Only the last `*` is ever backtracked to (a
/// later star can take whatever an earlier one would have), so the work stays within
/// pattern × name: trying every split at every star took exponential time, and
/// `--include '*a*a*a*a*a*a*a*a*a*a*a*a*b'` over a name of sixty `a`s ran past 30 s.
pub fn matches(pattern: &[char], name: &[char]) -> bool {
    let (mut p, mut n) = (0, 0);
    // The last star seen and the name position its run currently ends at.
    let mut star: Option<(usize, usize)> = None;
    while n < name.len() {
        match pattern.get(p) {
            Some('*') => {
                star = Some((p, n));
                p += 1;
            }
            Some(&c) if c == '?' || c == name[n] => {
                p += 1;
                n += 1;
            }
            _ => match star {
                Some((at, end)) => {
                    star = Some((at, end + 1));
                    p = at + 1;
                    n = end + 1;
                }
                None => return false,
            },
        }
    }
    pattern[p..].iter().all(|&c| c == '*')
}

#[cfg(test)]
mod tests {
    use super::*;

    fn shard(text: &str) -> Shard {
        text.parse().unwrap()
    }

    #[test]
    fn shards_are_disjoint_cover_everything_and_stay_put() {
        let keys: Vec<String> = (0..1000)
            .map(|i| format!("city/block{i}/car.ply"))
            .collect();
        for n in [1, 3, 7] {
            let mut counts = vec![0usize; n];
            for key in &keys {
                let owners: Vec<usize> = (0..n)
                    .filter(|&i| shard(&format!("{i}/{n}")).owns(key))
                    .collect();
                assert_eq!(owners.len(), 1, "{key} in shards {owners:?} of {n}");
                counts[owners[0]] += 1;
            }
            // Balanced within a few standard deviations of a fair split.
            let fair = keys.len() / n;
            assert!(
                counts.iter().all(|&c| c.abs_diff(fair) < fair / 4 + 10),
                "{counts:?}"
            );
        }
        // The hash is fixed by its definition: the same key lands in the same shard anywhere.
        assert_eq!(fnv1a(b"a"), 0xaf63_dc4c_8601_ec8c);
    }

    #[test]
    fn a_path_is_sharded_however_it_is_spelled() {
        assert_eq!(key(Path::new("./a//b/c.ply")), "a/b/c.ply");
        assert_eq!(key(Path::new("a/b/c.ply")), "a/b/c.ply");
    }

    #[test]
    fn shard_syntax_is_checked() {
        assert_eq!(shard("2/4"), Shard { index: 2, count: 4 });
        for bad in ["4/4", "1/0", "1", "a/b", "-1/4"] {
            assert!(bad.parse::<Shard>().is_err(), "{bad}");
        }
        let message = "4/4".parse::<Shard>().unwrap_err();
        assert!(message.contains("counted from 0"), "{message}");
    }

    #[test]
    fn lists_resolve_against_the_base_and_refuse_what_escapes_it() {
        let dir = tempfile::tempdir().unwrap();
        let list = dir.path().join("list.txt");
        let base = Path::new("/data/scans");
        std::fs::write(
            &list,
            "# inputs\n\na.ply\n./b/c.pcd\n/data/scans/d.las\na.ply\n",
        )
        .unwrap();
        assert_eq!(
            read_list(&list, base).unwrap(),
            ["a.ply", "b/c.pcd", "d.las"].map(PathBuf::from)
        );
        for (bad, why) in [
            ("../x.ply", "climbs out"),
            ("/elsewhere/x.ply", "not under"),
        ] {
            std::fs::write(&list, format!("a.ply\n{bad}\n")).unwrap();
            let message = read_list(&list, base).unwrap_err().to_string();
            assert!(
                message.contains("list.txt:2:") && message.contains(why),
                "{message}"
            );
        }
    }

    #[test]
    fn a_folder_is_nested_only_strictly_inside_the_root() {
        let dir = tempfile::tempdir().unwrap();
        let root = dir.path().join("in");
        std::fs::create_dir_all(root.join("out")).unwrap();
        let nested = nested_dir(&root, &root.join("out/later")).unwrap();
        assert!(lies_in(&root.join("out/later/a.ply"), &nested));
        assert!(!lies_in(&root.join("out/a.ply"), &nested));
        assert!(nested_dir(&root, &root).is_none());
        assert!(nested_dir(&root, &root.join(".")).is_none());
        assert!(nested_dir(&root, &dir.path().join("elsewhere")).is_none());
        assert!(nested_dir(&root.join("out"), &root).is_none());
    }

    #[cfg(unix)]
    #[test]
    fn a_walk_takes_each_file_once_and_skips_hidden_ones() {
        let dir = tempfile::tempdir().unwrap();
        let root = dir.path();
        std::fs::create_dir_all(root.join("x/y")).unwrap();
        for f in ["a.ply", "x/b.ply", "x/y/c.ply", ".tmp-d.ply", "x/notes.txt"] {
            std::fs::write(root.join(f), b"").unwrap();
        }
        std::os::unix::fs::symlink(root, root.join("x/y/up")).unwrap();
        std::os::unix::fs::symlink(root.join("a.ply"), root.join("x/same.ply")).unwrap();
        let ply = |p: &Path| p.extension().is_some_and(|e| e == "ply");
        assert_eq!(
            walk(root, ply).unwrap(),
            ["a.ply", "x/b.ply", "x/y/c.ply"].map(PathBuf::from)
        );
    }

    #[test]
    fn wildcards() {
        let m = |p: &str, n: &str| {
            matches(
                &p.chars().collect::<Vec<_>>(),
                &n.chars().collect::<Vec<_>>(),
            )
        };
        assert!(m("partial_*.ply", "partial_12.ply"));
        assert!(!m("partial_*.ply", "gt.ply"));
        assert!(m("*", "anything"));
        assert!(m("a?c", "abc"));
        assert!(!m("a?c", "ac"));
        assert!(m("*.p*", "x.pcd"));
        assert!(m("", ""));
        assert!(m("*", ""));
        assert!(m("**", "ab"));
        assert!(!m("?", ""));
        assert!(!m("", "a"));
        assert!(m("a*b*c", "abbbc"));
        assert!(!m("a*b*c", "acb"));
        assert!(m("*ab", "aab"));
        assert!(m("*a?", "xaab"));
        assert!(!m("*a", "ab"));
        // Many stars against a long name that almost matches: answered at once.
        assert!(!m("*a*a*a*a*a*a*a*a*a*a*a*a*b", &"a".repeat(60)));
        assert!(m(
            "*a*a*a*a*a*a*a*a*a*a*a*a*b",
            &format!("{}b", "a".repeat(60))
        ));
    }
}
