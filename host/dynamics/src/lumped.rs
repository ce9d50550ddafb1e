//! The lumped equations of motion in X_S that define the physics residual R_t.
//!
//! `M x'' + D x' + K x = B P + J^T tau + g`, divided through by the (unknown, invertible) mass
//! matrix: `x'' = A_x x + A_v x' + A_p P + A_f tau + c`. Only this normalised form can be
//! identified from motion alone, and it is all the residual needs.
//!
//! The residual of one step compares the velocity change over the step with the trapezoidal
//! (Crank-Nicolson) integral of the right-hand side, the inputs held over the step:
//!
//! `R_t = (v_{t+1} - v_t)/dt - [A_x (x_t + dt/4 (v_t + v_{t+1})) + A_v (v_t + v_{t+1})/2 + A_p P_t + A_f tau_t + c]`
//!
//! where `x_{t+1}` is replaced by its trapezoidal estimate `x_t + dt/2 (v_t + v_{t+1})`, so that
//! `R_t` depends on the network only through the predicted `v_{t+1}`, and affinely:
//! `R_t = G v_{t+1} + h_t`. On exact trajectories of the lumped system it vanishes to second
//! order in `dt`.

use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

use crate::error::{DynamicsError, Result};
use crate::trajectory::{FORCE_DIM, PRESSURE_DIM, Trajectory, check_set};

/// `x'' = A_x x + A_v x' + A_p P + A_f tau + c`, matrices row-major.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LumpedModel {
    /// Components of x (X_S).
    pub state_dim: usize,
    /// Stiffness term `-M^-1 K` (`n x n`), 1/s^2.
    pub a_x: Vec<f64>,
    /// Damping term `-M^-1 D` (`n x n`), 1/s.
    pub a_v: Vec<f64>,
    /// Pressure gain `M^-1 B` (`n x 3`), per kPa per s^2.
    pub a_p: Vec<f64>,
    /// Tip-force gain `M^-1 J^T` (`n x 3`), per N per s^2.
    pub a_f: Vec<f64>,
    /// Constant term (gravity, offsets) (`n`).
    pub c: Vec<f64>,
}

fn row_major(m: &DMatrix<f64>) -> Vec<f64> {
    m.transpose().as_slice().to_vec()
}

impl LumpedModel {
    /// The normalised model of `M x'' + D x' + K x = B P + J^T tau + g`.
    pub fn from_mdk(
        m: &DMatrix<f64>,
        d: &DMatrix<f64>,
        k: &DMatrix<f64>,
        b: &DMatrix<f64>,
        jt: &DMatrix<f64>,
        g: &DVector<f64>,
    ) -> Result<Self> {
        let n = m.nrows();
        let minv = m
            .clone()
            .try_inverse()
            .ok_or_else(|| DynamicsError::Identification("mass matrix is singular".into()))?;
        Ok(Self {
            state_dim: n,
            a_x: row_major(&(-&minv * k)),
            a_v: row_major(&(-&minv * d)),
            a_p: row_major(&(&minv * b)),
            a_f: row_major(&(&minv * jt)),
            c: (&minv * g).as_slice().to_vec(),
        })
    }

    /// The acceleration x'' at state (x, v) under inputs (p, f).
    pub fn acceleration(&self, x: &[f64], v: &[f64], p: &[f64], f: &[f64]) -> Vec<f64> {
        let n = self.state_dim;
        (0..n)
            .map(|i| {
                let row = |a: &[f64], cols: usize, z: &[f64]| -> f64 {
                    a[i * cols..(i + 1) * cols]
                        .iter()
                        .zip(z)
                        .map(|(a, z)| a * z)
                        .sum()
                };
                row(&self.a_x, n, x)
                    + row(&self.a_v, n, v)
                    + row(&self.a_p, PRESSURE_DIM, p)
                    + row(&self.a_f, FORCE_DIM, f)
                    + self.c[i]
            })
            .collect()
    }

    /// `G = I/dt - A_x dt/4 - A_v/2` (`n x n`, row-major): the residual's slope in `v_{t+1}`.
    pub fn residual_slope(&self, dt: f64) -> Vec<f64> {
        let n = self.state_dim;
        (0..n * n)
            .map(|k| {
                let eye = if k / n == k % n { 1.0 / dt } else { 0.0 };
                eye - self.a_x[k] * dt / 4.0 - self.a_v[k] / 2.0
            })
            .collect()
    }

    /// `h_t`: the residual at `v_{t+1} = 0` for the step starting at (x, v) under (p, f).
    pub fn residual_offset(&self, dt: f64, x: &[f64], v: &[f64], p: &[f64], f: &[f64]) -> Vec<f64> {
        let xm: Vec<f64> = x.iter().zip(v).map(|(x, v)| x + dt / 4.0 * v).collect();
        let vm: Vec<f64> = v.iter().map(|v| v / 2.0).collect();
        let rhs = self.acceleration(&xm, &vm, p, f);
        v.iter().zip(rhs).map(|(v, r)| -v / dt - r).collect()
    }

