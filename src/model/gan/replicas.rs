//! Data-parallel steps: one replica of both networks per device, each on its share of every
//! micro-batch, their gradients summed by Burn's multi-device optimizer step
//! (`MultiGradientsParams`, `ModuleOptimizer::step_multi`) into one update of the networks on
//! the first device, as PyTorch's `DataParallel` (which the original trains with) does.
//!
//! Burn 0.22's all-reduce (`burn::tensor::distributed`) runs only on CUDA through NCCL and
//! panics on the CPU backend, so it could not be tested here; `step_multi` runs on every
//! backend and is what the CPU tests check (docs/training.md, *Several devices*).

use super::{Batch, Gan, NoClock, Replica, StepLosses, Work};
use crate::core::guard::guarded;
use crate::model::loss::Target;
use crate::model::vgg::Vgg19;
use burn::module::Module;
use burn::optim::MultiGradientsParams;
use burn::tensor::{Device, Tensor};
use thiserror::Error;

/// A device that runs a replica besides the networks' own, with the frozen inputs of the loss
/// moved there once.
pub(super) struct Site {
    device: Device,
    vgg: Option<Vgg19>,
    depth_axes: Option<Tensor<5>>,
}

/// A replica whose share of a step panicked (a device lost, out of memory); the step is not
/// taken.
#[derive(Debug, Error)]
#[error("replica {index} failed: {why}")]
pub struct ReplicaFailure {
    /// 0 is the networks' own device.
    pub index: usize,
    pub why: String,
}

/// A failed step gives the networks back as they were before it.
pub type FailedStep = Box<(Gan, ReplicaFailure)>;

impl Gan {
    /// Runs every later [`Gan::step_replicated`] on `others` too (autodiff devices), besides
    /// the networks' own device, which keeps the weights, the optimizers' state, validation
    /// and checkpoints. Call it after `vgg` and `depth_axes` are set.
    pub fn replicate_on(&mut self, others: &[Device]) {
        self.sites = others
            .iter()
            .map(|device| Site {
                device: device.clone(),
                vgg: self.vgg.clone().map(|v| v.fork(device)),
                depth_axes: self.depth_axes.clone().map(|a| a.to_device(device)),
            })
            .collect();
    }

    /// How many devices a step runs on.
    pub fn replicas(&self) -> usize {
        1 + self.sites.len()
    }

