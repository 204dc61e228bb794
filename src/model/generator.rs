//! The inpainting generator: a per-view encoder with dilated residual blocks, a fusion
//! convolution over all views' bottleneck features, and a per-view decoder that sees its own
//! features beside the fused ones. Encoder and decoder weights are shared by the views.
//! With [`ModelConfig::copies_input`], the output keeps the input's pixels where it has them.

use super::layers::{ConvNorm, ConvSpec, LayerKind, Probe, ResBlock, UpNorm};
use super::{Dilation, Fusion, ModelConfig, Padding};
use burn::module::Module;
use burn::tensor::activation::relu;
use burn::tensor::{s, Device, Tensor};

/// The occupancy logit of a pixel the input has, with [`ModelConfig::copies_input`]: certain
/// (sigmoid ≈ 1 − 2e-9).
const MEASURED_LOGIT: f32 = 20.0;

#[derive(Module, Debug)]
pub struct Generator {
    stem: ConvNorm,
    down: Vec<ConvNorm>,
    middle: Vec<ResBlock>,
    fusion: ConvNorm,
    up: Vec<UpNorm>,
    head: ConvNorm,
    views: usize,
    channels: usize,
    /// `fusion` reads the input images (early fusion) rather than the bottleneck features.
    early_fusion: bool,
    /// The output keeps the input's pixels ([`ModelConfig::copies_input`]).
    copy_input: bool,
}

/// What the generator returns for a batch of objects.
#[derive(Debug, Clone)]
pub struct GeneratorOutput {
    /// `[batch, views, channels, S, S]` in [0, 1]: geometry (and colour) for every pixel.
    pub images: Tensor<5>,
    /// `[batch, views, 1, S, S]`: logit of the pixel being part of the completed object.
    pub occupancy: Tensor<5>,
}

impl Generator {
    pub(super) fn new(config: &ModelConfig, device: &Device) -> Generator {
        let w = config.width;
        let early_fusion = config.fusion() == Fusion::Early;
        let planes = config.input_channels();
        // Parts are made in the order of the layers (stem, down, middle, fusion, up, head):
        // a seeded fresh network's initial weights follow that order.
        let (stem, down, middle) = Self::encoder(config, device);
        // The original's fusion convolution zero-pads; the config's padding mode is kept for
        // all same-size convolutions alike so `Padding::Zero` removes every reflection.
        let fusion_channels = if early_fusion {
            [config.views * planes, w]
        } else {
            [config.views * 4 * w, 4 * w]
        };
        let fusion = ConvNorm::new(
            ConvSpec {
                norm: config.normalizes_fusion(),
                ..ConvSpec::normalized(fusion_channels, 3, 1, 1, LayerKind::Fusion)
            },
            Padding::Zero,
            device,
        );
        let (up, head) = Self::decoder(config, device);
        Generator {
            stem,
            down,
            middle,
            fusion,
            up,
            head,
            views: config.views,
            channels: config.channels.count(),
            early_fusion,
            copy_input: config.copies_input(),
        }
    }

    /// The per-view encoder: a 7×7 stem, two strided halvings to 4·width channels, and the
    /// residual blocks.
    fn encoder(config: &ModelConfig, device: &Device) -> (ConvNorm, Vec<ConvNorm>, Vec<ResBlock>) {
        let (w, padding) = (config.width, config.padding);
        let planes = config.input_channels();
        // Early fusion adds w fused planes to each view's input.
        let stem_in = if config.fusion() == Fusion::Early {
            planes + w
        } else {
            planes
        };
        let stem = ConvNorm::new(
            ConvSpec::normalized([stem_in, w], 7, 1, 3, LayerKind::Conv7x7),
            padding,
            device,
        );
        let down = [[w, 2 * w], [2 * w, 4 * w]]
            .map(|channels| {
                ConvNorm::new(
                    ConvSpec::normalized(channels, 4, 2, 1, LayerKind::ConvDown),
                    padding,
                    device,
                )
            })
            .into();
        let dilation = match config.dilation() {
            Dilation::Encoder => 2,
            Dilation::Decoder => 1,
        };
        let middle = (0..config.res_blocks)
            .map(|_| ResBlock::new(4 * w, padding, dilation, device))
            .collect();
        (stem, down, middle)
    }

