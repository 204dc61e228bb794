//! `mvpcc train` end to end on a few synthetic objects with the tiny model: the files a run
//! writes, exact resume, refusals, NaN and Ctrl-C handling.

use assert_cmd::Command;
use burn::tensor::{Device, Distribution, Tensor};
use mvpcc::model::weights::generator_from_bytes;
use predicates::prelude::*;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

mod common;

fn mvpcc() -> Command {
    Command::cargo_bin("mvpcc").unwrap()
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// The tiny dataset, made once per test run and shared by the tests, which only read it.
fn data() -> &'static Path {
    static DATA: OnceLock<PathBuf> = OnceLock::new();
    DATA.get_or_init(|| {
        let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("train-data");
        if dir.exists() {
            std::fs::remove_dir_all(&dir).unwrap();
        }
        common::prepare_tiny_data(&dir);
        dir
    })
}

/// The tiny model on two objects per step, validating and logging often; `changes` (option,
/// value pairs) replace or add options.
fn train(run: &Path, steps: u64, changes: &[&str]) -> Command {
    let steps = steps.to_string();
    #[rustfmt::skip]
    let mut options = vec![
        "--batch", "2", "--val-every", "3", "--val-samples", "2", "--seen-samples", "2",
        "--log-every", "2", "--checkpoint-every", "4", "--steps", &steps,
    ];
    for change in changes.chunks(2) {
        match options.iter().position(|o| *o == change[0]) {
            Some(at) => options[at + 1] = change[1],
            None => options.extend(change),
        }
    }
    let mut cmd = base(run);
    cmd.args(["--config", "tiny"]).args(options);
    cmd
}

/// `mvpcc train` on the shared data into `run`.
fn base(run: &Path) -> Command {
    Command::from_std(base_std(run))
}

fn base_std(run: &Path) -> std::process::Command {
    let mut cmd = std::process::Command::new(assert_cmd::cargo::cargo_bin("mvpcc"));
    cmd.args(["train", "--data", s(data()), "--out", s(run)]);
    cmd
}

/// The generator a run ended with, applied to one fixed random input.
fn output_of(run: &Path) -> Vec<f32> {
    let bytes = std::fs::read(run.join("generator.safetensors")).unwrap();
    let device = Device::flex();
    let (generator, config) = generator_from_bytes(&bytes, &device).unwrap();
    device.seed(11);
    let x = Tensor::<5>::random(
        [
            1,
            config.views,
            config.input_channels(),
            config.size,
            config.size,
        ],
        Distribution::Default,
        &device,
    );
    generator
        .forward(x)
        .images
        .into_data()
        .try_into_vec::<f32>()
        .unwrap()
}

fn max_difference(a: &[f32], b: &[f32]) -> f32 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f32::max)
}

