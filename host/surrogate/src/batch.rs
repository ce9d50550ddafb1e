//! A reduced-coordinate stepper for many surrogate environments at once: the chain's joint-space
//! dynamics M(q) qdd = tau_motor + tau_gravity + J^T F_contact with position motors integrated
//! implicitly (unconditionally stable for any gains), joint limits, and contact of the TCP
//! sensor sphere with the scene's surfaces (a frictionless penalty spring-damper along the
//! surface normal, linearised into the implicit step, so stiff contacts stay stable). The rapier
//! scene ([`crate::sim`]) is the general contact model (every link, friction); this one is for
//! throughput, and it is tested against rapier's equilibria, motions and contact forces.
//!
//! M(q) is assembled from the bodies' Jacobians (sum of m J_v^T J_v + J_w^T I J_w, the composite
//! inertia); the velocity-product (Coriolis and centrifugal) terms are left out: at the joint
//! speeds of a pneumatic bellows (well under 1 rad/s) they are orders of magnitude below the motor
//! and gravity torques.

use crate::chain::{ChainGeometry, JointKind, KINDS, N_JOINTS, Posture};
use crate::constraints::Limits;
use crate::sim::{SceneConfig, Surface};
use crate::{Result, SurrogateError};
use nalgebra::{SMatrix, SVector, Vector3};
use rayon::prelude::*;

type Mat = SMatrix<f64, N_JOINTS, N_JOINTS>;
type Vec11 = SVector<f64, N_JOINTS>;

/// The state of one environment.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EnvState {
    /// Joint positions.
    pub q: Posture,
    /// Joint velocities.
    pub v: Posture,
    /// Commanded posture (feasible).
    pub target: Posture,
}

/// Model data shared by all environments.
#[derive(Debug, Clone)]
pub struct BatchModel {
    chain: ChainGeometry,
    limits: Limits,
    stiffness: Posture,
    damping: Posture,
    gravity: Vector3<f64>,
    dt: f64,
    surfaces: Vec<Surface>,
    sensor_radius: f64,
    contact_k: f64,
    contact_c: f64,
}

impl BatchModel {
    /// The model with the motor gains, gravity and time step of a rapier scene configuration.
    pub fn new(chain: &ChainGeometry, limits: &Limits, cfg: &SceneConfig) -> Result<Self> {
        limits.validate()?;
        if !(cfg.dt_s > 0.0) || !cfg.dt_s.is_finite() {
            return Err(SurrogateError::Invalid(format!(
                "time step {} s must be positive",
                cfg.dt_s
            )));
        }
        for (name, v) in [
            ("contact stiffness (N/m)", cfg.contact_stiffness_n_per_m),
            ("contact damping (N s/m)", cfg.contact_damping_n_s_per_m),
            ("TCP sensor radius (m)", cfg.tcp_sensor_radius_m),
        ] {
            if !(v >= 0.0) || !v.is_finite() {
                return Err(SurrogateError::Invalid(format!(
                    "{name} {v} must be finite and >= 0"
                )));
            }
        }
        let gain = |j: usize, rev: f64, pri: f64| match KINDS[j] {
            JointKind::Prismatic => pri,
            _ => rev,
        };
        Ok(BatchModel {
            chain: *chain,
            limits: *limits,
            stiffness: std::array::from_fn(|j| {
                gain(j, cfg.revolute_stiffness, cfg.prismatic_stiffness)
            }),
            damping: std::array::from_fn(|j| gain(j, cfg.revolute_damping, cfg.prismatic_damping)),
            gravity: Vector3::new(0.0, 0.0, -cfg.gravity_m_s2),
            dt: cfg.dt_s,
            surfaces: cfg.surfaces.clone(),
            sensor_radius: cfg.tcp_sensor_radius_m,
            contact_k: cfg.contact_stiffness_n_per_m,
            contact_c: cfg.contact_damping_n_s_per_m,
        })
    }

    /// An environment at rest at a posture, commanding it: a starting state, so any finite posture
    /// is accepted and clamped onto the limits and grouped constraints ([`Limits::project`]).
    pub fn env_at(&self, q: &Posture) -> Result<EnvState> {
        let q = self.limits.project(q)?;
        Ok(EnvState {
            q,
            v: [0.0; N_JOINTS],
            target: q,
        })
    }

    /// Sets the command of an environment if it satisfies the joint limits and the grouped
    /// constraints; otherwise [`SurrogateError::OutOfRange`] (or `NotFinite`) names the first
    /// offending joint, its value and its allowed range, and the command is unchanged.
    pub fn command(&self, env: &mut EnvState, q: &Posture) -> Result<Posture> {
        self.limits.check(q)?;
        env.target = *q;
        Ok(env.target)
    }

    /// Sets the command clamped onto the limits and grouped constraints ([`Limits::project`]);
    /// returns it. Non-finite values are still an error.
    pub fn command_clamped(&self, env: &mut EnvState, q: &Posture) -> Result<Posture> {
        env.target = self.limits.project(q)?;
        Ok(env.target)
    }

