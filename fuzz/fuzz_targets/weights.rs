#![no_main]
//! Weights files: the generator, discriminator and orientation network readers (what
//! `complete --model`, `train --init` and `--orienter` load).

use burn::tensor::Device;
use libfuzzer_sys::fuzz_target;
use mvpcc::model::weights::{discriminator_from_bytes, generator_from_bytes, read_config, Network};
use mvpcc::complete::orient::Orienter;

fuzz_target!(|data: &[u8]| {
    let device = Device::flex();
    let _ = generator_from_bytes(data, &device);
    if let Ok(config) = read_config(data, Network::Discriminator) {
        let _ = discriminator_from_bytes(data, &config, &device);
    }
    let _ = Orienter::from_bytes(data, device);
});
