//! Forward and inverse lookups on a validated image, in fixed point, with
//! `f64` twins for the host that run the same integer path.

use fixed::traits::{Fixed, ToFixed};

use super::error::{LookupError, Quantity};
use super::fixed_math::{
    ONE, Side, Uniform, div_round, invert_row, invert_row_near, lerp, mul_one, saturate_i32,
};
use super::image::LutImage;
use super::{AngleRad, ForceN, LengthM, MomentNm, PressurePa, Strain};

/// Whether a lookup's input lay inside the range its table covers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Clamp {
    /// Inside the range: the value is interpolated.
    Inside,
    /// Below the range: the value is the table's lowest end.
    BelowRange,
    /// Above the range: the value is the table's highest end.
    AboveRange,
}

/// A lookup's answer and whether it was held at the end of the table.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Lookup<T> {
    /// The answer.
    pub value: T,
    /// Whether the input lay outside the table (the answer then saturates).
    pub clamp: Clamp,
}

impl<T> Lookup<T> {
    /// True when the input lay outside the table and the answer saturated.
    pub fn is_saturated(&self) -> bool {
        self.clamp != Clamp::Inside
    }

    /// Applies `f` to the value, keeping the clamp.
    pub fn map<U>(self, f: impl FnOnce(T) -> U) -> Lookup<U> {
        Lookup {
            value: f(self.value),
            clamp: self.clamp,
        }
    }
}

impl From<Side> for Clamp {
    fn from(side: Side) -> Self {
        match side {
            Side::Below => Clamp::BelowRange,
            Side::Inside => Clamp::Inside,
            Side::Above => Clamp::AboveRange,
        }
    }
}

impl Clamp {
    /// The clamp seen from the mirrored input `-x` (symmetry `M(-phi) = -M(phi)`).
    fn mirrored(self) -> Self {
        match self {
            Clamp::Inside => Clamp::Inside,
            Clamp::BelowRange => Clamp::AboveRange,
            Clamp::AboveRange => Clamp::BelowRange,
        }
    }
}

/// Angle cells at which a bending inverse found its answer on the lower and
/// the upper length level, for [`LutImage::bending_angle_near`] to start
/// from. Only a starting point: any value gives a correct answer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BendHint {
    cells: [u16; 2],
}

impl BendHint {
    /// No cell known: both levels bisect.
    pub const NONE: Self = Self {
        cells: [Self::UNSET; 2],
    };
    const UNSET: u16 = u16::MAX;
}

impl Default for BendHint {
    fn default() -> Self {
        Self::NONE
    }
}

/// One length level's combined moment row `M0 + P M1` (raw `I8F24`).
struct MomentRow<'a> {
    m0: &'a [[u8; 4]],
    m1: &'a [[u8; 4]],
    p: i32,
    shift: u32,
    /// `2^(shift-1)` (0 for shift 0): rounds the shift to nearest.
    half: i64,
}

impl MomentRow<'_> {
    /// Moment at angle point `i` (0 past the row, unreachable on a valid
    /// image).
    #[inline(always)]
    fn at(&self, i: usize) -> i64 {
        let (Some(m0), Some(m1)) = (self.m0.get(i), self.m1.get(i)) else {
            return 0;
        };
        let m0 = i64::from(i32::from_le_bytes(*m0));
        // |P| < 2^31 and |M1| < 2^31: the product and the rounding stay
        // below 2^63, and the sum with `M0` too.
        let pm1 = i64::from(self.p) * i64::from(i32::from_le_bytes(*m1)) + self.half;
        let scaled = if self.shift >= 32 {
            // floor(x / 2^s) = floor(floor(x / 2^32) / 2^(s-32)): the high
            // word and a 32-bit shift instead of a 64-bit one.
            i64::from(((pm1 >> 32) as i32) >> (self.shift - 32))
        } else {
            pm1 >> self.shift
        };
        m0 + scaled
    }
}

/// A length level and its `phi_max` as a uniform angle grid.
struct Level {
    index: usize,
    angles: Uniform,
}

