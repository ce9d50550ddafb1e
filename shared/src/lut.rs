//! The LUT image: fixed-point forward and inverse maps of one OCM type.
//!
//! An OCM's axial force `F_A(eps, P)` and bending moment `M(phi, s, P)`
//! (dissertation Ch. 3.3.4, eq 3.24-3.25, App. A) are sampled by the host
//! (`ocm-lutgen`) and written here into one checksummed little-endian byte
//! image. The firmware validates the image with [`LutImage::parse`] and then
//! answers the inverse questions it needs for control without floats, heap or
//! panics:
//!
//! * `eps = F_A^-1(F, P)`: [`LutImage::axial_strain`],
//! * `phi = F_B^-1(M, s, P)`: [`LutImage::bending_angle`],
//!
//! plus the forward maps [`LutImage::axial_force`] and
//! [`LutImage::bending_moment`], and `*_f64` twins of all four for the host,
//! which convert at the boundary and run the very same fixed-point path.
//!
//! # Physics the format relies on
//!
//! * Both maps are exactly affine in pressure (the pressure work is `P dV`,
//!   eq 3.7). The axial table therefore stores rows at a few pressure levels and
//!   interpolates *linearly* between the two neighbouring rows; outside the
//!   pressure grid the nearest two rows are extrapolated, which is exact for
//!   the physics. Lookups accept pressures in the window
//!   `[p_min - PRESSURE_MARGIN, p_max + PRESSURE_MARGIN]`
//!   ([`PRESSURE_MARGIN_PA`] = 20 kPa, so -20..50 kPa for the default grid,
//!   which covers the firmware's -20..35 kPa). The bending table stores the
//!   affine form itself: `M = M0 + P * M1`.
//! * For a fixed `P` (and `s`), `F_A` increases with `eps` and `M` with `phi`
//!   over the stored range. The reader *assumes* it: its inverses are bounded
//!   bisections (at most `ceil(log2(n - 1))` steps) on the row. The writer
//!   *checks* it: a row that decreases anywhere is rejected with
//!   [`EncodeError::NonMonotone`] naming table, row and column. Axial rows are
//!   checked at every stored pressure; bending rows at the lowest and highest
//!   pressure of the axial grid, which by affinity covers every pressure in
//!   between. Flat runs are allowed; the inverse then returns the largest
//!   abscissa of the run. Under extrapolated pressures a row may lose
//!   monotonicity; the inverse still returns a point where the interpolated row
//!   crosses the target whenever the row's first value lies below the target
//!   and its last value above it.
//! * `M(-phi) = -M(phi)`: only `phi >= 0` is stored; negative angles and
//!   moments are answered by symmetry.
//! * Between two length levels the bending lookups work on both levels and
//!   interpolate linearly in `s`: the forward map interpolates `M` at fixed
//!   `phi`, the inverse interpolates `phi` at fixed `M`. The feasible angle
//!   `phi_max(s)` is itself interpolated in `s`; where `phi` (or the angle
//!   reached) exceeds the shorter level's `phi_max`, that level's curve is
//!   extended along its last cell, and only an answer beyond `phi_max(s)`
//!   saturates.
//! * Saturation is not an error: every lookup returns a [`Lookup`] whose
//!   [`Clamp`] says whether the input lay below or above the table (the value
//!   is then the table's end). Errors ([`LookupError`]) are kept for inputs
//!   the table cannot place at all: a pressure outside the window, a length
//!   outside the stored levels, an `f64` that does not fit its Q-format.
//!
//! # Q-formats (types from the `fixed` crate)
//!
//! | quantity                    | type               | alias          | resolution       | range            |
//! |-----------------------------|--------------------|----------------|------------------|------------------|
//! | axial strain `eps`          | `I16F16`           | [`Strain`]     | 1.5e-5           | ±32768           |
//! | axial force `F`, N          | `I16F16`           | [`ForceN`]     | 1.5e-5 N         | ±32768 N         |
//! | pressure `P`, Pa            | `I24F8`            | [`PressurePa`] | 3.9e-3 Pa        | ±8.4 MPa         |
//! | bending angle `phi`, rad    | `I16F16`           | [`AngleRad`]   | 1.5e-5 rad       | ±32768 rad       |
//! | neutral-axis length `s`, m  | `I8F24`            | [`LengthM`]    | 6.0e-8 m         | ±128 m           |
//! | bending moment `M`, N*m     | `I8F24`            | [`MomentNm`]   | 6.0e-8 N*m       | ±128 N*m         |
//! | `dM/dP` (`M1`), N*m/Pa      | raw `i32` scaled by `2^-k`, `k` in the header (16..=62); the writer picks the largest `k` that fits the table | | | |
//!
//! Inputs and outputs of the fixed-point lookups use these types; results that
//! would leave the output type saturate at its bounds.
//!
//! # Byte layout (format version 1, all integers little-endian)
//!
//! | offset | size | type     | field                                                              |
//! |-------:|-----:|----------|--------------------------------------------------------------------|
//! | 0      | 8    | `[u8;8]` | magic `b"OCMLUT\0\x1a"` ([`MAGIC`])                                |
//! | 8      | 2    | `u16`    | format version, 1 ([`FORMAT_VERSION`])                             |
//! | 10     | 2    | `u16`    | header length in bytes, 112 ([`HEADER_LEN`]): offset of the tables |
//! | 12     | 4    | `u32`    | total image length in bytes, CRC included                          |
//! | 16     | 8    | `u64`    | parameter hash ([`crate::params::OcmParams::hash`])                |
//! | 24     | 4    | `u32`    | flags; none defined in version 1, must be 0                        |
//! | 28     | 4    | `i32`    | `eps_min`, `I16F16`                                                |
//! | 32     | 4    | `i32`    | `eps_max`, `I16F16`                                                |
//! | 36     | 2    | `u16`    | `n_eps`, strain grid points                                        |
//! | 38     | 2    | `u16`    | `n_p`, pressure levels                                             |
//! | 40     | 4    | `i32`    | `p_min`, `I24F8` Pa                                                |
//! | 44     | 4    | `i32`    | `p_max`, `I24F8` Pa                                                |
//! | 48     | 4    | `i32`    | `s_min`, `I8F24` m                                                 |
//! | 52     | 4    | `i32`    | `s_max`, `I8F24` m                                                 |
//! | 56     | 2    | `u16`    | `n_s`, neutral-axis length levels                                  |
//! | 58     | 2    | `u16`    | `n_u`, normalized angle grid points                                |
//! | 60     | 4    | `u32`    | reserved, must be 0                                                |
//! | 64     | 12   |          | descriptor 0: axial force `F[p][eps]`                              |
//! | 76     | 12   |          | descriptor 1: maximum angle `phi_max[s]`                           |
//! | 88     | 12   |          | descriptor 2: moment at zero pressure `M0[s][u]`                   |
//! | 100    | 12   |          | descriptor 3: moment per pascal `M1[s][u]`                         |
//! | 112    | ...  | `i32`    | the tables, where the descriptors point                            |
//! | len-4  | 4    | `u32`    | CRC-32 (ISO-HDLC, as zlib/PNG) of bytes `0..len-4`                 |
//!
//! Each descriptor is `offset: u32` (from the start of the image, a multiple
//! of 4, at or after the header and after the previous table's end),
//! `count: u32` (number of elements, which must match the grid),
//! `frac_bits: u8` (the binary point of the stored `i32`: 16 for the force and
//! `phi_max`, 24 for `M0`, 16..=62 for `M1`), `element: u8` (1 = `i32` LE,
//! the only type of version 1) and `reserved: u16` (0).
//!
//! Grids are uniform between their stored (already quantized) bounds:
//! `eps_i = eps_min + i (eps_max - eps_min) / (n_eps - 1)`, likewise the
//! pressure levels `P_j`, the length levels `s_k` and the normalized angle
//! `u_i = i / (n_u - 1)` with `phi = u * phi_max[k]`. Every grid has
//! 2..=[`MAX_GRID_POINTS`] points and `min < max`. The axial table is
//! row-major `[p][eps]`, the bending planes are row-major `[s][u]`, and
//! `phi_max[k] > 0`.
//!
//! The default image (axial 16 x 129, bending 17 x 129 x 2 planes) takes
//! 25 984 bytes, within the 32 KiB budget of one OCM type.
//!
//! # Reading order and errors
//!
//! [`LutImage::parse`] checks, in this order: length of the fixed header
//! ([`LutError::Truncated`]), magic ([`LutError::BadMagic`]), version
//! ([`LutError::UnsupportedVersion`]), declared length against the bytes
//! given ([`LutError::Truncated`]), the CRC ([`LutError::CrcMismatch`]), then
//! the header fields, grids and descriptors, each fault with its own variant.
//! Bytes after the declared length (flash padding) are ignored. It never
//! panics, whatever the input.