    /// The per-view decoder: two doublings back to width channels and a 7×7 head to the
    /// output's channels and the occupancy logit.
    fn decoder(config: &ModelConfig, device: &Device) -> (Vec<UpNorm>, ConvNorm) {
        let w = config.width;
        // Late fusion puts the fused features beside each view's own.
        let decoder_in = if config.fusion() == Fusion::Early {
            4 * w
        } else {
            8 * w
        };
        let dilation = match config.dilation() {
            Dilation::Encoder => 1,
            Dilation::Decoder => 2,
        };
        let up = vec![
            UpNorm::new([decoder_in, 2 * w], dilation, device),
            UpNorm::new([2 * w, w], dilation, device),
        ];
        let outputs = config.channels.count() + 1;
        let head = ConvNorm::new(
            ConvSpec {
                norm: false,
                ..ConvSpec::normalized([w, outputs], 7, 1, 3, LayerKind::Conv7x7)
            },
            config.padding,
            device,
        );
        (up, head)
    }

    /// # Shapes
    /// `input`: `[batch, views, channels + 1, S, S]` (the last plane is the input's occupancy).
    pub fn forward(&self, input: Tensor<5>) -> GeneratorOutput {
        self.forward_probed(input, &mut super::NoProbe)
    }

    /// [`Self::forward`] with every layer run through `probe`.
    pub fn forward_probed<P: Probe>(&self, input: Tensor<5>, probe: &mut P) -> GeneratorOutput {
        let [batch, _, _, size, _] = input.dims();
        let features = self.encode(input.clone(), probe);
        let joined = self.fuse(features, batch, probe);
        self.decode(joined, &input, batch, size, probe)
    }

    /// The shared per-view encoder: stem, two stride-2 downsamplings, dilated residual blocks
    /// (after the fusion of the input images, with early fusion).
    ///
    /// # Shapes
    /// `input`: `[batch, views, channels + 1, S, S]` → `[batch · views, 4w, S/4, S/4]`
    pub fn encode<P: Probe>(&self, input: Tensor<5>, probe: &mut P) -> Tensor<4> {
        let [batch, views, planes, size, _] = input.dims();
        assert_eq!(
            views, self.views,
            "the generator was built for {} views",
            self.views
        );
        assert_eq!(planes, self.channels + 1, "input planes");
        let x = input.reshape([batch * views, planes, size, size]); // [B·V, C+1, S, S]
        let x = if self.early_fusion {
            self.fuse_views(x, batch, probe) // [B·V, C+1+w, S, S]
        } else {
            x
        };

        let mut x = self.stem.forward(x, probe);
        x = probe.layer(LayerKind::Elementwise, || relu(x));
        for down in &self.down {
            x = down.forward(x, probe);
            x = probe.layer(LayerKind::Elementwise, || relu(x));
        }
        for block in &self.middle {
            x = block.forward(x, probe);
        }
        x
    }

    /// Late fusion of the encoder's features (nothing with early fusion, which happened in
    /// [`Self::encode`]).
    ///
    /// # Shapes
    /// `features`: `[batch · views, 4w, S/4, S/4]` → `[batch · views, 8w, S/4, S/4]` (late) or
    /// unchanged (early)
    pub fn fuse<P: Probe>(&self, features: Tensor<4>, batch: usize, probe: &mut P) -> Tensor<4> {
        if self.early_fusion {
            return features;
        }
        self.fuse_views(features, batch, probe)
    }

    /// One convolution over all views' planes, its result beside each view's own.
    ///
    /// # Shapes
    /// `x`: `[batch · views, c, h, w]` → `[batch · views, c + f, h, w]`, `f` the fusion
    /// convolution's output channels
    fn fuse_views<P: Probe>(&self, x: Tensor<4>, batch: usize, probe: &mut P) -> Tensor<4> {
        let views = self.views;
        let [_, c, h, w] = x.dims(); // [B·V, c, h, w]
        let all = x.clone().reshape([batch, views * c, h, w]); // [B, V·c, h, w]
        let fused = self.fusion.forward(all, probe); // [B, f, h, w]
        let [_, f, _, _] = fused.dims();
        let fused = probe.layer(LayerKind::Elementwise, || {
            relu(fused)
                .unsqueeze_dim::<5>(1)
                .expand([batch, views, f, h, w])
                .reshape([batch * views, f, h, w])
        }); // [B·V, f, h, w]
        probe.layer(LayerKind::Elementwise, || Tensor::cat(vec![x, fused], 1)) // [B·V, c+f, h, w]
    }