impl LutImage<'_> {
    /// Pressure cell (level index, Q16 weight) of `p`, or an error outside
    /// the window. The weight leaves `0..=1` when extrapolating.
    fn pressure_cell(&self, p: PressurePa) -> Result<(usize, i64), LookupError> {
        let grid = self.axial_grid();
        let (min, max) = grid.pressure_window();
        if p < min || p > max {
            return Err(LookupError::PressureOutOfRange {
                pressure: p,
                min,
                max,
            });
        }
        Ok(grid.pressure_grid().locate(p.to_bits().into()))
    }

    /// Checks that `p` lies in the pressure window (the bending lookups need
    /// no pressure cell: their table is affine in `p`).
    fn check_pressure(&self, p: PressurePa) -> Result<(), LookupError> {
        let (min, max) = self.axial_grid().pressure_window();
        if p < min || p > max {
            return Err(LookupError::PressureOutOfRange {
                pressure: p,
                min,
                max,
            });
        }
        Ok(())
    }

    /// Length cell (level index, Q16 weight in `0..=1`) of `s`, or an error
    /// outside the stored levels.
    fn length_cell(&self, s: LengthM) -> Result<(usize, i64), LookupError> {
        let grid = self.bending_grid();
        if s < grid.s_min || s > grid.s_max {
            return Err(LookupError::LengthOutOfRange {
                length: s,
                min: grid.s_min,
                max: grid.s_max,
            });
        }
        let (k, w) = grid.length_grid().locate(s.to_bits().into());
        Ok((k, w.clamp(0, ONE)))
    }

    /// Axial force row at pressure weight `t` between levels `j` and `j+1`.
    fn force_at_pressure(&self, j: usize, t: i64, i: usize) -> i64 {
        lerp(self.force_raw(j, i), self.force_raw(j + 1, i), t)
    }

    /// The combined moment row `M0 + P M1` of length level `k`.
    fn moment_row(&self, k: usize, p: PressurePa) -> MomentRow<'_> {
        let shift = self.m1_shift();
        MomentRow {
            m0: self.plane_row(2, k).as_chunks().0,
            m1: self.plane_row(3, k).as_chunks().0,
            p: p.to_bits(),
            shift: shift.min(62),
            half: (1i64 << shift.min(62)) >> 1,
        }
    }

    /// Length level `k` with its angle grid `0..=phi_max[k]`.
    fn level(&self, k: usize) -> Level {
        Level {
            index: k,
            angles: Uniform {
                min: 0,
                max: self.phi_max_raw(k),
                points: self.bending_grid().n_u,
            },
        }
    }

    /// Forward axial map `F_A(eps, P)`, bilinear. Strains outside the grid are
    /// held to its ends and flagged; pressures are extrapolated inside the
    /// window.
    pub fn axial_force(&self, eps: Strain, p: PressurePa) -> Result<Lookup<ForceN>, LookupError> {
        let (j, t) = self.pressure_cell(p)?;
        let strains = self.axial_grid().strain_grid();
        let (i, w, side) = strains.locate_clamped(eps.to_bits().into());
        let a = self.force_at_pressure(j, t, i);
        let b = self.force_at_pressure(j, t, i + 1);
        Ok(Lookup {
            value: ForceN::from_bits(saturate_i32(lerp(a, b, w))),
            clamp: side.into(),
        })
    }

    /// Inverse axial map `eps = F_A^-1(F, P)` (eq 3.24): the row at `P` is
    /// interpolated (or extrapolated inside the window) from the two
    /// neighbouring pressure levels, bisected, and interpolated linearly in
    /// the cell found. Forces beyond the row's ends give its end strain,
    /// flagged [`Clamp::BelowRange`] / [`Clamp::AboveRange`].
    pub fn axial_strain(
        &self,
        force: ForceN,
        p: PressurePa,
    ) -> Result<Lookup<Strain>, LookupError> {
        let (j, t) = self.pressure_cell(p)?;
        let strains = self.axial_grid().strain_grid();
        let (pos, side) = invert_row(strains.last(), force.to_bits().into(), |i| {
            self.force_at_pressure(j, t, i)
        });
        Ok(Lookup {
            value: Strain::from_bits(saturate_i32(strains.at_q16(pos))),
            clamp: side.into(),
        })
    }

    /// Largest angle at length cell `(k, w)`: `phi_max` interpolated in `s`.
    fn phi_top(&self, k: usize, w: i64) -> i64 {
        lerp(self.phi_max_raw(k), self.phi_max_raw(k + 1), w)
    }

    /// Largest feasible bending angle at neutral-axis length `s`: the
    /// stored `phi_max` levels interpolated in `s`, exactly as the bending
    /// lookups bound their angles.
    pub fn max_bend_angle(&self, s: LengthM) -> Result<AngleRad, LookupError> {
        let (k, w) = self.length_cell(s)?;
        Ok(AngleRad::from_bits(saturate_i32(self.phi_top(k, w))))
    }

    /// Forward bending map `M(phi, s, P)`: at each of the two neighbouring
    /// length levels the moment at `u = |phi| / phi_max` is interpolated, then
    /// linearly in `s`; `M(-phi) = -M(phi)`. Angles past `phi_max(s)` (itself
    /// interpolated in `s`) are held there and flagged; between levels the
    /// shorter level's curve is extended along its last cell up to it.
    pub fn bending_moment(
        &self,
        phi: AngleRad,
        s: LengthM,
        p: PressurePa,
    ) -> Result<Lookup<MomentNm>, LookupError> {
        let (k, w) = self.length_cell(s)?;
        self.check_pressure(p)?;
        let negative = phi < 0;
        let mut angle = i64::from(phi.to_bits()).abs();
        let top = self.phi_top(k, w);
        let mut clamp = Clamp::Inside;
        if angle > top {
            angle = top;
            clamp = Clamp::AboveRange;
        }
        let at_level = |level: Level| {
            let (i, u) = level.angles.locate(angle);
            let row = self.moment_row(level.index, p);
            lerp(row.at(i), row.at(i + 1), u)
        };
        let moment = if w == 0 {
            at_level(self.level(k))
        } else if w == ONE {
            at_level(self.level(k + 1))
        } else {
            lerp(at_level(self.level(k)), at_level(self.level(k + 1)), w)
        };
        let (moment, clamp) = if negative {
            (moment.saturating_neg(), clamp.mirrored())
        } else {
            (moment, clamp)
        };
        Ok(Lookup {
            value: MomentNm::from_bits(saturate_i32(moment)),
            clamp,
        })
    }

    /// Inverse bending map `phi = F_B^-1(M, s, P)` (eq 3.25): at each of the
    /// two neighbouring length levels `u` is bisected on `M0 + P M1` and
    /// scaled by that level's `phi_max`, then `phi` is interpolated linearly
    /// in `s`; a negative moment gives the negative angle. A level whose
    /// curve ends below `|M|` is extended along its last cell, and an answer
    /// beyond `phi_max(s)` (interpolated in `s`) is held there and flagged. A
    /// moment smaller than the table's value at `phi = 0` gives 0 (the dead
    /// band of a nonzero stored `M(0)`), unflagged.
    pub fn bending_angle(
        &self,
        moment: MomentNm,
        s: LengthM,
        p: PressurePa,
    ) -> Result<Lookup<AngleRad>, LookupError> {
        self.bending_angle_near(moment, s, p, BendHint::NONE)
            .map(|(phi, _)| phi)
    }

    /// [`Self::bending_angle`] that first tries the angle cells of `hint`
    /// (from an earlier call with a nearby moment, length and pressure) and
    /// bisects a level only when its cell no longer holds the moment; returns
    /// the hint for the next call. Without a hint the second length level
    /// starts from the first level's cell. On rows that increase (as the
    /// writer checks at stored pressures) the answer is exactly
    /// [`Self::bending_angle`]'s; under extrapolated pressures it is a point
    /// where the row crosses the moment, as there.
    #[inline(never)]
    pub fn bending_angle_near(
        &self,
        moment: MomentNm,
        s: LengthM,
        p: PressurePa,
        hint: BendHint,
    ) -> Result<(Lookup<AngleRad>, BendHint), LookupError> {
        let (k, w) = self.length_cell(s)?;
        self.check_pressure(p)?;
        let negative = moment < 0;
        let target = i64::from(moment.to_bits()).abs();
        let last = usize::from(self.bending_grid().n_u.max(2) - 1);
        let at_level = |index: usize, guess: Option<usize>| {
            let level = self.level(index);
            let row = self.moment_row(index, p);
            let f = |i| row.at(i);
            let (mut pos, side, cell) = invert_row_near(last, target, f, guess);
            if side == Side::Above {
                pos = pos.saturating_add(extension_q16(f(last - 1), f(last), target, last));
            }
            (level.angles.at_q16(pos), cell)
        };
        let [hint_k, hint_k1] = hint
            .cells
            .map(|c| (c != BendHint::UNSET).then_some(usize::from(c)));
        // `w` lies in 0..=ONE: at either end the other level's weight is 0
        // and `lerp` would return this level's value exactly.
        let (mut phi, cells) = if w == 0 {
            let (a, c) = at_level(k, hint_k);
            (a, [Some(c), None])
        } else if w == ONE {
            let (b, c) = at_level(k + 1, hint_k1);
            (b, [None, Some(c)])
        } else {
            let (a, ca) = at_level(k, hint_k);
            let (b, cb) = at_level(k + 1, hint_k1.or(Some(ca)));
            (lerp(a, b, w), [Some(ca), Some(cb)])
        };
        let top = self.phi_top(k, w);
        let mut clamp = Clamp::Inside;
        if phi > top {
            phi = top;
            clamp = Clamp::AboveRange;
        }
        let (phi, clamp) = if negative {
            (phi.saturating_neg(), clamp.mirrored())
        } else {
            (phi, clamp)
        };
        let next = BendHint {
            cells: cells.map(|c| {
                c.and_then(|c| u16::try_from(c).ok())
                    .unwrap_or(BendHint::UNSET)
            }),
        };
        Ok((
            Lookup {
                value: AngleRad::from_bits(saturate_i32(phi)),
                clamp,
            },
            next,
        ))
    }

    /// [`Self::axial_force`] for `f64` inputs and output (N, Pa).
    pub fn axial_force_f64(&self, eps: f64, p_pa: f64) -> Result<Lookup<f64>, LookupError> {
        let eps = to_fixed(eps, Quantity::Strain)?;
        let p = to_fixed(p_pa, Quantity::Pressure)?;
        Ok(self.axial_force(eps, p)?.map(|f| f.to_num()))
    }

    /// [`Self::axial_strain`] for `f64` inputs and output (N, Pa).
    pub fn axial_strain_f64(&self, force_n: f64, p_pa: f64) -> Result<Lookup<f64>, LookupError> {
        let force = to_fixed(force_n, Quantity::Force)?;
        let p = to_fixed(p_pa, Quantity::Pressure)?;
        Ok(self.axial_strain(force, p)?.map(|e| e.to_num()))
    }

    /// [`Self::bending_moment`] for `f64` inputs and output (rad, m, Pa, N*m).
    pub fn bending_moment_f64(
        &self,
        phi_rad: f64,
        s_m: f64,
        p_pa: f64,
    ) -> Result<Lookup<f64>, LookupError> {
        let phi = to_fixed(phi_rad, Quantity::Angle)?;
        let s = to_fixed(s_m, Quantity::Length)?;
        let p = to_fixed(p_pa, Quantity::Pressure)?;
        Ok(self.bending_moment(phi, s, p)?.map(|m| m.to_num()))
    }

    /// [`Self::bending_angle`] for `f64` inputs and output (N*m, m, Pa, rad).
    pub fn bending_angle_f64(
        &self,
        moment_nm: f64,
        s_m: f64,
        p_pa: f64,
    ) -> Result<Lookup<f64>, LookupError> {
        let moment = to_fixed(moment_nm, Quantity::Moment)?;
        let s = to_fixed(s_m, Quantity::Length)?;
        let p = to_fixed(p_pa, Quantity::Pressure)?;
        Ok(self.bending_angle(moment, s, p)?.map(|phi| phi.to_num()))
    }
}

/// How far past the last point (Q16 cells) the line through the last cell
/// `(before, end)` reaches `target`, at most `cells` more cells (doubling the
/// level's range; the caller holds the answer to `phi_max(s)` anyway).
fn extension_q16(before: i64, end: i64, target: i64, cells: usize) -> i64 {
    let slope = end.saturating_sub(before);
    if slope <= 0 {
        return 0;
    }
    let most = mul_one(cells as i64);
    div_round(mul_one(target.saturating_sub(end)), slope).clamp(0, most)
}

/// Rounds an `f64` input to its Q-format, naming it when it cannot.
fn to_fixed<F: Fixed>(value: f64, quantity: Quantity) -> Result<F, LookupError> {
    value
        .checked_to_fixed::<F>()
        .ok_or(LookupError::NotRepresentable { quantity, value })
}
