//! The Gymnasium-style environment: `reset(seed)` and `step(action)` over plain `f64` slices.
//!
//! Observation (40 values, each scaled to order one; see [`OBS_NAMES`]): the dissertation's
//! O_t = [theta, dtheta/dt, X, dX/dt, tau_ext] plus what the reward depends on and a policy
//! cannot otherwise know: the next target point, its offset from the TCP, and the target force.
//! Action: three normalised grouped joint commands in [-1, 1] (theta_x, theta_y, d), absolute,
//! mapped to the middle of each joint range plus the value times its half-width.

use crate::error::{Result, RlError};
use crate::reward::{approach_force_error, combined_reward};
use crate::robot::{Load, Robot};
use crate::tasks::{ContactConfig, Episode, POINTS, TaskKind};
use nalgebra::Vector3;
use ocm_surrogate::batch::EnvState;
use ocm_surrogate::chain::{JointKind, KINDS, N_JOINTS};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use serde::{Deserialize, Serialize};
use std::sync::Arc;

/// Observation length.
pub const OBS_DIM: usize = 40;
/// Action length.
pub const ACT_DIM: usize = 3;

/// Scale of TCP positions in the observation, m.
pub const POS_SCALE_M: f64 = 0.05;
/// Scale of the target offset in the observation, m.
pub const OFFSET_SCALE_M: f64 = 0.01;
/// Scale of forces in the observation, N.
pub const FORCE_SCALE_N: f64 = 2.0;
/// Scale of TCP velocities in the observation, m/s.
pub const VEL_SCALE_M_S: f64 = 0.1;

/// What each observation value is, with its scaling.
pub const OBS_NAMES: [&str; 8] = [
    "0..11 joint positions: (q - mid) / half-range",
    "11..22 joint velocities: rad/s / 1, m/s / 0.1",
    "22..25 TCP - rest TCP, / 0.05 m",
    "25..28 TCP velocity, / 0.1 m/s",
    "28..31 tau_ext (force of the surroundings on the TCP), / 2 N",
    "31..34 next target - rest TCP, / 0.05 m",
    "34..37 next target - TCP, / 0.01 m",
    "37..40 next target force, / 2 N",
];

/// Settings of an environment.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct EnvConfig {
    /// The task.
    pub task: TaskKind,
    /// Physics steps per action (the control period is this times the physics step).
    pub substeps: usize,
    /// Standard deviation of the seeded perturbation of the first command, in action units.
    pub init_noise: f64,
    /// The episode terminates when the TCP is farther than this from its target, m.
    pub lost_distance_m: f64,
    /// Contact of the plate tasks.
    pub contact: ContactConfig,
    /// Per-episode perturbations of the plant that neither the expert nor the observation's
    /// targets know (none by default).
    #[serde(default)]
    pub randomisation: Randomisation,
    /// Stiffness of the approach term of the force reward, N/m (0: eq 4.30 as printed). Out of
    /// contact, R_F scores the penalty law continued across the surface at this stiffness (a
    /// virtual pull proportional to the gap, `reward::approach_force_error`), so the force
    /// reward falls with the distance to the surface instead of being flat. Only the reward
    /// changes; `StepInfo::force_error_n` stays the measured error.
    #[serde(default)]
    pub approach_n_per_m: f64,
}

/// Per-episode perturbations of the plant, each uniform in [-half-width, half-width] and drawn
/// from the episode's seed on a stream of its own (the episode's path, load and start do not
/// change). The expert and BC plan with the nominal plant; the perturbations make the model gap
/// that a policy has to correct from what it observes.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Randomisation {
    /// Half-width of the bias added to each of the two grouped bending commands, rad (an
    /// actuation-map calibration error).
    pub bend_bias_rad: f64,
    /// Half-width of the bias added to the grouped extension command, m.
    pub extension_bias_m: f64,
    /// Half-width of the shift of the contact surface (plate or ball) along its normal, m;
    /// positive towards the robot. The targets stay on the nominal surface.
    pub surface_offset_m: f64,
}

impl Randomisation {
    /// Whether any perturbation is drawn.
    pub fn is_none(&self) -> bool {
        *self == Randomisation::default()
    }

