//! The tasks of Ch.4.8.4 and 4.9.3: reference paths, loads and force targets of an episode.
//!
//! Every task is a sequence of [`POINTS`] targets, one per control step. Positions are relative
//! to the TCP at rest (the origin of the tasks); the paths lie above it, where the extensions
//! can carry the TCP while it bends.

use crate::robot::Load;
use nalgebra::Vector3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

/// Targets per episode (the dissertation's 100 points).
pub const POINTS: usize = 100;

/// Radius of the circle and of the star's outer vertices, m.
pub const PATH_RADIUS_M: f64 = 0.025;

/// Height of the circle, star and weight paths above the rest TCP, m.
pub const PATH_LIFT_M: f64 = 0.015;

/// The tasks.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum TaskKind {
    /// Task 1: a horizontal circle of radius 25 mm.
    Circle,
    /// Task 1: a five-pointed star inscribed in the circle.
    Star,
    /// Task 2 (deformation): the circle with a weight of 50-200 g hanging from the TCP.
    Weight,
    /// Task 2 (force control): press a horizontal plate with a target force.
    Force,
    /// Task 3: the tilted ellipse of eq 4.28 on a sloped plate with a 1 N normal force.
    Ellipse,
}

impl TaskKind {
    /// All tasks.
    pub const ALL: [TaskKind; 5] = [
        TaskKind::Circle,
        TaskKind::Star,
        TaskKind::Weight,
        TaskKind::Force,
        TaskKind::Ellipse,
    ];

    /// The task's name (`circle`, `star`, `weight`, `force`, `ellipse`).
    pub fn name(self) -> &'static str {
        match self {
            TaskKind::Circle => "circle",
            TaskKind::Star => "star",
            TaskKind::Weight => "weight",
            TaskKind::Force => "force",
            TaskKind::Ellipse => "ellipse",
        }
    }

    /// The task of a name.
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|t| t.name() == name)
    }

    /// Weight alpha of the position reward in eq 4.29.
    pub fn alpha(self) -> f64 {
        match self {
            TaskKind::Circle | TaskKind::Star | TaskKind::Weight => 1.0,
            TaskKind::Force => 0.0,
            TaskKind::Ellipse => 0.5,
        }
    }

    /// Whether the task has a force objective.
    pub fn has_force(self) -> bool {
        self.alpha() < 1.0
    }
}

/// Contact settings of the plate tasks.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ContactConfig {
    /// Penalty stiffness, N/m.
    pub stiffness_n_m: f64,
    /// Penalty damping, N s/m.
    pub damping_n_s_m: f64,
}

impl Default for ContactConfig {
    fn default() -> Self {
        ContactConfig {
            stiffness_n_m: 5000.0,
            damping_n_s_m: 5.0,
        }
    }
}

/// One episode's targets and load, in the robot's frame (m, N).
#[derive(Debug, Clone, PartialEq)]
pub struct Episode {
    /// Which task.
    pub task: TaskKind,
    /// Target TCP per step, m.
    pub targets: Vec<Vector3<f64>>,
    /// Target force of the surroundings on the TCP per step, N (zero without force objective).
    pub force_targets: Vec<Vector3<f64>>,
    /// The load during the episode.
    pub load: Load,
}

/// `n` points of a horizontal circle of radius `r` about `c`, counter-clockwise from +x.
pub fn circle(c: &Vector3<f64>, r: f64, n: usize) -> Vec<Vector3<f64>> {
    (0..n)
        .map(|k| {
            let t = 2.0 * PI * k as f64 / n as f64;
            c + Vector3::new(r * t.cos(), r * t.sin(), 0.0)
        })
        .collect()
}

