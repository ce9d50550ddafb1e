//! What the assumption sweeps cover, and the check of it.

use super::super::StackError;
use super::super::solver::SolverConfig;
use crate::model::OcmModel;

/// What [`measure_assumptions`] sweeps.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct AssumptionConfig {
    /// Pressures of the axial sweep, pascals; the highest is also the
    /// target of the stability ramps.
    pub pressures_pa: Vec<f64>,
    /// Further axial-sweep pressures as fractions of the measured stability
    /// limit of the structure held at `l0` (see [`PressureStability`]).
    pub stable_pressure_fractions: Vec<f64>,
    /// Strains at which the plate is held in the axial sweep.
    pub axial_strains: Vec<f64>,
    /// Initial strains of the bending sweep.
    pub bend_strains: Vec<f64>,
    /// Pressure of the bending sweep, pascals.
    pub bend_pressure_pa: f64,
    /// Largest bending angle as a fraction of the feasible `phi_max(eps0)`.
    pub bend_fraction: f64,
    /// Bending angles per initial strain (evenly spaced, zero excluded).
    pub bend_points: usize,
    /// Load increments between consecutive sweep points.
    pub load_steps: usize,
    /// Largest number of pressure increments of the stability ramp up to the
    /// highest of `pressures_pa` (smaller steps are taken where needed).
    pub pressure_ramp_steps: usize,
    /// Resolution of the critical pressure search, pascals.
    pub pressure_resolution_pa: f64,
    /// Newton settings.
    pub solver: SolverConfig,
}

impl Default for AssumptionConfig {
    fn default() -> Self {
        Self {
            pressures_pa: vec![0.0, 10e3, 20e3, 30e3],
            stable_pressure_fractions: vec![0.5, 0.9],
            axial_strains: vec![-0.4, -0.3, -0.2, -0.1, 0.0, 0.1, 0.2, 0.3, 0.4],
            bend_strains: vec![-0.3, 0.0, 0.3],
            bend_pressure_pa: 0.0,
            bend_fraction: 0.9,
            bend_points: 6,
            load_steps: 4,
            pressure_ramp_steps: 30,
            pressure_resolution_pa: 1.0,
            solver: SolverConfig::default(),
        }
    }
}

pub(super) fn check_config(model: &OcmModel, cfg: &AssumptionConfig) -> Result<(), StackError> {
    let bad = |what: &'static str, reason: String| Err(StackError::InvalidInput { what, reason });
    let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
    if !finite(&cfg.pressures_pa) || cfg.pressures_pa.iter().any(|&p| p < 0.0) {
        return bad(
            "pressures_pa",
            format!(
                "must be finite and non-negative, got {:?}",
                cfg.pressures_pa
            ),
        );
    }
    let (lo, hi) = model.strain_limits();
    let in_range = |v: &[f64]| v.iter().all(|&e| e.is_finite() && e > lo && e < hi);
    if !in_range(&cfg.axial_strains) {
        return bad(
            "axial_strains",
            format!("must lie in ({lo}, {hi}), got {:?}", cfg.axial_strains),
        );
    }
    if !in_range(&cfg.bend_strains) {
        return bad(
            "bend_strains",
            format!("must lie in ({lo}, {hi}), got {:?}", cfg.bend_strains),
        );
    }
    if cfg
        .stable_pressure_fractions
        .iter()
        .any(|f| !(f.is_finite() && (0.0..=1.0).contains(f)))
    {
        return bad(
            "stable_pressure_fractions",
            format!(
                "must lie in [0, 1], got {:?}",
                cfg.stable_pressure_fractions
            ),
        );
    }
    if !(cfg.bend_pressure_pa.is_finite() && cfg.bend_pressure_pa >= 0.0) {
        return bad(
            "bend_pressure_pa",
            format!(
                "must be finite and non-negative, got {}",
                cfg.bend_pressure_pa
            ),
        );
    }
    if !(cfg.bend_fraction > 0.0 && cfg.bend_fraction < 1.0) {
        return bad(
            "bend_fraction",
            format!("must lie in (0, 1), got {}", cfg.bend_fraction),
        );
    }
    if cfg.bend_points == 0 || cfg.load_steps == 0 || cfg.pressure_ramp_steps == 0 {
        return bad(
            "bend_points/load_steps/pressure_ramp_steps",
            "must be at least 1".to_string(),
        );
    }
    if cfg.pressure_resolution_pa.is_nan() || cfg.pressure_resolution_pa <= 0.0 {
        return bad(
            "pressure_resolution_pa",
            format!("must be positive, got {}", cfg.pressure_resolution_pa),
        );
    }
    Ok(())
}
