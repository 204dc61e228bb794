//! The orientation network: the paper's spatial transformer reduced to what mvpcc needs, a
//! rotation about the vertical. A PointNet (a per-point MLP, max-pooled over the points, then
//! an MLP) reads a fixed number of the upright cloud's points and predicts its heading twice:
//! the length axis as `(cos 2h, sin 2h)`, which has no front/back ambiguity to learn, and the
//! front as `(cos h, sin h)`. The heading is the axis's end nearer the front estimate.

use super::{angle_between, toward};
use crate::core::cloud::Aabb;
use crate::core::rng::Lcg;
use crate::model::weights::{apply, read_declared, to_bytes, Network, WeightsError};
use burn::config::Config;
use burn::module::Module;
use burn::nn::{Linear, LinearConfig};
use burn::tensor::activation::relu;
use burn::tensor::{Device, Tensor, TensorData};

#[derive(Config, Debug, PartialEq)]
pub struct OrienterConfig {
    /// Widths of the per-point layers; the last is the pooled feature's.
    #[config(default = "vec![64, 128, 256]")]
    pub point_widths: Vec<usize>,
    /// Width of the hidden layer after pooling.
    #[config(default = 128)]
    pub hidden: usize,
    /// Points read from a cloud (drawn evenly over it).
    #[config(default = 1024)]
    pub points: usize,
}

impl OrienterConfig {
    /// Refuses shapes no orientation network needs (layers over 4096 wide, more than 16 of
    /// them, over 2¹⁶ points), which a damaged weights file could otherwise make the loader
    /// build before its tensors are looked at.
    pub fn validate(&self) -> Result<(), String> {
        let widths = self.point_widths.iter().chain([&self.hidden]);
        if self.point_widths.is_empty() || self.point_widths.len() > 16 {
            return Err(format!(
                "{} point layers (1 to 16 expected)",
                self.point_widths.len()
            ));
        }
        if let Some(w) = widths.into_iter().find(|&&w| w == 0 || w > 4096) {
            return Err(format!("a layer {w} wide (1 to 4096 expected)"));
        }
        if self.points == 0 || self.points > 1 << 16 {
            return Err(format!("{} points (1 to 65536 expected)", self.points));
        }
        Ok(())
    }
}

#[derive(Module, Debug)]
pub struct OrienterNet {
    point: Vec<Linear>,
    hidden: Linear,
    head: Linear,
}

impl OrienterNet {
    pub fn new(config: &OrienterConfig, device: &Device) -> OrienterNet {
        let mut widths = vec![3];
        widths.extend(&config.point_widths);
        let point = widths
            .windows(2)
            .map(|w| LinearConfig::new(w[0], w[1]).init(device))
            .collect();
        let pooled = *widths.last().expect("at least the input width");
        OrienterNet {
            point,
            hidden: LinearConfig::new(pooled, config.hidden).init(device),
            head: LinearConfig::new(config.hidden, 4).init(device),
        }
    }

    /// # Shapes
    /// `points`: `[batch, N, 3]` (upright, centred, longest side 1) → `[batch, 4]`:
    /// `(cos 2h, sin 2h, cos h, sin h)` of the heading `h`.
    pub fn forward(&self, points: Tensor<3>) -> Tensor<2> {
        let mut x = points;
        for layer in &self.point {
            // [batch, N, width]
            x = relu(layer.forward(x));
        }
        // [batch, width]: the symmetric function that makes the net ignore point order.
        let pooled: Tensor<2> = x.max_dim(1).squeeze_dim(1);
        self.head.forward(relu(self.hidden.forward(pooled)))
    }
}

/// Heading (degrees) from the network's four outputs.
pub fn decode(out: &[f32]) -> f64 {
    let axis = (out[1] as f64).atan2(out[0] as f64).to_degrees() / 2.0;
    let front = (out[3] as f64).atan2(out[2] as f64).to_degrees();
    toward(axis, front)
}

/// Network outputs wanted for heading `h`.
pub fn target(heading: f64) -> [f32; 4] {
    let (s2, c2) = (2.0 * heading).to_radians().sin_cos();
    let (s, c) = heading.to_radians().sin_cos();
    [c2 as f32, s2 as f32, c as f32, s as f32]
}

/// `count` points of `points` (upright), centred on their box and scaled to a longest side of
/// 1, as the network reads them. Points are drawn with a fixed stride from a random start, or
/// repeated when there are fewer.
pub fn sample_points(points: &[[f64; 3]], count: usize, rng: &mut Lcg) -> Vec<f32> {
    let bounds = Aabb::of(points).unwrap_or(Aabb {
        min: [0.0; 3],
        max: [0.0; 3],
    });
    let center = bounds.center();
    let extent = bounds.longest_side().max(f64::MIN_POSITIVE);
    let n = points.len();
    let start = rng.below(n.max(1));
    let mut out = Vec::with_capacity(count * 3);
    for k in 0..count {
        let p = points[(start + k * n / count.max(1) + k / n.max(1)) % n];
        out.extend((0..3).map(|i| ((p[i] - center[i]) / extent) as f32));
    }
    out
}

