//! The MVPCC-Net inpainting GAN in Burn: a generator shared over views with a feature-fusion
//! stage ([`Generator`]), a spectrally normalized PatchGAN discriminator ([`Discriminator`]),
//! the training losses ([`loss`]) and the weights file ([`weights`]).
//!
//! The model sees only tensors. A view image enters as `channels + 1` planes: the geometry
//! (normalized XYZ shifted into [0, 1], the 16-bit PNG's value / 65535), the colour when the
//! model has it, and the input's occupancy mask; empty pixels are zero. It leaves as `channels`
//! planes in [0, 1] plus an occupancy logit.

mod cpu;
pub mod device;
mod discriminator;
pub mod gan;
mod generator;
pub mod inpaint;
mod layers;
pub mod loss;
pub mod vgg;
pub mod weights;
pub mod widen;

pub use discriminator::{Discriminator, DiscriminatorOutput};
pub use generator::{Generator, GeneratorOutput};
pub use layers::{Formulation, LayerKind, NoProbe, Probe, SpectralConv2d};

use burn::config::Config;
use burn::tensor::Device;
use clap::ValueEnum;
use serde::{Deserialize, Serialize};
use thiserror::Error;

/// Which image channels the model reads and writes (besides occupancy).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum Channels {
    /// Geometry only: the paper's best geometric scores.
    Xyz,
    /// Geometry and colour.
    Xyzrgb,
}

impl Channels {
    pub fn count(self) -> usize {
        match self {
            Channels::Xyz => 3,
            Channels::Xyzrgb => 6,
        }
    }
}

/// How convolutions with a spatial kernel see past the image border.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum Padding {
    /// Reflection padding, as the original.
    Reflect,
    /// Zero padding folded into the convolution: cheaper on CPU.
    Zero,
}

/// Where the views' information meets (the paper's Table 6 compares the two).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum Fusion {
    /// One convolution over all views' bottleneck features, its result beside each view's own
    /// before the shared decoder: the paper's network.
    #[default]
    Late,
    /// One convolution over all views' input images at full resolution, its result beside each
    /// view's own input before the shared encoder; the decoder sees its view's features only.
    Early,
}

/// Shape of the generator and discriminator. Saved inside every weights file.
#[derive(Config, Debug, PartialEq)]
pub struct ModelConfig {
    /// Channels after the first convolution (`w`); the bottleneck has `4w`.
    #[config(default = 64)]
    pub width: usize,
    /// Dilated residual blocks in the shared encoder (`r`).
    #[config(default = 8)]
    pub res_blocks: usize,
    /// View image side in pixels (`S`): a multiple of 4, at least 32.
    #[config(default = 256)]
    pub size: usize,
    /// Views per object (`V`); the fusion convolution sees all of them at once.
    #[config(default = 4)]
    pub views: usize,
    #[config(default = "Channels::Xyzrgb")]
    pub channels: Channels,
    #[config(default = "Padding::Reflect")]
    pub padding: Padding,
    /// Channels of the discriminator's first layer (64 in the 70×70 PatchGAN).
    #[config(default = 64)]
    pub disc_width: usize,
    /// `Some(Fusion::Early)` for early fusion; `None` is late fusion, as in every weights file
    /// written before this choice existed (see [`ModelConfig::fusion`]).
    pub fusion: Option<Fusion>,
    /// `Some(true)`: the output keeps the input's pixels (see [`ModelConfig::copies_input`]);
    /// `None` in every weights file written before the choice existed.
    pub input_copy: Option<bool>,
    /// Probability above which an output pixel is occupied (becomes a point), chosen on the
    /// validation split for these weights; `None` is one half, as in every weights file
    /// written before the choice existed (see [`ModelConfig::occupancy_threshold`]).
    pub occupancy: Option<f64>,
}

/// Named model shapes; `mvpcc profile` and `mvpcc train` take these names.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Preset {
    /// The paper's network: w 64, r 8, S 256, V 4 (434 GFLOP per object).
    Paper,
    /// w 56, r 6, S 128, zero padding: chosen by measurement (see
    /// lab/2026-11-22-network-cpu-forward) as the largest whose whole `complete` stayed within a
    /// second on two cores (2026-12-01), and `train`'s default until it took the built-in model's
    /// shape (w 48, r 2, measured the same way on 2026-12-04, lab/2026-12-04-widening).
    Cpu,
    /// w 32, r 4, S 128, V 4 (18.7 GFLOP per object).
    Small,
    /// w 8, r 1, S 32: for tests and smoke runs, not for results.
    Tiny,
}

