//! A smooth scattered-data interpolant: cubic polyharmonic radial basis functions with a linear
//! polynomial tail (exact at the centres, C2, reproduces linear functions).

use crate::{Result, SurrogateError};
use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

/// An interpolant R^d -> R^m fitted to scattered samples.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct Rbf {
    /// Centres in scaled coordinates.
    pub centres: Vec<Vec<f64>>,
    /// Per input, (offset, scale): scaled = (x - offset) / scale.
    pub input_scaling: Vec<(f64, f64)>,
    /// Weights: one row per centre, then d + 1 polynomial rows; one column per output.
    pub weights: Vec<Vec<f64>>,
}

fn phi(r: f64) -> f64 {
    r * r * r
}

impl Rbf {
    /// Fits `values[i]` at `inputs[i]`; inputs are scaled to [-1, 1] per coordinate.
    pub fn fit(inputs: &[Vec<f64>], values: &[Vec<f64>]) -> Result<Self> {
        let n = inputs.len();
        if n == 0 || values.len() != n {
            return Err(SurrogateError::Invalid(format!(
                "interpolant needs matching inputs and values ({n} and {})",
                values.len()
            )));
        }
        let d = inputs[0].len();
        let m = values[0].len();
        if inputs
            .iter()
            .any(|x| x.len() != d || x.iter().any(|v| !v.is_finite()))
            || values
                .iter()
                .any(|y| y.len() != m || y.iter().any(|v| !v.is_finite()))
        {
            return Err(SurrogateError::Invalid(
                "interpolant data must be finite and of equal length".into(),
            ));
        }
        let input_scaling: Vec<(f64, f64)> = (0..d)
            .map(|k| {
                let lo = inputs.iter().map(|x| x[k]).fold(f64::INFINITY, f64::min);
                let hi = inputs
                    .iter()
                    .map(|x| x[k])
                    .fold(f64::NEG_INFINITY, f64::max);
                (0.5 * (lo + hi), (0.5 * (hi - lo)).max(1e-12))
            })
            .collect();
        let centres: Vec<Vec<f64>> = inputs
            .iter()
            .map(|x| {
                x.iter()
                    .zip(&input_scaling)
                    .map(|(v, (o, s))| (v - o) / s)
                    .collect()
            })
            .collect();
        let size = n + d + 1;
        let mut a = DMatrix::zeros(size, size);
        for i in 0..n {
            for j in 0..n {
                a[(i, j)] = phi(dist(&centres[i], &centres[j]));
            }
            a[(i, n)] = 1.0;
            a[(n, i)] = 1.0;
            for k in 0..d {
                a[(i, n + 1 + k)] = centres[i][k];
                a[(n + 1 + k, i)] = centres[i][k];
            }
        }
        let lu = a.lu();
        let mut weights = vec![vec![0.0; m]; size];
        for out in 0..m {
            let mut rhs = DVector::zeros(size);
            for i in 0..n {
                rhs[i] = values[i][out];
            }
            let w = lu.solve(&rhs).ok_or_else(|| {
                SurrogateError::Solver("interpolant system is singular (repeated inputs?)".into())
            })?;
            for i in 0..size {
                weights[i][out] = w[i];
            }
        }
        Ok(Rbf {
            centres,
            input_scaling,
            weights,
        })
    }

    /// Evaluates the interpolant at `x`.
    pub fn eval(&self, x: &[f64]) -> Vec<f64> {
        let xs: Vec<f64> = x
            .iter()
            .zip(&self.input_scaling)
            .map(|(v, (o, s))| (v - o) / s)
            .collect();
        let n = self.centres.len();
        let m = self.weights.first().map_or(0, |w| w.len());
        let mut y = vec![0.0; m];
        for (i, c) in self.centres.iter().enumerate() {
            let p = phi(dist(c, &xs));
            for (yo, w) in y.iter_mut().zip(&self.weights[i]) {
                *yo += p * w;
            }
        }
        for (yo, w) in y.iter_mut().zip(&self.weights[n]) {
            *yo += w;
        }
        for (k, xk) in xs.iter().enumerate() {
            for (yo, w) in y.iter_mut().zip(&self.weights[n + 1 + k]) {
                *yo += xk * w;
            }
        }
        y
    }
}

fn dist(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y) * (x - y))
        .sum::<f64>()
        .sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn interpolates_and_reproduces_linear_functions() {
        let mut xs = vec![];
        for i in 0..4 {
            for j in 0..4 {
                for k in 0..4 {
                    xs.push(vec![i as f64 * 10.0 - 20.0, j as f64 * 3.0, k as f64 * 0.5]);
                }
            }
        }
        let lin = |x: &[f64]| vec![1.0 + 0.2 * x[0] - 3.0 * x[1] + 7.0 * x[2]];
        let smooth = |x: &[f64]| vec![(0.05 * x[0]).sin() + x[1] * x[2] * 0.1];
        let f = Rbf::fit(&xs, &xs.iter().map(|x| lin(x)).collect::<Vec<_>>()).unwrap();
        // Exact (to round-off) for linear data anywhere, not only at the centres.
        for q in [[3.3, 1.7, 0.2], [-17.0, 8.0, 1.4]] {
            assert!((f.eval(&q)[0] - lin(&q)[0]).abs() < 1e-8);
        }
        let g = Rbf::fit(&xs, &xs.iter().map(|x| smooth(x)).collect::<Vec<_>>()).unwrap();
        for x in &xs {
            assert!((g.eval(x)[0] - smooth(x)[0]).abs() < 1e-9);
        }
        assert!((g.eval(&[5.0, 4.5, 0.75])[0] - smooth(&[5.0, 4.5, 0.75])[0]).abs() < 2e-2);
        assert!(Rbf::fit(&xs[..3], &[vec![1.0]]).is_err());
    }
}
