//! The compact state X_S of Fig 4.3 / App. E, computed by one function from any nodal field.
//!
//! Frame: the mesh frame of the bellows (metres, z up along the robot's axis at rest, origin at the
//! centre of the clamped base face). Components, in this order:
//!
//! | index | name | unit |
//! |---|---|---|
//! | 0-2 | TCP position (top-face centre + offset along the plate normal) | m |
//! | 3 | backbone arc length (constant-curvature arc, base centre to top-face centre) | m |
//! | 4 | backbone curvature | 1/m |
//! | 5-7 | top-plate rotation vector (axis times angle, rest to current, best-fit over the top frame) | rad |
//!
//! and their time derivatives (8-15, the units over s). The derivatives are the exact directional
//! derivatives of the same map along the nodal velocities, taken by a central difference of step
//! [`DERIVATIVE_STEP_S`] seconds (error of order 1e-12 relative); the derivative of the rotation
//! vector is d/dt of those three numbers, not the angular velocity. A full state and a reduced state
//! (u = V q, u' = V q') go through [`XsProbe::compact_state`] alike; the reduced one only forms the
//! probe nodes' rows of V.

use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};
use ocm_fem::bellows::{Bellows, backbone_arc};

/// Number of configuration components of X_S.
pub const XS_DIM: usize = 8;
/// Column names of X_S with units.
pub const XS_NAMES: [&str; XS_DIM] = [
    "tcp_x_m",
    "tcp_y_m",
    "tcp_z_m",
    "arc_length_m",
    "curvature_per_m",
    "rot_x_rad",
    "rot_y_rad",
    "rot_z_rad",
];
/// Time step of the central difference along the velocities, s.
pub const DERIVATIVE_STEP_S: f64 = 1e-6;

/// The nodes and rest data X_S is read from.
#[derive(Debug, Clone)]
pub struct XsProbe {
    /// Top-face nodes (their centroid is the backbone's end).
    pub top_face: Vec<usize>,
    /// Top-frame nodes (their best-fit rotation is the plate's).
    pub top_frame: Vec<usize>,
    /// Rest positions of every node, m.
    pub rest: Vec<Vector3<f64>>,
    /// Centre of the clamped base, m.
    pub base_center: Vector3<f64>,
    /// TCP offset above the top face along the plate normal, m.
    pub tcp_offset_m: f64,
}

impl XsProbe {
    /// The probe of the bellows scene.
    pub fn of_bellows(b: &Bellows) -> Self {
        XsProbe {
            top_face: b.top_face.clone(),
            top_frame: b.top_frame.clone(),
            rest: b.model.rest.clone(),
            base_center: b.base_center,
            tcp_offset_m: b.config.tcp_offset_mm * 1e-3,
        }
    }

    /// Every node X_S reads, sorted and unique.
    pub fn nodes(&self) -> Vec<usize> {
        let mut n: Vec<usize> = self
            .top_face
            .iter()
            .chain(&self.top_frame)
            .copied()
            .collect();
        n.sort_unstable();
        n.dedup();
        n
    }

    /// X_S (8 numbers) of the configuration with nodal displacements `u(i)`, m.
    pub fn configuration(&self, u: &dyn Fn(usize) -> Vector3<f64>) -> [f64; XS_DIM] {
        let pos = |i: usize| self.rest[i] + u(i);
        let n0 = self.top_frame.len() as f64;
        let c0 = self
            .top_frame
            .iter()
            .map(|&i| self.rest[i])
            .sum::<Vector3<f64>>()
            / n0;
        let c1 = self.top_frame.iter().map(|&i| pos(i)).sum::<Vector3<f64>>() / n0;
        let mut h = Matrix3::zeros();
        for &i in &self.top_frame {
            h += (pos(i) - c1) * (self.rest[i] - c0).transpose();
        }
        let r = ocm_fem::element::polar_rotation(&h);
        let top = self.top_face.iter().map(|&i| pos(i)).sum::<Vector3<f64>>()
            / self.top_face.len() as f64;
        let tcp = top + r * Vector3::z() * self.tcp_offset_m;
        let d = top - self.base_center;
        let (arc, kappa) = backbone_arc(&d);
        let rv = rotation_vector(&r);
        [tcp.x, tcp.y, tcp.z, arc, kappa, rv.x, rv.y, rv.z]
    }

    /// X_S and dX_S/dt (16 numbers) from nodal displacements `u(i)` (m) and velocities `v(i)` (m/s).
    /// This is the one function for full and reduced states.
    pub fn compact_state(
        &self,
        u: &dyn Fn(usize) -> Vector3<f64>,
        v: &dyn Fn(usize) -> Vector3<f64>,
    ) -> [f64; 2 * XS_DIM] {
        let h = DERIVATIVE_STEP_S;
        let x = self.configuration(u);
        let plus = self.configuration(&|i| u(i) + v(i) * h);
        let minus = self.configuration(&|i| u(i) - v(i) * h);
        let mut out = [0.0; 2 * XS_DIM];
        out[..XS_DIM].copy_from_slice(&x);
        for k in 0..XS_DIM {
            out[XS_DIM + k] = (plus[k] - minus[k]) / (2.0 * h);
        }
        out
    }