impl Preset {
    pub fn config(self) -> ModelConfig {
        let base = ModelConfig::new();
        match self {
            Preset::Paper => base,
            Preset::Cpu => base
                .with_width(56)
                .with_res_blocks(6)
                .with_size(128)
                .with_padding(Padding::Zero),
            Preset::Small => base.with_width(32).with_res_blocks(4).with_size(128),
            Preset::Tiny => base
                .with_width(8)
                .with_res_blocks(1)
                .with_size(32)
                .with_disc_width(8),
        }
    }
}

#[derive(Debug, Error, PartialEq)]
pub enum ConfigError {
    #[error("image size {0} is not a multiple of 4 of at least 32")]
    Size(usize),
    #[error("width {0} must be at least 1")]
    Width(usize),
    #[error("discriminator width {0} must be at least 1")]
    DiscWidth(usize),
    #[error("views {0} must be at least 1")]
    Views(usize),
    #[error("occupancy threshold {0} is not a probability between 0 and 1")]
    Occupancy(f64),
    #[error("{field} {value} is above the largest this build accepts ({limit})")]
    TooLarge {
        field: &'static str,
        value: usize,
        limit: usize,
    },
}

/// The largest shapes a config may declare. They lie far beyond any useful network (the paper's
/// is w 64, r 8, S 256, V 4) and keep a corrupt or hostile weights file from making the loader
/// build millions of layers before its tensors are looked at.
const LIMITS: [(&str, usize); 5] = [
    ("width", 1024),
    ("discriminator width", 1024),
    ("residual blocks", 64),
    ("image size", crate::views::MAX_VIEW_SIZE as usize),
    ("views", crate::core::camera::RIG_SIZE),
];

/// The largest micro-batch `train`, `train-orient` and `profile` accept. The relay trains with
/// 4; a batch of 100,000 asked the allocator for 183 GB and aborted the process, so a mistyped
/// batch is refused with a message instead. Below it a batch can still outgrow the machine's
/// memory.
pub const MAX_BATCH: usize = 1024;

impl ModelConfig {
    /// The shape in words, for the logs of `train` and `profile`: "4 views of 128², width 48,
    /// 2 residual blocks, xyzrgb, zero padding".
    pub fn describe(&self) -> String {
        let count = |n: usize, one: &str| format!("{n} {one}{}", if n == 1 { "" } else { "s" });
        format!(
            "{} of {}², width {}, {}, {:?}, {:?} padding",
            count(self.views, "view"),
            self.size,
            self.width,
            count(self.res_blocks, "residual block"),
            self.channels,
            self.padding
        )
        .to_lowercase()
    }

    /// Sizes the layers cannot work with: the two stride-2 stages and the discriminator's
    /// three need `S` divisible by 4 and its 4×4 stride-1 tail at least 32 pixels.
    pub fn validate(&self) -> Result<(), ConfigError> {
        if !self.size.is_multiple_of(4) || self.size < 32 {
            return Err(ConfigError::Size(self.size));
        }
        if self.width == 0 {
            return Err(ConfigError::Width(self.width));
        }
        if self.disc_width == 0 {
            return Err(ConfigError::DiscWidth(self.disc_width));
        }
        if self.views == 0 {
            return Err(ConfigError::Views(self.views));
        }
        if let Some(p) = self.occupancy.filter(|p| !(*p > 0.0 && *p < 1.0)) {
            return Err(ConfigError::Occupancy(p));
        }
        let values = [
            self.width,
            self.disc_width,
            self.res_blocks,
            self.size,
            self.views,
        ];
        for ((field, limit), value) in LIMITS.into_iter().zip(values) {
            if value > limit {
                return Err(ConfigError::TooLarge {
                    field,
                    value,
                    limit,
                });
            }
        }
        Ok(())
    }

    pub fn fusion(&self) -> Fusion {
        self.fusion.unwrap_or_default()
    }

    /// Sets the fusion, written as `None` when late so that configs compare equal to files
    /// that predate the choice.
    pub fn with_fusion_kind(self, fusion: Fusion) -> ModelConfig {
        self.with_fusion((fusion == Fusion::Early).then_some(Fusion::Early))
    }

    /// Whether the generator's output keeps the input's pixels: where the input has one, its
    /// geometry and colour replace the prediction's and the pixel is occupied, as inpainting
    /// networks composite their output with the known image. Without it the decoder must rebuild
    /// every measured pixel from quarter-size features, which it does to a few pixels' depth
    /// (lab/2026-12-02-input-copy); with it the network spends itself on the pixels it completes.
    /// It adds no weights, so weights trained either way load either way.
    pub fn copies_input(&self) -> bool {
        self.input_copy == Some(true)
    }

    /// Sets the input copy, written as `None` when off so that configs compare equal to files
    /// that predate it.
    pub fn with_input_copy_kind(self, copy: bool) -> ModelConfig {
        self.with_input_copy(copy.then_some(true))
    }

