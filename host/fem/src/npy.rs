//! Minimal NumPy .npy writer (format 1.0, little-endian float64, C order).

use crate::{FemError, Result};
use std::io::Write;

/// Writes a 2-D float64 array of `rows` x `cols` (row-major `data`).
pub fn write_f64_2d(out: &mut impl Write, data: &[f64], rows: usize, cols: usize) -> Result<()> {
    if data.len() != rows * cols {
        return Err(FemError::Model(format!(
            "npy: {} values for a {rows}x{cols} array",
            data.len()
        )));
    }
    let mut header =
        format!("{{'descr': '<f8', 'fortran_order': False, 'shape': ({rows}, {cols}), }}");
    // Magic (6) + version (2) + length (2) + header + newline must be a multiple of 64.
    let total = 10 + header.len() + 1;
    header.push_str(&" ".repeat((64 - total % 64) % 64));
    header.push('\n');
    let mut b = Vec::with_capacity(10 + header.len() + 8 * data.len());
    b.extend_from_slice(b"\x93NUMPY\x01\x00");
    b.extend_from_slice(&(header.len() as u16).to_le_bytes());
    b.extend_from_slice(header.as_bytes());
    for v in data {
        b.extend_from_slice(&v.to_le_bytes());
    }
    out.write_all(&b).map_err(|source| FemError::Io {
        path: "npy output".into(),
        source,
    })
}

/// Writes snapshots (each a flat vector of equal length) as a (count x length) .npy file.
pub fn write_snapshots(path: impl AsRef<std::path::Path>, snapshots: &[Vec<f64>]) -> Result<()> {
    let path = path.as_ref();
    let cols = snapshots.first().map_or(0, |s| s.len());
    if let Some(k) = snapshots.iter().position(|s| s.len() != cols) {
        return Err(FemError::Model(format!(
            "snapshot {k} has a different length"
        )));
    }
    let data: Vec<f64> = snapshots.iter().flatten().copied().collect();
    let mut f =
        std::io::BufWriter::new(std::fs::File::create(path).map_err(|source| FemError::Io {
            path: path.display().to_string(),
            source,
        })?);
    write_f64_2d(&mut f, &data, snapshots.len(), cols)?;
    f.flush().map_err(|source| FemError::Io {
        path: path.display().to_string(),
        source,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Header layout per the NumPy format spec: magic, version 1.0, 64-byte aligned, data follows.
    #[test]
    fn header_is_aligned_and_data_little_endian() {
        let mut b = Vec::new();
        write_f64_2d(&mut b, &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0], 2, 3).unwrap();
        assert_eq!(&b[..8], b"\x93NUMPY\x01\x00");
        let hl = u16::from_le_bytes([b[8], b[9]]) as usize;
        assert_eq!((10 + hl) % 64, 0);
        let h = std::str::from_utf8(&b[10..10 + hl]).unwrap();
        assert!(h.contains("'shape': (2, 3)") && h.ends_with('\n'));
        assert_eq!(
            f64::from_le_bytes(b[10 + hl + 40..10 + hl + 48].try_into().unwrap()),
            6.0
        );
        assert!(write_f64_2d(&mut b, &[1.0], 2, 3).is_err());
    }
}
