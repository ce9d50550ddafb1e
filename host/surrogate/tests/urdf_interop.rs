//! The generated URDF read by two consumers we did not write: `urdf-rs` and MuJoCo's URDF
//! compiler (Python `mujoco`, installed by the README's test command).

use nalgebra::{Rotation3, Vector3};
use ocm_surrogate::chain::{ChainGeometry, N_JOINTS, Posture};
use ocm_surrogate::constraints::Limits;
use ocm_surrogate::urdf::{joint_names, to_urdf};
use rand::{Rng, SeedableRng};

fn chain() -> ChainGeometry {
    // Dimensions of the order of the bellows surrogate (the values need not be the fitted ones).
    ChainGeometry {
        base_height_m: 0.015,
        segment_length_m: 0.0452,
        tcp_offset_m: 0.033,
        link_radius_m: 0.061,
        base_radius_m: 0.075,
        top_radius_m: 0.082,
        top_thickness_m: 0.0195,
        link_mass_kg: 0.82 / 7.0,
        dummy_mass_kg: 1e-5,
    }
}

fn random_feasible(limits: &Limits, n: usize, seed: u64) -> Vec<Posture> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let b = limits.increment_bounds();
    (0..n)
        .map(|_| {
            let z: Posture = std::array::from_fn(|j| rng.random_range(b[j].0..=b[j].1));
            limits.from_increments(&z)
        })
        .collect()
}

/// TCP by composing the parsed URDF's joint origins and axes (an evaluation independent of
/// `ChainGeometry::tcp`).
fn urdf_tcp(robot: &urdf_rs::Robot, q: &Posture) -> Vector3<f64> {
    let names = joint_names();
    let mut link = "base".to_string();
    let (mut r, mut p) = (Rotation3::identity(), Vector3::zeros());
    while let Some(j) = robot.joints.iter().find(|j| j.parent.link == link) {
        let o = &j.origin;
        p += r * Vector3::new(o.xyz[0], o.xyz[1], o.xyz[2]);
        r *= Rotation3::from_euler_angles(o.rpy[0], o.rpy[1], o.rpy[2]);
        let axis = Vector3::new(j.axis.xyz[0], j.axis.xyz[1], j.axis.xyz[2]);
        let v = names
            .iter()
            .position(|n| *n == j.name)
            .map_or(0.0, |k| q[k]);
        match j.joint_type {
            urdf_rs::JointType::Revolute => {
                r *= Rotation3::from_axis_angle(&nalgebra::Unit::new_normalize(axis), v)
            }
            urdf_rs::JointType::Prismatic => p += r * axis * v,
            _ => {}
        }
        link = j.child.link.clone();
    }
    assert_eq!(link, "tcp");
    p
}

#[test]
fn urdf_rs_reads_links_joints_limits_and_masses() {
    let (g, lim) = (chain(), Limits::default());
    let text = to_urdf("s", &g, &lim);
    let robot = urdf_rs::read_from_string(&text).expect("urdf-rs parses our URDF");
    assert_eq!(robot.joints.len(), N_JOINTS + 1);
    let revolute = robot
        .joints
        .iter()
        .filter(|j| matches!(j.joint_type, urdf_rs::JointType::Revolute))
        .count();
    let prismatic = robot
        .joints
        .iter()
        .filter(|j| matches!(j.joint_type, urdf_rs::JointType::Prismatic))
        .count();
    assert_eq!((revolute, prismatic), (8, 3));
    for j in &robot.joints {
        match j.joint_type {
            urdf_rs::JointType::Revolute => {
                assert_eq!([j.limit.lower, j.limit.upper], lim.revolute_rad)
            }
            urdf_rs::JointType::Prismatic => {
                assert_eq!([j.limit.lower, j.limit.upper], lim.prismatic_m)
            }
            _ => assert_eq!(j.name, "tcp_joint"),
        }
    }
    let moving: f64 = robot
        .links
        .iter()
        .filter(|l| l.name != "base")
        .map(|l| l.inertial.mass.value)
        .sum();
    assert!((moving - 0.82).abs() < 1e-3, "moving mass {moving}");
    let colliding = robot
        .links
        .iter()
        .filter(|l| !l.collision.is_empty())
        .count();
    assert_eq!(colliding, 8, "base, six body links, top plate");
    for q in random_feasible(&lim, 50, 7) {
        assert!((urdf_tcp(&robot, &q) - g.tcp(&q)).norm() < 1e-8);
    }
}

#[test]
fn mujoco_compiles_the_urdf_and_agrees_on_the_tcp() {
    let Some(python) = ocm_datadir::require_python(&["mujoco", "numpy"]) else {
        return;
    };
    let (g, lim) = (chain(), Limits::default());
    let dir = std::env::temp_dir().join(format!("ocm-surrogate-mj-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let urdf = dir.join("surrogate.urdf");
    std::fs::write(&urdf, to_urdf("s", &g, &lim)).unwrap();
    let qs = random_feasible(&lim, 40, 11);
    let names = joint_names();
    let script = r#"
import json, sys, mujoco, numpy as np
path, names, qs = json.loads(sys.stdin.read())
m = mujoco.MjModel.from_xml_path(path)
d = mujoco.MjData(m)
tcp = m.body("tcp").id
out = {"nq": int(m.nq), "lims": [list(map(float, m.jnt_range[m.joint(n).id])) for n in names],
       "mass": float(sum(m.body_mass[1:])), "tcp": []}
for q in qs:
    d.qpos[:] = 0
    for n, v in zip(names, q):
        d.qpos[m.joint(n).qposadr[0]] = v
    mujoco.mj_kinematics(m, d)
    out["tcp"].append(list(map(float, d.xpos[tcp])))
print(json.dumps(out))
"#;
    let input = serde_json::to_string(&(urdf.display().to_string(), names, &qs)).unwrap();
    let mut child = std::process::Command::new(python)
        .args(["-c", script])
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    use std::io::Write;
    child
        .stdin
        .take()
        .unwrap()
        .write_all(input.as_bytes())
        .unwrap();
    let out = child.wait_with_output().unwrap();
    assert!(
        out.status.success(),
        "mujoco failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["nq"].as_u64(), Some(N_JOINTS as u64));
    for (j, r) in v["lims"].as_array().unwrap().iter().enumerate() {
        let r: Vec<f64> = serde_json::from_value(r.clone()).unwrap();
        assert_eq!([r[0], r[1]], lim.range(j), "joint {j}");
    }
    // MuJoCo's total includes the fixed base: the moving part is 820 g.
    let mass = v["mass"].as_f64().unwrap() - g.link_mass_kg;
    assert!((mass - 0.82).abs() < 1e-3, "{mass}");
    let mut worst: f64 = 0.0;
    for (q, t) in qs.iter().zip(v["tcp"].as_array().unwrap()) {
        let t: Vec<f64> = serde_json::from_value(t.clone()).unwrap();
        worst = worst.max((Vector3::new(t[0], t[1], t[2]) - g.tcp(q)).norm());
    }
    assert!(worst < 1e-6, "MuJoCo TCP differs by {worst} m");
    let _ = std::fs::remove_dir_all(&dir);
}
