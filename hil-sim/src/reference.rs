//! Reference paths of the scenarios, as functions of time.

use serde::{Deserialize, Serialize};

use crate::pcc::Config;

/// A reference for the plate: a held configuration or a tip path.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum Path {
    /// Hold one configuration.
    Hold(Config),
    /// Circle in a plane of constant z, counter-clockwise from +x.
    Circle {
        /// Centre, metres.
        center_m: [f64; 3],
        /// Radius, metres.
        radius_m: f64,
        /// Time per turn, seconds.
        period_s: f64,
        /// Time the motion starts (held at the start point before), seconds.
        start_s: f64,
    },
    /// Closed polygon traversed at constant speed.
    Polygon {
        /// Vertices, metres.
        vertices_m: Vec<[f64; 3]>,
        /// Time per lap, seconds.
        period_s: f64,
        /// Time the motion starts, seconds.
        start_s: f64,
    },
    /// Step through targets, each held for `dwell_s`.
    Points {
        /// Targets, metres.
        targets_m: Vec<[f64; 3]>,
        /// Hold time per target, seconds.
        dwell_s: f64,
    },
}

impl Path {
    /// Reference tip position at `t`, metres (for `Hold`, the held
    /// configuration's plate position).
    pub fn tip_at(&self, t: f64) -> [f64; 3] {
        match self {
            Self::Hold(c) => c.position(),
            Self::Circle {
                center_m,
                radius_m,
                period_s,
                start_s,
            } => {
                let a = 2.0 * std::f64::consts::PI * (t - start_s).max(0.0) / period_s;
                [
                    center_m[0] + radius_m * a.cos(),
                    center_m[1] + radius_m * a.sin(),
                    center_m[2],
                ]
            }
            Self::Polygon {
                vertices_m,
                period_s,
                start_s,
            } => {
                let n = vertices_m.len();
                if n == 0 {
                    return [0.0; 3];
                }
                let u = ((t - start_s).max(0.0) / period_s).fract() * n as f64;
                let k = (u.floor() as usize).min(n - 1);
                let f = u - k as f64;
                let (a, b) = (vertices_m[k], vertices_m[(k + 1) % n]);
                std::array::from_fn(|i| a[i] + f * (b[i] - a[i]))
            }
            Self::Points { targets_m, dwell_s } => {
                if targets_m.is_empty() {
                    return [0.0; 3];
                }
                let k = ((t.max(0.0) / dwell_s) as usize).min(targets_m.len() - 1);
                targets_m[k]
            }
        }
    }

    /// Reference configuration at `t`.
    pub fn config_at(&self, t: f64) -> Config {
        match self {
            Self::Hold(c) => *c,
            _ => Config::from_position(self.tip_at(t)).unwrap_or_default(),
        }
    }
}
