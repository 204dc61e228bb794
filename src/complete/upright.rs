//! Measures of upright vehicle points (y up) shared by orientation and the symmetry plane, so
//! that neither stage depends on the other for them.

/// Points below this share of the height are where the wheels meet the ground. Chosen on the
/// validation split among 0.03, 0.05 and 0.1 (lab/2026-12-02-orientation-wheels-flank).
pub const GROUND: f64 = 0.05;
/// The height `share` of the way from the lowest of `points` (upright) to the highest.
pub fn at_height(points: &[[f64; 3]], share: f64) -> f64 {
    let (lo, hi) = points.iter().fold((f64::MAX, f64::MIN), |(lo, hi), p| {
        (lo.min(p[1]), hi.max(p[1]))
    });
    lo + share * (hi - lo)
}

/// Absolute difference of two headings, in [0, 180].
pub fn angle_between(a: f64, b: f64) -> f64 {
    let d = (a - b).rem_euclid(360.0);
    d.min(360.0 - d)
}

#[cfg(test)]
pub(crate) mod fixtures {
    use crate::core::rng::Lcg;
    use crate::datagen::mesh::SignedAxis;
    use crate::datagen::scan::{scan, PartialSpec};
    use crate::datagen::synth::{synthesize, Category};

    /// A car-like block in upright coordinates with its front at heading `heading`: a long low
    /// body with a tall cabin over its rear half, at arbitrary offsets.
    pub(crate) fn car_block(heading: f64, offset: [f64; 3]) -> Vec<[f64; 3]> {
        let mut canonical = Vec::new();
        for i in 0..=40 {
            for j in 0..=16 {
                let z = -2.0 + 0.1 * i as f64;
                let x = -0.8 + 0.1 * j as f64;
                // Body top 0.9 m, cabin 1.5 m from 0.2 m behind the middle.
                let top = if z > -0.2 { 1.5 } else { 0.9 };
                canonical.push([x, top, z]);
                if j == 16 {
                    for k in 0..=(top * 10.0) as usize {
                        canonical.push([x, 0.1 * k as f64, z]);
                    }
                }
            }
        }
        turned(canonical, heading, offset)
    }

    /// A drive-by scan of generated object `seed` of `category` (normalized: length along z, up
    /// y, its plane of symmetry x = 0) from `side`, the sensor `height` above the object's
    /// lowest point and 0.8 beside its centre.
    pub(crate) fn driven_past(
        category: Category,
        seed: u64,
        side: f32,
        height: f32,
    ) -> Vec<[f64; 3]> {
        let mut mesh = synthesize(0, seed, &[category.into()]).mesh;
        mesh.normalize(SignedAxis::PLUS_Y, SignedAxis::MINUS_Z)
            .unwrap();
        let spec = PartialSpec::Scanner {
            side,
            distance: 0.8,
            height,
            yaw_deg: 0.0,
            line_spacing: 0.008,
            angle_step_deg: 0.25,
            noise: 0.001,
        };
        let part = scan(&mesh, &spec, &mut Lcg::new(seed));
        part.points.iter().map(|p| p.map(f64::from)).collect()
    }

    /// Points of a canonical object (heading 90°) turned to `heading` and moved by `offset`.
    pub(crate) fn turned(
        canonical: Vec<[f64; 3]>,
        heading: f64,
        offset: [f64; 3],
    ) -> Vec<[f64; 3]> {
        // Turn by heading − 90° counter-clockwise seen from above, i.e. about +y by that angle.
        let (s, c) = (heading - 90.0).to_radians().sin_cos();
        canonical
            .into_iter()
            .map(|[x, y, z]| {
                [
                    offset[0] + c * x + s * z,
                    offset[1] + y,
                    offset[2] - s * x + c * z,
                ]
            })
            .collect()
    }
}
