//! The map between a cloud's own coordinates and the unit box the network works in.
//!
//! Convention of the original dataset: bounding box centred at the origin, longest side 1,
//! +y up, the object's length along z, its front towards −z. The map is a proper rotation (a
//! signed axis permutation, then a turn about the vertical when the object's heading is known,
//! so nothing is mirrored), a translation and a uniform scale, all in f64, so its inverse
//! restores georeferenced coordinates to ~1e-16 relative.
//!
//! A heading is the direction the object's front faces, in degrees counter-clockwise from the
//! input's +x axis seen from above (for a y-up input, from above means looking down −y). The
//! canonical pose has heading 90° in y-up coordinates.

use crate::core::cloud::{Aabb, PointCloud};
use serde::{Deserialize, Serialize};
use thiserror::Error;

/// Which input axis points up.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum UpAxis {
    Y,
    Z,
}

#[derive(Debug, Error, PartialEq)]
pub enum FrameError {
    #[error("the cloud has no points")]
    Empty,
    #[error("all points are identical (zero extent), so the cloud cannot be normalized")]
    ZeroExtent,
    /// Coordinates near ±1.8e308 span more than an f64 holds: the frame wrote a `null` extent
    /// that `reproject` then could not use.
    #[error("the coordinates are too large to normalize (their box overflows f64)")]
    Overflow,
}

/// The extent and centre of a frame, refused where they cannot normalize anything.
fn checked(extent: f64, center: [f64; 3]) -> Result<(), FrameError> {
    if extent.is_nan() || extent <= 0.0 {
        Err(FrameError::ZeroExtent)
    } else if !extent.is_finite() || center.iter().any(|c| !c.is_finite()) {
        Err(FrameError::Overflow)
    } else {
        Ok(())
    }
}

/// `normalized = R · (p − center) / extent`, with `R` a rotation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Frame {
    pub center: [f64; 3],
    pub extent: f64,
    pub rotation: [[f64; 3]; 3],
}

const IDENTITY: [[f64; 3]; 3] = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
/// z-up to y-up: (x, y, z) → (x, z, −y).
const Z_UP_TO_Y_UP: [[f64; 3]; 3] = [[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]];
/// Quarter turn about y that puts the x extent onto z: (x, y, z) → (−z, y, x).
const X_TO_Z: [[f64; 3]; 3] = [[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]];

fn mat_mul(a: &[[f64; 3]; 3], b: &[[f64; 3]; 3]) -> [[f64; 3]; 3] {
    let mut m = [[0.0; 3]; 3];
    for (i, row) in m.iter_mut().enumerate() {
        for (j, v) in row.iter_mut().enumerate() {
            *v = (0..3).map(|k| a[i][k] * b[k][j]).sum();
        }
    }
    m
}

fn apply(m: &[[f64; 3]; 3], v: [f64; 3]) -> [f64; 3] {
    [0, 1, 2].map(|i| m[i][0] * v[0] + m[i][1] * v[1] + m[i][2] * v[2])
}

fn transposed(m: &[[f64; 3]; 3]) -> [[f64; 3]; 3] {
    [0, 1, 2].map(|i| [0, 1, 2].map(|j| m[j][i]))
}

fn apply_transposed(m: &[[f64; 3]; 3], v: [f64; 3]) -> [f64; 3] {
    [0, 1, 2].map(|i| m[0][i] * v[0] + m[1][i] * v[1] + m[2][i] * v[2])
}

/// The rotation that stands a cloud with up axis `up` upright (+y up), keeping x.
pub fn upright(up: UpAxis) -> [[f64; 3]; 3] {
    match up {
        UpAxis::Y => IDENTITY,
        UpAxis::Z => Z_UP_TO_Y_UP,
    }
}

/// Turn about +y (y-up coordinates) that brings an upright object of `heading` degrees into
/// the canonical pose, front towards −z.
pub fn yaw_to_canonical(heading: f64) -> [[f64; 3]; 3] {
    let (s, c) = (90.0 - heading).to_radians().sin_cos();
    [[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]]
}

