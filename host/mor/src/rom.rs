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
//! [`ReducedModel::petrov_galerkin`] tests the same equations with another basis W instead of V.

use crate::drive::Input;
use crate::nnls;
use crate::{MorError, Result};
use nalgebra::{DMatrix, DVector, Vector3};
use ocm_fem::element::{self, Mat12, TetGeom};
use ocm_fem::material::Material;
use ocm_fem::model::Model;
use ocm_fem::solve::dynamics::Integrator;
use serde::Serialize;

/// Absolute Newton increment below which a reduced step has converged, in the units of q (m for
/// an orthonormal basis of displacements): the full solver's `dx_tol`.
const DQ_TOL: f64 = 1e-12;

/// Default relative residual tolerance of the reduced Newton ([`ReducedModel::rtol`]): 1e-5, ten
/// times the full solver's; measured on held-out bellows trajectories it changes the TCP by
/// under 0.02 mm at ranks 16 and 32 and saves ~20% of the iterations (crate README).
pub const DEFAULT_RTOL: f64 = 1e-5;

/// Newton iterations of a reduced step before it is halved.
const MAX_ITERATIONS: usize = 60;

/// Default of [`ReducedModel::damping_tangent_age`].
pub const DEFAULT_DAMPING_TANGENT_AGE: usize = 10;

/// The first Newton iterate of a reduced step.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum Predictor {
    /// q_n + h q'_n (the full solver's start).
    ConstantVelocity,
    /// q_n + h q'_n + c h^2 q''_n (c = 1 for backward Euler, where it extrapolates the velocity
    /// of the last two steps linearly; 1/2 for Newmark). On the bellows it saves ~6% of the
    /// iterations, but where the inputs jump it starts far off, Newton can fail and the step is
    /// halved (a different discrete solution), so it is not the default.
    ConstantAcceleration,
}

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
    /// Test-basis rows of the same DOFs (Petrov-Galerkin), 12 x r; `None`: the basis rows.
    t: Option<Vec<f64>>,
}

impl ReducedElement {
    /// Rows of the test basis the element's force is projected on.
    fn test_rows(&self) -> &[f64] {
        self.t.as_deref().unwrap_or(&self.v)
    }
}

/// The projected follower-pressure load of one cavity per pascal: G(q)_k = g0_k + L_kj q_j +
/// 1/2 S_kij q_i q_j with S_k symmetric (S_kij = Q_kij + Q_kji), so that dG_k/dq = L_k + S_k q.
#[derive(Debug, Clone)]
struct PressureForm {
    g0: Vec<f64>,
    lin: Vec<f64>,
    sym: Vec<f64>,
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
    /// The test basis W (3N x r) of a Petrov-Galerkin model, whose equations are W^T R(V q) = 0;
    /// `None` for Galerkin (W = V).
    pub test: Option<DMatrix<f64>>,
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
    /// Steps a projected tangent serves the Rayleigh stiffness damping before it is refreshed at
    /// a step start (1: refreshed at every step start, exactly as the full solver; larger values
    /// lag the damping tangent by up to this many steps, see the crate README).
    pub damping_tangent_age: usize,
    /// First iterate of each step.
    pub predictor: Predictor,
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

/// Elements whose four nodes lie on one rigid body that is not clamped (no fixed DOF).
pub fn body_elements(model: &Model) -> Vec<usize> {
    let mut body = vec![usize::MAX; model.num_nodes()];
    for (b, rb) in model.rigid_bodies.iter().enumerate() {
        if rb
            .nodes
            .iter()
            .any(|&i| (0..3).any(|d| model.fixed[3 * i + d]))
        {
            continue;
        }
        for &i in &rb.nodes {
            body[i] = b;
        }
    }
    (0..model.elements.len())
        .filter(|&e| {
            let n = model.elements[e].nodes;
            body[n[0]] != usize::MAX && n.iter().all(|&i| body[i] == body[n[0]])
        })
        .collect()
}

/// Dot product with eight independent partial sums: a single running sum is a chain of dependent
/// additions that the compiler may not reorder, bound by the add latency instead of throughput.
pub(crate) fn dot(a: &[f64], b: &[f64]) -> f64 {
    let (ca, cb) = (a.chunks_exact(8), b.chunks_exact(8));
    let mut s: f64 = ca
        .remainder()
        .iter()
        .zip(cb.remainder())
        .map(|(x, y)| x * y)
        .sum();
    let mut acc = [0.0; 8];
    for (x, y) in ca.zip(cb) {
        for i in 0..8 {
            acc[i] += x[i] * y[i];
        }
    }
    s += ((acc[0] + acc[4]) + (acc[1] + acc[5])) + ((acc[2] + acc[6]) + (acc[3] + acc[7]));
    s
}

fn rows3(basis: &DMatrix<f64>, node: usize, d: usize, k: usize) -> f64 {
    basis[(3 * node + d, k)]
}

/// An ECSW tolerance is a relative error of the training forces in [0, 1): 0 keeps every
/// element (plain Galerkin), 1 would allow dropping them all.
pub fn check_ecsw_tolerance(tolerance: f64) -> Result<()> {
    if (0.0..1.0).contains(&tolerance) {
        Ok(())
    } else {
        Err(MorError::Invalid(format!(
            "ECSW tolerance {tolerance} must lie in [0, 1) (a relative error of the training forces; 0 = plain Galerkin)"
        )))
    }
}

impl ReducedModel {
    /// Plain Galerkin projection of `model` on `basis` (3N x r); the tip force acts on `tip_nodes`
    /// in equal parts.
    pub fn galerkin(model: &Model, basis: DMatrix<f64>, tip_nodes: &[usize]) -> Result<Self> {
        Self::galerkin_with_body_penalty(model, basis, tip_nodes, None)
    }

