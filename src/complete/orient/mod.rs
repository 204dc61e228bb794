//! Which way a scanned vehicle faces: the yaw that turns its length onto z with its front
//! towards −z, the pose the network was trained in.
//!
//! Two estimators, both working on the upright cloud (+y up, see [`crate::core::frame`]):
//! - [`geometric`]: the length axis from the smallest rectangle around the ground footprint,
//!   the front by a height heuristic (the tallest part of a car, truck or van sits behind its
//!   middle: the cabin or the cargo box).
//! - [`Orienter`]: the paper's spatial transformer, a PointNet that reads the cloud and
//!   predicts the heading, trained on generated partials under random yaw (`mvpcc
//!   train-orient`).
//!
//! Headings are degrees counter-clockwise from the input's +x seen from above, in [0, 360).

pub(crate) mod net;

pub use net::{Orienter, OrienterConfig, OrienterNet};

use crate::complete::symmetry::{refine_heading, SymmetryParams};
pub use crate::complete::upright::angle_between;
use crate::complete::upright::{at_height, GROUND};
use crate::core::cloud::PointCloud;
use crate::core::frame::{upright, UpAxis};
use serde::{Deserialize, Serialize};
use std::str::FromStr;

/// The built-in orientation network (see docs/pipeline.md, *3. Heading, roll and the network's
/// pose* for how it was trained); a `static` for the reason [`crate::complete::DEFAULT_MODEL`] is
/// one.
pub static DEFAULT_ORIENTER: &[u8] = include_bytes!("../../../assets/orienter.safetensors");

/// How `complete` finds the heading (`--orient`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum OrientMode {
    /// The estimator that measured best (see lab/2026-12-06-orientation-test-split).
    Auto,
    /// Footprint rectangle and height heuristic.
    Geometric,
    /// The orientation network.
    Learned,
    /// The footprint rectangle's axis, the network's front.
    Combined,
    /// Trust the input's axes: the longer horizontal side becomes the length, no front decision.
    None,
    /// The user's heading in degrees.
    Heading(f64),
}

/// What `--orient auto` runs: the estimator with the lowest error on generated partials.
pub const AUTO: OrientMode = OrientMode::Combined;

impl FromStr for OrientMode {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "auto" => Ok(OrientMode::Auto),
            "geometric" => Ok(OrientMode::Geometric),
            "learned" => Ok(OrientMode::Learned),
            "combined" => Ok(OrientMode::Combined),
            "none" => Ok(OrientMode::None),
            _ => match s.parse::<f64>() {
                Ok(deg) if deg.is_finite() => Ok(OrientMode::Heading(deg.rem_euclid(360.0))),
                _ => Err(format!(
                    "`{s}` is not auto, geometric, learned, combined, none or a heading in degrees"
                )),
            },
        }
    }
}

impl OrientMode {
    /// Whether this mode runs the orientation network.
    pub fn needs_network(self) -> bool {
        matches!(self.resolved(), OrientMode::Learned | OrientMode::Combined)
    }

    fn resolved(self) -> OrientMode {
        match self {
            OrientMode::Auto => AUTO,
            other => other,
        }
    }
}

/// The heading found and by which estimator.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Orientation {
    /// `None` for `--orient none`: the frame keeps the input's axes.
    pub heading: Option<f64>,
    pub method: &'static str,
    /// Degrees the refinement turned the estimator's heading; `None` when the heading was
    /// given, neither the wheels nor the symmetry said anything near it, or its flat flanks
    /// kept the footprint axis (see `flat_flanks`).
    pub refinement: Option<f64>,
    /// What turned it: `"wheels"` (the line the lowest points lie on, the wheels' ground contact)
    /// or `"symmetry"` (the plane of symmetry, see [`refine_heading`]).
    pub refined_by: Option<&'static str>,
}

