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
use crate::engine::{Fields, Npe, contact_state};
use crate::model::Inputs;
use crate::stiffness::ForceFromDisplacement;
use crate::symmetry::{Symmetry, map_sample, permutation};

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
    /// Share of top nodes whose contact state the engine gets right (the FEM's: -u_z > 30 um;
    /// the engine's: its contact head when it has one, else the same rule on its u_z).
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
    /// Contact-node breakdown of this sample (which nodes are wrong and why).
    #[serde(default)]
    pub contact: ContactBreakdown,
    /// Root mean square over the top nodes of the nodal force error (3-D), N.
    #[serde(default)]
    pub nodal_force_rmse_n: f64,
    /// Total force read from the predicted displacement through the fitted stiffness
    /// functional, N (when one is given).
    #[serde(default)]
    pub force_from_u_n: Option<f64>,
    /// The same functional on the FEM's own displacement, N: the functional's floor.
    #[serde(default)]
    pub force_from_fem_u_n: Option<f64>,
    /// Contact-node accuracy when the engine's contact state is `-u_z > t` for each
    /// candidate threshold `t` of [`evaluate_with`] (the FEM's stays at 30 um).
    #[serde(default)]
    pub contact_accuracy_at: Vec<f64>,
    /// Elongation ([`elongation`]) of the FEM's contact mask (None when empty or a line).
    #[serde(default)]
    pub elongation_fem: Option<f64>,
    /// Elongation of the engine's contact mask (None when empty or a line).
    #[serde(default)]
    pub elongation_pred: Option<f64>,
    /// Pixels of the FEM's and the engine's contact masks (the orientation's masks).
    #[serde(default)]
    pub mask_pixels: [usize; 2],
}

/// Where the contact-node errors of a sample sit.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct ContactBreakdown {
    /// Top nodes in contact in the FEM (-u_z > 30 um).
    pub fem_contact: usize,
    /// Nodes the engine puts in contact and the FEM does not.
    pub false_pos: usize,
    /// Nodes in contact in the FEM that the engine misses.
    pub false_neg: usize,
    /// Wrong nodes whose FEM -u_z lies within 10 um of the threshold (20-40 um).
    pub wrong_near_threshold: usize,
    /// Wrong nodes that a contact point penetrates (the contact prior knows them).
    pub wrong_penetrated: usize,
    /// Wrong nodes that have a penetrated neighbour but are not penetrated (the patch's rim).
    pub wrong_rim: usize,
    /// Share of top nodes the geometric rule alone (penetration > 30 um) gets right.
    pub penetration_rule_accuracy: f64,
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
    /// Pooled root mean square of the per-node nodal force error over all top nodes of all
    /// samples (3-D), N: the per-node figure, independent of how many nodes add up.
    #[serde(default)]
    pub nodal_force_rmse_n: f64,
    /// The same over the nodes that carry FEM contact force only, N.
    #[serde(default)]
    pub nodal_force_rmse_contact_n: f64,
    /// Force RMSE over the root mean square of the FEM force, %.
    #[serde(default)]
    pub force_rmse_relative_pct: f64,
    /// Median of |F_pred - F_fem| / F_fem over samples, %.
    #[serde(default)]
    pub force_median_relative_pct: f64,
    /// Mean of the FEM force over the samples, N (the scale of the force figures).
    #[serde(default)]
    pub force_fem_mean_n: f64,
    /// Mean over samples of the share of top nodes the geometric rule alone (penetration
    /// > 30 um) classifies right, %.
    #[serde(default)]
    pub penetration_rule_accuracy_pct: f64,
    /// Contact-node errors summed over the samples.
    #[serde(default)]
    pub contact: ContactBreakdown,
    /// RMSE of the total force read from the predicted displacement through the stiffness
    /// functional, N.
    #[serde(default)]
    pub force_from_u_rmse_n: Option<f64>,
    /// RMSE of the same functional on the FEM displacement (its floor), N.
    #[serde(default)]
    pub force_from_fem_u_rmse_n: Option<f64>,
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

