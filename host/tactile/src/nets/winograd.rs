//! Winograd's minimal filtering F(4 x 4, 3 x 3) for the plain engine's 3 x 3 convolutions
//! (A. Lavin and S. Gray, "Fast algorithms for convolutional neural networks", CVPR 2016, with
//! the interpolation points 0, +-1, +-2 and infinity). A 4 x 4 block of output pixels needs a
//! 6 x 6 tile of the padded input; in the transformed domain the convolution over input
//! channels is 36 matrix products over the tiles, one per point of the tile, each with `c_in`
//! terms per output, where the direct convolution spends 144 multiplications per (input,
//! output) channel pair and block: a quarter of the arithmetic. Maps run channel-last, as in
//! [`super::infer`], so the tile transforms work on 8 channels per vector; blocks of tile rows
//! run in parallel, each through the transforms and all 36 products while its buffers are in
//! cache.

use faer::linalg::matmul::matmul;
use faer::{Accum, MatMut, MatRef, Par};
use rayon::prelude::*;

use super::map::{Map, give, take};

/// Output pixels per tile side.
const M: usize = 4;
/// Input pixels per tile side (M + 3 - 1).
const T: usize = 6;
/// Points of a transformed tile.
const P: usize = T * T;
/// Channels per vector in the transforms.
const L: usize = 8;
/// Tiles a block aims at: whole tile rows, at least one (so 80 at 320 pixels wide). Measured on
/// the perception network at 240 x 320 (batches of 8 on 2 threads, before [`PAD`]), 20 to 32
/// tiles ran at 36-37 images/s, 64 at 35, 320 at 30: the block's transformed tiles and
/// products stay in the core's cache.
const BLOCK_TILES: usize = 32;

/// Spare values after each point's matrix in the block buffers. Without them a point's matrix
/// spans a multiple of 2 KB (80 tiles of 32 channels: 10 KB), so the 36 points' rows of one
/// tile fall on two sets of the L1 cache and evict each other; one cache line more spreads
/// them over 36 sets (perception at 240 x 320: 36 to 40 images/s).
const PAD: usize = 16;

/// The distance between consecutive points' matrices of `tiles` rows of `c` values.
fn point_stride(tiles: usize, c: usize) -> usize {
    tiles * c + PAD
}

/// One input's 3 x 3 weights in the Winograd domain: for each of the 36 points of a tile a
/// `[c_in, c_out]` row-major matrix.
#[derive(Debug, Clone)]
pub(super) struct Weights {
    c_in: usize,
    c_out: usize,
    u: Vec<f32>,
}

/// G z for one column of three taps (G is 6 x 3).
fn g_times(z: [f64; 3]) -> [f64; T] {
    [
        z[0] / 4.0,
        -(z[0] + z[1] + z[2]) / 6.0,
        -(z[0] - z[1] + z[2]) / 6.0,
        z[0] / 24.0 + z[1] / 12.0 + z[2] / 6.0,
        z[0] / 24.0 - z[1] / 12.0 + z[2] / 6.0,
        z[2],
    ]
}

impl Weights {
    /// From the direct convolution's taps: per kernel row dy a `[3 c_in, c_out]` row-major
    /// matrix whose rows run over (dx, input channel). U = G g G^T per channel pair, in `f64`.
    pub(super) fn new(taps: &[Vec<f32>; 3], c_in: usize, c_out: usize) -> Self {
        let mut u = vec![0.0f32; P * c_in * c_out];
        for ci in 0..c_in {
            for co in 0..c_out {
                let g = |dy: usize, dx: usize| f64::from(taps[dy][(dx * c_in + ci) * c_out + co]);
                // G g: six rows of three.
                let mut gg = [[0.0f64; 3]; T];
                for dx in 0..3 {
                    let col = g_times([g(0, dx), g(1, dx), g(2, dx)]);
                    for (row, v) in gg.iter_mut().zip(col) {
                        row[dx] = v;
                    }
                }
                for (a, row) in gg.iter().enumerate() {
                    for (b, v) in g_times(*row).into_iter().enumerate() {
                        u[((a * T + b) * c_in + ci) * c_out + co] = v as f32;
                    }
                }
            }
        }
        Weights { c_in, c_out, u }
    }
}