mod encode;
mod error;
mod fixed_math;
mod image;
mod layout;
mod lookup;

pub use encode::{
    AxialTableSpec, BendingTableSpec, encode, encoded_len, length_grid_m, pressure_grid_pa,
    strain_grid,
};
pub use error::{EncodeError, Grid, LookupError, LutError, Quantity, TableId};
pub use fixed_math::udiv_u64_by_u32;
pub use image::{AxialGrid, AxialRow, BendingGrid, LutImage};
pub use layout::{FORMAT_VERSION, HEADER_LEN, MAGIC, MAX_GRID_POINTS, PRESSURE_MARGIN_PA};
pub use lookup::{BendHint, Clamp, Lookup};

use fixed::types::{I8F24, I16F16, I24F8};

/// Axial strain, dimensionless: `I16F16`.
pub type Strain = I16F16;
/// Axial force in newtons: `I16F16`.
pub type ForceN = I16F16;
/// Pressure in pascals: `I24F8`.
pub type PressurePa = I24F8;
/// Bending angle in radians: `I16F16`.
pub type AngleRad = I16F16;
/// Neutral-axis length of the whole cylinder in metres: `I8F24`.
pub type LengthM = I8F24;
/// Bending moment in newton-metres: `I8F24`.
pub type MomentNm = I8F24;

