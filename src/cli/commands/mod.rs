//! One module per subcommand; errors become anyhow here and one `error: …` line in main.

mod complete;
mod eval;
mod filter;
mod prepare;
mod profile;
mod project;
mod reproject;
mod synth;
mod train;
mod train_orient;

use crate::cli::args::{Cli, Command};
use crate::cli::streams::tell;
use anyhow::{bail, Context};
use mvpcc::app::Progress;
use mvpcc::core::cloud::PointCloud;
use mvpcc::io::{non_finite_warning, read_cloud, Format};
use mvpcc::model::device::{open, DeviceChoice, Opened};
use std::fmt::Display;
use std::path::Path;

pub fn run(cli: Cli) -> anyhow::Result<()> {
    crate::cli::interrupt::install().context("cannot install the signal handler")?;
    let log = Log { quiet: cli.quiet };
    match cli.command {
        Command::Complete(args) => complete::run(args, log),
        Command::Eval(args) => eval::run(args, log),
        Command::Project(args) => project::run(args, log),
        Command::Reproject(args) => reproject::run(args, log),
        Command::Filter(args) => filter::run(args, log),
        Command::Profile(args) => profile::run(args, log),
        Command::Prepare(args) => prepare::run(args, log),
        Command::Synth(args) => synth::run(args, log),
        Command::Train(args) => train::run(*args, log),
        Command::TrainOrient(args) => train_orient::run(args, log),
    }
}

/// Messages for a person, on stderr; `--quiet` keeps only warnings.
#[derive(Debug, Clone, Copy)]
pub struct Log {
    quiet: bool,
}

impl Log {
    pub fn info(&self, message: impl Display) {
        if !self.quiet {
            tell(message);
        }
    }

    pub fn warn(&self, message: impl Display) {
        tell(format_args!("warning: {message}"));
    }

    pub fn quiet(&self) -> bool {
        self.quiet
    }
}

/// Opens the device `--device` asks for, warning once when it falls back to the CPU.
pub(crate) fn open_device(choice: DeviceChoice, log: Log) -> anyhow::Result<Opened> {
    let opened = open(choice)?;
    if let Some(why) = &opened.fallback {
        log.warn(why);
    }
    Ok(opened)
}

/// Reads a cloud, warning about points dropped for NaN or infinite coordinates.
pub(crate) fn load(path: &Path, format: Option<Format>, log: Log) -> anyhow::Result<PointCloud> {
    let loaded = read_cloud(path, format)?;
    if let Some(warning) = non_finite_warning(loaded.non_finite_dropped) {
        log.warn(format!("{}: {warning}", path.display()));
    }
    Ok(loaded.cloud)
}

/// A training loop's progress bar over `steps` (0 until the loop knows them) on stderr, with
/// its rate; hidden under `--quiet`.
pub(crate) fn step_bar(steps: u64, log: Log) -> indicatif::ProgressBar {
    let bar = if log.quiet() {
        indicatif::ProgressBar::hidden()
    } else {
        indicatif::ProgressBar::new(steps)
    };
    bar.set_style(
        indicatif::ProgressStyle::with_template(
            "step {pos}/{len} {bar:30} {msg} [{elapsed} < {eta}, {per_sec}]",
        )
        .expect("a valid progress template"),
    );
    bar
}

/// A progress bar with ETA on stderr; hidden under `--quiet` or for a single item.
pub(crate) fn progress(len: usize, label: &str, log: Log) -> indicatif::ProgressBar {
    let bar = if len > 1 && !log.quiet() {
        indicatif::ProgressBar::new(len as u64)
    } else {
        indicatif::ProgressBar::hidden()
    };
    bar.set_style(
        indicatif::ProgressStyle::with_template(&format!(
            "{label} {{bar:40}} {{pos}}/{{len}} {{msg}} [{{elapsed}} < {{eta}}]"
        ))
        .expect("a valid progress template"),
    );
    bar
}

/// A progress bar on stderr for the library's long services, made when they say how many
/// items there are; hidden under `--quiet` or for a single item.
pub(crate) struct Bar {
    log: Log,
    bar: std::sync::OnceLock<indicatif::ProgressBar>,
}

impl Bar {
    pub(crate) fn new(log: Log) -> Bar {
        Bar {
            log,
            bar: std::sync::OnceLock::new(),
        }
    }
}

impl Progress for Bar {
    fn start(&self, total: usize, label: &str) {
        let _already = self.bar.set(progress(total, label, self.log));
    }

    fn done(&self, item: &str) {
        if let Some(bar) = self.bar.get() {
            bar.set_message(item.to_string());
            bar.inc(1);
        }
    }

    fn finish(&self) {
        if let Some(bar) = self.bar.get() {
            bar.finish_and_clear();
        }
    }

    fn warn(&self, message: &str) {
        match self.bar.get() {
            Some(bar) => bar.suspend(|| self.log.warn(message)),
            None => self.log.warn(message),
        }
    }

    fn note(&self, message: &str) {
        match self.bar.get() {
            Some(bar) => bar.suspend(|| self.log.info(message)),
            None => self.log.info(message),
        }
    }
}

/// Refuses an output folder whose name a file already holds, before any work is done.
pub(crate) fn check_out_dir(dir: &Path) -> anyhow::Result<()> {
    if dir.exists() && !dir.is_dir() {
        bail!("{}: exists and is not a directory", dir.display());
    }
    Ok(())
}
