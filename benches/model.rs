//! Generator forward pass on the CPU (flex) for the named model shapes, one object (all views)
//! per pass. `benches/reference/generator_torch.py` times the same shapes in PyTorch.

use burn::tensor::{Device, Distribution, Tensor};
use criterion::{criterion_group, criterion_main, Criterion};
use mvpcc::model::weights::{generator_from_bytes, generator_to_bytes};
use mvpcc::model::Preset;
use std::time::Duration;

fn generator_forward(c: &mut Criterion) {
    let device = Device::flex();
    let mut group = c.benchmark_group("generator forward (flex)");
    group
        .sample_size(10)
        .measurement_time(Duration::from_secs(20));
    for preset in [Preset::Small, Preset::Cpu, Preset::Original] {
        let config = preset.config();
        let generator = config.init_generator(&device).unwrap();
        let shape = [
            1,
            config.views,
            config.input_channels(),
            config.size,
            config.size,
        ];
        let input = Tensor::<5>::random(shape, Distribution::Default, &device);
        group.bench_function(format!("{preset:?}").to_lowercase(), |b| {
            b.iter(|| {
                let out = generator.forward(input.clone());
                out.occupancy.sum().into_data()
            })
        });
    }
    group.finish();
}

/// What `complete` pays before its first forward: parsing an embedded weights file.
fn load_weights(c: &mut Criterion) {
    let device = Device::flex();
    let config = Preset::Cpu.config();
    let generator = config.init_generator(&device).unwrap();
    let bytes = generator_to_bytes(&generator, &config).unwrap();
    c.bench_function(
        &format!(
            "load cpu generator weights ({} MB)",
            bytes.len() / 1_000_000
        ),
        |b| b.iter(|| generator_from_bytes(&bytes, &device).unwrap()),
    );
}

criterion_group!(benches, generator_forward, load_weights);
criterion_main!(benches);
