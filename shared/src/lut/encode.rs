//! The writer: checks sampled tables and lays them out as an image, without
//! allocating.

use fixed::traits::{Fixed, ToFixed};
use fixed::types::{I8F24, I16F16, I24F8, I32F0};

use super::error::{EncodeError, Grid, TableId};
use super::layout::*;

/// Samples of the axial force `F_A(eps, P)` on a uniform `(P, eps)` grid.
#[derive(Debug, Clone, Copy)]
pub struct AxialTableSpec<'a> {
    /// Lowest strain (rounded to `I16F16` in the image).
    pub eps_min: f64,
    /// Highest strain (rounded to `I16F16` in the image).
    pub eps_max: f64,
    /// Strain points, 2..=[`MAX_GRID_POINTS`].
    pub n_eps: u16,
    /// Lowest pressure level, Pa (rounded to `I24F8` in the image).
    pub p_min_pa: f64,
    /// Highest pressure level, Pa (rounded to `I24F8` in the image).
    pub p_max_pa: f64,
    /// Pressure levels, 2..=[`MAX_GRID_POINTS`].
    pub n_p: u16,
    /// Forces in newtons, row-major `[p][eps]`, each row non-decreasing.
    pub force_n: &'a [f64],
}

/// Samples of the bending moment `M = M0 + P M1` on uniform `(s, u)` grids,
/// `u = phi / phi_max(s)` in `0..=1`.
#[derive(Debug, Clone, Copy)]
pub struct BendingTableSpec<'a> {
    /// Shortest neutral-axis length level, m (rounded to `I8F24`).
    pub s_min_m: f64,
    /// Longest neutral-axis length level, m (rounded to `I8F24`).
    pub s_max_m: f64,
    /// Length levels, 2..=[`MAX_GRID_POINTS`].
    pub n_s: u16,
    /// Normalized angle points over `0..=1`, 2..=[`MAX_GRID_POINTS`].
    pub n_u: u16,
    /// Maximum feasible bending angle per length level, rad, positive.
    pub phi_max_rad: &'a [f64],
    /// Moment at zero pressure, N*m, row-major `[s][u]`.
    pub m0_nm: &'a [f64],
    /// Moment per pascal `dM/dP`, N*m/Pa, row-major `[s][u]`.
    pub m1_nm_per_pa: &'a [f64],
}

/// Bytes of the image [`encode`] writes for these grids.
pub fn encoded_len(axial: &AxialTableSpec, bending: &BendingTableSpec) -> usize {
    let elements = axial_count(axial)
        .saturating_add(usize::from(bending.n_s))
        .saturating_add(plane_count(bending).saturating_mul(2));
    HEADER_LEN
        .saturating_add(elements.saturating_mul(ELEMENT_LEN))
        .saturating_add(CRC_LEN)
}

/// Strain of grid point `i` exactly as the image places it (bounds rounded to
/// `I16F16`); NaN if a bound cannot be represented. Sample the model here.
pub fn strain_grid(eps_min: f64, eps_max: f64, n_eps: u16, i: u16) -> f64 {
    grid_point::<I16F16>(eps_min, eps_max, n_eps, i)
}

/// Pressure of level `j` in Pa exactly as the image places it (bounds rounded
/// to `I24F8`); NaN if a bound cannot be represented.
pub fn pressure_grid_pa(p_min_pa: f64, p_max_pa: f64, n_p: u16, j: u16) -> f64 {
    grid_point::<I24F8>(p_min_pa, p_max_pa, n_p, j)
}

/// Neutral-axis length of level `k` in m exactly as the image places it
/// (bounds rounded to `I8F24`); NaN if a bound cannot be represented.
pub fn length_grid_m(s_min_m: f64, s_max_m: f64, n_s: u16, k: u16) -> f64 {
    grid_point::<I8F24>(s_min_m, s_max_m, n_s, k)
}