#[test]
fn a_run_writes_its_files_and_resumes_exactly() {
    let dir = tempfile::tempdir().unwrap();
    let (whole, split, shorter) = (
        dir.path().join("whole"),
        dir.path().join("split"),
        dir.path().join("shorter"),
    );
    train(&whole, 8, &[]).assert().success().stderr(
        predicate::str::contains("stopped at step 8")
            .and(predicate::str::contains("validation CD"))
            .and(predicate::str::contains("; training samples CD"))
            .and(predicate::str::contains(
                "partial inputs of the 2 validation samples",
            )),
    );
    train(&split, 5, &[]).assert().success();
    train(&split, 8, &[])
        .arg("--resume")
        .assert()
        .success()
        .stderr(predicate::str::contains("resuming from"));
    train(&shorter, 7, &[]).assert().success();

    let (a, b, c) = (output_of(&whole), output_of(&split), output_of(&shorter));
    let resumed = max_difference(&a, &b);
    let one_step = max_difference(&a, &c);
    // Measured: 3e-6 to 6e-5 on earlier machines, 1.3e-3 on an AVX2-only one (2026-12-02),
    // while one step fewer moves the output by 0.035 to 0.1. Restored tensors take other SIMD
    // paths, and the gradients of the biases before each instance norm are rounding noise
    // that Adam scales up to whole steps, so the bound is relative to one step: a resume that
    // lost the optimizer's state moves the output by about a step.
    assert!(
        one_step > 1e-2,
        "one step fewer changes the output by only {one_step}"
    );
    assert!(
        resumed < one_step / 10.0,
        "resumed run differs by {resumed}, one step fewer by {one_step}"
    );

    for file in [
        "generator.safetensors",
        "config.json",
        "train.json",
        "losses.png",
        "log.jsonl",
        "checkpoints/latest",
        "checkpoints/step-00000008/state.json",
        "checkpoints/step-00000008/generator_optim.bpk",
        "best/generator.safetensors",
        "samples/00000003.png",
        "samples/00000006.png",
        // A run ended by --steps validates its last step too.
        "samples/00000008.png",
        "discriminator.safetensors",
    ] {
        assert!(whole.join(file).is_file(), "{file} missing");
    }
    let losses = image::open(whole.join("losses.png")).unwrap();
    assert!(losses.width() >= 800 && losses.height() >= 600);
    let log = std::fs::read_to_string(whole.join("log.jsonl")).unwrap();
    let kinds: Vec<String> = log
        .lines()
        .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap()["kind"].to_string())
        .collect();
    assert_eq!(kinds.iter().filter(|k| *k == "\"train\"").count(), 4);
    assert_eq!(validated_steps(&whole), [3, 6, 8]);
    // Each validation also scored two training samples, as the validation samples are.
    for line in log.lines() {
        let record: serde_json::Value = serde_json::from_str(line).unwrap();
        if record["kind"] == "validation" {
            assert_eq!(record["seen"]["samples"], 2, "{line}");
            assert!(record["seen"]["f1"].as_f64().unwrap() >= 0.0, "{line}");
        }
    }
    assert_eq!(kinds[0], "\"baseline\"");
    // The resumed run's log holds no line twice, and the validation of the step it was stopped
    // at (5) did not change what it went on to compute (compared above).
    assert_eq!(validated_steps(&split), [3, 5, 6, 8]);
    // Checkpoints beyond --keep (3) are pruned: 4 and 8 remain, plus the final one.
    let kept: Vec<String> = std::fs::read_dir(whole.join("checkpoints"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with("step-"))
        .collect();
    assert!(
        kept.len() <= 3 && kept.contains(&"step-00000008".to_string()),
        "{kept:?}"
    );
}

/// `cmd` fails with one line of error holding `text`.
fn refused_saying(cmd: &mut Command, text: &str) {
    cmd.assert().failure().stderr(
        predicate::str::starts_with("error: ")
            .and(predicate::str::contains(text))
            .and(predicate::str::contains("\n").count(1)),
    );
}

/// `cmd` (a run with `--init`) fails with one line saying the weights' config does not fit.
fn refused_for_its_config(cmd: &mut Command) {
    refused_saying(cmd, "--init: expected model config");
}

/// The steps of a run's validation records, in log order.
fn validated_steps(run: &Path) -> Vec<u64> {
    std::fs::read_to_string(run.join("log.jsonl"))
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap())
        .filter(|r| r["kind"] == "validation")
        .map(|r| r["step"].as_u64().unwrap())
        .collect()
}

#[test]
fn a_run_starts_from_another_runs_weights_and_refuses_other_shapes() {
    let dir = tempfile::tempdir().unwrap();
    let (first, second) = (dir.path().join("first"), dir.path().join("second"));
    train(&first, 2, &[]).assert().success();
    // No --config: the weights' own; no step: the generator comes out as it went in.
    base(&second)
        .args(["--init", s(&first), "--steps", "0", "--val-every", "0"])
        .assert()
        .success()
        .stderr(
            predicate::str::contains("starting from")
                .and(predicate::str::contains("discriminator.safetensors")),
        );
    assert_eq!(output_of(&first), output_of(&second));
    let settings = std::fs::read_to_string(second.join("train.json")).unwrap();
    assert!(settings.contains("generator.safetensors"), "{settings}");

    let third = dir.path().join("third");
    let mut cmd = base(&third);
    cmd.args(["--init", s(&first.join("generator.safetensors"))])
        .args(["--config", "small", "--size", "32", "--steps", "1"]);
    refused_for_its_config(&mut cmd);
    base(&third)
        .args(["--init", s(&first), "--resume"])
        .assert()
        .failure()
        .stderr(predicate::str::contains("cannot be used with"));
}

