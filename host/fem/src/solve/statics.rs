//! Static equilibrium: load stepping with Newton-Raphson, backtracking line search and step cutting.

use super::linear::SparseSolver;
use super::{NewtonOptions, norm};
use crate::model::{Evaluation, Loads, Model, Pattern, State};
use crate::{FemError, Result};

/// Line-search steps below this fraction make no real progress...
const TINY_STEP: f64 = 0.05;
/// ...and this many in a row mean the load step is too large (an indefinite tangent far from
/// equilibrium): the step is cut instead of crawling on.
const STAGNANT_ITERATIONS: usize = 3;

/// What a static solve did.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct StaticReport {
    /// Load steps accepted.
    pub steps: usize,
    /// Times a step was cut after a failure.
    pub cuts: usize,
    /// Newton iterations in total.
    pub iterations: usize,
    /// Final residual norm, N.
    pub residual: f64,
    /// Cavity volumes at equilibrium, m^3.
    pub cavity_volumes: Vec<f64>,
    /// Strain energy at equilibrium, J.
    pub strain_energy: f64,
    /// Smallest element volume ratio.
    pub min_jacobian: f64,
}

/// Static solver holding the sparse structure and its symbolic factorization.
#[derive(Debug, Clone)]
pub struct StaticSolver {
    /// Sparse structure of the model.
    pub pattern: Pattern,
    linear: SparseSolver,
    /// Newton controls.
    pub options: NewtonOptions,
    /// Initial number of load steps from rest.
    pub load_steps: usize,
}

impl StaticSolver {
    /// Prepares the solver for `model` (its constraints and cavities must be set).
    pub fn new(model: &Model) -> Result<Self> {
        let pattern = Pattern::new(model)?;
        let linear = SparseSolver::new(
            pattern.num_free(),
            pattern.col_ptr.clone(),
            pattern.row_idx.clone(),
        );
        Ok(StaticSolver {
            pattern,
            linear,
            options: NewtonOptions::default(),
            load_steps: 1,
        })
    }

    /// Factorizations that fell back to LU (indefinite tangent).
    pub fn lu_fallbacks(&self) -> usize {
        self.linear.lu_fallbacks
    }

    /// Solves from rest to the full dead loads and the given pressures.
    pub fn solve_from_rest(
        &mut self,
        model: &Model,
        loads: &Loads,
    ) -> Result<(State, StaticReport)> {
        let mut s = State::at_rest(model);
        let zero = Loads {
            pressures_pa: vec![0.0; loads.pressures_pa.len()],
        };
        let r = self.solve_path(model, &mut s, &zero, loads, 0.0)?;
        Ok((s, r))
    }

    /// Moves an equilibrium `state` under `from` loads (dead loads fully on) to `to`.
    pub fn continue_to(
        &mut self,
        model: &Model,
        state: &mut State,
        from: &Loads,
        to: &Loads,
    ) -> Result<StaticReport> {
        self.solve_path(model, state, from, to, 1.0)
    }

    /// Follows the path s in `[0, 1]`: pressures from -> to, dead loads and prescribed displacements dead0 -> 1.
    pub fn solve_path(
        &mut self,
        model: &Model,
        state: &mut State,
        from: &Loads,
        to: &Loads,
        dead0: f64,
    ) -> Result<StaticReport> {
        if from.pressures_pa.len() != to.pressures_pa.len() {
            return Err(FemError::Model(
                "start and end loads list different cavities".into(),
            ));
        }
        let mut rep = StaticReport::default();
        let mut s = 0.0;
        let mut ds = 1.0 / self.load_steps.max(1) as f64;
        let mut last: Option<Evaluation> = None;
        while s < 1.0 {
            let s_try = (s + ds).min(1.0);
            let loads = Loads {
                pressures_pa: from
                    .pressures_pa
                    .iter()
                    .zip(&to.pressures_pa)
                    .map(|(a, b)| a + s_try * (b - a))
                    .collect(),
            };
            let dead = dead0 + s_try * (1.0 - dead0);
            let saved = (state.x.clone(), state.bodies.clone());
            match self.newton(model, state, &loads, dead, &mut rep) {
                Ok(ev) => {
                    s = s_try;
                    rep.steps += 1;
                    last = Some(ev);
                    ds *= 1.5;
                }
                Err(e) => {
                    (state.x, state.bodies) = saved;
                    ds *= 0.5;
                    rep.cuts += 1;
                    if ds < self.options.min_step {
                        return Err(match e {
                            FemError::NoConvergence { residual, .. } => FemError::NoConvergence {
                                what: "static equilibrium".into(),
                                load_fraction: s,
                                residual,
                                step: ds,
                            },
                            other => other,
                        });
                    }
                }
            }
        }
        if let Some(ev) = last {
            rep.cavity_volumes = ev.cavity_volumes;
            rep.strain_energy = ev.strain_energy;
            rep.min_jacobian = ev.min_jacobian;
        }
        Ok(rep)
    }

