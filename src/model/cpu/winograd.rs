//! Winograd's minimal filtering for the 3×3 convolutions of many planes (the residual blocks;
//! the view fusion where its tiles are many enough, [`pays`]): each tile of m×m output pixels of a plane comes from an (m + 2)² input
//! patch through (m + 2)² products instead of 9m², the patches and kernels being turned into
//! that product space and the results back by small fixed matrices (Lavin & Gray, *Fast
//! Algorithms for Convolutional Neural Networks*, 2016). The products become (m + 2)² matrix
//! products over the planes, one per point of the tile's transform, each a plain gemm; the
//! transforms are sums of rows, run across a block of tiles at once so that they vectorize.

use super::{multiply, Strided, IN_PLACE_MIN_PLANES};
use rayon::prelude::*;
use std::ops::Range;

/// The matrices of one F(m×m, 3×3): `bt` is Bᵀ (α × α, α = m + 2), `g` is G (α × 3), `at` is
/// Aᵀ (m × α), all row-major.
struct Minimal {
    m: usize,
    bt: &'static [f32],
    g: &'static [f32],
    at: &'static [f32],
}

/// F(4×4, 3×3) on the points 0, ±1, ±2 and ∞: 36 products for 144.
#[rustfmt::skip]
const F4: Minimal = Minimal {
    m: 4,
    bt: &[
        4.0,  0.0, -5.0,  0.0, 1.0, 0.0,
        0.0, -4.0, -4.0,  1.0, 1.0, 0.0,
        0.0,  4.0, -4.0, -1.0, 1.0, 0.0,
        0.0, -2.0, -1.0,  2.0, 1.0, 0.0,
        0.0,  2.0, -1.0, -2.0, 1.0, 0.0,
        0.0,  4.0,  0.0, -5.0, 0.0, 1.0,
    ],
    g: &[
         1.0 / 4.0,   0.0,         0.0,
        -1.0 / 6.0,  -1.0 / 6.0,  -1.0 / 6.0,
        -1.0 / 6.0,   1.0 / 6.0,  -1.0 / 6.0,
         1.0 / 24.0,  1.0 / 12.0,  1.0 / 6.0,
         1.0 / 24.0, -1.0 / 12.0,  1.0 / 6.0,
         0.0,         0.0,         1.0,
    ],
    at: &[
        1.0, 1.0,  1.0, 1.0,  1.0, 0.0,
        0.0, 1.0, -1.0, 2.0, -2.0, 0.0,
        0.0, 1.0,  1.0, 4.0,  4.0, 0.0,
        0.0, 1.0, -1.0, 8.0, -8.0, 1.0,
    ],
};

/// Where the tiles lie. Along each axis the outputs of one phase modulo the dilation are
/// consecutive taps of a dilated kernel apart, so a tile covers m outputs of one phase, `dilation`
/// apart, and reads α inputs of the padded image as far apart.
#[derive(Clone, Copy)]
struct Tiles {
    m: usize,
    dilation: usize,
    /// Tiles along y and x.
    count: [usize; 2],
}

impl Tiles {
    fn new(m: usize, dilation: usize, [h, w]: [usize; 2]) -> Tiles {
        let along = |side: usize| dilation * side.div_ceil(m * dilation);
        Tiles {
            m,
            dilation,
            count: [along(h), along(w)],
        }
    }

    fn per_image(&self) -> usize {
        self.count[0] * self.count[1]
    }

    /// The image of tile `t` (counted over all images) and its first output (and input) row and
    /// column.
    fn place(&self, t: usize) -> (usize, usize, usize) {
        let d = self.dilation;
        let origin = |t: usize| t % d + (t / d) * self.m * d;
        let (image, within) = (t / self.per_image(), t % self.per_image());
        let [_, across] = self.count;
        (image, origin(within / across), origin(within % across))
    }
}

/// Tiles transformed and multiplied at a time, so that the products' operands stay a few MB
/// however large the image: at the paper's 256² the whole image's took 75 MB a convolution and
/// ran slower than the direct products (`mvpcc profile --config paper`, its residual
/// convolutions, paired: direct 771–803 ms, whole images 1,317–1,347 ms, blocks of 512 / 256 /
/// 128 tiles 781–794 / 574–641 / 527–538 ms; 64 no better than 128).
const BLOCK: usize = 128;

/// Whether a 3×3 convolution of `n` images of `h × w` pixels runs faster as tiles: over as many
/// planes as a product needs to run fast (`IN_PLACE_MIN_PLANES`; the direct products stack a
/// kernel row's taps below it), and with at least as many tiles as output planes. With fewer, as in the fusion of
/// one object's views (64 tiles, 768 → 192 planes), the kernels' transform, four times their
/// size, outweighs the products it saves: `complete` of CAR175 peaked at 174 MB with the fusion
/// as tiles against 135–156 MB without, in the same time (0.37–0.38 s, 4 runs each, paired).
pub(super) fn pays(
    n: usize,
    [c_in, c_out]: [usize; 2],
    [h, w]: [usize; 2],
    dilation: usize,
) -> bool {
    c_in >= IN_PLACE_MIN_PLANES && n * Tiles::new(F4.m, dilation, [h, w]).per_image() >= c_out
}

