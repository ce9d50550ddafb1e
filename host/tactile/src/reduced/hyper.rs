//! The gel's nonlinear (Neo-Hookean) internal force on a reduced basis, hyper-reduced by
//! energy-conserving sampling and weighting (ECSW).
//!
//! Split: f_int(u) = K_0 u + (f_int(u) - K_0 u). The linear part projects exactly,
//! Phi^T K_0 Phi q = K_r q (the reduced model's stiffness). Only the remainder, which vanishes to
//! second order in the strain and lives where the gel is strained hard (under and around the
//! indenter), is sampled: sum over the sampled elements e of w_e V_e^T (f_e(V_e q) - K0_e V_e q),
//! V_e the basis rows of the element's 12 DOFs. The weights w_e >= 0 come from the NNLS of
//! `ocm_mor::nnls` on training fields, and one weight set serves every placement's basis (the
//! POD modes plus that placement's footprint modes): the training rows stack the projected
//! remainders of several placements, each on its own basis. With every element at weight 1 the
//! force is exactly Phi^T f_int(Phi q).

use crate::gel::Gel;
// the basis alone: the reduced solve uses this module (no circle)
use super::basis::ReducedModel;
use crate::{Result, TactileError};
use nalgebra::{DMatrix, DVector, Vector3};
use ocm_fem::element::{Mat12, TetGeom, evaluate};
use ocm_fem::material::Material;
use rayon::prelude::*;

/// One sampled element with what its evaluation needs.
#[derive(Debug, Clone)]
struct Sampled {
    element: usize,
    weight: f64,
    /// Geometry with local node numbers 0..4.
    geom: TetGeom,
    rest: [Vector3<f64>; 4],
    /// Tangent at rest (the element's share of K_0).
    k_rest: Mat12,
    /// The fem's precomputed K0 of corotational laws (None for hyperelastic ones).
    k0_law: Option<Mat12>,
    scale: f64,
    /// Global DOF of each of the 12 local ones.
    dofs: [usize; 12],
}

/// Sampled gel elements with their ECSW weights (independent of the basis).
#[derive(Debug, Clone)]
pub struct NonlinearGel {
    elements: Vec<Sampled>,
    material: Material,
}

impl NonlinearGel {
    /// The elements `weights` (element index, weight >= 0) of `gel`; zero weights are dropped.
    pub fn new(gel: &Gel, weights: &[(usize, f64)]) -> Result<Self> {
        let model = &gel.model;
        let ne = model.elements.len();
        let elements = weights
            .par_iter()
            .filter(|(_, w)| *w != 0.0)
            .map(|&(e, w)| {
                if e >= ne {
                    return Err(TactileError::Input(format!(
                        "ECSW element {e} is not one of the gel's {ne} elements"
                    )));
                }
                if !(w.is_finite() && w > 0.0) {
                    return Err(TactileError::Input(format!(
                        "ECSW weight {w} of element {e} is not positive and finite"
                    )));
                }
                let g = &model.elements[e];
                let mut geom = g.clone();
                geom.nodes = [0, 1, 2, 3];
                let rest = g.nodes.map(|i| model.rest[i]);
                let k0_law = model.element_k0(e).cloned();
                let scale = model.element_scale[e];
                let ev = evaluate(
                    e,
                    &geom,
                    &model.material,
                    k0_law.as_ref(),
                    scale,
                    &rest,
                    true,
                )?;
                let k_rest = ev.stiffness.ok_or_else(|| {
                    TactileError::Input(format!("element {e}: no tangent at rest"))
                })?;
                let dofs = std::array::from_fn(|k| 3 * g.nodes[k / 3] + k % 3);
                Ok(Sampled {
                    element: e,
                    weight: w,
                    geom,
                    rest,
                    k_rest,
                    k0_law,
                    scale,
                    dofs,
                })
            })
            .collect::<Result<Vec<_>>>()?;
        Ok(NonlinearGel {
            elements,
            material: model.material,
        })
    }

    /// Every element of `gel` at weight 1 (the unreduced Galerkin force).
    pub fn all_elements(gel: &Gel) -> Result<Self> {
        let w: Vec<(usize, f64)> = (0..gel.model.elements.len()).map(|e| (e, 1.0)).collect();
        Self::new(gel, &w)
    }