/// Whether a convolution of `h` x `w` maps from inputs of `c_in` channels (each) to `c_out`
/// channels takes this path: whole tiles, and whole vectors of channels on both sides.
pub(super) fn fits(h: usize, w: usize, c_in: &[usize], c_out: usize) -> bool {
    h > 0
        && w > 0
        && h.is_multiple_of(M)
        && w.is_multiple_of(M)
        && c_out.is_multiple_of(L)
        && c_in.iter().all(|c| *c > 0 && c.is_multiple_of(L))
}

/// B^T z for six vectors (B^T is 6 x 6).
#[inline(always)]
fn bt(z: &[[f32; L]; T]) -> [[f32; L]; T] {
    let mut r = [[0.0f32; L]; T];
    for k in 0..L {
        let (z0, z1, z2, z3, z4, z5) = (z[0][k], z[1][k], z[2][k], z[3][k], z[4][k], z[5][k]);
        r[0][k] = 4.0 * z0 - 5.0 * z2 + z4;
        r[1][k] = -4.0 * (z1 + z2) + z3 + z4;
        r[2][k] = 4.0 * (z1 - z2) - z3 + z4;
        r[3][k] = 2.0 * (z3 - z1) - z2 + z4;
        r[4][k] = 2.0 * (z1 - z3) - z2 + z4;
        r[5][k] = 4.0 * z1 - 5.0 * z3 + z5;
    }
    r
}

/// A^T z for six vectors (A^T is 4 x 6).
#[inline(always)]
fn at(z: &[[f32; L]; T]) -> [[f32; L]; M] {
    let mut r = [[0.0f32; L]; M];
    for k in 0..L {
        let (z0, z1, z2, z3, z4, z5) = (z[0][k], z[1][k], z[2][k], z[3][k], z[4][k], z[5][k]);
        let (s12, d12, s34, d34) = (z1 + z2, z1 - z2, z3 + z4, z3 - z4);
        r[0][k] = z0 + s12 + s34;
        r[1][k] = d12 + 2.0 * d34;
        r[2][k] = s12 + 4.0 * s34;
        r[3][k] = d12 + 8.0 * d34 + z5;
    }
    r
}

/// The `L` values of `s` from `o` (a typed copy: `copy_from_slice` keeps a run-time check on
/// its arguments in the dev profile, which cost a third of the transforms' time).
#[inline(always)]
fn load(s: &[f32], o: usize) -> [f32; L] {
    s[o..o + L].try_into().expect("a slice of L values")
}

/// Writes `v` to the `L` values of `s` from `o`.
#[inline(always)]
fn store(s: &mut [f32], o: usize, v: [f32; L]) {
    let d: &mut [f32; L] = (&mut s[o..o + L]).try_into().expect("a slice of L values");
    *d = v;
}

/// Six vectors of `s` from `o`, `stride` apart.
#[inline(always)]
fn load6(s: &[f32], o: usize, stride: usize) -> [[f32; L]; T] {
    [
        load(s, o),
        load(s, o + stride),
        load(s, o + 2 * stride),
        load(s, o + 3 * stride),
        load(s, o + 4 * stride),
        load(s, o + 5 * stride),
    ]
}

/// `f` down each of the six columns of a tile: column j's six vectors start at `o + j step`,
/// `stride` apart; element j of the result is column j transformed.
#[inline(always)]
fn down_columns<const N: usize>(
    f: impl Fn(&[[f32; L]; T]) -> [[f32; L]; N],
    s: &[f32],
    o: usize,
    step: usize,
    stride: usize,
) -> [[[f32; L]; N]; T] {
    [
        f(&load6(s, o, stride)),
        f(&load6(s, o + step, stride)),
        f(&load6(s, o + 2 * step, stride)),
        f(&load6(s, o + 3 * step, stride)),
        f(&load6(s, o + 4 * step, stride)),
        f(&load6(s, o + 5 * step, stride)),
    ]
}

/// Column `i` of six columns (element `i` of each).
#[inline(always)]
fn across<const N: usize>(cols: &[[[f32; L]; N]; T], i: usize) -> [[f32; L]; T] {
    [
        cols[0][i], cols[1][i], cols[2][i], cols[3][i], cols[4][i], cols[5][i],
    ]
}

