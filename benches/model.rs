//! Generator forward pass on the CPU (flex) for the named model shapes, one object (all views)
//! per pass. `benches/reference/generator_torch.py` times the same shapes in PyTorch.

use burn::tensor::{Device, Distribution, Tensor};
use criterion::{criterion_group, criterion_main, Criterion};
use mvpcc::model::Preset;
use std::time::Duration;

fn generator_forward(c: &mut Criterion) {
    let device = Device::flex();
    let mut group = c.benchmark_group("generator forward (flex)");
    group
        .sample_size(10)
        .measurement_time(Duration::from_secs(20));
    for preset in [Preset::Small, Preset::Cpu, Preset::Paper] {
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

criterion_group!(benches, generator_forward);
criterion_main!(benches);
