//! The engine against the FEM (Table 6.1): contact-node accuracy, nodal displacement RMSE,
//! contact-patch orientation and total force.

use ocm_learn::values;
use ocm_tactile::dataset::TopSurface;
use ocm_tactile::gel::Gel;
use ocm_tactile::mask::{CONTACT_THRESHOLD_M, Grid, Mask};
use ocm_tactile::metrics::{nodal_rmse, rotation_error};
use serde::{Deserialize, Serialize};

use crate::Result;
use crate::data::Prepared;
use crate::engine::{Fields, Npe};

/// Major over minor second moment of a contact patch above which its orientation counts: a
/// rounder patch has no axis to recover.
pub const ELONGATION_MIN: f64 = 1.5;

/// Scores of one sample.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct SampleScore {
    /// Set-up name.
    pub setup: String,
    /// Depth, mm.
    pub depth_mm: f64,
    /// Share of top nodes whose contact state (-u_z > 30 um) the engine gets right.
    pub contact_accuracy: f64,
    /// Nodal displacement RMSE over the top nodes, mm.
    pub rmse_mm: f64,
    /// Angle between the principal axes of the predicted and FEM contact masks, degrees (None
    /// when the FEM patch is not elongated or a mask is empty).
    pub orientation_deg: Option<f64>,
    /// Total normal force on the indenter from the predicted nodal forces, N.
    pub force_pred_n: f64,
    /// The FEM's, N.
    pub force_fem_n: f64,
    /// Part of `force_pred_n` from the nodes the FEM puts no contact force on, N: a small
    /// per-node offset that the nodal-force error hardly sees adds up here over the whole face.
    pub force_off_contact_n: f64,
}

/// Summary over a set of samples.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Scores {
    /// Samples scored.
    pub samples: usize,
    /// Mean contact-node accuracy, %.
    pub contact_accuracy_pct: f64,
    /// Mean and standard deviation of the per-sample displacement RMSE, mm.
    pub rmse_mm: [f64; 2],
    /// RMSE over all nodes of all samples, mm.
    pub rmse_pooled_mm: f64,
    /// Mean and standard deviation of the orientation error, degrees.
    pub orientation_deg: [f64; 2],
    /// Samples with an elongated FEM patch (scored for orientation).
    pub orientation_samples: usize,
    /// RMSE of the total normal force, N.
    pub force_rmse_n: f64,
    /// Root mean square of the force from nodes without FEM contact force, N.
    #[serde(default)]
    pub force_off_contact_rms_n: f64,
}

fn mean_std(v: &[f64]) -> [f64; 2] {
    if v.is_empty() {
        return [f64::NAN; 2];
    }
    let m = v.iter().sum::<f64>() / v.len() as f64;
    let var = v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / v.len() as f64;
    [m, var.sqrt()]
}

/// Major over minor second central moment of a mask (infinite for a line, NaN when empty).
pub fn elongation(mask: &Mask) -> f64 {
    let g = &mask.grid;
    let pts: Vec<[f64; 2]> = (0..g.rows)
        .flat_map(|r| (0..g.cols).map(move |c| (r, c)))
        .filter(|&(r, c)| mask.pixels[r * g.cols + c])
        .map(|(r, c)| g.center(r, c))
        .collect();
    if pts.is_empty() {
        return f64::NAN;
    }
    let n = pts.len() as f64;
    let mx = pts.iter().map(|p| p[0]).sum::<f64>() / n;
    let my = pts.iter().map(|p| p[1]).sum::<f64>() / n;
    let (mut xx, mut yy, mut xy) = (0.0, 0.0, 0.0);
    for p in &pts {
        xx += (p[0] - mx).powi(2);
        yy += (p[1] - my).powi(2);
        xy += (p[0] - mx) * (p[1] - my);
    }
    let tr = xx + yy;
    let disc = ((xx - yy).powi(2) + 4.0 * xy * xy).sqrt();
    let (l1, l2) = (0.5 * (tr + disc), 0.5 * (tr - disc));
    if l2 <= 0.0 { f64::INFINITY } else { l1 / l2 }
}

