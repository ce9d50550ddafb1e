//! The joint chain of the surrogate (Fig 4.7, 4.9): a fixed base, four bending pairs (a rotation
//! about x followed by one about y, on coincident axes with a massless dummy link between them)
//! and, between consecutive pairs, a segment of two body links joined by a prismatic joint along
//! the local z. A rigid top plate follows the last pair and carries the TCP.
//!
//! Joint order (the posture vector): x1, y1, d1, x2, y2, d2, x3, y3, d3, x4, y4.

use nalgebra::{Matrix3, Rotation3, SMatrix, Vector3};
use serde::{Deserialize, Serialize};

/// Number of joints.
pub const N_JOINTS: usize = 11;

/// A joint posture (rad for rotations, m for extensions), in chain order.
pub type Posture = [f64; N_JOINTS];

/// Kinds of joints.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum JointKind {
    /// Rotation about the local x axis.
    RevoluteX,
    /// Rotation about the local y axis.
    RevoluteY,
    /// Extension along the local z axis.
    Prismatic,
}

impl JointKind {
    /// Short name (theta_x, theta_y, d).
    pub fn name(self) -> &'static str {
        match self {
            JointKind::RevoluteX => "theta_x",
            JointKind::RevoluteY => "theta_y",
            JointKind::Prismatic => "d",
        }
    }

    /// Unit of the joint coordinate.
    pub fn unit(self) -> &'static str {
        match self {
            JointKind::Prismatic => "m",
            _ => "rad",
        }
    }
}

use JointKind::{Prismatic as D, RevoluteX as X, RevoluteY as Y};

/// Joint kinds in chain order.
pub const KINDS: [JointKind; N_JOINTS] = [X, Y, D, X, Y, D, X, Y, D, X, Y];

/// Joint indices of the three groups (x, y, d), base first.
pub const GROUPS: [&[usize]; 3] = [&[0, 3, 6, 9], &[1, 4, 7, 10], &[2, 5, 8]];

/// Dimensions and masses of the chain (m, kg).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ChainGeometry {
    /// Height of the first bending pair above the clamped base face (top of the rigid base).
    pub base_height_m: f64,
    /// Distance between consecutive bending pairs at zero extension.
    pub segment_length_m: f64,
    /// Distance from the last bending pair to the TCP along the top plate's normal.
    pub tcp_offset_m: f64,
    /// Radius of the body links (the smallest layer contact radius, R_min).
    pub link_radius_m: f64,
    /// Radius of the rigid base.
    pub base_radius_m: f64,
    /// Radius of the top plate.
    pub top_radius_m: f64,
    /// Thickness of the top plate (from the last pair to the top face).
    pub top_thickness_m: f64,
    /// Mass of each of the six body links and of the top plate.
    pub link_mass_kg: f64,
    /// Mass of the massless-in-principle dummy links between the x and y rotations.
    pub dummy_mass_kg: f64,
}

/// A rigid transform as rotation and translation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Frame {
    /// Orientation.
    pub r: Matrix3<f64>,
    /// Origin, m.
    pub p: Vector3<f64>,
}

fn rot_x(a: f64) -> Matrix3<f64> {
    *Rotation3::from_axis_angle(&Vector3::x_axis(), a).matrix()
}

fn rot_y(a: f64) -> Matrix3<f64> {
    *Rotation3::from_axis_angle(&Vector3::y_axis(), a).matrix()
}

