//! View images in, completed view images out: the bridge between the geometry pipeline
//! ([`ViewImages`]) and the network ([`Generator`]).

use crate::model::weights::{generator_from_bytes, WeightsError};
use crate::model::{Channels, ConfigError, Generator, ModelConfig, NoProbe};
use crate::views::projection::{ViewImages, CHANNELS};
use burn::tensor::{Device, Tensor, TensorData};
use std::time::{Duration, Instant};
use thiserror::Error;

#[derive(Debug, Error)]
pub enum InpaintError {
    #[error("object {object} has {found} views, the model takes {expected}")]
    Views {
        object: usize,
        found: usize,
        expected: usize,
    },
    #[error(
        "object {object} has {found}×{found} pixel views, the model takes {expected}×{expected}"
    )]
    Size {
        object: usize,
        found: usize,
        expected: usize,
    },
    #[error("the device failed")]
    Device(#[source] crate::model::weights::Cause),
}

/// Wall time of the generator's three stages for one batch.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct StageTimes {
    pub encoder: Duration,
    pub fusion: Duration,
    pub decoder: Duration,
}

/// What the generator made of a batch, before any occupancy threshold: per object and view the
/// channels' planes and the occupancy logits.
#[derive(Debug, Clone, Default)]
pub struct Generated {
    images: Vec<f32>,
    logits: Vec<f32>,
}

/// Appends one object's network input: per view the channels' planes (geometry shifted into
/// [0, 1] like the dataset's PNGs, empty pixels 0) and its occupancy plane.
///
/// # Shapes
/// appends `[views, channels + 1, S, S]`
pub fn encode_input(views: &ViewImages, channels: Channels, out: &mut Vec<f32>) {
    for view in 0..views.views() {
        encode_planes(views, view, channels, out);
        encode_occupancy(views, view, out);
    }
}

/// Appends one object's training target: the channels' planes as [`encode_input`] writes them
/// to `images` and the occupancy to `occupancy`.
///
/// # Shapes
/// appends `[views, channels, S, S]` and `[views, 1, S, S]`
pub fn encode_target(
    views: &ViewImages,
    channels: Channels,
    images: &mut Vec<f32>,
    occupancy: &mut Vec<f32>,
) {
    for view in 0..views.views() {
        encode_planes(views, view, channels, images);
        encode_occupancy(views, view, occupancy);
    }
}

fn encode_occupancy(views: &ViewImages, view: usize, out: &mut Vec<f32>) {
    out.extend(
        views
            .view_occupancy(view)
            .iter()
            .map(|&o| if o { 1.0f32 } else { 0.0 }),
    );
}

fn encode_planes(views: &ViewImages, view: usize, channels: Channels, out: &mut Vec<f32>) {
    let plane = views.size * views.size;
    let px = views.view_pixels(view);
    let occupied = views.view_occupancy(view);
    for ch in 0..channels.count() {
        let src = &px[ch * plane..(ch + 1) * plane];
        let shift = if ch < 3 { 0.5 } else { 0.0 };
        out.extend(
            src.iter()
                .zip(occupied)
                .map(|(&x, &o)| if o { x + shift } else { 0.0 }),
        );
    }
}

pub struct Inpainter {
    generator: Generator,
    config: ModelConfig,
    device: Device,
}

impl Inpainter {
    pub fn new(generator: Generator, config: ModelConfig, device: Device) -> Inpainter {
        Inpainter {
            generator,
            config,
            device,
        }
    }

    /// Loads a generator weights file (see [`crate::model::weights`]).
    pub fn from_bytes(bytes: &[u8], device: Device) -> Result<Inpainter, WeightsError> {
        let (generator, config) = generator_from_bytes(bytes, &device)?;
        Ok(Inpainter::new(generator, config, device))
    }

    pub fn config(&self) -> &ModelConfig {
        &self.config
    }

    /// The same weights with another occupancy threshold (a probability in (0, 1); see
    /// [`ModelConfig::occupancy_threshold`]).
    pub fn with_occupancy(mut self, threshold: f64) -> Result<Inpainter, ConfigError> {
        let config = self.config.clone().with_occupancy(Some(threshold));
        config.validate()?;
        self.config = config;
        Ok(self)
    }

