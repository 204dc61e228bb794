//! Building blocks shared by the generator and the discriminator, and the probe that lets
//! `mvpcc profile` time each kind of layer without a second copy of the forward pass.

use super::{cpu, Padding};
use crate::core::rng::Lcg;
use burn::module::{Module, Param, RunningState};
use burn::nn::conv::{Conv2d, Conv2dConfig, ConvTranspose2d, ConvTranspose2dConfig};
use burn::nn::{Initializer, InstanceNorm, InstanceNormConfig, PaddingConfig2d};
use burn::tensor::activation::relu;
use burn::tensor::module::conv2d;
use burn::tensor::ops::{ConvOptions, PadMode};
use burn::tensor::{Device, Tensor, TensorData};
use std::cell::Cell;

/// What a stretch of the forward pass is spent on, for the per-layer profile.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum LayerKind {
    ReflectPad,
    /// The 7×7 convolutions at full resolution (first and last).
    Conv7x7,
    /// The two stride-2 convolutions of the encoder.
    ConvDown,
    /// The 3×3 convolutions of the residual blocks (dilated and plain).
    ConvResidual,
    /// The 3×3 convolution over all views' features.
    Fusion,
    ConvTranspose,
    InstanceNorm,
    /// ReLU, residual sums, concatenation and reshapes, the output's tanh.
    Elementwise,
}

impl LayerKind {
    pub fn name(self) -> &'static str {
        match self {
            LayerKind::ReflectPad => "reflect pad",
            LayerKind::Conv7x7 => "conv 7x7",
            LayerKind::ConvDown => "conv 4x4 stride 2",
            LayerKind::ConvResidual => "conv 3x3 residual",
            LayerKind::Fusion => "conv 3x3 fusion",
            LayerKind::ConvTranspose => "conv transposed",
            LayerKind::InstanceNorm => "instance norm",
            LayerKind::Elementwise => "elementwise",
        }
    }
}

/// Sees every layer of a forward pass run. [`NoProbe`] is the ordinary forward; the profiler's
/// probe synchronizes the device around each call and books the time under `kind`.
pub trait Probe {
    fn layer<const D: usize>(
        &mut self,
        kind: LayerKind,
        run: impl FnOnce() -> Tensor<D>,
    ) -> Tensor<D>;
}

pub struct NoProbe;

impl Probe for NoProbe {
    fn layer<const D: usize>(
        &mut self,
        _kind: LayerKind,
        run: impl FnOnce() -> Tensor<D>,
    ) -> Tensor<D> {
        run()
    }
}

/// Convolution with the padding mode of the config, then instance norm (affine = false, as
/// the original) when asked; the activation is the caller's.
#[derive(Module, Debug)]
pub struct ConvNorm {
    conv: Conv2d,
    norm: Option<InstanceNorm>,
    /// Reflection padding applied before the convolution (zero when it is folded into it).
    reflect: usize,
    /// Zero padding, applied by the convolution.
    zeros: usize,
    /// Wide enough to run as [`shifted_conv`] on the CPU with gradients (without them every
    /// stride-1 convolution does, see [`Formulation`]).
    shifted: bool,
    #[module(skip)]
    kind: LayerKind,
}

/// How the layers are written down. Flex (the CPU) runs slices, concatenations and plain matrix
/// products faster than its generic pad and im2col kernels; on a GPU the same slices become many
/// small kernels that stop Burn's fusion, and the backward of each slice builds a full-size zero
/// tensor, while autotune picks a tuned kernel for a plain `conv2d`. Both write the same function
/// (tested to agree), so weights do not depend on it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Formulation {
    /// Sliced on the CPU, plain on any other device.
    Auto,
    /// `reflect_pad` from slices, `shifted_conv` for wide stride-1 layers and `strided_conv`
    /// for the encoder's stride-2 ones; in a forward pass on the CPU without gradients, every
    /// stride-1 convolution and instance norm runs the kernels of `model::cpu`.
    Sliced,
    /// Burn's `conv2d` and `PadMode::Reflect`.
    Plain,
}

thread_local! {
    /// The choice of the thread that runs the forward pass; `mvpcc profile --layers` sets it to
    /// measure one against the other. Per thread so that tests running side by side cannot see
    /// each other's choice.
    static FORMULATION: Cell<Formulation> = const { Cell::new(Formulation::Auto) };
}