    /// The shared per-view decoder; `input` is what [`Self::encode`] read (for the input copy).
    ///
    /// # Shapes
    /// `x`: `[batch · views, 8w (late) or 4w (early), S/4, S/4]`, `input`: `[batch, views,
    /// channels + 1, S, S]` → images `[batch, views, channels, S, S]`,
    /// occupancy `[batch, views, 1, S, S]`
    pub fn decode<P: Probe>(
        &self,
        mut x: Tensor<4>,
        input: &Tensor<5>,
        batch: usize,
        size: usize,
        probe: &mut P,
    ) -> GeneratorOutput {
        for up in &self.up {
            x = up.forward(x, probe);
            x = probe.layer(LayerKind::Elementwise, || relu(x));
        }
        let x = self.head.forward(x, probe); // [B·V, C+1, S, S]
        let c = self.channels;
        let x = probe.layer(LayerKind::Elementwise, || {
            let images = x
                .clone()
                .narrow(1, 0, c)
                .tanh()
                .add_scalar(1.0)
                .div_scalar(2.0); // [B·V, C, S, S]
            Tensor::cat(vec![images, x.narrow(1, c, 1)], 1)
        }); // [B·V, C+1, S, S]
        let x = x.reshape([batch, self.views, c + 1, size, size]); // [B, V, C+1, S, S]
        let x = if self.copy_input {
            probe.layer(LayerKind::Elementwise, || copy_input(x, input))
        } else {
            x
        };
        GeneratorOutput {
            images: x.clone().narrow(2, 0, c),
            occupancy: x.narrow(2, c, 1),
        }
    }
}

