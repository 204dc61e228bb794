//! Files that lie about their size, run under a 1 GiB address-space limit: each is refused with
//! one line naming it, without a panic, and without allocating what its header claims.

#![cfg(unix)]

use mvpcc::core::cloud::PointCloud;
use mvpcc::io::{write_cloud, Encoding};
use std::path::{Path, PathBuf};
use tempfile::TempDir;

/// Runs the binary with `args` under `ulimit -v` 1 GiB and expects one `error:` line naming
/// `names` and saying `problem`.
fn refused(args: &[&str], names: &str, problem: &str) {
    let output = std::process::Command::new("sh")
        .arg("-c")
        .arg("ulimit -v 1048576 && exec \"$0\" \"$@\"")
        .arg(assert_cmd::cargo::cargo_bin("mvpcc"))
        .args(args)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(1), "{args:?}: {stderr}");
    let lines: Vec<&str> = stderr.lines().collect();
    assert_eq!(lines.len(), 1, "one line expected: {stderr}");
    assert!(
        lines[0].starts_with("error: ") && lines[0].contains(names),
        "{stderr}"
    );
    assert!(
        lines[0].contains(problem),
        "{stderr} should say {problem:?}"
    );
}

fn write(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, bytes).unwrap();
    path
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

const PLY_CLAIM: &str = "has 4611686018427387904 points or more, above the 200000000";
const PCD_CLAIM: &str = "has 1000000000000 points or more, above the 200000000";

#[test]
fn clouds_whose_headers_claim_billions_of_points() {
    let dir = TempDir::new().unwrap();
    let d = dir.path();
    let out = d.join("out.ply");
    let ply_of = |count: u64, format: &str, body: &[u8]| {
        let mut bytes = format!(
            "ply\nformat {format} 1.0\nelement vertex {count}\n\
             property float x\nproperty float y\nproperty float z\nend_header\n"
        )
        .into_bytes();
        bytes.extend(body);
        bytes
    };
    let pcd_of = |count: u64, data: &str, body: &[u8]| {
        let mut bytes = format!(
            "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\n\
             WIDTH {count}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {count}\n\
             DATA {data}\n"
        )
        .into_bytes();
        bytes.extend(body);
        bytes
    };
    let ply = |format: &str, body: &[u8]| ply_of(1 << 62, format, body);
    let pcd = |data: &str, body: &[u8]| pcd_of(1_000_000_000_000, data, body);
    // Under the point limit, so the file's size is what stops them: 150 million points would
    // take 10 GiB.
    let below = 150_000_000;
    let cut = "header declares 150000000 points but the file holds only";
    let mut compressed = 12u32.to_le_bytes().to_vec();
    compressed.extend(1000u32.to_le_bytes());
    compressed.extend([0; 12]);
    let cases = [
        (
            "binary.ply",
            ply("binary_little_endian", &[0; 120]),
            PLY_CLAIM,
        ),
        ("ascii.ply", ply("ascii", b"1 2 3\n"), PLY_CLAIM),
        ("ascii.pcd", pcd("ascii", b"1 2 3\n"), PCD_CLAIM),
        ("binary.pcd", pcd("binary", &[0; 120]), PCD_CLAIM),
        (
            "compressed.pcd",
            pcd("binary_compressed", &compressed),
            PCD_CLAIM,
        ),
        (
            "cut.ply",
            ply_of(below, "binary_little_endian", &[0; 120]),
            cut,
        ),
        ("cut_ascii.ply", ply_of(below, "ascii", b"1 2 3\n"), cut),
        ("cut.pcd", pcd_of(below, "binary", &[0; 120]), cut),
        ("cut_ascii.pcd", pcd_of(below, "ascii", b"1 2 3\n"), cut),
        (
            "cut_compressed.pcd",
            pcd_of(below, "binary_compressed", &compressed),
            "150000000 points need",
        ),
    ];
    for (name, bytes, problem) in cases {
        let input = write(d, name, &bytes);
        refused(&["filter", s(&input), s(&out)], name, problem);
    }
    assert!(!out.exists());
}

