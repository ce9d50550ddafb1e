//! Fixed-point arithmetic: the Q-formats of the firmware and bounded-time
//! trigonometry and square roots on them.
//!
//! | quantity                        | Q-format (raw `i32`) | resolution   | range        |
//! |---------------------------------|----------------------|--------------|--------------|
//! | length, metres                  | Q8.24                | 6.0e-8 m     | ±128 m       |
//! | force, newtons                  | Q16.16               | 1.5e-5 N     | ±32768 N     |
//! | moment, newton metres           | Q8.24                | 6.0e-8 N*m   | ±128 N*m     |
//! | pressure, pascals               | Q24.8                | 3.9e-3 Pa    | ±8.4 MPa     |
//! | strain (LUT)                    | Q16.16               | 1.5e-5       | ±32768       |
//! | angle, radians                  | Q3.28                | 3.7e-9 rad   | ±8 rad       |
//! | unit quantities (sin, cos, R)   | Q1.30                | 9.3e-10      | ±2           |
//!
//! Length, force, moment, pressure and strain match the LUT image
//! (`ocm_shared::lut`), so lookups need no conversion but the angle shift.
//! Every function here saturates instead of overflowing and runs a fixed
//! number of iterations.

/// One in Q1.30.
pub const Q30_ONE: i32 = 1 << 30;
/// One in Q3.28.
pub const Q28_ONE: i32 = 1 << 28;
/// One metre in Q8.24.
pub const Q24_ONE: i32 = 1 << 24;
/// pi in Q3.28.
pub const PI_Q28: i32 = 843_314_857;
/// 2 pi in Q3.28.
pub const TWO_PI_Q28: i32 = 1_686_629_713;
/// pi / 2 in Q3.28.
pub const HALF_PI_Q28: i32 = 421_657_428;

/// CORDIC iterations of `atan2`: 26 give about 3e-8 rad, far below what
/// the kinematics need (0.05 mm at the tip is 2e-4 rad at 0.25 m).
const CORDIC_STEPS: usize = 26;

/// pi / 4 in Q3.28: the edge of the sine and cosine polynomials' range.
const QUARTER_PI_Q28: i32 = 210_828_714;
/// 3 pi / 4 in Q3.28.
const THREE_QUARTER_PI_Q28: i32 = 632_486_143;

/// Taylor coefficients `1/3!, 1/5!, .., 1/11!` in Q1.30: on |x| <= pi/4 the
/// first term left out (x^13/13!) is below 1e-11, under one Q1.30 step.
const SIN_Q30: [i32; 5] = [178_956_971, 8_947_849, 213_042, 2_959, 27];
/// Taylor coefficients `1/2!, 1/4!, .., 1/12!` in Q1.30.
const COS_Q30: [i32; 6] = [536_870_912, 44_739_243, 1_491_308, 26_630, 296, 2];

/// `a * b` of two Q1.30 numbers of magnitude below one, rounded to Q1.30:
/// one 32 x 32 -> 64 bit multiply (a single `smull` on a Cortex-M4).
#[inline(always)]
fn mul_q30(a: i32, b: i32) -> i32 {
    ((i64::from(a) * i64::from(b) + (1 << 29)) >> 30) as i32
}

/// `atan(2^-i)` in Q1.30 for the CORDIC iterations.
const ATAN_Q30: [i32; 31] = [
    843_314_857,
    497_837_829,
    263_043_837,
    133_525_159,
    67_021_687,
    33_543_516,
    16_775_851,
    8_388_437,
    4_194_283,
    2_097_149,
    1_048_576,
    524_288,
    262_144,
    131_072,
    65_536,
    32_768,
    16_384,
    8_192,
    4_096,
    2_048,
    1_024,
    512,
    256,
    128,
    64,
    32,
    16,
    8,
    4,
    2,
    1,
];