impl ChainGeometry {
    /// Refuses dimensions and masses the scene cannot be built from: every one finite, the
    /// lengths, radii and link masses positive, the base height, TCP offset and dummy mass not
    /// negative.
    pub fn validate(&self) -> crate::error::Result<()> {
        let positive = [
            ("segment_length_m", self.segment_length_m),
            ("link_radius_m", self.link_radius_m),
            ("base_radius_m", self.base_radius_m),
            ("top_radius_m", self.top_radius_m),
            ("top_thickness_m", self.top_thickness_m),
            ("link_mass_kg", self.link_mass_kg),
        ];
        let non_negative = [
            ("base_height_m", self.base_height_m),
            ("tcp_offset_m", self.tcp_offset_m),
            ("dummy_mass_kg", self.dummy_mass_kg),
        ];
        for (name, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return Err(crate::error::SurrogateError::Invalid(format!(
                    "chain geometry: {name} = {v} must be finite and positive"
                )));
            }
        }
        for (name, v) in non_negative {
            if !(v.is_finite() && v >= 0.0) {
                return Err(crate::error::SurrogateError::Invalid(format!(
                    "chain geometry: {name} = {v} must be finite and not negative"
                )));
            }
        }
        Ok(())
    }

    /// The joint frames in chain order (each at the joint, after the joints below it) and the
    /// TCP frame last. A joint's axis is its frame's x, y or z column.
    pub fn joint_frames(&self, q: &Posture) -> ([Frame; N_JOINTS], Frame) {
        let mut r = Matrix3::identity();
        let mut p = Vector3::new(0.0, 0.0, self.base_height_m);
        let mut frames = [Frame { r, p }; N_JOINTS];
        for (j, kind) in KINDS.iter().enumerate() {
            match kind {
                JointKind::RevoluteX => {
                    frames[j] = Frame { r, p };
                    r *= rot_x(q[j]);
                }
                JointKind::RevoluteY => {
                    frames[j] = Frame { r, p };
                    r *= rot_y(q[j]);
                }
                JointKind::Prismatic => {
                    p += r.column(2) * (0.5 * self.segment_length_m);
                    frames[j] = Frame { r, p };
                    p += r.column(2) * (q[j] + 0.5 * self.segment_length_m);
                }
            }
        }
        let tcp = Frame {
            r,
            p: p + r.column(2) * self.tcp_offset_m,
        };
        (frames, tcp)
    }

    /// Frames of the eleven moving bodies, each the body attached after joint j (dummy links
    /// after the x rotations, body links after the y rotations and extensions, the top plate
    /// last), with the body's centre of mass in that frame (on its z axis, m) and its mass (kg).
    pub fn body_frames(&self, q: &Posture) -> [(Frame, f64, f64); N_JOINTS] {
        let (joints, _) = self.joint_frames(q);
        let h = self.segment_length_m;
        std::array::from_fn(|j| {
            let f = &joints[j];
            match KINDS[j] {
                JointKind::RevoluteX => (
                    Frame {
                        r: f.r * rot_x(q[j]),
                        p: f.p,
                    },
                    0.0,
                    self.dummy_mass_kg,
                ),
                JointKind::RevoluteY => {
                    let com = if j == N_JOINTS - 1 {
                        0.5 * self.top_thickness_m
                    } else {
                        0.25 * h
                    };
                    (
                        Frame {
                            r: f.r * rot_y(q[j]),
                            p: f.p,
                        },
                        com,
                        self.link_mass_kg,
                    )
                }
                JointKind::Prismatic => (
                    Frame {
                        r: f.r,
                        p: f.p + f.r.column(2) * q[j],
                    },
                    0.25 * h,
                    self.link_mass_kg,
                ),
            }
        })
    }

    /// Radius and length of the collision cylinder of the body after joint `j` (None for dummies).
    pub fn body_cylinder(&self, j: usize) -> Option<(f64, f64)> {
        match KINDS[j] {
            JointKind::RevoluteX => None,
            JointKind::RevoluteY if j == N_JOINTS - 1 => {
                Some((self.top_radius_m, self.top_thickness_m))
            }
            _ => Some((self.link_radius_m, 0.5 * self.segment_length_m)),
        }
    }

    /// TCP position, m.
    pub fn tcp(&self, q: &Posture) -> Vector3<f64> {
        self.joint_frames(q).1.p
    }

    /// TCP position and its Jacobian with respect to the posture (3 x 11).
    pub fn tcp_jacobian(&self, q: &Posture) -> (Vector3<f64>, SMatrix<f64, 3, N_JOINTS>) {
        let (frames, tcp) = self.joint_frames(q);
        let mut jac = SMatrix::<f64, 3, N_JOINTS>::zeros();
        for (j, kind) in KINDS.iter().enumerate() {
            let f = &frames[j];
            let col = match kind {
                JointKind::RevoluteX => f.r.column(0).cross(&(tcp.p - f.p)),
                JointKind::RevoluteY => f.r.column(1).cross(&(tcp.p - f.p)),
                JointKind::Prismatic => f.r.column(2).into_owned(),
            };
            jac.set_column(j, &col);
        }
        (tcp.p, jac)
    }

    /// Moving mass of the chain, kg.
    pub fn total_mass_kg(&self) -> f64 {
        7.0 * self.link_mass_kg + 4.0 * self.dummy_mass_kg
    }
}