/// The transformed tiles of `rows` tile rows from tile row `row0` of `x`: `v` holds 36
/// `[tiles, c]` row-major matrices, one per point, [`point_stride`] apart.
#[inline(always)]
fn input_tiles(x: &Map, row0: usize, rows: usize, v: &mut [f32]) {
    let (c, pw, tw) = (x.c, x.w + 2, x.w / M);
    let tiles = rows * tw;
    let point = point_stride(tiles, c);
    for tr in 0..rows {
        // Output rows 4 tr .. 4 tr + 4 read padded rows 4 tr .. 4 tr + 6.
        let top = (row0 + tr) * M;
        for tc in 0..tw {
            let t = tr * tw + tc;
            let corner = (top * pw + tc * M) * c;
            for ch in (0..c).step_by(L) {
                // B^T d B: down the columns (cols[j][i] = (B^T d)[i][j]), then along the rows.
                // Inlined functions, not closures: a closure built here was compiled on its own,
                // without the vector instructions the dispatch enables (a third of the time).
                let cols = down_columns(bt, &x.data, corner + ch, c, pw * c);
                for i in 0..T {
                    for (j, px) in bt(&across(&cols, i)).into_iter().enumerate() {
                        store(v, (i * T + j) * point + t * c + ch, px);
                    }
                }
            }
        }
    }
}

/// The output pixels of the products `prod` (36 `[tiles, c_out]` matrices over tile rows of
/// `tw` tiles, [`point_stride`] apart) into `out`, the product rows of those output rows (`pw`
/// pixels each; the last two of each row are not written).
#[inline(always)]
fn output_tiles(prod: &[f32], tiles: usize, tw: usize, c_out: usize, pw: usize, out: &mut [f32]) {
    let point = point_stride(tiles, c_out);
    for t in 0..tiles {
        let (tr, tc) = (t / tw, t % tw);
        let corner = (tr * M * pw + tc * M) * c_out;
        for ch in (0..c_out).step_by(L) {
            // A^T m A: down the columns (6 -> 4 rows), then along the rows.
            let cols = down_columns(at, prod, t * c_out + ch, point, T * point);
            for i in 0..M {
                for (j, px) in at(&across(&cols, i)).into_iter().enumerate() {
                    store(out, corner + (i * pw + j) * c_out + ch, px);
                }
            }
        }
    }
}

/// [`input_tiles`] compiled for the CPU's vector instructions (pulp's dispatch inlines
/// `with_simd` into a function built with the detected target features).
fn input_tiles_simd(x: &Map, row0: usize, rows: usize, v: &mut [f32]) {
    struct Run<'a>(&'a Map, usize, usize, &'a mut [f32]);
    impl pulp::WithSimd for Run<'_> {
        type Output = ();
        #[inline(always)]
        fn with_simd<S: pulp::Simd>(self, _simd: S) {
            input_tiles(self.0, self.1, self.2, self.3);
        }
    }
    pulp::Arch::new().dispatch(Run(x, row0, rows, v));
}

/// [`output_tiles`] compiled for the CPU's vector instructions.
fn output_tiles_simd(
    prod: &[f32],
    tiles: usize,
    tw: usize,
    c_out: usize,
    pw: usize,
    out: &mut [f32],
) {
    struct Run<'a>(&'a [f32], [usize; 4], &'a mut [f32]);
    impl pulp::WithSimd for Run<'_> {
        type Output = ();
        #[inline(always)]
        fn with_simd<S: pulp::Simd>(self, _simd: S) {
            let [tiles, tw, c_out, pw] = self.1;
            output_tiles(self.0, tiles, tw, c_out, pw, self.2);
        }
    }
    pulp::Arch::new().dispatch(Run(prod, [tiles, tw, c_out, pw], out));
}

