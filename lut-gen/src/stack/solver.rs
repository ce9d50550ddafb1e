//! Static equilibrium of the stack: Newton's method on the total potential
//! over the free node coordinates (and the plate translation), with a
//! backtracking line search on the energy and adaptive load stepping.
//!
//! Boundary conditions: the base ring is clamped; the top ring is bonded to
//! a rigid plate whose nodes move as `x_k = c + R(phi) d_k`, the rotation
//! `R(phi)` about [`BEND_AXIS`] prescribed, the centre `c` either free under
//! a dead force or prescribed.

use nalgebra::DVector;

use super::StackError;
use super::structure::{BEND_AXIS, Dof, Stack, add, mat_vec, rotation, scale};
use crate::geometry::{cross, dot, norm, sinc, sub};

/// How the plate centre is held.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub enum PlateTranslation {
    /// Free, loaded by a dead force (newtons, world frame).
    Free {
        /// External force on the plate, newtons.
        force_n: [f64; 3],
    },
    /// Prescribed plate centre, metres.
    Fixed {
        /// Plate centre, metres.
        centre_m: [f64; 3],
    },
}

/// A load case: pressure, plate rotation and plate translation condition.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Load {
    /// Internal gauge pressure, pascals.
    pub pressure_pa: f64,
    /// Prescribed plate rotation about [`BEND_AXIS`], radians.
    pub bend_angle_rad: f64,
    /// Plate translation condition.
    pub translation: PlateTranslation,
}

impl Load {
    /// The unloaded case: no pressure, plate level and free without force.
    pub const NONE: Self = Self {
        pressure_pa: 0.0,
        bend_angle_rad: 0.0,
        translation: PlateTranslation::Free { force_n: [0.0; 3] },
    };
}

impl core::fmt::Display for Load {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(
            f,
            "P = {:.1} Pa, phi = {:.4} rad, ",
            self.pressure_pa, self.bend_angle_rad
        )?;
        match self.translation {
            PlateTranslation::Free { force_n } => write!(
                f,
                "plate free, force = ({:.4e}, {:.4e}, {:.4e}) N",
                force_n[0], force_n[1], force_n[2]
            ),
            PlateTranslation::Fixed { centre_m } => write!(
                f,
                "plate centre fixed at ({:.4e}, {:.4e}, {:.4e}) m",
                centre_m[0], centre_m[1], centre_m[2]
            ),
        }
    }
}

/// Newton and load-stepping settings.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct SolverConfig {
    /// Converged when the largest residual component is below this, newtons.
    pub tolerance_n: f64,
    /// Newton iterations allowed per load step.
    pub max_iterations: usize,
    /// Smallest load-step fraction before giving up.
    pub min_step_fraction: f64,
    /// A node that moves farther than this from its rest position means the
    /// structure has diverged (ballooned), metres.
    pub divergence_m: f64,
}

impl Default for SolverConfig {
    fn default() -> Self {
        Self {
            tolerance_n: 1e-9,
            max_iterations: 30,
            min_step_fraction: 1.0 / 512.0,
            divergence_m: 0.2,
        }
    }
}

/// A converged equilibrium of the stack.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Equilibrium {
    /// The load it balances.
    pub load: Load,
    /// Nodal positions, metres.
    pub positions: Vec<[f64; 3]>,
    /// Plate centre, metres.
    pub plate_centre_m: [f64; 3],
    /// `k_b Pi_bar + k_h Pi_hinge - P (V - V0)`, joules.
    pub energy_j: f64,
    /// Internal force of the structure on the plate, `sum_k dE/dx_k`,
    /// newtons: the external force the plate must carry.
    pub plate_force_n: [f64; 3],
    /// Moment about the plate centre around [`BEND_AXIS`],
    /// `t . sum_k (x_k - c) x dE/dx_k`, newton-metres: the external moment
    /// the plate must carry.
    pub plate_moment_nm: f64,
    /// Largest residual component at every Newton iteration of the last
    /// load step, newtons.
    pub residual_history_n: Vec<f64>,
    /// Whether the Hessian over the unknowns is positive definite (a stable
    /// equilibrium).
    pub stable: bool,
}

