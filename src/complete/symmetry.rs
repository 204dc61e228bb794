//! The vehicle's long vertical plane of symmetry, found in the normalized frame (length along z,
//! up along y), where it is a plane `x = c`.
//!
//! Street vehicles are left–right symmetric, so a scan of one side and the roof already holds the
//! roof's two halves: the plane that maps most points onto other points is the symmetry plane.
//! Points close to a candidate plane map onto themselves whatever the candidate, so they are not
//! counted; otherwise a flat side would always be "symmetric" about itself.

use crate::complete::upright::{at_height, GROUND};
use crate::core::cloud::Aabb;
use crate::core::frame::Frame;
use crate::core::knn::{KnnIndex, MatchGrid};
use nalgebra::{Matrix3, SymmetricEigen, Vector3};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// The normal of the planes `x = c`.
const ACROSS: [f64; 3] = [1.0, 0.0, 0.0];

/// The tunables of the symmetry plane, the heading's symmetry refinement and the roll; lengths
/// are in the unit box unless said. A file may give some of them (`complete --tuning`); the rest
/// keep these defaults.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SymmetryParams {
    /// Points used to find the plane; a stride over the cloud keeps the search ~1 ms a candidate.
    pub sample: usize,
    /// A point within this distance (normalized units) of a candidate plane does not vote for it.
    pub min_lever: f64,
    /// ... nor, in [`find_plane`], within this share of the cloud's width: a train is 0.07 of its
    /// length wide, so 0.03 left only its flank and roof edges to vote and 4 of the 40 validation
    /// train partials had no plane. Chosen on the validation split among 0.1, 0.2, 0.25, 0.3, 0.4
    /// and none (lab/2026-12-02-plane-heading-cues).
    pub lever_of_width: f64,
    /// A mirrored point counts as matched within this distance of a measured one, or within 1.5
    /// point spacings of a sparser cloud.
    pub match_distance: f64,
    /// Below this fraction of matched points the best-supported plane says little (see
    /// [`find_plane`]).
    pub min_score: f64,
    /// Most Gauss–Newton rounds of `Sample::refine_offset`; it settles in fewer.
    pub icp_rounds: usize,
    /// Neighbours a point's normal is fitted to.
    pub normal_neighbours: usize,
    /// A point whose neighbours' centroid lies more than this many RMS neighbour distances from it is
    /// on the edge of what was seen. Mirror pairs ending there are where the overlap of a one-sided
    /// scan with its mirror image ends, and they pull the plane towards whatever overlap it already
    /// has, so the ICP leaves them out (as mesh zippering leaves out boundary pairs). Chosen on the
    /// validation split among 0.3, 0.4, 0.5, 0.8 and none (lab/2026-12-01-plane-pairs-slices).
    pub edge_offset: f64,
    /// The widest a road vehicle is for its length, wing mirrors included: cars are 0.38–0.47 of
    /// their length wide without them (real scans, generated and third-party meshes), the widest
    /// generated car with them 0.53; the frame makes the length the longer horizontal side.
    pub max_width: f64,
    /// Height of the slices `held_back` bounds the plane in, over the object's length.
    pub slice_height: f64,
    /// Points a slice needs to bound the plane.
    pub slice_points: usize,
    /// A slice bounds the plane only when it spans at least this fraction of the cloud's width, so
    /// that both sides of the vehicle are seen in it.
    pub slice_span: f64,
    /// How near a measured point the mirror image of a slice's far extreme must land (see
    /// `paired`). Chosen on the validation split among 0.01, 0.02, 0.025, 0.03, 0.035, 0.04,
    /// 0.05 and none (lab/2026-12-01-plane-pairs-slices).
    pub paired: f64,
    /// Two x values of a slice closer than this are one return position of the scan lines, apart
    /// only by range noise (the generated scans' noise is at most 0.002).
    pub distinct: f64,
    /// The far extreme's return spacing is believed up to this; a wider gap is more likely a gap
    /// in the surface than in the sampling.
    pub max_spacing: f64,
    /// Where the far edge is taken to lie beyond the far extreme, in return spacings: the last
    /// return falls anywhere within one spacing short of the edge, so half a spacing on average.
    /// With `max_spacing`, chosen on the validation split (lab/2026-12-01-plane-pairs-slices).
    pub far_edge: f64,
    /// The slices bound the plane only when at least this share of the points lies on the better
    /// scanned side of the middle of the width, as on a drive-by. Seen from several sides (camera
    /// partials, some motorcycles) a slice's near extent need not be the vehicle's width there, and one
    /// such slice moved planes found to within 0.01 % by several percent. Chosen on the validation
    /// split among 0, 0.6, 0.65, 0.7, 0.75, 0.8 and 0.85 (lab/2026-12-01-plane-pairs-slices).
    pub one_sided: f64,
    /// Points a tyre track needs in `between_the_tracks`: a side view at the vehicle's height
    /// sees the far tyres' inner faces through the gap under the body, often only a few points of
    /// them in the ground band. Chosen on the validation splits among 2, 3, 5 and 10
    /// (lab/2026-12-06-plane-tyres).
    pub track_points: usize,
    /// The gap between the two tracks spans at least this share of the cloud's width ...
    pub track_gap: f64,
    /// ... and this share of its length: the generated road vehicles' tracks lie 0.097 (long
    /// buses) to about 0.28 (cars) of their length apart, a train's wheels 0.05–0.07 under its body,
    /// where they show their outer faces and not their treads, so their gap's middle lies beyond
    /// the plane (a validation train went from 0.06 % to 0.49 % of its length off;
    /// lab/2026-12-06-plane-tyres).
    pub track_apart: f64,
    /// A near track at least this wide across (share of the length) shows its tyres' treads edge
    /// to edge, as a camera beside the vehicle at its height sees them, and then the gap's middle
    /// also overrules a plane the pairs alone placed beyond it, away from the scanned side; from
    /// above, a scanner sees the near tyres' side walls and not their treads' inner edges. Chosen
    /// on the validation splits among 0.01, 0.015, 0.02, 0.025 and 0.03 (lab/2026-12-06-plane-tyres).
    pub treads_seen: f64,
    /// `with_width` trusts the scanned flank to be seen at its widest only where it lies at least
    /// this share of the half-width from the plane found: a motorcycle seen without its near
    /// handlebar had its plane moved by 10 % of its length. Chosen on two validation splits among
    /// 0, 0.8 and 0.9 (lab/2026-12-03-plane-known-width).
    pub flank_seen: f64,
    /// Points the heading refinement looks at: it scores ~230 planes, and measured on generated
    /// partials 2,000 points find the heading as well as 4,000 (median 0.22° vs 0.18°, p95 3.0° vs
    /// 3.2°) in 20 % less time.
    pub refine_sample: usize,
    /// Most a heading is turned by [`refine_heading`], degrees.
    pub max_turn: f64,
    /// Most a cloud is found rolled by [`find_roll`], degrees: a road's crossfall is 2–3 % (about
    /// 1.5°), a wheel on a kerb a few degrees more.
    pub max_roll: f64,
    /// Support (the share of points mirrored onto others) the upright plane needs before a roll
    /// is looked for: one-sided scans pair too few points to tell a roll from the plane's offset,
    /// and on upright ones the roll found then scatters by degrees (lab/2026-12-05-roll).
    pub min_roll_support: f64,
}

impl Default for SymmetryParams {
    fn default() -> Self {
        SymmetryParams {
            sample: 4000,
            min_lever: 0.03,
            lever_of_width: 0.3,
            match_distance: 0.01,
            min_score: 0.05,
            icp_rounds: 20,
            normal_neighbours: 12,
            edge_offset: 0.4,
            max_width: 0.55,
            slice_height: 0.01,
            slice_points: 20,
            slice_span: 0.5,
            paired: 0.035,
            distinct: 0.002,
            max_spacing: 0.015,
            far_edge: 0.5,
            one_sided: 0.75,
            track_points: 3,
            track_gap: 0.5,
            track_apart: 0.08,
            treads_seen: 0.02,
            flank_seen: 0.8,
            refine_sample: 2000,
            max_turn: 8.0,
            max_roll: 4.0,
            min_roll_support: 0.3,
        }
    }
}

/// The symmetry plane found, and how much of the cloud supports it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Plane {
    /// The plane is `x = offset`.
    pub offset: f64,
    /// Fraction of the sampled points whose mirror image lands on another point.
    pub support: f64,
    /// How close a mirror image must come to a measured point to count as landing on it.
    pub tolerance: f64,
    /// Which step of [`find_plane`] placed it.
    pub fit: PlaneFit,
    /// What each cue said of the offset, in the same frame.
    pub cues: Cues,
    /// Whether the cues agree well enough to draw the plane's mirror image: false where the
    /// plane found would have made the vehicle implausibly wide (see [`PlaneFit::Proportions`]).
    pub vouched: bool,
    /// Whether the scan shows both flanks (under three quarters of its points on one side of
    /// its box's middle), so that its extent across the width is the vehicle's.
    pub both_sides: bool,
}

