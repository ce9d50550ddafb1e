//! Legacy VTK unstructured grids (ASCII and big-endian BINARY): reader and writer.
//!
//! Reads the classic `CELLS n size` layout and the version 5.x `OFFSETS`/`CONNECTIVITY`
//! layout. Keeps tetrahedra (type 10) and triangles (type 5), counts the rest.
//! Point and cell data sections after the cells are not needed by the solver and are ignored.

use super::Mesh;
use crate::{FemError, Result};
use std::io::Write;

const VTK_TRIANGLE: u8 = 5;
const VTK_TETRA: u8 = 10;

/// Reads a legacy VTK file.
pub fn read_path(path: impl AsRef<std::path::Path>) -> Result<Mesh> {
    let path = path.as_ref();
    let bytes = std::fs::read(path).map_err(|source| FemError::Io {
        path: path.display().to_string(),
        source,
    })?;
    read_bytes(&bytes).map_err(|e| e.in_file(path))
}

/// Scalar types that may appear in a legacy VTK file.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Scalar {
    F32,
    F64,
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    I64,
    U64,
}

impl Scalar {
    fn parse(name: &str) -> Option<Self> {
        Some(match name.to_ascii_lowercase().as_str() {
            "float" => Scalar::F32,
            "double" => Scalar::F64,
            "char" => Scalar::I8,
            "unsigned_char" => Scalar::U8,
            "short" => Scalar::I16,
            "unsigned_short" => Scalar::U16,
            "int" => Scalar::I32,
            "unsigned_int" => Scalar::U32,
            "long" | "vtktypeint64" => Scalar::I64,
            "unsigned_long" | "vtktypeuint64" => Scalar::U64,
            _ => return None,
        })
    }
    fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::F32 | Scalar::I32 | Scalar::U32 => 4,
            Scalar::F64 | Scalar::I64 | Scalar::U64 => 8,
        }
    }
    fn decode_be(self, b: &[u8]) -> f64 {
        let mut a = [0u8; 8];
        a[..b.len()].copy_from_slice(b);
        match self {
            Scalar::F32 => f32::from_be_bytes([a[0], a[1], a[2], a[3]]) as f64,
            Scalar::F64 => f64::from_be_bytes(a),
            Scalar::I8 => a[0] as i8 as f64,
            Scalar::U8 => a[0] as f64,
            Scalar::I16 => i16::from_be_bytes([a[0], a[1]]) as f64,
            Scalar::U16 => u16::from_be_bytes([a[0], a[1]]) as f64,
            Scalar::I32 => i32::from_be_bytes([a[0], a[1], a[2], a[3]]) as f64,
            Scalar::U32 => u32::from_be_bytes([a[0], a[1], a[2], a[3]]) as f64,
            Scalar::I64 => i64::from_be_bytes(a) as f64,
            Scalar::U64 => u64::from_be_bytes(a) as f64,
        }
    }
}

/// Byte cursor that knows its line number, for error messages.
struct Cursor<'a> {
    b: &'a [u8],
    pos: usize,
    /// Newlines consumed before `pos`.
    nl: usize,
    /// Line of the item most recently read (1-based), for messages.
    line: usize,
    binary: bool,
}

impl<'a> Cursor<'a> {
    fn err(&self, msg: impl Into<String>) -> FemError {
        let at = if self.binary {
            format!("line {} (byte {})", self.line, self.pos)
        } else {
            format!("line {}", self.line)
        };
        FemError::parse("VTK", at, msg)
    }

