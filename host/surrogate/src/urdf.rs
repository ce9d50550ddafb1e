//! The URDF of the surrogate (Ch.4.6.2): links with masses, inertias and collision cylinders,
//! joints with limits (eq 4.24), and a TCP frame on a fixed joint.
//!
//! Link names: `base`, `pair{i}_x` (dummy after the x rotation of pair i), `layer{k}` (body links,
//! k = 1..6, two per segment), `top`, `tcp`. Joint names: `x{i}`, `y{i}` (i = 1..4), `d{i}`
//! (i = 1..3), `tcp_joint`. The file also carries a `<mujoco>` element asking MuJoCo's compiler
//! to keep fixed-joint links (so the TCP body survives) and to use the inertias as written.

pub use crate::chain::joint_names;
use crate::chain::{ChainGeometry, JointKind, KINDS, N_JOINTS};
use crate::constraints::Limits;
use std::fmt::Write;

/// Effort limit written for every joint (N m or N); the position motors of the simulation use
/// their own gains.
pub const EFFORT_LIMIT: f64 = 100.0;
/// Velocity limit written for every joint (rad/s or m/s).
pub const VELOCITY_LIMIT: f64 = 2.0;

fn cylinder_inertia(m: f64, r: f64, h: f64) -> (f64, f64) {
    let ixx = m * (3.0 * r * r + h * h) / 12.0;
    (ixx, 0.5 * m * r * r)
}

fn link(out: &mut String, name: &str, mass: f64, shape: Option<(f64, f64, f64)>) {
    // shape: (radius, length, z of the cylinder centre in the link frame)
    let _ = writeln!(out, "  <link name=\"{name}\">");
    let (cz, ixx, izz) = match shape {
        Some((r, h, z)) => {
            let (a, b) = cylinder_inertia(mass, r, h);
            (z, a, b)
        }
        None => (0.0, 1e-9, 1e-9),
    };
    let _ = writeln!(
        out,
        "    <inertial>\n      <origin xyz=\"0 0 {cz:.9}\" rpy=\"0 0 0\"/>\n      <mass value=\"{mass:.9}\"/>\n      <inertia ixx=\"{ixx:.9e}\" ixy=\"0\" ixz=\"0\" iyy=\"{ixx:.9e}\" iyz=\"0\" izz=\"{izz:.9e}\"/>\n    </inertial>"
    );
    if let Some((r, h, z)) = shape {
        for tag in ["visual", "collision"] {
            let _ = writeln!(
                out,
                "    <{tag}>\n      <origin xyz=\"0 0 {z:.9}\" rpy=\"0 0 0\"/>\n      <geometry>\n        <cylinder radius=\"{r:.9}\" length=\"{h:.9}\"/>\n      </geometry>\n    </{tag}>"
            );
        }
    }
    let _ = writeln!(out, "  </link>");
}

#[allow(clippy::too_many_arguments)]
fn joint(
    out: &mut String,
    name: &str,
    kind: &str,
    parent: &str,
    child: &str,
    z: f64,
    axis: &str,
    limit: Option<[f64; 2]>,
) {
    let _ = writeln!(
        out,
        "  <joint name=\"{name}\" type=\"{kind}\">\n    <parent link=\"{parent}\"/>\n    <child link=\"{child}\"/>\n    <origin xyz=\"0 0 {z:.9}\" rpy=\"0 0 0\"/>\n    <axis xyz=\"{axis}\"/>"
    );
    if let Some([lo, hi]) = limit {
        let _ = writeln!(
            out,
            "    <limit lower=\"{lo}\" upper=\"{hi}\" effort=\"{EFFORT_LIMIT}\" velocity=\"{VELOCITY_LIMIT}\"/>"
        );
    }
    let _ = writeln!(out, "  </joint>");
}

/// The URDF text of the chain with the given limits.
pub fn to_urdf(name: &str, g: &ChainGeometry, limits: &Limits) -> String {
    let mut out = String::new();
    let _ = writeln!(out, "<?xml version=\"1.0\"?>");
    let _ = writeln!(
        out,
        "<!-- ocm surrogate of the bellows manipulator: SI units (m, kg, rad); joints x1 y1 d1 .. x4 y4 -->"
    );
    let _ = writeln!(out, "<robot name=\"{name}\">");
    let _ = writeln!(
        out,
        "  <mujoco>\n    <compiler fusestatic=\"false\" discardvisual=\"true\" balanceinertia=\"false\"/>\n  </mujoco>"
    );
    let h = g.segment_length_m;
    link(
        &mut out,
        "base",
        g.link_mass_kg,
        Some((g.base_radius_m, g.base_height_m, 0.5 * g.base_height_m)),
    );
    let mut parent = "base".to_string();
    let mut parent_z = g.base_height_m; // joint origin in the parent's frame
    let mut layer = 0;
    for j in 0..N_JOINTS {
        let kind = KINDS[j];
        let pair = j / 3 + 1;
        let lim = limits.range(j);
        match kind {
            JointKind::RevoluteX => {
                let child = format!("pair{pair}_x");
                link(&mut out, &child, g.dummy_mass_kg, None);
                joint(
                    &mut out,
                    &format!("x{pair}"),
                    "revolute",
                    &parent,
                    &child,
                    parent_z,
                    "1 0 0",
                    Some(lim),
                );
                parent = child;
                parent_z = 0.0;
            }
            JointKind::RevoluteY => {
                let child = if j == N_JOINTS - 1 {
                    link(
                        &mut out,
                        "top",
                        g.link_mass_kg,
                        Some((g.top_radius_m, g.top_thickness_m, 0.5 * g.top_thickness_m)),
                    );
                    "top".to_string()
                } else {
                    layer += 1;
                    let c = format!("layer{layer}");
                    link(
                        &mut out,
                        &c,
                        g.link_mass_kg,
                        Some((g.link_radius_m, 0.5 * h, 0.25 * h)),
                    );
                    c
                };
                joint(
                    &mut out,
                    &format!("y{pair}"),
                    "revolute",
                    &parent,
                    &child,
                    parent_z,
                    "0 1 0",
                    Some(lim),
                );
                parent = child;
                parent_z = 0.5 * h;
            }
            JointKind::Prismatic => {
                layer += 1;
                let child = format!("layer{layer}");
                link(
                    &mut out,
                    &child,
                    g.link_mass_kg,
                    Some((g.link_radius_m, 0.5 * h, 0.25 * h)),
                );
                joint(
                    &mut out,
                    &format!("d{pair}"),
                    "prismatic",
                    &parent,
                    &child,
                    parent_z,
                    "0 0 1",
                    Some(lim),
                );
                parent = child;
                parent_z = 0.5 * h;
            }
        }
    }
    link(&mut out, "tcp", 0.0, None);
    joint(
        &mut out,
        "tcp_joint",
        "fixed",
        "top",
        "tcp",
        g.tcp_offset_m,
        "0 0 1",
        None,
    );
    let _ = writeln!(out, "</robot>");
    out
}
