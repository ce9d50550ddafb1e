//! Articulated simulation of the surrogate on rapier (multibody joints with position motors and
//! limits, gravity, contact with rigid surroundings, a TCP force sensor): the scene for contact
//! tasks of Ch.4.8.
//!
//! Bodies follow the URDF ([`crate::urdf`]): the fixed base, per bending pair a dummy body and,
//! per segment, two body links joined by the prismatic joint, then the top plate with a small
//! sphere at the TCP as the force sensor. A command outside the joint limits or the grouped
//! constraints is refused with an error naming the joint and its allowed range
//! ([`Sim::command`]); [`Sim::command_clamped`] clamps it onto them instead ([`Limits::project`]).

use crate::chain::{ChainGeometry, JointKind, KINDS, N_JOINTS, Posture};
use crate::constraints::Limits;
use crate::{Result, SurrogateError};
use nalgebra::Vector3;
use rapier3d_f64::prelude::*;
use serde::{Deserialize, Serialize};

/// A rigid surrounding. The robot stands base-down with its TCP up, so the surroundings it
/// can touch lie above it: each surface is the boundary of a solid that fills the space above it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub enum Surface {
    /// A horizontal plate whose lower face is at `height_m`.
    Plane {
        /// Height of the lower face, m.
        height_m: f64,
    },
    /// A plate whose lower face passes through (0, 0, `height_m`) and rises towards +x at
    /// `slope_rad`.
    Ramp {
        /// Height on the z axis, m.
        height_m: f64,
        /// Inclination, rad.
        slope_rad: f64,
    },
}

/// Scene settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SceneConfig {
    /// Time step, s.
    pub dt_s: f64,
    /// Gravity along -z, m/s^2.
    pub gravity_m_s2: f64,
    /// Position-motor stiffness of the revolute joints, N m/rad (force-based motors: the gains
    /// are physical, so the TCP force under contact follows from them).
    pub revolute_stiffness: f64,
    /// Position-motor damping of the revolute joints, N m s/rad.
    pub revolute_damping: f64,
    /// Position-motor stiffness of the prismatic joints, N/m.
    pub prismatic_stiffness: f64,
    /// Position-motor damping of the prismatic joints, N s/m.
    pub prismatic_damping: f64,
    /// Constraint-solver iterations per step (rapier's default is 4; a stiff 11-joint chain under
    /// gravity needs more to reach its equilibrium).
    pub solver_iterations: usize,
    /// Radius of the TCP sensor sphere, m.
    pub tcp_sensor_radius_m: f64,
    /// Normal stiffness of the batch stepper's penalty contact between the TCP sensor and the
    /// surroundings, N/m (rapier's contacts are rigid and ignore it).
    #[serde(default = "default_contact_stiffness")]
    pub contact_stiffness_n_per_m: f64,
    /// Normal damping of the batch stepper's penalty contact, N s/m.
    #[serde(default = "default_contact_damping")]
    pub contact_damping_n_s_per_m: f64,
    /// Rigid surroundings.
    pub surfaces: Vec<Surface>,
}

impl Default for SceneConfig {
    fn default() -> Self {
        SceneConfig {
            dt_s: 1.0 / 240.0,
            gravity_m_s2: 9.81,
            revolute_stiffness: 50.0,
            revolute_damping: 1.0,
            prismatic_stiffness: 5000.0,
            prismatic_damping: 50.0,
            tcp_sensor_radius_m: 0.005,
            contact_stiffness_n_per_m: default_contact_stiffness(),
            contact_damping_n_s_per_m: default_contact_damping(),
            solver_iterations: 4,
            surfaces: vec![],
        }
    }
}

fn default_contact_stiffness() -> f64 {
    1e5
}

fn default_contact_damping() -> f64 {
    500.0
}

