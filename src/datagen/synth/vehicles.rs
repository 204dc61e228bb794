//! The street objects themselves, in metres: ground at y = 0, +y up, length along z with the
//! front towards −z, the right side at +x.

use super::builder::{Builder, V3};
use crate::core::rng::Lcg;

/// Car paint by approximate share of the European fleet: white, black, grey, silver, blue,
/// red, brown/beige, green, yellow/orange.
const PAINT: [([u8; 3], f64); 9] = [
    ([236, 236, 232], 0.25),
    ([22, 22, 24], 0.20),
    ([96, 98, 102], 0.18),
    ([170, 172, 176], 0.12),
    ([28, 52, 112], 0.09),
    ([150, 18, 22], 0.08),
    ([120, 96, 70], 0.03),
    ([34, 78, 50], 0.02),
    ([228, 160, 20], 0.03),
];

fn paint(rng: &mut Lcg) -> [u8; 3] {
    let mut x = rng.next_f64() * PAINT.iter().map(|p| p.1).sum::<f64>();
    let mut base = PAINT[0].0;
    for (rgb, share) in PAINT {
        base = rgb;
        if x < share {
            break;
        }
        x -= share;
    }
    jitter(rng, base, 10.0)
}

fn jitter(rng: &mut Lcg, rgb: [u8; 3], amount: f64) -> [u8; 3] {
    let d = rng.range(-amount, amount);
    rgb.map(|c| (c as f64 + d + rng.range(-amount / 3.0, amount / 3.0)).clamp(0.0, 255.0) as u8)
}

/// One of `palette`, jittered.
fn pick_color(rng: &mut Lcg, palette: &[[u8; 3]], amount: f64) -> [u8; 3] {
    let base = *rng.pick(palette);
    jitter(rng, base, amount)
}

fn lerp(a: f32, b: f32, t: f32) -> f32 {
    a + (b - a) * t
}

/// Piecewise-linear interpolation through `(z, value)` knots sorted by z.
fn piecewise(knots: &[(f32, f32)], z: f32) -> f32 {
    if z <= knots[0].0 {
        return knots[0].1;
    }
    for w in knots.windows(2) {
        if z <= w[1].0 {
            let t = (z - w[0].0) / (w[1].0 - w[0].0).max(1e-6);
            return lerp(w[0].1, w[1].1, t);
        }
    }
    knots[knots.len() - 1].1
}

/// Ring segments of a [`body`] section, right side first (see `section`).
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum Band {
    Underside,
    LowerCorner,
    Flank,
    Shoulder,
    LowerGlass,
    UpperGlass,
    RoofEdge,
    Roof,
}

const BANDS: [Band; 8] = [
    Band::Underside,
    Band::LowerCorner,
    Band::Flank,
    Band::Shoulder,
    Band::LowerGlass,
    Band::UpperGlass,
    Band::RoofEdge,
    Band::Roof,
];

/// Band and side (+1 right, −1 left) of ring segment `s` of a 16-point section.
fn band(s: usize) -> (Band, f32) {
    if s < 8 {
        (BANDS[s], 1.0)
    } else {
        (BANDS[15 - s], -1.0)
    }
}

/// The shape of a body along its length.
pub struct Profile {
    pub z0: f32,
    pub z1: f32,
    pub width: f32,
    /// Roof line `(z, height)`.
    pub top: Vec<(f32, f32)>,
    /// Height of the window sill.
    pub belt: f32,
    pub clearance: f32,
    /// Wheel arches `(z, radius, centre height)`.
    pub arches: Vec<(f32, f32, f32)>,
    /// Width of the roof relative to the body (tumblehome).
    pub roof_width: f32,
    /// Length over which the ends round off in plan view.
    pub end_rounding: f32,
}

impl Profile {
    fn bottom(&self, z: f32) -> f32 {
        let mut b = self.clearance;
        for &(wz, r, cy) in &self.arches {
            let dz = z - wz;
            if dz.abs() < r {
                b = b.max(cy + (r * r - dz * dz).sqrt());
            }
        }
        b
    }

    fn half_width(&self, z: f32) -> f32 {
        let w = self.width / 2.0;
        let d = (self.end_rounding - (z - self.z0).min(self.z1 - z)).max(0.0);
        if self.end_rounding <= 0.0 || d <= 0.0 {
            return w;
        }
        let t = (d / self.end_rounding).min(1.0);
        w * (0.86 + 0.14 * (1.0 - t * t).sqrt())
    }

