//! Integer arithmetic of the lookups: uniform-grid location, linear
//! interpolation with Q16 weights, bounded bisection and a 64-by-32-bit
//! division that avoids the 64-bit division routine.
//!
//! Values travel as `i64` holding a table's raw fixed-point bits. The parser
//! bounds every grid (`2..=MAX_GRID_POINTS` points, `i32` bounds, positive
//! spans), which keeps the products below `2^62`; the saturating operations are
//! a second fence so that no input can overflow or panic.

use core::num::NonZeroU32;

/// One, as a Q16 interpolation weight.
pub(crate) const ONE: i64 = 1 << 16;

/// `n / d` rounded down, exactly, or `None` for `d = 0`.
///
/// A Cortex-M4 divides 32-bit integers in hardware but 64-bit ones in a
/// library routine costing a few hundred instructions; this splits the
/// dividend into 32-bit digits and uses two hardware divisions per digit
/// (Knuth's algorithm D with 16-bit half-digits, as in Hacker's Delight
/// 9-3), a few dozen instructions in all.
pub fn udiv_u64_by_u32(n: u64, d: u32) -> Option<u64> {
    let d = NonZeroU32::new(d)?;
    let hi = (n >> 32) as u32;
    let lo = n as u32;
    if hi == 0 {
        return Some(u64::from(lo / d));
    }
    let q_hi = hi / d;
    // `hi % d < d`, so the second digit's quotient fits 32 bits.
    let r_hi = hi - q_hi * d.get();
    let q_lo = div_2by1(r_hi, lo, d);
    Some((u64::from(q_hi) << 32) | u64::from(q_lo))
}

/// `(hi * 2^32 + lo) / d` for `hi < d`: the quotient then fits 32 bits.
fn div_2by1(hi: u32, lo: u32, d: NonZeroU32) -> u32 {
    const B: u32 = 1 << 16;
    let s = d.leading_zeros();
    // Normalized so that the divisor's top bit is set; `hi < d` keeps the
    // shifted dividend inside 64 bits.
    let v = d.get() << s;
    let n = ((u64::from(hi) << 32) | u64::from(lo)) << s;
    let un32 = (n >> 32) as u32;
    let un10 = n as u32;
    let (un1, un0) = (un10 >> 16, un10 & (B - 1));
    // `v >= 2^31`, so its high half is at least 2^15.
    let vn1 = NonZeroU32::new(v >> 16).unwrap_or(NonZeroU32::MIN);
    let vn0 = v & (B - 1);
    let digit = |top: u32, next: u32| {
        // Estimate from the divisor's high half, then correct at most twice.
        let mut q = top / vn1;
        let mut rhat = top - q * vn1.get();
        while q >= B || q.wrapping_mul(vn0) > ((rhat << 16) | next) {
            q -= 1;
            rhat += vn1.get();
            if rhat >= B {
                break;
            }
        }
        q
    };
    let q1 = digit(un32, un1);
    let un21 = (un32 << 16)
        .wrapping_add(un1)
        .wrapping_sub(q1.wrapping_mul(v));
    let q0 = digit(un21, un0);
    (q1 << 16) | q0
}

/// `floor(n / d)` for `d > 0`; 32-bit divisors take the fast division.
#[inline(always)]
fn floor_div(n: i64, d: i64) -> i64 {
    let Ok(d32) = u32::try_from(d) else {
        return n.div_euclid(d.max(1));
    };
    if d32.is_power_of_two() {
        // An arithmetic shift rounds towards minus infinity, as wanted.
        return n >> d32.trailing_zeros();
    }
    if let (Ok(n32), Some(d)) = (u32::try_from(n), NonZeroU32::new(d32)) {
        // The common case of the lookups: one hardware division.
        return i64::from(n32 / d);
    }
    let a = n.unsigned_abs();
    let q = udiv_u64_by_u32(a, d32).unwrap_or(0);
    if n >= 0 {
        q as i64
    } else {
        // Round towards minus infinity; wrapping covers `n = i64::MIN, d = 1`.
        let exact = q.wrapping_mul(u64::from(d32)) == a;
        (q as i64).wrapping_neg().wrapping_sub(i64::from(!exact))
    }
}

/// `num / den` rounded to nearest (ties up). `den` is positive for every
/// caller; clamping it keeps the function total.
#[inline(always)]
pub(crate) fn div_round(num: i64, den: i64) -> i64 {
    let den = den.max(1);
    floor_div(num.saturating_add(den / 2), den)
}

/// `a * b`, saturating. Factors that fit `i32` (every product of the
/// lookups on a valid image) take one 32x32->64 multiply; only others pay
/// for the overflow check, which a 32-bit core does in a library routine.
#[inline(always)]
pub(crate) fn mul_sat(a: i64, b: i64) -> i64 {
    match (i32::try_from(a), i32::try_from(b)) {
        (Ok(a), Ok(b)) => i64::from(a) * i64::from(b),
        _ => a.saturating_mul(b),
    }
}