    /// Completes a batch of objects in one forward pass. Every pixel of the output comes from
    /// the network: it is occupied where the predicted occupancy exceeds the config's
    /// threshold ([`ModelConfig::occupancy_threshold`]), and holds
    /// the predicted geometry (and colour, for an XYZRGB model given coloured views).
    pub fn inpaint(&self, batch: &[ViewImages]) -> Result<Vec<ViewImages>, InpaintError> {
        self.inpaint_timed(batch).map(|(views, _)| views)
    }

    /// [`Self::inpaint`], timing the encoder, the fusion and the decoder (the device is
    /// synchronized between them, so each time is its own).
    pub fn inpaint_timed(
        &self,
        batch: &[ViewImages],
    ) -> Result<(Vec<ViewImages>, StageTimes), InpaintError> {
        let (generated, times) = self.generate_timed(batch)?;
        let views = self.views_at(batch, &generated, self.config.occupancy_threshold());
        Ok((views, times))
    }

    /// The generator's output for a batch, from which [`Self::views_at`] cuts views at any
    /// occupancy threshold; timed as [`Self::inpaint_timed`].
    pub fn generate_timed(
        &self,
        batch: &[ViewImages],
    ) -> Result<(Generated, StageTimes), InpaintError> {
        let mut times = StageTimes::default();
        if batch.is_empty() {
            return Ok((Generated::default(), times));
        }
        let input = self.input_tensor(batch)?; // [B, V, C+1, S, S]
        let sync = |device: &Device| device.sync().map_err(|e| InpaintError::Device(e.into()));
        sync(&self.device)?;
        let probe = &mut NoProbe;
        let start = Instant::now();
        let features = self.generator.encode(input.clone(), probe); // [B·V, 4w, S/4, S/4]
        sync(&self.device)?;
        times.encoder = start.elapsed();
        let start = Instant::now();
        let joined = self.generator.fuse(features, batch.len(), probe); // [B·V, 8w, S/4, S/4]
        sync(&self.device)?;
        times.fusion = start.elapsed();
        let start = Instant::now();
        let output = self
            .generator
            .decode(joined, &input, batch.len(), self.config.size, probe);
        let images = output
            .images
            .into_data()
            .try_into_vec::<f32>()
            .expect("the generator returns f32");
        let logits = output
            .occupancy
            .into_data()
            .try_into_vec::<f32>()
            .expect("the generator returns f32");
        times.decoder = start.elapsed();
        Ok((Generated { images, logits }, times))
    }

    /// # Shapes
    /// → `[batch, views, channels + 1, S, S]`
    fn input_tensor(&self, batch: &[ViewImages]) -> Result<Tensor<5>, InpaintError> {
        let (v, s) = (self.config.views, self.config.size);
        let c = self.config.channels.count();
        for (object, views) in batch.iter().enumerate() {
            if views.views() != v {
                return Err(InpaintError::Views {
                    object,
                    found: views.views(),
                    expected: v,
                });
            }
            if views.size != s {
                return Err(InpaintError::Size {
                    object,
                    found: views.size,
                    expected: s,
                });
            }
        }
        let mut data = Vec::with_capacity(batch.len() * v * (c + 1) * s * s);
        for views in batch {
            encode_input(views, self.config.channels, &mut data);
        }
        let shape = [batch.len(), v, c + 1, s, s];
        Ok(Tensor::from_data(
            TensorData::new(data, shape),
            &self.device,
        ))
    }

