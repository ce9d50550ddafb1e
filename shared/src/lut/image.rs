//! The reader: validates an image once and then serves its grids and tables
//! straight from the borrowed bytes.

use fixed::types::{I8F24, I16F16, I24F8};

use super::error::{Grid, LutError, TableId};
use super::fixed_math::{ONE, Uniform, saturate_i32};
use super::layout::*;
use super::{LengthM, PressurePa, Strain};

/// The axial table's grids: strain points and pressure levels.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct AxialGrid {
    /// Lowest strain point.
    pub eps_min: Strain,
    /// Highest strain point.
    pub eps_max: Strain,
    /// Strain points.
    pub n_eps: u16,
    /// Lowest pressure level.
    pub p_min: PressurePa,
    /// Highest pressure level.
    pub p_max: PressurePa,
    /// Pressure levels.
    pub n_p: u16,
}

impl AxialGrid {
    /// Strain grid as raw-bit uniform grid.
    pub(crate) fn strain_grid(&self) -> Uniform {
        Uniform {
            min: self.eps_min.to_bits().into(),
            max: self.eps_max.to_bits().into(),
            points: self.n_eps,
        }
    }

    /// Pressure grid as raw-bit uniform grid.
    pub(crate) fn pressure_grid(&self) -> Uniform {
        Uniform {
            min: self.p_min.to_bits().into(),
            max: self.p_max.to_bits().into(),
            points: self.n_p,
        }
    }

    /// Strain of point `i`, or `None` past the grid.
    pub fn strain_at(&self, i: u16) -> Option<Strain> {
        (i < self.n_eps)
            .then(|| point(self.strain_grid(), i))
            .map(Strain::from_bits)
    }

    /// Pressure of level `j`, or `None` past the grid.
    pub fn pressure_at(&self, j: u16) -> Option<PressurePa> {
        (j < self.n_p)
            .then(|| point(self.pressure_grid(), j))
            .map(PressurePa::from_bits)
    }

    /// Lowest and highest pressure the lookups answer: the grid widened by
    /// [`PRESSURE_MARGIN_PA`] on each side.
    pub fn pressure_window(&self) -> (PressurePa, PressurePa) {
        let margin = i64::from(PRESSURE_MARGIN_PA) << I24F8::FRAC_NBITS;
        let lo = i64::from(self.p_min.to_bits()) - margin;
        let hi = i64::from(self.p_max.to_bits()) + margin;
        (
            PressurePa::from_bits(saturate_i32(lo)),
            PressurePa::from_bits(saturate_i32(hi)),
        )
    }
}

/// The bending table's grids: length levels, angle points and the scale of
/// the `M1` plane.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BendingGrid {
    /// Shortest neutral-axis length level.
    pub s_min: LengthM,
    /// Longest neutral-axis length level.
    pub s_max: LengthM,
    /// Length levels.
    pub n_s: u16,
    /// Normalized angle points `u = phi / phi_max(s)` over `0..=1`.
    pub n_u: u16,
    /// Binary point of the stored `M1` (N*m/Pa): value = raw * 2^-bits.
    pub m1_frac_bits: u8,
}

impl BendingGrid {
    /// Length grid as raw-bit uniform grid.
    pub(crate) fn length_grid(&self) -> Uniform {
        Uniform {
            min: self.s_min.to_bits().into(),
            max: self.s_max.to_bits().into(),
            points: self.n_s,
        }
    }

    /// Neutral-axis length of level `k`, or `None` past the grid.
    pub fn length_at(&self, k: u16) -> Option<LengthM> {
        (k < self.n_s)
            .then(|| point(self.length_grid(), k))
            .map(LengthM::from_bits)
    }

    /// Normalized angle of point `i` (`I16F16`), or `None` past the grid.
    pub fn u_at(&self, i: u16) -> Option<I16F16> {
        let unit = Uniform {
            min: 0,
            max: ONE,
            points: self.n_u,
        };
        (i < self.n_u)
            .then(|| point(unit, i))
            .map(I16F16::from_bits)
    }
}

/// Raw bits of grid point `i`.
fn point(grid: Uniform, i: u16) -> i32 {
    saturate_i32(grid.at_q16(i64::from(i) * ONE))
}

/// A validated LUT image borrowed from its bytes.
#[derive(Debug, Clone, Copy)]
pub struct LutImage<'a> {
    /// Exactly the image, CRC included, without any trailing padding.
    bytes: &'a [u8],
    param_hash: u64,
    crc: u32,
    axial: AxialGrid,
    bending: BendingGrid,
    /// Byte offsets of the tables, in [`TableId`] order.
    table_at: [usize; TABLE_COUNT],
    /// Right shift taking `P * M1` (Q`8 + m1_frac_bits`) to `M0`'s Q24.
    m1_shift: u32,
}