/// `x * ONE` (a shift by 16), saturating.
#[inline(always)]
pub(crate) fn mul_one(x: i64) -> i64 {
    const LIMIT: i64 = i64::MAX >> 16;
    if (-LIMIT..=LIMIT).contains(&x) {
        x << 16
    } else if x < 0 {
        i64::MIN
    } else {
        i64::MAX
    }
}

/// `x / 2^shift` rounded to nearest (ties up), `shift` in `0..=62`.
#[inline(always)]
pub(crate) fn shr_round(x: i64, shift: u32) -> i64 {
    match shift {
        0 => x,
        1..=62 => x.saturating_add(1 << (shift - 1)) >> shift,
        _ => 0,
    }
}

/// `a + (b - a) t` with `t` a Q16 weight (any sign, for extrapolation).
#[inline(always)]
pub(crate) fn lerp(a: i64, b: i64, t_q16: i64) -> i64 {
    a.saturating_add(shr_round(mul_sat(b.saturating_sub(a), t_q16), 16))
}

/// Saturates to the `i32` bits of an output type.
#[inline(always)]
pub(crate) fn saturate_i32(x: i64) -> i32 {
    // The clamp makes the conversion lossless.
    x.clamp(i64::from(i32::MIN), i64::from(i32::MAX)) as i32
}

/// A uniform grid `min + i (max - min) / (points - 1)` in raw bits.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Uniform {
    pub min: i64,
    pub max: i64,
    pub points: u16,
}

impl Uniform {
    /// Number of cells, at least 1.
    #[inline(always)]
    fn cells(self) -> i64 {
        i64::from(self.points.max(2) - 1)
    }

    /// Width of the grid, at least 1.
    #[inline(always)]
    fn span(self) -> i64 {
        (self.max - self.min).max(1)
    }

    /// Index of the last point.
    pub fn last(self) -> usize {
        usize::from(self.points.max(2) - 1)
    }

    /// Cell containing `x` (index in `0..points-1`) and the Q16 position of
    /// `x` inside it; outside the grid the end cell is extended, so the weight
    /// leaves `0..=ONE` (extrapolation).
    ///
    /// One rounded division gives the Q16 position on the whole grid; its
    /// integer part is the cell. A position rounded up onto a grid point
    /// lands at weight 0 of the next cell, which interpolates to the same
    /// value as weight `ONE` of the cell before.
    pub fn locate(self, x: i64) -> (usize, i64) {
        let cells = self.cells();
        // |x - min| < 2^33 and cells < 2^12: the product stays below 2^61.
        let pos = mul_one(mul_sat(x.saturating_sub(self.min), cells));
        let pos_q16 = div_round(pos, self.span());
        let index = (pos_q16 >> 16).clamp(0, cells - 1);
        let weight = pos_q16.saturating_sub(index * ONE);
        // `index` lies in 0..cells, which fits a `u16`.
        (index as usize, weight)
    }

    /// Like [`Self::locate`] but holds `x` to the grid, saying on which side
    /// it was held.
    pub fn locate_clamped(self, x: i64) -> (usize, i64, Side) {
        if x < self.min {
            (0, 0, Side::Below)
        } else if x > self.max {
            (self.last() - 1, ONE, Side::Above)
        } else {
            let (i, w) = self.locate(x);
            (i, w.clamp(0, ONE), Side::Inside)
        }
    }

    /// Raw value at a fractional index given in Q16 (`index * ONE + weight`).
    pub fn at_q16(self, pos_q16: i64) -> i64 {
        self.min
            .saturating_add(div_round(mul_sat(self.span(), pos_q16), self.cells() * ONE))
    }
}

/// Where an input fell relative to the range a table covers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Side {
    Below,
    Inside,
    Above,
}

/// Fractional index (Q16) where the row `f(0..=last)`, assumed non-decreasing,
/// reaches `target`. Targets below `f(0)` or above `f(last)` return the end
/// index and the side. Evaluates `f` at most `ceil(log2(last)) + 2` times.
pub(crate) fn invert_row(last: usize, target: i64, f: impl Fn(usize) -> i64) -> (i64, Side) {
    let (pos, side, _) = invert_row_near(last, target, &f, None);
    (pos, side)
}

