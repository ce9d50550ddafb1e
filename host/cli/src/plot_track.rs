//! Plots of a virtual-lab scenario: the tip trajectory against the
//! reference, the position error over time, and the `rom` cloud.

use std::path::Path;

use anyhow::Result;
use ocm_hilsim::ScenarioReport;

use crate::plot::{Chart, Series};

/// Writes the scenario's plots into `dir` as PNG and SVG:
/// `<name>_trajectory`, `<name>_error` and, for `rom`, `rom_cloud_xy` and
/// `rom_cloud_xz`.
pub fn write(report: &ScenarioReport, dir: &Path) -> Result<()> {
    if !report.cloud.is_empty() {
        for (stem, axis, label) in [("rom_cloud_xy", 1, "y, mm"), ("rom_cloud_xz", 2, "z, mm")] {
            let pick = |p: &ocm_hilsim::RomPoint, model: bool| match (axis, model) {
                (1, false) => (p.x_mm, p.y_mm),
                (1, true) => (p.model_x_mm, p.model_y_mm),
                (_, false) => (p.x_mm, p.z_mm),
                (_, true) => (p.model_x_mm, p.model_z_mm),
            };
            Chart {
                title: "rom: 16^3 pressure combinations, plant against model",
                x_label: "x, mm",
                y_label: label,
                series: vec![
                    Series {
                        label: "model (eq 3.26-3.34)".into(),
                        points: report.cloud.iter().map(|p| pick(p, true)).collect(),
                        dots: true,
                    },
                    Series {
                        label: "plant".into(),
                        points: report.cloud.iter().map(|p| pick(p, false)).collect(),
                        dots: true,
                    },
                ],
                equal_axes: true,
            }
            .write(dir, stem)?;
        }
    }
    let Some(first) = report.runs.first() else {
        return Ok(());
    };
    let mut traj = vec![Series {
        label: "reference".into(),
        points: first.log.iter().map(|r| (r.ref_x_mm, r.ref_y_mm)).collect(),
        dots: false,
    }];
    let mut err = Vec::new();
    for run in &report.runs {
        traj.push(Series {
            label: run.controller.clone(),
            points: run.log.iter().map(|r| (r.x_mm, r.y_mm)).collect(),
            dots: false,
        });
        err.push(Series {
            label: format!("{} (RMSE {:.2} mm)", run.controller, run.rmse_mm),
            points: run.log.iter().map(|r| (r.t_s, r.err_mm)).collect(),
            dots: false,
        });
    }
    let title = format!("{}: tip trajectory (top view)", report.name);
    Chart {
        title: &title,
        x_label: "x, mm",
        y_label: "y, mm",
        series: traj,
        equal_axes: true,
    }
    .write(dir, &format!("{}_trajectory", report.name))?;
    let title = format!("{}: position error", report.name);
    Chart {
        title: &title,
        x_label: "time, s",
        y_label: "error, mm",
        series: err,
        equal_axes: false,
    }
    .write(dir, &format!("{}_error", report.name))
}