    fn validate(&self) -> Result<()> {
        for (name, v) in [
            ("bend bias (rad)", self.bend_bias_rad),
            ("extension bias (m)", self.extension_bias_m),
            ("surface offset (m)", self.surface_offset_m),
        ] {
            if !(v >= 0.0 && v.is_finite()) {
                return Err(RlError::Invalid(format!(
                    "randomisation: {name} half-width {v} must be finite and >= 0"
                )));
            }
        }
        Ok(())
    }
}

/// The perturbation drawn for one episode.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Perturbation {
    /// Added to the grouped command (theta_x rad, theta_y rad, d m) before the joint ranges
    /// clamp it.
    pub command_bias: [f64; 3],
    /// Shift of the contact surface along its normal, m.
    pub surface_offset_m: f64,
}

impl Perturbation {
    /// The perturbation of episode `seed` under `r` (zero when `r` is none).
    pub fn draw(r: &Randomisation, seed: u64) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x0c0f_fee0_5eed_0002);
        let mut u = |w: f64| w * (2.0 * rng.random::<f64>() - 1.0);
        Perturbation {
            command_bias: [
                u(r.bend_bias_rad),
                u(r.bend_bias_rad),
                u(r.extension_bias_m),
            ],
            surface_offset_m: u(r.surface_offset_m),
        }
    }

    /// `load` with its surface moved by the offset (other loads unchanged).
    pub fn apply_to(&self, load: Load) -> Load {
        let o = self.surface_offset_m;
        match load {
            Load::Plane {
                point_m,
                normal,
                stiffness_n_m,
                damping_n_s_m,
            } => Load::Plane {
                point_m: std::array::from_fn(|k| point_m[k] + o * normal[k]),
                normal,
                stiffness_n_m,
                damping_n_s_m,
            },
            Load::Sphere {
                centre_m,
                radius_m,
                stiffness_n_m,
                damping_n_s_m,
            } => Load::Sphere {
                centre_m,
                radius_m: radius_m + o,
                stiffness_n_m,
                damping_n_s_m,
            },
            other => other,
        }
    }

    fn biased(&self, u: [f64; 3]) -> [f64; 3] {
        std::array::from_fn(|g| u[g] + self.command_bias[g])
    }
}

/// Physics time step of the environments, s (the dissertation's surrogate ran above 1 kHz).
pub const PHYSICS_DT_S: f64 = 0.001;

impl EnvConfig {
    /// The defaults for `task`: 50 physics steps of 1 ms per action (20 Hz control).
    pub fn new(task: TaskKind) -> Self {
        EnvConfig {
            task,
            substeps: 50,
            init_noise: 0.02,
            lost_distance_m: 0.05,
            contact: ContactConfig::default(),
            randomisation: Randomisation::default(),
            approach_n_per_m: 0.0,
        }
    }

    fn validate(&self) -> Result<()> {
        self.randomisation.validate()?;
        let c = &self.contact;
        let ok = self.substeps > 0
            && self.init_noise >= 0.0
            && self.init_noise.is_finite()
            && self.lost_distance_m > 0.0
            && c.stiffness_n_m > 0.0
            && c.stiffness_n_m.is_finite()
            && c.damping_n_s_m >= 0.0
            && c.damping_n_s_m.is_finite()
            && self.approach_n_per_m >= 0.0
            && self.approach_n_per_m.is_finite();
        if !ok {
            return Err(RlError::Invalid(format!(
                "environment settings out of range: {self:?} (substeps >= 1, noise >= 0, \
                 lost distance > 0, stiffness > 0, damping >= 0, approach stiffness >= 0)"
            )));
        }
        Ok(())
    }
}

/// Facts about a step that are not in the observation.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct StepInfo {
    /// Index of the target this step aimed at.
    pub point: usize,
    /// TCP after the step, m.
    pub tcp_m: [f64; 3],
    /// The step's target, m.
    pub target_m: [f64; 3],
    /// Distance of the TCP from the target, m.
    pub position_error_m: f64,
    /// Force of the surroundings on the TCP, N.
    pub force_n: [f64; 3],
    /// The step's target force, N.
    pub force_target_n: [f64; 3],
    /// Norm of the force error, N.
    pub force_error_n: f64,
    /// Whether any action value was clipped into [-1, 1].
    pub clipped: bool,
}

