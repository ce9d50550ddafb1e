//! The rapier scene: joint motors reach commanded postures, rapier's link poses agree with our
//! forward kinematics, commands always satisfy the grouped constraints, gravity and contact
//! produce a TCP force.

mod common;
use common::chain;
use ocm_surrogate::SurrogateError;
use ocm_surrogate::batch::BatchModel;
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
fn out_of_range_commands_are_refused_and_clamping_is_explicit() {
    let (g, lim) = (chain(), Limits::default());
    let mut sim = Sim::new(&g, &lim, SceneConfig::default()).unwrap();
    let model = BatchModel::new(&g, &lim, &SceneConfig::default()).unwrap();
    let mut env = model.env_at(&[0.0; N_JOINTS]).unwrap();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(9);
    let mut refused = 0;
    for _ in 0..50 {
        let q: Posture = std::array::from_fn(|_| rng.random_range(-1.0..1.0));
        // Both steppers refuse an infeasible command with the same typed error and keep the
        // previous command; the explicit clamping API commands a feasible posture instead.
        let before = (sim.commanded(), env.target);
        match (lim.check(&q), sim.command(&q), model.command(&mut env, &q)) {
            (Err(e), Err(a), Err(b)) => {
                assert_eq!(e.to_string(), a.to_string());
                assert_eq!(e.to_string(), b.to_string());
                assert!(matches!(a, SurrogateError::OutOfRange { .. }), "{a}");
                assert_eq!((sim.commanded(), env.target), before);
                refused += 1;
            }
            (Ok(()), Ok(_), Ok(_)) => {}
            other => panic!("check and commands disagree: {other:?}"),
        }
        let applied = sim.command_clamped(&q).unwrap();
        lim.check(&applied).unwrap();
        assert_eq!(model.command_clamped(&mut env, &q).unwrap(), applied);
        sim.step();
    }
    assert_eq!(refused, 50, "uniform commands in +-1 are all infeasible");
    // The error names the joint, the value and the allowed range.
    let mut q = [0.0; N_JOINTS];
    q[2] = 0.03;
    match sim.command(&q).unwrap_err() {
        SurrogateError::OutOfRange {
            channel,
            value,
            lo,
            hi,
            unit,
        } => {
            assert!(channel.starts_with("joint 2 (d1, d)"), "{channel}");
            assert_eq!((value, lo, hi, unit), (0.03, 0.0, 0.02, "m"));
        }
        e => panic!("{e}"),
    }
    // A neighbour too far from the joint below: the range is the one eq 4.23 leaves it.
    let mut q = [0.0; N_JOINTS];
    q[0] = 0.1;
    q[3] = 0.12;
    let e = model.command(&mut env, &q).unwrap_err();
    let msg = e.to_string();
    assert!(
        msg.contains("joint 3 (x2, theta_x)") && msg.contains("[0.09") && msg.contains("eq 4.23"),
        "{msg}"
    );
    let mut bad = [0.0; N_JOINTS];
    bad[4] = f64::NAN;
    for e in [
        sim.command(&bad).unwrap_err(),
        sim.command_clamped(&bad).unwrap_err(),
        sim.set_posture(&bad).unwrap_err(),
        model.command(&mut env, &bad).unwrap_err(),
    ] {
        assert!(matches!(e, SurrogateError::NotFinite { .. }), "{e}");
        let msg = e.to_string();
        assert!(
            msg.contains("joint 4 (y2, theta_y)") && msg.contains("not finite"),
            "{msg}"
        );
    }
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

/// The batch stepper's penalty contact against rapier's rigid contact (32 solver iterations):
/// the robot extends into a plate and a ramp above its TCP under gravity; after 3 s the normal
/// forces on the sensor agree within 4 % (rapier lets contacts sink by up to its allowed linear
/// error, the penalty spring by depth = F / k; the batch contact is frictionless, rapier's not,
/// so only the normal component is compared).
#[test]
fn batch_contact_matches_rapier_contact_force() {
    let (g, lim) = (chain(), Limits::default());
    let rest_tcp = g.tcp(&[0.0; N_JOINTS]);
    let top = rest_tcp.z + 0.005 + 0.003;
    let mut q = [0.0; N_JOINTS];
    q[2] = 0.005;
    q[5] = 0.005;
    q[8] = 0.005;
    q[0] = 0.01;
    for surface in [
        Surface::Plane { height_m: top },
        Surface::Ramp {
            height_m: top,
            slope_rad: 0.2,
        },
    ] {
        let cfg = SceneConfig {
            surfaces: vec![surface],
            solver_iterations: 32,
            ..SceneConfig::default()
        };
        let mut sim = Sim::new(&g, &lim, cfg.clone()).unwrap();
        let model = BatchModel::new(&g, &lim, &cfg).unwrap();
        let mut env = model.env_at(&[0.0; N_JOINTS]).unwrap();
        sim.command(&q).unwrap();
        model.command(&mut env, &q).unwrap();
        for _ in 0..720 {
            sim.step();
            model.step(&mut env);
        }
        let (fr, fb) = (sim.tcp_force(), model.tcp_force(&env));
        let (_, n) = surface.point_and_normal();
        assert!(fb.dot(&n) > 1.0, "{fb:?}");
        assert!(
            (fr.dot(&n) - fb.dot(&n)).abs() < 0.04 * fr.dot(&n),
            "{surface:?}: normal force rapier {fr:?}, batch {fb:?}"
        );
    }
}

#[test]
fn bench_sizes_out_of_range_are_refused_by_name() {
    use ocm_surrogate::bench::{BenchConfig, Engine, run};
    let ok = BenchConfig {
        engine: Engine::Batch,
        envs: 2,
        steps: 2,
        threads: 1,
        repeats: 1,
        seed: 0,
    };
    for (cfg, want) in [
        (BenchConfig { envs: 0, ..ok }, "envs = 0"),
        (BenchConfig { repeats: 0, ..ok }, "repeats = 0"),
        (
            BenchConfig {
                threads: 100_000,
                ..ok
            },
            "threads = 100000",
        ),
    ] {
        let e = run(&chain(), &Limits::default(), &cfg)
            .unwrap_err()
            .to_string();
        assert!(e.contains(want), "{e}");
    }
}

#[test]
fn a_chain_of_negative_length_is_refused_not_a_panic() {
    let bad = ocm_surrogate::chain::ChainGeometry {
        segment_length_m: -0.03,
        ..chain()
    };
    let e = Sim::new(&bad, &Limits::default(), SceneConfig::default())
        .err()
        .expect("a negative segment length is refused")
        .to_string();
    assert!(e.contains("segment_length_m = -0.03"), "{e}");
}
