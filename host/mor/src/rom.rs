//! The Galerkin reduced model u = V q of eq 4.5-4.8, with ECSW hyper-reduction.
//!
//! Projected onto the basis V (3N x r), M a + D v + f_int(x) = f_ext(x) becomes
//! M_r q'' + D_r q' + f_r(q) = g_r(q): M_r = V^T M V (lumped mass, constant), D_r = alpha M_r +
//! beta K_r(q_n) (Rayleigh with the tangent frozen at the step start, as the full solver),
//! f_r = sum_e w_e V_e^T f_e(X_e + V_e q) over the elements that carry strain (w_e = 1 for plain
//! Galerkin, the ECSW weights otherwise), and g_r the projected loads. The follower pressure
//! p N / 3 per triangle node is bilinear in the positions, so its projection is an exact quadratic
//! polynomial in q whose r + r^2 + r^3 coefficients are formed once: the cost of a reduced step
//! then depends on r and the sampled elements only, not on the mesh. Constraints: the clamped DOFs
//! are zero in every snapshot and hence in V, so the constraint forces H^T lambda vanish under the
//! projection; the rigid parts follow the span of the snapshots (rigid to first order).

use crate::drive::Input;
use crate::nnls;
use crate::{MorError, Result};
use nalgebra::{DMatrix, DVector, Vector3};
use ocm_fem::element::{self, Mat12, TetGeom};
use ocm_fem::material::Material;
use ocm_fem::model::Model;
use ocm_fem::solve::dynamics::Integrator;
use serde::Serialize;

/// One element of the reduced force sum.
#[derive(Debug, Clone)]
pub struct ReducedElement {
    /// Index in the full model's elements.
    pub element: usize,
    /// Weight (1 for Galerkin, ECSW otherwise).
    pub weight: f64,
    geom: TetGeom,
    k0: Option<Mat12>,
    scale: f64,
    rest: [Vector3<f64>; 4],
    /// Basis rows of the element's 12 DOFs, 12 x r column-major.
    v: Vec<f64>,
}

/// The projected follower-pressure load of one cavity per pascal: G(q)_k = g0_k + L_kj q_j +
/// Q_kij q_i q_j.
#[derive(Debug, Clone)]
struct PressureForm {
    g0: Vec<f64>,
    lin: Vec<f64>,
    quad: Vec<f64>,
}

/// What the reduced model evaluates at a configuration.
#[derive(Debug, Clone)]
pub struct ReducedEval {
    /// Strain energy, J.
    pub energy: f64,
    /// f_r(q), N (generalised).
    pub f_int: DVector<f64>,
    /// K_r(q) when asked for.
    pub k: Option<DMatrix<f64>>,
}

/// A reduced state: generalised coordinates, velocities, accelerations.
#[derive(Debug, Clone, PartialEq)]
pub struct ReducedState {
    /// q.
    pub q: DVector<f64>,
    /// q'.
    pub v: DVector<f64>,
    /// q''.
    pub a: DVector<f64>,
    /// Time, s.
    pub t: f64,
}

/// Newton report of a reduced step.
#[derive(Debug, Clone, Copy, Default, Serialize)]
pub struct ReducedStepReport {
    /// Newton iterations.
    pub iterations: usize,
    /// Tangent evaluations.
    pub tangents: usize,
}

/// The reduced model.
#[derive(Debug, Clone)]
pub struct ReducedModel {
    /// The basis, 3N x r.
    pub basis: DMatrix<f64>,
    /// M_r.
    pub mass: DMatrix<f64>,
    /// Elements of the force sum.
    pub elements: Vec<ReducedElement>,
    pressure: Vec<PressureForm>,
    /// Projected unit tip force, r x 3.
    pub tip: DMatrix<f64>,
    /// Projected gravity load.
    pub gravity: DVector<f64>,
    material: Material,
    /// Rayleigh mass coefficient, 1/s.
    pub alpha: f64,
    /// Rayleigh stiffness coefficient, s.
    pub beta: f64,
    /// Relative residual tolerance of the reduced Newton.
    pub rtol: f64,
}

