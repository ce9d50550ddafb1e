//! What a scenario run returns: figures, logs and the `rom` cloud.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::SimError;

/// One logged sample (CSV row; units in the column names).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LogRow {
    /// Time, s.
    pub t_s: f64,
    /// Reference tip x, mm.
    pub ref_x_mm: f64,
    /// Reference tip y, mm.
    pub ref_y_mm: f64,
    /// Reference tip z, mm.
    pub ref_z_mm: f64,
    /// Plate x, mm.
    pub x_mm: f64,
    /// Plate y, mm.
    pub y_mm: f64,
    /// Plate z, mm.
    pub z_mm: f64,
    /// Position error, mm.
    pub err_mm: f64,
    /// Orientation error against the reference configuration, rad (eq 3.42).
    pub q_err_rad: f64,
    /// Commanded pressure 1, Pa.
    pub cmd1_pa: f64,
    /// Commanded pressure 2, Pa.
    pub cmd2_pa: f64,
    /// Commanded pressure 3, Pa.
    pub cmd3_pa: f64,
    /// Chamber pressure 1, Pa.
    pub p1_pa: f64,
    /// Chamber pressure 2, Pa.
    pub p2_pa: f64,
    /// Chamber pressure 3, Pa.
    pub p3_pa: f64,
    /// Hall code 1.
    pub hall1: i16,
    /// Hall code 2.
    pub hall2: i16,
    /// Hall code 3.
    pub hall3: i16,
    /// Tip force along z, N.
    pub load_z_n: f64,
    /// Elongation of column 1 from its rest length, mm (a state of the plant: the tip is a
    /// function of the three).
    pub e1_mm: f64,
    /// Elongation of column 2 from its rest length, mm.
    pub e2_mm: f64,
    /// Elongation of column 3 from its rest length, mm.
    pub e3_mm: f64,
    /// Sensitivity of plate x to column 1's elongation, mm per mm.
    pub dx_de1: f64,
    /// Sensitivity of plate x to column 2's elongation, mm per mm.
    pub dx_de2: f64,
    /// Sensitivity of plate x to column 3's elongation, mm per mm.
    pub dx_de3: f64,
    /// Sensitivity of plate y to column 1's elongation, mm per mm.
    pub dy_de1: f64,
    /// Sensitivity of plate y to column 2's elongation, mm per mm.
    pub dy_de2: f64,
    /// Sensitivity of plate y to column 3's elongation, mm per mm.
    pub dy_de3: f64,
    /// Sensitivity of plate z to column 1's elongation, mm per mm.
    pub dz_de1: f64,
    /// Sensitivity of plate z to column 2's elongation, mm per mm.
    pub dz_de2: f64,
    /// Sensitivity of plate z to column 3's elongation, mm per mm.
    pub dz_de3: f64,
}

/// Result of one controller on one scenario.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunReport {
    /// Controller name.
    pub controller: String,
    /// Position RMSE over the scored part, mm.
    pub rmse_mm: f64,
    /// Largest position error over the scored part, mm.
    pub max_err_mm: f64,
    /// Scenario-specific figures (names carry units).
    pub figures: BTreeMap<String, f64>,
    /// Simulated time, s.
    pub sim_s: f64,
    /// Simulated seconds per wall second.
    pub realtime_factor: f64,
    /// Decimated log.
    #[serde(skip)]
    pub log: Vec<LogRow>,
}

impl RunReport {
    /// The log as CSV bytes.
    pub fn csv_bytes(&self) -> Result<Vec<u8>, SimError> {
        let mut w = csv::Writer::from_writer(Vec::new());
        for r in &self.log {
            w.serialize(r).map_err(|e| SimError::Io {
                path: "<memory>".into(),
                message: format!("writing: {e}"),
            })?;
        }
        w.into_inner().map_err(|e| SimError::Io {
            path: "<memory>".into(),
            message: format!("writing: {e}"),
        })
    }
}

/// Summary of one scenario.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ScenarioReport {
    /// Scenario name.
    pub name: String,
    /// Seed used.
    pub seed: u64,
    /// Open-loop RMSE, mm, when the open loop ran.
    pub ol_rmse_mm: Option<f64>,
    /// Host closed-loop RMSE, mm, when it ran.
    pub cl_rmse_mm: Option<f64>,
    /// Oracle RMSE, mm, when it ran.
    pub oracle_rmse_mm: Option<f64>,
    /// Simulated seconds per wall second over all runs.
    pub realtime_factor: f64,
    /// Scenario-level figures (the `rom` metrics live here).
    pub figures: BTreeMap<String, f64>,
    /// One entry per controller.
    pub runs: Vec<RunReport>,
    /// `rom` only: every solved pressure combination.
    #[serde(skip)]
    pub cloud: Vec<RomPoint>,
}

/// One `rom` pressure combination: where the plant settles and where the
/// model puts it (CSV row; units in the column names).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct RomPoint {
    /// Chamber pressure 1, Pa.
    pub p1_pa: f64,
    /// Chamber pressure 2, Pa.
    pub p2_pa: f64,
    /// Chamber pressure 3, Pa.
    pub p3_pa: f64,
    /// Plant tip x, mm.
    pub x_mm: f64,
    /// Plant tip y, mm.
    pub y_mm: f64,
    /// Plant tip z, mm.
    pub z_mm: f64,
    /// Model tip x, mm.
    pub model_x_mm: f64,
    /// Model tip y, mm.
    pub model_y_mm: f64,
    /// Model tip z, mm.
    pub model_z_mm: f64,
    /// Position error, mm.
    pub err_mm: f64,
    /// Orientation error, rad (eq 3.42).
    pub q_err_rad: f64,
}

impl ScenarioReport {
    /// Writes one CSV log per run as `DIR/<scenario>_<controller>.csv`, and
    /// the `rom` cloud as `DIR/rom_cloud.csv`.
    pub fn write_csv(&self, dir: &std::path::Path) -> Result<(), SimError> {
        if !self.cloud.is_empty() {
            let path = dir.join("rom_cloud.csv");
            let io = |e: String| SimError::Io {
                path: path.display().to_string(),
                message: e,
            };
            std::fs::create_dir_all(dir).map_err(|e| io(format!("writing: {e}")))?;
            let mut w = csv::Writer::from_path(&path).map_err(|e| io(format!("writing: {e}")))?;
            for p in &self.cloud {
                w.serialize(p).map_err(|e| io(format!("writing: {e}")))?;
            }
            w.flush().map_err(|e| io(format!("writing: {e}")))?;
        }
        for r in &self.runs {
            let path = dir.join(format!("{}_{}.csv", self.name, r.controller));
            let io = |e: std::io::Error| SimError::Io {
                path: path.display().to_string(),
                message: format!("writing: {e}"),
            };
            std::fs::create_dir_all(dir).map_err(io)?;
            std::fs::write(&path, r.csv_bytes()?).map_err(io)?;
        }
        Ok(())
    }
}
