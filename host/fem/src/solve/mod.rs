//! Solvers: sparse linear algebra, static Newton with load stepping, implicit dynamics.

pub mod dynamics;
pub mod linear;
pub mod statics;

use crate::model::Pattern;

/// y = A x for a full CSC matrix on free DOFs.
pub fn spmv(pat: &Pattern, vals: &[f64], x: &[f64]) -> Vec<f64> {
    let mut y = vec![0.0; pat.num_free()];
    for j in 0..pat.num_free() {
        let xj = x[j];
        for k in pat.col_ptr[j]..pat.col_ptr[j + 1] {
            y[pat.row_idx[k]] += vals[k] * xj;
        }
    }
    y
}

/// Euclidean norm.
pub fn norm(v: &[f64]) -> f64 {
    v.iter().map(|x| x * x).sum::<f64>().sqrt()
}

/// Newton controls shared by static and dynamic solves.
#[derive(Debug, Clone, Copy, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct NewtonOptions {
    /// Iterations per load or time step before the step is cut.
    pub max_iterations: usize,
    /// Converged when |residual| <= rtol * max(|f_ext|, |f_int|) (all DOFs, reactions included).
    pub rtol: f64,
    /// Or when the update is below this length, m.
    pub dx_tol: f64,
    /// When the line search can make no further progress (an inexact tangent, as the corotational
    /// law's, stalls near round-off), a residual below stall_rtol * scale is accepted.
    pub stall_rtol: f64,
    /// Backtracking halvings in the line search.
    pub max_backtracks: usize,
    /// Smallest step fraction (load or time) before giving up.
    pub min_step: f64,
}

impl Default for NewtonOptions {
    fn default() -> Self {
        NewtonOptions {
            max_iterations: 25,
            rtol: 1e-6,
            dx_tol: 1e-12,
            stall_rtol: 1e-4,
            max_backtracks: 8,
            min_step: 1e-4,
        }
    }
}

/// A trial point of a line search: residual over free DOFs, its force scale, and what produced it.
pub(crate) struct Trial<T> {
    pub r: Vec<f64>,
    pub scale: f64,
    pub data: T,
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// Line search along a Newton direction `dx` from residual `r0`.
///
/// When `dx` descends the potential (dx . r0 < 0) the step is chosen where the directional
/// derivative dx . r(alpha) has dropped to half its size (regula falsi), which tolerates the
/// strongly curved paths of rotating stiff parts; otherwise the residual norm must decrease.
/// Steps that invert an element are halved. Returns None when no acceptable step exists.
pub(crate) fn line_search<T>(
    mut trial: impl FnMut(f64) -> crate::Result<Trial<T>>,
    dx: &[f64],
    r0: &[f64],
    max_backtracks: usize,
) -> crate::Result<Option<(f64, Trial<T>)>> {
    let g0 = dot(dx, r0);
    let rn0 = norm(r0);
    let mut a = 1.0;
    let mut first = None;
    for _ in 0..=max_backtracks {
        match trial(a) {
            Ok(t) if t.r.iter().all(|v| v.is_finite()) => {
                first = Some(t);
                break;
            }
            Ok(_) | Err(crate::FemError::Inverted { .. }) => a *= 0.5,
            Err(e) => return Err(e),
        }
    }
    let Some(t1) = first else { return Ok(None) };
    if g0 >= 0.0 {
        // Not a descent direction of the potential: plain backtracking on the residual norm.
        let mut t = t1;
        for _ in 0..=max_backtracks {
            if norm(&t.r) < (1.0 - 1e-4 * a) * rn0 {
                return Ok(Some((a, t)));
            }
            a *= 0.5;
            t = match trial(a) {
                Ok(t) => t,
                Err(crate::FemError::Inverted { .. }) => continue,
                Err(e) => return Err(e),
            };
        }
        return Ok(None);
    }
    let g1 = dot(dx, &t1.r);
    if g1 <= 0.5 * g0.abs() {
        return Ok(Some((a, t1)));
    }
    let (mut lo, mut glo, mut hi, mut ghi) = (0.0, g0, a, g1);
    let mut best = (a, t1);
    for _ in 0..max_backtracks {
        let am = (lo - glo * (hi - lo) / (ghi - glo))
            .clamp(lo + 0.05 * (hi - lo), hi - 0.05 * (hi - lo));
        let t = match trial(am) {
            Ok(t) => t,
            Err(crate::FemError::Inverted { .. }) => {
                hi = am;
                continue;
            }
            Err(e) => return Err(e),
        };
        let g = dot(dx, &t.r);
        let done = g.abs() <= 0.5 * g0.abs();
        if g < 0.0 {
            lo = am;
            glo = g;
        } else {
            hi = am;
            ghi = g;
        }
        best = (am, t);
        if done {
            break;
        }
    }
    Ok(Some(best))
}