/// One CORDIC vectoring-mode step `I` on `[x, y, z]`: turns the vector
/// towards the x axis, accumulating the angle turned in `z`.
///
/// Two spellings of the same integer operations, bit for bit (the QEMU
/// bit-exactness test runs one against the other): on the Cortex-M4 a
/// multiply by the sign +-1 folds into single-cycle multiply-accumulates;
/// on an x86-64 host (the lab's in-process firmware) both turns are
/// computed and one is picked by a conditional move, so the next step waits
/// on an add and a select instead of a multiply.
#[cfg(not(target_arch = "x86_64"))]
#[inline(always)]
fn vector_step<const I: u32>(v: &mut [i32; 3]) {
    let [x, y, z] = *v;
    // +1 where y > 0, -1 where y <= 0.
    let s = 2 * i32::from(y > 0) - 1;
    *v = [
        x.wrapping_add(s.wrapping_mul(y >> I)),
        y.wrapping_sub(s.wrapping_mul(x >> I)),
        z.wrapping_add(s.wrapping_mul(ATAN_Q30[I as usize])),
    ];
}

/// One CORDIC vectoring-mode step (the x86-64 spelling, see above).
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn vector_step<const I: u32>(v: &mut [i32; 3]) {
    let [x, y, z] = *v;
    let (xs, ys, a) = (x >> I, y >> I, ATAN_Q30[I as usize]);
    // Turn clockwise where y > 0, anticlockwise where y <= 0; a select,
    // not a branch: the sign is noise a CPU cannot predict.
    let clockwise = [x.wrapping_add(ys), y.wrapping_sub(xs), z.wrapping_add(a)];
    let anticlockwise = [x.wrapping_sub(ys), y.wrapping_add(xs), z.wrapping_sub(a)];
    *v = if y > 0 { clockwise } else { anticlockwise };
}

/// The `CORDIC_STEPS` steps of `$step` on `$v`, written out: constant
/// shifts (free on a Cortex-M's barrel shifter) and no loop counter or
/// table walk, the same operations in the same order as a loop.
macro_rules! cordic {
    ($step:ident, $v:ident) => {
        cordic!(@ $step, $v; 0 1 2 3 4 5 6 7 8 9 10 11 12 13 14 15 16 17 18 19 20 21 22 23 24 25)
    };
    (@ $step:ident, $v:ident; $($i:literal)*) => {{
        const _: () = assert!([$($i),*].len() == CORDIC_STEPS);
        $($step::<$i>(&mut $v);)*
    }};
}

/// Clamps an `i64` into `i32`.
#[inline]
pub fn sat(x: i64) -> i32 {
    x.clamp(i64::from(i32::MIN), i64::from(i32::MAX)) as i32
}

/// `(a * b) >> shift`, rounded to nearest, saturated to `i32`.
#[inline]
pub fn mul_shr(a: i32, b: i32, shift: u32) -> i32 {
    sat(rshift_round(i64::from(a) * i64::from(b), shift))
}

/// `x >> shift`, rounded to nearest (ties towards +inf).
#[inline]
pub fn rshift_round(x: i64, shift: u32) -> i64 {
    if shift == 0 {
        x
    } else {
        x.saturating_add(1i64 << (shift - 1)) >> shift
    }
}

/// `num / den` as `i64` rounded to nearest; `None` when `den == 0`.
#[inline]
pub fn div_round(num: i64, den: i64) -> Option<i64> {
    if den == 0 {
        return None;
    }
    // Fast path: the Cortex-M4 divides 32-bit integers in hardware, 64-bit
    // ones in a library routine ten times slower.
    let small = |x: i64| x > i64::from(i32::MIN) / 2 && x < i64::from(i32::MAX) / 2;
    if small(num) && small(den) {
        let (n, d) = (num as i32, den as i32);
        let (n, d) = if d < 0 { (-n, -d) } else { (n, d) };
        let half = d / 2;
        let q = if n >= 0 {
            (n + half) / d
        } else {
            -((-n + half) / d)
        };
        return Some(i64::from(q));
    }
    let (n, d) = if den < 0 {
        (num.checked_neg()?, den.checked_neg()?)
    } else {
        (num, den)
    };
    let half = d / 2;
    let q = if n >= 0 {
        n.checked_add(half)? / d
    } else {
        -(n.checked_neg()?.checked_add(half)? / d)
    };
    Some(q)
}

/// Wraps an angle into (-pi, pi], Q3.28.
pub fn wrap_angle_q28(a: i32) -> i32 {
    let mut a = i64::from(a);
    let pi = i64::from(PI_Q28);
    let two_pi = i64::from(TWO_PI_Q28);
    // |a| < 8 rad < 3 pi, so two corrections suffice.
    for _ in 0..2 {
        if a > pi {
            a -= two_pi;
        } else if a <= -pi {
            a += two_pi;
        }
    }
    a as i32
}