/// The 3 x 3 convolution of maps of one size summed over `inputs`, written into `dst` as
/// [`super::infer::conv3_f32`] writes it: `h (w + 2)` product rows of `c_out` values, row
/// q = r (w + 2) + col the output pixel (r, col); columns w and w + 1 of each row are left as
/// they were. The maps and channel counts must satisfy [`fits`]. Blocks of tile rows run on
/// the current rayon pool when `par` is a pool, else on this thread.
pub(super) fn conv3(dst: &mut [f32], inputs: &[(&Map, &Weights)], c_out: usize, par: Par) {
    let (h, w) = (inputs[0].0.h, inputs[0].0.w);
    debug_assert!(fits(
        h,
        w,
        &inputs.iter().map(|(x, _)| x.c).collect::<Vec<_>>(),
        c_out
    ));
    let (pw, tw) = (w + 2, w / M);
    let block_rows = BLOCK_TILES.div_ceil(tw).max(1);
    let row_values = M * pw * c_out;
    let body = |(b, out): (usize, &mut [f32])| {
        let rows = out.len() / row_values;
        let tiles = rows * tw;
        let sp = point_stride(tiles, c_out);
        let mut prod = take(P * sp);
        for (k, (x, wt)) in inputs.iter().enumerate() {
            debug_assert_eq!((x.c, wt.c_out), (wt.c_in, c_out));
            let ci = wt.c_in;
            let sv = point_stride(tiles, ci);
            let mut v = take(P * sv);
            input_tiles_simd(x, b * block_rows, rows, &mut v);
            for p in 0..P {
                matmul(
                    MatMut::from_row_major_slice_mut(
                        &mut prod[p * sp..p * sp + tiles * c_out],
                        tiles,
                        c_out,
                    ),
                    if k == 0 { Accum::Replace } else { Accum::Add },
                    MatRef::from_row_major_slice(&v[p * sv..p * sv + tiles * ci], tiles, ci),
                    MatRef::from_row_major_slice(
                        &wt.u[p * ci * c_out..(p + 1) * ci * c_out],
                        ci,
                        c_out,
                    ),
                    1.0f32,
                    Par::Seq,
                );
            }
            give(v);
        }
        output_tiles_simd(&prod, tiles, tw, c_out, pw, out);
        give(prod);
    };
    let dst = &mut dst[..h * pw * c_out];
    if matches!(par, Par::Rayon(_)) {
        dst.par_chunks_mut(block_rows * row_values)
            .enumerate()
            .for_each(body);
    } else {
        dst.chunks_mut(block_rows * row_values)
            .enumerate()
            .for_each(body);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Deterministic values in [-1, 1].
    fn wave(n: usize, k: usize) -> Vec<f32> {
        (0..n)
            .map(|i| ((i * 13 + k * 7) as f32 * 0.291).sin())
            .collect()
    }

    /// A map of `c` channels with values at every interior pixel and a zero border.
    fn map(h: usize, w: usize, c: usize, k: usize) -> Map {
        let x = wave(c * h * w, k);
        Map::from_chw(&x, c, h, w, Par::Seq)
    }

    /// The convolution by its definition, in `f64`: output (r, col, co) is the sum over dy, dx
    /// and ci of the padded input at (r + dy, col + dx) times the tap. Also the sum of the
    /// terms' magnitudes per output.
    fn direct(x: &Map, taps: &[Vec<f32>; 3], c_out: usize) -> (Vec<f64>, Vec<f64>) {
        let (h, w, c, pw) = (x.h, x.w, x.c, x.w + 2);
        let mut y = vec![0.0f64; h * w * c_out];
        let mut mag = vec![0.0f64; h * w * c_out];
        for r in 0..h {
            for col in 0..w {
                for (dy, tap) in taps.iter().enumerate() {
                    for dx in 0..3 {
                        for ci in 0..c {
                            let v = f64::from(x.data[((r + dy) * pw + col + dx) * c + ci]);
                            for co in 0..c_out {
                                let term = v * f64::from(tap[(dx * c + ci) * c_out + co]);
                                y[(r * w + col) * c_out + co] += term;
                                mag[(r * w + col) * c_out + co] += term.abs();
                            }
                        }
                    }
                }
            }
        }
        (y, mag)
    }

    /// The largest error relative to the largest sum of the terms' magnitudes: the transforms'
    /// coefficients (up to 8 in A, 5 in B, 1/24 in G) amplify f32's round-off (6e-8) by tens
    /// (measured at most 3.2e-6 over 1,000 cases of the property test below). Relative to
    /// the largest output instead, where the terms cancel, it reached 1.2e-4.
    const TOLERANCE: f64 = 2e-5;

    /// Winograd's product rows for inputs of `cs` channels (values from `seed`) to `c_out`
    /// channels on `h` x `w` maps, on this thread or on `pool`, against the convolution by
    /// definition: the largest error relative to the largest sum of the terms' magnitudes.
    /// Asserts that the junk columns are left untouched.
    fn worst_error(
        h: usize,
        w: usize,
        cs: &[usize],
        c_out: usize,
        seed: usize,
        pool: Option<&rayon::ThreadPool>,
    ) -> f64 {
        assert!(fits(h, w, cs, c_out));
        let maps: Vec<Map> = cs
            .iter()
            .enumerate()
            .map(|(k, &c)| map(h, w, c, seed + k))
            .collect();
        let taps: Vec<[Vec<f32>; 3]> = cs
            .iter()
            .enumerate()
            .map(|(k, &c)| std::array::from_fn(|dy| wave(3 * c * c_out, seed + 10 * k + dy + 3)))
            .collect();
        let mut want = vec![0.0f64; h * w * c_out];
        let mut mag = vec![0.0f64; h * w * c_out];
        for (x, t) in maps.iter().zip(&taps) {
            let (y, m) = direct(x, t, c_out);
            want.iter_mut().zip(y).for_each(|(a, b)| *a += b);
            mag.iter_mut().zip(m).for_each(|(a, b)| *a += b);
        }
        let weights: Vec<Weights> = cs
            .iter()
            .zip(&taps)
            .map(|(&c, t)| Weights::new(t, c, c_out))
            .collect();
        let inputs: Vec<(&Map, &Weights)> = maps.iter().zip(&weights).collect();
        let pw = w + 2;
        let mut dst = vec![f32::NAN; h * pw * c_out];
        match pool {
            Some(p) => p.install(|| conv3(&mut dst, &inputs, c_out, Par::rayon(0))),
            None => conv3(&mut dst, &inputs, c_out, Par::Seq),
        }
        let scale = mag.iter().fold(0.0f64, |m, v| m.max(*v));
        let mut worst = 0.0f64;
        for r in 0..h {
            for col in 0..pw {
                for co in 0..c_out {
                    let got = dst[(r * pw + col) * c_out + co];
                    if col >= w {
                        assert!(got.is_nan(), "junk column {col} written");
                    } else {
                        let e = want[(r * w + col) * c_out + co];
                        worst = worst.max((f64::from(got) - e).abs() / scale);
                    }
                }
            }
        }
        worst
    }

    /// A pool of two threads.
    fn pool() -> rayon::ThreadPool {
        rayon::ThreadPoolBuilder::new()
            .num_threads(2)
            .build()
            .unwrap()
    }

    /// Against the convolution by definition, summed over one or two inputs of different
    /// widths, on one thread and on a pool, at sizes with one and several blocks and a last
    /// block shorter than the rest.
    #[test]
    fn matches_the_convolution_by_definition() {
        let pool = pool();
        for (h, w, cs, c_out) in [
            (4, 4, vec![8], 8),
            (8, 12, vec![16, 8], 24),
            (36, 8, vec![8, 8], 16),
            (20, 400, vec![8], 8),
        ] {
            for p in [None, Some(&pool)] {
                let worst = worst_error(h, w, &cs, c_out, 0, p);
                eprintln!("{h} x {w} {cs:?} -> {c_out}: worst error {worst:.2e} of the magnitudes");
                assert!(
                    worst < TOLERANCE,
                    "{h} x {w} {cs:?} -> {c_out}: {worst:.2e}"
                );
            }
        }
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(48))]
        /// Any whole-tile size (4 to 40 rows, 4 to 56 columns), one to three inputs of 8 to 24
        /// channels, 8 to 32 outputs, any values, on one thread or the pool: within the
        /// tolerance of the convolution by definition.
        #[test]
        fn matches_the_definition_on_any_fitting_shape(
            th in 1usize..=10,
            tw in 1usize..=14,
            cs in proptest::collection::vec(1usize..=3, 1..=3),
            c_out in 1usize..=4,
            seed in 0usize..1000,
            pooled: bool,
        ) {
            let cs: Vec<usize> = cs.iter().map(|c| c * L).collect();
            let pool = pool();
            let worst = worst_error(4 * th, 4 * tw, &cs, c_out * L, seed, pooled.then_some(&pool));
            proptest::prop_assert!(worst < TOLERANCE, "{worst:.2e}");
        }
    }

    /// Where the path applies: whole tiles and whole vectors of channels only.
    #[test]
    fn fits_only_whole_tiles_and_vectors() {
        assert!(fits(240, 320, &[32, 32], 32));
        assert!(!fits(30, 40, &[32], 32));
        assert!(!fits(240, 320, &[3], 32));
        assert!(!fits(240, 320, &[32], 3));
        assert!(!fits(0, 320, &[32], 32));
    }
}
