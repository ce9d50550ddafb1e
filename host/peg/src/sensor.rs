//! What a sensor reports of its contact when the reading has the errors of a real tactile
//! perception: the patch shifted and turned as a whole, its depth and its force off.
//!
//! The rigid proxies give the exact contact. A DIGIT reads it through a camera and a perception
//! network, whose errors the tactile crate measures (centroid and rotation errors of the
//! perceived contact mask, on held-out FEM set-ups and on the real frames). This noise puts
//! those errors on the exact patch, per sensor and control step: independent from step to step,
//! or, with a correlation time, drifting slowly the way a network's error on one contact does.

use rand::Rng;
use rand_distr::{Distribution, StandardNormal};
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
    /// Correlation time of every error while a contact lasts, s: each follows a first-order
    /// autoregression with the same spread (0: a fresh draw each reading; infinity: one draw
    /// per contact). A new contact starts with a fresh draw. JSON has no infinity, so it is
    /// stored as "inf".
    #[serde(default, with = "seconds_or_inf")]
    pub correlation_s: f64,
}

/// A duration in JSON as a number, or "inf" for an unbounded one (serde_json writes an
/// infinite f64 as null, which does not read back).
mod seconds_or_inf {
    use serde::{Deserialize, Deserializer, Serializer, de::Error};

    pub fn serialize<S: Serializer>(v: &f64, s: S) -> Result<S::Ok, S::Error> {
        if *v == f64::INFINITY {
            s.serialize_str("inf")
        } else {
            s.serialize_f64(*v)
        }
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
        #[derive(Deserialize)]
        #[serde(untagged)]
        enum Repr {
            Seconds(f64),
            Word(String),
        }
        match Repr::deserialize(d)? {
            Repr::Seconds(v) => Ok(v),
            Repr::Word(w) if w == "inf" => Ok(f64::INFINITY),
            Repr::Word(w) => Err(D::Error::custom(format!(
                "expected a number of seconds or \"inf\", got {w:?}"
            ))),
        }
    }
}