    /// One optimizer step of both networks over `shards`: `shards[r][m]` is replica `r`'s part
    /// of micro-batch `m`, on that replica's device (replica 0 on the networks' own). Each part's
    /// losses weigh by its share of the micro-batch's objects, so the step equals one replica's
    /// step over the whole micro-batches (to float rounding). On a replica's failure no weight
    /// is updated (the first replica's power iteration may have advanced) and the networks come
    /// back with the failure.
    pub fn step_replicated(
        mut self,
        shards: &[Vec<Batch>],
        learning_rate: f64,
    ) -> Result<(Gan, StepLosses), FailedStep> {
        assert_eq!(shards.len(), self.replicas(), "one shard list per replica");
        let micro = shards[0].len();
        assert!(micro > 0, "a step needs at least one batch");
        assert!(
            shards.iter().all(|s| s.len() == micro),
            "every replica gets a part of every micro-batch"
        );
        if self.sites.is_empty() {
            return Ok(self.step(&shards[0], learning_rate));
        }
        let objects = |b: &Batch| b.input.dims()[0];
        let totals: Vec<usize> = (0..micro)
            .map(|m| shards.iter().map(|s| objects(&s[m])).sum())
            .collect();
        let foregrounds: Vec<f32> = (0..micro)
            .map(|m| whole_foreground(shards.iter().map(|s| &s[m].target)))
            .collect();
        let parts: Vec<Vec<Batch>> = shards
            .iter()
            .map(|s| {
                s.iter()
                    .zip(&foregrounds)
                    .map(|(b, &share)| {
                        let mut b = b.clone();
                        b.target.batch_foreground = Some(share);
                        b
                    })
                    .collect()
            })
            .collect();
        let plans: Vec<Vec<(&Batch, f64)>> = parts
            .iter()
            .map(|s| {
                s.iter()
                    .zip(&totals)
                    .map(|(b, &n)| (b, objects(b) as f64 / (n * micro) as f64))
                    .collect()
            })
            .collect();
        // Built here, not in the threads: the power iteration's state is synced per thread, and
        // this thread is the one that advances the networks' own.
        let replicas: Vec<Replica> = std::iter::once(self.local_replica())
            .chain(self.sites.iter().map(|site| self.remote_replica(site)))
            .collect();
        let weights = &self.weights;
        let results: Vec<Result<Work, String>> = std::thread::scope(|scope| {
            let mut replicas = replicas.into_iter().zip(&plans).enumerate();
            let (_, (local, local_plan)) = replicas.next().expect("the networks' own replica");
            let others: Vec<_> = replicas
                .map(|(index, (replica, plan))| {
                    scope.spawn(move || {
                        guarded(|| {
                            injected_failure(index);
                            replica.run(weights, plan, &mut NoClock)
                        })
                    })
                })
                .collect();
            let first = guarded(|| {
                injected_failure(0);
                local.run(weights, local_plan, &mut NoClock)
            });
            std::iter::once(first)
                .chain(others.into_iter().map(|h| {
                    h.join()
                        .unwrap_or_else(|_| Err("its thread ended".to_string()))
                }))
                .collect()
        });
        let mut works = Vec::with_capacity(results.len());
        for (index, result) in results.into_iter().enumerate() {
            match result {
                Ok(work) => works.push(work),
                Err(why) => return Err(Box::new((self, ReplicaFailure { index, why }))),
            }
        }
        let devices: Vec<Device> = std::iter::once(shards[0][0].input.device())
            .chain(self.sites.iter().map(|s| s.device.clone()))
            .collect();
        let losses = works
            .iter()
            .fold(StepLosses::default(), |sum, w| sum.plus(&w.losses));
        let home = devices[0].clone();
        if works[0].discriminator.is_some() {
            let grads = MultiGradientsParams {
                grads: works
                    .iter_mut()
                    .zip(&devices)
                    .filter_map(|(w, d)| w.discriminator.take().map(|g| (g, d.clone())))
                    .collect(),
            };
            let rate = learning_rate * self.optim.d_to_g_rate;
            let stepped = self.d_optim.step_multi(rate, self.discriminator, grads);
            self.discriminator = at_home(stepped, &home);
        }
        let grads = MultiGradientsParams {
            grads: works
                .into_iter()
                .zip(&devices)
                .map(|(w, d)| (w.generator, d.clone()))
                .collect(),
        };
        let stepped = self
            .g_optim
            .step_multi(learning_rate, self.generator, grads);
        self.generator = at_home(stepped, &home);
        Ok((self, losses))
    }

    /// Copies of the networks on `site`'s device, their gradients their own; the
    /// discriminator's power iteration there starts from the networks' own and is dropped after
    /// the step.
    fn remote_replica(&self, site: &Site) -> Replica {
        Replica {
            generator: self.generator.clone().fork(&site.device),
            discriminator: self.discriminator.replica(&site.device),
            vgg: site.vgg.clone(),
            depth_axes: site.depth_axes.clone(),
        }
    }
}

/// The occupied share of the pixels of a micro-batch given as its replicas' parts.
fn whole_foreground<'a>(parts: impl Iterator<Item = &'a Target>) -> f32 {
    let (occupied, pixels) = parts.fold((0.0, 0), |(o, n), t| {
        let sum: f32 = t.occupancy.clone().sum().into_scalar();
        (o + f64::from(sum), n + t.occupancy.shape().num_elements())
    });
    (occupied / pixels.max(1) as f64) as f32
}

/// `step_multi` updates each weight on the device its gradients were summed on; the networks
/// live on the first device between steps.
fn at_home<M: Module>(module: M, home: &Device) -> M {
    match module.devices().iter().all(|d| d == home) {
        true => module,
        false => module.fork(home),
    }
}

