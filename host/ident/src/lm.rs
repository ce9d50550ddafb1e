//! Levenberg-Marquardt on a sum of squared residuals that a free run computes (the
//! state-space baseline's refinement and the extensions' in-loop refinement): forward-difference
//! Jacobians computed in parallel, up to eight damped steps per iteration with the damping
//! growing tenfold each (tried as many at a time as the pool has threads and taken in order, so
//! the choice is the one-by-one choice), the damping a third of the successful one after a
//! step, and bound-constrained steps for parameters kept non-negative.

use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;

/// A damped step that lowered the cost: parameters, residuals, cost.
type Trial = (Vec<f64>, Vec<f64>, f64);

/// Finite-difference steps.
pub(crate) enum Steps<'a> {
    /// `1e-6 (|th_j| + s_j)`, `s_j` the RMS of parameter `j`'s group (ranges of indices).
    Groups(&'a [(usize, usize)]),
    /// `1e-6 max(|th_j|, floor)`.
    Floor(f64),
}

impl Steps<'_> {
    /// The step of every parameter at `th`.
    fn of(&self, th: &[f64]) -> Vec<f64> {
        match self {
            Steps::Groups(groups) => {
                let mut scale = vec![0.0; th.len()];
                for &(g0, g1) in groups.iter() {
                    if g1 > g0 {
                        let rms = (th[g0..g1].iter().map(|v| v * v).sum::<f64>()
                            / (g1 - g0) as f64)
                            .sqrt();
                        scale[g0..g1].iter_mut().for_each(|s| *s = rms);
                    }
                }
                th.iter()
                    .zip(&scale)
                    .map(|(t, s)| 1e-6 * (t.abs() + s).max(1e-12))
                    .collect()
            }
            Steps::Floor(floor) => th.iter().map(|t| 1e-6 * t.abs().max(*floor)).collect(),
        }
    }
}

/// How the minimisation runs.
pub(crate) struct Settings<'a> {
    /// Most iterations.
    pub iterations: usize,
    /// Relative decrease of the cost below which an iteration counts as small.
    pub tolerance: f64,
    /// Small iterations in a row that end the minimisation.
    pub patience: usize,
    /// Floor of each diagonal entry of `J^T J` in the damping term.
    pub diag_floor: f64,
    /// Added to each damped diagonal entry.
    pub diag_add: f64,
    /// Finite-difference steps.
    pub steps: Steps<'a>,
    /// Parameters kept non-negative.
    pub nonneg: &'a [usize],
}

