//! The stepwise indentation: the indenter moves along -z in equal depth steps and the gel is
//! brought to static equilibrium at each, by Newton on the FE residual plus the contact forces.

use crate::contact::{Contact, ContactParams, NodeForce};
use crate::gel::Gel;
use crate::indenter::{Indenter, Placed, Pose};
use crate::{Result, TactileError};
use nalgebra::{Matrix3, Vector3};
use ocm_fem::FemError;
use ocm_fem::model::{Evaluation, Loads, Pattern};
use ocm_fem::solve::linear::SparseSolver;
use serde::{Deserialize, Serialize};

/// How the indenter is placed over the gel: xy position of its origin and Euler angles.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Placement {
    /// Position of the indenter's origin over the gel (x, y), m.
    pub xy_m: [f64; 2],
    /// Rotation, degrees, about x then y then z.
    pub euler_deg: [f64; 3],
}

/// Controls of an indentation run.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct IndentOptions {
    /// Number of depth steps.
    pub steps: usize,
    /// Depth increment per step, m (depth is measured from first touch of the undeformed top).
    pub step_m: f64,
    /// Contact law.
    pub contact: ContactParams,
    /// Newton iterations per solve.
    pub max_newton: usize,
    /// Converged when |r| <= rtol * max(|f_int|, |f_contact|).
    pub rtol: f64,
    /// Times a failing depth increment may be halved.
    pub max_cuts: usize,
    /// Residuals below this are converged whatever the force scale (round-off), N.
    pub abs_tol_n: f64,
    /// Whether a frictionless step that fails under the closest-point law, after its cuts, is
    /// solved again under the held-plane law, which then stays on (see [`Contact::held`]).
    #[serde(default = "default_true")]
    pub held_plane_retry: bool,
    /// Whether a frictionless Newton step on an indefinite tangent solves the tangent shifted
    /// until it is positive definite (a descent step), instead of LU's step, which may climb
    /// the potential (see [`ocm_fem::solve::linear::SparseSolver::solve_descent`]).
    #[serde(default = "default_true")]
    pub shift_indefinite: bool,
}

fn default_true() -> bool {
    true
}

impl IndentOptions {
    /// Penetration accepted under the held-plane law, m. Planes only approximate a curved face
    /// near their point, so a node that slides along it meets the face a little inside the
    /// plane; the law accepts the same 5 % of one depth step that sets the closest-point law's
    /// 0.5 um at 10 um steps, and never less than the contact's own tolerance.
    pub fn held_penetration_tol_m(&self) -> f64 {
        self.contact
            .penetration_tol_m
            .max(HELD_TOL_STEP_SHARE * self.step_m)
    }

    /// The dissertation's protocol (100 steps of 10 um) for a gel of modulus `young_pa`.
    pub fn protocol(young_pa: f64) -> Self {
        IndentOptions {
            steps: 100,
            step_m: 10e-6,
            contact: ContactParams::for_modulus(young_pa),
            max_newton: 40,
            rtol: 1e-7,
            max_cuts: 5,
            abs_tol_n: 1e-12,
            held_plane_retry: true,
            shift_indefinite: true,
        }
    }
}

/// Result of one indentation step.
#[derive(Debug, Clone)]
pub struct StepOutput {
    /// Step number (1-based).
    pub step: usize,
    /// Indentation depth, m.
    pub depth_m: f64,
    /// Nodal displacement, m.
    pub displacement: Vec<[f64; 3]>,
    /// Contact force on each node (zero off contact), N.
    pub contact_force: Vec<[f64; 3]>,
    /// Force of the gel on the indenter (sum of nodal contact forces, sign flipped), N.
    pub indenter_force_n: [f64; 3],
    /// Newton iterations spent on this step (all multiplier updates and cuts).
    pub newton_iterations: usize,
    /// Augmented-Lagrangian multiplier updates.
    pub multiplier_updates: usize,
    /// Deepest penetration at equilibrium, m (0 when none).
    pub max_penetration_m: f64,
    /// Final residual norm, N.
    pub residual_n: f64,
    /// Nodes in contact.
    pub active_nodes: usize,
    /// Nodes in contact that slide.
    pub slipping_nodes: usize,
    /// Times the depth increment was halved.
    pub cuts: usize,
    /// Whether the step was solved under the held-plane law (see [`Contact::held`]).
    pub held_planes: bool,
    /// Newton iterations whose tangent was indefinite and solved shifted (see
    /// [`IndentOptions::shift_indefinite`]).
    pub shifted_solves: usize,
}