    /// [`Self::galerkin`], with the elements inside the unclamped rigid bodies added to the force
    /// sum at `penalty` times their stiffness when `penalty` is given. The full model moves a
    /// rigid body by six DOFs; the reduced model moves its nodes by linear combinations of
    /// snapshot displacements, whose non-rigid part then costs no strain energy unless the
    /// body's own elements resist it (as the penalty mode of the bellows scene does).
    pub fn galerkin_with_body_penalty(
        model: &Model,
        basis: DMatrix<f64>,
        tip_nodes: &[usize],
        penalty: Option<f64>,
    ) -> Result<Self> {
        Self::project(model, basis, None, tip_nodes, penalty)
    }

    /// Petrov-Galerkin projection: the trial basis `basis` (u = V q) with the equations tested
    /// by `test` (W^T R(V q) = 0, both 3N x r). Mass W^T M V, forces W^T f, loads W^T g; the
    /// matrices are no longer symmetric. With W = J0^-1 V ([`crate::modes::step_test_basis`])
    /// a linear step returns the Euclidean projection of the full step (crate README).
    pub fn petrov_galerkin(
        model: &Model,
        basis: DMatrix<f64>,
        test: DMatrix<f64>,
        tip_nodes: &[usize],
    ) -> Result<Self> {
        if test.shape() != basis.shape() {
            return Err(MorError::Invalid(format!(
                "test basis is {} x {}, the basis {} x {}",
                test.nrows(),
                test.ncols(),
                basis.nrows(),
                basis.ncols()
            )));
        }
        if test.iter().any(|x| !x.is_finite()) {
            return Err(MorError::Invalid(
                "test basis holds a non-finite value".into(),
            ));
        }
        Self::project(model, basis, Some(test), tip_nodes, None)
    }

