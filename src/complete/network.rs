//! The network stage of [`complete`](super::complete): the measured points (and their mirror
//! image, the mirrored pass) projected into the model's views, inpainted, snapped onto the
//! pixels' rays, re-projected, filtered and held to the network's box.

use super::symmetry::{mirror, Plane};
use super::{filter::inliers, CompleteError, NetworkViews, Options, Timings};
use crate::core::camera::Camera;
use crate::core::cloud::{Aabb, PointCloud};
use crate::model::inpaint::Inpainter;
use crate::views::projection::{project, ViewImages};
use crate::views::reprojection::{reproject_keeping, snap_to_rays, ReprojectOptions};
use std::borrow::Cow;
use std::time::Instant;

/// What the network made of one object, re-projected and filtered (the outlier filter and the
/// network's box).
pub(super) struct NetworkOutput {
    pub(super) predicted: PointCloud,
    /// The same from the pixels of occupancy above [`Options::near_occupancy`], when the near
    /// band needs them.
    pub(super) sure: Option<PointCloud>,
    pub(super) filtered_out: usize,
    /// 2 where the mirror image was completed too.
    pub(super) passes: usize,
    pub(super) views: Option<NetworkViews>,
}

/// Projection, inpainting, snapping, re-projection, the outlier filter and the network's box
/// (which needs the symmetry `plane` for its width), timed. With a plane and
/// [`Options::mirror_pass`] the network then completes the measured points' mirror image too,
/// and its points, mirrored back, join the first pass's: a second opinion from views that see
/// the other flank (docs/pipeline.md, *6. The network*). The two passes are one rayon
/// join, as the CPU backend's matrix products are rayon tasks: on idle cores the passes run
/// side by side and their products spread over the rest, while in a batch whose jobs fill the
/// cores nothing waits on a thread of its own (docs/speed.md).
pub(super) fn run_network(
    input: &PointCloud,
    measured: &[[f64; 3]],
    plane: Option<Plane>,
    inpainter: &Inpainter,
    options: &Options,
    timings: &mut Timings,
) -> Result<NetworkOutput, CompleteError> {
    let config = inpainter.config();
    if config.views != options.views.len() {
        return Err(CompleteError::Views {
            model: config.views,
            given: options.views.len(),
        });
    }
    let cameras = Camera::set(&options.views, config.size)?;
    let colors = input.colors.as_deref();
    let first = Pass::of(measured);
    let second = plane
        .filter(|_| options.mirror_pass)
        .map(|plane| Pass::mirrored(measured, plane));
    let cameras = &cameras;
    let mut first_done = Instant::now();
    let (output, second) = rayon::join(
        || {
            let output = first.run(colors, cameras, plane, inpainter, options, timings);
            first_done = Instant::now();
            output
        },
        || {
            second.map(|pass| {
                let mut own = Timings::default();
                pass.run(colors, cameras, plane, inpainter, options, &mut own)
            })
        },
    );
    timings.mirror_pass = first_done.elapsed();
    let mut output = output?;
    if let Some(more) = second {
        let more = more?;
        output.predicted.append(more.predicted);
        if let (Some(sure), Some(more)) = (output.sure.as_mut(), more.sure) {
            sure.append(more);
        }
        output.filtered_out += more.filtered_out;
        output.passes += 1;
    }
    Ok(output)
}

/// One object the network completes: the measured points, or their mirror image about the
/// plane at `x = mirrored`.
struct Pass<'a> {
    measured: Cow<'a, [[f64; 3]]>,
    mirrored: Option<f64>,
}

impl<'a> Pass<'a> {
    /// The measured points as they are.
    fn of(measured: &'a [[f64; 3]]) -> Self {
        Pass {
            measured: Cow::Borrowed(measured),
            mirrored: None,
        }
    }

    /// The measured points' mirror image about `plane`.
    fn mirrored(measured: &[[f64; 3]], plane: Plane) -> Self {
        Pass {
            measured: measured.iter().map(|&p| mirror(p, plane.offset)).collect(),
            mirrored: Some(plane.offset),
        }
    }

    /// The network's points for this pass's object, in the measured points' own frame; the
    /// views are kept (`keep_views`) of the measured points' pass only.
    fn run(
        &self,
        colors: Option<&[[u8; 3]]>,
        cameras: &[Camera],
        plane: Option<Plane>,
        inpainter: &Inpainter,
        options: &Options,
        timings: &mut Timings,
    ) -> Result<NetworkOutput, CompleteError> {
        let start = Instant::now();
        let points: Vec<[f32; 3]> = self.measured.iter().map(|p| p.map(|c| c as f32)).collect();
        let batch = [project(&points, colors, cameras)];
        timings.projection += start.elapsed();

        let (generated, stages) = inpainter.generate_timed(&batch)?;
        timings.encoder += stages.encoder;
        timings.fusion += stages.fusion;
        timings.decoder += stages.decoder;

        let threshold = inpainter.config().occupancy_threshold();
        let mut inpainted = inpainter.views_at(&batch, &generated, threshold);
        let inpainted = inpainted.pop().expect("one object in, one out");
        let views = (options.keep_views && self.mirrored.is_none()).then(|| NetworkViews {
            input: batch[0].clone(),
            output: inpainted.clone(),
        });
        // The pixels a copying generator took from its input are measured points.
        let copied = inpainter.config().copies_input().then_some(&batch[0]);
        let network = Network {
            cameras,
            copied,
            measured: &self.measured,
            plane,
            options,
        };
        let (predicted, filtered_out) = network.points(inpainted, timings);
        let sure = near_band(options, threshold).then(|| {
            let mut views = inpainter.views_at(&batch, &generated, options.near_occupancy);
            let views = views.pop().expect("one object in, one out");
            self.back(network.points(views, timings).0)
        });
        Ok(NetworkOutput {
            predicted: self.back(predicted),
            sure,
            filtered_out,
            passes: 1,
            views,
        })
    }

