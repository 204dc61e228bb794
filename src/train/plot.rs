//! Pictures of a run: `losses.png` (loss and validation curves, labelled with a built-in 3×5
//! pixel font so no font file is needed) and the sample grids (input | output | ground truth
//! for every view).

use super::validate::tile;
use crate::core::glyphs::{put, text};
use crate::views::projection::ViewImages;
use image::{Rgb, RgbImage};

const WHITE: Rgb<u8> = Rgb([255, 255, 255]);
const INK: Rgb<u8> = Rgb([30, 30, 30]);
const AXIS: Rgb<u8> = Rgb([150, 150, 150]);
/// Training curves in blue, validation in red, the partial inputs' scores in grey.
pub const TRAIN: Rgb<u8> = Rgb([31, 119, 180]);
pub const VALIDATION: Rgb<u8> = Rgb([214, 39, 40]);
pub const BASELINE: Rgb<u8> = Rgb([160, 160, 160]);

fn line(img: &mut RgbImage, (x0, y0): (f64, f64), (x1, y1): (f64, f64), color: Rgb<u8>) {
    let n = (x1 - x0).abs().max((y1 - y0).abs()).ceil().max(1.0) as i64;
    for i in 0..=n {
        let t = i as f64 / n as f64;
        let (x, y) = (x0 + t * (x1 - x0), y0 + t * (y1 - y0));
        put(img, x.round() as i64, y.round() as i64, color);
        put(img, x.round() as i64, y.round() as i64 + 1, color);
    }
}

/// A number in at most 8 characters of the built-in font.
pub fn label(v: f64) -> String {
    let a = v.abs();
    if a == 0.0 || (0.01..1000.0).contains(&a) {
        format!("{v:.3}")
    } else {
        format!("{v:.1e}")
    }
}

/// One curve of a panel.
pub struct Series<'a> {
    pub points: &'a [(f64, f64)],
    pub color: Rgb<u8>,
}

/// One panel: a title, a y range from the data (log10 when `log` and all positive), the x axis
/// from 0 to `max_x`.
pub struct Panel<'a> {
    pub title: &'a str,
    pub series: Vec<Series<'a>>,
    pub log: bool,
}

const PANEL_W: u32 = 420;
const PANEL_H: u32 = 230;

fn draw_panel(img: &mut RgbImage, ox: i64, oy: i64, panel: &Panel, max_x: f64) {
    let (left, right, top, bottom) = (
        ox + 70,
        ox + PANEL_W as i64 - 15,
        oy + 30,
        oy + PANEL_H as i64 - 30,
    );
    text(img, ox + 70, oy + 8, panel.title, 3, INK);
    let (log, lo, hi) = y_range(panel);
    let f = |v: f64| if log { v.log10() } else { v };
    for x in left..=right {
        put(img, x, bottom, AXIS);
    }
    for y in top..=bottom {
        put(img, left, y, AXIS);
    }
    let shown = |v: f64| if log { 10f64.powf(v) } else { v };
    text(img, ox + 4, top - 2, &label(shown(hi)), 2, INK);
    text(img, ox + 4, bottom - 10, &label(shown(lo)), 2, INK);
    let steps = format!("{max_x:.0}");
    text(
        img,
        right - 8 * steps.len() as i64,
        bottom + 8,
        &steps,
        2,
        INK,
    );
    text(img, left, bottom + 8, "0", 2, INK);
    let to_px = |(x, y): (f64, f64)| {
        (
            left as f64 + (right - left) as f64 * (x / max_x.max(1.0)),
            bottom as f64 - (bottom - top) as f64 * ((f(y) - lo) / (hi - lo)),
        )
    };
    for s in &panel.series {
        draw_series(img, s, to_px);
    }
}

/// Whether `panel` is drawn on a log scale (asked for, and every value positive), and the
/// lowest and highest of its finite values on that scale, spread apart when equal.
fn y_range(panel: &Panel) -> (bool, f64, f64) {
    let values: Vec<f64> = panel
        .series
        .iter()
        .flat_map(|s| s.points.iter().map(|p| p.1))
        .filter(|v| v.is_finite())
        .collect();
    let log = panel.log && values.iter().all(|&v| v > 0.0);
    let f = |v: f64| if log { v.log10() } else { v };
    let (mut lo, mut hi) = values
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
            (a.min(f(v)), b.max(f(v)))
        });
    if !lo.is_finite() {
        (lo, hi) = (0.0, 1.0);
    }
    if hi - lo < 1e-12 {
        (lo, hi) = (lo - 0.5, hi + 0.5);
    }
    (log, lo, hi)
}