impl Equilibrium {
    /// Final residual, newtons.
    pub fn residual_n(&self) -> f64 {
        self.residual_history_n.last().copied().unwrap_or(0.0)
    }
}

impl Stack {
    /// The unloaded stack, which is in equilibrium by construction.
    pub fn rest_equilibrium(&self) -> Equilibrium {
        let x = self.rest_positions().to_vec();
        let mut eq = self.equilibrium_at(Load::NONE, x, Vec::new(), true);
        eq.residual_history_n = vec![0.0];
        eq
    }

    /// Plate centre of positions `x` under `load`.
    fn plate_centre(&self, x: &[[f64; 3]], load: &Load) -> [f64; 3] {
        match load.translation {
            PlateTranslation::Fixed { centre_m } => centre_m,
            PlateTranslation::Free { .. } => {
                let rot = rotation(BEND_AXIS, load.bend_angle_rad);
                let (p, d) = (self.plate_nodes()[0], self.plate_offsets_m()[0]);
                sub(x[p], mat_vec(&rot, d))
            }
        }
    }

    /// Places the plate nodes at `c + R d_k`.
    fn place_plate(&self, x: &mut [[f64; 3]], centre: [f64; 3], bend_angle_rad: f64) {
        let rot = rotation(BEND_AXIS, bend_angle_rad);
        for (n, d) in self.plate_nodes().into_iter().zip(self.plate_offsets_m()) {
            x[n] = add(centre, mat_vec(&rot, d));
        }
    }

    fn equilibrium_at(
        &self,
        load: Load,
        positions: Vec<[f64; 3]>,
        residual_history_n: Vec<f64>,
        stable: bool,
    ) -> Equilibrium {
        let c = self.plate_centre(&positions, &load);
        let g = self.energy_gradient_n(&positions, load.pressure_pa);
        let mut force = [0.0; 3];
        let mut moment = 0.0;
        for n in self.plate_nodes() {
            force = add(force, g[n]);
            moment += dot(BEND_AXIS, cross(sub(positions[n], c), g[n]));
        }
        Equilibrium {
            load,
            energy_j: self.energy_j(&positions, load.pressure_pa),
            plate_centre_m: c,
            positions,
            plate_force_n: force,
            plate_moment_nm: moment,
            residual_history_n,
            stable,
        }
    }

    /// Total potential including the plate load, `E - f . c`.
    fn potential(&self, x: &[[f64; 3]], load: &Load, centre: [f64; 3]) -> f64 {
        let work = match load.translation {
            PlateTranslation::Free { force_n } => dot(force_n, centre),
            PlateTranslation::Fixed { .. } => 0.0,
        };
        self.energy_j(x, load.pressure_pa) - work
    }

    /// Positions from the unknowns `u` (free nodes, then the plate centre
    /// when free), the base at rest and the plate placed by the load.
    fn positions_from(
        &self,
        u: &DVector<f64>,
        load: &Load,
        template: &[[f64; 3]],
    ) -> Vec<[f64; 3]> {
        let mut x = template.to_vec();
        let rest = self.rest_positions();
        for (n, p) in x.iter_mut().enumerate() {
            match self.dof(n) {
                Dof::Free(i) => *p = [u[i], u[i + 1], u[i + 2]],
                // The base is clamped whatever the guess says.
                Dof::Fixed => *p = rest[n],
                Dof::Plate => {}
            }
        }
        let centre = match load.translation {
            PlateTranslation::Fixed { centre_m } => centre_m,
            PlateTranslation::Free { .. } => {
                let i = self.free_node_dofs();
                [u[i], u[i + 1], u[i + 2]]
            }
        };
        self.place_plate(&mut x, centre, load.bend_angle_rad);
        x
    }

