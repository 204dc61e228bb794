//! One adversarial training step with two optimizers, as the original trains: the
//! discriminator on real views against detached generated ones, then the generator on the
//! weighted sum of its losses. The real views pass through the discriminator once per step.

use super::loss::{
    discriminator_input, discriminator_loss, generator_losses, GeneratorLosses, LossWeights, Target,
};
use super::vgg::Vgg19;
use super::{ConfigError, Discriminator, Generator, GeneratorOutput, ModelConfig};
use burn::config::Config;
use burn::module::Module;
use burn::optim::{AdamConfig, GradientsAccumulator, GradientsParams, ModuleOptimizer};
use burn::tensor::activation::sigmoid;
use burn::tensor::{Bytes, Device, Distribution, Tensor};

mod replicas;
pub use replicas::{FailedStep, ReplicaFailure};

/// Optimizer settings; the defaults are the original's (Adam, β = (0, 0.9), the
/// discriminator at a tenth of the generator's rate). The generator's rate itself is given to
/// each [`Gan::step`], since the training stages change it.
#[derive(Config, Debug, PartialEq)]
pub struct GanOptimConfig {
    /// Discriminator rate ÷ generator rate (`D2G_LR`).
    #[config(default = 0.1)]
    pub d_to_g_rate: f64,
    #[config(default = 0.0)]
    pub beta_1: f32,
    #[config(default = 0.9)]
    pub beta_2: f32,
    /// PyTorch's Adam default (Burn's is 1e-5).
    #[config(default = 1e-8)]
    pub epsilon: f32,
}

/// Both networks and their optimizers.
pub struct Gan {
    pub generator: Generator,
    pub discriminator: Discriminator,
    pub config: ModelConfig,
    pub weights: LossWeights,
    /// Frozen VGG19 features for the perceptual and style terms; the discriminator's features
    /// when absent.
    pub vgg: Option<Vgg19>,
    /// The views' camera axes (`loss::depth_axes`) for the depth term; it is zero without them.
    pub depth_axes: Option<Tensor<5>>,
    optim: GanOptimConfig,
    g_optim: ModuleOptimizer,
    d_optim: ModuleOptimizer,
    /// The other devices of a data-parallel step ([`Gan::replicate_on`]).
    sites: Vec<replicas::Site>,
}

/// The parts of a training step, in the order they run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum StepPhase {
    GeneratorForward,
    /// The discriminator on real and generated views, and its loss.
    DiscriminatorLoss,
    DiscriminatorBackward,
    /// The discriminator on the generated views again (gradients flow to the views, not to the
    /// discriminator's weights), and every generator loss term.
    GeneratorLoss,
    GeneratorBackward,
    /// Both Adam updates.
    Optimizers,
}

impl StepPhase {
    pub fn name(self) -> &'static str {
        match self {
            StepPhase::GeneratorForward => "generator forward",
            StepPhase::DiscriminatorLoss => "discriminator forward + loss",
            StepPhase::DiscriminatorBackward => "discriminator backward",
            StepPhase::GeneratorLoss => "generator losses",
            StepPhase::GeneratorBackward => "generator backward",
            StepPhase::Optimizers => "Adam updates",
        }
    }
}

/// Sees a training step's phases end; `mvpcc profile --train` syncs the device and books the
/// time there. Work is queued asynchronously on a GPU, so without a sync the phases blur.
pub trait StepClock {
    fn done(&mut self, phase: StepPhase);
}

/// The ordinary step: no clock.
pub struct NoClock;

impl StepClock for NoClock {
    fn done(&mut self, _phase: StepPhase) {}
}

/// One batch of inputs and their ground truth.
///
/// # Shapes
/// `input`: `[B, V, C+1, S, S]`; `target.images`: `[B, V, C, S, S]`;
/// `target.occupancy`: `[B, V, 1, S, S]`
#[derive(Debug, Clone)]
pub struct Batch {
    pub input: Tensor<5>,
    pub target: Target,
}

