//! `mvpcc profile`: times the generator's forward pass, or with `--train` whole GAN training
//! steps, on random input and breaks the time down by layer kind or step phase, so a user can
//! pick a model shape and device, and anyone can reproduce the speed figures in the README and
//! docs/gpu.md.

use super::{model_shape, Log, BUILTIN};
use crate::cli::args::ProfileArgs;
use crate::cli::streams::say;
use anyhow::Context;
use burn::tensor::{Device, Distribution, Tensor};
use mvpcc::model::gan::{Batch, Gan, GanOptimConfig, StepClock, StepPhase};
use mvpcc::model::loss::LossWeights;
use mvpcc::model::{LayerKind, ModelConfig, Probe, MAX_BATCH};
use serde::Serialize;
use std::collections::BTreeMap;
use std::time::{Duration, Instant};

/// What `--json` prints.
#[derive(Debug, Serialize)]
struct Report {
    config: ModelConfig,
    device: String,
    /// `forward` or `train_step`.
    measured: &'static str,
    batch: usize,
    runs: usize,
    warmup: usize,
    /// Generator forward GFLOP for the batch.
    gflop: f64,
    median_ms: f64,
    all_ms: Vec<f64>,
    /// Layer kinds (forward) or step phases (`--train`, in the order they run), each timed
    /// with a device sync after it.
    breakdown: Vec<Part>,
}

#[derive(Debug, Serialize)]
struct Part {
    name: &'static str,
    ms: f64,
}

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
    let name = args.config.as_deref().unwrap_or(BUILTIN);
    let config = overridden(model_shape(name)?, &args);
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
    let mut report = if args.train {
        train_steps(&args, &config, opened.device)?
    } else {
        forwards(&args, &config, opened.device)?
    };
    report.device = opened.description;
    print(&report, args.json)
}

fn forwards(args: &ProfileArgs, config: &ModelConfig, device: Device) -> anyhow::Result<Report> {
    let generator = config.init_generator(&device)?;
    let shape = [
        args.batch,
        config.views,
        config.input_channels(),
        config.size,
        config.size,
    ];
    let input = Tensor::<5>::random(shape, Distribution::Default, &device);
    let forward = |probe: &mut Booked<LayerKind>| -> anyhow::Result<Duration> {
        let start = Instant::now();
        let out = generator.forward_probed(input.clone(), probe);
        // Reading one value back waits for every queued kernel on any backend.
        let _ = out.occupancy.sum().into_data();
        device.sync().context("device")?;
        Ok(start.elapsed())
    };
    measure(args, config, "forward", &device, forward)
}

fn train_steps(args: &ProfileArgs, config: &ModelConfig, device: Device) -> anyhow::Result<Report> {
    let device = device.autodiff();
    let gan = Gan::new(
        config.clone(),
        LossWeights::new(),
        GanOptimConfig::new(),
        &device,
    )?;
    let micro = [Batch::random(config, args.batch, &device)];
    let mut gan = Some(gan);
    let step = |clock: &mut Booked<StepPhase>| -> anyhow::Result<Duration> {
        let start = Instant::now();
        let (next, losses) = gan
            .take()
            .expect("the networks come back from each step")
            .step_clocked(&micro, 1e-4, clock);
        gan = Some(next);
        // The losses are read back as numbers inside the step: it has finished on the device.
        device.sync().context("device")?;
        anyhow::ensure!(
            losses.first_non_finite().is_none(),
            "a loss is not finite: {losses:?}"
        );
        Ok(start.elapsed())
    };
    measure(args, config, "train_step", &device, step)
}