/// Joint names in chain order, as the URDF and error messages write them.
pub fn joint_names() -> [String; N_JOINTS] {
    std::array::from_fn(|j| {
        let pair = j / 3 + 1;
        match KINDS[j] {
            JointKind::RevoluteX => format!("x{pair}"),
            JointKind::RevoluteY => format!("y{pair}"),
            JointKind::Prismatic => format!("d{pair}"),
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn geo() -> ChainGeometry {
        ChainGeometry {
            base_height_m: 0.015,
            segment_length_m: 0.045,
            tcp_offset_m: 0.033,
            link_radius_m: 0.06,
            base_radius_m: 0.07,
            top_radius_m: 0.08,
            top_thickness_m: 0.02,
            link_mass_kg: 0.1,
            dummy_mass_kg: 1e-5,
        }
    }

    #[test]
    fn bad_dimensions_are_refused_by_name() {
        geo().validate().unwrap();
        for (g, name) in [
            (
                ChainGeometry {
                    segment_length_m: -0.03,
                    ..geo()
                },
                "segment_length_m = -0.03",
            ),
            (
                ChainGeometry {
                    link_radius_m: f64::NAN,
                    ..geo()
                },
                "link_radius_m = NaN",
            ),
            (
                ChainGeometry {
                    base_height_m: -1e-3,
                    ..geo()
                },
                "base_height_m = -0.001",
            ),
        ] {
            let e = g.validate().unwrap_err().to_string();
            assert!(e.contains(name), "{e}");
        }
    }

    #[test]
    fn straight_chain_is_the_sum_of_lengths() {
        let g = geo();
        let mut q = [0.0; N_JOINTS];
        q[2] = 0.01;
        q[5] = 0.002;
        q[8] = 0.003;
        let t = g.tcp(&q);
        let h = 0.015 + 3.0 * 0.045 + 0.015 + 0.033;
        assert!((t - Vector3::new(0.0, 0.0, h)).norm() < 1e-15);
    }

    #[test]
    fn single_bend_by_hand() {
        // Only x1 = a: everything above the first pair rotates about the x axis through it.
        let g = geo();
        let a: f64 = 0.15;
        let mut q = [0.0; N_JOINTS];
        q[0] = a;
        let l = 3.0 * 0.045 + 0.033;
        let want = Vector3::new(0.0, -l * a.sin(), 0.015 + l * a.cos());
        assert!((g.tcp(&q) - want).norm() < 1e-15);
        // y1 = b after x1 = a: R = Rx(a) Ry(b), TCP = p0 + R (0, 0, l).
        let b: f64 = -0.1;
        q[1] = b;
        let want = Vector3::new(
            l * b.sin(),
            -l * a.sin() * b.cos(),
            0.015 + l * a.cos() * b.cos(),
        );
        assert!((g.tcp(&q) - want).norm() < 1e-15);
    }

    #[test]
    fn top_body_frame_carries_the_tcp() {
        let g = geo();
        let q: Posture = [
            0.1, -0.05, 0.01, 0.12, -0.04, 0.012, 0.11, -0.06, 0.008, 0.1, -0.05,
        ];
        let (f, _, _) = g.body_frames(&q)[N_JOINTS - 1];
        let tcp = f.p + f.r.column(2) * g.tcp_offset_m;
        assert!((tcp - g.tcp(&q)).norm() < 1e-15);
        // The upper link of segment 1 sits at the joint d1 moved by d1 along the local z.
        let (joints, _) = g.joint_frames(&q);
        let (u, _, _) = g.body_frames(&q)[2];
        assert!((u.p - joints[2].p - joints[2].r.column(2) * q[2]).norm() < 1e-15);
    }

    #[test]
    fn jacobian_matches_central_differences() {
        let g = geo();
        let q: Posture = [
            0.1, -0.05, 0.01, 0.12, -0.04, 0.012, 0.11, -0.06, 0.008, 0.1, -0.05,
        ];
        let (_, jac) = g.tcp_jacobian(&q);
        for j in 0..N_JOINTS {
            let h = 1e-6;
            let (mut a, mut b) = (q, q);
            a[j] += h;
            b[j] -= h;
            let fd = (g.tcp(&a) - g.tcp(&b)) / (2.0 * h);
            assert!((fd - jac.column(j)).norm() < 1e-9, "joint {j}");
        }
    }
}
