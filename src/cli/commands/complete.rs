//! `complete`: loads the networks, turns the options into the pipeline's settings, and runs
//! the library's file or batch step, saying what happened.

use super::{Bar, Log};
use crate::cli::args::CompleteArgs;
use crate::cli::count;
use crate::cli::streams::{say, tell};
use anyhow::bail;
use mvpcc::app::complete::{
    complete_file, Batch, BatchEntry, FileOptions, FileReport, Job, SceneJob,
};
use mvpcc::complete::orient::OrientMode;
use mvpcc::complete::{Completer, Method, Options, Settings, Source, Tuning};
use mvpcc::core::frame::UpAxis;
use mvpcc::io::default_up;
use mvpcc::scene::stream::StreamParams;
use mvpcc::scene::{SceneParams, Selection};
use std::path::{Path, PathBuf};

pub(super) fn run(args: Box<CompleteArgs>, log: Log) -> anyhow::Result<()> {
    let tuning = match &args.tuning {
        Some(path) => Tuning::read(path)?,
        None => Tuning::default(),
    };
    if args.print_tuning {
        return say(serde_json::to_string_pretty(&tuning)?);
    }
    let generator = match (args.method, &args.model) {
        (Method::Identity | Method::Mirror, _) => Source::Unused,
        (Method::Network, Some(path)) => Source::File(path),
        (Method::Network, None) => Source::Builtin,
    };
    let orienter = match (orient_mode(&args).needs_network(), &args.orienter) {
        (false, _) => Source::Unused,
        (true, Some(path)) => Source::File(path),
        (true, None) => Source::Builtin,
    };
    let device = match generator {
        Source::Unused => burn::tensor::Device::flex(),
        _ => super::open_device(args.device, log)?.device,
    };
    let completer = Completer::load(generator, orienter, device, args.occupancy)?;
    let settings = |input: &Path| settings(&args, input, tuning);
    let job = Job {
        completer: &completer,
        settings: &settings,
        files: FileOptions {
            input_format: args.input_options.format,
            out_format: args.output_options.out_format,
            encoding: args.output_options.encoding,
            preview: args.preview.clone(),
            report_on_stdout: args.json,
        },
        scene: args.scene.then(|| SceneJob {
            selection: match &args.vehicle_class {
                Some(codes) => Selection::Classes(codes.clone()),
                None => Selection::Detect,
            },
            params: SceneParams::default(),
            stream: StreamParams {
                from_points: args.stream_from,
                chunk: args.chunk,
                ..StreamParams::default()
            },
        }),
    };
    match (&args.input, &args.output, &args.input_dir, &args.output_dir) {
        (Some(input), Some(output), _, _) => {
            let report = complete_file(input, output, args.save_views.as_deref(), &job)?;
            tell_file(&report, args.timings && !args.json, log);
            if args.json {
                say(serde_json::to_string_pretty(&report)?)?;
            }
            Ok(())
        }
        (None, None, _, Some(output_dir)) => batch(&args, output_dir, &job, log),
        _ => bail!("give IN and OUT, or --input-dir (or --list) and --output-dir"),
    }
}

/// What one completed file says on stderr: what cleaning removed, its warnings, its summary
/// line and, with `--timings`, each stage's time.
fn tell_file(report: &FileReport, timings: bool, log: Log) {
    let input = report.input.display();
    if let Some(c) = &report.cleaned {
        log.info(format!(
            "{input}: --clean removed {} ground, {} isolated and {} other-object points",
            c.ground, c.isolated, c.other_objects
        ));
    }
    for w in &report.warnings {
        log.warn(format!("{input}: {w}"));
    }
    log.info(report.summary());
    if timings {
        for (name, d) in report.timings.stages() {
            tell(format_args!("{name:>14} {:9.1} ms", d.as_secs_f64() * 1e3));
        }
    }
}

fn batch(args: &CompleteArgs, output_dir: &Path, job: &Job, log: Log) -> anyhow::Result<()> {
    let batch = Batch {
        root: args.input_dir.clone().unwrap_or_else(|| PathBuf::from(".")),
        output_dir: output_dir.to_path_buf(),
        list: args.list.clone(),
        include: args.include.clone(),
        shard: args.shard,
        skip_existing: args.skip_existing,
        save_views: args.save_views.clone(),
        jobs: args.jobs,
    };
    let report = batch.run(job, &Bar::new(log))?;
    for w in report.grouped_warnings() {
        log.warn(w);
    }
    for entry in &report.results {
        if let BatchEntry::Failed { error, .. } = entry {
            tell(format_args!("failed: {error}"));
        }
    }
    log.info(format!(
        "{} of {} completed into {}{}, {} skipped, {} failed",
        report.completed,
        count(report.files, "file"),
        output_dir.display(),
        report
            .shard
            .as_ref()
            .map_or(String::new(), |s| format!(" (shard {s})")),
        report.skipped,
        report.failed
    ));
    if args.json {
        say(serde_json::to_string_pretty(&report)?)?;
    }
    if report.failed > 0 {
        bail!(
            "{} of {} failed",
            report.failed,
            count(report.files, "file")
        );
    }
    Ok(())
}

/// `--orient` (auto by default, none with `--paper`), except for the identity method, whose
/// output does not depend on the frame.
fn orient_mode(args: &CompleteArgs) -> OrientMode {
    let default = if args.paper {
        OrientMode::None
    } else {
        OrientMode::Auto
    };
    match args.method {
        Method::Identity => OrientMode::None,
        Method::Mirror | Method::Network => args.orient.unwrap_or(default),
    }
}

fn up_axis(args: &CompleteArgs, input: &Path) -> UpAxis {
    args.up
        .unwrap_or_else(|| default_up(input, args.input_options.format))
}

/// What the options ask of the pipeline for `input`.
fn settings(args: &CompleteArgs, input: &Path, tuning: Tuning) -> Settings {
    Settings {
        clean: args.clean,
        orient: orient_mode(args),
        options: options(args, input, tuning),
    }
}

fn options(args: &CompleteArgs, input: &Path, tuning: Tuning) -> Options {
    let up = up_axis(args, input);
    let sor = args.sor.params();
    if args.paper {
        return Options {
            views: args.views.0.clone(),
            erode: args.erode,
            sor,
            keep_views: args.save_views.is_some(),
            ..Options::paper(up, None)
        };
    }
    Options {
        method: args.method,
        up,
        heading: None,
        roll: args.roll.unwrap_or(Options::default().roll),
        views: args.views.0.clone(),
        erode: args.erode,
        smooth: args.smooth,
        dedup: Options::default().dedup,
        snap: !args.no_snap,
        sor,
        keep_input: !args.no_keep_input,
        merge_distance: args.merge_distance,
        near_distance: args.near_distance,
        near_occupancy: args.near_occupancy,
        box_margin: args.box_margin,
        thin: args.thin,
        symmetry: !args.no_symmetry,
        mirror_pass: !args.no_mirror_pass,
        symmetric_frame: true,
        keep_views: args.save_views.is_some(),
        vehicle_width: args.vehicle_width,
        // Known only in a scene, from each vehicle's size in metres (`--scene`).
        min_vehicle_width: None,
        tuning,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cli::args::{Cli, Command};
    use clap::Parser;

    #[test]
    fn the_library_defaults_are_the_commands() {
        let cli = Cli::try_parse_from(["mvpcc", "complete", "in.ply", "out.ply"]).unwrap();
        let Command::Complete(args) = cli.command else {
            panic!("parsed as another command");
        };
        let options = options(&args, Path::new("in.ply"), Tuning::default());
        assert_eq!(options, Options::default());
    }
}