/// Counts over one depth step: Newton iterations, multiplier updates, cuts, shifted solves.
type Stats = (usize, usize, usize, usize);

/// Why one Newton solve failed.
struct Failure {
    why: String,
    residual: f64,
    node: usize,
}

/// An indentation in progress: the gel state, contact history and solver.
pub struct Indentation<'a> {
    gel: &'a Gel,
    indenter: &'a Indenter,
    approach: Approach,
    pattern: Pattern,
    linear: SparseSolver,
    slots: Vec<[u32; 9]>,
    /// Current positions, m.
    pub x: Vec<f64>,
    /// Contact state.
    pub contact: Contact,
    /// Current depth, m.
    pub depth_m: f64,
    /// Options.
    pub options: IndentOptions,
    steps_done: usize,
    /// The last gel evaluation (with its tangent) and the positions it was taken at: a
    /// converged Newton solve ends with the tangent at its solution, which the next solve
    /// (the next multiplier update or depth) starts from.
    cached: Option<(Vec<f64>, Evaluation)>,
}

const NONE: u32 = u32::MAX;

/// A failing node this close to a self-touching edge of the indenter is reported as caught in
/// it, m.
const PINCH_NOTE_M: f64 = 0.1e-3;

/// Step lengths a Newton line search tries (halving from the full step).
const LINE_SEARCH_TRIALS: usize = 16;

/// Under the held-plane law, nodes this close outside the indenter take its tangent plane, m.
const HELD_BAND_M: f64 = 5e-6;
/// Penetration accepted under the held-plane law, as a share of one depth step (at least the
/// contact's own tolerance).
const HELD_TOL_STEP_SHARE: f64 = 0.05;
/// The held-plane law may take this many times the closest-point law's multiplier updates
/// (each may also add planes).
const HELD_UPDATES_FACTOR: usize = 3;

impl<'a> Indentation<'a> {
    /// Prepares an indentation of `gel` by `indenter` placed at `placement`, at zero depth.
    /// Errors when the indenter would not touch the gel's surface even at the final depth.
    pub fn new(
        name: &str,
        gel: &'a Gel,
        indenter: &'a Indenter,
        placement: Placement,
        options: IndentOptions,
    ) -> Result<Self> {
        if !(options.step_m > 0.0 && options.step_m.is_finite()) || options.steps == 0 {
            return Err(TactileError::Input(format!(
                "indentation needs at least one positive depth step (got {} steps of {} um)",
                options.steps,
                options.step_m * 1e6
            )));
        }
        options.contact.validate()?;
        // the base is held: a depth that reaches it would crush the gel onto a rigid plane
        let base_z = (0..gel.num_nodes())
            .filter(|&i| gel.model.fixed[3 * i + 2])
            .map(|i| gel.model.rest[i].z)
            .fold(f64::NEG_INFINITY, f64::max);
        let depth = options.steps as f64 * options.step_m;
        if base_z.is_finite() && depth >= gel.z_top - base_z {
            return Err(TactileError::Input(format!(
                "{name}: the final depth {:.3} mm ({} steps of {} um) reaches the gel's held base: the top stands {:.3} mm above it",
                depth * 1e3,
                options.steps,
                options.step_m * 1e6,
                (gel.z_top - base_z) * 1e3
            )));
        }
        let approach = Approach::new(name, gel, indenter, placement)?;
        let pattern = Pattern::new(&gel.model)?;
        let linear = SparseSolver::new(
            pattern.num_free(),
            pattern.col_ptr.clone(),
            pattern.row_idx.clone(),
        );
        let slots = gel
            .surface
            .iter()
            .map(|&i| {
                let mut s = [NONE; 9];
                for a in 0..3 {
                    for b in 0..3 {
                        let (ra, cb) = (pattern.free_of[3 * i + a], pattern.free_of[3 * i + b]);
                        if ra == usize::MAX || cb == usize::MAX {
                            continue;
                        }
                        let col = &pattern.row_idx[pattern.col_ptr[cb]..pattern.col_ptr[cb + 1]];
                        if let Ok(p) = col.binary_search(&ra) {
                            s[3 * a + b] = (pattern.col_ptr[cb] + p) as u32;
                        }
                    }
                }
                s
            })
            .collect();
        let x = gel.model.rest_dofs();
        let contact = Contact::new(
            options.contact,
            gel.surface.clone(),
            gel.area_m2.clone(),
            &x,
        );
        Ok(Indentation {
            gel,
            indenter,
            approach,
            pattern,
            linear,
            slots,
            x,
            contact,
            depth_m: 0.0,
            options,
            steps_done: 0,
            cached: None,
        })
    }

