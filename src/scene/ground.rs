//! The ground of a street scan: a grid of the lowest height in each cell, opened (eroded, then
//! dilated) twice, with a window wider than any vehicle and with one about a kerb's pavement
//! wide. The wide opening cuts away what stands on the ground (vehicles, walls' feet, poles) but
//! also a pavement narrower than its window; the narrow one keeps the pavement but not what is
//! wider than it. Where the two differ by at most a kerb's step the narrow one is the ground,
//! elsewhere the wide one: the progressive morphological filter of Zhang et al. (2003) with two
//! windows, which a street's small slopes allow. A point is ground when it lies within a
//! threshold above that surface.

use serde::{Deserialize, Serialize};

/// The ground filter's tunables.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GroundParams {
    /// Cell side, metres: fine enough to follow a kerb, coarse enough that every cell of a road
    /// holds a return at MLS densities.
    pub cell: f64,
    /// Wide opening window side, metres (15 cells of 0.5 m): wider than the widest vehicle
    /// (2.6 m) seen from one side, whose far half lies in the scan's shadow and holds no ground
    /// returns.
    pub window: f64,
    /// Narrow opening window side, metres: narrower than a car's footprint, so that only what
    /// is lower than a kerb survives both openings' difference.
    pub narrow_window: f64,
    /// The largest step of the ground between the two openings, metres: a kerb (0.10–0.15 m),
    /// below a car's sill (0.3 m), whose flank the narrow opening does not cut away.
    pub step: f64,
    /// Points up to this height above the opened surface are ground, metres: a kerb, the road's
    /// camber inside one cell and the range noise.
    pub height: f64,
}

impl Default for GroundParams {
    fn default() -> Self {
        GroundParams {
            cell: 0.5,
            window: 7.5,
            narrow_window: 1.5,
            step: 0.2,
            height: 0.25,
        }
    }
}

/// The most cells the ground grid holds (128 MB of heights and as much again for the openings).
const MAX_CELLS: usize = 16_000_000;

/// The ground surface as a grid over the scene's horizontal extent.
#[derive(Debug, Clone)]
pub struct Ground {
    origin: [f64; 2],
    cell: f64,
    cols: usize,
    rows: usize,
    /// The opened lowest height of each cell; infinite where no point lies within the window.
    heights: Vec<f64>,
}

impl Ground {
    /// The ground under `points`, each given as (horizontal position, height).
    pub fn fit(points: &[([f64; 2], f64)], params: &GroundParams) -> Ground {
        let [lo, hi] = horizontal_bounds(points);
        // A cell large enough that the grid stays within MAX_CELLS whatever the extent (a
        // caller's units or a stray point): coarser than asked only past about 2 km a side.
        let area = (hi[0] - lo[0]).max(0.0) * (hi[1] - lo[1]).max(0.0);
        let cell = params.cell.max((area / MAX_CELLS as f64).sqrt());
        let cols = ((hi[0] - lo[0]) / cell).floor() as usize + 1;
        let rows = ((hi[1] - lo[1]) / cell).floor() as usize + 1;
        let mut ground = Ground {
            origin: lo,
            cell,
            cols,
            rows,
            heights: vec![f64::INFINITY; cols * rows],
        };
        for &(p, h) in points {
            let at = ground.index(p);
            ground.heights[at] = ground.heights[at].min(h);
        }
        let wide = ground.opened(params.window);
        let narrow = ground.opened(params.narrow_window);
        ground.heights = wide
            .iter()
            .zip(&narrow)
            .map(|(&w, &n)| if n - w <= params.step { n } else { w })
            .collect();
        ground
    }

    /// The lowest heights opened with a square window of side `window` (metres).
    fn opened(&self, window: f64) -> Vec<f64> {
        let radius = ((window / self.cell - 1.0) / 2.0).round().max(0.0) as usize;
        let eroded = self.filtered(&self.heights, radius, f64::min);
        // Dilation takes the largest of the eroded values: empty cells (infinite) take no part.
        let finite_max = |a: f64, b: f64| match (a.is_finite(), b.is_finite()) {
            (true, true) => a.max(b),
            (true, false) => a,
            _ => b,
        };
        self.filtered(&eroded, radius, finite_max)
    }

