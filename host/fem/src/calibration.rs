//! The one calibrated material of the bellows manipulator, stored with its provenance.
//!
//! `calibration/bellows_material.toml` holds the result of `ocm fem calibrate grid` (the (E, nu)
//! cell whose TCPs best match `Pressure_vs_Pos.csv`) and the figures that run measured. It is
//! compiled in, so an installed binary and every test see the same numbers; the default of
//! [`crate::bellows::BellowsConfig`] comes from here.

use crate::material::Law;
use crate::{FemError, Result};
use serde::{Deserialize, Serialize};

/// The committed calibration file.
pub const BELLOWS_MATERIAL_TOML: &str = include_str!("../calibration/bellows_material.toml");

/// Where a calibrated material comes from and what it achieved.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Provenance {
    /// The command that produced the numbers.
    pub command: String,
    /// Mesh, relative to the data directory.
    pub mesh: String,
    /// Reference table, relative to the data directory.
    pub reference: String,
    /// Young's moduli of the grid, Pa.
    pub grid_youngs_pa: Vec<f64>,
    /// Poisson's ratios of the grid.
    pub grid_poissons: Vec<f64>,
    /// Pressure states of the grid search, kPa.
    pub states_kpa: String,
    /// How the rigid parts were modelled.
    pub rigid: String,
    /// What the grid minimised.
    pub objective: String,
    /// Best cell's TCP RMSE after aligning the frames, mm (None: not recorded).
    #[serde(default)]
    pub grid_best_rmse_aligned_mm: Option<f64>,
    /// Best cell's TCP RMSE in the mesh frame (nothing fitted), mm.
    #[serde(default)]
    pub grid_best_rmse_raw_mm: Option<f64>,
    /// `ocm fem sweep` (default grid) TCP RMSE after the frame rotation, mm.
    pub sweep_rmse_aligned_mm: f64,
    /// `ocm fem sweep` TCP RMSE in the mesh frame, mm.
    #[serde(default)]
    pub sweep_rmse_raw_mm: Option<f64>,
    /// The fitted rotation of the reference frame about z, degrees.
    #[serde(default)]
    pub sweep_frame_rotation_deg: Option<f64>,
    /// Mean lateral TCP excursion FEM / reference (reported, not fitted).
    #[serde(default)]
    pub sweep_lateral_gain: Option<f64>,
    /// Number of states of the sweep.
    pub sweep_states: usize,
}

/// A calibrated material with its provenance.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct CalibratedMaterial {
    /// Constitutive law.
    pub law: Law,
    /// Young's modulus, Pa.
    pub young_pa: f64,
    /// Poisson's ratio.
    pub poisson: f64,
    /// Density, kg/m^3.
    pub density_kg_m3: f64,
    /// How the values were obtained.
    pub provenance: Provenance,
}

impl CalibratedMaterial {
    /// Parses and checks a calibration TOML.
    pub fn from_toml(text: &str) -> Result<Self> {
        let m: CalibratedMaterial = toml::from_str(text).map_err(|e| {
            FemError::parse("material calibration TOML", "", e.message().to_string())
        })?;
        crate::material::Material::neo_hookean_bulk(m.young_pa, m.poisson).validate()?;
        if !(m.density_kg_m3 > 0.0) {
            return Err(FemError::Model(format!(
                "calibrated density {} must be positive",
                m.density_kg_m3
            )));
        }
        Ok(m)
    }
}

/// The committed bellows calibration.
pub fn bellows_material() -> CalibratedMaterial {
    // The file is part of the source and checked by a unit test, so parsing cannot fail at run time.
    CalibratedMaterial::from_toml(BELLOWS_MATERIAL_TOML)
        .unwrap_or_else(|e| unreachable!("committed bellows calibration is invalid: {e}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_committed_calibration_parses_and_is_the_bellows_default() {
        let m = CalibratedMaterial::from_toml(BELLOWS_MATERIAL_TOML).unwrap();
        let c = crate::bellows::BellowsConfig::default();
        assert_eq!(
            (c.law, c.young_pa, c.poisson, c.density_kg_m3),
            (m.law, m.young_pa, m.poisson, m.density_kg_m3)
        );
        // The calibrated cell is one of the grid's cells, and its error is a real measurement.
        assert!(m.provenance.grid_youngs_pa.contains(&m.young_pa));
        assert!(m.provenance.grid_poissons.contains(&m.poisson));
        let p = &m.provenance;
        assert!(p.sweep_rmse_aligned_mm > 0.0);
        // Aligning fits a rotation that includes the identity: it can only lower the error.
        if let Some(raw) = p.sweep_rmse_raw_mm {
            assert!(raw >= p.sweep_rmse_aligned_mm);
        }
        if let (Some(a), Some(r)) = (p.grid_best_rmse_aligned_mm, p.grid_best_rmse_raw_mm) {
            assert!(r >= a && a > 0.0);
        }
    }

    #[test]
    fn a_broken_calibration_is_rejected() {
        let bad = BELLOWS_MATERIAL_TOML.replace("poisson = 0.4", "poisson = 0.6");
        assert!(CalibratedMaterial::from_toml(&bad).is_err());
        let unknown = format!("{BELLOWS_MATERIAL_TOML}\nbogus = 1\n");
        assert!(CalibratedMaterial::from_toml(&unknown).is_err());
    }
}
