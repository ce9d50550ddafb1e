//! Minimal NumPy .npy writer (format 1.0, little-endian float64, C order) and reader (any rank;
//! float64, float32, int64, int32).

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

/// A float64 array read from a .npy file: row-major data and its shape (a 1-D array is `(n, 1)`
/// with `one_d` set).
#[derive(Debug, Clone, PartialEq)]
pub struct Array2 {
    /// Row-major values.
    pub data: Vec<f64>,
    /// Rows.
    pub rows: usize,
    /// Columns.
    pub cols: usize,
}

/// An array of any rank read from a .npy file, converted to f64: row-major (C order) data and
/// its shape (empty for a scalar).
#[derive(Debug, Clone, PartialEq)]
pub struct ArrayNd {
    /// Row-major values.
    pub data: Vec<f64>,
    /// Shape; `[]` for a 0-d scalar.
    pub shape: Vec<usize>,
}

/// Parses .npy bytes of any rank (versions 1.0-3.0, C order) with little-endian dtype `<f8`,
/// `<f4`, `<i8` or `<i4`, converting the values to f64; `name` labels the errors.
pub fn parse_nd(bytes: &[u8], name: &str) -> Result<ArrayNd> {
    let bad = |at: &str, msg: String| FemError::parse("NPY", format!("{name}: {at}"), msg);
    if bytes.len() < 10 || &bytes[..6] != b"\x93NUMPY" {
        return Err(bad("magic", "not a .npy file (bad magic string)".into()));
    }
    let (hlen, start) = match bytes[6] {
        1 => (u16::from_le_bytes([bytes[8], bytes[9]]) as usize, 10),
        2 | 3 if bytes.len() >= 12 => (
            u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize,
            12,
        ),
        v => return Err(bad("version", format!("unsupported .npy version {v}"))),
    };
    let header = bytes
        .get(start..start + hlen)
        .ok_or_else(|| bad("header", "file ends inside the header (truncated)".into()))?;
    let header =
        std::str::from_utf8(header).map_err(|_| bad("header", "header is not text".into()))?;
    let field = |key: &str| -> Option<&str> {
        let at = header.find(&format!("'{key}'"))?;
        let rest = header[at + key.len() + 2..]
            .trim_start()
            .strip_prefix(':')?;
        Some(rest.trim_start())
    };
    let descr = field("descr").ok_or_else(|| bad("header", "no 'descr'".into()))?;
    // Width in bytes and whether the dtype is a float.
    let (width, float) = if descr.starts_with("'<f8'") {
        (8, true)
    } else if descr.starts_with("'<f4'") {
        (4, true)
    } else if descr.starts_with("'<i8'") {
        (8, false)
    } else if descr.starts_with("'<i4'") {
        (4, false)
    } else {
        return Err(bad(
            "header",
            format!(
                "dtype {descr:.8} is not little-endian float64 '<f8' (nor '<f4', '<i8', '<i4')"
            ),
        ));
    };
    if !field("fortran_order").is_some_and(|f| f.starts_with("False")) {
        return Err(bad("header", "Fortran order is not supported".into()));
    }
    let shape = field("shape").ok_or_else(|| bad("header", "no 'shape'".into()))?;
    let inner = shape
        .strip_prefix('(')
        .and_then(|s| s.split(')').next())
        .ok_or_else(|| bad("header", format!("malformed shape {shape:.20}")))?;
    let dims: Vec<usize> = inner
        .split(',')
        .map(str::trim)
        .filter(|t| !t.is_empty())
        .map(|t| t.parse::<usize>())
        .collect::<std::result::Result<_, _>>()
        .map_err(|e| bad("header", format!("shape ({inner}): {e}")))?;
    let body = &bytes[start + hlen..];
    let want = dims
        .iter()
        .try_fold(width, |n: usize, &d| n.checked_mul(d))
        .ok_or_else(|| bad("header", format!("shape ({inner}) overflows")))?;
    if body.len() < want {
        return Err(bad(
            "data",
            format!(
                "truncated: shape ({inner}) needs {want} data bytes, the file has {}",
                body.len()
            ),
        ));
    }
    if body.len() > want {
        return Err(bad(
            "data",
            format!("{} bytes after the ({inner}) array", body.len() - want),
        ));
    }
    let data = body
        .chunks_exact(width)
        .map(|c| match (width, float) {
            (8, true) => f64::from_le_bytes([c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]]),
            (4, true) => f64::from(f32::from_le_bytes([c[0], c[1], c[2], c[3]])),
            (8, false) => {
                i64::from_le_bytes([c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]]) as f64
            }
            _ => f64::from(i32::from_le_bytes([c[0], c[1], c[2], c[3]])),
        })
        .collect();
    Ok(ArrayNd { data, shape: dims })
}

