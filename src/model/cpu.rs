//! Inference kernels on flex's own buffers, for forward passes on the CPU that record no
//! gradient (`complete`, validation): a stride-1 convolution whose taps accumulate into one
//! output buffer, or Winograd's tiles for the 3×3 ones over many planes (`winograd`), instance
//! normalization in two passes, and the stride-2 convolutions' space to depth as one pass of
//! copies. Written with Burn's tensor ops the same convolution leaves a full-size temporary and
//! a sum behind every tap (49 of each for a 7×7 kernel), instance norm takes five passes over its
//! input and the space to depth a permute copied element by element; the built-in model's
//! forward is ~25 % faster this way, `complete` ~17 % (lab/2026-12-06-cpu-inference-kernels),
//! and the tiles take another 10–20 % off the forward (*Winograd's tiles*). Training keeps
//! Burn's ops, whose gradients it needs; the results agree to rounding (tested).

use burn::tensor::{Tensor, TensorData};
use rayon::prelude::*;

mod winograd;

/// Whether the kernels of this module run `x`'s layer: a tensor on flex that records no
/// gradient.
pub(super) fn applies(x: &Tensor<4>) -> bool {
    !x.is_autodiff() && crate::model::device::is_cpu(&x.device())
}

/// Input planes from which each tap's product reads the input in place; with fewer (the
/// 7-plane input convolution) a product over 7 planes is too thin to run fast, so the shifted
/// windows of one kernel row are copied beside each other and multiplied at once (measured on
/// 2 cores, the 7×7 input convolution at 128²: 39 ms as one tap a product, 23 ms a row at once).
const IN_PLACE_MIN_PLANES: usize = 32;

/// Stride-1 convolution of an already padded input: as Winograd's tiles where they pay, else the
/// output computed on the padded width (so each tap's window of the flattened image is one
/// strided matrix) and cropped.
///
/// # Shapes
/// `x`: `[n, c_in, h + span, w + span]` with `span = (k − 1)·dilation`, `weight`:
/// `[c_out, c_in, k, k]`, `bias`: `[c_out]` → `[n, c_out, h, w]`
pub(super) fn conv(
    x: Tensor<4>,
    weight: Tensor<4>,
    bias: Option<Tensor<1>>,
    dilation: usize,
) -> Tensor<4> {
    let device = x.device();
    let [n, c_in, hp, wp] = x.dims();
    let [c_out, _, k, _] = weight.dims();
    let span = (k - 1) * dilation;
    let (h, w) = (hp - span, wp - span);
    let x = floats(x.into_data());
    let weight = floats(weight.into_data());
    let bias = bias.map_or_else(|| vec![0.0; c_out], |b| floats(b.into_data()));
    if k == 3 && winograd::pays(n, [c_in, c_out], [h, w], dilation) {
        let out = winograd::conv(&x, [n, c_in, hp, wp], &weight, &bias, dilation);
        return Tensor::from_data(TensorData::new(out, [n, c_out, h, w]), &device);
    }
    let taps_at_once = if c_in >= IN_PLACE_MIN_PLANES { 1 } else { k };
    let shape = ConvShape {
        c_in,
        c_out,
        k,
        dilation,
        padded: [hp, wp],
        len: (h - 1) * wp + w,
        taps_at_once,
    };
    let weight = shape.grouped_weight(&weight);
    let mut out = vec![0.0; n * c_out * h * w];
    let mut wide = vec![0.0; c_out * h * wp];
    // The windows of a kernel row, copied beside each other when taps are multiplied at once.
    let stack_len = if taps_at_once > 1 {
        c_in * k * shape.len
    } else {
        0
    };
    let mut stack = vec![0.0; stack_len];
    for (image, out) in x
        .chunks_exact(c_in * hp * wp)
        .zip(out.chunks_exact_mut(c_out * h * w))
    {
        shape.run(image, &weight, &bias, &mut wide, &mut stack);
        for (o, row) in out.chunks_exact_mut(w).enumerate() {
            let (plane, y) = (o / h, o % h);
            row.copy_from_slice(&wide[plane * h * wp + y * wp..][..w]);
        }
    }
    Tensor::from_data(TensorData::new(out, [n, c_out, h, w]), &device)
}