/// Sine and cosine of an angle in Q3.28, both in Q1.30 (error below 3e-9).
///
/// The angle is folded into |r| <= pi/4 by quarter turns, where two short
/// Horner polynomials reach Q1.30 precision: a third of the instructions of
/// the 26-step CORDIC this replaced, at the same accuracy.
pub fn sin_cos_q28(angle_q28: i32) -> (i32, i32) {
    let a = wrap_angle_q28(angle_q28);
    // Quarter turns taken off, counted anticlockwise (0..4).
    let (r, quarter) = if a > THREE_QUARTER_PI_Q28 {
        (a - PI_Q28, 2)
    } else if a > QUARTER_PI_Q28 {
        (a - HALF_PI_Q28, 1)
    } else if a >= -QUARTER_PI_Q28 {
        (a, 0)
    } else if a >= -THREE_QUARTER_PI_Q28 {
        (a + HALF_PI_Q28, 3)
    } else {
        (a + PI_Q28, 2)
    };
    // |r| <= pi/4 fits Q1.30 with room to spare, and every partial sum
    // below stays under one in magnitude.
    let x = r << 2;
    let x2 = mul_q30(x, x);
    let mut ps = SIN_Q30[4];
    for &c in SIN_Q30[..4].iter().rev() {
        ps = c - mul_q30(x2, ps);
    }
    let s = x - mul_q30(x, mul_q30(x2, ps));
    let mut pc = COS_Q30[5];
    for &c in COS_Q30[..5].iter().rev() {
        pc = c - mul_q30(x2, pc);
    }
    let c = Q30_ONE - mul_q30(x2, pc);
    match quarter {
        0 => (s, c),
        1 => (c, -s),
        2 => (-s, -c),
        _ => (-c, s),
    }
}

/// `atan2(y, x)` in Q3.28 within (-pi, pi]; 0 for the origin.
pub fn atan2_q28(y: i64, x: i64) -> i32 {
    if y == 0 {
        // Exact on the real axis (and 0 at the origin).
        return if x >= 0 { 0 } else { PI_Q28 };
    }
    let (mut x, mut y, offset) = if x < 0 {
        let off = if y >= 0 { PI_Q28 } else { -PI_Q28 };
        (x.saturating_neg(), y.saturating_neg(), off)
    } else {
        (x, y, 0)
    };
    // Normalise so that the CORDIC gain cannot overflow i32 and small
    // vectors keep their precision.
    let m = x.unsigned_abs().max(y.unsigned_abs());
    let lead = 64 - m.leading_zeros() as i32;
    let shift = lead - 29;
    if shift > 0 {
        x >>= shift;
        y >>= shift;
    } else {
        x <<= -shift;
        y <<= -shift;
    }
    let mut v = [x as i32, y as i32, 0i32];
    cordic!(vector_step, v);
    let z = v[2];
    let r = i64::from(rshift_round(i64::from(z), 2) as i32) + i64::from(offset);
    wrap_angle_q28(sat(r))
}

/// `sqrt(a^2 + b^2)` without overflow for any inputs (floor, with the
/// low bits dropped when the inputs exceed 2^31).
pub fn hypot(a: i64, b: i64) -> i64 {
    let m = a.unsigned_abs().max(b.unsigned_abs());
    let bits = 64 - m.leading_zeros();
    let shift = bits.saturating_sub(31);
    let (a, b) = ((a >> shift) as i128, (b >> shift) as i128);
    let sum = (a * a + b * b) as u64;
    (isqrt(sum) as i64) << shift
}

/// Integer square root of a `u64` (floor).
#[inline]
pub fn isqrt(x: u64) -> u64 {
    floor_sqrt(x)
}

/// The integer routine: the boards' FPU has no double precision.
#[cfg(not(target_arch = "x86_64"))]
#[inline]
fn floor_sqrt(x: u64) -> u64 {
    x.isqrt()
}

