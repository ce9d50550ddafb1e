//! The contact patch on a gel surface: the convex polygon spanned by contact points in the
//! sensor plane, with its area, centroid and second moments of area.

/// Area moments of a contact patch, in the sensor plane (x, y), metres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Patch {
    /// Area, m^2 (0 for fewer than three non-collinear points).
    pub area_m2: f64,
    /// Area centroid (the mean of the points when the area is zero), m.
    pub centroid_m: [f64; 2],
    /// Central second moments per unit area [xx, yy, xy], m^2 (the point covariance when the
    /// area is zero).
    pub moments_m2: [f64; 3],
}

impl Patch {
    /// Eigenvalues (major, minor) of the second-moment matrix, m^2, and the angle of the major
    /// axis from the x axis, rad, in (-pi/2, pi/2].
    pub fn principal(&self) -> (f64, f64, f64) {
        let [a, b, c] = self.moments_m2;
        let mean = 0.5 * (a + b);
        let r = (0.25 * (a - b) * (a - b) + c * c).sqrt();
        let angle = 0.5 * (2.0 * c).atan2(a - b);
        (mean + r, (mean - r).max(0.0), angle)
    }
}

/// The convex hull of 2-D points, counter-clockwise, without collinear points (Andrew's
/// monotone chain).
pub fn convex_hull(points: &[[f64; 2]]) -> Vec<[f64; 2]> {
    let mut p: Vec<[f64; 2]> = points.to_vec();
    p.sort_by(|a, b| a[0].total_cmp(&b[0]).then(a[1].total_cmp(&b[1])));
    p.dedup();
    if p.len() < 3 {
        return p;
    }
    let cross = |o: [f64; 2], a: [f64; 2], b: [f64; 2]| {
        (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])
    };
    let mut hull: Vec<[f64; 2]> = Vec::with_capacity(2 * p.len());
    for pass in 0..2 {
        let start = hull.len();
        let iter: Box<dyn Iterator<Item = &[f64; 2]>> = if pass == 0 {
            Box::new(p.iter())
        } else {
            Box::new(p.iter().rev())
        };
        for &q in iter {
            while hull.len() >= start + 2
                && cross(hull[hull.len() - 2], hull[hull.len() - 1], q) <= 0.0
            {
                hull.pop();
            }
            hull.push(q);
        }
        hull.pop();
    }
    hull
}

/// The patch of contact points (x, y used; z ignored). `None` without points.
pub fn patch(points: &[[f64; 3]]) -> Option<Patch> {
    if points.is_empty() {
        return None;
    }
    let xy: Vec<[f64; 2]> = points.iter().map(|p| [p[0], p[1]]).collect();
    let hull = convex_hull(&xy);
    // Shoelace sums relative to the first vertex keep the round-off small for patches far
    // from the origin.
    if hull.len() >= 3 {
        let o = hull[0];
        let (mut a2, mut cx, mut cy, mut ixx, mut iyy, mut ixy) = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
        for i in 0..hull.len() {
            let (x0, y0) = (hull[i][0] - o[0], hull[i][1] - o[1]);
            let j = (i + 1) % hull.len();
            let (x1, y1) = (hull[j][0] - o[0], hull[j][1] - o[1]);
            let w = x0 * y1 - x1 * y0;
            a2 += w;
            cx += (x0 + x1) * w;
            cy += (y0 + y1) * w;
            ixx += (x0 * x0 + x0 * x1 + x1 * x1) * w;
            iyy += (y0 * y0 + y0 * y1 + y1 * y1) * w;
            ixy += (x0 * y1 + 2.0 * x0 * y0 + 2.0 * x1 * y1 + x1 * y0) * w;
        }
        let area = 0.5 * a2;
        // Degenerate (near-collinear) hulls fall through to the point statistics.
        let scale = hull
            .iter()
            .map(|q| (q[0] - o[0]).hypot(q[1] - o[1]))
            .fold(0.0, f64::max);
        if area > 1e-9 * scale * scale && area > 0.0 {
            let (mx, my) = (cx / (6.0 * area), cy / (6.0 * area));
            // Integrals of x^2, y^2, xy over the polygon, then shifted to the centroid.
            let (sxx, syy, sxy) = (ixx / 12.0, iyy / 12.0, ixy / 24.0);
            return Some(Patch {
                area_m2: area,
                centroid_m: [mx + o[0], my + o[1]],
                moments_m2: [
                    sxx / area - mx * mx,
                    syy / area - my * my,
                    sxy / area - mx * my,
                ],
            });
        }
    }
    let n = xy.len() as f64;
    let mx = xy.iter().map(|p| p[0]).sum::<f64>() / n;
    let my = xy.iter().map(|p| p[1]).sum::<f64>() / n;
    let mut m = [0.0; 3];
    for p in &xy {
        m[0] += (p[0] - mx) * (p[0] - mx) / n;
        m[1] += (p[1] - my) * (p[1] - my) / n;
        m[2] += (p[0] - mx) * (p[1] - my) / n;
    }
    Some(Patch {
        area_m2: 0.0,
        centroid_m: [mx, my],
        moments_m2: m,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A rectangle a x b centred at (cx, cy), rotated by t: area a b, centroid (cx, cy),
    /// principal moments a^2/12 and b^2/12, major axis at angle t.
    #[test]
    fn rotated_rectangle_has_its_closed_form_moments() {
        let (a, b, t, cx, cy) = (0.006, 0.016, 0.3_f64, 0.002, -0.003);
        let (c, s) = (t.cos(), t.sin());
        let mut pts = Vec::new();
        for (u, v) in [
            (-1.0, -1.0),
            (1.0, -1.0),
            (1.0, 1.0),
            (-1.0, 1.0),
            (0.0, 1.0),
        ] {
            let (x, y) = (0.5 * b * u, 0.5 * a * v);
            pts.push([cx + c * x - s * y, cy + s * x + c * y, 0.0]);
        }
        let p = patch(&pts).unwrap();
        assert!((p.area_m2 - a * b).abs() < 1e-15);
        assert!((p.centroid_m[0] - cx).abs() < 1e-12 && (p.centroid_m[1] - cy).abs() < 1e-12);
        let (l1, l2, angle) = p.principal();
        assert!((l1 - b * b / 12.0).abs() < 1e-12 && (l2 - a * a / 12.0).abs() < 1e-12);
        assert!((angle - t).abs() < 1e-9);
    }

    #[test]
    fn two_points_fall_back_to_point_statistics() {
        let p = patch(&[[0.0, 0.0, 0.0], [0.002, 0.0, 0.0]]).unwrap();
        assert_eq!(p.area_m2, 0.0);
        assert!((p.centroid_m[0] - 0.001).abs() < 1e-15);
        assert!((p.moments_m2[0] - 1e-6).abs() < 1e-15);
        assert!(patch(&[]).is_none());
    }
}
