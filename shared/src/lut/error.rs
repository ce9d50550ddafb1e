//! What can go wrong writing, reading and querying a LUT image.

use thiserror::Error;

use super::{LengthM, PressurePa};

/// One axis of the image's grids.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Grid {
    /// Axial strain `eps`.
    Strain,
    /// Pressure levels of the axial table.
    Pressure,
    /// Neutral-axis length levels `s` of the bending table.
    Length,
    /// Normalized bending angle `u = phi / phi_max(s)`.
    NormalizedAngle,
}

/// One stored table, in descriptor order.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TableId {
    /// Axial force `F[p][eps]`, newtons.
    AxialForce,
    /// Maximum feasible bending angle `phi_max[s]`, radians.
    PhiMax,
    /// Bending moment at zero pressure `M0[s][u]`, newton-metres.
    MomentAtZeroPressure,
    /// Bending moment per pascal `M1[s][u]`, newton-metres per pascal.
    MomentPerPascal,
}

/// An input of the `*_f64` lookups.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Quantity {
    /// Axial strain.
    Strain,
    /// Axial force, N.
    Force,
    /// Pressure, Pa.
    Pressure,
    /// Bending angle, rad.
    Angle,
    /// Neutral-axis length, m.
    Length,
    /// Bending moment, N*m.
    Moment,
}

/// Why [`super::encode`] refused to write an image.
#[derive(Debug, Clone, Copy, PartialEq, Error)]
pub enum EncodeError {
    /// A grid has fewer than two points.
    #[error("{grid:?} grid has {points} points; at least 2 are needed")]
    EmptyGrid {
        /// The grid.
        grid: Grid,
        /// Points asked for.
        points: u16,
    },
    /// A grid has more than [`super::MAX_GRID_POINTS`] points.
    #[error("{grid:?} grid has {points} points; at most {max} are allowed", max = super::MAX_GRID_POINTS)]
    GridTooLarge {
        /// The grid.
        grid: Grid,
        /// Points asked for.
        points: u16,
    },
    /// A grid bound is NaN, infinite or outside its Q-format.
    #[error("{grid:?} grid bound {value} is not finite or not representable in its Q-format")]
    GridBound {
        /// The grid.
        grid: Grid,
        /// The offending bound.
        value: f64,
    },
    /// After rounding to the Q-format the grid's minimum is not below its maximum.
    #[error("{grid:?} grid minimum is not below its maximum (after rounding to the Q-format)")]
    InvertedGrid {
        /// The grid.
        grid: Grid,
    },
    /// A table slice does not have the length its grid implies.
    #[error("{table:?} has {got} values but its grid needs {expected}")]
    SizeMismatch {
        /// The table.
        table: TableId,
        /// Values the grid needs.
        expected: usize,
        /// Values given.
        got: usize,
    },
    /// A table value is NaN or infinite.
    #[error("{table:?} value at row {row}, column {col} is not finite")]
    NotFinite {
        /// The table.
        table: TableId,
        /// Row (pressure or length level).
        row: u16,
        /// Column (strain or normalized angle point; 0 for `phi_max`).
        col: u16,
    },
    /// A table value does not fit the table's Q-format.
    #[error("{table:?} value {value} at row {row}, column {col} does not fit its Q-format")]
    OutOfRange {
        /// The table.
        table: TableId,
        /// Row (pressure or length level).
        row: u16,
        /// Column (strain or normalized angle point; 0 for `phi_max`).
        col: u16,
        /// The value.
        value: f64,
    },
    /// A maximum bending angle is not positive (after rounding to `I16F16`).
    #[error("phi_max of length level {level} is not positive")]
    PhiMaxNotPositive {
        /// Length level.
        level: u16,
    },
    /// A row decreases: the inverse lookups need rows that never decrease.
    #[error("{table:?} row {row} decreases between columns {col} and {col}+1 at {pressure_pa} Pa")]
    NonMonotone {
        /// The table ([`TableId::AxialForce`], or [`TableId::MomentAtZeroPressure`]
        /// for the combined bending moment `M0 + P M1`).
        table: TableId,
        /// Row (pressure level for the axial table, length level for bending).
        row: u16,
        /// Column after which the value drops.
        col: u16,
        /// Pressure at which the row was checked, Pa.
        pressure_pa: f64,
    },
    /// The image would not fit the caller's buffer.
    #[error("image needs {needed} bytes but the buffer holds {got}")]
    BufferTooSmall {
        /// Bytes needed.
        needed: usize,
        /// Bytes available.
        got: usize,
    },
}

