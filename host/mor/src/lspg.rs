//! Least-squares Petrov-Galerkin (LSPG) steps of the reduced model u = V q, without
//! hyper-reduction: each implicit step minimises the full model's own step residual.
//!
//! Galerkin solves V^T R(V q) = 0; LSPG solves min_q ||R(V q)||_2 for the backward-Euler residual
//! R of the full solver (M a + (alpha M + beta K_n) v + f_int - f_ext on the solver's DOFs: the
//! free node DOFs, then per unclamped rigid body the resultant force and the moment about its
//! reference point, the moments divided by the body's radius of gyration so that every row is a
//! force). Gauss-Newton with the Jacobian at the current iterate, J = (c_a M + c_v D + K(x)) V_s,
//! makes the normal equations (J V_s)^T R = 0 at convergence, i.e. Petrov-Galerkin with the test
//! basis W = J V_s that changes with the state (Carlberg et al. 2011, 2017).
//!
//! V_s is V on the solver's DOFs: the free node rows of V as they are, and for each rigid body the
//! mass-weighted rigid fit (translation of the reference point, rotation vector) of V's motion of
//! the body's nodes at the current positions. The residual is evaluated exactly at the nodal
//! positions X + V q (which hold the body to first order only); the Jacobian maps an increment of
//! q through the fit, so it is exact for a model without rigid bodies and a first-order
//! approximation on the bodies' rows otherwise (Gauss-Newton then converges to where
//! (J V_s)^T R = 0 for that J). Every iteration assembles the full model's tangent: the cost of a
//! step grows with the mesh (about as much as a full step, more at high rank). This is the
//! accuracy experiment that decides whether sampled-residual hyper-reduction (GNAT) is worth
//! building; the crate README has the figures.
//!
//! On the bellows the assembled Jacobian is not good enough (the POD modes move the rigid top
//! frame's nodes rigidly only to first order, and the remainder meets the stiff elements around
//! it), so the measured variants take the Jacobian by forward differences
//! ([`LspgOptions::finite_difference_jacobian`]); [`Lspg::weight_by_rest_step_matrix`] minimises
//! ||J0^-1 R|| instead of ||R||, the variant that beats Galerkin there.

use crate::drive::Input;
use crate::full::tip_point_forces;
use crate::rom::{ReducedState, ReducedStepReport};
use crate::run::ReducedRun;
use crate::store::ReducedProbe;
use crate::{MorError, Result};
use nalgebra::{DMatrix, DVector, Matrix3, Vector3};
use ocm_fem::model::{Loads, Model, Pattern};
use ocm_fem::solve::linear::SparseSolver;

/// Stopping rules of the Gauss-Newton iteration of one LSPG step.
#[derive(Debug, Clone, Copy)]
pub struct LspgOptions {
    /// Gauss-Newton iterations before the step is halved.
    pub max_iterations: usize,
    /// Converged when the residual norm is below `rtol` times the force scale (the full solver's
    /// test: reached where V spans the full solution).
    pub rtol: f64,
    /// Converged when the cosine between the residual and the range of the Jacobian,
    /// ||J^T R|| / (||J||_F ||R||), is below this (the LSPG stationarity condition).
    pub gtol: f64,
    /// Converged when the accepted increment is below `xtol` times ||q - q_n|| or below 1e-12 (in
    /// the units of q, the full solver's absolute increment tolerance).
    pub xtol: f64,
    /// Step halvings of the line search on ||R||.
    pub max_backtracks: usize,
    /// Jacobian by forward differences of the residual (r more residual evaluations per
    /// iteration) instead of the assembled tangent through V_s: exact for the residual as
    /// evaluated, including the rigid bodies' rows where V moves a body's nodes non-rigidly.
    pub finite_difference_jacobian: bool,
}

impl Default for LspgOptions {
    fn default() -> Self {
        LspgOptions {
            max_iterations: 40,
            rtol: 1e-6,
            gtol: 1e-6,
            xtol: 1e-6,
            max_backtracks: 8,
            finite_difference_jacobian: false,
        }
    }
}

/// The start of a step: q_n, q'_n, the step's loads and the Rayleigh damping matrix frozen at
/// q_n (CSC values on the solver's pattern), as the full solver freezes it.
struct StepStart {
    qn: DVector<f64>,
    vn: DVector<f64>,
    h: f64,
    loads: Loads,
    damp: Vec<f64>,
}