/// On an x86-64 host (the lab's in-process firmware) the FPU's square root,
/// made exact: the root of the nearest double is within 2^-20 of the true
/// root (a relative error of 2^-52 on a root below 2^32), so its truncation
/// is the floor or one off it, and one integer test each way gives the same
/// floor as the integer routine, in a fraction of its time.
#[cfg(target_arch = "x86_64")]
#[inline]
fn floor_sqrt(x: u64) -> u64 {
    let r = libm::sqrt(x as f64) as u64;
    let r = if r.checked_mul(r).is_none_or(|sq| sq > x) {
        r - 1
    } else {
        r
    };
    if (r + 1).checked_mul(r + 1).is_some_and(|sq| sq <= x) {
        r + 1
    } else {
        r
    }
}

/// `sin(x) / x` in Q1.30 for `x` in Q3.28 (1 at 0).
pub fn sinc_q30(x_q28: i32) -> i32 {
    let x = i64::from(x_q28);
    if x.abs() < 1 << 26 {
        // |x| < 0.25: Taylor series to x^6, truncation error below 1e-10.
        let x2 = rshift_round(x * x, 26); // Q30
        let t2 = x2 / 6;
        let x4 = rshift_round(x2 * x2, 30);
        let t4 = x4 / 120;
        let x6 = rshift_round(x4 * x2, 30);
        let t6 = x6 / 5040;
        sat(i64::from(Q30_ONE) - t2 + t4 - t6)
    } else {
        let (s, _) = sin_cos_q28(x_q28);
        sat(div_round(i64::from(s) << 28, x).unwrap_or(0))
    }
}

/// Angle in Q3.28 from radians (host-side helper, saturating).
pub fn angle_q28_from_rad(rad: f64) -> i32 {
    from_f64(rad, 28)
}

/// Radians from an angle in Q3.28.
pub fn angle_q28_to_rad(q: i32) -> f64 {
    f64::from(q) / f64::from(Q28_ONE)
}

/// Rounds `x * 2^frac` to the nearest `i32`, saturating (NaN gives 0).
pub fn from_f64(x: f64, frac: i32) -> i32 {
    let v = libm::round(x * libm::exp2(f64::from(frac)));
    // `as` saturates and maps NaN to 0.
    v as i32
}

