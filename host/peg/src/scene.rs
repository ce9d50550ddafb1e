//! The peg-in-hole scene on rapier: a velocity-controlled parallel gripper carrying two DIGIT
//! pads as rigid proxies, a hexagonal peg held between them with an in-hand pose error, and a
//! board with a hexagonal hole.
//!
//! Frames: the hole frame has its origin on the hole's axis in the board's top face, z up; the
//! hole's flats face +-x (and every 60 degrees). The gripper frame has its origin midway between
//! the pads' gel surfaces, closing direction x (left pad at -x), z up; it translates freely and
//! rotates about x only (roll), which is the rotation that can undo a tilt of the peg in the
//! pads' plane. The peg frame has its origin on the peg's axis in its top face, z along the
//! axis towards the top; its flats face +-x, so they lie flat on the pads.

use rapier3d_f64::prelude::*;
use serde::{Deserialize, Serialize};

use crate::contact::{GelFoundation, SensorContact, SensorFrame, pad_contact};
use crate::error::{PegError, Result, finite, non_negative, positive};
use crate::grasp::{GelGrip, Grasp, GraspCompliance, HeldPeg, peg_inertia};
use crate::sensor::{ErrorState, SensorNoise};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// Proprioception values: gripper x, y, z (m, hole frame) and roll (rad).
pub const N_PROPRIO: usize = 4;
/// Action values: gripper velocity vx, vy, vz (m/s, hole frame) and roll rate (rad/s).
pub const N_ACTION: usize = 4;
/// Gauss-Seidel passes per solver iteration in a scene with a compliant grasp.
pub const GRASP_PGS_ITERATIONS: usize = 32;

/// Dimensions, materials and time stepping of the scene.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SceneConfig {
    /// Peg width across flats, m.
    pub peg_across_flats_m: f64,
    /// Peg length, m.
    pub peg_length_m: f64,
    /// Nominal height of the peg's top face above the pad centres, m (inside the pads, so the
    /// patch shows where the peg ends).
    pub peg_top_m: f64,
    /// Peg density, kg/m^3.
    pub peg_density_kg_m3: f64,
    /// Hole clearance per flat, m (hole across flats = peg across flats + 2 clearance).
    pub clearance_m: f64,
    /// Hole depth (board thickness above the hole's bottom), m.
    pub hole_depth_m: f64,
    /// Gel size along the sensor's x (horizontal), m.
    pub pad_width_m: f64,
    /// Gel size along the sensor's y (along the fingers), m.
    pub pad_height_m: f64,
    /// Gel thickness, m.
    pub gel_thickness_m: f64,
    /// How far each pad presses into the peg's flat (the grasp), m.
    pub squeeze_m: f64,
    /// Young's modulus of the gel (linear foundation for the normal force), Pa.
    pub gel_modulus_pa: f64,
    /// Friction coefficient of peg and board.
    pub friction: f64,
    /// Physics time step, s.
    pub dt_s: f64,
    /// Physics steps per control step.
    pub substeps: usize,
    /// Largest commanded speed, m/s.
    pub max_speed_m_s: f64,
    /// Largest commanded roll rate, rad/s.
    pub max_rate_rad_s: f64,
    /// A trial succeeds when the peg's tip is this far below the board's top face, m.
    pub success_depth_m: f64,
    /// A trial fails when it has not succeeded after this long, s.
    pub time_limit_s: f64,
    /// How the pads hold the peg (rigid when a stored configuration does not say).
    #[serde(default)]
    pub grasp: Grasp,
    /// Errors of what the sensors report (exact when a stored configuration does not say).
    #[serde(default)]
    pub sensor_noise: SensorNoise,
    /// Time constant of a first-order low-pass on each sensor's latent before a policy reads
    /// it, s (0: the latest reading alone).
    #[serde(default)]
    pub touch_filter_s: f64,
}