/// `n` points evenly spaced by arc length along a five-pointed star (outer radius `r`, the inner
/// vertices where the edges of the pentagram cross, r sin 18 deg / sin 126 deg), from the vertex
/// on +x.
pub fn star(c: &Vector3<f64>, r: f64, n: usize) -> Vec<Vector3<f64>> {
    let inner = r * (18f64.to_radians().sin() / 126f64.to_radians().sin());
    let verts: Vec<Vector3<f64>> = (0..10)
        .map(|i| {
            let t = PI * i as f64 / 5.0;
            let rr = if i % 2 == 0 { r } else { inner };
            c + Vector3::new(rr * t.cos(), rr * t.sin(), 0.0)
        })
        .collect();
    let edge = (verts[1] - verts[0]).norm();
    let total = 10.0 * edge;
    (0..n)
        .map(|k| {
            let s = total * k as f64 / n as f64;
            let i = ((s / edge).floor() as usize).min(9);
            let f = s / edge - i as f64;
            verts[i] + (verts[(i + 1) % 10] - verts[i]) * f
        })
        .collect()
}

/// `n` points of the tilted ellipse of eq 4.28 about `c` (x = 25 cos t, y = 25 sin t,
/// z = 10 cos(t - pi) + 10, mm), t from 0.
pub fn ellipse(c: &Vector3<f64>, n: usize) -> Vec<Vector3<f64>> {
    (0..n)
        .map(|k| {
            let t = 2.0 * PI * k as f64 / n as f64;
            c + Vector3::new(
                0.025 * t.cos(),
                0.025 * t.sin(),
                0.010 * (t - PI).cos() + 0.010,
            )
        })
        .collect()
}

/// Normal of the ellipse's plane (z = z_c + 10 mm - 0.4 (x - x_c)) pointing down, out of the
/// sloped plate above it.
pub fn ellipse_plate_normal() -> Vector3<f64> {
    -Vector3::new(0.4, 0.0, 1.0).normalize()
}

/// Rotates a closed path so that it starts at point `start`.
fn rotate(mut v: Vec<Vector3<f64>>, start: usize) -> Vec<Vector3<f64>> {
    let n = v.len().max(1);
    v.rotate_left(start % n);
    v
}