impl Formulation {
    /// Sets the formulation for forward passes run on this thread.
    pub fn set(self) {
        FORMULATION.with(|f| f.set(self));
    }

    fn current() -> Formulation {
        FORMULATION.with(Cell::get)
    }

    /// Whether layers running on `device` use the sliced formulation.
    fn sliced_on(device: &Device) -> bool {
        match Formulation::current() {
            Formulation::Auto => crate::model::device::is_cpu(device),
            Formulation::Sliced => true,
            Formulation::Plain => false,
        }
    }
}

/// Input planes from which [`shifted_conv`] beats flex's convolution: measured on 2 cores, 1.2–1.5×
/// faster for the 3×3 convolutions at 32² and 64² with 128–256 planes and 2× for the 7×7 output
/// convolution (56 → 7 planes at 128²), but 2–7× slower for the 7×7 input convolution, whose 7
/// planes make each matrix product too thin.
const SHIFTED_MIN_INPUT_PLANES: usize = 32;

pub struct ConvSpec {
    pub channels: [usize; 2],
    pub kernel: usize,
    pub stride: usize,
    pub dilation: usize,
    /// Border pixels the convolution needs to keep the size (before the stride).
    pub pad: usize,
    pub norm: bool,
    pub kind: LayerKind,
}

impl ConvSpec {
    /// A convolution without dilation, then instance norm.
    pub fn normalized(
        channels: [usize; 2],
        kernel: usize,
        stride: usize,
        pad: usize,
        kind: LayerKind,
    ) -> ConvSpec {
        ConvSpec {
            channels,
            kernel,
            stride,
            dilation: 1,
            pad,
            norm: true,
            kind,
        }
    }
}

impl ConvNorm {
    /// `padding` applies to same-size convolutions; the stride-2 ones always zero-pad by one
    /// pixel, as the original.
    pub fn new(spec: ConvSpec, padding: Padding, device: &Device) -> ConvNorm {
        let reflect = if padding == Padding::Reflect && spec.stride == 1 {
            spec.pad
        } else {
            0
        };
        let zeros = spec.pad - reflect;
        let shifted = spec.stride == 1 && spec.channels[0] >= SHIFTED_MIN_INPUT_PLANES;
        let conv = Conv2dConfig::new(spec.channels, [spec.kernel; 2])
            .with_stride([spec.stride; 2])
            .with_dilation([spec.dilation; 2])
            .with_padding(PaddingConfig2d::Explicit(zeros, zeros, zeros, zeros))
            .with_initializer(gan_init())
            .init(device);
        let norm = spec.norm.then(|| {
            InstanceNormConfig::new(spec.channels[1])
                .with_affine(false)
                .init(device)
        });
        ConvNorm {
            conv,
            norm,
            reflect,
            zeros,
            shifted,
            kind: spec.kind,
        }
    }

    /// # Shapes
    /// `[n, c_in, h, w]` → `[n, c_out, h', w']`
    pub fn forward<P: Probe>(&self, x: Tensor<4>, probe: &mut P) -> Tensor<4> {
        let sliced = Formulation::sliced_on(&x.device());
        let p = self.reflect;
        let x = match (p, sliced) {
            (0, _) => x,
            (_, true) => probe.layer(LayerKind::ReflectPad, || reflect_pad(x, p)),
            (_, false) => probe.layer(LayerKind::ReflectPad, || {
                x.pad([(p, p), (p, p)], PadMode::Reflect)
            }),
        };
        let x = probe.layer(self.kind, || {
            let bias = || self.conv.bias.as_ref().map(|b| b.val());
            if sliced && self.halves(&x) {
                return strided_conv(x, self.conv.weight.val(), bias());
            }
            let as_products =
                sliced && self.conv.stride == [1, 1] && (self.shifted || cpu::applies(&x));
            if !as_products {
                return self.conv.forward(x);
            }
            let z = self.zeros;
            let x = if z > 0 {
                x.pad([(z, z), (z, z)], PadMode::Constant(0.0))
            } else {
                x
            };
            shifted_conv(x, self.conv.weight.val(), bias(), self.conv.dilation[0])
        });
        match &self.norm {
            Some(norm) => probe.layer(LayerKind::InstanceNorm, || instance_norm(norm, x, sliced)),
            None => x,
        }
    }

