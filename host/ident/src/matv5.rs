//! A small reader for MATLAB level-5 MAT-files (little-endian), enough for measured data:
//! compressed elements (zlib), numeric arrays of every class, char arrays, cell arrays and
//! structs. Sparse and object arrays are rejected with a clear error. The `matfile` crate
//! reads numeric arrays only, and the soft-arm data is a cell array of structs, hence this.

use std::io::Read;

use crate::error::IdentError;

/// A MATLAB value.
#[derive(Debug, Clone, PartialEq)]
pub enum MatValue {
    /// Numeric or logical array, column-major, converted to f64 (real part).
    Numeric {
        /// Dimensions.
        dims: Vec<usize>,
        /// Column-major values.
        data: Vec<f64>,
    },
    /// Character array.
    Char(String),
    /// Cell array, column-major.
    Cell {
        /// Dimensions.
        dims: Vec<usize>,
        /// Items.
        items: Vec<MatValue>,
    },
    /// Struct array: field names and, per element (column-major), one value per field.
    Struct {
        /// Dimensions.
        dims: Vec<usize>,
        /// Field names.
        fields: Vec<String>,
        /// Elements, each with one value per field.
        items: Vec<Vec<MatValue>>,
    },
    /// An empty matrix element.
    Empty,
}

impl MatValue {
    /// Field of a 1x1 struct (or of element `index` of a struct array).
    pub fn field(&self, index: usize, name: &str) -> Option<&MatValue> {
        match self {
            MatValue::Struct { fields, items, .. } => {
                let j = fields.iter().position(|f| f == name)?;
                items.get(index)?.get(j)
            }
            _ => None,
        }
    }

    /// Dimensions of an array value.
    pub fn dims(&self) -> &[usize] {
        match self {
            MatValue::Numeric { dims, .. }
            | MatValue::Cell { dims, .. }
            | MatValue::Struct { dims, .. } => dims,
            _ => &[],
        }
    }
}

/// Reads all top-level variables of a MAT-file.
pub fn read_file(path: &std::path::Path) -> Result<Vec<(String, MatValue)>, IdentError> {
    let file = path.display().to_string();
    let bytes = std::fs::read(path).map_err(|e| IdentError::Io {
        file: file.clone(),
        source: e,
    })?;
    parse(&bytes, &file)
}

/// Parses MAT-file bytes; `file` names the source in errors.
pub fn parse(bytes: &[u8], file: &str) -> Result<Vec<(String, MatValue)>, IdentError> {
    let err = |offset: usize, message: &str| IdentError::Mat {
        file: file.to_string(),
        offset,
        message: message.to_string(),
    };
    if bytes.len() < 128 || !bytes.starts_with(b"MATLAB 5.0") {
        return Err(err(0, "not a MATLAB level-5 MAT-file"));
    }
    if &bytes[126..128] != b"IM" {
        return Err(err(126, "only little-endian MAT-files are supported"));
    }
    let mut out = Vec::new();
    let mut pos = 128;
    while pos + 8 <= bytes.len() {
        let (ty, n, data_at, next) = tag(bytes, pos).ok_or_else(|| err(pos, "truncated tag"))?;
        let body = bytes
            .get(data_at..data_at + n)
            .ok_or_else(|| err(pos, "element runs past the end of the file"))?;
        let (name, value) = match ty {
            15 => {
                let mut raw = Vec::new();
                flate2::read::ZlibDecoder::new(body)
                    .read_to_end(&mut raw)
                    .map_err(|e| err(pos, &format!("bad compressed element: {e}")))?;
                let (ity, inn, iat, _) =
                    tag(&raw, 0).ok_or_else(|| err(pos, "truncated compressed element"))?;
                if ity != 14 {
                    return Err(err(pos, "compressed element is not a matrix"));
                }
                let inner = raw
                    .get(iat..iat + inn)
                    .ok_or_else(|| err(pos, "compressed matrix is truncated"))?;
                matrix(inner).map_err(|m| err(pos, &m))?
            }
            14 => matrix(body).map_err(|m| err(pos, &m))?,
            _ => return Err(err(pos, &format!("unexpected top-level element type {ty}"))),
        };
        out.push((name, value));
        pos = next;
    }
    Ok(out)
}

