//! The environments: tasks, physics against the static equilibrium, determinism, invalid
//! actions, episode ends, vectorisation.

use nalgebra::Vector3;
use ocm_rl::RlError;
use ocm_rl::env::{ACT_DIM, Env, EnvConfig, OBS_DIM};
use ocm_rl::robot::Load;
use ocm_rl::tasks::{self, ContactConfig, Episode, POINTS, TaskKind};
use ocm_rl::vec_env::VecEnv;
use ocm_surrogate::chain::{JointKind, KINDS, N_JOINTS};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

mod common;
use common::robot;

#[test]
fn paths_have_the_dissertations_shapes() {
    let c = Vector3::new(0.01, -0.02, 0.2);
    let circle = tasks::circle(&c, 0.025, POINTS);
    assert_eq!(circle.len(), 100);
    for p in &circle {
        assert!(((p - c).norm() - 0.025).abs() < 1e-12);
        assert_eq!(p.z, c.z);
    }
    let star = tasks::star(&c, 0.025, POINTS);
    assert_eq!(star.len(), 100);
    let r: Vec<f64> = star.iter().map(|p| (p - c).norm()).collect();
    let inner = 0.025 * 18f64.to_radians().sin() / 126f64.to_radians().sin();
    assert!((r.iter().cloned().fold(0.0, f64::max) - 0.025).abs() < 1e-12);
    assert!(r.iter().all(|&v| v >= inner * 0.999 && v <= 0.025 + 1e-12));
    // Evenly spaced by arc length: steps are equal except the chords that cut a vertex.
    let steps: Vec<f64> = (0..100)
        .map(|k| (star[(k + 1) % 100] - star[k]).norm())
        .collect();
    let max = steps.iter().cloned().fold(0.0, f64::max);
    assert!(steps.iter().all(|&s| s > 0.5 * max));
    // eq 4.28 on its plate.
    let e = tasks::ellipse(&c, POINTS);
    let n = tasks::ellipse_plate_normal();
    let p0 = c + Vector3::new(0.0, 0.0, 0.010);
    for (k, p) in e.iter().enumerate() {
        let t = 2.0 * std::f64::consts::PI * k as f64 / 100.0;
        let d = p - c;
        assert!((d.x - 0.025 * t.cos()).abs() < 1e-12);
        assert!((d.y - 0.025 * t.sin()).abs() < 1e-12);
        assert!((d.z - (0.010 * (t - std::f64::consts::PI).cos() + 0.010)).abs() < 1e-12);
        assert!(n.dot(&(p - p0)).abs() < 1e-12);
    }
    assert!((e[0].z - c.z).abs() < 1e-12 && (e[50].z - c.z - 0.020).abs() < 1e-12);
}

#[test]
fn static_equilibrium_is_where_the_dynamics_settle() {
    let r = robot();
    for (u, f) in [
        ([0.05, -0.03, 0.01], Vector3::zeros()),
        ([-0.1, 0.08, 0.004], Vector3::zeros()),
        ([0.02, 0.06, 0.012], Vector3::new(0.0, 0.0, -1.5)),
        ([0.0, 0.0, 0.0], Vector3::new(0.0, 0.0, -1.0)),
    ] {
        let q_eq = r.equilibrium(&u, &f);
        let cmd = r.posture_of(&u);
        let mut s = r.state_at(&cmd, &cmd).unwrap();
        let mass = -f.z / 9.81;
        let load = if mass > 0.0 {
            Load::Weight { mass_kg: mass }
        } else {
            Load::Free
        };
        r.advance(&mut s, &load, 4000);
        let tcp_dyn = r.chain().tcp(&s.q);
        let tcp_eq = r.chain().tcp(&q_eq);
        assert!(
            (tcp_dyn - tcp_eq).norm() < 2e-5,
            "u {u:?}: settled TCP {tcp_dyn:?} vs equilibrium {tcp_eq:?}"
        );
        // Gravity (and the weight) sag the TCP away from the command's kinematic TCP, unless the
        // extensions sit on their lower stops and the chain is upright.
        if u[2] > 0.0 {
            assert!(
                (r.chain().tcp(&cmd) - tcp_eq).norm() > 1e-4,
                "u {u:?}: no sag"
            );
        }
    }
}

#[test]
fn expert_inverse_reaches_the_paths_with_and_without_load() {
    let r = robot();
    let origin = r.rest_tcp();
    for task in [
        TaskKind::Circle,
        TaskKind::Star,
        TaskKind::Weight,
        TaskKind::Ellipse,
    ] {
        let ep = Episode::new(task, &origin, &ContactConfig::default(), 3);
        let mut a = [0.0; 3];
        for k in (0..POINTS).step_by(7) {
            let (b, err) = r.inverse(&ep.planned_tcp(k), &ep.planned_force(k, 9.81), &a);
            assert!(err < 1e-5, "{task:?} point {k}: expert misses by {err} m");
            assert!(b.iter().all(|v| v.abs() <= 1.0));
            a = b;
        }
    }
}

