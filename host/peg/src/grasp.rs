//! How the pads hold the peg: rigidly (a fixed joint) or through the gels' shear, with Coulomb
//! slip once a load exceeds what the pads' friction holds.
//!
//! The compliant grasp is a joint between the gripper and the peg whose three free directions
//! are the ones two gel pads pressed on the peg's flats leave soft: sliding along the pads
//! (gripper y and z) and turning about their normal (gripper x). Each is a spring with the gel
//! layer's shear stiffness; the other three stay locked (the pads' normal stiffness and their
//! spread along x make those directions two orders of magnitude stiffer). A spring whose force
//! passes the pads' friction limit moves its rest position (the peg slips in the hand and stays
//! where it slipped to).

use ocm_fem::material::{check_elastic, lame};
use rapier3d_f64::prelude::*;
use serde::{Deserialize, Serialize};

use crate::error::{PegError, Result, non_negative, positive};

/// How the pads hold the peg.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Grasp {
    /// A fixed joint: the peg keeps its in-hand pose whatever it meets.
    #[default]
    Rigid,
    /// The gels' shear as springs in the pads' plane, with Coulomb slip.
    Compliant(GraspCompliance),
}

/// Springs and friction limits of a compliant grasp (both pads together).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct GraspCompliance {
    /// Stiffness of sliding along the pads (gripper y and z), N/m.
    pub shear_stiffness_n_m: f64,
    /// Stiffness of turning about the pads' normal (gripper x), N m/rad.
    pub twist_stiffness_nm_rad: f64,
    /// Tangential force at which the peg slides along the pads, N.
    pub slip_force_n: f64,
    /// Torque about the pads' normal at which the peg turns between them, N m.
    pub slip_torque_nm: f64,
    /// Damping of each spring as a fraction of the peg's critical damping.
    pub damping_ratio: f64,
}

/// Gel and pad values [`GraspCompliance::from_gel`] derives the grasp from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GelGrip {
    /// Young's modulus of the gel, Pa.
    pub modulus_pa: f64,
    /// Poisson's ratio of the gel.
    pub poisson: f64,
    /// Gel thickness, m.
    pub thickness_m: f64,
    /// How far each pad presses into the peg's flat, m.
    pub squeeze_m: f64,
    /// Width of the patch on each pad (the peg's flat), m.
    pub patch_width_m: f64,
    /// Length of the patch along the fingers, m.
    pub patch_length_m: f64,
    /// Coulomb friction coefficient of gel on peg.
    pub friction: f64,
}

impl GraspCompliance {
    /// The grasp of two bonded gel layers of thickness h and shear modulus G = E / (2 (1 + nu))
    /// on rectangular patches of area A and polar moment J about their centre: sliding
    /// stiffness 2 G A / h and twisting stiffness 2 G J / h (simple shear of each layer); each
    /// pad presses with N = E / h A squeeze (the linear foundation of the contact module),
    /// so the pads hold 2 mu N against sliding and 2 mu (N / A) int |r| dA against turning
    /// (uniform pressure). Critically damped.
    pub fn from_gel(g: &GelGrip) -> Result<Self> {
        check_elastic(g.modulus_pa, g.poisson)
            .map_err(|e| PegError::Invalid(format!("grasp gel: {e}")))?;
        for (name, v) in [
            ("thickness_m", g.thickness_m),
            ("squeeze_m", g.squeeze_m),
            ("patch_width_m", g.patch_width_m),
            ("patch_length_m", g.patch_length_m),
            ("friction", g.friction),
        ] {
            positive(&format!("grasp {name}"), v)?;
        }
        let (shear_pa, _) = lame(g.modulus_pa, g.poisson);
        let (a, b) = (g.patch_width_m, g.patch_length_m);
        let area = a * b;
        let polar = area * (a * a + b * b) / 12.0;
        let normal_n = g.modulus_pa / g.thickness_m * area * g.squeeze_m;
        Ok(Self {
            shear_stiffness_n_m: 2.0 * shear_pa * area / g.thickness_m,
            twist_stiffness_nm_rad: 2.0 * shear_pa * polar / g.thickness_m,
            slip_force_n: 2.0 * g.friction * normal_n,
            slip_torque_nm: 2.0 * g.friction * normal_n * mean_radius(a, b),
            damping_ratio: 1.0,
        })
    }

    /// Checks every value, naming the first bad one.
    pub fn validate(&self) -> Result<()> {
        for (name, v) in [
            ("shear_stiffness_n_m", self.shear_stiffness_n_m),
            ("twist_stiffness_nm_rad", self.twist_stiffness_nm_rad),
            ("slip_force_n", self.slip_force_n),
            ("slip_torque_nm", self.slip_torque_nm),
        ] {
            positive(&format!("grasp {name}"), v)?;
        }
        non_negative("grasp damping_ratio", self.damping_ratio)?;
        Ok(())
    }
}