/// Reads a tag at `pos`: (type, byte count, data offset, next element offset).
fn tag(b: &[u8], pos: usize) -> Option<(u32, usize, usize, usize)> {
    let w0 = u32::from_le_bytes(b.get(pos..pos + 4)?.try_into().ok()?);
    if w0 >> 16 != 0 {
        // small data element: type and size packed in 4 bytes, data in the next 4
        let n = (w0 >> 16) as usize;
        if n > 4 {
            return None;
        }
        return Some((w0 & 0xffff, n, pos + 4, pos + 8));
    }
    let n = u32::from_le_bytes(b.get(pos + 4..pos + 8)?.try_into().ok()?) as usize;
    let data = pos + 8;
    // compressed elements are not padded to 8 bytes
    let padded = if w0 == 15 { n } else { n.div_ceil(8) * 8 };
    Some((w0, n, data, data + padded))
}

/// Reads the sub-element at `*pos` of a matrix body, advancing `*pos`.
fn sub<'a>(b: &'a [u8], pos: &mut usize) -> Result<(u32, &'a [u8]), String> {
    let (ty, n, at, next) = tag(b, *pos).ok_or("truncated sub-element")?;
    let d = b
        .get(at..at + n)
        .ok_or("sub-element runs past its matrix")?;
    *pos = next;
    Ok((ty, d))
}

fn numbers(ty: u32, d: &[u8]) -> Result<Vec<f64>, String> {
    macro_rules! conv {
        ($t:ty, $w:expr) => {
            d.chunks_exact($w)
                .map(|c| <$t>::from_le_bytes(c.try_into().expect("chunk width")) as f64)
                .collect()
        };
    }
    Ok(match ty {
        1 => d.iter().map(|&v| v as i8 as f64).collect(),
        2 => d.iter().map(|&v| v as f64).collect(),
        3 => conv!(i16, 2),
        4 => conv!(u16, 2),
        5 => conv!(i32, 4),
        6 => conv!(u32, 4),
        7 => conv!(f32, 4),
        9 => conv!(f64, 8),
        12 => conv!(i64, 8),
        13 => conv!(u64, 8),
        16 => String::from_utf8_lossy(d)
            .chars()
            .map(|c| c as u32 as f64)
            .collect(),
        _ => return Err(format!("unsupported data type {ty}")),
    })
}