    /// Pose of the indenter at depth `depth_m`, measured from first touch of the undeformed gel.
    pub fn pose_at(&self, depth_m: f64) -> Pose {
        self.approach.pose_at(depth_m)
    }
}

/// How an indenter approaches the gel: its rotation and x-y position, and how far it travels
/// along -z from the gel's highest level before it touches the undeformed top face.
#[derive(Debug, Clone, Copy)]
pub struct Approach {
    /// Rotation of the indenter.
    pub rotation: Matrix3<f64>,
    /// Position of its origin over the gel (x, y), m.
    pub xy_m: [f64; 2],
    /// Lowest z of the rotated indenter relative to its origin, m.
    pub tip_z_m: f64,
    /// How far below the highest point of the gel the undeformed surface under the indenter
    /// lies (the indenter travels this before touching), m.
    pub touch_gap_m: f64,
    /// Height of the gel's highest point, m.
    pub z_top_m: f64,
}

impl Approach {
    /// The approach of `indenter` placed at `placement` over `gel`. Casts a ray up from every
    /// top-face node to the indenter with its tip at the gel's highest point: the shortest hit
    /// is how far it must travel to touch. No hit: it misses the gel (`OffGel`, naming `name`).
    pub fn new(name: &str, gel: &Gel, indenter: &Indenter, placement: Placement) -> Result<Self> {
        let rotation = Pose::rotation_from_degrees(placement.euler_deg);
        let mut a = Approach {
            rotation,
            xy_m: placement.xy_m,
            tip_z_m: indenter.lowest_z(&rotation),
            touch_gap_m: 0.0,
            z_top_m: gel.z_top,
        };
        let pose = a.pose_at(0.0);
        let up = rotation.transpose() * Vector3::z();
        let mut gap = f64::INFINITY;
        for &i in &gel.top {
            let x = Vector3::from(gel.mesh.points[i]);
            // Start below the top so nodes already under the tip's level are seen too.
            let origin = pose.to_local(&(x - Vector3::z() * 0.1));
            if let Some(t) = indenter.ray_local(&origin, &up, 1.0) {
                gap = gap.min(t - 0.1);
            }
        }
        if gap.is_finite() {
            a.touch_gap_m = gap.max(0.0);
            return Ok(a);
        }
        let (lo, hi) = gel.top_bounds();
        let placed = Placed { indenter, pose };
        let (blo, bhi) = placed.bounds();
        Err(TactileError::OffGel {
            setup: name.to_string(),
            msg: format!(
                "pressed along -z the indenter (x {:.2}..{:.2} mm, y {:.2}..{:.2} mm) touches no \
                 node of the top face (x {:.2}..{:.2} mm, y {:.2}..{:.2} mm)",
                blo[0] * 1e3,
                bhi[0] * 1e3,
                blo[1] * 1e3,
                bhi[1] * 1e3,
                lo[0] * 1e3,
                hi[0] * 1e3,
                lo[1] * 1e3,
                hi[1] * 1e3
            ),
        })
    }

