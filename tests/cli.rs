//! The real binary on small generated inputs: each command's happy path, and every kind of bad
//! input giving one `error:` line naming the file, a non-zero exit and no output file.

use assert_cmd::Command;
use mvpcc::cloud::PointCloud;
use mvpcc::io::{read_cloud, write_cloud, Encoding};
use mvpcc::metrics::compare_clouds;
use mvpcc::shapes;
use predicates::prelude::*;
use std::path::{Path, PathBuf};
use tempfile::TempDir;

fn mvpcc() -> Command {
    Command::cargo_bin("mvpcc").unwrap()
}

fn write(dir: &TempDir, name: &str, cloud: &PointCloud) -> PathBuf {
    let path = dir.path().join(name);
    write_cloud(&path, cloud, None, Encoding::Binary).unwrap();
    path
}

fn write_bytes(dir: &TempDir, name: &str, bytes: &[u8]) -> PathBuf {
    let path = dir.path().join(name);
    std::fs::write(&path, bytes).unwrap();
    path
}

fn car() -> PointCloud {
    shapes::car(20_000, 5).cloud
}

/// Runs `args`, expects failure with exactly one stderr line `error: …` that names `names`,
/// and checks that `output` was not created.
fn fails(args: &[&str], names: &str, problem: &str, output: &Path) {
    let assert = mvpcc().args(args).assert().failure();
    let stderr = String::from_utf8(assert.get_output().stderr.clone()).unwrap();
    let lines: Vec<&str> = stderr.lines().collect();
    assert_eq!(lines.len(), 1, "one line expected, got {stderr:?}");
    assert!(lines[0].starts_with("error: "), "{stderr}");
    assert!(lines[0].contains(names), "{stderr} should name {names}");
    assert!(
        lines[0].to_lowercase().contains(&problem.to_lowercase()),
        "{stderr} should say {problem:?}"
    );
    assert!(!stderr.contains("panicked"));
    assert!(!output.exists(), "{} must not be written", output.display());
}

