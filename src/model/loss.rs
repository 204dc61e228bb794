//! The training losses. Each returns a one-element tensor (a mean) so terms can be weighted
//! and summed; [`generator_losses`] assembles the generator's objective the way the original
//! does.

use super::vgg::{as_rgb, Vgg19, PERCEPTUAL_LAYERS, STYLE_LAYERS};
use super::{Discriminator, GeneratorOutput};
use crate::core::camera::Camera;
use burn::config::Config;
use burn::tensor::activation::relu;
use burn::tensor::{Device, Tensor, TensorData};
use clap::ValueEnum;
use serde::{Deserialize, Serialize};

/// Weights of the generator's loss terms. The defaults are the original code's
/// (`config.yml`); the paper's text swaps the style and perceptual weights.
#[derive(Config, Debug, PartialEq)]
pub struct LossWeights {
    #[config(default = 50.0)]
    pub l1: f64,
    #[config(default = 0.1)]
    pub adversarial: f64,
    #[config(default = 250.0)]
    pub style: f64,
    #[config(default = 0.1)]
    pub perceptual: f64,
    /// BCE between the predicted and the true occupancy.
    #[config(default = 0.1)]
    pub occupancy: f64,
    /// Total variation of the geometry planes, further divided by [`LossWeights::tv_scale`].
    #[config(default = 0.1)]
    pub tv: f64,
    /// What the total-variation weight is divided by: the original code's image side, or the
    /// text's pixel count (λ6 = 0.1/S, S = 256×256).
    #[config(default = "TvScale::Side")]
    pub tv_scale: TvScale,
    /// The planes the perceptual and style terms compare through VGG19: all (the original
    /// code's, as RGB triples) or the colour alone (the text's; the geometry of a model
    /// without colour, as the text does for its XYZ-only model). The discriminator's features
    /// see every plane at once whatever this says.
    #[config(default = "FeaturePlanes::All")]
    pub feature_planes: FeaturePlanes,
    /// Smooth L1 on each occupied pixel's depth along its camera's axis, divided by the
    /// foreground fraction. Not the original's: `complete` keeps only that depth of a completed
    /// pixel's XYZ (it moves the point onto the pixel's ray, `snap_to_rays`), so this term
    /// weighs the error that reaches the cloud, which the L1 on XYZ mixes with the two
    /// components across the ray.
    #[config(default = 0.0)]
    pub depth: f64,
    #[config(default = "Adversarial::Hinge")]
    pub adversarial_kind: Adversarial,
}

impl LossWeights {
    /// Whether the generator's loss involves the discriminator: through the adversarial term,
    /// or the perceptual and style terms when they compare the discriminator's features (no
    /// VGG19). Without it a training step neither runs nor trains the discriminator, whose
    /// passes would only feed terms weighted zero.
    pub fn needs_discriminator(&self, vgg: bool) -> bool {
        self.adversarial != 0.0 || (!vgg && self.compares_features())
    }

    fn compares_features(&self) -> bool {
        self.perceptual != 0.0 || self.style != 0.0
    }
}

/// What the total-variation weight is divided by ([`LossWeights::tv_scale`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum TvScale {
    /// The view's side `S` (the original code).
    Side,
    /// The view's pixels `S²` (the paper's text).
    Pixels,
}

impl TvScale {
    fn divisor(self, side: usize) -> f64 {
        match self {
            TvScale::Side => side as f64,
            TvScale::Pixels => (side * side) as f64,
        }
    }
}

/// Which planes VGG19 sees for the perceptual and style terms ([`LossWeights::feature_planes`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum FeaturePlanes {
    /// Every plane, as RGB triples (the original code).
    All,
    /// The colour planes alone, or the geometry of a model without colour (the paper's text).
    Colour,
}

