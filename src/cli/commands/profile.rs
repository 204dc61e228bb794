//! `mvpcc profile`: the model shape the options name, timed by the library (`app::profile`),
//! printed as a table or JSON.

use super::Log;
use crate::cli::args::ProfileArgs;
use crate::cli::streams::say;
use anyhow::Context;
use mvpcc::app::profile::Profile;
use mvpcc::app::table::{export, Export};
use mvpcc::complete::{named_shape, BUILTIN_SHAPE};
use mvpcc::model::{ModelConfig, MAX_BATCH};

/// `config` with the fields the options set.
fn overridden(config: ModelConfig, args: &ProfileArgs) -> ModelConfig {
    ModelConfig {
        size: args.size.unwrap_or(config.size),
        width: args.width.unwrap_or(config.width),
        res_blocks: args.res_blocks.unwrap_or(config.res_blocks),
        views: args.views.unwrap_or(config.views),
        channels: args.channels.unwrap_or(config.channels),
        padding: args.padding.unwrap_or(config.padding),
        ..config
    }
}

pub fn run(args: ProfileArgs, log: Log) -> anyhow::Result<()> {
    let name = args.config.as_deref().unwrap_or(BUILTIN_SHAPE);
    let config = overridden(named_shape(name)?, &args);
    config.validate().context("model config")?;
    anyhow::ensure!(args.runs > 0, "--runs must be at least 1");
    anyhow::ensure!(args.batch > 0, "--batch must be at least 1");
    anyhow::ensure!(
        args.batch <= MAX_BATCH,
        "--batch {} is above the largest this build accepts ({MAX_BATCH})",
        args.batch
    );
    let opened = super::open_device(args.device, log)?;
    args.layers.set();
    log.info(format!(
        "profiling {} of {} on {}: {}, batch {}, {} layers",
        if args.train {
            "training steps"
        } else {
            "the forward"
        },
        match &args.config {
            None => "the built-in model".to_string(),
            Some(name) => format!("--config {name}"),
        },
        opened.description,
        config.describe(),
        args.batch,
        format!("{:?}", args.layers).to_lowercase(),
    ));
    let profile = Profile {
        train: args.train,
        batch: args.batch,
        runs: args.runs,
        warmup: args.warmup,
    };
    let mut report = profile.run(&config, opened.device)?;
    report.device = opened.description;
    let how = if args.json {
        Export::Json
    } else {
        Export::Table
    };
    for line in export(&report, how)? {
        say(line)?;
    }
    Ok(())
}
