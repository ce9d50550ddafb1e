//! Matrix products with bfloat16 operands and `f32` sums, for the plain U-Net engine's
//! convolutions. On CPUs with AVX-512 BF16 each `vdpbf16ps` does 32 multiply-adds where an
//! `f32` FMA of the same width does 16, which is what lifts a full-size perception image above
//! the `f32` engine's arithmetic ceiling; elsewhere a portable loop does the same arithmetic
//! (each bf16 x bf16 product is exact in `f32`, the sums are rounded in the same order), so
//! both paths give the same values.
//!
//! The kernel is the workspace's one exception to its `unsafe_code` lint: no safe wrapper
//! (std, pulp) exposes the AVX-512 BF16 instructions. The exception is confined to the `x86`
//! module and its two call sites, which enter it only after checking the CPU's features and
//! every row's bounds.

use rayon::prelude::*;

/// Rounds to the nearest bfloat16, ties to even, with subnormals flushed to zero as the
/// instruction set's conversion does; a NaN stays a (quiet) NaN.
pub(crate) fn to_bf16(x: f32) -> u16 {
    let b = x.to_bits();
    if x.is_nan() {
        return ((b >> 16) | 0x40) as u16;
    }
    if b & 0x7f80_0000 == 0 {
        return (b >> 16) as u16 & 0x8000;
    }
    let round = 0x7fff + ((b >> 16) & 1);
    ((b + round) >> 16) as u16
}

/// The `f32` value of a bfloat16.
pub(crate) fn from_bf16(v: u16) -> f32 {
    f32::from_bits(u32::from(v) << 16)
}

/// Writes `src` rounded to bfloat16 into `dst` (same length).
pub(crate) fn convert(src: &[f32], dst: &mut [u16]) {
    assert_eq!(src.len(), dst.len(), "bf16 conversion lengths");
    #[cfg(target_arch = "x86_64")]
    if simd_available() {
        // SAFETY: the CPU has the features the function is compiled for (checked above), and
        // the lengths are equal.
        #[allow(unsafe_code)]
        unsafe {
            x86::convert(src, dst)
        };
        return;
    }
    for (d, s) in dst.iter_mut().zip(src) {
        *d = to_bf16(*s);
    }
}

/// Whether this CPU runs the AVX-512 BF16 kernel (otherwise the portable loop runs).
pub fn simd_available() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx512f")
            && std::arch::is_x86_feature_detected!("avx512bf16")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// Columns per vector of the kernel.
const LANES: usize = 16;

/// A `k x n` matrix in bfloat16, packed for the kernel: rows in pairs (2p, 2p + 1), each
/// column's pair adjacent, columns padded with zeros to a multiple of 16, and an odd last row
/// paired with a zero row.
#[derive(Debug, Clone)]
pub(crate) struct Packed {
    k: usize,
    n: usize,
    n_pad: usize,
    data: Vec<u16>,
}

impl Packed {
    /// From a row-major `k x n` matrix.
    pub(crate) fn new(b: &[f32], k: usize, n: usize) -> Self {
        assert_eq!(b.len(), k * n, "packed matrix size");
        let n_pad = n.div_ceil(LANES) * LANES;
        let pairs = k.div_ceil(2);
        let mut data = vec![0u16; pairs * n_pad * 2];
        for r in 0..k {
            for c in 0..n {
                data[((r / 2) * n_pad + c) * 2 + r % 2] = to_bf16(b[r * n + c]);
            }
        }
        Packed { k, n, n_pad, data }
    }

    /// Row pairs.
    fn pairs(&self) -> usize {
        self.k.div_ceil(2)
    }

    /// Element (row pair p, column c, half h) as an `f32`.
    fn at(&self, p: usize, c: usize, h: usize) -> f32 {
        from_bf16(self.data[(p * self.n_pad + c) * 2 + h])
    }
}

/// One term of a fused product: row q of its left matrix is `b.k` consecutive values of `src`
/// starting at `offset + q * stride` (rows may overlap, as a convolution's shifted views do).
pub(crate) struct Term<'a> {
    /// The left matrix's values.
    pub src: &'a [u16],
    /// Start of row 0.
    pub offset: usize,
    /// Distance between consecutive rows.
    pub stride: usize,
    /// The right matrix.
    pub b: &'a Packed,
}

impl Term<'_> {
    /// Whether rows 0..m can be read, a whole pair past an odd k included.
    fn fits(&self, m: usize) -> bool {
        m == 0 || self.offset + (m - 1) * self.stride + 2 * self.b.pairs() <= self.src.len()
    }
}

