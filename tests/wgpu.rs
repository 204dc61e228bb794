//! The wgpu backend run for real: the generator's forward pass, a training step and `complete`
//! on wgpu agree with the CPU (flex). Built only with `--features wgpu`; `.ci/run` installs
//! Mesa's software Vulkan (lavapipe) so that every CI run executes them without a GPU, and on a
//! machine with one they run there.

#![cfg(feature = "wgpu")]

mod common;

use assert_cmd::Command;
use burn::tensor::{Device, Tensor, TensorData};
use mvpcc::complete::DEFAULT_MODEL;
use mvpcc::core::knn::KnnIndex;
use mvpcc::core::rng::Lcg;
use mvpcc::io::read_cloud;
use mvpcc::model::device::{open, DeviceChoice};
use mvpcc::model::gan::{Batch, Gan, GanOptimConfig};
use mvpcc::model::loss::{LossWeights, Target};
use mvpcc::model::weights::{discriminator_to_bytes, generator_from_bytes, generator_to_bytes};
use mvpcc::model::{Generator, ModelConfig, Preset};
use std::path::Path;

/// The wgpu device, opened once for all the tests: adapters opened at once from several
/// threads fail on some drivers.
fn wgpu() -> Device {
    static DEVICE: std::sync::OnceLock<Device> = std::sync::OnceLock::new();
    DEVICE
        .get_or_init(|| {
            let opened = open(DeviceChoice::Wgpu).expect("a wgpu adapter (CI installs lavapipe)");
            eprintln!("wgpu: {}", opened.description);
            opened.device
        })
        .clone()
}

/// `shape`'s values drawn from `seed`, the same on every device; `occupied` of them kept
/// (the rest 0), as views are.
fn values(shape: [usize; 5], seed: u64, occupied: f64) -> TensorData {
    let mut rng = Lcg::new(seed);
    let n = shape.iter().product();
    let data: Vec<f32> = (0..n)
        .map(|_| {
            let v = rng.next_f64() as f32;
            if rng.next_f64() < occupied {
                v
            } else {
                0.0
            }
        })
        .collect();
    TensorData::new(data, shape)
}

/// A batch of `objects` views for `config`, built from the same numbers on any device.
fn input(config: &ModelConfig, objects: usize, device: &Device) -> Tensor<5> {
    let shape = [
        objects,
        config.views,
        config.input_channels(),
        config.size,
        config.size,
    ];
    Tensor::from_data(values(shape, 7, 0.4), device)
}

fn host(t: Tensor<5>) -> Vec<f32> {
    t.into_data().try_to_vec::<f32>().expect("f32 values")
}

/// The largest absolute difference between two equally long lists.
fn largest_difference(a: &[f32], b: &[f32]) -> f32 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f32::max)
}

fn forward(generator: &Generator, config: &ModelConfig, device: &Device) -> (Vec<f32>, Vec<f32>) {
    let out = generator.forward(input(config, 2, device));
    (host(out.images), host(out.occupancy))
}

/// Images are in [0, 1] and occupancy logits of a few units; f32 sums taken in another order
/// (tiled kernels against the CPU's) differ in the last bits of each of thousands of terms.
const IMAGE_TOLERANCE: f32 = 1e-4;
const LOGIT_TOLERANCE: f32 = 1e-3;

#[test]
fn the_forward_pass_on_wgpu_matches_the_cpu_for_the_tiny_and_built_in_models() {
    let (cpu, gpu) = (Device::flex(), wgpu());
    cpu.seed(5);
    let tiny = Preset::Tiny.config();
    let tiny_bytes = generator_to_bytes(&tiny.init_generator(&cpu).unwrap(), &tiny).unwrap();
    for (name, bytes) in [("tiny", tiny_bytes.as_slice()), ("built-in", DEFAULT_MODEL)] {
        let (on_cpu, config) = generator_from_bytes(bytes, &cpu).unwrap();
        let (on_gpu, _) = generator_from_bytes(bytes, &gpu).unwrap();
        let (images_cpu, logits_cpu) = forward(&on_cpu, &config, &cpu);
        let (images_gpu, logits_gpu) = forward(&on_gpu, &config, &gpu);
        let images = largest_difference(&images_cpu, &images_gpu);
        let logits = largest_difference(&logits_cpu, &logits_gpu);
        eprintln!("{name}: images differ by at most {images:e}, occupancy logits by {logits:e}");
        assert!(
            images <= IMAGE_TOLERANCE,
            "{name}: images differ by {images}"
        );
        assert!(
            logits <= LOGIT_TOLERANCE,
            "{name}: logits differ by {logits}"
        );
    }
}