/// One sensor's current errors in units of their standard deviations (none between contacts).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ErrorState {
    /// Shift along x and y, turn, depth, force.
    unit: Option<[f64; 5]>,
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
            correlation_s: 0.0,
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
            correlation_s: self.correlation_s,
        }
    }

    /// The same deviations with correlation time `seconds`.
    pub fn correlated(self, seconds: f64) -> Self {
        Self {
            correlation_s: seconds,
            ..self
        }
    }

    /// Whether every deviation is zero (the exact contact).
    pub fn is_exact(&self) -> bool {
        [
            self.centroid_m,
            self.rotation_rad,
            self.depth_m,
            self.force_rel,
        ] == [0.0; 4]
    }

    /// Checks every value, naming the first bad one.
    pub fn validate(&self) -> Result<()> {
        // Whole names, not formatted ones: `read_after` checks on every reading.
        for (name, v) in [
            ("sensor noise centroid_m", self.centroid_m),
            ("sensor noise rotation_rad", self.rotation_rad),
            ("sensor noise depth_m", self.depth_m),
            ("sensor noise force_rel", self.force_rel),
        ] {
            non_negative(name, v)?;
        }
        // Infinity is allowed here: one error per contact.
        if self.correlation_s.is_nan() || self.correlation_s < 0.0 {
            return Err(PegError::Invalid(format!(
                "sensor noise correlation_s must be zero, positive or infinite, got {}",
                self.correlation_s
            )));
        }
        Ok(())
    }

    /// The reading of `exact` with one independent draw of the errors from `rng` (no contact
    /// reads as none: the errors move a patch, they do not make one).
    pub fn read<R: Rng>(&self, exact: &SensorContact, rng: &mut R) -> Result<SensorContact> {
        self.read_after(exact, &mut ErrorState::default(), 0.0, rng)
    }

    /// The reading of `exact` `dt_s` after the reading that left `state`: each error keeps
    /// exp(-dt / correlation_s) of its last value in units of its deviation and draws the rest
    /// (its spread stays the same); a reading without contact clears the state.
    pub fn read_after<R: Rng>(
        &self,
        exact: &SensorContact,
        state: &mut ErrorState,
        dt_s: f64,
        rng: &mut R,
    ) -> Result<SensorContact> {
        self.validate()?;
        if !(dt_s >= 0.0 && dt_s.is_finite()) {
            return Err(PegError::Invalid(format!(
                "sensor reading interval must be a finite non-negative number of seconds, got {dt_s}"
            )));
        }
        if self.is_exact() || exact.points_m.is_empty() {
            *state = ErrorState::default();
            return Ok(exact.clone());
        }
        let fresh: [f64; 5] = std::array::from_fn(|_| StandardNormal.sample(rng));
        let unit = match state.unit {
            Some(last) if self.correlation_s > 0.0 => {
                let keep = (-dt_s / self.correlation_s).exp();
                let new = (1.0 - keep * keep).sqrt();
                std::array::from_fn(|k| keep * last[k] + new * fresh[k])
            }
            _ => fresh,
        };
        state.unit = Some(unit);
        let (dx, dy) = (self.centroid_m * unit[0], self.centroid_m * unit[1]);
        let turn = self.rotation_rad * unit[2];
        let dz = self.depth_m * unit[3];
        let df = self.force_rel * unit[4];
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

    /// An unbounded correlation time goes through JSON and back; a word other than "inf" is
    /// named.
    #[test]
    fn an_infinite_correlation_time_round_trips_through_json() {
        for c in [0.0, 0.25, f64::INFINITY] {
            let n = SensorNoise::perception_on_real_frames().correlated(c);
            let text = serde_json::to_string(&n).unwrap();
            assert_eq!(
                serde_json::from_str::<SensorNoise>(&text).unwrap(),
                n,
                "{text}"
            );
        }
        let old = r#"{"centroid_m":1e-4,"rotation_rad":0.0,"depth_m":0.0,"force_rel":0.0}"#;
        assert_eq!(
            serde_json::from_str::<SensorNoise>(old)
                .unwrap()
                .correlation_s,
            0.0
        );
        let bad =
            r#"{"centroid_m":0,"rotation_rad":0,"depth_m":0,"force_rel":0,"correlation_s":"long"}"#;
        let e = serde_json::from_str::<SensorNoise>(bad)
            .unwrap_err()
            .to_string();
        assert!(e.contains("\"long\""), "{e}");
    }

    /// The patch's centroid in the sensor's plane.
    fn centroid(c: &SensorContact) -> [f64; 2] {
        let n = c.points_m.len() as f64;
        [
            c.points_m.iter().map(|p| p[0]).sum::<f64>() / n,
            c.points_m.iter().map(|p| p[1]).sum::<f64>() / n,
        ]
    }

    /// With a correlation time the shift is a first-order autoregression: its lag-one
    /// correlation is exp(-dt / tau) and its spread that of the independent draws.
    #[test]
    fn correlated_errors_keep_exp_minus_dt_over_tau_of_the_last_one() {
        let (dt, tau) = (1.0 / 60.0, 0.1);
        let noise = SensorNoise::from_median_errors(0.5e-3, 0.05).correlated(tau);
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let mut state = ErrorState::default();
        let xs: Vec<f64> = (0..40_000)
            .map(|_| {
                centroid(
                    &noise
                        .read_after(&strip(), &mut state, dt, &mut rng)
                        .unwrap(),
                )[0]
            })
            .collect();
        let n = xs.len() as f64;
        let mean = xs.iter().sum::<f64>() / n;
        let var = xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n;
        let lag1 = xs
            .windows(2)
            .map(|w| (w[0] - mean) * (w[1] - mean))
            .sum::<f64>()
            / (n - 1.0)
            / var;
        let want = (-dt / tau).exp();
        assert!(
            (lag1 - want).abs() < 0.01,
            "lag-one correlation {lag1}, want {want}"
        );
        let sigma = noise.centroid_m;
        assert!(
            (var.sqrt() - sigma).abs() < 0.05 * sigma,
            "spread {} m, want {sigma} m",
            var.sqrt()
        );
    }

    /// Without a correlation time a reading is `read`'s independent draw; with an infinite one
    /// the error holds while the contact lasts, and a new contact draws a new one.
    #[test]
    fn zero_correlation_is_independent_and_infinite_holds_per_contact() {
        let real = SensorNoise::perception_on_real_frames();
        let (mut a, mut b) = (ChaCha8Rng::seed_from_u64(5), ChaCha8Rng::seed_from_u64(5));
        let mut state = ErrorState::default();
        for _ in 0..20 {
            assert_eq!(
                real.read(&strip(), &mut a).unwrap(),
                real.read_after(&strip(), &mut state, 0.01, &mut b).unwrap()
            );
        }
        let held = real.correlated(f64::INFINITY);
        let mut rng = ChaCha8Rng::seed_from_u64(6);
        let mut state = ErrorState::default();
        let first = held
            .read_after(&strip(), &mut state, 0.01, &mut rng)
            .unwrap();
        for _ in 0..10 {
            let r = held
                .read_after(&strip(), &mut state, 0.01, &mut rng)
                .unwrap();
            assert_eq!(r, first);
        }
        let none = SensorContact::default();
        assert_eq!(
            held.read_after(&none, &mut state, 0.01, &mut rng).unwrap(),
            none
        );
        let next = held
            .read_after(&strip(), &mut state, 0.01, &mut rng)
            .unwrap();
        assert_ne!(centroid(&next), centroid(&first));
        for bad in [f64::NAN, -1.0] {
            let e = real
                .correlated(bad)
                .read_after(&strip(), &mut state, 0.01, &mut rng)
                .unwrap_err()
                .to_string();
            assert!(e.contains("correlation_s"), "{e}");
        }
        let e = real
            .read_after(&strip(), &mut state, f64::NAN, &mut rng)
            .unwrap_err()
            .to_string();
        assert!(e.contains("interval"), "{e}");
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