#[test]
fn the_point_limit_is_stated_and_can_be_lowered() {
    let dir = TempDir::new().unwrap();
    let text: String = (0..1000).map(|i| format!("{i} 0 1\n")).collect();
    let input = write(dir.path(), "many.xyz", text.as_bytes());
    let out = dir.path().join("out.ply");
    assert_cmd::Command::cargo_bin("mvpcc")
        .unwrap()
        .env("MVPCC_MAX_POINTS", "999")
        .args(["filter", s(&input), s(&out)])
        .assert()
        .failure()
        .stderr(predicates::str::contains(
            "many.xyz: has 1000 points or more, above the 999 one input may have",
        ));
    assert!(!out.exists());
}

/// A text cloud's columns are sized for the lines left before they are read: a line of 100
/// numbers followed by two million empty lines reserved 1.6 GB, which aborted under the limit
/// before the bad line at the end was reached.
#[test]
fn a_text_file_of_empty_lines_reserves_little() {
    let dir = TempDir::new().unwrap();
    let mut text = vec!["1"; 100].join(" ");
    text.push_str(&"\n".repeat(2_000_000));
    text.push_str("1 2\n");
    let input = write(dir.path(), "newlines.xyz", text.as_bytes());
    let out = dir.path().join("out.ply");
    refused(
        &["filter", s(&input), s(&out)],
        "newlines.xyz",
        "2 values, expected at least x y z",
    );
}

/// Each extra-bytes field of a LAS file is a column of f64 once read, so a compressed file of
/// megabytes could ask for tens of gigabytes: the columns count against the same memory the
/// point limit stands for.
#[test]
fn extra_bytes_count_against_the_point_limit() {
    let dir = TempDir::new().unwrap();
    let n = 1000;
    let cloud = PointCloud {
        positions: (0..n).map(|i| [i as f64, 0.0, 1.0]).collect(),
        attributes: (0..20)
            .map(|k| mvpcc::core::cloud::Attribute {
                name: format!("field{k}"),
                kind: mvpcc::core::cloud::ScalarKind::U8,
                values: vec![k as f64; n],
            })
            .collect(),
        ..Default::default()
    };
    let input = dir.path().join("wide.laz");
    write_cloud(&input, &cloud, None, Encoding::Binary).unwrap();
    let out = dir.path().join("out.ply");
    // 1000 points with 20 columns more take what 1000 · (72 + 160) / 72 ≈ 3,222 points do.
    for (limit, ok) in [("3000", false), ("3300", true)] {
        let assert = assert_cmd::Command::cargo_bin("mvpcc")
            .unwrap()
            .env("MVPCC_MAX_POINTS", limit)
            .args(["filter", s(&input), s(&out)])
            .assert();
        if ok {
            assert.success();
        } else {
            assert.failure().stderr(predicates::str::contains(
                "wide.laz: its 1000 points with 20 extra-bytes fields take the memory of 3222 points, \
                 above the 3000 one input may have",
            ));
        }
        assert_eq!(out.exists(), ok, "limit {limit}");
    }
}