    /// The 16-point cross-section at `z`: bottom centre, up the right side (+x) to the roof
    /// centre, down the left side.
    fn section(&self, z: f32) -> Vec<V3> {
        let top = piecewise(&self.top, z);
        let w = self.half_width(z);
        let b = self.bottom(z).min(top - 0.05);
        let belt = self.belt.min(top).max(b + 0.02);
        let g = (top - belt).max(0.0);
        let gw = w * self.roof_width;
        let side_low = (b + 0.12).min(belt);
        let side_high = (belt - 0.06).max(side_low);
        let right: [[f32; 2]; 9] = [
            [0.0, b],
            [w - 0.06, b],
            [w, side_low],
            [w, side_high],
            [w - 0.02, belt],
            [lerp(w - 0.02, gw, 0.55), belt + 0.55 * g],
            [gw, belt + 0.92 * g],
            [gw * 0.55, top],
            [0.0, top],
        ];
        let mut ring: Vec<V3> = right.iter().map(|p| [p[0], p[1], z]).collect();
        ring.extend(right[1..8].iter().rev().map(|p| [-p[0], p[1], z]));
        ring
    }

    /// Section positions: evenly spaced plus every roof-line knot and arch edge, so slopes
    /// and arches keep their shape.
    fn stations(&self, steps: usize) -> Vec<f32> {
        let mut z: Vec<f32> = (0..=steps)
            .map(|i| lerp(self.z0, self.z1, i as f32 / steps as f32))
            .collect();
        z.extend(self.top.iter().map(|k| k.0));
        for &(wz, r, _) in &self.arches {
            for k in 0..=8 {
                z.push(wz - r + 2.0 * r * k as f32 / 8.0);
            }
        }
        z.retain(|&v| v >= self.z0 && v <= self.z1);
        z.sort_by(f32::total_cmp);
        z.dedup_by(|a, b| (*a - *b).abs() < 1e-3);
        z
    }
}

/// Lofts a body; `material(z, band, side)` colours each strip.
pub fn body(
    b: &mut Builder,
    profile: &Profile,
    caps: u32,
    material: impl Fn(f32, Band, f32) -> u32,
) {
    let z = profile.stations(64);
    let rings: Vec<Vec<V3>> = z.iter().map(|&z| profile.section(z)).collect();
    b.loft(
        &rings,
        |r, s| {
            let (band, side) = band(s);
            material((z[r] + z[r + 1]) / 2.0, band, side)
        },
        caps,
    );
}

/// A wheel with tyre and rim, axis along x.
fn wheel(b: &mut Builder, c: V3, radius: f32, width: f32, rim: u32) {
    let tyre = b.material("tyre", [26, 26, 28]);
    b.cylinder(c, 0, radius, width / 2.0, 20, [tyre, tyre]);
    b.cylinder(c, 0, radius * 0.62, width / 2.0 + 0.004, 16, [tyre, rim]);
}

fn glass(b: &mut Builder, rng: &mut Lcg) -> u32 {
    let tint = jitter(rng, [38, 46, 56], 14.0);
    b.material("glass", tint)
}

fn rim(b: &mut Builder, rng: &mut Lcg) -> u32 {
    if rng.chance(0.7) {
        b.material("rim", [176, 178, 182])
    } else {
        b.material("rim", [52, 52, 56])
    }
}

/// A vertical plate on the front (`end` = −1) or back (+1) face at `z`.
fn end_panel(b: &mut Builder, z: f32, end: f32, x: (f32, f32), y: (f32, f32), material: u32) {
    let (z_in, z_out) = (z - end * 0.02, z + end * 0.03);
    b.cuboid(
        [x.0, y.0, z_in.min(z_out)],
        [x.1, y.1, z_in.max(z_out)],
        material,
    );
}

/// Body styles of [`car`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CarStyle {
    Sedan,
    Hatchback,
    Estate,
    Suv,
    Van,
    Pickup,
}

const CAR_STYLES: [CarStyle; 6] = [
    CarStyle::Sedan,
    CarStyle::Hatchback,
    CarStyle::Estate,
    CarStyle::Suv,
    CarStyle::Van,
    CarStyle::Pickup,
];