/// Fits the stiffness functional on the FEM fields of the samples `idx` (the training
/// set-ups).
pub fn fit_stiffness(
    p: &Prepared,
    idx: &[usize],
    degree: usize,
    displacement_unit_m: f64,
) -> Result<ForceFromDisplacement> {
    let fields: Vec<(Vec<[f64; 3]>, f64)> = idx
        .iter()
        .map(|&i| {
            let s = &p.samples[i];
            let u = s
                .target
                .chunks(6)
                .map(|r| [0, 1, 2].map(|k| f64::from(r[k]) * displacement_unit_m))
                .collect();
            (u, s.force_n[2])
        })
        .collect();
    ForceFromDisplacement::fit(
        degree,
        &p.rest_m,
        fields.iter().map(|(u, f)| (u.as_slice(), *f)),
    )
}

/// Classifies the predicted contact state `pred` of every top node against the FEM's and
/// sorts the wrong ones: `pen_m` is each node's penetration by the contact points, `edges` the
/// top-face graph.
pub fn breakdown(
    pred: &[bool],
    fem_m: &[[f64; 3]],
    pen_m: &[f64],
    edges: &[[usize; 2]],
) -> ContactBreakdown {
    let mut rim = vec![false; pen_m.len()];
    for &[a, b] in edges {
        rim[a] |= pen_m[b] > 0.0;
        rim[b] |= pen_m[a] > 0.0;
    }
    let mut c = ContactBreakdown::default();
    let mut rule_right = 0;
    for (v, (&p, b)) in pred.iter().zip(fem_m).enumerate() {
        let t = -b[2] > CONTACT_THRESHOLD_M;
        c.fem_contact += usize::from(t);
        if (pen_m[v] > CONTACT_THRESHOLD_M) == t {
            rule_right += 1;
        }
        if p == t {
            continue;
        }
        c.false_pos += usize::from(p);
        c.false_neg += usize::from(t);
        c.wrong_near_threshold += usize::from((-b[2] - CONTACT_THRESHOLD_M).abs() <= 10e-6);
        if pen_m[v] > 0.0 {
            c.wrong_penetrated += 1;
        } else if rim[v] {
            c.wrong_rim += 1;
        }
    }
    c.penetration_rule_accuracy = rule_right as f64 / pred.len().max(1) as f64;
    c
}

/// Engines run on samples and on their images under maps of the top face, with the images'
/// outputs mapped back and everything averaged (test-time symmetrisation, and ensembles).
/// Over the whole group (identity, half turn and both mirrors) the averaged engine is
/// equivariant, whatever its weights.
pub struct Symmetrised {
    /// Each distinct map with its node permutation.
    maps: Vec<(Symmetry, Vec<usize>)>,
    /// Centre of the top face the maps act about (x, y), m.
    centre: [f64; 2],
}

impl Symmetrised {
    /// The maps `symmetrise` (repeats dropped) on the top face of `p`; an error when the face
    /// is not symmetric under one of them.
    pub fn new(p: &Prepared, symmetrise: &[Symmetry]) -> Result<Self> {
        let mut maps: Vec<(Symmetry, Vec<usize>)> = Vec::new();
        for &s in symmetrise {
            if !maps.iter().any(|(m, _)| *m == s) {
                maps.push((s, permutation(&p.rest_m, s)?));
            }
        }
        let c = Prepared::top_center(&p.rest_m);
        Ok(Self {
            maps,
            centre: [c[0], c[1]],
        })
    }