impl Episode {
    /// The episode of `task` drawn from `seed`, about the rest TCP `origin`. Closed paths start
    /// at a seeded point; the weight is uniform in 50..200 g; the force task's contact point is
    /// uniform in a disc of 10 mm and its target changes every 25 steps (uniform in 0.5..2 N).
    pub fn new(task: TaskKind, origin: &Vector3<f64>, contact: &ContactConfig, seed: u64) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let start = rng.random_range(0..POINTS);
        let center = origin + Vector3::new(0.0, 0.0, PATH_LIFT_M);
        let zero = vec![Vector3::zeros(); POINTS];
        match task {
            TaskKind::Circle => Episode {
                task,
                targets: rotate(circle(&center, PATH_RADIUS_M, POINTS), start),
                force_targets: zero,
                load: Load::Free,
            },
            TaskKind::Star => Episode {
                task,
                targets: rotate(star(&center, PATH_RADIUS_M, POINTS), start),
                force_targets: zero,
                load: Load::Free,
            },
            TaskKind::Weight => Episode {
                task,
                targets: rotate(circle(&center, PATH_RADIUS_M, POINTS), start),
                force_targets: zero,
                load: Load::Weight {
                    mass_kg: rng.random_range(0.05..0.2),
                },
            },
            TaskKind::Force => {
                let (r, t) = (
                    0.010 * rng.random_range(0.0f64..1.0).sqrt(),
                    rng.random_range(0.0..2.0 * PI),
                );
                let plate_z = origin.z + 0.010;
                let point = Vector3::new(origin.x + r * t.cos(), origin.y + r * t.sin(), plate_z);
                let levels: Vec<f64> = (0..4).map(|_| rng.random_range(0.5..2.0)).collect();
                Episode {
                    task,
                    targets: vec![point; POINTS],
                    force_targets: (0..POINTS)
                        .map(|k| Vector3::new(0.0, 0.0, -levels[k * 4 / POINTS]))
                        .collect(),
                    load: Load::Plane {
                        point_m: [point.x, point.y, plate_z],
                        normal: [0.0, 0.0, -1.0],
                        stiffness_n_m: contact.stiffness_n_m,
                        damping_n_s_m: contact.damping_n_s_m,
                    },
                }
            }
            TaskKind::Ellipse => {
                let c = origin + Vector3::new(0.0, 0.0, 0.005);
                let n = ellipse_plate_normal();
                Episode {
                    task,
                    targets: rotate(ellipse(&c, POINTS), start),
                    force_targets: vec![n; POINTS],
                    load: Load::Plane {
                        point_m: [c.x, c.y, c.z + 0.010],
                        normal: [n.x, n.y, n.z],
                        stiffness_n_m: contact.stiffness_n_m,
                        damping_n_s_m: contact.damping_n_s_m,
                    },
                }
            }
        }
    }

    /// The unseen path of Ch.4.10.4 (Fig 4.26-A): a figure-eight on a curved surface, pressed
    /// with 1 N along the surface normal. The surface is the underside of a ball of radius
    /// [`FIGURE_EIGHT_BALL_RADIUS_M`] whose lowest point is [`PATH_LIFT_M`] above the rest TCP
    /// `origin`; the path is the lemniscate of Gerono x = 25 sin t, y = 12.5 sin 2t (mm) lifted
    /// onto that surface, starting at a seeded point. Scored as Task 3 (alpha = 0.5).
    pub fn figure_eight(origin: &Vector3<f64>, contact: &ContactConfig, seed: u64) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let start = rng.random_range(0..POINTS);
        let r = FIGURE_EIGHT_BALL_RADIUS_M;
        let centre = origin + Vector3::new(0.0, 0.0, PATH_LIFT_M + r);
        let targets = rotate(figure_eight(&centre, r, POINTS), start);
        let force_targets = targets.iter().map(|p| (p - centre).normalize()).collect();
        Episode {
            task: TaskKind::Ellipse,
            targets,
            force_targets,
            load: Load::Sphere {
                centre_m: [centre.x, centre.y, centre.z],
                radius_m: r,
                stiffness_n_m: contact.stiffness_n_m,
                damping_n_s_m: contact.damping_n_s_m,
            },
        }
    }

    /// The force the expert plans with at step `k`: the weight, or the target contact force.
    pub fn planned_force(&self, k: usize, gravity_m_s2: f64) -> Vector3<f64> {
        match self.load {
            Load::Free => Vector3::zeros(),
            Load::Weight { mass_kg } => Vector3::new(0.0, 0.0, -mass_kg * gravity_m_s2),
            Load::Plane { .. } | Load::Sphere { .. } => self.force_targets[k],
        }
    }

    /// Where the expert puts the TCP at step `k`: the target, pressed into the surface by the
    /// depth at which the penalty spring gives the target force.
    pub fn planned_tcp(&self, k: usize) -> Vector3<f64> {
        let t = self.targets[k];
        match (self.load.surface_normal(&t), self.load.contact_stiffness()) {
            (Some(n), Some(k_n_m)) => {
                let depth = n.dot(&self.force_targets[k]).max(0.0) / k_n_m;
                t - n * depth
            }
            _ => t,
        }
    }
}

/// Radius of the ball whose underside carries the figure-eight, m.
pub const FIGURE_EIGHT_BALL_RADIUS_M: f64 = 0.1;

/// `n` points of the lemniscate of Gerono (x = 25 sin t, y = 12.5 sin 2t, mm) on the lower
/// surface of the ball of radius `r` about `centre`, t from 0.
pub fn figure_eight(centre: &Vector3<f64>, r: f64, n: usize) -> Vec<Vector3<f64>> {
    (0..n)
        .map(|k| {
            let t = 2.0 * PI * k as f64 / n as f64;
            let (x, y) = (
                PATH_RADIUS_M * t.sin(),
                0.5 * PATH_RADIUS_M * (2.0 * t).sin(),
            );
            centre + Vector3::new(x, y, -(r * r - x * x - y * y).sqrt())
        })
        .collect()
}