    /// Whether this is a 4×4 stride-2 convolution with one pixel of zero padding over an input
    /// of even sides (the encoder's), which [`strided_conv`] writes as plain matrix products.
    fn halves(&self, x: &Tensor<4>) -> bool {
        let [.., h, w] = x.dims();
        self.conv.stride == [2, 2]
            && self.conv.kernel_size == [4, 4]
            && self.zeros == 1
            && h % 2 == 0
            && w % 2 == 0
    }
}

/// `norm`'s instance normalization, with [`cpu::instance_norm`] where it applies and the layers
/// are `sliced`.
fn instance_norm(norm: &InstanceNorm, x: Tensor<4>, sliced: bool) -> Tensor<4> {
    if sliced && cpu::applies(&x) {
        cpu::instance_norm(x, norm.epsilon)
    } else {
        norm.forward(x)
    }
}

/// Reflection padding of the last two axes by `p` (< both sizes), as `PadMode::Reflect` but
/// built from flipped border slices and two concatenations, which flex runs faster than its
/// generic pad kernel (paper forward, 2 cores: 511 ms → 384 ms of padding).
pub fn reflect_pad(x: Tensor<4>, p: usize) -> Tensor<4> {
    let pad_axis = |x: Tensor<4>, axis: usize| {
        let n = x.dims()[axis];
        let before = x.clone().narrow(axis, 1, p).flip([axis]);
        let after = x.clone().narrow(axis, n - 1 - p, p).flip([axis]);
        Tensor::cat(vec![before, x, after], axis)
    };
    pad_axis(pad_axis(x, 3), 2)
}

/// Stride-1 convolution of an already padded input as k² matrix products, one per kernel tap,
/// each over a shifted window of the flattened image: no im2col buffer, and each product is a
/// plain gemm. The output is computed on the padded width and cropped.
///
/// # Shapes
/// `x`: `[n, c_in, h + span, w + span]` with `span = (k − 1)·dilation`, `weight`:
/// `[c_out, c_in, k, k]` → `[n, c_out, h, w]`
pub fn shifted_conv(
    x: Tensor<4>,
    weight: Tensor<4>,
    bias: Option<Tensor<1>>,
    dilation: usize,
) -> Tensor<4> {
    if cpu::applies(&x) {
        return cpu::conv(x, weight, bias, dilation);
    }
    let [n, c_in, hp, wp] = x.dims();
    let [c_out, _, k, _] = weight.dims();
    let span = (k - 1) * dilation;
    let (h, w) = (hp - span, wp - span);
    // The last valid output pixel reads the last input pixel, so windows of this length fit.
    let len = (h - 1) * wp + w;
    let flat = x.reshape([n, c_in, hp * wp]);
    let taps = weight.permute([2, 3, 0, 1]).reshape([k * k, c_out, c_in]);
    let mut sum: Option<Tensor<3>> = None;
    for ky in 0..k {
        for kx in 0..k {
            let window = flat.clone().narrow(2, (ky * wp + kx) * dilation, len); // [n, c_in, len]
            let tap = taps.clone().narrow(0, ky * k + kx, 1); // [1, c_out, c_in]
            let y = tap.matmul(window); // [n, c_out, len]
            sum = Some(match sum {
                Some(s) => s + y,
                None => y,
            });
        }
    }
    let y = sum
        .expect("a kernel has at least one tap")
        .pad([(0, wp - w)], PadMode::Constant(0.0))
        .reshape([n, c_out, h, wp])
        .narrow(3, 0, w); // [n, c_out, h, w]
    match bias {
        Some(b) => y + b.reshape([1, c_out, 1, 1]),
        None => y,
    }
}

/// 4×4 stride-2 convolution with one pixel of zero padding, as a 2×2 stride-1 [`shifted_conv`]
/// over the padded input's 2×2 pixel blocks stacked as planes (space to depth): the same sums,
/// but as plain matrix products over 4·c_in planes instead of flex's im2col.
///
/// # Shapes
/// `x`: `[n, c_in, h, w]` (h, w even), `weight`: `[c_out, c_in, 4, 4]` → `[n, c_out, h/2, w/2]`
pub fn strided_conv(x: Tensor<4>, weight: Tensor<4>, bias: Option<Tensor<1>>) -> Tensor<4> {
    let [n, c_in, h, w] = x.dims();
    let [c_out, ..] = weight.dims();
    let (hb, wb) = (h / 2 + 1, w / 2 + 1);
    let blocks = if cpu::applies(&x) {
        cpu::space_to_depth(x)
    } else {
        x.pad([(1, 1), (1, 1)], PadMode::Constant(0.0))
            .reshape([n * c_in, hb, 2, wb, 2])
            .permute([0, 2, 4, 1, 3])
            .reshape([n, c_in * 4, hb, wb]) // plane c·4 + 2·dy + dx
    };
    // Tap (2a + dy, 2b + dx) of the 4×4 kernel is tap (a, b) of plane (c, dy, dx).
    let weight = weight
        .reshape([c_out * c_in, 2, 2, 2, 2]) // [c_out·c_in, a, dy, b, dx]
        .permute([0, 2, 4, 1, 3])
        .reshape([c_out, c_in * 4, 2, 2]);
    shifted_conv(blocks, weight, bias, 1)
}