    /// Points of this pass's object in the measured points' own frame.
    fn back(&self, mut points: PointCloud) -> PointCloud {
        if let Some(offset) = self.mirrored {
            points
                .positions
                .iter_mut()
                .for_each(|p| *p = mirror(*p, offset));
        }
        points
    }
}

/// Whether completed points near the measured and mirrored ones need more than the model's
/// occupancy `threshold` ([`Options::near_distance`]).
fn near_band(options: &Options, threshold: f64) -> bool {
    options.keep_input
        && options.near_distance > options.merge_distance
        && options.near_occupancy > threshold
}

/// What turns inpainted views into the network's points.
struct Network<'a> {
    cameras: &'a [Camera],
    /// The input views, when the generator copies their pixels.
    copied: Option<&'a ViewImages>,
    measured: &'a [[f64; 3]],
    plane: Option<Plane>,
    options: &'a Options,
}

impl Network<'_> {
    /// Snapping, re-projection, the outlier filter and the network's box, timed; the points and
    /// how many the filter and the box removed.
    fn points(&self, mut inpainted: ViewImages, timings: &mut Timings) -> (PointCloud, usize) {
        let start = Instant::now();
        if self.options.snap {
            snap_to_rays(&mut inpainted, self.cameras, self.copied);
        }
        let reproject_options = ReprojectOptions {
            erode: self.options.erode,
            smooth: self.options.smooth,
            dedup_tolerance: self.options.dedup,
        };
        let predicted = reproject_keeping(&inpainted, reproject_options, self.copied);
        timings.reprojection += start.elapsed();

        let start = Instant::now();
        let keep = inliers(&predicted.positions, self.options.sor);
        let mut predicted = predicted.filter(&keep);
        let outside = drop_outside_box(
            &mut predicted,
            self.measured,
            self.plane,
            self.options.box_margin,
        );
        timings.filter += start.elapsed();
        (predicted, keep.iter().filter(|&&k| !k).count() + outside)
    }
}

/// Drops the network's points lying more than `margin` beyond the measured points' height or beyond
/// the width they and their mirror images span, and returns how many went (docs/ completing.md,
/// *The network's box*). The length is left open: a partial may lack a whole end, which the network
/// fills. Without a plane the width is not known either.
fn drop_outside_box(
    predicted: &mut PointCloud,
    measured: &[[f64; 3]],
    plane: Option<Plane>,
    margin: f64,
) -> usize {
    let images = plane
        .into_iter()
        .flat_map(|plane| measured.iter().map(move |&p| mirror(p, plane.offset)));
    let Some(bounds) = Aabb::of_iter(measured.iter().copied().chain(images)) else {
        return 0;
    };
    let axes = if plane.is_some() { 0..2 } else { 1..2 };
    let keep: Vec<bool> = predicted
        .positions
        .iter()
        .map(|p| {
            axes.clone()
                .all(|i| p[i] >= bounds.min[i] - margin && p[i] <= bounds.max[i] + margin)
        })
        .collect();
    let dropped = keep.iter().filter(|&&k| !k).count();
    if dropped > 0 {
        *predicted = predicted.filter(&keep);
    }
    dropped
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::complete::symmetry::PlaneFit;

    /// The width is the measured points' and their mirror images': a point beyond the measured
    /// flank but inside the mirrored one stays; points past the margin across the width or the
    /// height go, not along the length; without a plane only the height bounds; an infinite
    /// margin keeps everything.
    #[test]
    fn network_points_outside_the_box_are_dropped() {
        let measured = [[0.1, -0.2, -0.5], [0.3, 0.2, 0.5]];
        let plane = Plane {
            offset: 0.0,
            support: 0.5,
            tolerance: 0.01,
            fit: PlaneFit::Refined,
            cues: Default::default(),
            vouched: true,
            both_sides: false,
        };
        let predicted = PointCloud::from_positions(vec![
            [-0.3, 0.0, 0.0],
            [0.34, 0.0, 0.0],
            [0.0, 0.26, 0.0],
            [0.0, 0.0, -0.56],
            [0.0, 0.0, 0.0],
        ]);
        let kept = |plane, margin| {
            let mut cloud = predicted.clone();
            let dropped = drop_outside_box(&mut cloud, &measured, plane, margin);
            assert_eq!(dropped + cloud.len(), predicted.len());
            cloud.positions
        };
        let everything_but = |dropped: &[[f64; 3]]| {
            let mut all = predicted.positions.clone();
            all.retain(|p| !dropped.contains(p));
            all
        };
        assert_eq!(kept(Some(plane), 0.05), everything_but(&[[0.0, 0.26, 0.0]]));
        assert_eq!(kept(None, 0.05), everything_but(&[[0.0, 0.26, 0.0]]));
        assert_eq!(
            kept(Some(plane), 0.0),
            everything_but(&[[0.34, 0.0, 0.0], [0.0, 0.26, 0.0]])
        );
        assert_eq!(kept(None, 0.0), everything_but(&[[0.0, 0.26, 0.0]]));
        assert_eq!(kept(None, f64::INFINITY), predicted.positions);
    }
}
