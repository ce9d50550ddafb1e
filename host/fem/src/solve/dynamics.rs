//! Implicit time integration of M a + D v + f_int(x) = f_ext(x) (eq 2.2): backward Euler and Newmark.

use super::linear::SparseSolver;
use super::{NewtonOptions, norm, spmv};
use crate::model::{BodyState, Loads, Model, Pattern, State};
use crate::rigid::log_rotation;
use crate::{FemError, Result};
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

/// Time integrator.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Integrator {
    /// Backward (implicit) Euler, first order, numerically dissipative (SOFA's EulerImplicitSolver).
    ImplicitEuler,
    /// Newmark-beta; beta = 1/4, gamma = 1/2 is the energy-conserving average-acceleration rule.
    Newmark {
        /// beta.
        beta: f64,
        /// gamma.
        gamma: f64,
    },
}

impl Integrator {
    /// Average-acceleration Newmark.
    pub const AVERAGE_ACCELERATION: Integrator = Integrator::Newmark {
        beta: 0.25,
        gamma: 0.5,
    };
}

/// What one time step did.
#[derive(Debug, Clone, Default, Serialize)]
pub struct StepReport {
    /// Newton iterations.
    pub iterations: usize,
    /// Sub-steps taken (1 unless the step was cut).
    pub substeps: usize,
    /// Final residual, N.
    pub residual: f64,
    /// Factorizations of the iteration matrix (modified Newton reuses one while it converges fast).
    pub factorizations: usize,
}

/// Residual ratio per iteration above which the iteration matrix is refreshed at the current point.
const SLOW_CONTRACTION: f64 = 0.5;

/// Factorizes J = ca M + cv D + K into `linear`.
fn factorize_jacobian(
    linear: &mut SparseSolver,
    mass: &[f64],
    k: &[f64],
    ca: f64,
    cv: f64,
    damp: &[f64],
) -> Result<()> {
    let jac: Vec<f64> = k
        .iter()
        .zip(mass)
        .zip(damp)
        .map(|((k, m), d)| ca * m + cv * d + k)
        .collect();
    linear.factorize(&jac)
}

/// Dynamic solver with cached structure, mass and symbolic factorization.
///
/// Rigid bodies move in reduced coordinates: the Newmark (or Euler) formulas act on the reference
/// point and, for the rotation, on the spatial incremental rotation vector
/// Theta = log(R_{n+1} R_n^T) with the angular velocity and acceleration in place of v and a
/// (a Lie-group Newmark, second order). The residual is T^T (M a + f_int - f_ext) + D_r qdot with
/// the exact slave accelerations a_i = a_c + alpha x r_i + w x (w x r_i); the iteration matrix
/// drops the gyroscopic terms, which modified Newton tolerates.
#[derive(Debug, Clone)]
pub struct DynamicSolver {
    /// Sparse structure.
    pub pattern: Pattern,
    linear: SparseSolver,
    mass: Vec<f64>,
    /// Integrator.
    pub integrator: Integrator,
    /// Newton controls.
    pub options: NewtonOptions,
    initialized: bool,
    /// (ca, cv) of the iteration matrix whose factor `linear` holds, if any: later steps of the
    /// same size start their modified Newton from it.
    factor_coeffs: Option<(f64, f64)>,
}

/// Acceleration and velocity at the end of a step of length `h` from the increment `dx` and the
/// start values `v0`, `a0` (per component; also for rotation vectors).
fn kinematics(integrator: Integrator, h: f64, dx: f64, v0: f64, a0: f64) -> (f64, f64) {
    match integrator {
        Integrator::ImplicitEuler => (dx / (h * h) - v0 / h, dx / h),
        Integrator::Newmark { beta, gamma } => {
            let a = dx / (beta * h * h) - v0 / (beta * h) - (0.5 / beta - 1.0) * a0;
            (a, v0 + h * ((1.0 - gamma) * a0 + gamma * a))
        }
    }
}

/// Vector form of [`kinematics`].
fn kinematics3(
    integrator: Integrator,
    h: f64,
    dx: Vector3<f64>,
    v0: Vector3<f64>,
    a0: Vector3<f64>,
) -> (Vector3<f64>, Vector3<f64>) {
    let mut out = (Vector3::zeros(), Vector3::zeros());
    for k in 0..3 {
        (out.0[k], out.1[k]) = kinematics(integrator, h, dx[k], v0[k], a0[k]);
    }
    out
}

