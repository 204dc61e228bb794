//! Timing the generator's forward pass, or whole GAN training steps, on random input, broken
//! down by layer kind or step phase with a device sync after each: how a user picks a model
//! shape and device, and how the speed figures are reproduced.

use super::table::{Report, Table};
use crate::model::gan::{Batch, Gan, GanOptimConfig, StepClock, StepPhase};
use crate::model::loss::LossWeights;
use crate::model::{ConfigError, LayerKind, ModelConfig, Probe};
use burn::tensor::{Device, Distribution, ExecutionError, Tensor};
use serde::Serialize;
use std::collections::BTreeMap;
use std::time::{Duration, Instant};
use thiserror::Error;

#[derive(Debug, Error)]
pub enum ProfileError {
    #[error(transparent)]
    Config(#[from] ConfigError),
    #[error("device: {0}")]
    Device(#[from] ExecutionError),
    #[error("a loss is not finite: {0}")]
    NonFinite(String),
}

/// What is timed and how often.
#[derive(Debug, Clone, Copy)]
pub struct Profile {
    /// Whole training steps instead of the forward pass.
    pub train: bool,
    pub batch: usize,
    /// Timed runs (and as many again, booked part by part).
    pub runs: usize,
    /// Untimed runs first.
    pub warmup: usize,
}

impl Profile {
    /// Times `config` on `device`.
    pub fn run(&self, config: &ModelConfig, device: Device) -> Result<ProfileReport, ProfileError> {
        if self.train {
            train_steps(self, config, device)
        } else {
            forwards(self, config, device)
        }
    }
}

/// The timings, as `profile --json` prints them.
#[derive(Debug, Serialize)]
pub struct ProfileReport {
    pub config: ModelConfig,
    pub device: String,
    /// `forward` or `train_step`.
    pub measured: &'static str,
    pub batch: usize,
    pub runs: usize,
    pub warmup: usize,
    /// Generator forward GFLOP for the batch.
    pub gflop: f64,
    pub median_ms: f64,
    pub all_ms: Vec<f64>,
    /// Layer kinds (forward) or step phases (`--train`, in the order they run), each timed
    /// with a device sync after it.
    pub breakdown: Vec<Part>,
}

#[derive(Debug, Serialize)]
pub struct Part {
    pub name: &'static str,
    pub ms: f64,
}

impl Report for ProfileReport {
    fn table(&self) -> Table {
        let part = if self.measured == "forward" {
            "layer kind"
        } else {
            "step phase"
        };
        let summed: f64 = self.breakdown.iter().map(|p| p.ms).sum();
        let mut lines = vec![format!("{part:<30} {:>10} {:>7}", "ms", "share")];
        for Part { name, ms } in &self.breakdown {
            let share = 100.0 * ms / summed.max(f64::MIN_POSITIVE);
            lines.push(format!("{name:<30} {ms:>10.1} {share:>6.1}%"));
        }
        lines.push(format!(
            "{:<30} {summed:>10.1}  (part by part, with a device sync after each)",
            "sum"
        ));
        if self.measured == "forward" {
            lines.push(format!(
                "{:.1} GFLOP per forward, {:.1} GFLOP/s",
                self.gflop,
                self.gflop / (self.median_ms / 1e3)
            ));
        }
        lines.push(format!("{}_ms_median={:.1}", self.measured, self.median_ms));
        Table { lines }
    }
}

fn forwards(
    run: &Profile,
    config: &ModelConfig,
    device: Device,
) -> Result<ProfileReport, ProfileError> {
    let generator = config.init_generator(&device)?;
    let shape = [
        run.batch,
        config.views,
        config.input_channels(),
        config.size,
        config.size,
    ];
    let input = Tensor::<5>::random(shape, Distribution::Default, &device);
    let forward = |probe: &mut Booked<LayerKind>| -> Result<Duration, ProfileError> {
        let start = Instant::now();
        let out = generator.forward_probed(input.clone(), probe);
        // Reading one value back waits for every queued kernel on any backend.
        let _ = out.occupancy.sum().into_data();
        device.sync()?;
        Ok(start.elapsed())
    };
    measure(run, config, "forward", &device, forward)
}

fn train_steps(
    run: &Profile,
    config: &ModelConfig,
    device: Device,
) -> Result<ProfileReport, ProfileError> {
    let device = device.autodiff();
    let gan = Gan::new(
        config.clone(),
        LossWeights::new(),
        GanOptimConfig::new(),
        &device,
    )?;
    let micro = [Batch::random(config, run.batch, &device)];
    let mut gan = Some(gan);
    let step = |clock: &mut Booked<StepPhase>| -> Result<Duration, ProfileError> {
        let start = Instant::now();
        let (next, losses) = gan
            .take()
            .expect("the networks come back from each step")
            .step_clocked(&micro, 1e-4, clock);
        gan = Some(next);
        // The losses are read back as numbers inside the step: it has finished on the device.
        device.sync()?;
        if losses.first_non_finite().is_some() {
            return Err(ProfileError::NonFinite(format!("{losses:?}")));
        }
        Ok(start.elapsed())
    };
    measure(run, config, "train_step", &device, step)
}

/// Warm-up, `runs` timed runs without syncs inside, then `runs` more booking each part.
fn measure<K: Ord + Copy + Named>(
    settings: &Profile,
    config: &ModelConfig,
    measured: &'static str,
    device: &Device,
    mut run: impl FnMut(&mut Booked<K>) -> Result<Duration, ProfileError>,
) -> Result<ProfileReport, ProfileError> {
    for _ in 0..settings.warmup {
        run(&mut Booked::off(device))?;
    }
    let mut totals = Vec::with_capacity(settings.runs);
    for _ in 0..settings.runs {
        totals.push(run(&mut Booked::off(device))?);
    }
    let mut parts = Booked::on(device);
    for _ in 0..settings.runs {
        device.sync()?;
        parts.last = Instant::now();
        run(&mut parts)?;
    }
    let ms = |t: Duration| t.as_secs_f64() * 1e3;
    Ok(ProfileReport {
        config: config.clone(),
        device: String::new(),
        measured,
        batch: settings.batch,
        runs: settings.runs,
        warmup: settings.warmup,
        gflop: config.generator_gflop() * settings.batch as f64,
        median_ms: ms(median(&mut totals.clone())),
        all_ms: totals.into_iter().map(ms).collect(),
        breakdown: parts
            .spent
            .iter()
            .map(|(k, &t)| Part {
                name: k.name(),
                ms: ms(t) / settings.runs as f64,
            })
            .collect(),
    })
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
