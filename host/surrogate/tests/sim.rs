//! The rapier scene: joint motors reach commanded postures, rapier's link poses agree with our
//! forward kinematics, commands always satisfy the grouped constraints, gravity and contact
//! produce a TCP force.

mod common;
use common::chain;
use ocm_surrogate::chain::{N_JOINTS, Posture};
use ocm_surrogate::constraints::Limits;
use ocm_surrogate::sim::{SceneConfig, Sim, Surface};
use rand::{Rng, SeedableRng};

#[test]
fn rapier_posture_and_tcp_agree_with_our_kinematics() {
    let (g, lim) = (chain(), Limits::default());
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
    let b = lim.increment_bounds();
    for _ in 0..3 {
        let z: Posture = std::array::from_fn(|j| rng.random_range(b[j].0..=b[j].1));
        let q = lim.from_increments(&z);
        let cfg = SceneConfig {
            gravity_m_s2: 0.0,
            ..SceneConfig::default()
        };
        let mut sim = Sim::new(&g, &lim, cfg).unwrap();
        sim.command(&q).unwrap();
        for _ in 0..480 {
            sim.step();
        }
        let got = sim.posture();
        for j in 0..N_JOINTS {
            assert!(
                (got[j] - q[j]).abs() < 2e-3,
                "joint {j}: {} vs {}",
                got[j],
                q[j]
            );
        }
        // Rapier's body poses against our chain at rapier's own joint coordinates.
        let d = (sim.tcp() - g.tcp(&got)).norm();
        assert!(d < 1e-6, "TCP differs by {d} m");
        assert!(lim.check(&sim.commanded()).is_ok());
    }
}

#[test]
fn commands_are_projected_onto_the_grouped_constraints() {
    let (g, lim) = (chain(), Limits::default());
    let mut sim = Sim::new(&g, &lim, SceneConfig::default()).unwrap();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(9);
    for _ in 0..50 {
        let q: Posture = std::array::from_fn(|_| rng.random_range(-1.0..1.0));
        let applied = sim.command(&q).unwrap();
        lim.check(&applied).unwrap();
        sim.step();
    }
    let mut bad = [0.0; N_JOINTS];
    bad[4] = f64::NAN;
    let e = sim.command(&bad).unwrap_err().to_string();
    assert!(e.contains("joint 4") && e.contains("not finite"), "{e}");
}

#[test]
fn gravity_presses_the_tcp_onto_a_plane_and_a_ramp() {
    let (g, lim) = (chain(), Limits::default());
    let rest_tcp = g.tcp(&[0.0; N_JOINTS]);
    // Free: no contact force.
    let mut free = Sim::new(&g, &lim, SceneConfig::default()).unwrap();
    for _ in 0..60 {
        free.step();
    }
    assert_eq!(free.tcp_force().norm(), 0.0);
    // A plate 3 mm above the TCP sphere's top at rest, the robot commanded to extend 3 x 5 mm:
    // the plate must push the sensor back down.
    let top = rest_tcp.z + 0.005 + 0.003;
    for surface in [
        Surface::Plane { height_m: top },
        Surface::Ramp {
            height_m: top,
            slope_rad: 0.2,
        },
    ] {
        let cfg = SceneConfig {
            surfaces: vec![surface],
            ..SceneConfig::default()
        };
        let mut sim = Sim::new(&g, &lim, cfg).unwrap();
        let mut q = [0.0; N_JOINTS];
        q[2] = 0.005;
        q[5] = 0.005;
        q[8] = 0.005;
        sim.command(&q).unwrap();
        let mut f = nalgebra::Vector3::zeros();
        for _ in 0..480 {
            sim.step();
            f = sim.tcp_force();
        }
        assert!(f.z < -1.0, "{surface:?}: TCP force {f:?}");
        if let Surface::Ramp { slope_rad, .. } = surface {
            // The ramp's normal (towards the robot) leans to +x: so does the contact force.
            assert!(f.x > 0.0, "{f:?} on a ramp of {slope_rad} rad");
        }
    }
}

#[test]
fn batch_stepper_matches_rapier_equilibrium_and_motion() {
    use ocm_surrogate::batch::BatchModel;
    let (g, lim) = (chain(), Limits::default());
    let cfg = SceneConfig::default();
    let model = BatchModel::new(&g, &lim, &cfg).unwrap();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(21);
    let b = lim.increment_bounds();
    for _ in 0..2 {
        let z: Posture = std::array::from_fn(|j| rng.random_range(b[j].0..=b[j].1));
        let q = lim.from_increments(&z);
        let mut sim = Sim::new(
            &g,
            &lim,
            SceneConfig {
                solver_iterations: 32,
                ..cfg.clone()
            },
        )
        .unwrap();
        let mut env = model.env_at(&[0.0; N_JOINTS]).unwrap();
        sim.command(&q).unwrap();
        model.command(&mut env, &q).unwrap();
        let mut worst_motion: f64 = 0.0;
        for k in 0..720 {
            sim.step();
            model.step(&mut env);
            if k < 120 {
                worst_motion = worst_motion.max((sim.tcp() - model.tcp(&env)).norm());
            }
        }
        // Equilibrium under gravity (motor torque = gravity torque): the two must agree closely
        // (rapier with enough solver iterations to converge; at its default 4 it stops ~3e-4 rad short).
        let (qr, qb) = (sim.posture(), env.q);
        for j in 0..N_JOINTS {
            assert!(
                (qr[j] - qb[j]).abs() < 1e-4,
                "joint {j}: rapier {} batch {}",
                qr[j],
                qb[j]
            );
        }
        // The sag is real (gravity acts) and the same in both.
        let sag = (g.tcp(&q) - model.tcp(&env)).norm();
        assert!(sag > 1e-4, "no gravity sag: {sag}");
        // The transient (first 0.5 s): rapier's iterative motor constraints and our implicit
        // motors without velocity-product terms follow the same path to within a fifth of the
        // distance travelled.
        let travel = (g.tcp(&[0.0; N_JOINTS]) - model.tcp(&env)).norm();
        assert!(
            worst_motion < 0.2 * travel,
            "TCP paths differ by {worst_motion} m over a travel of {travel} m"
        );
    }
}

#[test]
fn set_posture_teleports_the_chain() {
    let (g, lim) = (chain(), Limits::default());
    let mut sim = Sim::new(&g, &lim, SceneConfig::default()).unwrap();
    let q: Posture = [
        0.1, -0.05, 0.01, 0.11, -0.045, 0.012, 0.12, -0.04, 0.009, 0.13, -0.035,
    ];
    let applied = sim.set_posture(&q).unwrap();
    assert_eq!(applied, q);
    let got = sim.posture();
    for j in 0..N_JOINTS {
        assert!(
            (got[j] - q[j]).abs() < 1e-12,
            "joint {j}: {} vs {}",
            got[j],
            q[j]
        );
    }
    assert!((sim.tcp() - g.tcp(&q)).norm() < 1e-9);
}
