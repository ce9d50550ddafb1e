//! Piecewise-constant-curvature kinematics of one segment in `f64`: the one
//! arc-to-tip map of the host (the virtual lab's plant, `ocm ident`, and the
//! firmware's floating-point twin in its tests all call this one).
//!
//! The coordinates are `q = (S, bx, by)`: backbone arc length and
//! the bending vector `b = theta (cos phi, sin phi)` (the polar PCC
//! configuration `(S_c, theta_c, phi_c)` of eq 3.26 in Cartesian form). The
//! columns sit at `beta_i = 0, 120, 240` degrees on radius `d`; `phi` is
//! measured from column 1 towards column 2 (the firmware's convention), so
//! the column lengths are linear in `q`: `l_i = S - d (cos beta_i bx + sin
//! beta_i by)`. That linearity is why the bending vector, not the polar
//! form, is the state: no singularity at the straight pose.

use serde::{Deserialize, Serialize};

/// `cos beta_i` of the three columns.
pub const COS_BETA: [f64; 3] = [1.0, -0.5, -0.5];
/// `sin beta_i` of the three columns.
pub const SIN_BETA: [f64; 3] = [0.0, 0.866_025_403_784_438_6, -0.866_025_403_784_438_6];

/// A segment configuration in the plant's coordinates.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Config {
    /// Backbone arc length `S_c`, metres.
    pub backbone_m: f64,
    /// `theta cos phi`, radians.
    pub bend_x_rad: f64,
    /// `theta sin phi`, radians.
    pub bend_y_rad: f64,
}

impl Config {
    /// From the polar PCC form `(S_c, theta_c, phi_c)`.
    pub fn from_polar(backbone_m: f64, bend_rad: f64, direction_rad: f64) -> Self {
        Self {
            backbone_m,
            bend_x_rad: bend_rad * direction_rad.cos(),
            bend_y_rad: bend_rad * direction_rad.sin(),
        }
    }

    /// As an array `[S, bx, by]`.
    pub fn to_array(self) -> [f64; 3] {
        [self.backbone_m, self.bend_x_rad, self.bend_y_rad]
    }

    /// From an array `[S, bx, by]`.
    pub fn from_array(a: [f64; 3]) -> Self {
        Self {
            backbone_m: a[0],
            bend_x_rad: a[1],
            bend_y_rad: a[2],
        }
    }

    /// Bending angle `theta_c`, radians.
    pub fn bend_rad(&self) -> f64 {
        // Bend components are angles of order one: the plain root cannot
        // overflow, and it costs a fraction of libm's `hypot` on the SIL path.
        (self.bend_x_rad * self.bend_x_rad + self.bend_y_rad * self.bend_y_rad).sqrt()
    }

    /// Column lengths (inverse of eq 3.26), metres.
    pub fn column_lengths(&self, d_m: f64) -> [f64; 3] {
        std::array::from_fn(|i| {
            self.backbone_m - d_m * (COS_BETA[i] * self.bend_x_rad + SIN_BETA[i] * self.bend_y_rad)
        })
    }

    /// Configuration from column lengths (eq 3.26).
    pub fn from_column_lengths(l: [f64; 3], d_m: f64) -> Self {
        Self {
            backbone_m: (l[0] + l[1] + l[2]) / 3.0,
            bend_x_rad: (l[1] + l[2] - 2.0 * l[0]) / (3.0 * d_m),
            bend_y_rad: (l[2] - l[1]) / (3.0_f64.sqrt() * d_m),
        }
    }

    /// The bend angle with the sine and cosine of its half: every map below
    /// is a function of these, so each costs one square root and one
    /// `sin_cos`, and a caller that needs several maps of one configuration
    /// (the lab: tip, IMU and Jacobian every tick) pays them once.
    pub fn turn(&self) -> Turn {
        let theta_rad = self.bend_rad();
        let half_rad = 0.5 * theta_rad;
        let (sin_half, cos_half) = half_rad.sin_cos();
        Turn {
            theta_rad,
            half_rad,
            sin_half,
            cos_half,
        }
    }

    /// `(theta, sinc(theta / 2), cos(theta / 2))`.
    fn half_turn(&self) -> (f64, f64, f64) {
        self.turn().parts()
    }