    /// Next non-empty line (without terminator), trimmed.
    fn line(&mut self) -> Option<&'a str> {
        loop {
            if self.pos >= self.b.len() {
                return None;
            }
            let start = self.pos;
            let end = self.b[start..]
                .iter()
                .position(|&c| c == b'\n')
                .map_or(self.b.len(), |k| start + k);
            self.pos = (end + 1).min(self.b.len());
            self.nl += 1;
            self.line = self.nl;
            let raw = &self.b[start..end];
            // A non-UTF-8 header line is reported as garbage rather than skipped.
            let s = std::str::from_utf8(raw).unwrap_or("\u{fffd}").trim();
            if !s.is_empty() {
                return Some(s);
            }
        }
    }

    /// Next whitespace-separated ASCII token.
    fn token(&mut self) -> Option<&'a str> {
        while self.pos < self.b.len() && self.b[self.pos].is_ascii_whitespace() {
            if self.b[self.pos] == b'\n' {
                self.nl += 1;
            }
            self.pos += 1;
        }
        self.line = self.nl + 1;
        let start = self.pos;
        while self.pos < self.b.len() && !self.b[self.pos].is_ascii_whitespace() {
            self.pos += 1;
        }
        if start == self.pos {
            None
        } else {
            std::str::from_utf8(&self.b[start..self.pos]).ok()
        }
    }

    /// Reads `n` numbers of type `ty`, ASCII or big-endian binary.
    fn numbers(&mut self, n: usize, ty: Scalar, what: &str) -> Result<Vec<f64>> {
        if self.binary {
            let bytes = n
                .checked_mul(ty.size())
                .ok_or_else(|| self.err(format!("{what}: count {n} too large")))?;
            if self.b.len() - self.pos < bytes {
                return Err(self.err(format!(
                    "{what}: need {bytes} bytes of binary data, only {} left",
                    self.b.len() - self.pos
                )));
            }
            let out = self.b[self.pos..self.pos + bytes]
                .chunks_exact(ty.size())
                .map(|c| ty.decode_be(c))
                .collect();
            self.line = self.nl + 1;
            self.pos += bytes;
            self.nl += self.b[self.pos - bytes..self.pos]
                .iter()
                .filter(|&&c| c == b'\n')
                .count();
            Ok(out)
        } else {
            // Cap the reservation: the count comes from the file and may be absurd.
            let mut out = Vec::with_capacity(n.min(1 << 20));
            for k in 0..n {
                let t = self.token().ok_or_else(|| {
                    self.err(format!("{what}: file ends after {k} of {n} values"))
                })?;
                let v: f64 = t
                    .parse()
                    .map_err(|_| self.err(format!("{what}: '{t}' is not a number")))?;
                out.push(v);
            }
            Ok(out)
        }
    }
}

fn parse_count(c: &Cursor, s: Option<&str>, what: &str) -> Result<usize> {
    let s = s.ok_or_else(|| c.err(format!("{what}: missing count")))?;
    s.parse::<usize>()
        .map_err(|_| c.err(format!("{what}: '{s}' is not a non-negative integer")))
}

fn as_index(c: &Cursor, v: f64, what: &str) -> Result<usize> {
    if v.is_finite() && v >= 0.0 && v.fract() == 0.0 && v < usize::MAX as f64 {
        Ok(v as usize)
    } else {
        Err(c.err(format!("{what}: {v} is not a valid index")))
    }
}