/// Transposed 4×4 stride-2 convolution (doubles the size), instance norm.
#[derive(Module, Debug)]
pub struct UpNorm {
    conv: ConvTranspose2d,
    norm: InstanceNorm,
}

impl UpNorm {
    /// With `dilation` 2 (the paper's text) the kernel spans 7 pixels, so the padding that keeps
    /// the output at twice the input is 3 with one more row and column at the end.
    pub fn new(channels: [usize; 2], dilation: usize, device: &Device) -> UpNorm {
        // (h − 1)·2 − 2·pad + dilation·3 + 1 + extra = 2h
        let (pad, extra) = match dilation {
            1 => (1, 0),
            2 => (3, 1),
            _ => unreachable!("the decoder is dilated by 1 or 2"),
        };
        UpNorm {
            conv: ConvTranspose2dConfig::new(channels, [4, 4])
                .with_stride([2, 2])
                .with_dilation([dilation; 2])
                .with_padding([pad; 2])
                .with_padding_out([extra; 2])
                .with_initializer(gan_init())
                .init(device),
            norm: InstanceNormConfig::new(channels[1])
                .with_affine(false)
                .init(device),
        }
    }

    /// # Shapes
    /// `[n, c_in, h, w]` → `[n, c_out, 2h, 2w]`
    pub fn forward<P: Probe>(&self, x: Tensor<4>, probe: &mut P) -> Tensor<4> {
        let x = probe.layer(LayerKind::ConvTranspose, || self.conv.forward(x));
        let sliced = Formulation::sliced_on(&x.device());
        probe.layer(LayerKind::InstanceNorm, || {
            instance_norm(&self.norm, x, sliced)
        })
    }
}

/// `x + IN(conv3×3(ReLU(IN(conv3×3 dilated d(x)))))`: the original's dilated residual block
/// with `d` 2, the paper's text's plain one with `d` 1.
#[derive(Module, Debug)]
pub struct ResBlock {
    dilated: ConvNorm,
    plain: ConvNorm,
}

impl ResBlock {
    pub fn new(channels: usize, padding: Padding, dilation: usize, device: &Device) -> ResBlock {
        let spec = |dilation| ConvSpec {
            channels: [channels; 2],
            kernel: 3,
            stride: 1,
            dilation,
            pad: dilation,
            norm: true,
            kind: LayerKind::ConvResidual,
        };
        ResBlock {
            dilated: ConvNorm::new(spec(dilation), padding, device),
            plain: ConvNorm::new(spec(1), padding, device),
        }
    }

    /// # Shapes
    /// `[n, c, h, w]` → `[n, c, h, w]`
    pub fn forward<P: Probe>(&self, x: Tensor<4>, probe: &mut P) -> Tensor<4> {
        let y = self.dilated.forward(x.clone(), probe);
        let y = probe.layer(LayerKind::Elementwise, || relu(y));
        let y = self.plain.forward(y, probe);
        probe.layer(LayerKind::Elementwise, || x + y)
    }
}

/// The original initializes every convolution with N(0, 0.02) (`init_weights('normal')`).
pub fn gan_init() -> Initializer {
    Initializer::Normal {
        mean: 0.0,
        std: 0.02,
    }
}

/// A 4×4 convolution whose weight is divided by its largest singular value, estimated by one
/// power-iteration step per training forward (Miyato et al. 2018, as `torch.nn.utils.
/// spectral_norm`). Burn has no such wrapper; the iteration vector `u` is running state, so it
/// is saved with the module and left untouched outside training.
#[derive(Module, Debug)]
pub struct SpectralConv2d {
    weight: Param<Tensor<4>>,
    bias: Option<Param<Tensor<1>>>,
    u: RunningState<Tensor<2>>,
    stride: usize,
    padding: usize,
}

