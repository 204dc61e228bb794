//! `prepare`: checks the options, runs the library's preparation and says what it did.

use super::{synth, Bar, Log};
use crate::cli::args::PrepareArgs;
use crate::cli::streams::say;
use anyhow::bail;
use mvpcc::app::prepare::{Meshes, Preparation};
use mvpcc::core::camera::{check_view_set, MAX_IMAGE_SIZE, MIN_IMAGE_SIZE};
use mvpcc::datagen::data::{PrepareParams, ViewsFrame, MAX_SAMPLES};
use mvpcc::datagen::mesh::Forward;
use mvpcc::datagen::scan::{PartialParams, MAX_PARTIAL_POINTS};

pub(super) fn run(args: PrepareArgs, log: Log) -> anyhow::Result<()> {
    let meshes = match (&args.meshes, args.synth) {
        (Some(dir), _) => Meshes::Folder(dir.clone()),
        (None, Some(count)) => Meshes::Synth {
            count,
            draws: args.synth_options.category.clone(),
            seed: args.synth_options.seed,
        },
        (None, None) => unreachable!("clap requires --meshes or --synth"),
    };
    let preparation = Preparation {
        meshes,
        out: args.out.clone(),
        params: params(&args)?,
        shard: args.shard,
    };
    let said = |done: &_| synth::say_generated(done, &args.out.join("meshes"), log);
    let report = preparation.run(&Bar::new(log), &said)?;
    log.info(report.summary());
    if args.json {
        say(serde_json::to_string_pretty(&report)?)?;
    }
    Ok(())
}

/// The settings the options give, checked ([`check`]).
fn params(args: &PrepareArgs) -> anyhow::Result<PrepareParams> {
    check(args)?;
    Ok(PrepareParams {
        views: args.views.0.clone(),
        size: args.size,
        gt_size: args.gt_size,
        gt_voxel: args.gt_voxel,
        samples: args.samples,
        train_fraction: args.split,
        partial: PartialParams {
            kinds: args.partial,
            min_points: args.min_points,
            max_points: args.max_points,
            max_yaw_deg: args.yaw_error,
            max_noise: args.noise,
        },
        up: args.up.to_string(),
        forward: args.forward.to_string(),
        seed: args.synth_options.seed,
        clouds: args.clouds,
        allow_missing_materials: args.allow_missing_materials,
        max_triangles: args.max_triangles,
        views_frame: ViewsFrame::Object,
    })
}

/// Refuses options no data can be made with, before anything is written.
fn check(args: &PrepareArgs) -> anyhow::Result<()> {
    if !(0.0..=1.0).contains(&args.split) {
        bail!("--split must lie in [0, 1], got {}", args.split);
    }
    if !(1..=MAX_SAMPLES).contains(&args.samples) {
        bail!(
            "--samples must lie in 1..={MAX_SAMPLES}, got {}",
            args.samples
        );
    }
    if let Some(count) = args.synth {
        mvpcc::app::synth::check_count(count, "--synth")?;
    }
    if args.size.min(args.gt_size) < MIN_IMAGE_SIZE {
        bail!("--size and --gt-size must be at least {MIN_IMAGE_SIZE} pixels");
    }
    if args.size.max(args.gt_size) > MAX_IMAGE_SIZE {
        bail!("--size and --gt-size must be at most {MAX_IMAGE_SIZE} pixels");
    }
    if args.min_points == 0 || args.min_points > args.max_points {
        bail!(
            "--min-points ({}) must be at least 1 and at most --max-points ({})",
            args.min_points,
            args.max_points
        );
    }
    if args.max_points > MAX_PARTIAL_POINTS {
        bail!(
            "--max-points {} is above the largest partial this build scans ({MAX_PARTIAL_POINTS})",
            args.max_points
        );
    }
    if !(args.gt_voxel >= 0.0 && args.noise >= 0.0 && args.yaw_error >= 0.0) {
        bail!("--gt-voxel, --noise and --yaw-error must not be negative");
    }
    if matches!(args.forward, Forward::Axis(f) if f.axis == args.up.axis) {
        bail!(
            "--up {} and --forward {} must be different axes",
            args.up,
            args.forward
        );
    }
    check_view_set(&args.views.0)?;
    Ok(())
}
