//! The outputs of `complete` with the built-in models, pinned bit for bit: the README's example
//! and the reference MLS scans. A refactoring must leave them unchanged; a change meant to alter
//! them updates `tests/pinned/complete.txt` with
//! `MVPCC_PIN=update cargo test --test pinned -- --include-ignored` and says why in its commit.

use assert_cmd::Command;
use std::path::{Path, PathBuf};

/// 64-bit FNV-1a of a file's bytes.
fn fnv1a(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325, |h, &b| {
        (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3)
    })
}

/// The README's example, shipped in `assets/`.
fn example() -> Vec<(String, PathBuf, Vec<&'static str>)> {
    let input = Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/example/car_partial.ply");
    vec![("example".to_string(), input, vec![])]
}

/// The reference MLS scans (z up).
fn reference_scans() -> Vec<(String, PathBuf, Vec<&'static str>)> {
    let mls = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/reference/clouds/mls");
    assert!(mls.is_dir(), "{} is absent", mls.display());
    ["CAR164", "CAR172", "CAR175", "CAR178"]
        .into_iter()
        .map(|name| {
            let input = mls.join(format!("{name}.pcd"));
            (name.to_string(), input, vec!["--up", "z"])
        })
        .collect()
}

#[test]
fn complete_gives_the_pinned_output_on_the_example() {
    check_pinned(example());
}

#[ignore = "needs ../shared/reference"]
#[test]
fn complete_gives_the_pinned_outputs_on_the_reference_scans() {
    check_pinned(reference_scans());
}

/// Completes each case and compares its output's hash and length with its line in
/// `tests/pinned/complete.txt` (with `MVPCC_PIN=update`, rewrites those lines instead).
fn check_pinned(cases: Vec<(String, PathBuf, Vec<&'static str>)>) {
    let pinned_path = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/pinned/complete.txt");
    let pinned = std::fs::read_to_string(&pinned_path).unwrap_or_default();
    let dir = tempfile::tempdir().unwrap();
    let mut found = Vec::new();
    for (name, input, options) in cases {
        let ext = input.extension().unwrap().to_str().unwrap();
        let output = dir.path().join(format!("{name}.{ext}"));
        Command::cargo_bin("mvpcc")
            .unwrap()
            .args(["complete", "-q"])
            .arg(&input)
            .arg(&output)
            .args(options)
            .assert()
            .success();
        let bytes = std::fs::read(&output).unwrap();
        found.push(format!("{name} {:016x} {}", fnv1a(&bytes), bytes.len()));
    }
    let name_of = |line: &str| line.split(' ').next().unwrap_or_default().to_string();
    if std::env::var("MVPCC_PIN").as_deref() == Ok("update") {
        let mut lines: Vec<String> = pinned
            .lines()
            .filter(|l| !found.iter().any(|f| name_of(f) == name_of(l)))
            .map(str::to_string)
            .chain(found.iter().cloned())
            .collect();
        lines.sort_by_key(|l| (name_of(l) != "example", name_of(l)));
        std::fs::write(&pinned_path, lines.join("\n") + "\n").unwrap();
        return;
    }
    for line in &found {
        let name = name_of(line);
        let expected = pinned
            .lines()
            .find(|l| name_of(l) == name)
            .unwrap_or_else(|| panic!("{name} is not pinned in {}", pinned_path.display()));
        assert_eq!(
            line, expected,
            "complete's output for {name} changed (hash, bytes)"
        );
    }
}
