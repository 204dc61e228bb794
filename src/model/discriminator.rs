//! 70×70 PatchGAN discriminator with spectral normalization, shared over views: each view is
//! judged on its own, patch by patch.

use super::layers::SpectralConv2d;
use super::ModelConfig;
use burn::module::Module;
use burn::tensor::activation::leaky_relu;
use burn::tensor::{Device, Tensor};

#[derive(Module, Debug)]
pub struct Discriminator {
    convs: Vec<SpectralConv2d>,
}

pub struct DiscriminatorOutput {
    /// `[n, 1, S/8 − 2, S/8 − 2]`: one real/fake logit per 70×70 patch.
    pub logits: Tensor<4>,
    /// Activations after each hidden layer: what the perceptual and style losses compare when
    /// no VGG19 weights are given.
    pub features: Vec<Tensor<4>>,
}

const SLOPE: f64 = 0.2;

impl Discriminator {
    pub(super) fn new(config: &ModelConfig, device: &Device) -> Discriminator {
        let d = config.disc_width;
        // The image planes plus the occupancy probability.
        let planes = config.channels.count() + 1;
        let layers = [
            (planes, d, 2),
            (d, 2 * d, 2),
            (2 * d, 4 * d, 2),
            (4 * d, 8 * d, 1),
            (8 * d, 1, 1),
        ];
        // Spectral norm makes the bias redundant; the original drops it (bias = not use_sn).
        let convs = layers
            .iter()
            .map(|&(c_in, c_out, stride)| {
                SpectralConv2d::new([c_in, c_out], 4, stride, 1, false, device)
            })
            .collect();
        Discriminator { convs }
    }

    /// A copy on `device` for another data-parallel replica: the weights forked (their
    /// gradients its own), the power iteration's state its own, so that only the networks'
    /// own replica advances theirs.
    pub fn replica(&self, device: &Device) -> Discriminator {
        Discriminator {
            convs: self.convs.iter().map(|c| c.replica(device)).collect(),
        }
    }

    /// # Shapes
    /// `input`: `[n, channels + 1, S, S]`, images in [0, 1] with the occupancy probability as
    /// the last plane.
    pub fn forward(&self, input: Tensor<4>) -> DiscriminatorOutput {
        let last = self.convs.len() - 1;
        let mut features = Vec::with_capacity(last);
        let mut x = input;
        for conv in &self.convs[..last] {
            x = leaky_relu(conv.forward(x), SLOPE);
            features.push(x.clone());
        }
        DiscriminatorOutput {
            logits: self.convs[last].forward(x),
            features,
        }
    }
}

#[cfg(test)]
mod tests {
    use crate::model::Preset;
    use burn::tensor::{Device, Distribution, Tensor};

    #[test]
    fn patch_logits_and_features_have_the_patchgan_shapes() {
        let device = Device::flex();
        let config = Preset::Tiny.config().with_size(64);
        let d = config.init_discriminator(&device).unwrap();
        let x = Tensor::<4>::random([3, 7, 64, 64], Distribution::Default, &device);
        let out = d.forward(x);
        assert_eq!(out.logits.dims(), [3, 1, 6, 6]);
        let shapes: Vec<[usize; 4]> = out.features.iter().map(|f| f.dims()).collect();
        assert_eq!(
            shapes,
            vec![
                [3, 8, 32, 32],
                [3, 16, 16, 16],
                [3, 32, 8, 8],
                [3, 64, 7, 7]
            ]
        );
    }
}
