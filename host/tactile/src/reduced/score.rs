//! The reduced model scored against full-FEM indentations read back from their folders.

use super::basis::ReducedModel;
use super::enrich::{Enrichment, placement_model};
use super::solve::{ReducedIndentation, ReducedOptions};
use crate::gel::Gel;
use crate::indent::Approach;
use crate::indenter::Indenter;
use crate::{Result, TactileError};
use serde::Serialize;
use std::path::Path;

/// A full-FEM indentation read back from its folder (as `ocm tactile indent` and the dataset's
/// FEM cache write it): depths from `force_depth.csv`, fields from `u_NNN.npy`.
#[derive(Debug, Clone)]
pub struct FemSequence {
    /// Depth of each step, m.
    pub depth_m: Vec<f64>,
    /// Nodal displacement of each step (N x 3), m.
    pub displacement: Vec<Vec<[f64; 3]>>,
    /// Force of the gel on the indenter at each step, N.
    pub force_n: Vec<[f64; 3]>,
}

impl FemSequence {
    /// Reads the consecutive steps from 1 in `dir` (at most as many as `force_depth.csv` lists).
    /// A run that stopped before writing `force_depth.csv` is read with step k at depth
    /// k `step_m` and the force from `f_NNN.npy` when `step_m` is given.
    pub fn read(dir: &Path, nodes: usize, step_m: Option<f64>) -> Result<Self> {
        let csv_path = dir.join("force_depth.csv");
        let csv = match (std::fs::read_to_string(&csv_path), step_m) {
            (Ok(c), _) => c,
            (Err(_), Some(h)) => Self::synthetic_csv(dir, nodes, h)?,
            (Err(e), None) => return Err(TactileError::io(&csv_path, e)),
        };
        let mut seq = FemSequence {
            depth_m: Vec::new(),
            displacement: Vec::new(),
            force_n: Vec::new(),
        };
        for (k, line) in csv.lines().skip(1).enumerate() {
            let p = dir.join(format!("u_{:03}.npy", k + 1));
            if !p.exists() {
                break;
            }
            let cols: Vec<f64> = line
                .split(',')
                .take(5)
                .map(|v| v.trim().parse().unwrap_or(f64::NAN))
                .collect();
            if cols.len() < 5 || cols.iter().any(|v| !v.is_finite()) {
                return Err(TactileError::Input(format!(
                    "{} line {}: expected step, depth_mm and three forces",
                    csv_path.display(),
                    k + 2
                )));
            }
            let u = crate::dataset::read_nodal(&p, nodes)?;
            seq.depth_m.push(cols[1] * 1e-3);
            seq.force_n.push([cols[2], cols[3], cols[4]]);
            seq.displacement.push(u);
        }
        Ok(seq)
    }

    /// The rows `step,depth_mm,fx,fy,fz` of a run without its CSV: depths k `step_m`, the
    /// force on the indenter minus the sum of `f_NNN.npy`.
    fn synthetic_csv(dir: &Path, nodes: usize, step_m: f64) -> Result<String> {
        let mut csv = String::from("step,depth_mm,force_x_n,force_y_n,force_z_n\n");
        for k in 1.. {
            let p = dir.join(format!("f_{k:03}.npy"));
            if !p.exists() {
                break;
            }
            let a = ocm_fem::npy::read_f64_2d(&p)?;
            if a.rows != nodes || a.cols != 3 {
                return Err(TactileError::Input(format!(
                    "{} is {} x {}, expected {nodes} x 3",
                    p.display(),
                    a.rows,
                    a.cols
                )));
            }
            let mut t = [0.0; 3];
            for c in a.data.chunks(3) {
                for d in 0..3 {
                    t[d] -= c[d];
                }
            }
            csv += &format!(
                "{k},{},{},{},{}\n",
                k as f64 * step_m * 1e3,
                t[0],
                t[1],
                t[2]
            );
        }
        Ok(csv)
    }
}

/// The reduced model against one full-FEM sequence.
#[derive(Debug, Clone, Serialize)]
pub struct SequenceScore {
    /// Set-up name.
    pub setup: String,
    /// Frames compared.
    pub frames: usize,
    /// Depth of each frame, m.
    pub depth_m: Vec<f64>,
    /// Nodal RMSE over all nodes per frame, m.
    pub rmse_m: Vec<f64>,
    /// Nodal RMSE over the top-face nodes per frame, m.
    pub rmse_top_m: Vec<f64>,
    /// The basis' own limit: RMSE of the FEM field's projection onto the modes, m.
    pub projection_rmse_m: Vec<f64>,
    /// Indenter force z, reduced and FEM, N.
    pub force_z_n: Vec<[f64; 2]>,
    /// Deepest penetration over the frames, m.
    pub max_penetration_m: f64,
    /// Linearisation passes over the frames of the last run.
    pub passes: usize,
    /// Signed-distance queries over the frames of the last run.
    pub queries: usize,
    /// Seconds of each timed repeat of the whole sequence (solve and top-face field).
    pub seconds: Vec<f64>,
}

