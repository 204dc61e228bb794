//! `complete --preview`: input and completed cloud side by side from three viewpoints, the
//! completed points tinted, as one PNG — what a person checks first.

use crate::core::glyphs::text;
use image::{Rgb, RgbImage};

/// Side of one rendered tile in pixels.
const TILE: u32 = 360;
const HEADER: u32 = 24;
const BACKGROUND: Rgb<u8> = Rgb([28, 30, 34]);
const INK: Rgb<u8> = Rgb([230, 230, 230]);
/// Completed points are blended halfway towards this.
const TINT: [f64; 3] = [255.0, 120.0, 0.0];

/// Viewpoints as (yaw, pitch) in degrees: three-quarter from the front left and above, the
/// side, and the top.
const VIEWPOINTS: [(f64, f64); 3] = [(-35.0, 25.0), (-90.0, 0.0), (-90.0, 89.0)];

/// One cloud to draw: points in the network's unit box, optional colours, and which points are
/// completed ones.
pub struct Layer<'a> {
    pub points: &'a [[f64; 3]],
    pub colors: Option<&'a [[u8; 3]]>,
    pub added: &'a [bool],
    pub title: String,
}

/// Two columns (input, output), one row per viewpoint.
pub fn render(left: &Layer, right: &Layer) -> RgbImage {
    let rows = VIEWPOINTS.len() as u32;
    let mut img = RgbImage::from_pixel(2 * TILE, HEADER + rows * TILE, BACKGROUND);
    for (column, layer) in [left, right].into_iter().enumerate() {
        let x0 = column as u32 * TILE;
        text(&mut img, x0 as i64 + 8, 6, &layer.title, 2, INK);
        for (row, &(yaw, pitch)) in VIEWPOINTS.iter().enumerate() {
            draw(&mut img, layer, x0, HEADER + row as u32 * TILE, yaw, pitch);
        }
    }
    img
}

/// Orthographic splatting with a depth buffer, 2×2 pixels a point, shaded by depth.
fn draw(img: &mut RgbImage, layer: &Layer, x0: u32, y0: u32, yaw: f64, pitch: f64) {
    let (sy, cy) = yaw.to_radians().sin_cos();
    let (sp, cp) = pitch.to_radians().sin_cos();
    let scale = TILE as f64 * 0.9;
    let mut depth = vec![f64::MAX; (TILE * TILE) as usize];
    for (i, p) in layer.points.iter().enumerate() {
        // Turn about the vertical, then tilt towards the viewer; depth grows away from it.
        let x = cy * p[0] - sy * p[2];
        let z = sy * p[0] + cy * p[2];
        let y = cp * p[1] - sp * z;
        let d = sp * p[1] + cp * z;
        let u = (TILE as f64 / 2.0 + x * scale) as i64;
        let v = (TILE as f64 / 2.0 - y * scale) as i64;
        let base = layer
            .colors
            .map_or([200.0, 200.0, 200.0], |c| c[i].map(f64::from));
        let shade = (1.0 - 0.6 * (d + 0.5)).clamp(0.4, 1.0);
        let tinted = if layer.added[i] {
            [0, 1, 2].map(|k| 0.5 * base[k] + 0.5 * TINT[k])
        } else {
            base
        };
        let color = Rgb(tinted.map(|c| (c * shade).round().clamp(0.0, 255.0) as u8));
        for (du, dv) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
            let (pu, pv) = (u + du, v + dv);
            if pu < 0 || pv < 0 || pu >= TILE as i64 || pv >= TILE as i64 {
                continue;
            }
            let at = (pv as u32 * TILE + pu as u32) as usize;
            if d < depth[at] {
                depth[at] = d;
                img.put_pixel(x0 + pu as u32, y0 + pv as u32, color);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn added_points_are_tinted_and_nearer_points_win() {
        let points = [[0.3, 0.0, 0.0], [-0.3, 0.0, 0.0]];
        let colors = [[0, 0, 255], [0, 255, 0]];
        let layer = Layer {
            points: &points,
            colors: Some(&colors),
            added: &[false, true],
            title: "IN".into(),
        };
        let img = render(&layer, &layer);
        // The side view looks from +x: both points fall on its centre, the nearer blue one wins.
        let side = *img.get_pixel(TILE / 2, HEADER + TILE + TILE / 2);
        assert!(
            side.0[2] > 100 && side.0[0] == 0 && side.0[1] == 0,
            "{side:?}"
        );
        // The three-quarter view separates them: one plain blue, one green tinted orange.
        let drawn: Vec<Rgb<u8>> = (0..TILE)
            .flat_map(|x| (0..TILE).map(move |y| (x, y)))
            .map(|(x, y)| *img.get_pixel(x, HEADER + y))
            .filter(|p| p.0 != BACKGROUND.0)
            .collect();
        assert!(
            drawn.iter().any(|p| p.0[0] > 60 && p.0[1] > 100),
            "tinted green"
        );
        assert!(
            drawn.iter().any(|p| p.0[2] > 100 && p.0[0] == 0),
            "plain blue"
        );
    }
}
