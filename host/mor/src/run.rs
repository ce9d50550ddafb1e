//! Driving the reduced model over input sequences and scoring it against the full model.

use crate::drive::Input;
use crate::rom::{ReducedModel, ReducedStepReport, Stepper};
use crate::store::ReducedProbe;
use crate::xs::XS_DIM;
use crate::{MorError, Result};
use ocm_fem::solve::dynamics::Integrator;

/// A reduced run: X_S rows and the wall time of each step alone.
#[derive(Debug, Clone)]
pub struct ReducedRun {
    /// X_S and its rate after each step.
    pub xs: Vec<[f64; 2 * XS_DIM]>,
    /// Wall time of each step (the implicit step only, not X_S), s.
    pub step_seconds: Vec<f64>,
    /// Newton iterations and tangent projections over the run.
    pub report: ReducedStepReport,
}

/// Runs the reduced model from rest over `inputs` (implicit Euler, one [`Stepper`] for the run).
pub fn simulate_reduced(
    rom: &ReducedModel,
    probe: &ReducedProbe,
    inputs: &[Input],
    dt_s: f64,
) -> Result<ReducedRun> {
    let mut s = rom.rest_state();
    let mut stepper = Stepper::new(rom, Integrator::ImplicitEuler);
    let mut xs = Vec::with_capacity(inputs.len());
    let mut step_seconds = Vec::with_capacity(inputs.len());
    for inp in inputs {
        let t0 = std::time::Instant::now();
        stepper.step(&mut s, inp, dt_s)?;
        step_seconds.push(t0.elapsed().as_secs_f64());
        xs.push(probe.compact_state(&s.q, &s.v));
    }
    Ok(ReducedRun {
        xs,
        step_seconds,
        report: stepper.report,
    })
}

/// Median of a sample (NaN when empty).
pub fn median(x: &[f64]) -> f64 {
    if x.is_empty() {
        return f64::NAN;
    }
    let mut v = x.to_vec();
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
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
