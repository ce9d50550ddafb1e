//! Training: behaviour cloning beats a random policy, training and collection are seeded and
//! deterministic, checkpoints round-trip.

mod common;
use common::{quick_train, robot};
use ocm_rl::bc;
use ocm_rl::env::{Env, EnvConfig};
use ocm_rl::eval::evaluate;
use ocm_rl::policy::{Policy, PolicyMeta};
use ocm_rl::ppo::{self, PpoConfig};
use ocm_rl::sac::{self, SacConfig};
use ocm_rl::tasks::TaskKind;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Margin of the short-training test: BC's mean circle error must be below this fraction of a
/// uniformly random policy's.
const MARGIN: f64 = 0.25;

#[test]
fn short_behaviour_cloning_beats_a_random_policy_on_the_circle() {
    let r = robot();
    let cfg = EnvConfig::new(TaskKind::Circle);
    let demos = bc::collect(&r, &cfg, 12, 0.03, 0, 2).unwrap();
    assert_eq!(demos.len(), 1200);
    let (policy, curve) = bc::fit(&demos, &[64, 64], &quick_train(), 0).unwrap();
    assert!(curve.last().unwrap().train_loss < 0.2 * curve[0].train_loss);
    let mut env = Env::new(r.clone(), cfg).unwrap();
    let trained = evaluate(&mut env, 3, 500, |_, o| policy.act(o)).unwrap();
    // no episodes: an error, not a report of zero means
    let e = evaluate(&mut env, 0, 500, |_, o| policy.act(o))
        .unwrap_err()
        .to_string();
    assert!(e.contains("episodes = 0"), "{e}");
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let random = evaluate(&mut env, 3, 500, |_, _| {
        Ok(std::array::from_fn(|_| rng.random_range(-1.0..1.0)))
    })
    .unwrap();
    eprintln!(
        "BC {:.2} mm, random {:.2} mm",
        trained.position_error_mm.mean, random.position_error_mm.mean
    );
    assert!(
        trained.position_error_mm.mean < MARGIN * random.position_error_mm.mean,
        "BC {} mm vs random {} mm",
        trained.position_error_mm.mean,
        random.position_error_mm.mean
    );
    assert!(trained.episode_return.mean > random.episode_return.mean);
}

#[test]
fn collection_and_fitting_are_deterministic() {
    let r = robot();
    let cfg = EnvConfig::new(TaskKind::Weight);
    let a = bc::collect(&r, &cfg, 3, 0.05, 7, 1).unwrap();
    let b = bc::collect(&r, &cfg, 3, 0.05, 7, 2).unwrap();
    assert_eq!(a, b);
    let mut t = quick_train();
    t.epochs = 3;
    let (p1, c1) = bc::fit(&a, &[16], &t, 3).unwrap();
    let (p2, c2) = bc::fit(&a, &[16], &t, 3).unwrap();
    assert_eq!(
        c1.iter().map(|r| r.train_loss).collect::<Vec<_>>(),
        c2.iter().map(|r| r.train_loss).collect::<Vec<_>>()
    );
    let obs: Vec<f64> = a.obs[..400].iter().map(|&v| f64::from(v)).collect();
    assert_eq!(p1.act_batch(&obs).unwrap(), p2.act_batch(&obs).unwrap());
}