    /// Sampled elements and their weights.
    pub fn weights(&self) -> Vec<(usize, f64)> {
        self.elements
            .iter()
            .map(|s| (s.element, s.weight))
            .collect()
    }

    /// Number of sampled elements.
    pub fn len(&self) -> usize {
        self.elements.len()
    }

    /// True when no element is sampled (the force is then the linear K_r q).
    pub fn is_empty(&self) -> bool {
        self.elements.is_empty()
    }

    /// This element set on the basis of `model` (gathers each element's 12 basis rows).
    pub fn on_basis<'a>(&'a self, model: &'a ReducedModel) -> ProjectedGel<'a> {
        let r = model.rank();
        let mut rows = vec![0.0; self.elements.len() * 12 * r];
        for (s, el) in self.elements.iter().enumerate() {
            for (k, &d) in el.dofs.iter().enumerate() {
                rows[(s * 12 + k) * r..(s * 12 + k + 1) * r]
                    .copy_from_slice(&model.modes[d * r..(d + 1) * r]);
            }
        }
        ProjectedGel {
            gel: self,
            model,
            rows,
            r,
        }
    }
}

/// Element remainder f_e(x) - K0_e u_e and, when asked, the tangent change K_e(x) - K0_e.
fn remainder(
    el: &Sampled,
    mat: &Material,
    u: &[f64; 12],
    want_k: bool,
) -> Result<([f64; 12], Option<Mat12>)> {
    let pos: [Vector3<f64>; 4] =
        std::array::from_fn(|a| el.rest[a] + Vector3::new(u[3 * a], u[3 * a + 1], u[3 * a + 2]));
    let ev = evaluate(
        el.element,
        &el.geom,
        mat,
        el.k0_law.as_ref(),
        el.scale,
        &pos,
        want_k,
    )?;
    let mut f = [0.0; 12];
    for i in 0..12 {
        let ku: f64 = (0..12).map(|j| el.k_rest[(i, j)] * u[j]).sum();
        f[i] = ev.force[i] - ku;
    }
    Ok((f, ev.stiffness.map(|k| k - el.k_rest)))
}

/// The hyper-reduced nonlinear internal force on one basis.
pub struct ProjectedGel<'a> {
    gel: &'a NonlinearGel,
    model: &'a ReducedModel,
    /// Per sampled element its 12 basis rows, each of length r.
    rows: Vec<f64>,
    r: usize,
}

/// Reduced internal force and tangent at a configuration.
#[derive(Debug, Clone)]
pub struct ReducedForce {
    /// f_r(q), N (generalised).
    pub force: DVector<f64>,
    /// K_r(q) = df_r/dq, when asked for.
    pub tangent: Option<DMatrix<f64>>,
}

