//! Rigid bodies by master-slave elimination.
//!
//! A body's nodes (slaves) follow its reference point c and rotation R exactly:
//! x_i = c + R (X_i - C0), with C0 the lumped-mass centre of the nodes at rest, so c stays the mass
//! centre of the slaves. A body carries six unknowns (dc, dtheta) instead of three per node; the
//! rotation is updated multiplicatively, R <- exp(dtheta) R, with dtheta a spatial rotation vector,
//! so the linearisation is du_i = dc + dtheta x (x_i - c). [`crate::model::Pattern`] holds the
//! reduced system and the solvers move bodies with [`BodyState::moved`].

use nalgebra::{Matrix3, Quaternion, UnitQuaternion, Vector3};

/// Skew matrix `[v]x` with `[v]x w = v x w`.
pub fn skew(v: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -v.z, v.y, v.z, 0.0, -v.x, -v.y, v.x, 0.0)
}

/// A set of model nodes that moves as one rigid body.
#[derive(Debug, Clone)]
pub struct RigidBody {
    /// Name for reports and errors.
    pub name: String,
    /// Its nodes (slaves), ascending.
    pub nodes: Vec<usize>,
    /// Rest offsets X_i - C0 of the nodes, m.
    pub offsets: Vec<Vector3<f64>>,
    /// Reference point C0 at rest: the lumped-mass centre of the nodes, m.
    pub center0: Vector3<f64>,
    /// Lumped mass of its nodes, kg.
    pub mass_kg: f64,
}

/// The configuration and motion of one rigid body (angular quantities in the spatial frame).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BodyState {
    /// Reference point c (the slaves' mass centre), m.
    pub center: Vector3<f64>,
    /// Rotation R from rest.
    pub rotation: UnitQuaternion<f64>,
    /// Velocity of the reference point, m/s.
    pub velocity: Vector3<f64>,
    /// Angular velocity (spatial), rad/s.
    pub angular_velocity: Vector3<f64>,
    /// Acceleration of the reference point, m/s^2.
    pub acceleration: Vector3<f64>,
    /// Angular acceleration (spatial), rad/s^2.
    pub angular_acceleration: Vector3<f64>,
}

impl BodyState {
    /// The body at rest in its undeformed place.
    pub fn at_rest(body: &RigidBody) -> Self {
        BodyState {
            center: body.center0,
            rotation: UnitQuaternion::identity(),
            velocity: Vector3::zeros(),
            angular_velocity: Vector3::zeros(),
            acceleration: Vector3::zeros(),
            angular_acceleration: Vector3::zeros(),
        }
    }

    /// Whether the body sits exactly in its rest place (then its nodes are placed at their rest
    /// positions bit for bit, as clamped bodies must be).
    pub fn is_home(&self, body: &RigidBody) -> bool {
        self.center == body.center0 && self.rotation == UnitQuaternion::identity()
    }

    /// Rotation matrix R.
    pub fn rotation_matrix(&self) -> Matrix3<f64> {
        self.rotation.to_rotation_matrix().into_inner()
    }

    /// The body shifted by `dc` and turned by the spatial rotation vector `dtheta` about c.
    pub fn moved(&self, dc: Vector3<f64>, dtheta: Vector3<f64>) -> Self {
        BodyState {
            center: self.center + dc,
            rotation: exp_rotation(&dtheta) * self.rotation,
            ..*self
        }
    }
}

/// exp: the unit quaternion of a rotation vector (axis times angle, rad).
pub fn exp_rotation(v: &Vector3<f64>) -> UnitQuaternion<f64> {
    let angle = v.norm();
    // sin(a/2)/a by its series near 0, where the quotient loses digits.
    let s = if angle > 1e-6 {
        (0.5 * angle).sin() / angle
    } else {
        0.5 - angle * angle / 48.0
    };
    UnitQuaternion::new_normalize(Quaternion::new(
        (0.5 * angle).cos(),
        s * v.x,
        s * v.y,
        s * v.z,
    ))
}

/// log: the rotation vector (|v| <= pi) of a unit quaternion, accurate for small angles.
pub fn log_rotation(q: &UnitQuaternion<f64>) -> Vector3<f64> {
    let (mut w, mut u) = (q.w, q.imag());
    if w < 0.0 {
        w = -w;
        u = -u;
    }
    let n = u.norm();
    // angle = 2 atan2(n, w); angle / n tends to 2 / w as n -> 0.
    let f = if n > 1e-12 {
        2.0 * n.atan2(w) / n
    } else {
        2.0 / w
    };
    u * f
}

#[cfg(test)]
mod tests {
    use super::*;

    /// exp and log invert each other, agree with nalgebra's axis-angle, and keep small angles exact.
    #[test]
    fn exp_and_log_are_inverse() {
        for v in [
            Vector3::new(0.3, -1.2, 0.7),
            Vector3::new(1e-9, 2e-9, -3e-9),
            Vector3::new(0.0, 0.0, 3.0),
            Vector3::zeros(),
        ] {
            let q = exp_rotation(&v);
            let back = log_rotation(&q);
            assert!(
                (back - v).norm() <= 1e-14 * (1.0 + v.norm()),
                "{v} -> {back}"
            );
            let reference = UnitQuaternion::from_scaled_axis(v);
            assert!(q.angle_to(&reference) < 1e-12);
        }
        // A small rotation applied to a vector moves it by v x r to first order.
        let v = Vector3::new(1e-7, -2e-7, 3e-7);
        let r = Vector3::new(0.2, 0.5, -0.1);
        let moved = exp_rotation(&v) * r;
        assert!((moved - r - v.cross(&r)).norm() < 1e-13);
    }
}
