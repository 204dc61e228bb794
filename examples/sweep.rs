//! The lab harness: sweeps one of the pipeline's tunables (`mvpcc complete --print-tuning`
//! lists them) over prepared validation sets and writes a lab record, so that a choice is made
//! on every set together and can be run again — instead of a throwaway build.
//!
//! Each value completes every test partial of each `--data` set as `mvpcc complete` does (with
//! `--method`, the network by default), scores it as `mvpcc eval --data` does (F1@`--tau`,
//! `cd_l2_half`, per category × protocol cell and overall) and writes
//! `lab/<date>-sweep-<name>/record.json` (date, commit, command, the results as data) and
//! `results.csv`. The real scans are measured by `examples/symmetry.rs --mls`.
//!
//! `cargo run --release --example sweep -- --param symmetry.max_width --values 0.5,0.55,0.6
//! --data val8 --data tp30 [--method mirror] [--tau 0.01] [--out lab/NAME] [--jobs N]`
//!
//! Choices are made on the validation sets (docs/quality.md, *The splits*; docs/data.md, *The
//! third-party validation set*); a test split is measured once, for the report.

use burn::tensor::Device;
use mvpcc::app::complete::{Batch, FileOptions, Job};
use mvpcc::app::eval::{eval_dataset, GroundTruth, Metric};
use mvpcc::app::Quiet;
use mvpcc::complete::orient::OrientMode;
use mvpcc::complete::{Completer, Method, Options, Settings, Tuning};
use mvpcc::datagen::data::{Layout, TEST};
use serde::Serialize;
use serde_json::Value;
use std::path::{Path, PathBuf};

type Error = Box<dyn std::error::Error + Send + Sync>;

/// Every value given for `name` on the command line (`--data a --data b`).
fn args_of(name: &str) -> Vec<String> {
    let args: Vec<String> = std::env::args().collect();
    args.windows(2)
        .filter(|w| w[0] == name)
        .map(|w| w[1].clone())
        .collect()
}

fn arg(name: &str) -> Option<String> {
    args_of(name).into_iter().next()
}

/// The default tuning with the tunable at `path` (`symmetry.max_width`) set to `value`.
fn tuned(path: &str, value: f64) -> Result<Tuning, Error> {
    let mut json = serde_json::to_value(Tuning::default())?;
    let slot = json
        .pointer_mut(&format!("/{}", path.replace('.', "/")))
        .ok_or_else(|| format!("--param {path}: no such tunable (see --print-tuning)"))?;
    *slot = if slot.is_u64() {
        Value::from(value as u64)
    } else {
        Value::from(value)
    };
    Ok(serde_json::from_value(json)?)
}

#[derive(Debug, Serialize)]
struct Row {
    value: f64,
    data: String,
    group: String,
    samples: usize,
    f1: Option<f64>,
    cd_l2_half: Option<f64>,
}

/// Completes and scores the test partials of `data` with `tuning`.
fn measure(
    data: &Path,
    value: f64,
    tuning: Tuning,
    method: Method,
    tau: f64,
    completer: &Completer,
) -> Result<Vec<Row>, Error> {
    let out = tempfile::tempdir()?;
    let settings = move |_: &Path| Settings {
        clean: false,
        orient: OrientMode::Auto,
        options: Options {
            method,
            tuning,
            ..Options::default()
        },
    };
    let job = Job {
        completer,
        settings: &settings,
        files: FileOptions::default(),
        scene: None,
    };
    let layout = Layout {
        root: data.to_path_buf(),
    };
    let batch = Batch {
        root: layout.root.join("clouds").join(TEST),
        output_dir: out.path().to_path_buf(),
        list: None,
        include: Some("partial_*".to_string()),
        shard: None,
        skip_existing: false,
        save_views: None,
        jobs: arg("--jobs").map_or(Ok(2), |j| j.parse())?,
    };
    let done = batch.run(&job, &Quiet)?;
    if done.failed > 0 {
        return Err(format!("{}: {} partials failed", data.display(), done.failed).into());
    }
    let metrics = [Metric::Cd, Metric::F1];
    let report = eval_dataset(
        data,
        out.path(),
        GroundTruth::Fine,
        &metrics,
        &[tau],
        &Quiet,
    )?;
    Ok(report
        .groups
        .iter()
        .map(|(group, g)| Row {
            value,
            data: data.display().to_string(),
            group: group.clone(),
            samples: g.samples,
            f1: g.scores.fscore.as_ref().map(|f| f[0].f1),
            cd_l2_half: g.scores.cd_l2_half,
        })
        .collect())
}

