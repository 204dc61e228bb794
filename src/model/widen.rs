//! A wider generator that starts as a narrower one's function (Net2Net's idea, Chen et al.
//! 2016, with zeros instead of copies): every channel the narrow network has keeps its weights,
//! the new channels get fresh ones, and the weights from a new channel into an old one are zero.
//! So the old channels compute what they computed, and the output, which reads only old
//! channels at first, is the narrow model's; training then lets the new channels in. This is
//! how a wider network continues the relay from the built-in model's weights instead of from
//! nothing (docs/training.md, *Starting from trained weights*).
//!
//! The instance norms have no parameters and act per channel, so they need nothing; a residual
//! block added at the same time would not start as the identity (a zero convolution followed by
//! an instance norm gives zero, but its first step's output is renormalized to unit variance),
//! so the depth stays the narrow network's.

use super::weights::{self, WeightsError};
use super::{Channels, Fusion, Generator, ModelConfig};
use burn::tensor::Device;
use std::collections::BTreeMap;

/// A geometry-only generator (`Channels::Xyz`) from the weights of a colour one of the same
/// shape: every layer keeps its weights but the input convolution, which forgets the colour
/// planes' weights, and the head, which stops writing colour. On an input without colour (its
/// colour planes zero) it computes the colour network's geometry and occupancy exactly, so a run
/// goes on from what the colour model learned instead of from nothing (the paper's Tables 1–2
/// and 7–8 are its XYZ-only model's). Late fusion only: early fusion's fusion convolution reads
/// the colour planes too.
pub fn generator_without_colour(
    bytes: &[u8],
    config: &ModelConfig,
    device: &Device,
) -> Result<Generator, WeightsError> {
    let coloured = weights::read_config(bytes, weights::Network::Generator)?;
    colour_droppable(&coloured, config)?;
    let mut geometry = config.init_generator(device)?;
    let mut fresh = weights::generator_to_bytes(&geometry, config)?;
    let old = Tensors::parse(bytes)?;
    let new = Tensors::parse(&fresh)?;
    let mut values = new.values(&fresh);
    // XYZ, RGB, occupancy in; XYZ, RGB, occupancy logit out: the geometry and the last plane stay.
    let planes = [0, 1, 2, coloured.channels.count()];
    for (name, (shape, _)) in &new.0 {
        let (old_shape, old_values) = old.values_of(bytes, name)?;
        let axis = match name.as_str() {
            _ if old_shape == *shape => None,
            "stem.conv.weight" => Some(1),
            "head.conv.weight" | "head.conv.bias" => Some(0),
            _ => return Err(WeightsError::Tensors(format!("{name}: unexpected shape"))),
        };
        let value = values.get_mut(name).ok_or_else(|| missing(name))?;
        value.1 = match axis {
            None => old_values,
            Some(axis) => select(&old_shape, &old_values, axis, &planes),
        };
    }
    new.write(&mut fresh, &values);
    weights::apply(&mut geometry, &fresh)?;
    Ok(geometry)
}

/// Whether `coloured`'s weights can start the geometry-only network `config`
/// ([`generator_without_colour`]): the same network, late fusion, but for the colour.
pub fn colour_droppable(coloured: &ModelConfig, config: &ModelConfig) -> Result<(), WeightsError> {
    let late = coloured.fusion() == Fusion::Late;
    if coloured.channels != Channels::Xyzrgb || config.channels != Channels::Xyz || !late {
        return Err(WeightsError::ConfigMismatch {
            expected: "a late-fusion xyzrgb generator for an xyz run".into(),
            found: serde_json::to_string(coloured).unwrap_or_default(),
        });
    }
    let same = coloured.clone().with_channels(Channels::Xyz);
    weights::compatible(&same, config)
}

/// The entries of a row-major tensor of `shape` whose index along `axis` is one of `kept`, in
/// that order along the axis.
fn select(shape: &[usize], values: &[f32], axis: usize, kept: &[usize]) -> Vec<f32> {
    let outer: usize = shape[..axis].iter().product();
    let inner: usize = shape[axis + 1..].iter().product();
    let mut out = Vec::with_capacity(outer * kept.len() * inner);
    for o in 0..outer {
        for &k in kept {
            let start = (o * shape[axis] + k) * inner;
            out.extend_from_slice(&values[start..start + inner]);
        }
    }
    out
}

/// Runs of channels along one tensor dimension: `(narrow count, wide count)` each, in order
/// (the fusion convolution reads one run per view, for example).
type Runs = Vec<(usize, usize)>;

/// One convolution's channel layout in both networks.
struct Layer {
    name: String,
    out: Runs,
    input: Runs,
    /// A transposed convolution, whose weight is `[in, out, k, k]` (else `[out, in, k, k]`).
    transposed: bool,
}