    fn project(
        model: &Model,
        basis: DMatrix<f64>,
        test: Option<DMatrix<f64>>,
        tip_nodes: &[usize],
        penalty: Option<f64>,
    ) -> Result<Self> {
        let n3 = 3 * model.num_nodes();
        if let Some(p) = penalty
            && !(p.is_finite() && p > 0.0)
        {
            return Err(MorError::Invalid(format!(
                "rigid-body penalty must be positive and finite, got {p}"
            )));
        }
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
        let w = test.as_ref().unwrap_or(&basis);
        let masses = model.nodal_masses();
        let mut mass = DMatrix::zeros(r, r);
        for d in 0..n3 {
            let m = masses[d / 3];
            let (row, wrow) = (basis.row(d), w.row(d));
            for j in 0..r {
                let mj = m * row[j];
                if mj != 0.0 {
                    for i in 0..r {
                        mass[(i, j)] += wrow[i] * mj;
                    }
                }
            }
        }
        let mut chosen: Vec<(usize, f64)> = straining_elements(model)
            .into_iter()
            .map(|e| (e, 1.0))
            .collect();
        if let Some(p) = penalty {
            chosen.extend(body_elements(model).into_iter().map(|e| (e, p)));
            chosen.sort_by_key(|c| c.0);
        }
        let elements = chosen
            .into_iter()
            .map(|(e, factor)| {
                let g = &model.elements[e];
                let mut geom = g.clone();
                geom.nodes = [0, 1, 2, 3];
                let rows = |m: &DMatrix<f64>| {
                    let mut v = vec![0.0; 12 * r];
                    for k in 0..r {
                        for a in 0..4 {
                            for d in 0..3 {
                                v[k * 12 + 3 * a + d] = rows3(m, g.nodes[a], d, k);
                            }
                        }
                    }
                    v
                };
                ReducedElement {
                    element: e,
                    weight: 1.0,
                    geom,
                    k0: model.element_k0(e).cloned(),
                    scale: factor * model.element_scale[e],
                    rest: g.nodes.map(|i| model.rest[i]),
                    v: rows(&basis),
                    t: test.as_ref().map(rows),
                }
            })
            .collect();
        let pressure = model
            .cavities
            .iter()
            .map(|c| pressure_form(model, &basis, w, &c.triangles))
            .collect();
        let mut tip = DMatrix::zeros(r, 3);
        for &i in tip_nodes {
            for d in 0..3 {
                for k in 0..r {
                    tip[(k, d)] += rows3(w, i, d, k) / tip_nodes.len() as f64;
                }
            }
        }
        let mut gravity = DVector::zeros(r);
        for (i, m) in masses.iter().enumerate() {
            for d in 0..3 {
                for k in 0..r {
                    gravity[k] += rows3(w, i, d, k) * m * model.gravity[d];
                }
            }
        }
        // Point forces already on the model are dead loads too.
        for (i, f) in &model.point_forces {
            for d in 0..3 {
                for k in 0..r {
                    gravity[k] += rows3(w, *i, d, k) * f[d];
                }
            }
        }
        Ok(ReducedModel {
            basis,
            test,
            mass,
            elements,
            pressure,
            tip,
            gravity,
            material: model.material,
            alpha: model.rayleigh_alpha,
            beta: model.rayleigh_beta,
            rtol: DEFAULT_RTOL,
            damping_tangent_age: DEFAULT_DAMPING_TANGENT_AGE,
            predictor: Predictor::ConstantVelocity,
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
            let tr = el.test_rows();
            for kk in 0..r {
                let col = &tr[kk * 12..kk * 12 + 12];
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
                        let col = &tr[i * 12..i * 12 + 12];
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
        let mut w = vec![0.0; r];
        for (c, form) in self.pressure.iter().enumerate() {
            let p = input.pressure_kpa.get(c).copied().unwrap_or(0.0) * 1e3;
            if p == 0.0 {
                continue;
            }
            for kk in 0..r {
                let sk = &form.sym[kk * r * r..(kk + 1) * r * r];
                for (j, wj) in w.iter_mut().enumerate() {
                    *wj = (0..r).map(|i| sk[j * r + i] * q[i]).sum();
                }
                let lk = &form.lin[kk * r..(kk + 1) * r];
                let val = form.g0[kk] + (0..r).map(|j| (lk[j] + 0.5 * w[j]) * q[j]).sum::<f64>();
                g[kk] += p * val;
                if let Some(jm) = jac.as_mut() {
                    for j in 0..r {
                        jm[(kk, j)] += p * (lk[j] + w[j]);
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

    /// Total energy: kinetic 1/2 q'^T M_r q' plus strain energy, J (a Galerkin model's; for a
    /// Petrov-Galerkin one M_r and the forces are tested with W and this is not the energy).
    pub fn energy(&self, s: &ReducedState) -> Result<f64> {
        let ke = 0.5 * s.v.dot(&(&self.mass * &s.v));
        Ok(ke + self.internal(&s.q, false)?.energy)
    }

    /// One implicit step of `h` seconds under `input` with a fresh [`Stepper`] (no iteration
    /// matrix carried over); halves the step (up to 4 times) when Newton fails.
    pub fn step(
        &self,
        s: &mut ReducedState,
        input: &Input,
        h: f64,
        integrator: Integrator,
    ) -> Result<ReducedStepReport> {
        Stepper::new(self, integrator).step(s, input, h)
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
            test: None,
            mass: DMatrix::zeros(0, 0),
            elements: vec![],
            pressure: vec![],
            tip: DMatrix::zeros(0, 0),
            gravity: DVector::zeros(0),
            material: self.material,
            alpha: self.alpha,
            beta: self.beta,
            rtol: self.rtol,
            damping_tangent_age: self.damping_tangent_age,
            predictor: self.predictor,
        }
    }

    /// ECSW hyper-reduction: non-negative element weights w (NNLS, Lawson-Hanson) such that
    /// sum_e w_e V_e^T f_e(q_s) reproduces the Galerkin force of every training configuration q_s
    /// to `tolerance` (relative, each configuration scaled to unit force). Returns the reduced
    /// model keeping the elements with w_e > 0.
    pub fn hyper_reduce(&self, training: &[DVector<f64>], tolerance: f64) -> Result<EcswResult> {
        check_ecsw_tolerance(tolerance)?;
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
        reduced.test = self.test.clone();
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

/// The pressure load W^T g(V q) of one cavity per pascal (`test` is W, V for Galerkin).
fn pressure_form(
    model: &Model,
    basis: &DMatrix<f64>,
    test: &DMatrix<f64>,
    tris: &[[usize; 3]],
) -> PressureForm {
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
    let tcol = |i: usize, k: usize| {
        Vector3::new(test[(3 * i, k)], test[(3 * i + 1, k)], test[(3 * i + 2, k)])
    };
    let mut cross = vec![Vector3::zeros(); r * r];
    for t in tris {
        let [a, b, c] = *t;
        let e1 = model.rest[b] - model.rest[a];
        let e2 = model.rest[c] - model.rest[a];
        let s: Vec<Vector3<f64>> = (0..r)
            .map(|k| (tcol(a, k) + tcol(b, k) + tcol(c, k)) / 3.0)
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
    // Symmetrise in (i, j): the quadratic form is unchanged and its gradient is S q.
    let mut sym = vec![0.0; r * r * r];
    for k in 0..r {
        let (qk, sk) = (
            &quad[k * r * r..(k + 1) * r * r],
            &mut sym[k * r * r..(k + 1) * r * r],
        );
        for i in 0..r {
            for j in 0..r {
                sk[i * r + j] = qk[i * r + j] + qk[j * r + i];
            }
        }
    }
    PressureForm { g0, lin, sym }
}

/// Implicit steps of a reduced model with their working memory: the projected tangent that serves
/// the Rayleigh stiffness damping, the factorised iteration matrix (kept across steps while it
/// contracts the residual: modified Newton, as the full solver) and the basis rows of the sampled
/// elements stacked for matrix-vector products.
pub struct Stepper<'a> {
    rom: &'a ReducedModel,
    integrator: Integrator,
    /// Basis rows of the sampled elements, 12 n_e x r (element c: rows 12c..12c+12).
    vall: faer::Mat<f64>,
    /// Test-basis rows of the same (Petrov-Galerkin); `None`: `vall`.
    tall: Option<faer::Mat<f64>>,
    /// Weighted element forces (or tangent times basis), 12 n_e x r scratch.
    kv: faer::Mat<f64>,
    /// Element displacements V q and weighted element forces, 12 n_e.
    u: faer::Mat<f64>,
    fe: faer::Mat<f64>,
    /// LU of the iteration matrix and the (c_a, c_v) it was made for.
    lu: Option<(nalgebra::LU<f64, nalgebra::Dyn, nalgebra::Dyn>, f64, f64)>,
    /// K_r - dg/dq of the latest tangent evaluation, and of the one the damping of this step uses.
    k_latest: DMatrix<f64>,
    k_damp: DMatrix<f64>,
    /// Steps since `k_damp` was taken; usize::MAX when there is none.
    damp_age: usize,
    /// Iterations of the last step.
    last_iterations: usize,
    /// The pressure form of this step's pressures: constant, linear, symmetric quadratic part.
    pg0: Vec<f64>,
    plin: Vec<f64>,
    psym: Vec<f64>,
    f: Vec<f64>,
    g: Vec<f64>,
    jg: Vec<f64>,
    w: Vec<f64>,
    /// Iterations and tangent projections so far.
    pub report: ReducedStepReport,
}

impl<'a> Stepper<'a> {
    /// A stepper of `rom` with `integrator`.
    pub fn new(rom: &'a ReducedModel, integrator: Integrator) -> Self {
        let r = rom.rank();
        let ne = rom.elements.len();
        let vall =
            faer::Mat::<f64>::from_fn(12 * ne, r, |i, k| rom.elements[i / 12].v[k * 12 + i % 12]);
        let tall = rom.test.as_ref().map(|_| {
            faer::Mat::<f64>::from_fn(12 * ne, r, |i, k| {
                rom.elements[i / 12].test_rows()[k * 12 + i % 12]
            })
        });
        Stepper {
            rom,
            integrator,
            vall,
            tall,
            kv: faer::Mat::zeros(12 * ne, r),
            u: faer::Mat::zeros(12 * ne, 1),
            fe: faer::Mat::zeros(12 * ne, 1),
            lu: None,
            k_latest: DMatrix::zeros(r, r),
            k_damp: DMatrix::zeros(r, r),
            damp_age: usize::MAX,
            last_iterations: 0,
            pg0: vec![0.0; r],
            plin: vec![0.0; r * r],
            psym: vec![0.0; r * r * r],
            f: vec![0.0; r],
            g: vec![0.0; r],
            jg: vec![0.0; r * r],
            w: vec![0.0; r],
            report: ReducedStepReport::default(),
        }
    }

    /// One implicit step of `h` seconds under `input`; halves the step (up to 4 times) when
    /// Newton fails. Returns the iterations and tangent projections of this step.
    pub fn step(
        &mut self,
        s: &mut ReducedState,
        input: &Input,
        h: f64,
    ) -> Result<ReducedStepReport> {
        let before = self.report;
        self.set_pressure(input);
        self.step_cut(s, input, h, 0)?;
        Ok(ReducedStepReport {
            iterations: self.report.iterations - before.iterations,
            tangents: self.report.tangents - before.tangents,
        })
    }

    fn step_cut(
        &mut self,
        s: &mut ReducedState,
        input: &Input,
        h: f64,
        depth: usize,
    ) -> Result<()> {
        let saved = s.clone();
        match self.substep(s, input, h) {
            Ok(()) => Ok(()),
            Err(_) if depth < 4 => {
                *s = saved;
                // Start the halves from fresh tangents.
                self.lu = None;
                self.damp_age = usize::MAX;
                self.step_cut(s, input, h / 2.0, depth + 1)?;
                self.step_cut(s, input, h / 2.0, depth + 1)
            }
            Err(e) => Err(e),
        }
    }

    /// Combines the cavities' pressure forms for this step's pressures (held over the step).
    fn set_pressure(&mut self, input: &Input) {
        self.pg0.fill(0.0);
        self.plin.fill(0.0);
        self.psym.fill(0.0);
        for (c, form) in self.rom.pressure.iter().enumerate() {
            let p = input.pressure_kpa.get(c).copied().unwrap_or(0.0) * 1e3;
            if p == 0.0 {
                continue;
            }
            for (a, b) in self.pg0.iter_mut().zip(&form.g0) {
                *a += p * b;
            }
            for (a, b) in self.plin.iter_mut().zip(&form.lin) {
                *a += p * b;
            }
            for (a, b) in self.psym.iter_mut().zip(&form.sym) {
                *a += p * b;
            }
        }
    }

    /// External load g(q) into `self.g` and its Jacobian into `self.jg` (row-major).
    fn external(&mut self, q: &[f64], tip: &[f64; 3]) {
        let rom = self.rom;
        let r = rom.rank();
        for k in 0..r {
            let sk = &self.psym[k * r * r..(k + 1) * r * r];
            for j in 0..r {
                let row = &sk[j * r..(j + 1) * r];
                self.w[j] = dot(row, q);
            }
            let lk = &self.plin[k * r..(k + 1) * r];
            let mut val = self.pg0[k] + rom.gravity[k];
            for d in 0..3 {
                val += rom.tip[(k, d)] * tip[d];
            }
            for j in 0..r {
                val += (lk[j] + 0.5 * self.w[j]) * q[j];
                self.jg[k * r + j] = lk[j] + self.w[j];
            }
            self.g[k] = val;
        }
    }

    /// Element sweep at `q`: the internal force sum_e w_e V_e^T f_e into `self.f`; with
    /// `tangent`, also K_r(q) - dg/dq(q) into `self.k_latest` (`self.jg` must be at q).
    fn sweep(&mut self, q: &[f64], tangent: bool) -> Result<()> {
        use faer::linalg::matmul::matmul;
        use faer::{Accum, Par};
        let rom = self.rom;
        let r = rom.rank();
        // Plain column sweeps: faer's kernels carry more overhead than a 12 n_e x r product costs.
        {
            let u = self.u.col_as_slice_mut(0);
            u.fill(0.0);
            for (k, &qk) in q.iter().enumerate() {
                for (ui, vi) in u.iter_mut().zip(self.vall.col_as_slice(k)) {
                    *ui += vi * qk;
                }
            }
        }
        for (c, el) in rom.elements.iter().enumerate() {
            let pos: [Vector3<f64>; 4] = std::array::from_fn(|a| {
                let b = 12 * c + 3 * a;
                el.rest[a] + Vector3::new(self.u[(b, 0)], self.u[(b + 1, 0)], self.u[(b + 2, 0)])
            });
            let ev = element::evaluate(
                el.element,
                &el.geom,
                &rom.material,
                el.k0.as_ref(),
                el.scale,
                &pos,
                tangent,
            )?;
            let w = el.weight;
            for i in 0..12 {
                self.fe[(12 * c + i, 0)] = w * ev.force[i];
            }
            if let Some(ke) = ev.stiffness.as_ref() {
                // Rows 12c.. of K V: w K_e V_e (K_e column-major, inner loop over rows).
                let ks = ke.as_slice();
                for k in 0..r {
                    let col = &el.v[k * 12..k * 12 + 12];
                    let mut acc = [0.0; 12];
                    for m in 0..12 {
                        let cm = w * col[m];
                        for (a, kk) in acc.iter_mut().zip(&ks[m * 12..m * 12 + 12]) {
                            *a += kk * cm;
                        }
                    }
                    self.kv.col_as_slice_mut(k)[12 * c..12 * c + 12].copy_from_slice(&acc);
                }
            }
        }
        let fe = self.fe.col_as_slice(0);
        let tall = self.tall.as_ref().unwrap_or(&self.vall);
        for k in 0..r {
            self.f[k] = dot(tall.col_as_slice(k), fe);
        }
        if tangent {
            let mut k = faer::Mat::<f64>::zeros(r, r);
            matmul(
                k.as_mut(),
                Accum::Replace,
                tall.transpose(),
                self.kv.as_ref(),
                1.0,
                Par::Seq,
            );
            for i in 0..r {
                for j in 0..r {
                    self.k_latest[(i, j)] = k[(i, j)] - self.jg[i * r + j];
                }
            }
        }
        Ok(())
    }

    /// Factorises J = (c_a + c_v alpha) M + (1 + c_v beta) (K - dg/dq) from `self.k_latest`.
    /// The damping's tangent is taken where the stiffness is: J only steers the iteration.
    fn factorise(&mut self, ca: f64, cv: f64) {
        let rom = self.rom;
        let r = rom.rank();
        let (cm, ck) = (ca + cv * rom.alpha, 1.0 + cv * rom.beta);
        let j = DMatrix::from_fn(r, r, |i, k| {
            cm * rom.mass[(i, k)] + ck * self.k_latest[(i, k)]
        });
        self.lu = Some((j.lu(), ca, cv));
        self.report.tangents += 1;
    }

    fn substep(&mut self, s: &mut ReducedState, input: &Input, h: f64) -> Result<()> {
        let rom = self.rom;
        let r = rom.rank();
        let integrator = self.integrator;
        let tip = input.tip_force_n;
        let (ca, cv) = match integrator {
            Integrator::ImplicitEuler => (1.0 / (h * h), 1.0 / h),
            Integrator::Newmark { beta, gamma } => (1.0 / (beta * h * h), gamma / (beta * h)),
        };
        if self
            .lu
            .as_ref()
            .is_some_and(|(_, a, b)| (*a, *b) != (ca, cv))
        {
            self.lu = None;
        }
        // The damping tangent: refreshed at q_n when there is none, when it is too old, or when
        // the last step needed many iterations (the configuration moved away from it).
        let stale = self.damp_age >= rom.damping_tangent_age.max(1) || self.last_iterations > 3;
        if self.damp_age == usize::MAX || stale {
            self.external(s.q.as_slice(), &tip);
            self.sweep(s.q.as_slice(), true)?;
            self.k_damp.copy_from(&self.k_latest);
            self.damp_age = 0;
            self.factorise(ca, cv);
        }
        self.damp_age += 1;
        let qn = s.q.as_slice().to_vec();
        let (vn, an) = (s.v.as_slice().to_vec(), s.a.as_slice().to_vec());
        let kin = |q: &[f64], a: &mut [f64], v: &mut [f64]| {
            for i in 0..q.len() {
                let dq = q[i] - qn[i];
                match integrator {
                    Integrator::ImplicitEuler => {
                        a[i] = dq * ca - vn[i] / h;
                        v[i] = dq / h;
                    }
                    Integrator::Newmark { beta, gamma } => {
                        a[i] = dq * ca - vn[i] / (beta * h) - an[i] * (0.5 / beta - 1.0);
                        v[i] = vn[i] + (an[i] * (1.0 - gamma) + a[i] * gamma) * h;
                    }
                }
            }
        };
        let c2 = match (rom.predictor, integrator) {
            (Predictor::ConstantVelocity, _) => 0.0,
            (Predictor::ConstantAcceleration, Integrator::ImplicitEuler) => h * h,
            (Predictor::ConstantAcceleration, Integrator::Newmark { .. }) => 0.5 * h * h,
        };
        let mut q: Vec<f64> = (0..r).map(|i| qn[i] + h * vn[i] + c2 * an[i]).collect();
        let (mut a, mut v) = (vec![0.0; r], vec![0.0; r]);
        let mut res = vec![0.0; r];
        let mut last = f64::INFINITY;
        let mut fresh = false;
        let mut iterations = 0;
        let mut fallback = c2 != 0.0;
        for it in 0..MAX_ITERATIONS {
            kin(&q, &mut a, &mut v);
            self.external(&q, &tip);
            match self.sweep(&q, false) {
                Ok(()) => {}
                Err(_) if fallback && iterations == 0 => {
                    // The extrapolation inverted an element (a sudden change of the inputs): start
                    // from the constant-velocity predictor rather than halving the step.
                    fallback = false;
                    for i in 0..r {
                        q[i] = qn[i] + h * vn[i];
                    }
                    kin(&q, &mut a, &mut v);
                    self.external(&q, &tip);
                    self.sweep(&q, false)?;
                }
                Err(e) => return Err(e),
            }
            // Residual M a + (alpha M + beta K_d) v + f(q) - g(q).
            let (mut n_ma, mut n_f, mut n_g) = (0.0f64, 0.0f64, 0.0f64);
            for i in 0..r {
                let (mut ma, mut dv) = (0.0, 0.0);
                for k in 0..r {
                    ma += rom.mass[(i, k)] * a[k];
                    dv += (rom.alpha * rom.mass[(i, k)] + rom.beta * self.k_damp[(i, k)]) * v[k];
                }
                res[i] = ma + dv + self.f[i] - self.g[i];
                n_ma += ma * ma;
                n_f += self.f[i] * self.f[i];
                n_g += self.g[i] * self.g[i];
            }
            let scale = n_f.max(n_g).max(n_ma).sqrt();
            let rn = res.iter().map(|x| x * x).sum::<f64>().sqrt();
            if rn <= rom.rtol * scale || rn == 0.0 {
                s.q.copy_from_slice(&q);
                s.v.copy_from_slice(&v);
                s.a.copy_from_slice(&a);
                s.t += h;
                self.last_iterations = iterations;
                return Ok(());
            }
            if self.lu.is_none() || (it > 0 && rn > 0.5 * last && !fresh) {
                // No matrix, or slow contraction: refresh the iteration matrix here.
                self.sweep(&q, true)?;
                self.factorise(ca, cv);
                fresh = true;
            } else {
                fresh = false;
            }
            last = rn;
            iterations += 1;
            self.report.iterations += 1;
            let Some((lu, _, _)) = self.lu.as_ref() else {
                return Err(MorError::Solve("no iteration matrix".into()));
            };
            let mut dq = DVector::from_iterator(r, res.iter().map(|x| -x));
            if !lu.solve_mut(&mut dq) {
                return Err(MorError::Solve("singular iteration matrix".into()));
            }
            let (mut dn, mut qnorm) = (0.0, 0.0);
            for i in 0..r {
                q[i] += dq[i];
                dn += dq[i] * dq[i];
                qnorm += q[i] * q[i];
            }
            // Converged to round-off (the tolerance asked for more than f64 holds), or the update
            // is below the full solver's absolute increment tolerance.
            if dn.sqrt() <= (1e-13 * qnorm.sqrt()).max(DQ_TOL) {
                kin(&q, &mut a, &mut v);
                s.q.copy_from_slice(&q);
                s.v.copy_from_slice(&v);
                s.a.copy_from_slice(&a);
                s.t += h;
                self.last_iterations = iterations;
                return Ok(());
            }
        }
        Err(MorError::Solve(format!(
            "dynamic Newton did not converge at t = {:.4} s",
            s.t
        )))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ocm_fem::material::Material;
    use ocm_fem::mesh::generate;

    /// The stepper's stacked sweep gives the force and tangent of [`ReducedModel::internal`].
    #[test]
    fn stepper_sweep_matches_the_reference_evaluation() {
        let mesh = generate::box_mesh([3, 2, 2], [0.06, 0.02, 0.02]);
        let mut model = Model::new(&mesh, Material::neo_hookean_bulk(2e5, 0.4), 1040.0).unwrap();
        model.fix_plane([0.0; 3], [1.0, 0.0, 0.0], 1e-9);
        let on_top = |i: usize| (model.rest[i].z - 0.02).abs() < 1e-12;
        let mut tris = vec![];
        for g in &model.elements {
            for skip in 0..4 {
                let f: Vec<usize> = (0..4).filter(|&k| k != skip).map(|k| g.nodes[k]).collect();
                if f.iter().all(|&i| on_top(i)) {
                    tris.push([f[0], f[1], f[2]]);
                }
            }
        }
        model.add_pressure_surface("top", tris).unwrap();
        let n3 = 3 * model.num_nodes();
        let r = 5;
        let basis = DMatrix::from_fn(n3, r, |i, k| {
            if model.fixed[i] {
                0.0
            } else {
                ((i * 7 + k * 13) % 11) as f64 * 1e-3 - 5e-3
            }
        });
        let test = DMatrix::from_fn(n3, r, |i, k| {
            if model.fixed[i] {
                0.0
            } else {
                ((i * 5 + k * 3) % 7) as f64 * 1e-3 - 3e-3
            }
        });
        let tip = [model.num_nodes() - 1];
        for rom in [
            ReducedModel::galerkin(&model, basis.clone(), &tip).unwrap(),
            ReducedModel::petrov_galerkin(&model, basis.clone(), test.clone(), &tip).unwrap(),
        ] {
            sweep_matches_reference(&rom);
        }
    }

    fn sweep_matches_reference(rom: &ReducedModel) {
        let r = rom.rank();
        let q = DVector::from_fn(r, |i, _| 0.3 - 0.1 * i as f64);
        let reference = rom.internal(&q, true).unwrap();
        let mut st = Stepper::new(rom, Integrator::ImplicitEuler);
        let input = Input {
            pressure_kpa: [2.0, 0.0, 0.0],
            tip_force_n: [0.1, 0.0, -0.2],
        };
        st.set_pressure(&input);
        st.external(q.as_slice(), &input.tip_force_n);
        let (g, jg) = rom.external(&q, &input, true);
        let jg = jg.unwrap();
        for i in 0..r {
            assert!((st.g[i] - g[i]).abs() <= 1e-10 * g.norm(), "g[{i}]");
            for j in 0..r {
                assert!(
                    (st.jg[i * r + j] - jg[(i, j)]).abs() <= 1e-10 * jg.norm(),
                    "jg[{i},{j}]"
                );
            }
        }
        let kref = reference.k.clone().unwrap() - &jg;
        // k_latest is the derivative of f - g (central differences).
        st.sweep(q.as_slice(), true).unwrap();
        let kl = st.k_latest.clone();
        let eps = 1e-7;
        for j in 0..r {
            let mut fd = [vec![0.0; r], vec![0.0; r]];
            for (side, sign) in [(0, 1.0), (1, -1.0)] {
                let mut qq = q.clone();
                qq[j] += sign * eps;
                st.external(qq.as_slice(), &input.tip_force_n);
                st.sweep(qq.as_slice(), false).unwrap();
                fd[side] = (0..r).map(|i| st.f[i] - st.g[i]).collect();
            }
            for i in 0..r {
                let d = (fd[0][i] - fd[1][i]) / (2.0 * eps);
                assert!(
                    (d - kl[(i, j)]).abs() <= 1e-5 * kl.norm(),
                    "dR[{i}]/dq[{j}]: {d} vs {}",
                    kl[(i, j)]
                );
            }
        }
        st.external(q.as_slice(), &input.tip_force_n);
        st.sweep(q.as_slice(), true).unwrap();
        for i in 0..r {
            assert!((st.f[i] - reference.f_int[i]).abs() <= 1e-10 * reference.f_int.norm());
            for j in 0..r {
                assert!(
                    (st.k_latest[(i, j)] - kref[(i, j)]).abs() <= 1e-10 * kref.norm(),
                    "K[{i},{j}] {} vs {}",
                    st.k_latest[(i, j)],
                    kref[(i, j)]
                );
            }
        }
    }

    /// With the penalty, the elements inside the rigid end resist a non-rigid motion of its
    /// nodes in proportion to the penalty (without it, a stretch of the body alone costs no strain
    /// energy at all); a rigid translation still costs nothing there.
    #[test]
    fn body_penalty_stiffens_only_non_rigid_body_motion() {
        let mesh = generate::box_mesh([4, 2, 2], [0.08, 0.02, 0.02]);
        let mut model = Model::new(&mesh, Material::neo_hookean_bulk(2e5, 0.4), 1040.0).unwrap();
        model.fix_plane([0.0; 3], [1.0, 0.0, 0.0], 1e-9);
        model.add_rigid_body("end", |p| p.x >= 0.06 - 1e-9).unwrap();
        let inside = body_elements(&model);
        assert!(!inside.is_empty());
        let n3 = 3 * model.num_nodes();
        let on_body = |i: usize| model.rest[i / 3].x >= 0.06 - 1e-9;
        // Column 0: stretch the body along x (non-rigid); column 1: translate it along y.
        let basis = DMatrix::from_fn(n3, 2, |i, k| match (k, i % 3) {
            (0, 0) if on_body(i) => model.rest[i / 3].x - 0.06,
            (1, 1) if on_body(i) => 1.0,
            _ => 0.0,
        });
        let energy = |penalty: Option<f64>, q: [f64; 2]| {
            let rom =
                ReducedModel::galerkin_with_body_penalty(&model, basis.clone(), &[0], penalty)
                    .unwrap();
            rom.internal(&DVector::from_row_slice(&q), false)
                .unwrap()
                .energy
        };
        let stretch = [1e-3, 0.0];
        let (e0, e50, e100) = (
            energy(None, stretch),
            energy(Some(50.0), stretch),
            energy(Some(100.0), stretch),
        );
        // The stretch starts at the body's first layer: only the body's own elements strain.
        assert!(e50 > 0.0 && e0.abs() <= 1e-9 * e50, "{e0} {e50}");
        assert!(((e100 - e0) / (e50 - e0) - 2.0).abs() < 1e-9);
        let shift = [0.0, 1e-4];
        let (t0, t50) = (energy(None, shift), energy(Some(50.0), shift));
        assert!(t0 > 0.0 && (t50 - t0).abs() <= 1e-9 * t0, "{t0} {t50}");
        let bad = ReducedModel::galerkin_with_body_penalty(&model, basis.clone(), &[0], Some(0.0));
        assert!(bad.is_err());
    }
}