/// Debug builds only: `MVPCC_FAIL_REPLICA=INDEX` makes that replica fail, for the tests of how
/// a run ends when one does.
fn injected_failure(index: usize) {
    #[cfg(debug_assertions)]
    if std::env::var("MVPCC_FAIL_REPLICA").is_ok_and(|v| v == index.to_string()) {
        panic!("failure injected by MVPCC_FAIL_REPLICA");
    }
    #[cfg(not(debug_assertions))]
    let _ = index;
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::gan::GanOptimConfig;
    use crate::model::loss::LossWeights;
    use crate::model::Preset;
    use burn::module::{ModuleVisitor, Param};
    use burn::tensor::TensorData;

    /// Every float of a module in visiting order: the weights, and with `state` the power
    /// iteration's running state too.
    struct Floats {
        state: bool,
        values: Vec<f32>,
    }

    impl ModuleVisitor for Floats {
        fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
            let tensor = param.val();
            if self.state || tensor.is_require_grad() {
                self.values
                    .extend(tensor.into_data().try_to_vec::<f32>().unwrap());
            }
        }
    }

    fn floats(gan: &Gan, state: bool) -> Vec<f32> {
        let mut f = Floats {
            state,
            values: Vec::new(),
        };
        gan.generator.visit(&mut f);
        gan.discriminator.visit(&mut f);
        f.values
    }

    fn largest_difference(a: &[f32], b: &[f32]) -> f32 {
        assert_eq!(a.len(), b.len());
        a.iter()
            .zip(b)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0, f32::max)
    }

    /// A second GAN with `gan`'s weights and power-iteration state, sharing nothing with it
    /// (the device's generator is shared by tests running at once, so no second draw).
    fn twin(gan: &Gan, device: &Device) -> Gan {
        Gan::from_parts(
            gan.generator.clone().fork(device),
            gan.discriminator.replica(device),
            gan.config.clone(),
            gan.weights.clone(),
            optim(),
        )
    }

    /// Adam's ε: with the original's 1e-8 a weight whose gradient is rounding noise moves by the
    /// whole rate either way, so equal steps would part by more than rounding; with ε = 1 (and
    /// a small rate) each update is nearly rate × gradient and rounding stays rounding.
    fn optim() -> GanOptimConfig {
        GanOptimConfig::new().with_epsilon(1.0)
    }

    /// The tiny GAN on the CPU, recording gradients.
    fn tiny_gan(weights: LossWeights) -> (Gan, Device) {
        let device = Device::flex().autodiff();
        let gan = Gan::new(Preset::Tiny.config(), weights, optim(), &device);
        (gan.unwrap(), device)
    }

    /// `n` disc-shaped objects seen on their left half, each a little off the last, their
    /// geometry a smooth ramp: random pixels would put activations at the nonlinearities'
    /// kinks, where rounding can flip a gradient.
    fn blobs(config: &crate::model::ModelConfig, n: usize, shift: usize, device: &Device) -> Batch {
        let (v, c, s) = (config.views, config.channels.count(), config.size);
        let mut images = vec![0.0f32; n * v * c * s * s];
        let mut occupancy = vec![0.0f32; n * v * s * s];
        let mut seen = vec![0.0f32; n * v * s * s];
        for (k, view, r, col) in (0..n).flat_map(|k| {
            (0..v).flat_map(move |view| {
                (0..s).flat_map(move |r| (0..s).map(move |col| (k, view, r, col)))
            })
        }) {
            let centre = (s / 2 + k + shift + view) as f32;
            let (dy, dx) = (r as f32 - centre, col as f32 - s as f32 / 2.0);
            if dy * dy + dx * dx < (s * s / 10) as f32 {
                let at = ((k * v + view) * s + r) * s + col;
                occupancy[at] = 1.0;
                seen[at] = if col < s / 2 { 1.0 } else { 0.0 };
                for ch in 0..c {
                    images[(((k * v + view) * c + ch) * s + r) * s + col] =
                        0.3 + 0.02 * ch as f32 + 0.005 * (r + col + k) as f32;
                }
            }
        }
        let t = |data: Vec<f32>, planes| {
            Tensor::<5>::from_data(TensorData::new(data, [n, v, planes, s, s]), device)
        };
        let (images, seen) = (t(images, c), t(seen, 1));
        Batch {
            input: Tensor::cat(vec![images.clone() * seen.clone(), seen], 2),
            target: Target::new(images, t(occupancy, 1)),
        }
    }

    /// Objects `range` of `batch`.
    fn part(batch: &Batch, range: std::ops::Range<usize>) -> Batch {
        let pick = |t: &Tensor<5>| t.clone().narrow(0, range.start, range.len());
        Batch {
            input: pick(&batch.input),
            target: Target::new(pick(&batch.target.images), pick(&batch.target.occupancy)),
        }
    }

    /// `steps` steps of one GAN over two micro-batches of three objects, and of its twin on two
    /// replicas that split each micro-batch 2 + 1 (unequal parts must weigh by their size):
    /// the largest difference of their weights, and how far the weights moved.
    fn one_against_two(weights: LossWeights, steps: usize) -> (f32, f32) {
        let (single, device) = tiny_gan(weights);
        let fresh = floats(&single, false);
        let mut split = twin(&single, &device);
        split.replicate_on(std::slice::from_ref(&device));
        assert_eq!(split.replicas(), 2);
        let mut single = single;
        for k in 0..steps {
            let micro: Vec<Batch> = (0..2)
                .map(|m| blobs(&single.config, 3, k + m, &device))
                .collect();
            let (a, la) = single.step(&micro, 1e-3);
            let shards = [
                micro.iter().map(|b| part(b, 0..2)).collect(),
                micro.iter().map(|b| part(b, 2..3)).collect(),
            ];
            let (b, lb) = split
                .step_replicated(&shards, 1e-3)
                .unwrap_or_else(|f| panic!("{}", f.1));
            (single, split) = (a, b);
            // The first step starts from equal weights; later ones from weights that rounding
            // has parted (see the tests below).
            let tolerance = if k == 0 { 1e-5 } else { 1e-3 };
            for ((name, x), (_, y)) in la.terms().into_iter().zip(lb.terms()) {
                let close = (x - y).abs() <= tolerance * x.abs().max(1.0);
                assert!(close, "step {k} {name}: {x} vs {y}");
            }
        }
        let trained = floats(&single, true);
        let worst = largest_difference(&trained, &floats(&split, true));
        (worst, largest_difference(&fresh, &floats(&single, false)))
    }

    #[test]
    fn two_replicas_train_the_generator_as_one_does_over_the_whole_batch() {
        let weights = LossWeights {
            adversarial: 0.0,
            perceptual: 0.0,
            style: 0.0,
            ..LossWeights::new()
        };
        assert!(!weights.needs_discriminator(false));
        let (worst, moved) = one_against_two(weights, 2);
        // Rounding is all that differs, but instance norm over a nearly constant channel can
        // magnify it over later steps: over 20 runs of two steps, at most 0.08 % of the move.
        assert!(worst < 0.01 * moved, "differ by {worst}, moved {moved}");
    }

    #[test]
    fn two_replicas_train_both_networks_as_one_does_over_the_whole_batch() {
        let weights = LossWeights::new();
        assert!(weights.needs_discriminator(false));
        let (worst, moved) = one_against_two(weights, 1);
        assert!(
            worst < 1e-6 && moved > 100.0 * worst,
            "differ by {worst}, moved {moved}"
        );
    }

    #[test]
    fn a_replica_that_fails_hands_back_the_networks_untouched() {
        let (mut gan, device) = tiny_gan(LossWeights::new());
        gan.replicate_on(std::slice::from_ref(&device));
        let before = floats(&gan, false);
        let good = Batch::random(&gan.config, 1, &device);
        // Three views where the networks expect four: the replica's loss panics.
        let mut bad = good.clone();
        bad.target.images = bad.target.images.narrow(1, 0, 3);
        let failed = gan
            .step_replicated(&[vec![good], vec![bad]], 1e-3)
            .err()
            .expect("the step must fail");
        let (gan, failure) = *failed;
        assert_eq!(failure.index, 1);
        assert!(
            failure.to_string().starts_with("replica 1 failed: "),
            "{failure}"
        );
        // The weights; the first replica's forward passes did advance the power iteration.
        assert!(
            floats(&gan, false) == before,
            "a failed step changed weights"
        );
    }
}