/// `dst[q * n + c]` = sum over the terms and their k of `A_t[q, k] B_t[k, c]`, for rows
/// `q < m` and the terms' `n` columns; each product is exact in `f32`, and per row pair the
/// odd row's product is added before the even one's (the order `vdpbf16ps` sums in). Rows run
/// in parallel on the current rayon pool when `parallel`.
///
/// Panics when the terms disagree on `n`, a term's rows reach past its values, or `dst` is not
/// `m x n`: the engine builds these from sizes it has already checked.
pub(crate) fn product(terms: &[Term], m: usize, dst: &mut [f32], parallel: bool) {
    let n = terms.first().map_or(0, |t| t.b.n);
    assert!(
        terms.iter().all(|t| t.b.n == n && t.fits(m)) && dst.len() == m * n,
        "bf16 product: inconsistent terms or destination"
    );
    if m == 0 || n == 0 {
        return;
    }
    // Row blocks of a few hundred rows: enough work per task, and a whole number of the
    // kernel's tiles.
    const ROWS_PER_TASK: usize = 384;
    let run = |(i, chunk): (usize, &mut [f32])| {
        let q0 = i * ROWS_PER_TASK;
        let rows = chunk.len() / n;
        #[cfg(target_arch = "x86_64")]
        if simd_available() {
            // SAFETY: the features are present (checked above) and every term's rows
            // q0..q0 + rows lie inside its values (checked by `fits` for all m rows).
            #[allow(unsafe_code)]
            unsafe {
                x86::rows(terms, q0, rows, chunk)
            };
            return;
        }
        portable_rows(terms, q0, rows, chunk);
    };
    if parallel {
        dst.par_chunks_mut(ROWS_PER_TASK * n)
            .enumerate()
            .for_each(run);
    } else {
        dst.chunks_mut(ROWS_PER_TASK * n).enumerate().for_each(run);
    }
}

/// [`product`]'s arithmetic in plain Rust, rows `q0..q0 + rows` into `dst`.
fn portable_rows(terms: &[Term], q0: usize, rows: usize, dst: &mut [f32]) {
    let n = terms[0].b.n;
    for (i, out) in dst.chunks_exact_mut(n).take(rows).enumerate() {
        out.fill(0.0);
        for t in terms {
            let row = t.offset + (q0 + i) * t.stride;
            for p in 0..t.b.pairs() {
                let a0 = from_bf16(t.src[row + 2 * p]);
                let a1 = from_bf16(t.src[row + 2 * p + 1]);
                for (c, o) in out.iter_mut().enumerate() {
                    // An odd k's padding row is zero, but 0 times a non-finite value past the
                    // row is not: the kernel multiplies it all the same, so this does too.
                    *o += a1 * t.b.at(p, c, 1);
                    *o += a0 * t.b.at(p, c, 0);
                }
            }
        }
    }
}

#[cfg(target_arch = "x86_64")]
#[allow(unsafe_code)]
mod x86 {
    use super::{LANES, Term};
    use std::arch::x86_64::*;

    /// Rounds `src` to bfloat16 into `dst`, 16 values per instruction.
    ///
    /// # Safety
    /// The CPU must have AVX-512F and AVX-512 BF16; the slices must have equal lengths.
    #[target_feature(enable = "avx512f,avx512bf16")]
    pub(super) unsafe fn convert(src: &[f32], dst: &mut [u16]) {
        let full = src.len() / LANES * LANES;
        for i in (0..full).step_by(LANES) {
            // SAFETY: i + 16 <= full <= both lengths.
            unsafe {
                let v = _mm512_loadu_ps(src.as_ptr().add(i));
                let b: __m256bh = _mm512_cvtneps_pbh(v);
                _mm256_storeu_si256(
                    dst.as_mut_ptr().add(i).cast::<__m256i>(),
                    std::mem::transmute::<__m256bh, __m256i>(b),
                );
            }
        }
        for i in full..src.len() {
            dst[i] = super::to_bf16(src[i]);
        }
    }