/// `raw * 2^-frac` as `f64`.
pub fn to_f64(raw: i64, frac: i32) -> f64 {
    raw as f64 * libm::exp2(-f64::from(frac))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The vectoring CORDIC as a plain loop with branches: the form the
    /// unrolled, branch-free steps must reproduce bit for bit.
    fn cordic_loop(mut v: [i32; 3]) -> [i32; 3] {
        for (i, &t) in ATAN_Q30.iter().enumerate().take(CORDIC_STEPS) {
            let [x, y, z] = v;
            let (dx, dy) = (y >> i, x >> i);
            v = if y > 0 {
                [x + dx, y - dy, z + t]
            } else {
                [x - dx, y + dy, z - t]
            };
        }
        v
    }

    #[test]
    fn square_root_is_the_integer_floor() {
        let mut seed = 0x9e37_79b9_7f4a_7c15u64;
        let mut vals = std::vec![
            0,
            1,
            2,
            3,
            4,
            u64::MAX,
            u64::MAX - 1,
            1 << 62,
            (1 << 62) - 1
        ];
        // Squares and their neighbours up to the largest root, where the
        // double's rounding decides the truncation.
        for k in (0..64).map(|b| 1u64 << (b / 2)).chain([
            3_037_000_499,
            3_037_000_500,
            4_294_967_295,
            4_294_967_294,
            94_906_265,
            94_906_266,
        ]) {
            let sq = k.wrapping_mul(k);
            if k <= u64::from(u32::MAX) {
                vals.extend([sq, sq.wrapping_sub(1), sq.wrapping_add(1)]);
            }
        }
        for _ in 0..200_000 {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            // Every magnitude, and near-squares of random roots.
            vals.push(seed >> (seed % 64));
            let k = seed >> 32;
            vals.extend([k * k, (k * k).wrapping_sub(1)]);
        }
        for x in vals {
            assert_eq!(isqrt(x), x.isqrt(), "x = {x}");
        }
    }

    #[test]
    fn unrolled_steps_match_the_loop_bit_for_bit() {
        let mut seed = 0x2545_f491_4f6c_dd1du64;
        let mut next = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            seed
        };
        for _ in 0..20_000 {
            let r = next();
            // Vectors below 2^29 (what atan2 normalises to).
            let (x, y) = ((r >> 35) as i32 & 0x1fff_ffff, (r as i32) >> 3);
            let mut vec = [x, y, 0];
            cordic!(vector_step, vec);
            assert_eq!(vec, cordic_loop([x, y, 0]), "x = {x}, y = {y}");
        }
    }

    fn rad(q: i32) -> f64 {
        angle_q28_to_rad(q)
    }

    #[test]
    fn sin_cos_matches_libm_over_full_range() {
        let mut worst = 0.0f64;
        for k in -8000..=8000 {
            let a = f64::from(k) * 1e-3;
            let (s, c) = sin_cos_q28(angle_q28_from_rad(a));
            let (s, c) = (to_f64(s.into(), 30), to_f64(c.into(), 30));
            worst = worst.max((s - a.sin()).abs()).max((c - a.cos()).abs());
        }
        assert!(worst < 1e-7, "worst sin/cos error {worst}");
    }

    #[test]
    fn sin_cos_is_within_a_few_q30_steps_of_the_quantised_angle() {
        // Every raw angle near the quarter-turn folds, and a sweep of the
        // whole Q3.28 range including its ends.
        let folds = [QUARTER_PI_Q28, THREE_QUARTER_PI_Q28, HALF_PI_Q28, PI_Q28];
        let near = folds
            .iter()
            .flat_map(|&f| [f, -f])
            .flat_map(|f| (-3..=3).map(move |d| f.saturating_add(d)));
        let sweep = (0..=40_000).map(|k| (i64::from(i32::MIN) + k * 107_374) as i32);
        let mut worst = 0.0f64;
        for raw in near.chain(sweep).chain([i32::MIN, i32::MAX, 0, 1, -1]) {
            let a = rad(raw);
            let (s, c) = sin_cos_q28(raw);
            let (s, c) = (to_f64(s.into(), 30), to_f64(c.into(), 30));
            worst = worst.max((s - a.sin()).abs()).max((c - a.cos()).abs());
        }
        // Three Q1.30 steps (9.3e-10 each) at most.
        assert!(worst < 4e-9, "worst sin/cos error {worst}");
    }

    #[test]
    fn atan2_matches_libm_in_every_quadrant() {
        let mut worst = 0.0f64;
        for i in -60..=60 {
            for j in -60..=60 {
                let (y, x) = (i64::from(i) * 1_234_567, i64::from(j) * 987_654);
                if x == 0 && y == 0 {
                    continue;
                }
                let got = rad(atan2_q28(y, x));
                let want = (y as f64).atan2(x as f64);
                let mut err = (got - want).abs();
                if err > core::f64::consts::PI {
                    err = 2.0 * core::f64::consts::PI - err;
                }
                worst = worst.max(err);
            }
        }
        assert!(worst < 1e-7, "worst atan2 error {worst}");
        assert_eq!(atan2_q28(0, 0), 0);
        // Tiny and huge vectors keep their precision.
        assert!((rad(atan2_q28(1, 1)) - core::f64::consts::FRAC_PI_4).abs() < 1e-7);
        assert!(
            (rad(atan2_q28(i64::MAX / 2, -(i64::MAX / 2))) - 0.75 * core::f64::consts::PI).abs()
                < 1e-7
        );
    }

    #[test]
    fn sinc_is_continuous_across_the_series_switch() {
        for k in -4000..=4000 {
            let x = f64::from(k) * 1e-3 + 1e-7;
            let got = to_f64(sinc_q30(angle_q28_from_rad(x)).into(), 30);
            let want = x.sin() / x;
            assert!((got - want).abs() < 5e-7, "sinc({x}) = {got}, want {want}");
        }
        assert_eq!(sinc_q30(0), Q30_ONE);
    }

    #[test]
    fn div_round_rounds_half_away_and_refuses_zero() {
        assert_eq!(div_round(7, 2), Some(4));
        assert_eq!(div_round(-7, 2), Some(-4));
        assert_eq!(div_round(7, -2), Some(-4));
        assert_eq!(div_round(1, 0), None);
        assert_eq!(div_round(i64::MIN, -1), None);
    }
}