/// An LSPG reduced model of a full FE model on a basis V (3N x r).
pub struct Lspg {
    model: Model,
    pat: Pattern,
    tip_nodes: Vec<usize>,
    /// The trial basis V, 3N x r.
    pub basis: DMatrix<f64>,
    rest: Vec<f64>,
    /// Row weights of the residual: 1 on forces, 1 / radius of gyration on body moments.
    row_weight: Vec<f64>,
    /// Per unclamped body (in the pattern's order): its nodes and their lumped masses.
    bodies: Vec<(Vec<usize>, Vec<f64>)>,
    /// The residual's weighting: the factor of the step matrix at rest J0 (minimise ||J0^-1 R||,
    /// scaled to metres) when set; `None`: the Euclidean norm of the forces.
    weight: Option<SparseSolver>,
    /// Stopping rules.
    pub options: LspgOptions,
    /// Gauss-Newton iterations and tangent assemblies so far.
    pub report: ReducedStepReport,
}

/// y = A X for the CSC values `vals` on `pat` (full pattern) and X row-major n x r.
fn csc_times(pat: &Pattern, vals: &[f64], x: &[f64], r: usize) -> Vec<f64> {
    let n = pat.num_free();
    let mut y = vec![0.0; n * r];
    for j in 0..n {
        let xj = &x[j * r..(j + 1) * r];
        for p in pat.col_ptr[j]..pat.col_ptr[j + 1] {
            let (i, a) = (pat.row_idx[p], vals[p]);
            let yi = &mut y[i * r..(i + 1) * r];
            for (yk, xk) in yi.iter_mut().zip(xj) {
                *yk += a * xk;
            }
        }
    }
    y
}

impl Lspg {
    /// LSPG of `model` on `basis` (3N x r, zero on the fixed DOFs); the tip force of an input acts
    /// on `tip_nodes` in equal parts.
    pub fn new(model: &Model, basis: DMatrix<f64>, tip_nodes: &[usize]) -> Result<Self> {
        let n3 = 3 * model.num_nodes();
        if basis.nrows() != n3 || basis.ncols() == 0 {
            return Err(MorError::Invalid(format!(
                "basis is {} x {}, the model has {n3} DOFs",
                basis.nrows(),
                basis.ncols()
            )));
        }
        if basis.iter().any(|v| !v.is_finite()) {
            return Err(MorError::Invalid("basis holds a non-finite value".into()));
        }
        if tip_nodes.is_empty() || tip_nodes.iter().any(|&i| i >= model.num_nodes()) {
            return Err(MorError::Invalid(format!(
                "tip nodes must be non-empty and below {}",
                model.num_nodes()
            )));
        }
        let vmax = basis.amax();
        for d in (0..n3).filter(|&d| model.fixed[d]) {
            if basis.row(d).amax() > 1e-12 * vmax {
                return Err(MorError::Invalid(format!(
                    "basis moves fixed DOF {d} (node {}, axis {})",
                    d / 3,
                    d % 3
                )));
            }
        }
        let pat = Pattern::new(model)?;
        let masses = model.nodal_masses();
        let mut row_weight = vec![1.0; pat.num_free()];
        let mut bodies = vec![];
        for b in &pat.bodies {
            let s = 1.0 / b.radius_m.max(f64::MIN_POSITIVE);
            for w in &mut row_weight[b.first + 3..b.first + 6] {
                *w = s;
            }
            let nodes = model.rigid_bodies[b.body].nodes.clone();
            let m = nodes.iter().map(|&i| masses[i]).collect();
            bodies.push((nodes, m));
        }
        Ok(Lspg {
            model: model.clone(),
            pat,
            tip_nodes: tip_nodes.to_vec(),
            basis,
            rest: model.rest_dofs(),
            row_weight,
            bodies,
            weight: None,
            options: LspgOptions::default(),
            report: ReducedStepReport::default(),
        })
    }