/// Elements that carry strain: all but those whose four nodes lie on one rigid body.
pub fn straining_elements(model: &Model) -> Vec<usize> {
    let mut body = vec![usize::MAX; model.num_nodes()];
    for (b, rb) in model.rigid_bodies.iter().enumerate() {
        for &i in &rb.nodes {
            body[i] = b;
        }
    }
    (0..model.elements.len())
        .filter(|&e| {
            let n = model.elements[e].nodes;
            !(body[n[0]] != usize::MAX && n.iter().all(|&i| body[i] == body[n[0]]))
        })
        .collect()
}

fn rows3(basis: &DMatrix<f64>, node: usize, d: usize, k: usize) -> f64 {
    basis[(3 * node + d, k)]
}

impl ReducedModel {
    /// Plain Galerkin projection of `model` on `basis` (3N x r); the tip force acts on `tip_nodes`
    /// in equal parts.
    pub fn galerkin(model: &Model, basis: DMatrix<f64>, tip_nodes: &[usize]) -> Result<Self> {
        let n3 = 3 * model.num_nodes();
        if basis.nrows() != n3 || basis.ncols() == 0 {
            return Err(MorError::Invalid(format!(
                "basis is {} x {}, the model has {n3} DOFs",
                basis.nrows(),
                basis.ncols()
            )));
        }
        if tip_nodes.is_empty() {
            return Err(MorError::Invalid("no tip nodes for the tip force".into()));
        }
        let r = basis.ncols();
        let masses = model.nodal_masses();
        let mut mass = DMatrix::zeros(r, r);
        for d in 0..n3 {
            let m = masses[d / 3];
            let row = basis.row(d);
            for j in 0..r {
                let mj = m * row[j];
                if mj != 0.0 {
                    for i in 0..r {
                        mass[(i, j)] += row[i] * mj;
                    }
                }
            }
        }
        let elements = straining_elements(model)
            .into_iter()
            .map(|e| {
                let g = &model.elements[e];
                let mut geom = g.clone();
                geom.nodes = [0, 1, 2, 3];
                let mut v = vec![0.0; 12 * r];
                for k in 0..r {
                    for a in 0..4 {
                        for d in 0..3 {
                            v[k * 12 + 3 * a + d] = rows3(&basis, g.nodes[a], d, k);
                        }
                    }
                }
                ReducedElement {
                    element: e,
                    weight: 1.0,
                    geom,
                    k0: model.element_k0(e).cloned(),
                    scale: model.element_scale[e],
                    rest: g.nodes.map(|i| model.rest[i]),
                    v,
                }
            })
            .collect();
        let pressure = model
            .cavities
            .iter()
            .map(|c| pressure_form(model, &basis, &c.triangles))
            .collect();
        let mut tip = DMatrix::zeros(r, 3);
        for &i in tip_nodes {
            for d in 0..3 {
                for k in 0..r {
                    tip[(k, d)] += rows3(&basis, i, d, k) / tip_nodes.len() as f64;
                }
            }
        }
        let mut gravity = DVector::zeros(r);
        for (i, m) in masses.iter().enumerate() {
            for d in 0..3 {
                for k in 0..r {
                    gravity[k] += rows3(&basis, i, d, k) * m * model.gravity[d];
                }
            }
        }
        // Point forces already on the model are dead loads too.
        for (i, f) in &model.point_forces {
            for d in 0..3 {
                for k in 0..r {
                    gravity[k] += rows3(&basis, *i, d, k) * f[d];
                }
            }
        }
        Ok(ReducedModel {
            basis,
            mass,
            elements,
            pressure,
            tip,
            gravity,
            material: model.material,
            alpha: model.rayleigh_alpha,
            beta: model.rayleigh_beta,
            rtol: 1e-8,
        })
    }

    /// Rank r.
    pub fn rank(&self) -> usize {
        self.basis.ncols()
    }

