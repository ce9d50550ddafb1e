//! Regression planes by SVD and orthogonal projection onto them (dissertation eq 4.20-4.22).

use crate::{Result, SurrogateError};
use nalgebra::{DMatrix, Vector3};

/// A plane n . x + d = 0 with unit normal `n`, fitted through `centroid`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Plane {
    /// Unit normal (the right singular vector of the smallest singular value), oriented +z.
    pub normal: Vector3<f64>,
    /// Offset d = -n . centroid.
    pub offset: f64,
    /// Mean of the fitted points (eq 4.20).
    pub centroid: Vector3<f64>,
}

/// Fits the least-squares plane through `points` (at least three, not collinear, finite).
pub fn fit_plane(points: &[Vector3<f64>]) -> Result<Plane> {
    if points.len() < 3 {
        return Err(SurrogateError::Invalid(format!(
            "plane fit needs at least 3 points, got {}",
            points.len()
        )));
    }
    if let Some(k) = points.iter().position(|p| !p.iter().all(|v| v.is_finite())) {
        return Err(SurrogateError::Invalid(format!(
            "plane fit: point {k} is not finite"
        )));
    }
    let centroid = points.iter().sum::<Vector3<f64>>() / points.len() as f64;
    let centred = DMatrix::from_fn(points.len(), 3, |i, j| points[i][j] - centroid[j]);
    let svd = centred.svd(false, true);
    let v_t = svd
        .v_t
        .ok_or_else(|| SurrogateError::Solver("plane fit: SVD gave no V".into()))?;
    // nalgebra does not sort singular values: take the smallest explicitly.
    let (mut k_min, mut k_mid) = (0, 0);
    let s = &svd.singular_values;
    for k in 1..s.len() {
        if s[k] < s[k_min] {
            k_min = k;
        }
    }
    for k in 0..s.len() {
        if k != k_min && (k_mid == k_min || s[k] < s[k_mid]) {
            k_mid = k;
        }
    }
    let scale = s.max();
    if !(s[k_mid] > 1e-9 * scale.max(f64::MIN_POSITIVE)) {
        return Err(SurrogateError::Invalid(
            "plane fit: points are collinear or coincident".into(),
        ));
    }
    let mut normal = Vector3::new(v_t[(k_min, 0)], v_t[(k_min, 1)], v_t[(k_min, 2)]).normalize();
    if normal.z < 0.0 {
        normal = -normal;
    }
    Ok(Plane {
        normal,
        offset: -normal.dot(&centroid),
        centroid,
    })
}

impl Plane {
    /// Signed distance of `p` from the plane (eq 4.22, delta_p).
    pub fn distance(&self, p: &Vector3<f64>) -> f64 {
        self.normal.dot(p) + self.offset
    }

    /// Orthogonal projection of `p` onto the plane (eq 4.22, v_p).
    pub fn project(&self, p: &Vector3<f64>) -> Vector3<f64> {
        p - self.distance(p) * self.normal
    }
}

/// Mean distance of the projections of `points` from their centroid: the contact radius of one
/// layer in one configuration.
pub fn projected_radius(plane: &Plane, points: &[Vector3<f64>]) -> f64 {
    let proj: Vec<Vector3<f64>> = points.iter().map(|p| plane.project(p)).collect();
    let c = proj.iter().sum::<Vector3<f64>>() / proj.len() as f64;
    proj.iter().map(|p| (p - c).norm()).sum::<f64>() / proj.len() as f64
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    #[test]
    fn recovers_a_known_plane_and_projects_onto_it() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let n = Vector3::new(0.3, -0.2, 1.0).normalize();
        let (u, v) = (n.cross(&Vector3::x()).normalize(), n);
        let w = u.cross(&v);
        let c = Vector3::new(0.01, 0.02, 0.1);
        let pts: Vec<Vector3<f64>> = (0..40)
            .map(|_| c + u * rng.random_range(-0.05..0.05) + w * rng.random_range(-0.05..0.05))
            .collect();
        let p = fit_plane(&pts).unwrap();
        assert!((p.normal - n).norm() < 1e-12, "{:?}", p.normal);
        assert!(p.distance(&c).abs() < 1e-12);
        // Points off the plane project onto it, along the normal.
        let q = c + 0.3 * u + 0.07 * n;
        let qp = p.project(&q);
        assert!(p.distance(&qp).abs() < 1e-14);
        assert!(((q - qp) - 0.07 * n).norm() < 1e-12);
    }

    #[test]
    fn radius_of_a_tilted_noisy_hexagon() {
        // A regular hexagon of circumradius 30 mm, tilted, with +-1 mm out-of-plane noise that
        // alternates in sign (so the best plane is the hexagon's own).
        let n = Vector3::new(0.1, 0.2, 1.0).normalize();
        let u = n.cross(&Vector3::x()).normalize();
        let w = n.cross(&u);
        let pts: Vec<Vector3<f64>> = (0..6)
            .map(|k| {
                let a = k as f64 * std::f64::consts::FRAC_PI_3;
                let s = if k % 2 == 0 { 1e-3 } else { -1e-3 };
                0.03 * (u * a.cos() + w * a.sin()) + n * s
            })
            .collect();
        let p = fit_plane(&pts).unwrap();
        assert!((p.normal - n).norm() < 1e-12);
        assert!((projected_radius(&p, &pts) - 0.03).abs() < 1e-12);
    }

    #[test]
    fn rejects_degenerate_input() {
        let line: Vec<Vector3<f64>> = (0..5).map(|k| Vector3::new(k as f64, 0.0, 0.0)).collect();
        assert!(
            fit_plane(&line)
                .unwrap_err()
                .to_string()
                .contains("collinear")
        );
        assert!(fit_plane(&line[..2]).is_err());
        let mut bad = line.clone();
        bad[1].y = 1.0;
        bad[3].z = f64::NAN;
        assert!(fit_plane(&bad).unwrap_err().to_string().contains("point 3"));
    }
}
