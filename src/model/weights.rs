//! Weights files: one safetensors file per network, its config and a format version in the
//! header's `__metadata__`, so a file is self-describing and any safetensors reader can open
//! it. Loading works from bytes, which is how the default model is embedded in the binary.

use super::{ConfigError, Discriminator, Generator, ModelConfig};
use burn::module::Module;
use burn::store::{ModuleSnapshot, SafetensorsStore};
use burn::tensor::Device;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use thiserror::Error;

/// Bumped whenever a change to the networks' structure makes older files unreadable.
pub const FORMAT_VERSION: u32 = 1;

/// A run's generator file, in its folder and each checkpoint's.
pub const GENERATOR_FILE: &str = "generator.safetensors";
/// The built-in generator's file in assets/.
pub const ASSETS_GENERATOR_FILE: &str = "model.safetensors";

/// The generator's weights in `dir`: a run's [`GENERATOR_FILE`] or assets/'
/// [`ASSETS_GENERATOR_FILE`], so that `--model` and `--init` take either folder.
pub fn generator_in(dir: &Path) -> Result<PathBuf, NoGenerator> {
    [GENERATOR_FILE, ASSETS_GENERATOR_FILE]
        .iter()
        .map(|name| dir.join(name))
        .find(|p| p.is_file())
        .ok_or_else(|| NoGenerator(dir.to_path_buf()))
}

/// A folder given for a model that holds no generator's weights.
#[derive(Debug, Error)]
#[error("{}: holds neither {GENERATOR_FILE} nor {ASSETS_GENERATOR_FILE}", .0.display())]
pub struct NoGenerator(pub PathBuf);

const KEY_KIND: &str = "mvpcc.network";
const KEY_VERSION: &str = "mvpcc.format_version";
const KEY_CONFIG: &str = "mvpcc.model_config";

/// Which network a weights file holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Network {
    Generator,
    Discriminator,
    /// The orientation network ([`crate::complete::orient::Orienter`]).
    Orienter,
}

impl Network {
    fn name(self) -> &'static str {
        match self {
            Network::Generator => "generator",
            Network::Discriminator => "discriminator",
            Network::Orienter => "orienter",
        }
    }
}

/// "a generator", "an orienter": a network's name as the error says it.
fn with_article(name: &str) -> String {
    let vowel = name.starts_with(['a', 'e', 'i', 'o', 'u']);
    format!("{} {name}", if vowel { "an" } else { "a" })
}