impl Surface {
    /// A point of the surface and its normal pointing out of the solid (towards the robot).
    pub fn point_and_normal(&self) -> (Vector3<f64>, Vector3<f64>) {
        match *self {
            Surface::Plane { height_m } => (Vector3::new(0.0, 0.0, height_m), -Vector3::z()),
            Surface::Ramp {
                height_m,
                slope_rad,
            } => (
                Vector3::new(0.0, 0.0, height_m),
                Vector3::new(slope_rad.sin(), 0.0, -slope_rad.cos()),
            ),
        }
    }
}

/// The rapier scene and the handles to read it.
pub struct Sim {
    world: PhysicsWorld,
    joints: [MultibodyJointHandle; N_JOINTS],
    top: RigidBodyHandle,
    tcp_sensor: ColliderHandle,
    chain: ChainGeometry,
    limits: Limits,
    config: SceneConfig,
    command: Posture,
}

fn v(x: f64, y: f64, z: f64) -> Vector {
    Vector::new(x, y, z)
}

fn axis_of(kind: JointKind) -> JointAxis {
    match kind {
        JointKind::Prismatic => JointAxis::LinX,
        _ => JointAxis::AngX,
    }
}

impl Sim {
    /// Builds the scene at the rest posture (projected onto the limits).
    pub fn new(chain: &ChainGeometry, limits: &Limits, config: SceneConfig) -> Result<Self> {
        limits.validate()?;
        chain.validate()?;
        if !(config.dt_s > 0.0) || !config.dt_s.is_finite() {
            return Err(SurrogateError::Invalid(format!(
                "time step {} s must be positive",
                config.dt_s
            )));
        }
        let mut world = PhysicsWorld::new();
        world.gravity = v(0.0, 0.0, -config.gravity_m_s2);
        world.integration_parameters.dt = config.dt_s;
        world.integration_parameters.num_solver_iterations = config.solver_iterations.max(1);
        let h = chain.segment_length_m;
        // Cylinders are along local y in rapier: turn them onto z.
        let upright = AngVector::new(std::f64::consts::FRAC_PI_2, 0.0, 0.0);
        // The links of the chain never touch each other (the bellows is one body); they touch
        // the surroundings only.
        let robot_groups =
            InteractionGroups::new(Group::GROUP_1, Group::GROUP_2, InteractionTestMode::And);
        let world_groups =
            InteractionGroups::new(Group::GROUP_2, Group::GROUP_1, InteractionTestMode::And);
        let cyl = |r: f64, len: f64, z: f64| {
            ColliderBuilder::cylinder(0.5 * len, r)
                .collision_groups(robot_groups)
                .translation(v(0.0, 0.0, z))
                .rotation(upright)
                .density(0.0)
        };
        let mass = |m: f64, r: f64, len: f64, z: f64| {
            let ixx = m * (3.0 * r * r + len * len) / 12.0;
            MassProperties::new(v(0.0, 0.0, z), m, AngVector::new(ixx, ixx, 0.5 * m * r * r))
        };
        let base = world.insert_body(RigidBodyBuilder::fixed());
        world.insert_collider(
            cyl(
                chain.base_radius_m,
                chain.base_height_m,
                0.5 * chain.base_height_m,
            ),
            Some(base),
        );
        let start = limits.project(&[0.0; N_JOINTS])?;
        let mut parent = base;
        let mut anchor = chain.base_height_m;
        let mut top = base;
        let mut joints = Vec::with_capacity(N_JOINTS);
        for j in 0..N_JOINTS {
            let kind = KINDS[j];
            let (child_mass, collider) = match kind {
                JointKind::RevoluteX => (
                    MassProperties::new(
                        v(0.0, 0.0, 0.0),
                        chain.dummy_mass_kg,
                        AngVector::splat(1e-9),
                    ),
                    None,
                ),
                JointKind::RevoluteY if j == N_JOINTS - 1 => (
                    mass(
                        chain.link_mass_kg,
                        chain.top_radius_m,
                        chain.top_thickness_m,
                        0.5 * chain.top_thickness_m,
                    ),
                    Some(cyl(
                        chain.top_radius_m,
                        chain.top_thickness_m,
                        0.5 * chain.top_thickness_m,
                    )),
                ),
                _ => (
                    mass(chain.link_mass_kg, chain.link_radius_m, 0.5 * h, 0.25 * h),
                    Some(cyl(chain.link_radius_m, 0.5 * h, 0.25 * h)),
                ),
            };
            let child = world.insert_body(
                RigidBodyBuilder::dynamic()
                    .additional_mass_properties(child_mass)
                    .can_sleep(false),
            );
            if let Some(c) = collider {
                world.insert_collider(c, Some(child));
            }
            let [lo, hi] = limits.range(j);
            let (stiff, damp) = match kind {
                JointKind::Prismatic => (config.prismatic_stiffness, config.prismatic_damping),
                _ => (config.revolute_stiffness, config.revolute_damping),
            };
            let joint: GenericJoint = match kind {
                JointKind::RevoluteX | JointKind::RevoluteY => {
                    let axis = if kind == JointKind::RevoluteX {
                        Vector::X
                    } else {
                        Vector::Y
                    };
                    RevoluteJointBuilder::new(axis)
                        .local_anchor1(v(0.0, 0.0, anchor))
                        .local_anchor2(v(0.0, 0.0, 0.0))
                        .limits([lo, hi])
                        .motor_position(start[j], stiff, damp)
                        .motor_model(MotorModel::ForceBased)
                        .contacts_enabled(false)
                        .build()
                        .into()
                }
                JointKind::Prismatic => PrismaticJointBuilder::new(Vector::Z)
                    .local_anchor1(v(0.0, 0.0, anchor))
                    .local_anchor2(v(0.0, 0.0, 0.0))
                    .limits([lo, hi])
                    .motor_position(start[j], stiff, damp)
                    .motor_model(MotorModel::ForceBased)
                    .contacts_enabled(false)
                    .build()
                    .into(),
            };
            let handle = world
                .multibody_joints
                .insert(parent, child, joint, true)
                .ok_or_else(|| SurrogateError::Solver(format!("rapier refused joint {j}")))?;
            joints.push(handle);
            anchor = match kind {
                JointKind::RevoluteX => 0.0,
                _ => 0.5 * h,
            };
            parent = child;
            top = child;
        }
        let tcp_sensor = world.insert_collider(
            ColliderBuilder::ball(config.tcp_sensor_radius_m)
                .collision_groups(robot_groups)
                .translation(v(0.0, 0.0, chain.tcp_offset_m))
                .density(0.0),
            Some(top),
        );
        let ground = world.insert_body(RigidBodyBuilder::fixed());
        for s in &config.surfaces {
            let (o, n) = s.point_and_normal();
            world.insert_collider(
                ColliderBuilder::halfspace(rapier3d_f64::na::Unit::new_unchecked(v(n.x, n.y, n.z)))
                    .collision_groups(world_groups)
                    .translation(v(o.x, o.y, o.z)),
                Some(ground),
            );
        }
        let joints: [MultibodyJointHandle; N_JOINTS] = joints
            .try_into()
            .map_err(|_| SurrogateError::Solver("joint count".into()))?;
        let mut sim = Sim {
            world,
            joints,
            top,
            tcp_sensor,
            chain: *chain,
            limits: *limits,
            config,
            command: start,
        };
        sim.set_posture(&start)?;
        Ok(sim)
    }