    fn unknowns_from(&self, x: &[[f64; 3]], load: &Load, centre: [f64; 3]) -> DVector<f64> {
        let free = self.free_node_dofs();
        let plate_free = matches!(load.translation, PlateTranslation::Free { .. });
        let mut u = DVector::zeros(free + if plate_free { 3 } else { 0 });
        for (n, p) in x.iter().enumerate() {
            if let Dof::Free(i) = self.dof(n) {
                u[i] = p[0];
                u[i + 1] = p[1];
                u[i + 2] = p[2];
            }
        }
        if plate_free {
            for d in 0..3 {
                u[free + d] = centre[d];
            }
        }
        u
    }

    /// Newton's method for `load` from the initial guess `guess` (nodal
    /// positions; the plate nodes are re-placed from the load, and for a
    /// free plate the centre is taken from the guess).
    pub fn solve(
        &self,
        guess: &[[f64; 3]],
        guess_centre_m: [f64; 3],
        load: &Load,
        cfg: &SolverConfig,
    ) -> Result<Equilibrium, StackError> {
        if guess.len() != self.node_count() {
            return Err(StackError::InvalidInput {
                what: "guess",
                reason: format!(
                    "has {} nodes, the stack has {}",
                    guess.len(),
                    self.node_count()
                ),
            });
        }
        let finite = |v: f64| v.is_finite();
        let load_ok = finite(load.pressure_pa)
            && finite(load.bend_angle_rad)
            && match load.translation {
                PlateTranslation::Free { force_n } => force_n.iter().all(|v| v.is_finite()),
                PlateTranslation::Fixed { centre_m } => centre_m.iter().all(|v| v.is_finite()),
            };
        if !load_ok {
            return Err(StackError::InvalidInput {
                what: "load",
                reason: format!("is not finite: {load}"),
            });
        }
        let plate_free = matches!(load.translation, PlateTranslation::Free { .. });
        let centre0 = match load.translation {
            PlateTranslation::Fixed { centre_m } => centre_m,
            PlateTranslation::Free { .. } => guess_centre_m,
        };
        let mut u = self.unknowns_from(guess, load, centre0);
        let mut history = Vec::new();
        let rest = self.rest_positions();
        for _ in 0..cfg.max_iterations {
            let x = self.positions_from(&u, load, guess);
            let drift = x
                .iter()
                .zip(rest)
                .map(|(a, b)| norm(sub(*a, *b)))
                .fold(0.0, f64::max);
            if drift.is_nan() || drift > cfg.divergence_m {
                return Err(StackError::Diverged {
                    load: load.to_string(),
                    displacement_m: drift,
                });
            }
            let asm = self.assemble(&x, load.pressure_pa, plate_free);
            let mut g = asm.gradient_n;
            if let PlateTranslation::Free { force_n } = load.translation {
                let i = self.free_node_dofs();
                for d in 0..3 {
                    g[i + d] -= force_n[d];
                }
            }
            let residual = g.amax();
            history.push(residual);
            if !residual.is_finite() {
                return Err(StackError::NonFinite {
                    load: load.to_string(),
                });
            }
            let h = asm.hessian_n_per_m;
            let chol = h.clone().cholesky();
            let stable = chol.is_some();
            if residual < cfg.tolerance_n {
                return Ok(self.equilibrium_at(*load, x, history, stable));
            }
            let direction = match chol {
                Some(c) => c.solve(&(-&g)),
                None => descent_direction(&h, &g),
            };
            let centre = self.plate_centre(&x, load);
            let e0 = self.potential(&x, load, centre);
            let slope = g.dot(&direction);
            let mut alpha = 1.0;
            loop {
                let trial = &u + alpha * &direction;
                let xt = self.positions_from(&trial, load, guess);
                let ct = self.plate_centre(&xt, load);
                let et = self.potential(&xt, load, ct);
                // Near convergence the energy change falls below round-off;
                // the sufficient-decrease test is then meaningless.
                let noise = 1e-13 * (e0.abs() + 1e-12);
                if et.is_finite()
                    && (et <= e0 + 1e-4 * alpha * slope || (alpha * slope).abs() < noise)
                {
                    u = trial;
                    break;
                }
                alpha *= 0.5;
                if alpha < 1e-10 {
                    return Err(StackError::LineSearch {
                        load: load.to_string(),
                        residual_n: residual,
                    });
                }
            }
        }
        Err(StackError::NotConverged {
            load: load.to_string(),
            iterations: cfg.max_iterations,
            residual_n: history.last().copied().unwrap_or(f64::NAN),
        })
    }