    /// Plate-centre position in the base frame, metres.
    pub fn position(&self) -> [f64; 3] {
        self.position_with(&self.turn())
    }

    /// [`Self::position`] from this configuration's [`Turn`].
    pub fn position_with(&self, turn: &Turn) -> [f64; 3] {
        let (_, sh, ch) = turn.parts();
        // (1 - cos th) / th^2 = sinc^2(th/2) / 2 and sin th / th =
        // sinc(th/2) cos(th/2): both smooth through the straight pose.
        let lateral = 0.5 * self.backbone_m * sh * sh;
        [
            lateral * self.bend_x_rad,
            lateral * self.bend_y_rad,
            self.backbone_m * sh * ch,
        ]
    }

    /// Plate orientation as a unit quaternion `[w, x, y, z]`: a turn by
    /// `theta` about the in-plane axis `(-sin phi, cos phi, 0)`.
    pub fn quaternion(&self) -> [f64; 4] {
        self.quaternion_with(&self.turn())
    }

    /// [`Self::quaternion`] from this configuration's [`Turn`].
    pub fn quaternion_with(&self, turn: &Turn) -> [f64; 4] {
        let (_, sh, ch) = turn.parts();
        let k = 0.5 * sh;
        [ch, -k * self.bend_y_rad, k * self.bend_x_rad, 0.0]
    }

    /// Plate orientation as a rotation matrix (rows), the same turn as
    /// [`Self::quaternion`]: `R = I + sin(theta) [k]x + (1 - cos(theta)) [k]x^2`
    /// with `k = (-sin phi, cos phi, 0)`.
    pub fn rotation(&self) -> [[f64; 3]; 3] {
        let (th, sh, ch) = self.half_turn();
        // sin(th)/th and (cos(th) - 1)/th^2, smooth through the straight pose.
        let s1 = sh * ch;
        let c1 = -0.5 * sh * sh;
        let (bx, by) = (self.bend_x_rad, self.bend_y_rad);
        [
            [1.0 + bx * bx * c1, bx * by * c1, bx * s1],
            [bx * by * c1, 1.0 + by * by * c1, by * s1],
            [-bx * s1, -by * s1, 1.0 + th * th * c1],
        ]
    }

    /// The configuration whose plate centre is at `p` (single segment): the
    /// arc through the origin, tangent to z there, ending at `p`.
    pub fn from_position(p: [f64; 3]) -> Option<Self> {
        let r = p[0].hypot(p[1]);
        if !(p.iter().all(|v| v.is_finite()) && p[2] > 0.0) {
            return None;
        }
        let th = 2.0 * r.atan2(p[2]);
        let chord = r.hypot(p[2]);
        let s = chord / sinc(0.5 * th);
        let dir = if r > 0.0 { p[1].atan2(p[0]) } else { 0.0 };
        Some(Self::from_polar(s, th, dir))
    }
}

/// The trigonometry of a configuration's bend ([`Config::turn`]).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Turn {
    /// Bend angle `theta`, radians.
    pub theta_rad: f64,
    /// `theta / 2`, radians.
    pub half_rad: f64,
    /// `sin(theta / 2)`.
    pub sin_half: f64,
    /// `cos(theta / 2)`.
    pub cos_half: f64,
}

impl Turn {
    /// `sin(theta / 2) / (theta / 2)`, exact through zero.
    pub fn sinc_half(&self) -> f64 {
        sinc_from_sin(self.half_rad, self.sin_half)
    }

    fn parts(&self) -> (f64, f64, f64) {
        (self.theta_rad, self.sinc_half(), self.cos_half)
    }
}

/// `sin(x)/x`, exact through zero.
pub fn sinc(x: f64) -> f64 {
    sinc_from_sin(x, x.sin())
}

/// `sin(x)/x` given `sin(x)`, with the series near zero (where the quotient
/// loses digits); callers that already hold the sine save a second one.
pub fn sinc_from_sin(x: f64, sin_x: f64) -> f64 {
    if x.abs() < 1e-4 {
        1.0 - x * x / 6.0
    } else {
        sin_x / x
    }
}

/// Geodesic angle between two unit quaternions (eq 3.42), radians.
pub fn quaternion_error_rad(a: [f64; 4], b: [f64; 4]) -> f64 {
    let dot: f64 = a.iter().zip(b).map(|(x, y)| x * y).sum();
    2.0 * dot.abs().min(1.0).acos()
}