/// Warm-up, `runs` timed runs without syncs inside, then `runs` more booking each part.
fn measure<K: Ord + Copy + Named>(
    args: &ProfileArgs,
    config: &ModelConfig,
    measured: &'static str,
    device: &Device,
    mut run: impl FnMut(&mut Booked<K>) -> anyhow::Result<Duration>,
) -> anyhow::Result<Report> {
    for _ in 0..args.warmup {
        run(&mut Booked::off(device))?;
    }
    let mut totals = Vec::with_capacity(args.runs);
    for _ in 0..args.runs {
        totals.push(run(&mut Booked::off(device))?);
    }
    let mut parts = Booked::on(device);
    for _ in 0..args.runs {
        device.sync().context("device")?;
        parts.last = Instant::now();
        run(&mut parts)?;
    }
    let ms = |t: Duration| t.as_secs_f64() * 1e3;
    Ok(Report {
        config: config.clone(),
        device: String::new(),
        measured,
        batch: args.batch,
        runs: args.runs,
        warmup: args.warmup,
        gflop: config.generator_gflop() * args.batch as f64,
        median_ms: ms(median(&mut totals.clone())),
        all_ms: totals.into_iter().map(ms).collect(),
        breakdown: parts
            .spent
            .iter()
            .map(|(k, &t)| Part {
                name: k.name(),
                ms: ms(t) / args.runs as f64,
            })
            .collect(),
    })
}

fn print(report: &Report, json: bool) -> anyhow::Result<()> {
    if json {
        say(serde_json::to_string_pretty(report)?)?;
        return Ok(());
    }
    let part = if report.measured == "forward" {
        "layer kind"
    } else {
        "step phase"
    };
    let summed: f64 = report.breakdown.iter().map(|p| p.ms).sum();
    say(format_args!("{part:<30} {:>10} {:>7}", "ms", "share"))?;
    for Part { name, ms } in &report.breakdown {
        say(format_args!(
            "{name:<30} {ms:>10.1} {:>6.1}%",
            100.0 * ms / summed.max(f64::MIN_POSITIVE)
        ))?;
    }
    say(format_args!(
        "{:<30} {summed:>10.1}  (part by part, with a device sync after each)",
        "sum"
    ))?;
    if report.measured == "forward" {
        say(format_args!(
            "{:.1} GFLOP per forward, {:.1} GFLOP/s",
            report.gflop,
            report.gflop / (report.median_ms / 1e3)
        ))?;
    }
    say(format_args!(
        "{}_ms_median={:.1}",
        report.measured, report.median_ms
    ))
}

fn median(times: &mut [Duration]) -> Duration {
    times.sort();
    let n = times.len();
    if n % 2 == 1 {
        times[n / 2]
    } else {
        (times[n / 2 - 1] + times[n / 2]) / 2
    }
}

trait Named {
    fn name(self) -> &'static str;
}

impl Named for LayerKind {
    fn name(self) -> &'static str {
        LayerKind::name(self)
    }
}

impl Named for StepPhase {
    fn name(self) -> &'static str {
        StepPhase::name(self)
    }
}

/// Books the time of each part (layer kind or step phase) since the previous one; switched off
/// it only passes calls through.
struct Booked<K> {
    device: Device,
    enabled: bool,
    last: Instant,
    spent: BTreeMap<K, Duration>,
}

impl<K: Ord> Booked<K> {
    fn on(device: &Device) -> Booked<K> {
        Booked {
            device: device.clone(),
            enabled: true,
            last: Instant::now(),
            spent: BTreeMap::new(),
        }
    }

    fn off(device: &Device) -> Booked<K> {
        Booked {
            enabled: false,
            ..Booked::on(device)
        }
    }

    /// Waits for the device, then books the time since the last mark under `part`.
    fn book(&mut self, part: K) {
        // A failed sync only loses this part's timing; the run's own sync reports it.
        let _ = self.device.sync();
        let now = Instant::now();
        *self.spent.entry(part).or_default() += now - self.last;
        self.last = now;
    }
}

impl Probe for Booked<LayerKind> {
    fn layer<const D: usize>(
        &mut self,
        kind: LayerKind,
        run: impl FnOnce() -> Tensor<D>,
    ) -> Tensor<D> {
        if !self.enabled {
            return run();
        }
        let _ = self.device.sync();
        self.last = Instant::now();
        let out = run();
        self.book(kind);
        out
    }
}

impl StepClock for Booked<StepPhase> {
    fn done(&mut self, phase: StepPhase) {
        if self.enabled {
            self.book(phase);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn median_of_odd_and_even_counts() {
        let ms = Duration::from_millis;
        assert_eq!(median(&mut [ms(5), ms(1), ms(3)]), ms(3));
        assert_eq!(
            median(&mut [ms(4), ms(1), ms(2), ms(3)]),
            Duration::from_micros(2500)
        );
    }
}