    /// Teleports the joints to a feasible posture at rest and commands it (an infeasible one is
    /// an error, as for [`Sim::command`]).
    pub fn set_posture(&mut self, q: &Posture) -> Result<Posture> {
        self.limits.check(q)?;
        let q = *q;
        for j in 0..N_JOINTS {
            let (mb, link) = self
                .world
                .multibody_joints
                .get_mut(self.joints[j])
                .ok_or_else(|| SurrogateError::Solver(format!("joint {j} vanished")))?;
            let ax = axis_of(KINDS[j]);
            let Some(l) = mb.link_mut(link) else {
                return Err(SurrogateError::Solver(format!("joint {j} has no link")));
            };
            // Each joint has one free coordinate: move it by the difference.
            let disp = q[j] - l.joint.coords()[ax as usize];
            l.joint.apply_displacement(&[disp]);
        }
        for j in 0..N_JOINTS {
            if let Some((mb, _)) = self.world.multibody_joints.get_mut(self.joints[j]) {
                mb.generalized_velocity_mut().fill(0.0);
                mb.forward_kinematics(&self.world.bodies, true);
                mb.update_rigid_bodies(&mut self.world.bodies, true);
                break;
            }
        }
        self.command(&q)
    }

    /// Commands a posture: sent to the position motors if it satisfies the joint limits and the
    /// grouped constraints; otherwise [`crate::SurrogateError::OutOfRange`] (or `NotFinite`)
    /// names the first offending joint, its value and its allowed range, and nothing changes.
    /// Returns the posture commanded.
    pub fn command(&mut self, q: &Posture) -> Result<Posture> {
        self.limits.check(q)?;
        self.send(q)
    }

