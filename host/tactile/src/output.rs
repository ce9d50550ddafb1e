//! Files of an indentation run: per-step VTK (ParaView) and NPY fields, contact masks as PNG,
//! and the force-depth table as CSV.

use crate::gel::Gel;
use crate::indent::StepOutput;
use crate::mask::{Grid, Mask, MaskStats};
use crate::{Result, TactileError};
use ocm_fem::mesh::vtk::{self, Field};
use serde::Serialize;
use std::io::Write;
use std::path::Path;

/// One row of the force-depth table.
#[derive(Debug, Clone, Serialize)]
pub struct StepRow {
    /// Step number.
    pub step: usize,
    /// Depth, mm.
    pub depth_mm: f64,
    /// Force on the indenter (x, y, z), N.
    pub force_n: [f64; 3],
    /// Nodes in contact.
    pub active_nodes: usize,
    /// Nodes sliding.
    pub slipping_nodes: usize,
    /// Newton iterations.
    pub newton_iterations: usize,
    /// Multiplier updates.
    pub multiplier_updates: usize,
    /// Deepest penetration, um.
    pub max_penetration_um: f64,
    /// Final residual, N.
    pub residual_n: f64,
    /// Contact mask statistics.
    pub mask: MaskStats,
    /// Whether the step was solved under the held-plane contact law.
    pub held_planes: bool,
    /// Newton iterations on an indefinite tangent, solved shifted.
    pub shifted_solves: usize,
}

impl StepRow {
    /// Summary row of a step with its mask statistics.
    pub fn new(s: &StepOutput, mask: MaskStats) -> Self {
        StepRow {
            step: s.step,
            depth_mm: s.depth_m * 1e3,
            force_n: s.indenter_force_n,
            active_nodes: s.active_nodes,
            slipping_nodes: s.slipping_nodes,
            newton_iterations: s.newton_iterations,
            multiplier_updates: s.multiplier_updates,
            max_penetration_um: s.max_penetration_m * 1e6,
            residual_n: s.residual_n,
            mask,
            held_planes: s.held_planes,
            shifted_solves: s.shifted_solves,
        }
    }
}

fn npy(path: &Path, v: &[[f64; 3]]) -> Result<()> {
    let data: Vec<f64> = v.iter().flatten().copied().collect();
    let mut f = std::io::BufWriter::new(
        std::fs::File::create(path).map_err(|e| TactileError::io(path, e))?,
    );
    ocm_fem::npy::write_f64_2d(&mut f, &data, v.len(), 3)?;
    f.flush().map_err(|e| TactileError::io(path, e))
}

/// Writes the step's fields: `u_NNN.npy` and `f_NNN.npy` (N x 3, m and N), `mask_NNN.png`,
/// and `step_NNN.vtk` when `vtk` is set. Returns the mask statistics.
pub fn write_step(
    dir: &Path,
    gel: &Gel,
    grid: &Grid,
    s: &StepOutput,
    vtk: bool,
) -> Result<MaskStats> {
    let tag = format!("{:03}", s.step);
    npy(&dir.join(format!("u_{tag}.npy")), &s.displacement)?;
    npy(&dir.join(format!("f_{tag}.npy")), &s.contact_force)?;
    let mask = Mask::from_displacement(gel, grid, &s.displacement);
    mask.write_png(dir.join(format!("mask_{tag}.png")))?;
    if vtk {
        vtk::write_path(
            dir.join(format!("step_{tag}.vtk")),
            &gel.mesh,
            &format!("DIGIT gel step {} depth {:.3} mm", s.step, s.depth_m * 1e3),
            &[
                Field::Vector("displacement_m", &s.displacement),
                Field::Vector("contact_force_n", &s.contact_force),
            ],
            &[],
        )?;
    }
    Ok(mask.stats())
}

/// Writes the force-depth table with units in the header.
pub fn write_force_depth_csv(path: &Path, rows: &[StepRow]) -> Result<()> {
    let mut out = String::from(
        "step,depth_mm,force_x_n,force_y_n,force_z_n,active_nodes,slipping_nodes,newton_iterations,multiplier_updates,max_penetration_um,residual_n,mask_area_mm2,centroid_x_mm,centroid_y_mm,axis_angle_rad,contact_law,shifted_newton_iterations\n",
    );
    for r in rows {
        out.push_str(&format!(
            "{},{:.4},{:.6e},{:.6e},{:.6e},{},{},{},{},{:.4},{:.3e},{:.5},{:.5},{:.5},{:.5},{},{}\n",
            r.step,
            r.depth_mm,
            r.force_n[0],
            r.force_n[1],
            r.force_n[2],
            r.active_nodes,
            r.slipping_nodes,
            r.newton_iterations,
            r.multiplier_updates,
            r.max_penetration_um,
            r.residual_n,
            r.mask.area_m2 * 1e6,
            r.mask.centroid_m[0] * 1e3,
            r.mask.centroid_m[1] * 1e3,
            r.mask.angle_rad,
            if r.held_planes {
                "held_planes"
            } else {
                "closest_point"
            },
            r.shifted_solves
        ));
    }
    std::fs::write(path, out).map_err(|e| TactileError::io(path, e))
}