/// Runs `mvpcc eval … --json` and parses what it prints.
fn eval_json(args: &[&str]) -> serde_json::Value {
    let out = mvpcc()
        .arg("eval")
        .args(args)
        .arg("--json")
        .assert()
        .success()
        .get_output()
        .stdout
        .clone();
    serde_json::from_slice(&out).unwrap()
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

#[test]
fn eval_reproduces_the_reference_fixture() {
    let dir = TempDir::new().unwrap();
    let p = write_bytes(&dir, "p.xyz", b"0 0 0\n0.006 0 0\n1 1 1\n0 0 0.01\n");
    let g = write_bytes(&dir, "g.xyz", b"0 0 0\n0 0.008 0\n");
    let v = eval_json(&["--metrics", "cd,f1", "--pred", s(&p), "--gt", s(&g)]);
    let pair = &v["pairs"][0];
    assert!((pair["cd_l2_half"].as_f64().unwrap() - 0.373041).abs() < 1e-12);
    assert!((pair["cd_l1"].as_f64().unwrap() - 0.219930544).abs() < 1e-9);
    assert_eq!(pair["fscore"][0]["tau"], 0.01);
    assert!((pair["fscore"][0]["f1"].as_f64().unwrap() - 2.0 / 3.0).abs() < 1e-12);
    assert!((pair["fscore"][1]["f1"].as_f64().unwrap() - 1.0 / 3.0).abs() < 1e-12);
    assert_eq!(pair["pred_points"], 4);
    assert_eq!(pair["gt_points"], 2);
    assert_eq!(v["normalization"], "none");
    // The table names its columns and prints the same number.
    mvpcc()
        .args(["eval", "--pred", s(&p), "--gt", s(&g)])
        .assert()
        .success()
        .stdout(
            predicate::str::contains("cd_l2_half").and(predicate::str::contains("3.730410e-1")),
        );
}

#[test]
fn eval_over_directories_matches_by_stem() {
    let dir = TempDir::new().unwrap();
    let (pred, gt) = (dir.path().join("pred"), dir.path().join("gt"));
    std::fs::create_dir_all(&pred).unwrap();
    std::fs::create_dir_all(&gt).unwrap();
    let full = shapes::car(4000, 1);
    let partial = shapes::scanned_side(&full);
    for name in ["a", "b"] {
        write_cloud(
            &gt.join(format!("{name}.ply")),
            &full.cloud,
            None,
            Encoding::Binary,
        )
        .unwrap();
        write_cloud(
            &pred.join(format!("{name}.pcd")),
            &partial,
            None,
            Encoding::Binary,
        )
        .unwrap();
    }
    let v = eval_json(&[
        "--pred-dir",
        s(&pred),
        "--gt-dir",
        s(&gt),
        "--normalize",
        "gt-box",
    ]);
    assert_eq!(v["pairs"].as_array().unwrap().len(), 2);
    assert_eq!(v["normalization"], "gt-box");
    let recall = v["mean"]["fscore"][0]["recall"].as_f64().unwrap();
    let precision = v["mean"]["fscore"][0]["precision"].as_f64().unwrap();
    assert!(
        precision > 0.99 && recall < 0.8,
        "a partial is precise but incomplete: {v}"
    );

    write_cloud(&gt.join("c.ply"), &full.cloud, None, Encoding::Binary).unwrap();
    write_cloud(&pred.join("d.ply"), &full.cloud, None, Encoding::Binary).unwrap();
    let stderr = mvpcc()
        .args(["eval", "--pred-dir", s(&pred), "--gt-dir", s(&gt)])
        .assert()
        .failure()
        .get_output()
        .stderr
        .clone();
    let stderr = String::from_utf8(stderr).unwrap();
    assert!(
        stderr.contains("only in predictions: [d]") && stderr.contains("only in ground truth: [c]"),
        "{stderr}"
    );
}

#[test]
fn project_then_reproject_returns_to_the_input_frame() {
    let dir = TempDir::new().unwrap();
    // A z-up car at georeferenced coordinates, as an MLS file would hold it.
    let mut cloud = car();
    for p in &mut cloud.positions {
        *p = [650_000.0 + p[2], 5_270_000.0 + p[0], 110.0 + p[1]];
    }
    let input = write(&dir, "car.las", &cloud);
    let views = dir.path().join("views");
    mvpcc()
        .args([
            "project",
            s(&input),
            s(&views),
            "--views",
            "5,6,7,8,17,19",
            "--size",
            "256",
        ])
        .assert()
        .success()
        .stderr(predicate::str::contains("6 views"));
    for cam in [5, 6, 7, 8, 17, 19] {
        assert!(views.join(format!("locations_{cam:03}.png")).exists());
        assert!(views.join(format!("color_{cam:03}.png")).exists());
    }
    let out = dir.path().join("back.ply");
    mvpcc()
        .args(["reproject", s(&views), s(&out), "--erode", "0"])
        .assert()
        .success();
    let back = read_cloud(&out, None).unwrap().cloud;
    let original = read_cloud(&input, None).unwrap().cloud;
    assert!(back.len() > 5_000, "{}", back.len());
    let m = compare_clouds(&back.positions, &original.positions, &[0.01]);
    // Back in metres at the original place: every re-projected point lies on the input.
    assert!(m.fscores[0].precision > 0.999, "{m:?}");
    assert!(m.cd_l1 < 0.05, "{m:?}");
    assert!(back.colors.is_some());
}

#[test]
fn filter_removes_far_outliers_and_keeps_attributes() {
    let dir = TempDir::new().unwrap();
    let mut cloud = car();
    let n = cloud.len();
    cloud
        .positions
        .extend([[30.0, 0.0, 0.0], [0.0, 40.0, 0.0], [-25.0, 1.0, 9.0]]);
    cloud.colors.as_mut().unwrap().extend([[1, 2, 3]; 3]);
    let input = write(&dir, "noisy.pcd", &cloud);
    let out = dir.path().join("clean.ply");
    mvpcc()
        .args([
            "filter",
            s(&input),
            s(&out),
            "--sor-k",
            "20",
            "--sor-std",
            "5",
        ])
        .assert()
        .success()
        .stderr(predicate::str::contains(format!("of {} points", n + 3)));
    let clean = read_cloud(&out, None).unwrap().cloud;
    assert!(clean.len() <= n && clean.len() > n - 50, "{}", clean.len());
    assert!(clean
        .positions
        .iter()
        .all(|p| p[0].abs() < 3.0 && p[1] < 3.0));
}

#[test]
fn nan_points_are_dropped_with_a_warning() {
    let dir = TempDir::new().unwrap();
    let input = write_bytes(
        &dir,
        "nan.xyz",
        b"0 0 0\nnan 1 1\n1 1 1\ninf 0 0\n0.5 0.2 0.1\n",
    );
    let out = dir.path().join("out.xyz");
    mvpcc()
        .args(["filter", s(&input), s(&out), "--sor-k", "0"])
        .assert()
        .success()
        .stderr(predicate::str::contains(
            "dropped 2 points with NaN or infinite coordinates",
        ));
    assert_eq!(read_cloud(&out, None).unwrap().cloud.len(), 3);
}

#[test]
fn bad_inputs_fail_cleanly() {
    let dir = TempDir::new().unwrap();
    let out = dir.path().join("out.ply");
    let o = s(&out);
    let header = "ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nend_header\n";
    let mut truncated = header.as_bytes().to_vec();
    truncated.extend_from_slice(&[0u8; 20]);

    let missing = dir.path().join("missing.ply");
    fails(
        &["filter", s(&missing), o],
        "missing.ply",
        "no such file",
        &out,
    );

    let subdir = dir.path().join("adir.ply");
    std::fs::create_dir(&subdir).unwrap();
    fails(
        &["filter", s(&subdir), o],
        "adir.ply",
        "is a directory",
        &out,
    );

    let cases: [(&str, &[u8], &str); 7] = [
        ("empty.pcd", b"", "empty"),
        (
            "zero.ply",
            b"ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nproperty float y\nproperty float z\nend_header\n",
            "no points",
        ),
        (
            "claims.pcd",
            b"FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 5\nHEIGHT 1\nPOINTS 5\nDATA ascii\n1 2 3\n4 5 6\n",
            "declares 5 points",
        ),
        ("cut.ply", &truncated, "declares 3 points but the file holds only 1"),
        (
            "format.ply",
            b"ply\nformat binary_middle_endian 1.0\nelement vertex 1\nproperty float x\nend_header\n",
            "unknown format line",
        ),
        ("token.xyz", b"0 0 0\n1 x 1\n", "not a number"),
        (
            "token.ply",
            b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\n1 abc 3\n",
            "do not match the header",
        ),
    ];
    for (name, bytes, problem) in cases {
        let input = write_bytes(&dir, name, bytes);
        fails(&["filter", s(&input), o], name, problem, &out);
    }

    let all_nan = write_bytes(&dir, "allnan.xyz", b"nan 0 0\n0 inf 0\n");
    fails(
        &["filter", s(&all_nan), o],
        "allnan.xyz",
        "NaN or infinite",
        &out,
    );

    let same = write_bytes(&dir, "same.xyz", b"1 2 3\n1 2 3\n1 2 3\n");
    let views = dir.path().join("views");
    fails(
        &["project", s(&same), s(&views)],
        "same.xyz",
        "zero extent",
        &views,
    );

    let unknown = write_bytes(&dir, "cloud.obj", b"v 0 0 0\n");
    fails(
        &["filter", s(&unknown), o],
        "cloud.obj",
        "unsupported file extension",
        &out,
    );

    let good = write(&dir, "good.ply", &car());
    let nodir = dir.path().join("nowhere/out.ply");
    fails(
        &["filter", s(&good), s(&nodir)],
        "nowhere",
        "does not exist",
        &nodir,
    );

    let before = std::fs::read(&good).unwrap();
    let assert = mvpcc()
        .args(["filter", s(&good), s(&good)])
        .assert()
        .failure();
    let stderr = String::from_utf8(assert.get_output().stderr.clone()).unwrap();
    assert!(
        stderr.starts_with("error: ") && stderr.contains("overwrite the input"),
        "{stderr}"
    );
    assert_eq!(
        std::fs::read(&good).unwrap(),
        before,
        "the input is untouched"
    );
}

#[test]
fn read_only_output_directory_fails_without_partial_files() {
    let dir = TempDir::new().unwrap();
    let good = write(&dir, "good.ply", &car());
    let locked = dir.path().join("locked");
    std::fs::create_dir(&locked).unwrap();
    let mut perms = std::fs::metadata(&locked).unwrap().permissions();
    use std::os::unix::fs::PermissionsExt;
    perms.set_mode(0o555);
    std::fs::set_permissions(&locked, perms).unwrap();
    // Root ignores permission bits; a read-only mount stops it.
    let target = if std::fs::write(locked.join("probe"), b"").is_ok() {
        PathBuf::from("/sys")
    } else {
        locked.clone()
    };
    if !target.is_dir() {
        eprintln!("skipped: no read-only directory available");
        return;
    }
    let out = target.join("out.ply");
    fails(&["filter", s(&good), s(&out)], "out.ply", "denied", &out);
    let leftovers: Vec<_> = std::fs::read_dir(&target)
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().starts_with(".mvpcc-"))
        .collect();
    assert!(leftovers.is_empty());
}