impl DynamicSolver {
    /// Prepares the solver.
    pub fn new(model: &Model, integrator: Integrator) -> Result<Self> {
        if let Integrator::Newmark { beta, gamma } = integrator
            && !(beta > 0.0 && gamma >= 0.0 && beta.is_finite() && gamma.is_finite())
        {
            return Err(FemError::Model(format!(
                "Newmark needs beta > 0, gamma >= 0 (got {beta}, {gamma})"
            )));
        }
        let pattern = Pattern::new(model)?;
        let linear = SparseSolver::new(
            pattern.num_free(),
            pattern.col_ptr.clone(),
            pattern.row_idx.clone(),
        );
        let mass = model.mass_values(&pattern);
        Ok(DynamicSolver {
            pattern,
            linear,
            mass,
            integrator,
            options: NewtonOptions::default(),
            initialized: false,
            factor_coeffs: None,
        })
    }

    /// Kinetic energy 1/2 v^T M v, J (slave velocities are those of their bodies).
    pub fn kinetic_energy(model: &Model, state: &State) -> f64 {
        let mv = model.mass_times(&state.v);
        0.5 * mv.iter().zip(&state.v).map(|(a, b)| a * b).sum::<f64>()
    }

    /// Reduced mass matrix at positions `x` (constant without rigid bodies).
    fn mass_at(&self, model: &Model, x: &[f64]) -> Vec<f64> {
        if self.pattern.bodies.is_empty() {
            self.mass.clone()
        } else {
            model.mass_values_at(&self.pattern, x)
        }
    }

    /// Advances `state` by `dt` seconds; halves the step (up to the minimum fraction) on failure.
    pub fn step(
        &mut self,
        model: &Model,
        state: &mut State,
        loads: &Loads,
        dt: f64,
    ) -> Result<StepReport> {
        if !(dt > 0.0 && dt.is_finite()) {
            return Err(FemError::Model(format!("time step {dt} must be positive")));
        }
        model.check_bodies(state)?;
        if state.x.len() != 3 * model.num_nodes()
            || state.v.len() != state.x.len()
            || state.a.len() != state.x.len()
        {
            return Err(FemError::Model("state does not match the model".into()));
        }
        if !self.initialized {
            model.rest_clamped(&self.pattern, state);
            model.place_bodies(state)?;
            self.initial_acceleration(model, state, loads)?;
            self.initialized = true;
        }
        let mut rep = StepReport::default();
        let mut remaining = dt;
        let mut h = dt;
        while remaining > 1e-15 * dt {
            h = h.min(remaining);
            let saved = state.clone();
            let result = self.substep(model, state, loads, h, &mut rep);
            if result.is_err() {
                self.factor_coeffs = None;
            }
            match result {
                Ok(()) => {
                    remaining -= h;
                    rep.substeps += 1;
                }
                Err(e) => {
                    *state = saved;
                    h *= 0.5;
                    if h < self.options.min_step * dt {
                        return Err(match e {
                            FemError::NoConvergence { residual, .. } => FemError::NoConvergence {
                                what: format!("time step at t = {:.6} s", state.t),
                                load_fraction: 1.0 - remaining / dt,
                                residual,
                                step: h,
                            },
                            other => other,
                        });
                    }
                }
            }
        }
        Ok(rep)
    }