    /// The views of `batch` the generator made (`generated`), a pixel occupied where its
    /// predicted occupancy exceeds `threshold` (a probability).
    pub fn views_at(
        &self,
        batch: &[ViewImages],
        generated: &Generated,
        threshold: f64,
    ) -> Vec<ViewImages> {
        let (v, s) = (self.config.views, self.config.size);
        let c = self.config.channels.count();
        let plane = s * s;
        let cut = self
            .config
            .clone()
            .with_occupancy(Some(threshold))
            .occupancy_logit();
        let (images, logits) = (&generated.images, &generated.logits);
        batch
            .iter()
            .enumerate()
            .map(|(b, input)| {
                let has_color = self.config.channels == Channels::Xyzrgb && input.has_color;
                let mut out = ViewImages::empty(input.cameras.clone(), s, has_color);
                for view in 0..v {
                    let object_view = b * v + view;
                    let logit = &logits[object_view * plane..(object_view + 1) * plane];
                    let img = &images[object_view * c * plane..(object_view + 1) * c * plane];
                    let px =
                        &mut out.pixels[view * CHANNELS * plane..(view + 1) * CHANNELS * plane];
                    let occ = &mut out.occupancy[view * plane..(view + 1) * plane];
                    for at in 0..plane {
                        if logit[at] <= cut {
                            continue;
                        }
                        occ[at] = true;
                        for ch in 0..3 {
                            px[ch * plane + at] = img[ch * plane + at] - 0.5;
                        }
                        if has_color {
                            for ch in 3..6 {
                                px[ch * plane + at] = img[ch * plane + at];
                            }
                        }
                    }
                }
                out
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::datagen::shapes::example_car_views;
    use crate::model::weights::generator_to_bytes;
    use crate::model::Preset;

    /// A freshly initialized tiny generator's weights file.
    fn tiny_weights(device: &Device) -> Vec<u8> {
        let config = Preset::Tiny.config();
        let g = config.init_generator(device).unwrap();
        generator_to_bytes(&g, &config).unwrap()
    }

    #[test]
    fn views_in_views_out_with_valid_geometry() {
        let device = Device::flex();
        let bytes = tiny_weights(&device);
        let inpainter = Inpainter::from_bytes(&bytes, device).unwrap();
        let views = example_car_views(32);
        let out = inpainter.inpaint(&[views.clone(), views.clone()]).unwrap();
        assert_eq!(out.len(), 2);
        for o in &out {
            assert_eq!((o.views(), o.size), (4, 32));
            assert_eq!(o.cameras, views.cameras);
            assert_eq!(o.has_color, views.has_color);
            let plane = 32 * 32;
            for v in 0..4 {
                let px = o.view_pixels(v);
                for (at, &occ) in o.view_occupancy(v).iter().enumerate() {
                    for ch in 0..3 {
                        let x = px[ch * plane + at];
                        if occ {
                            assert!((-0.5..=0.5).contains(&x));
                        } else {
                            assert_eq!(x, 0.0);
                        }
                    }
                }
            }
        }
        // The same object twice in one batch comes out the same.
        assert_eq!(out[0].pixels, out[1].pixels);
    }

    #[test]
    fn a_lower_occupancy_threshold_adds_pixels_and_moves_none() {
        let device = Device::flex();
        let bytes = tiny_weights(&device);
        let views = example_car_views(32);
        let inpainter = || Inpainter::from_bytes(&bytes, device.clone()).unwrap();
        let at = |p: f64| {
            let tuned = inpainter().with_occupancy(p).unwrap();
            tuned
                .inpaint(std::slice::from_ref(&views))
                .unwrap()
                .remove(0)
        };
        let half = inpainter()
            .inpaint(std::slice::from_ref(&views))
            .unwrap()
            .remove(0);
        assert_eq!(at(0.5), half);
        let (low, high) = (at(0.01), at(0.99));
        let count = |v: &ViewImages| v.occupancy.iter().filter(|&&o| o).count();
        assert!(count(&low) > count(&high));
        let plane = 32 * 32;
        for (fewer, more) in [(&high, &half), (&half, &low)] {
            for (at, _) in fewer.occupancy.iter().enumerate().filter(|(_, &o)| o) {
                assert!(more.occupancy[at]);
                let (v, i) = (at / plane, at % plane);
                for ch in 0..3 {
                    let k = (v * CHANNELS + ch) * plane + i;
                    assert_eq!(fewer.pixels[k], more.pixels[k]);
                }
            }
        }
        for p in [0.0, 1.0, f64::NAN] {
            assert!(matches!(
                inpainter().with_occupancy(p),
                Err(ConfigError::Occupancy(_))
            ));
        }
    }

    #[test]
    fn wrong_view_count_or_size_is_an_error() {
        let device = Device::flex();
        let config = Preset::Tiny.config();
        let inpainter = Inpainter::new(config.init_generator(&device).unwrap(), config, device);
        let wrong_size = example_car_views(64);
        assert!(matches!(
            inpainter.inpaint(&[wrong_size]),
            Err(InpaintError::Size {
                object: 0,
                found: 64,
                expected: 32
            })
        ));
        let three = ViewImages::empty(vec![5, 6, 7], 32, false);
        assert!(matches!(
            inpainter.inpaint(&[example_car_views(32), three]),
            Err(InpaintError::Views { object: 1, .. })
        ));
    }
}