/// Why [`super::LutImage::parse`] rejected some bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Error)]
pub enum LutError {
    /// Fewer bytes than the header or the declared length needs.
    #[error("image truncated: {needed} bytes needed, {got} given")]
    Truncated {
        /// Bytes needed.
        needed: usize,
        /// Bytes given.
        got: usize,
    },
    /// The first eight bytes are not [`super::MAGIC`].
    #[error("not a LUT image: magic {found:02x?}")]
    BadMagic {
        /// The first eight bytes found.
        found: [u8; 8],
    },
    /// A format version this reader does not know.
    #[error("LUT format version {found} is not supported (this reader knows {known})", known = super::FORMAT_VERSION)]
    UnsupportedVersion {
        /// Version found.
        found: u16,
    },
    /// The declared total length cannot hold the header and the CRC.
    #[error("declared image length {declared} is shorter than header and CRC")]
    BadTotalLength {
        /// Declared length.
        declared: u32,
    },
    /// The stored CRC does not match the bytes.
    #[error("CRC mismatch: stored {stored:#010x}, computed {computed:#010x}")]
    CrcMismatch {
        /// CRC stored in the trailer.
        stored: u32,
        /// CRC of the bytes before the trailer.
        computed: u32,
    },
    /// The header length field is not the one of this version.
    #[error("header length {found} is not {expected}", expected = super::HEADER_LEN)]
    BadHeaderLength {
        /// Header length found.
        found: u16,
    },
    /// Flags this version does not define are set.
    #[error("unknown flags {flags:#010x}")]
    UnsupportedFlags {
        /// The flags word.
        flags: u32,
    },
    /// A reserved header field is not zero.
    #[error("reserved header field at byte {offset} is not zero")]
    ReservedNotZero {
        /// Byte offset of the field.
        offset: usize,
    },
    /// A grid has fewer than two points.
    #[error("{grid:?} grid has {points} points; at least 2 are needed")]
    EmptyGrid {
        /// The grid.
        grid: Grid,
        /// Points found.
        points: u16,
    },
    /// A grid has more than [`super::MAX_GRID_POINTS`] points.
    #[error("{grid:?} grid has {points} points; at most {max} are allowed", max = super::MAX_GRID_POINTS)]
    GridTooLarge {
        /// The grid.
        grid: Grid,
        /// Points found.
        points: u16,
    },
    /// A grid's minimum is not below its maximum.
    #[error("{grid:?} grid minimum is not below its maximum")]
    InvertedGrid {
        /// The grid.
        grid: Grid,
    },
    /// A descriptor's element count does not match its grid.
    #[error("{table:?} holds {found} elements but its grid needs {expected}")]
    TableCount {
        /// The table.
        table: TableId,
        /// Elements the grid needs.
        expected: u32,
        /// Elements declared.
        found: u32,
    },
    /// A descriptor's binary point is not allowed for its table.
    #[error("{table:?} has {found} fractional bits, which this version does not allow")]
    TableFracBits {
        /// The table.
        table: TableId,
        /// Fractional bits found.
        found: u8,
    },
    /// A descriptor names an unknown element type or has reserved bits set.
    #[error("{table:?} has element type {found}; only 1 (i32 LE) is defined")]
    TableElementType {
        /// The table.
        table: TableId,
        /// Element type code found.
        found: u8,
    },
    /// A table is misaligned, overlaps the header or another table, or runs
    /// past the CRC.
    #[error("{table:?} at offset {offset} with {count} elements is misplaced")]
    TablePlacement {
        /// The table.
        table: TableId,
        /// Declared offset.
        offset: u32,
        /// Declared element count.
        count: u32,
    },
    /// A stored maximum bending angle is not positive.
    #[error("phi_max of length level {level} is not positive")]
    PhiMaxNotPositive {
        /// Length level.
        level: u16,
    },
}

/// Why a lookup could not answer.
#[derive(Debug, Clone, Copy, PartialEq, Error)]
pub enum LookupError {
    /// The pressure lies outside the grid widened by [`super::PRESSURE_MARGIN_PA`].
    #[error("pressure {pressure} Pa outside the table's window {min}..={max} Pa")]
    PressureOutOfRange {
        /// Pressure asked for.
        pressure: PressurePa,
        /// Lowest pressure answered.
        min: PressurePa,
        /// Highest pressure answered.
        max: PressurePa,
    },
    /// The neutral-axis length lies outside the bending table's levels.
    #[error("neutral-axis length {length} m outside the table's {min}..={max} m")]
    LengthOutOfRange {
        /// Length asked for.
        length: LengthM,
        /// Shortest stored level.
        min: LengthM,
        /// Longest stored level.
        max: LengthM,
    },
    /// An `f64` input is NaN, infinite or outside its Q-format.
    #[error("{quantity:?} input {value} is not finite or not representable in its Q-format")]
    NotRepresentable {
        /// Which input.
        quantity: Quantity,
        /// The value given.
        value: f64,
    },
}
