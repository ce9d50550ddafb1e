//! STL surface meshes (binary and ASCII), merged into an indexed triangle mesh.

use super::Mesh;
use crate::{FemError, Result};
use std::collections::HashMap;

/// Reads an STL file.
pub fn read_path(path: impl AsRef<std::path::Path>) -> Result<Mesh> {
    let path = path.as_ref();
    let bytes = std::fs::read(path).map_err(|source| FemError::Io {
        path: path.display().to_string(),
        source,
    })?;
    read_bytes(&bytes).map_err(|e| e.in_file(path))
}

/// Parses an STL held in memory; vertices with bit-identical coordinates are merged.
pub fn read_bytes(b: &[u8]) -> Result<Mesh> {
    if b.len() >= 84 {
        let n = u32::from_le_bytes([b[80], b[81], b[82], b[83]]) as usize;
        if 84 + 50 * n == b.len() {
            return read_binary(b, n);
        }
    }
    let start = b
        .iter()
        .position(|c| !c.is_ascii_whitespace())
        .unwrap_or(b.len());
    if b[start..].starts_with(b"solid") {
        return read_ascii(b);
    }
    if b.len() >= 84 {
        let n = u32::from_le_bytes([b[80], b[81], b[82], b[83]]) as u64;
        return Err(FemError::parse(
            "STL",
            "byte 80",
            format!(
                "binary header declares {n} triangles ({} bytes) but the file has {} bytes, and it does not start with 'solid'",
                84 + 50 * n,
                b.len()
            ),
        ));
    }
    Err(FemError::parse(
        "STL",
        "byte 0",
        "too short for binary STL and does not start with 'solid'",
    ))
}

#[derive(Default)]
struct Builder {
    mesh: Mesh,
    index: HashMap<[u64; 3], usize>,
}

impl Builder {
    fn vertex(&mut self, p: [f64; 3]) -> usize {
        // -0.0 and 0.0 are the same place.
        let key = p.map(|c| (c + 0.0).to_bits());
        *self.index.entry(key).or_insert_with(|| {
            self.mesh.points.push(p);
            self.mesh.points.len() - 1
        })
    }
}

fn read_binary(b: &[u8], n: usize) -> Result<Mesh> {
    let mut bl = Builder::default();
    for t in 0..n {
        let rec = &b[84 + 50 * t..84 + 50 * (t + 1)];
        let mut ids = [0; 3];
        for (k, id) in ids.iter_mut().enumerate() {
            let mut p = [0.0; 3];
            for (j, c) in p.iter_mut().enumerate() {
                let o = 12 + 12 * k + 4 * j;
                *c = f32::from_le_bytes([rec[o], rec[o + 1], rec[o + 2], rec[o + 3]]) as f64;
            }
            if p.iter().any(|c| !c.is_finite()) {
                return Err(FemError::parse(
                    "STL",
                    format!("byte {}", 84 + 50 * t + 12 + 12 * k),
                    format!("triangle {t} has a non-finite vertex"),
                ));
            }
            *id = bl.vertex(p);
        }
        bl.mesh.triangles.push(ids);
    }
    Ok(bl.mesh)
}

fn read_ascii(b: &[u8]) -> Result<Mesh> {
    let text = std::str::from_utf8(b).map_err(|e| {
        FemError::parse(
            "STL",
            format!("byte {}", e.valid_up_to()),
            "ASCII STL is not valid UTF-8",
        )
    })?;
    let mut bl = Builder::default();
    let mut corner: Vec<usize> = Vec::with_capacity(3);
    let mut in_loop = false;
    for (ln, line) in text.lines().enumerate() {
        let at = || format!("line {}", ln + 1);
        let mut it = line.split_whitespace();
        match it.next() {
            Some("vertex") => {
                if !in_loop {
                    return Err(FemError::parse(
                        "STL",
                        at(),
                        "'vertex' outside 'outer loop'",
                    ));
                }
                let mut p = [0.0; 3];
                for c in &mut p {
                    let tok = it.next().ok_or_else(|| {
                        FemError::parse("STL", at(), "vertex needs 3 coordinates")
                    })?;
                    *c = tok
                        .parse()
                        .ok()
                        .filter(|v: &f64| v.is_finite())
                        .ok_or_else(|| {
                            FemError::parse("STL", at(), format!("'{tok}' is not a finite number"))
                        })?;
                }
                if corner.len() == 3 {
                    return Err(FemError::parse(
                        "STL",
                        at(),
                        "facet has more than 3 vertices",
                    ));
                }
                corner.push(bl.vertex(p));
            }
            Some("outer") => {
                in_loop = true;
                corner.clear();
            }
            Some("endloop") => {
                if corner.len() != 3 {
                    return Err(FemError::parse(
                        "STL",
                        at(),
                        format!("facet has {} vertices, expected 3", corner.len()),
                    ));
                }
                bl.mesh.triangles.push([corner[0], corner[1], corner[2]]);
                in_loop = false;
            }
            Some("solid" | "facet" | "endfacet" | "endsolid") | None => {}
            Some(other) => {
                return Err(FemError::parse(
                    "STL",
                    at(),
                    format!(
                        "unexpected keyword '{}'",
                        other.chars().take(30).collect::<String>()
                    ),
                ));
            }
        }
    }
    if in_loop {
        return Err(FemError::parse(
            "STL",
            "end of file",
            "unterminated 'outer loop'",
        ));
    }
    Ok(bl.mesh)
}

/// Writes `mesh.triangles` as binary STL (for inspecting extracted cavities).
pub fn write_binary(out: &mut impl std::io::Write, mesh: &Mesh) -> Result<()> {
    let mut b = vec![0u8; 80];
    b[..20].copy_from_slice(b"ocm-fem binary STL  ");
    b.extend_from_slice(&(mesh.triangles.len() as u32).to_le_bytes());
    for t in &mesh.triangles {
        let p = t.map(|i| nalgebra::Vector3::from(mesh.points[i]));
        let n = (p[1] - p[0])
            .cross(&(p[2] - p[0]))
            .try_normalize(0.0)
            .unwrap_or_default();
        for v in n.iter().chain(p.iter().flat_map(|q| q.iter())) {
            b.extend_from_slice(&(*v as f32).to_le_bytes());
        }
        b.extend_from_slice(&[0, 0]);
    }
    out.write_all(&b).map_err(|source| FemError::Io {
        path: "STL output".into(),
        source,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ascii_and_binary_agree() {
        let s = "solid t\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\nendloop\nendfacet\nfacet normal 0 0 1\nouter loop\nvertex 1 0 0\nvertex 1 1 0\nvertex 0 1 0\nendloop\nendfacet\nendsolid t\n";
        let a = read_bytes(s.as_bytes()).unwrap();
        assert_eq!(a.points.len(), 4);
        assert_eq!(a.triangles.len(), 2);
        let mut buf = Vec::new();
        write_binary(&mut buf, &a).unwrap();
        assert_eq!(buf.len(), 84 + 100);
        let b = read_bytes(&buf).unwrap();
        assert_eq!(a, b);
    }

    #[test]
    fn ascii_errors_name_the_line() {
        let s = "solid t\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 zero 0\n";
        let e = read_bytes(s.as_bytes()).unwrap_err().to_string();
        assert!(e.contains("line 5") && e.contains("zero"), "{e}");
        let mut b = vec![0u8; 84 + 49];
        b[80] = 1;
        let e = read_bytes(&b).unwrap_err().to_string();
        assert!(e.contains("declares 1 triangles"), "{e}");
    }
}