    /// Internal force, energy and (optionally) tangent at `q`.
    pub fn internal(&self, q: &DVector<f64>, want_k: bool) -> Result<ReducedEval> {
        let r = self.rank();
        let mut f = DVector::zeros(r);
        let mut k = want_k.then(|| DMatrix::zeros(r, r));
        let mut energy = 0.0;
        let mut kv = vec![0.0; 12 * r];
        for el in &self.elements {
            let mut u = [0.0; 12];
            for (kk, qk) in q.iter().enumerate() {
                let col = &el.v[kk * 12..kk * 12 + 12];
                for i in 0..12 {
                    u[i] += col[i] * qk;
                }
            }
            let pos: [Vector3<f64>; 4] = std::array::from_fn(|a| {
                el.rest[a] + Vector3::new(u[3 * a], u[3 * a + 1], u[3 * a + 2])
            });
            let ev = element::evaluate(
                el.element,
                &el.geom,
                &self.material,
                el.k0.as_ref(),
                el.scale,
                &pos,
                want_k,
            )?;
            let w = el.weight;
            energy += w * ev.energy;
            for kk in 0..r {
                let col = &el.v[kk * 12..kk * 12 + 12];
                f[kk] += w * (0..12).map(|i| col[i] * ev.force[i]).sum::<f64>();
            }
            if let (Some(km), Some(ke)) = (k.as_mut(), ev.stiffness.as_ref()) {
                // K_e V_e (12 x r), then V_e^T (K_e V_e).
                for j in 0..r {
                    let col = &el.v[j * 12..j * 12 + 12];
                    for i in 0..12 {
                        kv[j * 12 + i] = (0..12).map(|m| ke[(i, m)] * col[m]).sum();
                    }
                }
                for j in 0..r {
                    let kcol = &kv[j * 12..j * 12 + 12];
                    for i in 0..r {
                        let col = &el.v[i * 12..i * 12 + 12];
                        km[(i, j)] += w * (0..12).map(|m| col[m] * kcol[m]).sum::<f64>();
                    }
                }
            }
        }
        Ok(ReducedEval {
            energy,
            f_int: f,
            k,
        })
    }

    /// Projected external load g_r(q) for an input, and optionally its Jacobian dg_r/dq.
    pub fn external(
        &self,
        q: &DVector<f64>,
        input: &Input,
        want_jac: bool,
    ) -> (DVector<f64>, Option<DMatrix<f64>>) {
        let r = self.rank();
        let mut g = &self.gravity + &self.tip * DVector::from_column_slice(&input.tip_force_n);
        let mut jac = want_jac.then(|| DMatrix::zeros(r, r));
        for (c, form) in self.pressure.iter().enumerate() {
            let p = input.pressure_kpa.get(c).copied().unwrap_or(0.0) * 1e3;
            if p == 0.0 {
                continue;
            }
            for kk in 0..r {
                let mut val = form.g0[kk];
                for j in 0..r {
                    val += form.lin[kk * r + j] * q[j];
                }
                let qk = &form.quad[kk * r * r..(kk + 1) * r * r];
                for i in 0..r {
                    let s: f64 = (0..r).map(|j| qk[i * r + j] * q[j]).sum();
                    val += q[i] * s;
                }
                g[kk] += p * val;
                if let Some(jm) = jac.as_mut() {
                    for j in 0..r {
                        let mut d = form.lin[kk * r + j];
                        for i in 0..r {
                            d += (qk[i * r + j] + qk[j * r + i]) * q[i];
                        }
                        jm[(kk, j)] += p * d;
                    }
                }
            }
        }
        (g, jac)
    }

    /// Static residual f_r(q) - g_r(q) and its tangent K_r - dg_r/dq.
    pub fn static_residual(
        &self,
        q: &DVector<f64>,
        input: &Input,
    ) -> Result<(DVector<f64>, DMatrix<f64>)> {
        let ev = self.internal(q, true)?;
        let (g, dg) = self.external(q, input, true);
        let k = ev.k.unwrap_or_else(|| DMatrix::zeros(0, 0))
            - dg.unwrap_or_else(|| DMatrix::zeros(0, 0));
        Ok((ev.f_int - g, k))
    }