/// `--init COLOUR --channels xyz` starts a geometry-only run from a colour model's weights (the
/// colour planes' weights dropped) with a fresh discriminator; the other way round is refused.
#[test]
fn a_geometry_only_run_starts_from_a_colour_models_weights() {
    let dir = tempfile::tempdir().unwrap();
    let (colour, xyz) = (dir.path().join("colour"), dir.path().join("xyz"));
    train(&colour, 2, &[]).assert().success();
    base(&xyz)
        .args(["--init", s(&colour), "--channels", "xyz", "--steps", "1"])
        .args(["--val-every", "0", "--seen-samples", "0", "--batch", "2"])
        .assert()
        .success()
        .stderr(predicate::str::contains("discriminator.safetensors").not());
    let bytes = std::fs::read(xyz.join("generator.safetensors")).unwrap();
    let (_, config) = generator_from_bytes(&bytes, &Device::flex()).unwrap();
    assert_eq!(config.channels, mvpcc::model::Channels::Xyz);
    let settings = std::fs::read_to_string(xyz.join("train.json")).unwrap();
    assert!(settings.contains("\"discriminator\": null"), "{settings}");

    let mut back = base(&dir.path().join("back"));
    back.args(["--init", s(&xyz), "--channels", "xyzrgb", "--steps", "1"]);
    refused_for_its_config(&mut back);
}

#[test]
fn a_fresh_run_takes_the_built_in_models_shape_unless_told_otherwise() {
    let dir = tempfile::tempdir().unwrap();
    let config = |run: &Path| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(run.join("config.json")).unwrap()).unwrap()
    };
    let builtin = mvpcc::complete::builtin_shape().unwrap();
    for (name, options) in [
        ("default", &[][..]),
        ("named", &["--config", "BuiltIn"][..]),
    ] {
        let run = dir.path().join(name);
        base(&run)
            .args(options)
            .args(["--steps", "0", "--val-every", "0"])
            .assert()
            .success();
        let c = config(&run);
        assert_eq!(c["width"], builtin.width, "{name}: {c}");
        assert_eq!(c["res_blocks"], builtin.res_blocks, "{name}: {c}");
        assert_eq!(c["size"], builtin.size, "{name}: {c}");
        // The threshold was chosen for the built-in weights, not for fresh ones.
        assert!(c["occupancy"].is_null(), "{name}: {c}");
    }
    let cpu = dir.path().join("cpu");
    base(&cpu)
        .args(["--config", "cpu", "--steps", "0", "--val-every", "0"])
        .assert()
        .success();
    assert_eq!(config(&cpu)["res_blocks"], 6);
    refused_saying(
        base(&dir.path().join("none")).args(["--config", "huge", "--steps", "0"]),
        "--config huge: neither builtin, a preset",
    );
}

#[test]
fn a_run_widens_another_runs_generator_and_starts_from_its_output() {
    let dir = tempfile::tempdir().unwrap();
    let [narrow, wide, thinner] = ["narrow", "wide", "thinner"].map(|n| dir.path().join(n));
    train(&narrow, 2, &[]).assert().success();
    #[rustfmt::skip]
    base(&wide)
        .args(["--init", s(&narrow), "--widen", "12", "--steps", "0", "--val-every", "0"])
        .assert()
        .success()
        .stderr(predicate::str::contains("width 12").and(predicate::str::contains("a fresh discriminator")));
    let (before, after) = (output_of(&narrow), output_of(&wide));
    let largest = before
        .iter()
        .zip(&after)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f32::max);
    assert!(largest < 1e-5, "outputs differ by {largest}");

    refused_saying(
        base(&thinner).args(["--init", s(&narrow), "--widen", "4", "--steps", "1"]),
        "its width 8 is larger than the 4 asked for",
    );
    assert!(!thinner.join("generator.safetensors").exists());
}

#[test]
fn a_run_without_the_input_copy_starts_one_with_it_and_back() {
    let dir = tempfile::tempdir().unwrap();
    let [plain, copying, back] = ["plain", "copying", "back"].map(|n| dir.path().join(n));
    let input_copy = |run: &Path| {
        let bytes = std::fs::read(run.join("config.json")).unwrap();
        serde_json::from_slice::<serde_json::Value>(&bytes).unwrap()["input_copy"].clone()
    };
    train(&plain, 1, &["--val-every", "0"]).assert().success();
    #[rustfmt::skip]
    base(&copying)
        .args(["--init", s(&plain), "--input-copy", "--steps", "1", "--val-every", "0"])
        .assert()
        .success();
    assert_eq!(input_copy(&copying), true);
    #[rustfmt::skip]
    base(&back)
        .args(["--init", s(&copying), "--config", "tiny", "--steps", "1", "--val-every", "0"])
        .assert()
        .success();
    assert!(input_copy(&back).is_null());
}