/// The result of a step.
#[derive(Debug, Clone, PartialEq)]
pub struct Step {
    /// Observation after the step.
    pub obs: Vec<f64>,
    /// Reward of eq 4.29.
    pub reward: f64,
    /// The episode failed (TCP lost or state not finite).
    pub terminated: bool,
    /// The last target of the sequence has been served (a time limit: the observation does not
    /// hold the step index).
    pub truncated: bool,
    /// Details.
    pub info: StepInfo,
}

/// One environment.
#[derive(Debug, Clone)]
pub struct Env {
    robot: Arc<Robot>,
    config: EnvConfig,
    state: Option<EnvState>,
    episode: Option<Episode>,
    point: usize,
    force: Vector3<f64>,
    done: bool,
    expert_warm: [f64; 3],
    perturbation: Perturbation,
}

fn scaled_joint(j: usize, q: f64, robot: &Robot) -> f64 {
    let [lo, hi] = robot.limits().range(j);
    (q - 0.5 * (lo + hi)) / (0.5 * (hi - lo))
}

/// What a policy observes of a plant: joints, TCP and the force of the surroundings.
#[derive(Debug, Clone, Copy)]
pub struct ObservedState<'a> {
    /// Joint positions (rad, m).
    pub q: &'a [f64; N_JOINTS],
    /// Joint velocities (rad/s, m/s).
    pub dq: &'a [f64; N_JOINTS],
    /// TCP, m.
    pub tcp_m: Vector3<f64>,
    /// TCP velocity, m/s.
    pub tcp_velocity_m_s: Vector3<f64>,
    /// Force of the surroundings on the TCP, N.
    pub force_n: Vector3<f64>,
}

/// The 40 observation values ([`OBS_NAMES`]) of a state and the next target: the one scaling
/// that the environments and the deployment on other plants (`transfer`) share.
pub fn observation_of(
    robot: &Robot,
    s: &ObservedState,
    target: &Vector3<f64>,
    force_target: &Vector3<f64>,
) -> Vec<f64> {
    let rest = robot.rest_tcp();
    let (p, v) = (s.tcp_m, s.tcp_velocity_m_s);
    let mut o = Vec::with_capacity(OBS_DIM);
    for j in 0..N_JOINTS {
        o.push(scaled_joint(j, s.q[j], robot));
    }
    for (kind, v) in KINDS.iter().zip(s.dq.iter()) {
        o.push(match kind {
            JointKind::Prismatic => v / 0.1,
            _ => *v,
        });
    }
    o.extend(((p - rest) / POS_SCALE_M).iter());
    o.extend((v / VEL_SCALE_M_S).iter());
    o.extend((s.force_n / FORCE_SCALE_N).iter());
    o.extend(((target - rest) / POS_SCALE_M).iter());
    o.extend(((target - p) / OFFSET_SCALE_M).iter());
    o.extend((force_target / FORCE_SCALE_N).iter());
    o
}

impl Env {
    /// An environment of `robot` with `config` (reset it before stepping).
    pub fn new(robot: Arc<Robot>, config: EnvConfig) -> Result<Self> {
        config.validate()?;
        Ok(Env {
            robot,
            config,
            state: None,
            episode: None,
            point: 0,
            force: Vector3::zeros(),
            done: true,
            expert_warm: [0.0; 3],
            perturbation: Perturbation::default(),
        })
    }

    /// An environment from a model file and a task name (the constructor bindings use).
    pub fn from_file(path: &std::path::Path, task: &str) -> Result<Self> {
        let task = TaskKind::from_name(task).ok_or_else(|| {
            RlError::Invalid(format!(
                "unknown task '{task}' (circle, star, weight, force, ellipse)"
            ))
        })?;
        let robot = Arc::new(Robot::read(path, PHYSICS_DT_S)?);
        Env::new(robot, EnvConfig::new(task))
    }

    /// Observation length.
    pub fn observation_size(&self) -> usize {
        OBS_DIM
    }

    /// Action length.
    pub fn action_size(&self) -> usize {
        ACT_DIM
    }