    /// `R_t` for the step from (x, v) under (p, f) to the velocity `v_next`.
    pub fn residual(
        &self,
        dt: f64,
        x: &[f64],
        v: &[f64],
        p: &[f64],
        f: &[f64],
        v_next: &[f64],
    ) -> Vec<f64> {
        let n = self.state_dim;
        let g = self.residual_slope(dt);
        let h = self.residual_offset(dt, x, v, p, f);
        (0..n)
            .map(|i| h[i] + (0..n).map(|j| g[i * n + j] * v_next[j]).sum::<f64>())
            .collect()
    }

    /// Identifies the model from trajectories by linear least squares on the residual itself,
    /// so that the identified model is the one whose residual is smallest on the data.
    pub fn identify(trajs: &[Trajectory]) -> Result<Self> {
        let (dt, n) = check_set(trajs)?;
        let p = 2 * n + PRESSURE_DIM + FORCE_DIM + 1;
        let rows: usize = trajs.iter().map(|t| t.len().saturating_sub(1)).sum();
        if rows < 2 * p {
            return Err(DynamicsError::Identification(format!(
                "{rows} steps are too few to identify {p} coefficients per component"
            )));
        }
        let mut phi = DMatrix::zeros(rows, p);
        let mut y = DMatrix::zeros(rows, n);
        let mut r = 0;
        for t in trajs {
            for k in 0..t.len() - 1 {
                let (x, v, v1) = (t.x(k), t.v(k), t.v(k + 1));
                for i in 0..n {
                    phi[(r, i)] = x[i] + dt / 4.0 * (v[i] + v1[i]);
                    phi[(r, n + i)] = 0.5 * (v[i] + v1[i]);
                    y[(r, i)] = (v1[i] - v[i]) / dt;
                }
                for i in 0..PRESSURE_DIM {
                    phi[(r, 2 * n + i)] = t.p(k)[i];
                }
                for i in 0..FORCE_DIM {
                    phi[(r, 2 * n + PRESSURE_DIM + i)] = t.f(k)[i];
                }
                phi[(r, p - 1)] = 1.0;
                r += 1;
            }
        }
        // Columns on a common scale, so that the rank cut-off means the same for all of them.
        let scale: Vec<f64> = (0..p)
            .map(|j| {
                let c = phi.column(j);
                let rms = (c.norm_squared() / rows as f64).sqrt();
                if rms > 0.0 { rms } else { 1.0 }
            })
            .collect();
        for (j, s) in scale.iter().enumerate() {
            phi.column_mut(j).scale_mut(1.0 / s);
        }
        let svd = phi.svd(true, true);
        let smax = svd.singular_values.max();
        let theta = svd
            .solve(&y, 1e-10 * smax)
            .map_err(|e| DynamicsError::Identification(e.to_string()))?;
        let coef = |row: usize, i: usize| theta[(row, i)] / scale[row];
        let block = |start: usize, cols: usize| -> Vec<f64> {
            (0..n)
                .flat_map(|i| (0..cols).map(move |j| (i, j)))
                .map(|(i, j)| coef(start + j, i))
                .collect()
        };
        Ok(Self {
            state_dim: n,
            a_x: block(0, n),
            a_v: block(n, n),
            a_p: block(2 * n, PRESSURE_DIM),
            a_f: block(2 * n + PRESSURE_DIM, FORCE_DIM),
            c: (0..n).map(|i| coef(p - 1, i)).collect(),
        })
    }

    /// Root mean square of the residual over all steps of `trajs`, per component, with the
    /// root mean square of the finite-difference acceleration `(v_{t+1}-v_t)/dt` beside it.
    pub fn residual_rms(&self, trajs: &[Trajectory]) -> (Vec<f64>, Vec<f64>) {
        let n = self.state_dim;
        let mut r2 = vec![0.0; n];
        let mut a2 = vec![0.0; n];
        let mut count = 0.0f64;
        for t in trajs {
            for k in 0..t.len().saturating_sub(1) {
                let r = self.residual(t.dt_s, t.x(k), t.v(k), t.p(k), t.f(k), t.v(k + 1));
                for i in 0..n {
                    r2[i] += r[i] * r[i];
                    let a = (t.v(k + 1)[i] - t.v(k)[i]) / t.dt_s;
                    a2[i] += a * a;
                }
                count += 1.0;
            }
        }
        let rms = |s: Vec<f64>| s.into_iter().map(|s| (s / count.max(1.0)).sqrt()).collect();
        (rms(r2), rms(a2))
    }