pub fn car(rng: &mut Lcg) -> (Builder, String) {
    let style = *rng.pick(&CAR_STYLES);
    let mut b = Builder::default();
    let r = |rng: &mut Lcg, lo: f64, hi: f64| rng.range(lo, hi) as f32;
    let (ranges, clearance, hood) = car_shape(style);
    let [length, width, height, wheel_r] = ranges.map(|(lo, hi)| rng.range(lo, hi) as f32);
    let (z0, z1) = (-length / 2.0, length / 2.0);
    let hood_h = (height * 0.66).max(0.85);
    let belt = hood_h + 0.04;
    let zw = z0 + hood * length;
    let zr1 = zw + (height - hood_h) * if style == CarStyle::Van { 0.9 } else { 1.6 };
    let (top, zr2, zt) = car_roofline(style, (z0, z1), zw, zr1, (hood_h, belt, height));
    let front_axle = z0 + r(rng, 0.78, 0.95);
    let rear_axle = z1 - r(rng, 0.8, 1.05);
    let arch = wheel_r + 0.05;
    let profile = Profile {
        z0,
        z1,
        width,
        top,
        belt,
        clearance,
        arches: vec![(front_axle, arch, wheel_r), (rear_axle, arch, wheel_r)],
        roof_width: r(rng, 0.74, 0.84),
        end_rounding: 0.3,
    };
    let body_paint = paint(rng);
    let paint_m = b.material("paint", body_paint);
    let glass_m = glass(&mut b, rng);
    let under = b.material("underbody", [34, 34, 36]);
    let trim = b.material("trim", [40, 40, 42]);
    let bed = b.material("bed", [48, 46, 44]);
    let pillar_z = (zr1 + zr2) / 2.0 + 0.05;
    body(&mut b, &profile, paint_m, |z, band, _| match band {
        Band::Underside => under,
        Band::LowerCorner if style == CarStyle::Suv => trim,
        Band::LowerGlass | Band::UpperGlass
            if z > zw + 0.15 && z < zt - 0.05 && (z - pillar_z).abs() > 0.06 && z < zr2 + 0.35 =>
        {
            glass_m
        }
        Band::RoofEdge | Band::Roof | Band::UpperGlass
            if (z > zw + 0.04 && z < zr1 - 0.04)
                || (z > zr2 + 0.04 && z < zt - 0.02 && style != CarStyle::Pickup) =>
        {
            glass_m
        }
        Band::Roof | Band::RoofEdge if style == CarStyle::Pickup && z > zt => bed,
        _ => paint_m,
    });
    let rim_m = rim(&mut b, rng);
    let track = width / 2.0 - 0.13;
    for z in [front_axle, rear_axle] {
        for side in [-1.0, 1.0] {
            wheel(&mut b, [side * track, wheel_r, z], wheel_r, 0.22, rim_m);
        }
    }
    let bumper = if rng.chance(0.5) { paint_m } else { trim };
    let ends = CarEnds {
        z: (z0, z1),
        width,
        hood_h,
        belt,
        zw,
        clearance,
        paint: paint_m,
        bumper,
    };
    car_ends(&mut b, &profile, &ends);
    (b, format!("{style:?}").to_lowercase())
}

/// Ranges of a car style's length, width, height and wheel radius (m); its ground clearance;
/// its hood's length as a share of the car's.
fn car_shape(style: CarStyle) -> ([(f64, f64); 4], f32, f32) {
    match style {
        CarStyle::Sedan => (
            [(4.3, 5.0), (1.72, 1.88), (1.38, 1.5), (0.30, 0.34)],
            0.14,
            0.27,
        ),
        CarStyle::Hatchback => (
            [(3.6, 4.3), (1.62, 1.8), (1.42, 1.55), (0.28, 0.32)],
            0.14,
            0.22,
        ),
        CarStyle::Estate => (
            [(4.5, 5.0), (1.75, 1.88), (1.45, 1.55), (0.31, 0.34)],
            0.15,
            0.25,
        ),
        CarStyle::Suv => (
            [(4.3, 5.0), (1.8, 1.98), (1.62, 1.85), (0.34, 0.39)],
            0.21,
            0.25,
        ),
        CarStyle::Van => (
            [(4.7, 5.6), (1.85, 2.0), (1.85, 2.3), (0.32, 0.36)],
            0.17,
            0.13,
        ),
        CarStyle::Pickup => (
            [(5.0, 5.6), (1.85, 2.0), (1.7, 1.9), (0.36, 0.40)],
            0.22,
            0.28,
        ),
    }
}

/// The car's side profile from the front bumper over the roof to the tail, and where the roof
/// ends (`zr2`) and the rear glass meets the body (`zt`).
fn car_roofline(
    style: CarStyle,
    (z0, z1): (f32, f32),
    zw: f32,
    zr1: f32,
    (hood_h, belt, height): (f32, f32, f32),
) -> (Vec<(f32, f32)>, f32, f32) {
    let length = z1 - z0;
    let mut top = vec![
        (z0, hood_h - 0.14),
        (z0 + 0.3, hood_h - 0.02),
        (zw, hood_h),
        (zr1, height),
    ];
    let (zr2, zt) = match style {
        CarStyle::Sedan => {
            let zr2 = zr1 + 0.3 * length;
            let zt = zr2 + 0.55;
            top.extend([
                (zr2, height),
                (zt, belt + 0.08),
                (z1 - 0.12, belt + 0.06),
                (z1, belt - 0.06),
            ]);
            (zr2, zt)
        }
        CarStyle::Hatchback => {
            let zr2 = z1 - 0.45;
            top.extend([
                (zr2, height),
                (z1 - 0.08, height - 0.4),
                (z1, height - 0.46),
            ]);
            (zr2, z1 - 0.08)
        }
        CarStyle::Estate | CarStyle::Suv | CarStyle::Van => {
            let zr2 = z1 - 0.22;
            top.extend([
                (zr2, height),
                (z1 - 0.04, height - 0.22),
                (z1, height - 0.3),
            ]);
            (zr2, z1 - 0.04)
        }
        CarStyle::Pickup => {
            let zr2 = zr1 + 1.25;
            top.extend([(zr2, height), (zr2 + 0.08, belt + 0.05), (z1, belt + 0.05)]);
            (zr2, zr2 + 0.08)
        }
    };
    (top, zr2, zt)
}