impl Batch {
    /// Random views shaped like real ones: 40 % of the pixels occupied, half of those seen by
    /// the partial input; for timing steps, not for learning.
    pub fn random(config: &ModelConfig, objects: usize, device: &Device) -> Batch {
        let (v, c, s) = (config.views, config.channels.count(), config.size);
        let occupancy =
            Tensor::<5>::random([objects, v, 1, s, s], Distribution::Bernoulli(0.4), device);
        let images = Tensor::<5>::random([objects, v, c, s, s], Distribution::Default, device)
            * occupancy.clone();
        let seen = occupancy.clone()
            * Tensor::random([objects, v, 1, s, s], Distribution::Bernoulli(0.5), device);
        Batch {
            input: Tensor::cat(vec![images.clone() * seen.clone(), seen], 2),
            target: Target::new(images, occupancy),
        }
    }
}

/// The losses of one step (averaged over its micro-batches), read back as numbers.
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize, serde::Deserialize)]
pub struct StepLosses {
    pub discriminator: f32,
    pub generator: f32,
    pub l1: f32,
    pub adversarial: f32,
    pub perceptual: f32,
    pub style: f32,
    pub occupancy: f32,
    pub tv: f32,
    /// Absent from logs written before the term existed.
    #[serde(default)]
    pub depth: f32,
}

impl Gan {
    /// `device` must record gradients (`Device::…().autodiff()`).
    pub fn new(
        config: ModelConfig,
        weights: LossWeights,
        optim: GanOptimConfig,
        device: &Device,
    ) -> Result<Gan, ConfigError> {
        let generator = config.init_generator(device)?;
        let discriminator = config.init_discriminator(device)?;
        Ok(Gan::from_parts(
            generator,
            discriminator,
            config,
            weights,
            optim,
        ))
    }

    pub fn from_parts(
        generator: Generator,
        discriminator: Discriminator,
        config: ModelConfig,
        weights: LossWeights,
        optim: GanOptimConfig,
    ) -> Gan {
        let adam = adam_config(&optim);
        Gan {
            generator,
            discriminator,
            config,
            weights,
            vgg: None,
            depth_axes: None,
            g_optim: adam.init(),
            d_optim: adam.init(),
            optim,
            sites: Vec::new(),
        }
    }

    /// One optimizer step of both networks over `micro` batches, whose gradients are
    /// accumulated (each loss divided by their number) so the effective batch is their sum.
    /// Both networks' losses are taken against the discriminator as it was when the step
    /// began, as the original computes its generator loss before the discriminator update.
    /// `learning_rate` is the generator's; the discriminator's is `d_to_g_rate` times that.
    pub fn step(self, micro: &[Batch], learning_rate: f64) -> (Gan, StepLosses) {
        self.step_clocked(micro, learning_rate, &mut NoClock)
    }

    /// [`Gan::step`], telling `clock` as each phase's work has been queued.
    pub fn step_clocked<C: StepClock>(
        mut self,
        micro: &[Batch],
        learning_rate: f64,
        clock: &mut C,
    ) -> (Gan, StepLosses) {
        assert!(!micro.is_empty(), "a step needs at least one batch");
        let share = 1.0 / micro.len() as f64;
        let shares: Vec<(&Batch, f64)> = micro.iter().map(|b| (b, share)).collect();
        let work = self.local_replica().run(&self.weights, &shares, clock);
        if let Some(d) = work.discriminator {
            self.discriminator = self.d_optim.step(
                learning_rate * self.optim.d_to_g_rate,
                self.discriminator,
                d,
            );
        }
        self.generator = self
            .g_optim
            .step(learning_rate, self.generator, work.generator);
        clock.done(StepPhase::Optimizers);
        (self, work.losses)
    }

    /// The networks as they run on their own device: clones that share the weights (and the
    /// discriminator's power iteration, which they advance).
    fn local_replica(&self) -> Replica {
        Replica {
            generator: self.generator.clone(),
            discriminator: self.discriminator.clone(),
            vgg: self.vgg.clone(),
            depth_axes: self.depth_axes.clone(),
        }
    }

