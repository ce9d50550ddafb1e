//! What a sensor reports of its contact when the reading has the errors of a real tactile
//! perception: the patch shifted and turned as a whole, its depth and its force off.
//!
//! The rigid proxies give the exact contact. A DIGIT reads it through a camera and a perception
//! network, whose errors the tactile crate measures (centroid and rotation errors of the
//! perceived contact mask, on held-out FEM set-ups and on the real frames). This noise puts
//! those errors on the exact patch, independently per sensor and control step.

use rand::Rng;
use rand_distr::{Distribution, Normal};
use serde::{Deserialize, Serialize};

use crate::contact::SensorContact;
use crate::error::{PegError, Result, non_negative};

/// Standard deviations of the reading's errors (all zero: the exact contact).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct SensorNoise {
    /// Shift of the whole patch along each of the sensor's in-plane axes, m.
    pub centroid_m: f64,
    /// Turn of the patch about its centre, rad.
    pub rotation_rad: f64,
    /// Offset of every point's depth, m (depths stay at or above zero).
    pub depth_m: f64,
    /// Relative error of the normal force (forces stay at or above zero).
    pub force_rel: f64,
}

/// A centroid error that is the median distance of a two-dimensional Gaussian shift is
/// sqrt(2 ln 2) = 1.177 of its per-axis standard deviation.
const MEDIAN_DISTANCE_PER_SIGMA: f64 = 1.177_410_022_515_474_7;
/// The median of |x| for a zero-mean Gaussian x is 0.6745 of its standard deviation.
const MEDIAN_ABS_PER_SIGMA: f64 = 0.674_489_750_196_081_7;

impl SensorNoise {
    /// Noise whose median centroid distance and median |rotation| are the given errors (the
    /// way the tactile crate reports its perception scores).
    pub fn from_median_errors(centroid_m: f64, rotation_rad: f64) -> Self {
        Self {
            centroid_m: centroid_m / MEDIAN_DISTANCE_PER_SIGMA,
            rotation_rad: rotation_rad / MEDIAN_ABS_PER_SIGMA,
            depth_m: 0.0,
            force_rel: 0.0,
        }
    }

    /// The perception network's errors on held-out FEM set-ups (240 x 320, ocm-tactile README:
    /// centroid 0.046 mm, rotation 0.010 rad).
    pub fn perception_on_fem() -> Self {
        Self::from_median_errors(0.046e-3, 0.010)
    }

    /// The same network's errors on the real DIGIT frames of the edge indentation
    /// (centroid 0.81 mm, rotation 0.094 rad).
    pub fn perception_on_real_frames() -> Self {
        Self::from_median_errors(0.81e-3, 0.094)
    }

    /// Every deviation times `factor`.
    pub fn scaled(self, factor: f64) -> Self {
        Self {
            centroid_m: self.centroid_m * factor,
            rotation_rad: self.rotation_rad * factor,
            depth_m: self.depth_m * factor,
            force_rel: self.force_rel * factor,
        }
    }

    /// Whether every deviation is zero (the exact contact).
    pub fn is_exact(&self) -> bool {
        *self == Self::default()
    }

    /// Checks every value, naming the first bad one.
    pub fn validate(&self) -> Result<()> {
        for (name, v) in [
            ("centroid_m", self.centroid_m),
            ("rotation_rad", self.rotation_rad),
            ("depth_m", self.depth_m),
            ("force_rel", self.force_rel),
        ] {
            non_negative(&format!("sensor noise {name}"), v)?;
        }
        Ok(())
    }