fn grid_point<F: Fixed>(min: f64, max: f64, n: u16, i: u16) -> f64 {
    match (min.checked_to_fixed::<F>(), max.checked_to_fixed::<F>()) {
        (Some(lo), Some(hi)) => {
            let (lo, hi): (f64, f64) = (lo.to_num(), hi.to_num());
            let cells = f64::from(n.max(2) - 1);
            lo + (hi - lo) * f64::from(i) / cells
        }
        _ => f64::NAN,
    }
}

fn axial_count(axial: &AxialTableSpec) -> usize {
    usize::from(axial.n_p).saturating_mul(usize::from(axial.n_eps))
}

fn plane_count(bending: &BendingTableSpec) -> usize {
    usize::from(bending.n_s).saturating_mul(usize::from(bending.n_u))
}

/// Writes the image of `axial` and `bending`, stamped with `param_hash`
/// ([`crate::params::OcmParams::hash`]), into the front of `out` and returns
/// its length. Values are rounded to nearest in their Q-formats. On error the
/// content of `out` is unspecified.
pub fn encode(
    param_hash: u64,
    axial: &AxialTableSpec,
    bending: &BendingTableSpec,
    out: &mut [u8],
) -> Result<usize, EncodeError> {
    let eps = grid_bounds::<I16F16>(Grid::Strain, axial.eps_min, axial.eps_max, axial.n_eps)?;
    let p = grid_bounds::<I24F8>(Grid::Pressure, axial.p_min_pa, axial.p_max_pa, axial.n_p)?;
    let s = grid_bounds::<I8F24>(Grid::Length, bending.s_min_m, bending.s_max_m, bending.n_s)?;
    check_points(Grid::NormalizedAngle, bending.n_u)?;

    let planes = plane_count(bending);
    check_size(TableId::AxialForce, axial_count(axial), axial.force_n.len())?;
    check_size(
        TableId::PhiMax,
        usize::from(bending.n_s),
        bending.phi_max_rad.len(),
    )?;
    check_size(TableId::MomentAtZeroPressure, planes, bending.m0_nm.len())?;
    check_size(TableId::MomentPerPascal, planes, bending.m1_nm_per_pa.len())?;

    let needed = encoded_len(axial, bending);
    if out.len() < needed {
        return Err(EncodeError::BufferTooSmall {
            needed,
            got: out.len(),
        });
    }

    let n_eps = usize::from(axial.n_eps);
    let n_u = usize::from(bending.n_u);
    check_finite(TableId::AxialForce, axial.force_n, n_eps)?;
    check_finite(TableId::PhiMax, bending.phi_max_rad, 1)?;
    check_finite(TableId::MomentAtZeroPressure, bending.m0_nm, n_u)?;
    check_finite(TableId::MomentPerPascal, bending.m1_nm_per_pa, n_u)?;

    // Axial rows must not decrease at any stored pressure.
    for (j, row) in axial.force_n.chunks_exact(n_eps).enumerate() {
        let pressure_pa = pressure_grid_pa(axial.p_min_pa, axial.p_max_pa, axial.n_p, j as u16);
        check_row(TableId::AxialForce, j, pressure_pa, row.iter().copied())?;
    }
    // Bending rows are affine in P: not decreasing at both ends of the
    // pressure grid means not decreasing anywhere between.
    for pressure_pa in [p.0.to_num::<f64>(), p.1.to_num::<f64>()] {
        let rows = bending.m0_nm.chunks_exact(n_u);
        let slopes = bending.m1_nm_per_pa.chunks_exact(n_u);
        for (k, (m0, m1)) in rows.zip(slopes).enumerate() {
            let combined = m0.iter().zip(m1).map(|(a, b)| a + pressure_pa * b);
            check_row(TableId::MomentAtZeroPressure, k, pressure_pa, combined)?;
        }
    }

    let m1_frac_bits = m1_frac_bits(bending.m1_nm_per_pa, n_u)?;

    // Header.
    write_bytes(out, OFF_MAGIC, &MAGIC);
    write_bytes(out, OFF_VERSION, &FORMAT_VERSION.to_le_bytes());
    write_bytes(out, OFF_HEADER_LEN, &(HEADER_LEN as u16).to_le_bytes());
    write_bytes(out, OFF_TOTAL_LEN, &(needed as u32).to_le_bytes());
    write_bytes(out, OFF_PARAM_HASH, &param_hash.to_le_bytes());
    write_bytes(out, OFF_FLAGS, &0u32.to_le_bytes());
    write_bytes(out, OFF_EPS_MIN, &eps.0.to_bits().to_le_bytes());
    write_bytes(out, OFF_EPS_MAX, &eps.1.to_bits().to_le_bytes());
    write_bytes(out, OFF_N_EPS, &axial.n_eps.to_le_bytes());
    write_bytes(out, OFF_N_P, &axial.n_p.to_le_bytes());
    write_bytes(out, OFF_P_MIN, &p.0.to_bits().to_le_bytes());
    write_bytes(out, OFF_P_MAX, &p.1.to_bits().to_le_bytes());
    write_bytes(out, OFF_S_MIN, &s.0.to_bits().to_le_bytes());
    write_bytes(out, OFF_S_MAX, &s.1.to_bits().to_le_bytes());
    write_bytes(out, OFF_N_S, &bending.n_s.to_le_bytes());
    write_bytes(out, OFF_N_U, &bending.n_u.to_le_bytes());
    write_bytes(out, OFF_RESERVED, &0u32.to_le_bytes());

    // Tables, back to back after the header, each with its descriptor.
    let tables = [
        (axial.force_n.len(), FORCE_FRAC_BITS),
        (bending.phi_max_rad.len(), PHI_MAX_FRAC_BITS),
        (planes, M0_FRAC_BITS),
        (planes, m1_frac_bits),
    ];
    let mut at = HEADER_LEN;
    let mut starts = [0usize; TABLE_COUNT];
    for (t, (count, frac_bits)) in tables.into_iter().enumerate() {
        let d = OFF_DESCRIPTORS + t * DESCRIPTOR_LEN;
        write_bytes(out, d, &(at as u32).to_le_bytes());
        write_bytes(out, d + 4, &(count as u32).to_le_bytes());
        write_bytes(out, d + 8, &[frac_bits, ELEMENT_I32, 0, 0]);
        starts[t] = at;
        at += count * ELEMENT_LEN;
    }

    write_table::<I16F16>(out, starts[0], TableId::AxialForce, axial.force_n, n_eps)?;
    write_table::<I16F16>(out, starts[1], TableId::PhiMax, bending.phi_max_rad, 1)?;
    for (k, raw) in out[starts[1]..starts[2]]
        .chunks_exact(ELEMENT_LEN)
        .enumerate()
    {
        if i32::from_le_bytes([raw[0], raw[1], raw[2], raw[3]]) <= 0 {
            return Err(EncodeError::PhiMaxNotPositive { level: k as u16 });
        }
    }
    write_table::<I8F24>(
        out,
        starts[2],
        TableId::MomentAtZeroPressure,
        bending.m0_nm,
        n_u,
    )?;
    let scale = pow2(m1_frac_bits);
    for (index, &v) in bending.m1_nm_per_pa.iter().enumerate() {
        let raw = (v * scale)
            .checked_to_fixed::<I32F0>()
            .ok_or_else(|| out_of_range(TableId::MomentPerPascal, index, n_u, v))?;
        write_bytes(
            out,
            starts[3] + index * ELEMENT_LEN,
            &raw.to_bits().to_le_bytes(),
        );
    }

    let body = needed - CRC_LEN;
    let crc = CRC32.checksum(&out[..body]);
    write_bytes(out, body, &crc.to_le_bytes());
    Ok(needed)
}