    /// X_S and its rate of a full FEM state.
    pub fn of_full_state(&self, s: &ocm_fem::model::State) -> [f64; 2 * XS_DIM] {
        let u = |i: usize| Vector3::new(s.x[3 * i], s.x[3 * i + 1], s.x[3 * i + 2]) - self.rest[i];
        let v = |i: usize| Vector3::new(s.v[3 * i], s.v[3 * i + 1], s.v[3 * i + 2]);
        self.compact_state(&u, &v)
    }
}

/// Rotation vector (axis times angle, radians) of a rotation matrix.
///
/// Through the quaternion: `Rotation3::scaled_axis` takes the angle as
/// `acos((trace - 1) / 2)`, which is NaN when rounding lifts the trace of a
/// rotation near the identity above 3 (the plate at rest).
fn rotation_vector(r: &Matrix3<f64>) -> Vector3<f64> {
    UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(*r)).scaled_axis()
}

#[cfg(test)]
mod tests {
    /// A rotation near the identity whose trace rounds above 3 still has its
    /// rotation vector (the NaN rows of `ocm mor dataset` came from this).
    #[test]
    fn rotation_vector_near_identity_is_finite() {
        let (s, c) = (1e-9f64, 1.0 + 1e-15);
        let r = nalgebra::Matrix3::new(c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0);
        assert!(r.trace() > 3.0);
        let rv = super::rotation_vector(&r);
        assert!(
            (rv - nalgebra::Vector3::new(0.0, 0.0, 1e-9)).norm() < 1e-15,
            "{rv}"
        );
        // and a finite turn is its axis times its angle
        let q = nalgebra::Rotation3::from_scaled_axis(nalgebra::Vector3::new(0.3, -0.2, 0.1));
        let rv = super::rotation_vector(q.matrix());
        assert!((rv - nalgebra::Vector3::new(0.3, -0.2, 0.1)).norm() < 1e-14);
    }
    use super::*;

    /// A column of nodes: base ring at z = 0, top face ring at z = 0.1, frame above it.
    fn probe() -> XsProbe {
        let mut rest = vec![];
        for z in [0.0, 0.1, 0.11] {
            for k in 0..6 {
                let a = k as f64 * std::f64::consts::PI / 3.0;
                rest.push(Vector3::new(0.02 * a.cos(), 0.02 * a.sin(), z));
            }
        }
        XsProbe {
            top_face: (6..12).collect(),
            top_frame: (6..18).collect(),
            rest,
            base_center: Vector3::zeros(),
            tcp_offset_m: 0.02,
        }
    }

    #[test]
    fn rest_state_and_a_rigid_rotation_with_its_rate() {
        let p = probe();
        let x0 = p.configuration(&|_| Vector3::zeros());
        assert!((x0[2] - 0.12).abs() < 1e-15 && x0[0].abs() < 1e-15);
        assert!((x0[3] - 0.1).abs() < 1e-15 && x0[4] == 0.0);
        // The top part turns about the axis w t through its centre, and translates at velocity c.
        let axis = Vector3::new(0.3, -0.5, 0.2).normalize();
        let (w, t) = (2.0, 0.1);
        let c = Vector3::new(0.01, 0.02, -0.005);
        let pivot = Vector3::new(0.0, 0.0, 0.105);
        let rot = |t: f64| Rotation3::from_scaled_axis(axis * w * t);
        let top = |i: usize| i >= 6;
        let u = |i: usize| {
            if top(i) {
                rot(t) * (p.rest[i] - pivot) + pivot + c * t - p.rest[i]
            } else {
                Vector3::zeros()
            }
        };
        let v = |i: usize| {
            if top(i) {
                (axis * w).cross(&(rot(t) * (p.rest[i] - pivot))) + c
            } else {
                Vector3::zeros()
            }
        };
        let s = p.compact_state(&u, &v);
        let rv = axis * w * t;
        for k in 0..3 {
            assert!((s[5 + k] - rv[k]).abs() < 1e-12, "rotation vector");
            // A rotation about a fixed axis: the rotation vector grows at axis * w.
            assert!((s[XS_DIM + 5 + k] - axis[k] * w).abs() < 1e-6, "rate {k}");
        }
        // TCP rate is the rigid velocity of the TCP point.
        let tcp_rest = Vector3::new(0.0, 0.0, 0.12);
        let tcp_now = rot(t) * (tcp_rest - pivot) + pivot + c * t;
        let tcp_rate = (axis * w).cross(&(rot(t) * (tcp_rest - pivot))) + c;
        for k in 0..3 {
            assert!((s[k] - tcp_now[k]).abs() < 1e-12);
            assert!((s[XS_DIM + k] - tcp_rate[k]).abs() < 1e-7, "tcp rate {k}");
        }
        // The arc-length rate agrees with a finite difference in time of the configuration.
        let dt = 1e-5;
        let at = |tt: f64| {
            p.configuration(&|i| {
                if top(i) {
                    rot(tt) * (p.rest[i] - pivot) + pivot + c * tt - p.rest[i]
                } else {
                    Vector3::zeros()
                }
            })
        };
        let fd = (at(t + dt)[3] - at(t - dt)[3]) / (2.0 * dt);
        assert!((s[XS_DIM + 3] - fd).abs() < 1e-6 * fd.abs().max(1e-3));
        let fd = (at(t + dt)[4] - at(t - dt)[4]) / (2.0 * dt);
        assert!((s[XS_DIM + 4] - fd).abs() < 1e-5 * fd.abs().max(1e-3));
    }
}
