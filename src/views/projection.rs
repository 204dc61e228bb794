//! Cloud → six-channel view images (XYZ in normalized object coordinates + RGB in [0, 1]) with
//! a true per-camera depth test: each pixel holds the point nearest to its camera.

use crate::core::camera::Camera;
use rayon::prelude::*;

/// Channels per pixel: x, y, z, r, g, b.
pub const CHANNELS: usize = 6;

/// V view images of one object.
#[derive(Debug, Clone, PartialEq)]
pub struct ViewImages {
    pub size: usize,
    /// Rig index of each view.
    pub cameras: Vec<usize>,
    /// Whether the RGB channels carry colour (a cloud without colour leaves them at zero).
    pub has_color: bool,
    /// `[views, 6, size, size]`, channel-major per view (the network's tensor layout); zero
    /// where a pixel is empty.
    pub pixels: Vec<f32>,
    /// `[views, size, size]`.
    pub occupancy: Vec<bool>,
}

impl ViewImages {
    pub fn empty(cameras: Vec<usize>, size: usize, has_color: bool) -> ViewImages {
        let v = cameras.len();
        ViewImages {
            size,
            cameras,
            has_color,
            pixels: vec![0.0; v * CHANNELS * size * size],
            occupancy: vec![false; v * size * size],
        }
    }

    pub fn views(&self) -> usize {
        self.cameras.len()
    }

    /// `[6, size, size]` of view `v`.
    pub fn view_pixels(&self, v: usize) -> &[f32] {
        let n = CHANNELS * self.size * self.size;
        &self.pixels[v * n..(v + 1) * n]
    }

    /// `[size, size]` of view `v`.
    pub fn view_occupancy(&self, v: usize) -> &[bool] {
        let n = self.size * self.size;
        &self.occupancy[v * n..(v + 1) * n]
    }

    pub fn occupied(&self) -> usize {
        self.occupancy.iter().filter(|o| **o).count()
    }
}

/// Projects normalized points (and their colours) into the views of `cameras`, which must all
/// share one image size. Parallel over views.
pub fn project(points: &[[f32; 3]], colors: Option<&[[u8; 3]]>, cameras: &[Camera]) -> ViewImages {
    let size = cameras.first().map_or(0, |c| c.size);
    assert!(
        cameras.iter().all(|c| c.size == size),
        "all cameras of a view set share one image size"
    );
    if let Some(colors) = colors {
        assert_eq!(colors.len(), points.len(), "one colour per point");
    }
    let plane = size * size;
    render_each_view(cameras, colors.is_some(), |camera, pixels, occupancy| {
        let projector = camera.projector();
        let mut depth = vec![f32::INFINITY; plane];
        let mut winner = vec![u32::MAX; plane];
        for (i, &p) in points.iter().enumerate() {
            if let Some((row, col, d)) = projector.project(p) {
                let at = row * size + col;
                // Strict: of equally near points the first one wins, deterministically.
                if d < depth[at] {
                    depth[at] = d;
                    winner[at] = i as u32;
                }
            }
        }
        for (at, &w) in winner.iter().enumerate() {
            if w == u32::MAX {
                continue;
            }
            occupancy[at] = true;
            let p = points[w as usize];
            for c in 0..3 {
                pixels[c * plane + at] = p[c];
            }
            if let Some(colors) = colors {
                let rgb = colors[w as usize];
                for c in 0..3 {
                    pixels[(3 + c) * plane + at] = rgb[c] as f32 / 255.0;
                }
            }
        }
    })
}

/// Views of `cameras` (one image size), each filled in parallel by `fill(camera, pixels
/// [6, S, S], occupancy [S, S])`.
pub fn render_each_view(
    cameras: &[Camera],
    has_color: bool,
    fill: impl Fn(&Camera, &mut [f32], &mut [bool]) + Sync,
) -> ViewImages {
    let size = cameras.first().map_or(0, |c| c.size);
    let mut images = ViewImages::empty(cameras.iter().map(|c| c.index).collect(), size, has_color);
    let plane = size * size;
    images
        .pixels
        .par_chunks_mut(CHANNELS * plane)
        .zip(images.occupancy.par_chunks_mut(plane))
        .zip(cameras.par_iter())
        .for_each(|((pixels, occupancy), camera)| fill(camera, pixels, occupancy));
    images
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cams(indices: &[usize], size: usize) -> Vec<Camera> {
        Camera::set(indices, size).unwrap()
    }

    #[test]
    fn nearest_point_wins_whatever_the_input_order() {
        let cam = Camera::rig(6, 64).unwrap();
        let c = cam.center();
        // Two points on the ray from the camera through the origin: the nearer must win.
        let near = (c * 0.1).map(|v| v as f32);
        let far = (c * -0.1).map(|v| v as f32);
        for (points, colors) in [
            (
                vec![near.into(), far.into()],
                vec![[255, 0, 0], [0, 0, 255]],
            ),
            (
                vec![far.into(), near.into()],
                vec![[0, 0, 255], [255, 0, 0]],
            ),
        ] {
            let img = project(&points, Some(&colors), std::slice::from_ref(&cam));
            assert_eq!(img.occupied(), 1);
            let at = img.occupancy.iter().position(|o| *o).unwrap();
            let plane = 64 * 64;
            assert_eq!(img.pixels[3 * plane + at], 1.0, "red (near) point wins");
            assert_eq!(img.pixels[5 * plane + at], 0.0);
            let near: [f32; 3] = near.into();
            assert_eq!(img.pixels[at], near[0]);
        }
    }

    #[test]
    fn pixels_hold_coordinates_and_empty_pixels_are_zero() {
        let points: Vec<[f32; 3]> = (0..200)
            .map(|i| {
                let t = i as f32 / 200.0 - 0.5;
                [t * 0.3, t * 0.2, t]
            })
            .collect();
        let img = project(&points, None, &cams(&[5, 6, 7, 8], 128));
        assert_eq!(img.views(), 4);
        let plane = 128 * 128;
        for v in 0..4 {
            let px = img.view_pixels(v);
            let occ = img.view_occupancy(v);
            assert!(occ.iter().any(|o| *o));
            for at in 0..plane {
                if occ[at] {
                    let p = [px[at], px[plane + at], px[2 * plane + at]];
                    assert!(points.contains(&p));
                } else {
                    assert!((0..CHANNELS).all(|c| px[c * plane + at] == 0.0));
                }
            }
        }
    }

    #[test]
    fn points_outside_the_window_leave_no_trace() {
        let img = project(&[[0.0, 5.0, 0.0]], None, &cams(&[5], 64));
        assert_eq!(img.occupied(), 0);
        assert!(img.pixels.iter().all(|v| *v == 0.0));
    }
}
