//! Per-feature affine scaling (standardisation) of network inputs and outputs.

use serde::{Deserialize, Serialize};

use crate::error::{LearnError, Result};

/// Maps each feature to zero mean and unit variance: `z = (x - mean) / std`.
///
/// Stored in checkpoints so that a model evaluated later sees its inputs scaled as in training.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Standardizer {
    /// Mean of each feature, in the feature's own unit.
    pub mean: Vec<f64>,
    /// Standard deviation of each feature (never zero: constant features get 1).
    pub std: Vec<f64>,
}

impl Standardizer {
    /// The identity scaling for `dim` features.
    pub fn identity(dim: usize) -> Self {
        Self {
            mean: vec![0.0; dim],
            std: vec![1.0; dim],
        }
    }

    /// Fits mean and standard deviation to row-major `data` of `dim` columns.
    pub fn fit(data: &[f64], dim: usize) -> Result<Self> {
        if dim == 0 || data.is_empty() || !data.len().is_multiple_of(dim) {
            return Err(LearnError::Data(format!(
                "cannot fit a scaler: {} values are not rows of {dim} features",
                data.len()
            )));
        }
        if let Some(i) = data.iter().position(|v| !v.is_finite()) {
            return Err(LearnError::Data(format!(
                "cannot fit a scaler: value {i} (row {}, column {}) is not finite",
                i / dim,
                i % dim
            )));
        }
        let rows = (data.len() / dim) as f64;
        let mut mean = vec![0.0; dim];
        for row in data.chunks_exact(dim) {
            for (m, v) in mean.iter_mut().zip(row) {
                *m += v;
            }
        }
        mean.iter_mut().for_each(|m| *m /= rows);
        let mut var = vec![0.0; dim];
        for row in data.chunks_exact(dim) {
            for ((s, v), m) in var.iter_mut().zip(row).zip(&mean) {
                *s += (v - m) * (v - m);
            }
        }
        let std = var
            .into_iter()
            .zip(&mean)
            .map(|(s, m)| {
                let sd = (s / rows).sqrt();
                // A constant feature carries no information; dividing by a tiny spread would
                // blow round-off up into large inputs.
                if sd > 1e-12 * (1.0 + m.abs()) {
                    sd
                } else {
                    1.0
                }
            })
            .collect();
        Ok(Self { mean, std })
    }

    /// Number of features.
    pub fn dim(&self) -> usize {
        self.mean.len()
    }

    /// Scales row-major `data` into `f32` network units.
    pub fn apply(&self, data: &[f64]) -> Result<Vec<f32>> {
        self.check(data.len())?;
        let d = self.dim();
        Ok(data
            .iter()
            .enumerate()
            .map(|(i, v)| ((v - self.mean[i % d]) / self.std[i % d]) as f32)
            .collect())
    }

    /// Maps row-major network outputs back to physical units.
    pub fn invert(&self, data: &[f32]) -> Result<Vec<f64>> {
        self.check(data.len())?;
        let d = self.dim();
        Ok(data
            .iter()
            .enumerate()
            .map(|(i, v)| f64::from(*v) * self.std[i % d] + self.mean[i % d])
            .collect())
    }

    fn check(&self, len: usize) -> Result<()> {
        if self.dim() == 0 || !len.is_multiple_of(self.dim()) {
            return Err(LearnError::Data(format!(
                "{len} values are not rows of the scaler's {} features",
                self.dim()
            )));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fit_gives_zero_mean_unit_variance_and_inverts() {
        let data = [1.0, 10.0, 3.0, 10.0, 5.0, 10.0];
        let s = Standardizer::fit(&data, 2).unwrap();
        assert!((s.mean[0] - 3.0).abs() < 1e-12);
        assert!((s.std[0] - (8.0f64 / 3.0).sqrt()).abs() < 1e-12);
        // The constant column keeps a unit spread.
        assert_eq!(s.std[1], 1.0);
        let z = s.apply(&data).unwrap();
        let back = s.invert(&z).unwrap();
        for (a, b) in back.iter().zip(&data) {
            assert!((a - b).abs() < 1e-5);
        }
        let m0: f32 = z.iter().step_by(2).sum();
        assert!(m0.abs() < 1e-6);
    }

    #[test]
    fn bad_shapes_and_nan_are_refused() {
        assert!(Standardizer::fit(&[1.0, 2.0, 3.0], 2).is_err());
        assert!(Standardizer::fit(&[1.0, f64::NAN], 2).is_err());
        let s = Standardizer::identity(3);
        assert!(s.apply(&[1.0, 2.0]).is_err());
    }
}