/// One convolution's sizes, in the padded-width layout of [`conv`].
struct ConvShape {
    c_in: usize,
    c_out: usize,
    k: usize,
    dilation: usize,
    padded: [usize; 2],
    /// Output pixels on the padded width whose window lies in the image: the last valid one
    /// reads the last input pixel.
    len: usize,
    /// Consecutive taps (row-major over the kernel) multiplied in one product.
    taps_at_once: usize,
}

impl ConvShape {
    /// The weights as one `[c_out, c_in · taps_at_once]` matrix per group of taps, rows in the
    /// order the group's windows are read (plane, then tap).
    fn grouped_weight(&self, weight: &[f32]) -> Vec<f32> {
        let (g, kk) = (self.taps_at_once, self.k * self.k);
        let mut grouped = Vec::with_capacity(weight.len());
        for group in 0..kk / g {
            for taps in weight.chunks_exact(kk) {
                grouped.extend_from_slice(&taps[group * g..][..g]);
            }
        }
        grouped
    }

    /// Pixel offset of tap `t`'s window in the flattened padded image.
    fn shift(&self, t: usize) -> usize {
        ((t / self.k) * self.padded[1] + t % self.k) * self.dilation
    }

    /// One image: `wide` (`[c_out, h · wp]`) becomes the bias plus every tap's product.
    fn run(
        &self,
        image: &[f32],
        weight: &[f32],
        bias: &[f32],
        wide: &mut [f32],
        stack: &mut [f32],
    ) {
        let plane = self.padded[0] * self.padded[1];
        let out_plane = wide.len() / self.c_out;
        for (row, &b) in wide.chunks_exact_mut(out_plane).zip(bias) {
            row.fill(b);
        }
        let g = self.taps_at_once;
        let rows = self.c_in * g;
        let dst = Strided::rows(self.c_out, self.len, out_plane);
        for (group, lhs) in weight.chunks_exact(self.c_out * rows).enumerate() {
            let lhs_view = Strided::rows(self.c_out, rows, rows);
            if g == 1 {
                let rhs = Strided {
                    start: self.shift(group),
                    ..Strided::rows(self.c_in, self.len, plane)
                };
                multiply(wide, dst, lhs, lhs_view, image, rhs, true);
                continue;
            }
            for (r, window) in stack.chunks_exact_mut(self.len).enumerate() {
                let start = (r / g) * plane + self.shift(group * g + r % g);
                window.copy_from_slice(&image[start..][..self.len]);
            }
            let rhs = Strided::rows(rows, self.len, self.len);
            multiply(wide, dst, lhs, lhs_view, stack, rhs, true);
        }
    }
}

/// A matrix in a slice: element (r, c) at `start + r · row_stride + c` (columns contiguous).
#[derive(Clone, Copy)]
struct Strided {
    start: usize,
    rows: usize,
    cols: usize,
    row_stride: usize,
}

impl Strided {
    fn rows(rows: usize, cols: usize, row_stride: usize) -> Strided {
        Strided {
            start: 0,
            rows,
            cols,
            row_stride,
        }
    }

    /// One past the last element, or `start` when empty.
    fn end(&self) -> usize {
        if self.rows == 0 || self.cols == 0 {
            return self.start;
        }
        self.start + (self.rows - 1) * self.row_stride + self.cols
    }
}