    /// Weights the residual by the inverse of the backward-Euler step matrix at rest for steps of
    /// `h` seconds, J0 = (1/h^2 + alpha/h) M + (1 + beta/h) K0 (K0 the tangent at rest, no
    /// pressure): LSPG then minimises ||J0^-1 R(V q)||, the step's error in displacement as J0
    /// sees it, whose minimiser in the linear range with J = J0 is the Euclidean projection of the
    /// full step (body rotations scaled by the radius of gyration to metres). The Jacobian must
    /// then be taken by differences.
    pub fn weight_by_rest_step_matrix(&mut self, h: f64) -> Result<()> {
        if !(h.is_finite() && h > 0.0) {
            return Err(MorError::Invalid(format!(
                "time step must be positive and finite, got {h}"
            )));
        }
        let loads = Loads {
            pressures_pa: vec![0.0; self.model.cavities.len()],
        };
        let mut model = self.model.clone();
        model.point_forces.clear();
        let k = model
            .evaluate(&self.pat, &self.rest, &loads, 1.0, true)?
            .tangent
            .ok_or_else(|| MorError::Solve("the model gave no tangent".into()))?;
        let m = model.mass_values_at(&self.pat, &self.rest);
        let (cm, ck) = (
            1.0 / (h * h) + model.rayleigh_alpha / h,
            1.0 + model.rayleigh_beta / h,
        );
        let j0: Vec<f64> = m.iter().zip(&k).map(|(m, k)| cm * m + ck * k).collect();
        let mut solver = SparseSolver::new(
            self.pat.num_free(),
            self.pat.col_ptr.clone(),
            self.pat.row_idx.clone(),
        );
        solver.factorize(&j0)?;
        // Rows of J0^-1 R: metres on translations, radians on rotations (times the radius).
        self.row_weight = vec![1.0; self.pat.num_free()];
        for b in &self.pat.bodies {
            for w in &mut self.row_weight[b.first + 3..b.first + 6] {
                *w = b.radius_m;
            }
        }
        self.weight = Some(solver);
        self.options.finite_difference_jacobian = true;
        Ok(())
    }

    /// Rank r.
    pub fn rank(&self) -> usize {
        self.basis.ncols()
    }

