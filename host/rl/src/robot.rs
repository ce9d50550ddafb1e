//! The surrogate as the environments drive it: the reduced-coordinate batch stepper of
//! `ocm-surrogate` under three grouped joint commands, with a load at the TCP (a hanging weight
//! or a compliant contact with a plane), its static equilibrium, and the inverse of that
//! equilibrium that serves as the expert.
//!
//! A grouped command u = (theta_x rad, theta_y rad, d m) sets every joint of a group to the same
//! value, which satisfies the neighbour bounds of eq 4.23 for any u inside the ranges of eq 4.24;
//! the inverse actuation map takes the same group means to pressures, so the command transfers.

use crate::error::Result;
use nalgebra::{Matrix3, Vector3};
use ocm_surrogate::batch::{BatchModel, EnvState};
use ocm_surrogate::chain::{ChainGeometry, GROUPS, JointKind, KINDS, N_JOINTS, Posture};
use ocm_surrogate::constraints::Limits;
use ocm_surrogate::model::SurrogateModel;
use ocm_surrogate::sim::SceneConfig;
use serde::{Deserialize, Serialize};

/// A load on the TCP.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub enum Load {
    /// Nothing touches the TCP.
    Free,
    /// A weight hangs from the TCP.
    Weight {
        /// Mass, kg.
        mass_kg: f64,
    },
    /// A rigid plane that the TCP point presses into with a penalty spring (no friction).
    Plane {
        /// A point of the plane, m.
        point_m: [f64; 3],
        /// Unit normal pointing out of the solid, towards the robot.
        normal: [f64; 3],
        /// Contact stiffness, N/m.
        stiffness_n_m: f64,
        /// Contact damping, N s/m (only while pressing; the force never pulls).
        damping_n_s_m: f64,
    },
    /// A rigid ball the TCP presses into from below (a curved surface, Fig 4.26-A), with the
    /// plane's penalty law along the local normal.
    Sphere {
        /// Centre, m.
        centre_m: [f64; 3],
        /// Radius, m.
        radius_m: f64,
        /// Contact stiffness, N/m.
        stiffness_n_m: f64,
        /// Contact damping, N s/m.
        damping_n_s_m: f64,
    },
}

impl Load {
    /// Force of the surroundings on the TCP at position `p` (m) moving at `v` (m/s), N.
    pub fn force(&self, p: &Vector3<f64>, v: &Vector3<f64>, gravity_m_s2: f64) -> Vector3<f64> {
        match *self {
            Load::Free => Vector3::zeros(),
            Load::Weight { mass_kg } => Vector3::new(0.0, 0.0, -mass_kg * gravity_m_s2),
            Load::Plane {
                point_m,
                normal,
                stiffness_n_m,
                damping_n_s_m,
            } => {
                let n = Vector3::from(normal);
                let depth = -n.dot(&(p - Vector3::from(point_m)));
                if depth <= 0.0 {
                    return Vector3::zeros();
                }
                let f = (stiffness_n_m * depth - damping_n_s_m * n.dot(v)).max(0.0);
                n * f
            }
            Load::Sphere {
                centre_m,
                radius_m,
                stiffness_n_m,
                damping_n_s_m,
            } => {
                let d = p - Vector3::from(centre_m);
                let dist = d.norm();
                let depth = radius_m - dist;
                if depth <= 0.0 || dist == 0.0 {
                    return Vector3::zeros();
                }
                let n = d / dist;
                let f = (stiffness_n_m * depth - damping_n_s_m * n.dot(v)).max(0.0);
                n * f
            }
        }
    }

    /// Outward unit normal of a contact surface at (or nearest to) `p`; `None` without one.
    pub fn surface_normal(&self, p: &Vector3<f64>) -> Option<Vector3<f64>> {
        match *self {
            Load::Plane { normal, .. } => Some(Vector3::from(normal)),
            Load::Sphere { centre_m, .. } => (p - Vector3::from(centre_m)).try_normalize(0.0),
            _ => None,
        }
    }

    /// Signed distance of `p` from a contact surface along its outward normal, m: positive out
    /// of contact, negative when pressed in (`None` without a surface).
    pub fn surface_gap_m(&self, p: &Vector3<f64>) -> Option<f64> {
        match *self {
            Load::Plane {
                point_m, normal, ..
            } => Some(Vector3::from(normal).dot(&(p - Vector3::from(point_m)))),
            Load::Sphere {
                centre_m, radius_m, ..
            } => Some((p - Vector3::from(centre_m)).norm() - radius_m),
            _ => None,
        }
    }

    /// Penalty stiffness of a contact surface, N/m (`None` without one).
    pub fn contact_stiffness(&self) -> Option<f64> {
        match *self {
            Load::Plane { stiffness_n_m, .. } | Load::Sphere { stiffness_n_m, .. } => {
                Some(stiffness_n_m)
            }
            _ => None,
        }
    }
}

