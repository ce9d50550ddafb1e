//! Every kind of corrupt image is rejected with its own error, also when the
//! CRC has been recomputed to hide the edit.

mod common;

use common::{Grids, Tables, fix_crc};
use ocm_shared::lut::{Grid, HEADER_LEN, LutError, LutImage, MAGIC, TableId};

fn tiny() -> Vec<u8> {
    Tables::sample(Grids::TINY).encode(0xDEAD_BEEF)
}

fn default_image() -> Vec<u8> {
    Tables::sample(Grids::DEFAULT).encode(0x0123_4567_89AB_CDEF)
}

/// Writes `value` little-endian at `at` and makes the CRC valid again.
fn edit(image: &[u8], at: usize, value: &[u8]) -> Vec<u8> {
    let mut bytes = image.to_vec();
    bytes[at..at + value.len()].copy_from_slice(value);
    fix_crc(&mut bytes);
    bytes
}

#[test]
fn wrong_magic_is_bad_magic() {
    let image = default_image();
    for at in 0..8 {
        let mut bytes = image.clone();
        bytes[at] ^= 0x20;
        match LutImage::parse(&bytes) {
            Err(LutError::BadMagic { found }) => assert_eq!(&found[..], &bytes[..8]),
            other => panic!("byte {at}: expected BadMagic, got {other:?}"),
        }
    }
    assert!(matches!(
        LutImage::parse(b"PNG"),
        Err(LutError::BadMagic { .. })
    ));
    assert_eq!(MAGIC, *b"OCMLUT\0\x1a");
}

#[test]
fn wrong_version_is_unsupported_version() {
    let image = default_image();
    for version in [0u16, 2, 0x0100, u16::MAX] {
        let mut bytes = image.clone();
        bytes[8..10].copy_from_slice(&version.to_le_bytes());
        assert_eq!(
            LutImage::parse(&bytes).unwrap_err(),
            LutError::UnsupportedVersion { found: version }
        );
        // Also with a valid CRC.
        let fixed = edit(&image, 8, &version.to_le_bytes());
        assert_eq!(
            LutImage::parse(&fixed).unwrap_err(),
            LutError::UnsupportedVersion { found: version }
        );
    }
}

#[test]
fn every_truncation_is_truncated() {
    for image in [tiny(), default_image()] {
        let len = image.len();
        for cut in 0..len {
            let needed = if cut < HEADER_LEN + 4 {
                HEADER_LEN + 4
            } else {
                len
            };
            assert_eq!(
                LutImage::parse(&image[..cut]).unwrap_err(),
                LutError::Truncated { needed, got: cut },
                "cut at {cut} of {len}"
            );
        }
        assert!(LutImage::parse(&image).is_ok());
    }
}

#[test]
fn every_flipped_bit_after_the_length_field_is_a_crc_mismatch() {
    let image = tiny();
    let good = LutImage::parse(&image).unwrap().crc();
    for at in 16..image.len() {
        for bit in 0..8 {
            let mut bytes = image.clone();
            bytes[at] ^= 1 << bit;
            match LutImage::parse(&bytes) {
                Err(LutError::CrcMismatch { stored, computed }) => {
                    assert_ne!(stored, computed);
                    assert!(stored == good || computed == good, "byte {at} bit {bit}");
                }
                other => panic!("byte {at} bit {bit}: expected CrcMismatch, got {other:?}"),
            }
        }
    }
    // A few flips across the default image.
    let image = default_image();
    for at in (16..image.len()).step_by(997) {
        let mut bytes = image.clone();
        bytes[at] ^= 0x10;
        assert!(
            matches!(LutImage::parse(&bytes), Err(LutError::CrcMismatch { .. })),
            "byte {at}"
        );
    }
}

#[test]
fn a_declared_length_too_short_for_header_and_crc_is_rejected() {
    let image = tiny();
    for declared in [0u32, 4, 115] {
        let mut bytes = image.clone();
        bytes[12..16].copy_from_slice(&declared.to_le_bytes());
        assert_eq!(
            LutImage::parse(&bytes).unwrap_err(),
            LutError::BadTotalLength { declared }
        );
    }
    let mut bytes = image.clone();
    bytes[12..16].copy_from_slice(&u32::MAX.to_le_bytes());
    assert_eq!(
        LutImage::parse(&bytes).unwrap_err(),
        LutError::Truncated {
            needed: u32::MAX as usize,
            got: image.len()
        }
    );
}

// Header offsets of format version 1 (see the module docs of `lut`).
const N_EPS: usize = 36;
const N_P: usize = 38;
const EPS_MIN: usize = 28;
const EPS_MAX: usize = 32;
const P_MIN: usize = 40;
const P_MAX: usize = 44;
const S_MIN: usize = 48;
const S_MAX: usize = 52;
const N_S: usize = 56;
const N_U: usize = 58;
const DESC: usize = 64;

