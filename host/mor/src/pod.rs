//! Proper orthogonal decomposition by a randomized SVD (range finder with oversampling and power
//! iterations, Halko, Martinsson & Tropp 2011) on faer products and QR factorizations.
//!
//! Snapshots are columns (3N x M, displacements from rest, not centred: rest is a state the robot
//! returns to). With k = r + oversampling Gaussian test vectors, Y = A Omega, q power iterations
//! (each re-orthonormalised by QR, which keeps the small singular values from drowning in round-off),
//! B = Q^T A, and the thin SVD of the small B gives U = Q U_B. Cost O(m n k (2 q + 2)), memory
//! O((m + n) k) beside A.

use crate::{MorError, Result};
use faer::linalg::matmul::matmul;
use faer::{Accum, Mat, MatRef, Par};
use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};
use serde::Serialize;

/// How many modes to keep.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub enum Truncation {
    /// Exactly this rank.
    Rank(usize),
    /// The smallest rank whose modes capture this fraction of the snapshot energy (sum of s_i^2),
    /// searched up to `max_rank`.
    Energy {
        /// Fraction in (0, 1].
        fraction: f64,
        /// Largest rank computed.
        max_rank: usize,
    },
}

/// Options of the randomized SVD.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct PodOptions {
    /// Truncation rule.
    pub truncation: Truncation,
    /// Extra test vectors beyond the rank.
    pub oversampling: usize,
    /// Power iterations (A A^T applications).
    pub power_iterations: usize,
    /// Seed of the Gaussian test matrix.
    pub seed: u64,
}

impl Default for PodOptions {
    fn default() -> Self {
        PodOptions {
            truncation: Truncation::Energy {
                fraction: 0.9999,
                max_rank: 200,
            },
            oversampling: 10,
            power_iterations: 2,
            seed: 1,
        }
    }
}

/// A POD basis and its figures.
#[derive(Debug, Clone)]
pub struct Pod {
    /// Orthonormal modes, 3N x r (column-major faer matrix).
    pub modes: Mat<f64>,
    /// Singular values of the snapshot matrix, all that were computed (>= r), descending.
    pub singular_values: Vec<f64>,
    /// Squared Frobenius norm of the snapshot matrix (its total energy).
    pub total_energy: f64,
}

impl Pod {
    /// Rank kept.
    pub fn rank(&self) -> usize {
        self.modes.ncols()
    }

    /// Fraction of the snapshot energy the kept modes capture.
    pub fn captured_energy(&self) -> f64 {
        let r = self.rank();
        self.singular_values[..r].iter().map(|s| s * s).sum::<f64>() / self.total_energy
    }

    /// Relative projection error ||A - U U^T A||_F / ||A||_F of other snapshots (columns of `a`).
    pub fn projection_error(&self, a: MatRef<'_, f64>) -> f64 {
        projection_error(self.modes.as_ref(), a)
    }
}

/// Relative projection error ||A - U U^T A||_F / ||A||_F (0 for an all-zero A).
pub fn projection_error(u: MatRef<'_, f64>, a: MatRef<'_, f64>) -> f64 {
    let mut c = Mat::<f64>::zeros(u.ncols(), a.ncols());
    matmul(
        c.as_mut(),
        Accum::Replace,
        u.transpose(),
        a,
        1.0,
        Par::rayon(0),
    );
    let mut resid = a.to_owned();
    matmul(
        resid.as_mut(),
        Accum::Add,
        u,
        c.as_ref(),
        -1.0,
        Par::rayon(0),
    );
    let na = a.norm_l2();
    if na == 0.0 { 0.0 } else { resid.norm_l2() / na }
}

fn orthonormal_columns(y: &Mat<f64>) -> Mat<f64> {
    y.qr().compute_thin_Q()
}