    /// Bounds of every action value (values outside are clipped, NaN is refused).
    pub fn action_bounds(&self) -> (f64, f64) {
        (-1.0, 1.0)
    }

    /// Bounds of every observation value (unbounded; the values are scaled to order one).
    pub fn observation_bounds(&self) -> (f64, f64) {
        (f64::NEG_INFINITY, f64::INFINITY)
    }

    /// The settings.
    pub fn config(&self) -> &EnvConfig {
        &self.config
    }

    /// The robot.
    pub fn robot(&self) -> &Arc<Robot> {
        &self.robot
    }

    /// Control period, s.
    pub fn control_period_s(&self) -> f64 {
        self.config.substeps as f64 * self.robot.dt_s()
    }

    /// The current episode (after a reset).
    pub fn episode(&self) -> Option<&Episode> {
        self.episode.as_ref()
    }

    /// Index of the next target.
    pub fn point(&self) -> usize {
        self.point
    }

    /// The plant perturbation of the current episode (zero without randomisation).
    pub fn perturbation(&self) -> &Perturbation {
        &self.perturbation
    }

    /// Starts an episode drawn from `seed`: targets and load from [`Episode::new`], the robot at
    /// rest at the static equilibrium of the expert's command for the first target, perturbed by
    /// seeded noise (force task: 5 mm below the plate, out of contact).
    pub fn reset(&mut self, seed: u64) -> Result<Vec<f64>> {
        let ep = Episode::new(
            self.config.task,
            &self.robot.rest_tcp(),
            &self.config.contact,
            seed,
        );
        self.reset_with(ep, seed)
    }