    /// Outputs (6 per node: scaled u and f, node v of sample j at `v * b + j`) and contact
    /// logits on the samples `idx` of `p`, averaged over `engines` (of one top face, scales
    /// and head layout) and each sample's images. `x` are the first engine's inputs; the
    /// others build their own.
    pub fn forward(
        &self,
        engines: &[&Npe],
        p: &Prepared,
        idx: &[usize],
        x: &Inputs,
    ) -> (Vec<f32>, Option<Vec<f32>>) {
        let b = idx.len();
        let images: Vec<Prepared> = self
            .maps
            .iter()
            .map(|(map, perm)| Prepared {
                samples: idx
                    .iter()
                    .map(|&i| map_sample(&p.samples[i], *map, self.centre, perm))
                    .collect(),
                ..p.without_samples()
            })
            .collect();
        let all: Vec<usize> = (0..b).collect();
        let mut out = vec![0.0f32; p.rest_m.len() * b * 6];
        let mut logits: Option<Vec<f32>> = None;
        // Adds one run's outputs; an image's node perm[v] carries node v's prediction, mapped
        // (maps are involutions).
        let mut add = |o: Vec<f32>, l: Option<Vec<f32>>, image: Option<&(Symmetry, Vec<usize>)>| {
            for v in 0..p.rest_m.len() {
                let w = image.map_or(v, |(_, perm)| perm[v]);
                for j in 0..b {
                    let (to, from) = ((v * b + j) * 6, (w * b + j) * 6);
                    for off in [0, 3] {
                        let u = [0, 1, 2].map(|c| f64::from(o[from + off + c]));
                        let u = image.map_or(u, |(map, _)| map.vector(u));
                        for c in 0..3 {
                            out[to + off + c] += u[c] as f32;
                        }
                    }
                    if let Some(l) = &l {
                        logits.get_or_insert_with(|| vec![0.0; l.len()])[v * b + j] += l[w * b + j];
                    }
                }
            }
        };
        for (k, npe) in engines.iter().enumerate() {
            let (pos, graph, device) = npe.parts();
            let own;
            let x = if k == 0 {
                x
            } else {
                own = p.inputs(&npe.config, idx);
                &own
            };
            let (o, l, _) = npe.net().forward_full(&npe.config, x, pos, graph, device);
            add(values(o), l.map(values), None);
            for (image, q) in self.maps.iter().zip(&images) {
                let xi = q.inputs(&npe.config, &all);
                let (o, l, _) = npe.net().forward_full(&npe.config, &xi, pos, graph, device);
                add(values(o), l.map(values), Some(image));
            }
        }
        let share = 1.0 / (engines.len() * (1 + self.maps.len())) as f32;
        out.iter_mut().for_each(|o| *o *= share);
        if let Some(l) = logits.as_mut() {
            l.iter_mut().for_each(|o| *o *= share);
        }
        (out, logits)
    }
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
    evaluate_with(npe, p, idx, gel, top, batch, &Extra::default())
}

/// What [`evaluate_with`] scores beyond [`evaluate`].
#[derive(Debug, Clone, Copy, Default)]
pub struct Extra<'a> {
    /// The force-from-displacement functional: scores the total force read from the
    /// predicted displacement.
    pub stiffness: Option<&'a ForceFromDisplacement>,
    /// Thresholds on the predicted -u_z for [`SampleScore::contact_accuracy_at`], m.
    pub thresholds_m: &'a [f64],
    /// Test-time symmetrisation: the engine also runs on each sample's image under these
    /// maps of the top face, and its outputs (fields and contact logits) are mapped back and
    /// averaged with the plain one's.
    pub symmetrise: &'a [Symmetry],
    /// More engines of the same top face, scales and contact head whose outputs are averaged
    /// with the engine's (an ensemble), each symmetrised like it.
    pub ensemble: &'a [Npe],
}