impl Plane {
    /// The plane as reports give it, `frame` being the one it was found in.
    pub fn report(&self, frame: &Frame) -> PlaneReport {
        let point = frame.to_input([self.offset, 0.0, 0.0]);
        let ahead = frame.to_input([self.offset + 1.0, 0.0, 0.0]);
        // One normalized unit is `extent` input units.
        let normal = [0, 1, 2].map(|i| (ahead[i] - point[i]) / frame.extent);
        PlaneReport {
            x: self.offset,
            point,
            normal,
            support: self.support,
            fit: self.fit,
            cues: self.cues,
            vouched: self.vouched,
        }
    }
}

/// The symmetry plane: `x = x` in the normalized frame, a point on it and its unit normal in
/// the input's coordinates, the share of points it mirrors onto others, and how it was placed.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct PlaneReport {
    pub x: f64,
    pub point: [f64; 3],
    pub normal: [f64; 3],
    pub support: f64,
    pub fit: PlaneFit,
    /// Where each cue put the plane, as `x`.
    pub cues: Cues,
    /// Whether the cues agree well enough for the mirror image to be drawn.
    pub vouched: bool,
}

/// What is known of a vehicle's width across its plane, in [`find_plane`]'s units.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Width {
    /// Its width, as the user gives it (`complete --vehicle-width`).
    Known(f64),
    /// The narrowest it can be, from its size in a scene in metres (`complete --scene`).
    AtLeast(f64),
}

/// Where each cue of [`find_plane`] puts the plane `x = c`, each found on its own; `None` where
/// a cue has nothing to say.
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize)]
pub struct Cues {
    /// The mirror pairs: the best-supported offset pulled by point-to-plane ICP (steps 1–2).
    pub pairs: Option<f64>,
    /// The scan's own extent (step 3): on a scan of one side the middle of the horizontal
    /// slice seen widest on both sides, the plane itself where that slice's far edge is seen,
    /// else a bound towards the scanned side; on a scan of both flanks the middle of its box.
    pub extent: Option<f64>,
    /// Half-way between the near and the far tyre tracks (step 4).
    pub tyres: Option<f64>,
    /// Half the given vehicle width from the scanned flank.
    pub width: Option<f64>,
}

impl Cues {
    /// Each cue's offset mapped by `f` (into another frame).
    pub fn map(self, f: impl Fn(f64) -> f64) -> Cues {
        Cues {
            pairs: self.pairs.map(&f),
            extent: self.extent.map(&f),
            tyres: self.tyres.map(&f),
            width: self.width.map(&f),
        }
    }
}

/// How [`find_plane`] placed a plane.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum PlaneFit {
    /// The best-supported offset; no mirror pairs pulled on it.
    Supported,
    /// The best-supported offset, moved by the mirror pairs' pull.
    Refined,
    /// Too little support to go by: the mirror pairs' pull from the middle of the width.
    Pairs,
    /// Held back at the middle of the slice seen widest on both sides: the pairs put it
    /// beyond, towards the better scanned side.
    HeldBack,
    /// Half-way between the near and the far tyres (see [`find_plane`]).
    Tyres,
    /// Half the vehicle's given width from the scanned flank: the plane found lay nearer it,
    /// or none was found (see [`find_plane`]).
    Width,
    /// At the middle of the scan's extent: the plane found would have drawn a vehicle wider
    /// than any road vehicle is for its length (see [`find_plane`]).
    Proportions,
}

/// Finds `x = c` in four steps:
///
/// 1. **Support**: `c` across the cloud's x range, coarse to fine, where the most mirror images
///    land on measured points.
/// 2. **Pairs**: point-to-plane ICP from there (`Sample::refine_offset`): only surfaces that
///    face across the width pull on the plane. A scan from one side (a drive-by) holds the near
///    flank, the roof and the near parts of the ends; their mirror images land on other points
///    wherever the plane sits on the flat ends and roof, and more of them do the nearer it moves
///    to the scanned side, so the best support leans a few hundredths towards it, while the
///    pairs on curved shoulders, wheel arches and corners do not lean. When the support is
///    below 5 % (a flank and a strip of the roof, common on buses and trains) the
///    pairs start from the middle of the width instead.
/// 3. **Bound**: at any height the scanned side's outermost points are the vehicle's widest
///    there, so a plane beyond the middle of a horizontal slice's width, towards that side,
///    would put the mirror images of the far side's points outside it, where they would have
///    been scanned: the plane is held back at the tightest such middle (`slices_middle`).
/// 4. **Tyres**: on a one-sided cloud whose lowest points show the near and the far tyres, a
///    plane short of the gap between them, towards the scanned side, moves to its middle
///    (`to_the_tyres`). Inward only from a plane the pairs alone placed, and only where
///    the near treads are seen across: seen from above, the near tyres show their side walls
///    and not their treads' inner edges, and the gap's middle then leans towards the scanned
///    side.
///
/// On the validation split (lab/2026-12-01-plane-pairs-slices) the pairs took the mirror's F1@0.01
/// from 0.673 to 0.699, most of it on the 27 % of partials that had no plane before. Given the
/// vehicle's known `width` ([`Width::Known`], normalized units), a scan of one side has its
/// plane kept at least half of it from the scanned flank (`with_width`); given the narrowest it
/// can be ([`Width::AtLeast`]), every plane is (`at_least`). `None` only when neither support,
/// pairs nor tyres show any symmetry (for example, one flat side) and no known width places a
/// plane.
pub fn find_plane(
    points: &[[f64; 3]],
    width: Option<Width>,
    tune: &SymmetryParams,
) -> Option<Plane> {
    let bounds = Aabb::of(points)?;
    let across = bounds.max[0] - bounds.min[0];
    let sample = Sample::of(
        points,
        tune.sample,
        tune.min_lever.min(tune.lever_of_width * across),
        tune,
    )?;
    let (best, support) = sample.best_offset(ACROSS);
    let supported = support >= tune.min_score;
    let start = if supported { best } else { bounds.center()[0] };
    let normals = sample.normals();
    // Without the edges' pairs first; where only edges pair (a flank and a roof strip of some
    // trains), with them.
    let pulled = sample
        .refine_offset(start, &normals, true)
        .or_else(|| sample.refine_offset(start, &normals, false));
    let seen = Seen::of(points, &bounds, tune);
    let found = match pulled {
        Some(c) if supported => Some((c, PlaneFit::Refined)),
        Some(c) => Some((c, PlaneFit::Pairs)),
        None if supported => Some((best, PlaneFit::Supported)),
        None => None,
    }
    .map(|(refined, fit)| {
        let offset = held_back(points, &bounds, &seen, refined, tune);
        let fit = if offset == refined {
            fit
        } else {
            PlaneFit::HeldBack
        };
        sample.plane(offset, fit)
    });
    let found = to_the_tyres(points, &bounds, &seen, &sample, found, tune);
    let found = match width {
        Some(Width::Known(width)) => with_width(points, &seen, &sample, width, found, tune),
        Some(Width::AtLeast(width)) => at_least(points, &seen, &sample, width, found, tune),
        None => found,
    };
    // A one-sided cloud's slices are already cut; the others' are cut here, once.
    let cut;
    let slices: &[Vec<usize>] = if seen.one_sided {
        &seen.slices
    } else {
        cut = horizontal_slices(points, &bounds, tune);
        &cut
    };
    let cues = Cues {
        pairs: pulled.or(supported.then_some(best)),
        extent: if seen.one_sided {
            slices_middle(points, &bounds, slices, seen.side, tune)
        } else {
            Some(bounds.center()[0])
        },
        tyres: between_the_tracks(points, &bounds, seen.side, tune).map(|t| t.middle),
        width: width.and_then(|width| {
            let (Width::Known(w) | Width::AtLeast(w)) = width;
            let flank = scanned_flank(points, slices, seen.side, tune)?;
            Some(seen.side * (flank - w / 2.0))
        }),
    };
    let both_sides = !seen.one_sided;
    let found = found.map(|p| Plane {
        cues,
        both_sides,
        ..p
    });
    in_proportion(points, &bounds, slices, &sample, cues.extent, found, tune)
}