const TABLES: [TableId; TABLE_COUNT] = [
    TableId::AxialForce,
    TableId::PhiMax,
    TableId::MomentAtZeroPressure,
    TableId::MomentPerPascal,
];

impl<'a> LutImage<'a> {
    /// Validates `bytes` as a LUT image (see the module docs for the order of
    /// checks). Bytes after the declared length are ignored.
    pub fn parse(bytes: &'a [u8]) -> Result<Self, LutError> {
        let min_len = HEADER_LEN + CRC_LEN;
        let head = bytes.get(..MAGIC.len()).unwrap_or(bytes);
        if head != &MAGIC[..head.len()] {
            let mut found = [0u8; 8];
            found[..head.len()].copy_from_slice(head);
            return Err(LutError::BadMagic { found });
        }
        if bytes.len() < min_len {
            return Err(LutError::Truncated {
                needed: min_len,
                got: bytes.len(),
            });
        }
        let u16_at = |at| read_u16(bytes, at).unwrap_or(0);
        let u32_at = |at| read_u32(bytes, at).unwrap_or(0);
        let i32_at = |at| read_i32(bytes, at).unwrap_or(0);

        let version = u16_at(OFF_VERSION);
        if version != FORMAT_VERSION {
            return Err(LutError::UnsupportedVersion { found: version });
        }
        let declared = u32_at(OFF_TOTAL_LEN);
        let total = usize::try_from(declared).unwrap_or(usize::MAX);
        if total < min_len {
            return Err(LutError::BadTotalLength { declared });
        }
        let Some(image) = bytes.get(..total) else {
            return Err(LutError::Truncated {
                needed: total,
                got: bytes.len(),
            });
        };
        let body_len = total - CRC_LEN;
        let stored = read_u32(image, body_len).unwrap_or(0);
        let computed = CRC32.checksum(image.get(..body_len).unwrap_or(&[]));
        if stored != computed {
            return Err(LutError::CrcMismatch { stored, computed });
        }

        let header_len = u16_at(OFF_HEADER_LEN);
        if usize::from(header_len) != HEADER_LEN {
            return Err(LutError::BadHeaderLength { found: header_len });
        }
        let flags = u32_at(OFF_FLAGS);
        if flags != 0 {
            return Err(LutError::UnsupportedFlags { flags });
        }
        if u32_at(OFF_RESERVED) != 0 {
            return Err(LutError::ReservedNotZero {
                offset: OFF_RESERVED,
            });
        }

        let axial = AxialGrid {
            eps_min: I16F16::from_bits(i32_at(OFF_EPS_MIN)),
            eps_max: I16F16::from_bits(i32_at(OFF_EPS_MAX)),
            n_eps: u16_at(OFF_N_EPS),
            p_min: I24F8::from_bits(i32_at(OFF_P_MIN)),
            p_max: I24F8::from_bits(i32_at(OFF_P_MAX)),
            n_p: u16_at(OFF_N_P),
        };
        let bending = BendingGrid {
            s_min: I8F24::from_bits(i32_at(OFF_S_MIN)),
            s_max: I8F24::from_bits(i32_at(OFF_S_MAX)),
            n_s: u16_at(OFF_N_S),
            n_u: u16_at(OFF_N_U),
            m1_frac_bits: read_u8(bytes, OFF_DESCRIPTORS + 3 * DESCRIPTOR_LEN + 8).unwrap_or(0),
        };
        check_grid(Grid::Strain, axial.strain_grid())?;
        check_grid(Grid::Pressure, axial.pressure_grid())?;
        check_grid(Grid::Length, bending.length_grid())?;
        check_points(Grid::NormalizedAngle, bending.n_u)?;

        let n_p = u32::from(axial.n_p);
        let n_s = u32::from(bending.n_s);
        let expected = [
            n_p * u32::from(axial.n_eps),
            n_s,
            n_s * u32::from(bending.n_u),
            n_s * u32::from(bending.n_u),
        ];
        let mut table_at = [0usize; TABLE_COUNT];
        let mut free_from = HEADER_LEN as u64;
        for (t, table) in TABLES.into_iter().enumerate() {
            let at = OFF_DESCRIPTORS + t * DESCRIPTOR_LEN;
            let offset = u32_at(at);
            let count = u32_at(at + 4);
            let frac_bits = read_u8(bytes, at + 8).unwrap_or(0);
            let element = read_u8(bytes, at + 9).unwrap_or(0);
            if element != ELEMENT_I32 {
                return Err(LutError::TableElementType {
                    table,
                    found: element,
                });
            }
            if u16_at(at + 10) != 0 {
                return Err(LutError::ReservedNotZero { offset: at + 10 });
            }
            let frac_ok = match table {
                TableId::AxialForce => frac_bits == FORCE_FRAC_BITS,
                TableId::PhiMax => frac_bits == PHI_MAX_FRAC_BITS,
                TableId::MomentAtZeroPressure => frac_bits == M0_FRAC_BITS,
                TableId::MomentPerPascal => {
                    (M1_FRAC_BITS_MIN..=M1_FRAC_BITS_MAX).contains(&frac_bits)
                }
            };
            if !frac_ok {
                return Err(LutError::TableFracBits {
                    table,
                    found: frac_bits,
                });
            }
            if count != expected[t] {
                return Err(LutError::TableCount {
                    table,
                    expected: expected[t],
                    found: count,
                });
            }
            let start = u64::from(offset);
            let end = start + u64::from(count) * ELEMENT_LEN as u64;
            if start % ELEMENT_LEN as u64 != 0 || start < free_from || end > body_len as u64 {
                return Err(LutError::TablePlacement {
                    table,
                    offset,
                    count,
                });
            }
            free_from = end;
            // `end <= body_len`, so the offset fits a `usize`.
            table_at[t] = offset as usize;
        }

        let lut = Self {
            bytes: image,
            param_hash: read_u64(bytes, OFF_PARAM_HASH).unwrap_or(0),
            crc: stored,
            axial,
            bending,
            table_at,
            // `m1_frac_bits` was checked to lie in 16..=62: a shift of 0..=46.
            m1_shift: u32::from(bending.m1_frac_bits)
                .saturating_add(8)
                .saturating_sub(u32::from(M0_FRAC_BITS)),
        };
        for level in 0..bending.n_s {
            if lut.phi_max_raw(usize::from(level)) <= 0 {
                return Err(LutError::PhiMaxNotPositive { level });
            }
        }
        Ok(lut)
    }