/// [`evaluate`], and what `extra` asks for: the total force read from the predicted
/// displacement (Table 6.1's force estimate), the accuracy at other contact thresholds.
pub fn evaluate_with(
    npe: &Npe,
    p: &Prepared,
    idx: &[usize],
    gel: &Gel,
    top: &TopSurface,
    batch: usize,
    extra: &Extra,
) -> Result<(Scores, Vec<SampleScore>)> {
    let (stiffness, thresholds_m) = (extra.stiffness, extra.thresholds_m);
    let grid = Grid::for_gel(gel);
    let n = p.rest_m.len();
    let mut per = Vec::new();
    let mut pooled = 0.0;
    let mut nodal_sq = [0.0; 2];
    let mut nodal_count = [0usize; 2];
    let maps = Symmetrised::new(p, extra.symmetrise)?;
    for (k, e) in extra.ensemble.iter().enumerate() {
        let why = if e.surface.rest_m != npe.surface.rest_m {
            "another top surface"
        } else if e.config.scales != npe.config.scales {
            "other scales"
        } else if e.config.contact_head != npe.config.contact_head {
            "a contact head where the first has none, or none where it has one"
        } else {
            continue;
        };
        return Err(crate::NpeError::Data(format!(
            "ensemble member {} has {why}: it cannot be averaged with the first engine",
            k + 2
        )));
    }
    let engines: Vec<&Npe> = std::iter::once(npe).chain(extra.ensemble).collect();
    for chunk in idx.chunks(batch.max(1)) {
        let x = p.inputs(&npe.config, chunk);
        let (out, logits) = maps.forward(&engines, p, chunk, &x);
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
            let mine_logits: Option<Vec<f32>> = logits
                .as_ref()
                .map(|z| (0..n).map(|v| z[v * b + j]).collect());
            let pred_contact = contact_state(&pred.displacement_m, mine_logits.as_deref());
            let right = pred_contact
                .iter()
                .zip(&truth)
                .filter(|(a, b)| **a == (-b[2] > CONTACT_THRESHOLD_M))
                .count();
            let pen: Vec<f64> = x.node_depth[j * n..(j + 1) * n]
                .iter()
                .map(|&d| f64::from(d) * npe.config.scales.z_m)
                .collect();
            let contact = breakdown(&pred_contact, &truth, &pen, &p.edges);
            let fs = npe.config.scales.nodal_force_n;
            let mut nf = [0.0; 2];
            let mut nc = 0usize;
            for (f, t) in pred.nodal_force_n.iter().zip(s.target.chunks(6)) {
                let e2: f64 = (0..3)
                    .map(|k| (f[k] - f64::from(t[3 + k]) * fs).powi(2))
                    .sum();
                nf[0] += e2;
                if t[3..6].iter().any(|&v| v != 0.0) {
                    nf[1] += e2;
                    nc += 1;
                }
            }
            nodal_sq[0] += nf[0];
            nodal_sq[1] += nf[1];
            nodal_count[0] += n;
            nodal_count[1] += nc;
            let rmse = nodal_rmse(&pred.displacement_m, &truth)?;
            pooled += rmse * rmse * n as f64;
            let mp = Mask::from_displacement(
                gel,
                &grid,
                &top.extend(&pred.displacement_m, gel.num_nodes()),
            );
            let mt = Mask::from_displacement(gel, &grid, &top.extend(&truth, gel.num_nodes()));
            let finite = |e: f64| e.is_finite().then_some(e);
            let (elong_fem, elong_pred) = (elongation(&mt), elongation(&mp));
            let orientation = (elong_fem >= ELONGATION_MIN && mp.count() > 0)
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
                contact,
                nodal_force_rmse_n: (nf[0] / n as f64).sqrt(),
                force_from_u_n: stiffness.map(|k| k.force_n(&p.rest_m, &pred.displacement_m)),
                force_from_fem_u_n: stiffness.map(|k| k.force_n(&p.rest_m, &truth)),
                contact_accuracy_at: thresholds_m
                    .iter()
                    .map(|&t| {
                        pred.displacement_m
                            .iter()
                            .zip(&truth)
                            .filter(|(a, b)| (-a[2] > t) == (-b[2] > CONTACT_THRESHOLD_M))
                            .count() as f64
                            / n as f64
                    })
                    .collect(),
                elongation_fem: finite(elong_fem),
                elongation_pred: finite(elong_pred),
                mask_pixels: [mt.count(), mp.count()],
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
    let fem_rms =
        (per.iter().map(|s| s.force_fem_n.powi(2)).sum::<f64>() / per.len().max(1) as f64).sqrt();
    let mut rel: Vec<f64> = per
        .iter()
        .filter(|s| s.force_fem_n > 0.0)
        .map(|s| (s.force_pred_n - s.force_fem_n).abs() / s.force_fem_n)
        .collect();
    rel.sort_by(f64::total_cmp);
    let rms_of = |get: &dyn Fn(&SampleScore) -> Option<f64>| {
        stiffness.map(|_| {
            (per.iter()
                .map(|s| (get(s).unwrap_or(0.0) - s.force_fem_n).powi(2))
                .sum::<f64>()
                / per.len().max(1) as f64)
                .sqrt()
        })
    };
    let force_from_u_rmse_n = rms_of(&|s| s.force_from_u_n);
    let force_from_fem_u_rmse_n = rms_of(&|s| s.force_from_fem_u_n);
    let mut sum = ContactBreakdown::default();
    for s in &per {
        let c = &s.contact;
        sum.fem_contact += c.fem_contact;
        sum.false_pos += c.false_pos;
        sum.false_neg += c.false_neg;
        sum.wrong_near_threshold += c.wrong_near_threshold;
        sum.wrong_penetrated += c.wrong_penetrated;
        sum.wrong_rim += c.wrong_rim;
    }
    let rule: Vec<f64> = per
        .iter()
        .map(|s| s.contact.penetration_rule_accuracy)
        .collect();
    sum.penetration_rule_accuracy = mean_std(&rule)[0];
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
            nodal_force_rmse_n: (nodal_sq[0] / nodal_count[0].max(1) as f64).sqrt(),
            nodal_force_rmse_contact_n: (nodal_sq[1] / nodal_count[1].max(1) as f64).sqrt(),
            force_rmse_relative_pct: 100.0 * fr.sqrt() / fem_rms,
            force_median_relative_pct: 100.0 * rel.get(rel.len() / 2).copied().unwrap_or(f64::NAN),
            force_fem_mean_n: per.iter().map(|s| s.force_fem_n).sum::<f64>()
                / per.len().max(1) as f64,
            penetration_rule_accuracy_pct: 100.0 * sum.penetration_rule_accuracy,
            contact: sum,
            force_from_u_rmse_n,
            force_from_fem_u_rmse_n,
        },
        per,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Four nodes on a chain 0-1-2-3, node 1 penetrated: each kind of error is counted where
    /// it is.
    #[test]
    fn breakdown_sorts_the_wrong_nodes() {
        let z = |v: f64| [0.0, 0.0, -v * 1e-6];
        let fem = [z(50.0), z(80.0), z(35.0), z(0.0)];
        // Node 0 missed (rim, 50 um: not near the threshold), node 1 right, node 2 missed
        // (rim, 35 um: near the threshold), node 3 a false positive (no penetrated neighbour).
        let pred = [z(10.0), z(80.0), z(25.0), z(31.0)].map(|u| -u[2] > CONTACT_THRESHOLD_M);
        let pen = [0.0, 80e-6, 0.0, 0.0];
        let c = breakdown(&pred, &fem, &pen, &[[0, 1], [1, 2], [2, 3]]);
        assert_eq!(c.fem_contact, 3);
        assert_eq!((c.false_pos, c.false_neg), (1, 2));
        assert_eq!(c.wrong_near_threshold, 1);
        assert_eq!(c.wrong_penetrated, 0);
        assert_eq!(c.wrong_rim, 2);
        // The rule penetration > 30 um gets node 1 and node 3 right.
        assert!((c.penetration_rule_accuracy - 0.5).abs() < 1e-12);
    }
}