fn commit() -> String {
    let out = std::process::Command::new("git")
        .args(["rev-parse", "--short", "HEAD"])
        .output();
    out.ok()
        .filter(|o| o.status.success())
        .map_or("unknown".into(), |o| {
            String::from_utf8_lossy(&o.stdout).trim().to_string()
        })
}

fn today() -> String {
    let out = std::process::Command::new("date")
        .arg("-u")
        .arg("+%F")
        .output();
    out.ok()
        .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
        .filter(|d| !d.is_empty())
        .unwrap_or_else(|| "undated".into())
}

fn main() -> Result<(), Error> {
    let param = arg("--param").ok_or("--param NAME (see mvpcc complete --print-tuning)")?;
    let values: Vec<f64> = arg("--values")
        .ok_or("--values A,B,…")?
        .split(',')
        .map(str::parse)
        .collect::<Result<_, _>>()?;
    let data: Vec<PathBuf> = args_of("--data").into_iter().map(PathBuf::from).collect();
    if data.is_empty() {
        return Err("--data DIR (one or more prepared validation sets)".into());
    }
    let method = match arg("--method").as_deref() {
        None | Some("network") => Method::Network,
        Some("mirror") => Method::Mirror,
        Some(other) => return Err(format!("--method {other}: network or mirror").into()),
    };
    let tau: f64 = arg("--tau").map_or(Ok(0.01), |t| t.parse())?;
    let date = today();
    let out = arg("--out").map_or_else(
        || PathBuf::from(format!("lab/{date}-sweep-{}", param.replace('.', "-"))),
        PathBuf::from,
    );
    let pointer = format!("/{}", param.replace('.', "/"));
    let default = serde_json::to_value(Tuning::default())?
        .pointer(&pointer)
        .cloned();
    let completer = Completer::builtin(Device::flex())?;
    let mut rows = Vec::new();
    for &value in &values {
        let tuning = tuned(&param, value)?;
        for dir in &data {
            let measured = measure(dir, value, tuning, method, tau, &completer)?;
            for r in measured.iter().filter(|r| r.group == "all") {
                eprintln!(
                    "{param} = {value}: {} F1@{tau} {:.4} cd_l2_half {:.4e} ({} partials)",
                    r.data,
                    r.f1.unwrap_or(f64::NAN),
                    r.cd_l2_half.unwrap_or(f64::NAN),
                    r.samples
                );
            }
            rows.extend(measured);
        }
    }
    std::fs::create_dir_all(&out)?;
    let record = serde_json::json!({
        "date": date,
        "commit": commit(),
        "command": std::env::args().collect::<Vec<_>>().join(" "),
        "param": param,
        "default": default,
        "method": format!("{method:?}").to_lowercase(),
        "tau": tau,
        "results": rows,
    });
    std::fs::write(
        out.join("record.json"),
        serde_json::to_string_pretty(&record)?,
    )?;
    let mut csv = String::from("value,data,group,samples,f1,cd_l2_half\n");
    for r in &rows {
        let num = |v: Option<f64>| v.map_or(String::new(), |v| v.to_string());
        csv += &format!(
            "{},{},\"{}\",{},{},{}\n",
            r.value,
            r.data,
            r.group,
            r.samples,
            num(r.f1),
            num(r.cd_l2_half)
        );
    }
    std::fs::write(out.join("results.csv"), csv)?;
    eprintln!("wrote {}", out.display());
    Ok(())
}