    /// Simulates the model from (x0, v0) under per-step inputs held over each step, with
    /// `substeps` RK4 steps per sample; velocities are the exact derivative of the state.
    pub fn simulate(
        &self,
        dt: f64,
        x0: &[f64],
        v0: &[f64],
        pressure_kpa: &[f64],
        force_n: &[f64],
        substeps: usize,
    ) -> Trajectory {
        let n = self.state_dim;
        let steps = pressure_kpa.len() / PRESSURE_DIM;
        let mut x = x0.to_vec();
        let mut v = v0.to_vec();
        let mut state = Vec::with_capacity(steps * n);
        let mut velocity = Vec::with_capacity(steps * n);
        let h = dt / substeps.max(1) as f64;
        let axpy = |a: &[f64], s: f64, b: &[f64]| -> Vec<f64> {
            a.iter().zip(b).map(|(a, b)| a + s * b).collect()
        };
        for k in 0..steps {
            state.extend_from_slice(&x);
            velocity.extend_from_slice(&v);
            let p = &pressure_kpa[k * PRESSURE_DIM..(k + 1) * PRESSURE_DIM];
            let f = &force_n[k * FORCE_DIM..(k + 1) * FORCE_DIM];
            for _ in 0..substeps.max(1) {
                let k1v = self.acceleration(&x, &v, p, f);
                let k1x = v.clone();
                let (x2, v2) = (axpy(&x, h / 2.0, &k1x), axpy(&v, h / 2.0, &k1v));
                let k2v = self.acceleration(&x2, &v2, p, f);
                let k2x = v2;
                let (x3, v3) = (axpy(&x, h / 2.0, &k2x), axpy(&v, h / 2.0, &k2v));
                let k3v = self.acceleration(&x3, &v3, p, f);
                let k3x = v3;
                let (x4, v4) = (axpy(&x, h, &k3x), axpy(&v, h, &k3v));
                let k4v = self.acceleration(&x4, &v4, p, f);
                let k4x = v4;
                for i in 0..n {
                    x[i] += h / 6.0 * (k1x[i] + 2.0 * k2x[i] + 2.0 * k3x[i] + k4x[i]);
                    v[i] += h / 6.0 * (k1v[i] + 2.0 * k2v[i] + 2.0 * k3v[i] + k4v[i]);
                }
            }
        }
        Trajectory {
            dt_s: dt,
            state_dim: n,
            pressure_kpa: pressure_kpa.to_vec(),
            force_n: force_n.to_vec(),
            state,
            velocity,
        }
    }
}

/// A seeded lumped system that stands in for the reduced FEM in tests and demos: `n` coupled
/// degrees of freedom with natural frequencies of 2-8 Hz, Rayleigh damping, three chambers at
/// 120 degrees and the tip force acting on the first three (TCP) components.
pub fn demo_system(n: usize, seed: u64) -> Result<LumpedModel> {
    use rand::{Rng, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let mass = DMatrix::from_diagonal(&DVector::from_fn(n, |_, _| rng.random_range(0.05..0.2)));
    // K = M^1/2 Q W^2 Q^T M^1/2 puts the natural frequencies exactly at W.
    let q = DMatrix::from_fn(n, n, |_, _| rng.random_range(-1.0..1.0f64))
        .qr()
        .q();
    let omega = DVector::from_fn(n, |i, _| {
        let f = 2.0 + 6.0 * i as f64 / (n.max(2) - 1) as f64;
        std::f64::consts::TAU * f
    });
    let sqrt_m = mass.map(f64::sqrt);
    let k = &sqrt_m * &q * DMatrix::from_diagonal(&omega.map(|w| w * w)) * q.transpose() * &sqrt_m;
    // Rayleigh damping: damping ratios of about 0.2 to 0.5 over the band.
    let d = &mass * 2.0 + &k * 0.02;
    // 35 kPa in one chamber moves the TCP by roughly 2 cm sideways.
    let mut b = DMatrix::zeros(n, PRESSURE_DIM);
    for c in 0..PRESSURE_DIM {
        let a = std::f64::consts::TAU * c as f64 / 3.0;
        let gains = [a.cos(), a.sin(), 0.3];
        for (i, g) in gains.iter().enumerate().take(n) {
            b[(i, c)] = 0.02 / 35.0 * g * k[(i, i)];
        }
        for i in 3..n {
            b[(i, c)] = rng.random_range(-0.2..0.2) * 0.02 / 35.0 * k[(i, i)];
        }
    }
    let mut jt = DMatrix::zeros(n, FORCE_DIM);
    for i in 0..n.min(FORCE_DIM) {
        jt[(i, i)] = 1.0;
    }
    let g = DVector::from_fn(n, |i, _| if i == 2 { -9.81 * mass[(i, i)] } else { 0.0 });
    LumpedModel::from_mdk(&mass, &d, &k, &b, &jt, &g)
}