/// The tunables of the geometric heading estimators and their refinement; shares are of the
/// footprint's length or the points unless said. A file may give some of them (`complete
/// --tuning`); the rest keep these defaults.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct OrientParams {
    /// Points the footprint search looks at: a stride keeps it a few milliseconds.
    pub footprint_sample: usize,
    /// Share of the footprint cut off at each end of each side, so stray points do not widen it.
    pub trim: f64,
    /// Share of the points a flank must hold for [`footprint_axis`] to take its axis over the
    /// smallest rectangle's (chosen on the validation split, lab/2026-12-02-orientation-wheels-flank).
    pub flank_axis: f64,
    /// Share of the points on the footprint rectangle's long sides above which the rectangle's
    /// axis is kept as it is. Flat flanks pin the axis better than the symmetry refinement does:
    /// on a drive-by scan (one flank seen) the best-supported symmetry plane leans towards the
    /// scanned side and turns with it. Measured on the 300 generated test partials (README,
    /// *Orientation*): cars, buses, trucks and trains have 0.43–0.61 of their points there,
    /// motorcycles 0.09, whose rectangle the refinement corrects by degrees.
    pub flat_flanks: f64,
    /// Width of the band `straightest_flank` looks for a flank in, over the footprint's length:
    /// about the generated scans' range noise, so that a straight flank seen edge-on from above
    /// falls within it. Chosen on the validation split among 0.002, 0.003, 0.004, 0.005 and 0.01
    /// (lab/2026-12-06-orientation-flank-tyres).
    pub flank_band: f64,
    /// `straightest_flank` turns the axis by at most this many degrees, in steps of
    /// `flank_step`.
    pub flank_turn: f64,
    pub flank_step: f64,
    /// Points a flank's line needs for its direction to count.
    pub flank_points: usize,
    /// Share of the points a flank's band must hold for the flank to count as flat. On the
    /// generated validation partials the densest band holds 0.08–0.84 of them (0.12 or more where it
    /// turned the axis by over 0.01°); on a ShapeNet car of the reference data, whose flank curves
    /// in plan, 0.08, and its tangent there turned the axis 0.6° the wrong way.
    pub flat_band: f64,
    /// Bins of a quarter band: `densest_band`'s window is four of them.
    pub band_bins: usize,
    /// The ground points must span at least this share of the footprint's length along their line,
    /// so that both ends' wheels are in it.
    pub wheelbase: f64,
    /// ... and lie this thin across it (RMS across over RMS along): a line, not a patch. On the
    /// validation split 0.1, 0.2 and 0.3 score alike (lab/2026-12-02-orientation-wheels-flank); at 0.2
    /// a few low returns from the far wheels of a real scan (CAR164) turned its line 3° off its flank.
    pub wheel_line_width: f64,
    /// The wheels' line turns an estimate by at most this many degrees; more is another line.
    pub max_wheel_turn: f64,
    /// The two ends' tyres must be seen this alike across the line (the widths of their points
    /// within this share of each other) for `between_the_tyres` to go by their middles.
    pub tyres_alike: f64,
    /// Points above this share of the height count as the vehicle's top.
    pub top: f64,
}

impl Default for OrientParams {
    fn default() -> Self {
        OrientParams {
            footprint_sample: 6000,
            trim: 0.01,
            flank_axis: 0.4,
            flat_flanks: 0.3,
            flank_band: 0.003,
            flank_turn: 2.0,
            flank_step: 0.05,
            flank_points: 10,
            flat_band: 0.1,
            band_bins: 4,
            wheelbase: 0.5,
            wheel_line_width: 0.1,
            max_wheel_turn: 20.0,
            tyres_alike: 0.5,
            top: 0.75,
        }
    }
}

/// Finds the heading of `cloud` (up axis `up`). `orienter` is needed by the modes that
/// [`OrientMode::needs_network`]. An estimated heading is then turned onto the cloud's plane of
/// symmetry.
pub fn orient(
    cloud: &PointCloud,
    up: UpAxis,
    mode: OrientMode,
    orienter: Option<&Orienter>,
    tune: &OrientParams,
    symmetry: &SymmetryParams,
) -> Orientation {
    let fixed = |heading, method| Orientation {
        heading,
        method,
        refinement: None,
        refined_by: None,
    };
    match mode.resolved() {
        OrientMode::None => fixed(None, "none"),
        OrientMode::Heading(h) => fixed(Some(h), "given"),
        mode => {
            let points = upright_points(cloud, up);
            let (estimate, method) = estimate(mode, &points, orienter, tune);
            // The flat-flank rule is about the footprint's axis; 90° by default counts as one.
            let from_footprint = match method {
                "geometric" | "combined" => true,
                "learned" => false,
                _ => mode != OrientMode::Learned,
            };
            let refined =
                if from_footprint && flank_share(&points, estimate, tune) >= tune.flat_flanks {
                    None
                } else {
                    wheel_line(&points, tune)
                        .map(|line| toward(line, estimate))
                        .filter(|&line| angle_between(line, estimate) <= tune.max_wheel_turn)
                        .map(|line| (line, "wheels"))
                        .or_else(|| {
                            refine_heading(&points, estimate, symmetry).map(|h| (h, "symmetry"))
                        })
                };
            Orientation {
                heading: Some(refined.map_or(estimate, |r| r.0)),
                method,
                refinement: refined.map(|r| signed_turn(estimate, r.0)),
                refined_by: refined.map(|r| r.1),
            }
        }
    }
}

/// The heading `mode` estimates and the estimator that gave it, as it happened: without an
/// orientation network the learned and combined modes fall back to the footprint (reported as
/// `geometric`), and a cloud no estimator can read gets 90° (reported as `default`).
fn estimate(
    mode: OrientMode,
    points: &[[f64; 3]],
    orienter: Option<&Orienter>,
    tune: &OrientParams,
) -> (f64, &'static str) {
    let learned = || orienter.map(|o| o.heading(points));
    let footprint = || geometric(points, tune).map(|h| (h, "geometric"));
    let found = match mode {
        OrientMode::Geometric => footprint(),
        OrientMode::Learned => learned().map(|h| (h, "learned")).or_else(footprint),
        _ => match (footprint_axis(points, tune), learned()) {
            (Some(axis), Some(learned)) => Some((toward(axis, learned), "combined")),
            (None, Some(learned)) => Some((learned, "learned")),
            (Some(_), None) => footprint(),
            (None, None) => None,
        },
    };
    found.unwrap_or((90.0, "default"))
}