    /// Both optimizers' state (Adam moments and step counts), generator's first, in Burn's
    /// burnpack format. They refer to parameters by id, so they only fit networks restored
    /// with their ids (a burnpack module record, not a safetensors file).
    pub fn optimizer_bytes(&self) -> Result<[Vec<u8>; 2], String> {
        let bytes = |o: &ModuleOptimizer| {
            o.into_bytes()
                .map(|b| b.to_vec())
                .map_err(|e| e.to_string())
        };
        Ok([bytes(&self.g_optim)?, bytes(&self.d_optim)?])
    }

    /// Restores what [`Gan::optimizer_bytes`] saved.
    pub fn load_optimizers(
        mut self,
        generator: &[u8],
        discriminator: &[u8],
    ) -> Result<Gan, String> {
        let load = |o: ModuleOptimizer, b: &[u8]| {
            o.from_bytes(Bytes::from_bytes_vec(b.to_vec()))
                .map_err(|e| e.to_string())
        };
        let adam = self.adam();
        self.g_optim = load(std::mem::replace(&mut self.g_optim, adam.init()), generator)?;
        self.d_optim = load(
            std::mem::replace(&mut self.d_optim, adam.init()),
            discriminator,
        )?;
        Ok(self)
    }

    fn adam(&self) -> AdamConfig {
        adam_config(&self.optim)
    }
}

/// The networks and frozen inputs of one step on one device.
struct Replica {
    generator: Generator,
    discriminator: Discriminator,
    vgg: Option<Vgg19>,
    depth_axes: Option<Tensor<5>>,
}

/// What a replica's share of a step yields: both networks' gradients (the discriminator's
/// when it trains) and its losses, weighted by its share.
struct Work {
    discriminator: Option<GradientsParams>,
    generator: GradientsParams,
    losses: StepLosses,
}

impl Replica {
    /// Both networks' gradients over `micro`, each batch's losses weighted by its share of the
    /// step (the shares of a whole step, over every replica, sum to 1).
    fn run<C: StepClock>(
        &self,
        weights: &LossWeights,
        micro: &[(&Batch, f64)],
        clock: &mut C,
    ) -> Work {
        let mut d_grads = GradientsAccumulator::<Discriminator>::new();
        let mut g_grads = GradientsAccumulator::<Generator>::new();
        let mut losses = StepLosses::default();
        let game = weights.needs_discriminator(self.vgg.is_some());
        for &(batch, share) in micro {
            let output = self.generator.forward(batch.input.clone());
            clock.done(StepPhase::GeneratorForward);
            let target = &batch.target;
            let (d_loss, real_features) = match game {
                true => {
                    self.discriminator_step(weights, &output, target, share, &mut d_grads, clock)
                }
                false => {
                    clock.done(StepPhase::DiscriminatorLoss);
                    clock.done(StepPhase::DiscriminatorBackward);
                    (0.0, Vec::new())
                }
            };
            let g = self.generator_step(
                weights,
                (&output, target),
                &real_features,
                share,
                &mut g_grads,
                clock,
            );
            losses = losses.plus(&StepLosses::read(d_loss, g).scaled(share as f32));
        }
        Work {
            discriminator: game.then(|| d_grads.grads()),
            generator: g_grads.grads(),
            losses,
        }
    }

    /// The generator's losses on one batch, their gradients accumulated into `g_grads` with
    /// `share` of the step's weight; `real_features` are the discriminator's features of the
    /// real views (empty when no term needs them).
    fn generator_step<C: StepClock>(
        &self,
        weights: &LossWeights,
        (output, target): (&GeneratorOutput, &Target),
        real_features: &[Tensor<4>],
        share: f64,
        g_grads: &mut GradientsAccumulator<Generator>,
        clock: &mut C,
    ) -> GeneratorLosses {
        // Where a term needs it, the generator's loss flows through the discriminator but
        // must not train it: a copy whose weights record no gradient spares the backward
        // pass their gradients.
        let judge = self.discriminator.clone().no_grad();
        let g = generator_losses(
            output,
            target,
            &judge,
            real_features,
            self.vgg.as_ref(),
            self.depth_axes.as_ref(),
            weights,
        );
        clock.done(StepPhase::GeneratorLoss);
        let grads = g.total.clone().mul_scalar(share).backward();
        g_grads.accumulate(
            &self.generator,
            GradientsParams::from_grads(grads, &self.generator),
        );
        clock.done(StepPhase::GeneratorBackward);
        g
    }

