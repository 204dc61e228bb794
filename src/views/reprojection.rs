//! View images → points. Each occupied pixel already stores its XYZ, so no depth math: erode
//! each view's foreground (inpainted views have ragged, unreliable rims), collect, merge, and
//! drop near-duplicates. Inpainted views are first snapped onto their pixels' rays
//! ([`snap_to_rays`]).

use crate::core::camera::Camera;
use crate::core::cloud::PointCloud;
use crate::views::projection::{ViewImages, CHANNELS};
use rayon::prelude::*;
use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};

/// The widest erosion element or median window the commands take (pixels a side). The median
/// costs its window's area at every pixel: `--smooth 1000` on eleven 256² views ran 10.7 s to
/// give each view one point (a window wider than the image is the whole view's median), and
/// on 4096² views it would run for days.
pub const MAX_WINDOW: usize = 31;

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReprojectOptions {
    /// Side of the square erosion element; 0 or 1 leaves the masks as they are. Meant for dense
    /// inpainted views: eroding a raw sparse scan removes most of it.
    pub erode: usize,
    /// Points closer than this (normalized units) to an earlier point are dropped; 0 keeps all.
    pub dedup_tolerance: f64,
    /// Side of the window whose occupied pixels' median replaces each pixel's XYZ; 0 or 1 keeps
    /// the pixels as they are. A generator's per-pixel XYZ jitters by several pixels' worth
    /// around the surface; the median keeps the surface and its edges.
    pub smooth: usize,
}

impl Default for ReprojectOptions {
    fn default() -> Self {
        ReprojectOptions {
            erode: 3,
            dedup_tolerance: 1e-4,
            smooth: 0,
        }
    }
}

/// Binary erosion with a `k`×`k` square (k odd; an even k is rounded up). Pixels outside the
/// image count as foreground, as in OpenCV's default border, so objects touching the border are
/// not eaten from it.
pub fn erode(mask: &[bool], size: usize, k: usize) -> Vec<bool> {
    if k <= 1 {
        return mask.to_vec();
    }
    let r = k / 2;
    // Separable: a horizontal pass, then a vertical one.
    let pass = |src: &[bool], horizontal: bool| -> Vec<bool> {
        let mut out = vec![false; src.len()];
        for row in 0..size {
            for col in 0..size {
                let (fixed, moving) = if horizontal { (row, col) } else { (col, row) };
                let lo = moving.saturating_sub(r);
                let hi = (moving + r).min(size - 1);
                let all = (lo..=hi).all(|m| {
                    let at = if horizontal {
                        fixed * size + m
                    } else {
                        m * size + fixed
                    };
                    src[at]
                });
                out[row * size + col] = all;
            }
        }
        out
    };
    pass(&pass(mask, true), false)
}

#[derive(Default)]
struct CellHasher(u64);

impl Hasher for CellHasher {
    fn finish(&self) -> u64 {
        self.0
    }
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.write_u64(b as u64);
        }
    }
    /// MurmurHash3's finalizer: every key bit reaches the low bits the table indexes with
    /// (a plain multiply would leave them to the x coordinate alone).
    fn write_u64(&mut self, v: u64) {
        let mut h = self.0 ^ v;
        h ^= h >> 33;
        h = h.wrapping_mul(0xff51_afd7_ed55_8ccd);
        h ^= h >> 33;
        h = h.wrapping_mul(0xc4ce_b9fe_1a85_ec53);
        h ^= h >> 33;
        self.0 = h;
    }
}