/// A generator for `config` whose output at the start is that of the (narrower) generator in
/// `bytes`: see the module's documentation.
pub fn generator_widened(
    bytes: &[u8],
    config: &ModelConfig,
    device: &Device,
) -> Result<Generator, WeightsError> {
    let narrow = weights::read_config(bytes, weights::Network::Generator)?;
    widenable(&narrow, config)?;
    let mut wide = config.init_generator(device)?;
    let mut fresh = weights::generator_to_bytes(&wide, config)?;
    let old = Tensors::parse(bytes)?;
    let new = Tensors::parse(&fresh)?;
    let mut values = new.values(&fresh);
    for layer in layers(&narrow, config) {
        for (part, copy) in [("weight", copy_weight as CopyTensor), ("bias", copy_bias)] {
            let name = format!("{}.conv.{part}", layer.name);
            let old = old.values_of(bytes, &name)?;
            let new = values.get_mut(&name).ok_or_else(|| missing(&name))?;
            copy(&layer, &old, new)
                .map_err(|why| WeightsError::Tensors(format!("{name}: {why}")))?;
        }
    }
    new.write(&mut fresh, &values);
    weights::apply(&mut wide, &fresh)?;
    Ok(wide)
}

/// Whether weights for `narrow` can start a network for `wide`: the same network but for a
/// width at least as large (and what changes no weight: the image size, the input copy, the
/// occupancy threshold).
pub fn widenable(narrow: &ModelConfig, wide: &ModelConfig) -> Result<(), WeightsError> {
    if wide.width < narrow.width {
        return Err(WeightsError::Narrower {
            found: narrow.width,
            wanted: wide.width,
        });
    }
    let mut same = narrow.clone();
    same.width = wide.width;
    weights::compatible(&same, wide)
}

/// The generator's convolutions, with each dimension's runs of channels (see
/// `Generator::new`: its layers, their order and their concatenations).
fn layers(narrow: &ModelConfig, wide: &ModelConfig) -> Vec<Layer> {
    let scaled = |k: usize| vec![(k * narrow.width, k * wide.width)];
    let fixed = |n: usize| vec![(n, n)];
    let planes = narrow.input_channels();
    let early = narrow.fusion() == Fusion::Early;
    let conv = |name: &str, out: Runs, input: Runs| Layer {
        name: name.to_string(),
        out,
        input,
        transposed: false,
    };
    let mut layers = vec![
        conv(
            "stem",
            scaled(1),
            if early {
                [fixed(planes), scaled(1)].concat()
            } else {
                fixed(planes)
            },
        ),
        conv("down.0", scaled(2), scaled(1)),
        conv("down.1", scaled(4), scaled(2)),
    ];
    for block in 0..narrow.res_blocks {
        for part in ["dilated", "plain"] {
            layers.push(conv(
                &format!("middle.{block}.{part}"),
                scaled(4),
                scaled(4),
            ));
        }
    }
    let (fusion_out, fusion_in, decoder_in) = if early {
        (scaled(1), fixed(planes), scaled(4))
    } else {
        (scaled(4), scaled(4), [scaled(4), scaled(4)].concat())
    };
    layers.push(conv("fusion", fusion_out, fusion_in.repeat(narrow.views)));
    for (name, input, out) in [
        ("up.0", decoder_in, scaled(2)),
        ("up.1", scaled(2), scaled(1)),
    ] {
        layers.push(Layer {
            transposed: true,
            ..conv(name, out, input)
        });
    }
    layers.push(conv("head", fixed(narrow.channels.count() + 1), scaled(1)));
    layers
}

/// Where channel `i` of the narrow network is in the wide one.
fn place(runs: &Runs, mut i: usize) -> usize {
    let mut offset = 0;
    for &(narrow, wide) in runs {
        if i < narrow {
            return offset + i;
        }
        i -= narrow;
        offset += wide;
    }
    unreachable!("channel past the layout's runs")
}

fn count(runs: &Runs) -> [usize; 2] {
    runs.iter().fold([0, 0], |[n, w], &(a, b)| [n + a, w + b])
}

/// A tensor's shape and values.
type Values = (Vec<usize>, Vec<f32>);

/// Writes a narrow tensor into the wide one; why not, when its shape does not fit the layout.
type CopyTensor = fn(&Layer, &Values, &mut Values) -> Result<(), String>;