    /// Hash of the OCM parameters the tables were built from.
    pub fn param_hash(&self) -> u64 {
        self.param_hash
    }

    /// The image's CRC-32 (checked by [`Self::parse`]).
    pub fn crc(&self) -> u32 {
        self.crc
    }

    /// Format version of the image.
    pub fn version(&self) -> u16 {
        FORMAT_VERSION
    }

    /// Length of the image in bytes, CRC included, padding excluded.
    pub fn size_bytes(&self) -> usize {
        self.bytes.len()
    }

    /// The image's bytes, CRC included, padding excluded.
    pub fn as_bytes(&self) -> &'a [u8] {
        self.bytes
    }

    /// Grids of the axial table.
    pub fn axial_grid(&self) -> AxialGrid {
        self.axial
    }

    /// Grids of the bending table.
    pub fn bending_grid(&self) -> BendingGrid {
        self.bending
    }

    /// Stored axial force at pressure level `j`, strain point `i`.
    pub fn axial_force_at(&self, j: u16, i: u16) -> Option<I16F16> {
        (j < self.axial.n_p && i < self.axial.n_eps)
            .then(|| self.force_raw(usize::from(j), usize::from(i)))
            .map(|raw| I16F16::from_bits(saturate_i32(raw)))
    }

    /// Stored maximum bending angle of length level `k`.
    pub fn phi_max_at(&self, k: u16) -> Option<I16F16> {
        (k < self.bending.n_s)
            .then(|| self.phi_max_raw(usize::from(k)))
            .map(|raw| I16F16::from_bits(saturate_i32(raw)))
    }

    /// Stored zero-pressure moment of length level `k`, angle point `i`.
    pub fn moment_at_zero_pressure_at(&self, k: u16, i: u16) -> Option<I8F24> {
        (k < self.bending.n_s && i < self.bending.n_u)
            .then(|| self.plane_raw(2, usize::from(k), usize::from(i)))
            .map(|raw| I8F24::from_bits(saturate_i32(raw)))
    }

    /// Stored moment per pascal of length level `k`, angle point `i`, as raw
    /// bits with [`BendingGrid::m1_frac_bits`] fractional bits.
    pub fn moment_per_pascal_raw_at(&self, k: u16, i: u16) -> Option<i32> {
        (k < self.bending.n_s && i < self.bending.n_u)
            .then(|| self.plane_raw(3, usize::from(k), usize::from(i)))
            .map(saturate_i32)
    }

    /// Stored moment per pascal of length level `k`, angle point `i`, N*m/Pa.
    pub fn moment_per_pascal_f64_at(&self, k: u16, i: u16) -> Option<f64> {
        let raw = self.moment_per_pascal_raw_at(k, i)?;
        Some(f64::from(raw) * pow2_neg(self.bending.m1_frac_bits))
    }

    /// Row `j` (one pressure level) of the axial table, for callers that
    /// interpolate on it many times; `None` past the grid.
    pub fn axial_row(&self, j: u16) -> Option<AxialRow<'a>> {
        if j >= self.axial.n_p {
            return None;
        }
        let len = usize::from(self.axial.n_eps) * ELEMENT_LEN;
        let start = self.table_at[0].checked_add(usize::from(j).checked_mul(len)?)?;
        let bytes = self.bytes.get(start..start.checked_add(len)?)?;
        Some(AxialRow { bytes })
    }

    /// Bytes of row `k` (one length level, `n_u` elements) of bending plane
    /// `t` (2 = `M0`, 3 = `M1`); empty past the end (unreachable after
    /// validation), whose elements the lookups read as zeros.
    pub(crate) fn plane_row(&self, t: usize, k: usize) -> &'a [u8] {
        let n = usize::from(self.bending.n_u);
        let base = self.table_at.get(t).copied().unwrap_or(0);
        let start = k
            .checked_mul(n * ELEMENT_LEN)
            .and_then(|o| o.checked_add(base));
        let end = start.and_then(|s| s.checked_add(n * ELEMENT_LEN));
        match (start, end) {
            (Some(s), Some(e)) => self.bytes.get(s..e).unwrap_or(&[]),
            _ => &[],
        }
    }

    /// Shift taking `P (Q8) * M1` to the `I8F24` of `M0`.
    #[inline(always)]
    pub(crate) fn m1_shift(&self) -> u32 {
        self.m1_shift
    }

    /// Raw element `index` of table `t`; 0 past the end (unreachable after
    /// validation, and keeps the accessors total).
    #[inline(always)]
    fn element(&self, t: usize, index: usize) -> i64 {
        let base = self.table_at.get(t).copied().unwrap_or(0);
        let at = index
            .checked_mul(ELEMENT_LEN)
            .and_then(|o| o.checked_add(base));
        at.and_then(|at| read_i32(self.bytes, at))
            .map_or(0, i64::from)
    }

    /// Raw force at pressure level `j`, strain point `i`.
    pub(crate) fn force_raw(&self, j: usize, i: usize) -> i64 {
        self.element(0, j * usize::from(self.axial.n_eps) + i)
    }

    /// Raw `phi_max` of length level `k`.
    #[inline(always)]
    pub(crate) fn phi_max_raw(&self, k: usize) -> i64 {
        self.element(1, k)
    }

    /// Raw element of bending plane `t` (2 = `M0`, 3 = `M1`).
    pub(crate) fn plane_raw(&self, t: usize, k: usize, i: usize) -> i64 {
        self.element(t, k * usize::from(self.bending.n_u) + i)
    }
}