/// A trained orientation network ready to run.
#[derive(Debug)]
pub struct Orienter {
    net: OrienterNet,
    config: OrienterConfig,
    device: Device,
}

impl Orienter {
    pub fn new(net: OrienterNet, config: OrienterConfig, device: Device) -> Orienter {
        Orienter {
            net,
            config,
            device,
        }
    }

    /// The built-in orientation network, on the CPU: a network this small runs fastest there.
    pub fn builtin() -> Result<Orienter, WeightsError> {
        Orienter::from_bytes(super::DEFAULT_ORIENTER, Device::flex())
    }

    pub fn from_bytes(bytes: &[u8], device: Device) -> Result<Orienter, WeightsError> {
        let config: OrienterConfig = read_declared(bytes, Network::Orienter)?;
        config.validate().map_err(WeightsError::InvalidOrienter)?;
        let mut net = OrienterNet::new(&config, &device);
        apply(&mut net, bytes)?;
        Ok(Orienter::new(net, config, device))
    }

    pub fn to_bytes(&self) -> Result<Vec<u8>, WeightsError> {
        to_bytes(&self.net, Network::Orienter, &self.config)
    }

    pub fn config(&self) -> &OrienterConfig {
        &self.config
    }

    /// Heading of an upright cloud. The network runs on a few draws of the points and the
    /// heading most of them agree with wins, so one unlucky draw cannot flip the front.
    pub fn heading(&self, points: &[[f64; 3]]) -> f64 {
        const DRAWS: usize = 4;
        if points.is_empty() {
            return 90.0;
        }
        let n = self.config.points;
        let mut rng = Lcg::new(0x6f72_6965_6e74);
        let data: Vec<f32> = (0..DRAWS)
            .flat_map(|_| sample_points(points, n, &mut rng))
            .collect();
        let input = Tensor::<3>::from_data(TensorData::new(data, [DRAWS, n, 3]), &self.device);
        let out = self
            .net
            .forward(input)
            .into_data()
            .try_into_vec::<f32>()
            .unwrap_or_default();
        let headings: Vec<f64> = out.chunks_exact(4).map(decode).collect();
        let Some(&first) = headings.first() else {
            return 90.0;
        };
        // Mean of the draws' output vectors, decoded once: a vote weighted by confidence.
        let mut mean = [0f32; 4];
        for chunk in out.chunks_exact(4) {
            for (m, v) in mean.iter_mut().zip(chunk) {
                *m += v / DRAWS as f32;
            }
        }
        let voted = decode(&mean);
        if voted.is_finite() && headings.iter().any(|&h| angle_between(h, voted) < 45.0) {
            voted
        } else {
            first
        }
    }

    pub fn net(&self) -> &OrienterNet {
        &self.net
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn targets_decode_to_their_heading() {
        for h in [0.0, 30.0, 89.0, 180.0, 271.0, 359.5] {
            let t = target(h);
            assert!(angle_between(decode(&t), h) < 1e-4, "{h}");
        }
    }

    #[test]
    fn samples_are_centred_scaled_and_sized() {
        let points: Vec<[f64; 3]> = (0..10)
            .map(|i| [1000.0 + i as f64, 5.0, 2.0 * i as f64])
            .collect();
        let mut rng = Lcg::new(1);
        let s = sample_points(&points, 25, &mut rng);
        assert_eq!(s.len(), 75);
        for p in s.chunks(3) {
            assert!(p.iter().all(|v| v.abs() <= 0.5 + 1e-6), "{p:?}");
        }
        let z: Vec<f32> = s.chunks(3).map(|p| p[2]).collect();
        assert!(z.contains(&0.5) && z.contains(&-0.5));
    }

    #[test]
    fn weights_round_trip() {
        let device = Device::flex();
        let config = OrienterConfig::new()
            .with_point_widths(vec![8, 16])
            .with_hidden(8);
        let net = OrienterNet::new(&config, &device);
        let orienter = Orienter::new(net, config.clone(), device.clone());
        let bytes = orienter.to_bytes().unwrap();
        let back = Orienter::from_bytes(&bytes, device).unwrap();
        assert_eq!(back.config(), &config);
        let points: Vec<[f64; 3]> = (0..300)
            .map(|i| [(i % 7) as f64, (i % 3) as f64, (i % 11) as f64 * 0.7])
            .collect();
        assert_eq!(orienter.heading(&points), back.heading(&points));
        // A generator file is not an orienter.
        assert!(Orienter::from_bytes(crate::complete::DEFAULT_MODEL, Device::flex()).is_err());
    }
}