/// The surrogate chain, its limits and the dynamics settings of the environments.
#[derive(Debug, Clone)]
pub struct Robot {
    chain: ChainGeometry,
    limits: Limits,
    scene: SceneConfig,
    batch: BatchModel,
    stiffness: Posture,
    rest_tcp: Vector3<f64>,
}

/// Iterations of the fixed point of the static equilibrium (a contraction: the motors are far
/// stiffer than the gradient of the gravity torque).
const EQ_ITERATIONS: usize = 30;

impl Robot {
    /// A robot from a chain and limits, simulated with time step `physics_dt_s` and the default
    /// motor gains and gravity of [`SceneConfig`].
    pub fn new(chain: &ChainGeometry, limits: &Limits, physics_dt_s: f64) -> Result<Self> {
        let scene = SceneConfig {
            dt_s: physics_dt_s,
            ..SceneConfig::default()
        };
        let batch = BatchModel::new(chain, limits, &scene)?;
        let stiffness = std::array::from_fn(|j| match KINDS[j] {
            JointKind::Prismatic => scene.prismatic_stiffness,
            _ => scene.revolute_stiffness,
        });
        let rest = limits.project(&[0.0; N_JOINTS])?;
        Ok(Robot {
            chain: *chain,
            limits: *limits,
            batch,
            stiffness,
            rest_tcp: chain.tcp(&rest),
            scene,
        })
    }

    /// The robot of a stored surrogate model (`ocm surrogate map`).
    pub fn from_model(model: &SurrogateModel, physics_dt_s: f64) -> Result<Self> {
        Self::new(&model.geometry.chain, &model.limits, physics_dt_s)
    }

    /// Reads `surrogate.json` and builds its robot.
    pub fn read(path: &std::path::Path, physics_dt_s: f64) -> Result<Self> {
        Self::from_model(&SurrogateModel::read(path)?, physics_dt_s)
    }

    /// The chain.
    pub fn chain(&self) -> &ChainGeometry {
        &self.chain
    }

    /// The joint limits.
    pub fn limits(&self) -> &Limits {
        &self.limits
    }

    /// Gravity, m/s^2.
    pub fn gravity_m_s2(&self) -> f64 {
        self.scene.gravity_m_s2
    }

    /// Physics time step, s.
    pub fn dt_s(&self) -> f64 {
        self.scene.dt_s
    }

    /// TCP at the rest posture (no bending, no extension), m: the origin of the tasks.
    pub fn rest_tcp(&self) -> Vector3<f64> {
        self.rest_tcp
    }

    /// Grouped command (rad, rad, m) from a normalised action in [-1, 1]^3 (clamped): the
    /// middle of each group's range plus `a` times its half-width.
    pub fn command_of_action(&self, a: &[f64; 3]) -> [f64; 3] {
        std::array::from_fn(|g| {
            let [lo, hi] = self.limits.range(GROUPS[g][0]);
            0.5 * (lo + hi) + 0.5 * (hi - lo) * a[g].clamp(-1.0, 1.0)
        })
    }

    /// Normalised action of a grouped command (inverse of [`Robot::command_of_action`]).
    pub fn action_of_command(&self, u: &[f64; 3]) -> [f64; 3] {
        std::array::from_fn(|g| {
            let [lo, hi] = self.limits.range(GROUPS[g][0]);
            (u[g] - 0.5 * (lo + hi)) / (0.5 * (hi - lo))
        })
    }

    /// The posture of a grouped command: every joint of a group at the group's value.
    pub fn posture_of(&self, u: &[f64; 3]) -> Posture {
        let mut q = [0.0; N_JOINTS];
        for (g, members) in GROUPS.iter().enumerate() {
            for &j in members.iter() {
                let [lo, hi] = self.limits.range(j);
                q[j] = u[g].clamp(lo, hi);
            }
        }
        q
    }

    /// A state at rest at posture `q`, commanding `target`.
    pub fn state_at(&self, q: &Posture, target: &Posture) -> Result<EnvState> {
        let mut s = self.batch.env_at(q)?;
        self.batch.command(&mut s, target)?;
        Ok(s)
    }

    /// Sets the command of a state (projected onto the limits).
    pub fn command(&self, s: &mut EnvState, target: &Posture) -> Result<()> {
        self.batch.command(s, target)?;
        Ok(())
    }

    /// TCP position (m) and velocity (m/s) of a state.
    pub fn tcp_and_velocity(&self, s: &EnvState) -> (Vector3<f64>, Vector3<f64>) {
        let (p, jac) = self.chain.tcp_jacobian(&s.q);
        (p, jac * nalgebra::SVector::<f64, N_JOINTS>::from(s.v))
    }