#[test]
fn view_metrics_compare_colour_images() {
    let dir = TempDir::new().unwrap();
    let full = shapes::car(8000, 2);
    let gt = write(&dir, "gt.ply", &full.cloud);
    let partial = write(&dir, "partial.ply", &shapes::scanned_side(&full));
    let (gv, pv) = (dir.path().join("gtv"), dir.path().join("pv"));
    for (input, views) in [(&gt, &gv), (&partial, &pv)] {
        mvpcc()
            .args(["project", s(input), s(views), "--size", "64"])
            .assert()
            .success();
    }
    let v = eval_json(&[
        "--metrics",
        "psnr,ssim,mae",
        "--pred-views",
        s(&pv),
        "--gt-views",
        s(&gv),
    ]);
    let views = &v["views"];
    assert_eq!(views["cameras"], serde_json::json!([5, 6, 7, 8]));
    let psnr = views["psnr_db"].as_f64().unwrap();
    assert!(psnr.is_finite() && psnr > 5.0, "{v}");
    assert!(views["mae"].as_f64().unwrap() > 0.0);
    // Against itself, perfect.
    let v = eval_json(&[
        "--metrics",
        "ssim,mae",
        "--pred-views",
        s(&gv),
        "--gt-views",
        s(&gv),
    ]);
    assert_eq!(v["views"]["mae"], 0.0);
    assert!((v["views"]["ssim"].as_f64().unwrap() - 1.0).abs() < 1e-9);
}