/// Indices of the points to keep: each point is dropped when it lies closer than `tolerance` to
/// an earlier kept point. Grid cells of side 2·tolerance mean every point has to look at only
/// the 8 cells nearest to it.
pub fn dedup_indices(points: &[[f64; 3]], tolerance: f64) -> Vec<usize> {
    if tolerance.is_nan() || tolerance <= 0.0 {
        return (0..points.len()).collect();
    }
    let cell = 2.0 * tolerance;
    let tol2 = tolerance * tolerance;
    let pack = |c: [i64; 3]| -> u64 {
        ((c[0] as u64) & 0x1F_FFFF)
            | (((c[1] as u64) & 0x1F_FFFF) << 21)
            | (((c[2] as u64) & 0x1F_FFFF) << 42)
    };
    let mut heads: HashMap<u64, u32, BuildHasherDefault<CellHasher>> =
        HashMap::with_capacity_and_hasher(points.len(), Default::default());
    let mut next: Vec<u32> = Vec::with_capacity(points.len());
    let mut kept: Vec<usize> = Vec::with_capacity(points.len());
    for (i, p) in points.iter().enumerate() {
        let scaled = p.map(|c| c / cell);
        let base = scaled.map(|s| s.floor() as i64);
        let step = [0, 1, 2].map(|a| {
            if scaled[a] - (base[a] as f64) < 0.5 {
                -1
            } else {
                1
            }
        });
        let mut duplicate = false;
        'cells: for dx in [0, step[0]] {
            for dy in [0, step[1]] {
                for dz in [0, step[2]] {
                    let key = pack([base[0] + dx, base[1] + dy, base[2] + dz]);
                    let mut at = heads.get(&key).copied().unwrap_or(u32::MAX);
                    while at != u32::MAX {
                        let q = points[kept[at as usize]];
                        let d2: f64 = (0..3).map(|a| (p[a] - q[a]).powi(2)).sum();
                        if d2 < tol2 {
                            duplicate = true;
                            break 'cells;
                        }
                        at = next[at as usize];
                    }
                }
            }
        }
        if !duplicate {
            let slot = kept.len() as u32;
            let head = heads.entry(pack(base)).or_insert(u32::MAX);
            next.push(*head);
            *head = slot;
            kept.push(i);
        }
    }
    kept
}

/// Component-wise median XYZ of the occupied pixels in the `k`×`k` window around `at`. The
/// window is cut to the image first: `--smooth 100000` visited 10¹⁰ positions per pixel.
fn median_xyz(px: &[f32], occupied: &[bool], size: usize, at: usize, k: usize) -> [f64; 3] {
    let plane = size * size;
    let half = k / 2;
    let (row, col) = (at / size, at % size);
    let rows = row.saturating_sub(half)..=(row + half).min(size - 1);
    let cols = col.saturating_sub(half)..=(col + half).min(size - 1);
    let mut window: [Vec<f32>; 3] = Default::default();
    for r in rows {
        for c in cols.clone() {
            let i = r * size + c;
            if occupied[i] {
                for (ch, values) in window.iter_mut().enumerate() {
                    values.push(px[ch * plane + i]);
                }
            }
        }
    }
    window.map(|mut values| {
        let mid = values.len() / 2;
        *values.select_nth_unstable_by(mid, f32::total_cmp).1 as f64
    })
}

/// Moves every occupied pixel's XYZ onto the ray through the pixel's centre, keeping its depth.
/// A generator regresses the three coordinates separately and its errors point every way, but
/// the pixel fixes where the surface point lies up to its depth: only the depth is the
/// network's to say. (Measured on `mvpcc complete`'s test split, README *Quality*.) Near the
/// image's rim a ray at the predicted depth can leave the unit box the network's XYZ are bound
/// to; such points are kept (clamped into the box instead, the validation split of README
/// *Quality* scored F1 0.6796 vs 0.6793 and a worse CD on trucks, 1.05e-3 vs 8.9e-4: their
/// scans can be shorter than the vehicle). Pixels occupied in `measured` stay where they are:
/// a generator that keeps its input's pixels (`ModelConfig::copies_input`) returns the
/// measured points there, which lie anywhere in their pixel, not on its centre's ray.
pub fn snap_to_rays(views: &mut ViewImages, cameras: &[Camera], measured: Option<&ViewImages>) {
    let size = views.size;
    let plane = size * size;
    assert_eq!(cameras.len(), views.views(), "one camera per view");
    let occupancy = &views.occupancy;
    let spared = |v: usize, at: usize| measured.is_some_and(|m| m.view_occupancy(v)[at]);
    views
        .pixels
        .par_chunks_mut(CHANNELS * plane)
        .zip(occupancy.par_chunks(plane))
        .zip(cameras.par_iter())
        .enumerate()
        .for_each(|(v, ((px, occupied), camera))| {
            for at in (0..plane).filter(|&at| occupied[at] && !spared(v, at)) {
                let p = [0, 1, 2].map(|c| px[c * plane + at] as f64);
                let q = camera.on_ray(at / size, at % size, p);
                for c in 0..3 {
                    px[c * plane + at] = q[c] as f32;
                }
            }
        });
}

/// Occupied pixels (after erosion) of every view, as one de-duplicated cloud in normalized
/// coordinates, with colour when the views carry it.
pub fn reproject(views: &ViewImages, options: ReprojectOptions) -> PointCloud {
    reproject_keeping(views, options, None)
}