const SN_EPS: f64 = 1e-12;

impl SpectralConv2d {
    pub fn new(
        channels: [usize; 2],
        kernel: usize,
        stride: usize,
        padding: usize,
        bias: bool,
        device: &Device,
    ) -> SpectralConv2d {
        let [c_in, c_out] = channels;
        let weight = gan_init().init([c_out, c_in, kernel, kernel], device);
        let bias = bias.then(|| Initializer::Zeros.init([c_out], device));
        // The power iteration's start is not in the weights files, so it is drawn from a fixed
        // seed rather than the device's generator: a discriminator loaded on any device, CPU or
        // GPU, estimates the same norm from its first step.
        let mut rng = Lcg::new(0x5eed_u64 ^ (c_out as u64) << 20 ^ c_in as u64);
        let start: Vec<f32> = (0..c_out).map(|_| rng.next_f64() as f32 - 0.5).collect();
        let u = Tensor::<2>::from_data(TensorData::new(start, [c_out, 1]), device);
        SpectralConv2d {
            weight,
            bias,
            u: RunningState::new(normalize(u)),
            stride,
            padding,
        }
    }

    /// A copy on `device` whose power-iteration state starts from this one's (synced on the
    /// calling thread) and is its own from then on.
    pub fn replica(&self, device: &Device) -> SpectralConv2d {
        SpectralConv2d {
            weight: self.weight.clone().fork(device),
            bias: self.bias.clone().map(|b| b.fork(device)),
            u: RunningState::new(self.u.value_sync().to_device(device)),
            stride: self.stride,
            padding: self.padding,
        }
    }

    /// The weight divided by its estimated spectral norm; advances the power iteration when
    /// the device records gradients.
    pub fn normalized_weight(&self) -> Tensor<4> {
        let w = self.weight.val();
        let [c_out, c_in, kh, kw] = w.dims();
        let matrix = w.clone().reshape([c_out, c_in * kh * kw]); // [out, in·k·k]
        let fixed = matrix.clone().detach();
        let training = w.device().is_autodiff();
        let u = if training {
            self.u.value_sync()
        } else {
            self.u.value()
        }
        .to_device(&w.device())
        .detach(); // [out, 1]
        let v = normalize(fixed.clone().transpose().matmul(u.clone())); // [in·k·k, 1]
        let u = if training {
            let u = normalize(fixed.matmul(v.clone()));
            self.u.update(u.clone());
            u
        } else {
            u
        };
        let sigma = u.transpose().matmul(matrix.matmul(v)); // [1, 1]
        w / sigma.reshape([1, 1, 1, 1])
    }

    /// # Shapes
    /// `[n, c_in, h, w]` → `[n, c_out, h', w']`
    pub fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let options = ConvOptions::new([self.stride; 2], [self.padding; 2], [1, 1], 1);
        conv2d(
            x,
            self.normalized_weight(),
            self.bias.as_ref().map(|b| b.val()),
            options,
        )
    }
}

/// `x / |x|` for a column vector `[n, 1]`.
fn normalize(x: Tensor<2>) -> Tensor<2> {
    let norm = x.clone().powf_scalar(2.0).sum().sqrt().add_scalar(SN_EPS); // [1]
    x / norm.reshape([1, 1])
}

#[cfg(test)]
mod tests {
    use super::*;
    use burn::tensor::Distribution;

    /// Largest singular value of a row-major `rows × cols` matrix, by power iteration in f64.
    fn spectral_norm(m: &[f32], rows: usize, cols: usize) -> f64 {
        let mut v = vec![1.0f64; cols];
        let mut sigma = 0.0;
        for _ in 0..2000 {
            let u: Vec<f64> = (0..rows)
                .map(|r| (0..cols).map(|c| m[r * cols + c] as f64 * v[c]).sum())
                .collect();
            let w: Vec<f64> = (0..cols)
                .map(|c| (0..rows).map(|r| m[r * cols + c] as f64 * u[r]).sum())
                .collect();
            let n = w.iter().map(|x| x * x).sum::<f64>().sqrt();
            sigma = n.sqrt();
            v = w.iter().map(|x| x / n).collect();
        }
        sigma
    }

    fn weight_matrix(conv: &SpectralConv2d) -> (Vec<f32>, usize, usize) {
        let w = conv.normalized_weight();
        let [o, i, kh, kw] = w.dims();
        let data = w.into_data().try_into_vec::<f32>().unwrap();
        (data, o, i * kh * kw)
    }