    /// Commands the posture clamped onto the limits and grouped constraints
    /// ([`Limits::project`]); returns what was commanded. Non-finite values are still an error.
    pub fn command_clamped(&mut self, q: &Posture) -> Result<Posture> {
        let q = self.limits.project(q)?;
        self.send(&q)
    }

    fn send(&mut self, q: &Posture) -> Result<Posture> {
        let q = *q;
        let c = &self.config;
        for j in 0..N_JOINTS {
            let (stiff, damp) = match KINDS[j] {
                JointKind::Prismatic => (c.prismatic_stiffness, c.prismatic_damping),
                _ => (c.revolute_stiffness, c.revolute_damping),
            };
            let (mb, link) = self
                .world
                .multibody_joints
                .get_mut(self.joints[j])
                .ok_or_else(|| SurrogateError::Solver(format!("joint {j} vanished")))?;
            if let Some(l) = mb.link_mut(link) {
                l.joint
                    .data
                    .set_motor_position(axis_of(KINDS[j]), q[j], stiff, damp);
            }
        }
        self.command = q;
        Ok(q)
    }

    /// The last commanded posture.
    pub fn commanded(&self) -> Posture {
        self.command
    }

    /// Advances one time step.
    pub fn step(&mut self) {
        self.world.step();
    }

    /// Current joint positions.
    pub fn posture(&self) -> Posture {
        std::array::from_fn(|j| {
            self.world
                .multibody_joints
                .get(self.joints[j])
                .and_then(|(mb, link)| mb.link(link))
                .map_or(f64::NAN, |l| l.joint.coords()[axis_of(KINDS[j]) as usize])
        })
    }

    /// Current TCP position, m.
    pub fn tcp(&self) -> Vector3<f64> {
        let b = &self.world.bodies[self.top];
        let p = b.position() * v(0.0, 0.0, self.chain.tcp_offset_m);
        Vector3::new(p.x, p.y, p.z)
    }

    /// Contact force of the surroundings on the TCP sensor over the last step, N.
    pub fn tcp_force(&self) -> Vector3<f64> {
        let mut f = Vector::ZERO;
        for pair in self.world.narrow_phase.contact_pairs_with(self.tcp_sensor) {
            // The pair's impulse pushes collider2 along its normal, collider1 against it.
            let imp = pair.total_impulse();
            f += if pair.collider2 == self.tcp_sensor {
                imp
            } else {
                -imp
            };
        }
        let f = f / self.config.dt_s;
        Vector3::new(f.x, f.y, f.z)
    }

    /// The scene settings.
    pub fn config(&self) -> &SceneConfig {
        &self.config
    }
}