    /// Reduced statics from rest with `load_steps` equal load increments.
    pub fn solve_static(&self, input: &Input, load_steps: usize) -> Result<DVector<f64>> {
        let mut q = DVector::zeros(self.rank());
        let n = load_steps.max(1);
        for s in 1..=n {
            let lam = s as f64 / n as f64;
            let inp = Input {
                pressure_kpa: input.pressure_kpa.map(|p| p * lam),
                tip_force_n: input.tip_force_n.map(|f| f * lam),
            };
            let mut done = false;
            for _ in 0..30 {
                let (res, k) = self.static_residual(&q, &inp)?;
                let (g, _) = self.external(&q, &inp, false);
                let scale = g.norm().max(1e-12);
                if res.norm() <= self.rtol * scale {
                    done = true;
                    break;
                }
                let dq = k
                    .lu()
                    .solve(&(-res))
                    .ok_or_else(|| MorError::Solve("singular reduced tangent".into()))?;
                q += dq;
            }
            if !done {
                return Err(MorError::Solve(format!(
                    "static Newton did not converge at load fraction {lam}"
                )));
            }
        }
        Ok(q)
    }

    /// Rest state.
    pub fn rest_state(&self) -> ReducedState {
        let r = self.rank();
        ReducedState {
            q: DVector::zeros(r),
            v: DVector::zeros(r),
            a: DVector::zeros(r),
            t: 0.0,
        }
    }

    /// Total energy: kinetic 1/2 q'^T M_r q' plus strain energy, J.
    pub fn energy(&self, s: &ReducedState) -> Result<f64> {
        let ke = 0.5 * s.v.dot(&(&self.mass * &s.v));
        Ok(ke + self.internal(&s.q, false)?.energy)
    }

    /// One implicit step of `h` seconds under `input`; halves the step (up to 4 times) when Newton fails.
    pub fn step(
        &self,
        s: &mut ReducedState,
        input: &Input,
        h: f64,
        integrator: Integrator,
    ) -> Result<ReducedStepReport> {
        let mut rep = ReducedStepReport::default();
        self.step_cut(s, input, h, integrator, 0, &mut rep)?;
        Ok(rep)
    }

    fn step_cut(
        &self,
        s: &mut ReducedState,
        input: &Input,
        h: f64,
        integrator: Integrator,
        depth: usize,
        rep: &mut ReducedStepReport,
    ) -> Result<()> {
        let saved = s.clone();
        match self.substep(s, input, h, integrator, rep) {
            Ok(()) => Ok(()),
            Err(e) if depth < 4 => {
                *s = saved;
                let _ = e;
                self.step_cut(s, input, h / 2.0, integrator, depth + 1, rep)?;
                self.step_cut(s, input, h / 2.0, integrator, depth + 1, rep)
            }
            Err(e) => Err(e),
        }
    }

    fn substep(
        &self,
        s: &mut ReducedState,
        input: &Input,
        h: f64,
        integrator: Integrator,
        rep: &mut ReducedStepReport,
    ) -> Result<()> {
        let (ca, cv) = match integrator {
            Integrator::ImplicitEuler => (1.0 / (h * h), 1.0 / h),
            Integrator::Newmark { beta, gamma } => (1.0 / (beta * h * h), gamma / (beta * h)),
        };
        let kin = |q: &DVector<f64>| -> (DVector<f64>, DVector<f64>) {
            let dq = q - &s.q;
            match integrator {
                Integrator::ImplicitEuler => (&dq * ca - &s.v / h, &dq / h),
                Integrator::Newmark { beta, gamma } => {
                    let a = &dq * ca - &s.v / (beta * h) - &s.a * (0.5 / beta - 1.0);
                    let v = &s.v + (&s.a * (1.0 - gamma) + &a * gamma) * h;
                    (a, v)
                }
            }
        };
        // Rayleigh damping with the tangent (internal and pressure) frozen at the step start.
        let ev_n = self.internal(&s.q, true)?;
        rep.tangents += 1;
        let (_, dg_n) = self.external(&s.q, input, true);
        let k_n = ev_n.k.clone().unwrap_or_else(|| DMatrix::zeros(0, 0))
            - dg_n.unwrap_or_else(|| DMatrix::zeros(0, 0));
        let damp = &self.mass * self.alpha + &k_n * self.beta;
        let jac_of = |k: &DMatrix<f64>| &self.mass * ca + &damp * cv + k;
        let mut lu = jac_of(&k_n).lu();
        let mut q = &s.q + &s.v * h;
        let mut last = f64::INFINITY;
        for it in 0..30 {
            let ev = self.internal(&q, false)?;
            let (g, _) = self.external(&q, input, false);
            let (a, v) = kin(&q);
            let ma = &self.mass * &a;
            let res = &ma + &damp * &v + &ev.f_int - &g;
            let scale = ev.f_int.norm().max(g.norm()).max(ma.norm());
            let rn = res.norm();
            if rn <= self.rtol * scale || rn == 0.0 {
                (s.a, s.v) = (a, v);
                s.q = q;
                s.t += h;
                return Ok(());
            }
            if it > 0 && rn > 0.5 * last {
                // Slow contraction: refresh the iteration matrix at the current point.
                let evk = self.internal(&q, true)?;
                rep.tangents += 1;
                let (_, dg) = self.external(&q, input, true);
                let kq = evk.k.unwrap_or_else(|| DMatrix::zeros(0, 0))
                    - dg.unwrap_or_else(|| DMatrix::zeros(0, 0));
                lu = jac_of(&kq).lu();
            }
            last = rn;
            rep.iterations += 1;
            let dq = lu
                .solve(&(-res))
                .ok_or_else(|| MorError::Solve("singular iteration matrix".into()))?;
            q += &dq;
            if dq.norm() <= 1e-13 * q.norm() {
                // Converged to round-off: the tolerance asked for more than f64 holds.
                let (a, v) = kin(&q);
                (s.a, s.v) = (a, v);
                s.q = q;
                s.t += h;
                return Ok(());
            }
        }
        Err(MorError::Solve(format!(
            "dynamic Newton did not converge at t = {:.4} s",
            s.t
        )))
    }