#[test]
fn a_las_file_claiming_a_billion_points() {
    let dir = TempDir::new().unwrap();
    let input = dir.path().join("claim.las");
    let one = PointCloud {
        positions: vec![[1.0, 2.0, 3.0]],
        ..Default::default()
    };
    write_cloud(&input, &one, None, Encoding::Binary).unwrap();
    let mut bytes = std::fs::read(&input).unwrap();
    // The legacy point count (LAS 1.0–1.4) and, from 1.4, the 64-bit one.
    bytes[107..111].copy_from_slice(&1_000_000_000u32.to_le_bytes());
    if bytes[25] >= 4 {
        bytes[247..255].copy_from_slice(&1_000_000_000u64.to_le_bytes());
    }
    std::fs::write(&input, bytes).unwrap();
    let out = dir.path().join("out.ply");
    refused(
        &["filter", s(&input), s(&out)],
        "claim.las",
        "has 1000000000 points or more",
    );
    // Under the limit, the file's end stops it.
    let mut bytes = std::fs::read(&input).unwrap();
    bytes[107..111].copy_from_slice(&150_000_000u32.to_le_bytes());
    if bytes[25] >= 4 {
        bytes[247..255].copy_from_slice(&150_000_000u64.to_le_bytes());
    }
    std::fs::write(&input, bytes).unwrap();
    refused(
        &["filter", s(&input), s(&out)],
        "claim.las",
        "file ends before all the points its header declares",
    );
}

/// CRC-32 (ISO-HDLC), as PNG chunks carry it.
fn crc32(bytes: &[u8]) -> u32 {
    !bytes.iter().fold(!0u32, |mut c, &b| {
        c ^= u32::from(b);
        for _ in 0..8 {
            c = if c & 1 == 1 {
                (c >> 1) ^ 0xEDB8_8320
            } else {
                c >> 1
            };
        }
        c
    })
}

fn chunk(kind: &[u8], data: &[u8]) -> Vec<u8> {
    let mut out = (data.len() as u32).to_be_bytes().to_vec();
    let body = [kind, data].concat();
    out.extend(&body);
    out.extend(crc32(&body).to_be_bytes());
    out
}

#[test]
fn a_view_png_of_30000_squared_pixels() {
    let dir = TempDir::new().unwrap();
    let views = dir.path().join("views");
    std::fs::create_dir(&views).unwrap();
    let mut header = 30000u32.to_be_bytes().to_vec();
    header.extend(30000u32.to_be_bytes());
    header.extend([16, 2, 0, 0, 0]);
    let png = [
        b"\x89PNG\r\n\x1a\n".to_vec(),
        chunk(b"IHDR", &header),
        chunk(b"IDAT", &[0x78, 0x9c, 0x03, 0x00, 0x00, 0x00, 0x00, 0x01]),
        chunk(b"IEND", &[]),
    ]
    .concat();
    write(&views, "locations_001.png", &png);
    let out = dir.path().join("out.ply");
    refused(
        &["reproject", s(&views), s(&out)],
        "locations_001.png",
        "exceeds 4096×4096 px",
    );
}

/// A safetensors file holding no tensors, whose metadata declares `config` for `network`.
fn declared(network: &str, config: &str) -> Vec<u8> {
    let header = serde_json::json!({"__metadata__": {
        "mvpcc.network": network,
        "mvpcc.format_version": "1",
        "mvpcc.model_config": config,
    }})
    .to_string();
    let mut bytes = (header.len() as u64).to_le_bytes().to_vec();
    bytes.extend(header.as_bytes());
    bytes
}

#[test]
fn weights_that_are_garbage_or_declare_huge_networks() {
    let dir = TempDir::new().unwrap();
    let d = dir.path();
    let input = d.join("car.ply");
    let car = mvpcc::datagen::shapes::scanned_side(&mvpcc::datagen::shapes::car(3000, 1));
    write_cloud(&input, &car, None, Encoding::Binary).unwrap();
    let out = d.join("out.ply");
    let garbage: Vec<u8> = (0..4096u32)
        .map(|i| (i.wrapping_mul(2654435761) >> 13) as u8)
        .collect();
    let generator_with = |field: &str, value: usize| {
        let mut config = serde_json::json!({"width": 16, "res_blocks": 2, "size": 64, "views": 4,
            "channels": "xyzrgb", "padding": "zero", "disc_width": 16});
        config[field] = value.into();
        declared("generator", &config.to_string())
    };
    let generator = |field: &str| generator_with(field, 100_000_000);
    let cases = [
        ("garbage.safetensors", garbage, "not a safetensors file"),
        (
            "deep.safetensors",
            generator("res_blocks"),
            "residual blocks 100000000",
        ),
        ("wide.safetensors", generator("width"), "width 100000000"),
        (
            "empty.safetensors",
            generator_with("width", 16),
            "tensors the network needs are missing",
        ),
    ];
    for (name, bytes, problem) in cases {
        let model = write(d, name, &bytes);
        refused(
            &["complete", s(&input), s(&out), "--model", s(&model)],
            name,
            problem,
        );
    }
    let orienter = write(
        d,
        "orienter.safetensors",
        &declared(
            "orienter",
            r#"{"point_widths":[100000000],"hidden":8,"points":64}"#,
        ),
    );
    refused(
        &[
            "complete",
            s(&input),
            s(&out),
            "--orient",
            "learned",
            "--orienter",
            s(&orienter),
        ],
        "orienter.safetensors",
        "a layer 100000000 wide",
    );
    assert!(!out.exists());
}

