//! Residual RL on a BC policy and the plant randomisation it trains under: the zero residual
//! acts exactly as its base and round-trips through its two checkpoints; the perturbations are
//! seeded, bounded and act on the plant as stated; PPO on the residual starts at the base.

mod common;
use common::{quick_train, robot};
use ocm_rl::bc;
use ocm_rl::env::{Env, EnvConfig, Perturbation, Randomisation};
use ocm_rl::eval::evaluate;
use ocm_rl::policy::{Policy, PolicyMeta};
use ocm_rl::ppo::{self, PpoConfig};
use ocm_rl::robot::Load;
use ocm_rl::tasks::TaskKind;

fn meta(algorithm: &str) -> PolicyMeta {
    PolicyMeta {
        task: "circle".into(),
        algorithm: algorithm.into(),
        seed: 0,
        score: 0.0,
        residual: None,
    }
}

fn temp_dir(name: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("ocm-rl-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// A small BC policy of the circle and the observations it was fitted on.
fn small_bc() -> (Policy, Vec<f64>) {
    let r = robot();
    let cfg = EnvConfig::new(TaskKind::Circle);
    let demos = bc::collect(&r, &cfg, 4, 0.03, 0, 2).unwrap();
    let mut t = quick_train();
    t.epochs = 20;
    let (p, _) = bc::fit(&demos, &[16], &t, 0).unwrap();
    let obs = demos.obs.iter().map(|&v| f64::from(v)).collect();
    (p, obs)
}

#[test]
fn a_zero_residual_acts_exactly_as_its_base_and_round_trips() {
    let (base, obs) = small_bc();
    let want = base.act_batch(&obs).unwrap();
    let res = Policy::zero_residual(base.clone(), &[32, 32], 0.1, 7).unwrap();
    // Bit for bit, on every one of the 400 fitted observations.
    assert_eq!(res.act_batch(&obs).unwrap(), want);
    assert!(res.residual().is_some() && base.residual().is_none());
    let dir = temp_dir("residual");
    let path = dir.join("policy.ckpt");
    res.save(&path, &meta("ppo-residual")).unwrap();
    assert!(dir.join("policy.base.ckpt").exists());
    let (back, m) = Policy::load(&path).unwrap();
    let r = m.residual.expect("the facts name the base");
    assert_eq!((r.base_file.as_str(), r.scale), ("policy.base.ckpt", 0.1));
    assert_eq!(back.act_batch(&obs).unwrap(), want);
    // Without its base the residual is refused, naming the missing file.
    std::fs::remove_file(dir.join("policy.base.ckpt")).unwrap();
    let e = Policy::load(&path).unwrap_err().to_string();
    assert!(e.contains("policy.base.ckpt"), "{e}");
    for bad in [0.0, -0.1, f64::NAN, 3.0] {
        assert!(Policy::zero_residual(base.clone(), &[8], bad, 0).is_err());
    }
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_residual_correction_is_bounded_by_its_scale() {
    let (base, obs) = small_bc();
    let want = base.act_batch(&obs).unwrap();
    // Random output weights: the raw outputs are far from zero, the correction is not.
    let config = ocm_rl::policy::policy_config(&[16]);
    let mlp = config.init(&ocm_learn::cpu(), 3);
    let res = Policy::residual_on(base, mlp, config, 0.05).unwrap();
    let got = res.act_batch(&obs).unwrap();
    let largest = got
        .iter()
        .zip(&want)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    assert!(largest <= 0.05 + 1e-12 && largest > 0.0, "{largest}");
    assert!(got.iter().all(|a| a.abs() <= 1.0));
}

#[test]
fn perturbations_are_seeded_bounded_and_act_on_the_plant() {
    let r = robot();
    let rnd = Randomisation {
        bend_bias_rad: 0.01,
        extension_bias_m: 0.001,
        surface_offset_m: 0.002,
    };
    // None drawn without randomisation: the nominal episodes are untouched.
    assert_eq!(
        Perturbation::draw(&Randomisation::default(), 5),
        Perturbation::default()
    );
    let (mut seen_neg, mut seen_pos) = (false, false);
    for seed in 0..50 {
        let p = Perturbation::draw(&rnd, seed);
        assert_eq!(p, Perturbation::draw(&rnd, seed));
        assert!(p.command_bias[0].abs() <= 0.01 && p.command_bias[1].abs() <= 0.01);
        assert!(p.command_bias[2].abs() <= 0.001 && p.surface_offset_m.abs() <= 0.002);
        seen_neg |= p.surface_offset_m < -0.001;
        seen_pos |= p.surface_offset_m > 0.001;
    }
    assert!(seen_neg && seen_pos);
    assert_ne!(Perturbation::draw(&rnd, 1), Perturbation::draw(&rnd, 2));
    let bad = Randomisation {
        surface_offset_m: f64::NAN,
        ..rnd
    };
    let cfg = EnvConfig {
        randomisation: bad,
        ..EnvConfig::new(TaskKind::Force)
    };
    assert!(Env::new(r.clone(), cfg).is_err());

    // Force control with only the plate moved: the open-loop expert presses to the nominal
    // depth, so the plate (5000 N/m) and the robot's own compliance along z, in series, take
    // the offset: the force changes by o / (1/k + c), c from the static equilibrium.
    let only_surface = Randomisation {
        surface_offset_m: 0.002,
        ..Randomisation::default()
    };
    let cfg = EnvConfig {
        randomisation: only_surface,
        ..EnvConfig::new(TaskKind::Force)
    };
    let mut env = Env::new(r.clone(), cfg).unwrap();
    let mut nominal = Env::new(r.clone(), EnvConfig::new(TaskKind::Force)).unwrap();
    for seed in [3, 4, 5] {
        env.reset(seed).unwrap();
        nominal.reset(seed).unwrap();
        let o = env.perturbation().surface_offset_m;
        if let (Some(Load::Plane { point_m: a, .. }), Some(Load::Plane { point_m: b, .. })) =
            (env.load(), nominal.load())
        {
            // The plate's normal is -z: a positive offset moves it down, towards the robot.
            assert!((a[2] - (b[2] - o)).abs() < 1e-15);
        } else {
            panic!("the force task has a plate");
        }
        let (mut f, mut f0, mut a) = (0.0, 0.0, [0.0; 3]);
        for _ in 0..25 {
            a = env.expert_action().unwrap();
            let s = env.step(&a).unwrap();
            let a0 = nominal.expert_action().unwrap();
            assert_eq!(a, a0, "the expert does not know the offset");
            let s0 = nominal.step(&a0).unwrap();
            f = -s.info.force_n[2];
            f0 = -s0.info.force_n[2];
        }
        let mid = 0.5 * (f + f0);
        let h = 0.01;
        let z = |f: f64| r.static_tcp(&a, &nalgebra::Vector3::new(0.0, 0.0, -f)).z;
        let c = (z(mid - h) - z(mid + h)) / (2.0 * h);
        let want = o / (1.0 / 5000.0 + c);
        eprintln!(
            "offset {:.3} mm: force {f:.3} N, nominal {f0:.3} N, series springs {want:.3} N \
             (robot {:.0} N/m)",
            o * 1e3,
            1.0 / c
        );
        assert!(
            (f - f0 - want).abs() < 0.1 * want.abs().max(0.5),
            "offset {o}: {f} - {f0} against {want}"
        );
    }

    // A bias of the extension command moves the settled free TCP along the chain by that much.
    let bias = Randomisation {
        extension_bias_m: 0.001,
        ..Randomisation::default()
    };
    let cfg = EnvConfig {
        randomisation: bias,
        init_noise: 0.0,
        ..EnvConfig::new(TaskKind::Circle)
    };
    let mut env = Env::new(r.clone(), cfg).unwrap();
    let mut nominal = Env::new(
        r.clone(),
        EnvConfig {
            init_noise: 0.0,
            ..EnvConfig::new(TaskKind::Circle)
        },
    )
    .unwrap();
    env.reset(11).unwrap();
    nominal.reset(11).unwrap();
    let d = env.perturbation().command_bias[2];
    let (mut p, mut p0) = ([0.0; 3], [0.0; 3]);
    for _ in 0..10 {
        p = env.step(&[0.0, 0.0, 0.0]).unwrap().info.tcp_m;
        p0 = nominal.step(&[0.0, 0.0, 0.0]).unwrap().info.tcp_m;
    }
    // Straight chain: the extension joints act along z, 11 joints in three groups; the
    // extension group moves the TCP by (number of prismatic joints) x d.
    let n_prismatic = ocm_surrogate::chain::KINDS
        .iter()
        .filter(|k| matches!(k, ocm_surrogate::chain::JointKind::Prismatic))
        .count() as f64;
    let dz = p[2] - p0[2];
    eprintln!(
        "extension bias {:.3} mm: TCP moved {:.3} mm",
        d * 1e3,
        dz * 1e3
    );
    assert!(
        (dz - n_prismatic * d).abs() < 0.05 * (n_prismatic * d).abs(),
        "{dz} vs {d}"
    );
}

/// PPO on the residual starts at exactly the base (iteration 0 scores it, and the kept policy
/// acts as the base while the actor is held), and refuses a residual together with a warm
/// start.
#[test]
fn ppo_on_a_residual_starts_at_its_base() {
    let r = robot();
    let cfg = EnvConfig::new(TaskKind::Circle);
    let (base, obs) = small_bc();
    let dir = temp_dir("residual-ppo");
    let path = dir.join("bc.ckpt");
    base.save(&path, &meta("bc")).unwrap();
    let ppo_cfg = PpoConfig {
        iterations: 2,
        envs: 2,
        horizon: 16,
        epochs: 2,
        minibatch: 16,
        hidden: vec![16],
        eval_every: 1,
        eval_episodes: 1,
        residual_on: Some(path.clone()),
        residual_scale: 0.1,
        critic_warmup: 2,
        ..PpoConfig::default()
    };
    let (p, curve) = ppo::train(&r, &cfg, &ppo_cfg, |_| {}).unwrap();
    let (start_return, _, _) = ppo::score(&r, &cfg, &base, 1).unwrap();
    assert_eq!(curve[0].iteration, 0);
    assert_eq!(curve[0].eval_return, start_return);
    assert!(p.residual().is_some());
    assert_eq!(p.act_batch(&obs).unwrap(), base.act_batch(&obs).unwrap());
    let both = PpoConfig {
        init_from: Some(path.clone()),
        ..ppo_cfg
    };
    assert!(ppo::train(&r, &cfg, &both, |_| {}).is_err());
    let mut env = Env::new(r.clone(), cfg).unwrap();
    let a = evaluate(&mut env, 1, 9, |_, o| p.act(o)).unwrap();
    let b = evaluate(&mut env, 1, 9, |_, o| base.act(o)).unwrap();
    assert_eq!(a.position_error_mm, b.position_error_mm);
    std::fs::remove_dir_all(&dir).ok();
}

/// The property residual RL is for: under plate heights the expert and BC do not know (+-2 mm),
/// BC presses to the nominal depth and misses the force by about 1 N; a short PPO run on a
/// residual that sees the measured force cuts the held-out force error (evaluation seeds
/// disjoint from the training and selection seeds) to well below BC's.
#[test]
fn a_short_residual_run_beats_bc_on_held_out_plate_offsets() {
    let r = robot();
    let nominal = EnvConfig::new(TaskKind::Force);
    let demos = bc::collect(&r, &nominal, 8, 0.03, 0, 2).unwrap();
    let (base, _) = bc::fit(&demos, &[32, 32], &quick_train(), 0).unwrap();
    let dir = temp_dir("residual-force");
    let path = dir.join("bc.ckpt");
    base.save(&path, &meta("bc")).unwrap();
    let cfg = EnvConfig {
        randomisation: Randomisation {
            surface_offset_m: 0.002,
            ..Randomisation::default()
        },
        ..nominal
    };
    let ppo_cfg = PpoConfig {
        iterations: 60,
        envs: 4,
        horizon: 100,
        epochs: 4,
        minibatch: 100,
        hidden: vec![32, 32],
        std_start: 0.15,
        std_end: 0.03,
        learning_rate: 1e-3,
        eval_every: 5,
        eval_episodes: 2,
        residual_on: Some(path.clone()),
        residual_scale: 0.2,
        ..PpoConfig::default()
    };
    let t0 = std::time::Instant::now();
    let (p, _) = ppo::train(&r, &cfg, &ppo_cfg, |_| {}).unwrap();
    let mut env = Env::new(r.clone(), cfg).unwrap();
    let res = evaluate(&mut env, 6, 2_000_000, |_, o| p.act(o)).unwrap();
    let bc = evaluate(&mut env, 6, 2_000_000, |_, o| base.act(o)).unwrap();
    eprintln!(
        "held-out force error: BC {:.3} N, BC + residual {:.3} N ({:.0} s)",
        bc.force_error_n.mean,
        res.force_error_n.mean,
        t0.elapsed().as_secs_f64()
    );
    assert!(bc.force_error_n.mean > 0.5, "the offsets must hurt BC");
    assert!(
        res.force_error_n.mean < 0.5 * bc.force_error_n.mean,
        "{} against BC's {}",
        res.force_error_n.mean,
        bc.force_error_n.mean
    );
    assert_eq!(res.failures, 0);
    std::fs::remove_dir_all(&dir).ok();
}