/// `dst += lhs · rhs` with gemm on rayon's pool, or `dst = lhs · rhs` unless `accumulate`.
fn multiply(
    dst: &mut [f32],
    d: Strided,
    lhs: &[f32],
    l: Strided,
    rhs: &[f32],
    r: Strided,
    accumulate: bool,
) {
    assert!(
        d.rows == l.rows && d.cols == r.cols && l.cols == r.rows,
        "product shapes"
    );
    assert!(
        d.end() <= dst.len() && l.end() <= lhs.len() && r.end() <= rhs.len(),
        "bounds"
    );
    // Rows of `dst` must not overlap, or two threads would write one element.
    assert!(d.rows <= 1 || d.row_stride >= d.cols, "overlapping rows");
    if l.cols == 0 && !accumulate {
        for r in 0..d.rows {
            dst[d.start + r * d.row_stride..][..d.cols].fill(0.0);
        }
    }
    if d.rows == 0 || d.cols == 0 || l.cols == 0 {
        return;
    }
    // SAFETY: the asserts above keep every element gemm reads or writes inside its slice, and
    // the output's elements distinct; `dst` is borrowed mutably, so it overlaps no input.
    unsafe {
        gemm::gemm(
            d.rows,
            d.cols,
            l.cols,
            dst.as_mut_ptr().add(d.start),
            1,
            d.row_stride as isize,
            accumulate,
            lhs.as_ptr().add(l.start),
            1,
            l.row_stride as isize,
            rhs.as_ptr().add(r.start),
            1,
            r.row_stride as isize,
            1.0,
            1.0,
            false,
            false,
            false,
            gemm::Parallelism::Rayon(0),
        );
    }
}

/// The input of a 4×4 stride-2 convolution with one pixel of zero padding, its padded 2×2
/// pixel blocks stacked as planes: plane `c·4 + 2·dy + dx`, block `(by, bx)` holds pixel
/// `(2·by + dy − 1, 2·bx + dx − 1)` of plane `c` (zero outside). One pass of plain copies, where
/// Burn's pad, permute and copy to a contiguous layout take three, the permute's element by
/// element.
///
/// # Shapes
/// `[n, c, h, w]` (h, w even) → `[n, 4c, h/2 + 1, w/2 + 1]`
pub(super) fn space_to_depth(x: Tensor<4>) -> Tensor<4> {
    let device = x.device();
    let [n, c, h, w] = x.dims();
    let (hb, wb) = (h / 2 + 1, w / 2 + 1);
    let x = floats(x.into_data());
    let mut blocks = vec![0.0; n * c * 4 * hb * wb];
    blocks
        .par_chunks_mut(hb * wb)
        .enumerate()
        .for_each(|(plane, out)| {
            let (source, dy, dx) = (plane / 4, plane % 4 / 2, plane % 2);
            let source = &x[source * h * w..][..h * w];
            for (by, row) in out.chunks_exact_mut(wb).enumerate() {
                let Some(y) = (2 * by + dy).checked_sub(1).filter(|&y| y < h) else {
                    continue;
                };
                let line = &source[y * w..][..w];
                // Pixel 2·bx + dx − 1 of the line: with dx = 0 block 0 is padding.
                let (first, from) = if dx == 0 { (1, 1) } else { (0, 0) };
                for (v, &p) in row[first..].iter_mut().zip(line[from..].iter().step_by(2)) {
                    *v = p;
                }
            }
        });
    Tensor::from_data(TensorData::new(blocks, [n, c * 4, hb, wb]), &device)
}

/// Instance normalization without affine parameters, as Burn's `InstanceNorm` (biased
/// variance, `epsilon` inside the root), the statistics summed in f64.
///
/// # Shapes
/// `[n, c, h, w]` → `[n, c, h, w]`
pub(super) fn instance_norm(x: Tensor<4>, epsilon: f64) -> Tensor<4> {
    let device = x.device();
    let dims = x.dims();
    let plane = dims[2] * dims[3];
    let mut values = floats(x.into_data());
    values
        .par_chunks_mut(plane.max(1))
        .with_min_len(4)
        .for_each(|plane| {
            let count = plane.len() as f64;
            let mean = sum(plane, |v| v) / count;
            let variance = sum(plane, |v| (v - mean) * (v - mean)) / count;
            let scale = (variance + epsilon).sqrt().recip() as f32;
            let mean = mean as f32;
            for v in plane {
                *v = (*v - mean) * scale;
            }
        });
    Tensor::from_data(TensorData::new(values, dims), &device)
}