/// Bytes of the firmware's LUT upload buffer, on every board and in every
/// host that emulates one: the default image ([`defaults::IMAGE_LEN`],
/// 25 984 bytes) plus a little slack, so that the whole firmware (buffer,
/// app, stack) stays inside the 32 KiB of RAM of the smallest target. A
/// larger grid needs a larger board, not a larger constant.
pub const LUT_CAPACITY: usize = 26 * 1024;

const _: () = assert!(defaults::IMAGE_LEN <= LUT_CAPACITY);

/// Default grids of one OCM type (issue 2): 16 pressure levels of 2 kPa,
/// 129 strain points over -0.6..0.6, 17 length levels, 129 angle points.
pub mod defaults {
    /// Lowest stored strain.
    pub const EPS_MIN: f64 = -0.6;
    /// Highest stored strain.
    pub const EPS_MAX: f64 = 0.6;
    /// Strain grid points.
    pub const N_EPS: u16 = 129;
    /// Lowest stored pressure, Pa.
    pub const P_MIN_PA: f64 = 0.0;
    /// Highest stored pressure, Pa.
    pub const P_MAX_PA: f64 = 30_000.0;
    /// Pressure levels (2 kPa apart).
    pub const N_P: u16 = 16;
    /// Neutral-axis length levels.
    pub const N_S: u16 = 17;
    /// Normalized angle grid points.
    pub const N_U: u16 = 129;
    /// Bytes of an image on these grids: header, axial table, the length
    /// levels' largest angles, the two bending planes, CRC.
    pub const IMAGE_LEN: usize = super::HEADER_LEN
        + 4 * (N_P as usize * N_EPS as usize + N_S as usize + 2 * N_S as usize * N_U as usize)
        + 4;
}