impl Frame {
    /// Fits the frame to a cloud whose up axis is `up`; the longer horizontal extent is turned
    /// onto z (which end is the front is left as it comes).
    pub fn fit(cloud: &PointCloud, up: UpAxis) -> Result<Frame, FrameError> {
        let bounds = cloud.bounds().ok_or(FrameError::Empty)?;
        let size = bounds.extent();
        let extent = bounds.longest_side();
        checked(extent, bounds.center())?;
        let upright = upright(up);
        // Extents of the upright box along its x and z (a permutation only moves the sides).
        let upright_size = apply(&upright, size).map(f64::abs);
        let rotation = if upright_size[0] > upright_size[2] {
            mat_mul(&X_TO_Z, &upright)
        } else {
            upright
        };
        Ok(Frame {
            center: bounds.center(),
            extent,
            rotation,
        })
    }

    /// Fits the frame to a cloud whose up axis is `up` and whose front faces `heading`
    /// degrees: the cloud is turned into the canonical pose, then boxed.
    pub fn fit_heading(cloud: &PointCloud, up: UpAxis, heading: f64) -> Result<Frame, FrameError> {
        Frame::fit_rotation(cloud, mat_mul(&yaw_to_canonical(heading), &upright(up)))
    }

    /// The cloud turned by `rotation`, then boxed.
    fn fit_rotation(cloud: &PointCloud, rotation: [[f64; 3]; 3]) -> Result<Frame, FrameError> {
        let bounds = cloud.bounds().ok_or(FrameError::Empty)?;
        // Turned about the axis-aligned centre, so georeferenced offsets cost no precision.
        let origin = bounds.center();
        checked(bounds.longest_side(), origin)?;
        let turned = Aabb::of_iter(
            cloud
                .positions
                .iter()
                .map(|p| apply(&rotation, [0, 1, 2].map(|i| p[i] - origin[i]))),
        )
        .ok_or(FrameError::Empty)?;
        let extent = turned.longest_side();
        let offset = apply_transposed(&rotation, turned.center());
        let center = [0, 1, 2].map(|i| origin[i] + offset[i]);
        checked(extent, center)?;
        Ok(Frame {
            center,
            extent,
            rotation,
        })
    }

    /// This frame turned about its length axis (z) by `-roll` degrees and fitted to `cloud`
    /// again: a vehicle whose plane of symmetry has the normal (cos r, sin r, 0) in this frame
    /// stands upright in the new one (see [`crate::complete::symmetry::find_roll`]).
    pub fn rolled(&self, cloud: &PointCloud, roll: f64) -> Result<Frame, FrameError> {
        let (s, c) = roll.to_radians().sin_cos();
        let unroll = [[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]];
        Frame::fit_rotation(cloud, mat_mul(&unroll, &self.rotation))
    }

    /// Refuses a frame read from a file that cannot map points back: a non-finite centre, an
    /// extent that is not positive, or a rotation that is not one (rows orthonormal to 1e-6).
    pub fn check(&self) -> Result<(), String> {
        if !self.center.iter().all(|c| c.is_finite()) {
            return Err("the frame's centre is not finite".into());
        }
        if !(self.extent.is_finite() && self.extent > 0.0) {
            return Err(format!(
                "the frame's extent {} is not positive",
                self.extent
            ));
        }
        let gram = mat_mul(&self.rotation, &transposed(&self.rotation));
        let off = (0..3)
            .flat_map(|i| (0..3).map(move |j| (i, j)))
            .map(|(i, j)| (gram[i][j] - f64::from(u8::from(i == j))).abs())
            .fold(0.0, f64::max);
        if off.is_nan() || off > 1e-6 {
            return Err("the frame's rotation is not a rotation".into());
        }
        Ok(())
    }

    pub fn to_normalized(&self, p: [f64; 3]) -> [f64; 3] {
        let d = [0, 1, 2].map(|i| (p[i] - self.center[i]) / self.extent);
        apply(&self.rotation, d)
    }

    pub fn to_input(&self, q: [f64; 3]) -> [f64; 3] {
        let d = apply_transposed(&self.rotation, q);
        [0, 1, 2].map(|i| d[i] * self.extent + self.center[i])
    }