    #[test]
    fn spectral_norm_of_the_normalized_weight_converges_to_one() {
        let device = Device::flex().autodiff();
        device.seed(3);
        let conv = SpectralConv2d::new([5, 7], 4, 2, 1, true, &device);
        let raw = conv.weight.val().into_data().try_into_vec::<f32>().unwrap();
        let raw_sigma = spectral_norm(&raw, 7, 80);
        assert!(
            (raw_sigma - 1.0).abs() > 0.3,
            "test needs a weight far from unit norm"
        );
        let x = Tensor::<4>::ones([1, 5, 8, 8], &device);
        // One power-iteration step per forward; the estimate converges at (σ₂/σ₁)² a step,
        // which for random 7×80 weights measured up to 1.0005 after 30 steps.
        for _ in 0..100 {
            let _ = conv.forward(x.clone());
        }
        let (m, rows, cols) = weight_matrix(&conv);
        let sigma = spectral_norm(&m, rows, cols);
        assert!((sigma - 1.0).abs() < 1e-3, "σ = {sigma}");
    }

    #[test]
    fn inference_leaves_the_iteration_vector_alone() {
        let device = Device::flex();
        let conv = SpectralConv2d::new([3, 4], 4, 1, 1, false, &device);
        let before = conv.u.value().into_data();
        let x =
            Tensor::<4>::from_data(TensorData::new(vec![0.5f32; 3 * 36], [1, 3, 6, 6]), &device);
        let a = conv.forward(x.clone()).into_data();
        let b = conv.forward(x).into_data();
        assert_eq!(a, b);
        assert_eq!(conv.u.value().into_data(), before);
    }

    #[test]
    fn shifted_conv_matches_flex_convolution() {
        let device = Device::flex();
        for (c_in, c_out, k, dilation, h, w) in
            [(3, 5, 3, 1, 6, 9), (4, 2, 3, 2, 9, 7), (2, 3, 7, 1, 8, 8)]
        {
            let pad = (k - 1) * dilation / 2;
            let x = Tensor::<4>::random([2, c_in, h, w], Distribution::Default, &device);
            let weight = Tensor::<4>::random([c_out, c_in, k, k], Distribution::Default, &device);
            let bias = Tensor::<1>::random([c_out], Distribution::Default, &device);
            let options = ConvOptions::new([1, 1], [pad, pad], [dilation, dilation], 1);
            let reference = conv2d(x.clone(), weight.clone(), Some(bias.clone()), options);
            let padded = x.pad([(pad, pad), (pad, pad)], PadMode::Constant(0.0));
            let ours = shifted_conv(padded, weight, Some(bias), dilation);
            assert_eq!(ours.dims(), [2, c_out, h, w]);
            let err = (ours - reference).abs().max().into_scalar::<f32>();
            assert!(err < 1e-4, "k {k} d {dilation}: {err}");
        }
    }

    #[test]
    fn strided_conv_matches_flex_convolution() {
        let device = Device::flex();
        for (c_in, c_out, h, w) in [(3, 5, 6, 8), (2, 4, 4, 10)] {
            let x = Tensor::<4>::random([2, c_in, h, w], Distribution::Default, &device);
            let bias = Tensor::<1>::random([c_out], Distribution::Default, &device);
            let weight = Tensor::<4>::random([c_out, c_in, 4, 4], Distribution::Default, &device);
            let options = ConvOptions::new([2, 2], [1, 1], [1, 1], 1);
            let reference = conv2d(x.clone(), weight.clone(), Some(bias.clone()), options);
            let ours = strided_conv(x, weight, Some(bias));
            assert_eq!(ours.dims(), [2, c_out, h / 2, w / 2]);
            let err = (ours - reference).abs().max().into_scalar::<f32>();
            assert!(err < 1e-4, "{c_in}→{c_out}: {err}");
        }
    }