/// Where a car's lights, plates, bumpers and mirrors go, and in which materials.
struct CarEnds {
    z: (f32, f32),
    width: f32,
    hood_h: f32,
    belt: f32,
    zw: f32,
    clearance: f32,
    paint: u32,
    bumper: u32,
}

/// Head and tail lights, door mirrors, bumpers and number plates.
fn car_ends(b: &mut Builder, profile: &Profile, e: &CarEnds) {
    let (z0, z1) = e.z;
    let (width, hood_h, belt, zw, clearance, paint_m, bumper) = (
        e.width,
        e.hood_h,
        e.belt,
        e.zw,
        e.clearance,
        e.paint,
        e.bumper,
    );
    let end_w = width / 2.0 * 0.86;
    let head = b.material("headlight", [236, 236, 222]);
    let tail = b.material("taillight", [186, 22, 24]);
    let plate = b.material("plate", [234, 234, 232]);
    for side in [-1.0f32, 1.0] {
        let x = (side * end_w * 0.55, side * end_w * 0.92);
        let x = (x.0.min(x.1), x.0.max(x.1));
        end_panel(b, z0, -1.0, x, (hood_h - 0.3, hood_h - 0.17), head);
        let tail_h = piecewise(&profile.top, z1) - 0.1;
        end_panel(b, z1, 1.0, x, (tail_h - 0.14, tail_h), tail);
        // Mirrors on the doors, below the windscreen's foot.
        let mx = (side * (width / 2.0 - 0.02), side * (width / 2.0 + 0.17));
        b.cuboid(
            [mx.0.min(mx.1), belt + 0.04, zw + 0.12],
            [mx.0.max(mx.1), belt + 0.17, zw + 0.24],
            paint_m,
        );
    }
    for (z, end) in [(z0, -1.0), (z1, 1.0)] {
        end_panel(
            b,
            z - end * 0.02,
            end,
            (-end_w, end_w),
            (clearance + 0.12, clearance + 0.36),
            bumper,
        );
        end_panel(
            b,
            z + end * 0.02,
            end,
            (-0.26, 0.26),
            (clearance + 0.2, clearance + 0.31),
            plate,
        );
    }
}

/// Window rows with pillars every `pitch` metres, and doors (full-height dark panels) at
/// `doors` (positions along the body from its front end).
struct Openings {
    pitch: f32,
    doors: Vec<(f32, f32)>,
    /// Doors on both sides (trains) or on the right only (buses).
    both_sides: bool,
    glass: u32,
    door: u32,
    other: u32,
}

impl Openings {
    fn material(&self, z: f32, band: Band, side: f32) -> u32 {
        let in_door = self.doors.iter().any(|&(a, b)| z > a && z < b);
        let door_band = matches!(
            band,
            Band::Flank | Band::Shoulder | Band::LowerGlass | Band::UpperGlass
        );
        if in_door && door_band && (side > 0.0 || self.both_sides) {
            return self.door;
        }
        let pillar = (z / self.pitch).rem_euclid(1.0) < 0.1;
        if matches!(band, Band::LowerGlass | Band::UpperGlass) && !pillar {
            self.glass
        } else {
            self.other
        }
    }
}

const BUS_WIDTH: f32 = 2.55;
const BUS_WHEEL_RADIUS: f32 = 0.5;

/// The materials of a bus.
struct BusMaterials {
    paint: u32,
    glass: u32,
    door: u32,
    under: u32,
    rim: u32,
}

/// Up to three doors of a bus section from `z0`, `len` long, evenly spread and left out
/// where they would meet a wheel at `axles`; as (start, end) from the section's start.
fn bus_doors(z0: f32, len: f32, axles: &[f32]) -> Vec<(f32, f32)> {
    (0..3)
        .map(|d| {
            let c = z0 + 0.9 + d as f32 * (len - 1.8) / 2.0;
            (c - 0.6, c + 0.6)
        })
        .filter(|&(a, bb)| {
            axles
                .iter()
                .all(|&w| (w - a).abs() > 0.7 && (w - bb).abs() > 0.7)
        })
        .map(|(a, bb)| (a - z0, bb - z0))
        .collect()
}

/// A bus's front from `z0`, `height` high: the windscreen, the destination sign above it and
/// the roof unit behind.
fn bus_front(b: &mut Builder, z0: f32, height: f32, glass: u32) {
    end_panel(b, z0, -1.0, (-1.1, 1.1), (1.0, height - 0.35), glass);
    let sign = b.material("sign", [250, 170, 30]);
    end_panel(
        b,
        z0 - 0.01,
        -1.0,
        (-0.9, 0.9),
        (height - 0.3, height - 0.12),
        sign,
    );
    let roof_box = b.material("roof_unit", [200, 200, 198]);
    b.cuboid(
        [-0.8, height, z0 + 2.0],
        [0.8, height + 0.28, z0 + 4.2],
        roof_box,
    );
}