    /// Pose of the indenter at depth `depth_m`, measured from first touch of the undeformed gel.
    pub fn pose_at(&self, depth_m: f64) -> Pose {
        Pose {
            rotation: self.rotation,
            translation: Vector3::new(
                self.xy_m[0],
                self.xy_m[1],
                self.z_top_m - self.touch_gap_m - depth_m - self.tip_z_m,
            ),
        }
    }
}

impl Indentation<'_> {
    /// Surface nodes (indices into the surface list) near the placed indenter.
    fn candidates(&self, placed: &Placed) -> Vec<usize> {
        let (lo, hi) = placed.bounds();
        let margin = 0.5e-3;
        self.gel
            .surface
            .iter()
            .enumerate()
            .filter(|&(_, &i)| {
                (0..3).all(|d| {
                    let v = self.x[3 * i + d];
                    v >= lo[d] - margin && v <= hi[d] + margin
                })
            })
            .map(|(k, _)| k)
            .collect()
    }

    /// Runs all steps of the protocol, calling `progress` after each.
    pub fn run(&mut self, mut progress: impl FnMut(&StepOutput)) -> Result<Vec<StepOutput>> {
        let mut out = Vec::with_capacity(self.options.steps);
        for k in 1..=self.options.steps {
            let s = self.advance_to(k as f64 * self.options.step_m)?;
            progress(&s);
            out.push(s);
        }
        Ok(out)
    }

    /// Moves the indenter to `depth_m` and solves; a failing increment is halved up to
    /// `max_cuts` times before the error names the step, depth, residual and node.
    pub fn advance_to(&mut self, depth_m: f64) -> Result<StepOutput> {
        self.steps_done += 1;
        let step = self.steps_done;
        let mut stats = (0usize, 0usize, 0usize, 0usize);
        let mut targets = vec![depth_m];
        let mut last: Option<(Vec<NodeForce>, f64)> = None;
        while let Some(&target) = targets.last() {
            let saved = (self.x.clone(), self.contact.clone());
            match self.solve_at(target, &mut stats) {
                Ok(r) => {
                    self.depth_m = target;
                    targets.pop();
                    last = Some(r);
                }
                Err(f) => {
                    (self.x, self.contact) = saved;
                    stats.2 += 1;
                    if stats.2 > self.options.max_cuts
                        && self.options.held_plane_retry
                        && self.contact.held.is_none()
                        && self.options.contact.friction == 0.0
                    {
                        // Retried with the held-plane law from the last converged depth; it
                        // stays on for the rest of the run.
                        if trace() {
                            eprintln!(
                                "closest-point law failed ({}); held planes from here",
                                f.why
                            );
                        }
                        self.contact.held = Some(vec![Vec::new(); self.contact.nodes.len()]);
                        stats.2 = 0;
                        targets = vec![depth_m];
                        continue;
                    }
                    if stats.2 > self.options.max_cuts {
                        let why = self.explain(f.why, f.node, target);
                        return Err(TactileError::NoConvergence {
                            step,
                            depth_mm: target * 1e3,
                            why,
                            residual_n: f.residual,
                            node: f.node,
                        });
                    }
                    targets.push(0.5 * (self.depth_m + target));
                }
            }
        }
        let (active, residual) = last.unwrap_or_default();
        let n = self.gel.num_nodes();
        let mut contact_force = vec![[0.0; 3]; n];
        let mut total = Vector3::zeros();
        let mut pen: f64 = 0.0;
        for a in &active {
            let i = self.contact.nodes[a.k];
            contact_force[i] = [a.force.x, a.force.y, a.force.z];
            total -= a.force;
            pen = pen.max(-a.gap_m);
        }
        let rest = &self.gel.model.rest;
        let displacement = (0..n)
            .map(|i| {
                [
                    self.x[3 * i] - rest[i].x,
                    self.x[3 * i + 1] - rest[i].y,
                    self.x[3 * i + 2] - rest[i].z,
                ]
            })
            .collect();
        Ok(StepOutput {
            step,
            depth_m: self.depth_m,
            displacement,
            contact_force,
            indenter_force_n: [total.x, total.y, total.z],
            newton_iterations: stats.0,
            multiplier_updates: stats.1,
            max_penetration_m: pen.max(0.0),
            residual_n: residual,
            active_nodes: active.len(),
            slipping_nodes: active.iter().filter(|a| a.slipping).count(),
            cuts: stats.2,
            held_planes: self.contact.held.is_some(),
            shifted_solves: stats.3,
        })
    }

    /// A failure's reason, with where its worst node sits when that is at an edge where the
    /// indenter's surface touches itself: under the closest-point law a node wedged in that
    /// zero-width crevice is pushed by one side at a time, so Newton cannot settle it.
    fn explain(&self, why: String, node: usize, depth_m: f64) -> String {
        if self.contact.held.is_some() {
            return why;
        }
        let placed = Placed {
            indenter: self.indenter,
            pose: self.pose_at(depth_m),
        };
        let x = Vector3::new(self.x[3 * node], self.x[3 * node + 1], self.x[3 * node + 2]);
        match placed.nearest_pinch(&x) {
            Some((d, c)) if d <= PINCH_NOTE_M => format!(
                "{why}; node {node} lies {:.3} mm from ({:.3}, {:.3}, {:.3}) mm on an edge where \
                 the indenter's surface touches itself (more than two triangles share it): a \
                 node in that zero-width crevice is pushed by one side at a time, as contact \
                 takes one closest point per node",
                d * 1e3,
                c.x * 1e3,
                c.y * 1e3,
                c.z * 1e3
            ),
            _ => why,
        }
    }

    /// Equilibrium at `depth_m` with augmented-Lagrangian updates until the penetration is
    /// within tolerance. `stats` accumulates the step's counts.
    fn solve_at(
        &mut self,
        depth_m: f64,
        stats: &mut Stats,
    ) -> std::result::Result<(Vec<NodeForce>, f64), Failure> {
        let pose = self.pose_at(depth_m);
        let motion = pose.translation - self.pose_at(self.depth_m).translation;
        let indenter = self.indenter;
        let placed = Placed { indenter, pose };
        let cands = self.candidates(&placed);
        // Under held planes (`Contact::held`) the planes come from the closest points at the
        // start and are renewed, with their multipliers, after every Newton solve.
        let held = self.contact.held.is_some();
        let (tol, updates, what) = if held {
            self.contact
                .refresh_planes(&placed, &cands, &self.x, HELD_BAND_M, false);
            (
                self.options.held_penetration_tol_m(),
                HELD_UPDATES_FACTOR * self.options.contact.max_updates,
                "updates of the held planes",
            )
        } else {
            (
                self.options.contact.penetration_tol_m,
                self.options.contact.max_updates,
                "multiplier updates",
            )
        };
        for update in 0..=updates {
            let (active, res) = self.newton(&placed, &motion, &cands, stats)?;
            let pen = if held {
                self.contact
                    .refresh_planes(&placed, &cands, &self.x, HELD_BAND_M, true)
            } else {
                active.iter().map(|a| -a.gap_m).fold(0.0, f64::max)
            };
            if trace() {
                eprintln!(
                    "depth {:.4} mm update {update}{}: penetration {:.3} um, active {}",
                    depth_m * 1e3,
                    if held { " (held planes)" } else { "" },
                    pen * 1e6,
                    active.len()
                );
            }
            if pen <= tol {
                self.contact.commit_step(&active, &self.x);
                return Ok((active, res));
            }
            if update == updates {
                let worst = active
                    .iter()
                    .max_by(|a, b| b.gap_m.total_cmp(&a.gap_m))
                    .map_or(0, |a| self.contact.nodes[a.k]);
                return Err(Failure {
                    why: format!(
                        "penetration {:.3} um stays above the tolerance {:.3} um after {update} {what}",
                        pen * 1e6,
                        tol * 1e6,
                    ),
                    residual: res,
                    node: worst,
                });
            }
            if !held {
                self.contact.update_multipliers(&active);
            }
            stats.1 += 1;
        }
        unreachable!("the loop returns on its last update")
    }

    /// The gel's evaluation with its tangent at the current positions, from the cache when it
    /// was taken there.
    fn evaluate_current(&mut self) -> ocm_fem::Result<Evaluation> {
        if let Some((x, ev)) = self.cached.take()
            && x == self.x
            && ev.tangent.is_some()
        {
            return Ok(ev);
        }
        self.evaluate(&self.x, true)
    }

    fn evaluate(&self, x: &[f64], tangent: bool) -> ocm_fem::Result<Evaluation> {
        self.gel
            .model
            .evaluate(&self.pattern, x, &Loads::default(), 1.0, tangent)
    }

    /// Reduced residual (f_int - f_contact on free DOFs) and its force scale.
    fn residual(&self, ev: &Evaluation, forces: &[NodeForce]) -> (Vec<f64>, f64) {
        let mut net: Vec<f64> = ev.f_int.iter().zip(&ev.f_ext).map(|(a, b)| a - b).collect();
        let mut fc = 0.0;
        for a in forces {
            let i = self.contact.nodes[a.k];
            for d in 0..3 {
                net[3 * i + d] -= a.force[d];
            }
            fc += a.force.norm_squared();
        }
        let r = self.pattern.reduce(&self.x, &net);
        let scale = norm(&ev.f_int).max(fc.sqrt());
        (r, scale)
    }

    fn worst(&self, r: &[f64]) -> (f64, usize) {
        let mut best = (0.0, 0);
        for (j, &d) in self.pattern.dof_of.iter().enumerate() {
            if r[j].abs() > best.0 {
                best = (r[j].abs(), d / 3);
            }
        }
        best
    }

    fn newton(
        &mut self,
        placed: &Placed,
        motion: &Vector3<f64>,
        cands: &[usize],
        stats: &mut Stats,
    ) -> std::result::Result<(Vec<NodeForce>, f64), Failure> {
        let fail = |why: String, r: &[f64], s: &Self| {
            let (res, node) = s.worst(r);
            Failure {
                why,
                residual: res,
                node,
            }
        };
        let mut ev = self.evaluate_current().map_err(|e| Failure {
            why: e.to_string(),
            residual: f64::NAN,
            node: 0,
        })?;
        let mut forces = self.contact.evaluate(placed, motion, cands, &self.x);
        let (mut r, mut scale) = self.residual(&ev, &forces);
        // One pass more than the limit: the last iteration's step is checked before failing.
        for iteration in 0..=self.options.max_newton {
            let rn = norm(&r);
            if trace() {
                eprintln!(
                    "  newton: |r| {rn:.3e} N, scale {scale:.3e} N, active {}",
                    forces.len()
                );
            }
            if rn <= self.options.rtol * scale || rn <= self.options.abs_tol_n {
                if ev.tangent.is_some() {
                    self.cached = Some((self.x.clone(), ev));
                }
                return Ok((forces, rn));
            }
            if iteration == self.options.max_newton {
                break;
            }
            stats.0 += 1;
            let mut vals = match ev.tangent.take() {
                Some(v) => v,
                None => match self.evaluate(&self.x, true) {
                    Ok(e) => e.tangent.unwrap_or_default(),
                    Err(e) => return Err(fail(e.to_string(), &r, self)),
                },
            };
            for a in &forces {
                let s = &self.slots[a.k];
                for ab in 0..9 {
                    if s[ab] != NONE {
                        vals[s[ab] as usize] += a.stiffness[(ab / 3, ab % 3)];
                    }
                }
            }
            let mut dx: Vec<f64> = r.iter().map(|v| -v).collect();
            // Frictionless contact minimises a potential, so an indefinite tangent (the gel
            // crushed under a punch's edge) is shifted until it is positive definite: its LU
            // step can climb the potential, and the line search then finds nothing. With
            // friction there is no potential, and LU's step is kept.
            let solved = if self.options.contact.friction == 0.0 && self.options.shift_indefinite {
                self.linear.solve_descent(&vals, &mut dx)
            } else {
                self.linear.solve(&vals, &mut dx).map(|()| 0.0)
            };
            let shift = match solved {
                Ok(t) => t,
                Err(e) => return Err(fail(e.to_string(), &r, self)),
            };
            if shift > 0.0 {
                stats.3 += 1;
                if trace() {
                    eprintln!("    indefinite tangent: shifted by {shift:.0e} of its diagonal");
                }
            }
            // Frictionless contact has a potential (strain energy plus the penalty potentials):
            // Armijo backtracking on it copes with the active set jumping; with friction the
            // residual norm must fall instead.
            let slope: f64 = dx.iter().zip(&r).map(|(a, b)| a * b).sum();
            let use_energy = self.options.contact.friction == 0.0 && slope < 0.0;
            let merit0 = ev.strain_energy + forces.iter().map(|a| a.energy_j).sum::<f64>();
            let mut alpha = 1.0;
            let mut accepted = None;
            let mut fallback = None;
            let mut inverted = 0;
            for _ in 0..LINE_SEARCH_TRIALS {
                let mut xt = self.x.clone();
                for (j, &d) in self.pattern.dof_of.iter().enumerate() {
                    xt[d] += alpha * dx[j];
                }
                match self.evaluate(&xt, alpha == 1.0) {
                    Ok(evt) => {
                        let ft = self.contact.evaluate(placed, motion, cands, &xt);
                        let saved = std::mem::replace(&mut self.x, xt);
                        let (rt, st) = self.residual(&evt, &ft);
                        let norm_ok = norm(&rt) < (1.0 - 1e-4 * alpha) * rn;
                        let ok = if use_energy {
                            let m = evt.strain_energy + ft.iter().map(|a| a.energy_j).sum::<f64>();
                            m <= merit0 + 1e-4 * alpha * slope
                        } else {
                            norm_ok
                        };
                        if ok {
                            accepted = Some((evt, ft, rt, st));
                            break;
                        }
                        // Near equilibrium the energy change drowns in round-off; the first
                        // step that lowers the residual is then taken instead.
                        if norm_ok && fallback.is_none() {
                            fallback = Some((self.x.clone(), (evt, ft, rt, st)));
                        }
                        self.x = saved;
                    }
                    Err(FemError::Inverted { .. }) => inverted += 1,
                    Err(e) => return Err(fail(e.to_string(), &r, self)),
                }
                alpha *= 0.5;
            }
            if accepted.is_none()
                && let Some((xf, a)) = fallback
            {
                self.x = xf;
                accepted = Some(a);
            }
            let Some((evt, ft, rt, st)) = accepted else {
                let why = if inverted > 0 {
                    format!(
                        "line search found no step that lowers the residual {rn:.3e} N \
                         ({inverted} of its {LINE_SEARCH_TRIALS} trial steps would invert an element)"
                    )
                } else {
                    format!("line search found no step that lowers the residual {rn:.3e} N")
                };
                return Err(fail(why, &r, self));
            };
            ev = evt;
            forces = ft;
            r = rt;
            scale = st;
        }
        let rn = norm(&r);
        Err(fail(
            format!(
                "Newton iteration limit {} reached (residual {:.3e} N, target {:.3e} N)",
                self.options.max_newton,
                rn,
                self.options.rtol * scale
            ),
            &r,
            self,
        ))
    }
}

/// Per-iteration residuals on stderr when `OCM_TACTILE_TRACE` is set.
fn trace() -> bool {
    static ON: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    *ON.get_or_init(|| std::env::var_os("OCM_TACTILE_TRACE").is_some())
}

fn norm(v: &[f64]) -> f64 {
    v.iter().map(|x| x * x).sum::<f64>().sqrt()
}