/// Step 5 of [`find_plane`]: on a scan no wider than [`SymmetryParams::max_width`] of its length, a plane that
/// would put either flank's mirror image more than that from the other flank is no vehicle's,
/// so it goes to the middle
/// of the scan's own extent (`extent`, [`slices_middle`]; of the whole box where there is
/// none), the cue a plane far off the middle contradicts most, and is not vouched for.
/// `slices` are the points' [`horizontal_slices`].
fn in_proportion(
    points: &[[f64; 3]],
    bounds: &Aabb,
    slices: &[Vec<usize>],
    sample: &Sample,
    extent: Option<f64>,
    found: Option<Plane>,
    tune: &SymmetryParams,
) -> Option<Plane> {
    let plane = found?;
    let length = bounds.max[2] - bounds.min[2];
    // A scan already wider than that is no road vehicle seen along its length (or its heading
    // is off), and the proportions say nothing of it.
    if bounds.max[0] - bounds.min[0] > tune.max_width * length {
        return Some(plane);
    }
    let widest = [-1.0, 1.0]
        .into_iter()
        .filter_map(|side| Some(scanned_flank(points, slices, side, tune)? - side * plane.offset))
        .fold(0.0, f64::max);
    if 2.0 * widest <= tune.max_width * length {
        return Some(plane);
    }
    let middle = extent.unwrap_or_else(|| bounds.center()[0]);
    Some(Plane {
        cues: plane.cues,
        vouched: false,
        both_sides: plane.both_sides,
        ..sample.plane(middle, PlaneFit::Proportions)
    })
}

/// Step 4 of [`find_plane`]: the plane `found` on a one-sided cloud moved to the middle between
/// the tyre tracks (see [`between_the_tracks`]) where it lies short of it, towards the scanned
/// side, or where the pairs alone placed it and the near treads are seen edge to edge (then
/// still held back by the slices, [`held_back`]). `bounds` is the points' box, `seen` how they
/// were seen in it, `sample` [`find_plane`]'s.
fn to_the_tyres(
    points: &[[f64; 3]],
    bounds: &Aabb,
    seen: &Seen,
    sample: &Sample,
    found: Option<Plane>,
    tune: &SymmetryParams,
) -> Option<Plane> {
    let tracks = seen
        .one_sided
        .then(|| between_the_tracks(points, bounds, seen.side, tune))
        .flatten();
    match (found, tracks) {
        (Some(p), Some(t)) if (t.middle - p.offset) * seen.side < 0.0 => {
            Some(sample.plane(t.middle, PlaneFit::Tyres))
        }
        (Some(p), Some(t)) if p.fit == PlaneFit::Pairs && t.near_width >= tune.treads_seen => {
            let offset = held_back(points, bounds, seen, t.middle, tune);
            let fit = if offset == t.middle {
                PlaneFit::Tyres
            } else {
                PlaneFit::HeldBack
            };
            Some(sample.plane(offset, fit))
        }
        (None, Some(t)) => Some(sample.plane(t.middle, PlaneFit::Tyres)),
        (found, _) => found,
    }
}

/// The tightest bound on the plane from `scanned_side` (±1): the middle of each horizontal
/// slice's x range, the one farthest from that side. In every slice the scanned side's
/// outermost point is the vehicle's width there and the far side's is at most its width, so
/// every slice's middle lies on the plane or towards the scanned side; the slice seen widest on
/// both sides (often the roof's, seen from above) lies nearest the plane. The middle of the
/// whole cloud's range pairs the near flank's widest part with the far roof's edge, which is
/// narrower, and so lies farther: on the validation split it leaned 0.8 % of the length
/// towards the scanner (median), the slices' 0.2 %. A slice counts only where its far
/// extreme's mirror image lands on a measured point ([`paired`]). The far side is seen at a
/// grazing angle, where the returns lie far apart, so the last one falls short of the edge:
/// the chosen slice's far extreme is moved out by [`SymmetryParams::far_edge`] of the spacing between it and
/// the next return position. `None` when no slice spans the width. `bounds` is the points'
/// box, `slices` their [`horizontal_slices`].
fn slices_middle(
    points: &[[f64; 3]],
    bounds: &Aabb,
    slices: &[Vec<usize>],
    scanned_side: f64,
    tune: &SymmetryParams,
) -> Option<f64> {
    let width = bounds.max[0] - bounds.min[0];
    let x = |i: &usize| points[*i][0];
    let (middle, slice, far) = slices
        .iter()
        .filter(|m| m.len() >= tune.slice_points)
        .filter_map(|m| {
            let lo = m.iter().copied().min_by(|a, b| x(a).total_cmp(&x(b)))?;
            let hi = m.iter().copied().max_by(|a, b| x(a).total_cmp(&x(b)))?;
            let middle = (x(&lo) + x(&hi)) / 2.0;
            let far = if scanned_side > 0.0 { lo } else { hi };
            (x(&hi) - x(&lo) >= tune.slice_span * width && paired(points, m, far, middle, tune))
                .then_some((middle, m, far))
        })
        .min_by(|a, b| (a.0 * scanned_side).total_cmp(&(b.0 * scanned_side)))?;
    // The spacing between the far extreme and the next return position towards the near side.
    let spacing = slice
        .iter()
        .map(|i| (x(i) - x(&far)) * scanned_side)
        .filter(|&d| d > tune.distinct)
        .fold(tune.max_spacing, f64::min);
    Some(middle - scanned_side * spacing * tune.far_edge / 2.0)
}

/// Whether the mirror image of point `far` about `x = middle` lands within [`SymmetryParams::paired`] of one of
/// the points `among`. A slice's far extreme that pairs with nothing on the scanned side, where
/// its image would have been seen, is not the mirror of the near extreme: a part on one side
/// only (a motorcycle's exhaust), so its slice says nothing about the plane.
fn paired(
    points: &[[f64; 3]],
    among: &[usize],
    far: usize,
    middle: f64,
    tune: &SymmetryParams,
) -> bool {
    let image = mirror(points[far], middle);
    among.iter().any(|&i| {
        let d: f64 = (0..3).map(|k| (points[i][k] - image[k]).powi(2)).sum();
        d <= tune.paired * tune.paired
    })
}

/// The plane offset `c`, held back at the middle of the slice seen widest on both sides
/// ([`slices_middle`]; of the points' whole x range when none is or the cloud is not seen from
/// one side, [`SymmetryParams::one_sided`]) when it lies beyond it towards the better scanned side (see
/// [`find_plane`]). `bounds` is the points' box, `seen` how they were seen in it.
fn held_back(
    points: &[[f64; 3]],
    bounds: &Aabb,
    seen: &Seen,
    c: f64,
    tune: &SymmetryParams,
) -> f64 {
    let whole = bounds.center()[0];
    let middle = if seen.one_sided {
        slices_middle(points, bounds, &seen.slices, seen.side, tune).unwrap_or(whole)
    } else {
        whole
    };
    if (c - middle) * seen.side > 0.0 {
        middle
    } else {
        c
    }
}

/// How a cloud was seen across its width, found once for the slices' bound and the width.
struct Seen {
    /// The better scanned side of the width's middle (±1: the side holding more points).
    side: f64,
    /// Whether at least [`SymmetryParams::one_sided`] of the points lie on that side, as on a drive-by.
    one_sided: bool,
    /// The points' [`horizontal_slices`] where the cloud is one-sided (nothing reads them
    /// otherwise), else none.
    slices: Vec<Vec<usize>>,
}

impl Seen {
    /// `bounds` is the points' box.
    fn of(points: &[[f64; 3]], bounds: &Aabb, tune: &SymmetryParams) -> Seen {
        let whole = bounds.center()[0];
        let mean = points.iter().map(|p| p[0]).sum::<f64>() / points.len() as f64;
        let side = (mean - whole).signum();
        let near_share = points
            .iter()
            .filter(|p| (p[0] - whole) * side > 0.0)
            .count() as f64
            / points.len() as f64;
        let one_sided = near_share >= tune.one_sided;
        let slices = if one_sided {
            horizontal_slices(points, bounds, tune)
        } else {
            Vec::new()
        };
        Seen {
            side,
            one_sided,
            slices,
        }
    }
}

/// Two tyre tracks in a cloud's ground points (see [`between_the_tracks`]).
#[derive(Debug, Clone, Copy, PartialEq)]
struct Tracks {
    /// The middle of the gap between them.
    middle: f64,
    /// How wide across the track on the scanned side is.
    near_width: f64,
}