/// One section of a bus from `z0` to `z1`: body with windows and doors, wheels, and on the
/// `first` section the windscreen, destination sign and roof unit.
fn bus_section(
    b: &mut Builder,
    (z0, z1): (f32, f32),
    (first, articulated): (bool, bool),
    height: f32,
    m: &BusMaterials,
) {
    let (width, wheel_r, len) = (BUS_WIDTH, BUS_WHEEL_RADIUS, z1 - z0);
    let (paint_m, glass_m, door_m, under, rim_m) = (m.paint, m.glass, m.door, m.under, m.rim);
    let top = vec![
        (z0, height - if first { 0.15 } else { 0.05 }),
        (z0 + 0.3, height),
        (z1 - 0.3, height),
        (z1, height - 0.08),
    ];
    let mut axles = vec![];
    if first {
        axles.push(z0 + 2.7);
    }
    axles.push(z1 - if first && articulated { 1.2 } else { 3.2 });
    let profile = Profile {
        z0,
        z1,
        width,
        top,
        belt: 1.1,
        clearance: 0.3,
        arches: axles
            .iter()
            .map(|&z| (z, wheel_r + 0.06, wheel_r))
            .collect(),
        roof_width: 0.97,
        end_rounding: 0.25,
    };
    let openings = Openings {
        pitch: 1.3,
        doors: bus_doors(z0, len, &axles),
        both_sides: false,
        glass: glass_m,
        door: door_m,
        other: paint_m,
    };
    body(b, &profile, paint_m, |z, band, side| match band {
        Band::Underside => under,
        _ => openings.material(z - z0, band, side),
    });
    for &z in &axles {
        for side in [-1.0, 1.0] {
            wheel(
                b,
                [side * (width / 2.0 - 0.2), wheel_r, z],
                wheel_r,
                0.3,
                rim_m,
            );
        }
    }
    if first {
        bus_front(b, z0, height, glass_m);
    }
    let lights = b.material("headlight", [236, 236, 222]);
    for side in [-1.0f32, 1.0] {
        let x = (side * 0.85, side * 1.15);
        end_panel(
            b,
            z0,
            -1.0,
            (x.0.min(x.1), x.0.max(x.1)),
            (0.55, 0.75),
            lights,
        );
    }
}

pub fn bus(rng: &mut Lcg) -> (Builder, String) {
    let mut b = Builder::default();
    let articulated = rng.chance(0.3);
    let height = rng.range(2.95, 3.25) as f32;
    let lengths: Vec<f32> = if articulated {
        vec![rng.range(10.5, 11.5) as f32, rng.range(6.5, 7.5) as f32]
    } else {
        vec![rng.range(10.0, 13.5) as f32]
    };
    let gap = 0.7;
    let total: f32 = lengths.iter().sum::<f32>() + gap * (lengths.len() - 1) as f32;
    let livery = pick_color(
        rng,
        &[
            [230, 230, 226],
            [200, 30, 40],
            [30, 80, 160],
            [240, 190, 30],
            [40, 120, 70],
        ],
        12.0,
    );
    let paint_m = b.material("paint", livery);
    let glass_m = glass(&mut b, rng);
    let door_m = b.material("door", [60, 64, 70]);
    let under = b.material("underbody", [34, 34, 36]);
    let rim_m = rim(&mut b, rng);
    let mut z0 = -total / 2.0;
    for (i, &len) in lengths.iter().enumerate() {
        let z1 = z0 + len;
        let first = i == 0;
        let materials = BusMaterials {
            paint: paint_m,
            glass: glass_m,
            door: door_m,
            under,
            rim: rim_m,
        };
        bus_section(&mut b, (z0, z1), (first, articulated), height, &materials);
        z0 = z1 + gap;
        if i + 1 < lengths.len() {
            let bellows = b.material("bellows", [40, 40, 40]);
            b.cuboid(
                [-1.1, 0.45, z1 - 0.05],
                [1.1, height - 0.1, z1 + gap + 0.05],
                bellows,
            );
        }
    }
    (
        b,
        if articulated { "articulated" } else { "single" }.to_string(),
    )
}