impl Default for SceneConfig {
    fn default() -> Self {
        Self {
            peg_across_flats_m: 0.010,
            peg_length_m: 0.040,
            peg_top_m: 0.006,
            peg_density_kg_m3: 2700.0,
            clearance_m: 0.0005,
            hole_depth_m: 0.015,
            pad_width_m: 0.015,
            pad_height_m: 0.020,
            gel_thickness_m: 0.002,
            squeeze_m: 0.0003,
            gel_modulus_pa: 0.3e6,
            friction: 0.3,
            dt_s: 1.0 / 240.0,
            substeps: 4,
            max_speed_m_s: 0.02,
            max_rate_rad_s: 0.3,
            success_depth_m: 0.008,
            time_limit_s: 8.0,
            grasp: Grasp::Rigid,
            sensor_noise: SensorNoise::default(),
            touch_filter_s: 0.0,
        }
    }
}

impl SceneConfig {
    /// Checks every value, naming the first bad one.
    pub fn validate(&self) -> Result<()> {
        let must_be_positive = [
            ("peg_across_flats_m", self.peg_across_flats_m),
            ("peg_length_m", self.peg_length_m),
            ("peg_density_kg_m3", self.peg_density_kg_m3),
            ("clearance_m", self.clearance_m),
            ("hole_depth_m", self.hole_depth_m),
            ("pad_width_m", self.pad_width_m),
            ("pad_height_m", self.pad_height_m),
            ("gel_thickness_m", self.gel_thickness_m),
            ("squeeze_m", self.squeeze_m),
            ("gel_modulus_pa", self.gel_modulus_pa),
            ("dt_s", self.dt_s),
            ("max_speed_m_s", self.max_speed_m_s),
            ("max_rate_rad_s", self.max_rate_rad_s),
            ("success_depth_m", self.success_depth_m),
            ("time_limit_s", self.time_limit_s),
        ];
        for (name, v) in must_be_positive {
            positive(name, v)?;
        }
        if !(self.friction.is_finite() && self.friction >= 0.0) {
            return Err(PegError::Invalid(format!(
                "friction = {} must be finite and not negative",
                self.friction
            )));
        }
        if !self.peg_top_m.is_finite() || self.peg_top_m.abs() >= 0.5 * self.pad_height_m {
            return Err(PegError::Invalid(format!(
                "peg_top_m = {} must lie inside the pads (|.| < {} m)",
                self.peg_top_m,
                0.5 * self.pad_height_m
            )));
        }
        if self.squeeze_m >= self.gel_thickness_m {
            return Err(PegError::Invalid(format!(
                "squeeze_m = {} must be below the gel thickness {}",
                self.squeeze_m, self.gel_thickness_m
            )));
        }
        if self.success_depth_m > self.hole_depth_m {
            return Err(PegError::Invalid(format!(
                "success_depth_m = {} is deeper than the hole ({} m)",
                self.success_depth_m, self.hole_depth_m
            )));
        }
        if self.substeps == 0 {
            return Err(PegError::Invalid("substeps must be at least 1".into()));
        }
        if let Grasp::Compliant(c) = &self.grasp {
            c.validate()?;
        }
        non_negative("touch_filter_s", self.touch_filter_s)?;
        self.sensor_noise.validate()
    }

    /// The compliant grasp of this scene's gel pads on the peg's flats at the nominal in-hand
    /// pose (patch: one flat's width by the length of peg inside the pads), with gel-on-peg
    /// friction coefficient `friction` and the tactile gel's Poisson's ratio.
    pub fn gel_grasp(&self, friction: f64) -> Result<GraspCompliance> {
        GraspCompliance::from_gel(&GelGrip {
            modulus_pa: self.gel_modulus_pa,
            poisson: ocm_tactile::gel::GelMaterial::default().poisson,
            thickness_m: self.gel_thickness_m,
            squeeze_m: self.squeeze_m,
            patch_width_m: self.peg_across_flats_m / 3f64.sqrt(),
            patch_length_m: (self.peg_top_m + 0.5 * self.pad_height_m).min(self.peg_length_m),
            friction,
        })
    }