    fn index(&self, p: [f64; 2]) -> usize {
        let col =
            (((p[0] - self.origin[0]) / self.cell).floor().max(0.0) as usize).min(self.cols - 1);
        let row =
            (((p[1] - self.origin[1]) / self.cell).floor().max(0.0) as usize).min(self.rows - 1);
        row * self.cols + col
    }

    /// `values` combined over a square of `radius` cells about each cell, rows then columns
    /// (a square window is separable for min and max). Near the grid's edge the window shrinks
    /// on both sides alike, so that an opening keeps a sloping road's height there (a window cut
    /// on one side only would take the lower side's heights for the edge's).
    fn filtered(
        &self,
        values: &[f64],
        radius: usize,
        combine: impl Fn(f64, f64) -> f64,
    ) -> Vec<f64> {
        let (cols, rows) = (self.cols, self.rows);
        let along_rows = window_pass(values, [rows, cols], [cols, 1], radius, &combine);
        window_pass(&along_rows, [cols, rows], [1, cols], radius, &combine)
    }

    /// The ground's height under `p`: infinite where the scan saw no ground near it.
    pub fn height_at(&self, p: [f64; 2]) -> f64 {
        self.heights[self.index(p)]
    }
}

/// `values` (a grid) combined over a window of `radius` cells along one axis: `counts` are the
/// other axis's cells and this one's, `strides` their steps in `values`. Near the edge the window
/// shrinks on both sides alike.
fn window_pass(
    values: &[f64],
    counts: [usize; 2],
    strides: [usize; 2],
    radius: usize,
    combine: &impl Fn(f64, f64) -> f64,
) -> Vec<f64> {
    let mut out = vec![f64::INFINITY; values.len()];
    let n = counts[1];
    for a in 0..counts[0] {
        for b in 0..n {
            let k = radius.min(b).min(n - 1 - b);
            out[a * strides[0] + b * strides[1]] = (b - k..b + k + 1)
                .map(|j| values[a * strides[0] + j * strides[1]])
                .reduce(combine)
                .expect("a window holds its own cell");
        }
    }
    out
}

/// The lowest and highest horizontal coordinates of `points` (both zero when there are none).
pub fn horizontal_bounds(points: &[([f64; 2], f64)]) -> [[f64; 2]; 2] {
    if points.is_empty() {
        return [[0.0; 2]; 2];
    }
    let mut lo = [f64::INFINITY; 2];
    let mut hi = [f64::NEG_INFINITY; 2];
    for (p, _) in points {
        for k in 0..2 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    [lo, hi]
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A sloping road with a kerb and a 2 m pavement, a box standing on it (a vehicle, 2 m wide and 1.5 m high)
    /// whose far side the scan did not reach: the road and the kerb are ground, the box not.
    #[test]
    fn the_ground_follows_road_and_kerb_under_a_vehicle() {
        let mut points = Vec::new();
        let road = |x: f64, y: f64| 0.03 * x + if y > 6.0 { 0.15 } else { 0.0 };
        for i in 0..200 {
            for j in 0..80 {
                let (x, y) = (i as f64 * 0.1, j as f64 * 0.1);
                let under_box = (8.0..12.0).contains(&x) && (2.0..6.5).contains(&y);
                if !under_box {
                    points.push(([x, y], road(x, y)));
                }
            }
        }
        let mut vehicle = Vec::new();
        for i in 0..40 {
            for k in 0..15 {
                let (x, h) = (8.0 + i as f64 * 0.1, 0.3 + k as f64 * 0.1);
                vehicle.push(([x, 2.0], road(x, 2.0) + h));
            }
            vehicle.push(([8.0 + i as f64 * 0.1, 3.0], road(8.0, 3.0) + 1.6));
        }
        points.extend(&vehicle);
        let params = GroundParams::default();
        let ground = Ground::fit(&points, &params);
        for &(p, h) in &points[..points.len() - vehicle.len()] {
            assert!((h - ground.height_at(p)).abs() <= params.height, "{p:?}");
        }
        for &(p, h) in &vehicle {
            assert!(h - ground.height_at(p) > params.height, "{p:?}");
        }
    }
}