/// Rounds a grid's bounds to `F` and checks points and order.
fn grid_bounds<F: Fixed>(
    grid: Grid,
    min: f64,
    max: f64,
    points: u16,
) -> Result<(F, F), EncodeError> {
    check_points(grid, points)?;
    let q = |value: f64| {
        value
            .checked_to_fixed::<F>()
            .ok_or(EncodeError::GridBound { grid, value })
    };
    let (lo, hi) = (q(min)?, q(max)?);
    if lo >= hi {
        return Err(EncodeError::InvertedGrid { grid });
    }
    Ok((lo, hi))
}

fn check_points(grid: Grid, points: u16) -> Result<(), EncodeError> {
    if points < 2 {
        Err(EncodeError::EmptyGrid { grid, points })
    } else if points > MAX_GRID_POINTS {
        Err(EncodeError::GridTooLarge { grid, points })
    } else {
        Ok(())
    }
}

fn check_size(table: TableId, expected: usize, got: usize) -> Result<(), EncodeError> {
    if expected == got {
        Ok(())
    } else {
        Err(EncodeError::SizeMismatch {
            table,
            expected,
            got,
        })
    }
}

/// Row and column of element `index` in a table `cols` wide. Grids hold at
/// most [`MAX_GRID_POINTS`] points, so both fit a `u16`.
fn row_col(index: usize, cols: usize) -> (u16, u16) {
    let cols = cols.max(1);
    ((index / cols) as u16, (index % cols) as u16)
}

