//! `eval`: checks the options, runs the library's scoring and prints its report.

use super::{Bar, Log};
use crate::cli::args::EvalArgs;
use crate::cli::streams::say;
use anyhow::bail;
use mvpcc::app::eval::{eval_dataset, matched_pairs, CloudEval, EvalReport, Metric, Pair};
use mvpcc::app::table::{export, Export, Report};

pub(super) fn run(args: EvalArgs, log: Log) -> anyhow::Result<()> {
    let how = if args.json {
        Export::Json
    } else {
        Export::Table
    };
    if let (Some(data), Some(pred_dir)) = (&args.data, &args.pred_dir) {
        let bar = Bar::new(log);
        let (metrics, tau) = (&args.metrics, &args.tau);
        let report = eval_dataset(data, pred_dir, args.ground_truth, metrics, tau, &bar)?;
        for w in &report.warnings {
            log.warn(w);
        }
        return print(&report, how);
    }
    let (geometry, color) = check(&args)?;
    let settings = CloudEval {
        metrics: args.metrics.clone(),
        tau: args.tau.clone(),
        normalize: args.normalize,
        format: args.input.format,
    };
    let mut report = EvalReport::new(&settings);
    if geometry {
        let pairs = match (&args.pred, &args.gt, &args.pred_dir, &args.gt_dir) {
            (Some(pred), Some(gt), _, _) => vec![Pair::of_files(pred, gt)?],
            (_, _, Some(pd), Some(gd)) => matched_pairs(pd, gd, args.input.format)?,
            _ => unreachable!("checked: clouds were given"),
        };
        report.score_pairs(pairs, &settings, &Bar::new(log))?;
    }
    if color {
        let (Some(pred), Some(gt)) = (&args.pred_views, &args.gt_views) else {
            unreachable!("checked: clap requires both");
        };
        report.score_views(pred, gt)?;
    }
    for w in &report.warnings {
        log.warn(w);
    }
    print(&report, how)
}

fn print(report: &impl Report, how: Export) -> anyhow::Result<()> {
    for line in export(report, how)? {
        say(line)?;
    }
    Ok(())
}

/// Which kinds of metric the options ask for (geometry, colour), after checking that they
/// name what those need.
fn check(args: &EvalArgs) -> anyhow::Result<(bool, bool)> {
    let geometry = args
        .metrics
        .iter()
        .any(|m| matches!(m, Metric::Cd | Metric::F1));
    let color = args
        .metrics
        .iter()
        .any(|m| matches!(m, Metric::Psnr | Metric::Ssim | Metric::Mae));
    if args.pred_dir.is_some() && args.gt_dir.is_none() {
        bail!("--pred-dir needs --gt-dir or --data");
    }
    let have_clouds = args.pred.is_some() || args.pred_dir.is_some();
    if geometry && !have_clouds {
        bail!("cd and f1 compare clouds: pass --pred and --gt, or --pred-dir and --gt-dir");
    }
    if color && args.pred_views.is_none() {
        bail!("psnr, ssim and mae compare view images: pass --pred-views and --gt-views");
    }
    if let Some(t) = args.tau.iter().find(|t| !(t.is_finite() && **t > 0.0)) {
        bail!("--tau {t}: thresholds must be positive numbers");
    }
    if let Some((_, t)) = args
        .tau
        .iter()
        .enumerate()
        .find(|(i, t)| args.tau[..*i].contains(t))
    {
        bail!("--tau: {t} given twice");
    }
    Ok((geometry, color))
}