/// [`reproject`] with the pixels occupied in `measured` spared by the erosion and the
/// smoothing. A generator that keeps its input's pixels (`ModelConfig::copies_input`) returns
/// those exactly, so the rim the erosion is for is only the rim of what it completed, and the
/// median would only move measured points.
pub fn reproject_keeping(
    views: &ViewImages,
    options: ReprojectOptions,
    measured: Option<&ViewImages>,
) -> PointCloud {
    let size = views.size;
    let plane = size * size;
    type ViewPoints = (Vec<[f64; 3]>, Vec<[u8; 3]>);
    let per_view: Vec<ViewPoints> = (0..views.views())
        .into_par_iter()
        .map(|v| {
            let spared = measured.map(|m| m.view_occupancy(v));
            let is_spared = |at: usize| spared.is_some_and(|s| s[at]);
            let mut mask = erode(views.view_occupancy(v), size, options.erode);
            let occupied = views.view_occupancy(v);
            for (at, kept) in mask.iter_mut().enumerate() {
                *kept |= is_spared(at) && occupied[at];
            }
            let px = views.view_pixels(v);
            let mut positions = Vec::new();
            let mut colors = Vec::new();
            for at in (0..plane).filter(|&at| mask[at]) {
                positions.push(if options.smooth > 1 && !is_spared(at) {
                    median_xyz(px, occupied, size, at, options.smooth)
                } else {
                    [0, 1, 2].map(|c| px[c * plane + at] as f64)
                });
                if views.has_color {
                    colors.push(
                        [3, 4, 5]
                            .map(|c| (px[c * plane + at] * 255.0).round().clamp(0.0, 255.0) as u8),
                    );
                }
            }
            (positions, colors)
        })
        .collect();
    let mut positions = Vec::new();
    let mut colors = Vec::new();
    for (p, c) in per_view {
        positions.extend(p);
        colors.extend(c);
    }
    let merged = PointCloud {
        positions,
        colors: views.has_color.then_some(colors),
        ..Default::default()
    };
    let keep = dedup_indices(&merged.positions, options.dedup_tolerance);
    if keep.len() == merged.len() {
        merged
    } else {
        merged.select(&keep)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::views::projection::project;
    use nalgebra::Vector3;

    #[test]
    fn a_median_window_is_cut_to_the_image() {
        let size = 4;
        let plane = size * size;
        // x = the pixel's index, y = −x, z = 2x; the first row empty.
        let mut px = vec![0.0f32; 3 * plane];
        for i in 0..plane {
            px[i] = i as f32;
            px[plane + i] = -(i as f32);
            px[2 * plane + i] = 2.0 * i as f32;
        }
        let occupied: Vec<bool> = (0..plane).map(|i| i >= size).collect();
        // Around pixel 5 (row 1, col 1) a 3×3 window holds rows 1–2 of cols 0–2: 4 5 6 8 9 10.
        assert_eq!(median_xyz(&px, &occupied, size, 5, 3), [8.0, -6.0, 16.0]);
        // A window beyond the image on every side holds the whole image, 4..=15.
        let whole = median_xyz(&px, &occupied, size, 0, 2 * size + 1);
        assert_eq!(whole, [10.0, -9.0, 20.0]);
        assert_eq!(median_xyz(&px, &occupied, size, 0, usize::MAX), whole);
    }

    #[test]
    fn erosion_removes_the_rim_and_isolated_pixels() {
        let size = 8;
        let mut mask = vec![false; size * size];
        for r in 1..6 {
            for c in 1..6 {
                mask[r * size + c] = true;
            }
        }
        mask[7 * size + 7] = true;
        let e = erode(&mask, size, 3);
        let on: Vec<usize> = (0..size * size).filter(|&i| e[i]).collect();
        let want: Vec<usize> = (2..5)
            .flat_map(|r| (2..5).map(move |c| r * size + c))
            .collect();
        assert_eq!(on, want);
        assert_eq!(erode(&mask, size, 0), mask);
        // The border counts as foreground.
        assert!(erode(&[true; 64], 8, 3).iter().all(|b| *b));
    }

    #[test]
    fn snapping_undoes_errors_across_the_rays_and_keeps_depth() {
        // A roof at y = 0.1, seen from above by two rig cameras.
        let roof: Vec<[f32; 3]> = (0..200)
            .flat_map(|i| {
                (0..100).map(move |j| [i as f32 / 400.0 - 0.25, 0.1, j as f32 / 400.0 - 0.125])
            })
            .collect();
        let cameras = Camera::set(&[5, 6], 64).unwrap();
        let mut views = project(&roof, None, &cameras);
        let plane = 64 * 64;
        // Every pixel's XYZ moved three pixels' worth across its camera's optical axis, which
        // leaves its depth as it was: off the roof, as a generator's XYZ often is.
        for (v, camera) in cameras.iter().enumerate() {
            let pixel = camera.center().norm() / camera.focal;
            let shift =
                camera.rotation.transpose() * Vector3::new(1.0, 2.0, 0.0).normalize() * 3.0 * pixel;
            let px = &mut views.pixels[v * CHANNELS * plane..(v + 1) * CHANNELS * plane];
            for at in (0..plane).filter(|&at| views.occupancy[v * plane + at]) {
                for c in 0..3 {
                    px[c * plane + at] += shift[c] as f32;
                }
            }
        }
        let off_roof = |views: &ViewImages| {
            let cloud = reproject(
                views,
                ReprojectOptions {
                    erode: 0,
                    ..Default::default()
                },
            );
            cloud
                .positions
                .iter()
                .map(|p| (p[1] - 0.1).abs())
                .sum::<f64>()
                / cloud.len() as f64
        };
        let before = off_roof(&views);
        snap_to_rays(&mut views, &cameras, None);
        let after = off_roof(&views);
        // What is left is the pixel's own width: the centre ray meets the seen point's depth
        // within half a pixel of it, off the roof by that times the ray's slope.
        assert!(before > 0.03 && after < before / 4.0, "{before} → {after}");
    }

    /// A copying generator's measured pixels are measured points: snapping leaves them off
    /// their centre rays and the erosion leaves their rim, while it still eats the rest.
    #[test]
    fn measured_pixels_are_neither_snapped_nor_eroded() {
        let roof: Vec<[f32; 3]> = (0..200)
            .flat_map(|i| {
                (0..100).map(move |j| [i as f32 / 400.0 - 0.25, 0.1, j as f32 / 400.0 - 0.125])
            })
            .collect();
        let cameras = Camera::set(&[5], 64).unwrap();
        let measured = project(&roof, None, &cameras);
        // The completed view: the measured pixels and a band of predicted ones beside them.
        let mut completed = measured.clone();
        let plane = 64 * 64;
        let predicted: Vec<usize> = (0..plane)
            .filter(|&at| !measured.occupancy[at] && measured.occupancy[at.saturating_sub(3)])
            .collect();
        assert!(!predicted.is_empty());
        for &at in &predicted {
            completed.occupancy[at] = true;
            for c in 0..3 {
                completed.pixels[c * plane + at] = measured.pixels[c * plane + at - 3];
            }
        }
        let mut snapped = completed.clone();
        snap_to_rays(&mut snapped, &cameras, Some(&measured));
        for at in 0..plane {
            let same =
                (0..3).all(|c| snapped.pixels[c * plane + at] == completed.pixels[c * plane + at]);
            assert_eq!(same, !predicted.contains(&at), "pixel {at}");
        }
        let count = |cloud: PointCloud| cloud.len();
        let options = |erode| ReprojectOptions {
            erode,
            dedup_tolerance: 0.0,
            smooth: 0,
        };
        let all = count(reproject(&completed, options(0)));
        let kept = count(reproject_keeping(&completed, options(3), Some(&measured)));
        let eroded = count(reproject(&completed, options(3)));
        assert_eq!(all, measured.occupied() + predicted.len());
        assert!(eroded < kept && kept < all, "{eroded} < {kept} < {all}");
        assert!(kept >= measured.occupied());
        // The median smoothing leaves the measured points where they are, too.
        let seen: std::collections::HashSet<[u64; 3]> = (0..plane)
            .filter(|&at| measured.occupancy[at])
            .map(|at| [0, 1, 2].map(|c| (measured.pixels[c * plane + at] as f64).to_bits()))
            .collect();
        let smoothed = ReprojectOptions {
            smooth: 3,
            ..options(0)
        };
        // How many of the measured points the cloud holds exactly.
        let exact = |cloud: PointCloud| {
            let held: std::collections::HashSet<[u64; 3]> = cloud
                .positions
                .iter()
                .map(|p| p.map(f64::to_bits))
                .collect();
            seen.intersection(&held).count()
        };
        assert_eq!(
            exact(reproject_keeping(&completed, smoothed, Some(&measured))),
            seen.len()
        );
        assert!(exact(reproject(&completed, smoothed)) < seen.len());
    }

    #[test]
    fn dedup_drops_points_within_tolerance_only() {
        let pts = [
            [0.0, 0.0, 0.0],
            [0.0, 0.0, 0.0],
            [0.00005, 0.0, 0.0],
            [0.00015, 0.0, 0.0],
            [-0.00009, 0.00001, 0.0],
            [0.3, 0.3, 0.3],
            [0.3, 0.3, 0.3 + 2e-4],
        ];
        assert_eq!(dedup_indices(&pts, 1e-4), vec![0, 3, 5, 6]);
        assert_eq!(dedup_indices(&pts, 0.0).len(), pts.len());
    }

    #[test]
    fn dedup_matches_brute_force_on_random_points() {
        let mut rng = crate::core::rng::Lcg::new(3);
        let mut next = || rng.range(-0.005, 0.005);
        let pts: Vec<[f64; 3]> = (0..3000).map(|_| [next(), next(), next()]).collect();
        let tol = 5e-4;
        let mut want: Vec<usize> = Vec::new();
        for (i, p) in pts.iter().enumerate() {
            let dup = want.iter().any(|&j| {
                let q = pts[j];
                (0..3).map(|a| (p[a] - q[a]).powi(2)).sum::<f64>() < tol * tol
            });
            if !dup {
                want.push(i);
            }
        }
        assert!(want.len() < pts.len());
        assert_eq!(dedup_indices(&pts, tol), want);
    }

    #[test]
    fn reprojection_recovers_the_projected_points() {
        let points: Vec<[f32; 3]> = (0..2000)
            .map(|i| {
                let t = i as f32 / 2000.0;
                [0.3 * (t * 40.0).sin(), 0.2 * (t * 13.0).cos(), t - 0.5]
            })
            .collect();
        let colors: Vec<[u8; 3]> = (0..2000).map(|i| [(i % 256) as u8, 9, 200]).collect();
        let views = project(
            &points,
            Some(&colors),
            &Camera::set(&[5, 6, 7, 8], 128).unwrap(),
        );
        let cloud = reproject(
            &views,
            ReprojectOptions {
                erode: 0,
                dedup_tolerance: 1e-6,
                smooth: 0,
            },
        );
        // Every visible point once, however many views saw it.
        assert!(cloud.len() > 500 && cloud.len() <= points.len());
        let colors_out = cloud.colors.as_ref().unwrap();
        for (p, c) in cloud.positions.iter().zip(colors_out) {
            let i = points
                .iter()
                .position(|q| (0..3).all(|a| q[a] as f64 == p[a]))
                .expect("a re-projected point is an input point");
            assert_eq!(*c, colors[i]);
        }
        let unique: std::collections::HashSet<_> = cloud
            .positions
            .iter()
            .map(|p| p.map(f64::to_bits))
            .collect();
        assert_eq!(unique.len(), cloud.len());
    }

    #[test]
    fn smoothing_removes_a_spike_and_keeps_a_plane() {
        // One view of a tilted plane z = 0.1·x with one pixel pushed off it.
        let size = 16;
        let plane = size * size;
        let mut views = ViewImages::empty(vec![5], size, false);
        for at in 0..plane {
            let (x, y) = ((at % size) as f32 / 32.0, (at / size) as f32 / 32.0);
            views.pixels[at] = x;
            views.pixels[plane + at] = y;
            views.pixels[2 * plane + at] = 0.1 * x;
            views.occupancy[at] = true;
        }
        let spike = 8 * size + 8;
        views.pixels[2 * plane + spike] = 0.4;
        let options = ReprojectOptions {
            erode: 0,
            dedup_tolerance: 0.0,
            smooth: 0,
        };
        let off_plane = |cloud: &PointCloud| {
            cloud
                .positions
                .iter()
                .map(|p| (p[2] - 0.1 * p[0]).abs())
                .fold(0.0, f64::max)
        };
        assert!(off_plane(&reproject(&views, options)) > 0.3);
        let smoothed = reproject(
            &views,
            ReprojectOptions {
                smooth: 3,
                ..options
            },
        );
        assert_eq!(smoothed.len(), plane);
        assert!(off_plane(&smoothed) < 1e-6, "{}", off_plane(&smoothed));
    }
}