    /// Follows the equilibrium path from `start` to `target` in `steps`
    /// equal load increments, halving a step that fails down to
    /// `cfg.min_step_fraction`; each step starts from the previous solution
    /// moved by the change of the uniform kinematic configuration (a
    /// predictor that keeps large plate rotations from crushing the top layer).
    pub fn continue_to(
        &self,
        start: &Equilibrium,
        target: &Load,
        steps: usize,
        cfg: &SolverConfig,
    ) -> Result<Equilibrium, StackError> {
        let from = self.as_mode_of(start, target);
        let steps = steps.max(1);
        let mut current = start.clone();
        let mut previous: Option<(Equilibrium, f64)> = None;
        let mut lambda = 0.0;
        let mut dl = 1.0 / steps as f64;
        while lambda < 1.0 {
            let next = (lambda + dl).min(1.0);
            let load = interpolate(&from, target, next);
            let secant = previous
                .as_ref()
                .map(|(prev, lp)| (prev, (next - lambda) / (lambda - lp)));
            match self.step(&current, secant, &load, cfg) {
                Ok(eq) => {
                    previous = Some((core::mem::replace(&mut current, eq), lambda));
                    lambda = next;
                    dl = (dl * 1.5).min(1.0 / steps as f64);
                }
                Err(e) => {
                    dl *= 0.5;
                    if dl < cfg.min_step_fraction {
                        return Err(StackError::PathBroken {
                            from: from.to_string(),
                            to: target.to_string(),
                            reached_fraction: lambda,
                            cause: Box::new(e),
                        });
                    }
                }
            }
        }
        Ok(current)
    }

    /// One load step from the converged `current` to `load`. The initial
    /// guess extrapolates along the path through `previous` (the state
    /// before `current`, with the ratio of the new step to the last one)
    /// when there is one, else it moves the nodes as the uniform kinematic
    /// map would.
    pub(crate) fn step(
        &self,
        current: &Equilibrium,
        previous: Option<(&Equilibrium, f64)>,
        load: &Load,
        cfg: &SolverConfig,
    ) -> Result<Equilibrium, StackError> {
        let (guess, centre) = match previous {
            Some((prev, ratio)) if ratio.is_finite() => {
                let guess = current
                    .positions
                    .iter()
                    .zip(&prev.positions)
                    .map(|(c, p)| add(*c, scale(sub(*c, *p), ratio)))
                    .collect::<Vec<_>>();
                let centre = add(
                    current.plate_centre_m,
                    scale(sub(current.plate_centre_m, prev.plate_centre_m), ratio),
                );
                (guess, centre)
            }
            _ => self.predict(current, load),
        };
        self.solve(&guess, centre, load, cfg)
    }

    /// `start.load` rewritten in the translation mode of `target`, so that
    /// the two can be interpolated: a fixed plate becomes a free one under
    /// its reaction force, a free one a fixed one at its current centre.
    fn as_mode_of(&self, start: &Equilibrium, target: &Load) -> Load {
        let translation = match (start.load.translation, target.translation) {
            (PlateTranslation::Fixed { .. }, PlateTranslation::Free { .. }) => {
                PlateTranslation::Free {
                    force_n: start.plate_force_n,
                }
            }
            (PlateTranslation::Free { .. }, PlateTranslation::Fixed { .. }) => {
                PlateTranslation::Fixed {
                    centre_m: start.plate_centre_m,
                }
            }
            (t, _) => t,
        };
        Load {
            translation,
            ..start.load
        }
    }