/// The turn from heading `a` to heading `b`, in (−180°, 180°].
fn signed_turn(a: f64, b: f64) -> f64 {
    let d = (b - a).rem_euclid(360.0);
    if d > 180.0 {
        d - 360.0
    } else {
        d
    }
}

/// The cloud stood upright (+y up), centred on its bounding box.
pub fn upright_points(cloud: &PointCloud, up: UpAxis) -> Vec<[f64; 3]> {
    let r = upright(up);
    let center = cloud.bounds().map_or([0.0; 3], |b| b.center());
    cloud
        .positions
        .iter()
        .map(|p| {
            let d = [0, 1, 2].map(|i| p[i] - center[i]);
            [0, 1, 2].map(|i| r[i][0] * d[0] + r[i][1] * d[1] + r[i][2] * d[2])
        })
        .collect()
}

/// Heading of the horizontal direction `(x, z)` in upright coordinates.
fn heading_of(x: f64, z: f64) -> f64 {
    (-z).atan2(x).to_degrees().rem_euclid(360.0)
}

/// Unit direction `(x, z)` of a heading in upright coordinates.
fn direction(heading: f64) -> (f64, f64) {
    let (s, c) = heading.to_radians().sin_cos();
    (c, -s)
}

/// Whichever of the axis's two headings (`axis` and `axis + 180°`) is nearer `hint`.
fn toward(axis: f64, hint: f64) -> f64 {
    if angle_between(axis, hint) <= 90.0 {
        axis.rem_euclid(360.0)
    } else {
        (axis + 180.0).rem_euclid(360.0)
    }
}

/// Heading of a canonical object (heading 90°) turned counter-clockwise by `turn` degrees.
pub fn heading_of_turn(turn: f64) -> f64 {
    (90.0 + turn).rem_euclid(360.0)
}

/// Heading of the length axis (one of its two ends) from the ground footprint; `None` for
/// fewer than three points. The smallest rectangle around the footprint turned onto its
/// straightest flank (`straightest_flank`) where its long sides hold many points; where they
/// hold few and another axis puts most of them on one long, straight flank, that flank's: a
/// scan that sees one flank and, sparsely, an end is a thin L, whose smallest rectangle lies
/// diagonally across it (10–18° off on validation camera partials seen from the side).
pub fn footprint_axis(points: &[[f64; 3]], tune: &OrientParams) -> Option<f64> {
    if points.len() < 3 {
        return None;
    }
    let stride = points.len().div_ceil(tune.footprint_sample);
    let sample: Vec<[f64; 3]> = points.iter().step_by(stride).copied().collect();
    let rectangle = smallest_rectangle_axis(&sample, tune);
    if flank_share(&sample, rectangle, tune) >= tune.flat_flanks {
        return Some(straightest_flank(&sample, rectangle, tune));
    }
    let (flank, share) = flank_axis(&sample, tune);
    let (length, (lo, hi)) = extents(&sample, flank, tune);
    Some(if share >= tune.flank_axis && length >= hi - lo {
        flank_line(&sample, flank, tune)
    } else {
        rectangle
    })
}

/// Heading of the longer side of the smallest rectangle around `points`' footprint.
fn smallest_rectangle_axis(points: &[[f64; 3]], tune: &OrientParams) -> f64 {
    let mut along = Vec::with_capacity(points.len());
    let mut across = Vec::with_capacity(points.len());
    let mut sides = |angle: f64| {
        let (s, c) = angle.to_radians().sin_cos();
        along.clear();
        across.clear();
        for p in points {
            along.push(p[0] * c + p[2] * s);
            across.push(-p[0] * s + p[2] * c);
        }
        (
            trimmed_span(&mut along, tune),
            trimmed_span(&mut across, tune),
        )
    };
    let area = |sides: (f64, f64)| sides.0 * sides.1;
    let mut best = (0.0, f64::MAX);
    for i in 0..90 {
        let a = i as f64;
        let value = area(sides(a));
        if value < best.1 {
            best = (a, value);
        }
    }
    let coarse = best.0;
    for i in -20..=20 {
        let a = coarse + i as f64 * 0.05;
        let value = area(sides(a));
        if value < best.1 {
            best = (a, value);
        }
    }
    let (length, width) = sides(best.0);
    // Angle of the rectangle's longer side in the (x, z) plane.
    let angle = if length >= width {
        best.0
    } else {
        best.0 + 90.0
    };
    let (s, c) = angle.to_radians().sin_cos();
    heading_of(c, s)
}