#[derive(Debug, Error)]
pub enum WeightsError {
    #[error("not a safetensors file ({0})")]
    NotSafetensors(&'static str),
    #[error("not an mvpcc weights file (no {KEY_KIND} in the safetensors metadata)")]
    NotMvpcc,
    #[error("holds {}, not {}", with_article(.found), with_article(.expected))]
    WrongNetwork {
        expected: &'static str,
        found: String,
    },
    #[error("format version {found}, this mvpcc reads version {FORMAT_VERSION}")]
    Version { found: String },
    #[error("its metadata has no {KEY_CONFIG}")]
    MissingConfig,
    #[error("its model config is unreadable")]
    Config(#[source] serde_json::Error),
    #[error("its model config is invalid: {0}")]
    InvalidConfig(#[from] ConfigError),
    #[error("expected model config {expected}, the file has {found}")]
    ConfigMismatch { expected: String, found: String },
    #[error(
        "its width {found} is larger than the {wanted} asked for: widening only adds channels"
    )]
    Narrower { found: usize, wanted: usize },
    #[error("its orienter config is invalid: {0}")]
    InvalidOrienter(String),
    #[error("its tensors do not fit the config it declares: {0}")]
    Tensors(String),
    #[error("its tensors could not be read")]
    Load(#[source] Cause),
    #[error("not usable as VGG19 weights: {0}")]
    Vgg(String),
    #[error("not usable as VGG19 weights")]
    VggLoad(#[source] Cause),
    #[error("could not serialize the weights")]
    Save(#[source] Cause),
}

/// A third-party error kept as the source of a [`WeightsError`]: its text is the next link of
/// the error's chain, not part of this one's.
pub type Cause = Box<dyn std::error::Error + Send + Sync>;

/// The `__metadata__` map of a safetensors file, read without touching the tensors.
fn metadata(bytes: &[u8]) -> Result<BTreeMap<String, String>, WeightsError> {
    let len: [u8; 8] = bytes
        .get(..8)
        .and_then(|b| b.try_into().ok())
        .ok_or(WeightsError::NotSafetensors("shorter than its header"))?;
    let len = u64::from_le_bytes(len);
    let header = usize::try_from(len)
        .ok()
        .and_then(|len| bytes.get(8..8usize.checked_add(len)?))
        .ok_or(WeightsError::NotSafetensors("header length past the end"))?;
    #[derive(serde::Deserialize)]
    struct Header {
        #[serde(rename = "__metadata__", default)]
        metadata: BTreeMap<String, String>,
    }
    let header: Header = serde_json::from_slice(header)
        .map_err(|_| WeightsError::NotSafetensors("header is not JSON"))?;
    Ok(header.metadata)
}

/// The config a weights file declares, after checking that it holds `network` in a format
/// this build reads.
pub fn read_config(bytes: &[u8], network: Network) -> Result<ModelConfig, WeightsError> {
    let config: ModelConfig = read_declared(bytes, network)?;
    config.validate()?;
    Ok(config)
}

/// The config of any network's file, unchecked beyond its kind and format version.
pub(crate) fn read_declared<C: serde::de::DeserializeOwned>(
    bytes: &[u8],
    network: Network,
) -> Result<C, WeightsError> {
    let meta = metadata(bytes)?;
    let kind = meta.get(KEY_KIND).ok_or(WeightsError::NotMvpcc)?;
    if kind != network.name() {
        return Err(WeightsError::WrongNetwork {
            expected: network.name(),
            found: kind.clone(),
        });
    }
    let version = meta.get(KEY_VERSION).cloned().unwrap_or_default();
    if version != FORMAT_VERSION.to_string() {
        return Err(WeightsError::Version { found: version });
    }
    serde_json::from_str(meta.get(KEY_CONFIG).ok_or(WeightsError::MissingConfig)?)
        .map_err(WeightsError::Config)
}

pub(crate) fn to_bytes<M: Module, C: serde::Serialize>(
    module: &M,
    network: Network,
    config: &C,
) -> Result<Vec<u8>, WeightsError> {
    let config = serde_json::to_string(config).map_err(|e| WeightsError::Save(e.into()))?;
    let mut store = SafetensorsStore::from_bytes(None)
        .metadata(KEY_KIND, network.name())
        .metadata(KEY_VERSION, FORMAT_VERSION.to_string())
        .metadata(KEY_CONFIG, config);
    module
        .save_into(&mut store)
        .map_err(|e| WeightsError::Save(e.into()))?;
    store.get_bytes().map_err(|e| WeightsError::Save(e.into()))
}

/// Loads `bytes` into `module`; a tensor the file lacks, has extra or shapes otherwise is an
/// error.
pub(crate) fn apply<M: Module>(module: &mut M, bytes: &[u8]) -> Result<(), WeightsError> {
    // Partial and unvalidated, so that what does not fit comes back as data to word in one
    // line instead of Burn's multi-line report.
    let mut store = SafetensorsStore::from_bytes(Some(bytes.to_vec()))
        .allow_partial(true)
        .validate(false);
    let result = module
        .load_from(&mut store)
        .map_err(|e| WeightsError::Load(e.into()))?;
    let problem = |count: usize, what: &str, example: String| {
        WeightsError::Tensors(format!("{count} {what}, e.g. {example}"))
    };
    if let Some(e) = result.errors.first() {
        return Err(problem(
            result.errors.len(),
            "tensors do not fit the network",
            e.to_string(),
        ));
    }
    if let Some((path, _)) = result.missing.first() {
        return Err(problem(
            result.missing.len(),
            "tensors the network needs are missing",
            path.to_string(),
        ));
    }
    if let Some(unused) = result.unused.first() {
        return Err(problem(
            result.unused.len(),
            "tensors the network does not have",
            unused.clone(),
        ));
    }
    Ok(())
}

pub fn generator_to_bytes(
    generator: &Generator,
    config: &ModelConfig,
) -> Result<Vec<u8>, WeightsError> {
    to_bytes(generator, Network::Generator, config)
}

/// A generator and the config it was built from.
pub fn generator_from_bytes(
    bytes: &[u8],
    device: &Device,
) -> Result<(Generator, ModelConfig), WeightsError> {
    let config = read_config(bytes, Network::Generator)?;
    let mut generator = config.init_generator(device)?;
    apply(&mut generator, bytes)?;
    Ok((generator, config))
}

pub fn discriminator_to_bytes(
    discriminator: &Discriminator,
    config: &ModelConfig,
) -> Result<Vec<u8>, WeightsError> {
    to_bytes(discriminator, Network::Discriminator, config)
}

/// A discriminator whose file must declare `expected` (the generator's config it trains with).
pub fn discriminator_from_bytes(
    bytes: &[u8],
    expected: &ModelConfig,
    device: &Device,
) -> Result<Discriminator, WeightsError> {
    let config = read_config(bytes, Network::Discriminator)?;
    if &config != expected {
        return Err(WeightsError::ConfigMismatch {
            expected: serde_json::to_string(expected).unwrap_or_default(),
            found: serde_json::to_string(&config).unwrap_or_default(),
        });
    }
    let mut discriminator = config.init_discriminator(device)?;
    apply(&mut discriminator, bytes)?;
    Ok(discriminator)
}

/// A generator built from `config` with the weights of a file made for a config that may
/// differ from it in the image size alone: the networks are convolutional, so no tensor's shape
/// depends on the size, and a model trained at 64² starts a 128² run.
pub fn generator_for(
    bytes: &[u8],
    config: &ModelConfig,
    device: &Device,
) -> Result<Generator, WeightsError> {
    network_for(bytes, Network::Generator, config, |c| {
        c.init_generator(device)
    })
}

/// [`generator_for`] for a discriminator's file.
pub fn discriminator_for(
    bytes: &[u8],
    config: &ModelConfig,
    device: &Device,
) -> Result<Discriminator, WeightsError> {
    network_for(bytes, Network::Discriminator, config, |c| {
        c.init_discriminator(device)
    })
}

fn network_for<M: Module>(
    bytes: &[u8],
    network: Network,
    config: &ModelConfig,
    init: impl FnOnce(&ModelConfig) -> Result<M, ConfigError>,
) -> Result<M, WeightsError> {
    let found = read_config(bytes, network)?;
    compatible(&found, config)?;
    let mut module = init(config)?;
    apply(&mut module, bytes)?;
    Ok(module)
}

/// Whether weights made for `found` fit a network built from `expected`: every field equal but
/// the image size, the input copy and the occupancy threshold, which change no weight
/// ([`ModelConfig::copies_input`], [`ModelConfig::occupancy_threshold`]).
pub fn compatible(found: &ModelConfig, expected: &ModelConfig) -> Result<(), WeightsError> {
    let fitted = found
        .clone()
        .with_size(expected.size)
        .with_input_copy(expected.input_copy)
        .with_occupancy(expected.occupancy);
    if fitted == *expected {
        return Ok(());
    }
    Err(WeightsError::ConfigMismatch {
        expected: serde_json::to_string(expected).unwrap_or_default(),
        found: serde_json::to_string(found).unwrap_or_default(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::{Channels, Preset};
    use burn::tensor::{Distribution, Tensor};

    #[test]
    fn generator_save_load_gives_identical_outputs() {
        let device = Device::flex();
        let config = Preset::Tiny.config();
        let g = config.init_generator(&device).unwrap();
        let bytes = generator_to_bytes(&g, &config).unwrap();
        let (back, back_config) = generator_from_bytes(&bytes, &device).unwrap();
        assert_eq!(back_config, config);
        let x = Tensor::<5>::random([1, 4, 7, 32, 32], Distribution::Default, &device);
        let a = g.forward(x.clone());
        let b = back.forward(x);
        assert_eq!(a.images.into_data(), b.images.into_data());
        assert_eq!(a.occupancy.into_data(), b.occupancy.into_data());
        // A fresh generator is different, so the equality above is not vacuous.
        let other = config.init_generator(&device).unwrap();
        let bytes_other = generator_to_bytes(&other, &config).unwrap();
        assert_ne!(bytes, bytes_other);
    }

    #[test]
    fn discriminator_round_trip_keeps_the_power_iteration_state() {
        let device = Device::flex();
        let config = Preset::Tiny.config();
        let d = config.init_discriminator(&device).unwrap();
        let bytes = discriminator_to_bytes(&d, &config).unwrap();
        let back = discriminator_from_bytes(&bytes, &config, &device).unwrap();
        let x = Tensor::<4>::random([2, 7, 32, 32], Distribution::Default, &device);
        assert_eq!(
            d.forward(x.clone()).logits.into_data(),
            back.forward(x).logits.into_data()
        );
        let other = config.clone().with_disc_width(16);
        assert!(matches!(
            discriminator_from_bytes(&bytes, &other, &device),
            Err(WeightsError::ConfigMismatch { .. })
        ));
    }

    #[test]
    fn weights_start_a_model_of_another_image_size_but_no_other_shape() {
        let device = Device::flex();
        let small = Preset::Tiny.config();
        let g = small.init_generator(&device).unwrap();
        let d = small.init_discriminator(&device).unwrap();
        let (g_bytes, d_bytes) = (
            generator_to_bytes(&g, &small).unwrap(),
            discriminator_to_bytes(&d, &small).unwrap(),
        );
        let large = small.clone().with_size(64);
        let g64 = generator_for(&g_bytes, &large, &device).unwrap();
        discriminator_for(&d_bytes, &large, &device).unwrap();
        let x = Tensor::<5>::random([1, 4, 7, 32, 32], Distribution::Default, &device);
        assert_eq!(
            g.forward(x.clone()).images.into_data(),
            g64.forward(x).images.into_data()
        );
        let wider = small.clone().with_width(16);
        assert!(matches!(
            generator_for(&g_bytes, &wider, &device),
            Err(WeightsError::ConfigMismatch { .. })
        ));
        assert!(matches!(
            generator_for(&d_bytes, &large, &device),
            Err(WeightsError::WrongNetwork { .. })
        ));
    }

    /// The input copy adds no weights: weights trained without it load into a model with it
    /// and back, and predict the same where the input has no pixel.
    #[test]
    fn weights_load_with_and_without_the_input_copy() {
        let device = Device::flex();
        let plain = Preset::Tiny.config();
        let copying = plain.clone().with_input_copy_kind(true);
        let g = plain.init_generator(&device).unwrap();
        let bytes = generator_to_bytes(&g, &plain).unwrap();
        let copier = generator_for(&bytes, &copying, &device).unwrap();
        let mut x = Tensor::<5>::random([1, 4, 7, 32, 32], Distribution::Default, &device);
        x = x.slice_assign(
            [0..1, 0..4, 6..7, 0..32, 0..32],
            Tensor::zeros([1, 4, 1, 32, 32], &device),
        );
        assert_eq!(
            g.forward(x.clone()).images.into_data(),
            copier.forward(x.clone()).images.into_data()
        );
        let copier_bytes = generator_to_bytes(&copier, &copying).unwrap();
        let (back, config) = generator_from_bytes(&copier_bytes, &device).unwrap();
        assert!(config.copies_input());
        let plain_again = generator_for(&copier_bytes, &plain, &device).unwrap();
        assert_eq!(
            back.forward(x.clone()).images.into_data(),
            plain_again.forward(x).images.into_data()
        );
    }

    #[test]
    fn the_occupancy_threshold_travels_with_the_weights_and_changes_none() {
        let device = Device::flex();
        let plain = Preset::Tiny.config();
        let tuned = plain.clone().with_occupancy(Some(0.05));
        let g = plain.init_generator(&device).unwrap();
        let bytes = generator_to_bytes(&g, &tuned).unwrap();
        let (_, config) = generator_from_bytes(&bytes, &device).unwrap();
        assert_eq!(config.occupancy_threshold(), 0.05);
        assert!(generator_for(&bytes, &plain, &device).is_ok());
        let wider = plain.with_width(16);
        assert!(matches!(
            generator_for(&bytes, &wider, &device),
            Err(WeightsError::ConfigMismatch { .. })
        ));
    }

    #[test]
    fn mismatches_and_garbage_are_errors_not_panics() {
        let device = Device::flex();
        let config = Preset::Tiny.config();
        let g = config.init_generator(&device).unwrap();
        let good = generator_to_bytes(&g, &config).unwrap();

        let err = |bytes: &[u8]| generator_from_bytes(bytes, &device).unwrap_err();
        assert!(matches!(err(b""), WeightsError::NotSafetensors(_)));
        assert!(matches!(
            err(b"\xff\xff\xff\xff\xff\xff\xff\x7f{}"),
            WeightsError::NotSafetensors(_)
        ));
        assert!(matches!(
            err(&good[..good.len() / 2]),
            WeightsError::Load(_)
        ));

        let d = config.init_discriminator(&device).unwrap();
        let disc = discriminator_to_bytes(&d, &config).unwrap();
        let wrong = err(&disc);
        assert!(matches!(wrong, WeightsError::WrongNetwork { .. }));
        assert_eq!(wrong.to_string(), "holds a discriminator, not a generator");
        assert_eq!(with_article("orienter"), "an orienter");

        // Same tensor names, other shapes: the declared config is tampered with.
        let wider = serde_json::to_string(&config.clone().with_width(16)).unwrap();
        let narrow = serde_json::to_string(&config).unwrap();
        let tampered = replace_in_header(&good, &narrow, &wider);
        assert!(matches!(err(&tampered), WeightsError::Tensors(_)));
        let xyz = serde_json::to_string(&config.clone().with_channels(Channels::Xyz)).unwrap();
        assert!(matches!(
            err(&replace_in_header(&good, &narrow, &xyz)),
            WeightsError::Tensors(_)
        ));
        let version = replace_in_header(
            &good,
            &format!("\"{KEY_VERSION}\":\"{FORMAT_VERSION}\""),
            &format!("\"{KEY_VERSION}\":\"99\""),
        );
        assert!(matches!(err(&version), WeightsError::Version { .. }));
    }

    /// Rewrites a string inside the JSON header, fixing the header length.
    fn replace_in_header(bytes: &[u8], from: &str, to: &str) -> Vec<u8> {
        let len = u64::from_le_bytes(bytes[..8].try_into().unwrap()) as usize;
        let header = std::str::from_utf8(&bytes[8..8 + len]).unwrap();
        let escaped = |s: &str| serde_json::to_string(s).unwrap();
        let (from_json, to_json) = if from.starts_with('"') {
            (from.to_string(), to.to_string())
        } else {
            let f = escaped(from);
            let t = escaped(to);
            (f[1..f.len() - 1].to_string(), t[1..t.len() - 1].to_string())
        };
        assert!(header.contains(&from_json), "{from_json} not in {header}");
        let new_header = header.replace(&from_json, &to_json);
        let mut out = (new_header.len() as u64).to_le_bytes().to_vec();
        out.extend_from_slice(new_header.as_bytes());
        out.extend_from_slice(&bytes[8 + len..]);
        out
    }
}