/// One pressure level of the axial table ([`LutImage::axial_row`]).
#[derive(Debug, Clone, Copy)]
pub struct AxialRow<'a> {
    bytes: &'a [u8],
}

impl AxialRow<'_> {
    /// Stored forces (raw `I16F16` bits) at strain points `i` and `i + 1`,
    /// the ends of strain cell `i`; `None` past the row.
    #[inline(always)]
    pub fn cell(&self, i: usize) -> Option<[i32; 2]> {
        let at = i.checked_mul(ELEMENT_LEN)?;
        let pair = self.bytes.get(at..at.checked_add(2 * ELEMENT_LEN)?)?;
        let (a, b) = pair.split_at_checked(ELEMENT_LEN)?;
        Some([
            i32::from_le_bytes(a.try_into().ok()?),
            i32::from_le_bytes(b.try_into().ok()?),
        ])
    }
}

/// `2^-bits` as `f64`, exact for `bits` in `0..=1022`.
pub(crate) fn pow2_neg(bits: u8) -> f64 {
    f64::from_bits((1023 - u64::from(bits)) << 52)
}

/// A grid needs `2..=MAX_GRID_POINTS` points.
fn check_points(grid: Grid, points: u16) -> Result<(), LutError> {
    if points < 2 {
        Err(LutError::EmptyGrid { grid, points })
    } else if points > MAX_GRID_POINTS {
        Err(LutError::GridTooLarge { grid, points })
    } else {
        Ok(())
    }
}

/// A grid needs a valid point count and `min < max`.
fn check_grid(grid: Grid, uniform: Uniform) -> Result<(), LutError> {
    check_points(grid, uniform.points)?;
    if uniform.min >= uniform.max {
        return Err(LutError::InvertedGrid { grid });
    }
    Ok(())
}