/// Parses a legacy VTK unstructured grid held in memory.
pub fn read_bytes(bytes: &[u8]) -> Result<Mesh> {
    let mut c = Cursor {
        b: bytes,
        pos: 0,
        nl: 0,
        line: 0,
        binary: false,
    };
    let head = c.line().ok_or_else(|| c.err("empty file"))?;
    if !head.starts_with("# vtk DataFile") {
        return Err(c.err(format!(
            "expected '# vtk DataFile Version x.x', found '{}'",
            clip(head)
        )));
    }
    let version: f64 = head
        .rsplit(' ')
        .next()
        .and_then(|v| v.parse().ok())
        .unwrap_or(2.0);
    // The title line may be blank, so it is read raw rather than with `line()`.
    skip_raw_line(&mut c);
    let fmt = c.line().ok_or_else(|| c.err("missing ASCII/BINARY line"))?;
    let binary = match fmt.to_ascii_uppercase().as_str() {
        "ASCII" => false,
        "BINARY" => true,
        other => return Err(c.err(format!("expected ASCII or BINARY, found '{}'", clip(other)))),
    };
    let ds = c.line().ok_or_else(|| c.err("missing DATASET line"))?;
    let mut it = ds.split_whitespace();
    if it.next().map(|s| s.to_ascii_uppercase()) != Some("DATASET".into()) {
        return Err(c.err(format!("expected DATASET, found '{}'", clip(ds))));
    }
    match it.next() {
        Some(t) if t.eq_ignore_ascii_case("UNSTRUCTURED_GRID") => {}
        other => {
            return Err(c.err(format!(
                "only UNSTRUCTURED_GRID is supported, found {:?}",
                other.map(clip)
            )));
        }
    }
    c.binary = binary;
    let _ = version;

    let mut mesh = Mesh::default();
    let mut points: Option<Vec<[f64; 3]>> = None;
    let mut cells: Option<Vec<Vec<usize>>> = None;
    let mut types: Option<Vec<u8>> = None;
    loop {
        let save = (c.pos, c.nl, c.line);
        let Some(kw_line) = c.token_line() else { break };
        let mut it = kw_line.split_whitespace();
        let kw = it.next().unwrap_or("").to_ascii_uppercase();
        match kw.as_str() {
            "POINTS" => {
                let n = parse_count(&c, it.next(), "POINTS")?;
                let tyn = it
                    .next()
                    .ok_or_else(|| c.err("POINTS: missing data type"))?;
                let ty = Scalar::parse(tyn)
                    .ok_or_else(|| c.err(format!("POINTS: unknown data type '{}'", clip(tyn))))?;
                let n3 = n
                    .checked_mul(3)
                    .ok_or_else(|| c.err("POINTS: count too large"))?;
                let v = c.numbers(n3, ty, "POINTS")?;
                points = Some(v.chunks_exact(3).map(|p| [p[0], p[1], p[2]]).collect());
            }
            "CELLS" => {
                let n = parse_count(&c, it.next(), "CELLS")?;
                let size = parse_count(&c, it.next(), "CELLS")?;
                let peek = (c.pos, c.nl, c.line);
                let next = if c.binary {
                    c.token_line_peek()
                } else {
                    c.token_peek()
                };
                if next.is_some_and(|s| s.to_ascii_uppercase().starts_with("OFFSETS")) {
                    cells = Some(read_cells_v5(&mut c, n, size)?);
                } else {
                    (c.pos, c.nl, c.line) = peek;
                    let raw = c.numbers(size, Scalar::I32, "CELLS")?;
                    let mut out = Vec::with_capacity(n.min(1 << 20));
                    let mut k = 0;
                    for ci in 0..n {
                        let m = raw.get(k).ok_or_else(|| {
                            c.err(format!("CELLS: list ends before cell {ci} of {n}"))
                        })?;
                        let m = as_index(&c, *m, "CELLS vertex count")?;
                        let ids = raw.get(k + 1..k + 1 + m).ok_or_else(|| {
                            c.err(format!(
                                "CELLS: cell {ci} claims {m} vertices past the end of the list"
                            ))
                        })?;
                        out.push(
                            ids.iter()
                                .map(|&v| as_index(&c, v, "CELLS"))
                                .collect::<Result<Vec<_>>>()?,
                        );
                        k += 1 + m;
                    }
                    if k != size {
                        return Err(c.err(format!(
                            "CELLS: size {size} declared but cells use {k} values"
                        )));
                    }
                    cells = Some(out);
                }
            }
            "CELL_TYPES" => {
                let n = parse_count(&c, it.next(), "CELL_TYPES")?;
                let raw = c.numbers(n, Scalar::I32, "CELL_TYPES")?;
                types = Some(
                    raw.iter()
                        .map(|&v| {
                            let i = as_index(&c, v, "CELL_TYPES")?;
                            u8::try_from(i)
                                .map_err(|_| c.err(format!("CELL_TYPES: unknown type {i}")))
                        })
                        .collect::<Result<Vec<_>>>()?,
                );
            }
            "POINT_DATA" | "CELL_DATA" | "FIELD" | "METADATA" => {
                // Attribute data is not needed to build a model.
                let _ = save;
                break;
            }
            _ => return Err(c.err(format!("unexpected keyword '{}'", clip(&kw)))),
        }
    }
    let points = points.ok_or_else(|| c.err("no POINTS section"))?;
    let cells = cells.unwrap_or_default();
    let types = types.unwrap_or_default();
    if cells.len() != types.len() {
        return Err(c.err(format!(
            "{} cells but {} cell types",
            cells.len(),
            types.len()
        )));
    }
    let np = points.len();
    for (k, (cell, &ty)) in cells.iter().zip(&types).enumerate() {
        if let Some(&bad) = cell.iter().find(|&&i| i >= np) {
            return Err(c.err(format!(
                "cell {k} references point {bad}, but there are {np} points"
            )));
        }
        match (ty, cell.len()) {
            (VTK_TETRA, 4) => mesh.tets.push([cell[0], cell[1], cell[2], cell[3]]),
            (VTK_TRIANGLE, 3) => mesh.triangles.push([cell[0], cell[1], cell[2]]),
            (VTK_TETRA | VTK_TRIANGLE, m) => {
                return Err(c.err(format!("cell {k} of type {ty} has {m} vertices")));
            }
            _ => *mesh.skipped.entry(ty).or_default() += 1,
        }
    }
    mesh.points = points;
    // a NaN coordinate parses as a number; the reader hands out only usable meshes
    mesh.validate()?;
    Ok(mesh)
}

