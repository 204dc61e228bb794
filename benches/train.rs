//! Training step time on the CPU (flex) for one object (all views) per step: the generator
//! with smooth L1 and Adam alone (the shape of the PyTorch figures the issue quotes), the
//! full GAN step (discriminator, every loss term, both optimizers) and the GAN step with the
//! reconstruction terms alone, which leaves the discriminator out. Also what the loader
//! spends rendering one step's samples, to check it stays out of the step's way.
//! `MVPCC_BENCH_PAPER=1` adds the paper's shape as the original code builds it (`original`; minutes
//! per sample).

use burn::optim::{AdamConfig, GradientsParams};
use burn::tensor::Device;
use criterion::{criterion_group, criterion_main, Criterion};
use mvpcc::core::camera::{Camera, DEFAULT_VIEWS};
use mvpcc::core::rng::Lcg;
use mvpcc::datagen::shapes::example_car_views;
use mvpcc::model::gan::{Batch, Gan, GanOptimConfig};
use mvpcc::model::loss::{smooth_l1, LossWeights};
use mvpcc::model::Preset;
use mvpcc::train::dataset::{load_sample, AugmentSettings, Cache, SampleRef};
use mvpcc::views::write_views;
use std::time::Duration;

fn presets() -> Vec<Preset> {
    let mut p = vec![Preset::Small, Preset::Cpu];
    if std::env::var_os("MVPCC_BENCH_PAPER").is_some() {
        p.push(Preset::Original);
    }
    p
}

/// The relay legs' losses (`train --loss-adversarial 0 --loss-perceptual 0 --loss-style 0`):
/// no term needs the discriminator, so the step runs the generator alone.
fn reconstruction() -> LossWeights {
    LossWeights::new()
        .with_adversarial(0.0)
        .with_perceptual(0.0)
        .with_style(0.0)
}

fn training_step(c: &mut Criterion) {
    let device = Device::flex().autodiff();
    let mut group = c.benchmark_group("training step (flex, 1 object)");
    group
        .sample_size(10)
        .measurement_time(Duration::from_secs(30));
    for preset in presets() {
        let config = preset.config();
        let name = format!("{preset:?}").to_lowercase();
        let data = Batch::random(&config, 1, &device);

        let mut generator = Some(config.init_generator(&device).unwrap());
        let mut adam = AdamConfig::new().with_beta_1(0.0).with_beta_2(0.9).init();
        group.bench_function(format!("{name}: generator + L1 + Adam"), |b| {
            b.iter(|| {
                let g = generator.take().unwrap();
                let out = g.forward(data.input.clone());
                let loss = smooth_l1(out.images, data.target.images.clone());
                let grads = GradientsParams::from_grads(loss.backward(), &g);
                generator = Some(adam.step(1e-4, g, grads));
            })
        });

        let mut gan = Some(
            Gan::new(
                config.clone(),
                LossWeights::new(),
                GanOptimConfig::new(),
                &device,
            )
            .unwrap(),
        );
        let micro = [data];
        group.bench_function(format!("{name}: full GAN step"), |b| {
            b.iter(|| {
                let (next, losses) = gan.take().unwrap().step(&micro, 1e-4);
                gan = Some(next);
                losses
            })
        });

        let mut relay =
            Some(Gan::new(config, reconstruction(), GanOptimConfig::new(), &device).unwrap());
        group.bench_function(
            format!("{name}: GAN step, reconstruction terms only"),
            |b| {
                b.iter(|| {
                    let (next, losses) = relay.take().unwrap().step(&micro, 1e-4);
                    relay = Some(next);
                    losses
                })
            },
        );
    }
    group.finish();
}

/// Four samples of a car scanned at 256² rendered at the CPU model's 128² with mirror, yaw and
/// colour jitter, as the loader does for one step of `--batch 4`, from its cache.
fn loader_step(c: &mut Criterion) {
    let dir = tempfile::tempdir().unwrap();
    let views = example_car_views(256);
    for sub in ["gt", "in"] {
        std::fs::create_dir_all(dir.path().join(sub)).unwrap();
        write_views(&dir.path().join(sub), &views).unwrap();
    }
    let sample = SampleRef {
        category: "car".into(),
        name: "example".into(),
        sample: "1".into(),
        gt: dir.path().join("gt"),
        input: dir.path().join("in"),
        clouds: None,
    };
    let cameras = Camera::set(&DEFAULT_VIEWS, Preset::Cpu.config().size).unwrap();
    let cache = Cache::new(1 << 30);
    let settings = AugmentSettings {
        mirror: true,
        max_yaw_deg: 5.0,
        color_jitter: 0.1,
    };
    let mut rng = Lcg::new(1);
    c.bench_function(
        "loader: render one step of 4 samples (256² → 128², cached)",
        |b| {
            b.iter(|| {
                (0..4)
                    .map(|_| {
                        load_sample(&sample, &cameras, &settings.draw(&mut rng), &cache).unwrap()
                    })
                    .count()
            })
        },
    );
}

criterion_group!(benches, training_step, loader_step);
criterion_main!(benches);