/// The middle of the gap between the near and the far tyres, where the ground points (the lowest
/// [`GROUND`] of the height) fall into two tracks across the width. Seen from beside the vehicle at
/// its height, the near tyres show their treads edge to edge and the far ones their inner faces
/// under the body, so the gap's two sides are mirror twins, while nothing else of the far side may
/// be in view (camera partials: lab/2026-12-06-plane-tyres). `bounds` is the points' box, `points`
/// in [`find_plane`]'s frame (unit length), `scanned_side` (±1) the side the near track is on.
fn between_the_tracks(
    points: &[[f64; 3]],
    bounds: &Aabb,
    scanned_side: f64,
    tune: &SymmetryParams,
) -> Option<Tracks> {
    let ground = at_height(points, GROUND);
    let mut low: Vec<f64> = points
        .iter()
        .filter(|p| p[1] <= ground)
        .map(|p| p[0])
        .collect();
    low.sort_by(f64::total_cmp);
    let (gap, at) = low
        .windows(2)
        .enumerate()
        .map(|(i, w)| (w[1] - w[0], i + 1))
        .max_by(|a, b| a.0.total_cmp(&b.0))?;
    let tracks = at >= tune.track_points && low.len() - at >= tune.track_points;
    let apart = gap >= tune.track_gap * (bounds.max[0] - bounds.min[0]) && gap >= tune.track_apart;
    let near_width = if scanned_side > 0.0 {
        low[low.len() - 1] - low[at]
    } else {
        low[at - 1] - low[0]
    };
    (tracks && apart).then(|| Tracks {
        middle: (low[at - 1] + low[at]) / 2.0,
        near_width,
    })
}

/// The plane of a scan seen from one side (`one_sided`, as for the slices' bound) whose vehicle is
/// `width` wide (normalized units): no nearer the scanned flank than half the width, so the
/// mirrored far flank lies at least as far out as the vehicle's width puts it, unless the flank
/// lies under `flank_seen` of that from the plane (its widest part is then not seen); where no
/// plane was found, half the width from that flank. The flank is the outermost point of the scanned
/// side over the horizontal slices of `slice_points` points or more. The width bounds the plane
/// only on that side: where the heading is off by a fraction of a degree, the ends of a long
/// vehicle stick out past its flank, and setting every plane at half the width from that outermost
/// point moved good planes by 0.6 % of the length (validation split,
/// lab/2026-12-03-plane-known-width). Clouds seen from both sides keep `plane` as found. `seen` is
/// how the points were seen, `sample` [`find_plane`]'s.
fn with_width(
    points: &[[f64; 3]],
    seen: &Seen,
    sample: &Sample,
    width: f64,
    plane: Option<Plane>,
    tune: &SymmetryParams,
) -> Option<Plane> {
    if !seen.one_sided {
        return plane;
    }
    let side = seen.side;
    let Some(flank) = scanned_flank(points, &seen.slices, side, tune) else {
        return plane;
    };
    let bound = side * (flank - width / 2.0);
    match plane {
        Some(p) if (p.offset - bound) * side <= 0.0 => Some(p),
        Some(p) if flank - p.offset * side < tune.flank_seen * width / 2.0 => Some(p),
        _ => Some(sample.plane(bound, PlaneFit::Width)),
    }
}

/// The plane of a scan seen from one side (as for [`with_width`]) of a vehicle at least `width`
/// wide (normalized units): no nearer the scanned flank than half of it, whatever the plane
/// found, since a narrowest width is met by every vehicle of its kind; no plane is made where
/// none was found, since the narrowest width does not place one. `seen` is how the points were
/// seen, `sample` [`find_plane`]'s.
fn at_least(
    points: &[[f64; 3]],
    seen: &Seen,
    sample: &Sample,
    width: f64,
    plane: Option<Plane>,
    tune: &SymmetryParams,
) -> Option<Plane> {
    let side = seen.side;
    let bound = seen
        .one_sided
        .then(|| scanned_flank(points, &seen.slices, side, tune))
        .flatten()
        .map(|flank| side * (flank - width / 2.0));
    match (plane, bound) {
        (Some(p), Some(bound)) if (p.offset - bound) * side > 0.0 => {
            Some(sample.plane(bound, PlaneFit::Width))
        }
        (plane, _) => plane,
    }
}

/// The outermost x towards `side` (±1, times `side`) over the `slices` (see
/// [`horizontal_slices`]) holding at least [`SymmetryParams::slice_points`] points; `None` when no slice does.
/// A stray point alone in its slice does not count.
fn scanned_flank(
    points: &[[f64; 3]],
    slices: &[Vec<usize>],
    side: f64,
    tune: &SymmetryParams,
) -> Option<f64> {
    slices
        .iter()
        .filter(|m| m.len() >= tune.slice_points)
        .flat_map(|m| m.iter().map(|&i| points[i][0] * side))
        .max_by(f64::total_cmp)
}

/// The indices of `points` in each horizontal slice [`SymmetryParams::slice_height`] high, from the bottom of
/// `bounds` (the points' box) up.
fn horizontal_slices(points: &[[f64; 3]], bounds: &Aabb, tune: &SymmetryParams) -> Vec<Vec<usize>> {
    let slices = (((bounds.max[1] - bounds.min[1]) / tune.slice_height).ceil() as usize).max(1);
    let mut members = vec![Vec::new(); slices];
    for (i, p) in points.iter().enumerate() {
        let slice = (((p[1] - bounds.min[1]) / tune.slice_height) as usize).min(slices - 1);
        members[slice].push(i);
    }
    members
}

/// Turns `heading` (degrees counter-clockwise from +x seen from above, see
/// [`mod@crate::complete::orient`]) by at most ±8° so that the vertical plane along it is the
/// cloud's plane of symmetry. `points` are upright (+y up), in any unit. `None` when the cloud
/// shows no symmetry near that heading.
///
/// A heading a few degrees off leaves the mirror images and the network's views turned by as
/// much, which costs more F1@0.01 than any other part of orientation; the symmetry plane of a
/// vehicle pins its length axis to a fraction of a degree.
pub fn refine_heading(points: &[[f64; 3]], heading: f64, tune: &SymmetryParams) -> Option<f64> {
    let sample = unit_sample(points, tune)?;
    // The plane along heading h has the horizontal normal (sin h, 0, cos h).
    let normal = |h: f64| {
        let (s, c) = h.to_radians().sin_cos();
        [s, 0.0, c]
    };
    best_angle(&sample, normal, heading, tune.max_turn, tune.min_score).map(|h| h.rem_euclid(360.0))
}

/// How far a vehicle leans across its width, in degrees about its length: `points` are in the
/// canonical pose (x across, y up, z along; any unit), and the plane of symmetry that fits them
/// best has the normal (cos r, sin r, 0) for the r returned, within ±[`SymmetryParams::max_roll`]. A scanner's
/// up axis is the plumb line, while a vehicle on a cambered road or a kerb leans with it, and
/// its mirror images then land beside their partners: a lean of 1.5° cost the mirror a tenth of
/// its F1@0.01 on the validation split (lab/2026-12-05-roll). `None` when the cloud does not
/// show enough symmetry to tell.
pub fn find_roll(points: &[[f64; 3]], tune: &SymmetryParams) -> Option<f64> {
    let sample = cross_section_sample(points, tune)?;
    let normal = |r: f64| {
        let (s, c) = r.to_radians().sin_cos();
        [c, s, 0.0]
    };
    best_angle(&sample, normal, 0.0, tune.max_roll, tune.min_roll_support)
}

/// [`SymmetryParams::refine_sample`] points of the cloud, centred on its box and scaled by its cross-section
/// (the larger of its width and height): a roll moves points across the width by their height
/// times its angle, so a bus's is measured against its own size, not its length. Mirroring
/// across a plane that holds the length axis commutes with any scaling along it.
fn cross_section_sample(points: &[[f64; 3]], tune: &SymmetryParams) -> Option<Sample> {
    let bounds = Aabb::of(points)?;
    let [w, h, _] = bounds.extent();
    scaled_sample(points, &bounds, w.max(h), tune)
}

/// [`SymmetryParams::refine_sample`] points of the cloud, centred on its box and scaled to unit length.
fn unit_sample(points: &[[f64; 3]], tune: &SymmetryParams) -> Option<Sample> {
    let bounds = Aabb::of(points)?;
    scaled_sample(points, &bounds, bounds.longest_side(), tune)
}

/// [`SymmetryParams::refine_sample`] points of the cloud, centred on its box and divided by `extent`.
fn scaled_sample(
    points: &[[f64; 3]],
    bounds: &Aabb,
    extent: f64,
    tune: &SymmetryParams,
) -> Option<Sample> {
    if extent <= 0.0 {
        return None;
    }
    let center = bounds.center();
    let unit: Vec<[f64; 3]> = points
        .iter()
        .map(|p| [0, 1, 2].map(|i| (p[i] - center[i]) / extent))
        .collect();
    Sample::of(&unit, tune.refine_sample, tune.min_lever, tune)
}