    /// Rows `q0..q0 + rows` of the fused product into `dst` (`rows x n`), tiles of MR rows
    /// and NV vectors of 16 columns, then the remaining rows one at a time.
    ///
    /// # Safety
    /// The CPU must have AVX-512F and AVX-512 BF16, every term's rows `q0..q0 + rows` must lie
    /// inside its values (a whole last pair included), the terms must share `n` and `dst` must
    /// hold `rows x n` values.
    #[target_feature(enable = "avx512f,avx512bf16")]
    pub(super) unsafe fn rows(terms: &[Term], q0: usize, rows: usize, dst: &mut [f32]) {
        let b = terms[0].b;
        let vecs = b.n_pad / LANES;
        // (tile rows, column vectors, the whole-tile kernel, its one-row kernel)
        let (mr, nv, tile, tail): (usize, usize, Tile, Tile) = if vecs.is_multiple_of(4) {
            (6, 4, tile_6x4, tile_1x4)
        } else if vecs.is_multiple_of(2) {
            (12, 2, tile_12x2, tile_1x2)
        } else {
            (12, 1, tile_12x1, tile_1x1)
        };
        let whole = rows / mr * mr;
        let starts = (0..whole).step_by(mr).map(|i| (i, tile));
        for (i, kernel) in starts.chain((whole..rows).map(|i| (i, tail))) {
            for v0 in (0..vecs).step_by(nv) {
                let out = &mut dst[i * b.n..];
                for (k, t) in terms.iter().enumerate() {
                    // SAFETY: the tile's rows lie in q0..q0 + rows and its columns in
                    // 0..n_pad (the stores are masked to n), as the caller guarantees.
                    unsafe { kernel(t, q0 + i, v0, out, k == 0) };
                }
            }
        }
    }

    /// A tile kernel: term, first row, first column vector, destination rows, whether the
    /// tile starts from zero.
    type Tile = unsafe fn(&Term, usize, usize, &mut [f32], bool);

    /// One row of a tile: the row's pair of A values broadcast, times each column vector.
    macro_rules! dot_row {
        ($acc:ident, $i:literal, $av:ident, $bv:ident, [$($j:literal),*]) => {
            $( $acc[$i][$j] = _mm512_dpbf16_ps($acc[$i][$j], $av, $bv[$j]); )*
        };
        (@load $acc:ident, $i:literal, $out:ident, $n:ident, $masks:ident, [$($j:literal),*]) => {
            $(
                $acc[$i][$j] = _mm512_maskz_loadu_ps(
                    $masks[$j],
                    $out.wrapping_add($n.wrapping_mul($i) + $j * LANES),
                );
            )*
        };
        (@store $acc:ident, $i:literal, $out:ident, $n:ident, $masks:ident, [$($j:literal),*]) => {
            $(
                _mm512_mask_storeu_ps(
                    $out.wrapping_add($n.wrapping_mul($i) + $j * LANES),
                    $masks[$j],
                    $acc[$i][$j],
                );
            )*
        };
    }

    /// A tile kernel of fixed shape, written out row by row so the accumulators stay in
    /// registers (loops over arrays of vectors kept them on the stack), for one term at a
    /// time (the sum over terms inside the kernel spilled them too).
    macro_rules! tile_kernel {
        ($name:ident, $mr:literal, $nv:literal, [$($i:literal),*], $js:tt) => {
            /// One tile of the product at row q and vector column v0 for term t, started from
            /// zero (`first`) or from the values in `dst`, and stored (masked at the last
            /// columns).
            ///
            /// # Safety
            /// As [`rows`], for rows q..q + MR and vector columns v0..v0 + NV.
            #[target_feature(enable = "avx512f,avx512bf16")]
            unsafe fn $name(t: &Term, q: usize, v0: usize, dst: &mut [f32], first: bool) {
                let n = t.b.n;
                let masks: [u16; $nv] = std::array::from_fn(|j| {
                    let col = (v0 + j) * LANES;
                    if col >= n {
                        0
                    } else if n - col >= LANES {
                        u16::MAX
                    } else {
                        ((1u32 << (n - col)) - 1) as u16
                    }
                });
                let out = dst.as_mut_ptr().wrapping_add(v0 * LANES);
                let mut acc = [[_mm512_setzero_ps(); $nv]; $mr];
                // SAFETY (this block and the next): rows q..q + MR of the term, the packed
                // columns of the tile and rows 0..MR of dst exist (caller); the masks keep
                // every access of dst inside its n columns. Wrapping arithmetic and masked
                // loads: the offsets stay in bounds, and checked arithmetic, `add` and
                // `read_unaligned` cost a test per access, and spilled accumulators, in builds
                // with debug assertions (the dev profile), where the same loop ran at 40 % of
                // the speed.
                unsafe {
                    if !first {
                        $( dot_row!(@load acc, $i, out, n, masks, $js); )*
                    }
                    let stride = t.stride;
                    let mut ap = t.src.as_ptr().wrapping_add(t.offset + q * stride);
                    let mut bp = t.b.data.as_ptr().wrapping_add(v0 * LANES * 2);
                    let row_pairs = t.b.n_pad * 2;
                    for _ in 0..t.b.pairs() {
                        let bv: [__m512bh; $nv] = std::array::from_fn(|j| {
                            std::mem::transmute::<__m512i, __m512bh>(_mm512_maskz_loadu_epi32(
                                u16::MAX,
                                bp.wrapping_add(j * LANES * 2).cast(),
                            ))
                        });
                        $(
                            let pair = _mm512_maskz_loadu_epi32(
                                1,
                                ap.wrapping_add(stride.wrapping_mul($i)).cast(),
                            );
                            let av = std::mem::transmute::<__m512i, __m512bh>(
                                _mm512_broadcastd_epi32(_mm512_castsi512_si128(pair)),
                            );
                            dot_row!(acc, $i, av, bv, $js);
                        )*
                        bp = bp.wrapping_add(row_pairs);
                        ap = ap.wrapping_add(2);
                    }
                    $( dot_row!(@store acc, $i, out, n, masks, $js); )*
                }
            }
        };
    }