#[test]
fn plate_contact_balances_the_motors() {
    // Press the plate of the force task: at rest the motor torques balance gravity and J^T F,
    // and F is the penalty spring's.
    let r = robot();
    let origin = r.rest_tcp();
    let ep = Episode::new(TaskKind::Force, &origin, &ContactConfig::default(), 1);
    let (a, _) = r.inverse(&ep.planned_tcp(0), &ep.planned_force(0, 9.81), &[0.0; 3]);
    let u = r.command_of_action(&a);
    let cmd = r.posture_of(&u);
    let mut s = r.state_at(&cmd, &cmd).unwrap();
    let f = r.advance(&mut s, &ep.load, 5000);
    assert!((f - ep.force_targets[0]).norm() < 0.02 * ep.force_targets[0].norm() + 1e-3);
    let Load::Plane { point_m, .. } = ep.load else {
        panic!("force task has a plate")
    };
    let p = r.chain().tcp(&s.q);
    assert!((f.z + 5000.0 * (p.z - point_m[2])).abs() < 1e-6 + 0.05 * f.norm());
    let q_eq = r.equilibrium(&u, &f);
    for j in 0..N_JOINTS {
        let tol = if KINDS[j] == JointKind::Prismatic {
            2e-6
        } else {
            2e-5
        };
        assert!((q_eq[j] - s.q[j]).abs() < tol, "joint {j}");
    }
}

#[test]
fn approach_term_scores_the_gap_out_of_contact_and_nothing_else() {
    // Two force-control environments, one with the approach term, driven by the same actions:
    // the episode's start (5 mm below the plate), a step that stays out of contact, and the
    // expert's, which presses.
    let r = robot();
    let plain = EnvConfig::new(TaskKind::Force);
    let shaped = EnvConfig {
        approach_n_per_m: 100.0,
        ..plain
    };
    assert!(
        Env::new(
            r.clone(),
            EnvConfig {
                approach_n_per_m: f64::NAN,
                ..plain
            }
        )
        .is_err()
    );
    let (mut a, mut b) = (
        Env::new(r.clone(), plain).unwrap(),
        Env::new(r.clone(), shaped).unwrap(),
    );
    assert_eq!(a.reset(4).unwrap(), b.reset(4).unwrap());
    let Some(Load::Plane { point_m, .. }) = b.load() else {
        panic!("force task has a plate")
    };
    let low = [0.0, 0.0, -1.0];
    let (mut out, mut pressed) = (0, 0);
    for k in 0..8 {
        let expert = b.expert_action().unwrap();
        let act = if k < 2 { low } else { expert };
        let (sa, sb) = (a.step(&act).unwrap(), b.step(&act).unwrap());
        assert_eq!(sa.obs, sb.obs);
        assert_eq!(sa.info, sb.info);
        let f_ref = Vector3::from(sb.info.force_target_n).norm();
        let gap = point_m[2] - sb.info.tcp_m[2];
        if gap > 0.0 {
            out += 1;
            assert_eq!(sb.info.force_error_n, f_ref);
            assert!((sa.reward - (1.0 - 0.5 * f_ref)).abs() < 1e-12);
            let want = 1.0 - 0.5 * (f_ref + 100.0 * gap);
            assert!((sb.reward - want).abs() < 1e-9, "{} vs {want}", sb.reward);
        } else {
            pressed += 1;
            assert_eq!(sa.reward, sb.reward);
        }
    }
    assert!(
        out >= 2 && pressed >= 3,
        "{out} steps out of contact, {pressed} pressing"
    );
}

fn random_actions(seed: u64, n: usize) -> Vec<[f64; 3]> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..n)
        .map(|_| std::array::from_fn(|_| rng.random_range(-1.0..1.0)))
        .collect()
}

#[test]
fn episodes_are_deterministic_in_the_seed() {
    let r = robot();
    for task in TaskKind::ALL {
        let run = |seed: u64| {
            let mut env = Env::new(r.clone(), EnvConfig::new(task)).unwrap();
            let mut out = vec![env.reset(seed).unwrap()];
            for a in random_actions(9, 5) {
                let s = env.step(&a.map(|v| 0.1 * v)).unwrap();
                out.push(s.obs);
                out.push(vec![s.reward]);
            }
            out
        };
        assert_eq!(run(4), run(4), "{task:?}");
        assert_ne!(run(4), run(5), "{task:?}: seeds must matter");
    }
}