#[test]
fn a_run_writes_the_occupancy_threshold_it_is_given_into_its_weights() {
    let dir = tempfile::tempdir().unwrap();
    let [first, chosen, refused] = ["first", "chosen", "refused"].map(|n| dir.path().join(n));
    train(&first, 1, &["--val-every", "0"]).assert().success();
    #[rustfmt::skip]
    base(&chosen)
        .args(["--init", s(&first), "--occupancy", "0.02", "--steps", "0", "--val-every", "0"])
        .assert()
        .success();
    let bytes = std::fs::read(chosen.join("generator.safetensors")).unwrap();
    let (_, config) = generator_from_bytes(&bytes, &Device::flex()).unwrap();
    assert_eq!(config.occupancy, Some(0.02));
    assert_eq!(output_of(&first), output_of(&chosen));

    refused_saying(
        base(&refused).args(["--init", s(&first), "--occupancy", "1.5", "--steps", "0"]),
        "1.5 is not a probability",
    );
    assert!(!refused.join("generator.safetensors").exists());
}

#[test]
fn loss_weights_the_adversarial_loss_and_early_fusion_are_options_kept_in_the_run() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    #[rustfmt::skip]
    let options = [
        "--loss-l1", "10", "--loss-adversarial", "0.2", "--loss-perceptual", "250",
        "--loss-style", "0.1", "--loss-bce", "1", "--loss-tv", "0.5", "--loss-depth", "5",
        "--adversarial", "non-saturating", "--tv-from-stage", "1", "--val-every", "0",
        "--fusion", "early",
    ];
    train(&run, 2, &options).assert().success();
    let config: serde_json::Value =
        serde_json::from_slice(&std::fs::read(run.join("config.json")).unwrap()).unwrap();
    assert_eq!(config["fusion"], "early");
    let bytes = std::fs::read(run.join("generator.safetensors")).unwrap();
    let (_, config) = generator_from_bytes(&bytes, &Device::flex()).unwrap();
    assert_eq!(config.fusion(), mvpcc::model::Fusion::Early);
    base(&run)
        .args(["--resume", "--fusion", "late"])
        .assert()
        .failure()
        .stderr(predicate::str::contains("fusion"));
    let settings: serde_json::Value =
        serde_json::from_slice(&std::fs::read(run.join("train.json")).unwrap()).unwrap();
    let loss = &settings["loss"];
    let weights: Vec<f64> = [
        "l1",
        "adversarial",
        "perceptual",
        "style",
        "occupancy",
        "tv",
        "depth",
    ]
    .iter()
    .map(|k| loss[k].as_f64().unwrap())
    .collect();
    assert_eq!(weights, [10.0, 0.2, 250.0, 0.1, 1.0, 0.5, 5.0]);
    // The depth term is logged where it is weighted (a step's depth error is never exactly 0).
    let log = std::fs::read_to_string(run.join("log.jsonl")).unwrap();
    let depth = log
        .lines()
        .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap())
        .filter_map(|r| r["losses"]["depth"].as_f64())
        .collect::<Vec<_>>();
    assert!(!depth.is_empty() && depth.iter().all(|d| *d > 0.0), "{log}");
    assert_eq!(loss["adversarial_kind"], "non-saturating");
    assert_eq!(settings["tv_from_stage"], 1);

    // A negative weight trained away from the target without a word, a NaN one (or jitter) until
    // the losses went NaN.
    for (option, value, said) in [
        ("--loss-l1", "-1", "loss weight l1 -1"),
        ("--loss-tv", "nan", "loss weight tv NaN"),
        ("--color-jitter", "nan", "colour jitter NaN"),
    ] {
        let refused = dir.path().join("refused");
        refused_saying(&mut train(&refused, 1, &[option, value]), said);
        assert!(!refused.exists(), "{option} {value}");
    }
}