    fn residual(ev: &Evaluation) -> (Vec<f64>, f64) {
        let scale = norm(&ev.f_ext).max(norm(&ev.f_int));
        (ev.residual.clone(), scale)
    }

    /// Newton at fixed loads; returns the converged evaluation.
    fn newton(
        &mut self,
        model: &Model,
        state: &mut State,
        loads: &Loads,
        dead: f64,
        rep: &mut StaticReport,
    ) -> Result<Evaluation> {
        model.check_bodies(state)?;
        if state.x.len() != 3 * model.num_nodes() {
            return Err(FemError::Model("state does not match the model".into()));
        }
        for d in 0..state.x.len() {
            if model.fixed[d] {
                state.x[d] = model.rest[d / 3][d % 3] + dead * model.prescribed[d];
            }
        }
        model.rest_clamped(&self.pattern, state);
        model.place_positions(&mut state.x, &state.bodies);
        let opts = self.options;
        let mut ev = model.evaluate(&self.pattern, &state.x, loads, dead, true)?;
        let (mut r, mut scale) = Self::residual(&ev);
        let mut rn = self.pattern.residual_norm(&r);
        let mut tiny_steps = 0;
        for _ in 0..opts.max_iterations {
            if rn <= opts.rtol * scale || rn == 0.0 {
                rep.residual = rn;
                return Ok(ev);
            }
            rep.iterations += 1;
            let mut dx: Vec<f64> = r.iter().map(|v| -v).collect();
            let k = ev
                .tangent
                .as_ref()
                .ok_or_else(|| FemError::Linear("tangent missing".into()))?;
            self.linear.solve(k, &mut dx)?;
            let pattern = &self.pattern;
            let (x0, b0) = (state.x.clone(), state.bodies.clone());
            let found = super::line_search(
                |alpha| {
                    let (mut xt, mut bt) = (x0.clone(), b0.clone());
                    model.apply_increment(pattern, &mut xt, &mut bt, &dx, alpha);
                    // Full steps are usually accepted, so they carry their tangent along.
                    let evt = model.evaluate(pattern, &xt, loads, dead, alpha == 1.0)?;
                    let (r, scale) = Self::residual(&evt);
                    Ok(super::Trial {
                        r,
                        scale,
                        data: (xt, bt, evt),
                    })
                },
                &dx,
                &r,
                opts.max_backtracks,
            )?;
            let Some((alpha, t)) = found else {
                if rn <= opts.stall_rtol * scale {
                    rep.residual = rn;
                    return Ok(ev);
                }
                return Err(FemError::NoConvergence {
                    what: "line search found no acceptable step".into(),
                    load_fraction: dead,
                    residual: rn,
                    step: 0.0,
                });
            };
            let (xt, bt, evt) = t.data;
            ev = if evt.tangent.is_some() {
                evt
            } else {
                model.evaluate(&self.pattern, &xt, loads, dead, true)?
            };
            state.x = xt;
            state.bodies = bt;
            r = t.r;
            scale = t.scale;
            rn = self.pattern.residual_norm(&r);
            if alpha * norm(&dx) <= opts.dx_tol {
                rep.residual = rn;
                return Ok(ev);
            }
            tiny_steps = if alpha < TINY_STEP { tiny_steps + 1 } else { 0 };
            if tiny_steps >= STAGNANT_ITERATIONS && rn > opts.stall_rtol * scale {
                return Err(FemError::NoConvergence {
                    what: "Newton stagnates (tiny line-search steps)".into(),
                    load_fraction: dead,
                    residual: rn,
                    step: alpha,
                });
            }
        }
        if rn <= opts.stall_rtol * scale {
            rep.residual = rn;
            return Ok(ev);
        }
        Err(FemError::NoConvergence {
            what: "Newton iteration limit".into(),
            load_fraction: dead,
            residual: rn,
            step: 1.0,
        })
    }
}