    /// Duration of one control step, s.
    pub fn control_dt_s(&self) -> f64 {
        self.dt_s * self.substeps as f64
    }

    /// Control steps before the time limit.
    pub fn max_control_steps(&self) -> usize {
        (self.time_limit_s / self.control_dt_s()).ceil() as usize
    }

    /// The gel foundation of the normal force.
    pub fn gel(&self) -> GelFoundation {
        GelFoundation {
            modulus_pa: self.gel_modulus_pa,
            thickness_m: self.gel_thickness_m,
        }
    }

    /// The sensor frame of pad `i` (0 left at -x, 1 right at +x) in the pad collider's frame:
    /// y along the fingers (up), z into the gel, x = y cross z.
    pub fn sensor_frame(&self, i: usize) -> SensorFrame {
        let h = 0.5 * self.gel_thickness_m;
        if i == 0 {
            SensorFrame {
                origin_m: [h, 0.0, 0.0],
                axes: [[0.0, -1.0, 0.0], [0.0, 0.0, 1.0], [-1.0, 0.0, 0.0]],
            }
        } else {
            SensorFrame {
                origin_m: [-h, 0.0, 0.0],
                axes: [[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]],
            }
        }
    }
}

/// How the peg sits in the hand, relative to the nominal grasp: offsets along the gripper's y
/// and z and a tilt about the closing direction x (the error that touch has to reveal).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct InHandError {
    /// Offset along the pads' horizontal direction (gripper y), m.
    pub offset_y_m: f64,
    /// Offset along the fingers (gripper z, positive: the peg sits higher), m.
    pub offset_z_m: f64,
    /// Tilt about the gripper's x axis, rad.
    pub tilt_rad: f64,
}

/// Pose of the gripper in the hole frame.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct GripperPose {
    /// Position x, m.
    pub x_m: f64,
    /// Position y, m.
    pub y_m: f64,
    /// Position z, m.
    pub z_m: f64,
    /// Rotation about x, rad.
    pub roll_rad: f64,
}

impl GripperPose {
    /// As `[x, y, z, roll]`.
    pub fn to_array(self) -> [f64; N_PROPRIO] {
        [self.x_m, self.y_m, self.z_m, self.roll_rad]
    }

    fn pose(self) -> Pose {
        Pose::from_parts(
            Vector::new(self.x_m, self.y_m, self.z_m),
            Rotation::from_rotation_x(self.roll_rad),
        )
    }
}

/// A running scene (the evolving state; the configuration is immutable).
pub struct PegScene {
    world: PhysicsWorld,
    gripper: RigidBodyHandle,
    peg: RigidBodyHandle,
    pads: [ColliderHandle; 2],
    peg_collider: ColliderHandle,
    config: SceneConfig,
    error: InHandError,
    /// The hole's axis in the believed frame, m.
    hole_m: [f64; 2],
    /// The compliant grasp's joint and springs (None: a fixed joint).
    held: Option<HeldPeg>,
    /// Largest |in-hand shift| seen at the end of a control step, per component.
    largest_shift: [f64; 3],
    /// The draws of the sensors' errors.
    sensor_rng: ChaCha8Rng,
    /// Each sensor's current errors (for errors correlated in time).
    sensor_errors: [ErrorState; 2],
    /// The low-passed latents of both sensors (None before the first reading).
    filtered: Option<Vec<f64>>,
    steps: usize,
}

/// Mixed into a trial's seed for its sensor errors, so that they do not repeat the draws of
/// the trial's initial condition.
const SENSOR_SEED_SALT: u64 = 0x5e45_0a15_e000_0001;

fn roll_of(r: &Rotation) -> f64 {
    // The bodies rotate about x only (up to solver round-off): q = (sin(a/2), 0, 0, cos(a/2)).
    2.0 * r.x.atan2(r.w)
}

