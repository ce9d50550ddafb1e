//! The OCM maps the kinematics need (eq 3.24-3.25, App. A): the inverse
//! axial map `eps = F_A^-1(F, P)`, the forward axial map `F = F_A(eps, P)` and
//! the inverse bending map `phi = F_B^-1(M, s, P)`, in fixed point
//! ([`OcmMaps`]).
//!
//! The implementation is the LUT image of `ocm_shared::lut`, with
//! [`FastLut`] and [`MemoBend`] for the control tick. Host-side maps (the
//! `f64` twin, closed-form test maps) live in `ocm-firmware-support`.

use ocm_shared::lut::{
    AngleRad, AxialRow, ForceN, LengthM, LutImage, MomentNm, PressurePa, Strain, udiv_u64_by_u32,
};

/// Fixed-point OCM maps. Units and Q-formats as in [`crate::fx`]:
/// force N Q16.16, pressure Pa Q24.8, strain Q16.16, moment N*m Q8.24,
/// length m Q8.24, angle (output) rad Q16.16. `None` means the query lies
/// outside what the map can answer.
pub trait OcmMaps {
    /// `eps = F_A^-1(F, P)`.
    fn strain(&self, force_q16: i32, pressure_q8: i32) -> Option<i32>;
    /// `F = F_A(eps, P)`.
    fn force(&self, strain_q16: i32, pressure_q8: i32) -> Option<i32>;
    /// `phi = F_B^-1(M, s, P)` for one OCM of neutral-axis length `s`.
    fn bend(&self, moment_q24: i32, s_q24: i32, pressure_q8: i32) -> Option<i32>;

    /// The pressure with `F_A(eps, P) = F`. The map is affine in `P`
    /// (eq 3.7), so two forward evaluations at `p_lo` and `p_hi` give it by
    /// one secant step. The result may lie outside `[p_lo, p_hi]`.
    fn pressure_for(
        &self,
        strain_q16: i32,
        force_q16: i32,
        p_lo_q8: i32,
        p_hi_q8: i32,
    ) -> Option<i32> {
        let fa = i64::from(self.force(strain_q16, p_lo_q8)?);
        let fb = i64::from(self.force(strain_q16, p_hi_q8)?);
        let span = i64::from(p_hi_q8) - i64::from(p_lo_q8);
        let step = crate::fx::div_round((i64::from(force_q16) - fa).saturating_mul(span), fb - fa)?;
        Some(crate::fx::sat(i64::from(p_lo_q8) + step))
    }
}

impl OcmMaps for LutImage<'_> {
    fn strain(&self, force_q16: i32, pressure_q8: i32) -> Option<i32> {
        self.axial_strain(
            ForceN::from_bits(force_q16),
            PressurePa::from_bits(pressure_q8),
        )
        .ok()
        .map(|l| l.value.to_bits())
    }

    fn force(&self, strain_q16: i32, pressure_q8: i32) -> Option<i32> {
        self.axial_force(
            Strain::from_bits(strain_q16),
            PressurePa::from_bits(pressure_q8),
        )
        .ok()
        .map(|l| l.value.to_bits())
    }

    fn bend(&self, moment_q24: i32, s_q24: i32, pressure_q8: i32) -> Option<i32> {
        self.bending_angle(
            MomentNm::from_bits(moment_q24),
            LengthM::from_bits(s_q24),
            PressurePa::from_bits(pressure_q8),
        )
        .ok()
        .map(|l: ocm_shared::lut::Lookup<AngleRad>| l.value.to_bits())
    }
}

/// A loaded LUT with the reciprocals the control tick needs precomputed,
/// so that the pressure solve of the inverse map costs one division.
///
/// The pressure solve reads the axial table's lowest and highest pressure
/// rows at the strain cell and intersects the affine map they span (eq 3.7);
/// all other queries go to the image's own lookups.
#[derive(Debug, Clone, Copy)]
pub struct FastLut<'a> {
    /// The validated image.
    pub image: LutImage<'a>,
    eps_min: i64,
    eps_max: i64,
    cells: i64,
    /// `cells * 2^40 / (eps_max - eps_min)`: strain (raw Q16 bits) to the
    /// grid position in Q40, by one multiplication.
    pos_per_strain_q40: i64,
    /// The lowest and the highest pressure row.
    rows: Option<(AxialRow<'a>, AxialRow<'a>)>,
    p_min_q8: i32,
    p_span_q8: i32,
}

impl<'a> FastLut<'a> {
    /// Precomputes the grid constants of `image`.
    pub fn new(image: LutImage<'a>) -> Self {
        let g = image.axial_grid();
        let eps_min = i64::from(g.eps_min.to_bits());
        let eps_max = i64::from(g.eps_max.to_bits());
        let span = (eps_max - eps_min).max(1);
        let cells = i64::from(g.n_eps.max(2) - 1);
        let p_min = i64::from(g.p_min.to_bits());
        let p_span = (i64::from(g.p_max.to_bits()) - p_min).max(1);
        let rows = image
            .axial_row(0)
            .zip(image.axial_row(g.n_p.saturating_sub(1)));
        Self {
            image,
            eps_min,
            eps_max,
            cells,
            pos_per_strain_q40: cells * ((1i64 << 40) / span),
            rows,
            p_min_q8: g.p_min.to_bits(),
            p_span_q8: crate::fx::sat(p_span),
        }
    }
}