    /// On the CPU without autodiff the sliced layers run [`cpu`]'s kernels: the same values as
    /// Burn's layers, through every kind of layer of the generator.
    #[test]
    fn the_cpu_inference_kernels_agree_with_burns_layers() {
        let device = Device::flex();
        let planes = 8;
        let input = Tensor::<4>::random([2, 7, 16, 12], Distribution::Default, &device);
        for padding in [Padding::Reflect, Padding::Zero] {
            let spec = ConvSpec::normalized;
            let head = ConvNorm::new(
                spec([7, planes], 7, 1, 3, LayerKind::Conv7x7),
                padding,
                &device,
            );
            let down = ConvNorm::new(
                spec([planes, 2 * planes], 4, 2, 1, LayerKind::ConvDown),
                padding,
                &device,
            );
            let block = ResBlock::new(2 * planes, padding, 2, &device);
            let up = UpNorm::new([2 * planes, planes], 1, &device);
            let run = |formulation: Formulation| {
                formulation.set();
                let y = head.forward(input.clone(), &mut NoProbe);
                let y = block.forward(down.forward(y, &mut NoProbe), &mut NoProbe);
                let y = up.forward(y, &mut NoProbe);
                Formulation::Auto.set();
                y
            };
            let (sliced, plain) = (run(Formulation::Sliced), run(Formulation::Plain));
            assert_eq!(sliced.dims(), [2, planes, 16, 12]);
            let err = (sliced - plain).abs().max().into_scalar::<f32>();
            assert!(err < 1e-4, "{padding:?}: {err}");
        }
    }

    /// Both formulations of the layers that have two (reflection padding, wide stride-1
    /// convolutions, stride-2 convolutions), values and input gradients.
    #[test]
    fn sliced_and_plain_formulations_agree_in_value_and_gradient() {
        let device = Device::flex().autodiff();
        let planes = SHIFTED_MIN_INPUT_PLANES;
        // A varied input: on a constant one, reflection keeps every map constant and instance
        // norm divides rounding noise by a near-zero spread.
        let input = Tensor::<4>::random([1, 7, 16, 16], Distribution::Default, &device);
        let run = |formulation: Formulation, block: &ResBlock, head: &ConvNorm, down: &ConvNorm| {
            formulation.set();
            let x = input.clone().detach().require_grad();
            let y = head.forward(x.clone(), &mut NoProbe);
            let y = block.forward(down.forward(y, &mut NoProbe), &mut NoProbe);
            let grads = y.clone().powf_scalar(2.0).sum().backward();
            let dx = x.grad(&grads).unwrap();
            Formulation::Auto.set();
            (y.detach(), dx)
        };
        for padding in [Padding::Reflect, Padding::Zero] {
            let block = ResBlock::new(planes, padding, 2, &device);
            assert!(block.dilated.shifted && block.plain.shifted);
            let head = ConvNorm::new(
                ConvSpec::normalized([7, planes], 7, 1, 3, LayerKind::Conv7x7),
                padding,
                &device,
            );
            let down = ConvNorm::new(
                ConvSpec::normalized([planes, planes], 4, 2, 1, LayerKind::ConvDown),
                padding,
                &device,
            );
            let (ys, dxs) = run(Formulation::Sliced, &block, &head, &down);
            let (yp, dxp) = run(Formulation::Plain, &block, &head, &down);
            // Relative to the largest entry, since the random weights set the scale: measured
            // 4e-7 to 8e-7 apart (rounding of sums taken in another order).
            let relative = |a: Tensor<4>, b: Tensor<4>| {
                let scale = a.clone().abs().max().into_scalar::<f32>().max(1e-6);
                (a - b).abs().max().into_scalar::<f32>() / scale
            };
            let err = relative(ys, yp);
            assert!(err < 1e-5, "{padding:?} value: {err}");
            let err = relative(dxs, dxp);
            assert!(err < 1e-5, "{padding:?} gradient: {err}");
        }
    }

    #[test]
    fn reflect_pad_matches_burns_reflect_mode() {
        let device = Device::flex();
        let x = Tensor::<4>::random([2, 3, 7, 9], Distribution::Default, &device);
        for p in [1, 2, 3] {
            let ours = reflect_pad(x.clone(), p);
            let burn = x.clone().pad([(p, p), (p, p)], PadMode::Reflect);
            assert_eq!(ours.into_data(), burn.into_data(), "p = {p}");
        }
    }

    #[test]
    fn reflect_and_zero_padding_keep_the_size() {
        let device = Device::flex();
        for padding in [Padding::Reflect, Padding::Zero] {
            let block = ResBlock::new(4, padding, 2, &device);
            let x = Tensor::<4>::random([2, 4, 9, 9], Distribution::Default, &device);
            assert_eq!(block.forward(x, &mut NoProbe).dims(), [2, 4, 9, 9]);
        }
    }
}