    /// Training data of ECSW for configurations `qs`: per configuration the element contributions
    /// V_e^T f_e (columns) and their sum. Configurations where an element inverts are skipped.
    fn contributions(&self, qs: &[DVector<f64>]) -> (Vec<Vec<f64>>, usize) {
        let r = self.rank();
        let mut blocks = vec![];
        let mut skipped = 0;
        for q in qs {
            let mut block = vec![0.0; r * self.elements.len()];
            let mut ok = true;
            for (c, el) in self.elements.iter().enumerate() {
                let single = ReducedModel {
                    elements: vec![ReducedElement {
                        weight: 1.0,
                        ..el.clone()
                    }],
                    ..self.shallow()
                };
                match single.internal(q, false) {
                    Ok(ev) => block[c * r..(c + 1) * r].copy_from_slice(ev.f_int.as_slice()),
                    Err(_) => {
                        ok = false;
                        break;
                    }
                }
            }
            if ok {
                blocks.push(block);
            } else {
                skipped += 1;
            }
        }
        (blocks, skipped)
    }

    fn shallow(&self) -> ReducedModel {
        ReducedModel {
            basis: DMatrix::zeros(0, self.rank()),
            mass: DMatrix::zeros(0, 0),
            elements: vec![],
            pressure: vec![],
            tip: DMatrix::zeros(0, 0),
            gravity: DVector::zeros(0),
            material: self.material,
            alpha: self.alpha,
            beta: self.beta,
            rtol: self.rtol,
        }
    }