/// Parses a matrix body into (name, value).
fn matrix(b: &[u8]) -> Result<(String, MatValue), String> {
    if b.is_empty() {
        return Ok((String::new(), MatValue::Empty));
    }
    let mut pos = 0;
    let (_, flags) = sub(b, &mut pos)?;
    let flags0 = u32::from_le_bytes(
        flags
            .get(0..4)
            .ok_or("short array flags")?
            .try_into()
            .unwrap_or([0; 4]),
    );
    let class = flags0 & 0xff;
    let (_, dims_raw) = sub(b, &mut pos)?;
    let dims: Vec<usize> = numbers(5, dims_raw)?
        .into_iter()
        .map(|v| v.max(0.0) as usize)
        .collect();
    let count: usize = dims.iter().product();
    let (_, name_raw) = sub(b, &mut pos)?;
    let name = String::from_utf8_lossy(name_raw).to_string();
    let value = match class {
        1 => {
            let mut items = Vec::with_capacity(count);
            for _ in 0..count {
                let (ty, d) = sub(b, &mut pos)?;
                if ty != 14 {
                    return Err("cell item is not a matrix".into());
                }
                items.push(matrix(d)?.1);
            }
            MatValue::Cell { dims, items }
        }
        2 => {
            let (_, len_raw) = sub(b, &mut pos)?;
            let len = *numbers(5, len_raw)?
                .first()
                .ok_or("missing field name length")? as usize;
            let (_, names_raw) = sub(b, &mut pos)?;
            if len == 0 {
                return Err("zero field name length".into());
            }
            let fields: Vec<String> = names_raw
                .chunks(len)
                .map(|c| {
                    let end = c.iter().position(|&x| x == 0).unwrap_or(c.len());
                    String::from_utf8_lossy(&c[..end]).to_string()
                })
                .collect();
            let mut items = Vec::with_capacity(count);
            for _ in 0..count {
                let mut vals = Vec::with_capacity(fields.len());
                for _ in 0..fields.len() {
                    let (ty, d) = sub(b, &mut pos)?;
                    if ty != 14 {
                        return Err("struct field is not a matrix".into());
                    }
                    vals.push(matrix(d)?.1);
                }
                items.push(vals);
            }
            MatValue::Struct {
                dims,
                fields,
                items,
            }
        }
        4 => {
            let (ty, d) = sub(b, &mut pos)?;
            let codes = numbers(ty, d)?;
            MatValue::Char(
                codes
                    .iter()
                    .filter_map(|&c| char::from_u32(c as u32))
                    .collect(),
            )
        }
        5 => return Err("sparse arrays are not supported".into()),
        6..=15 => {
            let (ty, d) = sub(b, &mut pos)?;
            let data = numbers(ty, d)?;
            if data.len() != count {
                return Err(format!(
                    "numeric array `{name}` has {} values for dims {dims:?}",
                    data.len()
                ));
            }
            MatValue::Numeric { dims, data }
        }
        c => return Err(format!("unsupported array class {c}")),
    };
    Ok((name, value))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Builds an uncompressed MAT-file with one double matrix, to check the reader against
    /// values written by an independent encoder path.
    fn element(ty: u32, data: &[u8]) -> Vec<u8> {
        let mut v = Vec::new();
        v.extend_from_slice(&ty.to_le_bytes());
        v.extend_from_slice(&(data.len() as u32).to_le_bytes());
        v.extend_from_slice(data);
        while v.len() % 8 != 0 {
            v.push(0);
        }
        v
    }

    fn double_matrix(name: &str, rows: i32, cols: i32, vals: &[f64]) -> Vec<u8> {
        let mut body = Vec::new();
        body.extend(element(6, &[6, 0, 0, 0, 0, 0, 0, 0]));
        let mut dims = Vec::new();
        dims.extend_from_slice(&rows.to_le_bytes());
        dims.extend_from_slice(&cols.to_le_bytes());
        body.extend(element(5, &dims));
        body.extend(element(1, name.as_bytes()));
        let raw: Vec<u8> = vals.iter().flat_map(|v| v.to_le_bytes()).collect();
        body.extend(element(9, &raw));
        element(14, &body)
    }

    fn header() -> Vec<u8> {
        let mut h = b"MATLAB 5.0 MAT-file, test".to_vec();
        h.resize(124, b' ');
        h.extend_from_slice(&[0, 1, b'I', b'M']);
        h
    }

    #[test]
    fn reads_plain_and_compressed_double_matrices() {
        let vals = [1.0, -2.5, 3.25, 4.0, 5.0, 6.0];
        let m = double_matrix("a", 2, 3, &vals);
        let mut file = header();
        file.extend(&m);
        let mut enc = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::fast());
        std::io::Write::write_all(&mut enc, &double_matrix("b", 3, 2, &vals)).unwrap();
        let z = enc.finish().unwrap();
        // compressed elements are written without padding
        file.extend_from_slice(&15u32.to_le_bytes());
        file.extend_from_slice(&(z.len() as u32).to_le_bytes());
        file.extend_from_slice(&z);
        file.extend(double_matrix("c", 1, 1, &[7.0]));
        let vars = parse(&file, "t.mat").unwrap();
        assert_eq!(vars.len(), 3);
        assert_eq!(
            vars[2].1,
            MatValue::Numeric {
                dims: vec![1, 1],
                data: vec![7.0]
            }
        );
        assert_eq!(vars[0].0, "a");
        assert_eq!(
            vars[0].1,
            MatValue::Numeric {
                dims: vec![2, 3],
                data: vals.to_vec()
            }
        );
        assert_eq!(vars[1].0, "b");
        assert_eq!(vars[1].1.dims(), &[3, 2]);
    }

    #[test]
    fn rejects_garbage_with_offset() {
        let e = parse(b"hello", "x.mat").unwrap_err().to_string();
        assert!(e.contains("x.mat") && e.contains("byte 0"), "{e}");
        let mut file = header();
        file.extend(element(14, &[1, 2, 3]));
        let e = parse(&file, "y.mat").unwrap_err().to_string();
        assert!(e.contains("byte 128"), "{e}");
    }
}