/// Sizes and batches that would take hundreds of gigabytes: each aborted the process on an
/// allocation (and a batch of 0 crashed `train-orient`) before these were refused. Counts of
/// objects and samples past theirs wrote until the disk was full.
#[test]
fn sizes_and_batches_beyond_the_limits() {
    let dir = TempDir::new().unwrap();
    let d = dir.path();
    let input = write(d, "cloud.xyz", b"0 0 0\n1 0 0\n0 1 0\n0 0 1\n1 1 1\n");
    let out = d.join("out");
    let data = d.join("data");
    let (cloud, to, from) = (s(&input), s(&out), s(&data));
    let project: &[&str] = &["project", cloud, to];
    let prepare: &[&str] = &["prepare", "--synth", "1", "--out", to];
    let profile: &[&str] = &["profile", "--config", "tiny"];
    let train: &[&str] = &["train", "--data", from, "--out", to];
    let orient: &[&str] = &["train-orient", "--data", from, "--out", to];
    let synth: &[&str] = &["synth", "--out", to];
    let synth_prepare: &[&str] = &["prepare", "--out", to];
    let over_1024 = "above the largest this build accepts (1024)";
    let cases = [
        (
            project,
            ["--size", "100000"],
            "--size: image size 100000",
            "above the largest this build renders (4096)",
        ),
        (
            project,
            ["--size", "0"],
            "--size: image size",
            "must be at least 8 pixels, got 0",
        ),
        (
            prepare,
            ["--gt-size", "100000"],
            "--gt-size",
            "at most 4096 pixels",
        ),
        (
            prepare,
            ["--max-points", "100000000000"],
            "--max-points 100000000000",
            "above the largest partial this build scans (10000000)",
        ),
        (
            prepare,
            ["--samples", "100000"],
            "--samples",
            "must lie in 1..=1000, got 100000",
        ),
        (
            synth,
            ["--count", "100000000000"],
            "--count",
            "must lie in 1..=100000, got 100000000000",
        ),
        (
            synth_prepare,
            ["--synth", "0"],
            "--synth",
            "must lie in 1..=100000, got 0",
        ),
        (profile, ["--batch", "100000"], "--batch 100000", over_1024),
        (
            train,
            ["--accumulate", "5000"],
            "accumulate 5000",
            over_1024,
        ),
        (train, ["--batch", "100000"], "batch 100000", over_1024),
        (orient, ["--batch", "0"], "batch 0", "1 to 1024 expected"),
        (
            orient,
            ["--batch", "100000000"],
            "batch 100000000",
            "1 to 1024 expected",
        ),
        (orient, ["--points", "0"], "--points", "1 to 65536 expected"),
    ];
    for (command, option, names, problem) in cases {
        let args: Vec<&str> = command.iter().chain(&option).copied().collect();
        refused(&args, names, problem);
        assert!(!out.exists(), "{args:?} wrote {}", out.display());
    }
}
