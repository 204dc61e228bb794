//! VGG19's convolutional features (torchvision's `vgg19().features`, up to relu5_2) for the
//! perceptual and style losses, as EdgeConnect and the paper compute them: perceptual on
//! relu1_1…relu5_1, style on the Gram matrices of relu2_2, relu3_4, relu4_4 and relu5_2. The
//! weights come from a file the user has (torchvision's `vgg19-dcbd0d2f.pth`, or a safetensors
//! export with the same keys); nothing is downloaded. The network is frozen.

use super::weights::WeightsError;
use burn::module::Module;
use burn::nn::conv::{Conv2d, Conv2dConfig};
use burn::nn::pool::{MaxPool2d, MaxPool2dConfig};
use burn::nn::PaddingConfig2d;
use burn::store::{ModuleSnapshot, PytorchStore, SafetensorsStore};
use burn::tensor::activation::relu;
use burn::tensor::{Device, Tensor, TensorData};
use std::path::Path;

/// Output channels of torchvision's 14 first VGG19 convolutions (through conv5_2).
const CHANNELS: [usize; 14] = [
    64, 64, 128, 128, 256, 256, 256, 256, 512, 512, 512, 512, 512, 512,
];
/// Index of each of those convolutions in torchvision's `features` Sequential.
const TORCHVISION_INDEX: [usize; 14] = [0, 2, 5, 7, 10, 12, 14, 16, 19, 21, 23, 25, 28, 30];
/// Convolutions followed by a 2×2 max pool.
const POOL_AFTER: [usize; 4] = [1, 3, 7, 11];
/// relu1_1, relu2_1, relu3_1, relu4_1, relu5_1.
pub const PERCEPTUAL_LAYERS: [usize; 5] = [0, 2, 4, 8, 12];
/// relu2_2, relu3_4, relu4_4, relu5_2.
pub const STYLE_LAYERS: [usize; 4] = [3, 7, 11, 13];
const IMAGENET_MEAN: [f32; 3] = [0.485, 0.456, 0.406];
const IMAGENET_STD: [f32; 3] = [0.229, 0.224, 0.225];

#[derive(Module, Debug)]
pub struct Vgg19 {
    features: Vec<Conv2d>,
    pool: MaxPool2d,
}

impl Vgg19 {
    /// Random weights (for tests and for writing a file of the right shape).
    pub fn new(device: &Device) -> Vgg19 {
        let mut c_in = 3;
        let features = CHANNELS
            .iter()
            .map(|&c_out| {
                let conv = Conv2dConfig::new([c_in, c_out], [3, 3])
                    .with_padding(PaddingConfig2d::Explicit(1, 1, 1, 1))
                    .init(device);
                c_in = c_out;
                conv
            })
            .collect();
        Vgg19 {
            features,
            pool: MaxPool2dConfig::new([2, 2]).with_strides([2, 2]).init(),
        }
    }

    /// Reads torchvision's VGG19 weights (`.pth`/`.pt`, or `.safetensors` with the same
    /// `features.N.weight` keys); the classifier and the convolutions past conv5_2 are ignored.
    pub fn load(path: &Path, device: &Device) -> Result<Vgg19, WeightsError> {
        let mut vgg = Vgg19::new(device);
        let is_pytorch = path
            .extension()
            .and_then(|e| e.to_str())
            .is_some_and(|e| matches!(e.to_ascii_lowercase().as_str(), "pth" | "pt" | "bin"));
        // torchvision numbers the Sequential's layers (0, 2, 5, 7, …, ReLUs and pools between);
        // the stores renumber them contiguously, which is this module's numbering.
        let result = if is_pytorch {
            vgg.load_from(
                &mut PytorchStore::from_file(path)
                    .with_regex(r"^features\.")
                    .map_indices_contiguous(true),
            )
            .map_err(|e| WeightsError::VggLoad(e.into()))?
        } else {
            vgg.load_from(
                &mut SafetensorsStore::from_file(path)
                    .with_regex(r"^features\.")
                    .map_indices_contiguous(true),
            )
            .map_err(|e| WeightsError::VggLoad(e.into()))?
        };
        if let Some((name, why)) = result.missing.first() {
            return Err(WeightsError::Vgg(format!(
                "{} of its tensors missing, e.g. {name} ({why})",
                result.missing.len()
            )));
        }
        if let Some(e) = result.errors.first() {
            return Err(WeightsError::Vgg(e.to_string()));
        }
        Ok(vgg.no_grad())
    }

