//! `scripts/gpu-run.sh --tiny`: the prepared GPU run, every step of it on the CPU with the tiny
//! model, so that the command a GPU session sends has run before it costs GPU minutes.

use std::path::Path;
use std::process::Command;

#[cfg(unix)]
#[test]
fn the_prepared_gpu_run_leaves_profiles_a_trained_leg_and_timings() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let scratch = scratch_dir(dir.path());
    let output = Command::new("bash")
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .env("TMPDIR", &scratch)
        .arg("scripts/gpu-run.sh")
        .args([
            "--tiny",
            "--minutes",
            "1",
            "--loss-depth",
            "5",
            "--warmup-steps",
            "3",
            "--input-copy",
            "--category",
            "car,motorcycle=3",
            "--bin",
        ])
        .arg(assert_cmd::cargo::cargo_bin("mvpcc"))
        .arg(&out)
        .output()
        .unwrap();
    let log = std::fs::read_to_string(out.join("run.log")).unwrap_or_default();
    assert!(output.status.success(), "{log}");
    assert_empty(&scratch);
    assert!(log.contains("--category car,motorcycle=3"), "{log}");

    let profiles = std::fs::read_to_string(out.join("profiles.txt")).unwrap();
    for line in [
        "mvpcc cpu tiny train step, batch 2: train_step_ms_median=",
        "mvpcc cpu tiny train step, batch 2, sliced layers: train_step_ms_median=",
        "mvpcc cpu tiny forward, batch 1: forward_ms_median=",
        "scaling devices=1 (cpu) batch=2: steps_per_second=",
        "scaling devices=2 (cpu,cpu) batch=4: steps_per_second=",
    ] {
        assert!(profiles.contains(line), "no {line:?} in {profiles}");
    }
    // The built-in model completes every file, in the default and the paper's pipeline; the
    // leg's, briefly trained, is timed on the files it completes (the count of failed ones is
    // reported, not hidden). Each `complete --json` report comes back whole.
    let completions: Vec<&str> = profiles
        .lines()
        .filter(|l| l.starts_with("mvpcc complete, model"))
        .collect();
    assert_eq!(completions.len(), 3, "{profiles}\n{log}");
    for (line, model) in [(0, "built-in"), (2, "built-in, --paper")] {
        assert!(
            completions[line].contains(&format!(
                "{model}, 9 files completed, 0 failed: network_ms_median="
            )),
            "{profiles}\n{log}"
        );
    }
    let reports: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("complete.json")).unwrap()).unwrap();
    for name in ["built-in", "leg", "paper"] {
        let results = reports[name]["results"].as_array();
        assert_eq!(results.map(Vec::len), Some(9), "{name}: {reports}");
    }
    // What the device tool brings back is counted in files (8 at most).
    assert!(std::fs::read_dir(&out).unwrap().count() <= 8);

    let summary: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("train.json")).unwrap())
            .unwrap_or_else(|e| panic!("train.json: {e}\n{log}"));
    assert_eq!(summary["outcome"], "interrupted", "{summary}");
    assert!(summary["step"].as_u64().unwrap() > 0, "{summary}");

    let run = dir.path().join("run");
    std::fs::create_dir(&run).unwrap();
    let parts: Vec<_> = std::fs::read_dir(&out)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.to_string_lossy().contains("run.tar.xz.part-"))
        .collect();
    assert!(!parts.is_empty() && parts.len() <= 5, "{parts:?}");
    let unpacked = Command::new("bash")
        .arg("-c")
        .arg(format!(
            "cat {}/run.tar.xz.part-* | tar -xJ -C {}",
            out.display(),
            run.display()
        ))
        .status()
        .unwrap();
    assert!(unpacked.success());
    for file in [
        "generator.safetensors",
        "config.json",
        "train.json",
        "log.jsonl",
        "losses.png",
    ] {
        assert!(
            run.join(file).is_file(),
            "{file} missing from the packed run"
        );
    }
    let settings: serde_json::Value =
        serde_json::from_slice(&std::fs::read(run.join("train.json")).unwrap()).unwrap();
    assert_eq!(settings["loss"]["depth"], 5.0, "{settings}");
    assert_eq!(settings["warmup_steps"], 3, "{settings}");
    let config: serde_json::Value =
        serde_json::from_slice(&std::fs::read(run.join("config.json")).unwrap()).unwrap();
    assert_eq!(config["input_copy"], true, "{config}");
    assert!(!run.join("checkpoints").exists());
    // The l1 losses never train the discriminator: it would come back as it went.
    assert!(!run.join("discriminator.safetensors").exists());
    assert!(has_png(&run.join("samples")), "no samples drawn");
}

/// A losses choice the script does not know is refused before anything runs.
#[cfg(unix)]
#[test]
fn an_unknown_losses_choice_is_refused_at_once() {
    let dir = tempfile::tempdir().unwrap();
    let output = Command::new("bash")
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .arg("scripts/gpu-run.sh")
        .args(["--losses", "wgan"])
        .arg(dir.path().join("out"))
        .output()
        .unwrap();
    assert!(!output.status.success());
    assert_eq!(
        String::from_utf8_lossy(&output.stderr),
        "error: --losses wgan: gan or l1\n"
    );
    assert!(!dir.path().join("out").exists());
}

/// A binary built before an option the leg passes (a stale target/cuda-dist) is refused before
/// any data is made, naming the option.
#[cfg(unix)]
#[test]
fn a_binary_without_the_legs_options_is_refused_before_the_data() {
    let dir = tempfile::tempdir().unwrap();
    let old = dir.path().join("old-mvpcc");
    std::fs::write(&old, "#!/bin/sh\necho 'Usage: mvpcc train --data <DATA>'\n").unwrap();
    let executable = std::os::unix::fs::PermissionsExt::from_mode(0o755);
    std::fs::set_permissions(&old, executable).unwrap();
    let out = dir.path().join("out");
    let scratch = scratch_dir(dir.path());
    let output = Command::new("bash")
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .env("TMPDIR", &scratch)
        .arg("scripts/gpu-run.sh")
        .args(["--widen", "48", "--bin"])
        .arg(&old)
        .arg(&out)
        .output()
        .unwrap();
    assert!(!output.status.success());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        stderr.contains("its train has no --init; rebuild it"),
        "{stderr}"
    );
    assert!(!std::fs::read_to_string(out.join("run.log"))
        .unwrap()
        .contains("prepare"));
    assert_empty(&scratch);
}

/// Where the script makes its working directory (TMPDIR), so a test can see it removed.
fn scratch_dir(parent: &Path) -> std::path::PathBuf {
    let scratch = parent.join("scratch");
    std::fs::create_dir(&scratch).unwrap();
    scratch
}

/// The script's working directory (binary, data, run: 100+ MB) is gone once it ends.
fn assert_empty(scratch: &Path) {
    let left: Vec<_> = std::fs::read_dir(scratch)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    assert!(left.is_empty(), "left behind: {left:?}");
}

fn has_png(dir: &Path) -> bool {
    std::fs::read_dir(dir).is_ok_and(|mut d| {
        d.any(|e| e.is_ok_and(|e| e.path().extension().is_some_and(|x| x == "png")))
    })
}
