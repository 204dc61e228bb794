//! `mvpcc profile`: times the generator's forward pass on random input and breaks it down by
//! layer kind, so a user can pick a model shape and device, and anyone can reproduce the
//! speed figures in the README.

use super::Log;
use crate::cli::ProfileArgs;
use crate::device::open;
use crate::model::{LayerKind, ModelConfig, Probe};
use anyhow::Context;
use burn::tensor::{Device, Distribution, Tensor};
use std::collections::BTreeMap;
use std::time::{Duration, Instant};

pub fn run(args: ProfileArgs, log: Log) -> anyhow::Result<()> {
    let config = args.model_config();
    config.validate().context("model config")?;
    anyhow::ensure!(args.runs > 0, "--runs must be at least 1");
    anyhow::ensure!(args.batch > 0, "--batch must be at least 1");
    let opened = open(args.device);
    if let Some(why) = &opened.fallback {
        log.warn(why);
    }
    let device = opened.device;
    log.info(format!(
        "profiling {:?} on {}: {}",
        args.config,
        opened.description,
        describe(&config)
    ));
    let generator = config.init_generator(&device)?;
    let shape = [
        args.batch,
        config.views,
        config.input_channels(),
        config.size,
        config.size,
    ];
    let input = Tensor::<5>::random(shape, Distribution::Default, &device);
    let forward = |probe: &mut TimingProbe| -> anyhow::Result<Duration> {
        let start = Instant::now();
        let out = generator.forward_probed(input.clone(), probe);
        // Reading one value back waits for every queued kernel on any backend.
        let _ = out.occupancy.sum().into_data();
        device.sync().context("device")?;
        Ok(start.elapsed())
    };

    forward(&mut TimingProbe::off(&device))?;
    let mut totals = Vec::with_capacity(args.runs);
    for _ in 0..args.runs {
        totals.push(forward(&mut TimingProbe::off(&device))?);
    }
    let mut by_kind = TimingProbe::on(&device);
    for _ in 0..args.runs {
        forward(&mut by_kind)?;
    }
    let median_ms = median(&mut totals).as_secs_f64() * 1e3;
    let gflop = config.generator_gflop() * args.batch as f64;
    let layers: Vec<(LayerKind, f64)> = by_kind
        .spent
        .iter()
        .map(|(&kind, &t)| (kind, t.as_secs_f64() * 1e3 / args.runs as f64))
        .collect();
    let profiled_ms: f64 = layers.iter().map(|(_, ms)| ms).sum();

    if args.json {
        let json = serde_json::json!({
            "config": serde_json::to_value(&config)?,
            "device": opened.description,
            "batch": args.batch,
            "runs": args.runs,
            "gflop": gflop,
            "forward_ms_median": median_ms,
            "forward_ms_all": totals.iter().map(|t| t.as_secs_f64() * 1e3).collect::<Vec<_>>(),
            "layers_ms": layers.iter().map(|(k, ms)| (k.name(), *ms)).collect::<BTreeMap<_, _>>(),
        });
        println!("{}", serde_json::to_string_pretty(&json)?);
        return Ok(());
    }
    println!("{:<20} {:>10} {:>7}", "layer kind", "ms", "share");
    for (kind, ms) in &layers {
        println!(
            "{:<20} {:>10.1} {:>6.1}%",
            kind.name(),
            ms,
            100.0 * ms / profiled_ms.max(f64::MIN_POSITIVE)
        );
    }
    println!(
        "{:<20} {:>10.1}  (layer by layer, with a device sync after each)",
        "sum", profiled_ms
    );
    println!(
        "{gflop:.1} GFLOP per forward, {:.1} GFLOP/s",
        gflop / (median_ms / 1e3)
    );
    println!("forward_ms_median={median_ms:.1}");
    Ok(())
}

fn describe(config: &ModelConfig) -> String {
    format!(
        "w {} r {} S {} V {} {:?} {:?} padding",
        config.width, config.res_blocks, config.size, config.views, config.channels, config.padding
    )
    .to_lowercase()
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

/// Books the time of each layer under its kind; switched off it only passes calls through.
struct TimingProbe {
    device: Device,
    enabled: bool,
    spent: BTreeMap<LayerKind, Duration>,
}

impl TimingProbe {
    fn on(device: &Device) -> TimingProbe {
        TimingProbe {
            device: device.clone(),
            enabled: true,
            spent: BTreeMap::new(),
        }
    }

    fn off(device: &Device) -> TimingProbe {
        TimingProbe {
            enabled: false,
            ..TimingProbe::on(device)
        }
    }
}

impl Probe for TimingProbe {
    fn layer<const D: usize>(
        &mut self,
        kind: LayerKind,
        run: impl FnOnce() -> Tensor<D>,
    ) -> Tensor<D> {
        if !self.enabled {
            return run();
        }
        let start = Instant::now();
        let out = run();
        // A failed sync only loses this layer's timing; the final read-back reports it.
        let _ = self.device.sync();
        *self.spent.entry(kind).or_default() += start.elapsed();
        out
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