impl ProjectedGel<'_> {
    /// Rank of the basis.
    pub fn rank(&self) -> usize {
        self.r
    }

    /// f_r(q) = K_r q + sum_e w_e V_e^T (f_e - K0_e u_e) and its tangent
    /// K_r + sum_e w_e V_e^T (K_e - K0_e) V_e. An element inverted at `q` is an error naming it.
    pub fn evaluate(&self, q: &[f64], want_k: bool) -> Result<ReducedForce> {
        let r = self.r;
        if q.len() != r {
            return Err(TactileError::Input(format!(
                "reduced coordinates of length {}, the basis has rank {r}",
                q.len()
            )));
        }
        let mat = &self.gel.material;
        let zero = || (vec![0.0; r], vec![0.0; if want_k { r * r } else { 0 }]);
        let (f_rem, k_rem) = self
            .gel
            .elements
            .par_iter()
            .enumerate()
            .with_min_len(32)
            .try_fold(zero, |(mut f, mut k), (s, el)| -> Result<_> {
                let v = &self.rows[s * 12 * r..(s + 1) * 12 * r];
                let mut u = [0.0; 12];
                for (i, ui) in u.iter_mut().enumerate() {
                    *ui = v[i * r..(i + 1) * r]
                        .iter()
                        .zip(q)
                        .map(|(a, b)| a * b)
                        .sum();
                }
                let (fe, ke) = remainder(el, mat, &u, want_k)?;
                let w = el.weight;
                for i in 0..12 {
                    let c = w * fe[i];
                    if c != 0.0 {
                        for (fk, vk) in f.iter_mut().zip(&v[i * r..(i + 1) * r]) {
                            *fk += c * vk;
                        }
                    }
                }
                if let Some(ke) = ke {
                    // (K_e - K0_e) V_e: 12 x r, then V_e^T of it, both weighted.
                    let mut kv = vec![0.0; 12 * r];
                    for i in 0..12 {
                        for m in 0..12 {
                            let a = w * ke[(i, m)];
                            if a != 0.0 {
                                let vm = &v[m * r..(m + 1) * r];
                                for (x, y) in kv[i * r..(i + 1) * r].iter_mut().zip(vm) {
                                    *x += a * y;
                                }
                            }
                        }
                    }
                    for i in 0..12 {
                        let vi = &v[i * r..(i + 1) * r];
                        let kvi = &kv[i * r..(i + 1) * r];
                        for (a, &va) in vi.iter().enumerate() {
                            if va != 0.0 {
                                for (x, y) in k[a * r..(a + 1) * r].iter_mut().zip(kvi) {
                                    *x += va * y;
                                }
                            }
                        }
                    }
                }
                Ok((f, k))
            })
            .try_reduce(zero, |(mut f1, mut k1), (f2, k2)| {
                f1.iter_mut().zip(&f2).for_each(|(a, b)| *a += b);
                k1.iter_mut().zip(&k2).for_each(|(a, b)| *a += b);
                Ok((f1, k1))
            })?;
        let qv = DVector::from_column_slice(q);
        let force = &self.model.stiffness * &qv + DVector::from_vec(f_rem);
        let tangent = want_k.then(|| {
            let k = &self.model.stiffness + DMatrix::from_row_slice(r, r, &k_rem);
            (&k + k.transpose()) * 0.5
        });
        Ok(ReducedForce { force, tangent })
    }
}

/// What an ECSW fit returns.
#[derive(Debug, Clone)]
pub struct EcswFit {
    /// Elements with a positive weight: (element, weight).
    pub weights: Vec<(usize, f64)>,
    /// ||G w - b|| / ||b|| over the training rows (each field's block scaled to a unit target).
    pub relative_residual: f64,
    /// Training fields used.
    pub fields: usize,
    /// Training fields skipped (their projection inverts an element).
    pub skipped: usize,
    /// Rows of the NNLS (the sum of the fields' basis ranks).
    pub rows: usize,
    /// Candidate elements (columns).
    pub candidates: usize,
}

/// One training placement: its basis and the full fields (N x 3, m) whose projections train the weights.
pub struct EcswTraining<'a> {
    /// The placement's basis.
    pub model: &'a ReducedModel,
    /// Fields on the whole gel.
    pub fields: Vec<&'a [[f64; 3]]>,
}

/// Remainder contributions of every candidate element at the projection of `u` onto `model`:
/// column-major `r` x candidates (entry k of column c: V_c^T (f_c - K0_c u_c), row k).
fn contributions(
    all: &NonlinearGel,
    model: &ReducedModel,
    u: &[[f64; 3]],
) -> Result<(Vec<f64>, usize)> {
    let q = model.project(u);
    let proj = all.on_basis(model);
    let r = proj.r;
    let mat = &all.material;
    let cols: Vec<Vec<f64>> = all
        .elements
        .par_iter()
        .enumerate()
        .with_min_len(64)
        .map(|(s, el)| -> Result<Vec<f64>> {
            let v = &proj.rows[s * 12 * r..(s + 1) * 12 * r];
            let mut ue = [0.0; 12];
            for (i, ui) in ue.iter_mut().enumerate() {
                *ui = v[i * r..(i + 1) * r]
                    .iter()
                    .zip(&q)
                    .map(|(a, b)| a * b)
                    .sum();
            }
            let (fe, _) = remainder(el, mat, &ue, false)?;
            let mut c = vec![0.0; r];
            for i in 0..12 {
                for (ck, vk) in c.iter_mut().zip(&v[i * r..(i + 1) * r]) {
                    *ck += fe[i] * vk;
                }
            }
            Ok(c)
        })
        .collect::<Result<_>>()?;
    Ok((cols.concat(), r))
}

