//! A plan view of a completed street (`complete --scene --preview`): every point seen from
//! above, the highest in each pixel, the scan's own points grey by height and each vehicle's
//! completed points in colour, so that what was added, and where, shows at a glance.

use super::split;
use crate::core::cloud::PointCloud;
use crate::core::frame::UpAxis;
use image::{Rgb, RgbImage};

/// The most pixels along the street's longer side.
pub const LONG_SIDE: usize = 2000;

/// The smallest pixel, metres: twice an MLS scan's line spacing (10 cm at 10 m/s and 100 Hz),
/// so that the scan lines fill the road instead of striping it.
pub const PIXEL: f64 = 0.2;

/// The plan view of `cloud`, whose first `scanned` points are the scan's and the rest
/// completed.
pub fn plan_view(cloud: &PointCloud, scanned: usize, up: UpAxis) -> RgbImage {
    let Some(bounds) = cloud.bounds() else {
        return PlanView::new([0.0; 3], [0.0; 3], up).finish();
    };
    let mut view = PlanView::new(bounds.min, bounds.max, up);
    for (i, &p) in cloud.positions.iter().enumerate() {
        view.add(p, i >= scanned);
    }
    view.finish()
}

/// A plan view drawn a point at a time, the scan's points first: the bounds are given up front,
/// so that a tile streamed a batch at a time is drawn without holding its points.
pub struct PlanView {
    origin: [f64; 3],
    up: UpAxis,
    /// The lowest height and the range of heights, for the grey scale.
    low: f64,
    heights: f64,
    scale: f64,
    size: [usize; 2],
    top: Vec<f64>,
    image: RgbImage,
}

impl PlanView {
    /// A blank view of the box from `min` to `max` (the input's coordinates).
    pub fn new(min: [f64; 3], max: [f64; 3], up: UpAxis) -> PlanView {
        let (span, heights) = split(max, min, up);
        let span = span.map(|s| s.max(1e-9));
        let scale = ((LONG_SIDE - 1) as f64 / span[0].max(span[1])).min(1.0 / PIXEL);
        let size = [
            (span[0] * scale) as usize + 1,
            (span[1] * scale) as usize + 1,
        ];
        PlanView {
            origin: min,
            up,
            low: 0.0,
            heights: heights.max(1e-9),
            scale,
            size,
            top: vec![f64::NEG_INFINITY; size[0] * size[1]],
            image: RgbImage::from_pixel(size[0] as u32, size[1] as u32, Rgb([255, 255, 255])),
        }
    }

    /// Draws `p`: in colour where `completed` (over whatever lies under it, so that it shows
    /// over the ground), else grey by height where it is the highest so far in its pixel.
    /// Points outside the box are drawn at its edge.
    pub fn add(&mut self, p: [f64; 3], completed: bool) {
        let (flat, height) = split(p, self.origin, self.up);
        let [w, h] = self.size;
        let pixel = |v: f64, n: usize| ((v * self.scale).max(0.0) as usize).min(n - 1);
        let col = pixel(flat[0], w);
        // Image rows run down; the second horizontal axis up.
        let row = h - 1 - pixel(flat[1], h);
        let at = row * w + col;
        if !completed && height < self.top[at] {
            return;
        }
        self.top[at] = self.top[at].max(height);
        let colour = if completed {
            Rgb([230, 60, 30])
        } else {
            let shade = 60.0 + 170.0 * ((height - self.low) / self.heights).clamp(0.0, 1.0);
            Rgb([shade as u8; 3])
        };
        self.image.put_pixel(col as u32, row as u32, colour);
    }

    /// The view; a short street is drawn larger, each pixel as a square of pixels, to be read
    /// on a screen.
    pub fn finish(self) -> RgbImage {
        let image = self.image;
        let k = (MIN_WIDTH / self.size[0].max(1)).max(1) as u32;
        if k == 1 {
            return image;
        }
        image::imageops::resize(
            &image,
            image.width() * k,
            image.height() * k,
            image::imageops::FilterType::Nearest,
        )
    }
}

/// A plan view narrower than this is enlarged by a whole factor.
const MIN_WIDTH: usize = 1000;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn completed_points_show_in_colour_over_the_scan() {
        let mut positions: Vec<[f64; 3]> = (0..100)
            .flat_map(|i| (0..20).map(move |j| [i as f64 * 0.1, j as f64 * 0.1, 0.0]))
            .filter(|p| !(p[0] < 3.0 && (0.5..1.5).contains(&p[1])))
            .collect();
        positions.push([5.0, 1.0, -1.0]);
        let cloud = PointCloud::from_positions(positions);
        let image = plan_view(&cloud, cloud.len() - 1, UpAxis::Z);
        // 9.9 m at 20 cm a pixel, enlarged 20 times.
        assert_eq!(image.width(), 1000);
        let red = image.pixels().filter(|p| p.0 == [230, 60, 30]).count();
        assert_eq!(
            red, 400,
            "the completed point, though below the ground, is drawn"
        );
        let white = image.pixels().filter(|p| p.0 == [255, 255, 255]).count();
        // The hole in the scan is white, the rest is not.
        assert!(white > 0 && white < (image.width() * image.height()) as usize / 4);
    }
}