    /// The reading of `exact` with one draw of the errors from `rng` (no contact reads as none:
    /// the errors move a patch, they do not make one).
    pub fn read<R: Rng>(&self, exact: &SensorContact, rng: &mut R) -> Result<SensorContact> {
        if self.is_exact() || exact.points_m.is_empty() {
            return Ok(exact.clone());
        }
        let mut draw = |sigma: f64| -> Result<f64> {
            Ok(Normal::new(0.0, sigma)
                .map_err(|e| PegError::Invalid(format!("sensor noise: {e}")))?
                .sample(rng))
        };
        let (dx, dy) = (draw(self.centroid_m)?, draw(self.centroid_m)?);
        let turn = draw(self.rotation_rad)?;
        let dz = draw(self.depth_m)?;
        let df = draw(self.force_rel)?;
        let n = exact.points_m.len() as f64;
        let cx = exact.points_m.iter().map(|p| p[0]).sum::<f64>() / n;
        let cy = exact.points_m.iter().map(|p| p[1]).sum::<f64>() / n;
        let (s, c) = turn.sin_cos();
        let points_m = exact
            .points_m
            .iter()
            .map(|p| {
                let (x, y) = (p[0] - cx, p[1] - cy);
                [
                    cx + dx + c * x - s * y,
                    cy + dy + s * x + c * y,
                    (p[2] + dz).max(0.0),
                ]
            })
            .collect();
        Ok(SensorContact {
            points_m,
            force_n: (exact.force_n * (1.0 + df)).max(0.0),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    fn strip() -> SensorContact {
        SensorContact {
            points_m: vec![
                [-1e-3, -4e-3, 3e-4],
                [1e-3, -4e-3, 3e-4],
                [1e-3, 4e-3, 3e-4],
                [-1e-3, 4e-3, 3e-4],
            ],
            force_n: 2.0,
        }
    }

    /// Over many draws the centroid's median shift and the axis' median turn are the errors the
    /// noise was made from; the patch keeps its shape.
    #[test]
    fn draws_have_the_median_errors_they_were_made_from() {
        let noise = SensorNoise::from_median_errors(0.5e-3, 0.05);
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let exact = strip();
        let (mut dist, mut turn) = (Vec::new(), Vec::new());
        for _ in 0..4001 {
            let r = noise.read(&exact, &mut rng).unwrap();
            let cx = r.points_m.iter().map(|p| p[0]).sum::<f64>() / 4.0;
            let cy = r.points_m.iter().map(|p| p[1]).sum::<f64>() / 4.0;
            dist.push(cx.hypot(cy));
            let a = r.points_m[2];
            let b = r.points_m[1];
            turn.push(((a[1] - b[1]).atan2(a[0] - b[0]) - std::f64::consts::FRAC_PI_2).abs());
            let side = (a[0] - b[0]).hypot(a[1] - b[1]);
            assert!((side - 8e-3).abs() < 1e-12);
            assert_eq!(r.force_n, 2.0);
        }
        let median = |v: &mut Vec<f64>| {
            v.sort_by(f64::total_cmp);
            v[v.len() / 2]
        };
        let (d, t) = (median(&mut dist), median(&mut turn));
        assert!((d - 0.5e-3).abs() < 0.04 * 0.5e-3, "median shift {d} m");
        assert!((t - 0.05).abs() < 0.04 * 0.05, "median turn {t} rad");
    }

    #[test]
    fn no_contact_stays_none_exact_stays_exact_and_bad_values_are_named() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let none = SensorContact::default();
        let noisy = SensorNoise::perception_on_real_frames();
        assert_eq!(noisy.read(&none, &mut rng).unwrap(), none);
        assert_eq!(
            SensorNoise::default().read(&strip(), &mut rng).unwrap(),
            strip()
        );
        let deep = SensorNoise {
            depth_m: 1.0,
            force_rel: 10.0,
            ..Default::default()
        };
        for _ in 0..50 {
            let r = deep.read(&strip(), &mut rng).unwrap();
            assert!(r.force_n >= 0.0 && r.points_m.iter().all(|p| p[2] >= 0.0));
        }
        let e = SensorNoise {
            rotation_rad: f64::NAN,
            ..Default::default()
        }
        .validate()
        .unwrap_err()
        .to_string();
        assert!(e.contains("rotation_rad"), "{e}");
    }
}