    /// Residual rows (the solver's DOFs).
    pub fn rows(&self) -> usize {
        self.pat.num_free()
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

    /// Nodal positions X + V q (fixed DOFs at their prescribed values).
    fn positions(&self, q: &DVector<f64>) -> Vec<f64> {
        let u = &self.basis * q;
        let mut x: Vec<f64> = self.rest.iter().zip(u.iter()).map(|(a, b)| a + b).collect();
        for (d, xd) in x.iter_mut().enumerate() {
            if self.model.fixed[d] {
                *xd = self.rest[d] + self.model.prescribed[d];
            }
        }
        x
    }

    /// V on the solver's DOFs at positions `x`, row-major (rows x r).
    fn solver_basis(&self, x: &[f64]) -> Vec<f64> {
        let r = self.rank();
        let mut vs = vec![0.0; self.rows() * r];
        for (j, &d) in self.pat.dof_of.iter().enumerate() {
            for k in 0..r {
                vs[j * r + k] = self.basis[(d, k)];
            }
        }
        let centers = self.pat.body_centers(x);
        for ((bd, (nodes, m)), c) in self.pat.bodies.iter().zip(&self.bodies).zip(&centers) {
            let mtot: f64 = m.iter().sum();
            let rel: Vec<Vector3<f64>> = nodes
                .iter()
                .map(|&i| Vector3::new(x[3 * i], x[3 * i + 1], x[3 * i + 2]) - c)
                .collect();
            let mut inertia = Matrix3::zeros();
            for (ri, mi) in rel.iter().zip(m) {
                inertia += (Matrix3::identity() * ri.norm_squared() - ri * ri.transpose()) * *mi;
            }
            let inv = inertia.try_inverse().unwrap_or_else(Matrix3::zeros);
            for k in 0..r {
                let (mut lin, mut ang) = (Vector3::zeros(), Vector3::zeros());
                for ((&i, ri), mi) in nodes.iter().zip(&rel).zip(m) {
                    let w = Vector3::new(
                        self.basis[(3 * i, k)],
                        self.basis[(3 * i + 1, k)],
                        self.basis[(3 * i + 2, k)],
                    );
                    lin += w * *mi;
                    ang += ri.cross(&w) * *mi;
                }
                let th = inv * ang;
                for a in 0..3 {
                    vs[(bd.first + a) * r + k] = lin[a] / mtot;
                    vs[(bd.first + 3 + a) * r + k] = th[a];
                }
            }
        }
        vs
    }

    fn start(&mut self, s: &ReducedState, input: &Input, h: f64) -> Result<StepStart> {
        if !(h.is_finite() && h > 0.0) {
            return Err(MorError::Invalid(format!(
                "time step must be positive and finite, got {h}"
            )));
        }
        if s.q.len() != self.rank() || s.v.len() != self.rank() {
            return Err(MorError::Invalid(format!(
                "state has {} coordinates, the model rank {}",
                s.q.len(),
                self.rank()
            )));
        }
        if input
            .pressure_kpa
            .iter()
            .chain(&input.tip_force_n)
            .any(|v| !v.is_finite())
        {
            return Err(MorError::Invalid(format!(
                "input at t = {:.4} s holds a non-finite value",
                s.t
            )));
        }
        let loads = Loads {
            pressures_pa: (0..self.model.cavities.len())
                .map(|c| input.pressure_kpa.get(c).copied().unwrap_or(0.0) * 1e3)
                .collect(),
        };
        self.model.point_forces = tip_point_forces(&self.tip_nodes, input.tip_force_n);
        let xn = self.positions(&s.q);
        let k = self
            .model
            .evaluate(&self.pat, &xn, &loads, 1.0, true)?
            .tangent
            .ok_or_else(|| MorError::Solve("the model gave no tangent".into()))?;
        self.report.tangents += 1;
        let m = self.model.mass_values_at(&self.pat, &xn);
        let (alpha, beta) = (self.model.rayleigh_alpha, self.model.rayleigh_beta);
        let damp = m
            .iter()
            .zip(&k)
            .map(|(m, k)| alpha * m + beta * k)
            .collect();
        Ok(StepStart {
            qn: s.q.clone(),
            vn: s.v.clone(),
            h,
            loads,
            damp,
        })
    }

    /// The weighted step residual at `q`, the force scale of the full solver's test and, when
    /// asked, the weighted Jacobian (rows x r).
    fn eval(
        &mut self,
        st: &StepStart,
        q: &DVector<f64>,
        jacobian: bool,
    ) -> Result<(DVector<f64>, f64, Option<DMatrix<f64>>)> {
        let (h, r) = (st.h, self.rank());
        let (ca, cv) = (1.0 / (h * h), 1.0 / h);
        let dq = q - &st.qn;
        let aq = &dq * ca - &st.vn * cv;
        let vq = &dq * cv;
        let x = self.positions(q);
        let a_nodal = &self.basis * &aq;
        let ma = self.model.mass_times(a_nodal.as_slice());
        let mut res = self.pat.reduce(&x, &ma);
        let vs = self.solver_basis(&x);
        let vsv: Vec<f64> = (0..self.rows())
            .map(|j| {
                let row = &vs[j * r..(j + 1) * r];
                row.iter().zip(vq.iter()).map(|(a, b)| a * b).sum()
            })
            .collect();
        let vel = csc_times(&self.pat, &st.damp, &vsv, 1);
        let ev = self
            .model
            .evaluate(&self.pat, &x, &st.loads, 1.0, jacobian)?;
        for ((rj, dj), ej) in res.iter_mut().zip(&vel).zip(&ev.residual) {
            *rj += dj + ej;
        }
        let norm = |v: &[f64]| v.iter().map(|a| a * a).sum::<f64>().sqrt();
        let scale = norm(&ev.f_int).max(norm(&ev.f_ext)).max(norm(&ma));
        let scale = if let Some(f) = &self.weight {
            // The weighted residual is a displacement: compared with the step's own.
            f.solve_factored(&mut res)?;
            dq.norm()
        } else {
            scale
        };
        for (rj, w) in res.iter_mut().zip(&self.row_weight) {
            *rj *= w;
        }
        let jac = if jacobian && self.weight.is_none() {
            self.report.tangents += 1;
            let k = ev
                .tangent
                .ok_or_else(|| MorError::Solve("the model gave no tangent".into()))?;
            let m = self.model.mass_values_at(&self.pat, &x);
            let vals: Vec<f64> = k
                .iter()
                .zip(&m)
                .zip(&st.damp)
                .map(|((k, m), d)| ca * m + cv * d + k)
                .collect();
            let jv = csc_times(&self.pat, &vals, &vs, r);
            let w = &self.row_weight;
            Some(DMatrix::from_fn(self.rows(), r, |i, k| {
                jv[i * r + k] * w[i]
            }))
        } else {
            None
        };
        Ok((DVector::from_vec(res), scale, jac))
    }

    /// The Jacobian at `q` (whose residual is `res`): assembled, or by forward differences.
    fn jacobian(
        &mut self,
        st: &StepStart,
        q: &DVector<f64>,
        res: &DVector<f64>,
    ) -> Result<DMatrix<f64>> {
        if !self.options.finite_difference_jacobian && self.weight.is_none() {
            let (_, _, jac) = self.eval(st, q, true)?;
            return jac.ok_or_else(|| MorError::Solve("no Jacobian".into()));
        }
        self.report.tangents += 1;
        let e = 1e-7 * q.norm().max(1e-3);
        let mut jac = DMatrix::zeros(self.rows(), self.rank());
        for k in 0..self.rank() {
            let mut qk = q.clone();
            qk[k] += e;
            let (rk, _, _) = self.eval(st, &qk, false)?;
            jac.set_column(k, &((rk - res) / e));
        }
        Ok(jac)
    }

    /// The weighted backward-Euler residual of a step of `h` seconds from `start` under `input`,
    /// evaluated at `q` (moments divided by the bodies' radii of gyration), and its Gauss-Newton
    /// Jacobian (rows x r). LSPG's step is the minimiser of this residual's norm.
    pub fn residual(
        &mut self,
        start: &ReducedState,
        input: &Input,
        h: f64,
        q: &DVector<f64>,
    ) -> Result<(DVector<f64>, DMatrix<f64>)> {
        let st = self.start(start, input, h)?;
        let (res, _, _) = self.eval(&st, q, false)?;
        let jac = self.jacobian(&st, q, &res)?;
        Ok((res, jac))
    }

    /// One backward-Euler step of `h` seconds under `input` (held over the step); halves the step
    /// (up to 4 times) when Gauss-Newton fails. Returns the iterations of this step.
    pub fn step(
        &mut self,
        s: &mut ReducedState,
        input: &Input,
        h: f64,
    ) -> Result<ReducedStepReport> {
        let before = self.report;
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
                self.step_cut(s, input, h / 2.0, depth + 1)?;
                self.step_cut(s, input, h / 2.0, depth + 1)
            }
            Err(e) => Err(e),
        }
    }

    fn substep(&mut self, s: &mut ReducedState, input: &Input, h: f64) -> Result<()> {
        let st = self.start(s, input, h)?;
        let opts = self.options;
        let mut q = &st.qn + &st.vn * h;
        let (mut res, mut scale, _) = self.eval(&st, &q, false)?;
        let finish = |s: &mut ReducedState, q: &DVector<f64>| {
            let dq = q - &st.qn;
            s.a = (&dq / h - &st.vn) / h;
            s.v = dq / h;
            s.q = q.clone();
            s.t += h;
        };
        for _ in 0..opts.max_iterations {
            let rn = res.norm();
            if rn <= opts.rtol * scale || rn == 0.0 {
                finish(s, &q);
                return Ok(());
            }
            let jac = self.jacobian(&st, &q, &res)?;
            let g = jac.tr_mul(&res);
            if g.norm() <= opts.gtol * jac.norm() * rn {
                finish(s, &q);
                return Ok(());
            }
            self.report.iterations += 1;
            let n = jac.tr_mul(&jac);
            let dq = match n.clone().cholesky() {
                Some(c) => c.solve(&(-&g)),
                None => n
                    .lu()
                    .solve(&(-&g))
                    .ok_or_else(|| MorError::Solve("singular Gauss-Newton matrix".into()))?,
            };
            let mut alpha = 1.0;
            let mut accepted = None;
            for _ in 0..=opts.max_backtracks {
                let qt = &q + &dq * alpha;
                if let Ok((rt, sc, _)) = self.eval(&st, &qt, false)
                    && rt.norm() < rn
                {
                    accepted = Some((qt, rt, sc));
                    break;
                }
                alpha *= 0.5;
            }
            let Some((qt, rt, sc)) = accepted else {
                // At the minimum to round-off no trial lowers ||R||: the predicted decrease
                // -g.dq is then negligible against ||R||^2.
                if -g.dot(&dq) <= 1e-12 * rn * rn {
                    finish(s, &q);
                    return Ok(());
                }
                return Err(MorError::Solve(format!(
                    "LSPG line search failed at t = {:.4} s (residual {rn:.3e} N)",
                    s.t
                )));
            };
            let step = alpha * dq.norm();
            let moved = (&qt - &st.qn).norm();
            (q, res, scale) = (qt, rt, sc);
            if step <= (opts.xtol * moved).max(1e-12) {
                finish(s, &q);
                return Ok(());
            }
        }
        Err(MorError::Solve(format!(
            "LSPG Gauss-Newton did not converge at t = {:.4} s",
            s.t
        )))
    }

    /// Runs from rest over `inputs` with steps of `dt_s`; X_S through `probe` (a probe of a
    /// reduced model on the same basis).
    pub fn simulate(
        &mut self,
        probe: &ReducedProbe,
        inputs: &[Input],
        dt_s: f64,
    ) -> Result<ReducedRun> {
        let mut s = self.rest_state();
        let before = self.report;
        let mut xs = Vec::with_capacity(inputs.len());
        let mut step_seconds = Vec::with_capacity(inputs.len());
        for inp in inputs {
            let t0 = std::time::Instant::now();
            self.step(&mut s, inp, dt_s)?;
            step_seconds.push(t0.elapsed().as_secs_f64());
            xs.push(probe.compact_state(&s.q, &s.v));
        }
        Ok(ReducedRun {
            xs,
            step_seconds,
            report: ReducedStepReport {
                iterations: self.report.iterations - before.iterations,
                tangents: self.report.tangents - before.tangents,
            },
        })
    }
}