/// [`crate::fx::div_round`] (nearest, ties away from zero; `None` for a zero
/// divisor or an overflow) with the 64-by-32-bit division of
/// [`udiv_u64_by_u32`] instead of the 64-bit library routine.
fn div_round_fast(num: i64, den: i64) -> Option<i64> {
    if num == i64::MIN || den == i64::MIN {
        return None;
    }
    let d = den.unsigned_abs();
    let Ok(d32) = u32::try_from(d) else {
        return crate::fx::div_round(num, den);
    };
    let n = num.unsigned_abs().checked_add(d / 2)?;
    if n > i64::MAX.unsigned_abs() {
        return None;
    }
    // `n <= i64::MAX`, so the quotient fits an `i64`.
    let q = udiv_u64_by_u32(n, d32)? as i64;
    Some(if (num < 0) != (den < 0) { -q } else { q })
}

impl OcmMaps for FastLut<'_> {
    fn strain(&self, force_q16: i32, pressure_q8: i32) -> Option<i32> {
        self.image.strain(force_q16, pressure_q8)
    }

    fn force(&self, strain_q16: i32, pressure_q8: i32) -> Option<i32> {
        self.image.force(strain_q16, pressure_q8)
    }

    fn bend(&self, moment_q24: i32, s_q24: i32, pressure_q8: i32) -> Option<i32> {
        self.image.bend(moment_q24, s_q24, pressure_q8)
    }

    // Out of line: inlined, its frame would join the caller's for good.
    #[inline(never)]
    fn pressure_for(&self, strain_q16: i32, force_q16: i32, _lo: i32, _hi: i32) -> Option<i32> {
        // The clamp keeps `e <= span`, so the product stays below `cells * 2^40`.
        let e = i64::from(strain_q16).clamp(self.eps_min, self.eps_max) - self.eps_min;
        let pos_q16 = (e * self.pos_per_strain_q40) >> 24;
        let i = (pos_q16 >> 16).clamp(0, self.cells - 1);
        let w = (pos_q16 - (i << 16)).clamp(0, 1 << 16);
        let (lo_row, hi_row) = self.rows?;
        let i = usize::try_from(i).ok()?;
        let at = |[a, b]: [i32; 2]| {
            let (a, b) = (i64::from(a), i64::from(b));
            a + (((b - a) * w) >> 16)
        };
        let f_lo = at(lo_row.cell(i)?);
        let f_hi = at(hi_row.cell(i)?);
        // Both factors fit `i32` on any valid image (forces are `I16F16`
        // table values): one 32x32->64 multiply, not the overflow-checked
        // 64-bit routine.
        let excess = i64::from(force_q16) - f_lo;
        let num = match i32::try_from(excess) {
            Ok(x) => i64::from(x) * i64::from(self.p_span_q8),
            Err(_) => excess.saturating_mul(i64::from(self.p_span_q8)),
        };
        let step = div_round_fast(num, f_hi - f_lo)?;
        Some(crate::fx::sat(i64::from(self.p_min_q8) + step))
    }
}

/// One remembered bending query: `(moment, s, pressure) -> phi`.
pub type BendEntry = Option<(i32, i32, i32, i32)>;

/// Memoizes [`OcmMaps::bend`] over a few recent queries, exactly keyed, so
/// that a control loop whose moment, length and (rounded) pressure do not
/// change does not repeat the bisection every tick. Other maps pass
/// through.
pub struct MemoBend<'m, M> {
    inner: &'m M,
    cache: &'m core::cell::Cell<[BendEntry; 3]>,
}

impl<'m, M: OcmMaps> MemoBend<'m, M> {
    /// Wraps `inner` with the cache `cache` (kept by the caller across calls).
    pub fn new(inner: &'m M, cache: &'m core::cell::Cell<[BendEntry; 3]>) -> Self {
        Self { inner, cache }
    }
}

impl<M: OcmMaps> OcmMaps for MemoBend<'_, M> {
    fn strain(&self, force_q16: i32, pressure_q8: i32) -> Option<i32> {
        self.inner.strain(force_q16, pressure_q8)
    }

    fn force(&self, strain_q16: i32, pressure_q8: i32) -> Option<i32> {
        self.inner.force(strain_q16, pressure_q8)
    }

    #[inline(never)]
    fn bend(&self, moment_q24: i32, s_q24: i32, pressure_q8: i32) -> Option<i32> {
        // Entry by entry: copying the whole array out of the cell would
        // cost a block copy on every tick.
        let cache: &core::cell::Cell<[BendEntry]> = self.cache;
        let slots = cache.as_slice_of_cells();
        for slot in slots {
            if let Some(e) = slot.get()
                && (e.0, e.1, e.2) == (moment_q24, s_q24, pressure_q8)
            {
                return Some(e.3);
            }
        }
        let phi = self.inner.bend(moment_q24, s_q24, pressure_q8)?;
        let mut entries = self.cache.get();
        entries.rotate_right(1);
        entries[0] = Some((moment_q24, s_q24, pressure_q8, phi));
        self.cache.set(entries);
        Some(phi)
    }

    fn pressure_for(
        &self,
        strain_q16: i32,
        force_q16: i32,
        p_lo_q8: i32,
        p_hi_q8: i32,
    ) -> Option<i32> {
        self.inner
            .pressure_for(strain_q16, force_q16, p_lo_q8, p_hi_q8)
    }
}
