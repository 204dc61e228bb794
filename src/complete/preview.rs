//! `complete --preview`: input and completed cloud side by side from three viewpoints, the
//! completed points tinted, the symmetry plane outlined, as one PNG — what a person checks
//! first.

use crate::core::cloud::Aabb;
use crate::core::glyphs::text;
use image::{Rgb, RgbImage};

/// Side of one rendered tile in pixels.
const TILE: u32 = 360;
const HEADER: u32 = 24;
const BACKGROUND: Rgb<u8> = Rgb([28, 30, 34]);
const INK: Rgb<u8> = Rgb([230, 230, 230]);
/// Completed points are blended halfway towards this.
const TINT: [f64; 3] = [255.0, 120.0, 0.0];
/// The symmetry plane's outline.
const PLANE_INK: Rgb<u8> = Rgb([0, 200, 255]);

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
    /// The symmetry plane `x = offset`, outlined where it cuts the points' box.
    pub plane: Option<f64>,
}

/// Two columns (input, output), one row per viewpoint.
pub fn render(left: &Layer, right: &Layer) -> RgbImage {
    let rows = VIEWPOINTS.len() as u32;
    let mut img = RgbImage::from_pixel(2 * TILE, HEADER + rows * TILE, BACKGROUND);
    for (column, layer) in [left, right].into_iter().enumerate() {
        let x0 = column as u32 * TILE;
        text(&mut img, x0 as i64 + 8, 6, &layer.title, 2, INK);
        for (row, &(yaw, pitch)) in VIEWPOINTS.iter().enumerate() {
            let view = View { yaw, pitch };
            draw(&mut img, layer, x0, HEADER + row as u32 * TILE, view);
            if let Some(offset) = layer.plane {
                outline_plane(
                    &mut img,
                    layer,
                    offset,
                    x0,
                    HEADER + row as u32 * TILE,
                    view,
                );
            }
        }
    }
    img
}

/// An orthographic viewpoint, degrees.
#[derive(Clone, Copy)]
struct View {
    yaw: f64,
    pitch: f64,
}

impl View {
    /// Tile pixel coordinates (u right, v down) and depth (growing away from the viewer).
    fn project(self, p: [f64; 3]) -> (f64, f64, f64) {
        let (sy, cy) = self.yaw.to_radians().sin_cos();
        let (sp, cp) = self.pitch.to_radians().sin_cos();
        let scale = TILE as f64 * 0.9;
        // Turn about the vertical, then tilt towards the viewer.
        let x = cy * p[0] - sy * p[2];
        let z = sy * p[0] + cy * p[2];
        let y = cp * p[1] - sp * z;
        let d = sp * p[1] + cp * z;
        (
            TILE as f64 / 2.0 + x * scale,
            TILE as f64 / 2.0 - y * scale,
            d,
        )
    }
}

/// Orthographic splatting with a depth buffer, 2×2 pixels a point, shaded by depth.
fn draw(img: &mut RgbImage, layer: &Layer, x0: u32, y0: u32, view: View) {
    let mut depth = vec![f64::MAX; (TILE * TILE) as usize];
    for (i, p) in layer.points.iter().enumerate() {
        let (u, v, d) = view.project(*p);
        let (u, v) = (u as i64, v as i64);
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

/// The rectangle where the plane `x = offset` cuts the layer's box, drawn over the points.
fn outline_plane(img: &mut RgbImage, layer: &Layer, offset: f64, x0: u32, y0: u32, view: View) {
    let Some(b) = Aabb::of(layer.points) else {
        return;
    };
    let corners = [
        [offset, b.min[1], b.min[2]],
        [offset, b.max[1], b.min[2]],
        [offset, b.max[1], b.max[2]],
        [offset, b.min[1], b.max[2]],
    ];
    for k in 0..4 {
        let (a, c) = (view.project(corners[k]), view.project(corners[(k + 1) % 4]));
        let steps = ((c.0 - a.0).abs().max((c.1 - a.1).abs()) * 2.0)
            .ceil()
            .max(1.0) as usize;
        for s in 0..=steps {
            let t = s as f64 / steps as f64;
            let (u, v) = (a.0 + t * (c.0 - a.0), a.1 + t * (c.1 - a.1));
            if (0.0..TILE as f64).contains(&u) && (0.0..TILE as f64).contains(&v) {
                img.put_pixel(x0 + u as u32, y0 + v as u32, PLANE_INK);
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
            plane: None,
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

    #[test]
    fn the_plane_is_outlined_in_every_view_of_its_layer_only() {
        let points = [[-0.2, -0.1, -0.5], [0.2, 0.1, 0.5]];
        let layer = |plane| Layer {
            points: &points,
            colors: None,
            added: &[false, false],
            title: String::new(),
            plane,
        };
        let img = render(&layer(None), &layer(Some(0.05)));
        let inked = |column: u32, row: u32| {
            (0..TILE)
                .flat_map(|x| (0..TILE).map(move |y| (x, y)))
                .filter(|&(x, y)| {
                    *img.get_pixel(column * TILE + x, HEADER + row * TILE + y) == PLANE_INK
                })
                .count()
        };
        for row in 0..VIEWPOINTS.len() as u32 {
            assert_eq!(inked(0, row), 0, "no plane on the left, row {row}");
            assert!(inked(1, row) > 100, "an outline on the right, row {row}");
        }
    }
}