#[test]
fn malformed_grids_are_rejected_even_with_a_valid_crc() {
    let image = default_image();
    let parse = |at: usize, value: &[u8]| LutImage::parse(&edit(&image, at, value)).unwrap_err();
    let cases: [(usize, Grid); 4] = [
        (N_EPS, Grid::Strain),
        (N_P, Grid::Pressure),
        (N_S, Grid::Length),
        (N_U, Grid::NormalizedAngle),
    ];
    for (at, grid) in cases {
        for points in [0u16, 1] {
            assert_eq!(
                parse(at, &points.to_le_bytes()),
                LutError::EmptyGrid { grid, points }
            );
        }
        assert_eq!(
            parse(at, &5000u16.to_le_bytes()),
            LutError::GridTooLarge { grid, points: 5000 }
        );
    }
    let bounds = [
        (EPS_MIN, EPS_MAX, Grid::Strain),
        (P_MIN, P_MAX, Grid::Pressure),
        (S_MIN, S_MAX, Grid::Length),
    ];
    for (lo, hi, grid) in bounds {
        // min == max
        let max = image[hi..hi + 4].to_vec();
        assert_eq!(parse(lo, &max), LutError::InvertedGrid { grid });
        // min > max
        let min = image[lo..lo + 4].to_vec();
        let mut swapped = edit(&image, lo, &max);
        swapped[hi..hi + 4].copy_from_slice(&min);
        fix_crc(&mut swapped);
        assert_eq!(
            LutImage::parse(&swapped).unwrap_err(),
            LutError::InvertedGrid { grid }
        );
    }
}

#[test]
fn malformed_header_fields_are_rejected_with_their_own_error() {
    let image = default_image();
    let parse = |at: usize, value: &[u8]| LutImage::parse(&edit(&image, at, value)).unwrap_err();
    assert_eq!(
        parse(10, &100u16.to_le_bytes()),
        LutError::BadHeaderLength { found: 100 }
    );
    assert_eq!(
        parse(24, &1u32.to_le_bytes()),
        LutError::UnsupportedFlags { flags: 1 }
    );
    assert_eq!(
        parse(60, &7u32.to_le_bytes()),
        LutError::ReservedNotZero { offset: 60 }
    );
    assert_eq!(
        parse(DESC + 10, &[1, 0]),
        LutError::ReservedNotZero { offset: DESC + 10 }
    );
}

#[test]
fn malformed_table_descriptors_are_rejected() {
    let image = default_image();
    let parse = |at: usize, value: &[u8]| LutImage::parse(&edit(&image, at, value)).unwrap_err();
    let tables = [
        TableId::AxialForce,
        TableId::PhiMax,
        TableId::MomentAtZeroPressure,
        TableId::MomentPerPascal,
    ];
    for (t, table) in tables.into_iter().enumerate() {
        let d = DESC + 12 * t;
        let offset = u32::from_le_bytes(image[d..d + 4].try_into().unwrap());
        let count = u32::from_le_bytes(image[d + 4..d + 8].try_into().unwrap());
        assert_eq!(
            parse(d + 4, &(count + 1).to_le_bytes()),
            LutError::TableCount {
                table,
                expected: count,
                found: count + 1
            }
        );
        assert_eq!(
            parse(d + 9, &[2]),
            LutError::TableElementType { table, found: 2 }
        );
        assert_eq!(
            parse(d + 8, &[70]),
            LutError::TableFracBits { table, found: 70 }
        );
        assert_eq!(
            parse(d, &(offset + 2).to_le_bytes()),
            LutError::TablePlacement {
                table,
                offset: offset + 2,
                count
            }
        );
        // Moving a table 4 bytes back overlaps the header or its predecessor.
        assert_eq!(
            parse(d, &(offset - 4).to_le_bytes()),
            LutError::TablePlacement {
                table,
                offset: offset - 4,
                count
            }
        );
        // Past the CRC.
        let late = image.len() as u32;
        assert_eq!(
            parse(d, &late.to_le_bytes()),
            LutError::TablePlacement {
                table,
                offset: late,
                count
            }
        );
    }
    // Q-formats fixed by version 1: force and phi_max I16F16, M0 I8F24.
    assert_eq!(
        parse(DESC + 8, &[24]),
        LutError::TableFracBits {
            table: TableId::AxialForce,
            found: 24
        }
    );
    assert_eq!(
        parse(DESC + 24 + 8, &[16]),
        LutError::TableFracBits {
            table: TableId::MomentAtZeroPressure,
            found: 16
        }
    );
    assert_eq!(
        parse(DESC + 36 + 8, &[15]),
        LutError::TableFracBits {
            table: TableId::MomentPerPascal,
            found: 15
        }
    );
}

#[test]
fn a_non_positive_phi_max_is_rejected() {
    let image = default_image();
    let phi_max_at = u32::from_le_bytes(image[DESC + 12..DESC + 16].try_into().unwrap()) as usize;
    for value in [0i32, -65_536] {
        let bytes = edit(&image, phi_max_at + 4 * 3, &value.to_le_bytes());
        assert_eq!(
            LutImage::parse(&bytes).unwrap_err(),
            LutError::PhiMaxNotPositive { level: 3 }
        );
    }
}