/// The sum of `f` over `values` in f64, in eight running sums: one sum is a chain of dependent
/// additions, which neither vectorizes nor overlaps.
fn sum(values: &[f32], f: impl Fn(f64) -> f64) -> f64 {
    let mut lanes = [0.0; 8];
    let chunks = values.chunks_exact(8);
    let rest: f64 = chunks.remainder().iter().map(|&v| f(f64::from(v))).sum();
    for chunk in chunks {
        for (lane, &v) in lanes.iter_mut().zip(chunk) {
            *lane += f(f64::from(v));
        }
    }
    lanes.iter().sum::<f64>() + rest
}

fn floats(data: TensorData) -> Vec<f32> {
    data.try_into_vec::<f32>()
        .expect("the model's tensors hold f32 (its weights are loaded as f32)")
}

#[cfg(test)]
mod tests {
    use super::*;
    use burn::nn::InstanceNormConfig;
    use burn::tensor::module::conv2d;
    use burn::tensor::ops::{ConvOptions, PadMode};
    use burn::tensor::{Device, Distribution};

    fn largest_difference(a: Tensor<4>, b: Tensor<4>) -> f32 {
        assert_eq!(a.dims(), b.dims());
        (a - b).abs().max().into_scalar::<f32>()
    }

    #[test]
    fn conv_matches_burns_convolution() {
        let device = Device::flex();
        // (batch, c_in, c_out, k, dilation, h, w): kernel rows stacked (c_in < 32), taps in
        // place, a 1×1 kernel, one output plane, and Winograd's tiles (3×3, c_in ≥ 32, as many
        // tiles as output planes) dilated, cut by the image's edge in both phases of a dilation
        // and larger than the image.
        for (n, c_in, c_out, k, dilation, h, w) in [
            (2, 3, 5, 3, 1, 6, 9),
            (1, 7, 4, 7, 1, 10, 12),
            (1, 40, 3, 1, 1, 5, 4),
            (1, 32, 1, 4, 1, 3, 8),
            (2, 33, 6, 3, 2, 7, 9),
            (1, 32, 5, 3, 1, 13, 6),
            (2, 48, 3, 3, 3, 10, 17),
            (1, 64, 1, 3, 1, 1, 2),
        ] {
            let pad = (k - 1) * dilation;
            let x = Tensor::<4>::random([n, c_in, h, w], Distribution::Default, &device);
            let weight = Tensor::<4>::random([c_out, c_in, k, k], Distribution::Default, &device);
            let bias = Tensor::<1>::random([c_out], Distribution::Default, &device);
            let padded = x.pad([(0, pad), (pad, 0)], PadMode::Constant(0.0));
            let options = ConvOptions::new([1, 1], [0, 0], [dilation, dilation], 1);
            for bias in [Some(bias), None] {
                let reference = conv2d(
                    padded.clone(),
                    weight.clone(),
                    bias.clone(),
                    options.clone(),
                );
                let ours = conv(padded.clone(), weight.clone(), bias, dilation);
                // Winograd's transforms round at about 1e-6 of the outputs' size.
                let size = reference.clone().abs().max().into_scalar::<f32>().max(1.0);
                let err = largest_difference(ours, reference) / size;
                assert!(
                    err < 1e-5,
                    "{c_in}→{c_out}, k {k}, dilation {dilation}: {err}"
                );
            }
        }
    }

    #[test]
    fn instance_norm_matches_burns() {
        let device = Device::flex();
        let norm = InstanceNormConfig::new(3).with_affine(false).init(&device);
        let x = Tensor::<4>::random([2, 3, 5, 7], Distribution::Normal(4.0, 3.0), &device);
        let err = largest_difference(instance_norm(x.clone(), norm.epsilon), norm.forward(x));
        assert!(err < 1e-5, "{err}");
    }

    #[test]
    fn only_forward_passes_without_gradients_on_the_cpu_take_these_kernels() {
        let x = Tensor::<4>::zeros([1, 1, 2, 2], &Device::flex());
        assert!(applies(&x));
        assert!(!applies(&x.autodiff()));
    }
}