    tile_kernel!(tile_6x4, 6, 4, [0, 1, 2, 3, 4, 5], [0, 1, 2, 3]);
    tile_kernel!(
        tile_12x2,
        12,
        2,
        [0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11],
        [0, 1]
    );
    tile_kernel!(
        tile_12x1,
        12,
        1,
        [0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11],
        [0]
    );
    tile_kernel!(tile_1x4, 1, 4, [0], [0, 1, 2, 3]);
    tile_kernel!(tile_1x2, 1, 2, [0], [0, 1]);
    tile_kernel!(tile_1x1, 1, 1, [0], [0]);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rounding_to_bf16_is_nearest_even() {
        // 1 + 2^-8 lies halfway between 1 and 1 + 2^-7: ties go to the even mantissa (1).
        assert_eq!(to_bf16(1.0 + 2f32.powi(-8)), to_bf16(1.0));
        assert_eq!(
            from_bf16(to_bf16(1.0 + 3.0 * 2f32.powi(-8))),
            1.0 + 2f32.powi(-6)
        );
        assert_eq!(from_bf16(to_bf16(-2.5)), -2.5);
        assert!(from_bf16(to_bf16(f32::NAN)).is_nan());
        assert_eq!(from_bf16(to_bf16(1e-40)), 0.0);
        assert_eq!(from_bf16(to_bf16(f32::INFINITY)), f32::INFINITY);
        // Every value's error is at most half a unit in the last of its 8 significant bits.
        for i in 0..2000 {
            let x = ((i as f32) * 0.731).sin() * 10f32.powi(i % 7 - 3);
            let y = from_bf16(to_bf16(x));
            assert!((y - x).abs() <= x.abs() * 2f32.powi(-8), "{x} -> {y}");
        }
        // The vector conversion agrees with the scalar one, tail included.
        let xs: Vec<f32> = (0..37).map(|i| (i as f32 * 1.37).cos() * 3.0).collect();
        let mut v = vec![0u16; xs.len()];
        convert(&xs, &mut v);
        let s: Vec<u16> = xs.iter().map(|&x| to_bf16(x)).collect();
        assert_eq!(v, s);
    }

    fn values(n: usize, seed: f32) -> Vec<f32> {
        (0..n)
            .map(|i| ((i as f32 + seed) * 0.618).sin() * 2.0)
            .collect()
    }