fn read_cells_v5(c: &mut Cursor, n: usize, size: usize) -> Result<Vec<Vec<usize>>> {
    // Version 5 layout: "CELLS n_offsets n_connectivity", then OFFSETS and CONNECTIVITY arrays.
    let l = c
        .token_line()
        .ok_or_else(|| c.err("CELLS: missing OFFSETS"))?;
    let ty = l
        .split_whitespace()
        .nth(1)
        .and_then(Scalar::parse)
        .ok_or_else(|| c.err(format!("OFFSETS: bad header '{}'", clip(l))))?;
    let off = c.numbers(n, ty, "OFFSETS")?;
    let l = c
        .token_line()
        .ok_or_else(|| c.err("CELLS: missing CONNECTIVITY"))?;
    if !l.to_ascii_uppercase().starts_with("CONNECTIVITY") {
        return Err(c.err(format!("expected CONNECTIVITY, found '{}'", clip(l))));
    }
    let ty = l
        .split_whitespace()
        .nth(1)
        .and_then(Scalar::parse)
        .ok_or_else(|| c.err(format!("CONNECTIVITY: bad header '{}'", clip(l))))?;
    let conn = c.numbers(size, ty, "CONNECTIVITY")?;
    let mut out = Vec::with_capacity(n.saturating_sub(1).min(1 << 20));
    for w in off.windows(2) {
        let a = as_index(c, w[0], "OFFSETS")?;
        let b = as_index(c, w[1], "OFFSETS")?;
        let ids = conn.get(a..b).ok_or_else(|| {
            c.err(format!(
                "OFFSETS: range {a}..{b} outside connectivity of {size}"
            ))
        })?;
        out.push(
            ids.iter()
                .map(|&v| as_index(c, v, "CONNECTIVITY"))
                .collect::<Result<Vec<_>>>()?,
        );
    }
    Ok(out)
}

impl<'a> Cursor<'a> {
    /// Next keyword line; in binary files the keyword follows the data's trailing newline.
    fn token_line(&mut self) -> Option<&'a str> {
        self.line()
    }
    fn token_line_peek(&mut self) -> Option<&'a str> {
        let save = (self.pos, self.nl, self.line);
        let r = self.line();
        (self.pos, self.nl, self.line) = save;
        r
    }
    fn token_peek(&mut self) -> Option<&'a str> {
        let save = (self.pos, self.nl, self.line);
        let r = self.token();
        (self.pos, self.nl, self.line) = save;
        r
    }
}