/// The angle (degrees) within `max` of `start` whose plane, `normal(angle)` its unit normal,
/// the sample's mirror images land closest to, coarse to fine, the plane's offset searched
/// with it. `None` when the plane at `start` mirrors under `min_support` of the sample onto it.
fn best_angle(
    sample: &Sample,
    normal: impl Fn(f64) -> [f64; 3] + Sync,
    start: f64,
    max: f64,
    min_support: f64,
) -> Option<f64> {
    let (c0, support) = sample.best_offset(normal(start));
    if support < min_support {
        return None;
    }
    // Turning about the box centre moves the plane's offset by the lever of the vehicle's
    // middle, a few hundredths at most. The candidates are scored side by side (each score a
    // sum over a sample too small for rayon to split) and the first best kept, as in turn.
    let search = |best: (f64, f64, f64), turns: &[f64], offsets: &[f64]| {
        let (a, c) = (best.0, best.1);
        let candidates: Vec<(f64, f64)> = turns
            .iter()
            .flat_map(|&t| offsets.iter().map(move |&o| (a + t, c + o)))
            .collect();
        let scores: Vec<f64> = candidates
            .par_iter()
            .map(|&(angle, offset)| sample.closeness(normal(angle), offset))
            .collect();
        candidates
            .into_iter()
            .zip(scores)
            .fold(best, |best, ((angle, offset), score)| {
                if score > best.2 {
                    (angle, offset, score)
                } else {
                    best
                }
            })
    };
    let start = (start, c0, sample.closeness(normal(start), c0));
    let coarse: Vec<f64> = (-8..=8).map(|i| i as f64 * max / 8.0).collect();
    let best = search(start, &coarse, &[-0.02, -0.01, 0.0, 0.01, 0.02]);
    let fine: Vec<f64> = (-5..=5).map(|i| i as f64 * 0.2).collect();
    let best = search(best, &fine, &[-0.005, -0.0025, 0.0, 0.0025, 0.005]);
    let finest: Vec<f64> = (-4..=4).map(|i| i as f64 * 0.05).collect();
    let best = search(best, &finest, &[-0.001, 0.0, 0.001]);
    Some(best.0)
}

/// A strided sample of a cloud with the distance within which a mirror image counts as landing
/// on a point, and a grid of cells that size to find such points.
struct Sample {
    points: Vec<[f64; 3]>,
    tolerance: f64,
    /// Points nearer a candidate plane than this do not vote for it ([`SymmetryParams::min_lever`]).
    lever: f64,
    grid: MatchGrid,
    index: KnnIndex,
    tune: SymmetryParams,
}

impl Sample {
    fn of(points: &[[f64; 3]], size: usize, lever: f64, tune: &SymmetryParams) -> Option<Sample> {
        if points.len() < 2 {
            return None;
        }
        let stride = points.len().div_ceil(size);
        let points: Vec<[f64; 3]> = points.iter().step_by(stride).copied().collect();
        let index = KnnIndex::new(&points);
        let mut spacing: Vec<f64> = index
            .k_nearest_distances(&points, 2)
            .chunks(2)
            .map(|d| d[1])
            .filter(|d| d.is_finite())
            .collect();
        spacing.sort_by(f64::total_cmp);
        let tolerance = spacing
            .get(spacing.len() / 2)
            .map_or(tune.match_distance, |&s| tune.match_distance.max(1.5 * s));
        let grid = MatchGrid::new(&points, tolerance);
        Some(Sample {
            points,
            tolerance,
            lever,
            grid,
            index,
            tune: *tune,
        })
    }

    /// Unit normals of the sample's points, each from the plane through its nearest
    /// neighbours (the sign is arbitrary), and whether the point lies on the edge of what was
    /// seen (see [`SymmetryParams::edge_offset`]).
    fn normals(&self) -> Vec<([f64; 3], bool)> {
        let neighbours = self.tune.normal_neighbours;
        self.index
            .k_nearest(&self.points, neighbours)
            .par_chunks(neighbours)
            .map(|near| {
                let mean = near.iter().fold([0.0; 3], |m, &i| {
                    [0, 1, 2].map(|k| m[k] + self.points[i][k] / neighbours as f64)
                });
                let mut cov = Matrix3::zeros();
                for &i in near {
                    let d = Vector3::from([0, 1, 2].map(|k| self.points[i][k] - mean[k]));
                    cov += d * d.transpose();
                }
                let spread = (cov.trace() / neighbours as f64).sqrt();
                let own = self.points[near[0]];
                let off = (0..3)
                    .map(|k| (own[k] - mean[k]).powi(2))
                    .sum::<f64>()
                    .sqrt();
                let eigen = SymmetricEigen::new(cov);
                let smallest = eigen.eigenvalues.imin();
                let n = eigen.eigenvectors.column(smallest);
                ([n[0], n[1], n[2]], off > self.tune.edge_offset * spread)
            })
            .collect()
    }

    /// Point-to-plane ICP on the offset of `x = c` from `start`: each point farther than
    /// the lever from the plane is mirrored and paired with the nearest sampled point
    /// within a reach, and `c` moves to minimize Σ (n·(m − q))² over the pairs (`m` the mirror
    /// image, `q` its partner, `n` the normal there; with `skip_edges`, partners on the edge of
    /// what was seen are left out). A mirror image moves by 2 along x per
    /// unit of `c`, so only pairs whose surface faces across the width pull on the plane: the
    /// roof and the ends, which slide along themselves, do not, and they are what makes the
    /// best-supported plane lean towards the scanned side. `None` when no pair pulls.
    fn refine_offset(
        &self,
        start: f64,
        normals: &[([f64; 3], bool)],
        skip_edges: bool,
    ) -> Option<f64> {
        let mut c = start;
        for round in 0..self.tune.icp_rounds {
            // Wide first, so a plane a few tolerances off finds its pairs, then tight.
            let reach = if round < 5 { 3.0 } else { 1.5 } * self.tolerance;
            let images: Vec<[f64; 3]> = self.points.iter().map(|&p| mirror(p, c)).collect();
            let pairs = self.index.nearest(&images);
            let (mut num, mut den) = (0.0, 0.0);
            for ((p, m), (q, d)) in self.points.iter().zip(&images).zip(&pairs) {
                if (p[0] - c).abs() <= self.lever || *d > reach {
                    continue;
                }
                let (n, edge) = normals[*q];
                if edge && skip_edges {
                    continue;
                }
                let qp = self.points[*q];
                let r = (0..3).map(|k| n[k] * (m[k] - qp[k])).sum::<f64>();
                let j = 2.0 * n[0];
                num += j * r;
                den += j * j;
            }
            if den <= 0.0 {
                return None;
            }
            // Gauss–Newton, at most a match distance a round.
            let step = (-num / den).clamp(-self.tune.match_distance, self.tune.match_distance);
            c += step;
            if step.abs() < 1e-6 {
                break;
            }
        }
        Some(c)
    }

    /// The plane `x = c` with its support and this sample's match tolerance.
    fn plane(&self, c: f64, fit: PlaneFit) -> Plane {
        Plane {
            offset: c,
            support: self.support(ACROSS, c),
            tolerance: self.tolerance,
            fit,
            cues: Cues::default(),
            vouched: true,
            both_sides: false,
        }
    }

    /// Fraction of the sample whose mirror image across the plane `p·n = c` lands on a sampled
    /// point; `n` is the plane's unit normal.
    fn support(&self, n: [f64; 3], c: f64) -> f64 {
        self.mirrored_sum(n, c, |_| 1.0)
    }

    /// [`Sample::support`] with each landing weighted by how close it is, `1 − (d / tolerance)²`:
    /// smooth in the plane's angle, where the count changes in steps.
    fn closeness(&self, n: [f64; 3], c: f64) -> f64 {
        let t2 = self.tolerance * self.tolerance;
        self.mirrored_sum(n, c, |d2| 1.0 - d2 / t2)
    }

    /// Σ `weight(d²)` over the sample's mirror images that land within the tolerance of a
    /// sampled point (d: the distance to the nearest), over the sample size. Points closer to
    /// the plane than the lever map onto themselves and do not count.
    fn mirrored_sum(&self, n: [f64; 3], c: f64, weight: impl Fn(f64) -> f64 + Sync) -> f64 {
        let sum: f64 = self
            .points
            .par_iter()
            .with_min_len(1024)
            .filter_map(|p| {
                let d = dot(*p, n) - c;
                if d.abs() <= self.lever {
                    return None;
                }
                self.grid
                    .nearest_within([0, 1, 2].map(|k| p[k] - 2.0 * d * n[k]))
                    .map(&weight)
            })
            .sum();
        sum / self.points.len() as f64
    }