    /// The fused product of overlapping-row terms, odd k and a column count that is not a
    /// multiple of 16 included, against an f64 sum of the same bf16 operands, and the SIMD
    /// kernel (where the CPU has it) against the portable loop bit for bit.
    #[test]
    fn product_matches_f64_sums_of_the_rounded_operands() {
        for &(m, n, k1, k2) in &[
            (29, 32, 9, 96),
            (40, 64, 192, 6),
            (13, 20, 7, 5),
            (7, 128, 2, 3),
        ] {
            let (s1, s2) = (3, 5);
            let mut src1: Vec<u16> = values(m * s1 + k1 + 2, 0.3)
                .iter()
                .map(|&x| to_bf16(x))
                .collect();
            let mut src2: Vec<u16> = values(m * s2 + k2 + 9, 1.7)
                .iter()
                .map(|&x| to_bf16(x))
                .collect();
            // The value just past an odd row is read and multiplied by the zero padding.
            src1.push(0);
            src2.push(0);
            let (b1, b2) = (values(k1 * n, 2.1), values(k2 * n, 4.4));
            let (p1, p2) = (Packed::new(&b1, k1, n), Packed::new(&b2, k2, n));
            let terms = [
                Term {
                    src: &src1,
                    offset: 2,
                    stride: s1,
                    b: &p1,
                },
                Term {
                    src: &src2,
                    offset: 7,
                    stride: s2,
                    b: &p2,
                },
            ];
            let mut got = vec![f32::NAN; m * n];
            product(&terms, m, &mut got, true);
            let mut portable = vec![f32::NAN; m * n];
            portable_rows(&terms, 0, m, &mut portable);
            assert_eq!(got, portable, "kernel and portable loop, m {m} n {n}");
            let rb = |b: &[f32], r: usize, c: usize| f64::from(from_bf16(to_bf16(b[r * n + c])));
            for q in 0..m {
                for c in 0..n {
                    let (mut want, mut size) = (0.0f64, 0.0f64);
                    for (t, b, k) in [(&terms[0], &b1, k1), (&terms[1], &b2, k2)] {
                        for r in 0..k {
                            let a = f64::from(from_bf16(t.src[t.offset + q * t.stride + r]));
                            want += a * rb(b, r, c);
                            size += (a * rb(b, r, c)).abs();
                        }
                    }
                    let err = (f64::from(got[q * n + c]) - want).abs();
                    assert!(
                        err <= size * 1e-6,
                        "m {m} n {n} row {q} col {c}: {} against {want}",
                        got[q * n + c]
                    );
                }
            }
        }
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(64))]
        /// Any shapes (rows, columns not a multiple of 16, odd or even k, overlapping or
        /// spread rows, one to three terms): the kernel equals the portable loop bit for bit
        /// and every sum lies within 1e-6 of its magnitudes of the f64 sum.
        #[test]
        fn kernel_equals_the_portable_loop_on_any_shape(
            m in 1usize..80,
            n in 1usize..70,
            ks in proptest::collection::vec((1usize..40, 1usize..50, 0usize..9), 1..4),
            seed in 0u32..1000,
        ) {
            let srcs: Vec<Vec<u16>> = ks
                .iter()
                .enumerate()
                .map(|(t, &(k, stride, offset))| {
                    let len = offset + (m - 1) * stride + k + 1;
                    values(len, (seed as usize * 7 + t) as f32)
                        .iter()
                        .map(|&x| to_bf16(x))
                        .collect()
                })
                .collect();
            let bs: Vec<Vec<f32>> = ks
                .iter()
                .enumerate()
                .map(|(t, &(k, _, _))| values(k * n, (seed as usize * 3 + t) as f32 + 0.5))
                .collect();
            let packs: Vec<Packed> =
                ks.iter().zip(&bs).map(|(&(k, _, _), b)| Packed::new(b, k, n)).collect();
            let terms: Vec<Term> = ks
                .iter()
                .zip(&srcs)
                .zip(&packs)
                .map(|((&(_, stride, offset), src), b)| Term { src, offset, stride, b })
                .collect();
            let mut got = vec![f32::NAN; m * n];
            product(&terms, m, &mut got, seed % 2 == 0);
            let mut portable = vec![f32::NAN; m * n];
            portable_rows(&terms, 0, m, &mut portable);
            proptest::prop_assert_eq!(&got, &portable);
            for q in 0..m {
                for c in 0..n {
                    let (mut want, mut size) = (0.0f64, 0.0f64);
                    for ((t, b), &(k, _, _)) in terms.iter().zip(&bs).zip(&ks) {
                        for r in 0..k {
                            let a = f64::from(from_bf16(t.src[t.offset + q * t.stride + r]));
                            let w = f64::from(from_bf16(to_bf16(b[r * n + c])));
                            want += a * w;
                            size += (a * w).abs();
                        }
                    }
                    proptest::prop_assert!((f64::from(got[q * n + c]) - want).abs() <= size * 1e-6);
                }
            }
        }
    }

    #[test]
    fn a_row_past_the_values_is_refused() {
        let src = vec![0u16; 10];
        let p = Packed::new(&[1.0; 8], 4, 2);
        let t = Term {
            src: &src,
            offset: 0,
            stride: 3,
            b: &p,
        };
        assert!(t.fits(3));
        assert!(!t.fits(4));
    }
}