fn skip_raw_line(c: &mut Cursor) {
    if let Some(k) = c.b[c.pos..].iter().position(|&b| b == b'\n') {
        c.pos += k + 1;
    } else {
        c.pos = c.b.len();
    }
    c.nl += 1;
    c.line = c.nl;
}

fn clip(s: &str) -> String {
    s.chars().take(40).collect()
}

/// A named per-point or per-cell field to write.
#[derive(Debug, Clone)]
pub enum Field<'a> {
    /// One scalar per point or cell.
    Scalar(&'a str, &'a [f64]),
    /// One 3-vector per point or cell.
    Vector(&'a str, &'a [[f64; 3]]),
}

impl Field<'_> {
    fn len(&self) -> usize {
        match self {
            Field::Scalar(_, v) => v.len(),
            Field::Vector(_, v) => v.len(),
        }
    }
    fn name(&self) -> &str {
        match self {
            Field::Scalar(n, _) | Field::Vector(n, _) => n,
        }
    }
}

/// Writes `mesh` (tets then triangles) with point and cell data as a BINARY legacy VTK file.
///
/// Cell data covers all cells in that order (tets, then triangles). Names must not contain spaces.
pub fn write(
    out: &mut impl Write,
    mesh: &Mesh,
    title: &str,
    point_data: &[Field],
    cell_data: &[Field],
) -> Result<()> {
    let io = |source| FemError::Io {
        path: "VTK output".into(),
        source,
    };
    let ncell = mesh.tets.len() + mesh.triangles.len();
    for f in point_data {
        if f.len() != mesh.points.len() {
            return Err(FemError::Model(format!(
                "point field '{}' has {} values for {} points",
                f.name(),
                f.len(),
                mesh.points.len()
            )));
        }
    }
    for f in cell_data {
        if f.len() != ncell {
            return Err(FemError::Model(format!(
                "cell field '{}' has {} values for {} cells",
                f.name(),
                f.len(),
                ncell
            )));
        }
    }
    for f in point_data.iter().chain(cell_data) {
        if f.name().is_empty() || f.name().contains(char::is_whitespace) {
            return Err(FemError::Model(format!(
                "field name '{}' must be one word",
                f.name()
            )));
        }
    }
    let mut b: Vec<u8> = Vec::new();
    let title: String = title.chars().filter(|&ch| ch != '\n').take(250).collect();
    b.extend_from_slice(
        format!("# vtk DataFile Version 3.0\n{title}\nBINARY\nDATASET UNSTRUCTURED_GRID\n")
            .as_bytes(),
    );
    b.extend_from_slice(format!("POINTS {} double\n", mesh.points.len()).as_bytes());
    for p in &mesh.points {
        for v in p {
            b.extend_from_slice(&v.to_be_bytes());
        }
    }
    let size = mesh.tets.len() * 5 + mesh.triangles.len() * 4;
    b.extend_from_slice(format!("\nCELLS {ncell} {size}\n").as_bytes());
    let push_i32 = |b: &mut Vec<u8>, v: usize| b.extend_from_slice(&(v as i32).to_be_bytes());
    for t in &mesh.tets {
        push_i32(&mut b, 4);
        t.iter().for_each(|&i| push_i32(&mut b, i));
    }
    for t in &mesh.triangles {
        push_i32(&mut b, 3);
        t.iter().for_each(|&i| push_i32(&mut b, i));
    }
    b.extend_from_slice(format!("\nCELL_TYPES {ncell}\n").as_bytes());
    for _ in &mesh.tets {
        push_i32(&mut b, VTK_TETRA as usize);
    }
    for _ in &mesh.triangles {
        push_i32(&mut b, VTK_TRIANGLE as usize);
    }
    b.push(b'\n');
    for (section, n, fields) in [
        ("POINT_DATA", mesh.points.len(), point_data),
        ("CELL_DATA", ncell, cell_data),
    ] {
        if fields.is_empty() {
            continue;
        }
        b.extend_from_slice(format!("{section} {n}\n").as_bytes());
        for f in fields {
            match f {
                Field::Scalar(name, v) => {
                    b.extend_from_slice(
                        format!("SCALARS {name} double 1\nLOOKUP_TABLE default\n").as_bytes(),
                    );
                    v.iter().for_each(|x| b.extend_from_slice(&x.to_be_bytes()));
                }
                Field::Vector(name, v) => {
                    b.extend_from_slice(format!("VECTORS {name} double\n").as_bytes());
                    v.iter()
                        .flatten()
                        .for_each(|x| b.extend_from_slice(&x.to_be_bytes()));
                }
            }
            b.push(b'\n');
        }
    }
    out.write_all(&b).map_err(io)
}