/// `--config paper` and `--config original` train (at 32², one step) and write the network and
/// loss docs/paper.md's preset table gives them; their perceptual and style terms are VGG19's,
/// which is not shipped, and the run says so.
#[test]
fn the_paper_and_original_presets_train_with_the_settings_the_table_gives() {
    let dir = tempfile::tempdir().unwrap();
    let read = |run: &Path, file: &str| -> serde_json::Value {
        serde_json::from_slice(&std::fs::read(run.join(file)).unwrap()).unwrap()
    };
    #[rustfmt::skip]
    let expected = [
        ("paper", "decoder", false, 250.0, 0.1, "pixels", "colour", "non-saturating"),
        ("original", "encoder", true, 0.1, 250.0, "side", "all", "hinge"),
    ];
    for (preset, dilation, fusion_norm, perceptual, style, tv_scale, planes, adversarial) in
        expected
    {
        let run = dir.path().join(preset);
        base(&run)
            .args([
                "--config", preset, "--size", "32", "--steps", "1", "--batch", "1",
            ])
            .args(["--val-every", "0", "--seen-samples", "0"])
            .assert()
            .success()
            .stderr(predicate::str::contains(format!(
                "warning: --config {preset}: its perceptual and style terms are VGG19's"
            )));
        let bytes = std::fs::read(run.join("generator.safetensors")).unwrap();
        let (_, config) = generator_from_bytes(&bytes, &Device::flex()).unwrap();
        assert_eq!(
            (config.width, config.res_blocks, config.size),
            (64, 8, 32),
            "{preset}"
        );
        let dilation_of = |d: mvpcc::model::Dilation| format!("{d:?}").to_lowercase();
        assert_eq!(dilation_of(config.dilation()), dilation, "{preset}");
        assert_eq!(config.normalizes_fusion(), fusion_norm, "{preset}");
        let loss = &read(&run, "train.json")["loss"];
        assert_eq!(loss["perceptual"].as_f64(), Some(perceptual), "{preset}");
        assert_eq!(loss["style"].as_f64(), Some(style), "{preset}");
        assert_eq!(loss["tv_scale"], tv_scale, "{preset}");
        assert_eq!(loss["feature_planes"], planes, "{preset}");
        assert_eq!(loss["adversarial_kind"], adversarial, "{preset}");
    }
    // A preset's choice is an option like any other: the original network with the text's
    // dilation and loss scale.
    let mixed = dir.path().join("mixed");
    #[rustfmt::skip]
    base(&mixed)
        .args(["--config", "original", "--size", "32", "--steps", "1", "--batch", "1"])
        .args(["--val-every", "0", "--seen-samples", "0", "--dilation", "decoder"])
        .args(["--tv-scale", "pixels", "--fusion-norm", "false", "--loss-perceptual", "0"])
        .args(["--loss-style", "0"])
        .assert()
        .success()
        .stderr(predicate::str::contains("VGG19").not());
    let config = read(&mixed, "config.json");
    assert_eq!(config["dilation"], "decoder");
    assert_eq!(config["fusion_norm"], false);
    assert_eq!(read(&mixed, "train.json")["loss"]["tv_scale"], "pixels");
}

#[test]
fn a_run_refuses_to_overwrite_or_to_resume_with_other_settings() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    train(&run, 1, &[]).assert().success();
    train(&run, 2, &[]).assert().failure().stderr(
        predicate::str::contains("already holds a training run")
            .and(predicate::str::contains("--resume")),
    );
    for (change, said) in [
        (["--batch", "3"], "batch: the run has 2, the options give 3"),
        (
            ["--loss-style", "1"],
            "loss.style: the run has 250.0, the options give 1.0",
        ),
    ] {
        train(&run, 2, &change)
            .arg("--resume")
            .assert()
            .failure()
            .stderr(predicate::str::contains(said));
    }
    // A run saved before a setting existed resumes with that setting's default.
    let settings = run.join("train.json");
    let mut saved: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&settings).unwrap()).unwrap();
    saved["loss"].as_object_mut().unwrap().remove("depth");
    std::fs::write(&settings, saved.to_string()).unwrap();
    train(&run, 2, &[]).arg("--resume").assert().success();
    let resumed: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&settings).unwrap()).unwrap();
    assert_eq!(resumed["loss"]["depth"], 0.0);
    // Which training samples are scored beside the validation changes nothing the run computes.
    train(&run, 3, &["--seen-samples", "1"])
        .arg("--resume")
        .assert()
        .success();
    // Rendering views larger than the data's leaves holes: said, not refused.
    base(&dir.path().join("larger"))
        .args([
            "--config",
            "small",
            "--steps",
            "1",
            "--batch",
            "1",
            "--val-every",
            "0",
        ])
        .assert()
        .success()
        .stderr(predicate::str::contains(
            "warning: the data's views are 32² and the model's 128²",
        ));
    let fresh = dir.path().join("fresh");
    train(&fresh, 2, &[])
        .arg("--resume")
        .assert()
        .failure()
        .stderr(predicate::str::starts_with("error: "));
    mvpcc()
        .args(["train", "--data", s(dir.path()), "--out", s(&fresh)])
        .assert()
        .failure()
        .stderr(format!(
            "error: {}: not a shapenet-views directory (no GT/train folder)\n",
            dir.path().display()
        ));
    assert!(
        !fresh.exists(),
        "refused data leaves no run directory behind"
    );
}