/// Hamilton product `a * b` of quaternions `[w, x, y, z]`.
pub fn quat_mul(a: [f64; 4], b: [f64; 4]) -> [f64; 4] {
    [
        a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3],
        a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2],
        a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1],
        a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0],
    ]
}

/// Unit quaternion of the rotation vector `v` (axis times angle, radians).
pub fn quat_from_rotvec(v: [f64; 3]) -> [f64; 4] {
    let a = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    let (s, c) = (0.5 * a).sin_cos();
    let k = 0.5 * sinc_from_sin(0.5 * a, s);
    [c, k * v[0], k * v[1], k * v[2]]
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The frame every user of the map shares: column 1 at +x, column 2 at +120 deg; a
    /// segment bends away from its longest column.
    #[test]
    fn frame_is_pinned_column_one_at_plus_x() {
        let d = 0.06;
        let c = Config::from_column_lengths([0.13, 0.12, 0.12], d);
        let p = c.position();
        assert!(p[0] < -1e-3 && p[1].abs() < 1e-15, "{p:?}");
        let c = Config::from_column_lengths([0.12, 0.12, 0.13], d);
        let p = c.position();
        let dir = p[1].atan2(p[0]).to_degrees();
        assert!(
            (dir - 60.0).abs() < 1e-9,
            "column 3 at -120 deg longest: tip at +60, got {dir}"
        );
        // lengths -> configuration -> lengths is the identity
        let l = c.column_lengths(d);
        assert!((l[2] - 0.13).abs() < 1e-15 && (l[0] - 0.12).abs() < 1e-15);
    }

    /// The rotation matrix is the quaternion's turn, straight pose included.
    #[test]
    fn rotation_matrix_is_the_quaternion() {
        for c in [
            Config::from_polar(0.12, 0.7, 2.1),
            Config::from_polar(0.1, 1e-9, -0.4),
            Config::from_polar(0.1, 0.0, 0.0),
        ] {
            let [w, x, y, z] = c.quaternion();
            let q = [
                [
                    1.0 - 2.0 * (y * y + z * z),
                    2.0 * (x * y - w * z),
                    2.0 * (x * z + w * y),
                ],
                [
                    2.0 * (x * y + w * z),
                    1.0 - 2.0 * (x * x + z * z),
                    2.0 * (y * z - w * x),
                ],
                [
                    2.0 * (x * z - w * y),
                    2.0 * (y * z + w * x),
                    1.0 - 2.0 * (x * x + y * y),
                ],
            ];
            let r = c.rotation();
            for i in 0..3 {
                for j in 0..3 {
                    assert!((r[i][j] - q[i][j]).abs() < 1e-14, "{c:?} {r:?} {q:?}");
                }
            }
        }
        // the plate normal is the arc's tangent at the tip
        let c = Config::from_polar(0.12, 0.7, 2.1);
        let r = c.rotation();
        let t = [
            0.7f64.sin() * 2.1f64.cos(),
            0.7f64.sin() * 2.1f64.sin(),
            0.7f64.cos(),
        ];
        for i in 0..3 {
            assert!((r[i][2] - t[i]).abs() < 1e-14);
        }
    }

    #[test]
    fn position_is_the_arc_and_from_position_inverts_it() {
        let c = Config::from_polar(0.12, 0.7, 2.1);
        let p = c.position();
        let r = c.backbone_m / c.bend_rad();
        // the tip lies on the circle of radius r centred at (r cos phi, r sin phi, 0)
        let centre = [r * 2.1f64.cos(), r * 2.1f64.sin(), 0.0];
        let dist = ((p[0] - centre[0]).powi(2) + (p[1] - centre[1]).powi(2) + p[2].powi(2)).sqrt();
        assert!((dist - r).abs() < 1e-12, "{dist} vs {r}");
        let back = Config::from_position(p).unwrap();
        for (a, b) in back.to_array().iter().zip(c.to_array()) {
            assert!((a - b).abs() < 1e-12, "{a} vs {b}");
        }
        assert!(Config::from_position([0.0, 0.0, -1.0]).is_none());
        assert!(Config::from_position([f64::NAN, 0.0, 1.0]).is_none());
    }
}