    /// a0 = M^-1 (f_ext - f_int - D v0) (reduced, with the bodies' centripetal terms) so that
    /// Newmark starts consistently.
    fn initial_acceleration(
        &mut self,
        model: &Model,
        state: &mut State,
        loads: &Loads,
    ) -> Result<()> {
        let pat = &self.pattern;
        let ev = model.evaluate(pat, &state.x, loads, 1.0, true)?;
        let k = ev
            .tangent
            .as_ref()
            .ok_or_else(|| FemError::Linear("tangent missing".into()))?;
        let mass = self.mass_at(model, &state.x);
        let vr = pat.reduced_velocity(state);
        let mv = spmv(pat, &mass, &vr);
        let kv = spmv(pat, k, &vr);
        // Inertia of the body spin alone: slave accelerations w x (w x r_i).
        let mut a_spin = vec![0.0; state.x.len()];
        for (b, c) in pat.bodies.iter().zip(pat.body_centers(&state.x)) {
            let w = state.bodies[b.body].angular_velocity;
            for &i in &b.nodes {
                let r = Vector3::new(state.x[3 * i], state.x[3 * i + 1], state.x[3 * i + 2]) - c;
                let a = w.cross(&w.cross(&r));
                a_spin[3 * i..3 * i + 3].copy_from_slice(a.as_slice());
            }
        }
        let spin = pat.reduce(&state.x, &model.mass_times(&a_spin));
        let mut rhs: Vec<f64> = (0..pat.num_free())
            .map(|j| {
                -ev.residual[j]
                    - spin[j]
                    - model.rayleigh_alpha * mv[j]
                    - model.rayleigh_beta * kv[j]
            })
            .collect();
        self.factor_coeffs = None;
        self.linear.solve(&mass, &mut rhs)?;
        state.a = vec![0.0; state.x.len()];
        for (j, &d) in pat.dof_of.iter().enumerate() {
            state.a[d] = rhs[j];
        }
        for b in &pat.bodies {
            let f = b.first;
            let bs = &mut state.bodies[b.body];
            bs.acceleration = Vector3::new(rhs[f], rhs[f + 1], rhs[f + 2]);
            bs.angular_acceleration = Vector3::new(rhs[f + 3], rhs[f + 4], rhs[f + 5]);
        }
        model.place_bodies(state)
    }