#[test]
fn a_diverging_loss_stops_the_run_and_keeps_the_last_good_checkpoint() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    train(
        &run,
        30,
        &[
            "--lr",
            "1e30",
            "--checkpoint-every",
            "1",
            "--val-every",
            "0",
        ],
    )
    .assert()
    .failure()
    .stderr(
        predicate::str::is_match(r"loss is (NaN|inf|-inf) at step \d+; stopped without saving")
            .unwrap(),
    );
    let latest = std::fs::read_to_string(run.join("checkpoints/latest")).unwrap();
    assert!(run
        .join("checkpoints")
        .join(latest.trim())
        .join("state.json")
        .is_file());
    assert!(!run.join("generator.safetensors").exists());
}

/// Ctrl-C, or a scheduler's SIGTERM before its SIGKILL, ends a run with a checkpoint.
#[cfg(unix)]
#[test]
fn a_stop_signal_saves_a_checkpoint_and_the_run_resumes_from_it() {
    for signal in ["-INT", "-TERM"] {
        let dir = tempfile::tempdir().unwrap();
        let run = dir.path().join("run");
        let child = base_std(&run)
            .args(["--config", "tiny"])
            .args(["--batch", "1", "--val-every", "0", "--log-every", "1"])
            .args(["--checkpoint-every", "100000"])
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        let log = run.join("log.jsonl");
        let started = std::time::Instant::now();
        while !std::fs::read_to_string(&log).is_ok_and(|t| t.contains("\"train\"")) {
            assert!(started.elapsed().as_secs() < 120, "no training step logged");
            std::thread::sleep(std::time::Duration::from_millis(50));
        }
        let status = std::process::Command::new("kill")
            .args([signal, &child.id().to_string()])
            .status()
            .unwrap();
        assert!(status.success());
        let output = child.wait_with_output().unwrap();
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert!(output.status.success(), "{signal}: {stderr}");
        assert!(stderr.contains("interrupted at step"), "{signal}: {stderr}");
        assert!(run.join("generator.safetensors").is_file());
        let latest = std::fs::read_to_string(run.join("checkpoints/latest")).unwrap();
        let step: u64 = latest.trim().trim_start_matches("step-").parse().unwrap();
        base(&run)
            .args(["--resume", "--steps"])
            .arg((step + 1).to_string())
            .assert()
            .success()
            .stderr(predicate::str::contains(format!(
                "stopped at step {}",
                step + 1
            )));
    }
}

/// Starts `train` into `run` and kills it with SIGKILL as soon as `ready` holds (polled without
/// pause, so a moment that lasts milliseconds is caught).
#[cfg(unix)]
fn kill_when(run: &Path, resume: bool, ready: impl Fn(&Path) -> bool) {
    let mut cmd = base_std(run);
    cmd.args(["--config", "tiny", "--batch", "1", "--val-every", "2"])
        .args([
            "--val-samples",
            "2",
            "--seen-samples",
            "2",
            "--log-every",
            "1",
            "--checkpoint-every",
            "1",
        ])
        .args(["--keep", "2", "--steps", "1000"])
        .stderr(std::process::Stdio::null());
    if resume {
        cmd.arg("--resume");
    }
    let mut child = cmd.spawn().unwrap();
    let started = std::time::Instant::now();
    while !ready(run) {
        assert!(child.try_wait().unwrap().is_none(), "the run ended early");
        assert!(started.elapsed().as_secs() < 60, "the moment never came");
    }
    child.kill().unwrap();
    child.wait().unwrap();
}

fn train_lines(run: &Path) -> usize {
    std::fs::read_to_string(run.join("log.jsonl"))
        .map(|t| t.matches("\"train\"").count())
        .unwrap_or(0)
}