    /// Saves the weights under torchvision's keys (`features.0`, `features.2`, `features.5`, …).
    pub fn to_safetensors(&self) -> Result<Vec<u8>, WeightsError> {
        // Through a temporary prefix, so that no renamed key is renamed again by a later rule.
        let mut store = TORCHVISION_INDEX
            .iter()
            .enumerate()
            .fold(SafetensorsStore::from_bytes(None), |store, (k, tv)| {
                store.with_key_remapping(format!(r"^features\.{k}\."), format!("torchvision.{tv}."))
            })
            .with_key_remapping(r"^torchvision\.", "features.");
        self.save_into(&mut store)
            .map_err(|e| WeightsError::Save(e.into()))?;
        store.get_bytes().map_err(|e| WeightsError::Save(e.into()))
    }

    /// ReLU outputs of every convolution.
    ///
    /// # Shapes
    /// `images`: `[n, 3, S, S]` in [0, 1] → 14 maps `[n, c_k, S/2^p, S/2^p]`
    pub fn forward(&self, images: Tensor<4>) -> Vec<Tensor<4>> {
        let device = images.device();
        let stat = |v: [f32; 3]| {
            Tensor::<4>::from_data(TensorData::new(v.to_vec(), [1, 3, 1, 1]), &device)
        };
        let mut x = (images - stat(IMAGENET_MEAN)) / stat(IMAGENET_STD);
        let mut out = Vec::with_capacity(self.features.len());
        for (k, conv) in self.features.iter().enumerate() {
            x = relu(conv.forward(x));
            out.push(x.clone());
            if POOL_AFTER.contains(&k) {
                x = self.pool.forward(x);
            }
        }
        out
    }
}

/// View images as RGB triples for VGG: every group of three planes (geometry, then colour)
/// becomes one image.
///
/// # Shapes
/// `[B, V, C, S, S]` (C a multiple of 3) → `[B·V·C/3, 3, S, S]`
pub fn as_rgb(images: Tensor<5>) -> Tensor<4> {
    let [b, v, c, s, _] = images.dims();
    images.reshape([b * v * c / 3, 3, s, s])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn features_have_vgg_shapes_and_weights_round_trip_under_torchvision_keys() {
        let device = Device::flex();
        let vgg = Vgg19::new(&device);
        let x = Tensor::<4>::ones([2, 3, 32, 32], &device).mul_scalar(0.5);
        let maps = vgg.forward(x.clone());
        assert_eq!(maps.len(), 14);
        assert_eq!(maps[0].dims(), [2, 64, 32, 32]);
        assert_eq!(maps[3].dims(), [2, 128, 16, 16]);
        assert_eq!(maps[7].dims(), [2, 256, 8, 8]);
        assert_eq!(maps[13].dims(), [2, 512, 2, 2]);

        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("vgg19.safetensors");
        let bytes = vgg.to_safetensors().unwrap();
        let len = u64::from_le_bytes(bytes[..8].try_into().unwrap()) as usize;
        let header = String::from_utf8_lossy(&bytes[8..8 + len]).into_owned();
        assert!(
            header.contains("features.30.weight") && !header.contains("features.13."),
            "{header}"
        );
        std::fs::write(&path, bytes).unwrap();
        let back = Vgg19::load(&path, &device).unwrap();
        let a = vgg.forward(x.clone())[13]
            .clone()
            .into_data()
            .try_into_vec::<f32>()
            .unwrap();
        let b = back.forward(x)[13]
            .clone()
            .into_data()
            .try_into_vec::<f32>()
            .unwrap();
        assert_eq!(a, b);

        std::fs::write(&path, b"not weights").unwrap();
        assert!(Vgg19::load(&path, &device).is_err());
    }
}