/// The heading (one of the axis's two) with the largest [`flank_share`], searched at 1° then
/// 0.1°, and that share.
fn flank_axis(points: &[[f64; 3]], tune: &OrientParams) -> (f64, f64) {
    let best_of = |headings: Vec<f64>| {
        headings
            .into_iter()
            .map(|h| (h, flank_share(points, h, tune)))
            .fold(
                (0.0, f64::MIN),
                |best, at| if at.1 > best.1 { at } else { best },
            )
    };
    let coarse = best_of((0..180).map(f64::from).collect());
    let fine = best_of((-10..=10).map(|i| coarse.0 + f64::from(i) * 0.1).collect());
    if fine.1 > coarse.1 {
        fine
    } else {
        coarse
    }
}

/// Length of the middle `1 − 2·TRIM` of `values` (reordered in place).
fn trimmed_span(values: &mut [f64], tune: &OrientParams) -> f64 {
    let (lo, hi) = trimmed_range(values, tune);
    hi - lo
}

/// Ends of the middle `1 − 2·TRIM` of `values` (reordered in place).
fn trimmed_range(values: &mut [f64], tune: &OrientParams) -> (f64, f64) {
    let n = values.len();
    let cut = ((n as f64 * tune.trim) as usize).min((n - 1) / 2);
    let hi = *values.select_nth_unstable_by(n - 1 - cut, f64::total_cmp).1;
    let lo = *values.select_nth_unstable_by(cut, f64::total_cmp).1;
    (lo, hi)
}

/// Share of `points` (upright) within 1 % of the length from either long side of the footprint
/// along `heading` (sides trimmed like [`footprint_axis`]'s).
fn flank_share(points: &[[f64; 3]], heading: f64, tune: &OrientParams) -> f64 {
    if points.len() < 3 {
        return 0.0;
    }
    let (length, (lo, hi)) = extents(points, heading, tune);
    let band = 0.01 * length;
    let (s, c) = heading.to_radians().sin_cos();
    let on_sides = points
        .iter()
        .map(|p| p[0] * s + p[2] * c)
        .filter(|&u| (u - lo).abs() < band || (u - hi).abs() < band)
        .count();
    on_sides as f64 / points.len() as f64
}

/// The heading within [`OrientParams::flank_turn`] of `heading` along which the most points of `points`
/// (upright) line up in one [`OrientParams::flank_band`], refined to those points' principal direction: a
/// flat flank seen edge-on from above. The smallest rectangle follows the trimmed extremes of
/// the footprint, which a far side seen over part of the length, or a cab narrower than its
/// box, turns by tenths of a degree (1.7° on a validation train); the flank itself is straight.
fn straightest_flank(points: &[[f64; 3]], heading: f64, tune: &OrientParams) -> f64 {
    let (length, _) = extents(points, heading, tune);
    let band = tune.flank_band * length;
    let steps = (tune.flank_turn / tune.flank_step).round() as i32;
    let (_, h, lo) = (-steps..=steps)
        .map(|i| {
            let h = heading + f64::from(i) * tune.flank_step;
            let (count, lo) = densest_band(points, h, band, tune);
            (count, h, lo)
        })
        .fold(
            (0, heading, 0.0),
            |best, at| if at.0 > best.0 { at } else { best },
        );
    let (s, c) = h.to_radians().sin_cos();
    let line: Vec<&[f64; 3]> = points
        .iter()
        .filter(|p| (0.0..=band).contains(&(p[0] * s + p[2] * c - lo)))
        .collect();
    if line.len() < tune.flank_points || (line.len() as f64) < tune.flat_band * points.len() as f64
    {
        return heading;
    }
    toward(principal_axis(&line).0, h)
}

/// The most of `points` (upright) within one `band` across `heading`, and where that band
/// starts, counted in bins of a quarter band. Points more than a band beyond the footprint's
/// trimmed sides are not counted, so that a stray point far off cannot make the bins many.
fn densest_band(points: &[[f64; 3]], heading: f64, band: f64, tune: &OrientParams) -> (usize, f64) {
    let (s, c) = heading.to_radians().sin_cos();
    let mut across: Vec<f64> = points.iter().map(|p| p[0] * s + p[2] * c).collect();
    let (lo, hi) = trimmed_range(&mut across, tune);
    let (lo, hi) = (lo - band, hi + band);
    let bin = band / tune.band_bins as f64;
    let mut counts = vec![0usize; ((hi - lo) / bin) as usize + 1];
    for u in across.iter().filter(|&&u| (lo..=hi).contains(&u)) {
        counts[((u - lo) / bin) as usize] += 1;
    }
    let mut best = (0, lo);
    let mut window: usize = counts.iter().take(tune.band_bins).sum();
    for start in 0..counts.len() {
        if window > best.0 {
            best = (window, lo + start as f64 * bin);
        }
        window -= counts[start];
        if let Some(next) = counts.get(start + tune.band_bins) {
            window += next;
        }
    }
    best
}