/// Writes the narrow weight into the wide one: each old output channel reads its old inputs
/// with their old weights and nothing from the new ones.
fn copy_weight(layer: &Layer, old: &Values, new: &mut Values) -> Result<(), String> {
    let [out_n, out_w] = count(&layer.out);
    let [in_n, in_w] = count(&layer.input);
    let (dims_n, dims_w) = match layer.transposed {
        false => ([out_n, in_n], [out_w, in_w]),
        true => ([in_n, out_n], [in_w, out_w]),
    };
    let (old_shape, new_shape) = (&old.0, &new.0);
    let kernel: usize = old_shape.iter().skip(2).product();
    if old_shape.len() != 4
        || old_shape[..2] != dims_n
        || new_shape[..2] != dims_w
        || old_shape[2..] != new_shape[2..]
    {
        return Err(format!(
            "shapes {old_shape:?} and {new_shape:?} do not fit the layout"
        ));
    }
    // Index of the kernel block of (output channel o, input channel i).
    let at = |o: usize, i: usize, dims: [usize; 2]| match layer.transposed {
        false => (o * dims[1] + i) * kernel,
        true => (i * dims[1] + o) * kernel,
    };
    let new = &mut new.1;
    for o in 0..out_n {
        let o_wide = place(&layer.out, o);
        for i in 0..in_w {
            let start = at(o_wide, i, dims_w);
            new[start..start + kernel].fill(0.0);
        }
        for i in 0..in_n {
            let (from, to) = (at(o, i, dims_n), at(o_wide, place(&layer.input, i), dims_w));
            new[to..to + kernel].copy_from_slice(&old.1[from..from + kernel]);
        }
    }
    Ok(())
}

fn copy_bias(layer: &Layer, old: &Values, new: &mut Values) -> Result<(), String> {
    if [old.1.len(), new.1.len()] != count(&layer.out) {
        return Err(format!(
            "lengths {} and {} do not fit the layout",
            old.1.len(),
            new.1.len()
        ));
    }
    for (o, &value) in old.1.iter().enumerate() {
        new.1[place(&layer.out, o)] = value;
    }
    Ok(())
}

fn missing(name: &str) -> WeightsError {
    WeightsError::Tensors(format!("no tensor {name}"))
}

/// The f32 tensors of a safetensors file: name → (shape, byte range in the file).
struct Tensors(BTreeMap<String, (Vec<usize>, std::ops::Range<usize>)>);

impl Tensors {
    fn parse(bytes: &[u8]) -> Result<Tensors, WeightsError> {
        #[derive(serde::Deserialize)]
        struct Entry {
            dtype: String,
            shape: Vec<usize>,
            data_offsets: [usize; 2],
        }
        let bad = WeightsError::NotSafetensors("header unreadable");
        let len = bytes
            .get(..8)
            .ok_or(WeightsError::NotSafetensors("short"))?;
        let len = usize::try_from(u64::from_le_bytes(len.try_into().expect("8 bytes")))
            .ok()
            .and_then(|len| len.checked_add(8))
            .ok_or(WeightsError::NotSafetensors("header length past the end"))?;
        let header = bytes.get(8..len).ok_or(bad)?;
        let mut entries: BTreeMap<String, serde_json::Value> = serde_json::from_slice(header)
            .map_err(|_| WeightsError::NotSafetensors("header is not JSON"))?;
        entries.remove("__metadata__");
        let mut tensors = BTreeMap::new();
        for (name, value) in entries {
            let entry: Entry = serde_json::from_value(value)
                .map_err(|_| WeightsError::NotSafetensors("tensor entry unreadable"))?;
            // Checked, since the file is the user's: a range past its end or of another
            // size than the shape's is refused, not a panic.
            let [a, b] = entry.data_offsets;
            let size = entry
                .shape
                .iter()
                .try_fold(4usize, |n, &d| n.checked_mul(d));
            let range = len.checked_add(a).zip(len.checked_add(b));
            let fits = |&(start, end): &(usize, usize)| {
                end <= bytes.len() && end.checked_sub(start) == size
            };
            match range.filter(fits) {
                Some((start, end)) if entry.dtype == "F32" => {
                    tensors.insert(name, (entry.shape, start..end));
                }
                _ => {
                    return Err(WeightsError::Tensors(format!(
                        "{name}: not f32 data of its shape"
                    )))
                }
            }
        }
        Ok(Tensors(tensors))
    }

