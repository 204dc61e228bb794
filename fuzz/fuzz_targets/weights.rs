#![no_main]
//! Weights files: the generator, discriminator and orientation network readers (what
//! `complete --model`, `train --init` and `--orienter` load).

use burn::tensor::Device;
use libfuzzer_sys::fuzz_target;
use mvpcc::model::weights::{discriminator_from_bytes, generator_from_bytes};
use mvpcc::orient::Orienter;

fuzz_target!(|data: &[u8]| {
    let device = Device::flex();
    let _ = generator_from_bytes(data, &device);
    let _ = discriminator_from_bytes(data, &device);
    let _ = Orienter::from_bytes(data, device);
});
