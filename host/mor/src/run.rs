//! Driving the reduced model over input sequences and scoring it against the full model.

use crate::drive::Input;
use crate::rom::ReducedModel;
use crate::store::ReducedProbe;
use crate::xs::XS_DIM;
use crate::{MorError, Result};
use ocm_fem::solve::dynamics::Integrator;

/// X_S rows of a reduced run from rest and its wall time of the steps alone, s.
pub fn simulate_reduced(
    rom: &ReducedModel,
    probe: &ReducedProbe,
    inputs: &[Input],
    dt_s: f64,
) -> Result<(Vec<[f64; 2 * XS_DIM]>, f64)> {
    let mut s = rom.rest_state();
    let mut out = Vec::with_capacity(inputs.len());
    let mut secs = 0.0;
    for inp in inputs {
        let t0 = std::time::Instant::now();
        rom.step(&mut s, inp, dt_s, Integrator::ImplicitEuler)?;
        secs += t0.elapsed().as_secs_f64();
        out.push(probe.compact_state(&s.q, &s.v));
    }
    Ok((out, secs))
}

/// RMSE of the TCP position between two X_S runs of equal length, mm.
pub fn tcp_rmse_mm(a: &[[f64; 2 * XS_DIM]], b: &[[f64; 2 * XS_DIM]]) -> Result<f64> {
    if a.len() != b.len() || a.is_empty() {
        return Err(MorError::Invalid(format!(
            "cannot compare runs of {} and {} steps",
            a.len(),
            b.len()
        )));
    }
    let ss: f64 = a
        .iter()
        .zip(b)
        .map(|(x, y)| (0..3).map(|k| (x[k] - y[k]).powi(2)).sum::<f64>())
        .sum();
    Ok((ss / a.len() as f64).sqrt() * 1e3)
}