    /// Joint-space mass matrix and gravity torque at `q`.
    pub fn mass_and_gravity(&self, q: &Posture) -> (Mat, Vec11) {
        let (joints, _) = self.chain.joint_frames(q);
        let bodies = self.chain.body_frames(q);
        let mut m = Mat::zeros();
        let mut g = Vec11::zeros();
        // Joint axes (zero for prismatic rotation) and origins, once.
        let mut axis = [Vector3::zeros(); N_JOINTS];
        for j in 0..N_JOINTS {
            let f = &joints[j];
            axis[j] = match KINDS[j] {
                JointKind::RevoluteX => f.r.column(0).into_owned(),
                JointKind::RevoluteY => f.r.column(1).into_owned(),
                JointKind::Prismatic => f.r.column(2).into_owned(),
            };
        }
        let mut jv = [Vector3::zeros(); N_JOINTS];
        let mut jw = [Vector3::zeros(); N_JOINTS];
        let mut ijw = [Vector3::zeros(); N_JOINTS];
        for (b, (frame, com_z, mass)) in bodies.iter().enumerate() {
            let c = frame.p + frame.r.column(2) * *com_z;
            // Body b moves with joints 0..=b only: the Jacobians are lower-triangular in b.
            for j in 0..=b {
                if KINDS[j] == JointKind::Prismatic {
                    jv[j] = axis[j];
                    jw[j] = Vector3::zeros();
                } else {
                    jv[j] = axis[j].cross(&(c - joints[j].p));
                    jw[j] = axis[j];
                }
            }
            let iw = match self.chain.body_cylinder(b) {
                Some((r, len)) => {
                    let ixx = mass * (3.0 * r * r + len * len) / 12.0;
                    let local = SMatrix::<f64, 3, 3>::from_diagonal(&Vector3::new(
                        ixx,
                        ixx,
                        0.5 * mass * r * r,
                    ));
                    frame.r * local * frame.r.transpose()
                }
                None => SMatrix::<f64, 3, 3>::identity() * 1e-9,
            };
            for j in 0..=b {
                ijw[j] = iw * jw[j];
                g[j] += *mass * jv[j].dot(&self.gravity);
            }
            for j in 0..=b {
                for k in 0..=j {
                    let v = *mass * jv[j].dot(&jv[k]) + jw[j].dot(&ijw[k]);
                    m[(j, k)] += v;
                }
            }
        }
        for j in 0..N_JOINTS {
            for k in 0..j {
                m[(k, j)] = m[(j, k)];
            }
        }
        (m, g)
    }

    /// Advances one environment by one step.
    pub fn step(&self, env: &mut EnvState) {
        self.step_loaded(env, &[0.0; N_JOINTS]);
    }

    /// Advances one environment by one step with an extra generalised force `tau_ext` (N m for
    /// rotations, N for extensions; e.g. J^T F of a load F at the TCP), held constant over the
    /// step (explicit in the load, implicit in the motors).
    pub fn step_loaded(&self, env: &mut EnvState, tau_ext: &Posture) {
        let (m, g) = self.mass_and_gravity(&env.q);
        let dt = self.dt;
        let mut a = m;
        let mut rhs = m * Vec11::from(env.v) + (g + Vec11::from(*tau_ext)) * dt;
        for j in 0..N_JOINTS {
            a[(j, j)] += dt * self.damping[j] + dt * dt * self.stiffness[j];
            rhs[j] += dt * self.stiffness[j] * (env.target[j] - env.q[j]);
        }
        if !self.surfaces.is_empty() {
            let (p, jac) = self.chain.tcp_jacobian(&env.q);
            let v = jac * Vec11::from(env.v);
            for s in &self.surfaces {
                let (o, n) = s.point_and_normal();
                let depth = self.sensor_radius - (p - o).dot(&n);
                if depth <= 0.0 {
                    continue;
                }
                // F = n (k depth - c n.v) with depth and n.v at the end of the step, depth
                // linearised (depth1 = depth0 - dt n^T J v1): dt (k dt + c) J^T n n^T J joins
                // the implicit matrix and dt k depth0 J^T n the right-hand side.
                let jn = jac.transpose() * n;
                let f0 = self.contact_k * depth - self.contact_c * n.dot(&v);
                if f0 <= 0.0 {
                    continue;
                }
                let w = dt * (self.contact_k * dt + self.contact_c);
                a += jn * jn.transpose() * w;
                rhs += jn * (dt * self.contact_k * depth);
            }
        }
        let v = match a.cholesky() {
            Some(ch) => ch.solve(&rhs),
            None => a.lu().solve(&rhs).unwrap_or_else(Vec11::zeros),
        };
        for j in 0..N_JOINTS {
            let [lo, hi] = self.limits.range(j);
            let mut qj = env.q[j] + dt * v[j];
            let mut vj = v[j];
            if qj < lo {
                qj = lo;
                vj = vj.max(0.0);
            } else if qj > hi {
                qj = hi;
                vj = vj.min(0.0);
            }
            env.q[j] = qj;
            env.v[j] = vj;
        }
    }

    /// Steps every environment once, in parallel on the current rayon pool.
    pub fn step_all(&self, envs: &mut [EnvState]) {
        envs.par_iter_mut().for_each(|e| self.step(e));
    }

    /// The TCP of an environment, m.
    pub fn tcp(&self, env: &EnvState) -> Vector3<f64> {
        self.chain.tcp(&env.q)
    }

    /// Force of the surroundings on the TCP sensor at the environment's state, N (the penalty
    /// law of the step; zero without contact).
    pub fn tcp_force(&self, env: &EnvState) -> Vector3<f64> {
        if self.surfaces.is_empty() {
            return Vector3::zeros();
        }
        let (p, jac) = self.chain.tcp_jacobian(&env.q);
        let v = jac * Vec11::from(env.v);
        let mut f = Vector3::zeros();
        for s in &self.surfaces {
            let (o, n) = s.point_and_normal();
            let depth = self.sensor_radius - (p - o).dot(&n);
            if depth > 0.0 {
                f += n * (self.contact_k * depth - self.contact_c * n.dot(&v)).max(0.0);
            }
        }
        f
    }
}