    /// The best offset of a plane with normal `n` across the sample, coarse to fine, and its
    /// support.
    fn best_offset(&self, n: [f64; 3]) -> (f64, f64) {
        let (lo, hi) = self
            .points
            .iter()
            .fold((f64::MAX, f64::MIN), |(lo, hi), p| {
                let s = dot(*p, n);
                (lo.min(s), hi.max(s))
            });
        let best_of = |candidates: Vec<f64>| {
            let supports: Vec<f64> = candidates.par_iter().map(|&c| self.support(n, c)).collect();
            candidates
                .into_iter()
                .zip(supports)
                .fold((0.0, -1.0), |best, s| if s.1 > best.1 { s } else { best })
        };
        let coarse = 40;
        let step = (hi - lo) / coarse as f64;
        let (c, _) = best_of((0..=coarse).map(|i| lo + step * i as f64).collect());
        let fine = 20;
        best_of(
            (0..=fine)
                .map(|i| c - step + 2.0 * step * i as f64 / fine as f64)
                .collect(),
        )
    }
}

fn dot(p: [f64; 3], n: [f64; 3]) -> f64 {
    p[0] * n[0] + p[1] * n[1] + p[2] * n[2]
}

/// `p` mirrored across `x = offset`.
pub fn mirror(p: [f64; 3], offset: f64) -> [f64; 3] {
    [2.0 * offset - p[0], p[1], p[2]]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::complete::upright::angle_between;
    use crate::complete::upright::fixtures::{car_block, driven_past};
    use crate::datagen::shapes::{example_car, scanned_side};
    use crate::datagen::synth::Category;

    #[test]
    fn the_plane_of_drive_by_scans_is_not_pulled_towards_the_scanned_side() {
        // Generated cars scanned from a path beside them: one flank, the roof and the ends seen
        // at a slant, the far halves of the ends only in part. The car's plane is x = 0. The
        // best-supported plane lies 0.020–0.059 towards the scanned side; held back at the
        // middle of the whole width it lay 0.010–0.016 from the car's (the far flank's widest
        // part is not seen, so that middle itself leans that way); moved by the mirror pairs,
        // 0.003–0.010; held back at the middle of the slice seen widest on both sides,
        // 0.001–0.0055.
        for (seed, side) in [(1, 1.0), (2, -1.0), (3, 1.0), (4, -1.0)] {
            let plane = drive_by_plane(Category::Car, seed, side)
                .expect("the roof and the ends are symmetric");
            assert!(
                plane.offset.abs() < 0.006,
                "car {seed} scanned from {side}: plane at {}",
                plane.offset
            );
        }
    }

    #[test]
    fn a_leaning_car_s_roll_is_found_and_one_side_is_left_upright() {
        let sampled = crate::datagen::shapes::car(20_000, 1);
        let lean = |points: &[[f64; 3]], deg: f64| -> Vec<[f64; 3]> {
            let (s, c) = f64::to_radians(deg).sin_cos();
            points
                .iter()
                .map(|p| [p[0] * c - p[1] * s, p[0] * s + p[1] * c, p[2]])
                .collect()
        };
        for deg in [0.0, 1.5, -3.0] {
            let found = find_roll(
                &lean(&sampled.cloud.positions, deg),
                &SymmetryParams::default(),
            )
            .expect("a whole car");
            assert!(
                (found - deg).abs() <= 0.25,
                "leaning {deg}°, found {found}°"
            );
        }
        // One flank and the whole roof, as a scanner above the roof sees them: the roof's halves
        // pair across the plane.
        let side = scanned_side(&sampled).positions;
        let found = find_roll(&lean(&side, 2.0), &SymmetryParams::default())
            .expect("the roof is symmetric");
        assert!(
            (found - 2.0).abs() <= 0.25,
            "one side leaning 2°, found {found}°"
        );
        // The near flank below the windows alone pairs too few points to tell a lean from the
        // plane's offset.
        let top = side.iter().map(|p| p[1]).fold(f64::MIN, f64::max);
        let flank: Vec<[f64; 3]> = side
            .into_iter()
            .filter(|p| p[0] > 0.0 && p[1] < 0.6 * top)
            .collect();
        assert_eq!(
            find_roll(&lean(&flank, 2.0), &SymmetryParams::default()),
            None
        );
    }

    #[test]
    fn a_narrow_vehicle_has_a_plane() {
        // A generated train is about 0.07 of its length wide: with a fixed lever of 0.03 only
        // its flank and roof edges voted and these two had no plane.
        for seed in [4, 5] {
            let plane = drive_by_plane(Category::Train, seed, 1.0).expect("a roof is symmetric");
            assert!(
                plane.offset.abs() < 0.003,
                "train {seed}: plane at {}",
                plane.offset
            );
        }
    }

    /// The plane found on a drive-by scan of generated object `seed` of `category`, from
    /// `side` (sensor 0.45 above the object's lowest point, 0.8 beside its centre); the
    /// object's own plane is x = 0.
    fn drive_by_plane(category: Category, seed: u64, side: f32) -> Option<Plane> {
        find_plane(
            &driven_past(category, seed, side, 0.45),
            None,
            &SymmetryParams::default(),
        )
    }

    /// A cross-section's (x, y) points repeated along the length, 50 times 0.01 apart.
    fn extruded(section: &[[f64; 2]]) -> Vec<[f64; 3]> {
        (0..50)
            .flat_map(|k| section.iter().map(move |&[x, y]| [x, y, k as f64 * 0.01]))
            .collect()
    }

    #[test]
    fn the_plane_is_held_back_at_the_slice_seen_on_both_sides() {
        // A near flank at x = 0.2 up to the shoulder, a narrower roof seen edge to edge at
        // y = 0.3: the whole x range's middle (0.025) pairs the flank with the far roof edge,
        // the roof's slice says where the plane is. The flank holds most points, as a
        // drive-by's does. The roof's returns lie 0.01 apart, so its far edge is taken half a
        // spacing beyond the last one, and the plane half of that beyond the roof's middle.
        let mut section: Vec<[f64; 2]> = (0..100).map(|i| [0.2, i as f64 * 0.002]).collect();
        section.extend((0..=30).map(|i| [-0.15 + i as f64 * 0.01, 0.3]));
        let points = extruded(&section);
        let bounds = Aabb::of(&points).unwrap();
        assert!((bounds.center()[0] - 0.025).abs() < 1e-9);
        let bound = -0.01 * SymmetryParams::default().far_edge / 2.0;
        let slices = horizontal_slices(&points, &bounds, &SymmetryParams::default());
        assert!(
            (slices_middle(&points, &bounds, &slices, 1.0, &SymmetryParams::default()).unwrap()
                - bound)
                .abs()
                < 1e-9
        );
        let seen = Seen::of(&points, &bounds, &SymmetryParams::default());
        assert!(
            (held_back(&points, &bounds, &seen, 0.02, &SymmetryParams::default()) - bound).abs()
                < 1e-9,
            "beyond it: held back"
        );
        assert_eq!(
            held_back(&points, &bounds, &seen, -0.01, &SymmetryParams::default()),
            -0.01,
            "short of it: kept"
        );
    }

    /// A side view from the vehicle's height, as cameras beside it see one (x = 0 its plane):
    /// the near flank at x = 0.2, the back seen in part (to x = -0.12), the near tyres' treads
    /// edge to edge (x 0.15 to 0.2) and, with `far_tyre`, the far back tyre's inner face at
    /// x = -0.15 under the body.
    fn side_view(far_tyre: bool) -> Vec<[f64; 3]> {
        let steps = |from: f64, to: f64, step: f64| {
            let n = ((to - from) / step).round() as usize;
            (0..=n).map(move |i| from + i as f64 * step)
        };
        let mut points: Vec<[f64; 3]> = steps(0.05, 0.3, 0.002)
            .flat_map(|y| steps(0.0, 0.49, 0.01).map(move |z| [0.2, y, z]))
            .collect();
        points.extend(
            steps(-0.12, 0.2, 0.01).flat_map(|x| steps(0.05, 0.3, 0.01).map(move |y| [x, y, 0.5])),
        );
        let tyre = |xs: (f64, f64), z0: f64| {
            steps(xs.0, xs.1, 0.005).flat_map(move |x| {
                steps(0.0, 0.014, 0.002)
                    .flat_map(move |y| steps(z0, z0 + 0.07, 0.01).map(move |z| [x, y, z]))
            })
        };
        points.extend(tyre((0.15, 0.2), 0.05).chain(tyre((0.15, 0.2), 0.37)));
        if far_tyre {
            points.extend(tyre((-0.15, -0.15), 0.37));
        }
        points
    }

    #[test]
    fn a_side_view_s_plane_lies_between_the_tyres() {
        // The back's slice pairs the near flank with the back's far extreme, short of the far
        // edge, so the slices hold the plane about 0.035 towards the camera; the gap between
        // the near treads' inner edge and the far tyre's inner face is centred on the plane.
        let points = side_view(true);
        let bounds = Aabb::of(&points).unwrap();
        let tracks = between_the_tracks(&points, &bounds, 1.0, &SymmetryParams::default()).unwrap();
        assert!(tracks.middle.abs() < 1e-9, "{tracks:?}");
        assert!(
            (tracks.near_width - 0.05).abs() < 1e-9,
            "the treads: {tracks:?}"
        );
        let plane = find_plane(&points, None, &SymmetryParams::default())
            .expect("the back and the tyres pair");
        assert_eq!(plane.fit, PlaneFit::Tyres);
        assert!(plane.offset.abs() < 1e-9, "plane at {}", plane.offset);
        // Without the far tyre the ground points are one track, and the slices bound it.
        let points = side_view(false);
        let bounds = Aabb::of(&points).unwrap();
        assert_eq!(
            between_the_tracks(&points, &bounds, 1.0, &SymmetryParams::default()),
            None
        );
        // Squeezed to a rail vehicle's width the tracks lie too near each other to be tyres'.
        let narrow: Vec<[f64; 3]> = side_view(true)
            .iter()
            .map(|p| [p[0] * 0.2, p[1], p[2]])
            .collect();
        assert_eq!(
            between_the_tracks(
                &narrow,
                &Aabb::of(&narrow).unwrap(),
                1.0,
                &SymmetryParams::default()
            ),
            None
        );
        let plane = find_plane(&points, None, &SymmetryParams::default()).expect("the back pairs");
        assert_eq!(plane.fit, PlaneFit::HeldBack);
        assert!(plane.offset > 0.03, "plane at {}", plane.offset);
    }

    #[test]
    fn the_treads_seen_edge_to_edge_overrule_the_pairs_alone() {
        // A plane the pairs alone placed 0.02 beyond the tyres' middle, away from the scanned
        // side, moves to it where the near treads are seen across (0.05 wide); where only the
        // near tyres' side walls are (a track as thin as a scanner from above sees), it stays.
        let plane = |points: &[[f64; 3]], fit| {
            let bounds = Aabb::of(points).unwrap();
            let sample = Sample::of(
                points,
                SymmetryParams::default().sample,
                SymmetryParams::default().min_lever,
                &SymmetryParams::default(),
            )
            .unwrap();
            let seen = Seen::of(points, &bounds, &SymmetryParams::default());
            let found = Some(sample.plane(-0.02, fit));
            to_the_tyres(
                points,
                &bounds,
                &seen,
                &sample,
                found,
                &SymmetryParams::default(),
            )
            .unwrap()
        };
        let treads = side_view(true);
        let moved = plane(&treads, PlaneFit::Pairs);
        assert_eq!(
            (moved.fit, moved.offset.abs() < 1e-9),
            (PlaneFit::Tyres, true)
        );
        assert_eq!(plane(&treads, PlaneFit::Refined).offset, -0.02);
        let walls: Vec<[f64; 3]> = treads
            .into_iter()
            .filter(|p| p[1] > 0.02 || p[0] < 0.0 || p[0] > 0.19)
            .collect();
        assert_eq!(plane(&walls, PlaneFit::Pairs).offset, -0.02);
    }

    /// [`with_width`] with the box and the sample [`find_plane`] gives it.
    fn widen(points: &[[f64; 3]], width: f64, plane: Option<Plane>) -> Option<Plane> {
        bound(points, Width::Known(width), plane)
    }

    /// `plane` bounded by `width` as [`find_plane`] bounds the plane it found.
    fn bound(points: &[[f64; 3]], width: Width, plane: Option<Plane>) -> Option<Plane> {
        let bounds = Aabb::of(points).unwrap();
        let across = bounds.max[0] - bounds.min[0];
        let sample = Sample::of(
            points,
            SymmetryParams::default().sample,
            SymmetryParams::default()
                .min_lever
                .min(SymmetryParams::default().lever_of_width * across),
            &SymmetryParams::default(),
        )
        .unwrap();
        let seen = Seen::of(points, &bounds, &SymmetryParams::default());
        let tune = SymmetryParams::default();
        match width {
            Width::Known(w) => with_width(points, &seen, &sample, w, plane, &tune),
            Width::AtLeast(w) => at_least(points, &seen, &sample, w, plane, &tune),
        }
    }

    /// A near flank at x = 0.2 and a roof seen only to x = -0.05 (a tall vehicle driven past):
    /// a vehicle 0.4 wide has its plane at x = 0.
    fn tall_flank() -> Vec<[f64; 3]> {
        let mut section: Vec<[f64; 2]> = (0..100).map(|i| [0.2, i as f64 * 0.002]).collect();
        section.extend((0..=25).map(|i| [-0.05 + i as f64 * 0.01, 0.3]));
        extruded(&section)
    }

    /// A plane held back at `offset`, as [`find_plane`] may have found it before a width.
    fn held_at(offset: f64) -> Plane {
        Plane {
            offset,
            support: 0.3,
            tolerance: 0.01,
            fit: PlaneFit::HeldBack,
            cues: Cues::default(),
            vouched: true,
            both_sides: false,
        }
    }

    #[test]
    fn a_narrowest_width_moves_every_plane_nearer_the_scanned_flank_and_places_none() {
        let points = tall_flank();
        let least = Width::AtLeast(0.4);
        // 0.14 from the flank, 0.7 of the half-width: a known width leaves it (its widest part
        // may be unseen), the narrowest every such vehicle reaches does not.
        assert_eq!(
            widen(&points, 0.4, Some(held_at(0.06))),
            Some(held_at(0.06))
        );
        let moved = bound(&points, least, Some(held_at(0.06))).unwrap();
        assert!(moved.offset.abs() < 1e-12, "{moved:?}");
        assert_eq!(moved.fit, PlaneFit::Width);
        assert_eq!(
            bound(&points, least, Some(held_at(-0.01))),
            Some(held_at(-0.01))
        );
        assert_eq!(bound(&points, least, None), None);
        let flipped: Vec<[f64; 3]> = points.iter().map(|&p| mirror(p, 0.0)).collect();
        let moved = bound(&flipped, least, Some(held_at(-0.06))).unwrap();
        assert!(moved.offset.abs() < 1e-12, "{moved:?}");
    }

    #[test]
    fn a_known_width_keeps_the_plane_half_of_it_from_the_scanned_flank() {
        // A point alone in its slice beyond the flank (a stray return) does not move the flank.
        let mut points = tall_flank();
        points.push([0.23, 0.25, 0.2]);
        let widened = widen(&points, 0.4, Some(held_at(0.03))).unwrap();
        assert!(widened.offset.abs() < 1e-12, "{widened:?}");
        assert_eq!(widened.fit, PlaneFit::Width);
        assert!(
            widened.support > 0.0 && widened.tolerance > 0.0,
            "{widened:?}"
        );
        assert_eq!(
            widen(&points, 0.4, Some(held_at(0.06))),
            Some(held_at(0.06)),
            "the flank 0.7 of the half-width from the plane: its widest part not seen, kept"
        );
        assert_eq!(
            widen(&points, 0.4, Some(held_at(-0.01))),
            Some(held_at(-0.01)),
            "farther from the flank than half the width: kept"
        );
        let placed = widen(&points, 0.4, None).unwrap();
        assert!(placed.offset.abs() < 1e-12 && placed.fit == PlaneFit::Width);

        // Scanned from the other side.
        let flipped: Vec<[f64; 3]> = points.iter().map(|&p| mirror(p, 0.0)).collect();
        let widened = widen(&flipped, 0.4, Some(held_at(-0.03))).unwrap();
        assert!(widened.offset.abs() < 1e-12, "{widened:?}");

        // Seen from both sides, the points say where the plane is.
        let both: Vec<[f64; 3]> = points.iter().chain(&flipped).copied().collect();
        assert_eq!(widen(&both, 0.6, Some(held_at(0.01))), Some(held_at(0.01)));
        assert_eq!(widen(&both, 0.6, None), None);
    }

    #[test]
    fn a_part_on_the_far_side_only_does_not_bound_the_plane() {
        // The roof's slice says the plane is near x = 0. Low down, the near side is 0.2 out along
        // the front half and 0.1 along the back half, where the far side has a part of its own
        // 0.3 out (an exhaust): its slice's middle, -0.05, would bound the plane, but its far
        // extreme's mirror image lands where the near side is not.
        let mut points: Vec<[f64; 3]> = Vec::new();
        for k in 0..50 {
            let z = k as f64 * 0.01;
            let near = if z < 0.25 { 0.2 } else { 0.1 };
            points.extend((0..100).map(|i| [near, i as f64 * 0.002, z]));
            points.extend((0..=60).map(|i| [-0.15 + i as f64 * 0.005, 0.3, z]));
            if z >= 0.4 {
                points.extend((0..5).map(|i| [-0.3, 0.1 + i as f64 * 0.001, z]));
            }
        }
        let bounds = Aabb::of(&points).unwrap();
        let roof = -0.005 * SymmetryParams::default().far_edge / 2.0;
        let slices = horizontal_slices(&points, &bounds, &SymmetryParams::default());
        assert!(
            (slices_middle(&points, &bounds, &slices, 1.0, &SymmetryParams::default()).unwrap()
                - roof)
                .abs()
                < 1e-9
        );
    }

    #[test]
    fn a_plane_that_would_make_the_vehicle_too_wide_goes_to_the_middle_unvouched() {
        // One unit long: a near flank at x = 0.2 up to the shoulder and a roof seen edge to
        // edge at y = 0.3 from -0.15 to 0.15 (the scan's extent says the plane is at 0).
        let mut section: Vec<[f64; 2]> = (0..100).map(|i| [0.2, i as f64 * 0.002]).collect();
        section.extend((0..=30).map(|i| [-0.15 + i as f64 * 0.01, 0.3]));
        let points: Vec<[f64; 3]> = (0..=100)
            .flat_map(|k| section.iter().map(move |&[x, y]| [x, y, k as f64 * 0.01]))
            .collect();
        let bounds = Aabb::of(&points).unwrap();
        let sample = Sample::of(
            &points,
            SymmetryParams::default().sample,
            SymmetryParams::default().min_lever,
            &SymmetryParams::default(),
        )
        .unwrap();
        let slices = horizontal_slices(&points, &bounds, &SymmetryParams::default());
        let extent = slices_middle(&points, &bounds, &slices, 1.0, &SymmetryParams::default());
        let check = |offset: f64| {
            let found = Some(sample.plane(offset, PlaneFit::Refined));
            in_proportion(
                &points,
                &bounds,
                &slices,
                &sample,
                extent,
                found,
                &SymmetryParams::default(),
            )
            .unwrap()
        };
        // 0.4 wide for its length of 1: a car's proportions, kept.
        let kept = check(0.0);
        assert_eq!(
            (kept.offset, kept.fit, kept.vouched),
            (0.0, PlaneFit::Refined, true)
        );
        // At -0.1 the near flank's mirror image would make it 0.6 wide.
        let moved = check(-0.1);
        assert_eq!((moved.fit, moved.vouched), (PlaneFit::Proportions, false));
        assert!(moved.offset.abs() < 0.01, "moved to {}", moved.offset);
        // Near the scanned flank the far roof edge's image makes it 0.6 wide the other way.
        assert_eq!(check(0.15).fit, PlaneFit::Proportions);
    }

    #[test]
    fn a_cloud_seen_from_both_sides_is_held_back_at_its_whole_width() {
        // Both flanks seen, one at a shorter range (more points); a slice where the far flank
        // sticks out (a mirror, say) must not bound the plane.
        let mut section: Vec<[f64; 2]> = (0..60).map(|i| [0.2, i as f64 * 0.005]).collect();
        section.extend((0..40).map(|i| [-0.2, i as f64 * 0.0075]));
        section.extend([[-0.3, 0.32], [0.1, 0.32]]);
        let points = extruded(&section);
        let bounds = Aabb::of(&points).unwrap();
        let whole = bounds.center()[0];
        let slices = horizontal_slices(&points, &bounds, &SymmetryParams::default());
        assert!(
            slices_middle(&points, &bounds, &slices, 1.0, &SymmetryParams::default()).unwrap()
                < whole - 0.04
        );
        assert_eq!(
            held_back(
                &points,
                &bounds,
                &Seen::of(&points, &bounds, &SymmetryParams::default()),
                0.02,
                &SymmetryParams::default()
            ),
            whole
        );
    }

    #[test]
    fn the_pairs_place_a_plane_where_the_support_says_little() {
        // Drive-bys of trains and trucks whose flank and roof strip support no plane (under 5 %
        // of mirror images land on points): before the pairs, nothing was mirrored. The pairs
        // place it, held back by the widest-seen slice where they pull beyond it.
        for (category, seed, side) in [
            (Category::Train, 1, -1.0),
            (Category::Train, 2, -1.0),
            (Category::Train, 6, -1.0),
            (Category::Truck, 2, 1.0),
            (Category::Truck, 5, 1.0),
            (Category::Truck, 6, 1.0),
        ] {
            let plane = drive_by_plane(category, seed, side).expect("the pairs find one");
            assert!(
                matches!(plane.fit, PlaneFit::Pairs | PlaneFit::HeldBack),
                "{category:?} {seed}: {:?}",
                plane.fit
            );
            assert!(
                plane.offset.abs() < 0.01,
                "{category:?} {seed}: plane at {}",
                plane.offset
            );
        }
    }

    #[test]
    fn finds_the_plane_of_a_one_sided_car_scan() {
        // Seen from +x and above: one side and the roof; the car's plane is x = 0 before the
        // shift. The example car is 4.4 m long: divided by that, it is in normalized units.
        let side = scanned_side(&example_car());
        for shift in [0.0, 0.07, -0.12] {
            let points: Vec<[f64; 3]> = side
                .positions
                .iter()
                .map(|p| [p[0] / 4.4 + shift, p[1] / 4.4, p[2] / 4.4])
                .collect();
            let plane = find_plane(&points, None, &SymmetryParams::default())
                .expect("a car scan is symmetric");
            assert!(
                (plane.offset - shift).abs() < 0.01,
                "plane at {} for a car centred at {shift}",
                plane.offset
            );
            assert!(plane.support > 0.1, "support {}", plane.support);
        }
    }

    #[test]
    fn a_flat_wall_has_no_plane() {
        let wall: Vec<[f64; 3]> = (0..2000)
            .map(|i| [0.2, (i / 50) as f64 * 0.01, (i % 50) as f64 * 0.01])
            .collect();
        assert_eq!(find_plane(&wall, None, &SymmetryParams::default()), None);
    }

    #[test]
    fn refinement_turns_a_heading_onto_the_plane_of_symmetry() {
        for (truth, error) in [(30.0, 5.0), (200.0, -6.5), (90.0, 2.0), (300.0, 0.0)] {
            let block = car_block(truth, [3.0, -1.0, 7.0]);
            let refined = refine_heading(&block, truth + error, &SymmetryParams::default())
                .expect("a car block is symmetric");
            assert!(
                angle_between(refined, truth) < 0.3,
                "{refined} for a block at {truth} estimated at {}",
                truth + error
            );
        }
    }

    #[test]
    fn refinement_needs_symmetry() {
        let wall: Vec<[f64; 3]> = (0..2000)
            .map(|i| [0.2, (i / 50) as f64 * 0.01, (i % 50) as f64 * 0.01])
            .collect();
        assert_eq!(
            refine_heading(&wall, 90.0, &SymmetryParams::default()),
            None
        );
        assert_eq!(
            refine_heading(&[[1.0, 2.0, 3.0]; 10], 90.0, &SymmetryParams::default()),
            None
        );
    }

    #[test]
    fn the_grid_finds_what_a_search_of_every_point_finds() {
        let mut rng = crate::core::rng::Lcg::new(7);
        let mut next = || rng.range(-0.5, 0.5);
        let points: Vec<[f64; 3]> = (0..3000).map(|_| [next(), 0.3 * next(), next()]).collect();
        let distance = 0.03;
        let grid = MatchGrid::new(&points, distance);
        for _ in 0..3000 {
            // Queries reach past the points' box, and a few far beyond it.
            let scale = if next() > 0.45 { 100.0 } else { 1.2 };
            let q = [scale * next(), scale * next(), scale * next()];
            let brute = points
                .iter()
                .map(|p| (0..3).map(|k| (p[k] - q[k]).powi(2)).sum::<f64>())
                .filter(|&d2| d2 < distance * distance)
                .fold(None, |best: Option<f64>, d2| {
                    Some(best.map_or(d2, |b| b.min(d2)))
                });
            assert_eq!(grid.nearest_within(q), brute, "query {q:?}");
        }
    }

    #[test]
    fn mirroring_twice_is_the_identity() {
        let p = [0.3, -0.1, 0.25];
        assert_eq!(mirror(mirror(p, 0.05), 0.05), p);
        assert!((mirror(p, 0.05)[0] - -0.2).abs() < 1e-12);
    }
}