    fn values_of(&self, bytes: &[u8], name: &str) -> Result<Values, WeightsError> {
        let (shape, range) = self.0.get(name).ok_or_else(|| missing(name))?;
        let values = bytes[range.clone()]
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes(b.try_into().expect("4 bytes")))
            .collect();
        Ok((shape.clone(), values))
    }

    fn values(&self, bytes: &[u8]) -> BTreeMap<String, Values> {
        self.0
            .keys()
            .map(|name| (name.clone(), self.values_of(bytes, name).expect("parsed")))
            .collect()
    }

    fn write(&self, bytes: &mut [u8], values: &BTreeMap<String, Values>) {
        for (name, (_, range)) in &self.0 {
            let out = &mut bytes[range.clone()];
            for (chunk, value) in out.chunks_exact_mut(4).zip(&values[name].1) {
                chunk.copy_from_slice(&value.to_le_bytes());
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::gan::value;
    use crate::model::{Fusion, Preset};
    use burn::tensor::{Distribution, Tensor};

    fn widened_matches(narrow: ModelConfig, width: usize) {
        let device = Device::flex();
        let small = narrow.init_generator(&device).unwrap();
        let bytes = weights::generator_to_bytes(&small, &narrow).unwrap();
        let mut wide_config = narrow.clone();
        wide_config.width = width;
        let wide = generator_widened(&bytes, &wide_config, &device).unwrap();
        let x = Tensor::<5>::random([2, 4, 7, 32, 32], Distribution::Default, &device);
        let (a, b) = (small.forward(x.clone()), wide.forward(x.clone()));
        let diff = |p: Tensor<5>, q: Tensor<5>| value(p.sub(q).abs().max());
        assert!(diff(a.images.clone(), b.images) < 1e-5);
        assert!(diff(a.occupancy, b.occupancy) < 1e-4);
        // A fresh wide generator computes something else: the equality is the widening's.
        let other = wide_config.init_generator(&device).unwrap().forward(x);
        assert!(diff(a.images, other.images) > 1e-3);
    }

    #[test]
    fn a_widened_generator_starts_as_the_narrow_one() {
        widened_matches(Preset::Tiny.config(), 11);
    }

    #[test]
    fn a_widened_early_fusion_generator_starts_as_the_narrow_one() {
        widened_matches(Preset::Tiny.config().with_fusion_kind(Fusion::Early), 12);
    }

    /// Without colour in its input the narrowed generator is the colour one's geometry and
    /// occupancy; an early-fusion or geometry-only source is refused.
    #[test]
    fn a_generator_without_colour_starts_as_the_colour_ones_geometry() {
        let device = Device::flex();
        let coloured = Preset::Tiny.config();
        let g = coloured.init_generator(&device).unwrap();
        let bytes = weights::generator_to_bytes(&g, &coloured).unwrap();
        let xyz = coloured.clone().with_channels(Channels::Xyz);
        let narrowed = generator_without_colour(&bytes, &xyz, &device).unwrap();
        let geometry = Tensor::<5>::random([2, 4, 3, 32, 32], Distribution::Default, &device);
        let mask = Tensor::<5>::random([2, 4, 1, 32, 32], Distribution::Default, &device)
            .greater_elem(0.5)
            .float();
        let no_colour = Tensor::zeros([2, 4, 3, 32, 32], &device);
        let with_colour = Tensor::cat(vec![geometry.clone(), no_colour, mask.clone()], 2);
        let (a, b) = (
            g.forward(with_colour),
            narrowed.forward(Tensor::cat(vec![geometry, mask], 2)),
        );
        let diff = |p: Tensor<5>, q: Tensor<5>| value(p.sub(q).abs().max());
        assert!(diff(a.images.narrow(2, 0, 3), b.images) < 1e-5);
        assert!(diff(a.occupancy, b.occupancy) < 1e-4);

        let early = coloured.clone().with_fusion_kind(Fusion::Early);
        let xyz_early = early.clone().with_channels(Channels::Xyz);
        assert!(colour_droppable(&early, &xyz_early).is_err());
        assert!(colour_droppable(&xyz, &xyz).is_err());
        assert!(colour_droppable(&coloured, &xyz.clone().with_width(9)).is_err());
    }

    #[test]
    fn a_cut_off_file_is_an_error_not_a_panic() {
        let device = Device::flex();
        let narrow = Preset::Tiny.config();
        let g = narrow.init_generator(&device).unwrap();
        let bytes = weights::generator_to_bytes(&g, &narrow).unwrap();
        let mut wide = narrow.clone();
        wide.width += 2;
        let cut = &bytes[..bytes.len() - 100];
        assert!(matches!(
            generator_widened(cut, &wide, &device),
            Err(WeightsError::Tensors(_))
        ));
    }

    #[test]
    fn narrower_or_deeper_is_refused() {
        let narrow = Preset::Tiny.config();
        let mut thinner = narrow.clone();
        thinner.width -= 1;
        assert!(matches!(
            widenable(&narrow, &thinner),
            Err(WeightsError::Narrower { .. })
        ));
        let mut deeper = narrow.clone();
        deeper.width += 2;
        deeper.res_blocks += 1;
        assert!(matches!(
            widenable(&narrow, &deeper),
            Err(WeightsError::ConfigMismatch { .. })
        ));
    }
}