    /// The discriminator's loss on one batch, its gradients accumulated into `d_grads` with
    /// `share` of the step's weight, and its features of the real views. One pass over the real
    /// views serves both networks: its logits train the discriminator, its features (as
    /// constants) are what the generator's perceptual and style terms compare against.
    fn discriminator_step<C: StepClock>(
        &self,
        weights: &LossWeights,
        output: &GeneratorOutput,
        target: &Target,
        share: f64,
        d_grads: &mut GradientsAccumulator<Discriminator>,
        clock: &mut C,
    ) -> (f32, Vec<Tensor<4>>) {
        let fake =
            discriminator_input(output.images.clone(), sigmoid(output.occupancy.clone())).detach();
        let real = self.discriminator.forward(discriminator_input(
            target.images.clone(),
            target.occupancy.clone(),
        ));
        let real_features = real.features.iter().map(|f| f.clone().detach()).collect();
        let d_loss = discriminator_loss(
            weights.adversarial_kind,
            real.logits,
            self.discriminator.forward(fake).logits,
        );
        clock.done(StepPhase::DiscriminatorLoss);
        d_grads.accumulate(
            &self.discriminator,
            GradientsParams::from_grads(
                d_loss.clone().mul_scalar(share).backward(),
                &self.discriminator,
            ),
        );
        clock.done(StepPhase::DiscriminatorBackward);
        (value(d_loss), real_features)
    }
}

fn adam_config(optim: &GanOptimConfig) -> AdamConfig {
    AdamConfig::new()
        .with_beta_1(optim.beta_1)
        .with_beta_2(optim.beta_2)
        .with_epsilon(optim.epsilon)
}

/// A one-element tensor (a loss) read back as a number; NaN if the backend cannot give one.
pub(crate) fn value(t: Tensor<1>) -> f32 {
    t.into_data()
        .try_into_vec::<f32>()
        .ok()
        .and_then(|v| v.first().copied())
        .unwrap_or(f32::NAN)
}

impl StepLosses {
    /// The discriminator's loss `discriminator` and the generator's terms, read back.
    fn read(discriminator: f32, g: GeneratorLosses) -> StepLosses {
        StepLosses {
            discriminator,
            generator: value(g.total),
            l1: value(g.l1),
            adversarial: value(g.adversarial),
            perceptual: value(g.perceptual),
            style: value(g.style),
            occupancy: value(g.occupancy),
            tv: value(g.tv),
            depth: value(g.depth),
        }
    }

    pub fn plus(mut self, o: &StepLosses) -> StepLosses {
        for (a, b) in self.terms_mut().into_iter().zip(o.terms()) {
            *a += b.1;
        }
        self
    }

    pub fn scaled(mut self, factor: f32) -> StepLosses {
        for a in self.terms_mut() {
            *a *= factor;
        }
        self
    }