impl PegScene {
    /// Builds the scene with the gripper at `start` holding the peg with `error`, the hole
    /// where the proprioception's frame says it is.
    pub fn new(config: &SceneConfig, start: GripperPose, error: InHandError) -> Result<Self> {
        Self::with_hole(config, start, error, [0.0; 2])
    }

    /// Builds the scene with the hole's axis at `hole_m` (x, y, m) in the frame the robot
    /// believes is the hole's: the frame of its proprioception and of [`PegScene::peg_tip`].
    pub fn with_hole(
        config: &SceneConfig,
        start: GripperPose,
        error: InHandError,
        hole_m: [f64; 2],
    ) -> Result<Self> {
        config.validate()?;
        for (name, v) in [
            ("hole x_m", hole_m[0]),
            ("hole y_m", hole_m[1]),
            ("start x_m", start.x_m),
            ("start y_m", start.y_m),
            ("start z_m", start.z_m),
            ("start roll_rad", start.roll_rad),
            ("offset_y_m", error.offset_y_m),
            ("offset_z_m", error.offset_z_m),
            ("tilt_rad", error.tilt_rad),
        ] {
            finite(name, v)?;
        }
        let c = config;
        let apothem = 0.5 * c.peg_across_flats_m;
        let side = c.peg_across_flats_m / 3f64.sqrt();
        if error.offset_y_m.abs() + 0.5 * side > 0.5 * c.pad_width_m
            || (c.peg_top_m + error.offset_z_m).abs() >= 0.5 * c.pad_height_m
            || error.tilt_rad.abs() > 0.5
        {
            return Err(PegError::Invalid(format!(
                "in-hand error {error:?} puts the peg off the pads (|offset_y| <= {} m, peg top \
                 inside the pads, |tilt| <= 0.5 rad)",
                0.5 * (c.pad_width_m - side)
            )));
        }
        let mut world = PhysicsWorld::new();
        world.gravity = Vector::new(0.0, 0.0, -9.81);
        world.integration_parameters.dt = c.dt_s;
        // Millimetre features: tolerances and prediction distance scale with the length unit
        // (default 1 m would allow 5 mm of penetration).
        world.integration_parameters.length_unit = 0.005;
        if matches!(c.grasp, Grasp::Compliant(_)) {
            // The grasp's springs act at the patch centre, 12 mm above the peg's centre of mass,
            // so the sliding and twisting rows are strongly coupled through the peg's inertia:
            // with one Gauss-Seidel pass per solver iteration a tilted peg's static turn came out
            // 4.2 times the spring's (8 passes 1.2 times, 32 passes within 1 %).
            world.integration_parameters.num_internal_pgs_iterations = GRASP_PGS_ITERATIONS;
        }
        world.integration_parameters.num_solver_iterations = 8;

        let pad_groups =
            InteractionGroups::new(Group::GROUP_1, Group::GROUP_2, InteractionTestMode::And);
        let peg_groups = InteractionGroups::new(
            Group::GROUP_2,
            Group::GROUP_1 | Group::GROUP_3,
            InteractionTestMode::And,
        );
        let board_groups =
            InteractionGroups::new(Group::GROUP_3, Group::GROUP_2, InteractionTestMode::And);

        // Board: six walls outside the hole's flats and a bottom plate, one fixed body.
        let board = world.insert_body(
            RigidBodyBuilder::fixed().translation(Vector::new(hole_m[0], hole_m[1], 0.0)),
        );
        let hole_apothem = apothem + c.clearance_m;
        let (wall, span, bottom) = (0.04, 0.1, 0.005);
        for k in 0..6 {
            let a = k as f64 * std::f64::consts::FRAC_PI_3;
            let r = hole_apothem + 0.5 * wall;
            world.insert_collider(
                ColliderBuilder::cuboid(0.5 * wall, 0.5 * span, 0.5 * c.hole_depth_m)
                    .position(Pose::from_parts(
                        Vector::new(r * a.cos(), r * a.sin(), -0.5 * c.hole_depth_m),
                        Rotation::from_rotation_z(a),
                    ))
                    .friction(c.friction)
                    .collision_groups(board_groups),
                Some(board),
            );
        }
        world.insert_collider(
            ColliderBuilder::cuboid(0.5 * span, 0.5 * span, 0.5 * bottom)
                .translation(Vector::new(0.0, 0.0, -c.hole_depth_m - 0.5 * bottom))
                .friction(c.friction)
                .collision_groups(board_groups),
            Some(board),
        );

        // Gripper: velocity-controlled (its velocity is set every physics step), no gravity,
        // roll only. The contact solver still stops it where the peg meets the board.
        let gripper = world.insert_body(
            RigidBodyBuilder::dynamic()
                .pose(start.pose())
                .enabled_rotations(true, false, false)
                .gravity_scale(0.0)
                .additional_mass_properties(MassProperties::new(
                    Vector::ZERO,
                    1.0,
                    AngVector::splat(1e-3),
                ))
                .can_sleep(false),
        );
        let pad_x = apothem - c.squeeze_m + 0.5 * c.gel_thickness_m;
        let mut pads = [ColliderHandle::invalid(); 2];
        for (i, sign) in [(0, -1.0), (1, 1.0)] {
            pads[i] = world.insert_collider(
                ColliderBuilder::cuboid(
                    0.5 * c.gel_thickness_m,
                    0.5 * c.pad_width_m,
                    0.5 * c.pad_height_m,
                )
                .translation(Vector::new(sign * pad_x, 0.0, 0.0))
                .density(0.0)
                .collision_groups(pad_groups)
                // Contacts are detected (they are what the sensors feel) but never solved: the
                // grasp is the fixed joint below.
                .solver_groups(InteractionGroups::none()),
                Some(gripper),
            );
        }

        // Peg: a hexagonal prism, flats facing +-x, held by a fixed joint at the in-hand pose.
        let radius = apothem / (std::f64::consts::FRAC_PI_6).cos();
        let mut verts = Vec::with_capacity(12);
        for z in [0.0, -c.peg_length_m] {
            for k in 0..6 {
                let a = std::f64::consts::FRAC_PI_6 + k as f64 * std::f64::consts::FRAC_PI_3;
                verts.push(Vector::new(radius * a.cos(), radius * a.sin(), z));
            }
        }
        let in_hand = Pose::from_parts(
            Vector::new(0.0, error.offset_y_m, c.peg_top_m + error.offset_z_m),
            Rotation::from_rotation_x(error.tilt_rad),
        );
        let peg = world.insert_body(
            RigidBodyBuilder::dynamic()
                .pose(start.pose() * in_hand)
                .can_sleep(false),
        );
        let peg_collider = world.insert_collider(
            ColliderBuilder::convex_hull(&verts)
                .ok_or_else(|| PegError::Scene("peg hull".into()))?
                .density(c.peg_density_kg_m3)
                .friction(c.friction)
                .collision_groups(peg_groups),
            Some(peg),
        );
        let held = match c.grasp {
            Grasp::Rigid => {
                world.insert_impulse_joint(
                    gripper,
                    peg,
                    FixedJointBuilder::new()
                        .local_frame1(in_hand)
                        .local_frame2(Pose::IDENTITY)
                        .contacts_enabled(true),
                );
                None
            }
            Grasp::Compliant(compliance) => {
                // The springs act at the centre of the peg's length inside the pads.
                let inside = (c.peg_top_m + error.offset_z_m + 0.5 * c.pad_height_m)
                    .clamp(0.0, c.peg_length_m);
                let below_top = 0.5 * inside;
                Some(HeldPeg::insert(
                    &mut world,
                    gripper,
                    peg,
                    in_hand,
                    below_top,
                    compliance,
                    peg_inertia(c.peg_density_kg_m3, radius, c.peg_length_m, below_top),
                )?)
            }
        };
        let mut scene = Self {
            world,
            gripper,
            peg,
            pads,
            peg_collider,
            config: c.clone(),
            error,
            hole_m,
            held,
            largest_shift: [0.0; 3],
            sensor_rng: ChaCha8Rng::seed_from_u64(SENSOR_SEED_SALT),
            sensor_errors: [ErrorState::default(); 2],
            filtered: None,
            steps: 0,
        };
        // One step at rest fills the contact manifolds of the grasp.
        scene.physics_step([0.0; N_ACTION]);
        scene.steps = 0;
        Ok(scene)
    }