pub fn truck(rng: &mut Lcg) -> (Builder, String) {
    let mut b = Builder::default();
    let width = 2.5;
    let cab_h = rng.range(2.9, 3.3) as f32;
    let cab_len = rng.range(2.0, 2.4) as f32;
    let cargo_len = rng.range(5.0, 8.0) as f32;
    let total = cab_len + 0.25 + cargo_len;
    let z0 = -total / 2.0;
    let cab_paint = paint(rng);
    let paint_m = b.material("paint", cab_paint);
    let glass_m = glass(&mut b, rng);
    let under = b.material("underbody", [34, 34, 36]);
    let rim_m = rim(&mut b, rng);
    let wheel_r = 0.52;
    let front_axle = z0 + 1.4;
    let profile = Profile {
        z0,
        z1: z0 + cab_len,
        width,
        top: vec![
            (z0, cab_h - 0.35),
            (z0 + 0.25, cab_h),
            (z0 + cab_len, cab_h),
        ],
        belt: 1.75,
        clearance: 0.45,
        arches: vec![(front_axle, wheel_r + 0.06, wheel_r)],
        roof_width: 0.95,
        end_rounding: 0.2,
    };
    body(&mut b, &profile, paint_m, |z, band, _| match band {
        Band::Underside => under,
        Band::LowerGlass | Band::UpperGlass if z < z0 + 1.0 && z > z0 + 0.2 => glass_m,
        _ => paint_m,
    });
    end_panel(&mut b, z0, -1.0, (-1.1, 1.1), (1.8, cab_h - 0.25), glass_m);
    let grille = b.material("grille", [50, 52, 56]);
    end_panel(&mut b, z0, -1.0, (-0.9, 0.9), (0.7, 1.5), grille);
    let cz0 = z0 + cab_len + 0.25;
    let cz1 = z0 + total;
    let chassis = b.material("chassis", [30, 30, 30]);
    b.cuboid([-0.5, 0.55, z0 + cab_len - 0.2], [0.5, 1.0, cz1], chassis);
    let kind = truck_cargo(&mut b, rng, (cz0, cz1, cargo_len), chassis);
    let axles = 1 + rng.below(2);
    for z in std::iter::once(front_axle).chain((0..axles).map(|i| cz1 - 1.0 - 1.35 * i as f32)) {
        for side in [-1.0, 1.0] {
            wheel(
                &mut b,
                [side * (width / 2.0 - 0.2), wheel_r, z],
                wheel_r,
                0.32,
                rim_m,
            );
        }
    }
    let lights = b.material("headlight", [236, 236, 222]);
    for side in [-1.0f32, 1.0] {
        let x = (side * 0.8, side * 1.15);
        end_panel(
            &mut b,
            z0,
            -1.0,
            (x.0.min(x.1), x.0.max(x.1)),
            (0.8, 1.0),
            lights,
        );
    }
    (b, kind.to_string())
}

/// A truck's load behind its cab, from `cz0` to `cz1` (`cargo_len` long, as drawn) over the
/// `chassis`: a box, a flatbed with one to three crates, or a tank; returns which.
fn truck_cargo(
    b: &mut Builder,
    rng: &mut Lcg,
    (cz0, cz1, cargo_len): (f32, f32, f32),
    chassis: u32,
) -> &'static str {
    let kind = *rng.pick(&["box", "flatbed", "tank"]);
    let cargo_paint = if rng.chance(0.6) {
        jitter(rng, [235, 235, 232], 8.0)
    } else {
        paint(rng)
    };
    let cargo = b.material("cargo", cargo_paint);
    match kind {
        "box" => b.cuboid(
            [-1.28, 1.0, cz0],
            [1.28, rng.range(3.5, 4.0) as f32, cz1],
            cargo,
        ),
        "flatbed" => {
            b.cuboid([-1.25, 1.0, cz0], [1.25, 1.2, cz1], cargo);
            let load = b.material("load", jitter(rng, [150, 120, 80], 20.0));
            let n = 1 + rng.below(3);
            for i in 0..n {
                let a = cz0 + 0.2 + i as f32 * (cargo_len - 0.4) / n as f32;
                let h = rng.range(0.5, 1.4) as f32;
                b.cuboid(
                    [-1.1, 1.2, a],
                    [1.1, 1.2 + h, a + (cargo_len - 0.4) / n as f32 - 0.2],
                    load,
                );
            }
        }
        _ => {
            let tank = b.material("tank", [196, 198, 202]);
            b.cylinder(
                [0.0, 2.1, (cz0 + cz1) / 2.0],
                2,
                1.1,
                cargo_len / 2.0,
                24,
                [tank, tank],
            );
            b.cuboid([-0.9, 1.0, cz0 + 0.2], [0.9, 1.15, cz1 - 0.2], chassis);
        }
    }
    kind
}

/// Two bogies of four wheels under a rail car starting at `z0`.
fn bogies(b: &mut Builder, (z0, car_len): (f32, f32), floor: f32, (bogie, rim_m): (u32, u32)) {
    for f in [0.17f32, 0.83] {
        let c = z0 + car_len * f;
        b.cuboid([-1.0, 0.25, c - 1.3], [1.0, floor - 0.02, c + 1.3], bogie);
        for dz in [-0.9, 0.9] {
            for side in [-1.0, 1.0] {
                wheel(b, [side * 0.72, 0.42, c + dz], 0.42, 0.14, rim_m);
            }
        }
    }
}