/// A GAN of `config` on `device` with the weights in `bytes` (generator, discriminator).
fn gan(config: &ModelConfig, bytes: &(Vec<u8>, Vec<u8>), device: &Device) -> Gan {
    let (generator, _) = generator_from_bytes(&bytes.0, device).unwrap();
    let discriminator =
        mvpcc::model::weights::discriminator_from_bytes(&bytes.1, config, device).unwrap();
    Gan::from_parts(
        generator,
        discriminator,
        config.clone(),
        LossWeights::new(),
        // Adam's first step moves every weight by the whole rate, either way by its gradient's
        // sign, so a weight whose gradient is rounding noise lands 2 × rate apart on the two
        // backends (a run failed so, 1.9e-3 apart); with ε = 1 the step is nearly rate ×
        // gradient and compares the gradients themselves.
        GanOptimConfig::new().with_epsilon(1.0),
    )
}

fn batch(config: &ModelConfig, device: &Device) -> Batch {
    let (v, c, s) = (config.views, config.channels.count(), config.size);
    let occupancy = values([2, v, 1, s, s], 11, 1.0).convert::<f32>();
    let occupancy = Tensor::<5>::from_data(occupancy, device)
        .greater_elem(0.6)
        .float();
    let images =
        Tensor::<5>::from_data(values([2, v, c, s, s], 13, 1.0), device) * occupancy.clone();
    Batch {
        input: input(config, 2, device),
        target: Target::new(images, occupancy),
    }
}

#[test]
fn one_training_step_on_wgpu_matches_the_cpu() {
    let (cpu, gpu) = (Device::flex().autodiff(), wgpu().autodiff());
    // Fixed weights: with fresh ones each run, now and then a pre-activation lies within
    // rounding of a ReLU's kink, the backends take different branches and the stepped logits
    // land 1.4e-3 apart (a CI run did; they are usually within 3e-5), which says nothing
    // about the gradients.
    cpu.seed(5);
    let config = Preset::Tiny.config();
    let bytes = (
        generator_to_bytes(&config.init_generator(&cpu).unwrap(), &config).unwrap(),
        discriminator_to_bytes(&config.init_discriminator(&cpu).unwrap(), &config).unwrap(),
    );
    let step = |device: &Device| {
        let (after, losses) = gan(&config, &bytes, device).step(&[batch(&config, device)], 0.1);
        let weights = generator_to_bytes(&after.generator, &config).unwrap();
        (losses, weights)
    };
    let ((losses_cpu, weights_cpu), (losses_gpu, weights_gpu)) = (step(&cpu), step(&gpu));
    eprintln!("CPU {losses_cpu:?}\nwgpu {losses_gpu:?}");
    for ((name, a), (_, b)) in losses_cpu.terms().into_iter().zip(losses_gpu.terms()) {
        let tolerance = 1e-4 * a.abs().max(1.0);
        assert!(
            (a - b).abs() <= tolerance,
            "{name}: {a} on the CPU, {b} on wgpu"
        );
    }
    // The stepped weights, compared by what they compute on the CPU.
    let stepped = |weights: &[u8]| {
        let (generator, _) = generator_from_bytes(weights, &Device::flex()).unwrap();
        forward(&generator, &config, &Device::flex())
    };
    let ((images_cpu, logits_cpu), (images_gpu, logits_gpu)) =
        (stepped(&weights_cpu), stepped(&weights_gpu));
    let images = largest_difference(&images_cpu, &images_gpu);
    let logits = largest_difference(&logits_cpu, &logits_gpu);
    eprintln!("after one step: images differ by at most {images:e}, logits by {logits:e}");
    let before = stepped(&bytes.0);
    let moved = largest_difference(&before.0, &images_cpu);
    let moved_logits = largest_difference(&before.1, &logits_cpu);
    eprintln!("the step moved the images by up to {moved:e}, logits by {moved_logits:e}");
    assert!(images <= IMAGE_TOLERANCE && logits <= LOGIT_TOLERANCE);
    // The step moved the output far more than the backends differ.
    assert!(
        moved > 100.0 * IMAGE_TOLERANCE,
        "the step moved the images by {moved} only"
    );
}

/// `complete --device wgpu` on the example scan: every point the CPU's run writes is written
/// within 1e-4 of the car's length, and the other way round.
#[test]
fn complete_on_wgpu_gives_the_cpus_points() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let input = root.join("assets/example/car_partial.ply");
    let dir = tempfile::tempdir().unwrap();
    let run = |device: &str| {
        let output = dir.path().join(format!("{device}.ply"));
        Command::cargo_bin("mvpcc")
            .unwrap()
            .args(["complete", "-q", "--device", device])
            .arg(&input)
            .arg(&output)
            .assert()
            .success();
        read_cloud(&output, None).unwrap().cloud
    };
    let (cpu, gpu) = (run("cpu"), run("wgpu"));
    let length = cpu.bounds().unwrap().longest_side();
    for (a, b, which) in [(&cpu, &gpu, "CPU"), (&gpu, &cpu, "wgpu")] {
        let nearest = KnnIndex::new(&b.positions).nearest(&a.positions);
        let far = nearest.iter().filter(|(_, d)| *d > 1e-4 * length).count();
        eprintln!("{which}: {} points, {far} without a partner", a.len());
        assert_eq!(far, 0, "{far} of the {which} run's points have no partner");
    }
}