/// Mean distance of a point of an a x b rectangle from its centre: with half-sides p, q and
/// d = sqrt(p^2 + q^2), the integral over a quarter is
/// (2 p q d + p^3 ln((q + d) / p) + q^3 ln((p + d) / q)) / 6.
fn mean_radius(a: f64, b: f64) -> f64 {
    let (p, q) = (0.5 * a, 0.5 * b);
    let d = p.hypot(q);
    (2.0 * p * q * d + p.powi(3) * ((q + d) / p).ln() + q.powi(3) * ((p + d) / q).ln())
        / (6.0 * p * q)
}

/// The peg's mass, kg, and its moment of inertia about the gripper's x axis through a point of
/// its axis `below_top_m` under its top face, kg m^2 (a hexagonal prism of circumradius
/// `radius_m`, length `length_m`).
pub(crate) fn peg_inertia(
    density_kg_m3: f64,
    radius_m: f64,
    length_m: f64,
    below_top_m: f64,
) -> (f64, f64) {
    let area = 1.5 * 3f64.sqrt() * radius_m * radius_m;
    let mass = density_kg_m3 * area * length_m;
    // A regular hexagon's second moment of area about a diameter is 5 sqrt(3) / 16 R^4.
    let section = 5.0 * radius_m * radius_m / 24.0;
    let lever = 0.5 * length_m - below_top_m;
    let inertia = mass * (length_m * length_m / 12.0 + section + lever * lever);
    (mass, inertia)
}

/// A compliant grasp in a running scene: the joint, its frames and the springs' rest positions.
#[derive(Debug, Clone)]
pub(crate) struct HeldPeg {
    joint: ImpulseJointHandle,
    /// The joint's frame on the gripper (the drawn in-hand pose, moved to the patch centre).
    frame_gripper: Pose,
    /// The joint's frame on the peg (the patch centre on its axis).
    frame_peg: Pose,
    compliance: GraspCompliance,
    /// Critical damping of sliding and of turning.
    damping: [f64; 2],
    /// Rest positions of the springs: slide along y and z (m), turn about x (rad).
    rest: [f64; 3],
    /// Physics steps in which the peg slipped.
    slips: usize,
}

/// The relative pose of the joint's peg frame in its gripper frame: slide along y and z (m)
/// and turn about x (rad).
fn slide_and_turn(frame1_world: Pose, frame2_world: Pose) -> [f64; 3] {
    let rel = frame1_world.inverse() * frame2_world;
    let r = rel.rotation;
    [rel.translation.y, rel.translation.z, 2.0 * r.x.atan2(r.w)]
}

impl HeldPeg {
    /// Joins `peg` to `gripper` at the in-hand pose `in_hand` (of the peg's top-face frame in the
    /// gripper's frame), the springs centred `below_top_m` under the top face.
    pub(crate) fn insert(
        world: &mut PhysicsWorld,
        gripper: RigidBodyHandle,
        peg: RigidBodyHandle,
        in_hand: Pose,
        below_top_m: f64,
        compliance: GraspCompliance,
        mass_inertia: (f64, f64),
    ) -> Result<Self> {
        compliance.validate()?;
        let frame_peg = Pose::from_translation(Vector::new(0.0, 0.0, -below_top_m));
        let frame_gripper = in_hand * frame_peg;
        let (mass, inertia) = mass_inertia;
        let zeta = compliance.damping_ratio;
        let damping = [
            2.0 * zeta * (compliance.shear_stiffness_n_m * mass).sqrt(),
            2.0 * zeta * (compliance.twist_stiffness_nm_rad * inertia).sqrt(),
        ];
        let mut joint = GenericJointBuilder::new(
            JointAxesMask::LIN_X | JointAxesMask::ANG_Y | JointAxesMask::ANG_Z,
        )
        .local_frame1(frame_gripper)
        .local_frame2(frame_peg)
        .contacts_enabled(true)
        .build();
        for (axis, k, c, limit) in [
            (
                JointAxis::LinY,
                compliance.shear_stiffness_n_m,
                damping[0],
                compliance.slip_force_n,
            ),
            (
                JointAxis::LinZ,
                compliance.shear_stiffness_n_m,
                damping[0],
                compliance.slip_force_n,
            ),
            (
                JointAxis::AngX,
                compliance.twist_stiffness_nm_rad,
                damping[1],
                compliance.slip_torque_nm,
            ),
        ] {
            joint
                .set_motor_model(axis, MotorModel::ForceBased)
                .set_motor_position(axis, 0.0, k, c)
                // The spring cannot pull harder than the pads' friction holds within a step;
                // the rest position follows after the step (`HeldPeg::slip`).
                .set_motor_max_force(axis, limit);
        }
        let handle = world.insert_impulse_joint(gripper, peg, joint);
        Ok(Self {
            joint: handle,
            frame_gripper,
            frame_peg,
            compliance,
            damping,
            rest: [0.0; 3],
            slips: 0,
        })
    }