    /// Every term by name, in a fixed order.
    pub fn terms(&self) -> [(&'static str, f32); 9] {
        [
            ("discriminator", self.discriminator),
            ("generator", self.generator),
            ("l1", self.l1),
            ("adversarial", self.adversarial),
            ("perceptual", self.perceptual),
            ("style", self.style),
            ("occupancy", self.occupancy),
            ("tv", self.tv),
            ("depth", self.depth),
        ]
    }

    fn terms_mut(&mut self) -> [&mut f32; 9] {
        [
            &mut self.discriminator,
            &mut self.generator,
            &mut self.l1,
            &mut self.adversarial,
            &mut self.perceptual,
            &mut self.style,
            &mut self.occupancy,
            &mut self.tv,
            &mut self.depth,
        ]
    }

    /// The first term that is NaN or infinite.
    pub fn first_non_finite(&self) -> Option<(&'static str, f32)> {
        self.terms().into_iter().find(|(_, v)| !v.is_finite())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::{NoProbe, Preset};
    use burn::tensor::TensorData;

    /// A blob-shaped object: occupied where inside a disc, geometry a smooth ramp.
    fn sample(device: &Device) -> (Tensor<5>, Target) {
        let (v, c, s) = (4, 6, 32);
        let mut images = vec![0.0f32; v * c * s * s];
        let mut occ = vec![0.0f32; v * s * s];
        let mut partial = vec![0.0f32; v * s * s];
        for view in 0..v {
            for r in 0..s {
                for col in 0..s {
                    let (dy, dx) = (r as f32 - 16.0, col as f32 - 16.0);
                    if dy * dy + dx * dx < 100.0 {
                        let at = r * s + col;
                        occ[view * s * s + at] = 1.0;
                        partial[view * s * s + at] = if col < 16 { 1.0 } else { 0.0 };
                        for ch in 0..c {
                            images[(view * c + ch) * s * s + at] =
                                0.3 + 0.02 * (ch as f32) + 0.01 * (r + col) as f32 / 2.0;
                        }
                    }
                }
            }
        }
        let images = Tensor::<5>::from_data(TensorData::new(images, [1, v, c, s, s]), device);
        let occupancy = Tensor::<5>::from_data(TensorData::new(occ, [1, v, 1, s, s]), device);
        let seen = Tensor::<5>::from_data(TensorData::new(partial, [1, v, 1, s, s]), device);
        let input = Tensor::cat(vec![images.clone() * seen.clone(), seen], 2);
        (input, Target::new(images, occupancy))
    }

    /// The tiny GAN on the CPU, recording gradients, from a seeded initialization.
    fn tiny_gan(weights: LossWeights, seed: u64) -> (Gan, Device) {
        let device = Device::flex().autodiff();
        device.seed(seed);
        let optim = GanOptimConfig::new();
        let gan = Gan::new(Preset::Tiny.config(), weights, optim, &device).unwrap();
        (gan, device)
    }

    fn train(weights: LossWeights, steps: usize) -> (Gan, Vec<StepLosses>) {
        let (gan, device) = tiny_gan(weights, 7);
        train_gan(gan, &device, steps)
    }

    /// `steps` steps of `gan` on [`sample`].
    fn train_gan(mut gan: Gan, device: &Device, steps: usize) -> (Gan, Vec<StepLosses>) {
        let (input, target) = sample(device);
        let batch = [Batch { input, target }];
        let mut history = Vec::new();
        for _ in 0..steps {
            let (next, losses) = gan.step(&batch, 2e-3);
            gan = next;
            assert!(
                [losses.generator, losses.discriminator]
                    .iter()
                    .all(|l| l.is_finite()),
                "{losses:?}"
            );
            history.push(losses);
        }
        (gan, history)
    }

    /// Asserts that a loss read by `pick` fell below `factor` × its first value.
    fn falls(history: &[StepLosses], name: &str, factor: f32, pick: fn(&StepLosses) -> f32) {
        let (first, last) = (pick(&history[0]), pick(&history[history.len() - 1]));
        assert!(last < factor * first, "{name} {first} → {last}");
    }

    #[test]
    fn generator_loss_falls_over_a_few_steps_on_one_sample() {
        let (gan, history) = train(LossWeights::new(), 12);
        falls(&history, "L1", 0.5, |l| l.l1);
        falls(&history, "total", 0.5, |l| l.generator);
        // The trained generator still runs without autodiff.
        let plain = gan.generator.valid();
        let x = Tensor::<5>::random([1, 4, 7, 32, 32], Distribution::Default, &Device::flex());
        let out = plain.forward_probed(x, &mut NoProbe);
        assert_eq!(out.images.dims(), [1, 4, 6, 32, 32]);
    }

    #[test]
    fn the_generators_loss_gives_gradients_to_the_generator_alone() {
        let (gan, device) = tiny_gan(LossWeights::new(), 5);
        let (input, target) = sample(&device);
        let real = gan.discriminator.forward(discriminator_input(
            target.images.clone(),
            target.occupancy.clone(),
        ));
        let features: Vec<Tensor<4>> = real.features.iter().map(|f| f.clone().detach()).collect();
        // A backward pass consumes its graph: each count runs the generator anew.
        let count = |judge: &Discriminator| {
            let output = gan.generator.forward(input.clone());
            let g = generator_losses(&output, &target, judge, &features, None, None, &gan.weights);
            let mut grads = g.total.backward();
            let d = GradientsParams::from_module(&mut grads, &gan.discriminator).len();
            let g = GradientsParams::from_module(&mut grads, &gan.generator).len();
            (d, g)
        };
        // The frozen copy gets no gradient, the generator the same set either way, and
        // freezing the copy left the discriminator itself trainable.
        let (d_frozen, g_frozen) = count(&gan.discriminator.clone().no_grad());
        let (d_live, g_live) = count(&gan.discriminator);
        assert!(d_live > 0 && g_live > 0);
        assert_eq!((d_frozen, g_frozen), (0, g_live));
    }

    #[test]
    fn without_terms_that_need_it_the_discriminator_is_neither_run_nor_trained() {
        // Judged without autodiff, so judging advances no power iteration.
        let judged = |gan: &Gan| {
            let (_, target) = sample(&Device::flex());
            let real = discriminator_input(target.images, target.occupancy);
            gan.discriminator.valid().forward(real).logits.into_data()
        };
        let l1_only = LossWeights::new()
            .with_adversarial(0.0)
            .with_perceptual(0.0)
            .with_style(0.0);
        for (weights, game) in [(LossWeights::new(), true), (l1_only, false)] {
            let (gan, device) = tiny_gan(weights, 7);
            let initial = judged(&gan);
            let (gan, history) = train_gan(gan, &device, 6);
            assert_eq!(judged(&gan) != initial, game);
            let played = |l: &StepLosses| [l.discriminator, l.adversarial, l.perceptual, l.style];
            assert_eq!(
                history.iter().all(|l| played(l).iter().all(|&t| t != 0.0)),
                game,
                "{history:?}"
            );
            falls(&history, "L1", 0.5, |l| l.l1);
        }
    }

    #[test]
    fn vgg_features_drive_the_perceptual_and_style_terms() {
        let (mut gan, device) = tiny_gan(LossWeights::new(), 3);
        let (input, target) = sample(&device);
        let batch = [Batch { input, target }];
        let (next, plain) = gan.step(&batch, 1e-4);
        gan = next;
        gan.vgg = Some(crate::model::vgg::Vgg19::new(&device).no_grad());
        let vgg_params_before = gan.vgg.as_ref().unwrap().num_params();
        let (next, with_vgg) = gan.step(&batch, 1e-4);
        assert!(with_vgg.generator.is_finite());
        // Other feature maps, other values: VGG's relu1_1 maps have 64 channels at full size.
        assert!(
            (with_vgg.perceptual - plain.perceptual).abs() > 1e-3,
            "{with_vgg:?}"
        );
        assert_eq!(next.vgg.unwrap().num_params(), vgg_params_before);
    }

    #[test]
    fn occupancy_output_learns_from_the_bce_term() {
        // Measured: with the default weights the style term (250 × Gram differences of the
        // discriminator's features) outweighs BCE 0.1 on the occupancy plane in the first
        // steps; without the feature terms both reconstruction losses fall.
        let weights = LossWeights::new()
            .with_style(0.0)
            .with_perceptual(0.0)
            .with_adversarial(0.0);
        let (_, history) = train(weights, 12);
        falls(&history, "L1", 0.5, |l| l.l1);
        falls(&history, "BCE", 0.8, |l| l.occupancy);
    }
}