/// The gradient of each of the discriminator's parameters, in visiting order.
struct Gradients<'a>(&'a burn::tensor::Gradients, Vec<Vec<f32>>);

impl burn::module::ModuleVisitor for Gradients<'_> {
    fn visit_float<const D: usize>(&mut self, param: &burn::module::Param<Tensor<D>>) {
        if let Some(grad) = param.val().grad(self.0) {
            self.1
                .push(grad.into_data().try_to_vec::<f32>().expect("f32 values"));
        }
    }
}

/// Guards the discriminator's loss, which came out at about half its value on Burn 0.22's
/// fused wgpu backend while written as two means added (the logits equal), with nothing read
/// back between the forward passes and the loss; and every layer's gradients but the last.
/// The logit head's weight gradient (one output channel) is wrong there, by 1–3× its largest
/// element and differently each run, though the gradient it passes back is right: it
/// is printed, not asserted, and `train --device wgpu` warns (docs/gpu.md, *wgpu*).
#[test]
fn the_discriminator_loss_and_its_gradients_but_the_heads_on_wgpu_match_the_cpu() {
    use burn::module::Module;
    use mvpcc::model::loss::{discriminator_input, discriminator_loss, Adversarial};
    let (cpu, gpu) = (Device::flex().autodiff(), wgpu().autodiff());
    let config = Preset::Tiny.config();
    let bytes = discriminator_to_bytes(&config.init_discriminator(&cpu).unwrap(), &config).unwrap();
    let planes = config.channels.count() + 1;
    for kind in [Adversarial::Hinge, Adversarial::NonSaturating] {
        let run = |device: &Device| {
            let d =
                mvpcc::model::weights::discriminator_from_bytes(&bytes, &config, device).unwrap();
            let b = batch(&config, device);
            let fake = input(&config, 2, device).narrow(2, 0, planes).reshape([
                2 * config.views,
                planes,
                config.size,
                config.size,
            ]);
            let real = d.forward(discriminator_input(b.target.images, b.target.occupancy));
            let loss = discriminator_loss(kind, real.logits, d.forward(fake).logits);
            let grads = loss.clone().backward();
            let mut collected = Gradients(&grads, Vec::new());
            d.visit(&mut collected);
            (
                loss.into_data().try_to_vec::<f32>().unwrap()[0],
                collected.1,
            )
        };
        let ((loss_cpu, grads_cpu), (loss_gpu, grads_gpu)) = (run(&cpu), run(&gpu));
        eprintln!("{kind:?}: loss {loss_cpu} on the CPU, {loss_gpu} on wgpu");
        assert!(
            (loss_cpu - loss_gpu).abs() <= 1e-5,
            "{kind:?}: loss {loss_cpu} on the CPU, {loss_gpu} on wgpu"
        );
        assert_eq!(grads_cpu.len(), grads_gpu.len());
        let head = grads_cpu.len() - 1;
        for (layer, (a, b)) in grads_cpu.iter().zip(&grads_gpu).enumerate() {
            let largest = a.iter().fold(0.0f32, |m, g| m.max(g.abs()));
            let differ = largest_difference(a, b);
            eprintln!("  layer {layer}: gradients differ by {differ:e} (largest {largest:e})");
            assert!(
                layer == head || differ <= 1e-4 * largest,
                "{kind:?}, layer {layer}: gradients differ by {differ:e} of {largest:e}"
            );
        }
    }
}

/// `train --device wgpu` says that the discriminator would learn wrongly there when a term
/// trains it, and says nothing of it when none does.
#[test]
fn training_on_wgpu_warns_when_the_discriminator_trains() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    common::prepare_tiny_data(&data);
    let warning = "the discriminator's last layer learns from a wrong gradient";
    for (name, losses, warned) in [
        ("adversarial", &[][..], true),
        (
            "generator-only",
            &[
                "--loss-adversarial",
                "0",
                "--loss-perceptual",
                "0",
                "--loss-style",
                "0",
            ][..],
            false,
        ),
    ] {
        let out = Command::cargo_bin("mvpcc")
            .unwrap()
            .args([
                "train", "--device", "wgpu", "--config", "tiny", "--steps", "0",
            ])
            .args([
                "--batch",
                "1",
                "--val-every",
                "0",
                "--seen-samples",
                "0",
                "--data",
            ])
            .arg(&data)
            .arg("--out")
            .arg(dir.path().join(name))
            .args(losses)
            .assert()
            .success();
        let stderr = String::from_utf8_lossy(&out.get_output().stderr).into_owned();
        assert_eq!(stderr.contains(warning), warned, "{name}: {stderr}");
    }
}
