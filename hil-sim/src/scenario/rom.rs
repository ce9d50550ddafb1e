//! The `rom` scenario: the static sweep of pressure combinations.

use std::collections::BTreeMap;
use std::time::Instant;

use crate::SimError;
use crate::metrics::{distance, rms, workspace_diagonal};
use crate::pcc::{Config, quaternion_error_rad};
use crate::plant::{Plant, PlateLoad};

use super::{RomPoint, ScenarioReport, SimConfig};

/// The `rom` scenario: plant statics against the model's forward map for
/// every pressure combination.
pub(super) fn rom(cfg: &SimConfig) -> Result<ScenarioReport, SimError> {
    let start = Instant::now();
    let plant = Plant::new(cfg.plant, cfg.seed)?;
    let model = plant.model();
    let load = PlateLoad::default();
    let tension = plant.external_force_n(&load)[2] / 3.0;
    let (p_lo, p_hi) = cfg
        .rom_pressure_pa
        .unwrap_or((cfg.limits.min_pa, cfg.limits.max_pa));
    let n = cfg.rom_levels.max(2);
    let level = |k: usize| p_lo + (p_hi - p_lo) * k as f64 / (n - 1) as f64;
    let d = cfg.plant.manipulator.column_radius_m;
    let col = plant.column_rest_length_m();
    let (mut plant_pts, mut errs, mut q_errs, mut reduced) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let mut theta_max: f64 = 0.0;
    let mut failed = 0usize;
    let mut cloud = Vec::with_capacity(n * n * n);
    let lim = model.strain_limits();
    for a in 0..n {
        for b in 0..n {
            for c in 0..n {
                let p = [level(a), level(b), level(c)];
                // The model's forward map (eq 3.29, 3.33, 3.34 without moments, 3.26).
                let eps: Result<Vec<f64>, _> = p
                    .iter()
                    .map(|&pi| model.strain_for_force(tension, pi, (-0.95, 0.98 * lim.1)))
                    .collect();
                let Ok(eps) = eps else {
                    failed += 1;
                    continue;
                };
                let l = [0, 1, 2].map(|i| col * (1.0 + eps[i]));
                let predicted = Config::from_column_lengths(l, d);
                let Ok(actual) = plant.static_equilibrium(p, &load, predicted) else {
                    failed += 1;
                    continue;
                };
                let (x, xh) = (actual.position(), predicted.position());
                let e = distance(x, xh);
                errs.push(e);
                let qe = quaternion_error_rad(actual.quaternion(), predicted.quaternion());
                q_errs.push(qe);
                cloud.push(RomPoint {
                    p1_pa: p[0],
                    p2_pa: p[1],
                    p3_pa: p[2],
                    x_mm: x[0] * 1e3,
                    y_mm: x[1] * 1e3,
                    z_mm: x[2] * 1e3,
                    model_x_mm: xh[0] * 1e3,
                    model_y_mm: xh[1] * 1e3,
                    model_z_mm: xh[2] * 1e3,
                    err_mm: e * 1e3,
                    q_err_rad: qe,
                });
                theta_max = theta_max.max(actual.bend_rad());
                if x[0].abs() <= 0.05 && x[1].abs() <= 0.05 && (0.07..=0.14).contains(&x[2]) {
                    reduced.push(e);
                }
                plant_pts.push(x);
            }
        }
    }
    let l_max = workspace_diagonal(&plant_pts);
    let rmse = rms(&errs);
    let q_rmse = rms(&q_errs);
    let mut figures = BTreeMap::new();
    figures.insert("points".into(), errs.len() as f64);
    figures.insert("failed".into(), failed as f64);
    figures.insert("pressure_min_pa".into(), p_lo);
    figures.insert("pressure_max_pa".into(), p_hi);
    figures.insert("rmse_mm".into(), rmse * 1e3);
    figures.insert(
        "max_err_mm".into(),
        errs.iter().cloned().fold(0.0, f64::max) * 1e3,
    );
    figures.insert("l_max_mm".into(), l_max * 1e3);
    figures.insert(
        "rmse_pct_of_l_max".into(),
        if l_max > 0.0 {
            100.0 * rmse / l_max
        } else {
            0.0
        },
    );
    figures.insert("q_rmse_rad".into(), q_rmse);
    figures.insert("theta_max_rad".into(), theta_max);
    figures.insert(
        "q_rmse_pct_of_theta_max".into(),
        if theta_max > 0.0 {
            100.0 * q_rmse / theta_max
        } else {
            0.0
        },
    );
    figures.insert("reduced_points".into(), reduced.len() as f64);
    figures.insert("reduced_rmse_mm".into(), rms(&reduced) * 1e3);
    Ok(ScenarioReport {
        name: "rom".into(),
        seed: cfg.seed,
        ol_rmse_mm: None,
        cl_rmse_mm: None,
        oracle_rmse_mm: None,
        realtime_factor: 0.0,
        figures: {
            figures.insert("wall_s".into(), start.elapsed().as_secs_f64());
            figures
        },
        runs: Vec::new(),
        cloud,
    })
}