#[test]
fn shipped_example_is_what_the_generator_makes() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/example");
    let car = shapes::example_car();
    let gt = read_cloud(&dir.join("car_gt.ply"), None).unwrap().cloud;
    let partial = read_cloud(&dir.join("car_partial.ply"), None)
        .unwrap()
        .cloud;
    assert_eq!(gt, car.cloud);
    assert_eq!(partial, shapes::scanned_side(&car));
}

#[test]
fn profile_reports_a_median_and_a_breakdown() {
    let assert = mvpcc()
        .args([
            "profile", "--config", "tiny", "--runs", "2", "--device", "gpu",
        ])
        .assert()
        .success();
    let out = assert.get_output();
    let stdout = String::from_utf8(out.stdout.clone()).unwrap();
    let last = stdout.lines().last().unwrap();
    let ms: f64 = last
        .strip_prefix("forward_ms_median=")
        .unwrap_or_else(|| panic!("last line {last:?}"))
        .parse()
        .unwrap();
    assert!(ms > 0.0);
    for kind in [
        "conv 7x7",
        "conv 3x3 residual",
        "instance norm",
        "reflect pad",
    ] {
        assert!(stdout.contains(kind), "{kind} missing from {stdout}");
    }
    // A CPU-only build asked for a GPU says so once on stderr and goes on.
    let stderr = String::from_utf8(out.stderr.clone()).unwrap();
    if !cfg!(feature = "wgpu") {
        assert!(stderr.contains("warning: this mvpcc was built without GPU support"));
    }

    let json = mvpcc()
        .args(["profile", "--config", "tiny", "--runs", "1", "--json"])
        .args(["--channels", "xyz", "--padding", "zero", "--views", "2"])
        .assert()
        .success()
        .get_output()
        .stdout
        .clone();
    let json: serde_json::Value = serde_json::from_slice(&json).unwrap();
    assert_eq!(json["config"]["channels"], "xyz");
    assert_eq!(json["config"]["views"], 2);
    assert!(json["forward_ms_median"].as_f64().unwrap() > 0.0);
    assert!(json["layers_ms"].get("reflect pad").is_none());
}

#[test]
fn profile_refuses_a_size_the_network_cannot_take() {
    let none = Path::new("never-written");
    fails(
        &["profile", "--config", "tiny", "--size", "30"],
        "model config",
        "not a multiple of 4",
        none,
    );
}