/// The direction of the points on the fuller long side of the footprint along `heading` (within
/// 1 % of the length of it), as the heading nearest `heading`: a straight flank pins the axis
/// more finely than the share's plateau, which is as wide as the band.
fn flank_line(points: &[[f64; 3]], heading: f64, tune: &OrientParams) -> f64 {
    let (length, (lo, hi)) = extents(points, heading, tune);
    let band = 0.01 * length;
    let (s, c) = heading.to_radians().sin_cos();
    let near = |side: f64| move |p: &&[f64; 3]| (p[0] * s + p[2] * c - side).abs() < band;
    let side = if points.iter().filter(near(lo)).count() >= points.iter().filter(near(hi)).count() {
        lo
    } else {
        hi
    };
    let flank: Vec<&[f64; 3]> = points.iter().filter(near(side)).collect();
    toward(principal_axis(&flank).0, heading)
}

/// The principal direction of `points`' footprint (upright, at least one) as a heading, and
/// the RMS spreads of the points along and across it.
fn principal_axis(points: &[&[f64; 3]]) -> (f64, f64, f64) {
    let n = points.len() as f64;
    let (mx, mz) = points
        .iter()
        .fold((0.0, 0.0), |(x, z), p| (x + p[0] / n, z + p[2] / n));
    let (sxx, sxz, szz) = points.iter().fold((0.0, 0.0, 0.0), |(xx, xz, zz), p| {
        let (dx, dz) = (p[0] - mx, p[2] - mz);
        (xx + dx * dx / n, xz + dx * dz / n, zz + dz * dz / n)
    });
    let angle = 0.5 * (2.0 * sxz).atan2(sxx - szz);
    // The covariance's eigenvalues.
    let mean = (sxx + szz) / 2.0;
    let half = ((sxx - szz) * (sxx - szz) / 4.0 + sxz * sxz).sqrt();
    (
        heading_of(angle.cos(), angle.sin()),
        (mean + half).sqrt(),
        (mean - half).max(0.0).sqrt(),
    )
}

/// The trimmed length of `points` (at least three, upright) along `heading` and their trimmed
/// range across it.
fn extents(points: &[[f64; 3]], heading: f64, tune: &OrientParams) -> (f64, (f64, f64)) {
    let (s, c) = heading.to_radians().sin_cos();
    let mut along: Vec<f64> = points.iter().map(|p| p[0] * c - p[2] * s).collect();
    let mut across: Vec<f64> = points.iter().map(|p| p[0] * s + p[2] * c).collect();
    (
        trimmed_span(&mut along, tune),
        trimmed_range(&mut across, tune),
    )
}

/// Heading of the line (one of its two ends) the lowest points of `points` (upright) lie on,
/// where they lie on one: the wheels' ground contact, front and back, which runs parallel to
/// the plane of symmetry (a motorcycle's tyres, a car's near tyres on a one-sided scan).
/// `None` when the ground points are few, short of the footprint's length or not thin across.
fn wheel_line(points: &[[f64; 3]], tune: &OrientParams) -> Option<f64> {
    let ground = at_height(points, GROUND);
    let low: Vec<&[f64; 3]> = points.iter().filter(|p| p[1] <= ground).collect();
    if low.len() < 10 {
        return None;
    }
    let (heading, along, across) = principal_axis(&low);
    let long = span_along(low.iter().copied(), heading)
        >= tune.wheelbase * span_along(points.iter(), heading);
    let thin = across <= tune.wheel_line_width * along;
    (long && thin).then(|| between_the_tyres(&low, heading, tune))
}

/// The wheels' line `heading` through the middles of the two ends' tyres: the principal
/// direction of the ground points leans towards whichever side wall of each tyre is seen more
/// (0.7–1.2° on validation motorcycles seen by cameras), while the middle of a tyre's points
/// across the line is its centre wherever its tread is seen edge to edge. Where the two ends'
/// points are not alike in width (one tyre seen from one side only), `heading` as it is.
fn between_the_tyres(low: &[&[f64; 3]], heading: f64, tune: &OrientParams) -> f64 {
    let n = low.len() as f64;
    let (mx, mz) = low
        .iter()
        .fold((0.0, 0.0), |(x, z), p| (x + p[0] / n, z + p[2] / n));
    let (ux, uz) = direction(heading);
    let coordinates = low.iter().map(|p| {
        let (dx, dz) = (p[0] - mx, p[2] - mz);
        (dx * ux + dz * uz, dz * ux - dx * uz)
    });
    // Per end (behind, ahead of the middle): the mean along, the middle and width across.
    let end = |ahead: bool| {
        let points: Vec<(f64, f64)> = coordinates
            .clone()
            .filter(|c| (c.0 >= 0.0) == ahead)
            .collect();
        let along = points.iter().map(|c| c.0).sum::<f64>() / points.len() as f64;
        let (lo, hi) = points.iter().fold((f64::MAX, f64::MIN), |(lo, hi), c| {
            (lo.min(c.1), hi.max(c.1))
        });
        (points.len(), along, (lo + hi) / 2.0, hi - lo)
    };
    let (behind, ahead) = (end(false), end(true));
    let widest = behind.3.max(ahead.3);
    if behind.0 < 3 || ahead.0 < 3 || (behind.3 - ahead.3).abs() > tune.tyres_alike * widest {
        return heading;
    }
    let (along, across) = (ahead.1 - behind.1, ahead.2 - behind.2);
    toward(
        heading_of(along * ux - across * uz, along * uz + across * ux),
        heading,
    )
}

