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

/// Where the generator's dilated convolutions are (the text and the original code disagree).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum Dilation {
    /// The first convolution of each encoder residual block, dilation 2: the original code.
    #[default]
    Encoder,
    /// The decoder's two upsampling convolutions, dilation 2, and no dilation in the residual
    /// blocks: the paper's text (§3.2: "upsampled … using dilated convolutions").
    Decoder,
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
    /// `Some(Dilation::Decoder)` for the text's dilation; `None` is the original's, as in every
    /// weights file written before the choice existed (see [`ModelConfig::dilation`]).
    pub dilation: Option<Dilation>,
    /// `Some(false)`: the fusion convolution is followed by its ReLU alone, as the text says;
    /// `None` is instance norm before the ReLU, as the original code and every weights file
    /// written before the choice existed (see [`ModelConfig::normalizes_fusion`]).
    pub fusion_norm: Option<bool>,
}

/// Named model shapes; `mvpcc profile` and `mvpcc train` take these names.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Preset {
    /// The paper's network as its text describes it: w 64, r 8, S 256, V 4 (434 GFLOP per
    /// object), dilation in the decoder, no norm after the fusion convolution; with `train`,
    /// the text's loss too ([`Preset::loss`]).
    Paper,
    /// The paper's network as the original code builds it (dilated residual blocks, instance
    /// norm after the fusion convolution), with its `config.yml` loss.
    Original,
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
            Preset::Paper => base
                .with_dilation(Some(Dilation::Decoder))
                .with_fusion_norm(Some(false)),
            Preset::Original => base,
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

impl Preset {
    /// The loss a run of this preset trains with unless options say otherwise: the text's for
    /// `paper` (docs/paper.md, *The presets*), the original code's `config.yml` for the rest.
    pub fn loss(self) -> loss::LossWeights {
        let original = loss::LossWeights::new();
        match self {
            Preset::Paper => original
                .with_perceptual(250.0)
                .with_style(0.1)
                .with_tv_scale(loss::TvScale::Pixels)
                .with_feature_planes(loss::FeaturePlanes::Colour)
                .with_adversarial_kind(loss::Adversarial::NonSaturating),
            _ => original,
        }
    }

    /// Whether the perceptual and style terms of this preset are VGG19's, as in the paper and
    /// the original code (`train --vgg19 FILE`; mvpcc neither ships nor fetches the weights).
    pub fn wants_vgg19(self) -> bool {
        matches!(self, Preset::Paper | Preset::Original)
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
        let shape = format!(
            "{} of {}², width {}, {}, {:?}, {:?} padding",
            count(self.views, "view"),
            self.size,
            self.width,
            count(self.res_blocks, "residual block"),
            self.channels,
            self.padding
        )
        .to_lowercase();
        // Only what differs from the original's network is named, so existing logs read as before.
        let text = [
            (self.dilation() == Dilation::Decoder, ", dilated decoder"),
            (!self.normalizes_fusion(), ", fusion without norm"),
        ];
        text.into_iter()
            .filter(|(differs, _)| *differs)
            .fold(shape, |s, (_, words)| s + words)
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

    pub fn dilation(&self) -> Dilation {
        self.dilation.unwrap_or_default()
    }

    /// Whether instance norm follows the fusion convolution.
    pub fn normalizes_fusion(&self) -> bool {
        self.fusion_norm.unwrap_or(true)
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
    use std::collections::BTreeMap;

    #[test]
    fn a_shape_is_described_in_words() {
        assert_eq!(
            Preset::Tiny.config().describe(),
            "4 views of 32², width 8, 1 residual block, xyzrgb, reflect padding"
        );
        let one_view = Preset::Original
            .config()
            .with_views(1)
            .with_channels(Channels::Xyz);
        assert_eq!(
            one_view.describe(),
            "1 view of 256², width 64, 8 residual blocks, xyz, reflect padding"
        );
        assert_eq!(
            Preset::Paper.config().describe(),
            "4 views of 256², width 64, 8 residual blocks, xyzrgb, reflect padding, \
             dilated decoder, fusion without norm"
        );
    }

    /// Every setting of a preset's network and loss by name (`model.width`, `loss.style`),
    /// with the defaults that `None` stands for written out.
    fn settings(preset: Preset) -> BTreeMap<String, serde_json::Value> {
        let c = preset.config();
        let model = c
            .clone()
            .with_fusion(Some(c.fusion()))
            .with_dilation(Some(c.dilation()))
            .with_fusion_norm(Some(c.normalizes_fusion()));
        let mut all = BTreeMap::new();
        let parts = [
            ("model", serde_json::to_value(model).unwrap()),
            ("loss", serde_json::to_value(preset.loss()).unwrap()),
        ];
        for (part, value) in parts {
            for (key, v) in value.as_object().unwrap() {
                all.insert(format!("{part}.{key}"), v.clone());
            }
        }
        all.insert("vgg19".into(), preset.wants_vgg19().into());
        all
    }

    /// The rows of docs/paper.md's preset table: setting → (`--config paper`'s cell,
    /// `--config original`'s cell), backticks removed.
    fn preset_table() -> BTreeMap<String, [String; 2]> {
        let doc = include_str!("../../docs/paper.md");
        let start = doc
            .find("### The presets")
            .expect("docs/paper.md has *The presets*");
        let code = |cell: &str| cell.trim().trim_matches('`').to_string();
        doc[start..]
            .lines()
            .skip_while(|l| !l.starts_with("| setting"))
            .skip(2)
            .take_while(|l| l.starts_with('|'))
            .map(|row| {
                let cells: Vec<&str> = row.trim_matches('|').split('|').collect();
                assert_eq!(cells.len(), 5, "a row of five cells: {row}");
                (code(cells[0]), [code(cells[3]), code(cells[4])])
            })
            .collect()
    }

    fn matches(cell: &str, value: &serde_json::Value) -> bool {
        match value {
            serde_json::Value::Number(n) => cell.parse::<f64>().ok() == n.as_f64(),
            serde_json::Value::String(s) => cell == s,
            other => {
                serde_json::from_str::<serde_json::Value>(cell)
                    .ok()
                    .as_ref()
                    == Some(other)
            }
        }
    }

    #[test]
    fn the_paper_and_original_presets_differ_exactly_where_docs_paper_md_says() {
        let (paper, original) = (settings(Preset::Paper), settings(Preset::Original));
        assert_eq!(
            paper.keys().collect::<Vec<_>>(),
            original.keys().collect::<Vec<_>>()
        );
        let differing: Vec<&String> = paper.keys().filter(|k| paper[*k] != original[*k]).collect();
        let table = preset_table();
        assert_eq!(
            table.keys().collect::<Vec<_>>(),
            differing,
            "the table's settings are the ones the presets differ in"
        );
        for (key, [in_paper, in_original]) in &table {
            assert!(
                matches(in_paper, &paper[key]),
                "{key}: {in_paper} vs {}",
                paper[key]
            );
            assert!(
                matches(in_original, &original[key]),
                "{key}: {in_original} vs {}",
                original[key]
            );
        }
        // The original preset is mvpcc's defaults at the paper's size: the table is everything
        // `--config paper` changes.
        assert_eq!(Preset::Original.loss(), loss::LossWeights::new());
        assert_eq!(Preset::Original.config(), ModelConfig::new());
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