fn check_finite(table: TableId, values: &[f64], cols: usize) -> Result<(), EncodeError> {
    match values.iter().position(|v| !v.is_finite()) {
        Some(index) => {
            let (row, col) = row_col(index, cols);
            Err(EncodeError::NotFinite { table, row, col })
        }
        None => Ok(()),
    }
}

fn check_row(
    table: TableId,
    row: usize,
    pressure_pa: f64,
    values: impl Iterator<Item = f64>,
) -> Result<(), EncodeError> {
    let mut previous: Option<f64> = None;
    for (col, v) in values.enumerate() {
        if let Some(prev) = previous
            && v < prev
        {
            return Err(EncodeError::NonMonotone {
                table,
                row: row as u16,
                col: (col - 1) as u16,
                pressure_pa,
            });
        }
        previous = Some(v);
    }
    Ok(())
}

fn out_of_range(table: TableId, index: usize, cols: usize, value: f64) -> EncodeError {
    let (row, col) = row_col(index, cols);
    EncodeError::OutOfRange {
        table,
        row,
        col,
        value,
    }
}

/// Rounds every value to `F` and writes its raw bits little-endian.
fn write_table<F: Fixed<Bits = i32>>(
    out: &mut [u8],
    start: usize,
    table: TableId,
    values: &[f64],
    cols: usize,
) -> Result<(), EncodeError> {
    for (index, &v) in values.iter().enumerate() {
        let q = v
            .checked_to_fixed::<F>()
            .ok_or_else(|| out_of_range(table, index, cols, v))?;
        write_bytes(out, start + index * ELEMENT_LEN, &q.to_bits().to_le_bytes());
    }
    Ok(())
}

/// `2^bits` as `f64`, exact for `bits` in `0..=1023`.
fn pow2(bits: u8) -> f64 {
    f64::from_bits((1023 + u64::from(bits)) << 52)
}

/// The largest binary point in `16..=62` at which every `M1` fits an `i32`,
/// which keeps the most resolution for the small slopes of real OCMs.
fn m1_frac_bits(m1: &[f64], cols: usize) -> Result<u8, EncodeError> {
    let magnitude = |v: f64| if v < 0.0 { -v } else { v };
    let (index, largest) =
        m1.iter()
            .copied()
            .map(magnitude)
            .enumerate()
            .fold(
                (0, 0.0),
                |best, (i, v)| if v > best.1 { (i, v) } else { best },
            );
    // Below 2^31 - 1 after rounding to nearest.
    let limit = f64::from(i32::MAX) - 0.5;
    (M1_FRAC_BITS_MIN..=M1_FRAC_BITS_MAX)
        .rev()
        .find(|&bits| largest * pow2(bits) < limit)
        .ok_or_else(|| {
            let value = m1.get(index).copied().unwrap_or(largest);
            out_of_range(TableId::MomentPerPascal, index, cols, value)
        })
}