/// A pantograph on the roof at `height`, its base centred at `base_z`.
fn pantograph(b: &mut Builder, base_z: f32, height: f32) {
    let panto = b.material("pantograph", [60, 60, 64]);
    b.cuboid(
        [-0.6, height, base_z - 0.8],
        [0.6, height + 0.18, base_z + 0.8],
        panto,
    );
    let knee = [0.0, height + 0.95, base_z + 0.7];
    b.beam(
        [0.0, height + 0.18, base_z - 0.6],
        knee,
        0.04,
        0.5,
        [1.0, 0.0, 0.0],
        panto,
    );
    let head = [0.0, height + 1.6, base_z - 0.2];
    b.beam(knee, head, 0.03, 0.45, [1.0, 0.0, 0.0], panto);
    b.cuboid(
        [-0.9, head[1], head[2] - 0.06],
        [0.9, head[1] + 0.06, head[2] + 0.06],
        panto,
    );
}

pub fn train(rng: &mut Lcg) -> (Builder, String) {
    let mut b = Builder::default();
    let tram = rng.chance(0.5);
    let cars = if tram { 1 } else { 1 + rng.below(2) };
    let width = if tram { 2.4 } else { 2.9 };
    let height = if tram {
        3.4
    } else {
        rng.range(3.8, 4.1) as f32
    };
    let car_len = if tram {
        rng.range(18.0, 26.0) as f32
    } else {
        rng.range(17.0, 22.0) as f32
    };
    let gap = 0.6;
    let total = cars as f32 * car_len + (cars - 1) as f32 * gap;
    let livery = pick_color(
        rng,
        &[
            [236, 236, 232],
            [200, 30, 40],
            [30, 70, 150],
            [245, 200, 30],
            [40, 120, 80],
            [120, 124, 130],
        ],
        10.0,
    );
    let paint_m = b.material("paint", livery);
    let stripe = b.material(
        "stripe",
        pick_color(
            rng,
            &[[30, 30, 30], [200, 30, 40], [30, 70, 150], [245, 200, 30]],
            10.0,
        ),
    );
    let glass_m = glass(&mut b, rng);
    let door_m = b.material("door", [70, 74, 80]);
    let under = b.material("underbody", [34, 34, 36]);
    let bogie = b.material("bogie", [44, 44, 46]);
    let rim_m = b.material("rim", [120, 120, 124]);
    let shape = RailCar {
        tram,
        width,
        height,
        length: car_len,
        floor: if tram { 0.35 } else { 0.95 },
    };
    let materials = RailMaterials {
        paint: paint_m,
        stripe,
        glass: glass_m,
        door: door_m,
        under,
        bogie,
        rim: rim_m,
    };
    let mut z0 = -total / 2.0;
    for i in 0..cars {
        let z1 = z0 + car_len;
        rail_car(&mut b, &shape, &materials, z0, (i == 0, i == cars - 1));
        if i == 0 {
            pantograph(&mut b, z0 + car_len * 0.35, height);
        }
        z0 = z1 + gap;
        if i + 1 < cars {
            b.cuboid(
                [-1.0, shape.floor + 0.1, z1 - 0.05],
                [1.0, height - 0.3, z1 + gap + 0.05],
                under,
            );
        }
    }
    (b, if tram { "tram" } else { "train" }.to_string())
}

/// The shape shared by a train's cars.
struct RailCar {
    tram: bool,
    width: f32,
    height: f32,
    length: f32,
    /// The floor's height, where the body starts above the bogies.
    floor: f32,
}

/// A train's materials.
struct RailMaterials {
    paint: u32,
    stripe: u32,
    glass: u32,
    door: u32,
    under: u32,
    bogie: u32,
    rim: u32,
}

/// One car of a train from `z0` on: its body (with a glazed nose at the front and at the back
/// where asked), doors and windows on both sides, and its bogies.
fn rail_car(
    b: &mut Builder,
    car: &RailCar,
    m: &RailMaterials,
    z0: f32,
    (nose_front, nose_back): (bool, bool),
) {
    let z1 = z0 + car.length;
    let (height, floor) = (car.height, car.floor);
    let nose = if car.tram { 1.0 } else { 2.2 };
    let mut top = vec![];
    if nose_front {
        top.extend([(z0, height * 0.55), (z0 + nose, height)]);
    } else {
        top.push((z0, height));
    }
    if nose_back {
        top.extend([(z1 - nose, height), (z1, height * 0.55)]);
    } else {
        top.push((z1, height));
    }
    let profile = Profile {
        z0,
        z1,
        width: car.width,
        top,
        belt: floor + 0.9,
        clearance: floor,
        arches: vec![],
        roof_width: 0.78,
        end_rounding: 0.4,
    };
    let openings = Openings {
        pitch: 2.0,
        doors: [0.22f32, 0.5, 0.78]
            .iter()
            .map(|f| (car.length * f - 0.65, car.length * f + 0.65))
            .collect(),
        both_sides: true,
        glass: m.glass,
        door: m.door,
        other: m.paint,
    };
    body(b, &profile, m.paint, |z, band, side| {
        let local = z - z0;
        if band == Band::Underside {
            return m.under;
        }
        let in_nose = (nose_front && local < nose) || (nose_back && z > z1 - nose);
        if in_nose && !matches!(band, Band::Flank | Band::LowerCorner) {
            return m.glass;
        }
        if band == Band::Shoulder {
            return m.stripe;
        }
        openings.material(local, band, side)
    });
    bogies(b, (z0, car.length), floor, (m.bogie, m.rim));
}

