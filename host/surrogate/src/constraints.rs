//! Joint limits and the grouped constraints of eq 4.23-4.24 (App. F, eq F.1-F.2).
//!
//! The eleven joints form three groups: the x rotations, the y rotations and the extensions, each
//! ordered from the base up. Every joint lies in its absolute range and neighbours within a group
//! differ by at most delta. The dissertation writes the neighbour bound with a strict "<"; it is
//! applied here as "<=" so that the feasible set is closed (a projection onto it exists and the
//! bounds of the optimiser are attainable).

use crate::chain::{GROUPS, JointKind, KINDS, N_JOINTS, Posture};
use crate::{Result, SurrogateError};
use serde::{Deserialize, Serialize};

/// Absolute limits and neighbour bounds (SI: rad and m).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Limits {
    /// Range of every revolute joint, rad (eq 4.24: [-0.2, 0.2]).
    pub revolute_rad: [f64; 2],
    /// Range of every prismatic joint, m (eq 4.24: [0, 0.02]).
    pub prismatic_m: [f64; 2],
    /// Largest difference of neighbouring x rotations, rad (eq 4.23: 0.01).
    pub delta_x_rad: f64,
    /// Largest difference of neighbouring y rotations, rad (eq 4.23: 0.01).
    pub delta_y_rad: f64,
    /// Largest difference of neighbouring extensions, m (eq 4.23: 0.005).
    pub delta_d_m: f64,
}

impl Default for Limits {
    fn default() -> Self {
        Limits {
            revolute_rad: [-0.2, 0.2],
            prismatic_m: [0.0, 0.02],
            delta_x_rad: 0.01,
            delta_y_rad: 0.01,
            delta_d_m: 0.005,
        }
    }
}

/// Round-off allowed when checking a posture, in the joint's unit.
const TOL: f64 = 1e-12;

/// The name of joint `j` in errors: its index, URDF name and kind, e.g. `joint 4 (y2, theta_y)`.
pub fn joint_channel(j: usize) -> String {
    format!(
        "joint {j} ({}, {})",
        crate::chain::joint_names()[j],
        KINDS[j].name()
    )
}

impl Limits {
    /// The absolute range of joint `j`.
    pub fn range(&self, j: usize) -> [f64; 2] {
        match KINDS[j] {
            JointKind::RevoluteX | JointKind::RevoluteY => self.revolute_rad,
            JointKind::Prismatic => self.prismatic_m,
        }
    }

    /// The neighbour bound of group `g` (0 x, 1 y, 2 d).
    pub fn delta(&self, g: usize) -> f64 {
        [self.delta_x_rad, self.delta_y_rad, self.delta_d_m][g]
    }

    /// Checks the limits themselves (finite, ordered, non-negative deltas).
    pub fn validate(&self) -> Result<()> {
        let ok = |r: [f64; 2]| r[0].is_finite() && r[1].is_finite() && r[0] <= r[1];
        if !ok(self.revolute_rad) || !ok(self.prismatic_m) {
            return Err(SurrogateError::Invalid(format!(
                "joint ranges must be finite and ordered: revolute {:?}, prismatic {:?}",
                self.revolute_rad, self.prismatic_m
            )));
        }
        for g in 0..3 {
            if !(self.delta(g) >= 0.0) || !self.delta(g).is_finite() {
                return Err(SurrogateError::Invalid(format!(
                    "group {g} neighbour bound {} must be finite and >= 0",
                    self.delta(g)
                )));
            }
        }
        Ok(())
    }

    /// Errors naming the first joint that is non-finite ([`SurrogateError::NotFinite`]), out of
    /// its range, or farther than delta from the joint below it in its group (eq 4.23; both
    /// [`SurrogateError::OutOfRange`], with the range it had to lie in).
    pub fn check(&self, q: &Posture) -> Result<()> {
        for j in 0..N_JOINTS {
            SurrogateError::check_value(
                || joint_channel(j),
                q[j],
                self.range(j),
                TOL,
                KINDS[j].unit(),
            )?;
        }
        for (g, members) in GROUPS.iter().enumerate() {
            for w in members.windows(2) {
                let (below, d) = (q[w[0]], self.delta(g));
                SurrogateError::check_value(
                    || {
                        format!(
                            "{} within {d} {} of {} (eq 4.23)",
                            joint_channel(w[1]),
                            KINDS[w[1]].unit(),
                            joint_channel(w[0])
                        )
                    },
                    q[w[1]],
                    {
                        let [lo, hi] = self.range(w[1]);
                        [lo.max(below - d), hi.min(below + d)]
                    },
                    TOL,
                    KINDS[w[1]].unit(),
                )?;
            }
        }
        Ok(())
    }

    /// Clamps any finite posture onto the feasible set: each group from the base up, every joint
    /// clamped to its range and to within delta of the joint below (feasible postures are
    /// unchanged). This is the explicit clamping API; the simulations' `command` rejects
    /// infeasible commands instead. Non-finite values are an error, not clamped.
    pub fn project(&self, q: &Posture) -> Result<Posture> {
        for j in 0..N_JOINTS {
            SurrogateError::check_value(
                || joint_channel(j),
                q[j],
                self.range(j),
                f64::INFINITY,
                KINDS[j].unit(),
            )?;
        }
        let mut out = *q;
        for (g, members) in GROUPS.iter().enumerate() {
            let d = self.delta(g);
            for (k, &j) in members.iter().enumerate() {
                let [lo, hi] = self.range(j);
                let (a, b) = if k == 0 {
                    (lo, hi)
                } else {
                    let below = out[members[k - 1]];
                    (lo.max(below - d), hi.min(below + d))
                };
                out[j] = out[j].clamp(a, b);
            }
        }
        Ok(out)
    }

    /// Box bounds of the increment coordinates (see [`Limits::from_increments`]).
    pub fn increment_bounds(&self) -> [(f64, f64); N_JOINTS] {
        let mut b = [(0.0, 0.0); N_JOINTS];
        for (g, members) in GROUPS.iter().enumerate() {
            for (k, &j) in members.iter().enumerate() {
                let [lo, hi] = self.range(j);
                b[j] = if k == 0 {
                    (lo, hi)
                } else {
                    (-self.delta(g), self.delta(g))
                };
            }
        }
        b
    }

    /// The posture of increment coordinates `z`: the lowest joint of a group takes its value, each
    /// higher one the joint below plus its increment (clamped to +-delta), clamped to the range.
    /// Every `z` gives a feasible posture and every feasible posture has such a
    /// `z` ([`Limits::to_increments`]), so a box-bounded optimiser over `z` searches exactly the
    /// feasible set.
    pub fn from_increments(&self, z: &Posture) -> Posture {
        let mut q = [0.0; N_JOINTS];
        for (g, members) in GROUPS.iter().enumerate() {
            let d = self.delta(g);
            for (k, &j) in members.iter().enumerate() {
                let [lo, hi] = self.range(j);
                q[j] = if k == 0 {
                    z[j].clamp(lo, hi)
                } else {
                    (q[members[k - 1]] + z[j].clamp(-d, d)).clamp(lo, hi)
                };
            }
        }
        q
    }

    /// Increment coordinates of a posture (inverse of [`Limits::from_increments`] on feasible
    /// postures).
    pub fn to_increments(&self, q: &Posture) -> Posture {
        let mut z = *q;
        for members in GROUPS.iter() {
            for k in 1..members.len() {
                z[members[k]] = q[members[k]] - q[members[k - 1]];
            }
        }
        z
    }
}