    /// The cloud in normalized coordinates; colours and attributes are kept.
    pub fn normalize(&self, cloud: &PointCloud) -> PointCloud {
        PointCloud {
            positions: cloud
                .positions
                .iter()
                .map(|&p| self.to_normalized(p))
                .collect(),
            quantization: None,
            crs: Vec::new(),
            viewpoint: None,
            ..cloud.clone()
        }
    }

    /// The cloud mapped back into the input's coordinates.
    pub fn denormalize(&self, cloud: &PointCloud) -> PointCloud {
        PointCloud {
            positions: cloud.positions.iter().map(|&q| self.to_input(q)).collect(),
            ..cloud.clone()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn det(m: &[[f64; 3]; 3]) -> f64 {
        m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
            - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
    }

    /// A z-up box 4 m long along x, 2 m wide, 1.5 m high, at georeferenced coordinates.
    fn georeferenced_box() -> PointCloud {
        let base = [650_123.25, 5_270_456.5, 112.75];
        let mut positions = Vec::new();
        for i in 0..=4 {
            for j in 0..=2 {
                for k in 0..=3 {
                    positions.push([
                        base[0] + i as f64,
                        base[1] + j as f64,
                        base[2] + 0.5 * k as f64,
                    ]);
                }
            }
        }
        PointCloud::from_positions(positions)
    }

    #[test]
    fn a_rolled_frame_stands_the_leaning_plane_upright() {
        let cloud = georeferenced_box();
        let frame = Frame::fit_heading(&cloud, UpAxis::Z, 0.0).unwrap();
        let roll = 2.5_f64;
        let rolled = frame.rolled(&cloud, roll).unwrap();
        assert!(rolled.check().is_ok());
        // The plane's normal (cos r, sin r, 0) in the upright frame is +x in the rolled one.
        let (s, c) = roll.to_radians().sin_cos();
        let origin = frame.to_input([0.0; 3]);
        let tip = frame.to_input([c, s, 0.0]);
        let [a, b] = [origin, tip].map(|p| rolled.to_normalized(p));
        let n = [0, 1, 2].map(|i| (b[i] - a[i]) * rolled.extent / frame.extent);
        assert!(
            (n[0] - 1.0).abs() < 1e-9 && n[1].abs() < 1e-9 && n[2].abs() < 1e-9,
            "{n:?}"
        );
        // Refitted: the box still holds every point within the unit cube's half-side.
        let reach = cloud
            .positions
            .iter()
            .flat_map(|&p| rolled.to_normalized(p))
            .fold(0.0_f64, |m, v| m.max(v.abs()));
        assert!((reach - 0.5).abs() < 1e-9, "{reach}");
    }

    #[test]
    fn z_up_box_becomes_unit_box_with_length_on_z_and_height_on_y() {
        let cloud = georeferenced_box();
        let frame = Frame::fit(&cloud, UpAxis::Z).unwrap();
        assert_eq!(det(&frame.rotation), 1.0);
        let n = frame.normalize(&cloud);
        let b = n.bounds().unwrap();
        let e = b.extent();
        assert!((e[2] - 1.0).abs() < 1e-12, "length on z: {e:?}");
        assert!((e[0] - 0.5).abs() < 1e-12, "width on x: {e:?}");
        assert!((e[1] - 0.375).abs() < 1e-12, "height on y: {e:?}");
        for c in b.center() {
            assert!(c.abs() < 1e-12);
        }
        // The top of the box (largest input z) must end up at the largest y.
        let top = cloud
            .positions
            .iter()
            .position(|p| p[2] == 112.75 + 1.5)
            .unwrap();
        assert!((n.positions[top][1] - 0.1875).abs() < 1e-12);
    }

    #[test]
    fn round_trip_restores_georeferenced_coordinates() {
        let cloud = georeferenced_box();
        for up in [UpAxis::Y, UpAxis::Z] {
            let frame = Frame::fit(&cloud, up).unwrap();
            let back = frame.denormalize(&frame.normalize(&cloud));
            for (a, b) in cloud.positions.iter().zip(&back.positions) {
                for i in 0..3 {
                    assert!((a[i] - b[i]).abs() <= 1e-9 * a[i].abs(), "{a:?} vs {b:?}");
                }
            }
        }
    }

    #[test]
    fn y_up_cloud_long_on_z_is_not_rotated() {
        let cloud = PointCloud::from_positions(vec![[0.0, 0.0, 0.0], [1.0, 1.0, 3.0]]);
        let frame = Frame::fit(&cloud, UpAxis::Y).unwrap();
        assert_eq!(frame.rotation, IDENTITY);
        assert_eq!(frame.extent, 3.0);
        assert_eq!(
            frame.to_normalized([1.0, 1.0, 3.0]),
            [1.0 / 6.0, 1.0 / 6.0, 0.5]
        );
    }

    #[test]
    fn heading_turns_the_front_to_minus_z_and_round_trips() {
        // The box is 4 m long on x; a front facing +x (heading 0°) must land at −z.
        let mut cloud = georeferenced_box();
        let front = [650_127.25, 5_270_457.5, 113.5];
        cloud.positions.push(front);
        let frame = Frame::fit_heading(&cloud, UpAxis::Z, 0.0).unwrap();
        assert!((det(&frame.rotation) - 1.0).abs() < 1e-12);
        let f = frame.to_normalized(front);
        assert!((f[2] + 0.5).abs() < 1e-12 && f[0].abs() < 1e-12, "{f:?}");
        let b = frame.normalize(&cloud).bounds().unwrap();
        let e = b.extent();
        assert!(
            (e[2] - 1.0).abs() < 1e-12 && (e[0] - 0.5).abs() < 1e-12,
            "{e:?}"
        );
        // The same box turned by 37° about the vertical, fitted with its heading.
        let (s, c) = 37f64.to_radians().sin_cos();
        let turned = PointCloud::from_positions(
            cloud
                .positions
                .iter()
                .map(|p| {
                    let (x, y) = (p[0] - 650_000.0, p[1] - 5_270_000.0);
                    [650_000.0 + c * x - s * y, 5_270_000.0 + s * x + c * y, p[2]]
                })
                .collect(),
        );
        let frame = Frame::fit_heading(&turned, UpAxis::Z, 37.0).unwrap();
        let e = frame.normalize(&turned).bounds().unwrap().extent();
        assert!(
            (e[2] - 1.0).abs() < 1e-9 && (e[0] - 0.5).abs() < 1e-9,
            "{e:?}"
        );
        let back = frame.denormalize(&frame.normalize(&turned));
        for (a, b) in turned.positions.iter().zip(&back.positions) {
            for i in 0..3 {
                assert!((a[i] - b[i]).abs() < 1e-6, "{a:?} vs {b:?}");
            }
        }
    }

    #[test]
    fn canonical_heading_is_the_identity_for_y_up() {
        let r = yaw_to_canonical(90.0);
        for (i, row) in r.iter().enumerate() {
            for (j, v) in row.iter().enumerate() {
                assert!((v - IDENTITY[i][j]).abs() < 1e-15);
            }
        }
    }

    #[test]
    fn degenerate_clouds_are_refused() {
        let same = PointCloud::from_positions(vec![[1.0, 2.0, 3.0]; 5]);
        assert_eq!(Frame::fit(&same, UpAxis::Y), Err(FrameError::ZeroExtent));
        assert_eq!(
            Frame::fit(&PointCloud::default(), UpAxis::Y),
            Err(FrameError::Empty)
        );
        assert_eq!(
            Frame::fit_heading(&same, UpAxis::Z, 10.0),
            Err(FrameError::ZeroExtent)
        );
        let wide = PointCloud::from_positions(vec![[1e308, 0.0, 0.0], [-1e308, 1.0, 0.0]]);
        assert_eq!(Frame::fit(&wide, UpAxis::Y), Err(FrameError::Overflow));
        assert_eq!(
            Frame::fit_heading(&wide, UpAxis::Y, 0.0),
            Err(FrameError::Overflow)
        );
        let far = PointCloud::from_positions(vec![[1.5e308, 0.0, 0.0], [1.6e308, 1.0, 0.0]]);
        assert_eq!(Frame::fit(&far, UpAxis::Y), Err(FrameError::Overflow));
        assert_eq!(
            Frame::fit_heading(&far, UpAxis::Y, 0.0),
            Err(FrameError::Overflow)
        );
    }
}