/// [`invert_row`] that first tries the cell `guess` (two evaluations of
/// `f`) and bisects only when the target does not lie in it; also returns
/// the cell found, to guess with next time. On a non-decreasing row the
/// cell with `f(i) <= target < f(i + 1)` is unique, so a right guess gives
/// exactly the bisection's answer.
pub(crate) fn invert_row_near(
    last: usize,
    target: i64,
    f: impl Fn(usize) -> i64,
    guess: Option<usize>,
) -> (i64, Side, usize) {
    if let Some(lo) = guess.filter(|&g| g < last) {
        let (f_lo, f_hi) = (f(lo), f(lo + 1));
        if f_lo <= target && target < f_hi {
            return (cell_q16(lo, target, f_lo, f_hi), Side::Inside, lo);
        }
    }
    let last_q16 = (last as i64) * ONE;
    let first = f(0);
    if target < first {
        return (0, Side::Below, 0);
    }
    let end = f(last);
    if target >= end {
        let side = if target > end {
            Side::Above
        } else {
            Side::Inside
        };
        return (last_q16, side, last.saturating_sub(1));
    }
    // Invariant: f(lo) <= target < f(hi).
    let (mut lo, mut hi) = (0usize, last);
    let (mut f_lo, mut f_hi) = (first, end);
    while hi - lo > 1 {
        let mid = lo + (hi - lo) / 2;
        let f_mid = f(mid);
        if f_mid <= target {
            lo = mid;
            f_lo = f_mid;
        } else {
            hi = mid;
            f_hi = f_mid;
        }
    }
    (cell_q16(lo, target, f_lo, f_hi), Side::Inside, lo)
}

/// Q16 index of `target` in cell `lo`, whose ends are `f_lo <= target < f_hi`.
fn cell_q16(lo: usize, target: i64, f_lo: i64, f_hi: i64) -> i64 {
    let weight = div_round(
        mul_one(target.saturating_sub(f_lo)),
        f_hi.saturating_sub(f_lo),
    )
    .clamp(0, ONE);
    (lo as i64) * ONE + weight
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// `floor(num / den)` in 128 bits, the reference for the fast paths.
    fn floor_ref(num: i128, den: i128) -> i128 {
        num.div_euclid(den)
    }

    #[test]
    fn udiv_handles_the_edges() {
        for &(n, d) in &[
            (0u64, 1u32),
            (u64::MAX, 1),
            (u64::MAX, u32::MAX),
            (u64::MAX, 2),
            (u64::MAX, 0x8000_0000),
            (u64::MAX, 0x7fff_ffff),
            ((1u64 << 32) - 1, 3),
            (1u64 << 32, 0xffff),
            (0xffff_fffe_0000_0001, 0xffff_ffff),
        ] {
            assert_eq!(udiv_u64_by_u32(n, d), Some(n / u64::from(d)), "{n} / {d}");
        }
        assert_eq!(udiv_u64_by_u32(5, 0), None);
    }

    proptest! {
        #[test]
        fn udiv_matches_the_native_division(n in any::<u64>(), d in 1u32..) {
            prop_assert_eq!(udiv_u64_by_u32(n, d), Some(n / u64::from(d)));
        }

        #[test]
        fn udiv_matches_for_small_divisors(n in any::<u64>(), d in 1u32..70_000) {
            prop_assert_eq!(udiv_u64_by_u32(n, d), Some(n / u64::from(d)));
        }

        #[test]
        fn div_round_matches_the_wide_reference(
            num in -(1i64 << 62)..(1i64 << 62),
            den in prop_oneof![1i64..(1 << 16), 1i64..(1 << 33), Just(1 << 20)],
        ) {
            let want = floor_ref(i128::from(num) + i128::from(den / 2), i128::from(den));
            prop_assert_eq!(i128::from(div_round(num, den)), want);
        }

        #[test]
        fn locate_splits_one_rounded_position(
            min in -(1i64 << 30)..(1i64 << 30),
            width in 1i64..(1 << 30),
            points in 2u16..200,
            x in -(1i64 << 31)..(1i64 << 31),
        ) {
            let grid = Uniform { min, max: min + width, points };
            let cells = i128::from(points - 1);
            let (i, w) = grid.locate(x);
            // Reference: the Q16 position on the whole grid, rounded once.
            let pos = floor_ref(
                (i128::from(x) - i128::from(min)) * cells * 65_536 + i128::from(width / 2),
                i128::from(width),
            );
            let want_i = (pos >> 16).clamp(0, cells - 1);
            prop_assert_eq!(i as i128, want_i);
            prop_assert_eq!(i128::from(w), pos - want_i * 65_536);
        }

        #[test]
        fn mul_sat_matches_saturating_mul(a in any::<i64>(), b in any::<i64>(), small in -(1i64 << 31)..(1i64 << 31)) {
            prop_assert_eq!(mul_sat(a, b), a.saturating_mul(b));
            prop_assert_eq!(mul_sat(small, b), small.saturating_mul(b));
            prop_assert_eq!(mul_sat(small, small), small.saturating_mul(small));
            prop_assert_eq!(mul_one(a), a.saturating_mul(ONE));
        }
    }
}