    /// Initial guess for `load` from the converged `current`: each node
    /// moves as it would in the uniform kinematic map from `current`'s
    /// bending angle and neutral-axis length to `load`'s.
    fn predict(&self, current: &Equilibrium, load: &Load) -> (Vec<[f64; 3]>, [f64; 3]) {
        let l0 = self.rest_length_m();
        let strain_a = self.neutral_axis(&current.positions).arc_m / l0 - 1.0;
        let phi_a = current.load.bend_angle_rad;
        let phi_b = load.bend_angle_rad;
        let strain_b = match load.translation {
            PlateTranslation::Fixed { centre_m } => norm(centre_m) / sinc(0.5 * phi_b) / l0 - 1.0,
            PlateTranslation::Free { .. } => strain_a,
        };
        if phi_a == phi_b && strain_a == strain_b {
            return (current.positions.clone(), current.plate_centre_m);
        }
        let a = self.uniform_positions(strain_a, phi_a);
        let b = self.uniform_positions(strain_b, phi_b);
        let guess = current
            .positions
            .iter()
            .zip(a.iter().zip(&b))
            .map(|(x, (p, q))| add(*x, sub(*q, *p)))
            .collect();
        let shift = sub(
            self.uniform_plate_centre_m(strain_b, phi_b),
            self.uniform_plate_centre_m(strain_a, phi_a),
        );
        (guess, add(current.plate_centre_m, shift))
    }

    /// Moment of the plate reaction about the plate centre and the
    /// generalised force conjugate to `phi` when the plate centre follows
    /// the path `c(phi)` with tangent `dc_dphi`: `f . c' + M`.
    pub fn generalised_moment_nm(eq: &Equilibrium, dc_dphi_m: [f64; 3]) -> f64 {
        dot(eq.plate_force_n, dc_dphi_m) + eq.plate_moment_nm
    }

    /// Smallest eigenvalue of the Hessian over the unknowns at `eq`,
    /// newtons per metre (negative: unstable).
    pub fn min_stiffness_n_per_m(&self, eq: &Equilibrium) -> f64 {
        let plate_free = matches!(eq.load.translation, PlateTranslation::Free { .. });
        let asm = self.assemble(&eq.positions, eq.load.pressure_pa, plate_free);
        asm.hessian_n_per_m.symmetric_eigenvalues().min()
    }
}

/// A descent direction when the Hessian is indefinite: Newton on the
/// Hessian shifted by the smallest multiple of the identity that makes it
/// positive definite (Levenberg-Marquardt style).
fn descent_direction(h: &nalgebra::DMatrix<f64>, g: &DVector<f64>) -> DVector<f64> {
    let scale_h = h.diagonal().amax().max(1e-12);
    let mut mu = 1e-8 * scale_h;
    let n = h.nrows();
    for _ in 0..60 {
        let shifted = h + nalgebra::DMatrix::<f64>::identity(n, n) * mu;
        if let Some(c) = shifted.cholesky() {
            return c.solve(&(-g));
        }
        mu *= 4.0;
    }
    -g / scale_h
}

/// Linear interpolation of two loads of the same translation mode.
fn interpolate(a: &Load, b: &Load, s: f64) -> Load {
    let lerp = |p: f64, q: f64| p + s * (q - p);
    let lerp3 = |p: [f64; 3], q: [f64; 3]| add(p, scale(sub(q, p), s));
    let translation = match (a.translation, b.translation) {
        (PlateTranslation::Free { force_n: p }, PlateTranslation::Free { force_n: q }) => {
            PlateTranslation::Free {
                force_n: lerp3(p, q),
            }
        }
        (PlateTranslation::Fixed { centre_m: p }, PlateTranslation::Fixed { centre_m: q }) => {
            PlateTranslation::Fixed {
                centre_m: lerp3(p, q),
            }
        }
        (_, t) => t,
    };
    Load {
        pressure_pa: lerp(a.pressure_pa, b.pressure_pa),
        bend_angle_rad: lerp(a.bend_angle_rad, b.bend_angle_rad),
        translation,
    }
}