/// SIGKILL three times, at three kinds of moment (after a step's log line, while a checkpoint
/// is being written, right as the log grows), then `--resume` runs to the end: every file is
/// whole, and the log holds each step once.
#[cfg(unix)]
#[test]
fn a_run_killed_three_times_resumes_and_finishes() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    kill_when(&run, false, |run| train_lines(run) >= 2);
    let writing = |run: &Path| {
        std::fs::read_dir(run.join("checkpoints")).is_ok_and(|entries| {
            entries
                .filter_map(|e| e.ok())
                .any(|e| e.file_name().to_string_lossy().starts_with(".tmp-"))
        })
    };
    kill_when(&run, true, writing);
    let before = train_lines(&run);
    kill_when(&run, true, |run| train_lines(run) > before + 1);

    let latest = std::fs::read_to_string(run.join("checkpoints/latest")).unwrap();
    let step: u64 = latest.trim().trim_start_matches("step-").parse().unwrap();
    assert!(step >= 2, "the kills came before any progress ({latest})");
    let last = step + 3;
    #[rustfmt::skip]
    let same = [
        "--batch", "1", "--val-every", "2", "--log-every", "1", "--checkpoint-every", "1",
        "--keep", "2",
    ];
    train(&run, last, &same)
        .arg("--resume")
        .assert()
        .success()
        .stderr(predicate::str::contains(format!("stopped at step {last}")));
    let log = std::fs::read_to_string(run.join("log.jsonl")).unwrap();
    let mut steps: Vec<u64> = log
        .lines()
        .map(|l| serde_json::from_str::<serde_json::Value>(l).expect("whole lines"))
        .filter(|r| r["kind"] == "train")
        .map(|r| r["step"].as_u64().unwrap())
        .collect();
    let logged = steps.len();
    steps.dedup();
    assert_eq!(steps.len(), logged, "a step logged twice: {steps:?}");
    assert!(steps.windows(2).all(|w| w[0] < w[1]), "{steps:?}");
    assert_eq!(steps.last(), Some(&last));
    let validated = validated_steps(&run);
    assert!(validated.windows(2).all(|w| w[0] < w[1]), "{validated:?}");
    let bytes = std::fs::read(run.join("generator.safetensors")).unwrap();
    generator_from_bytes(&bytes, &Device::flex()).unwrap();
    let best = std::fs::read(run.join("best/state.json")).unwrap();
    serde_json::from_slice::<serde_json::Value>(&best).unwrap();
    let leftovers: Vec<String> = std::fs::read_dir(run.join("checkpoints"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with('.'))
        .collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");
}

/// A full disk, emulated by a file-size limit with its signal ignored (so a write past it fails
/// with "File too large" as one past a full disk fails with "No space left"): the checkpoint
/// that cannot be written is an error, and the run resumes from the one before.
#[cfg(unix)]
#[test]
fn a_checkpoint_that_cannot_be_written_is_an_error_and_keeps_the_previous_one() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    let quiet = ["--val-every", "0"];
    train(&run, 4, &quiet).assert().success();
    let mut limited = std::process::Command::new("sh");
    limited
        .arg("-c")
        .arg("trap '' XFSZ; ulimit -f 32 && exec \"$0\" \"$@\"")
        .arg(assert_cmd::cargo::cargo_bin("mvpcc"))
        .args(train(&run, 8, &quiet).get_args())
        .arg("--resume");
    let output = limited.output().unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(!output.status.success(), "{stderr}");
    let last = stderr.lines().last().unwrap_or_default();
    assert!(
        last.starts_with("error: ") && last.contains("checkpoints") && last.contains("too large"),
        "{stderr}"
    );
    let latest = std::fs::read_to_string(run.join("checkpoints/latest")).unwrap();
    assert_eq!(latest.trim(), "step-00000004");
    train(&run, 8, &quiet)
        .arg("--resume")
        .assert()
        .success()
        .stderr(predicate::str::contains("stopped at step 8"));
}

#[ignore = "needs ../shared/reference"]
#[test]
fn the_reference_bus_trains_without_a_validation_split() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/reference/views");
    assert!(root.is_dir(), "{} is absent", root.display());
    let dir = tempfile::tempdir().unwrap();
    mvpcc()
        .args([
            "train",
            "--data",
            s(&root),
            "--out",
            s(dir.path()),
            "--config",
            "tiny",
        ])
        .args(["--batch", "1", "--steps", "2"])
        .assert()
        .success()
        .stderr(
            predicate::str::contains("1 samples for training, 0 held back")
                .and(predicate::str::contains("no validation samples")),
        );
    assert!(dir.path().join("generator.safetensors").is_file());
}

#[test]
fn vgg19_weights_feed_the_feature_losses_and_bad_ones_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let weights = dir.path().join("vgg19.safetensors");
    let vgg = mvpcc::model::vgg::Vgg19::new(&Device::flex());
    std::fs::write(&weights, vgg.to_safetensors().unwrap()).unwrap();
    let run = dir.path().join("run");
    train(&run, 2, &["--vgg19", s(&weights), "--val-every", "0"])
        .assert()
        .success()
        .stderr(predicate::str::contains("VGG19 features from"));
    let saved = std::fs::read_to_string(run.join("train.json")).unwrap();
    assert!(saved.contains("vgg19.safetensors"));

    let bad = dir.path().join("bad.safetensors");
    std::fs::write(&bad, b"nothing").unwrap();
    train(&dir.path().join("other"), 2, &["--vgg19", s(&bad)])
        .assert()
        .failure()
        .stderr(
            predicate::str::is_match(r"(?m)^error: .*bad\.safetensors: not usable as VGG19")
                .unwrap(),
        );
}

