//! From the image grid back to the gel mesh: a field predicted per pixel (the perception
//! network's surface displacement) becomes a nodal field on the top face, so it can stand in for
//! the neural physics engine's nodal output U (dissertation eq 6.1).

use super::camera::CameraMap;
use crate::{Result, TactileError};

/// Precomputed bilinear interpolation of a rows x cols pixel field at given gel points: each
/// point remembers its four neighbouring pixel centres and their weights, so resampling a frame
/// costs four reads per point. Points beyond the outermost pixel centres take the border value.
#[derive(Debug, Clone)]
pub struct GridToMesh {
    /// Image rows.
    pub rows: usize,
    /// Image columns.
    pub cols: usize,
    taps: Vec<[(u32, f32); 4]>,
}

impl GridToMesh {
    /// Locates the gel points `points_m` (x, y in metres; z ignored) on a rows x cols image
    /// seen through `map`.
    pub fn new(points_m: &[[f64; 3]], rows: usize, cols: usize, map: &CameraMap) -> Result<Self> {
        if rows < 2 || cols < 2 {
            return Err(TactileError::Input(format!(
                "grid-to-mesh resampling needs at least 2 x 2 pixels, got {rows} x {cols}"
            )));
        }
        let mut taps = Vec::with_capacity(points_m.len());
        for (i, p) in points_m.iter().enumerate() {
            if !(p[0].is_finite() && p[1].is_finite()) {
                return Err(TactileError::Input(format!("gel point {i} is {p:?}")));
            }
            let q = map.to_px([p[0], p[1]]);
            // Pixel centres sit at half-integers.
            let axis = |v: f64, n: usize| -> (usize, f32) {
                let t = (v - 0.5).clamp(0.0, (n - 1) as f64);
                let k = (t.floor() as usize).min(n - 2);
                (k, (t - k as f64) as f32)
            };
            let (c, fc) = axis(q[0], cols);
            let (r, fr) = axis(q[1], rows);
            let at = |rr: usize, cc: usize| (rr * cols + cc) as u32;
            taps.push([
                (at(r, c), (1.0 - fr) * (1.0 - fc)),
                (at(r, c + 1), (1.0 - fr) * fc),
                (at(r + 1, c), fr * (1.0 - fc)),
                (at(r + 1, c + 1), fr * fc),
            ]);
        }
        Ok(GridToMesh { rows, cols, taps })
    }

    /// Number of points.
    pub fn len(&self) -> usize {
        self.taps.len()
    }

    /// Whether there are no points.
    pub fn is_empty(&self) -> bool {
        self.taps.is_empty()
    }

    /// The pixel field `field` (rows x cols, row-major) at every point.
    pub fn sample(&self, field: &[f32]) -> Result<Vec<f64>> {
        if field.len() != self.rows * self.cols {
            return Err(TactileError::Input(format!(
                "field of {} values for a {} x {} image",
                field.len(),
                self.rows,
                self.cols
            )));
        }
        if let Some(i) = field.iter().position(|v| !v.is_finite()) {
            return Err(TactileError::Input(format!(
                "field at pixel (row {}, col {}) is {}",
                i / self.cols,
                i % self.cols,
                field[i]
            )));
        }
        Ok(self
            .taps
            .iter()
            .map(|t| {
                t.iter()
                    .map(|&(k, w)| f64::from(w) * f64::from(field[k as usize]))
                    .sum()
            })
            .collect())
    }

    /// The adjoint of [`GridToMesh::sample`]: per-point weights `point_w` spread onto the pixels
    /// through the same bilinear taps, so that `sum(scatter(w) * field) = sum(w * sample(field))`.
    pub fn scatter(&self, point_w: &[f64]) -> Result<Vec<f64>> {
        if point_w.len() != self.taps.len() {
            return Err(TactileError::Input(format!(
                "{} point weights for a resampler of {} points",
                point_w.len(),
                self.taps.len()
            )));
        }
        let mut out = vec![0.0; self.rows * self.cols];
        for (t, &w) in self.taps.iter().zip(point_w) {
            for &(k, f) in t {
                out[k as usize] += f64::from(f) * w;
            }
        }
        Ok(out)
    }