/// Randomized SVD of the snapshot matrix `a` (3N x M).
pub fn pod(a: MatRef<'_, f64>, opts: &PodOptions) -> Result<Pod> {
    let (m, n) = (a.nrows(), a.ncols());
    if m == 0 || n == 0 {
        return Err(MorError::Invalid("POD of an empty snapshot matrix".into()));
    }
    if let Some((i, j)) = (0..n)
        .flat_map(|j| (0..m).map(move |i| (i, j)))
        .find(|&(i, j)| !a[(i, j)].is_finite())
    {
        return Err(MorError::Invalid(format!(
            "snapshot matrix entry ({i}, {j}) is not finite"
        )));
    }
    let target = match opts.truncation {
        Truncation::Rank(r) => r,
        Truncation::Energy { fraction, max_rank } => {
            if !(fraction > 0.0 && fraction <= 1.0) {
                return Err(MorError::Invalid(format!(
                    "energy fraction {fraction} must be in (0, 1]"
                )));
            }
            max_rank
        }
    };
    if target == 0 || target > m.min(n) {
        return Err(MorError::Invalid(format!(
            "rank {target} must be in 1..={} for a {m} x {n} snapshot matrix",
            m.min(n)
        )));
    }
    let k = (target + opts.oversampling).min(m.min(n));
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(opts.seed);
    let omega = Mat::<f64>::from_fn(n, k, |_, _| StandardNormal.sample(&mut rng));
    let par = Par::rayon(0);
    let mut y = Mat::<f64>::zeros(m, k);
    matmul(y.as_mut(), Accum::Replace, a, omega.as_ref(), 1.0, par);
    drop(omega);
    let mut q = orthonormal_columns(&y);
    let mut z = Mat::<f64>::zeros(n, k);
    for _ in 0..opts.power_iterations {
        matmul(
            z.as_mut(),
            Accum::Replace,
            a.transpose(),
            q.as_ref(),
            1.0,
            par,
        );
        let qz = orthonormal_columns(&z);
        matmul(y.as_mut(), Accum::Replace, a, qz.as_ref(), 1.0, par);
        q = orthonormal_columns(&y);
    }
    drop(z);
    drop(y);
    // B^T = A^T Q (n x k) = Q_b R. The SVD of the small triangle R = U_r S V^T
    // gives B's singular values and B = V S (Q_b U_r)^T, so U = Q V: neither
    // Q_b nor the n x k left factor is ever formed. The thin SVD of B^T itself
    // (a bidiagonalisation of the tall matrix, mostly memory-bound) cost the
    // most time of the whole POD at the benchmark's size.
    let mut bt = Mat::<f64>::zeros(n, k);
    matmul(
        bt.as_mut(),
        Accum::Replace,
        a.transpose(),
        q.as_ref(),
        1.0,
        par,
    );
    let r_factor = bt.qr().thin_R().to_owned();
    drop(bt);
    let svd = r_factor
        .svd()
        .map_err(|e| MorError::Solve(format!("SVD of the sketch did not converge: {e:?}")))?;
    let s: Vec<f64> = (0..k).map(|i| svd.S()[i]).collect();
    let total_energy = a.squared_norm_l2();
    let r = match opts.truncation {
        Truncation::Rank(r) => r,
        Truncation::Energy { fraction, .. } => {
            let mut acc = 0.0;
            let hit = s.iter().position(|v| {
                acc += v * v;
                acc >= fraction * total_energy
            });
            match hit {
                Some(i) if i < target => i + 1,
                _ => {
                    return Err(MorError::Invalid(format!(
                        "{target} modes capture {:.6} of the energy, less than {fraction}: raise the maximum rank",
                        s[..target].iter().map(|v| v * v).sum::<f64>() / total_energy
                    )));
                }
            }
        }
    };
    let mut modes = Mat::<f64>::zeros(m, r);
    matmul(
        modes.as_mut(),
        Accum::Replace,
        q.as_ref(),
        svd.V().get(.., ..r),
        1.0,
        par,
    );
    Ok(Pod {
        modes,
        singular_values: s,
        total_energy,
    })
}