/// Parses .npy bytes (versions 1.0-3.0, `<f8`, C order, 1-D or 2-D); `name` labels the errors.
pub fn parse_f64_2d(bytes: &[u8], name: &str) -> Result<Array2> {
    let bad = |at: &str, msg: String| FemError::parse("NPY", format!("{name}: {at}"), msg);
    // Only float64 is accepted here: callers store f64 fields and a silent conversion from an
    // integer or f32 file would hide a wrong file.
    if let Some(at) = bytes.windows(7).position(|w| w == b"'descr'") {
        let rest = &bytes[at + 7..bytes.len().min(at + 20)];
        let text = String::from_utf8_lossy(rest);
        let text = text.trim_start().trim_start_matches(':').trim_start();
        if !text.starts_with("'<f8'") && bytes.starts_with(b"\x93NUMPY") {
            return Err(bad(
                "header",
                format!("dtype {text:.8} is not little-endian float64 '<f8'"),
            ));
        }
    }
    let a = parse_nd(bytes, name)?;
    let (rows, cols) = match a.shape[..] {
        [n] => (n, 1),
        [r, c] => (r, c),
        _ => {
            return Err(bad(
                "header",
                format!("shape {:?} is not 1-D or 2-D", a.shape),
            ));
        }
    };
    Ok(Array2 {
        data: a.data,
        rows,
        cols,
    })
}

/// Reads a float64 .npy file (see [`parse_f64_2d`]); errors name the file.
pub fn read_f64_2d(path: impl AsRef<std::path::Path>) -> Result<Array2> {
    let path = path.as_ref();
    let bytes = std::fs::read(path).map_err(|source| FemError::Io {
        path: path.display().to_string(),
        source,
    })?;
    parse_f64_2d(&bytes, &path.display().to_string())
}

/// Writes a 2-D float64 array to a file.
pub fn write_f64_2d_path(
    path: impl AsRef<std::path::Path>,
    data: &[f64],
    rows: usize,
    cols: usize,
) -> Result<()> {
    let path = path.as_ref();
    let io = |source| FemError::Io {
        path: path.display().to_string(),
        source,
    };
    let mut f = std::io::BufWriter::new(std::fs::File::create(path).map_err(io)?);
    write_f64_2d(&mut f, data, rows, cols)?;
    f.flush().map_err(io)
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

    #[test]
    fn reader_round_trips_and_names_the_problem() {
        let mut b = Vec::new();
        write_f64_2d(&mut b, &[1.5, -2.0, 3.25, 4.0, 5.0, 6.0], 3, 2).unwrap();
        let a = parse_f64_2d(&b, "x.npy").unwrap();
        assert_eq!((a.rows, a.cols), (3, 2));
        assert_eq!(a.data, vec![1.5, -2.0, 3.25, 4.0, 5.0, 6.0]);
        let e = parse_f64_2d(&b[..b.len() - 3], "x.npy")
            .unwrap_err()
            .to_string();
        assert!(e.contains("x.npy") && e.contains("truncated"), "{e}");
        let e = parse_f64_2d(b"hello world", "y.npy")
            .unwrap_err()
            .to_string();
        assert!(e.contains("y.npy") && e.contains("magic"), "{e}");
        let mut c = b.clone();
        let at = c.windows(3).position(|w| w == b"<f8").unwrap();
        c[at + 1] = b'i';
        let e = parse_f64_2d(&c, "z.npy").unwrap_err().to_string();
        assert!(e.contains("z.npy") && e.contains("float64"), "{e}");
    }

    fn npy_bytes(descr: &str, shape: &str, body: &[u8]) -> Vec<u8> {
        let h = format!("{{'descr': '{descr}', 'fortran_order': False, 'shape': {shape}, }}\n");
        let mut b = b"\x93NUMPY\x01\x00".to_vec();
        b.extend_from_slice(&(h.len() as u16).to_le_bytes());
        b.extend_from_slice(h.as_bytes());
        b.extend_from_slice(body);
        b
    }

    /// A 3-D float64 array keeps its shape and C order; a 0-d int64 scalar (what numpy's
    /// `np.savez(bins=125)` stores) and float32 data convert to f64; the 2-D reader refuses both.
    #[test]
    fn nd_reader_shapes_and_dtypes() {
        let vals: Vec<f64> = (0..24).map(|i| i as f64 * 0.5 - 3.0).collect();
        let body: Vec<u8> = vals.iter().flat_map(|v| v.to_le_bytes()).collect();
        let a = parse_nd(&npy_bytes("<f8", "(2, 3, 4)", &body), "t.npy").unwrap();
        assert_eq!(a.shape, vec![2, 3, 4]);
        assert_eq!(a.data, vals);
        let e = parse_f64_2d(&npy_bytes("<f8", "(2, 3, 4)", &body), "t.npy")
            .unwrap_err()
            .to_string();
        assert!(e.contains("not 1-D or 2-D"), "{e}");
        let s = parse_nd(&npy_bytes("<i8", "()", &125i64.to_le_bytes()), "bins.npy").unwrap();
        assert_eq!((s.shape.len(), s.data.clone()), (0, vec![125.0]));
        assert!(parse_f64_2d(&npy_bytes("<i8", "(1,)", &125i64.to_le_bytes()), "b").is_err());
        let f: Vec<u8> = [1.5f32, -2.25]
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        let a = parse_nd(&npy_bytes("<f4", "(2,)", &f), "f.npy").unwrap();
        assert_eq!(a.data, vec![1.5, -2.25]);
        let e = parse_nd(&npy_bytes("<u2", "(2,)", &[0; 4]), "u.npy")
            .unwrap_err()
            .to_string();
        assert!(e.contains("u.npy") && e.contains("dtype"), "{e}");
    }
}