/// Writes a VTK file to `path`.
pub fn write_path(
    path: impl AsRef<std::path::Path>,
    mesh: &Mesh,
    title: &str,
    point_data: &[Field],
    cell_data: &[Field],
) -> Result<()> {
    let path = path.as_ref();
    let mut f =
        std::io::BufWriter::new(std::fs::File::create(path).map_err(|source| FemError::Io {
            path: path.display().to_string(),
            source,
        })?);
    write(&mut f, mesh, title, point_data, cell_data)?;
    f.flush().map_err(|source| FemError::Io {
        path: path.display().to_string(),
        source,
    })
}

/// Reads the point and cell fields written by [`write()`] (binary or ASCII), by name.
/// Returns (name, components, values) for every SCALARS/VECTORS section, point data first.
pub fn read_fields(bytes: &[u8]) -> Result<Vec<(String, usize, Vec<f64>)>> {
    let mesh_end = find(bytes, b"POINT_DATA").or_else(|| find(bytes, b"CELL_DATA"));
    let Some(start) = mesh_end else {
        return Ok(vec![]);
    };
    let binary = find(bytes, b"BINARY").is_some_and(|k| k < start);
    let mut c = Cursor {
        b: bytes,
        pos: start,
        nl: 0,
        line: 0,
        binary,
    };
    let mut out = Vec::new();
    let mut count = 0usize;
    while let Some(l) = c.line() {
        let mut it = l.split_whitespace();
        match it.next().unwrap_or("") {
            "POINT_DATA" | "CELL_DATA" => count = parse_count(&c, it.next(), "data section")?,
            "SCALARS" => {
                let name = it.next().unwrap_or("").to_string();
                let ty = it
                    .next()
                    .and_then(Scalar::parse)
                    .ok_or_else(|| c.err("SCALARS: bad type"))?;
                let lut = c.line().unwrap_or("");
                if !lut.starts_with("LOOKUP_TABLE") {
                    return Err(c.err("SCALARS: missing LOOKUP_TABLE"));
                }
                out.push((name, 1, c.numbers(count, ty, "SCALARS")?));
            }
            "VECTORS" => {
                let name = it.next().unwrap_or("").to_string();
                let ty = it
                    .next()
                    .and_then(Scalar::parse)
                    .ok_or_else(|| c.err("VECTORS: bad type"))?;
                out.push((name, 3, c.numbers(count * 3, ty, "VECTORS")?));
            }
            other => return Err(c.err(format!("unexpected '{}' in data section", clip(other)))),
        }
    }
    Ok(out)
}

fn find(h: &[u8], n: &[u8]) -> Option<usize> {
    h.windows(n.len()).position(|w| w == n)
}

#[cfg(test)]
mod tests {
    use super::*;

    const ASCII: &str = "# vtk DataFile Version 2.0\ncube\nASCII\nDATASET UNSTRUCTURED_GRID\nPOINTS 5 float\n0 0 0 1 0 0 0 1 0 0 0 1 1 1 1\nCELLS 4 14\n4 0 1 2 3\n3 0 1 2\n1 4\n2 0 4\nCELL_TYPES 4\n10\n5\n1\n3\nCELL_DATA 4\nSCALARS x float 1\nLOOKUP_TABLE default\n1 2 3 4\n";