    /// ECSW hyper-reduction: non-negative element weights w (NNLS, Lawson-Hanson) such that
    /// sum_e w_e V_e^T f_e(q_s) reproduces the Galerkin force of every training configuration q_s
    /// to `tolerance` (relative, each configuration scaled to unit force). Returns the reduced
    /// model keeping the elements with w_e > 0.
    pub fn hyper_reduce(&self, training: &[DVector<f64>], tolerance: f64) -> Result<EcswResult> {
        let r = self.rank();
        let ne = self.elements.len();
        let (blocks, skipped) = self.contributions(training);
        if blocks.is_empty() {
            return Err(MorError::Invalid(
                "no usable ECSW training configuration (all invert an element)".into(),
            ));
        }
        let rows = r * blocks.len();
        // Column-major G (rows x elements), each configuration's block scaled to a unit target.
        let mut g = vec![0.0; rows * ne];
        let mut b = vec![0.0; rows];
        for (s, block) in blocks.iter().enumerate() {
            let mut target = vec![0.0; r];
            for c in 0..ne {
                for k in 0..r {
                    target[k] += self.elements[c].weight * block[c * r + k];
                }
            }
            let norm = target.iter().map(|v| v * v).sum::<f64>().sqrt().max(1e-300);
            for c in 0..ne {
                for k in 0..r {
                    g[c * rows + s * r + k] = block[c * r + k] / norm;
                }
            }
            for k in 0..r {
                b[s * r + k] = target[k] / norm;
            }
        }
        let sol = nnls::solve(&g, rows, ne, &b, tolerance)?;
        let mut reduced = self.shallow();
        reduced.basis = self.basis.clone();
        reduced.mass = self.mass.clone();
        reduced.pressure = self.pressure.clone();
        reduced.tip = self.tip.clone();
        reduced.gravity = self.gravity.clone();
        reduced.elements = sol
            .weights
            .iter()
            .enumerate()
            .filter(|(_, w)| **w > 0.0)
            .map(|(c, &w)| ReducedElement {
                weight: w,
                ..self.elements[c].clone()
            })
            .collect();
        Ok(EcswResult {
            model: reduced,
            weights: sol.weights,
            relative_residual: sol.relative_residual,
            training_configurations: blocks.len(),
            skipped_configurations: skipped,
        })
    }

    /// Nodal displacement of node `i` for coordinates `q`.
    pub fn node_displacement(&self, i: usize, q: &DVector<f64>) -> Vector3<f64> {
        let mut u = Vector3::zeros();
        for d in 0..3 {
            u[d] = self.basis.row(3 * i + d).dot(&q.transpose());
        }
        u
    }

    /// Full displacement field V q (3N).
    pub fn displacement(&self, q: &DVector<f64>) -> DVector<f64> {
        &self.basis * q
    }
}

/// Result of ECSW.
#[derive(Debug, Clone)]
pub struct EcswResult {
    /// The hyper-reduced model.
    pub model: ReducedModel,
    /// Weight of every element of the Galerkin model (most are zero).
    pub weights: Vec<f64>,
    /// ||G w - b|| / ||b|| on the training data.
    pub relative_residual: f64,
    /// Configurations used.
    pub training_configurations: usize,
    /// Configurations skipped because an element inverted in them.
    pub skipped_configurations: usize,
}

fn pressure_form(model: &Model, basis: &DMatrix<f64>, tris: &[[usize; 3]]) -> PressureForm {
    let r = basis.ncols();
    let mut g0 = vec![0.0; r];
    let mut lin = vec![0.0; r * r];
    let mut quad = vec![0.0; r * r * r];
    let col = |i: usize, k: usize| {
        Vector3::new(
            basis[(3 * i, k)],
            basis[(3 * i + 1, k)],
            basis[(3 * i + 2, k)],
        )
    };
    let mut cross = vec![Vector3::zeros(); r * r];
    for t in tris {
        let [a, b, c] = *t;
        let e1 = model.rest[b] - model.rest[a];
        let e2 = model.rest[c] - model.rest[a];
        let s: Vec<Vector3<f64>> = (0..r)
            .map(|k| (col(a, k) + col(b, k) + col(c, k)) / 3.0)
            .collect();
        let d1: Vec<Vector3<f64>> = (0..r).map(|k| col(b, k) - col(a, k)).collect();
        let d2: Vec<Vector3<f64>> = (0..r).map(|k| col(c, k) - col(a, k)).collect();
        let n0 = 0.5 * e1.cross(&e2);
        for k in 0..r {
            g0[k] += s[k].dot(&n0);
        }
        for j in 0..r {
            let dn = 0.5 * (e1.cross(&d2[j]) + d1[j].cross(&e2));
            for k in 0..r {
                lin[k * r + j] += s[k].dot(&dn);
            }
        }
        for i in 0..r {
            for j in 0..r {
                cross[i * r + j] = 0.5 * d1[i].cross(&d2[j]);
            }
        }
        for k in 0..r {
            let sk = s[k];
            if sk == Vector3::zeros() {
                continue;
            }
            let qk = &mut quad[k * r * r..(k + 1) * r * r];
            for (m, cv) in cross.iter().enumerate() {
                qk[m] += sk.dot(cv);
            }
        }
    }
    PressureForm { g0, lin, quad }
}