impl FeaturePlanes {
    /// The planes of `[B, V, C, S, S]` images that these are.
    fn of(self, images: Tensor<5>) -> Tensor<5> {
        let channels = images.dims()[2];
        match self {
            FeaturePlanes::All => images,
            FeaturePlanes::Colour => images.narrow(2, channels.saturating_sub(3), 3),
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum Adversarial {
    /// Hinge loss (SNGAN), the original's choice.
    Hinge,
    /// The non-saturating cross-entropy GAN loss.
    NonSaturating,
}

/// Mean Huber loss with β = 1 (PyTorch's `SmoothL1Loss`), written as `q·(d − q/2)` with
/// `q = min(d, 1)` so it needs no branch.
pub fn smooth_l1<const D: usize>(pred: Tensor<D>, target: Tensor<D>) -> Tensor<1> {
    let d = (pred - target).abs();
    let q = d.clone().clamp_max(1.0);
    (q.clone() * (d - q.div_scalar(2.0))).mean()
}

/// Mean binary cross-entropy of `logits` against targets in [0, 1], in the overflow-free form
/// `max(x, 0) − x·t + log(1 + e^{−|x|})`.
pub fn bce_with_logits<const D: usize>(logits: Tensor<D>, target: Tensor<D>) -> Tensor<1> {
    let softplus_tail = logits.clone().abs().neg().exp().log1p();
    (logits.clone().clamp_min(0.0) - logits * target + softplus_tail).mean()
}

/// The discriminator's loss on its logits for real and generated patches of one batch (the
/// two terms averaged, as the original halves their sum).
///
/// Both terms are one mean over the logits side by side, which equals the average of two
/// means because the two halves are the same size. Two means added in one graph come out wrong
/// on Burn 0.22's fused wgpu backend (about half the value, and different between runs; the
/// logits themselves agree with the CPU); tests/wgpu.rs guards it. The logit head's weight
/// gradient is still wrong there (docs/gpu.md, *wgpu*).
pub fn discriminator_loss(kind: Adversarial, real: Tensor<4>, fake: Tensor<4>) -> Tensor<1> {
    assert_eq!(
        real.dims(),
        fake.dims(),
        "real and generated logits of one batch"
    );
    match kind {
        Adversarial::Hinge => relu(Tensor::cat(vec![real.neg(), fake], 0).add_scalar(1.0)).mean(),
        Adversarial::NonSaturating => {
            let targets = Tensor::cat(vec![real.ones_like(), fake.zeros_like()], 0);
            bce_with_logits(Tensor::cat(vec![real, fake], 0), targets)
        }
    }
}

/// The generator's adversarial loss on the discriminator's logits for its output.
pub fn generator_adversarial(kind: Adversarial, fake: Tensor<4>) -> Tensor<1> {
    match kind {
        Adversarial::Hinge => fake.mean().neg(),
        Adversarial::NonSaturating => {
            let ones = fake.ones_like();
            bce_with_logits(fake, ones)
        }
    }
}

/// Sum over layers of the mean absolute feature difference.
pub fn perceptual(fake: &[Tensor<4>], real: &[Tensor<4>]) -> Tensor<1> {
    sum_over_layers(fake, real, |f, r| (f - r).abs().mean())
}

/// Gram matrix of each sample's features, normalized by their number.
///
/// # Shapes
/// `[n, c, h, w]` → `[n, c, c]`
pub fn gram(features: Tensor<4>) -> Tensor<3> {
    let [n, c, h, w] = features.dims();
    let f = features.reshape([n, c, h * w]);
    f.clone()
        .matmul(f.swap_dims(1, 2))
        .div_scalar((c * h * w) as f64)
}

/// Sum over layers of the mean absolute difference of Gram matrices.
pub fn style(fake: &[Tensor<4>], real: &[Tensor<4>]) -> Tensor<1> {
    sum_over_layers(fake, real, |f, r| (gram(f) - gram(r)).abs().mean())
}

fn sum_over_layers(
    fake: &[Tensor<4>],
    real: &[Tensor<4>],
    term: impl Fn(Tensor<4>, Tensor<4>) -> Tensor<1>,
) -> Tensor<1> {
    assert_eq!(fake.len(), real.len(), "one real feature map per fake one");
    fake.iter()
        .zip(real)
        .map(|(f, r)| term(f.clone(), r.clone()))
        .reduce(|a, b| a + b)
        .expect("at least one feature layer")
}

/// Anisotropic total variation: per image plane, the summed absolute differences of
/// neighbouring pixels, averaged over planes.
pub fn total_variation(x: Tensor<4>) -> Tensor<1> {
    let [n, c, h, w] = x.dims();
    let dy = (x.clone().narrow(2, 1, h - 1) - x.clone().narrow(2, 0, h - 1))
        .abs()
        .sum();
    let dx = (x.clone().narrow(3, 1, w - 1) - x.narrow(3, 0, w - 1))
        .abs()
        .sum();
    (dy + dx).div_scalar((n * c) as f64)
}

/// What the discriminator judges: the images masked by the occupancy probability, with that
/// probability as an extra plane, so empty pixels look alike in real and generated views.
///
/// # Shapes
/// `images`: `[B, V, C, S, S]`, `occupancy`: `[B, V, 1, S, S]` probabilities →
/// `[B·V, C+1, S, S]`
pub fn discriminator_input(images: Tensor<5>, occupancy: Tensor<5>) -> Tensor<4> {
    let [b, v, c, s, _] = images.dims();
    Tensor::cat(vec![images * occupancy.clone(), occupancy], 2).reshape([b * v, c + 1, s, s])
}

/// Each view's camera axis in the XYZ planes' coordinates: a pixel's depth is the dot product
/// of its XYZ with its view's axis (plus a constant, which differences cancel). The planes hold
/// the coordinates scaled by one factor and shifted, so the axes are the cameras' own.
///
/// # Shapes
/// → `[1, V, 3, 1, 1]`
pub fn depth_axes(cameras: &[Camera], device: &Device) -> Tensor<5> {
    let axes: Vec<f32> = cameras
        .iter()
        .flat_map(|c| (0..3).map(|k| c.rotation[(2, k)] as f32))
        .collect();
    Tensor::from_data(TensorData::new(axes, [1, cameras.len(), 3, 1, 1]), device)
}

/// Smooth L1 between the predicted and the true depth of the pixels the target occupies,
/// divided by the foreground fraction as the L1 term is.
///
/// # Shapes
/// `images`, `target.images`: `[B, V, C, S, S]` (C ≥ 3, XYZ first); `axes`: `[1, V, 3, 1, 1]`
pub fn depth_l1(images: Tensor<5>, target: &Target, axes: Tensor<5>) -> Tensor<1> {
    let error = images.narrow(2, 0, 3) - target.images.clone().narrow(2, 0, 3);
    // [B, V, 1, S, S]: the error's component along each view's axis, where the target has a point.
    let along = (error * axes).sum_dim(2) * target.occupancy.clone();
    smooth_l1(along.clone(), along.zeros_like()) / target.foreground()
}

/// One training sample's ground truth.
#[derive(Debug, Clone)]
pub struct Target {
    /// `[B, V, C, S, S]` in [0, 1], zero where empty.
    pub images: Tensor<5>,
    /// `[B, V, 1, S, S]`, 1 where occupied.
    pub occupancy: Tensor<5>,
    /// The occupied share of the whole micro-batch when this is one replica's part of it
    /// (`Gan::step_replicated`): the per-pixel terms divide by the whole batch's share, so the
    /// parts add up to the whole batch's loss.
    pub batch_foreground: Option<f32>,
}

impl Target {
    pub fn new(images: Tensor<5>, occupancy: Tensor<5>) -> Target {
        Target {
            images,
            occupancy,
            batch_foreground: None,
        }
    }

    /// The occupied share of the pixels (at least 1e-3), a constant that per-pixel terms are
    /// divided by so that sparse objects weigh the same as dense ones.
    pub fn foreground(&self) -> Tensor<1> {
        match self.batch_foreground {
            Some(share) => Tensor::from_floats([share], &self.occupancy.device()),
            None => self.occupancy.clone().mean(),
        }
        .clamp_min(1e-3)
        .detach()
    }
}

/// The generator's loss terms, unweighted, and their weighted sum.
pub struct GeneratorLosses {
    pub l1: Tensor<1>,
    pub adversarial: Tensor<1>,
    pub perceptual: Tensor<1>,
    pub style: Tensor<1>,
    pub occupancy: Tensor<1>,
    pub tv: Tensor<1>,
    pub depth: Tensor<1>,
    pub total: Tensor<1>,
}

/// The generator's objective for one batch. The smooth L1 term covers every output plane and
/// is divided by the foreground fraction as the original does, so sparse objects weigh the
/// same as dense ones. `real_features` are the discriminator's features of the real views
/// (constants), which the perceptual and style terms compare against when no VGG19 is given.
/// The depth term needs the views' `depth_axes`; without them it is zero. The adversarial,
/// perceptual and style terms are left at zero, not computed, when their weights are zero, and
/// the discriminator runs only when one of them needs it ([`LossWeights::needs_discriminator`]).
pub fn generator_losses(
    output: &GeneratorOutput,
    target: &Target,
    discriminator: &Discriminator,
    real_features: &[Tensor<4>],
    vgg: Option<&Vgg19>,
    depth_axes: Option<&Tensor<5>>,
    weights: &LossWeights,
) -> GeneratorLosses {
    let [b, v, _, s, _] = output.images.dims();
    let l1 = smooth_l1(output.images.clone(), target.images.clone()) / target.foreground();
    let occupancy = bce_with_logits(output.occupancy.clone(), target.occupancy.clone());

    let zero = || l1.zeros_like();
    let [adversarial, perceptual, style] =
        critics_losses(output, target, discriminator, real_features, vgg, weights);

    let geometry = output
        .images
        .clone()
        .narrow(2, 0, 3)
        .reshape([b * v, 3, s, s]);
    let tv = total_variation(geometry);
    let depth = match depth_axes {
        Some(axes) => depth_l1(output.images.clone(), target, axes.clone()),
        None => zero(),
    };

    let total = l1.clone().mul_scalar(weights.l1)
        + adversarial.clone().mul_scalar(weights.adversarial)
        + perceptual.clone().mul_scalar(weights.perceptual)
        + style.clone().mul_scalar(weights.style)
        + occupancy.clone().mul_scalar(weights.occupancy)
        + tv.clone()
            .mul_scalar(weights.tv / weights.tv_scale.divisor(s))
        + depth.clone().mul_scalar(weights.depth);
    GeneratorLosses {
        l1,
        adversarial,
        perceptual,
        style,
        occupancy,
        tv,
        depth,
        total,
    }
}

/// The adversarial, perceptual and style terms of [`generator_losses`], zero where their
/// weights are; the discriminator runs only when one of them needs it.
fn critics_losses(
    output: &GeneratorOutput,
    target: &Target,
    discriminator: &Discriminator,
    real_features: &[Tensor<4>],
    vgg: Option<&Vgg19>,
    weights: &LossWeights,
) -> [Tensor<1>; 3] {
    let zero = || Tensor::<1>::zeros([1], &output.images.device());
    let probability = burn::tensor::activation::sigmoid(output.occupancy.clone());
    let fake = weights.needs_discriminator(vgg.is_some()).then(|| {
        discriminator.forward(discriminator_input(
            output.images.clone(),
            probability.clone(),
        ))
    });
    let adversarial = match &fake {
        Some(fake) if weights.adversarial != 0.0 => {
            generator_adversarial(weights.adversarial_kind, fake.logits.clone())
        }
        _ => zero(),
    };
    let (perceptual, style) = match (weights.compares_features(), vgg, &fake) {
        (true, Some(vgg), _) => vgg_losses(vgg, output, probability, target, weights),
        (true, None, Some(fake)) => (
            self::perceptual(&fake.features, real_features),
            self::style(&fake.features, real_features),
        ),
        _ => (zero(), zero()),
    };
    [adversarial, perceptual, style]
}

/// The perceptual and style terms on VGG19's features of the masked views, the real views'
/// features held constant.
///
/// # Shapes
/// - `probability`: `[batch, views, 1, S, S]`, the occupancy after the sigmoid
/// - returns two `[1]` scalars
fn vgg_losses(
    vgg: &Vgg19,
    output: &GeneratorOutput,
    probability: Tensor<5>,
    target: &Target,
    weights: &LossWeights,
) -> (Tensor<1>, Tensor<1>) {
    let planes = |images: Tensor<5>| as_rgb(weights.feature_planes.of(images));
    let fake = vgg.forward(planes(output.images.clone() * probability));
    let real: Vec<Tensor<4>> = vgg
        .forward(planes(target.images.clone() * target.occupancy.clone()))
        .into_iter()
        .map(|f| f.detach())
        .collect();
    let pick = |maps: &[Tensor<4>], layers: &[usize]| -> Vec<Tensor<4>> {
        layers.iter().map(|&k| maps[k].clone()).collect()
    };
    (
        perceptual(
            &pick(&fake, &PERCEPTUAL_LAYERS),
            &pick(&real, &PERCEPTUAL_LAYERS),
        ),
        style(&pick(&fake, &STYLE_LAYERS), &pick(&real, &STYLE_LAYERS)),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use burn::tensor::TensorData;
    use std::f64::consts::LN_2;
    use std::slice;

    fn t1(values: &[f32]) -> Tensor<1> {
        Tensor::from_data(
            TensorData::new(values.to_vec(), [values.len()]),
            &Device::flex(),
        )
    }

    fn t4(values: &[f32], shape: [usize; 4]) -> Tensor<4> {
        Tensor::from_data(TensorData::new(values.to_vec(), shape), &Device::flex())
    }

    fn scalar(t: Tensor<1>) -> f64 {
        t.into_data().try_into_vec::<f32>().unwrap()[0] as f64
    }

    fn close(a: f64, b: f64) {
        assert!((a - b).abs() < 1e-5, "{a} vs {b}");
    }

    /// The text's scale divides the total-variation weight by the pixels, the original's by the
    /// side; the colour planes alone are those after the geometry (or the geometry alone).
    #[test]
    fn the_texts_tv_scale_and_feature_planes() {
        assert_eq!(TvScale::Side.divisor(256), 256.0);
        assert_eq!(TvScale::Pixels.divisor(256), 65536.0);
        let device = Device::flex();
        let planes = |c: usize| {
            let values: Vec<f32> = (0..c).map(|k| k as f32).collect();
            Tensor::<5>::from_data(TensorData::new(values, [1, 1, c, 1, 1]), &device)
        };
        let picked = |t: Tensor<5>| t.into_data().try_into_vec::<f32>().unwrap();
        assert_eq!(picked(FeaturePlanes::Colour.of(planes(6))), [3.0, 4.0, 5.0]);
        assert_eq!(picked(FeaturePlanes::Colour.of(planes(3))), [0.0, 1.0, 2.0]);
        assert_eq!(picked(FeaturePlanes::All.of(planes(6))).len(), 6);
    }

    #[test]
    fn smooth_l1_is_quadratic_below_one_and_linear_above() {
        // |d| = 0.5 → 0.125; |d| = 3 → 2.5; mean 1.3125.
        close(scalar(smooth_l1(t1(&[0.5, -3.0]), t1(&[0.0, 0.0]))), 1.3125);
    }

    #[test]
    fn bce_matches_the_textbook_formula_and_survives_large_logits() {
        let x = [-2.0f32, 0.0, 3.0, 80.0, -80.0];
        let t = [0.0f32, 1.0, 1.0, 0.0, 0.0];
        // t·softplus(−x) + (1 − t)·softplus(x), term by term.
        let expected = (0.126_928_011 + LN_2 + 0.048_587_352 + 80.0 + 0.0) / 5.0;
        let got = scalar(bce_with_logits(t1(&x), t1(&t)));
        assert!(
            (got - expected).abs() / expected < 1e-5,
            "{got} vs {expected}"
        );
    }

    #[test]
    fn hinge_losses() {
        let real = t4(&[2.0, 0.5], [1, 1, 1, 2]); // relu(1 − x): 0, 0.5 → mean 0.25
        let fake = t4(&[-2.0, 0.0], [1, 1, 1, 2]); // relu(1 + x): 0, 1 → mean 0.5
        close(
            scalar(discriminator_loss(Adversarial::Hinge, real, fake.clone())),
            0.375,
        );
        close(scalar(generator_adversarial(Adversarial::Hinge, fake)), 1.0);
    }

    #[test]
    fn non_saturating_losses() {
        let zero = t4(&[0.0], [1, 1, 1, 1]);
        close(
            scalar(discriminator_loss(
                Adversarial::NonSaturating,
                zero.clone(),
                zero.clone(),
            )),
            LN_2,
        );
        close(
            scalar(generator_adversarial(Adversarial::NonSaturating, zero)),
            LN_2,
        );
        // softplus(−2) for the real logit, softplus(−1) for the generated one, averaged.
        let (real, fake) = (t4(&[2.0], [1, 1, 1, 1]), t4(&[-1.0], [1, 1, 1, 1]));
        close(
            scalar(discriminator_loss(Adversarial::NonSaturating, real, fake)),
            (0.126_928_011 + 0.313_261_688) / 2.0,
        );
    }

    #[test]
    fn gram_and_style() {
        // One sample, two channels of two pixels: F = [[1, 2], [3, 4]], F·Fᵀ / 4.
        let f = t4(&[1.0, 2.0, 3.0, 4.0], [1, 2, 1, 2]);
        let g = gram(f.clone()).into_data().try_into_vec::<f32>().unwrap();
        assert_eq!(g, vec![1.25, 2.75, 2.75, 6.25]);
        close(scalar(style(slice::from_ref(&f), slice::from_ref(&f))), 0.0);
        let zero = f.zeros_like();
        close(
            scalar(style(slice::from_ref(&f), slice::from_ref(&zero))),
            13.0 / 4.0,
        );
        close(scalar(perceptual(&[f], &[zero])), 2.5);
    }

    fn t5(values: &[f32], shape: [usize; 5]) -> Tensor<5> {
        Tensor::from_data(TensorData::new(values.to_vec(), shape), &Device::flex())
    }

    #[test]
    fn depth_counts_only_the_error_along_the_axis_where_the_target_has_a_point() {
        let axes = t5(&[0.0, 0.0, 1.0], [1, 1, 3, 1, 1]);
        // Two pixels, planes X, Y, Z; the target at 0.5 everywhere.
        let target = |occupied: [f32; 2]| {
            Target::new(
                t5(&[0.5; 6], [1, 1, 3, 1, 2]),
                t5(&occupied, [1, 1, 1, 1, 2]),
            )
        };
        // Pixel 0 is off by 0.4 across the axis only, pixel 1 by 0.3 along it: 0.3²/2 over 2 pixels.
        let pred = t5(&[0.9, 0.5, 0.1, 0.5, 0.5, 0.8], [1, 1, 3, 1, 2]);
        close(
            scalar(depth_l1(pred.clone(), &target([1.0, 1.0]), axes.clone())),
            0.0225,
        );
        // Without a point at pixel 1 nothing is left, whatever is predicted there.
        close(scalar(depth_l1(pred, &target([1.0, 0.0]), axes)), 0.0);
    }

    #[test]
    fn depth_axes_are_the_cameras_viewing_directions() {
        let cameras = Camera::set(&crate::core::camera::DEFAULT_VIEWS, 64).unwrap();
        let axes = depth_axes(&cameras, &Device::flex());
        assert_eq!(axes.dims(), [1, 4, 3, 1, 1]);
        let axes = axes.into_data().try_into_vec::<f32>().unwrap();
        for (camera, axis) in cameras.iter().zip(axes.chunks(3)) {
            let p = nalgebra::Vector3::new(0.1, -0.2, 0.3);
            let depth = (camera.rotation * p + camera.translation)[2];
            let along = axis
                .iter()
                .zip(p.iter())
                .map(|(a, b)| *a as f64 * b)
                .sum::<f64>();
            close(along + camera.translation[2], depth);
        }
    }

    #[test]
    fn total_variation_counts_neighbour_steps() {
        // 2×3 plane: rows [0 1 3], [0 0 0]: horizontal |1|+|2| = 3, vertical 1+3 = 4.
        let x = t4(&[0.0, 1.0, 3.0, 0.0, 0.0, 0.0], [1, 1, 2, 3]);
        close(scalar(total_variation(x)), 7.0);
        close(scalar(total_variation(t4(&[5.0; 6], [1, 1, 2, 3]))), 0.0);
    }
}