/// A series' finite points joined by lines, with `to_px` placing them; a single point is
/// drawn as a small cross.
fn draw_series(img: &mut RgbImage, s: &Series, to_px: impl Fn((f64, f64)) -> (f64, f64)) {
    let pts: Vec<(f64, f64)> = s
        .points
        .iter()
        .copied()
        .filter(|p| p.1.is_finite())
        .collect();
    if pts.len() == 1 {
        let (x, y) = to_px(pts[0]);
        for d in -2..=2 {
            put(img, x as i64 + d, y as i64, s.color);
            put(img, x as i64, y as i64 + d, s.color);
        }
    }
    for w in pts.windows(2) {
        line(img, to_px(w[0]), to_px(w[1]), s.color);
    }
}

/// Panels two per row.
pub fn panels(panels: &[Panel], max_x: f64) -> RgbImage {
    let rows = panels.len().div_ceil(2) as u32;
    let mut img = RgbImage::from_pixel(2 * PANEL_W, rows * PANEL_H, WHITE);
    for (i, panel) in panels.iter().enumerate() {
        let (ox, oy) = ((i % 2) as u32 * PANEL_W, (i / 2) as u32 * PANEL_H);
        draw_panel(&mut img, ox as i64, oy as i64, panel, max_x);
    }
    img
}

/// Rows of views, columns input | output | ground truth as geometry pseudo-colour, then the
/// same three in colour when `color`; tiles enlarged to at least 128 pixels.
pub fn sample_grid(
    input: &ViewImages,
    output: &ViewImages,
    target: &ViewImages,
    color: bool,
) -> RgbImage {
    let s = input.size as u32;
    let zoom = (128 / s).max(1);
    let tile_side = s * zoom;
    let gap = 4;
    let columns = if color { 6 } else { 3 };
    let views = input.views() as u32;
    let mut img = RgbImage::from_pixel(
        columns * (tile_side + gap) + gap,
        views * (tile_side + gap) + gap,
        WHITE,
    );
    for v in 0..views {
        let sources = [input, output, target];
        let tiles = sources
            .iter()
            .map(|src| tile(src, v as usize, false))
            .chain(
                sources
                    .iter()
                    .filter(|_| color)
                    .map(|src| tile(src, v as usize, true)),
            );
        for (col, t) in tiles.enumerate() {
            let (x0, y0) = (
                gap + col as u32 * (tile_side + gap),
                gap + v * (tile_side + gap),
            );
            for (x, y, p) in t.enumerate_pixels() {
                for dy in 0..zoom {
                    for dx in 0..zoom {
                        img.put_pixel(x0 + x * zoom + dx, y0 + y * zoom + dy, *p);
                    }
                }
            }
        }
    }
    img
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn text_draws_the_glyph_pixels() {
        let mut img = RgbImage::from_pixel(20, 10, WHITE);
        text(&mut img, 0, 0, "1-", 1, INK);
        let dark = |x, y| *img.get_pixel(x, y) == INK;
        // "1": top row 010, bottom row 111; "-" starts 4 pixels right: its middle row.
        assert!(dark(1, 0) && !dark(0, 0) && dark(0, 4) && dark(2, 4));
        assert!(dark(4, 2) && dark(6, 2) && !dark(4, 1));
    }

    #[test]
    fn curves_land_inside_their_panel() {
        let pts = [(0.0, 1.0), (50.0, 0.5), (100.0, 0.1)];
        let img = panels(
            &[Panel {
                title: "L1",
                series: vec![Series {
                    points: &pts,
                    color: TRAIN,
                }],
                log: true,
            }],
            100.0,
        );
        assert_eq!(img.dimensions(), (2 * PANEL_W, PANEL_H));
        let blue: Vec<(u32, u32)> = img
            .enumerate_pixels()
            .filter(|(_, _, p)| **p == TRAIN)
            .map(|(x, y, _)| (x, y))
            .collect();
        assert!(!blue.is_empty());
        // A falling curve: its leftmost pixels sit higher than its rightmost ones.
        let left = blue.iter().min_by_key(|p| p.0).unwrap();
        let right = blue.iter().max_by_key(|p| p.0).unwrap();
        assert!(left.1 < right.1 && right.0 < PANEL_W);
        assert_eq!(label(0.5), "0.500");
        assert_eq!(label(0.00123), "1.2e-3");
    }
}