#[test]
fn ppo_is_seeded_and_its_best_policy_round_trips() {
    let r = robot();
    let cfg = EnvConfig::new(TaskKind::Circle);
    let ppo_cfg = PpoConfig {
        iterations: 2,
        envs: 2,
        horizon: 16,
        epochs: 2,
        minibatch: 16,
        hidden: vec![16],
        eval_every: 1,
        eval_episodes: 1,
        ..PpoConfig::default()
    };
    let (p1, c1) = ppo::train(&r, &cfg, &ppo_cfg, |_| {}).unwrap();
    let (_, c2) = ppo::train(&r, &cfg, &ppo_cfg, |_| {}).unwrap();
    let strip = |c: &[ppo::RlRecord]| {
        c.iter()
            .map(|r| (r.mean_reward, r.eval_return, r.eval_position_error_mm))
            .collect::<Vec<_>>()
    };
    assert_eq!(strip(&c1), strip(&c2));
    let dir = std::env::temp_dir().join(format!("ocm-rl-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("policy.ckpt");
    let meta = PolicyMeta {
        task: "circle".into(),
        algorithm: "ppo".into(),
        seed: 0,
        score: c1[1].eval_return,
        residual: None,
    };
    p1.save(&path, &meta).unwrap();
    let (p3, m3) = Policy::load(&path).unwrap();
    assert_eq!(m3, meta);
    let mut env = Env::new(r.clone(), cfg).unwrap();
    let obs = env.reset(3).unwrap();
    assert_eq!(p1.act(&obs).unwrap(), p3.act(&obs).unwrap());
    std::fs::write(&path, b"not a checkpoint").unwrap();
    assert!(Policy::load(&path).is_err());
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn sac_is_seeded_and_its_policy_acts_in_bounds() {
    let r = robot();
    let cfg = EnvConfig::new(TaskKind::Ellipse);
    let sac_cfg = SacConfig {
        steps: 24,
        envs: 2,
        warmup: 8,
        batch: 16,
        hidden: vec![16],
        eval_every: 12,
        eval_episodes: 1,
        ..SacConfig::default()
    };
    let (p1, c1) = sac::train(&r, &cfg, &sac_cfg, |_| {}).unwrap();
    let (p2, c2) = sac::train(&r, &cfg, &sac_cfg, |_| {}).unwrap();
    assert_eq!(c1.len(), 2);
    let strip = |c: &[ppo::RlRecord]| {
        c.iter()
            .map(|r| (r.mean_reward, r.eval_return, r.eval_force_error_n))
            .collect::<Vec<_>>()
    };
    assert_eq!(strip(&c1), strip(&c2));
    let mut env = Env::new(r.clone(), cfg).unwrap();
    let obs = env.reset(1).unwrap();
    let a = p1.act(&obs).unwrap();
    assert_eq!(a, p2.act(&obs).unwrap());
    assert!(a.iter().all(|v| v.abs() < 1.0));
}

/// PPO and SAC warm-started from a saved BC policy: PPO starts at exactly that policy (scored as
/// iteration 0, and kept while the actor is held), SAC's actor is fitted to it before any SAC
/// update.
#[test]
fn ppo_and_sac_start_from_a_saved_policy() {
    let r = robot();
    let cfg = EnvConfig::new(TaskKind::Circle);
    let demos = bc::collect(&r, &cfg, 4, 0.03, 0, 2).unwrap();
    let mut t = quick_train();
    t.epochs = 20;
    let (teacher, _) = bc::fit(&demos, &[16], &t, 0).unwrap();
    let dir = std::env::temp_dir().join(format!("ocm-rl-init-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("bc.ckpt");
    let meta = PolicyMeta {
        task: "circle".into(),
        algorithm: "bc".into(),
        seed: 0,
        score: 0.0,
        residual: None,
    };
    teacher.save(&path, &meta).unwrap();
    let obs: Vec<f64> = demos.obs[..40 * 200]
        .iter()
        .map(|&v| f64::from(v))
        .collect();
    let want = teacher.act_batch(&obs).unwrap();
    let ppo_cfg = PpoConfig {
        iterations: 2,
        envs: 2,
        horizon: 16,
        epochs: 2,
        minibatch: 16,
        hidden: vec![16],
        eval_every: 1,
        eval_episodes: 1,
        init_from: Some(path.clone()),
        critic_warmup: 2,
        ..PpoConfig::default()
    };
    let (p, curve) = ppo::train(&r, &cfg, &ppo_cfg, |_| {}).unwrap();
    let (start_return, _, _) = ppo::score(&r, &cfg, &teacher, 1).unwrap();
    assert_eq!(curve[0].iteration, 0);
    assert_eq!(curve[0].eval_return, start_return);
    assert_eq!(p.act_batch(&obs).unwrap(), want);
    // A network of another shape is refused, naming the file.
    let wrong = PpoConfig {
        hidden: vec![8],
        ..ppo_cfg
    };
    let e = ppo::train(&r, &cfg, &wrong, |_| {})
        .unwrap_err()
        .to_string();
    assert!(e.contains("bc.ckpt"), "{e}");
    let sac_cfg = SacConfig {
        steps: 101,
        envs: 2,
        warmup: 100,
        batch: 64,
        hidden: vec![32, 32],
        eval_every: 101,
        eval_episodes: 1,
        init_from: Some(path.clone()),
        pretrain_steps: 400,
        critic_warmup: 100,
        learning_rate: 3e-3,
        ..SacConfig::default()
    };
    let (s, _) = sac::train(&r, &cfg, &sac_cfg, |_| {}).unwrap();
    let got = s.act_batch(&obs).unwrap();
    let gap = got
        .iter()
        .zip(&want)
        .map(|(a, b)| (a - b).abs())
        .sum::<f64>()
        / want.len() as f64;
    let spread = want.iter().map(|a| a.abs()).sum::<f64>() / want.len() as f64;
    eprintln!("SAC actor after fitting: mean |a - a_bc| {gap:.4} (mean |a_bc| {spread:.3})");
    assert!(gap < 0.2 * spread, "{gap} vs {spread}");
    std::fs::remove_dir_all(&dir).ok();
}

/// PPO's `bc_weight` anchors the policy mean to its start: after the same updates the anchored
/// policy stays much closer to the initial network than the free one; a NaN weight is refused.
#[test]
fn ppo_bc_weight_anchors_the_policy_to_its_start() {
    let r = robot();
    let cfg = EnvConfig::new(TaskKind::Circle);
    let base = PpoConfig {
        iterations: 3,
        envs: 2,
        horizon: 32,
        epochs: 4,
        minibatch: 16,
        hidden: vec![16],
        eval_every: 3,
        eval_episodes: 1,
        learning_rate: 3e-3,
        ..PpoConfig::default()
    };
    // A zero step size leaves the initial network.
    let (start, _) = ppo::train(
        &r,
        &cfg,
        &PpoConfig {
            learning_rate: 0.0,
            ..base.clone()
        },
        |_| {},
    )
    .unwrap();
    let demos = bc::collect(&r, &cfg, 2, 0.03, 0, 2).unwrap();
    let obs: Vec<f64> = demos.obs[..40 * 100]
        .iter()
        .map(|&v| f64::from(v))
        .collect();
    let a0 = start.act_batch(&obs).unwrap();
    let drift = |w: f64| {
        let (p, _) = ppo::train(
            &r,
            &cfg,
            &PpoConfig {
                bc_weight: w,
                ..base.clone()
            },
            |_| {},
        )
        .unwrap();
        let a = p.act_batch(&obs).unwrap();
        a.iter().zip(&a0).map(|(x, y)| (x - y).abs()).sum::<f64>() / a.len() as f64
    };
    let (free, anchored) = (drift(0.0), drift(1e3));
    eprintln!("mean |a - a_start|: free {free:.4}, anchored {anchored:.4}");
    assert!(
        free > 1e-3 && anchored < 0.3 * free,
        "free {free}, anchored {anchored}"
    );
    let bad = PpoConfig {
        bc_weight: f64::NAN,
        ..base
    };
    assert!(ppo::train(&r, &cfg, &bad, |_| {}).is_err());
}