    /// Advances `steps` physics steps under `load`; returns the load's force at the end, N.
    pub fn advance(&self, s: &mut EnvState, load: &Load, steps: usize) -> Vector3<f64> {
        let g = self.scene.gravity_m_s2;
        for _ in 0..steps {
            let tau = if matches!(load, Load::Free) {
                [0.0; N_JOINTS]
            } else {
                let (p, jac) = self.chain.tcp_jacobian(&s.q);
                let v = jac * nalgebra::SVector::<f64, N_JOINTS>::from(s.v);
                let f = load.force(&p, &v, g);
                let t = jac.transpose() * f;
                std::array::from_fn(|j| t[j])
            };
            self.batch.step_loaded(s, &tau);
        }
        let (p, v) = self.tcp_and_velocity(s);
        load.force(&p, &v, g)
    }

    /// Static equilibrium under the grouped command `u` with a constant force `f_n` (N) on the
    /// TCP: K (q - q_cmd) = tau_gravity(q) + J(q)^T F, each joint held inside its range by its
    /// stop.
    pub fn equilibrium(&self, u: &[f64; 3], f_n: &Vector3<f64>) -> Posture {
        let cmd = self.posture_of(u);
        let mut q = cmd;
        for _ in 0..EQ_ITERATIONS {
            let (_, g) = self.batch.mass_and_gravity(&q);
            let (_, jac) = self.chain.tcp_jacobian(&q);
            let t = jac.transpose() * f_n;
            for j in 0..N_JOINTS {
                let [lo, hi] = self.limits.range(j);
                q[j] = (cmd[j] + (g[j] + t[j]) / self.stiffness[j]).clamp(lo, hi);
            }
        }
        q
    }

    /// TCP (m) of the static equilibrium under the normalised action `a` and the force `f_n`.
    pub fn static_tcp(&self, a: &[f64; 3], f_n: &Vector3<f64>) -> Vector3<f64> {
        self.chain
            .tcp(&self.equilibrium(&self.command_of_action(a), f_n))
    }

    /// d(static TCP)/d(action) at `a` under the force `f_n` (m per action unit), by one-sided
    /// differences pointing into the action box.
    pub fn action_jacobian(&self, a: &[f64; 3], f_n: &Vector3<f64>) -> Matrix3<f64> {
        self.action_jacobian_at(a, f_n, &self.static_tcp(a, f_n))
    }

    /// [`Robot::action_jacobian`] given the static TCP at `a`.
    fn action_jacobian_at(
        &self,
        a: &[f64; 3],
        f_n: &Vector3<f64>,
        tcp_a: &Vector3<f64>,
    ) -> Matrix3<f64> {
        let h = 1e-5;
        let mut jac = Matrix3::zeros();
        for k in 0..3 {
            let mut b = *a;
            let step = if a[k] + h > 1.0 { -h } else { h };
            b[k] += step;
            jac.set_column(k, &((self.static_tcp(&b, f_n) - tcp_a) / step));
        }
        jac
    }

    /// The expert of eq 4.31: the normalised action whose static equilibrium under the force
    /// `f_n` puts the TCP at `target_m`, by damped Gauss-Newton from `start` (clamped to the
    /// action box). Returns the action and the remaining TCP distance, m.
    pub fn inverse(
        &self,
        target_m: &Vector3<f64>,
        f_n: &Vector3<f64>,
        start: &[f64; 3],
    ) -> ([f64; 3], f64) {
        let tcp_of = |a: &[f64; 3]| self.static_tcp(a, f_n);
        let mut a = start.map(|v| {
            if v.is_finite() {
                v.clamp(-1.0, 1.0)
            } else {
                0.0
            }
        });
        let mut r = tcp_of(&a) - target_m;
        for _ in 0..20 {
            if r.norm() < 1e-7 {
                break;
            }
            let jac = self.action_jacobian_at(&a, f_n, &(r + target_m));
            let jt = jac.transpose();
            let lhs = jt * jac + Matrix3::identity() * 1e-10;
            let Some(delta) = lhs.lu().solve(&(-jt * r)) else {
                break;
            };
            // Backtrack until the distance shrinks (the stops make the map piecewise smooth).
            let mut t = 1.0;
            let mut improved = false;
            for _ in 0..8 {
                let b: [f64; 3] = std::array::from_fn(|k| (a[k] + t * delta[k]).clamp(-1.0, 1.0));
                let rb = tcp_of(&b) - target_m;
                if rb.norm() < r.norm() {
                    a = b;
                    r = rb;
                    improved = true;
                    break;
                }
                t *= 0.5;
            }
            if !improved {
                break;
            }
        }
        (a, r.norm())
    }
}