/// ECSW weights for the elements of `candidates` (all weight 1; the target is their full sum)
/// such that the weighted remainder reproduces each training field's projected remainder to
/// `tolerance` (relative, each field's block scaled to a unit target), by `ocm_mor::nnls`.
pub fn fit_ecsw(
    candidates: &NonlinearGel,
    training: &[EcswTraining],
    tolerance: f64,
) -> Result<EcswFit> {
    if !(tolerance.is_finite() && tolerance > 0.0 && tolerance < 1.0) {
        return Err(TactileError::Input(format!(
            "ECSW tolerance {tolerance} is not within (0, 1)"
        )));
    }
    if candidates.elements.iter().any(|e| e.weight != 1.0) {
        return Err(TactileError::Input(
            "ECSW candidates must all have weight 1".into(),
        ));
    }
    let ne = candidates.elements.len();
    let mut blocks: Vec<(Vec<f64>, usize)> = Vec::new();
    let mut skipped = 0;
    for t in training {
        for u in &t.fields {
            if u.len() != t.model.info.mesh_nodes {
                return Err(TactileError::Input(format!(
                    "an ECSW training field has {} nodes, the basis {}",
                    u.len(),
                    t.model.info.mesh_nodes
                )));
            }
            match contributions(candidates, t.model, u) {
                Ok(b) => blocks.push(b),
                Err(TactileError::Fem(ocm_fem::FemError::Inverted { .. })) => skipped += 1,
                Err(e) => return Err(e),
            }
        }
    }
    let rows: usize = blocks.iter().map(|(_, r)| r).sum();
    if rows == 0 {
        return Err(TactileError::Input(
            "no usable ECSW training field (none given, or every projection inverts an element)"
                .into(),
        ));
    }
    let mut g = vec![0.0; rows * ne];
    let mut b = vec![0.0; rows];
    let mut at = 0;
    for (block, r) in &blocks {
        let r = *r;
        let mut target = vec![0.0; r];
        for c in 0..ne {
            for k in 0..r {
                target[k] += block[c * r + k];
            }
        }
        let norm = target.iter().map(|v| v * v).sum::<f64>().sqrt().max(1e-300);
        for c in 0..ne {
            for k in 0..r {
                g[c * rows + at + k] = block[c * r + k] / norm;
            }
        }
        for k in 0..r {
            b[at + k] = target[k] / norm;
        }
        at += r;
    }
    drop(blocks);
    let sol = ocm_mor::nnls::solve(&g, rows, ne, &b, tolerance)
        .map_err(|e| TactileError::Input(format!("ECSW NNLS: {e}")))?;
    let weights = sol
        .weights
        .iter()
        .enumerate()
        .filter(|(_, w)| **w > 0.0)
        .map(|(c, &w)| (candidates.elements[c].element, w))
        .collect();
    Ok(EcswFit {
        weights,
        relative_residual: sol.relative_residual,
        fields: training.iter().map(|t| t.fields.len()).sum::<usize>() - skipped,
        skipped,
        rows,
        candidates: ne,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gel::GelMaterial;
    use ocm_fem::model::{Loads, Pattern};
    use ocm_mor::pod::{PodOptions, Truncation};

    fn block() -> Gel {
        let mesh = ocm_fem::mesh::generate::box_mesh([6, 4, 3], [6e-3, 4e-3, 2e-3]);
        Gel::from_mesh(mesh, GelMaterial::default(), 1e-9).unwrap()
    }

    type Shape = fn(f64, f64, f64) -> [f64; 3];

    /// Smooth fields that vanish on the base (z = 0): a dent, a shear and a twist of the top,
    /// each a few hundred um at the top (strains of 10-30 %, well inside the nonlinear range).
    fn fields(gel: &Gel, amp: f64) -> Vec<Vec<[f64; 3]>> {
        use std::f64::consts::PI as pi;
        let shapes: [Shape; 5] = [
            |x, y, _| [0.0, 0.0, -(pi * x / 6e-3).sin() * (pi * y / 4e-3).sin()],
            |x, _, _| [0.6 * (pi * x / 6e-3).cos(), 0.0, 0.0],
            |x, y, _| {
                [
                    0.0,
                    0.5 * (pi * x / 6e-3).sin(),
                    -0.3 * (2.0 * pi * y / 4e-3).cos(),
                ]
            },
            |x, y, _| [-(y - 2e-3) / 2e-3 * 0.4, (x - 3e-3) / 3e-3 * 0.4, 0.0],
            |x, y, _| {
                [
                    0.0,
                    0.0,
                    -((x - 2e-3).powi(2) + (y - 2e-3).powi(2)).sqrt() / 3e-3,
                ]
            },
        ];
        shapes
            .iter()
            .map(|f| {
                gel.mesh
                    .points
                    .iter()
                    .map(|p| {
                        let s = (p[2] / 2e-3).powi(2) * amp;
                        f(p[0], p[1], p[2]).map(|v| v * s)
                    })
                    .collect()
            })
            .collect()
    }

    fn basis(gel: &Gel, snaps: &[Vec<[f64; 3]>], rank: usize) -> ReducedModel {
        let opts = PodOptions {
            truncation: Truncation::Rank(rank),
            oversampling: 4,
            power_iterations: 1,
            seed: 2,
        };
        ReducedModel::build(gel, "block", snaps, vec!["synthetic".into()], &opts).unwrap()
    }

    /// Every element at weight 1: the reduced force is the full FEM's internal force projected
    /// on the basis, Phi^T f_int(X + Phi q), at a configuration strained far beyond linear.
    #[test]
    fn all_elements_give_the_projected_fem_force() {
        let gel = block();
        let snaps = fields(&gel, 0.3e-3);
        let m = basis(&gel, &snaps, 5);
        let all = NonlinearGel::all_elements(&gel).unwrap();
        assert_eq!(all.len(), gel.model.elements.len());
        let proj = all.on_basis(&m);
        let q: Vec<f64> = m
            .project(&snaps[0])
            .iter()
            .zip([1.0, 0.7, -0.5, 0.4, 0.9])
            .map(|(a, b)| a + b * 1e-4)
            .collect();
        let got = proj.evaluate(&q, false).unwrap().force;
        let u = m.displacement(&q);
        let mut x = gel.model.rest_dofs();
        for (i, ui) in u.iter().enumerate() {
            for d in 0..3 {
                x[3 * i + d] += ui[d];
            }
        }
        let pattern = Pattern::new(&gel.model).unwrap();
        let ev = gel
            .model
            .evaluate(&pattern, &x, &Loads::default(), 1.0, false)
            .unwrap();
        let r = m.rank();
        let want: Vec<f64> = (0..r)
            .map(|j| (0..x.len()).map(|d| m.modes[d * r + j] * ev.f_int[d]).sum())
            .collect();
        let lin = &m.stiffness * DVector::from_column_slice(&q);
        let scale = want.iter().map(|v| v.abs()).fold(0.0, f64::max);
        let nonlinear = (0..r).map(|j| (want[j] - lin[j]).abs()).fold(0.0, f64::max);
        println!(
            "projected force {want:?}; its nonlinear part up to {:.1} %",
            100.0 * nonlinear / scale
        );
        // The configuration is nonlinear enough for the remainder to matter.
        assert!(nonlinear > 0.02 * scale, "remainder {nonlinear} of {scale}");
        for j in 0..r {
            assert!(
                (got[j] - want[j]).abs() < 1e-9 * scale,
                "row {j}: {} vs {}",
                got[j],
                want[j]
            );
        }
    }

    /// The reduced tangent of a weighted element subset against central differences of its force.
    #[test]
    fn reduced_tangent_matches_finite_differences() {
        let gel = block();
        let snaps = fields(&gel, 0.3e-3);
        let m = basis(&gel, &snaps, 5);
        let w: Vec<(usize, f64)> = (0..gel.model.elements.len())
            .filter(|e| e % 3 == 0)
            .map(|e| (e, 0.5 + (e % 7) as f64 * 0.3))
            .collect();
        let nl = NonlinearGel::new(&gel, &w).unwrap();
        let proj = nl.on_basis(&m);
        let q = m.project(&snaps[2]);
        let ev = proj.evaluate(&q, true).unwrap();
        let k = ev.tangent.unwrap();
        let r = m.rank();
        let scale = k.abs().max();
        let h = 1e-7;
        for j in 0..r {
            let mut qp = q.clone();
            let mut qm = q.clone();
            qp[j] += h;
            qm[j] -= h;
            let fp = proj.evaluate(&qp, false).unwrap().force;
            let fm = proj.evaluate(&qm, false).unwrap().force;
            for i in 0..r {
                let fd = (fp[i] - fm[i]) / (2.0 * h);
                assert!(
                    (fd - k[(i, j)]).abs() < 1e-5 * scale,
                    "K[{i},{j}] {} vs FD {fd}",
                    k[(i, j)]
                );
            }
        }
        // Bad input is refused, not a panic.
        assert!(proj.evaluate(&q[..r - 1], false).is_err());
        assert!(NonlinearGel::new(&gel, &[(usize::MAX, 1.0)]).is_err());
        assert!(NonlinearGel::new(&gel, &[(0, f64::NAN)]).is_err());
    }

    /// ECSW over two bases: the weights are non-negative, fewer elements than the mesh, and
    /// reproduce every training field's projected remainder to the tolerance; on a field not
    /// trained on they still carry most of it.
    #[test]
    fn ecsw_weights_reproduce_the_training_forces() {
        let gel = block();
        let snaps = fields(&gel, 0.3e-3);
        let m1 = basis(&gel, &snaps, 4);
        let m2 = basis(&gel, &snaps[1..], 3);
        let amps = |s: &[[f64; 3]], a: f64| -> Vec<[f64; 3]> {
            s.iter().map(|v| v.map(|x| x * a)).collect()
        };
        let train1: Vec<Vec<[f64; 3]>> = vec![
            amps(&snaps[0], 1.0),
            amps(&snaps[2], 0.7),
            amps(&snaps[3], 1.2),
        ];
        let train2: Vec<Vec<[f64; 3]>> = vec![amps(&snaps[1], 1.0), amps(&snaps[4], 0.8)];
        let all = NonlinearGel::all_elements(&gel).unwrap();
        let tol = 1e-3;
        let training = [
            EcswTraining {
                model: &m1,
                fields: train1.iter().map(|v| v.as_slice()).collect(),
            },
            EcswTraining {
                model: &m2,
                fields: train2.iter().map(|v| v.as_slice()).collect(),
            },
        ];
        let fit = fit_ecsw(&all, &training, tol).unwrap();
        println!(
            "{} of {} elements, residual {:.2e}, {} rows",
            fit.weights.len(),
            fit.candidates,
            fit.relative_residual,
            fit.rows
        );
        assert_eq!(fit.rows, 3 * 4 + 2 * 3);
        assert_eq!(fit.fields, 5);
        assert!(fit.relative_residual <= tol);
        assert!(fit.weights.iter().all(|(_, w)| *w > 0.0));
        assert!(
            fit.weights.len() < all.len() / 4,
            "{} elements",
            fit.weights.len()
        );
        let ecsw = NonlinearGel::new(&gel, &fit.weights).unwrap();
        // Recompute the stacked residual from the sampled force, field by field.
        let (mut num, mut den) = (0.0, 0.0);
        for (m, set) in [(&m1, &train1), (&m2, &train2)] {
            let (pa, pe) = (all.on_basis(m), ecsw.on_basis(m));
            for u in set.iter() {
                let q = m.project(u);
                let lin = &m.stiffness * DVector::from_column_slice(&q);
                let want = pa.evaluate(&q, false).unwrap().force - &lin;
                let got = pe.evaluate(&q, false).unwrap().force - &lin;
                num += ((&got - &want).norm() / want.norm()).powi(2);
                den += 1.0;
            }
        }
        let stacked = (num / den).sqrt();
        println!("recomputed relative residual {stacked:.2e}");
        assert!((stacked - fit.relative_residual).abs() < 1e-6);
        // Untrained: the dent's field at another amplitude on the first basis.
        let u = amps(&snaps[0], 0.5);
        let q = m1.project(&u);
        let lin = &m1.stiffness * DVector::from_column_slice(&q);
        let want = all.on_basis(&m1).evaluate(&q, false).unwrap().force - &lin;
        let got = ecsw.on_basis(&m1).evaluate(&q, false).unwrap().force - &lin;
        let rel = (&got - &want).norm() / want.norm();
        println!("untrained amplitude: relative error {rel:.3}");
        assert!(rel < 0.2, "{rel}");
        assert!(fit_ecsw(&all, &training, 0.0).is_err());
        assert!(fit_ecsw(&all, &[], 1e-3).is_err());
    }
}