    /// Starts the given episode (an unseen path such as [`Episode::figure_eight`]); `seed`
    /// draws the perturbation of the first command and the plant's randomisation as in
    /// [`Env::reset`].
    pub fn reset_with(&mut self, mut ep: Episode, seed: u64) -> Result<Vec<f64>> {
        if ep.targets.len() != POINTS || ep.force_targets.len() != POINTS {
            return Err(RlError::Invalid(format!(
                "an episode has {POINTS} targets and force targets, not {} and {}",
                ep.targets.len(),
                ep.force_targets.len()
            )));
        }
        let robot = self.robot.clone();
        let gravity = robot.gravity_m_s2();
        let pert = Perturbation::draw(&self.config.randomisation, seed);
        ep.load = pert.apply_to(ep.load);
        self.perturbation = pert;
        let (start_tcp, start_force) = if ep.task == TaskKind::Force {
            (
                ep.targets[0] - Vector3::new(0.0, 0.0, 0.005),
                Vector3::zeros(),
            )
        } else {
            (ep.planned_tcp(0), ep.planned_force(0, gravity))
        };
        let (a, _) = robot.inverse(&start_tcp, &start_force, &[0.0; 3]);
        self.expert_warm = a;
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x0c0f_fee0_5eed_0001);
        let normal = Normal::new(0.0, self.config.init_noise.max(1e-300))
            .map_err(|e| RlError::Invalid(format!("init noise: {e}")))?;
        let a0: [f64; 3] = std::array::from_fn(|k| {
            let n = if self.config.init_noise > 0.0 {
                normal.sample(&mut rng)
            } else {
                0.0
            };
            (a[k] + n).clamp(-1.0, 1.0)
        });
        let u = pert.biased(robot.command_of_action(&a0));
        let q = robot.equilibrium(&u, &start_force);
        let state = robot.state_at(&q, &robot.posture_of(&u))?;
        let (p, v) = robot.tcp_and_velocity(&state);
        self.force = ep.load.force(&p, &v, gravity);
        self.state = Some(state);
        self.episode = Some(ep);
        self.point = 0;
        self.done = false;
        Ok(self.observation())
    }

    /// The observation of the current state (zeros before the first reset).
    pub fn observation(&self) -> Vec<f64> {
        let (Some(s), Some(ep)) = (&self.state, &self.episode) else {
            return vec![0.0; OBS_DIM];
        };
        let (p, v) = self.robot.tcp_and_velocity(s);
        let k = self.point.min(POINTS - 1);
        observation_of(
            &self.robot,
            &ObservedState {
                q: &s.q,
                dq: &s.v,
                tcp_m: p,
                tcp_velocity_m_s: v,
                force_n: self.force,
            },
            &ep.targets[k],
            &ep.force_targets[k],
        )
    }

    /// The expert's action for the next target (eq 4.31's inverse model: the inverse of the
    /// static equilibrium under the planned force, warm-started from its previous answer).
    pub fn expert_action(&mut self) -> Result<[f64; 3]> {
        let ep = self
            .episode
            .as_ref()
            .ok_or_else(|| RlError::State("expert_action before reset".into()))?;
        let k = self.point.min(POINTS - 1);
        let (a, _) = self.robot.inverse(
            &ep.planned_tcp(k),
            &ep.planned_force(k, self.robot.gravity_m_s2()),
            &self.expert_warm,
        );
        self.expert_warm = a;
        Ok(a)
    }

    /// Applies `action` for one control period and scores the TCP against the step's target.
    /// Wrong length and non-finite values are errors (the state is untouched); values outside
    /// [-1, 1] are clipped (`info.clipped`).
    pub fn step(&mut self, action: &[f64]) -> Result<Step> {
        if action.len() != ACT_DIM {
            return Err(RlError::ActionSize {
                found: action.len(),
                expected: ACT_DIM,
            });
        }
        if let Some((index, &value)) = action.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            return Err(RlError::NonFiniteAction { index, value });
        }
        if self.done {
            return Err(RlError::State(
                "step on a finished or never started episode: call reset".into(),
            ));
        }
        let clipped = action.iter().any(|v| v.abs() > 1.0);
        let a: [f64; 3] = std::array::from_fn(|k| action[k].clamp(-1.0, 1.0));
        let robot = self.robot.clone();
        let (Some(state), Some(ep)) = (self.state.as_mut(), self.episode.as_ref()) else {
            return Err(RlError::State("step before reset".into()));
        };
        let u = self.perturbation.biased(robot.command_of_action(&a));
        robot.command(state, &robot.posture_of(&u))?;
        self.force = robot.advance(state, &ep.load, self.config.substeps);
        let k = self.point;
        let (p, _) = robot.tcp_and_velocity(state);
        let target = ep.targets[k];
        let ft = ep.force_targets[k];
        let dq = (p - target).norm();
        let force_err = if ep.task.has_force() {
            (self.force - ft).norm()
        } else {
            0.0
        };
        let finite = state.q.iter().chain(state.v.iter()).all(|v| v.is_finite());
        let k_approach = self.config.approach_n_per_m;
        let scored_force_err = match (ep.load.surface_gap_m(&p), ep.load.surface_normal(&p)) {
            (Some(gap), Some(n)) if ep.task.has_force() && k_approach > 0.0 => {
                approach_force_error(
                    &[ft.x, ft.y, ft.z],
                    &[self.force.x, self.force.y, self.force.z],
                    &[n.x, n.y, n.z],
                    gap,
                    k_approach,
                )
            }
            _ => force_err,
        };
        let reward = combined_reward(ep.task.alpha(), dq, scored_force_err);
        let terminated = !finite || dq.is_nan() || dq > self.config.lost_distance_m;
        self.point += 1;
        let truncated = !terminated && self.point >= POINTS;
        self.done = terminated || truncated;
        let info = StepInfo {
            point: k,
            tcp_m: [p.x, p.y, p.z],
            target_m: [target.x, target.y, target.z],
            position_error_m: dq,
            force_n: [self.force.x, self.force.y, self.force.z],
            force_target_n: [ft.x, ft.y, ft.z],
            force_error_n: force_err,
            clipped,
        };
        Ok(Step {
            obs: self.observation(),
            reward: if reward.is_finite() { reward } else { -1.0 },
            terminated,
            truncated,
            info,
        })
    }

    /// The load of the current episode.
    pub fn load(&self) -> Option<Load> {
        self.episode.as_ref().map(|e| e.load)
    }

    /// Grouped joint command (rad, rad, m) of a normalised action, for deployment.
    pub fn command_of_action(&self, action: &[f64; 3]) -> [f64; 3] {
        self.robot.command_of_action(action)
    }
}