/// Minimises the sum of squared `residuals` from `(th, r, cost)` (`r` the residuals at `th`,
/// `cost` their sum of squares) with the `settings`. Returns the parameters, residuals, cost and
/// the last Jacobian (one column per parameter, `-d r / d th`).
pub(crate) fn minimise(
    mut th: Vec<f64>,
    mut r: Vec<f64>,
    mut cost: f64,
    settings: &Settings,
    residuals: &(dyn Fn(&[f64]) -> Option<Vec<f64>> + Sync),
) -> (Vec<f64>, Vec<f64>, f64, Vec<Vec<f64>>) {
    let np = th.len();
    let nonneg = settings.nonneg;
    let mut lambda = 1e-3;
    let mut jac: Vec<Vec<f64>> = Vec::new();
    let mut small = 0;
    for _ in 0..settings.iterations {
        let steps = settings.steps.of(&th);
        // one simulation per parameter, independent of the others: the columns are
        // computed in parallel (the bulk of the refinement's time) and land in order
        jac = (0..np)
            .into_par_iter()
            .map(|j| {
                let h = steps[j];
                let mut t = th.clone();
                t[j] += h;
                match residuals(&t) {
                    Some(rj) => rj.iter().zip(&r).map(|(p, q)| (q - p) / h).collect(),
                    None => vec![0.0; r.len()],
                }
            })
            .collect();
        let mut jtj = DMatrix::<f64>::zeros(np, np);
        let mut jtr = DVector::<f64>::zeros(np);
        for p in 0..np {
            jtr[p] = jac[p].iter().zip(&r).map(|(a, b)| a * b).sum();
            for q in p..np {
                let s: f64 = jac[p].iter().zip(&jac[q]).map(|(a, b)| a * b).sum();
                jtj[(p, q)] = s;
                jtj[(q, p)] = s;
            }
        }
        // Bound-constrained steps: a dissipative weight at zero whose gradient points below
        // zero is held there (its row and column leave the system). Clipping it after an
        // unconstrained step instead spoils the step of every other parameter: a cause
        // added at zero weights beside a refined one then never left zero (exactly 0 %
        // gain for every second cause of the pairs).
        for &p in nonneg {
            if th[p] <= 0.0 && jtr[p] <= 0.0 {
                for q in 0..np {
                    jtj[(p, q)] = 0.0;
                    jtj[(q, p)] = 0.0;
                }
                jtj[(p, p)] = 1.0;
                jtr[p] = 0.0;
            }
        }
        let mut improved = false;
        let mut accepted = false;
        // Up to 8 damped steps, lambda growing tenfold each: the first that lowers the cost
        // is taken. They are tried as many at a time as the pool has threads (each is one
        // free run) and taken in order, so the choice is the one-by-one choice.
        // lambda times ten, k times over (as the one-by-one loop multiplied it)
        let damping = |k: i32| (0..k).fold(lambda, |l, _| l * 10.0);
        let trial = |k: i32| -> Option<Trial> {
            let lam = damping(k);
            let mut lhs = jtj.clone();
            for d in 0..np {
                lhs[(d, d)] += lam * jtj[(d, d)].max(settings.diag_floor) + settings.diag_add;
            }
            let step = lhs.cholesky().map(|ch| ch.solve(&jtr))?;
            let mut t: Vec<f64> = th.iter().zip(step.iter()).map(|(p, s)| p + s).collect();
            // projected step: dissipative weights stay non-negative
            for &p in nonneg {
                t[p] = t[p].max(0.0);
            }
            let rt = residuals(&t)?;
            let ct: f64 = rt.iter().map(|e| e * e).sum();
            (ct < cost).then_some((t, rt, ct))
        };
        let width = rayon::current_num_threads().clamp(1, 8) as i32;
        let mut k = 0;
        let mut found = None;
        while k < 8 && found.is_none() {
            let batch: Vec<i32> = (k..(k + width).min(8)).collect();
            let outs: Vec<Option<Trial>> = batch.par_iter().map(|&q| trial(q)).collect();
            found = batch
                .into_iter()
                .zip(outs)
                .find_map(|(q, o)| o.map(|o| (q, o)));
            k += width;
        }
        match found {
            Some((q, (t, rt, ct))) => {
                let rel = (cost - ct) / cost.max(1e-300);
                th = t;
                r = rt;
                cost = ct;
                lambda = (damping(q) / 3.0).max(1e-9);
                improved = rel > settings.tolerance;
                accepted = true;
            }
            None => lambda = damping(8),
        }
        // A small decrease ends the refinement only after `patience` in a row (the in-loop
        // refinement waits for three: where a friction's sign makes the cost rough, one short
        // step at high damping is no sign of convergence; a one-mass LuGre friction stopped
        // after 11 iterations at twice the cost of the stop operators that then took its name).
        small = if improved { 0 } else { small + 1 };
        if !accepted || small >= settings.patience {
            break;
        }
    }
    (th, r, cost, jac)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Residuals of `y = a exp(b t) + c` against data made with `(2, -1.5, c_true)`.
    fn exp_fit(c_true: f64) -> impl Fn(&[f64]) -> Option<Vec<f64>> + Sync {
        let t: Vec<f64> = (0..50).map(|i| i as f64 * 0.1).collect();
        let y: Vec<f64> = t.iter().map(|t| 2.0 * (-1.5 * t).exp() + c_true).collect();
        move |p: &[f64]| {
            Some(
                t.iter()
                    .zip(&y)
                    .map(|(t, y)| y - (p[0] * (p[1] * t).exp() + p[2]))
                    .collect(),
            )
        }
    }

    fn settings<'a>(steps: Steps<'a>, nonneg: &'a [usize]) -> Settings<'a> {
        Settings {
            iterations: 200,
            tolerance: 1e-12,
            patience: 3,
            diag_floor: 1e-300,
            diag_add: 1e-300,
            steps,
            nonneg,
        }
    }

    #[test]
    fn recovers_an_exponential_from_a_far_start() {
        let res = exp_fit(0.3);
        let th = vec![1.0, -0.2, 0.0];
        let r = res(&th).unwrap();
        let cost = r.iter().map(|e| e * e).sum();
        for steps in [Steps::Floor(1e-2), Steps::Groups(&[(0, 3)])] {
            let (th, _, cost, jac) =
                minimise(th.clone(), r.clone(), cost, &settings(steps, &[]), &res);
            assert!(cost < 1e-16, "cost {cost}");
            for (got, want) in th.iter().zip([2.0, -1.5, 0.3]) {
                assert!((got - want).abs() < 1e-6, "{th:?}");
            }
            // the Jacobian is -d r / d th: for the offset c, d r / d c = -1 on every row
            assert!(jac[2].iter().all(|v| (v - 1.0).abs() < 1e-4));
        }
    }

    #[test]
    fn a_bound_parameter_stays_non_negative_and_the_others_reach_their_constrained_optimum() {
        // data with a negative offset: with c >= 0 the optimum puts c at zero
        let res = exp_fit(-0.3);
        let th = vec![1.0, -1.0, 0.5];
        let r = res(&th).unwrap();
        let cost = r.iter().map(|e| e * e).sum();
        let (th, _, cost, _) = minimise(th, r, cost, &settings(Steps::Floor(1e-2), &[2]), &res);
        assert_eq!(th[2], 0.0, "{th:?}");
        // the constrained optimum in (a, b) with c = 0, found without the bound from c fixed
        let fixed = |p: &[f64]| res(&[p[0], p[1], 0.0]);
        let t0 = vec![1.0, -1.0];
        let r0 = fixed(&t0).unwrap();
        let c0 = r0.iter().map(|e| e * e).sum();
        let (t_ref, _, c_ref, _) = minimise(t0, r0, c0, &settings(Steps::Floor(1e-2), &[]), &fixed);
        assert!(
            (cost - c_ref).abs() <= 1e-9 * c_ref.max(1e-300),
            "{cost} vs {c_ref}"
        );
        assert!((th[0] - t_ref[0]).abs() < 1e-6 && (th[1] - t_ref[1]).abs() < 1e-6);
    }
}