    /// Slide along y and z (m) and turn about x (rad) of the peg from its drawn in-hand pose.
    pub(crate) fn displacement(&self, gripper: Pose, peg: Pose) -> [f64; 3] {
        slide_and_turn(gripper * self.frame_gripper, peg * self.frame_peg)
    }

    /// The springs' rest positions (where the peg would settle without load).
    pub(crate) fn rest(&self) -> [f64; 3] {
        self.rest
    }

    /// Physics steps in which the peg slipped.
    pub(crate) fn slips(&self) -> usize {
        self.slips
    }

    /// After a physics step: where a spring's force exceeds the pads' friction, its rest
    /// position moves towards the peg until the force equals the limit (Coulomb slip; the
    /// sliding force is limited along its direction in the pads' plane, the torque apart).
    pub(crate) fn slip(
        &mut self,
        world: &mut PhysicsWorld,
        gripper: RigidBodyHandle,
        peg: RigidBodyHandle,
    ) {
        let (Some(g), Some(p)) = (world.bodies.get(gripper), world.bodies.get(peg)) else {
            return;
        };
        let d = self.displacement(*g.position(), *p.position());
        let c = self.compliance;
        let (ey, ez) = (d[0] - self.rest[0], d[1] - self.rest[1]);
        let force = c.shear_stiffness_n_m * ey.hypot(ez);
        let mut moved = false;
        if force > c.slip_force_n {
            let s = 1.0 - c.slip_force_n / force;
            self.rest[0] += s * ey;
            self.rest[1] += s * ez;
            moved = true;
        }
        let et = d[2] - self.rest[2];
        let torque = c.twist_stiffness_nm_rad * et.abs();
        if torque > c.slip_torque_nm {
            self.rest[2] += (1.0 - c.slip_torque_nm / torque) * et;
            moved = true;
        }
        if !moved {
            return;
        }
        self.slips += 1;
        if let Some(j) = world.impulse_joints.get_mut(self.joint, true) {
            j.data
                .set_motor_position(
                    JointAxis::LinY,
                    self.rest[0],
                    c.shear_stiffness_n_m,
                    self.damping[0],
                )
                .set_motor_position(
                    JointAxis::LinZ,
                    self.rest[1],
                    c.shear_stiffness_n_m,
                    self.damping[0],
                )
                .set_motor_position(
                    JointAxis::AngX,
                    self.rest[2],
                    c.twist_stiffness_nm_rad,
                    self.damping[1],
                );
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mean_radius_matches_the_closed_form_of_a_square() {
        // For a square of side s the mean distance from the centre is
        // s (sqrt(2) + ln(1 + sqrt(2))) / 6.
        let s: f64 = 0.01;
        let exact = s * (2f64.sqrt() + (1.0 + 2f64.sqrt()).ln()) / 6.0;
        assert!((mean_radius(s, s) - exact).abs() < 1e-5 * s);
    }

    #[test]
    fn gel_values_follow_the_shear_of_a_bonded_layer() {
        let g = GelGrip {
            modulus_pa: 0.3e6,
            poisson: 0.5 - 1e-9,
            thickness_m: 0.002,
            squeeze_m: 0.0003,
            patch_width_m: 0.004,
            patch_length_m: 0.012,
            friction: 1.0,
        };
        let c = GraspCompliance::from_gel(&g).unwrap();
        // G = E / 3 at nu = 1/2: 0.1 MPa; 2 G A / h = 2 * 1e5 * 4.8e-5 / 2e-3.
        assert!((c.shear_stiffness_n_m - 4800.0).abs() < 1e-3);
        let polar = 4.8e-5 * (16e-6 + 144e-6) / 12.0;
        assert!((c.twist_stiffness_nm_rad - 2.0 * 1e5 * polar / 0.002).abs() < 1e-9);
        // N = E / h A squeeze = 1.5e8 * 4.8e-5 * 3e-4 = 2.16 N per pad.
        assert!((c.slip_force_n - 4.32).abs() < 1e-9);
        assert!(c.slip_torque_nm < c.slip_force_n * 0.5 * 0.004f64.hypot(0.012));
        let bad = GelGrip { poisson: 0.5, ..g };
        assert!(GraspCompliance::from_gel(&bad).is_err());
        let bad = GelGrip {
            friction: f64::NAN,
            ..g
        };
        let e = GraspCompliance::from_gel(&bad).unwrap_err().to_string();
        assert!(e.contains("friction"), "{e}");
    }
}
