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
    let origin = cloud.positions.first().copied().unwrap_or_default();
    let flat: Vec<([f64; 2], f64)> = cloud
        .positions
        .iter()
        .map(|&p| split(p, origin, up))
        .collect();
    let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
    for (p, h) in &flat {
        for (k, v) in [p[0], p[1], *h].into_iter().enumerate() {
            lo[k] = lo[k].min(v);
            hi[k] = hi[k].max(v);
        }
    }
    let span = [hi[0] - lo[0], hi[1] - lo[1]].map(|s| s.max(1e-9));
    let scale = ((LONG_SIDE - 1) as f64 / span[0].max(span[1])).min(1.0 / PIXEL);
    let (w, h) = (
        (span[0] * scale) as usize + 1,
        (span[1] * scale) as usize + 1,
    );
    let mut top = vec![f64::NEG_INFINITY; w * h];
    let mut image = RgbImage::from_pixel(w as u32, h as u32, Rgb([255, 255, 255]));
    // The completed points last, so that they show over the ground under them.
    for (i, (p, height)) in flat.iter().enumerate() {
        let col = ((p[0] - lo[0]) * scale) as usize;
        // Image rows run down; the second horizontal axis up.
        let row = h - 1 - ((p[1] - lo[1]) * scale) as usize;
        let at = row * w + col;
        let completed = i >= scanned;
        if !completed && *height < top[at] {
            continue;
        }
        top[at] = top[at].max(*height);
        let colour = if completed {
            Rgb([230, 60, 30])
        } else {
            let shade = 60.0 + 170.0 * (height - lo[2]) / (hi[2] - lo[2]).max(1e-9);
            Rgb([shade as u8; 3])
        };
        image.put_pixel(col as u32, row as u32, colour);
    }
    // A short street is drawn larger, each pixel as a square of pixels, to be read on a screen.
    let k = (MIN_WIDTH / w.max(1)).max(1) as u32;
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