    fn physics_step(&mut self, a: [f64; N_ACTION]) {
        if let Some(g) = self.world.bodies.get_mut(self.gripper) {
            g.set_linvel(Vector::new(a[0], a[1], a[2]), true);
            g.set_angvel(AngVector::new(a[3], 0.0, 0.0), true);
        }
        self.world.step();
        if let Some(h) = &mut self.held {
            h.slip(&mut self.world, self.gripper, self.peg);
        }
    }

    /// Clamps an action to the speed limits; non-finite values are an error.
    pub fn clamp_action(&self, a: [f64; N_ACTION]) -> Result<[f64; N_ACTION]> {
        for (i, v) in a.iter().enumerate() {
            finite(&format!("action[{i}]"), *v)?;
        }
        let mut a = a;
        let speed = (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
        if speed > self.config.max_speed_m_s {
            let s = self.config.max_speed_m_s / speed;
            a[0] *= s;
            a[1] *= s;
            a[2] *= s;
        }
        a[3] = a[3].clamp(-self.config.max_rate_rad_s, self.config.max_rate_rad_s);
        Ok(a)
    }

    /// Applies a gripper velocity (clamped to the limits) for one control step.
    pub fn step(&mut self, action: [f64; N_ACTION]) -> Result<()> {
        let a = self.clamp_action(action)?;
        for _ in 0..self.config.substeps {
            self.physics_step(a);
        }
        self.record_shift();
        self.steps += 1;
        Ok(())
    }

    /// Applies a gripper velocity without the speed limits (replay of a recorded path) for one
    /// control step; non-finite values are an error.
    pub fn step_unclamped(&mut self, action: [f64; N_ACTION]) -> Result<()> {
        for (i, v) in action.iter().enumerate() {
            finite(&format!("action[{i}]"), *v)?;
        }
        for _ in 0..self.config.substeps {
            self.physics_step(action);
        }
        self.record_shift();
        self.steps += 1;
        Ok(())
    }

    /// Time since the start, s.
    pub fn time_s(&self) -> f64 {
        self.steps as f64 * self.config.control_dt_s()
    }

    /// Control steps taken.
    pub fn steps(&self) -> usize {
        self.steps
    }

    /// The configuration.
    pub fn config(&self) -> &SceneConfig {
        &self.config
    }

    /// The in-hand error of this trial (privileged: the policy never sees it).
    pub fn error(&self) -> InHandError {
        self.error
    }

    /// How far the peg has moved in the hand from its drawn in-hand pose: slide along the
    /// pads' horizontal direction (gripper y, m), along the fingers (gripper z, m) and turn
    /// about the closing direction (rad). Zero for a rigid grasp (privileged).
    pub fn in_hand_shift(&self) -> [f64; 3] {
        match &self.held {
            Some(h) => h.displacement(
                *self.world.bodies[self.gripper].position(),
                *self.world.bodies[self.peg].position(),
            ),
            None => [0.0; 3],
        }
    }

    /// Where the compliant grasp's springs rest now (the slip so far), as
    /// [`PegScene::in_hand_shift`]; zero for a rigid grasp.
    pub fn slipped(&self) -> [f64; 3] {
        self.held.as_ref().map_or([0.0; 3], HeldPeg::rest)
    }

    fn record_shift(&mut self) {
        if self.held.is_some() {
            let d = self.in_hand_shift();
            for (m, v) in self.largest_shift.iter_mut().zip(d) {
                *m = m.max(v.abs());
            }
        }
    }

    /// The largest |in-hand shift| at the end of any control step so far, per component (as
    /// [`PegScene::in_hand_shift`]; zero for a rigid grasp).
    pub fn largest_shift(&self) -> [f64; 3] {
        self.largest_shift
    }

    /// Physics steps in which the peg slipped in the hand.
    pub fn slip_steps(&self) -> usize {
        self.held.as_ref().map_or(0, HeldPeg::slips)
    }

    /// The gripper's pose (proprioception).
    pub fn gripper(&self) -> GripperPose {
        let b = &self.world.bodies[self.gripper];
        let t = b.translation();
        GripperPose {
            x_m: t.x,
            y_m: t.y,
            z_m: t.z,
            roll_rad: roll_of(b.rotation()),
        }
    }

    /// Where the hole's axis really is in the frame the robot believes is the hole's, m
    /// (privileged).
    pub fn hole_m(&self) -> [f64; 2] {
        self.hole_m
    }

    /// The peg's tip (centre of its bottom face) in the frame the robot believes is the
    /// hole's (the hole frame when the hole is where it is believed), m, and its roll, rad
    /// (privileged).
    pub fn peg_tip(&self) -> ([f64; 3], f64) {
        let b = &self.world.bodies[self.peg];
        let p = b
            .position()
            .transform_point(Vector::new(0.0, 0.0, -self.config.peg_length_m));
        ([p.x, p.y, p.z], roll_of(b.rotation()))
    }

    /// Whether the peg's tip has reached the success depth.
    pub fn inserted(&self) -> bool {
        self.peg_tip().0[2] <= -self.config.success_depth_m
    }

    /// Draws the sensors' errors from stream `stream` of `seed` from now on (each trial its
    /// own stream, as its initial condition).
    pub fn seed_sensors(&mut self, seed: u64, stream: u64) {
        self.sensor_rng = ChaCha8Rng::seed_from_u64(seed ^ SENSOR_SEED_SALT);
        self.sensor_rng.set_stream(stream);
        self.sensor_errors = [ErrorState::default(); 2];
    }

    /// What the left (0) and right (1) sensor report: the contact with the configuration's
    /// sensor errors, drawn afresh or carried on from the last reading by their correlation
    /// time (the exact contact when there are none). Call once per control step.
    pub fn sensed(&mut self) -> Result<[SensorContact; 2]> {
        let [left, right] = self.contacts()?;
        let noise = self.config.sensor_noise;
        let dt = self.config.control_dt_s();
        let [el, er] = &mut self.sensor_errors;
        Ok([
            noise.read_after(&left, el, dt, &mut self.sensor_rng)?,
            noise.read_after(&right, er, dt, &mut self.sensor_rng)?,
        ])
    }

    /// Passes one control step's latents of both sensors through the configuration's low-pass
    /// (time constant `touch_filter_s`; the first reading starts it) and returns what a policy
    /// reads. Call once per control step.
    pub fn low_pass(&mut self, latents: Vec<f64>) -> Vec<f64> {
        let tau = self.config.touch_filter_s;
        if tau <= 0.0 {
            return latents;
        }
        let dt = self.config.control_dt_s();
        let a = dt / (tau + dt);
        let out = match self.filtered.take() {
            Some(prev) if prev.len() == latents.len() => prev
                .iter()
                .zip(&latents)
                .map(|(p, z)| p + a * (z - p))
                .collect(),
            _ => latents,
        };
        self.filtered = Some(out.clone());
        out
    }

    /// What the left (0) and right (1) sensor feel.
    pub fn contacts(&self) -> Result<[SensorContact; 2]> {
        let gel = self.config.gel();
        let left = pad_contact(
            &self.world,
            self.pads[0],
            self.peg_collider,
            &self.config.sensor_frame(0),
            &gel,
        )?;
        let right = pad_contact(
            &self.world,
            self.pads[1],
            self.peg_collider,
            &self.config.sensor_frame(1),
            &gel,
        )?;
        Ok([left, right])
    }
}