    #[test]
    fn ascii_tet_and_triangle_with_skipped_cells() {
        let m = read_bytes(ASCII.as_bytes()).unwrap();
        assert_eq!(m.points.len(), 5);
        assert_eq!(m.tets, vec![[0, 1, 2, 3]]);
        assert_eq!(m.triangles, vec![[0, 1, 2]]);
        assert_eq!(m.skipped.get(&1), Some(&1));
        assert_eq!(m.skipped.get(&3), Some(&1));
        assert_eq!(m.points[4], [1.0, 1.0, 1.0]);
    }

    #[test]
    fn version5_offsets_layout() {
        let s = "# vtk DataFile Version 5.1\nt\nASCII\nDATASET UNSTRUCTURED_GRID\nPOINTS 4 double\n0 0 0 1 0 0 0 1 0 0 0 1\nCELLS 3 7\nOFFSETS vtktypeint64\n0 4 7\nCONNECTIVITY vtktypeint64\n0 1 2 3 0 1 2\nCELL_TYPES 2\n10\n5\n";
        let m = read_bytes(s.as_bytes()).unwrap();
        assert_eq!(m.tets, vec![[0, 1, 2, 3]]);
        assert_eq!(m.triangles, vec![[0, 1, 2]]);
    }

    #[test]
    fn binary_round_trip_with_fields() {
        let m = read_bytes(ASCII.as_bytes()).unwrap();
        let disp: Vec<[f64; 3]> = (0..5).map(|i| [i as f64, 0.5, -1.0]).collect();
        let s: Vec<f64> = (0..5).map(|i| i as f64 * 0.25).collect();
        let cs = vec![7.0, 8.0];
        let mut buf = Vec::new();
        write(
            &mut buf,
            &m,
            "round trip",
            &[Field::Vector("u", &disp), Field::Scalar("s", &s)],
            &[Field::Scalar("id", &cs)],
        )
        .unwrap();
        let back = read_bytes(&buf).unwrap();
        assert_eq!(back.points, m.points);
        assert_eq!(back.tets, m.tets);
        assert_eq!(back.triangles, m.triangles);
        let f = read_fields(&buf).unwrap();
        assert_eq!(f[0].0, "u");
        assert_eq!(f[0].2[3], 1.0);
        assert_eq!(f[1].2, s);
        assert_eq!(f[2].2, cs);
    }

    #[test]
    fn errors_name_the_line() {
        let bad = ASCII.replace("0 1 0 0 0 1 1 1 1", "0 1 0 0 0 1 1 x 1");
        let e = read_bytes(bad.as_bytes()).unwrap_err().to_string();
        assert!(e.contains("line 6") && e.contains("'x'"), "{e}");
        let bad = ASCII.replace("4 0 1 2 3", "4 0 1 2 9");
        let e = read_bytes(bad.as_bytes()).unwrap_err().to_string();
        assert!(e.contains("references point 9"), "{e}");
        let e = read_bytes(b"# vtk DataFile Version 2.0\nx\nBINARY\nDATASET UNSTRUCTURED_GRID\nPOINTS 3 double\n\x00\x00")
            .unwrap_err()
            .to_string();
        assert!(e.contains("need 72 bytes"), "{e}");
        let e = read_bytes(b"hello").unwrap_err().to_string();
        assert!(e.contains("line 1"), "{e}");
        // a NaN parses as a number: the reader refuses the mesh, naming the point
        let bad = ASCII.replace("0 1 0 0 0 1 1 1 1", "0 1 0 0 0 1 1 nan 1");
        let e = read_bytes(bad.as_bytes()).unwrap_err().to_string();
        assert!(e.contains("point 4 has a non-finite coordinate"), "{e}");
        // read from a file, the error also names the file
        let path = std::env::temp_dir().join(format!("ocm-bad-{}.vtk", std::process::id()));
        std::fs::write(&path, bad.replace("nan", "x")).unwrap();
        let e = read_path(&path).unwrap_err().to_string();
        std::fs::remove_file(&path).ok();
        assert!(
            e.starts_with(&path.display().to_string()) && e.contains("line 6"),
            "{e}"
        );
    }
}
