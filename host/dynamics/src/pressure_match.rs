//! Training pairs of f_RS (App. D) between the full FEM and the hyper-reduced model: for a
//! static full-FEM state at pressures P_R (the stand-in for the real robot), the pressures P_S at
//! which the reduced model's static TCP is the same point.
//!
//! The reduced model is what the data sets, the learned dynamics and the policies' deployment
//! run on; its pressure-to-TCP map differs from the full FEM's by the reduction error. f_RS
//! translates a pressure meant for the full model (or recorded on it) into the reduced model's
//! pressure space, as the dissertation's f_RS translates real pressures into simulated ones.

use nalgebra::{Matrix3, Vector3};
use ocm_mor::drive::Input;
use ocm_mor::rom::ReducedModel;
use ocm_mor::store::ReducedProbe;
use serde::{Deserialize, Serialize};

use crate::error::{DynamicsError, Result};

/// Pressure range of the bellows, kPa.
pub const PRESSURE_RANGE_KPA: (f64, f64) = (-20.0, 35.0);

/// One matched pair.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PressurePair {
    /// Pressures of the full FEM, kPa.
    pub real_kpa: [f64; 3],
    /// Reduced-model pressures with the same static TCP, kPa.
    pub sim_kpa: [f64; 3],
    /// Remaining TCP distance, m.
    pub tcp_error_m: f64,
}

/// Settings of the match.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PressureMatchConfig {
    /// Gauss-Newton iterations at most.
    pub max_iterations: usize,
    /// Stop when the TCP is this close, m.
    pub tolerance_m: f64,
    /// Forward-difference step of the Jacobian, kPa.
    pub step_kpa: f64,
    /// Load steps of each reduced static solve from rest.
    pub load_steps: usize,
}

impl Default for PressureMatchConfig {
    fn default() -> Self {
        Self {
            max_iterations: 12,
            tolerance_m: 1e-6,
            step_kpa: 0.25,
            load_steps: 4,
        }
    }
}

/// The reduced model's static TCP (m) at `pressures_kpa`, no tip force.
pub fn reduced_static_tcp(
    rom: &ReducedModel,
    probe: &ReducedProbe,
    pressures_kpa: &[f64; 3],
    load_steps: usize,
) -> Result<Vector3<f64>> {
    let q = rom
        .solve_static(
            &Input {
                pressure_kpa: *pressures_kpa,
                tip_force_n: [0.0; 3],
            },
            load_steps,
        )
        .map_err(DynamicsError::Mor)?;
    let xs = probe.compact_state(&q, &nalgebra::DVector::zeros(rom.rank()));
    Ok(Vector3::new(xs[0], xs[1], xs[2]))
}

fn clamp(p: [f64; 3]) -> [f64; 3] {
    p.map(|v| v.clamp(PRESSURE_RANGE_KPA.0, PRESSURE_RANGE_KPA.1))
}

/// The reduced-model pressures whose static TCP is `target_m`, by damped Gauss-Newton from
/// `start_kpa` with a forward-difference Jacobian, kept inside the pressure range (the best
/// iterate is returned, with its distance).
pub fn match_pressures(
    rom: &ReducedModel,
    probe: &ReducedProbe,
    target_m: &Vector3<f64>,
    start_kpa: &[f64; 3],
    cfg: &PressureMatchConfig,
) -> Result<([f64; 3], f64)> {
    if !target_m.iter().all(|v| v.is_finite()) {
        return Err(DynamicsError::Data(format!(
            "target TCP {target_m:?} is not finite"
        )));
    }
    let mut p = clamp(*start_kpa);
    let mut tcp = reduced_static_tcp(rom, probe, &p, cfg.load_steps)?;
    let mut best = (p, (tcp - target_m).norm());
    for _ in 0..cfg.max_iterations {
        if best.1 <= cfg.tolerance_m {
            break;
        }
        let mut jac = Matrix3::zeros();
        for k in 0..3 {
            let mut pk = p;
            // Step inwards at the upper bound so the probe stays in range.
            let h = if pk[k] + cfg.step_kpa > PRESSURE_RANGE_KPA.1 {
                -cfg.step_kpa
            } else {
                cfg.step_kpa
            };
            pk[k] += h;
            // A probe where the reduced statics fail ends the search at the best iterate.
            let Ok(t) = reduced_static_tcp(rom, probe, &pk, cfg.load_steps) else {
                return Ok(best);
            };
            jac.set_column(k, &((t - tcp) / h));
        }
        let r = tcp - target_m;
        // Levenberg damping keeps the step finite where a chamber barely moves the TCP.
        let jtj = jac.transpose() * jac;
        let damp = 1e-9 * jtj.trace().max(1e-30);
        let Some(dp) = (jtj + Matrix3::identity() * damp)
            .lu()
            .solve(&(-jac.transpose() * r))
        else {
            break;
        };
        // At most 10 kPa per chamber and step.
        let s = (dp.amax() / 10.0).max(1.0);
        let next = clamp([p[0] + dp[0] / s, p[1] + dp[1] / s, p[2] + dp[2] / s]);
        let Ok(t) = reduced_static_tcp(rom, probe, &next, cfg.load_steps) else {
            break;
        };
        let e = (t - target_m).norm();
        if e >= best.1 {
            break;
        }
        p = next;
        tcp = t;
        best = (p, e);
    }
    Ok(best)
}

/// f_RS pairs for full-FEM static samples `(P_R, TCP_R)`, each matched from P_R; `on_sample`
/// counts finished samples. Samples at which the reduced statics fail from rest (the reduced
/// model inverts elements at some corners of the pressure box) are left out and their indices
/// returned.
pub fn match_samples(
    rom: &ReducedModel,
    probe: &ReducedProbe,
    samples: &[([f64; 3], [f64; 3])],
    cfg: &PressureMatchConfig,
    mut on_sample: impl FnMut(usize),
) -> Result<(Vec<PressurePair>, Vec<usize>)> {
    let mut out = Vec::with_capacity(samples.len());
    let mut failed = Vec::new();
    for (i, (p_r, tcp)) in samples.iter().enumerate() {
        match match_pressures(rom, probe, &Vector3::from(*tcp), p_r, cfg) {
            Ok((p_s, e)) => out.push(PressurePair {
                real_kpa: *p_r,
                sim_kpa: p_s,
                tcp_error_m: e,
            }),
            Err(DynamicsError::Mor(_)) => failed.push(i),
            Err(e) => return Err(e),
        }
        on_sample(i + 1);
    }
    Ok((out, failed))
}
