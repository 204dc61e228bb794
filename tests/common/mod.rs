//! Set-up shared by the integration tests that need a prepared dataset.

use assert_cmd::Command;
use std::path::Path;

/// `mvpcc prepare` of six synthetic objects (a third for the test split), two samples each,
/// 32-pixel views: the smallest data `train` and `train-orient` run on.
pub fn prepare_tiny_data(out: &Path) {
    Command::cargo_bin("mvpcc")
        .unwrap()
        .args([
            "prepare",
            "--synth",
            "6",
            "--split",
            "0.67",
            "--samples",
            "2",
        ])
        .args(["--size", "32", "--gt-size", "64", "--min-points", "500"])
        .args(["--max-points", "3000", "-q", "--out"])
        .arg(out)
        .assert()
        .success();
}