/// 3×3 stride-1 convolution of an already padded input, dilated by `dilation`.
///
/// # Shapes
/// `x`: `[n, c_in, h + 2·dilation, w + 2·dilation]` (`dims`), `weight`: `[c_out, c_in, 3, 3]`,
/// `bias`: `[c_out]` → `[n, c_out, h, w]`
pub(super) fn conv(
    x: &[f32],
    dims: [usize; 4],
    weight: &[f32],
    bias: &[f32],
    dilation: usize,
) -> Vec<f32> {
    let f = &F4;
    let [n, c_in, hp, wp] = dims;
    let c_out = bias.len();
    let (h, w) = (hp - 2 * dilation, wp - 2 * dilation);
    let tiles = Tiles::new(f.m, dilation, [h, w]);
    let total = n * tiles.per_image();
    let points = (f.m + 2) * (f.m + 2);
    let u = transform_weights(f, weight, c_in); // [c_out, points, c_in]
    let mut v = vec![0.0; c_in * points * BLOCK.min(total)]; // [c_in, points, block]
    let mut products = vec![0.0; c_out * points * BLOCK.min(total)]; // [c_out, points, block]
    let mut out = vec![0.0; n * c_out * h * w];
    for first in (0..total).step_by(BLOCK) {
        let block = first..total.min(first + BLOCK);
        let len = block.len();
        transform_input(f, x, dims, tiles, block.clone(), &mut v);
        for p in 0..points {
            let lhs = Strided {
                start: p * c_in,
                ..Strided::rows(c_out, c_in, points * c_in)
            };
            let rhs = Strided {
                start: p * len,
                ..Strided::rows(c_in, len, points * len)
            };
            let dst = Strided {
                start: p * len,
                ..Strided::rows(c_out, len, points * len)
            };
            multiply(&mut products, dst, &u, lhs, &v, rhs, false);
        }
        transform_output(f, &products, bias, [h, w], tiles, block, &mut out);
    }
    out
}

/// `L · X · Lᵀ` for every tile at once: `x` holds the `inner × inner` matrices' elements as
/// rows of `len` tiles (element (i, j) in row `i·inner + j`), `out` gets `rows × rows` such rows
/// for the `rows × inner` matrix `l`, and `scratch` holds the `rows · inner` rows of `L · X`.
fn sandwich(l: &[f32], inner: usize, x: &[f32], len: usize, scratch: &mut [f32], out: &mut [f32]) {
    let rows = l.len() / inner;
    scratch.fill(0.0);
    out.fill(0.0);
    // Row block i of `x` (its `inner` rows (i, ·)) makes row block r of L · X.
    left_multiply(l, inner, x, inner * len, scratch);
    for (lx, out) in scratch
        .chunks_exact(inner * len)
        .zip(out.chunks_exact_mut(rows * len))
    {
        left_multiply(l, inner, lx, len, out);
    }
}

/// `out[r] += Σ_k left[r][k] · blocks[k]` over blocks of `len` values, `left` having `inner`
/// columns; the transforms are mostly zeros and ones, so zero coefficients are skipped and each
/// term is one pass along a block, which vectorizes.
fn left_multiply(left: &[f32], inner: usize, blocks: &[f32], len: usize, out: &mut [f32]) {
    for (row, out) in left.chunks_exact(inner).zip(out.chunks_exact_mut(len)) {
        for (k, &coefficient) in row.iter().enumerate() {
            if coefficient == 0.0 {
                continue;
            }
            for (o, &b) in out.iter_mut().zip(&blocks[k * len..][..len]) {
                *o += coefficient * b;
            }
        }
    }
}

/// G · g · Gᵀ for every kernel, planes innermost.
///
/// # Shapes
/// `weight`: `[c_out, c_in, 3, 3]` → `[c_out, α², c_in]`
fn transform_weights(f: &Minimal, weight: &[f32], c_in: usize) -> Vec<f32> {
    let alpha = f.m + 2;
    let c_out = weight.len() / (9 * c_in);
    let mut u = vec![0.0; c_out * alpha * alpha * c_in];
    u.par_chunks_mut(alpha * alpha * c_in)
        .zip(weight.par_chunks(9 * c_in))
        .for_each_init(
            || (vec![0.0; 9 * c_in], vec![0.0; alpha * 3 * c_in]),
            |(taps, scratch), (u, kernels)| {
                // [9, c_in]: tap (i, j) of every plane's kernel as row i·3 + j.
                for (c, kernel) in kernels.chunks_exact(9).enumerate() {
                    for (t, &v) in kernel.iter().enumerate() {
                        taps[t * c_in + c] = v;
                    }
                }
                sandwich(f.g, 3, taps, c_in, scratch, u);
            },
        );
    u
}