/// A queue of 10⁹ steps aborted the process on its allocation, and 10⁸ workers spent minutes
/// spawning threads: both are refused before anything is read or written.
#[test]
fn loader_threads_and_queue_are_bounded() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    for (option, value, range) in [
        ("--prefetch", "1000000000", "0..=256"),
        ("--workers", "100000000", "1..=256"),
        ("--workers", "0", "1..=256"),
    ] {
        mvpcc()
            .args(["train", "--data", "no-such-data", "--out", s(&run)])
            .args([option, value])
            .assert()
            .code(2)
            .stderr(predicate::str::contains(format!(
                "{value} is not in {range}"
            )));
        assert!(!run.exists());
    }
}

/// The losses of the `train` records of a run's log, in order.
fn logged_losses(run: &Path) -> Vec<f64> {
    let log = std::fs::read_to_string(run.join("log.jsonl")).unwrap();
    log.lines()
        .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap())
        .filter(|r| r["kind"] == "train")
        .flat_map(|r| {
            let losses = r["losses"].as_object().unwrap().clone();
            losses.into_values().map(|v| v.as_f64().unwrap())
        })
        .collect()
}

#[test]
fn two_cpu_replicas_train_as_one_device_does_on_the_whole_batch() {
    let dir = tempfile::tempdir().unwrap();
    let (one, two) = (dir.path().join("one"), dir.path().join("two"));
    train(&one, 4, &[]).assert().success();
    train(&two, 4, &["--devices", "cpu,cpu"])
        .assert()
        .success()
        .stderr(predicate::str::contains("on 2 replicas, the first on CPU"));
    let (a, b) = (logged_losses(&one), logged_losses(&two));
    assert!(a.len() >= 16 && a.len() == b.len(), "{a:?} {b:?}");
    for (x, y) in a.iter().zip(&b) {
        assert!(
            (x - y).abs() <= 1e-4 * x.abs().max(1.0),
            "losses {a:?} vs {b:?}"
        );
    }
    let difference = max_difference(&output_of(&one), &output_of(&two));
    assert!(difference < 1e-3, "outputs differ by {difference}");
}

#[test]
fn device_lists_that_cannot_work_are_refused_before_any_work() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    for (list, batch, problem) in [
        ("cpu,cuda:0", "2", "mixes the CPU and GPUs"),
        ("cuda:1,cuda:1", "2", "cuda:1 is listed twice"),
        ("cpu,cpu,cpu", "2", "3 replicas need --batch 3 or more"),
        ("cpu;cpu", "2", "`cpu;cpu` is not a device"),
    ] {
        refused_saying(
            &mut train(&run, 1, &["--devices", list, "--batch", batch]),
            problem,
        );
        assert!(!run.exists(), "{list} left a run directory");
    }
}

/// Debug builds only: a release build has no way to make a replica fail on purpose.
#[cfg(debug_assertions)]
#[test]
fn a_replica_that_fails_stops_the_run_at_a_checkpoint_it_resumes_from() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    let failed = train(&run, 3, &["--devices", "cpu,cpu"])
        .env("MVPCC_FAIL_REPLICA", "1")
        .assert()
        .failure();
    let stderr = String::from_utf8_lossy(&failed.get_output().stderr).into_owned();
    let errors: Vec<&str> = stderr.lines().filter(|l| l.starts_with("error")).collect();
    let checkpoint = run.join("checkpoints/step-00000000");
    let said = |line: &str| {
        line.starts_with(
            "error: replica 1 failed: failure injected by MVPCC_FAIL_REPLICA (on CPU (flex, ",
        ) && line.ends_with(&format!(
            "threads)) in step 1; stopped with a checkpoint of step 0, {}: continue with --resume",
            checkpoint.display()
        ))
    };
    assert!(errors.len() == 1 && said(errors[0]), "{stderr}");
    assert!(run.join("checkpoints/step-00000000").is_dir());
    train(&run, 3, &["--devices", "cpu,cpu"])
        .arg("--resume")
        .assert()
        .success()
        .stderr(predicate::str::contains("stopped at step 3"));
}