    /// Probability above which an output pixel is occupied. The occupancy plane is trained
    /// with BCE against whole objects, and a network that cannot place a pixel exactly still
    /// gives the pixels of a gap it fills a small probability: a threshold below one half
    /// keeps them, and with them points in the gaps the mean squared distance counts most
    /// (lab/2026-12-02-occupancy-threshold).
    pub fn occupancy_threshold(&self) -> f64 {
        self.occupancy.unwrap_or(0.5)
    }

    /// The logit [`Self::occupancy_threshold`] corresponds to: a pixel is occupied where the
    /// generator's occupancy logit exceeds it.
    pub fn occupancy_logit(&self) -> f32 {
        let p = self.occupancy_threshold();
        (p / (1.0 - p)).ln() as f32
    }

    /// Image planes per view the generator reads: the channels plus the occupancy mask.
    pub fn input_channels(&self) -> usize {
        self.channels.count() + 1
    }

    pub fn init_generator(&self, device: &Device) -> Result<Generator, ConfigError> {
        self.validate()?;
        Ok(Generator::new(self, device))
    }

    pub fn init_discriminator(&self, device: &Device) -> Result<Discriminator, ConfigError> {
        self.validate()?;
        Ok(Discriminator::new(self, device))
    }

    /// Multiply-accumulate count of one generator forward for one object (all views), in
    /// GFLOP (2 per MAC): the figure the speed targets are quoted in.
    pub fn generator_gflop(&self) -> f64 {
        let (w, s, v) = (self.width as f64, self.size as f64, self.views as f64);
        let (cin, cout) = (
            self.input_channels() as f64,
            self.channels.count() as f64 + 1.0,
        );
        let q = s / 4.0;
        let per_view = s * s * 49.0 * cin * w
            + (s / 2.0).powi(2) * 16.0 * w * 2.0 * w
            + q * q * 16.0 * 2.0 * w * 4.0 * w
            + self.res_blocks as f64 * 2.0 * q * q * 9.0 * (4.0 * w).powi(2)
            + q * q * 16.0 * 8.0 * w * 2.0 * w
            + (s / 2.0).powi(2) * 16.0 * 2.0 * w * w
            + s * s * 49.0 * w * cout;
        let (fusion, extra) = match self.fusion() {
            Fusion::Late => (q * q * 9.0 * v * 4.0 * w * 4.0 * w, 0.0),
            // The fused planes widen the stem; the decoder's first layer reads half as much.
            Fusion::Early => (
                s * s * 9.0 * v * cin * w,
                s * s * 49.0 * w * w - q * q * 16.0 * 4.0 * w * 2.0 * w,
            ),
        };
        2.0 * (v * (per_view + extra) + fusion) / 1e9
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_shape_is_described_in_words() {
        assert_eq!(
            Preset::Tiny.config().describe(),
            "4 views of 32², width 8, 1 residual block, xyzrgb, reflect padding"
        );
        let one_view = Preset::Paper
            .config()
            .with_views(1)
            .with_channels(Channels::Xyz);
        assert_eq!(
            one_view.describe(),
            "1 view of 256², width 64, 8 residual blocks, xyz, reflect padding"
        );
    }

    #[test]
    fn presets_are_valid_and_paper_matches_the_publication() {
        for p in Preset::value_variants() {
            p.config().validate().unwrap();
        }
        let paper = Preset::Paper.config();
        assert_eq!(
            (paper.width, paper.res_blocks, paper.size, paper.views),
            (64, 8, 256, 4)
        );
    }

    #[test]
    fn flop_count_matches_the_quoted_figures() {
        // The quoted 434 GFLOP (paper) and 18.7 GFLOP (small) count 6 planes in and out; ours
        // carry a seventh (occupancy) in the first and last 7×7 convolutions.
        for (preset, quoted) in [(Preset::Paper, 434.0), (Preset::Small, 18.7)] {
            let c = preset.config();
            let (s, w, v) = (c.size as f64, c.width as f64, c.views as f64);
            let seventh_plane = 2.0 * 2.0 * s * s * 49.0 * w * v / 1e9;
            let six = c.generator_gflop() - seventh_plane;
            assert!((six - quoted).abs() / quoted < 0.005, "{preset:?}: {six}");
        }
    }

    #[test]
    fn bad_sizes_are_refused() {
        for s in [0, 16, 30, 34] {
            assert_eq!(
                ModelConfig::new().with_size(s).validate(),
                Err(ConfigError::Size(s))
            );
        }
        assert!(ModelConfig::new().with_views(0).validate().is_err());
    }

    #[test]
    fn config_round_trips_through_json() {
        let c = Preset::Tiny.config().with_channels(Channels::Xyz);
        let json = serde_json::to_string(&c).unwrap();
        let back: ModelConfig = serde_json::from_str(&json).unwrap();
        assert_eq!(back, c);
    }
}