/// Runs the reduced model through the depths of `fem` (`repeats` timed runs from rest, each
/// solving every frame and evaluating the top-face field), then scores the last run's fields
/// against the FEM. With `nonlinear` the internal force is that hyper-reduced Neo-Hookean force.
#[allow(clippy::too_many_arguments)]
pub fn score_sequence(
    model: &ReducedModel,
    gel: &Gel,
    setup: &crate::setup::Setup,
    fem: &FemSequence,
    options: ReducedOptions,
    repeats: usize,
    enrich: Option<Enrichment>,
    nonlinear: Option<&super::hyper::NonlinearGel>,
) -> Result<SequenceScore> {
    let indenter = Indenter::from_stl(&setup.stl)?;
    let mut seconds = Vec::new();
    let mut frames = Vec::new();
    let deepest = fem.depth_m.iter().copied().fold(0.0, f64::max);
    let mut local = None;
    for _ in 0..repeats.max(1) {
        let t0 = std::time::Instant::now();
        // Per-placement modes are part of each timed run: a new placement pays for them.
        if let Some(enrich) = enrich {
            let approach = Approach::new(&setup.name, gel, &indenter, setup.placement)?;
            local = Some(placement_model(
                model, enrich, gel, &indenter, &approach, deepest,
            )?);
        }
        let model = local.as_ref().unwrap_or(model);
        let mut run =
            ReducedIndentation::new(&setup.name, model, gel, &indenter, setup.placement, options)?;
        if let Some(nl) = nonlinear {
            run = run.with_nonlinear(nl);
        }
        frames.clear();
        for &d in &fem.depth_m {
            let f = run.advance_to(d)?;
            let top = model.displacement_of(&gel.top, &f.q);
            std::hint::black_box(&top);
            frames.push(f);
        }
        seconds.push(t0.elapsed().as_secs_f64());
    }
    let mut s = SequenceScore {
        setup: setup.name.clone(),
        frames: frames.len(),
        depth_m: fem.depth_m.clone(),
        rmse_m: Vec::new(),
        rmse_top_m: Vec::new(),
        projection_rmse_m: Vec::new(),
        force_z_n: Vec::new(),
        max_penetration_m: frames
            .iter()
            .map(|f| f.max_penetration_m)
            .fold(0.0, f64::max),
        passes: frames.iter().map(|f| f.passes).sum(),
        queries: frames.iter().map(|f| f.queries).sum(),
        seconds,
    };
    s.depth_m.truncate(s.frames);
    let model = local.as_ref().unwrap_or(model);
    for ((f, u), force) in frames.iter().zip(&fem.displacement).zip(&fem.force_n) {
        let ur = model.displacement(&f.q);
        s.rmse_m.push(crate::metrics::nodal_rmse(&ur, u)?);
        let top_r: Vec<[f64; 3]> = gel.top.iter().map(|&i| ur[i]).collect();
        let top_f: Vec<[f64; 3]> = gel.top.iter().map(|&i| u[i]).collect();
        s.rmse_top_m
            .push(crate::metrics::nodal_rmse(&top_r, &top_f)?);
        let up = model.displacement(&model.project(u));
        s.projection_rmse_m
            .push(crate::metrics::nodal_rmse(&up, u)?);
        s.force_z_n.push([f.indenter_force_n[2], force[2]]);
    }
    Ok(s)
}

/// The frame of the largest nodal RMSE over several scored sequences.
#[derive(Debug, Clone, Serialize)]
pub struct WorstFrame {
    /// Set-up name.
    pub setup: String,
    /// Depth of the frame, m.
    pub depth_m: f64,
    /// Nodal RMSE over all nodes, m.
    pub rmse_m: f64,
    /// Nodal RMSE over the top face, m.
    pub rmse_top_m: f64,
    /// The basis' own limit at that frame (projection RMSE), m.
    pub projection_rmse_m: f64,
}

/// The worst frame (largest all-node RMSE) of `scores`; `None` when no frame was scored.
pub fn worst_frame(scores: &[SequenceScore]) -> Option<WorstFrame> {
    scores
        .iter()
        .flat_map(|s| (0..s.rmse_m.len()).map(move |k| (s, k)))
        .max_by(|a, b| a.0.rmse_m[a.1].total_cmp(&b.0.rmse_m[b.1]))
        .map(|(s, k)| WorstFrame {
            setup: s.setup.clone(),
            depth_m: s.depth_m.get(k).copied().unwrap_or(f64::NAN),
            rmse_m: s.rmse_m[k],
            rmse_top_m: s.rmse_top_m[k],
            projection_rmse_m: s.projection_rmse_m[k],
        })
}

/// The deepest depth, m, up to which every scored frame's nodal RMSE is at most `tol_m`: the
/// depth range in which the reduced model holds a tolerance on every held-out set-up. `None`
/// when the shallowest frame already misses it (or nothing was scored).
pub fn deepest_depth_within(scores: &[SequenceScore], tol_m: f64) -> Option<f64> {
    let mut frames: Vec<(f64, f64)> = scores
        .iter()
        .flat_map(|s| s.depth_m.iter().copied().zip(s.rmse_m.iter().copied()))
        .collect();
    frames.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut deepest = None;
    let mut k = 0;
    while k < frames.len() {
        // Frames at one depth pass or fail together.
        let d = frames[k].0;
        let mut all_ok = true;
        while k < frames.len() && frames[k].0 == d {
            all_ok &= frames[k].1 <= tol_m;
            k += 1;
        }
        if !all_ok {
            break;
        }
        deepest = Some(d);
    }
    deepest
}