    /// Nodal displacement (m) from surface heights towards the camera `height_m` per pixel:
    /// u = (0, 0, -h). The image carries no lateral displacement, so u_x = u_y = 0.
    pub fn displacement(&self, height_m: &[f32]) -> Result<Vec<[f64; 3]>> {
        Ok(self
            .sample(height_m)?
            .into_iter()
            .map(|h| [0.0, 0.0, -h])
            .collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn map() -> CameraMap {
        CameraMap {
            px_per_m: 16_000.0,
            angle_rad: 0.3,
            mirror: true,
            offset_px: [20.0, 35.0],
        }
    }

    /// Bilinear interpolation reproduces a field linear in the image coordinates exactly, at
    /// points inside the pixel centres; outside, the border value holds.
    #[test]
    fn linear_fields_are_exact() {
        let (rows, cols) = (48, 64);
        let m = map();
        let f = |col: f64, row: f64| 1e-4 + 2e-6 * col - 3e-6 * row;
        let field: Vec<f32> = (0..rows * cols)
            .map(|i| f((i % cols) as f64 + 0.5, (i / cols) as f64 + 0.5) as f32)
            .collect();
        let mut pts = Vec::new();
        for k in 0..200 {
            let q = [
                1.0 + (k as f64 * 0.618).fract() * (cols as f64 - 2.0),
                1.0 + (k as f64 * 0.382).fract() * (rows as f64 - 2.0),
            ];
            let p = m.to_gel(q);
            pts.push([p[0], p[1], 2e-3]);
        }
        let g = GridToMesh::new(&pts, rows, cols, &m).unwrap();
        let u = g.displacement(&field).unwrap();
        for (p, u) in pts.iter().zip(&u) {
            let q = m.to_px([p[0], p[1]]);
            assert!((u[2] + f(q[0], q[1])).abs() < 1e-9, "{u:?} at {q:?}");
            assert_eq!((u[0], u[1]), (0.0, 0.0));
        }
        // Far outside: the nearest corner pixel.
        let far = m.to_gel([-50.0, -50.0]);
        let g = GridToMesh::new(&[[far[0], far[1], 0.0]], rows, cols, &m).unwrap();
        assert!((g.sample(&field).unwrap()[0] - f64::from(field[0])).abs() < 1e-12);
        assert!(g.sample(&field[1..]).is_err());
        let mut bad = field.clone();
        bad[70] = f32::NAN;
        let e = g.sample(&bad).unwrap_err().to_string();
        assert!(e.contains("row 1, col 6"), "{e}");
        assert!(GridToMesh::new(&[[f64::NAN, 0.0, 0.0]], rows, cols, &m).is_err());
    }

    /// `scatter` is the transpose of `sample`: <scatter(w), f> = <w, sample(f)> for arbitrary
    /// w and f, and the weights of a point inside the grid sum to its own weight.
    #[test]
    fn scatter_is_the_adjoint_of_sample() {
        let (rows, cols) = (20, 30);
        let m = map();
        let pts: Vec<[f64; 3]> = (0..50)
            .map(|k| {
                let q = [
                    (k as f64 * 0.618).fract() * cols as f64,
                    (k as f64 * 0.382).fract() * rows as f64,
                ];
                let p = m.to_gel(q);
                [p[0], p[1], 0.0]
            })
            .collect();
        let g = GridToMesh::new(&pts, rows, cols, &m).unwrap();
        let field: Vec<f32> = (0..rows * cols)
            .map(|i| ((i * 37 % 101) as f32 - 50.0) * 1e-3)
            .collect();
        let w: Vec<f64> = (0..pts.len()).map(|k| (k as f64 * 0.7).sin()).collect();
        let lhs: f64 = g
            .scatter(&w)
            .unwrap()
            .iter()
            .zip(&field)
            .map(|(a, b)| a * f64::from(*b))
            .sum();
        let rhs: f64 = g
            .sample(&field)
            .unwrap()
            .iter()
            .zip(&w)
            .map(|(a, b)| a * b)
            .sum();
        assert!((lhs - rhs).abs() < 1e-9, "{lhs} vs {rhs}");
        let one = g.scatter(&[0.0; 50].map(|_: f64| 1.0)).unwrap();
        assert!((one.iter().sum::<f64>() - 50.0).abs() < 1e-5);
        assert!(g.scatter(&w[1..]).is_err());
    }
}
