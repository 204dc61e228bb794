//! The outputs of `complete` with the built-in models, pinned bit for bit: the README's example
//! and the reference MLS scans. A refactoring must leave them unchanged; a change meant to alter
//! them updates `tests/pinned/complete.txt` with `MVPCC_PIN=update cargo test --test pinned` and
//! says why in its commit.

use assert_cmd::Command;
use std::path::{Path, PathBuf};

/// 64-bit FNV-1a of a file's bytes.
fn fnv1a(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325, |h, &b| {
        (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3)
    })
}

/// Each case: a name, the input, and the options beside IN OUT.
fn cases() -> Vec<(String, PathBuf, Vec<&'static str>)> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut cases = vec![(
        "example".to_string(),
        root.join("assets/example/car_partial.ply"),
        vec![],
    )];
    let mls = root.join("../shared/reference/clouds/mls");
    for name in ["CAR164", "CAR172", "CAR175", "CAR178"] {
        let input = mls.join(format!("{name}.pcd"));
        if input.is_file() {
            cases.push((name.to_string(), input, vec!["--up", "z"]));
        } else {
            eprintln!("skipped {name}: {} is absent", input.display());
        }
    }
    cases
}

#[test]
fn complete_gives_the_pinned_outputs() {
    let pinned_path = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/pinned/complete.txt");
    let pinned = std::fs::read_to_string(&pinned_path).unwrap_or_default();
    let dir = tempfile::tempdir().unwrap();
    let mut found = Vec::new();
    for (name, input, options) in cases() {
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
    if std::env::var("MVPCC_PIN").as_deref() == Ok("update") {
        std::fs::write(&pinned_path, found.join("\n") + "\n").unwrap();
        return;
    }
    for line in &found {
        let name = line.split(' ').next().unwrap();
        let expected = pinned
            .lines()
            .find(|l| l.split(' ').next() == Some(name))
            .unwrap_or_else(|| panic!("{name} is not pinned in {}", pinned_path.display()));
        assert_eq!(
            line, expected,
            "complete's output for {name} changed (hash, bytes)"
        );
    }
}