/// The input's pixels in place of the prediction's, where the input has one: its geometry and
/// colour, and an occupancy logit of [`MEASURED_LOGIT`]. A measured point is exact to the
/// metrics, which score points against the true surface, while a pixel of the ground truth's
/// view is one sample of a footprint 1.6 % of the object wide at 64²: trained to that target,
/// a learned blend closed itself and the network alone lost F1 (lab/2026-12-02-input-copy).
///
/// # Shapes
/// `prediction`, `input`: `[batch, views, C + 1, S, S]` (images, then the occupancy logit or
/// the input's mask) → `[batch, views, C + 1, S, S]`
fn copy_input(prediction: Tensor<5>, input: &Tensor<5>) -> Tensor<5> {
    let dims = prediction.dims();
    let mask = input.clone().slice(s![.., .., -1.., .., ..]).expand(dims); // [B, V, C+1, S, S]
    let measured = input
        .clone()
        .slice_fill(s![.., .., -1.., .., ..], MEASURED_LOGIT); // [B, V, C+1, S, S]
    prediction.clone() + (measured - prediction) * mask
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::{Channels, Preset};
    use burn::tensor::Distribution;

    #[test]
    fn output_shapes_ranges_and_finiteness() {
        let device = Device::flex();
        for channels in [Channels::Xyz, Channels::Xyzrgb] {
            let config = Preset::Tiny.config().with_channels(channels).with_views(3);
            let g = config.init_generator(&device).unwrap();
            let c = channels.count();
            let x = Tensor::<5>::random([2, 3, c + 1, 32, 32], Distribution::Default, &device);
            let out = g.forward(x);
            assert_eq!(out.images.dims(), [2, 3, c, 32, 32]);
            assert_eq!(out.occupancy.dims(), [2, 3, 1, 32, 32]);
            let images = out.images.into_data().try_into_vec::<f32>().unwrap();
            assert!(images.iter().all(|v| (0.0..=1.0).contains(v)));
            let logits = out.occupancy.into_data().try_into_vec::<f32>().unwrap();
            assert!(logits.iter().all(|v| v.is_finite()));
        }
    }

    /// `--config paper`'s network (the text's dilation, no norm after fusion) keeps every view's
    /// size and is built as its config says, which the original's is not.
    #[test]
    fn the_texts_network_dilates_its_decoder_and_fuses_without_norm() {
        let device = Device::flex();
        let text = Preset::Tiny
            .config()
            .with_dilation(Some(Dilation::Decoder))
            .with_fusion_norm(Some(false));
        for size in [32, 48] {
            let config = text.clone().with_size(size);
            let g = config.init_generator(&device).unwrap();
            let x = Tensor::<5>::random([1, 4, 7, size, size], Distribution::Default, &device);
            let out = g.forward(x);
            assert_eq!(out.images.dims(), [1, 4, 6, size, size]);
        }
        // The layers as built, in their debug form: where the dilation 2 is, and whether the
        // fusion convolution has its norm.
        let built = |config: &ModelConfig| {
            let g = config.init_generator(&device).unwrap();
            let dilated = |part: String| part.matches("dilation: [2, 2]").count();
            (
                dilated(format!("{:?}", g.middle)),
                dilated(format!("{:?}", g.up)),
                format!("{:?}", g.fusion).contains("norm: None"),
            )
        };
        assert_eq!(built(&text), (0, 2, true));
        assert_eq!(built(&Preset::Tiny.config()), (1, 0, false));
    }

    /// A config asking for the copy builds it. Where the input has a pixel the output is the
    /// input's, and certainly occupied; elsewhere it is the prediction of the same weights
    /// without the copy.
    #[test]
    fn the_input_copy_keeps_the_inputs_pixels_and_changes_nothing_else() {
        let device = Device::flex();
        let plain = Preset::Tiny.config().with_views(1);
        let g = plain.init_generator(&device).unwrap();
        let built = plain.clone().with_input_copy_kind(true);
        assert!(built.init_generator(&device).unwrap().copy_input);
        let copying = Generator {
            copy_input: true,
            ..g.clone()
        };
        let s = 32;
        let values = Tensor::<5>::random([1, 1, 6, s, s], Distribution::Default, &device);
        let mask: Vec<f32> = (0..s * s).map(|i| (i % 3 == 0) as u8 as f32).collect();
        let mask = Tensor::<1>::from_floats(mask.as_slice(), &device).reshape([1, 1, 1, s, s]);
        let x = Tensor::cat(vec![values.clone(), mask], 2);
        let flat = |t: Tensor<5>| t.into_data().try_into_vec::<f32>().unwrap();
        let (pred, out) = (g.forward(x.clone()), copying.forward(x));
        let input = flat(values);
        let (pred_images, out_images) = (flat(pred.images), flat(out.images));
        let (pred_occupancy, out_occupancy) = (flat(pred.occupancy), flat(out.occupancy));
        let measured = |i: usize| (i % (s * s)).is_multiple_of(3);
        for (i, ((p, o), x)) in pred_images.iter().zip(&out_images).zip(&input).enumerate() {
            if measured(i) {
                assert!(
                    (o - x).abs() < 1e-6,
                    "pixel {i}: {o} is not the input's {x}"
                );
            } else {
                assert_eq!(o, p, "pixel {i} has no input");
            }
        }
        for (i, (p, o)) in pred_occupancy.iter().zip(&out_occupancy).enumerate() {
            if measured(i) {
                assert!(*o > 19.9, "pixel {i}: occupancy logit {o}");
            } else {
                assert_eq!(o, p, "pixel {i} has no input");
            }
        }
    }

    #[test]
    fn views_are_fused_and_objects_are_not() {
        for fusion in [Fusion::Late, Fusion::Early] {
            views_are_fused_with(fusion);
        }
    }

    /// Changing view 0 of object 0 must change the other views of object 0 (through the fusion
    /// convolution) and leave object 1 alone.
    fn views_are_fused_with(fusion: Fusion) {
        let device = Device::flex();
        let config = Preset::Tiny.config().with_fusion_kind(fusion);
        let g = config.init_generator(&device).unwrap();
        let shape = [2, 4, 7, 32, 32];
        let x = Tensor::<5>::random(shape, Distribution::Default, &device);
        let bump = Tensor::<5>::zeros(shape, &device).slice_assign(
            [0..1, 0..1, 0..7, 0..32, 0..32],
            // Not a constant: instance norm would cancel a uniform shift.
            Tensor::random([1, 1, 7, 32, 32], Distribution::Default, &device),
        );
        let a = g.forward(x.clone()).images;
        let b = g.forward(x + bump).images;
        let diff = |o: usize, v: usize| {
            let range = [o..o + 1, v..v + 1, 0..6, 0..32, 0..32];
            (a.clone().slice(range.clone()) - b.clone().slice(range))
                .abs()
                .max()
                .into_scalar::<f32>()
        };
        assert!(
            diff(0, 2) > 1e-6,
            "other views of the object see the change"
        );
        assert_eq!(diff(1, 0), 0.0, "another object does not");
        assert_eq!(diff(1, 3), 0.0);
    }
}