/// Scores the engine on the samples `idx` of `p` against the FEM fields, in batches of
/// `batch`. `gel` and `top` are the mesh the dataset was made on (for the contact masks).
pub fn evaluate(
    npe: &Npe,
    p: &Prepared,
    idx: &[usize],
    gel: &Gel,
    top: &TopSurface,
    batch: usize,
) -> Result<(Scores, Vec<SampleScore>)> {
    let grid = Grid::for_gel(gel);
    let n = p.rest_m.len();
    let (pos, graph, device) = npe.parts();
    let mut per = Vec::new();
    let mut pooled = 0.0;
    for chunk in idx.chunks(batch.max(1)) {
        let x = p.inputs(&npe.config, chunk);
        let (out, _) = npe.net().forward(&npe.config, &x, pos, graph, device);
        let out = values(out);
        let b = chunk.len();
        for (j, &i) in chunk.iter().enumerate() {
            let s = &p.samples[i];
            let mine: Vec<f32> = (0..n)
                .flat_map(|v| out[(v * b + j) * 6..(v * b + j) * 6 + 6].to_vec())
                .collect();
            let pred: Fields = npe.unscale(&mine);
            let sc = npe.config.scales.displacement_m;
            let off: f64 = pred
                .nodal_force_n
                .iter()
                .zip(s.target.chunks(6))
                .filter(|(_, t)| t[3..6].iter().all(|&v| v == 0.0))
                .map(|(f, _)| -f[2])
                .sum();
            let truth: Vec<[f64; 3]> = s
                .target
                .chunks(6)
                .map(|r| [0, 1, 2].map(|k| f64::from(r[k]) * sc))
                .collect();
            let right = pred
                .displacement_m
                .iter()
                .zip(&truth)
                .filter(|(a, b)| (-a[2] > CONTACT_THRESHOLD_M) == (-b[2] > CONTACT_THRESHOLD_M))
                .count();
            let rmse = nodal_rmse(&pred.displacement_m, &truth)?;
            pooled += rmse * rmse * n as f64;
            let mp = Mask::from_displacement(
                gel,
                &grid,
                &top.extend(&pred.displacement_m, gel.num_nodes()),
            );
            let mt = Mask::from_displacement(gel, &grid, &top.extend(&truth, gel.num_nodes()));
            let orientation = (elongation(&mt) >= ELONGATION_MIN && mp.count() > 0)
                .then(|| rotation_error(mp.stats().angle_rad, mt.stats().angle_rad).to_degrees());
            per.push(SampleScore {
                setup: p.setup_names[s.setup].clone(),
                depth_mm: s.depth_m * 1e3,
                contact_accuracy: right as f64 / n as f64,
                rmse_mm: rmse * 1e3,
                orientation_deg: orientation,
                force_pred_n: pred.total_force_n()[2],
                force_fem_n: s.force_n[2],
                force_off_contact_n: off,
            });
        }
    }
    let acc: Vec<f64> = per.iter().map(|s| s.contact_accuracy).collect();
    let rm: Vec<f64> = per.iter().map(|s| s.rmse_mm).collect();
    let or: Vec<f64> = per.iter().filter_map(|s| s.orientation_deg).collect();
    let fr = per
        .iter()
        .map(|s| (s.force_pred_n - s.force_fem_n).powi(2))
        .sum::<f64>()
        / per.len().max(1) as f64;
    Ok((
        Scores {
            samples: per.len(),
            contact_accuracy_pct: 100.0 * mean_std(&acc)[0],
            rmse_mm: mean_std(&rm),
            rmse_pooled_mm: (pooled / (per.len().max(1) * n) as f64).sqrt() * 1e3,
            orientation_deg: mean_std(&or),
            orientation_samples: or.len(),
            force_rmse_n: fr.sqrt(),
            force_off_contact_rms_n: (per
                .iter()
                .map(|s| s.force_off_contact_n.powi(2))
                .sum::<f64>()
                / per.len().max(1) as f64)
                .sqrt(),
        },
        per,
    ))
}
