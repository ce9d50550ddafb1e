//! Byte offsets and constants of format version 1, and the little-endian
//! field access shared by the writer and the reader.

/// First eight bytes of every image. The trailing `0x1a` stops text tools.
pub const MAGIC: [u8; 8] = *b"OCMLUT\0\x1a";
/// Format version written and read by this crate.
pub const FORMAT_VERSION: u16 = 1;
/// Length of the fixed header; the tables start at or after it.
pub const HEADER_LEN: usize = 112;
/// Largest number of points on any one grid axis. Bounding it keeps every
/// intermediate of the fixed-point lookups inside `i64`.
pub const MAX_GRID_POINTS: u16 = 4096;
/// How far outside the stored pressure grid (on each side) the lookups
/// extrapolate, in pascals.
pub const PRESSURE_MARGIN_PA: i32 = 20_000;

/// Bytes of the trailing CRC-32.
pub(crate) const CRC_LEN: usize = 4;
/// Bytes of one table element (`i32`).
pub(crate) const ELEMENT_LEN: usize = 4;
/// Element type code of a little-endian `i32`.
pub(crate) const ELEMENT_I32: u8 = 1;

/// Binary point of the stored axial forces (`I16F16`).
pub(crate) const FORCE_FRAC_BITS: u8 = 16;
/// Binary point of the stored maximum angles (`I16F16`).
pub(crate) const PHI_MAX_FRAC_BITS: u8 = 16;
/// Binary point of the stored zero-pressure moments (`I8F24`).
pub(crate) const M0_FRAC_BITS: u8 = 24;
/// Smallest binary point of the stored `dM/dP` (keeps `P * M1` a right shift).
pub(crate) const M1_FRAC_BITS_MIN: u8 = 16;
/// Largest binary point of the stored `dM/dP`.
pub(crate) const M1_FRAC_BITS_MAX: u8 = 62;

pub(crate) const OFF_MAGIC: usize = 0;
pub(crate) const OFF_VERSION: usize = 8;
pub(crate) const OFF_HEADER_LEN: usize = 10;
pub(crate) const OFF_TOTAL_LEN: usize = 12;
pub(crate) const OFF_PARAM_HASH: usize = 16;
pub(crate) const OFF_FLAGS: usize = 24;
pub(crate) const OFF_EPS_MIN: usize = 28;
pub(crate) const OFF_EPS_MAX: usize = 32;
pub(crate) const OFF_N_EPS: usize = 36;
pub(crate) const OFF_N_P: usize = 38;
pub(crate) const OFF_P_MIN: usize = 40;
pub(crate) const OFF_P_MAX: usize = 44;
pub(crate) const OFF_S_MIN: usize = 48;
pub(crate) const OFF_S_MAX: usize = 52;
pub(crate) const OFF_N_S: usize = 56;
pub(crate) const OFF_N_U: usize = 58;
pub(crate) const OFF_RESERVED: usize = 60;
pub(crate) const OFF_DESCRIPTORS: usize = 64;
/// Bytes of one table descriptor.
pub(crate) const DESCRIPTOR_LEN: usize = 12;
/// Number of table descriptors, in [`crate::lut::TableId`] order.
pub(crate) const TABLE_COUNT: usize = 4;

/// The CRC used for the trailer: CRC-32/ISO-HDLC (zlib, PNG, Ethernet).
pub(crate) const CRC32: crc::Crc<u32> = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);

/// Reads `N` bytes at `at`, or `None` past the end.
fn bytes_at<const N: usize>(bytes: &[u8], at: usize) -> Option<[u8; N]> {
    let end = at.checked_add(N)?;
    bytes.get(at..end)?.try_into().ok()
}

/// Little-endian `u8` at `at`.
pub(crate) fn read_u8(bytes: &[u8], at: usize) -> Option<u8> {
    bytes.get(at).copied()
}

/// Little-endian `u16` at `at`.
pub(crate) fn read_u16(bytes: &[u8], at: usize) -> Option<u16> {
    bytes_at(bytes, at).map(u16::from_le_bytes)
}

/// Little-endian `u32` at `at`.
pub(crate) fn read_u32(bytes: &[u8], at: usize) -> Option<u32> {
    bytes_at(bytes, at).map(u32::from_le_bytes)
}

/// Little-endian `i32` at `at`.
pub(crate) fn read_i32(bytes: &[u8], at: usize) -> Option<i32> {
    bytes_at(bytes, at).map(i32::from_le_bytes)
}

/// Little-endian `u64` at `at`.
pub(crate) fn read_u64(bytes: &[u8], at: usize) -> Option<u64> {
    bytes_at(bytes, at).map(u64::from_le_bytes)
}

/// Writes `src` at `at`; the writer sized `out` beforehand, so a short buffer
/// only drops bytes instead of panicking.
pub(crate) fn write_bytes(out: &mut [u8], at: usize, src: &[u8]) {
    if let Some(dst) = at
        .checked_add(src.len())
        .and_then(|end| out.get_mut(at..end))
    {
        dst.copy_from_slice(src);
    }
}