/// A seeded matrix of standard normal entries (benchmarks: a spectrum without decay is the
/// hardest case for the range finder).
pub fn gaussian_matrix(rows: usize, cols: usize, seed: u64) -> Mat<f64> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    Mat::<f64>::from_fn(rows, cols, |_, _| StandardNormal.sample(&mut rng))
}

/// The spectrum of a benchmark matrix: the measured singular values `measured` (descending,
/// positive), continued to `len` values at the geometric decay rate of their last tenth (at
/// least 10 values), so that the tail keeps the measured decay instead of dropping to zero.
pub fn continued_spectrum(measured: &[f64], len: usize) -> Result<Vec<f64>> {
    if measured.len() < 10 || measured.iter().any(|s| !(s.is_finite() && *s > 0.0)) {
        return Err(MorError::Invalid(format!(
            "need at least 10 positive finite singular values to continue a spectrum, got {}",
            measured.len()
        )));
    }
    let n = measured.len();
    let span = (n / 10).max(9);
    let rate = (measured[n - 1] / measured[n - 1 - span])
        .powf(1.0 / span as f64)
        .min(1.0);
    let mut out: Vec<f64> = measured.iter().copied().take(len).collect();
    while out.len() < len {
        let last = out[out.len() - 1];
        out.push(last * rate);
    }
    Ok(out)
}

/// A benchmark snapshot matrix with a prescribed spectrum: A = U diag(sigma) W^T (rows x cols)
/// with U and W the orthonormalised columns of seeded Gaussian matrices (so the singular values
/// of A are `sigma` to round-off), and `held` more columns U diag(sigma) W_h^T whose coefficients
/// W_h are Gaussian with the variance 1/cols of W's entries (held-out snapshots of the same
/// process). Returns (A, held-out columns).
pub fn spectrum_matrix(
    sigma: &[f64],
    rows: usize,
    cols: usize,
    held: usize,
    seed: u64,
) -> Result<(Mat<f64>, Mat<f64>)> {
    let k = sigma.len();
    if k == 0 || k > rows.min(cols) {
        return Err(MorError::Invalid(format!(
            "{k} singular values do not fit a {rows} x {cols} matrix"
        )));
    }
    let par = Par::rayon(0);
    let u = gaussian_matrix(rows, k, seed).qr().compute_thin_Q();
    let w = gaussian_matrix(cols, k, seed.wrapping_add(1))
        .qr()
        .compute_thin_Q();
    let wh =
        gaussian_matrix(held, k, seed.wrapping_add(2)) * faer::Scale(1.0 / (cols as f64).sqrt());
    let us = Mat::<f64>::from_fn(rows, k, |i, j| u[(i, j)] * sigma[j]);
    drop(u);
    let mut a = Mat::<f64>::zeros(rows, cols);
    matmul(
        a.as_mut(),
        Accum::Replace,
        us.as_ref(),
        w.transpose(),
        1.0,
        par,
    );
    let mut h = Mat::<f64>::zeros(rows, held);
    matmul(
        h.as_mut(),
        Accum::Replace,
        us.as_ref(),
        wh.transpose(),
        1.0,
        par,
    );
    Ok((a, h))
}