pub fn motorcycle(rng: &mut Lcg) -> (Builder, String) {
    let mut b = Builder::default();
    let r = 0.31;
    let wheelbase = rng.range(1.35, 1.55) as f32;
    let (zf, zr) = (-wheelbase / 2.0, wheelbase / 2.0);
    let paint_m = b.material("paint", paint(rng));
    let frame = b.material("frame", [40, 40, 44]);
    let chrome = b.material("chrome", [190, 192, 196]);
    let seat = b.material("seat", [24, 22, 22]);
    let engine = b.material("engine", [90, 92, 96]);
    let rim_m = rim(&mut b, rng);
    for z in [zf, zr] {
        wheel(&mut b, [0.0, r, z], r, 0.13, rim_m);
        b.cuboid(
            [-0.09, r + 0.22, z - 0.3],
            [0.09, r + 0.28, z + 0.25],
            paint_m,
        );
    }
    let head = [0.0, 1.0, zf + 0.22];
    b.beam([0.0, r, zf], head, 0.05, 0.12, [1.0, 0.0, 0.0], chrome);
    b.beam(
        head,
        [0.0, 0.55, zr - 0.1],
        0.05,
        0.06,
        [1.0, 0.0, 0.0],
        frame,
    );
    b.beam(
        [0.0, r, zr],
        [0.0, 0.8, zr - 0.35],
        0.04,
        0.1,
        [1.0, 0.0, 0.0],
        frame,
    );
    b.cuboid([-0.16, 0.3, -0.25], [0.16, 0.68, 0.22], engine);
    b.cuboid([-0.17, 0.78, zf + 0.3], [0.17, 1.0, 0.05], paint_m);
    b.cuboid([-0.15, 0.8, 0.05], [0.15, 0.9, zr - 0.15], seat);
    b.cuboid(
        [-0.38, 1.05, head[2] - 0.03],
        [0.38, 1.09, head[2] + 0.03],
        chrome,
    );
    let light = b.material("headlight", [236, 236, 222]);
    b.cylinder(
        [0.0, 0.98, head[2] - 0.1],
        2,
        0.09,
        0.05,
        14,
        [chrome, light],
    );
    b.cylinder([0.2, 0.33, 0.35], 2, 0.05, 0.38, 10, [chrome, chrome]);
    let tail = b.material("taillight", [186, 22, 24]);
    b.cuboid([-0.06, 0.82, zr - 0.16], [0.06, 0.88, zr - 0.1], tail);
    let rider = rng.chance(0.5);
    if rider {
        motorcyclist(&mut b, rng, head[2]);
    }
    (b, if rider { "with_rider" } else { "parked" }.to_string())
}

/// A rider astride a motorcycle whose handlebars are at `bars_z`: torso, helmet, legs on the
/// footpegs and arms to the bars.
fn motorcyclist(b: &mut Builder, rng: &mut Lcg, bars_z: f32) {
    let jacket = b.material(
        "jacket",
        pick_color(
            rng,
            &[[30, 30, 34], [60, 60, 70], [120, 30, 30], [40, 60, 100]],
            10.0,
        ),
    );
    let pants = b.material("pants", [40, 44, 60]);
    let helmet = b.material(
        "helmet",
        pick_color(rng, &[[20, 20, 20], [230, 230, 230], [180, 20, 20]], 8.0),
    );
    let hip = [0.0, 0.98, 0.1];
    let shoulder = [0.0, 1.5, -0.12];
    b.beam(hip, shoulder, 0.2, 0.12, [1.0, 0.0, 0.0], jacket);
    b.sphere([0.0, 1.68, -0.2], 0.14, helmet);
    for side in [-1.0f32, 1.0] {
        let knee = [side * 0.2, 0.95, -0.25];
        b.beam(
            [side * 0.1, 0.95, 0.1],
            knee,
            0.07,
            0.08,
            [0.0, 1.0, 0.0],
            pants,
        );
        b.beam(
            knee,
            [side * 0.2, 0.45, -0.15],
            0.06,
            0.07,
            [1.0, 0.0, 0.0],
            pants,
        );
        b.beam(
            [side * 0.2, 1.45, -0.1],
            [side * 0.33, 1.08, bars_z],
            0.05,
            0.05,
            [1.0, 0.0, 0.0],
            jacket,
        );
    }
}