    fn substep(
        &mut self,
        model: &Model,
        state: &mut State,
        loads: &Loads,
        h: f64,
        rep: &mut StepReport,
    ) -> Result<()> {
        let integrator = self.integrator;
        let (ca, cv) = match integrator {
            Integrator::ImplicitEuler => (1.0 / (h * h), 1.0 / h),
            Integrator::Newmark { beta, gamma } => (1.0 / (beta * h * h), gamma / (beta * h)),
        };
        let xn = state.x.clone();
        let vn = state.v.clone();
        let an = state.a.clone();
        let bn = state.bodies.clone();
        // Rigid-body end-of-step motion from a trial configuration (bodies moved, velocities and
        // accelerations filled in from the Lie-group Newmark formulas).
        let body_motion = |bodies: &[BodyState]| -> Vec<BodyState> {
            let mut out = bodies.to_vec();
            for b in &self.pattern.bodies {
                let (s, s0) = (&mut out[b.body], &bn[b.body]);
                let dc = s.center - s0.center;
                let theta = log_rotation(&(s.rotation * s0.rotation.inverse()));
                (s.acceleration, s.velocity) =
                    kinematics3(integrator, h, dc, s0.velocity, s0.acceleration);
                (s.angular_acceleration, s.angular_velocity) = kinematics3(
                    integrator,
                    h,
                    theta,
                    s0.angular_velocity,
                    s0.angular_acceleration,
                );
            }
            out
        };
        // Full accelerations (free nodes by Newmark, slaves rigid, fixed zero) and reduced
        // velocities of a trial point.
        let motion = |x: &[f64], bodies: &[BodyState]| -> (Vec<f64>, Vec<f64>) {
            let pat = &self.pattern;
            let mut a = vec![0.0; x.len()];
            let mut vr = Vec::with_capacity(pat.num_free());
            for &d in &pat.dof_of {
                let (ad, vd) = kinematics(integrator, h, x[d] - xn[d], vn[d], an[d]);
                a[d] = ad;
                vr.push(vd);
            }
            let moved = body_motion(bodies);
            for b in &pat.bodies {
                let s = &moved[b.body];
                vr.extend(s.velocity.iter().chain(s.angular_velocity.iter()));
                let (w, al) = (s.angular_velocity, s.angular_acceleration);
                for &i in &b.nodes {
                    let r = Vector3::new(x[3 * i], x[3 * i + 1], x[3 * i + 2]) - s.center;
                    let ai = s.acceleration + al.cross(&r) + w.cross(&w.cross(&r));
                    a[3 * i..3 * i + 3].copy_from_slice(ai.as_slice());
                }
            }
            (a, vr)
        };
        // Rayleigh damping D = alpha M + beta K with the mass and stiffness frozen at the step start.
        let k_n = model
            .evaluate(&self.pattern, &xn, loads, 1.0, true)?
            .tangent
            .ok_or_else(|| FemError::Linear("tangent missing".into()))?;
        let mass = self.mass_at(model, &xn);
        let damp: Vec<f64> = mass
            .iter()
            .zip(&k_n)
            .map(|(m, k)| model.rayleigh_alpha * m + model.rayleigh_beta * k)
            .collect();
        let residual =
            |ev: &crate::model::Evaluation, x: &[f64], bodies: &[BodyState]| -> (Vec<f64>, f64) {
                let (a, vr) = motion(x, bodies);
                let ma = model.mass_times(&a);
                let mut r = self.pattern.reduce(x, &ma);
                let dv = spmv(&self.pattern, &damp, &vr);
                for ((rj, dj), ej) in r.iter_mut().zip(&dv).zip(&ev.residual) {
                    *rj += dj + ej;
                }
                let scale = norm(&ev.f_int).max(norm(&ev.f_ext)).max(norm(&ma));
                (r, scale)
            };
        let opts = self.options;
        let mut x = xn.clone();
        for d in 0..x.len() {
            if model.fixed[d] {
                x[d] = model.rest[d / 3][d % 3] + model.prescribed[d];
            }
        }
        // Predictor: constant velocity (the bodies spin on at their angular velocity).
        for &d in &self.pattern.dof_of {
            x[d] += h * vn[d];
        }
        let mut bodies = bn.clone();
        for b in &self.pattern.bodies {
            let s = bodies[b.body];
            bodies[b.body] = s.moved(h * s.velocity, h * s.angular_velocity);
        }
        model.place_positions(&mut x, &bodies);
        // Modified Newton: the iteration matrix J = ca M + cv D + K is factorized with the tangent
        // at the step start (already needed for the damping) and reused while it contracts the
        // residual fast enough; it is refreshed at the current point when the contraction slows
        // or the line search stalls. The convergence test is that of full Newton, so the solution
        // is the same to within the tolerance, and trial points need no tangent.
        let ev = model.evaluate(&self.pattern, &x, loads, 1.0, false)?;
        let (mut r, mut scale) = residual(&ev, &x, &bodies);
        let mut rn = self.pattern.residual_norm(&r);
        let mut converged = false;
        // None: no factor yet; Some(fresh): a factor exists, fresh when from the current point.
        // The last step's factor (same h) is as good a start as one from K_n and costs nothing.
        let mut factor: Option<bool> = (self.factor_coeffs == Some((ca, cv))).then_some(false);
        self.factor_coeffs = None;
        for _ in 0..opts.max_iterations {
            if rn <= opts.rtol * scale || rn == 0.0 {
                converged = true;
                break;
            }
            rep.iterations += 1;
            if factor.is_none() {
                factorize_jacobian(&mut self.linear, &mass, &k_n, ca, cv, &damp)?;
                rep.factorizations += 1;
                factor = Some(false);
            }
            let mut dx: Vec<f64> = r.iter().map(|v| -v).collect();
            self.linear.solve_factored(&mut dx)?;
            let pattern = &self.pattern;
            let (x0, b0) = (x.clone(), bodies.clone());
            let found = super::line_search(
                |alpha| {
                    let (mut xt, mut bt) = (x0.clone(), b0.clone());
                    model.apply_increment(pattern, &mut xt, &mut bt, &dx, alpha);
                    let evt = model.evaluate(pattern, &xt, loads, 1.0, false)?;
                    let (r, scale) = residual(&evt, &xt, &bt);
                    Ok(super::Trial {
                        r,
                        scale,
                        data: (xt, bt),
                    })
                },
                &dx,
                &r,
                opts.max_backtracks,
            )?;
            let Some((alpha, t)) = found else {
                if factor == Some(true) {
                    break;
                }
                // A stale matrix may point nowhere useful: retry from here with the exact tangent.
                let k = model
                    .evaluate(&self.pattern, &x, loads, 1.0, true)?
                    .tangent
                    .ok_or_else(|| FemError::Linear("tangent missing".into()))?;
                let m = self.mass_at(model, &x);
                factorize_jacobian(&mut self.linear, &m, &k, ca, cv, &damp)?;
                rep.factorizations += 1;
                factor = Some(true);
                continue;
            };
            let rn_new = self.pattern.residual_norm(&t.r);
            (x, bodies) = t.data;
            r = t.r;
            scale = t.scale;
            let slow = rn_new > SLOW_CONTRACTION * rn;
            rn = rn_new;
            if alpha * norm(&dx) <= opts.dx_tol {
                converged = true;
                break;
            }
            if slow && rn > opts.rtol * scale {
                let k = model
                    .evaluate(&self.pattern, &x, loads, 1.0, true)?
                    .tangent
                    .ok_or_else(|| FemError::Linear("tangent missing".into()))?;
                let m = self.mass_at(model, &x);
                factorize_jacobian(&mut self.linear, &m, &k, ca, cv, &damp)?;
                rep.factorizations += 1;
                factor = Some(true);
            } else if factor == Some(true) {
                factor = Some(false);
            }
        }
        if !converged && rn > opts.stall_rtol * scale {
            return Err(FemError::NoConvergence {
                what: "dynamic Newton".into(),
                load_fraction: 0.0,
                residual: rn,
                step: h,
            });
        }
        if factor.is_some() {
            self.factor_coeffs = Some((ca, cv));
        }
        rep.residual = rn;
        let mut v = vec![0.0; x.len()];
        let mut a = vec![0.0; x.len()];
        for &d in &self.pattern.dof_of {
            (a[d], v[d]) = kinematics(integrator, h, x[d] - xn[d], vn[d], an[d]);
        }
        state.x = x;
        state.v = v;
        state.a = a;
        state.bodies = body_motion(&bodies);
        state.t += h;
        model.place_bodies(state)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::material::Material;
    use crate::mesh::generate;
    use nalgebra::Vector3;

    /// Each modified-Newton step ends on the implicit Euler equations, recomputed here from the
    /// model alone: M a + (alpha M + beta K(x_n)) v + f_int(x) = f_ext(x), a = (x - x_n)/h^2 - v_n/h,
    /// v = (x - x_n)/h; and the factorization is reused across iterations and steps.
    #[test]
    fn modified_newton_steps_satisfy_the_implicit_euler_equations() {
        let mesh = generate::box_mesh([6, 2, 2], [0.1, 0.02, 0.02]);
        let mut model = Model::new(&mesh, Material::neo_hookean_bulk(2e5, 0.4), 1040.0).unwrap();
        model.gravity = Vector3::new(0.0, 0.0, -9.81);
        model.fix_plane([0.0; 3], [1.0, 0.0, 0.0], 1e-9);
        model.rayleigh_alpha = 2.0;
        model.rayleigh_beta = 0.005;
        let mut solver = DynamicSolver::new(&model, Integrator::ImplicitEuler).unwrap();
        let pat = Pattern::new(&model).unwrap();
        let loads = Loads::default();
        let h = 0.01;
        let mut s = State::at_rest(&model);
        let (mut iterations, mut factorizations) = (0, 0);
        for _ in 0..8 {
            let (xn, vn) = (s.x.clone(), s.v.clone());
            let rep = solver.step(&model, &mut s, &loads, h).unwrap();
            assert_eq!(rep.substeps, 1);
            iterations += rep.iterations;
            factorizations += rep.factorizations;
            let k_n = model
                .evaluate(&pat, &xn, &loads, 1.0, true)
                .unwrap()
                .tangent
                .unwrap();
            let ev = model.evaluate(&pat, &s.x, &loads, 1.0, false).unwrap();
            let a: Vec<f64> = (0..xn.len())
                .map(|d| (s.x[d] - xn[d]) / (h * h) - vn[d] / h)
                .collect();
            let ma = model.mass_times(&a);
            let v_free: Vec<f64> = pat.dof_of.iter().map(|&d| (s.x[d] - xn[d]) / h).collect();
            let kv = spmv(&pat, &k_n, &v_free);
            let mv = model.mass_times(
                &(0..xn.len())
                    .map(|d| (s.x[d] - xn[d]) / h)
                    .collect::<Vec<_>>(),
            );
            let r: Vec<f64> = pat
                .dof_of
                .iter()
                .enumerate()
                .map(|(j, &d)| {
                    ma[d] + model.rayleigh_alpha * mv[d] + model.rayleigh_beta * kv[j] + ev.f_int[d]
                        - ev.f_ext[d]
                })
                .collect();
            let scale = norm(&ev.f_int).max(norm(&ev.f_ext)).max(norm(&ma));
            assert!(
                norm(&r) <= 2.0 * solver.options.rtol * scale,
                "residual {} vs scale {scale}",
                norm(&r)
            );
            for (d, &fixed) in model.fixed.iter().enumerate() {
                if fixed {
                    assert_eq!(s.x[d], xn[d]);
                }
            }
        }
        let tip = 3 * (model.num_nodes() - 1) + 2;
        assert!(
            s.x[tip] < model.rest[model.num_nodes() - 1].z - 1e-6,
            "gravity must move the tip"
        );
        assert!(
            factorizations < iterations,
            "factorizations {factorizations} must be reused over {iterations} iterations"
        );
    }
}