/// The extent of `points` (upright) along `heading`.
fn span_along<'a>(points: impl Iterator<Item = &'a [f64; 3]>, heading: f64) -> f64 {
    let (s, c) = heading.to_radians().sin_cos();
    let (lo, hi) = points
        .map(|p| p[0] * c - p[2] * s)
        .fold((f64::MAX, f64::MIN), |(lo, hi), u| (lo.min(u), hi.max(u)));
    hi - lo
}

/// The footprint rectangle's axis, turned so the front is away from the centre of the
/// vehicle's top: a car's cabin, a van's or truck's box sit behind the middle.
pub fn geometric(points: &[[f64; 3]], tune: &OrientParams) -> Option<f64> {
    let axis = footprint_axis(points, tune)?;
    let (dx, dz) = direction(axis);
    let threshold = at_height(points, tune.top);
    let along: Vec<f64> = points.iter().map(|p| p[0] * dx + p[2] * dz).collect();
    let (a_lo, a_hi) = along
        .iter()
        .fold((f64::MAX, f64::MIN), |(lo, hi), &a| (lo.min(a), hi.max(a)));
    let middle = (a_lo + a_hi) / 2.0;
    let (sum, count) = points
        .iter()
        .zip(&along)
        .filter(|(p, _)| p[1] >= threshold)
        .fold((0.0, 0usize), |(s, n), (_, &a)| (s + a - middle, n + 1));
    let top_offset = if count == 0 { 0.0 } else { sum / count as f64 };
    // The top sits behind the middle, so the front is where `along` is smaller than the top's.
    Some(if top_offset > 0.0 {
        (axis + 180.0).rem_euclid(360.0)
    } else {
        axis
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::complete::upright::fixtures::{car_block, driven_past, turned};

    /// [`orient`] of an upright (y up) cloud with the default tunables.
    fn orient_y(cloud: &PointCloud, mode: OrientMode, orienter: Option<&Orienter>) -> Orientation {
        let defaults = (OrientParams::default(), SymmetryParams::default());
        orient(cloud, UpAxis::Y, mode, orienter, &defaults.0, &defaults.1)
    }
    use crate::core::rng::Lcg;
    use crate::datagen::synth::Category;

    /// Degrees between the axis through `axis` (either end) and `heading`.
    fn axis_error(axis: f64, heading: f64) -> f64 {
        angle_between(axis, heading).min(angle_between(axis + 180.0, heading))
    }

    #[test]
    fn modes_parse() {
        assert_eq!("auto".parse(), Ok(OrientMode::Auto));
        assert_eq!("none".parse(), Ok(OrientMode::None));
        assert_eq!("-90".parse(), Ok(OrientMode::Heading(270.0)));
        assert_eq!("37.5".parse(), Ok(OrientMode::Heading(37.5)));
        assert!("sideways".parse::<OrientMode>().is_err());
        assert!("nan".parse::<OrientMode>().is_err());
    }

    #[test]
    fn headings_and_directions_agree() {
        for h in [0.0, 37.0, 90.0, 181.0, 359.0] {
            let (x, z) = direction(h);
            assert!(angle_between(heading_of(x, z), h) < 1e-9);
        }
        // Heading 90° faces −z: the canonical pose.
        let (x, z) = direction(90.0);
        assert!(x.abs() < 1e-12 && (z + 1.0).abs() < 1e-12);
        assert_eq!(angle_between(350.0, 10.0), 20.0);
        assert_eq!(toward(10.0, 200.0), 190.0);
        assert_eq!(toward(190.0, 20.0), 10.0);
    }

    #[test]
    fn geometric_estimator_finds_the_known_heading_of_boxes() {
        for heading in [0.0, 15.0, 90.0, 137.0, 200.0, 271.5, 333.0] {
            let points = car_block(heading, [512.0, -3.0, 77.0]);
            let axis = footprint_axis(&points, &OrientParams::default()).unwrap();
            assert!(
                axis_error(axis, heading) < 0.5,
                "axis {axis} for heading {heading}"
            );
            let found = geometric(&points, &OrientParams::default()).unwrap();
            assert!(
                angle_between(found, heading) < 0.5,
                "found {found} for heading {heading}"
            );
        }
    }

    #[test]
    fn a_flank_seen_with_a_sparse_end_keeps_the_flank_axis() {
        // One flank seen from the side at mid-height (4 m long, 1.5 m high, densely sampled)
        // and the end beside it at a grazing angle: 40 points across the 1.6 m width.
        let mut canonical = Vec::new();
        for i in 0..=200 {
            for k in 0..=15 {
                canonical.push([-0.8, 0.1 * k as f64, -2.0 + 0.02 * i as f64]);
            }
        }
        for j in 0..40 {
            canonical.push([-0.8 + 0.04 * j as f64, 0.5, 2.0]);
        }
        for heading in [90.0, 23.0, 161.5] {
            let points = turned(canonical.clone(), heading, [3.0, 0.0, -1.0]);
            // The smallest rectangle lies across the thin L.
            assert!(
                axis_error(
                    smallest_rectangle_axis(&points, &OrientParams::default()),
                    heading
                ) > 3.0
            );
            let axis = footprint_axis(&points, &OrientParams::default()).unwrap();
            assert!(
                axis_error(axis, heading) < 0.2,
                "axis {axis} for heading {heading}"
            );
        }
    }

    #[test]
    fn a_flat_flank_sets_the_axis_where_the_smallest_rectangle_turns() {
        // Generated drive-bys whose smallest rectangle is turned by 0.15–0.35°: the far side
        // is seen over part of the length, the near flank is straight.
        let heading = 107.3;
        for (category, seed, side, height) in [
            (Category::Car, 4, -1.0, 0.6),
            (Category::Car, 5, -1.0, 0.6),
            (Category::Bus, 3, 1.0, 1.2),
            (Category::Bus, 4, -1.0, 0.6),
        ] {
            let points = turned(driven_past(category, seed, side, height), heading, [0.0; 3]);
            let sample: Vec<[f64; 3]> = points
                .iter()
                .step_by(
                    points
                        .len()
                        .div_ceil(OrientParams::default().footprint_sample),
                )
                .copied()
                .collect();
            let rectangle = smallest_rectangle_axis(&sample, &OrientParams::default());
            assert!(
                flank_share(&sample, rectangle, &OrientParams::default())
                    >= OrientParams::default().flat_flanks
            );
            assert!(
                axis_error(rectangle, heading) >= 0.1,
                "{category:?} {seed}: rectangle {rectangle}"
            );
            let axis = footprint_axis(&points, &OrientParams::default()).unwrap();
            assert!(
                axis_error(axis, heading) < 0.05,
                "{category:?} {seed}: axis {axis}"
            );
        }
    }

    #[test]
    fn a_flank_counts_only_where_its_band_holds_a_tenth_of_the_points() {
        // A straight flank 1° off the given axis among points spread over a 4 × 1.6 footprint:
        // it sets the axis where it holds 30 % of the points, not where it holds 5 %.
        let mut rng = Lcg::new(7);
        let mut cloud = |flank: usize, spread: usize| -> Vec<[f64; 3]> {
            let mut canonical: Vec<[f64; 3]> = (0..flank)
                .map(|i| [-0.8, 0.5, -2.0 + 4.0 * i as f64 / flank as f64])
                .collect();
            canonical
                .extend((0..spread).map(|_| [rng.range(-0.7, 0.8), 1.0, rng.range(-2.0, 2.0)]));
            turned(canonical, 91.0, [0.0; 3])
        };
        let flat = cloud(600, 1400);
        assert!(
            axis_error(
                straightest_flank(&flat, 90.0, &OrientParams::default()),
                91.0
            ) < 0.01
        );
        let sparse = cloud(100, 1900);
        assert_eq!(
            straightest_flank(&sparse, 90.0, &OrientParams::default()),
            90.0
        );
    }

    #[test]
    fn the_wheels_line_runs_through_the_tyres_middles() {
        // Two tyres' ground points, their treads seen edge to edge (0.06 wide), the front's
        // left side wall and the rear's right one seen more: the principal direction leans.
        let tyre = |z0: f64, wall: f64| {
            let tread = (0..=12).flat_map(move |i| {
                (0..8).map(move |k| [-0.03 + 0.005 * f64::from(i), 0.0, z0 + 0.02 * f64::from(k)])
            });
            let side = (0..40).map(move |k| [wall, 0.01, z0 + 0.004 * f64::from(k)]);
            tread.chain(side)
        };
        let heading = 37.0;
        let points = turned(
            tyre(-0.45, -0.03).chain(tyre(0.3, 0.03)).collect(),
            heading,
            [1.0; 3],
        );
        let low: Vec<&[f64; 3]> = points.iter().collect();
        let leaning = principal_axis(&low).0;
        assert!(axis_error(leaning, heading) > 0.5, "{leaning}");
        let between = between_the_tyres(&low, leaning, &OrientParams::default());
        assert!(
            axis_error(between, heading) < 0.05,
            "leaning {leaning}, between {between}"
        );
        // The rear tyre seen from one side only: its middle is not its centre.
        let one_side: Vec<[f64; 3]> = tyre(-0.45, -0.03)
            .chain((0..40).map(|k| [0.03, 0.0, 0.3 + 0.004 * f64::from(k)]))
            .collect();
        let points = turned(one_side, heading, [1.0; 3]);
        let low: Vec<&[f64; 3]> = points.iter().collect();
        let leaning = principal_axis(&low).0;
        assert_eq!(
            between_the_tyres(&low, leaning, &OrientParams::default()),
            leaning
        );
    }

    #[test]
    fn a_motorcycle_is_turned_onto_its_wheels_line() {
        // Generated motorcycles, driven past (their length along z, heading 90° or 270°): the
        // tyres' lowest returns lie on a line parallel to the plane of symmetry.
        for (seed, side) in [(1, 1.0), (2, -1.0), (3, 1.0)] {
            let cloud =
                PointCloud::from_positions(driven_past(Category::Motorcycle, seed, side, 0.6));
            let found = orient_y(&cloud, OrientMode::Geometric, None);
            assert_eq!(found.refined_by, Some("wheels"), "{found:?}");
            let heading = found.heading.unwrap();
            let off = angle_between(heading, 90.0).min(angle_between(heading, 270.0));
            assert!(off < 0.1, "motorcycle {seed}: heading {heading}");
        }
        // A round lump has no wheels' line.
        assert_eq!(wheel_line(&ellipsoid(), &OrientParams::default()), None);
    }

    #[test]
    fn the_reported_method_is_the_estimator_that_ran() {
        let cloud = PointCloud::from_positions(car_block(37.0, [0.0; 3]));
        // No orientation network: the learned and combined modes fall back to the footprint.
        for mode in [
            OrientMode::Learned,
            OrientMode::Combined,
            OrientMode::Geometric,
        ] {
            assert_eq!(orient_y(&cloud, mode, None).method, "geometric");
        }
        // Nothing to read a heading from: 90°, said so.
        let found = orient_y(&PointCloud::default(), OrientMode::Geometric, None);
        assert_eq!((found.heading, found.method), (Some(90.0), "default"));
    }

    #[test]
    fn flat_flanks_keep_the_footprint_axis_and_round_shapes_are_refined() {
        // The block's scanned flank and its roof's long edges: about half the points.
        let block = car_block(37.0, [0.0; 3]);
        let share = flank_share(&block, 37.0, &OrientParams::default());
        assert!(
            share >= OrientParams::default().flat_flanks,
            "block: {share}"
        );
        let cloud = PointCloud::from_positions(block);
        let found = orient_y(&cloud, OrientMode::Geometric, None);
        assert_eq!(found.refinement, None);
        // An ellipsoid (a round, motorcycle-like footprint) has no flat flank.
        let share = flank_share(&ellipsoid(), 90.0, &OrientParams::default());
        assert!(
            share < OrientParams::default().flat_flanks / 3.0,
            "ellipsoid: {share}"
        );
    }

    /// An ellipsoid 0.8 wide, 1 high and 2 long (along z), without its poles.
    fn ellipsoid() -> Vec<[f64; 3]> {
        let mut points = Vec::new();
        for i in 0..60 {
            for j in 1..30 {
                let (a, b) = (
                    i as f64 * 6.0_f64.to_radians(),
                    j as f64 * 6.0_f64.to_radians(),
                );
                points.push([
                    0.4 * b.sin() * a.cos(),
                    0.5 * b.cos(),
                    1.0 * b.sin() * a.sin(),
                ]);
            }
        }
        points
    }

    #[test]
    fn geometric_heading_of_a_z_up_cloud() {
        // A z-up input: upright maps (x, y, z) → (x, z, −y), so the block's upright z is −y.
        let cloud = PointCloud::from_positions(
            car_block(30.0, [0.0; 3])
                .into_iter()
                .map(|[x, y, z]| [x + 650_000.0, -z + 5_270_000.0, y + 110.0])
                .collect(),
        );
        let found = orient(
            &cloud,
            UpAxis::Z,
            OrientMode::Geometric,
            None,
            &OrientParams::default(),
            &SymmetryParams::default(),
        );
        assert!(
            angle_between(found.heading.unwrap(), 30.0) < 0.5,
            "{found:?}"
        );
        assert_eq!(
            orient(
                &cloud,
                UpAxis::Z,
                OrientMode::Heading(12.0),
                None,
                &OrientParams::default(),
                &SymmetryParams::default()
            )
            .heading,
            Some(12.0)
        );
        assert_eq!(
            orient(
                &cloud,
                UpAxis::Z,
                OrientMode::None,
                None,
                &OrientParams::default(),
                &SymmetryParams::default()
            )
            .heading,
            None
        );
    }
}