/// Bᵀ · d · B for the input patches of the tiles in `block`, tiles innermost.
///
/// # Shapes
/// `x`: `[n, c_in, hp, wp]` (`dims`) → `v`: `[c_in, α², block.len()]`
fn transform_input(
    f: &Minimal,
    x: &[f32],
    dims: [usize; 4],
    tiles: Tiles,
    block: Range<usize>,
    v: &mut [f32],
) {
    let [_, c_in, hp, wp] = dims;
    let alpha = f.m + 2;
    let points = alpha * alpha;
    let len = block.len();
    let d = tiles.dilation;
    v[..c_in * points * len]
        .par_chunks_mut(points * len)
        .enumerate()
        .for_each_init(
            || (vec![0.0; points * len], vec![0.0; points * len]),
            |(patches, scratch), (c, v)| {
                // [α², len]: element (i, j) of every patch as row i·α + j; zero past the image.
                patches.fill(0.0);
                for (k, t) in block.clone().enumerate() {
                    let (image, y0, x0) = tiles.place(t);
                    let plane = &x[(image * c_in + c) * hp * wp..][..hp * wp];
                    for i in (0..alpha).take_while(|i| y0 + i * d < hp) {
                        let line = &plane[(y0 + i * d) * wp..][..wp];
                        for j in (0..alpha).take_while(|j| x0 + j * d < wp) {
                            patches[(i * alpha + j) * len + k] = line[x0 + j * d];
                        }
                    }
                }
                sandwich(f.bt, alpha, patches, len, scratch, v);
            },
        );
}

/// Aᵀ · M · A for the tiles in `block`, plus the bias, written into the output image.
///
/// # Shapes
/// `products`: `[c_out, α², block.len()]` → `out`: `[n, c_out, h, w]`
fn transform_output(
    f: &Minimal,
    products: &[f32],
    bias: &[f32],
    [h, w]: [usize; 2],
    tiles: Tiles,
    block: Range<usize>,
    out: &mut [f32],
) {
    let (m, alpha) = (f.m, f.m + 2);
    let points = alpha * alpha;
    let c_out = bias.len();
    let per_image = tiles.per_image();
    let d = tiles.dilation;
    for image in block.start / per_image..block.end.div_ceil(per_image) {
        let here = block.start.max(image * per_image)..block.end.min((image + 1) * per_image);
        let (count, skip) = (here.len(), here.start - block.start);
        out[image * c_out * h * w..][..c_out * h * w]
            .par_chunks_mut(h * w)
            .zip(bias)
            .enumerate()
            .for_each_init(
                || {
                    let buffer = |rows: usize| vec![0.0; rows * count];
                    (buffer(points), buffer(m * alpha), buffer(m * m))
                },
                |(own, scratch, values), (o, (plane, &b))| {
                    // Plane o's products for this image's tiles, [α², count].
                    let source = &products[o * points * block.len()..][..points * block.len()];
                    for (row, s) in own
                        .chunks_exact_mut(count)
                        .zip(source.chunks_exact(block.len()))
                    {
                        row.copy_from_slice(&s[skip..][..count]);
                    }
                    sandwich(f.at, alpha, own, count, scratch, values);
                    for (k, t) in here.clone().enumerate() {
                        let (_, y0, x0) = tiles.place(t);
                        for i in (0..m).take_while(|i| y0 + i * d < h) {
                            let line = &mut plane[(y0 + i * d) * w..][..w];
                            for j in (0..m).take_while(|j| x0 + j * d < w) {
                                line[x0 + j * d] = values[(i * m + j) * count + k] + b;
                            }
                        }
                    }
                },
            );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_residual_blocks_take_tiles_and_one_objects_fusion_does_not() {
        // The built-in model's shapes: 4 views at 32² after the encoder, 192 planes.
        assert!(pays(4, [192, 192], [32, 32], 2));
        assert!(!pays(1, [768, 192], [32, 32], 1));
        assert!(!pays(4, [16, 16], [32, 32], 1));
    }

    #[test]
    fn tiles_cover_every_output_of_each_phase_once() {
        for (dilation, side) in [(1, 9), (2, 32), (3, 10)] {
            let tiles = Tiles::new(F4.m, dilation, [side, side]);
            let mut covered = vec![0; side];
            for t in 0..tiles.count[1] {
                let (_, _, x0) = tiles.place(t);
                for x in (0..F4.m).map(|i| x0 + i * dilation).filter(|&x| x < side) {
                    covered[x] += 1;
                }
            }
            assert!(
                covered.iter().all(|&c| c == 1),
                "dilation {dilation}: {covered:?}"
            );
        }
    }
}