/// Largest principal angle between the column spaces of two orthonormal bases, radians.
pub fn subspace_angle(u: MatRef<'_, f64>, w: MatRef<'_, f64>) -> f64 {
    // sin(theta_max) = ||(I - U U^T) W||_2.
    let mut c = Mat::<f64>::zeros(u.ncols(), w.ncols());
    matmul(c.as_mut(), Accum::Replace, u.transpose(), w, 1.0, Par::Seq);
    let mut resid = w.to_owned();
    matmul(resid.as_mut(), Accum::Add, u, c.as_ref(), -1.0, Par::Seq);
    let s = resid.singular_values().unwrap_or_default();
    s.first().copied().unwrap_or(0.0).clamp(0.0, 1.0).asin()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 120 x 80 matrix U diag(s) V^T with known, decaying singular values.
    fn known(seed: u64) -> (Mat<f64>, Vec<f64>) {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let g1 = Mat::<f64>::from_fn(120, 80, |_, _| StandardNormal.sample(&mut rng));
        let g2 = Mat::<f64>::from_fn(80, 80, |_, _| StandardNormal.sample(&mut rng));
        let (u, v) = (g1.qr().compute_thin_Q(), g2.qr().compute_thin_Q());
        let s: Vec<f64> = (0..80).map(|i| 10.0 * 0.7f64.powi(i)).collect();
        let us = Mat::<f64>::from_fn(120, 80, |i, j| u[(i, j)] * s[j]);
        let mut a = Mat::<f64>::zeros(120, 80);
        matmul(
            a.as_mut(),
            Accum::Replace,
            us.as_ref(),
            v.transpose(),
            1.0,
            Par::Seq,
        );
        (a, s)
    }

    #[test]
    fn randomized_svd_matches_the_dense_svd() {
        let (a, s) = known(3);
        let dense = a.thin_svd().unwrap();
        let p = pod(
            a.as_ref(),
            &PodOptions {
                truncation: Truncation::Rank(12),
                ..PodOptions::default()
            },
        )
        .unwrap();
        for i in 0..12 {
            let sd = dense.S()[i];
            assert!((sd - s[i]).abs() < 1e-10 * s[0], "dense svd {i}");
            assert!(
                (p.singular_values[i] - sd).abs() <= 1e-9 * sd,
                "sigma_{i}: {} vs {sd}",
                p.singular_values[i]
            );
        }
        let angle = subspace_angle(p.modes.as_ref(), dense.U().get(.., ..12));
        assert!(angle < 1e-6, "subspace angle {angle}");
        // Orthonormal modes, and the captured energy is the spectrum's.
        let mut g = Mat::<f64>::zeros(12, 12);
        matmul(
            g.as_mut(),
            Accum::Replace,
            p.modes.transpose(),
            p.modes.as_ref(),
            1.0,
            Par::Seq,
        );
        for i in 0..12 {
            for j in 0..12 {
                assert!((g[(i, j)] - f64::from(u8::from(i == j))).abs() < 1e-12);
            }
        }
        let e: f64 =
            s[..12].iter().map(|v| v * v).sum::<f64>() / s.iter().map(|v| v * v).sum::<f64>();
        assert!((p.captured_energy() - e).abs() < 1e-12);
        // Projection error of the matrix itself is sqrt(1 - captured energy).
        let pe = p.projection_error(a.as_ref());
        assert!((pe - (1.0 - e).sqrt()).abs() < 1e-8, "{pe}");
    }

    #[test]
    fn energy_truncation_takes_the_smallest_rank_that_reaches_it() {
        let (a, s) = known(5);
        let total: f64 = s.iter().map(|v| v * v).sum();
        let p = pod(
            a.as_ref(),
            &PodOptions {
                truncation: Truncation::Energy {
                    fraction: 0.999,
                    max_rank: 40,
                },
                ..PodOptions::default()
            },
        )
        .unwrap();
        let r = p.rank();
        let cap = |k: usize| s[..k].iter().map(|v| v * v).sum::<f64>() / total;
        assert!(cap(r) >= 0.999 && cap(r - 1) < 0.999, "rank {r}");
        let e = pod(
            a.as_ref(),
            &PodOptions {
                truncation: Truncation::Energy {
                    fraction: 0.999,
                    max_rank: 3,
                },
                ..PodOptions::default()
            },
        )
        .unwrap_err();
        assert!(e.to_string().contains("raise the maximum rank"), "{e}");
    }
}