#[test]
fn invalid_actions_are_refused_or_clipped_never_panic() {
    let r = robot();
    let mut env = Env::new(r.clone(), EnvConfig::new(TaskKind::Circle)).unwrap();
    assert!(matches!(env.step(&[0.0; 3]), Err(RlError::State(_))));
    env.reset(1).unwrap();
    assert!(matches!(
        env.step(&[0.0, f64::NAN, 0.0]),
        Err(RlError::NonFiniteAction { index: 1, .. })
    ));
    assert!(matches!(
        env.step(&[f64::INFINITY, 0.0, 0.0]),
        Err(RlError::NonFiniteAction { index: 0, .. })
    ));
    assert!(matches!(
        env.step(&[0.0; 2]),
        Err(RlError::ActionSize {
            found: 2,
            expected: 3
        })
    ));
    // The refused calls left the state alone: the same as a fresh environment.
    let mut fresh = Env::new(r.clone(), EnvConfig::new(TaskKind::Circle)).unwrap();
    fresh.reset(1).unwrap();
    let a = env.step(&[5.0, -7.0, 0.3]).unwrap();
    let b = fresh.step(&[1.0, -1.0, 0.3]).unwrap();
    assert!(a.info.clipped && !b.info.clipped);
    assert_eq!(a.obs, b.obs);
    assert_eq!(a.reward, b.reward);
    assert_eq!(a.obs.len(), OBS_DIM);
}

#[test]
fn episodes_end_after_100_points_or_when_lost() {
    let r = robot();
    let mut env = Env::new(r.clone(), EnvConfig::new(TaskKind::Circle)).unwrap();
    env.reset(2).unwrap();
    let mut n = 0;
    loop {
        let a = env.expert_action().unwrap();
        let s = env.step(&a).unwrap();
        n += 1;
        assert!(!s.terminated);
        assert_eq!(s.info.point, n - 1);
        if s.truncated {
            break;
        }
    }
    assert_eq!(n, POINTS);
    assert!(matches!(env.step(&[0.0; 3]), Err(RlError::State(_))));
    // Full extension and bend drives the TCP far off the circle: terminated, not truncated.
    let mut cfg = EnvConfig::new(TaskKind::Circle);
    cfg.lost_distance_m = 0.01;
    let mut env = Env::new(r.clone(), cfg).unwrap();
    env.reset(2).unwrap();
    let s = env.step(&[1.0, 1.0, 1.0]).unwrap();
    assert!(s.terminated && !s.truncated && s.info.position_error_m > 0.01);
}

#[test]
fn vector_env_matches_single_envs_and_resets_itself() {
    let r = robot();
    let cfg = EnvConfig::new(TaskKind::Star);
    let mut v = VecEnv::new(r.clone(), cfg, 3, 2).unwrap();
    let obs = v.reset(10).unwrap();
    assert_eq!(obs.len(), 3 * OBS_DIM);
    let mut singles: Vec<Env> = (0..3).map(|_| Env::new(r.clone(), cfg).unwrap()).collect();
    for (i, e) in singles.iter_mut().enumerate() {
        assert_eq!(
            e.reset(10 + i as u64).unwrap(),
            obs[i * OBS_DIM..(i + 1) * OBS_DIM]
        );
    }
    let acts = random_actions(3, 6);
    let flat: Vec<f64> = acts[..3].iter().flatten().map(|v| 0.2 * v).collect();
    let s = v.step(&flat).unwrap();
    for (i, e) in singles.iter_mut().enumerate() {
        let si = e.step(&flat[i * ACT_DIM..(i + 1) * ACT_DIM]).unwrap();
        assert_eq!(si.obs, s.obs[i * OBS_DIM..(i + 1) * OBS_DIM]);
        assert_eq!(si.reward, s.rewards[i]);
    }
    assert!(v.step(&[0.0; 5]).is_err());
    // Lost episodes restart on their own with the environment's next seed.
    let mut cfg = cfg;
    cfg.lost_distance_m = 0.005;
    let mut v = VecEnv::new(r.clone(), cfg, 2, 2).unwrap();
    v.reset(0).unwrap();
    let s = v.step(&[1.0; 6]).unwrap();
    assert!(s.terminated.iter().all(|&t| t));
    assert!(s.final_obs.iter().all(|o| o.is_some()));
    let mut e = Env::new(r.clone(), cfg).unwrap();
    assert_eq!(e.reset(2).unwrap(), s.obs[..OBS_DIM]);
}
